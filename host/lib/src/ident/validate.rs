//! Model validation: simulation fit, residual analysis and Bode comparison
//! data.
//!
//! - FIT as the System Identification Toolbox's `compare` reports it,
//!   `100·(1 − ‖y − ŷ‖ / ‖y − mean(y)‖)` [%] with ŷ the simulated output
//!   (../shared/DESIGN.md §7). Seed 000 eq. (16) prints a variance ratio instead; the
//!   paper used the toolbox, so the toolbox definition is the one used and
//!   it is named [`FIT_NAME`] wherever shown.
//! - Residual analysis after Ljung, *System Identification: Theory for the
//!   User*, 2nd ed. (1999), §16.6: the normalised autocorrelation of
//!   ε = y − ŷ at lags 1 … M must stay inside ±2.58/√N (99 %, whiteness),
//!   and the normalised cross-correlation of ε with past inputs u(t − τ),
//!   τ = 0 … M, inside ±2.58·√(Σ_k r_ε(k) r_u(k) / N) (independence; the sum
//!   widens the bound for coloured signals). In closed loop ε correlates with
//!   *future* inputs through the feedback, so only τ ≥ 0 is tested.
//! - A test passes when both of its figures say so, so that the verdict
//!   follows every number printed beside it:
//!   - the lags outside the per-lag 99 % band are no more than chance
//!     allows: at most [`CorrelationTest::allowed`], the 99 % quantile of the
//!     binomial count of lags outside when each falls outside with
//!     probability 1 % ([`allowed_outside`]; 2 of 26 lags);
//!   - Ljung's portmanteau χ² test at 1 % (same section): whiteness
//!     ζ = N Σ_{k=1..M} r_ε(k)² against χ²(M); independence
//!     ζ = N R̂_εuᵀ R̂_u⁻¹ R̂_εu / R̂_ε(0) against χ²(M+1), with R̂_εu the
//!     cross-covariances at τ = 0 … M and R̂_u the (M+1)×(M+1) Toeplitz
//!     autocovariance matrix of u. It can fail with no lag outside the band
//!     (many lags each just inside it).
//! - A residual with a NaN or infinite sample (a model whose simulation
//!   diverged) fails both tests: its correlations are NaN, every lag counts
//!   as outside, ζ is infinite ([`CorrelationTest::non_finite`] counts the
//!   samples). A FIT that is not finite fails [`Validation::pass`].
//! - Bode comparison: a measured FRF with its σ against model responses;
//!   per model, the share of lines where the model lies outside ±2σ.
// Units in brackets (`[s]`, `[Hz]`, `[dB]`) are not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

use rustfft::num_complex::Complex64;

use serde::Serialize;

/// A fit's cost above this multiple of its expected value (the noise level) is reported:
/// the frequency-domain fits warn, and the line residual test takes it as its bound.
pub const COST_RATIO_WARN: f64 = 2.0;

/// how a fit figure is labelled wherever it is shown
pub const FIT_NAME: &str = "FIT (toolbox compare, NRMSE) [%]";

/// 99 % two-sided normal quantile used for the correlation bounds
pub const Z99: f64 = 2.58;

/// Errors of validation.
#[derive(Debug, PartialEq, thiserror::Error)]
pub enum ValidateError {
    /// measured and simulated outputs differ in length
    #[error("measured output has {measured} samples, simulated {simulated}")]
    LengthMismatch {
        /// samples of y
        measured: usize,
        /// samples of ŷ
        simulated: usize,
    },
    /// not enough samples for the requested lags
    #[error("{samples} samples are too few for {lags} lags (need more than twice as many)")]
    TooShort {
        /// samples
        samples: usize,
        /// lags
        lags: usize,
    },
    /// y is constant: FIT undefined
    #[error("measured output is constant: fit undefined")]
    ConstantOutput,
}

/// FIT [%] as the toolbox's `compare`: `100·(1 − ‖y − ŷ‖ / ‖y − mean(y)‖)`.
///
/// # Errors
/// [`ValidateError::LengthMismatch`], [`ValidateError::ConstantOutput`].
pub fn fit_percent(y: &[f64], yhat: &[f64]) -> Result<f64, ValidateError> {
    if y.len() != yhat.len() {
        return Err(ValidateError::LengthMismatch {
            measured: y.len(),
            simulated: yhat.len(),
        });
    }
    let den = centred_sum_of_squares(y);
    if den == 0.0 {
        return Err(ValidateError::ConstantOutput);
    }
    let num: f64 = y.iter().zip(yhat).map(|(a, b)| (a - b).powi(2)).sum();
    Ok(fit_from_sums(num, den))
}

/// `Σ (y − mean(y))²`, the denominator of the FIT (squared).
pub fn centred_sum_of_squares(y: &[f64]) -> f64 {
    let mean = y.iter().sum::<f64>() / y.len().max(1) as f64;
    y.iter().map(|v| (v - mean).powi(2)).sum()
}

/// FIT [%] from the residual sum of squares `ssr` and [`centred_sum_of_squares`] `ss_tot`
/// of the measured output, for a caller that has the sums already (an optimiser's cost).
pub fn fit_from_sums(ssr: f64, ss_tot: f64) -> f64 {
    100.0 * (1.0 - (ssr / ss_tot).sqrt())
}

/// One correlation test: values per lag against a bound.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CorrelationTest {
    /// what is tested
    pub name: String,
    /// lags [samples]
    pub lags: Vec<i64>,
    /// normalised correlation per lag
    pub values: Vec<f64>,
    /// 99 % bound (symmetric)
    pub bound: f64,
    /// largest |value|
    pub max_abs: f64,
    /// what `lags` count: "lags" [samples], or "lines" (excited lines, [`line_residual_test`])
    pub unit: &'static str,
    /// lags outside the bound (a NaN value counts as outside)
    pub outside: usize,
    /// most lags outside the bound that the test accepts ([`allowed_outside`])
    pub allowed: usize,
    /// residual samples that are NaN or infinite (any fails the test)
    pub non_finite: usize,
    /// portmanteau statistic ζ
    pub statistic: f64,
    /// degrees of freedom of its χ² distribution
    pub dof: usize,
    /// 99 % quantile of χ²(dof)
    pub critical: f64,
    /// no residual sample is NaN or infinite, `outside <= allowed` and
    /// `statistic <= critical`
    pub pass: bool,
}

impl CorrelationTest {
    /// Why the test failed, in words and figures; `None` when it passed.
    pub fn failure(&self) -> Option<String> {
        if self.non_finite > 0 {
            return Some(format!(
                "{} residual samples are NaN or infinite",
                self.non_finite
            ));
        }
        let mut why = Vec::new();
        if self.outside > self.allowed {
            why.push(format!(
                "{} of {} {} outside the band, at most {} allowed",
                self.outside,
                self.lags.len(),
                self.unit,
                self.allowed
            ));
        }
        if self.statistic > self.critical || self.statistic.is_nan() {
            why.push(format!(
                "ζ = {:.1} above χ²({}) 99 % = {:.1}",
                self.statistic, self.dof, self.critical
            ));
        }
        (!self.pass).then(|| why.join("; "))
    }
}

/// Most of `lags` lags that may fall outside their 99 % band by chance: the
/// smallest k with P(X ≤ k) ≥ 0.99 for X ~ Binomial(`lags`, 0.01).
pub fn allowed_outside(lags: usize) -> usize {
    let p: f64 = 0.01;
    // P(X = 0), then P(X = k + 1) = P(X = k) (n − k)/(k + 1) p/(1 − p)
    let mut pmf = (1.0 - p).powi(i32::try_from(lags).unwrap_or(i32::MAX));
    let mut cdf = pmf;
    let mut k = 0;
    while cdf < 0.99 && k < lags {
        pmf *= (lags - k) as f64 / (k + 1) as f64 * p / (1.0 - p);
        cdf += pmf;
        k += 1;
    }
    k
}

/// 99 % quantile of χ²(ν), Wilson–Hilferty approximation
/// `ν (1 − 2/(9ν) + 2.326 √(2/(9ν)))³` (relative error below 1 % for ν ≥ 5).
pub fn chi2_quantile_99(nu: usize) -> f64 {
    let nu = nu.max(1) as f64;
    let a = 2.0 / (9.0 * nu);
    nu * (1.0 - a + 2.326 * a.sqrt()).powi(3)
}

/// biased sample cross-covariance Σ a(t) b(t − τ) / N for τ ≥ 0
fn xcov(a: &[f64], b: &[f64], tau: usize) -> f64 {
    let n = a.len();
    (tau..n).map(|t| a[t] * b[t - tau]).sum::<f64>() / n as f64
}

fn centred(x: &[f64]) -> Vec<f64> {
    let m = x.iter().sum::<f64>() / x.len().max(1) as f64;
    x.iter().map(|v| v - m).collect()
}

/// Whiteness of `e`: normalised autocorrelation at lags 1 … `m` against
/// ±2.58/√N.
///
/// # Errors
/// [`ValidateError::TooShort`] when N ≤ 2m.
pub fn whiteness_test(e: &[f64], m: usize) -> Result<CorrelationTest, ValidateError> {
    let n = e.len();
    if n <= 2 * m || m == 0 {
        return Err(ValidateError::TooShort {
            samples: n,
            lags: m,
        });
    }
    let non_finite = count_non_finite(e);
    if non_finite > 0 {
        return Ok(not_finite(
            "residual autocorrelation",
            (1..=m as i64).collect(),
            Z99 / (n as f64).sqrt(),
            m,
            non_finite,
        ));
    }
    let e = centred(e);
    let r0 = xcov(&e, &e, 0);
    let values: Vec<f64> = (1..=m)
        .map(|k| if r0 > 0.0 { xcov(&e, &e, k) / r0 } else { 0.0 })
        .collect();
    let statistic = n as f64 * values.iter().map(|v| v * v).sum::<f64>();
    Ok(finish(
        "residual autocorrelation",
        (1..=m as i64).collect(),
        values,
        Z99 / (n as f64).sqrt(),
        statistic,
        m,
    ))
}

/// Name of [`line_residual_test`].
pub const LINE_RESIDUAL_NAME: &str = "standardised line residuals |Ĝ − G|/σ (per excited line)";

/// The residual test of a fit to the FRF: the standardised residuals
/// `e_k = (Ĝ_k − G_k)/σ_k` at the K excited lines (in `values`, the line index in `lags`)
/// against the 99 % bound of `|e_k|` for a right model, where `|e_k|²/1` is F(2, ν)
/// distributed, σ_k² estimated with `nu` real degrees of freedom (exponential for
/// `nu = ∞`): `|e|² ≤ (ν/2)(0.01^{−2/ν} − 1)`. Lines outside are counted against
/// [`allowed_outside`]; the level of all lines, `2 Σ |e_k|² (ν − 2)/ν` (mean 2K), against
/// [`COST_RATIO_WARN`] times 2K, where the fit itself warns that its cost is above the
/// noise: a χ² quantile would be too narrow, as the F-distributed `|e_k|²` of
/// estimated variances spread more than a χ² (1.5 times its variance at ν = 12).
///
/// This is what the fit assumed: independent line errors of variance σ_k² (Pintelon &
/// Schoukens 2012, §8.3, the residual analysis of a frequency-domain fit). A correlation
/// over the lines cannot serve: a missed resonance puts nearly all the misfit on one or
/// two lines, which no normalised correlation sees; nor can the time-domain
/// autocorrelation of the same residual, near 1 at every short lag of a low-pass band
/// whatever the model.
///
/// # Errors
/// [`ValidateError::TooShort`] when there is no line.
pub fn line_residual_test(e: &[Complex64], nu: f64) -> Result<CorrelationTest, ValidateError> {
    let k = e.len();
    if k == 0 {
        return Err(ValidateError::TooShort {
            samples: 0,
            lags: 1,
        });
    }
    let lags: Vec<i64> = (0..k as i64).collect();
    let q = if nu.is_finite() && nu > 2.0 {
        nu / 2.0 * (0.01f64.powf(-2.0 / nu) - 1.0)
    } else {
        -(0.01f64.ln())
    };
    let bound = q.sqrt();
    let non_finite = e
        .iter()
        .filter(|v| !(v.re.is_finite() && v.im.is_finite()))
        .count();
    if non_finite > 0 {
        let mut t = not_finite(LINE_RESIDUAL_NAME, lags, bound, 2 * k, non_finite);
        t.unit = "lines";
        return Ok(t);
    }
    let values: Vec<f64> = e.iter().map(|v| v.norm()).collect();
    let shrink = if nu.is_finite() && nu > 2.0 {
        (nu - 2.0) / nu
    } else {
        1.0
    };
    let statistic = 2.0 * shrink * e.iter().map(|v| v.norm_sqr()).sum::<f64>();
    let mut t = finish(LINE_RESIDUAL_NAME, lags, values, bound, statistic, 2 * k);
    t.critical = COST_RATIO_WARN * (2 * k) as f64;
    t.unit = "lines";
    t.pass = t.outside <= t.allowed && t.statistic <= t.critical;
    Ok(t)
}

/// Independence of `e` from past inputs: normalised cross-correlation
/// r_εu(τ) = R_εu(τ)/√(R_ε(0) R_u(0)), R_εu(τ) = Σ ε(t) u(t − τ)/N, τ = 0 … `m`,
/// against ±2.58·√(Σ_{|k|≤m} r_ε(k) r_u(k) / N).
///
/// # Errors
/// [`ValidateError::TooShort`], [`ValidateError::LengthMismatch`].
pub fn input_independence_test(
    e: &[f64],
    u: &[f64],
    m: usize,
) -> Result<CorrelationTest, ValidateError> {
    let n = e.len();
    if u.len() != n {
        return Err(ValidateError::LengthMismatch {
            measured: u.len(),
            simulated: n,
        });
    }
    if n <= 2 * m || m == 0 {
        return Err(ValidateError::TooShort {
            samples: n,
            lags: m,
        });
    }
    let non_finite = count_non_finite(e);
    if non_finite > 0 {
        return Ok(not_finite(
            "residual-input cross-correlation (past inputs)",
            (0..=m as i64).collect(),
            Z99 / (n as f64).sqrt(),
            m + 1,
            non_finite,
        ));
    }
    let (e, u) = (centred(e), centred(u));
    let (re0, ru0) = (xcov(&e, &e, 0), xcov(&u, &u, 0));
    let norm = (re0 * ru0).sqrt();
    let values: Vec<f64> = (0..=m)
        .map(|k| {
            if norm > 0.0 {
                xcov(&e, &u, k) / norm
            } else {
                0.0
            }
        })
        .collect();
    let mut p1 = 1.0;
    if re0 > 0.0 && ru0 > 0.0 {
        for k in 1..=m {
            p1 += 2.0 * (xcov(&e, &e, k) / re0) * (xcov(&u, &u, k) / ru0);
        }
    }
    let ru = nalgebra::DMatrix::from_fn(m + 1, m + 1, |i, j| xcov(&u, &u, i.abs_diff(j)));
    let reu = nalgebra::DVector::from_fn(m + 1, |k, _| xcov(&e, &u, k));
    let statistic = match (ru.cholesky(), re0 > 0.0) {
        (Some(ch), true) => n as f64 * reu.dot(&ch.solve(&reu)) / re0,
        // u without excitation at these lags, or ε ≡ 0: nothing to test
        _ => 0.0,
    };
    Ok(finish(
        "residual-input cross-correlation (past inputs)",
        (0..=m as i64).collect(),
        values,
        Z99 * (p1.max(1e-12) / n as f64).sqrt(),
        statistic,
        m + 1,
    ))
}

fn count_non_finite(e: &[f64]) -> usize {
    e.iter().filter(|v| !v.is_finite()).count()
}

/// The failed test of a residual with `non_finite` NaN or infinite samples.
fn not_finite(
    name: &str,
    lags: Vec<i64>,
    bound: f64,
    dof: usize,
    non_finite: usize,
) -> CorrelationTest {
    let m = lags.len();
    CorrelationTest {
        name: name.into(),
        values: vec![f64::NAN; m],
        lags,
        bound,
        max_abs: f64::NAN,
        unit: "lags",
        outside: m,
        allowed: allowed_outside(m),
        non_finite,
        statistic: f64::INFINITY,
        dof,
        critical: chi2_quantile_99(dof),
        pass: false,
    }
}

fn finish(
    name: &str,
    lags: Vec<i64>,
    values: Vec<f64>,
    bound: f64,
    statistic: f64,
    dof: usize,
) -> CorrelationTest {
    // a NaN value counts as outside
    let outside = values
        .iter()
        .filter(|v| v.abs() > bound || v.is_nan())
        .count();
    let allowed = allowed_outside(values.len());
    let critical = chi2_quantile_99(dof);
    CorrelationTest {
        name: name.into(),
        lags,
        max_abs: values.iter().fold(0.0, |a, v| a.max(v.abs())),
        values,
        bound,
        unit: "lags",
        outside,
        allowed,
        non_finite: 0,
        statistic,
        dof,
        critical,
        pass: outside <= allowed && statistic <= critical,
    }
}

/// Result of [`validate`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Validation {
    /// label of the fit figure, [`FIT_NAME`]
    pub fit_name: String,
    /// FIT [%], toolbox `compare` definition
    pub fit: f64,
    /// residual whiteness test
    pub whiteness: CorrelationTest,
    /// residual / past-input independence test
    pub independence: CorrelationTest,
    /// FIT is finite and both residual tests pass
    pub pass: bool,
}

/// default number of lags M for the residual tests (as the toolbox's `resid`)
pub const DEFAULT_LAGS: usize = 25;

/// FIT and residual tests of a simulated output `yhat` against `y` with input `u`.
///
/// # Errors
/// As [`fit_percent`], [`whiteness_test`], [`input_independence_test`].
pub fn validate(
    u: &[f64],
    y: &[f64],
    yhat: &[f64],
    lags: usize,
) -> Result<Validation, ValidateError> {
    validation(u, y, yhat, lags, |e| whiteness_test(e, lags))
}

/// FIT, the input independence of `y − yhat`, and `whiteness` of it.
fn validation(
    u: &[f64],
    y: &[f64],
    yhat: &[f64],
    lags: usize,
    whiteness: impl FnOnce(&[f64]) -> Result<CorrelationTest, ValidateError>,
) -> Result<Validation, ValidateError> {
    let fit = fit_percent(y, yhat)?;
    let e: Vec<f64> = y.iter().zip(yhat).map(|(a, b)| a - b).collect();
    let whiteness = whiteness(&e)?;
    let independence = input_independence_test(&e, u, lags)?;
    Ok(Validation {
        fit_name: FIT_NAME.into(),
        fit,
        pass: fit.is_finite() && whiteness.pass && independence.pass,
        whiteness,
        independence,
    })
}

/// FIT and residual tests of a frequency-domain fit on a periodic record: the FIT and the
/// input independence on one steady-state period (`u`, `y`, `yhat`: slow disturbances and
/// drift averaged out); in the place of whiteness, the standardised line residuals
/// `line_e` against their bound ([`line_residual_test`], σ² with `nu` degrees of freedom).
///
/// # Errors
/// As [`fit_percent`], [`line_residual_test`], [`input_independence_test`].
pub fn validate_periodic(
    u: &[f64],
    y: &[f64],
    yhat: &[f64],
    line_e: &[Complex64],
    nu: f64,
    lags: usize,
) -> Result<Validation, ValidateError> {
    validation(u, y, yhat, lags, |_| line_residual_test(line_e, nu))
}

/// A model's frequency response for Bode plots and comparison.
#[derive(Clone, Debug, PartialEq)]
pub struct BodeCurve {
    /// legend name
    pub name: String,
    /// frequencies [Hz]
    pub freq_hz: Vec<f64>,
    /// complex response at each frequency [output unit / input unit]
    pub response: Vec<Complex64>,
}

/// A measured FRF with its standard deviation, as the plots and comparisons
/// take it.
#[derive(Clone, Debug, PartialEq)]
pub struct FrfBand {
    /// frequencies [Hz]
    pub freq_hz: Vec<f64>,
    /// estimate [output unit / input unit]
    pub g: Vec<Complex64>,
    /// standard deviation (complex) [output unit / input unit]
    pub sigma: Vec<f64>,
}

impl From<&crate::ident::frf::Frf> for FrfBand {
    fn from(f: &crate::ident::frf::Frf) -> Self {
        FrfBand {
            freq_hz: f.freq_hz.clone(),
            g: f.g.clone(),
            sigma: f.sigma.clone(),
        }
    }
}

/// How one model departs from the measured FRF.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BodeMismatch {
    /// model name
    pub model: String,
    /// share of FRF lines where |G_model − Ĝ| > 2σ [0 … 1]
    pub outside_2sigma: f64,
    /// frequencies where the model leaves the ±2σ region [Hz]
    pub outside_freq_hz: Vec<f64>,
    /// RMS over the lines of 20·log10|G_model/Ĝ| [dB]
    pub rms_mag_error_db: f64,
}

/// Compares model responses with a measured FRF; each model must be
/// evaluated at the FRF's frequencies (`freq_hz` equal within 1e-9 relative).
///
/// Models whose frequencies differ are compared by nearest frequency.
pub fn compare_bode(frf: &FrfBand, models: &[BodeCurve]) -> Vec<BodeMismatch> {
    models
        .iter()
        .map(|m| {
            let mut outside = Vec::new();
            let mut sq = 0.0;
            for (i, f) in frf.freq_hz.iter().enumerate() {
                let j = nearest(&m.freq_hz, *f);
                let gm = m.response[j];
                if (gm - frf.g[i]).norm() > 2.0 * frf.sigma[i] {
                    outside.push(*f);
                }
                sq += (20.0 * (gm.norm() / frf.g[i].norm()).log10()).powi(2);
            }
            let n = frf.freq_hz.len().max(1) as f64;
            BodeMismatch {
                model: m.name.clone(),
                outside_2sigma: outside.len() as f64 / n,
                outside_freq_hz: outside,
                rms_mag_error_db: (sq / n).sqrt(),
            }
        })
        .collect()
}

fn nearest(xs: &[f64], x: f64) -> usize {
    let mut best = 0;
    for (i, v) in xs.iter().enumerate() {
        if (v - x).abs() < (xs[best] - x).abs() {
            best = i;
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Lcg(u64);
    impl Lcg {
        fn gauss(&mut self) -> f64 {
            let mut u = || {
                self.0 = self
                    .0
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((self.0 >> 11) as f64 + 0.5) / (1u64 << 53) as f64
            };
            let (a, b) = (u(), u());
            (-2.0 * a.ln()).sqrt() * (2.0 * std::f64::consts::PI * b).cos()
        }
    }

    #[test]
    fn fit_is_the_toolbox_nrmse_definition() {
        let y = [1.0, 2.0, 3.0, 4.0];
        assert_eq!(fit_percent(&y, &y).unwrap(), 100.0);
        // predicting the mean gives 0 %
        assert!(fit_percent(&y, &[2.5; 4]).unwrap().abs() < 1e-12);
        // error norm 1, deviation norm √5: 100(1 − 1/√5)
        let f = fit_percent(&y, &[1.0, 2.0, 3.0, 5.0]).unwrap();
        assert!((f - 100.0 * (1.0 - 1.0 / 5f64.sqrt())).abs() < 1e-12);
        assert!(matches!(
            fit_percent(&[1.0, 1.0], &[1.0, 1.0]),
            Err(ValidateError::ConstantOutput)
        ));
        assert!(matches!(
            fit_percent(&y, &y[..3]),
            Err(ValidateError::LengthMismatch { .. })
        ));
    }

    #[test]
    fn chi2_quantile_matches_tables() {
        // tabulated 99 % points: χ²(10) = 23.209, χ²(25) = 44.314, χ²(26) = 45.642
        for (nu, q) in [(10, 23.209), (25, 44.314), (26, 45.642)] {
            assert!((chi2_quantile_99(nu) / q - 1.0).abs() < 0.005, "{nu}");
        }
    }

    #[test]
    fn residual_tests_pass_white_and_fail_coloured_or_input_dependent() {
        let n = 4000;
        let mut g = Lcg(42);
        let u: Vec<f64> = (0..n).map(|_| g.gauss()).collect();
        let y: Vec<f64> = (0..n)
            .map(|t| if t > 0 { 0.8 * u[t - 1] } else { 0.0 })
            .collect();
        let white: Vec<f64> = (0..n).map(|_| 0.1 * g.gauss()).collect();
        // correct model + white noise: passes
        let yn: Vec<f64> = y.iter().zip(&white).map(|(a, b)| a + b).collect();
        let v = validate(&u, &yn, &y, 25).unwrap();
        assert!(v.pass, "{v:?}");
        assert!(v.fit > 85.0);
        // coloured residual (MA(1)): whiteness fails, first lag ≈ 0.5
        let col: Vec<f64> = (0..n)
            .map(|t| white[t] + if t > 0 { white[t - 1] } else { 0.0 })
            .collect();
        let yc: Vec<f64> = y.iter().zip(&col).map(|(a, b)| a + b).collect();
        let v = validate(&u, &yc, &y, 25).unwrap();
        assert!(
            !v.whiteness.pass && (v.whiteness.values[0] - 0.5).abs() < 0.05,
            "{:?}",
            v.whiteness
        );
        // wrong gain: residual = 0.2 u(t−1): independence fails at lag 1
        let yw: Vec<f64> = y.iter().map(|v| v * 0.75).collect();
        let v = validate(&u, &yn, &yw, 25).unwrap();
        assert!(!v.independence.pass, "{:?}", v.independence);
        assert!(v.independence.values[1] > 0.5);
        assert!(!v.pass);
    }

    #[test]
    fn residual_tests_false_alarms_are_rare_on_white_noise() {
        let (mut wf, mut xf) = (0, 0);
        for s in 0..50 {
            let mut g = Lcg(s);
            let e: Vec<f64> = (0..2000).map(|_| g.gauss()).collect();
            // coloured input u = AR(1) 0.9, independent of e
            let mut u = vec![0.0; 2000];
            for t in 1..2000 {
                u[t] = 0.9 * u[t - 1] + g.gauss();
            }
            wf += usize::from(!whiteness_test(&e, 25).unwrap().pass);
            xf += usize::from(!input_independence_test(&e, &u, 25).unwrap().pass);
        }
        assert!(wf <= 3, "{wf} of 50 white sequences failed whiteness");
        assert!(xf <= 3, "{xf} of 50 independent pairs failed independence");
    }

    #[test]
    fn allowed_outside_is_the_binomial_99_quantile() {
        // P(X ≤ 1) = 0.972, P(X ≤ 2) = 0.9976 for X ~ Bin(26, 0.01)
        assert_eq!(allowed_outside(26), 2);
        assert_eq!(allowed_outside(25), 2);
        // P(X ≤ 0) = 0.99^1 = 0.99
        assert_eq!(allowed_outside(1), 0);
        assert_eq!(allowed_outside(0), 0);
        // 200 lags: mean 2, the 99 % point is 6
        assert_eq!(allowed_outside(200), 6);
    }

    #[test]
    fn verdict_follows_the_lags_outside_and_the_statistic() {
        // every lag far outside its band: fails whatever ζ says
        let t = finish("t", (0..26).collect(), vec![0.5; 26], 0.1, 0.0, 26);
        assert_eq!(t.outside, 26);
        assert!(!t.pass, "{t:?}");
        assert!(
            t.failure()
                .unwrap()
                .contains("26 of 26 lags outside the band, at most 2 allowed"),
            "{:?}",
            t.failure()
        );
        // two lags outside are within chance, a small ζ: passes
        let mut v = vec![0.0; 26];
        v[3] = 0.2;
        v[9] = -0.2;
        let t = finish("t", (0..26).collect(), v.clone(), 0.1, 10.0, 26);
        assert!(t.pass && t.failure().is_none(), "{t:?}");
        // the same lags and a large ζ: fails and says why, with 0 of them decisive
        let t = finish("t", (0..26).collect(), v, 0.1, 80.0, 26);
        assert!(!t.pass);
        assert!(t.failure().unwrap().starts_with("ζ = 80.0 above χ²(26)"));
        // a NaN value is outside, never inside
        let mut v = vec![0.0; 26];
        v[0] = f64::NAN;
        v[1] = f64::NAN;
        v[2] = f64::NAN;
        let t = finish("t", (0..26).collect(), v, 0.1, 0.0, 26);
        assert_eq!(t.outside, 3);
        assert!(!t.pass);
    }

    #[test]
    fn line_residuals_pass_at_the_noise_and_fail_on_a_missed_mode() {
        // K = 80 lines, each a complex error over a σ estimated from ν = 12 real
        // degrees of freedom (P = 3 periods, three lines pooled): F(2, 12)-distributed
        // |e|². Over 200 draws the test passes at its 99 % level.
        let (k, nu) = (80, 12usize);
        let mut g = Lcg(7);
        let draw = |g: &mut Lcg| -> Vec<Complex64> {
            (0..k)
                .map(|_| {
                    let e = Complex64::new(g.gauss(), g.gauss()) / 2f64.sqrt();
                    let var = (0..nu).map(|_| g.gauss().powi(2)).sum::<f64>() / nu as f64;
                    e / var.sqrt()
                })
                .collect()
        };
        let failed = (0..200)
            .filter(|_| !line_residual_test(&draw(&mut g), nu as f64).unwrap().pass)
            .count();
        assert!(failed <= 6, "{failed} of 200 false alarms");
        // a mode the model misses: five neighbouring lines ten σ off
        let mut e = draw(&mut g);
        for v in &mut e[30..35] {
            *v += Complex64::new(10.0, 0.0);
        }
        let t = line_residual_test(&e, nu as f64).unwrap();
        assert!(!t.pass && t.outside >= 5, "{t:?}");
        assert!(t.failure().unwrap().contains("lines outside the band"));
        // a NaN line fails
        e[0] = Complex64::new(f64::NAN, 0.0);
        assert!(!line_residual_test(&e, nu as f64).unwrap().pass);
    }

    #[test]
    fn a_diverged_simulation_fails_every_test() {
        let n = 2000;
        let mut g = Lcg(7);
        let u: Vec<f64> = (0..n).map(|_| g.gauss()).collect();
        let y: Vec<f64> = (0..n).map(|_| g.gauss()).collect();
        // the simulated output overflows half-way, then is NaN (inf − inf)
        let yhat: Vec<f64> = (0..n)
            .map(|t| match t {
                0..1000 => y[t],
                1000..1500 => f64::INFINITY,
                _ => f64::NAN,
            })
            .collect();
        let v = validate(&u, &y, &yhat, 25).unwrap();
        assert!(v.fit.is_nan());
        assert!(!v.pass);
        for t in [&v.whiteness, &v.independence] {
            assert!(!t.pass, "{t:?}");
            assert_eq!(t.non_finite, 1000);
            assert_eq!(t.outside, t.lags.len());
            assert_eq!(
                t.failure().unwrap(),
                "1000 residual samples are NaN or infinite"
            );
        }
        // a NaN FIT alone fails the validation, residual tests aside
        let mut yhat = y.clone();
        yhat[5] = f64::NAN;
        let v = validate(&u, &y, &yhat, 25).unwrap();
        assert!(v.fit.is_nan() && !v.pass);
    }

    #[test]
    fn compare_bode_counts_lines_outside_two_sigma() {
        let frf = FrfBand {
            freq_hz: vec![1.0, 2.0, 3.0, 4.0],
            g: vec![Complex64::new(1.0, 0.0); 4],
            sigma: vec![0.1; 4],
        };
        let m = BodeCurve {
            name: "m".into(),
            freq_hz: vec![1.0, 2.0, 3.0, 4.0],
            response: vec![
                Complex64::new(1.05, 0.0),
                Complex64::new(1.0, 0.15),
                Complex64::new(1.3, 0.0),
                Complex64::new(1.0, 0.0),
            ],
        };
        let r = compare_bode(&frf, &[m]);
        assert_eq!(r[0].outside_freq_hz, vec![3.0]);
        assert!((r[0].outside_2sigma - 0.25).abs() < 1e-12);
    }
}
