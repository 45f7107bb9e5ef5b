//! Identification data: one input, one output, uniformly sampled; loading and
//! preparation.
//!
//! - the capture CSV (read and write, the `# key=value` contract) and any CSV with a
//!   column mapping in [`csv`];
//! - detrending and the order of preparation in [`prep`];
//! - integer decimation with a zero-phase anti-alias filter in [`dsp`];
//! - the one rule of every output file (no overwrite without `--force`, whole or not at
//!   all) in [`output`];
//! - [`IdData`], [`Dataset`], whole excitation periods and the loader registry here.
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
// Units in brackets (`[s]`, `[Hz]`, `[dB]`) are not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;

pub use jointid_core::excitation::{ExcitationConfig, SignalKind};

pub mod csv;

/// `x` rounded to `digits` significant digits (at least 1) and written in its shortest
/// form: how times and rates are shown to the user (`Ts = 0.001 s` for a sample
/// interval estimated as 0.0009999839611225525 s, `fs = 2000 Hz`, `f0 = 0.4 Hz`).
/// Not for values written as data.
pub fn fmt_sig(x: f64, digits: usize) -> String {
    if !x.is_finite() {
        return x.to_string();
    }
    let rounded: f64 = format!("{:.*e}", digits.max(1) - 1, x).parse().unwrap_or(x);
    format!("{rounded}")
}
pub mod dsp;
pub mod output;
pub mod prep;

pub use csv::{
    excitation_comment_lines, load_csv, parse_csv, write_capture_csv, write_table, EXCITATION_KEYS,
    SAMPLE_INTERVAL_TOLERANCE,
};
pub use dsp::{decimate, decimation_taps};
pub use prep::{detrend, Detrend, Prep};

/// Relative difference of two sample intervals below which two records count as sampled
/// at one rate. Intervals estimated from recorded time stamps differ by tens of ppm
/// (EMPS: 999.992 Hz against 1000.02 Hz); 0.1 % moves a 100 Hz resonance by 0.1 Hz.
pub const SAME_RATE_TOLERANCE: f64 = 1e-3;

/// Whether sample intervals `a` and `b` [s] are one rate ([`SAME_RATE_TOLERANCE`]).
pub fn same_rate(a: f64, b: f64) -> bool {
    (a - b).abs() <= SAME_RATE_TOLERANCE * a.abs().max(b.abs())
}

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

    /// What every estimator checks first: `u` and `y` of equal length, at least
    /// `min_samples` of them, a positive finite sample interval, every value of `u` and
    /// `y` finite.
    ///
    /// # Errors
    /// The first [`RecordError`] found, in that order.
    pub fn check(&self, min_samples: usize) -> Result<(), RecordError> {
        if self.u.len() != self.y.len() {
            return Err(RecordError::LengthMismatch {
                input: self.u.len(),
                output: self.y.len(),
            });
        }
        if self.len() < min_samples {
            return Err(RecordError::TooShort {
                samples: self.len(),
                min: min_samples,
            });
        }
        if !(self.ts > 0.0 && self.ts.is_finite()) {
            return Err(RecordError::BadInterval { ts: self.ts });
        }
        if let Some(index) = self.u.iter().chain(&self.y).position(|v| !v.is_finite()) {
            return Err(RecordError::NonFinite { index });
        }
        Ok(())
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

/// Why a record cannot go to an estimator ([`IdData::check`]).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum RecordError {
    /// `u` and `y` differ in length
    #[error("input has {input} samples, output {output}")]
    LengthMismatch {
        /// samples of `u`
        input: usize,
        /// samples of `y`
        output: usize,
    },
    /// fewer samples than the estimator needs
    #[error("{samples} samples are too few (need at least {min})")]
    TooShort {
        /// samples in the record
        samples: usize,
        /// samples needed
        min: usize,
    },
    /// the sample interval is zero, negative or not finite
    #[error("sample interval {ts} s is not positive and finite")]
    BadInterval {
        /// the sample interval [s]
        ts: f64,
    },
    /// a value of `u` or `y` is NaN or infinite
    #[error("non-finite value at position {index} of u followed by y")]
    NonFinite {
        /// position in `u` followed by `y` (`index - len` is the position in `y`)
        index: usize,
    },
}

/// Errors of loading and preparing data.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// the file could not be read
    #[error("{file}: {}", io_phrase(source))]
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
    /// a registered loader failed (its message names the file once)
    #[error("{}", named_once(file, source.as_ref()))]
    Loader {
        /// file name
        file: String,
        /// the loader's error
        source: Box<dyn std::error::Error + Send + Sync>,
    },
}

/// An I/O error without the `(os error N)` suffix (still a prefix of the error's own
/// text, so the command line does not repeat it as the cause).
fn io_phrase(e: &std::io::Error) -> String {
    let mut m = e.to_string();
    if let Some(i) = m.find(" (os error ") {
        m.truncate(i);
    }
    m
}

/// `file: message`, unless the message already begins with the file's name.
fn named_once(file: &str, source: &dyn std::error::Error) -> String {
    let m = source.to_string();
    if m.starts_with(file) {
        m
    } else {
        format!("{file}: {m}")
    }
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
    #[test]
    fn fmt_sig_rounds_times_and_rates_for_the_user() {
        use super::fmt_sig;
        assert_eq!(fmt_sig(0.000_999_983_961_122_552_5, 4), "0.001");
        assert_eq!(fmt_sig(2000.0, 4), "2000");
        assert_eq!(fmt_sig(1.0 / 2.5, 4), "0.4");
        assert_eq!(fmt_sig(1.0 / 3.0, 4), "0.3333");
        assert_eq!(fmt_sig(-0.126, 2), "-0.13");
        assert_eq!(fmt_sig(f64::NAN, 4), "NaN");
    }

    use super::*;

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

    #[test]
    fn check_names_the_first_fault_with_its_numbers() {
        let ok = IdData {
            ts: 0.01,
            u: vec![1.0; 60],
            y: vec![2.0; 60],
            r: None,
        };
        assert_eq!(ok.check(50), Ok(()));
        let mut d = ok.clone();
        d.y.pop();
        assert_eq!(
            d.check(50),
            Err(RecordError::LengthMismatch {
                input: 60,
                output: 59
            })
        );
        assert_eq!(
            ok.check(61),
            Err(RecordError::TooShort {
                samples: 60,
                min: 61
            })
        );
        let mut d = ok.clone();
        d.ts = 0.0;
        assert_eq!(d.check(50), Err(RecordError::BadInterval { ts: 0.0 }));
        let mut d = ok.clone();
        d.y[3] = f64::NAN;
        assert_eq!(d.check(50), Err(RecordError::NonFinite { index: 63 }));
        assert_eq!(
            RecordError::NonFinite { index: 63 }.to_string(),
            "non-finite value at position 63 of u followed by y"
        );
    }
}
