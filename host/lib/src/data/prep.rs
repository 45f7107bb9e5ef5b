//! Preparation of a record before the estimators, in one order: detrend at the capture
//! rate, then decimate ([`Prep::apply`]). `jointid fit` prepares its data this way, the
//! model file records the [`Prep`] and `jointid validate` repeats it, and `validate
//! --simulated` prepares both columns alike.
// Units in brackets (`[s]`, `[Hz]`, `[dB]`) are not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

use serde::{Deserialize, Serialize};

use super::{DataError, IdData};

/// How [`detrend`] removes the trend (`none`, `mean` or `linear` in a model file and on
/// the command line).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Detrend {
    /// leave the data as they are
    #[default]
    None,
    /// subtract the mean
    Mean,
    /// subtract the least-squares straight line
    Linear,
}

impl Detrend {
    /// Every choice with its name and what it does, in the order of the enum.
    pub const ALL: [(Detrend, &'static str, &'static str); 3] = [
        (Detrend::None, "none", "leave the data as they are"),
        (Detrend::Mean, "mean", "subtract the mean"),
        (Detrend::Linear, "linear", "subtract the least-squares line"),
    ];

    /// The choice named `name` (`none`, `mean`, `linear`).
    pub fn from_name(name: &str) -> Option<Detrend> {
        Self::ALL.iter().find(|d| d.1 == name).map(|d| d.0)
    }
}

/// Preparation of a raw record: detrending at the capture rate, then decimation by
/// `decimate` ([`super::decimate`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Prep {
    /// decimation factor (0 and 1: none)
    pub decimate: usize,
    /// detrending: `none`, `mean` or `linear`
    pub detrend: Detrend,
}

impl Prep {
    /// `raw` detrended as asked, at the capture rate.
    pub fn detrended(&self, raw: &IdData) -> IdData {
        let mut r = raw.clone();
        r.detrend(self.detrend);
        r
    }

    /// `raw` detrended, then decimated.
    ///
    /// # Errors
    /// [`DataError::DecimationTooShort`] when the record is shorter than the anti-alias filter.
    pub fn apply(&self, raw: &IdData) -> Result<IdData, DataError> {
        self.detrended(raw).decimate(self.decimate.max(1))
    }
}

/// Removes the mean or the least-squares line from `x` in place (nothing for
/// [`Detrend::None`]).
pub fn detrend(x: &mut [f64], how: Detrend) {
    let n = x.len();
    if n == 0 || how == Detrend::None {
        return;
    }
    let nf = n as f64;
    let mean = x.iter().sum::<f64>() / nf;
    match how {
        Detrend::None => {}
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn detrend_linear_removes_a_line_exactly() {
        let mut x: Vec<f64> = (0..50).map(|k| 3.0 - 0.2 * k as f64).collect();
        detrend(&mut x, Detrend::Linear);
        assert!(x.iter().all(|v| v.abs() < 1e-12));
        let mut m = vec![1.0, 2.0, 6.0];
        detrend(&mut m, Detrend::Mean);
        assert_eq!(m, vec![-2.0, -1.0, 3.0]);
    }

    #[test]
    fn prep_detrends_at_the_capture_rate_then_decimates_and_keeps_the_model_file_names() {
        let raw = IdData {
            ts: 1e-3,
            u: (0..400)
                .map(|k| (k as f64 * 0.05).sin() + 0.01 * k as f64)
                .collect(),
            y: (0..400).map(|k| (k as f64 * 0.02).cos() + 3.0).collect(),
            r: None,
        };
        let prep = Prep {
            decimate: 4,
            detrend: Detrend::Linear,
        };
        let mut d = raw.clone();
        d.detrend(Detrend::Linear);
        assert_eq!(prep.apply(&raw).unwrap(), d.decimate(4).unwrap());
        assert_eq!(Prep::default().apply(&raw).unwrap(), raw);
        assert_eq!(
            serde_json::to_string(&prep).unwrap(),
            r#"{"decimate":4,"detrend":"linear"}"#
        );
        for (d, name, _) in Detrend::ALL {
            assert_eq!(Detrend::from_name(name), Some(d));
            assert_eq!(serde_json::to_string(&d).unwrap(), format!("\"{name}\""));
        }
    }
}
