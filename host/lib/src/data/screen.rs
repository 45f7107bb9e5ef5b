//! Samples far outside their record: a flipped bit, a logger's glitch, `1e300` typed into
//! a CSV. One such sample spoils an FRF (every line gets its spectrum) and a least-squares
//! fit (its square outweighs the record), and a value near the largest `f64` makes sums
//! of squares overflow, so results turn NaN or an iteration never ends. [`outliers`]
//! finds them, so that a check refuses them and a fit is refused before it starts, naming
//! each by its row.
//!
//! The scale is robust, so the outliers cannot hide by inflating it: the median absolute
//! deviation (MAD) from the column's median, times 1.4826 (a normal distribution's σ); a
//! sample counts when it lies more than [`OUTLIER_SIGMAS`] of those from the median. The
//! measured signals of the reference data (seed 001's records, EMPS, DaISy's robot arm)
//! reach at most 5 such σ; a normal distribution passes 8 σ once in 10¹⁵ samples.
//! Whatever the scale, a value of magnitude [`MAX_MAGNITUDE`] or more, and one that is
//! not finite, counts too.
// Units in brackets (`[s]`) are not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

use serde::Serialize;

use super::Dataset;

/// Distance from the column's median, in robust standard deviations (1.4826 × MAD), beyond
/// which a sample is an outlier: ten times what the reference data reach.
pub const OUTLIER_SIGMAS: f64 = 50.0;

/// Magnitude from which a value is an outlier whatever the record's scale: its square
/// summed over a record comes within reach of the largest `f64` (1.8e308), no unit of a
/// torque, force, angle or position gets near it.
pub const MAX_MAGNITUDE: f64 = 1e100;

/// Most samples the median and the MAD are taken from (evenly spaced through the record):
/// the scale of a ten-million-row file without a copy of each column.
const SCALE_SAMPLES: usize = 1 << 20;

/// Which signal of a record a sample belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Signal {
    /// the input `u`
    Input,
    /// the output `y` (`theta_m`)
    Output,
    /// the reference `r` (`theta_ref`)
    Reference,
}

/// A sample far outside its column ([`outliers`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Outlier {
    /// its signal
    pub signal: Signal,
    /// its data row, from 1: the rows of every piece of the record in order (a CSV's
    /// data lines without comments and header, a capture's samples as `export` writes them)
    pub row: usize,
    /// its time [s]
    pub t_s: f64,
    /// its value
    pub value: f64,
    /// its distance from the column's median in robust standard deviations (`None`: not
    /// finite)
    pub sigmas: Option<f64>,
    /// the column's median
    pub median: f64,
    /// the column's robust standard deviation (1.4826 × MAD)
    pub sigma: f64,
}

impl Outlier {
    /// What is wrong with the value, after `column `NAME`: VALUE`: not finite, too large to
    /// compute with, or how far it lies.
    pub fn why(&self) -> String {
        if !self.value.is_finite() {
            return "not finite".into();
        }
        if self.value.abs() >= MAX_MAGNITUDE {
            return format!(
                "magnitude ≥ {MAX_MAGNITUDE:e}: too large to compute with (its square summed \
                 over a record nears the largest f64)"
            );
        }
        format!(
            "{} robust σ from the column's median {} (σ = 1.4826·MAD = {}); the limit is {} σ",
            sci(self.sigmas.unwrap_or(f64::INFINITY)),
            sci(self.median),
            sci(self.sigma),
            OUTLIER_SIGMAS
        )
    }
}

/// Most outliers [`outliers`] keeps (it counts them all): enough to name them, bounded
/// for a file that is garbage throughout.
pub const MAX_KEPT: usize = 1000;

/// `1.6e302`, `0.0061`: three significant digits.
fn sci(x: f64) -> String {
    if x == 0.0 || (1e-3..1e4).contains(&x.abs()) {
        super::fmt_sig(x, 3)
    } else if x.is_finite() {
        format!("{x:.2e}")
    } else {
        format!("{x}")
    }
}

/// Median of `v` (reordered); `v` not empty.
fn median(v: &mut [f64]) -> f64 {
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, f64::total_cmp);
    *m
}

/// The median and robust standard deviation of one signal over the pieces; `None` when it
/// holds no finite value. A column that is constant but for a few samples (MAD 0) takes
/// the mean absolute deviation from the median (× 1.2533, also σ for a normal
/// distribution) instead; a constant one has σ 0.
fn scale(pieces: &[&[f64]]) -> Option<(f64, f64)> {
    let n: usize = pieces.iter().map(|p| p.len()).sum();
    let step = n.div_ceil(SCALE_SAMPLES).max(1);
    let mut v: Vec<f64> = pieces
        .iter()
        .flat_map(|p| p.iter())
        .step_by(step)
        .copied()
        .filter(|x| x.is_finite())
        .collect();
    if v.is_empty() {
        return None;
    }
    let med = median(&mut v);
    for x in &mut v {
        *x = (*x - med).abs();
    }
    let mad = median(&mut v);
    if mad > 0.0 {
        return Some((med, 1.4826 * mad));
    }
    let mean_abs = v.iter().sum::<f64>() / v.len() as f64;
    Some((med, 1.2533 * mean_abs))
}

/// One signal of a piece, when it has it.
type SignalOf = fn(&Dataset) -> Option<&[f64]>;

/// The outliers of a record (its gap-free pieces in order) that `keep` accepts (those of
/// a selection: [`within`]): the first [`MAX_KEPT`] in signal then row order, and how
/// many there are. An outlier is a sample not finite, of magnitude [`MAX_MAGNITUDE`] or
/// more, or more than [`OUTLIER_SIGMAS`] robust standard deviations from its signal's
/// median over the whole record.
pub fn outliers(record: &[Dataset], keep: impl Fn(&Outlier) -> bool) -> (Vec<Outlier>, usize) {
    let signals: [(Signal, SignalOf); 3] = [
        (Signal::Input, |d| Some(&d.data.u)),
        (Signal::Output, |d| Some(&d.data.y)),
        (Signal::Reference, |d| d.data.r.as_deref()),
    ];
    let mut found = Vec::new();
    let mut count = 0;
    for (signal, of) in signals {
        let pieces: Vec<&[f64]> = record.iter().filter_map(of).collect();
        if pieces.len() != record.len() {
            continue;
        }
        let (median, sigma) = scale(&pieces).unwrap_or((0.0, 0.0));
        let mut row = 0;
        for (p, x) in record.iter().zip(&pieces) {
            for (k, &value) in x.iter().enumerate() {
                let sigmas = ((value - median).abs() / sigma).max(0.0);
                let bad = !value.is_finite()
                    || value.abs() >= MAX_MAGNITUDE
                    || (sigma > 0.0 && sigmas > OUTLIER_SIGMAS)
                    || (sigma == 0.0 && value != median);
                if !bad {
                    continue;
                }
                let o = Outlier {
                    signal,
                    row: row + k + 1,
                    t_s: p.t0 + k as f64 * p.data.ts,
                    value,
                    sigmas: value.is_finite().then_some(sigmas),
                    median,
                    sigma,
                };
                if keep(&o) {
                    count += 1;
                    if found.len() < MAX_KEPT {
                        found.push(o);
                    }
                }
            }
            row += x.len();
        }
    }
    (found, count)
}

/// Whether the sample of an outlier lies in `ds` (a piece of its record, or a window of
/// one).
pub fn within(o: &Outlier, ds: &Dataset) -> bool {
    let k = (o.t_s - ds.t0) / ds.data.ts;
    k > -0.5 && k < ds.data.len() as f64 - 0.5
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::IdData;

    fn record(u: Vec<f64>, y: Vec<f64>) -> Vec<Dataset> {
        vec![Dataset {
            name: "x.csv".into(),
            data: IdData {
                ts: 0.5,
                u,
                y,
                r: None,
            },
            t0: 1.0,
            excitation: None,
            meta: Default::default(),
        }]
    }

    fn wave(n: usize) -> Vec<f64> {
        (0..n)
            .map(|k| (0.37 * k as f64).sin() + 0.3 * (1.9 * k as f64).cos())
            .collect()
    }

    #[test]
    fn a_spike_is_found_at_its_row_and_time_and_the_clean_record_has_none() {
        let all = |_: &Outlier| true;
        assert_eq!(outliers(&record(wave(1000), wave(1000)), all).1, 0);
        let mut y = wave(1000);
        y[499] = 1e6;
        let (found, _) = outliers(&record(wave(1000), y), all);
        assert_eq!(found.len(), 1);
        let o = &found[0];
        assert_eq!(
            (o.signal, o.row, o.t_s, o.value),
            (Signal::Output, 500, 250.5, 1e6)
        );
        assert!(o.sigmas.unwrap() > 1e5, "{o:?}");
        assert!(o.why().ends_with("the limit is 50 σ"), "{}", o.why());
        // a value no sum of squares carries is one whatever the record's scale; the count
        // goes on beyond those kept
        let big = vec![3e100; 600];
        let (kept, count) = outliers(&record(big.clone(), big), all);
        assert_eq!((kept.len(), count), (MAX_KEPT, 1200));
        assert!(
            kept[0].why().starts_with("magnitude ≥ 1e100: too large"),
            "{}",
            kept[0].why()
        );
        // only those `keep` accepts: here the input's
        let (kept, count) = outliers(&record(vec![3e100; 5], wave(5)), |o| {
            o.signal == Signal::Input
        });
        assert_eq!((kept.len(), count), (5, 5));
    }

    #[test]
    fn a_sparse_pulse_is_within_the_fallback_scale_a_lone_sample_off_a_constant_is_outside() {
        // 10 % of the record at 1, the rest at 0: MAD 0, mean absolute deviation 0.1
        let pulse: Vec<f64> = (0..1000)
            .map(|k| f64::from(u8::from(k % 10 == 0)))
            .collect();
        assert_eq!(outliers(&record(pulse, wave(1000)), |_| true).1, 0);
        // one sample off a constant column: mean absolute deviation 0.005, 2.5 is 80 σ away
        let mut flat = vec![2.0; 100];
        flat[7] = 2.5;
        let (found, _) = outliers(&record(flat, wave(100)), |_| true);
        assert_eq!(found.len(), 1, "{found:?}");
        assert_eq!(
            (found[0].row, found[0].sigmas.map(f64::round)),
            (8, Some(80.0))
        );
    }
}
