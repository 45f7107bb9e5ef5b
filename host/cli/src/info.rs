//! `jointid info FILE [--json]`: what a capture or a data file holds.
//!
//! A `.jcap` capture: board, session, sample rate, excitation, scale, then the report:
//! samples, gaps, damaged frames with byte offsets, board counters, link events.
//! `--json` prints one object with the same report fields as `capture --json`, plus
//! `file` and `header` (null when no session header arrived). Works on a capture without a
//! header and on one whose excitation cannot be regenerated (the reference check is then
//! skipped).
//!
//! Any other input the analysis commands read (a capture CSV, a CSV or MAT-file with a
//! column mapping, `-` standard input): its format, its columns (a CSV's header, a
//! MAT-file's variables), the columns read, samples, rate, gaps and gap-free segments, the
//! excitation and other `# key=value` comments, and the reader's notes (`--json`: the
//! document `info-data`). A CSV or MAT-file without the capture columns and without
//! `--time/--input/--output` is described by its columns alone, with the flags that read
//! it.
//!
//! Exit status: 0, 1 with `--strict` when anything is missing or damaged, 2 error.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use jointid_core::wire::SessionHeader;
use serde::Serialize;

use super::args::{ColumnArgs, DelimiterArg};
use super::{print_json, CmdResult, Context, Outcome};
use jointid::capture::export::kind_name;
use jointid::capture::{
    jcap_session_reports, read_jcap_session_reports, segments_of, CaptureReport,
};
use jointid::data::input::{input_name, is_stdin, read_input};
use jointid::data::output::io_msg;
use jointid::data::{
    csv::header_columns, fmt_sig, mat, matlab_kind, ColumnMap, ExcitationConfig, Input, Record,
    SegmentInfo, JCAP_MAGIC_PREFIX, MATLAB_V5,
};

/// Arguments of `jointid info`.
#[derive(Clone, Debug, clap::Args)]
pub struct InfoArgs {
    /// Capture or data file: a .jcap capture, a capture CSV, any CSV or MAT-file (its
    /// samples with --time/--input/--output), `-` for standard input
    #[arg(value_name = "FILE")]
    pub file: PathBuf,
    /// Report only this session of a .jcap capture, by its id (default: every session, the
    /// first one on top)
    #[arg(long, value_name = "K")]
    pub session: Option<u32>,
    /// Exit with status 1 when anything is missing or damaged
    #[arg(long)]
    pub strict: bool,
    /// the columns of a data file that is no capture
    #[command(flatten)]
    pub columns: ColumnArgs,
    /// how a CSV's columns are split
    #[command(flatten)]
    pub csv: DelimiterArg,
    /// no progress line on standard error (shown only when it is a terminal, for reading
    /// a file that lasts over 2 s)
    #[arg(long, short)]
    pub quiet: bool,
}

/// One session of `info --json`'s `per_session`.
#[derive(Debug, Serialize)]
pub struct SessionInfo {
    /// the session's header (null when no session header arrived)
    pub header: Option<SessionHeader>,
    /// the session's report
    #[serde(flatten)]
    pub report: CaptureReport,
    /// the session's gap-free segments (what `--segment N` of the analysis commands picks)
    pub segments: Vec<SegmentInfo>,
}

/// What `info --json` prints.
#[derive(Debug, Serialize)]
pub struct InfoSummary {
    /// the capture file
    pub file: String,
    /// the reported session's header
    pub header: Option<SessionHeader>,
    /// the report
    #[serde(flatten)]
    pub report: CaptureReport,
    /// the reported session's gap-free segments
    pub segments: Vec<SegmentInfo>,
    /// every session (or the one asked for), in stream order, each with its own report
    pub per_session: Vec<SessionInfo>,
}

/// Runs `jointid info`: [`Outcome::CheckFailed`] with `--strict` when anything is
/// missing or damaged.
///
/// # Errors
/// The file cannot be read, is a damaged jcap file ([`jointid::capture::CaptureError`])
/// or data the loaders refuse ([`jointid::data::DataError`]); `--session` on a file that
/// is no capture; output errors.
pub fn run(args: &InfoArgs, ctx: &mut Context<'_>) -> CmdResult {
    let stdin = is_stdin(&args.file);
    let name = input_name(&args.file);
    // reading a large file takes seconds (a 532 MB CSV: 3 s): said on a terminal
    super::progress::start(args.quiet);
    let size = std::fs::metadata(&args.file)
        .ok()
        .filter(|m| m.is_file())
        .map_or_else(String::new, |m| {
            format!(" ({} MB)", jointid::data::fmt_sig(m.len() as f64 / 1e6, 3))
        });
    super::progress::step(format!("reading {name}{size}"));
    if !stdin && !starts_with_magic(&args.file).map_err(|e| format!("{name}: {}", io_msg(&e)))? {
        if let Some(head) = text_head(&args.file).map_err(|e| format!("{name}: {}", io_msg(&e)))? {
            return run_data(args, ctx, &name, head.head.as_bytes(), Some(head.rows));
        }
    }
    let bytes = read_input(&args.file).map_err(|e| format!("{name}: {}", io_msg(&e)))?;
    if !bytes.starts_with(JCAP_MAGIC_PREFIX) {
        return run_data(args, ctx, &name, &bytes, None);
    }
    let mut all = if stdin {
        jcap_session_reports(Path::new(&name), &bytes, args.session)?
    } else {
        read_jcap_session_reports(&args.file, args.session)?
    };
    let clean = all.iter().all(|(r, _)| r.is_clean());
    let segs = |r: &CaptureReport, h: &Option<SessionHeader>| {
        h.as_ref().map_or_else(Vec::new, |h| segments_of(r, h))
    };
    let (report, header) = all.remove(0);
    let segments = segs(&report, &header);
    let mut per_session = vec![SessionInfo {
        header,
        report: report.clone(),
        segments: segments.clone(),
    }];
    per_session.extend(all.into_iter().map(|(report, header)| SessionInfo {
        segments: segs(&report, &header),
        header,
        report,
    }));
    let summary = InfoSummary {
        file: name,
        header,
        report,
        segments,
        per_session,
    };
    super::progress::finish();
    if ctx.json {
        print_json(ctx.out, "info", &summary)?;
    } else {
        write!(ctx.out, "{}", describe(&summary))?;
    }
    Ok(if args.strict && !clean {
        Outcome::CheckFailed
    } else {
        Outcome::Ok
    })
}

/// The human-readable description `info` prints.
pub fn describe(s: &InfoSummary) -> String {
    let mut out = format!("{}\n", s.file);
    if s.per_session.len() > 1 {
        out.push_str(&format!("{} sessions\n", s.per_session.len()));
        for (i, p) in s.per_session.iter().enumerate() {
            let id = p
                .report
                .session_id
                .map_or_else(|| "-".to_string(), |id| id.to_string());
            out.push_str(&format!(
                "\n== session {id} ({} of {})\n",
                i + 1,
                s.per_session.len()
            ));
            describe_session(&mut out, p.header.as_ref(), &p.report, &p.segments);
        }
        return out;
    }
    describe_session(&mut out, s.header.as_ref(), &s.report, &s.segments);
    out
}

fn describe_session(
    out: &mut String,
    header: Option<&SessionHeader>,
    report: &CaptureReport,
    segments: &[SegmentInfo],
) {
    match header {
        None => out.push_str("no session header: counts cannot be scaled to SI\n"),
        Some(h) => {
            let x = &h.excitation;
            let duration =
                report.last_seq.map_or(0.0, |l| f64::from(l) + 1.0) / f64::from(h.sample_rate_hz);
            out.push_str(&format!(
                "board {:#010x}  session {}  protocol {}\n\
                 sampling    {} Hz (timer {} Hz), {duration:.3} s up to the last sample\n\
                 scale       {} N·m/count, {} rad/count\n\
                 excitation  {}\n",
                h.board_id,
                h.session_id,
                h.protocol_version,
                h.sample_rate_hz,
                h.timer_hz,
                h.scale.torque_nm_per_count,
                h.scale.angle_rad_per_count,
                excitation_text(x),
            ));
        }
    }
    out.push_str(&report.to_string());
    if !segments.is_empty() {
        out.push_str(&format!(
            "\nsegments         {} gap-free (--segment N of analyze, fit, validate, diagnose)\n",
            segments.len()
        ));
        segment_lines(out, segments);
    }
    out.push('\n');
}

/// The excitation's parameters on one line.
fn excitation_text(x: &ExcitationConfig) -> String {
    format!(
        "{} fs={} Hz N={} F={} cutoff={} Hz rms={} rad seed={} ramp={} periods={}",
        kind_name(x.kind),
        x.fs_hz,
        x.period_samples,
        x.max_line,
        x.cutoff_hz,
        x.rms_rad,
        x.seed,
        x.ramp_samples,
        x.periods,
    )
}

/// One line per gap-free segment.
fn segment_lines(out: &mut String, segments: &[SegmentInfo]) {
    for g in segments {
        out.push_str(&format!(
            "  {:>3}  from {} s, {} s, {} samples, {}\n",
            g.index,
            fmt_sig(g.start_s, 6),
            fmt_sig(g.length_s, 6),
            g.samples,
            g.whole_periods.map_or_else(
                || "periods unknown".to_string(),
                |p| format!("{p} whole periods")
            )
        ));
    }
}

/// The columns a data file was read with.
#[derive(Debug, Serialize)]
pub struct ColumnsRead {
    /// time column [s]
    pub time: String,
    /// input column
    pub input: String,
    /// output column
    pub output: String,
    /// reference column, if any
    pub reference: Option<String>,
}

/// What `info --json` prints for a file that is no `.jcap` capture (kind `info-data`).
#[derive(Debug, Serialize)]
pub struct DataInfo {
    /// the file read (`standard input` for `-`)
    pub file: String,
    /// `capture CSV`, `CSV` or the MATLAB file's kind
    pub format: String,
    /// the file's columns: a CSV's header, a MAT-file's variables (each with its size)
    pub columns: Vec<String>,
    /// the rows under a CSV's header (null for a MAT-file)
    pub rows: Option<usize>,
    /// the columns read (null: none, the file has no capture columns and no mapping was
    /// given)
    pub read: Option<ColumnsRead>,
    /// samples read (null when nothing was read)
    pub samples: Option<usize>,
    /// sample rate [Hz]
    pub sample_rate_hz: Option<f64>,
    /// from the first sample to the end of the last [s]
    pub duration_s: Option<f64>,
    /// samples missing in the gaps between the segments
    pub missing_samples: Option<u64>,
    /// the excitation from the file's `# key=value` comments
    pub excitation: Option<ExcitationConfig>,
    /// every other `# key=value` comment
    pub comments: BTreeMap<String, String>,
    /// the gap-free segments (what `--segment N` picks)
    pub segments: Vec<SegmentInfo>,
    /// what the reader ignored or guessed, or what reads the file
    pub notes: Vec<String>,
}

/// The capture CSV's columns: time, input, output (the reference beside them when there).
const CAPTURE_COLUMNS: [&str; 3] = ["t", "u", "theta_m"];

/// `info` of a file that is no capture (module documentation).
/// `info` of a file that is no capture: `bytes` the whole file, or (`streamed`: the rows
/// counted) a text file's comments and header only, its samples then read line by line.
fn run_data(
    args: &InfoArgs,
    ctx: &mut Context<'_>,
    name: &str,
    bytes: &[u8],
    streamed: Option<usize>,
) -> CmdResult {
    if let Some(k) = args.session {
        return Err(format!(
            "--session {k}: {name} is no .jcap capture; only a capture has sessions"
        )
        .into());
    }
    let delimiter = args.csv.delimiter;
    let is_mat = matlab_kind(bytes) == Some(MATLAB_V5);
    // the file's own columns, as far as they can be told without reading the samples
    let (columns, rows) = if is_mat {
        let m = mat::read_mat(bytes, name)?;
        let cols = m
            .vars
            .iter()
            .map(|(n, v)| format!("{n} ({})", v.describe()))
            .collect();
        let names: Vec<String> = m.vars.iter().map(|(n, _)| n.clone()).collect();
        (cols, (None, names))
    } else {
        match std::str::from_utf8(bytes)
            .ok()
            .and_then(|t| header_columns(t, delimiter))
        {
            Some((cols, n)) => (cols.clone(), (Some(streamed.unwrap_or(n)), cols)),
            None => (Vec::new(), (None, Vec::new())),
        }
    };
    let (rows, names) = rows;
    let has = |c: &str| names.iter().any(|n| n == c);
    let map = if args.columns.mapped() {
        let c = &args.columns;
        Some(ColumnMap {
            time: c.time.clone().unwrap_or_default(),
            input: c.input.clone().unwrap_or_default(),
            output: c.output.clone().unwrap_or_default(),
            reference: c.reference.clone(),
            delimiter,
        })
    } else if CAPTURE_COLUMNS.iter().all(|c| has(c)) || names.is_empty() {
        // a capture CSV (or what the reader says about a file it cannot split); its
        // reference `theta_ref` unless --reference names another, as the analysis
        // commands read it, none when it has neither
        let mut m = ColumnMap::capture();
        if args.columns.reference.is_some() || (!has("theta_ref") && !names.is_empty()) {
            m.reference = args.columns.reference.clone();
        }
        m.delimiter = delimiter;
        Some(m)
    } else {
        None
    };
    let format = if is_mat {
        MATLAB_V5.to_string()
    } else if !args.columns.mapped() && map.is_some() {
        "capture CSV".to_string()
    } else {
        "CSV".to_string()
    };
    let mut info = DataInfo {
        file: name.to_string(),
        format,
        columns,
        rows,
        read: None,
        samples: None,
        sample_rate_hz: None,
        duration_s: None,
        missing_samples: None,
        excitation: None,
        comments: BTreeMap::new(),
        segments: Vec::new(),
        notes: Vec::new(),
    };
    match &map {
        Some(map) => {
            let record = if streamed.is_some() {
                ctx.loaders.load_record(&args.file, map)?
            } else {
                let input = Input {
                    name,
                    path: (!is_stdin(&args.file)).then_some(args.file.as_path()),
                    bytes,
                };
                ctx.loaders.load_input(&input, map)?
            };
            describe_record(&mut info, &record, map);
        }
        None => info.notes.push(format!(
            "no capture columns ({}): give --time COL --input COL --output COL to read its \
             samples, rate, gaps and segments",
            CAPTURE_COLUMNS.join(", ")
        )),
    }
    let missing = info.missing_samples.unwrap_or(0) > 0;
    super::progress::finish();
    if ctx.json {
        print_json(ctx.out, "info-data", &info)?;
    } else {
        write!(ctx.out, "{}", describe_data(&info))?;
    }
    Ok(if args.strict && missing {
        Outcome::CheckFailed
    } else {
        Outcome::Ok
    })
}

/// Whether the file `path` starts with the `.jcap` magic.
fn starts_with_magic(path: &Path) -> std::io::Result<bool> {
    use std::io::Read;
    let mut head = Vec::new();
    std::fs::File::open(path)?
        .take(JCAP_MAGIC_PREFIX.len() as u64)
        .read_to_end(&mut head)?;
    Ok(head.starts_with(JCAP_MAGIC_PREFIX))
}

/// The start of a text file up to and including its header line, and the count of its
/// rows after it, read line by line (a 532 MB CSV was read whole, 838 MB at the peak):
/// the comments and header are what [`header_columns`] needs, the rows are counted.
/// `None` for a file that is no UTF-8 text or a MATLAB file: those are read whole.
fn text_head(path: &Path) -> std::io::Result<Option<TextHead>> {
    use std::io::{BufRead, Read};
    let mut file = std::fs::File::open(path)?;
    let mut start = Vec::new();
    file.by_ref().take(520).read_to_end(&mut start)?;
    if matlab_kind(&start).is_some() {
        return Ok(None);
    }
    let mut reader = std::io::BufReader::new(std::io::Cursor::new(start).chain(file));
    let (mut head, mut rows, mut header) = (String::new(), 0usize, false);
    let mut line = Vec::new();
    loop {
        line.clear();
        if reader.read_until(b'\n', &mut line)? == 0 {
            break;
        }
        let Ok(text) = std::str::from_utf8(&line) else {
            return Ok(None);
        };
        let t = text.trim();
        if header {
            rows += usize::from(!t.is_empty() && !t.starts_with('#'));
        } else {
            head.push_str(text);
            header = !t.is_empty() && !t.trim_start_matches('\u{feff}').starts_with('#');
        }
    }
    Ok(Some(TextHead { head, rows }))
}

/// A text file's comments and header line, and how many rows follow ([`text_head`]).
struct TextHead {
    head: String,
    rows: usize,
}

/// The figures of a record read with `map` into `info`.
fn describe_record(info: &mut DataInfo, record: &Record, map: &ColumnMap) {
    let first = &record.pieces[0];
    let last = &record.pieces[record.pieces.len() - 1];
    let ts = first.data.ts;
    info.read = Some(ColumnsRead {
        time: map.time.clone(),
        input: map.input.clone(),
        output: map.output.clone(),
        reference: map.reference.clone(),
    });
    info.samples = Some(record.pieces.iter().map(|p| p.data.len()).sum());
    info.sample_rate_hz = Some(1.0 / ts);
    info.duration_s = Some(last.t0 + last.data.len() as f64 * ts - first.t0);
    info.missing_samples = Some(record.missing_samples());
    info.excitation = first.excitation;
    info.comments = first.meta.clone();
    info.segments = record.segments();
    info.notes = record.notes.clone();
}

/// The text `info` prints for a file that is no capture.
fn describe_data(d: &DataInfo) -> String {
    let mut out = format!("{}\nformat      {}\n", d.file, d.format);
    if !d.columns.is_empty() {
        out.push_str(&format!("columns     {}\n", d.columns.join(", ")));
    }
    if let Some(r) = &d.read {
        out.push_str(&format!(
            "read        time {}, input {}, output {}, reference {}\n",
            r.time,
            r.input,
            r.output,
            r.reference.as_deref().unwrap_or("none")
        ));
    }
    match (d.samples, d.sample_rate_hz, d.duration_s) {
        (Some(n), Some(fs), Some(t)) => out.push_str(&format!(
            "samples     {n} at {} Hz (Ts = {} s), {} s{}\n",
            fmt_sig(fs, 6),
            fmt_sig(1.0 / fs, 4),
            fmt_sig(t, 6),
            match d.missing_samples {
                Some(0) | None => String::new(),
                Some(m) => format!(
                    " with {} gap(s), {m} samples missing",
                    d.segments.len().saturating_sub(1)
                ),
            }
        )),
        _ => {
            if let Some(r) = d.rows {
                out.push_str(&format!("rows        {r}\n"));
            }
        }
    }
    if d.read.is_some() {
        out.push_str(&format!(
            "excitation  {}\n",
            d.excitation.as_ref().map_or_else(
                || "not stated (no `# kind=...` comments)".to_string(),
                |x| format!("{} (from the file's comments)", excitation_text(x))
            )
        ));
    }
    if !d.comments.is_empty() {
        out.push_str(&format!(
            "comments    {}\n",
            d.comments
                .iter()
                .map(|(k, v)| format!("{k}={v}"))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    if !d.segments.is_empty() {
        out.push_str(&format!(
            "segments    {} gap-free (--segment N of analyze, fit, validate, diagnose)\n",
            d.segments.len()
        ));
        segment_lines(&mut out, &d.segments);
    }
    for n in &d.notes {
        out.push_str(&format!("note: {n}\n"));
    }
    out
}
