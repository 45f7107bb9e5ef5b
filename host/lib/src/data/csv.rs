//! The capture CSV (../shared/DESIGN.md §5) and any CSV with a column mapping: read, checked for
//! uniform sampling, and written back losslessly.
//!
//! # Capture CSV contract (`# key=value` comments)
//!
//! A capture CSV may open with comment lines `# key=value` (spaces around the
//! key and the value are trimmed). Keys this module understands:
//!
//! | key | type | meaning |
//! | --- | --- | --- |
//! | `kind` | `special_odd_multisine`, `random_odd_multisine` or `band_limited_noise` | [`SignalKind`] |
//! | `fs_hz` | u32 | sample rate of the excitation [Hz] |
//! | `period_samples` | u32 | excitation period N [samples] |
//! | `max_line` | u32 | highest excited harmonic F |
//! | `cutoff_hz` | f32 | amplitude-shape cut-off [Hz] |
//! | `rms_rad` | f32 | RMS of the full-amplitude reference [rad] |
//! | `seed` | u64 | phase / noise seed |
//! | `ramp_samples` | u32 | raised-cosine ramp length [samples] |
//! | `periods` | u32 | full-amplitude periods after the ramp-in (0 = endless) |
//! | `sample_interval_s` | f64 | nominal sample interval [s] (optional) |
//! | `gaps` | `a..b;c..d` or `none` | sequence numbers missing (`jointid export`; optional) |
//!
//! The time column must agree with the comments: `fs_hz` with its rate, and
//! `sample_interval_s` with the median of its intervals, else the file is refused naming
//! both rates ([`DataError::RateContradiction`]), not read as a gap after every sample.
//! Only the missing samples a `gaps` comment lists may make the median a multiple of the
//! stated interval (a capture that lost every other sample).
//! The nine excitation keys come as a group: when `kind` is present all nine
//! must be, and they are parsed into an [`ExcitationConfig`]. Any other key is
//! kept verbatim in [`Dataset::meta`]. The sample `k = 0` of the file is the
//! first sample of the ramp-in (the excitation's first sample).
//! After the comments comes the header `t,theta_ref,u,theta_m` (extra
//! columns are allowed and ignored), then one row per sample.
// Units in brackets (`[s]`, `[Hz]`, `[dB]`) are not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

use std::collections::BTreeMap;
use std::io::{self, Write};
use std::path::Path;

use super::{ColumnMap, DataError, Dataset, ExcitationConfig, IdData, Record, SignalKind};

/// relative tolerance on each sample interval against the nominal one
pub const SAMPLE_INTERVAL_TOLERANCE: f64 = 0.01;

/// The nine `# key=value` comment keys of an excitation config in a capture CSV, in the
/// order they are written.
pub const EXCITATION_KEYS: [&str; 9] = [
    "kind",
    "fs_hz",
    "period_samples",
    "max_line",
    "cutoff_hz",
    "rms_rad",
    "seed",
    "ramp_samples",
    "periods",
];

/// Parses a CSV text (capture CSV or any CSV through `map`) as one uniformly sampled
/// record.
///
/// # Errors
/// As [`parse_csv_record`]; [`DataError::TimeGap`] naming the line of the first gap when
/// the time column has one.
pub fn parse_csv(text: &str, name: &str, map: &ColumnMap) -> Result<Dataset, DataError> {
    let (record, first_gap) = parse_inner(text.as_bytes(), None, name, map)?;
    match first_gap {
        Some(e) => Err(e),
        None => record.into_single(),
    }
}

/// Parses a CSV text (capture CSV or any CSV through `map`) into its gap-free pieces.
///
/// `name` is used in error messages. Rows are split on `map.delimiter`, else on `,`
/// (or on `;` or a tab when the header line holds no `,`: a note says so); blank lines
/// are skipped; cells are trimmed. The sample interval is `sample_interval_s` when
/// given, else the median interval; every interval must be within
/// [`SAMPLE_INTERVAL_TOLERANCE`] of it or of a whole multiple of it: a multiple is a gap
/// (samples missing), which starts a new piece. Comment keys of another logger (no
/// `kind`, so no full excitation config) are kept in [`Dataset::meta`]; those this module
/// does not use are named in a note.
///
/// # Errors
/// Every [`DataError`] naming `name`, the line and the column at fault.
pub fn parse_csv_record(text: &str, name: &str, map: &ColumnMap) -> Result<Record, DataError> {
    parse_inner(text.as_bytes(), None, name, map).map(|(r, _)| r)
}

/// Reads a CSV from `reader` line by line into its gap-free pieces, as
/// [`parse_csv_record`] parses a text: the text is never held whole, only the columns
/// `map` names, as `f64` (a ten-million-row file of 532 MB is read in the 240 MB of its
/// three columns). `size`, the input's length in bytes when known, sizes the columns.
///
/// # Errors
/// As [`parse_csv_record`]; [`DataError::NotText`] when the input is not UTF-8 text or
/// holds a NUL (binary content: the first such byte by its offset, a byte that is not
/// UTF-8 before a NUL, wherever they lie, as a check of the whole text would say),
/// [`DataError::Io`] when it cannot be read.
pub fn read_csv_record(
    reader: impl io::BufRead,
    size: Option<u64>,
    name: &str,
    map: &ColumnMap,
) -> Result<Record, DataError> {
    parse_inner(reader, size, name, map).map(|(r, _)| r)
}

/// The lines of a CSV read from a [`io::BufRead`], without their line ends (`\n`, or
/// `\r\n`, as [`str::lines`] splits), numbered from 1, a leading byte-order mark
/// dropped. One line is held at a time. A line that is not UTF-8 text or holds a NUL
/// ends the reading with [`DataError::NotText`].
struct Lines<R> {
    reader: R,
    name: String,
    buf: Vec<u8>,
    /// number of the line in `buf`
    line: usize,
    /// byte offset of the line after it
    offset: u64,
}

impl<R: io::BufRead> Lines<R> {
    fn new(reader: R, name: &str) -> Self {
        Lines {
            reader,
            name: name.to_string(),
            buf: Vec::new(),
            line: 0,
            offset: 0,
        }
    }

    fn io(&self, source: io::Error) -> DataError {
        DataError::Io {
            file: self.name.clone(),
            source,
        }
    }

    /// Reads the next line into `buf` with its end; `false` at the end of the input.
    fn fill(&mut self) -> Result<bool, DataError> {
        self.buf.clear();
        loop {
            match self.reader.read_until(b'\n', &mut self.buf) {
                Ok(0) => return Ok(false),
                Ok(_) => return Ok(true),
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(self.io(e)),
            }
        }
    }

    /// The next line and its number; `None` at the end of the input.
    fn next_line(&mut self) -> Result<Option<(usize, &str)>, DataError> {
        let start = self.offset;
        if !self.fill()? {
            return Ok(None);
        }
        self.line += 1;
        self.offset += self.buf.len() as u64;
        let skip = if self.line == 1 && self.buf.starts_with("\u{feff}".as_bytes()) {
            3
        } else {
            0
        };
        if std::str::from_utf8(&self.buf).is_err() || self.buf.contains(&0) {
            return Err(self.not_text(start));
        }
        let mut l = &self.buf[skip..];
        if let Some(rest) = l.strip_suffix(b"\n") {
            l = rest.strip_suffix(b"\r").unwrap_or(rest);
        }
        // checked above; `l` ends at an ASCII byte, so it is text too
        Ok(Some((
            self.line,
            std::str::from_utf8(l).unwrap_or_default(),
        )))
    }

    /// The error of binary content found in the line in `buf` (at byte `start`) or after
    /// it: the first byte that is not UTF-8, else the first NUL.
    fn not_text(&mut self, mut start: u64) -> DataError {
        let mut nul = None;
        loop {
            if let Err(e) = std::str::from_utf8(&self.buf) {
                return self.binary(format!(
                    "byte {} is not UTF-8 text",
                    start + e.valid_up_to() as u64
                ));
            }
            if let (None, Some(i)) = (nul, self.buf.iter().position(|b| *b == 0)) {
                nul = Some(start + i as u64);
            }
            start += self.buf.len() as u64;
            match self.fill() {
                Ok(true) => {}
                Ok(false) => break,
                Err(e) => return e,
            }
        }
        match nul {
            Some(i) => self.binary(format!(
                "byte {i} is a NUL: binary content of an unknown type"
            )),
            None => self.binary("not text".into()),
        }
    }

    fn binary(&self, reason: String) -> DataError {
        DataError::NotText {
            file: self.name.clone(),
            reason,
        }
    }

    /// What the rest of the input says against `e`, an error found before its end: that
    /// it is binary content ([`Lines::not_text`]), which a check of the whole text
    /// reports first; else `e`.
    fn rest_or(&mut self, e: DataError) -> DataError {
        if matches!(e, DataError::NotText { .. } | DataError::Io { .. }) {
            return e;
        }
        while let Ok(true) = self.fill() {
            if std::str::from_utf8(&self.buf).is_err() || self.buf.contains(&0) {
                let at = self.offset;
                return self.not_text(at);
            }
            self.offset += self.buf.len() as u64;
        }
        e
    }
}

/// Each data row's line in its file (a CSV's line, a MAT-file's sample), for messages:
/// kept as the rows where the numbering jumps (blank or comment lines among the rows), so
/// a file of ten million rows holds a handful of entries, not a number per row.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub(super) struct RowLines {
    /// (row, its line) where a row's line is not the one before plus one
    jumps: Vec<(usize, usize)>,
    rows: usize,
}

impl RowLines {
    /// Rows `0..rows` on the lines (samples) `first, first + 1, …`.
    pub(super) fn counting(first: usize, rows: usize) -> Self {
        RowLines {
            jumps: vec![(0, first)],
            rows,
        }
    }

    /// The next row, on `line`.
    fn push(&mut self, line: usize) {
        let follows = self
            .jumps
            .last()
            .is_some_and(|&(r, l)| l + (self.rows - r) == line);
        if !follows {
            self.jumps.push((self.rows, line));
        }
        self.rows += 1;
    }

    /// The number of rows.
    pub(super) fn len(&self) -> usize {
        self.rows
    }

    /// The line of row `row` (< [`RowLines::len`]).
    pub(super) fn line(&self, row: usize) -> usize {
        let i = self.jumps.partition_point(|&(r, _)| r <= row).max(1) - 1;
        self.jumps.get(i).map_or(row + 1, |&(r, l)| l + (row - r))
    }
}

/// Comment keys used from a CSV without the full excitation config (another logger's).
pub const OTHER_LOGGER_KEYS: [&str; 4] = ["sample_interval_s", "period_samples", "f0_hz", "fs_hz"];

fn parse_inner(
    reader: impl io::BufRead,
    size: Option<u64>,
    name: &str,
    map: &ColumnMap,
) -> Result<(Record, Option<DataError>), DataError> {
    let mut lines = Lines::new(reader, name);
    match read_columns(&mut lines, size, map) {
        Ok((meta, excitation, notes, columns, rows)) => {
            record_from_columns(name, map, meta, excitation, notes, columns, rows)
        }
        Err(e) => Err(lines.rest_or(e)),
    }
}

/// What [`read_columns`] reads: the comment keys with their lines, the excitation, the
/// notes, the columns `map` names and each row's line.
type ReadColumns = (
    BTreeMap<String, (usize, String)>,
    Option<ExcitationConfig>,
    Vec<String>,
    Vec<Vec<f64>>,
    RowLines,
);

/// Reads the comments, the header and the cells of the columns `map` names, row by row.
fn read_columns(
    lines: &mut Lines<impl io::BufRead>,
    size: Option<u64>,
    map: &ColumnMap,
) -> Result<ReadColumns, DataError> {
    let name = lines.name.clone();
    let name = name.as_str();
    let file = || name.to_string();
    let mut notes = Vec::new();
    let mut meta: BTreeMap<String, (usize, String)> = BTreeMap::new();
    let (header_line, header) = loop {
        match lines.next_line()? {
            None => return Err(DataError::NoHeader { file: file() }),
            Some((_, l)) if l.trim().is_empty() => continue,
            Some((ln, l)) if l.trim_start().starts_with('#') => {
                let body = l.trim_start()[1..].trim();
                if let Some((k, v)) = body.split_once('=') {
                    meta.insert(k.trim().to_string(), (ln, v.trim().to_string()));
                }
            }
            Some((ln, l)) => break (ln, l.to_string()),
        }
    };
    let header = header.as_str();
    let excitation = if meta.contains_key("kind") {
        parse_excitation(&meta, name)?
    } else {
        let partial: Vec<&str> = EXCITATION_KEYS
            .iter()
            .copied()
            .filter(|k| meta.contains_key(*k))
            .collect();
        let ours = meta
            .get("format")
            .is_some_and(|(_, v)| v == "jointid capture csv");
        let unknown: Vec<&str> = meta
            .keys()
            .map(String::as_str)
            .filter(|k| !OTHER_LOGGER_KEYS.contains(k))
            .collect();
        if !partial.is_empty() {
            notes.push(format!(
                "{name}: comment keys {} without `kind`: not a full excitation config (the nine \
                 keys {} come together); read as another logger's",
                partial.join(", "),
                EXCITATION_KEYS.join(", ")
            ));
        }
        if !unknown.is_empty() && !ours {
            notes.push(format!(
                "{name}: comment keys not used: {} (used: {})",
                unknown.join(", "),
                OTHER_LOGGER_KEYS.join(", ")
            ));
        }
        None
    };
    let (delim, guessed) = header_delimiter(header, map.delimiter);
    if guessed {
        notes.push(format!(
            "{name}: no `,` in the header line {header_line}: columns split on {} \
             (--delimiter sets it)",
            if delim == '\t' {
                "tabs".to_string()
            } else {
                format!("`{delim}`")
            }
        ));
    }
    let cols = header_cells(header, delim);
    let find = |c: &str| {
        cols.iter()
            .position(|h| *h == c)
            .ok_or_else(|| DataError::MissingColumn {
                file: file(),
                line: header_line,
                column: c.to_string(),
                have: cols.join(","),
            })
    };
    let mut wanted = vec![
        (map.time.as_str(), find(&map.time)?),
        (map.input.as_str(), find(&map.input)?),
        (map.output.as_str(), find(&map.output)?),
    ];
    if let Some(r) = &map.reference {
        wanted.push((r.as_str(), find(r)?));
    }
    let mut columns: Vec<Vec<f64>> = vec![Vec::new(); wanted.len()];
    let mut rows = RowLines::default();
    // the columns sized from the first rows' length and the input's size
    let (sizing_rows, rows_from) = (64, lines.offset);
    while let Some((ln, l)) = lines.next_line()? {
        if l.trim().is_empty() || l.trim_start().starts_with('#') {
            continue;
        }
        let cells: Vec<&str> = l.split(delim).collect();
        for (slot, (cname, idx)) in wanted.iter().enumerate() {
            let cell = cells.get(*idx).ok_or_else(|| DataError::ShortRow {
                file: file(),
                line: ln,
                column: cname.to_string(),
                cells: cells.len(),
            })?;
            let cell = cell.trim().trim_matches('"');
            let v: f64 = cell.parse().map_err(|_| DataError::NotNumeric {
                file: file(),
                line: ln,
                column: cname.to_string(),
                cell: cell.to_string(),
            })?;
            if !v.is_finite() {
                return Err(DataError::NotFinite {
                    file: file(),
                    line: ln,
                    column: cname.to_string(),
                    cell: cell.to_string(),
                });
            }
            columns[slot].push(v);
        }
        rows.push(ln);
        if let (Some(size), true) = (size, rows.len() == sizing_rows) {
            let per_row = (lines.offset - rows_from) as f64 / sizing_rows as f64;
            let left = size.saturating_sub(lines.offset) as f64 / per_row.max(1.0);
            for c in &mut columns {
                c.reserve((1.05 * left) as usize + 16);
            }
        }
    }
    for c in &mut columns {
        c.shrink_to_fit();
    }
    Ok((meta, excitation, notes, columns, rows))
}

/// The delimiter of a CSV whose header line is `header`: `given`, else `,`, or `;` or a
/// tab when the header holds no `,` (then `true`: guessed, worth a note).
fn header_delimiter(header: &str, given: Option<char>) -> (char, bool) {
    match given {
        Some(d) => (d, false),
        None if header.contains(',') => (',', false),
        None => match [';', '\t'].into_iter().find(|d| header.contains(*d)) {
            Some(d) => (d, true),
            None => (',', false),
        },
    }
}

/// The column names of a header line split on `delim`, trimmed and unquoted.
fn header_cells(header: &str, delim: char) -> Vec<&str> {
    header
        .split(delim)
        .map(|c| c.trim().trim_matches('"').trim())
        .collect()
}

/// What a CSV text holds before any column mapping: the columns of its header line (the
/// first line that is neither blank nor a `#` comment, split as [`parse_csv_record`] splits
/// it, `delimiter` or the one it would choose) and the rows under it (the lines that are
/// neither blank nor comments). `None` when the text has no header line.
pub fn header_columns(text: &str, delimiter: Option<char>) -> Option<(Vec<String>, usize)> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut lines = text
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
    let header = lines.next()?;
    let (delim, _) = header_delimiter(header, delimiter);
    let columns = header_cells(header, delim)
        .into_iter()
        .map(str::to_string)
        .collect();
    Some((columns, lines.count()))
}

/// The record of columns already read (time, input, output and, when `map` has one, the
/// reference), checked as [`parse_csv_record`] describes; `line_of_row` gives each row's
/// position for messages (a line of a CSV, a sample of a MAT-file), `meta` the comment
/// keys with their lines. Also returns the first gap as an error, for [`parse_csv`].
///
/// # Errors
/// As [`parse_csv_record`] after the cells are read.
pub(super) fn record_from_columns(
    name: &str,
    map: &ColumnMap,
    meta: BTreeMap<String, (usize, String)>,
    excitation: Option<ExcitationConfig>,
    notes: Vec<String>,
    columns: Vec<Vec<f64>>,
    line_of_row: RowLines,
) -> Result<(Record, Option<DataError>), DataError> {
    let file = || name.to_string();
    let rows = line_of_row.len();
    if rows < 2 {
        return Err(DataError::TooShort { file: file(), rows });
    }
    let t = &columns[0];
    let nominal =
        match meta.get("sample_interval_s") {
            Some((ln, v)) => Some(v.parse::<f64>().ok().filter(|x| *x > 0.0).ok_or_else(|| {
                DataError::BadMeta {
                    file: file(),
                    line: *ln,
                    key: "sample_interval_s".into(),
                    reason: format!("`{v}` is not a positive number"),
                }
            })?),
            None => None,
        };
    for k in 1..rows {
        if t[k] <= t[k - 1] {
            return Err(DataError::NonMonotonic {
                file: file(),
                line: line_of_row.line(k),
                prev: t[k - 1],
                next: t[k],
            });
        }
    }
    let median = {
        let mut d: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
        let mid = d.len() / 2;
        *d.select_nth_unstable_by(mid, f64::total_cmp).1
    };
    let ts = nominal.unwrap_or(median);
    if (median - ts).abs() > SAMPLE_INTERVAL_TOLERANCE * ts
        && listed_missing(&meta).is_none_or(|listed| listed != implied_missing(t, ts))
    {
        return Err(DataError::RateContradiction {
            file: file(),
            line: meta["sample_interval_s"].0,
            stated_s: ts,
            column_s: median,
            intervals: rows - 1,
        });
    }
    // piece boundaries: a jump by a whole number m ≥ 2 of intervals is a gap
    let mut starts = vec![0usize];
    let mut first_gap = None;
    for k in 1..rows {
        let dt = t[k] - t[k - 1];
        if (dt - ts).abs() <= SAMPLE_INTERVAL_TOLERANCE * ts {
            continue;
        }
        let m = (dt / ts).round();
        if m >= 2.0 && (dt - m * ts).abs() <= SAMPLE_INTERVAL_TOLERANCE * ts {
            starts.push(k);
            first_gap.get_or_insert(DataError::TimeGap {
                file: file(),
                line: line_of_row.line(k),
                prev: t[k - 1],
                next: t[k],
                missing: m as u64 - 1,
            });
            continue;
        }
        return Err(DataError::NonUniform {
            file: file(),
            line: line_of_row.line(k),
            prev: t[k - 1],
            next: t[k],
            dt,
            ts,
        });
    }
    if let Some(cfg) = &excitation {
        let fs = 1.0 / ts;
        if (fs - f64::from(cfg.fs_hz)).abs() > SAMPLE_INTERVAL_TOLERANCE * fs {
            let (ln, _) = &meta["fs_hz"];
            return Err(DataError::BadMeta {
                file: file(),
                line: *ln,
                key: "fs_hz".into(),
                reason: format!(
                    "{} Hz disagrees with the time column ({fs:.6} Hz)",
                    cfg.fs_hz
                ),
            });
        }
        // the period must fit the record: a longer one cannot be the data's
        if cfg.period_samples as usize > rows {
            let (ln, _) = &meta["period_samples"];
            return Err(DataError::BadMeta {
                file: file(),
                line: *ln,
                key: "period_samples".into(),
                reason: format!(
                    "{} samples is longer than the record ({rows} rows)",
                    cfg.period_samples
                ),
            });
        }
    }
    if let Some(cfg) = &excitation {
        // the period must be the data's: the longest piece repeats over it
        let longest = starts
            .iter()
            .zip(starts.iter().skip(1).chain(std::iter::once(&rows)))
            .map(|(&a, &b)| a..b)
            .max_by_key(|r| r.len())
            .unwrap_or(0..rows);
        // its samples in the periods, between the ramp in and the ramp out (`periods` 0:
        // no end) on the excitation's time line
        let n = cfg.period_samples as usize;
        let (t_in, t_out) = (
            f64::from(cfg.ramp_samples) * ts * (1.0 - 1e-9),
            match cfg.periods {
                0 => f64::INFINITY,
                p => (f64::from(cfg.ramp_samples) + f64::from(p) * n as f64) * ts * (1.0 - 1e-9),
            },
        );
        // the time column increases, so they are one run of samples
        let during =
            |bound: f64| longest.start + t[longest.clone()].partition_point(|x| *x < bound);
        let (first, end) = (during(t_in), during(t_out));
        let span = first..end.max(first);
        // the reference repeats exactly; the measured columns to within their noise
        let reference = map
            .reference
            .as_ref()
            .and_then(|_| repeat_misfit(&columns[3][span.clone()], n))
            .map(|rho| (rho, REFERENCE_MISFIT_LIMIT, "the reference column"));
        let measured = [1, 2]
            .iter()
            .filter_map(|&c| repeat_misfit(&columns[c][span.clone()], n))
            .min_by(f64::total_cmp)
            .map(|rho| (rho, PERIOD_MISFIT_LIMIT, "both measured columns"));
        if let Some((rho, _, which)) = reference.or(measured).filter(|(rho, limit, _)| rho > limit)
        {
            let (ln, _) = &meta["period_samples"];
            return Err(DataError::BadMeta {
                file: file(),
                line: *ln,
                key: "period_samples".into(),
                reason: format!(
                    "{n} samples is not the data's period: successive stretches of that length \
                     differ by {:.2} % of their power in {which}",
                    100.0 * rho
                ),
            });
        }
    }
    let meta: BTreeMap<String, String> = meta
        .into_iter()
        .filter(|(k, _)| excitation.is_none() || !EXCITATION_KEYS.contains(&k.as_str()))
        .map(|(k, (_, v))| (k, v))
        .collect();
    // the pieces take the columns' samples, the last piece first, each column shrunk as
    // it goes, so no moment holds a column twice (one piece, the usual file, moves them)
    let t0: Vec<f64> = starts.iter().map(|&k| t[k]).collect();
    let mut columns = columns.into_iter().skip(1);
    let (mut u, mut y) = (
        columns.next().unwrap_or_default(),
        columns.next().unwrap_or_default(),
    );
    let mut r = map.reference.as_ref().and(columns.next());
    let mut pieces = Vec::with_capacity(starts.len());
    for (&k, &t0) in starts.iter().zip(&t0).rev() {
        let take = |c: &mut Vec<f64>| {
            if k == 0 {
                return std::mem::take(c);
            }
            let tail = c[k..].to_vec();
            c.truncate(k);
            c.shrink_to_fit();
            tail
        };
        let data = IdData {
            ts,
            u: take(&mut u),
            y: take(&mut y),
            r: r.as_mut().map(take),
        };
        pieces.push(Dataset {
            name: name.to_string(),
            data,
            t0,
            excitation,
            meta: meta.clone(),
        });
    }
    pieces.reverse();
    Ok((Record { pieces, notes }, first_gap))
}

/// The samples the `gaps` comment (`a..b;c..d`, inclusive, or `none`) lists as missing;
/// `None` without one or when it does not read.
fn listed_missing(meta: &BTreeMap<String, (usize, String)>) -> Option<u64> {
    let (_, v) = meta.get("gaps")?;
    if v.trim() == "none" {
        return Some(0);
    }
    v.split(';')
        .map(|r| {
            let (a, b) = r.trim().split_once("..")?;
            let (a, b): (u64, u64) = (a.trim().parse().ok()?, b.trim().parse().ok()?);
            (b >= a).then_some(b - a + 1)
        })
        .sum()
}

/// The samples the time column `t` lacks at the interval `ts` [s]: `m − 1` for each jump
/// of about `m ≥ 2` intervals.
fn implied_missing(t: &[f64], ts: f64) -> u64 {
    t.windows(2)
        .map(|w| ((w[1] - w[0]) / ts).round())
        .filter(|m| *m >= 2.0)
        .map(|m| m as u64 - 1)
        .sum()
}

/// Largest share of its power by which a measured column (torque, angle) may differ
/// between successive periods for the stated period to be the data's (uncorrelated
/// stretches differ by about 100 %; noise and disturbance by their share of the power).
pub const PERIOD_MISFIT_LIMIT: f64 = 0.5;

/// The same for the reference column, which the board repeats exactly from one table: a
/// period one sample off the default excitation's 5000 differs by 1.3 %.
pub const REFERENCE_MISFIT_LIMIT: f64 = 1e-5;

/// Shortest period [samples] [`repeat_misfit`] judges: shorter ones are too few samples
/// to tell a period from noise.
const SHORTEST_CHECKED_PERIOD: usize = 32;

/// How far `x` is from repeating every `n` samples:
/// `Σ (x_{k+n} − x_k)² / Σ ((x_k − x̄)² + (x_{k+n} − x̄)²)` over its whole periods (0:
/// exactly periodic; about 1: no relation). `None` when `x` holds fewer than two whole
/// periods, `n` is shorter than [`SHORTEST_CHECKED_PERIOD`], or `x` is constant.
fn repeat_misfit(x: &[f64], n: usize) -> Option<f64> {
    let whole = x.len() / n.max(1) * n;
    if n < SHORTEST_CHECKED_PERIOD || whole < 2 * n {
        return None;
    }
    let x = &x[..whole];
    let mean = x.iter().sum::<f64>() / whole as f64;
    let (mut num, mut den) = (0.0, 0.0);
    for k in 0..whole - n {
        num += (x[k + n] - x[k]).powi(2);
        den += (x[k] - mean).powi(2) + (x[k + n] - mean).powi(2);
    }
    (den > 0.0).then(|| num / den)
}

pub(super) fn parse_excitation(
    meta: &BTreeMap<String, (usize, String)>,
    file: &str,
) -> Result<Option<ExcitationConfig>, DataError> {
    if !EXCITATION_KEYS.iter().any(|k| meta.contains_key(*k)) {
        return Ok(None);
    }
    let first_line = EXCITATION_KEYS
        .iter()
        .filter_map(|k| meta.get(*k).map(|(l, _)| *l))
        .min()
        .unwrap_or(1);
    let get = |key: &str| -> Result<(usize, &str), DataError> {
        meta.get(key)
            .map(|(l, v)| (*l, v.as_str()))
            .ok_or_else(|| DataError::BadMeta {
                file: file.to_string(),
                line: first_line,
                key: key.to_string(),
                reason: "missing: the excitation keys kind, fs_hz, period_samples, max_line, cutoff_hz, rms_rad, seed, ramp_samples, periods come together".into(),
            })
    };
    fn num<T: std::str::FromStr>(
        file: &str,
        key: &str,
        (line, v): (usize, &str),
    ) -> Result<T, DataError> {
        v.parse().map_err(|_| DataError::BadMeta {
            file: file.to_string(),
            line,
            key: key.to_string(),
            reason: format!("`{v}` is not a valid {}", std::any::type_name::<T>()),
        })
    }
    let (kl, kv) = get("kind")?;
    let kind = match kv {
        "special_odd_multisine" => SignalKind::SpecialOddMultisine,
        "random_odd_multisine" => SignalKind::RandomOddMultisine,
        "band_limited_noise" => SignalKind::BandLimitedNoise,
        other => {
            return Err(DataError::BadMeta {
                file: file.to_string(),
                line: kl,
                key: "kind".into(),
                reason: format!(
                    "unknown kind `{other}` (special_odd_multisine, random_odd_multisine, band_limited_noise)"
                ),
            })
        }
    };
    let cfg = ExcitationConfig {
        kind,
        fs_hz: num(file, "fs_hz", get("fs_hz")?)?,
        period_samples: num(file, "period_samples", get("period_samples")?)?,
        max_line: num(file, "max_line", get("max_line")?)?,
        cutoff_hz: num(file, "cutoff_hz", get("cutoff_hz")?)?,
        rms_rad: num(file, "rms_rad", get("rms_rad")?)?,
        seed: num(file, "seed", get("seed")?)?,
        ramp_samples: num(file, "ramp_samples", get("ramp_samples")?)?,
        periods: num(file, "periods", get("periods")?)?,
    };
    if cfg.fs_hz == 0 {
        let (l, _) = get("fs_hz")?;
        return Err(DataError::BadMeta {
            file: file.to_string(),
            line: l,
            key: "fs_hz".into(),
            reason: "0 Hz: the sample rate must be positive".into(),
        });
    }
    if cfg.period_samples < 2 {
        let (l, _) = get("period_samples")?;
        return Err(DataError::BadMeta {
            file: file.to_string(),
            line: l,
            key: "period_samples".into(),
            reason: format!("{} samples: a period needs at least 2", cfg.period_samples),
        });
    }
    Ok(Some(cfg))
}

/// Writes the `# key=value` lines of the capture CSV contract for `cfg`
/// (the inverse of what [`parse_csv`] reads).
pub fn excitation_comment_lines(cfg: &ExcitationConfig) -> String {
    let kind = match cfg.kind {
        SignalKind::SpecialOddMultisine => "special_odd_multisine",
        SignalKind::RandomOddMultisine => "random_odd_multisine",
        SignalKind::BandLimitedNoise => "band_limited_noise",
    };
    format!(
        "# kind={kind}\n# fs_hz={}\n# period_samples={}\n# max_line={}\n# cutoff_hz={}\n# rms_rad={}\n# seed={}\n# ramp_samples={}\n# periods={}\n",
        cfg.fs_hz,
        cfg.period_samples,
        cfg.max_line,
        cfg.cutoff_hz,
        cfg.rms_rad,
        cfg.seed,
        cfg.ramp_samples,
        cfg.periods
    )
}

/// The `# key=value` comment lines of a capture CSV ([`write_capture_csv`]): the
/// excitation's, the sample interval `ts` \[s\], then `meta` (keys with `=` and values with
/// a newline left out).
pub fn capture_csv_comments(
    excitation: Option<&ExcitationConfig>,
    ts: f64,
    meta: &std::collections::BTreeMap<String, String>,
) -> String {
    let mut comments = excitation.map(excitation_comment_lines).unwrap_or_default();
    comments.push_str(&format!("# sample_interval_s={ts}\n"));
    for (k, v) in meta {
        if k != "sample_interval_s" && !k.contains('=') && !v.contains('\n') {
            comments.push_str(&format!("# {k}={v}\n"));
        }
    }
    comments
}

/// Writes `ds` as a capture CSV: the excitation keys (when known),
/// `sample_interval_s`, every other meta key, the header
/// `t,theta_ref,u,theta_m` and one row per sample, numbers in shortest
/// round-trip form, so [`parse_csv`] reads back exactly the same data. The
/// rows are written by [`write_table`], the one capture CSV row writer.
///
/// # Errors
/// [`std::io::ErrorKind::InvalidInput`] when the dataset has no reference
/// (the capture header needs `theta_ref`), or a write error.
pub fn write_capture_csv(out: &mut dyn std::io::Write, ds: &Dataset) -> std::io::Result<()> {
    let r = ds.data.r.as_ref().ok_or_else(|| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("{}: no reference signal for the theta_ref column", ds.name),
        )
    })?;
    let comments = capture_csv_comments(ds.excitation.as_ref(), ds.data.ts, &ds.meta);
    let rows = r
        .iter()
        .zip(&ds.data.u)
        .zip(&ds.data.y)
        .enumerate()
        .map(|(k, ((&rk, &uk), &yk))| [ds.t0 + k as f64 * ds.data.ts, rk, uk, yk]);
    write_table(out, &comments, rows)
}

/// Writes a capture CSV from its parts: `comments` verbatim (whole `# key=value` lines),
/// the header `t,theta_ref,u,theta_m`, then one row per `[t [s], θref [rad], u [N·m],
/// θm [rad]]`, each number in its shortest form that reads back to the same `f64`
/// written in 64 KiB blocks; flushes `out` at the end. The one writer of capture CSV
/// rows ([`write_capture_csv`] and `capture::export::write_csv` call it).
///
/// # Errors
/// Whatever `out` returns; [`io::ErrorKind::InvalidData`] naming the row and the column
/// of the first value that is not finite (NaN or infinite is never written as data; the
/// rows before it may have been written).
pub fn write_table<W: Write + ?Sized>(
    out: &mut W,
    comments: &str,
    rows: impl IntoIterator<Item = [f64; 4]>,
) -> io::Result<()> {
    let mut table = TableWriter::new(out, comments)?;
    for row in rows {
        table.row(row)?;
    }
    table.finish()
}

/// Bytes of rows [`TableWriter`] collects before it hands them on [bytes]: as large as the
/// 64 KiB buffer of [`crate::data::output`]'s writer, so that a `BufWriter` of that size
/// passes each block straight to the file instead of copying it into its buffer first.
const TABLE_BLOCK: usize = 1 << 16;

/// The row writer of [`write_table`], one row at a time (for rows produced as they are
/// written, e.g. a streamed simulation): the same bytes, the same refusal of a value that
/// is not finite.
pub struct TableWriter<'w, W: Write + ?Sized> {
    out: &'w mut W,
    fmt: zmij::Buffer,
    block: Vec<u8>,
    rows: usize,
}

impl<'w, W: Write + ?Sized> TableWriter<'w, W> {
    /// Writes `comments` and the header line.
    ///
    /// # Errors
    /// Whatever `out` returns.
    pub fn new(out: &'w mut W, comments: &str) -> io::Result<Self> {
        out.write_all(comments.as_bytes())?;
        if !comments.is_empty() && !comments.ends_with('\n') {
            out.write_all(b"\n")?;
        }
        out.write_all(b"t,theta_ref,u,theta_m\n")?;
        Ok(TableWriter {
            out,
            fmt: zmij::Buffer::new(),
            block: Vec::with_capacity(TABLE_BLOCK + 256),
            rows: 0,
        })
    }

    /// One row `[t [s], θref [rad], u [N·m], θm [rad]]`.
    ///
    /// # Errors
    /// [`io::ErrorKind::InvalidData`] naming the row and the column of a value that is not
    /// finite; whatever `out` returns.
    pub fn row(&mut self, row: [f64; 4]) -> io::Result<()> {
        const COLUMNS: [&str; 4] = ["t", "theta_ref", "u", "theta_m"];
        let k = self.rows;
        for (i, v) in row.into_iter().enumerate() {
            if !v.is_finite() {
                return Err(io::Error::new(
                    io::ErrorKind::InvalidData,
                    format!(
                        "data row {} (sample {k}): {} = {v} is not a finite number; not written",
                        k + 1,
                        COLUMNS[i]
                    ),
                ));
            }
            if i > 0 {
                self.block.push(b',');
            }
            // finite: checked above
            self.block
                .extend_from_slice(self.fmt.format_finite(v).as_bytes());
        }
        self.block.push(b'\n');
        self.rows += 1;
        if self.block.len() >= TABLE_BLOCK {
            self.out.write_all(&self.block)?;
            self.block.clear();
        }
        Ok(())
    }

    /// Writes what is buffered and flushes `out`.
    ///
    /// # Errors
    /// Whatever `out` returns.
    pub fn finish(self) -> io::Result<()> {
        self.out.write_all(&self.block)?;
        self.out.flush()
    }
}

/// Reads a CSV file as one uniformly sampled record (see [`parse_csv`]).
///
/// # Errors
/// [`DataError::Io`] when the file cannot be read, else as [`parse_csv`].
pub fn load_csv(path: &Path, map: &ColumnMap) -> Result<Dataset, DataError> {
    let name = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|source| DataError::Io {
        file: name.clone(),
        source,
    })?;
    parse_csv(&text, &name, map)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::PeriodLayout;

    fn capture_text(extra_meta: &str, rows: &str) -> String {
        format!("{extra_meta}t,theta_ref,u,theta_m\n{rows}")
    }

    fn cfg() -> ExcitationConfig {
        ExcitationConfig {
            kind: SignalKind::SpecialOddMultisine,
            fs_hz: 1000,
            period_samples: 4,
            max_line: 1,
            cutoff_hz: 50.0,
            rms_rad: 0.01,
            seed: 7,
            ramp_samples: 2,
            periods: 3,
        }
    }

    #[test]
    fn period_samples_is_checked_against_the_record_naming_its_line() {
        let rows: String = (0..10)
            .map(|k| format!("{},0,1,2\n", k as f64 * 1e-3))
            .collect();
        let with = |period: &str| {
            capture_text(
                &excitation_comment_lines(&cfg())
                    .replace("# period_samples=4", &format!("# period_samples={period}")),
                &rows,
            )
        };
        // the comment lines: kind, fs_hz, period_samples (line 3)
        for (period, reason) in [
            ("0", "0 samples: a period needs at least 2"),
            ("11", "11 samples is longer than the record (10 rows)"),
            ("50000", "50000 samples is longer than the record (10 rows)"),
        ] {
            let e = parse_csv(&with(period), "p.csv", &ColumnMap::capture()).unwrap_err();
            assert_eq!(
                e.to_string(),
                format!("p.csv:3: `period_samples`: {reason}"),
                "{period}"
            );
        }
        // a period that fits is accepted
        let ds = parse_csv(&with("10"), "p.csv", &ColumnMap::capture()).unwrap();
        assert_eq!(ds.excitation.unwrap().period_samples, 10);
    }

    #[test]
    fn a_period_that_the_data_do_not_repeat_over_is_refused() {
        // 5 periods of 40 samples after a ramp of 2: the reference repeats exactly, the
        // measured columns to within a little noise
        let n = 40;
        // a deterministic scramble in [−0.5, 0.5) as the noise
        let noise = |k: usize, m: usize| ((k * 7919 + m * 104_729) % 1009) as f64 / 1009.0 - 0.5;
        let rows: String = (0..2 + 5 * n)
            .map(|k| {
                let ph = 2.0 * std::f64::consts::PI * k as f64 / n as f64;
                let r = ph.sin() + 0.3 * (3.0 * ph).sin();
                let u = 2.0 * (ph + 0.4).sin() + 0.3 * noise(k, 1);
                let y = 0.9 * r + 0.05 * noise(k, 2);
                format!("{},{r},{u},{y}\n", k as f64 * 1e-3)
            })
            .collect();
        let with = |period: usize| {
            let c = ExcitationConfig {
                period_samples: period as u32,
                periods: 5,
                ..cfg()
            };
            capture_text(&excitation_comment_lines(&c), &rows)
        };
        let ds = parse_csv(&with(n), "p.csv", &ColumnMap::capture()).unwrap();
        assert_eq!(ds.excitation.unwrap().period_samples, 40);
        // one sample off: the reference tells
        let e = parse_csv(&with(n - 1), "p.csv", &ColumnMap::capture()).unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.starts_with("p.csv:3: `period_samples`: 39 samples is not the data's period")
                && msg.ends_with("in the reference column"),
            "{msg}"
        );
        // without a reference column the measured ones judge: the right period passes,
        // a wrong one is refused
        let map = ColumnMap {
            reference: None,
            ..ColumnMap::capture()
        };
        assert!(parse_csv(&with(n), "p.csv", &map).is_ok());
        let e = parse_csv(&with(n * 5 / 4), "p.csv", &map).unwrap_err();
        assert!(
            e.to_string()
                .contains("50 samples is not the data's period")
                && e.to_string().ends_with("in both measured columns"),
            "{e}"
        );
    }

    #[test]
    fn parse_csv_reads_capture_header_and_excitation_keys() {
        let mut rows = String::new();
        for k in 0..20 {
            rows.push_str(&format!(
                "{},{},{},{},9\n",
                k as f64 * 0.001,
                k,
                2 * k,
                3 * k
            ));
        }
        let text = format!(
            "# sample_interval_s=0.001\n# board=nucleo\n{}t,theta_ref,u,theta_m,extra\n{rows}",
            excitation_comment_lines(&cfg())
        );
        let ds = parse_csv(&text, "cap.csv", &ColumnMap::capture()).unwrap();
        assert_eq!(ds.excitation, Some(cfg()));
        assert_eq!(ds.meta.get("board").map(String::as_str), Some("nucleo"));
        assert!(!ds.meta.contains_key("kind"));
        assert_eq!(ds.data.len(), 20);
        assert_eq!(ds.data.u[3], 6.0);
        assert_eq!(ds.data.y[3], 9.0);
        assert_eq!(ds.data.r.as_ref().unwrap()[3], 3.0);
        assert!((ds.data.ts - 0.001).abs() < 1e-15);
        let lay = ds.period_layout(1).unwrap();
        // ramp 2 + one settling period of 4, then 2 periods (3 - 1), not 4
        assert_eq!(
            lay,
            PeriodLayout {
                period: 4,
                start: 6,
                count: 2
            }
        );
    }

    #[test]
    fn write_capture_csv_round_trips_through_parse_csv() {
        let ds = Dataset {
            name: "rt".into(),
            data: IdData {
                ts: 0.001,
                u: (0..40).map(|k| (k as f64 * 0.37).sin() * 1e-3).collect(),
                y: (0..40).map(|k| (k as f64 * 0.11).cos() / 3.0).collect(),
                r: Some((0..40).map(|k| k as f64 / 7.0).collect()),
            },
            t0: 0.0,
            excitation: Some(cfg()),
            meta: [("board".to_string(), "sim".to_string())]
                .into_iter()
                .collect(),
        };
        let mut buf = Vec::new();
        write_capture_csv(&mut buf, &ds).unwrap();
        let back = parse_csv(
            std::str::from_utf8(&buf).unwrap(),
            "rt",
            &ColumnMap::capture(),
        )
        .unwrap();
        assert_eq!(back.data, ds.data);
        assert_eq!(back.excitation, ds.excitation);
        assert_eq!(back.meta.get("board").map(String::as_str), Some("sim"));
        let mut no_ref = ds.clone();
        no_ref.data.r = None;
        assert!(write_capture_csv(&mut Vec::new(), &no_ref).is_err());
    }

    #[test]
    fn parse_csv_errors_name_file_line_and_column() {
        let bad = capture_text("", "0,0,0,0\n0.001,0,abc,0\n");
        let e = parse_csv(&bad, "a.csv", &ColumnMap::capture()).unwrap_err();
        assert_eq!(e.to_string(), "a.csv:3: column `u`: `abc` is not a number");

        let nan = capture_text("# x=1\n", "0,0,0,0\n0.001,0,0,NaN\n");
        let e = parse_csv(&nan, "b.csv", &ColumnMap::capture()).unwrap_err();
        assert_eq!(
            e.to_string(),
            "b.csv:4: column `theta_m`: value `NaN` is not finite"
        );

        let inf = capture_text("", "0,inf,0,0\n0.001,0,0,0\n");
        let e = parse_csv(&inf, "b.csv", &ColumnMap::capture()).unwrap_err();
        assert!(
            e.to_string().starts_with("b.csv:2: column `theta_ref`"),
            "{e}"
        );

        let short = capture_text("", "0,0,0,0\n0.001,0,0\n");
        let e = parse_csv(&short, "c.csv", &ColumnMap::capture()).unwrap_err();
        assert_eq!(
            e.to_string(),
            "c.csv:3: column `theta_m` missing (row has 3 cells)"
        );

        let map = ColumnMap {
            time: "t_s".into(),
            input: "force".into(),
            output: "q".into(),
            reference: None,
            delimiter: None,
        };
        let e = parse_csv("t_s,force_N,q\n0,1,2\n", "d.csv", &map).unwrap_err();
        assert_eq!(
            e.to_string(),
            "d.csv:1: column `force` not in header (have: t_s,force_N,q)"
        );

        let partial = capture_text("# kind=special_odd_multisine\n# fs_hz=1000\n", "0,0,0,0\n");
        let e = parse_csv(&partial, "e.csv", &ColumnMap::capture()).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("e.csv:1: `period_samples`: missing"),
            "{e}"
        );

        let badkind = format!(
            "{}t,theta_ref,u,theta_m\n0,0,0,0\n0.001,0,0,0\n",
            excitation_comment_lines(&cfg()).replace("special_odd_multisine", "chirp")
        );
        let e = parse_csv(&badkind, "f.csv", &ColumnMap::capture()).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("f.csv:1: `kind`: unknown kind `chirp`"),
            "{e}"
        );
    }

    #[test]
    fn parse_csv_rejects_non_uniform_and_non_monotonic_time() {
        let gap = capture_text(
            "",
            "0,0,0,0\n0.001,0,0,0\n0.002,0,0,0\n0.004,0,0,0\n0.005,0,0,0\n",
        );
        // a jump by whole intervals is a gap: one record is refused naming its line,
        // the record reads as two pieces
        let e = parse_csv(&gap, "g.csv", &ColumnMap::capture()).unwrap_err();
        assert!(matches!(e, DataError::TimeGap { line: 5, .. }), "{e}");
        assert_eq!(
            e.to_string(),
            "g.csv:5: gap: time jumps 0.002 s -> 0.004 s, 1 samples missing"
        );
        let rec = parse_csv_record(&gap, "g.csv", &ColumnMap::capture()).unwrap();
        assert_eq!(rec.pieces.len(), 2);
        assert_eq!((rec.pieces[0].data.len(), rec.pieces[1].data.len()), (3, 2));
        assert_eq!(rec.pieces[1].t0, 0.004);
        // a jump that is no whole number of intervals is non-uniform sampling
        let odd = capture_text(
            "",
            "0,0,0,0\n0.001,0,0,0\n0.002,0,0,0\n0.0035,0,0,0\n0.0045,0,0,0\n0.0055,0,0,0\n",
        );
        let e = parse_csv(&odd, "g.csv", &ColumnMap::capture()).unwrap_err();
        assert!(matches!(e, DataError::NonUniform { line: 5, .. }), "{e}");
        assert!(
            e.to_string()
                .starts_with("g.csv:5: non-uniform sampling: interval 0.002 s -> 0.0035 s"),
            "{e}"
        );

        let back = capture_text("", "0,0,0,0\n0.001,0,0,0\n0.0005,0,0,0\n");
        let e = parse_csv(&back, "h.csv", &ColumnMap::capture()).unwrap_err();
        assert_eq!(
            e.to_string(),
            "h.csv:4: time not increasing: 0.001 s -> 0.0005 s"
        );

        // a 2 % jitter on one interval is caught even with a stated interval
        let jit = capture_text(
            "# sample_interval_s=0.001\n",
            "0,0,0,0\n0.001,0,0,0\n0.00202,0,0,0\n0.003,0,0,0\n",
        );
        let e = parse_csv(&jit, "j.csv", &ColumnMap::capture()).unwrap_err();
        assert!(matches!(e, DataError::NonUniform { line: 5, .. }), "{e}");
    }

    #[test]
    fn parse_csv_accepts_bom_crlf_and_quoted_header() {
        let text = "\u{feff}\"t\", \"theta_ref\",u,theta_m\r\n0,1,2,3\r\n0.5,1,2,3\r\n";
        let ds = parse_csv(text, "w.csv", &ColumnMap::capture()).unwrap();
        assert_eq!(ds.data.len(), 2);
        assert_eq!(ds.data.y, vec![3.0, 3.0]);
    }

    #[test]
    fn fs_hz_disagreeing_with_time_column_is_an_error() {
        let text = format!(
            "{}t,theta_ref,u,theta_m\n0,0,0,0\n0.002,0,0,0\n0.004,0,0,0\n",
            excitation_comment_lines(&cfg())
        );
        let e = parse_csv(&text, "k.csv", &ColumnMap::capture()).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("k.csv:2: `fs_hz`: 1000 Hz disagrees"),
            "{e}"
        );
    }

    #[test]
    fn a_sample_interval_the_time_column_contradicts_is_named_with_both_rates() {
        // a header of 2 kHz over a time column at 1 kHz (and at 4 kHz): before, a gap
        // after every sample (or a non-uniform step at the first row)
        let rows = |dt: f64| -> String {
            (0..40)
                .map(|k| format!("{},0,{k},0\n", k as f64 * dt))
                .collect()
        };
        for (dt, hz) in [(1e-3, "1000"), (2.5e-4, "4000")] {
            let text = capture_text("# rig=b\n# sample_interval_s=0.0005\n", &rows(dt));
            let e = parse_csv_record(&text, "k.csv", &ColumnMap::capture()).unwrap_err();
            assert!(matches!(e, DataError::RateContradiction { .. }), "{e}");
            assert_eq!(
                e.to_string(),
                format!(
                    "k.csv:2: the comments give a sample interval of 0.0005 s (2000 Hz), but \
                     the time column's samples are {dt} s apart ({hz} Hz, the median of its 39 \
                     intervals): one of them is wrong; correct `sample_interval_s` or the time \
                     column"
                )
            );
        }
        // the stated rate with a gap after every other sample: what `gaps` lists is read
        let every_other: String = (0..40)
            .map(|k| format!("{},0,{k},0\n", (2 * k) as f64 * 5e-4))
            .collect();
        let gaps: Vec<String> = (0..39).map(|k| format!("{0}..{0}", 2 * k + 1)).collect();
        let listed = format!("# sample_interval_s=0.0005\n# gaps={}\n", gaps.join(";"));
        let r = parse_csv_record(
            &capture_text(&listed, &every_other),
            "k.csv",
            &ColumnMap::capture(),
        )
        .unwrap();
        assert_eq!((r.pieces.len(), r.pieces[0].data.ts), (40, 5e-4));
        // gaps that do not account for them: the contradiction
        let short = format!(
            "# sample_interval_s=0.0005\n# gaps={}\n",
            gaps[..5].join(";")
        );
        let e = parse_csv_record(
            &capture_text(&short, &every_other),
            "k.csv",
            &ColumnMap::capture(),
        )
        .unwrap_err();
        assert!(matches!(e, DataError::RateContradiction { .. }), "{e}");
        // the stated rate over its time column, with a gap: read
        let ok: String = rows(5e-4)
            .lines()
            .enumerate()
            .filter(|(k, _)| *k != 3)
            .map(|(_, l)| format!("{l}\n"))
            .collect();
        let text = capture_text("# sample_interval_s=0.0005\n", &ok);
        let r = parse_csv_record(&text, "k.csv", &ColumnMap::capture()).unwrap();
        assert_eq!(r.pieces.len(), 2);
    }

    use crate::test_support::shared_data as shared;

    #[test]
    fn load_csv_reads_emps_and_daisy_with_column_mapping() {
        let map = ColumnMap {
            time: "t_s".into(),
            input: "force_N".into(),
            output: "qm_m".into(),
            reference: None,
            delimiter: None,
        };
        let ds = load_csv(&shared("emps/emps_train_DATA_EMPS.csv"), &map).unwrap();
        assert_eq!(ds.data.len(), 24_841);
        assert!((ds.data.ts - 1e-3).abs() < 1e-7, "{}", ds.data.ts);
        assert!(ds.excitation.is_none() && ds.data.r.is_none());
        let map = ColumnMap {
            time: "t_assumed_s".into(),
            input: "u_reaction_torque".into(),
            output: "y_arm_acceleration".into(),
            reference: None,
            delimiter: None,
        };
        let ds = load_csv(&shared("daisy-robot-arm/robot_arm.csv"), &map).unwrap();
        assert_eq!(ds.data.len(), 1024);
        assert!((ds.data.ts - 0.01).abs() < 1e-12);
        assert_eq!(ds.data.u[0], 0.22183165);
        assert_eq!(ds.data.y[1], -0.11470789);
    }

    #[test]
    fn header_columns_lists_the_header_and_counts_the_rows_as_the_reader_splits_them() {
        let text = "# kind=x\n\ntime;force;\"pos\"\n0;1;2\n# late comment\n1;2;3\n\n";
        assert_eq!(
            header_columns(text, None),
            Some((vec!["time".into(), "force".into(), "pos".into()], 2))
        );
        assert_eq!(
            header_columns("a,b\n", Some(';')),
            Some((vec!["a,b".into()], 0))
        );
        assert_eq!(header_columns("# only\n\n", None), None);
    }

    #[test]
    fn write_table_refuses_a_value_that_is_not_finite_naming_row_and_column() {
        let mut out = Vec::new();
        write_table(&mut out, "", [[0.0, 1.0, 2.0, 3.0]]).unwrap();
        assert_eq!(
            String::from_utf8(out).unwrap(),
            "t,theta_ref,u,theta_m\n0.0,1.0,2.0,3.0\n"
        );
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let mut out = Vec::new();
            let err = write_table(&mut out, "", [[0.0, 1.0, 2.0, 3.0], [0.1, 1.0, 2.0, bad]])
                .unwrap_err();
            assert_eq!(err.kind(), std::io::ErrorKind::InvalidData);
            assert_eq!(
                err.to_string(),
                format!(
                    "data row 2 (sample 1): theta_m = {bad} is not a finite number; not written"
                )
            );
            assert!(!String::from_utf8(out).unwrap().contains(&bad.to_string()));
        }
    }
}
