//! The checks that turn a doubtful frequency-domain fit into [`FitWarning`]s (module docs
//! of [`super`]), the output-kind check from the FRF's top slope, and the periodic
//! steady-state FIT and residuals of a fitted response.

use super::*;

/// The checks of a finished fit (module docs; [`FitWarning`]).
pub(super) fn check(fit: &FrfFit, opts: &LmOptions, frf: &Frf) -> Vec<FitWarning> {
    let mut w = Vec::new();
    let names = fit.model.structure.param_names();
    let nm = names.len();
    if fit.lm.termination == Termination::MaxIterations {
        w.push(FitWarning::IterationLimit {
            iterations: fit.lm.iterations,
        });
    }
    let at: Vec<String> = fit
        .lm
        .at_bounds(opts)
        .into_iter()
        // a lag or delay of zero is an answer, not a bound hit
        .filter(|&i| i < nm || fit.lm.theta[i] > 0.0)
        .map(|i| match i {
            i if i < nm => names[i].to_string(),
            i if i == nm => "current-loop lag".into(),
            _ => "delay".into(),
        })
        .collect();
    if !at.is_empty() {
        w.push(FitWarning::AtBounds { names: at });
    }
    // above the noise, and large enough to matter: a misfit below
    // NEGLIGIBLE_MISFIT of the response (noise-free simulations, where the
    // "noise" is rounding) is not reported
    let ratio = fit.cost_ratio();
    let misfit = 1.0 - periodic_fit_percent(frf, &fit.freq_response(&frf.freq_hz)) / 100.0;
    let negligible = misfit.is_finite() && misfit < NEGLIGIBLE_MISFIT;
    if ratio > COST_RATIO_WARN && !negligible {
        w.push(FitWarning::CostAboveNoise { ratio });
    }
    let tol = |f: f64| PEAK_MATCH_REL * f + line_gap(frf, f);
    // peaks the model shows at the measured lines (the lines the FRF's own peaks were read
    // from: its noise and distortion kept)
    let seen = Frf {
        g: fit.freq_response(&frf.freq_hz),
        ..frf.clone()
    };
    let model_peaks = frf_peaks(&seen, fit.model.output);
    for p in &fit.peaks {
        // a bump the model's response has too (the corner of a large damping, for one)
        // is no missed mode
        let near = |f: f64| (f - p.freq_hz).abs() <= tol(p.freq_hz);
        if p.prominence_db >= MISSED_PEAK_DB
            && !fit.resonances_hz.iter().any(|&m| near(m))
            && !model_peaks
                .iter()
                .any(|m| near(m.freq_hz) && m.prominence_db >= 0.5 * p.prominence_db)
        {
            w.push(FitWarning::MissedResonance {
                freq_hz: p.freq_hz,
                prominence_db: p.prominence_db,
            });
        }
    }
    // peaks the model would show at the measured lines but the FRF does not
    for m in model_peaks {
        if m.prominence_db >= MISSED_PEAK_DB
            && !fit
                .peaks
                .iter()
                .any(|p| (m.freq_hz - p.freq_hz).abs() <= tol(m.freq_hz))
        {
            w.push(FitWarning::ExtraResonance { freq_hz: m.freq_hz });
        }
    }
    w.extend(distortion_check(frf));
    let expected = -20.0 * rigid_power(fit.model.output) as f64;
    w.extend(output_kind_check(frf, expected));
    for p in &fit.params {
        let rel = p.std / p.value.abs().max(f64::MIN_POSITIVE);
        if rel > POORLY_DETERMINED_REL {
            w.push(FitWarning::PoorlyDetermined {
                name: p.name.clone(),
                rel_std: rel,
            });
        }
    }
    w
}

/// Damping below which a black box's mode outside the reliable lines is
/// reported ([`unsupported_modes`]): a pair this light makes a peak, where a
/// better damped one below the band stands for the rigid-body poles.
const UNSUPPORTED_MODE_DAMPING: f64 = 0.2;

/// [`FitWarning::UnsupportedMode`] for each lightly damped mode of `model`
/// below 0.9 × the lowest reliable line or above 1.1 × the highest
/// ([`reliable_lines`]): the states a black box has beyond what the joint
/// needs go where no line holds them.
pub fn unsupported_modes(frf: &Frf, model: &crate::ident::ss::StateSpace) -> Vec<FitWarning> {
    let lines = reliable_lines(frf);
    let (Some(&lo), Some(&hi)) = (lines.first(), lines.last()) else {
        return Vec::new();
    };
    let band_hz = (frf.freq_hz[lo], frf.freq_hz[hi]);
    model
        .resonances(0.0, UNSUPPORTED_MODE_DAMPING)
        .resonances
        .into_iter()
        .filter(|m| m.freq_hz < 0.9 * band_hz.0 || m.freq_hz > 1.1 * band_hz.1)
        .map(|m| FitWarning::UnsupportedMode {
            freq_hz: m.freq_hz,
            damping: m.damping,
            band_hz,
        })
        .collect()
}

/// Share of excited lines on which the distortion dominates from which
/// [`FitWarning::Distortion`] is raised.
const DISTORTION_WARN_SHARE: f64 = 0.25;

/// [`FitWarning::Distortion`] when the odd distortion's variance exceeds three times the
/// noise's, and its σ [`NEGLIGIBLE_MISFIT`] of the response, on at least
/// `DISTORTION_WARN_SHARE` of the excited lines (a noise-free simulation's rounding stands
/// far above its noise and changes nothing).
pub fn distortion_check(frf: &Frf) -> Option<FitWarning> {
    let total = frf.sigma_total();
    let mut db: Vec<f64> = frf
        .sigma
        .iter()
        .zip(&total)
        .zip(&frf.g)
        .filter(|((s, t), g)| {
            let d2 = **t * **t - **s * **s;
            d2 > 3.0 * **s * **s && d2 > (NEGLIGIBLE_MISFIT * g.norm()).powi(2)
        })
        .map(|((s, t), _)| 10.0 * ((t * t - s * s) / (s * s).max(1e-300)).log10())
        .collect();
    let of = frf.g.len();
    if of == 0 || (db.len() as f64) < DISTORTION_WARN_SHARE * of as f64 {
        return None;
    }
    db.sort_by(f64::total_cmp);
    Some(FitWarning::Distortion {
        lines: db.len(),
        of,
        above_noise_db: db[db.len() / 2],
    })
}

/// Slope of `20 log10 |Ĝ|` against `log10 f` over the reliable lines of the
/// top half-decade of the band [dB/decade] (least squares; None with fewer
/// than four lines).
pub fn top_slope_db_per_decade(frf: &Frf) -> Option<f64> {
    let top = frf.freq_hz.last().copied()?;
    let pts: Vec<(f64, f64)> = reliable_lines(frf)
        .into_iter()
        .filter(|&i| frf.freq_hz[i] >= top / 10f64.sqrt())
        .map(|i| (frf.freq_hz[i].log10(), 20.0 * frf.g[i].norm().log10()))
        .collect();
    if pts.len() < 4 {
        return None;
    }
    let n = pts.len() as f64;
    let (mx, my) = (
        pts.iter().map(|p| p.0).sum::<f64>() / n,
        pts.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    (sxx > 0.0).then(|| sxy / sxx)
}

/// [`FitWarning::OutputKind`] when the FRF's top half-decade falls more than
/// 20 dB/decade more slowly than `expected_db_per_decade` (−40 for an angle
/// output of a strictly proper mechanical model, −20 for a velocity).
pub fn output_kind_check(frf: &Frf, expected_db_per_decade: f64) -> Option<FitWarning> {
    let measured = top_slope_db_per_decade(frf)?;
    (measured > expected_db_per_decade + 20.0).then_some(FitWarning::OutputKind {
        measured_db_per_decade: measured,
        expected_db_per_decade,
    })
}

/// widest spacing between the lines on either side of `f` [Hz]: a peak
/// can only be placed to within it
fn line_gap(frf: &Frf, f: f64) -> f64 {
    let i = frf.freq_hz.partition_point(|&x| x < f);
    let at = |j: usize| frf.freq_hz.get(j).copied();
    let mut gap: f64 = 0.0;
    for j in i.saturating_sub(1)..i + 1 {
        if let (Some(a), Some(b)) = (at(j), at(j + 1)) {
            gap = gap.max(b - a);
        }
    }
    gap
}

/// name of the FIT [`periodic_fit_percent`] computes
pub const PERIODIC_FIT_NAME: &str = "FIT of the period-averaged steady state at the reliable \
     excited lines (σ/|G| ≤ 10 %), 100·(1 − ‖Ȳ − G·Ū‖/‖Ȳ‖)";

/// FIT [%] of a model response `g` (at `frf.freq_hz`) on the period-averaged
/// steady state of the record `frf` came from, over its reliable lines
/// ([`reliable_lines`]): by Parseval, the time-domain FIT of that part of one
/// averaged period, mean removed. Slow disturbances and drift, which are not
/// synchronous with the excitation, do not enter it; the lowest lines, where
/// what is left of them still dominates the output (σ/|Ĝ| > 10 %), are left
/// out so that the figure measures the model and not the disturbance. NaN
/// when `frf` carries no spectra or no reliable line.
pub fn periodic_fit_percent(frf: &Frf, g: &[Complex64]) -> f64 {
    let s = &frf.spectra;
    if s.u.len() != g.len() || g.is_empty() {
        return f64::NAN;
    }
    let (mut e, mut d) = (0.0, 0.0);
    for k in reliable_lines(frf) {
        e += (s.y[k] - g[k] * s.u[k]).norm_sqr();
        d += s.y[k].norm_sqr();
    }
    crate::ident::validate::fit_from_sums(e, d)
}

/// The residuals the fit weighted, one per excited line of `frf`, `E|·|² = 1` at the
/// true model: the sample-maximum-likelihood residuals of the model whose response
/// `respond(f_hz)` gives (`Lines`); `(Ĝ − G)/σ` with [`Frf::sigma_total`] when the
/// FRF keeps no spectra. Also the number of real degrees of freedom of their variances.
pub fn line_residuals(
    frf: &Frf,
    respond: impl Fn(&[f64]) -> Vec<Complex64>,
) -> (Vec<Complex64>, f64) {
    // z is not used: the noise lines are evaluated by `respond`
    let lines = Lines::new(frf, 1.0);
    match &lines.spectra {
        Some(s) => (
            lines
                .sml_lines(s, &respond(&s.noise_freq_hz))
                .into_iter()
                .map(|l| l.e / l.var.sqrt())
                .collect(),
            s.dof(),
        ),
        None => {
            let g = respond(&frf.freq_hz);
            let e = frf
                .g
                .iter()
                .zip(&g)
                .zip(frf.sigma_total())
                .filter(|(_, s)| *s > 0.0)
                .map(|((m, g), s)| (m - g) / s)
                .collect();
            (e, f64::INFINITY)
        }
    }
}

/// What [`periodic_fit_percent`] compares, as one period of `period` samples: the
/// period-averaged output Ȳ and the model's G·Ū at the reliable lines only, synthesised
/// from the amplitude-scaled line spectra, `(ȳ, ŷ)`. By Parseval the toolbox FIT of `ŷ`
/// against `ȳ` is the periodic FIT (both have no mean). `None` when `frf` carries no
/// spectra or `g` does not match its lines.
pub fn periodic_fit_signals(
    frf: &Frf,
    g: &[Complex64],
    period: usize,
) -> Option<(Vec<f64>, Vec<f64>)> {
    let s = &frf.spectra;
    if s.u.len() != g.len() || g.is_empty() || frf.lines.len() != g.len() || period < 2 {
        return None;
    }
    let lines: Vec<(f64, Complex64, Complex64)> = reliable_lines(frf)
        .into_iter()
        .filter(|&k| frf.lines[k] > 0 && 2 * (frf.lines[k] as usize) < period)
        .map(|k| {
            let w = 2.0 * std::f64::consts::PI * f64::from(frf.lines[k]) / period as f64;
            (w, s.y[k], g[k] * s.u[k])
        })
        .collect();
    let at = |t: usize, pick: fn(&(f64, Complex64, Complex64)) -> Complex64| {
        lines
            .iter()
            .map(|l| (pick(l) * Complex64::from_polar(1.0, l.0 * t as f64)).re)
            .sum::<f64>()
    };
    let y = (0..period).map(|t| at(t, |l| l.1)).collect();
    let y_hat = (0..period).map(|t| at(t, |l| l.2)).collect();
    Some((y, y_hat))
}

/// One period of the periodic steady state (see [`periodic_steady_state`]).
#[derive(Clone, Debug, PartialEq)]
pub struct SteadyState {
    /// period-averaged input, mean removed [input unit]
    pub u: Vec<f64>,
    /// period-averaged output, mean removed [output unit]
    pub y: Vec<f64>,
    /// the model's periodic response to `u` [output unit]
    pub y_hat: Vec<f64>,
}

/// One period of the steady state: the period-averaged input `ū` and output
/// `ȳ` of `data` over `layout` (means removed) and the model's periodic
/// response `ŷ` to `ū`, from the model response `response(f_hz)` at every
/// line 1 … N/2. What [`crate::ident::validate::validate`] needs for residual
/// tests that slow disturbances and drift do not dominate.
///
/// # Errors
/// [`crate::ident::frf::FrfError::OutOfRange`] when the layout does not fit the data.
pub fn periodic_steady_state(
    data: &crate::data::IdData,
    layout: &crate::data::PeriodLayout,
    response: impl Fn(&[f64]) -> Vec<Complex64>,
) -> Result<SteadyState, crate::ident::frf::FrfError> {
    let n = layout.period;
    let range = layout.range();
    if range.end > data.len() || n < 2 || layout.count == 0 {
        return Err(crate::ident::frf::FrfError::OutOfRange {
            start: range.start,
            end: range.end,
            len: data.len(),
        });
    }
    let avg = |x: &[f64]| -> Vec<f64> {
        let mut a = vec![0.0; n];
        for p in 0..layout.count {
            let s = layout.start + p * n;
            for (ai, xi) in a.iter_mut().zip(&x[s..s + n]) {
                *ai += xi / layout.count as f64;
            }
        }
        let m = a.iter().sum::<f64>() / n as f64;
        a.iter_mut().for_each(|v| *v -= m);
        a
    };
    let (ub, yb) = (avg(&data.u), avg(&data.y));
    let mut planner = rustfft::FftPlanner::<f64>::new();
    let mut buf: Vec<Complex64> = ub.iter().map(|v| Complex64::new(*v, 0.0)).collect();
    planner.plan_fft_forward(n).process(&mut buf);
    let f0 = 1.0 / (n as f64 * data.ts);
    let freqs: Vec<f64> = (1..=n / 2).map(|k| k as f64 * f0).collect();
    let g = response(&freqs);
    buf[0] = Complex64::new(0.0, 0.0);
    for k in 1..=n / 2 {
        buf[k] *= g[k - 1];
        if k != n - k {
            buf[n - k] = buf[k].conj();
        }
    }
    planner.plan_fft_inverse(n).process(&mut buf);
    Ok(SteadyState {
        u: ub,
        y: yb,
        y_hat: buf.iter().map(|c| c.re / n as f64).collect(),
    })
}
