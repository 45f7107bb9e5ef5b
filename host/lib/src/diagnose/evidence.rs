//! Stage 2, the evidence: where the nominal's validation residual lies (operating regions,
//! frequency bands), the odd/even non-excited lines of every periodic capture
//! ([`crate::ident::frf`]), with two estimation captures how distortion and gap change with
//! amplitude, and the nominal's residual at the non-excited odd lines that each model's
//! share is read against ([`locate::odd_explained`]).

use crate::data::{Dataset, IdData};
use crate::ident::frf::{amplitude_trend, ClassLevel, FrfAnalysis, Linearity};

use super::fits::{Fitted, Fitter};
use super::locate;
use super::metric::{score_segments, DrivenModel, Measured};
use super::{Amplitude, AmplitudeLevel, Distortion, Where};

/// What the nominal leaves, and where.
pub(super) struct Evidence {
    /// the residual's location, reported
    pub location: Where,
    /// the nominal's residual band-passed velocity over the scored range [rad/s]
    pub residual: Vec<f64>,
    /// the FRF analysis of each periodic capture, by name
    pub analyses: Vec<(String, FrfAnalysis)>,
    /// the nominal's residual at the non-excited odd lines of a periodic validation
    /// capture given as one record or, when that capture has no such line, of the first
    /// estimation capture that has ([`Evidence::odd_on`])
    pub odd_nominal: Option<ClassLevel>,
    /// the estimation capture the odd lines are read on, with its measured side, when the
    /// validation capture has none: a band-limited noise excites every line (an independent
    /// bench validates so). A linear model puts nothing at a line it is not driven at, in
    /// sample or out of it, so the nominal's residual there is the distortion all the same;
    /// each model's share of it is then read in sample. `None`: on the validation capture
    odd_on: Option<(Dataset, Measured)>,
    /// the odd-line record's settling periods
    settle_periods: usize,
}

impl Evidence {
    /// The share of the nominal's odd-line residual the model `f` removes, on the capture the
    /// odd lines are read on ([`Evidence::odd_level`]).
    pub fn odd_of(&self, val: &Dataset, f: &Fitted) -> Option<f64> {
        locate::odd_explained(self.odd_nominal.as_ref()?, &self.odd_level(val, f)?)
    }

    /// The residual the model `f` leaves at the non-excited odd lines, read as the
    /// nominal's is: on `val` (the validation record) when it is periodic, else on the
    /// estimation capture of [`Evidence::odd_on`], in sample.
    pub fn odd_level(&self, val: &Dataset, f: &Fitted) -> Option<ClassLevel> {
        self.odd_nominal.as_ref()?;
        match &self.odd_on {
            None => locate::odd_residual(val, &f.scored.driven.theta_m, self.settle_periods),
            Some((est, measured)) => {
                let s = measured
                    .score(&DrivenModel::of_fit(&f.fit), &est.data, 1)
                    .ok()?;
                locate::odd_residual(est, &s.driven.theta_m, self.settle_periods)
            }
        }
    }

    /// Whether the odd lines are read in sample, on an estimation capture
    /// ([`Evidence::odd_on`]).
    pub fn odd_in_sample(&self) -> bool {
        self.odd_on.is_some()
    }

    /// The capture the odd lines are read on, in words ([`Evidence::odd_on`]).
    pub fn odd_lines_of(&self) -> String {
        match &self.odd_on {
            None => "the validation capture".to_string(),
            Some((d, _)) => format!(
                "the estimation capture {} (the validation capture has none: it excites every \
                 line), in sample",
                d.name
            ),
        }
    }
}

/// The evidence of the nominal `nominal` on the records of `fitter`.
pub(super) fn gather(fitter: &Fitter<'_>, nominal: &Fitted) -> Evidence {
    let (rec, o) = (fitter.rec, &fitter.req.options);
    let (measured, val, s) = (&rec.measured, &rec.val, rec.measured.skip);
    let residual: Vec<f64> = measured.velocity[s..]
        .iter()
        .zip(&nominal.scored.velocity[s..])
        .map(|(a, b)| a - b)
        .collect();
    let regions = locate::regions(
        &residual,
        &val.data.u[s..],
        &val.data.y[s..],
        &nominal.scored.driven.omega_m[s..],
        &nominal.scored.driven.gearbox_deflection[s..],
    );
    let bands = locate::bands(&residual, &measured.velocity[s..], rec.ts);
    let mut distortion = Vec::new();
    let mut lin_of: Vec<Option<Linearity>> = Vec::new();
    let mut analyses: Vec<(String, FrfAnalysis)> = Vec::new();
    for (name, a) in fitter.starts.analyses.iter().cloned() {
        let lin = a.as_ref().map(|a| a.linearity_y.clone());
        if let Some(l) = &lin {
            distortion.push(Distortion {
                capture: name.clone(),
                linearity: l.clone(),
            });
        }
        if let Some(a) = a {
            analyses.push((name, a));
        }
        lin_of.push(lin);
    }
    let amplitude = (rec.est.len() == 2).then(|| amplitude(fitter, nominal, &lin_of));
    let on_val = match rec.val_segs {
        [one] => locate::odd_residual(one, &nominal.scored.driven.theta_m, o.settle_periods),
        _ => None,
    };
    let (odd_nominal, odd_on) = match on_val {
        Some(c) if c.lines > 0 => (Some(c), None),
        _ => match odd_on_estimation(fitter, nominal) {
            Some((c, on)) => (Some(c), Some(on)),
            None => (on_val, None),
        },
    };
    Evidence {
        location: Where {
            bands_hz: bands,
            regions,
            amplitude,
            distortion,
        },
        residual,
        analyses,
        odd_nominal,
        odd_on,
        settle_periods: o.settle_periods,
    }
}

/// The nominal's residual at the non-excited odd lines of the first estimation capture
/// given as one periodic record that has such lines, in sample ([`Evidence::odd_on`]), with
/// that capture and its measured side.
fn odd_on_estimation(
    fitter: &Fitter<'_>,
    nominal: &Fitted,
) -> Option<(ClassLevel, (Dataset, Measured))> {
    let o = &fitter.req.options;
    let model = DrivenModel::of_fit(&nominal.fit);
    fitter.rec.est.iter().find_map(|segs| {
        let [one] = segs else { return None };
        one.excitation.as_ref()?;
        let measured = o.measured(&one.data);
        let s = measured.score(&model, &one.data, 1).ok()?;
        let c = locate::odd_residual(one, &s.driven.theta_m, o.settle_periods)?;
        (c.lines > 0).then(|| (c, (one.clone(), measured)))
    })
}

/// How the nominal's gap and the odd distortion (`lin_of`, by capture) change from the
/// smaller to the larger of the two estimation captures.
fn amplitude(fitter: &Fitter<'_>, nominal: &Fitted, lin_of: &[Option<Linearity>]) -> Amplitude {
    let (rec, o) = (fitter.rec, &fitter.req.options);
    let nom_model = DrivenModel::of_fit(&nominal.fit);
    let skip0 = o.skip_of(&rec.val_segs[0].data);
    let mut levels = Vec::new();
    for segs in rec.est {
        let ms: Vec<Measured> = segs
            .iter()
            .map(|ds| {
                Measured::new(&ds.data, o.band_hz, skip0.min(ds.data.len() / 4))
                    .with_tracking(o.tracking_hz)
            })
            .collect();
        let data: Vec<IdData> = segs.iter().map(|d| d.data.clone()).collect();
        let gap = score_segments(&ms, &nom_model, &data, 1)
            .map(|sc| 100.0 - sc.fit)
            .unwrap_or(f64::NAN);
        let u: Vec<f64> = segs.iter().flat_map(|d| d.data.u.iter().copied()).collect();
        levels.push(AmplitudeLevel {
            capture: segs[0].name.clone(),
            u_rms: rms(&u),
            gap,
        });
    }
    let swap = levels[0].u_rms > levels[1].u_rms;
    let (lo, hi) = if swap { (1, 0) } else { (0, 1) };
    let distortion = match (&lin_of[lo], &lin_of[hi]) {
        (Some(a), Some(b)) => Some(amplitude_trend(a, b)),
        _ => None,
    };
    let dg = levels[hi].gap - levels[lo].gap;
    let gap_trend = if dg > 1.0 {
        "grows"
    } else if dg < -1.0 {
        "falls"
    } else {
        "unclear"
    };
    if swap {
        levels.swap(0, 1);
    }
    Amplitude {
        levels,
        distortion,
        gap_trend: gap_trend.into(),
        bla: fitter
            .starts
            .nonlinearity
            .as_ref()
            .and_then(|n| n.bla.clone()),
    }
}

fn rms(x: &[f64]) -> f64 {
    (x.iter().map(|v| v * v).sum::<f64>() / x.len().max(1) as f64).sqrt()
}

impl Evidence {
    /// The nominal's residual at the non-excited odd lines against the noise [dB], when it
    /// stands at least [`locate::ODD_RESIDUAL_ABOVE_NOISE_DB`] above it: odd distortion a
    /// linear model cannot follow.
    pub fn odd_left_db(&self) -> Option<f64> {
        self.odd_nominal
            .as_ref()
            .filter(|n| n.vs_noise_db >= locate::ODD_RESIDUAL_ABOVE_NOISE_DB)
            .map(|n| n.vs_noise_db)
    }
}
