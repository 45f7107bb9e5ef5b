//! Identification data: one input, one output, uniformly sampled; loading and
//! preparation.
//!
//! What: read the capture CSV of DESIGN.md §5 (and any CSV with a column
//! mapping), check that sampling is uniform, and prepare the record for the
//! estimators: detrending, integer decimation with an anti-alias filter,
//! dropping the transient and cutting whole excitation periods, and the
//! estimation/validation split.
//!
//! Why: every estimator takes one [`IdData`] and does no IO; this module is
//! the only place that turns files into `IdData`.
//!
//! Source: seed 000 (Norrlöf et al.), §3 (periodic special odd multisine,
//! transient periods dropped before averaging) and §6 (2 kHz data decimated
//! by 10 before identification).
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
//!
//! The nine excitation keys come as a group: when `kind` is present all nine
//! must be, and they are parsed into an [`ExcitationConfig`]. Any other key is
//! kept verbatim in [`Dataset::meta`]. The sample `k = 0` of the file is the
//! first sample of the ramp-in (the excitation's first sample).
//! After the comments comes the header `t,theta_ref,u,theta_m` (extra
//! columns are allowed and ignored), then one row per sample.
// Units in brackets (`[s]`, `[Hz]`, `[dB]`) are not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;

pub use jointid_core::excitation::{ExcitationConfig, SignalKind};

/// Input/output record of one experiment, uniformly sampled.
#[derive(Clone, Debug, PartialEq)]
pub struct IdData {
    /// sample interval [s]
    pub ts: f64,
    /// input: motor torque reference `u` [N·m] (or force [N] for a linear axis)
    pub u: Vec<f64>,
    /// output: motor angle `theta_m` [rad] (or position [m])
    pub y: Vec<f64>,
    /// excitation reference `theta_ref` [rad], when recorded or regenerated
    pub r: Option<Vec<f64>>,
}

impl IdData {
    /// number of samples
    pub fn len(&self) -> usize {
        self.u.len()
    }

    /// true when the record holds no sample
    pub fn is_empty(&self) -> bool {
        self.u.is_empty()
    }

    /// samples `range` of every signal, same sample interval
    pub fn slice(&self, range: std::ops::Range<usize>) -> IdData {
        IdData {
            ts: self.ts,
            u: self.u[range.clone()].to_vec(),
            y: self.y[range.clone()].to_vec(),
            r: self.r.as_ref().map(|r| r[range].to_vec()),
        }
    }

    /// estimation / validation split: the first `fraction` of the samples
    /// (rounded down) and the rest
    pub fn split(&self, fraction: f64) -> (IdData, IdData) {
        let k = ((self.len() as f64) * fraction.clamp(0.0, 1.0)).floor() as usize;
        (self.slice(0..k), self.slice(k..self.len()))
    }

    /// removes the mean or the least-squares line from `u`, `y` and `r`
    pub fn detrend(&mut self, how: Detrend) {
        detrend(&mut self.u, how);
        detrend(&mut self.y, how);
        if let Some(r) = self.r.as_mut() {
            detrend(r, how);
        }
    }

    /// decimates every signal by `q` with the anti-alias filter of
    /// [`decimate`]; the sample interval becomes `q * ts`
    ///
    /// # Errors
    /// [`DataError::Decimation`] when `q` is 0 or the record is shorter than
    /// the filter.
    pub fn decimate(&self, q: usize) -> Result<IdData, DataError> {
        Ok(IdData {
            ts: self.ts * q as f64,
            u: decimate(&self.u, q)?,
            y: decimate(&self.y, q)?,
            r: self.r.as_ref().map(|r| decimate(r, q)).transpose()?,
        })
    }
}

/// How [`detrend`] removes the trend.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Detrend {
    /// subtract the mean
    Mean,
    /// subtract the least-squares straight line
    Linear,
}

/// Removes the mean or the least-squares line from `x` in place.
pub fn detrend(x: &mut [f64], how: Detrend) {
    let n = x.len();
    if n == 0 {
        return;
    }
    let nf = n as f64;
    let mean = x.iter().sum::<f64>() / nf;
    match how {
        Detrend::Mean => x.iter_mut().for_each(|v| *v -= mean),
        Detrend::Linear => {
            let tm = (nf - 1.0) / 2.0;
            let (mut sxy, mut sxx) = (0.0, 0.0);
            for (k, v) in x.iter().enumerate() {
                let dt = k as f64 - tm;
                sxy += dt * (v - mean);
                sxx += dt * dt;
            }
            let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
            for (k, v) in x.iter_mut().enumerate() {
                *v -= mean + slope * (k as f64 - tm);
            }
        }
    }
}

/// Anti-alias filter taps for decimation by `q`: windowed sinc (Blackman),
/// cut-off at the new Nyquist frequency `0.5/q` (cycles per input sample),
/// `28 q + 1` taps, unit DC gain.
///
/// The transition band `0.4/q … 0.6/q` keeps 80 % of the new band flat (as
/// MATLAB `decimate` does) while every component that would fold into it is
/// at least ~70 dB down.
pub fn decimation_taps(q: usize) -> Vec<f64> {
    let len = 28 * q + 1;
    let m = (len - 1) as f64;
    let fc = 0.5 / q as f64;
    let mut h: Vec<f64> = (0..len)
        .map(|i| {
            let x = i as f64 - m / 2.0;
            let sinc = if x == 0.0 {
                2.0 * fc
            } else {
                (2.0 * std::f64::consts::PI * fc * x).sin() / (std::f64::consts::PI * x)
            };
            let w = 0.42 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / m).cos()
                + 0.08 * (4.0 * std::f64::consts::PI * i as f64 / m).cos();
            sinc * w
        })
        .collect();
    let s: f64 = h.iter().sum();
    h.iter_mut().for_each(|v| *v /= s);
    h
}

/// Integer decimation by `q` with a zero-phase anti-alias filter.
///
/// The symmetric FIR of [`decimation_taps`] is applied centred on each kept
/// sample (no delay, no phase shift); the ends are extended by odd
/// reflection about the end samples, as `filtfilt` does, so a ramp passes
/// undistorted. Output sample `j` is at input sample `j q`.
///
/// # Errors
/// [`DataError::Decimation`] when `q` is 0 or `x` is shorter than the filter.
pub fn decimate(x: &[f64], q: usize) -> Result<Vec<f64>, DataError> {
    if q == 0 {
        return Err(DataError::Decimation("factor must be at least 1".into()));
    }
    if q == 1 {
        return Ok(x.to_vec());
    }
    let h = decimation_taps(q);
    let half = (h.len() - 1) / 2;
    let n = x.len();
    if n <= half + 1 {
        return Err(DataError::Decimation(format!(
            "record of {n} samples is shorter than the {}-tap anti-alias filter",
            h.len()
        )));
    }
    let at = |k: isize| -> f64 {
        if k < 0 {
            2.0 * x[0] - x[(-k) as usize]
        } else if k as usize >= n {
            let over = k as usize - (n - 1);
            2.0 * x[n - 1] - x[n - 1 - over]
        } else {
            x[k as usize]
        }
    };
    Ok((0..n.div_ceil(q))
        .map(|j| {
            let c = (j * q) as isize;
            h.iter()
                .enumerate()
                .map(|(i, hi)| hi * at(c + i as isize - half as isize))
                .sum()
        })
        .collect())
}

/// Which CSV columns hold time, input, output and reference.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ColumnMap {
    /// time column [s]
    pub time: String,
    /// input column (motor torque [N·m] or force [N])
    pub input: String,
    /// output column (motor angle [rad] or position [m])
    pub output: String,
    /// reference column, if any; `None` means no reference
    pub reference: Option<String>,
}

impl ColumnMap {
    /// the capture CSV header `t,theta_ref,u,theta_m` of DESIGN.md §5
    pub fn capture() -> Self {
        ColumnMap {
            time: "t".into(),
            input: "u".into(),
            output: "theta_m".into(),
            reference: Some("theta_ref".into()),
        }
    }
}

impl Default for ColumnMap {
    fn default() -> Self {
        Self::capture()
    }
}

/// A loaded experiment: the data, where it came from, and the excitation
/// that produced it when known.
#[derive(Clone, Debug, PartialEq)]
pub struct Dataset {
    /// source name (file path or a label)
    pub name: String,
    /// the uniformly sampled record
    pub data: IdData,
    /// time of the first sample [s]
    pub t0: f64,
    /// excitation config from the `# key=value` comments, when present
    pub excitation: Option<ExcitationConfig>,
    /// every other `# key=value` comment, verbatim
    pub meta: BTreeMap<String, String>,
}

/// Where the steady-state excitation periods lie in a record.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct PeriodLayout {
    /// period length N [samples]
    pub period: usize,
    /// index of the first sample of the first kept period
    pub start: usize,
    /// number of whole kept periods P
    pub count: usize,
}

impl PeriodLayout {
    /// sample range covered by the kept periods
    pub fn range(&self) -> std::ops::Range<usize> {
        self.start..self.start + self.period * self.count
    }
}

impl Dataset {
    /// Layout of the whole steady-state periods from the excitation config:
    /// skips the ramp-in and `settle_periods` more periods (transient), then
    /// takes every whole period left: at most `periods − settle_periods` when
    /// the run is finite, so the ramp-out is excluded; for an endless run
    /// (`periods = 0`) the last `ramp_samples` samples of the record are left
    /// out, as they may hold a ramp-out.
    ///
    /// # Errors
    /// [`DataError::NoPeriods`] when there is no config or no whole period
    /// remains.
    pub fn period_layout(&self, settle_periods: usize) -> Result<PeriodLayout, DataError> {
        let cfg = self.excitation.ok_or_else(|| DataError::NoPeriods {
            file: self.name.clone(),
            reason: "no excitation config in the file".into(),
        })?;
        let period = cfg.period_samples as usize;
        let start = cfg.ramp_samples as usize + settle_periods * period;
        let count = if cfg.periods > 0 {
            let avail = self.data.len().saturating_sub(start) / period.max(1);
            avail.min((cfg.periods as usize).saturating_sub(settle_periods))
        } else {
            // endless run stopped by the user: its last `ramp_samples` may be
            // the ramp-out, so they are left out
            let end = self.data.len().saturating_sub(cfg.ramp_samples as usize);
            end.saturating_sub(start) / period.max(1)
        };
        if period == 0 || count == 0 {
            return Err(DataError::NoPeriods {
                file: self.name.clone(),
                reason: format!(
                    "{} samples leave no whole period of {period} after {start} transient samples",
                    self.data.len()
                ),
            });
        }
        Ok(PeriodLayout {
            period,
            start,
            count,
        })
    }
}

impl Dataset {
    /// The record restricted to its whole steady-state periods
    /// ([`Dataset::period_layout`]), for estimators that want periodic data
    /// without the transient.
    ///
    /// # Errors
    /// As [`Dataset::period_layout`].
    pub fn steady_data(&self, settle_periods: usize) -> Result<(IdData, PeriodLayout), DataError> {
        let lay = self.period_layout(settle_periods)?;
        Ok((self.data.slice(lay.range()), lay))
    }
}

/// Errors of loading and preparing data.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// the file could not be read
    #[error("{file}: {source}")]
    Io {
        /// file name
        file: String,
        /// underlying error
        source: std::io::Error,
    },
    /// no header line
    #[error("{file}: no header line")]
    NoHeader {
        /// file name
        file: String,
    },
    /// a mapped column is not in the header
    #[error("{file}:{line}: column `{column}` not in header (have: {have})")]
    MissingColumn {
        /// file name
        file: String,
        /// header line (1-based)
        line: usize,
        /// missing column name
        column: String,
        /// the header's columns, comma separated
        have: String,
    },
    /// a row has fewer cells than the mapped columns need
    #[error("{file}:{line}: column `{column}` missing (row has {cells} cells)")]
    ShortRow {
        /// file name
        file: String,
        /// line (1-based)
        line: usize,
        /// column name
        column: String,
        /// cells in the row
        cells: usize,
    },
    /// a cell is not a number
    #[error("{file}:{line}: column `{column}`: `{cell}` is not a number")]
    NotNumeric {
        /// file name
        file: String,
        /// line (1-based)
        line: usize,
        /// column name
        column: String,
        /// the cell text
        cell: String,
    },
    /// a cell is NaN or infinite
    #[error("{file}:{line}: column `{column}`: value `{cell}` is not finite")]
    NotFinite {
        /// file name
        file: String,
        /// line (1-based)
        line: usize,
        /// column name
        column: String,
        /// the cell text
        cell: String,
    },
    /// time does not increase
    #[error("{file}:{line}: time not increasing: {prev} s -> {next} s")]
    NonMonotonic {
        /// file name
        file: String,
        /// line (1-based) of the later sample
        line: usize,
        /// previous time [s]
        prev: f64,
        /// this time [s]
        next: f64,
    },
    /// sample interval departs from the nominal one (gap or jitter)
    #[error("{file}:{line}: non-uniform sampling: interval {prev} s -> {next} s is {dt} s, expected {ts} s")]
    NonUniform {
        /// file name
        file: String,
        /// line (1-based) of the later sample
        line: usize,
        /// previous time [s]
        prev: f64,
        /// this time [s]
        next: f64,
        /// the interval [s]
        dt: f64,
        /// nominal interval [s]
        ts: f64,
    },
    /// too few samples
    #[error("{file}: {rows} data rows, need at least 2")]
    TooShort {
        /// file name
        file: String,
        /// rows found
        rows: usize,
    },
    /// a `# key=value` comment is malformed or inconsistent
    #[error("{file}:{line}: `{key}`: {reason}")]
    BadMeta {
        /// file name
        file: String,
        /// line (1-based)
        line: usize,
        /// key
        key: String,
        /// what is wrong
        reason: String,
    },
    /// no whole excitation period could be found
    #[error("{file}: no whole excitation period: {reason}")]
    NoPeriods {
        /// file name
        file: String,
        /// why
        reason: String,
    },
    /// decimation impossible
    #[error("decimation: {0}")]
    Decimation(String),
    /// no loader for this file extension
    #[error("{file}: no loader for `.{ext}` files (known: {known})")]
    NoLoader {
        /// file name
        file: String,
        /// extension
        ext: String,
        /// registered extensions
        known: String,
    },
    /// a registered loader failed
    #[error("{file}: {source}")]
    Loader {
        /// file name
        file: String,
        /// the loader's error
        source: Box<dyn std::error::Error + Send + Sync>,
    },
}

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

/// Parses a CSV text (capture CSV or any CSV through `map`).
///
/// `name` is used in error messages. Rows are split on `,`; blank lines are
/// skipped; cells are trimmed. The sample interval is
/// `sample_interval_s` when given, else the median interval; every interval
/// must be within [`SAMPLE_INTERVAL_TOLERANCE`] of it.
///
/// # Errors
/// Every [`DataError`] naming `name`, the line and the column at fault.
pub fn parse_csv(text: &str, name: &str, map: &ColumnMap) -> Result<Dataset, DataError> {
    let file = || name.to_string();
    let mut meta: BTreeMap<String, (usize, String)> = BTreeMap::new();
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l));
    let (header_line, header) = loop {
        match lines.next() {
            None => return Err(DataError::NoHeader { file: file() }),
            Some((_, l)) if l.trim().is_empty() => continue,
            Some((ln, l)) if l.trim_start().starts_with('#') => {
                let body = l.trim_start()[1..].trim();
                if let Some((k, v)) = body.split_once('=') {
                    meta.insert(k.trim().to_string(), (ln, v.trim().to_string()));
                }
            }
            Some((ln, l)) => break (ln, l),
        }
    };
    let excitation = parse_excitation(&meta, name)?;
    let cols: Vec<&str> = header
        .split(',')
        .map(|c| c.trim().trim_matches('"').trim())
        .collect();
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
    let mut line_of_row = Vec::new();
    for (ln, l) in lines {
        if l.trim().is_empty() || l.trim_start().starts_with('#') {
            continue;
        }
        let cells: Vec<&str> = l.split(',').collect();
        for (slot, (cname, idx)) in wanted.iter().enumerate() {
            let cell = cells.get(*idx).ok_or_else(|| DataError::ShortRow {
                file: file(),
                line: ln,
                column: cname.to_string(),
                cells: cells.len(),
            })?;
            let cell = cell.trim();
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
        line_of_row.push(ln);
    }
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
                line: line_of_row[k],
                prev: t[k - 1],
                next: t[k],
            });
        }
    }
    let ts = nominal.unwrap_or_else(|| {
        let mut d: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
        d.sort_by(f64::total_cmp);
        d[d.len() / 2]
    });
    for k in 1..rows {
        let dt = t[k] - t[k - 1];
        if (dt - ts).abs() > SAMPLE_INTERVAL_TOLERANCE * ts {
            return Err(DataError::NonUniform {
                file: file(),
                line: line_of_row[k],
                prev: t[k - 1],
                next: t[k],
                dt,
                ts,
            });
        }
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
    }
    let t0 = t[0];
    let r = map
        .reference
        .as_ref()
        .map(|_| columns.pop().unwrap_or_default());
    let y = columns.pop().unwrap_or_default();
    let u = columns.pop().unwrap_or_default();
    Ok(Dataset {
        name: name.to_string(),
        data: IdData { ts, u, y, r },
        t0,
        excitation,
        meta: meta
            .into_iter()
            .filter(|(k, _)| !EXCITATION_KEYS.contains(&k.as_str()))
            .map(|(k, (_, v))| (k, v))
            .collect(),
    })
}

fn parse_excitation(
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
    if cfg.fs_hz == 0 || cfg.period_samples < 2 {
        let (l, _) = get("period_samples")?;
        return Err(DataError::BadMeta {
            file: file.to_string(),
            line: l,
            key: "period_samples".into(),
            reason: "fs_hz must be positive and period_samples at least 2".into(),
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

/// Writes `ds` as a capture CSV: the excitation keys (when known),
/// `sample_interval_s`, every other meta key, the header
/// `t,theta_ref,u,theta_m` and one row per sample, numbers in shortest
/// round-trip form, so [`parse_csv`] reads back exactly the same data. The
/// rows are written by `capture::export::write_table`, the one capture CSV
/// row writer.
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
    let mut comments = ds
        .excitation
        .as_ref()
        .map(excitation_comment_lines)
        .unwrap_or_default();
    comments.push_str(&format!("# sample_interval_s={}\n", ds.data.ts));
    for (k, v) in &ds.meta {
        if k != "sample_interval_s" && !k.contains('=') && !v.contains('\n') {
            comments.push_str(&format!("# {k}={v}\n"));
        }
    }
    let rows = r
        .iter()
        .zip(&ds.data.u)
        .zip(&ds.data.y)
        .enumerate()
        .map(|(k, ((&rk, &uk), &yk))| [ds.t0 + k as f64 * ds.data.ts, rk, uk, yk]);
    crate::capture::export::write_table(out, &comments, rows)
}

/// Reads a CSV file (see [`parse_csv`]).
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

/// A file loader for one extension: path and column mapping in, dataset out.
pub type LoaderFn = Box<
    dyn Fn(&Path, &ColumnMap) -> Result<Dataset, Box<dyn std::error::Error + Send + Sync>>
        + Send
        + Sync,
>;

/// Registry of loaders by file extension. CSV is built in and also serves
/// files with no or an unknown extension that are not registered otherwise;
/// other formats (the native `.jcap` capture file) are registered by the
/// module that owns them with [`Loaders::register`].
#[derive(Default)]
pub struct Loaders {
    by_ext: Vec<(String, LoaderFn)>,
}

impl fmt::Debug for Loaders {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list()
            .entries(self.by_ext.iter().map(|(e, _)| e))
            .finish()
    }
}

/// extensions that must have a registered loader (never read as CSV)
pub const BINARY_EXTENSIONS: [&str; 1] = ["jcap"];

impl Loaders {
    /// registers `f` for files ending in `.ext` (without the dot), replacing
    /// an earlier loader for the same extension
    pub fn register(&mut self, ext: &str, f: LoaderFn) -> &mut Self {
        let ext = ext.trim_start_matches('.').to_ascii_lowercase();
        self.by_ext.retain(|(e, _)| *e != ext);
        self.by_ext.push((ext, f));
        self
    }

    /// Loads `path`: a registered loader for its extension, else CSV.
    ///
    /// # Errors
    /// [`DataError::NoLoader`] for a binary extension (`.jcap`) with no
    /// registered loader, [`DataError::Loader`] wrapping a loader's error,
    /// else as [`load_csv`].
    pub fn load(&self, path: &Path, map: &ColumnMap) -> Result<Dataset, DataError> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        if let Some((_, f)) = self.by_ext.iter().find(|(e, _)| *e == ext) {
            return f(path, map).map_err(|source| DataError::Loader {
                file: path.display().to_string(),
                source,
            });
        }
        if BINARY_EXTENSIONS.contains(&ext.as_str()) {
            let mut known: Vec<&str> = self.by_ext.iter().map(|(e, _)| e.as_str()).collect();
            known.push("csv");
            return Err(DataError::NoLoader {
                file: path.display().to_string(),
                ext,
                known: known.join(", "),
            });
        }
        load_csv(path, map)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
        let e = parse_csv(&gap, "g.csv", &ColumnMap::capture()).unwrap_err();
        assert!(matches!(e, DataError::NonUniform { line: 5, .. }), "{e}");
        assert!(
            e.to_string()
                .starts_with("g.csv:5: non-uniform sampling: interval 0.002 s -> 0.004 s"),
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
    fn detrend_linear_removes_a_line_exactly() {
        let mut x: Vec<f64> = (0..50).map(|k| 3.0 - 0.2 * k as f64).collect();
        detrend(&mut x, Detrend::Linear);
        assert!(x.iter().all(|v| v.abs() < 1e-12));
        let mut m = vec![1.0, 2.0, 6.0];
        detrend(&mut m, Detrend::Mean);
        assert_eq!(m, vec![-2.0, -1.0, 3.0]);
    }

    fn tone(n: usize, f: f64) -> Vec<f64> {
        (0..n)
            .map(|k| (2.0 * std::f64::consts::PI * f * k as f64).sin())
            .collect()
    }

    fn amp_at(x: &[f64], f: f64) -> f64 {
        let (mut c, mut s) = (0.0, 0.0);
        for (k, v) in x.iter().enumerate() {
            let ph = 2.0 * std::f64::consts::PI * f * k as f64;
            c += v * ph.cos();
            s += v * ph.sin();
        }
        2.0 * (c * c + s * s).sqrt() / x.len() as f64
    }

    #[test]
    fn decimate_keeps_in_band_amplitude_and_removes_aliases() {
        let q = 10;
        let n = 40_000;
        // in band: 0.03 cycles/sample = 0.3 of the new rate (below 0.4)
        let f_in = 0.03;
        let d = decimate(&tone(n, f_in), q).unwrap();
        assert_eq!(d.len(), n / q);
        let mid = &d[200..3800];
        let a = amp_at(mid, f_in * q as f64);
        assert!((a - 1.0).abs() < 1e-3, "in-band amplitude {a}");
        // a tone at 0.07 cycles/sample would alias to 0.3 of the new rate
        let f_out = 0.07;
        let d = decimate(&tone(n, f_out), q).unwrap();
        let alias = amp_at(&d[200..3800], 1.0 - f_out * q as f64);
        assert!(alias < 3e-4, "alias amplitude {alias}");
        // plain subsampling would keep it at full amplitude (sanity of the probe)
        let raw: Vec<f64> = tone(n, f_out).into_iter().step_by(q).collect();
        assert!(amp_at(&raw[200..3800], 1.0 - f_out * q as f64) > 0.99);
    }

    #[test]
    fn decimate_passes_a_ramp_at_the_edges() {
        let x: Vec<f64> = (0..500).map(|k| 0.5 * k as f64).collect();
        let d = decimate(&x, 5).unwrap();
        for (j, v) in d.iter().enumerate() {
            assert!((v - 2.5 * j as f64).abs() < 1e-9, "{j}: {v}");
        }
        assert!(matches!(
            decimate(&x[..10], 5),
            Err(DataError::Decimation(_))
        ));
    }

    #[test]
    fn split_and_slice_keep_signals_aligned() {
        let d = IdData {
            ts: 0.1,
            u: (0..10).map(f64::from).collect(),
            y: (10..20).map(f64::from).collect(),
            r: Some((20..30).map(f64::from).collect()),
        };
        let (e, v) = d.split(0.6);
        assert_eq!(e.len(), 6);
        assert_eq!(v.u[0], 6.0);
        assert_eq!(v.y[0], 16.0);
        assert_eq!(v.r.unwrap()[0], 26.0);
    }

    #[test]
    fn loaders_dispatch_on_extension_and_refuse_unregistered_jcap() {
        let dir = std::env::temp_dir().join(format!("jointid-data-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let csv = dir.join("x.csv");
        std::fs::write(&csv, "t,theta_ref,u,theta_m\n0,0,1,2\n0.5,0,1,2\n").unwrap();
        let mut loaders = Loaders::default();
        assert_eq!(
            loaders.load(&csv, &ColumnMap::capture()).unwrap().data.ts,
            0.5
        );
        let jcap = dir.join("x.jcap");
        let e = loaders.load(&jcap, &ColumnMap::capture()).unwrap_err();
        assert!(
            e.to_string()
                .ends_with("no loader for `.jcap` files (known: csv)"),
            "{e}"
        );
        loaders.register(
            "jcap",
            Box::new(|p, _| Err(format!("fake loader saw {}", p.display()).into())),
        );
        let e = loaders.load(&jcap, &ColumnMap::capture()).unwrap_err();
        assert!(e.to_string().contains("fake loader saw"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// `shared/data/<path>`: the first ancestor of the crate holding
    /// `shared/data` (the repository sits beside `shared/`)
    fn shared(path: &str) -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .ancestors()
            .map(|a| a.join("shared/data"))
            .find(|d| d.is_dir())
            .expect("shared/data beside the repository")
            .join(path)
    }

    #[test]
    fn load_csv_reads_emps_and_daisy_with_column_mapping() {
        let map = ColumnMap {
            time: "t_s".into(),
            input: "force_N".into(),
            output: "qm_m".into(),
            reference: None,
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
        };
        let ds = load_csv(&shared("daisy-robot-arm/robot_arm.csv"), &map).unwrap();
        assert_eq!(ds.data.len(), 1024);
        assert!((ds.data.ts - 0.01).abs() < 1e-12);
        assert_eq!(ds.data.u[0], 0.22183165);
        assert_eq!(ds.data.y[1], -0.11470789);
    }
}
