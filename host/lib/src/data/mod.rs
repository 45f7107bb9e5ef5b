//! Identification data: one input, one output, uniformly sampled; loading and
//! preparation.
//!
//! - the capture CSV (read and write, the `# key=value` contract) and any CSV with a
//!   column mapping in [`csv`];
//! - detrending and the order of preparation in [`prep`];
//! - integer decimation with a zero-phase anti-alias filter in [`dsp`];
//! - the one rule of every output file (no overwrite without `--force`, whole or not at
//!   all) in [`output`];
//! - samples far outside their record (outliers, on a robust scale) in [`screen`];
//! - where an input comes from (a file, or `-` for standard input read whole) and how
//!   messages name it in [`input`];
//! - [`IdData`], [`Dataset`], whole excitation periods and the loader registry here.
//!
//! What: read the capture CSV of ../shared/DESIGN.md §5 (and any CSV with a column
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
/// interval estimated as 0.0009999839611225525 s, `fs = 2000 Hz`, `f0 = 0.4 Hz`);
/// outside [`FMT_SIG_PLAIN`] in scientific notation (`1e99 Hz` from a time column in steps
/// of 1e-99 s, not a hundred digits). Not for values written as data.
pub fn fmt_sig(x: f64, digits: usize) -> String {
    if !x.is_finite() {
        return x.to_string();
    }
    let rounded: f64 = format!("{:.*e}", digits.max(1) - 1, x).parse().unwrap_or(x);
    let (low, high) = FMT_SIG_PLAIN;
    if rounded != 0.0 && !(low..high).contains(&rounded.abs()) {
        format!("{rounded:e}")
    } else {
        format!("{rounded}")
    }
}

/// Magnitudes [`fmt_sig`] writes in plain digits: from 1e-6 (a microsecond) up to 1e9
/// (a gigahertz), at most 15 characters before any rounding.
pub const FMT_SIG_PLAIN: (f64, f64) = (1e-6, 1e9);
/// How an undefined figure is shown to the user (a 0/0 share, the FIT of a simulation that
/// diverged): a dash, never `NaN` or `inf`.
pub const UNDEFINED: &str = "—";

/// A percentage (a FIT [%], a share [%], a relative error [%]) or a difference of them
/// (FIT points) as the user reads it, for `{}` with the caller's precision, sign and width
/// (`format!("{:+7.2}", Percent(x))`): [`UNDEFINED`] when `x` is not finite, and in
/// scientific notation from a magnitude of 1e6 on (a FIT of a simulation that left the
/// data far behind), so that no figure runs to hundreds of digits. Not for values written
/// as data (`--json` writes a non-finite value as `null`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Percent(pub f64);

/// Magnitude from which [`Percent`] writes a figure in scientific notation.
pub const PERCENT_SCIENTIFIC_FROM: f64 = 1e6;

impl fmt::Display for Percent {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let x = self.0;
        let sign = if f.sign_plus() && x >= 0.0 { "+" } else { "" };
        let text = if !x.is_finite() {
            UNDEFINED.to_string()
        } else if x.abs() >= PERCENT_SCIENTIFIC_FROM {
            format!("{sign}{x:.2e}")
        } else {
            match f.precision() {
                Some(p) => format!("{sign}{x:.p$}"),
                None => format!("{sign}{x}"),
            }
        };
        // right-aligned by default, as numbers are
        let width = f.width().unwrap_or(0);
        let len = text.chars().count();
        if len >= width {
            return f.write_str(&text);
        }
        let pad = width - len;
        let (before, after) = match f.align() {
            Some(fmt::Alignment::Left) => (0, pad),
            Some(fmt::Alignment::Center) => (pad / 2, pad - pad / 2),
            _ => (pad, 0),
        };
        let fill = f.fill().to_string();
        write!(f, "{}{text}{}", fill.repeat(before), fill.repeat(after))
    }
}

pub mod dsp;
pub mod input;
pub mod mat;
pub mod output;
pub mod prep;
pub mod screen;
pub mod segment;

pub use csv::{
    capture_csv_comments, excitation_comment_lines, load_csv, parse_csv, parse_csv_record,
    read_csv_record, write_capture_csv, write_table, TableWriter, EXCITATION_KEYS,
    SAMPLE_INTERVAL_TOLERANCE,
};
pub use dsp::{decimate, decimation_taps};
pub use prep::{detrend, Detrend, Prep};
pub use segment::{
    Record, SegmentChoice, SegmentInfo, Selected, Selection, SelectionParseError, TimeBound,
};

/// Relative difference of two sample intervals below which two records count as sampled
/// at one rate. Intervals estimated from recorded time stamps differ by tens of ppm
/// (EMPS: 999.992 Hz against 1000.02 Hz); 0.1 % moves a 100 Hz resonance by 0.1 Hz.
pub const SAME_RATE_TOLERANCE: f64 = 1e-3;

/// Root mean square of `x` about its mean (a signal's spread, its offset aside); 0 for an
/// empty `x`.
pub fn rms_about_mean(x: &[f64]) -> f64 {
    let n = x.len().max(1) as f64;
    let mean = x.iter().sum::<f64>() / n;
    (x.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n).sqrt()
}

/// The top of the band where the excitation `c` and the joint's response to it lie [Hz]:
/// the highest excited line `F·f0`, or three times the corner of the amplitude shape when
/// that is higher (the power sits below the corner, and its third-order distortion, the
/// first a nonlinear joint adds, reaches three times as high); `None` for a zero period, or
/// when that is not below 0.4 × the sample rate `1/ts` (room for a low-pass's roll-off
/// below Nyquist).
pub fn excited_band_top(c: &ExcitationConfig, ts: f64) -> Option<f64> {
    let top = (c.max_line as f64 * c.f0_hz()).max(3.0 * f64::from(c.cutoff_hz));
    (c.f0_hz() > 0.0 && top > 0.0 && top < 0.4 / ts).then_some(top)
}

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

    /// The record with its input taken as samples of a band-limited signal that moves
    /// between them, for models that hold each input sample over its interval (as a drive
    /// holds its torque reference): each sample replaced by the value whose hold over the
    /// interval passes the signal's components with unit gain and no delay to second order
    /// in `x = ω·Ts/2`, `(7·(u[k] + u[k+1]) − (u[k−1] + u[k+2])) / 12`, the ends repeated
    /// and the last sample kept. A measured analog input (a voltage, a force sensor) held as
    /// it is lags the model by half a sample; held at the interval mean `(u[k] + u[k+1])/2`
    /// it has no lag but a gain `cos x · sin x / x` (0.94 at a tenth of the sample rate:
    /// a grounded mass driven by a band-limited force was fitted with `J` and `k` 6.8 and
    /// 7.0 % low), this one 0.996 (0.6 and 0.8 %).
    pub fn input_as_sampled(&self) -> IdData {
        let u = &self.u;
        let n = u.len();
        let at = |k: isize| u[k.clamp(0, n as isize - 1) as usize];
        let mut d = self.clone();
        for k in 0..n.saturating_sub(1) {
            let k = k as isize;
            d.u[k as usize] = (7.0 * (at(k) + at(k + 1)) - (at(k - 1) + at(k + 2))) / 12.0;
        }
        d
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
    /// [`DataError::DecimationFactor`] when `q` is 0, [`DataError::DecimationTooShort`] when the
    /// record is shorter than the filter.
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
    /// column delimiter; `None`: `,`, or `;` or a tab when the header holds no `,`
    pub delimiter: Option<char>,
}

impl ColumnMap {
    /// the capture CSV header `t,theta_ref,u,theta_m` of ../shared/DESIGN.md §5
    pub fn capture() -> Self {
        ColumnMap {
            time: "t".into(),
            input: "u".into(),
            output: "theta_m".into(),
            reference: Some("theta_ref".into()),
            delimiter: None,
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

/// A record that holds no whole steady-state period ([`PeriodLayout::of`]).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{what} leave no whole period of {period} after {transient}")]
pub struct NoWholePeriod {
    /// the record's samples (`N samples`, or their excitation sample numbers)
    pub what: String,
    /// samples per period
    pub period: usize,
    /// where the steady state begins
    pub transient: String,
}

impl PeriodLayout {
    /// The whole steady-state periods of `len` samples starting at excitation sample
    /// `first_sample` (see [`Dataset::period_layout`]); `start` is counted from the first
    /// of these samples.
    ///
    /// # Errors
    /// [`NoWholePeriod`]: why no whole period remains.
    pub fn of(
        cfg: &ExcitationConfig,
        first_sample: usize,
        len: usize,
        settle_periods: usize,
    ) -> Result<PeriodLayout, NoWholePeriod> {
        let period = cfg.period_samples as usize;
        let ramp = cfg.ramp_samples as usize;
        let k0 = first_sample;
        // in excitation samples: the first whole steady-state period boundary in the record
        let transient_end = ramp + settle_periods * period;
        let abs_start = if k0 <= transient_end || period == 0 {
            transient_end
        } else {
            ramp + (k0 - ramp).div_ceil(period) * period
        };
        let abs_end = if cfg.periods > 0 {
            (k0 + len).min(ramp + cfg.periods as usize * period)
        } else {
            // endless run stopped by the user: its last `ramp_samples` may be
            // the ramp-out, so they are left out
            (k0 + len).saturating_sub(ramp)
        };
        let count = abs_end.saturating_sub(abs_start) / period.max(1);
        if period == 0 || count == 0 {
            let (what, transient) = if k0 == 0 {
                (
                    format!("{len} samples"),
                    format!("{transient_end} transient samples"),
                )
            } else {
                (
                    format!("samples {k0}..{} of the excitation", k0 + len),
                    format!("excitation sample {abs_start}"),
                )
            };
            return Err(NoWholePeriod {
                what,
                period,
                transient,
            });
        }
        Ok(PeriodLayout {
            period,
            start: abs_start - k0,
            count,
        })
    }

    /// As [`PeriodLayout::of`] for a piece of a run whose last sample is excitation sample
    /// `run_last` (when known): an endless run's ramp-out can only lie in its last
    /// `ramp_samples`, so a piece that ends earlier loses none of its periods to it.
    ///
    /// # Errors
    /// As [`PeriodLayout::of`].
    pub fn in_run(
        cfg: &ExcitationConfig,
        first_sample: usize,
        len: usize,
        settle_periods: usize,
        run_last: Option<usize>,
    ) -> Result<PeriodLayout, NoWholePeriod> {
        let ramp = cfg.ramp_samples as usize;
        let end = first_sample + len;
        match run_last {
            Some(last) if cfg.periods == 0 && last + 1 >= end + ramp => {
                let l = PeriodLayout::of(cfg, first_sample, len + ramp, settle_periods)?;
                let count = l.count.min(len.saturating_sub(l.start) / l.period.max(1));
                if count == 0 {
                    return PeriodLayout::of(cfg, first_sample, len, settle_periods);
                }
                Ok(PeriodLayout { count, ..l })
            }
            _ => PeriodLayout::of(cfg, first_sample, len, settle_periods),
        }
    }

    /// sample range covered by the kept periods
    pub fn range(&self) -> std::ops::Range<usize> {
        self.start..self.start + self.period * self.count
    }
}

/// How a model reads the input samples of its records: held over each interval as they
/// are (a drive holds its torque reference), or taken as samples of a signal that moves
/// between them ([`IdData::input_as_sampled`]: a measured analog input). A model fitted on
/// one reading is validated and simulated on the same one; `fit --save` records it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum InputTaken {
    /// each sample held over its interval
    #[default]
    Held,
    /// samples of a band-limited signal ([`IdData::input_as_sampled`])
    Sampled,
}

impl InputTaken {
    /// Whether the input is held as it is (the default, which model files leave out).
    pub fn is_held(&self) -> bool {
        *self == InputTaken::Held
    }

    /// The record `d` with its input read so.
    pub fn record(self, d: IdData) -> IdData {
        match self {
            InputTaken::Held => d,
            InputTaken::Sampled => d.input_as_sampled(),
        }
    }

    /// The capture `d` with its input read so.
    pub fn capture(self, d: Dataset) -> Dataset {
        match self {
            InputTaken::Held => d,
            InputTaken::Sampled => d.input_as_sampled(),
        }
    }
}

impl Dataset {
    /// The capture with its input taken as sampled ([`IdData::input_as_sampled`]).
    pub fn input_as_sampled(&self) -> Dataset {
        Dataset {
            data: self.data.input_as_sampled(),
            ..self.clone()
        }
    }

    /// Excitation sample index of the first sample: `t0 / ts` rounded (the time column
    /// counts from the first sample of the ramp-in, so a record that starts later, such as
    /// a segment after a gap, starts at `t0 = k Ts`); 0 when `t0` is not positive.
    pub fn first_sample(&self) -> usize {
        let k = self.t0 / self.data.ts;
        if k.is_finite() && k > 0.5 {
            k.round() as usize
        } else {
            0
        }
    }

    /// The excitation sample index of the run's last sample, when the file states it
    /// (`# last_seq=`, as a capture and its CSV do): a piece of a run with gaps ends
    /// before it.
    pub fn last_sample_of_run(&self) -> Option<usize> {
        self.meta.get("last_seq")?.parse().ok()
    }

    /// Layout of the whole steady-state periods from the excitation config:
    /// skips the ramp-in and `settle_periods` more periods (transient), then
    /// takes every whole period left: at most `periods − settle_periods` when
    /// the run is finite, so the ramp-out is excluded; for an endless run
    /// (`periods = 0`) the last `ramp_samples` samples of the run are left
    /// out, as they may hold a ramp-out. A record that starts later than the
    /// ramp-in ([`Dataset::first_sample`] > 0) starts at its first whole period
    /// boundary after the transient.
    ///
    /// # Errors
    /// [`DataError::NoPeriods`] when there is no config or no whole period
    /// remains.
    pub fn period_layout(&self, settle_periods: usize) -> Result<PeriodLayout, DataError> {
        let cfg = self.excitation.ok_or_else(|| DataError::NoPeriods {
            file: self.name.clone(),
            reason: "no excitation config in the file".into(),
        })?;
        let lay = PeriodLayout::in_run(
            &cfg,
            self.first_sample(),
            self.data.len(),
            settle_periods,
            self.last_sample_of_run(),
        );
        lay.map_err(|e| DataError::NoPeriods {
            file: self.name.clone(),
            reason: e.to_string(),
        })
    }

    /// The period [samples] a file states without a full excitation config (another
    /// logger's `# period_samples=N`, or `# f0_hz=F` with the sample interval), or of the
    /// excitation config when there is one.
    pub fn stated_period(&self) -> Option<usize> {
        if let Some(c) = self.excitation {
            return Some(c.period_samples as usize);
        }
        if let Some(n) = self
            .meta
            .get("period_samples")
            .and_then(|v| v.parse::<usize>().ok())
        {
            return Some(n).filter(|n| *n >= 2);
        }
        let f0 = self.meta.get("f0_hz")?.parse::<f64>().ok()?;
        let n = 1.0 / (f0 * self.data.ts);
        (n.is_finite() && n >= 2.0 && (n - n.round()).abs() < 1e-6 * n)
            .then_some(n.round() as usize)
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
    /// the comments' sample interval and the time column's contradict each other (a
    /// header of 2 kHz over a time column at 1 kHz read as one gap after every sample)
    #[error(
        "{file}:{line}: the comments give a sample interval of {} s ({} Hz), but the time \
         column's samples are {} s apart ({} Hz, the median of its {intervals} intervals): \
         one of them is wrong; correct `sample_interval_s` or the time column",
        fmt_sig(*stated_s, 6),
        fmt_sig(1.0 / stated_s, 6),
        fmt_sig(*column_s, 6),
        fmt_sig(1.0 / column_s, 6)
    )]
    RateContradiction {
        /// file name
        file: String,
        /// line of the `sample_interval_s` comment (1-based)
        line: usize,
        /// the comment's interval [s]
        stated_s: f64,
        /// the time column's interval, the median of its intervals [s]
        column_s: f64,
        /// the time column's intervals
        intervals: usize,
    },
    /// no whole excitation period could be found
    #[error("{file}: no whole excitation period: {reason}")]
    NoPeriods {
        /// file name
        file: String,
        /// why
        reason: String,
    },
    /// the record has gaps and one uniformly sampled record was asked for
    #[error("{file}: {gaps} gap{}, {missing} samples missing; gap-free segments {segments}; choose with --segment longest|N|all (and --from/--to)", if *gaps == 1 { "" } else { "s" })]
    Gaps {
        /// file name
        file: String,
        /// number of gaps
        gaps: usize,
        /// samples missing in them
        missing: u64,
        /// the segments, described
        segments: String,
    },
    /// a time column jumps by a whole number of sample intervals: samples are missing
    #[error("{file}:{line}: gap: time jumps {prev} s -> {next} s, {missing} samples missing")]
    TimeGap {
        /// file name
        file: String,
        /// line (1-based) of the sample after the gap
        line: usize,
        /// time before the gap [s]
        prev: f64,
        /// time after the gap [s]
        next: f64,
        /// samples missing
        missing: u64,
    },
    /// the segment or window asked for cannot be used
    #[error("{file}: {reason}")]
    Selection {
        /// file name
        file: String,
        /// what is wrong
        reason: String,
    },
    /// a file type recognised by its content that no loader reads
    #[error("{file}: {what}: not supported yet ({hint})")]
    Unsupported {
        /// file name
        file: String,
        /// the type recognised (`MATLAB file (v5)`)
        what: String,
        /// what to do instead
        hint: String,
    },
    /// a file that is neither a registered binary format nor text
    #[error("{file}: not a CSV text file: {reason}")]
    NotText {
        /// file name
        file: String,
        /// what was found
        reason: String,
    },
    /// decimation by a factor of nought
    #[error("decimation: factor must be at least 1")]
    DecimationFactor,
    /// a record too short for the decimation's anti-alias filter
    #[error(
        "decimation: record of {samples} samples is shorter than the {taps}-tap anti-alias filter"
    )]
    DecimationTooShort {
        /// samples in the record
        samples: usize,
        /// taps of the filter
        taps: usize,
    },
    /// a binary format recognised by its content, with no loader registered
    #[error("{file}: {format} file, and no loader for it is registered (known: {known})")]
    NoLoader {
        /// file name
        file: String,
        /// the format recognised
        format: String,
        /// registered formats
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

/// What a loader reads: the file's name for messages, its path when it is a file (not
/// standard input), and its whole content.
#[derive(Clone, Copy, Debug)]
pub struct Input<'a> {
    /// name used in messages (the path, or `standard input`)
    pub name: &'a str,
    /// the file, when the data is one (sidecar files sit beside it)
    pub path: Option<&'a Path>,
    /// the whole content
    pub bytes: &'a [u8],
}

/// A loader of one binary format: content and column mapping in, record out.
pub type LoaderFn = Box<
    dyn Fn(&Input<'_>, &ColumnMap) -> Result<Record, Box<dyn std::error::Error + Send + Sync>>
        + Send
        + Sync,
>;

/// Registry of loaders, chosen by the file's content, never by its name: a registered
/// format by its magic bytes (the native `.jcap` capture, registered by the module that
/// owns it with [`Loaders::register`]), MATLAB Level-5 files read by [`mat`] (v7.3, HDF5,
/// refused with a clear message), anything else read as CSV text. `-` reads standard input.
#[derive(Default)]
pub struct Loaders {
    formats: Vec<(String, Vec<u8>, LoaderFn)>,
}

impl fmt::Debug for Loaders {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list()
            .entries(self.formats.iter().map(|(n, _, _)| n))
            .finish()
    }
}

/// Magic bytes of the native capture file (`JCAP`, then the version): a file starting
/// with them is never read as CSV.
pub const JCAP_MAGIC_PREFIX: &[u8] = b"JCAP";

/// The signature of an HDF5 file (MATLAB v7.3 files are HDF5 after a 512-byte header).
const HDF5_SIGNATURE: &[u8] = b"\x89HDF\r\n\x1a\n";

/// What [`matlab_kind`] calls a Level-5 MAT-file, which [`mat`] reads.
pub const MATLAB_V5: &str = "MATLAB file (v5)";

/// The MATLAB file type of `bytes`, when it is one (`MATLAB 5.0 MAT-file` text header,
/// or the HDF5 signature at byte 0 or 512).
pub fn matlab_kind(bytes: &[u8]) -> Option<&'static str> {
    let head = &bytes[..bytes.len().min(116)];
    let text = String::from_utf8_lossy(head);
    if text.starts_with("MATLAB 7.3 MAT-file")
        || bytes.get(512..520) == Some(HDF5_SIGNATURE)
        || bytes.starts_with(HDF5_SIGNATURE)
    {
        return Some("MATLAB file (v7.3, HDF5)");
    }
    if text.starts_with("MATLAB ") && text.contains("MAT-file") {
        return Some(MATLAB_V5);
    }
    None
}

impl Loaders {
    /// Registers `f` for files starting with `magic` under the name `format`, replacing an
    /// earlier loader of that name.
    pub fn register(&mut self, format: &str, magic: &[u8], f: LoaderFn) -> &mut Self {
        self.formats.retain(|(n, _, _)| n != format);
        self.formats.push((format.to_string(), magic.to_vec(), f));
        self
    }

    /// Reads `path` (`-`: standard input) whole and loads it as one uniformly sampled
    /// dataset ([`Loaders::load_record`], then [`Record::into_single`]).
    ///
    /// # Errors
    /// As [`Loaders::load_record`]; [`DataError::Gaps`] when the data has gaps.
    pub fn load(&self, path: &Path, map: &ColumnMap) -> Result<Dataset, DataError> {
        self.load_record(path, map)?.into_single()
    }

    /// Reads `path` (`-`: standard input) and loads it by its content: a registered
    /// format by its magic bytes, else CSV ([`csv::parse_csv_record`]). A CSV file is read
    /// line by line ([`csv::read_csv_record`]: never held whole); the other formats, and
    /// standard input, are read whole.
    ///
    /// # Errors
    /// [`DataError::Io`] when it cannot be read, [`DataError::Unsupported`] for a MATLAB
    /// file, [`DataError::NoLoader`] for a `.jcap` with no loader registered,
    /// [`DataError::Loader`] wrapping a loader's error, [`DataError::NotText`] for other
    /// binary content, else as [`csv::parse_csv_record`].
    pub fn load_record(&self, path: &Path, map: &ColumnMap) -> Result<Record, DataError> {
        use std::io::Read;
        let name = input::input_name(path);
        let io = |source| DataError::Io {
            file: name.clone(),
            source,
        };
        let (bytes, path) = if input::is_stdin(path) {
            (input::read_input(path).map_err(io)?, None)
        } else {
            // enough of the start to tell the format (a MATLAB header, HDF5 at byte 512)
            let mut file = std::fs::File::open(path).map_err(io)?;
            let mut head = Vec::new();
            file.by_ref()
                .take(FORMAT_HEAD)
                .read_to_end(&mut head)
                .map_err(io)?;
            if self.is_text(&head) {
                let size = file
                    .metadata()
                    .ok()
                    .filter(|m| m.is_file())
                    .map(|m| m.len());
                let reader = std::io::BufReader::new(std::io::Cursor::new(head).chain(file));
                return csv::read_csv_record(reader, size, &name, map);
            }
            file.read_to_end(&mut head).map_err(io)?;
            (head, Some(path))
        };
        let input = Input {
            name: &name,
            path,
            bytes: &bytes,
        };
        self.load_input(&input, map)
    }

    /// Whether content starting with `head` goes to the CSV reader: no registered magic,
    /// not a `.jcap`, not a MATLAB file.
    fn is_text(&self, head: &[u8]) -> bool {
        !self
            .formats
            .iter()
            .any(|(_, m, _)| !m.is_empty() && head.starts_with(m))
            && !head.starts_with(JCAP_MAGIC_PREFIX)
            && matlab_kind(head).is_none()
    }

    /// Loads content already read (see [`Loaders::load_record`]).
    ///
    /// # Errors
    /// As [`Loaders::load_record`].
    pub fn load_input(&self, input: &Input<'_>, map: &ColumnMap) -> Result<Record, DataError> {
        let name = input.name.to_string();
        if let Some((_, _, f)) = self
            .formats
            .iter()
            .find(|(_, m, _)| !m.is_empty() && input.bytes.starts_with(m))
        {
            return f(input, map).map_err(|source| DataError::Loader { file: name, source });
        }
        if input.bytes.starts_with(JCAP_MAGIC_PREFIX) {
            let mut known: Vec<&str> = self.formats.iter().map(|(n, _, _)| n.as_str()).collect();
            known.push("csv");
            return Err(DataError::NoLoader {
                file: name,
                format: "jcap capture".into(),
                known: known.join(", "),
            });
        }
        if let Some(what) = matlab_kind(input.bytes) {
            if what == MATLAB_V5 {
                return mat::parse_mat_record(input.bytes, &name, map);
            }
            return Err(DataError::Unsupported {
                file: name,
                what: what.into(),
                hint: "save it as a Level-5 MAT-file with `save(file, '-v7', ...)` in \
                       MATLAB, or the signals as a CSV with a header line"
                    .into(),
            });
        }
        csv::read_csv_record(input.bytes, Some(input.bytes.len() as u64), &name, map)
    }
}

/// Bytes of a file's start that tell its format: [`matlab_kind`] reads the HDF5
/// signature at byte 512.
const FORMAT_HEAD: u64 = 520;

#[cfg(test)]
mod tests {
    /// An input taken as sampled: a ramp is held at its intervals' midpoints (no lag); a
    /// sine at a tenth of the sample rate, held so, has the unit gain of the signal to
    /// within 1 % (the interval mean would leave 0.94); the output and the rest as they were.
    #[test]
    fn an_input_taken_as_sampled_is_held_without_lag_or_loss() {
        let ramp = super::IdData {
            ts: 0.5,
            u: (0..6).map(f64::from).collect(),
            y: vec![1.0; 6],
            r: None,
        };
        let s = ramp.input_as_sampled();
        assert_eq!(s.u[1..4], [1.5, 2.5, 3.5]);
        assert_eq!((s.u[5], &s.y, s.ts), (5.0, &ramp.y, ramp.ts));
        let w = 2.0 * std::f64::consts::PI / 10.0;
        let sine = super::IdData {
            u: (0..40).map(|k| (w * f64::from(k)).cos()).collect(),
            ..ramp
        };
        // the hold over an interval passes a sine with the gain sin(x)/x, x = ω·Ts/2
        let hold = (w / 2.0).sin() / (w / 2.0);
        for (k, h) in sine
            .input_as_sampled()
            .u
            .iter()
            .enumerate()
            .take(38)
            .skip(1)
        {
            let mid = (w * (k as f64 + 0.5)).cos();
            assert!((h * hold - mid).abs() < 0.01, "sample {k}: {h} vs {mid}");
        }
    }

    #[test]
    fn fmt_sig_rounds_times_and_rates_for_the_user() {
        use super::fmt_sig;
        assert_eq!(fmt_sig(0.000_999_983_961_122_552_5, 4), "0.001");
        assert_eq!(fmt_sig(2000.0, 4), "2000");
        assert_eq!(fmt_sig(1.0 / 2.5, 4), "0.4");
        assert_eq!(fmt_sig(1.0 / 3.0, 4), "0.3333");
        assert_eq!(fmt_sig(-0.126, 2), "-0.13");
        assert_eq!(fmt_sig(f64::NAN, 4), "NaN");
        // far outside seconds and hertz: scientific, not hundreds of digits
        assert_eq!(fmt_sig(1.0 / 1e-99, 6), "1e99");
        assert_eq!(fmt_sig(1e308, 6), "1e308");
        assert_eq!(fmt_sig(-2.5e-300, 4), "-2.5e-300");
        assert_eq!(fmt_sig(1.0 / 3e-12, 4), "3.333e11");
        assert_eq!(fmt_sig(2e-6, 4), "0.000002");
        assert_eq!(fmt_sig(0.0, 4), "0");
    }

    #[test]
    fn percent_shows_undefined_and_huge_figures_readably_in_the_callers_format() {
        assert_eq!(format!("{:.2}", Percent(67.004)), "67.00");
        assert_eq!(format!("{:+.1}", Percent(2.25)), "+2.2");
        assert_eq!(format!("{:+.1}", Percent(-2.25)), "-2.2");
        assert_eq!(format!("{:>7.2}", Percent(-1.5)), "  -1.50");
        assert_eq!(format!("{:<4.0}|", Percent(f64::NAN)), "—   |");
        assert_eq!(format!("{:>3.2}", Percent(f64::NEG_INFINITY)), "  —");
        assert_eq!(format!("{:.2}", Percent(-1e300)), "-1.00e300");
        assert_eq!(format!("{:.2}", Percent(-999_999.0)), "-999999.00");
        assert_eq!(format!("{}", Percent(f64::INFINITY)), UNDEFINED);
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
    fn loaders_choose_by_content_not_by_name() {
        let dir = std::env::temp_dir().join(format!("jointid-data-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // CSV text named .jcap is read as CSV
        let csv = dir.join("x.jcap");
        std::fs::write(&csv, "t,theta_ref,u,theta_m\n0,0,1,2\n0.5,0,1,2\n").unwrap();
        let mut loaders = Loaders::default();
        assert_eq!(
            loaders.load(&csv, &ColumnMap::capture()).unwrap().data.ts,
            0.5
        );
        // capture bytes named .csv go to the capture loader, or are refused without one
        let jcap = dir.join("x.csv");
        std::fs::write(&jcap, b"JCAP\x01\r\n\x1a\x00\x01").unwrap();
        let e = loaders.load(&jcap, &ColumnMap::capture()).unwrap_err();
        assert_eq!(
            e.to_string(),
            format!(
                "{}: jcap capture file, and no loader for it is registered (known: csv)",
                jcap.display()
            )
        );
        loaders.register(
            "jcap",
            JCAP_MAGIC_PREFIX,
            Box::new(|i, _| Err(format!("fake loader saw {} bytes", i.bytes.len()).into())),
        );
        let e = loaders.load(&jcap, &ColumnMap::capture()).unwrap_err();
        assert!(e.to_string().ends_with("fake loader saw 10 bytes"), "{e}");
        // MATLAB files, v5 and v7.3, are named as such
        let mat = dir.join("run.mat");
        let mut v5 = b"MATLAB 5.0 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1".to_vec();
        v5.resize(128, b' ');
        v5.extend_from_slice(&[0, 1, 0x49, 0x4d, 0, 0, 0, 0]);
        std::fs::write(&mat, &v5).unwrap();
        let e = loaders.load(&mat, &ColumnMap::capture()).unwrap_err();
        assert!(
            e.to_string().starts_with(&format!(
                "{}: endian indicator \"  \" at byte 126 is neither `IM` nor `MI`",
                mat.display()
            )),
            "{e}"
        );
        // a Level-5 file is read by its variables, whatever its name
        let mut w = mat::MatWriter::new("loader test");
        for (n, x) in [("t", [0.0, 0.5]), ("theta_ref", [0.0; 2]), ("u", [1.0; 2])] {
            w.var(n, &mat::MatOut::column(&x));
        }
        w.var("theta_m", &mat::MatOut::row(&[2.0, 3.0]));
        std::fs::write(&csv, w.finish()).unwrap();
        let ds = loaders.load(&csv, &ColumnMap::capture()).unwrap();
        assert_eq!((ds.data.ts, ds.data.y.clone()), (0.5, vec![2.0, 3.0]));
        let mut v73 = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, HDF5 schema 1.00 .".to_vec();
        v73.resize(512, 0);
        v73.extend_from_slice(b"\x89HDF\r\n\x1a\n");
        std::fs::write(&mat, &v73).unwrap();
        let e = loaders.load(&mat, &ColumnMap::capture()).unwrap_err();
        assert!(
            e.to_string()
                .contains("MATLAB file (v7.3, HDF5): not supported yet"),
            "{e}"
        );
        // other binary content is not parsed as CSV
        std::fs::write(&mat, [0x7f, b'E', b'L', b'F', 0, 0]).unwrap();
        let e = loaders.load(&mat, &ColumnMap::capture()).unwrap_err();
        assert!(
            e.to_string().ends_with(
                "not a CSV text file: byte 4 is a NUL: binary content of an unknown type"
            ),
            "{e}"
        );
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
