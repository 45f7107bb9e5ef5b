//! Physical models fitted to the nonparametric FRF at the excited lines,
//! weighted by the noise on both spectra: the frequency-domain path of
//! `jointid fit` for periodic data.
//!
//! Why here and not on the time record: an output-error simulation driven by
//! the measured torque integrates every unmodelled slow torque (the
//! disturbance the controller rejects, an offset, friction) into a drift of
//! the motor angle, and a time-domain cost then fits the drift. The
//! period-averaged spectra at the excited lines keep only what is
//! synchronous with the reference; slow disturbances, offsets and the
//! rigid-body drift do not reach them (seed 000 §3 fits there; Pintelon &
//! Schoukens, *System Identification: A Frequency Domain Approach*, IEEE
//! Press 2001, ch. 7 and 10, the FDIDENT school).
//!
//! Model: the sampled response of [`GreyBoxModel`] (seed 000 eq. (5)–(8),
//! DESIGN.md §6) behind an optional first-order current-loop lag `τ_c`
//! ([`DrivenModel`]) and a transport delay `D = n + φ` samples on the
//! torque. The input is held (ZOH, seed 000 eq. (12)–(13)); with the switch
//! of the held input delayed by `φT` inside the sample,
//! `x(k+1) = A x(k) + Γ((1−φ)T) v(k) + e^{F(1−φ)T} Γ(φT) v(k−1)`,
//! `v(k) = u(k−n)`, `Γ(h) = ∫₀ʰ e^{Fs} ds G` (Van Loan's block exponential),
//! so the model response at line `k` is exact, not a continuous-time
//! approximation (which is 0.4 % off at 100 Hz, 2 kHz, more than the
//! FRF's σ there).
//!
//! Cost: the sample maximum-likelihood cost of Pintelon & Schoukens
//! (eq. (10-58), errors in variables, noise on `u` and on `θ_m` correlated
//! through the loop):
//! `V(θ) = Σ_k |Ȳ_k − G_k(θ) Ū_k|² / σ²_k(θ)`,
//! `σ²_k = σ²_Ȳ + |G_k|² σ²_Ū − 2 Re(G_k* σ_ȲŪ)`, with the (co)variances of
//! the period means from the period-to-period spread ([`FrfSpectra`],
//! pooled over neighbouring lines). Each complex term is split into two real
//! residuals of unit variance, so at the true model `V` is a χ² statistic:
//! [`FrfFit::expected_cost`] and [`FrfFit::cost_ratio`] turn it into a
//! model-adequacy test.
//!
//! Search: the start comes from the FRF itself. Resonances are the peaks of
//! `|Ĝ| ω²` (angle output; `|Ĝ| ω` for velocity) with their topographic
//! prominence; for each choice of `masses − 1` of the strongest peaks and
//! two damping levels, anti-resonances (the deepest notch below each
//! chosen peak), the rigid-body inertia and friction (low lines,
//! `1/G ≈ −J ω² + j f ω`) give a start through
//! [`crate::ident::grey_box::initial_values`]. Each start is refined on the
//! log-FRF cost `Σ w_k² |ln G_k(θ) − ln Ĝ_k|²`, `w_k = 1/max(σ_k/|Ĝ_k|, 0.02)`
//! (wide basin: a wrong resonance frequency costs in proportion to how far
//! it is, not to a peak's height), first the losses and the drive, then
//! everything; the best starts then go to the SML cost. The drive is chosen
//! among lag only, delay only, and both by Akaike's criterion `V + 2p`
//! (lag and delay are nearly collinear below the first resonance).
//! Levenberg–Marquardt ([`crate::ident::lm`]) in log-parameters with box bounds
//! (three decades around the start; lag and delay 0–20 samples), Jacobian by
//! forward differences.
//!
//! Uncertainty: `cov = σ̂² (JᵀJ)^{−1}` at the SML minimum (Pintelon &
//! Schoukens §10.4; `σ̂²` absorbs the variance inflation of estimated
//! weights), delta method `σ_p = p σ_{ln p}`.
//!
//! Never silently wrong: every fit is checked ([`FitWarning`]).
//!
//! See also: [`crate::ident::frf`] for the FRF and its spectra, [`crate::ident::fit`] for
//! the time-domain path, [`crate::ident::grey_box`] for the models.

use nalgebra::{DMatrix, DVector};
use rustfft::num_complex::Complex64;
use thiserror::Error;

use crate::ident::fit::DrivenModel;
use crate::ident::frf::{Frf, FrfSpectra};
use crate::ident::grey_box::{self, Features, GreyBoxModel, Output, PhysParam};
use crate::ident::lm::{self, LeastSquares, LmFit, LmOptions, Normal, Termination};
use crate::ident::ss::{ContinuousSs, StateSpace};
use crate::model::spec::Structure;

/// relative standard deviation above which a line of the FRF is not used to
/// find resonances or the starting rigid body
pub const RELIABLE_REL_SIGMA: f64 = 0.1;
/// largest lag or delay considered [samples]
pub const MAX_DRIVE_SAMPLES: f64 = 20.0;
/// cost above this multiple of its expected value is reported
pub const COST_RATIO_WARN: f64 = 2.0;
/// a resonance of the FRF this prominent [dB] must be in the model
pub const MISSED_PEAK_DB: f64 = 6.0;
/// a model and an FRF resonance match within this relative distance
pub const PEAK_MATCH_REL: f64 = 0.05;
/// relative misfit of the periodic steady state (1 − FIT/100) below which a
/// cost above the noise level is not reported
pub const NEGLIGIBLE_MISFIT: f64 = 1e-3;
/// a start whose SML cost is below this multiple of its expected value ends
/// the search for starts
const GOOD_START_RATIO: f64 = 3.0;
/// relative standard deviation above which a parameter is "poorly determined"
pub const POORLY_DETERMINED_REL: f64 = 0.5;

/// How a drive parameter (lag or delay) enters the fit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Drive {
    /// estimated from the FRF
    Estimate,
    /// held at this value [samples]
    Fixed(f64),
}

/// Options of [`fit_frf`].
#[derive(Clone, Debug, PartialEq)]
pub struct FrfFitOptions {
    /// mechanical structure
    pub structure: Structure,
    /// which motor signal the FRF's output is
    pub output: Output,
    /// gear ratio `r` (fixed)
    pub r: f64,
    /// sample interval of the data [s]
    pub ts: f64,
    /// current-loop lag `τ_c` [samples]
    pub lag: Drive,
    /// transport delay [samples]
    pub delay: Drive,
    /// iterations of the final (SML) refinement
    pub max_iter: usize,
}

impl FrfFitOptions {
    /// Defaults for a structure at sample interval `ts`: angle output, gear
    /// ratio of seed 000, lag and delay estimated.
    pub fn new(structure: Structure, ts: f64) -> Self {
        FrfFitOptions {
            structure,
            output: Output::Angle,
            r: grey_box::DEFAULT_GEAR_RATIO,
            ts,
            lag: Drive::Estimate,
            delay: Drive::Estimate,
            max_iter: 200,
        }
    }
}

/// Why a frequency-domain fit could not be made.
#[derive(Debug, Error, PartialEq)]
pub enum FrfFitError {
    /// too few lines for the parameters
    #[error("the FRF has {lines} excited lines; a {structure} fit needs at least {needed}")]
    TooFewLines {
        /// lines in the FRF
        lines: usize,
        /// parameters + 2
        needed: usize,
        /// structure name
        structure: &'static str,
    },
    /// no positive rigid-body inertia could be read off the FRF
    #[error("no positive rigid-body inertia in the lowest FRF lines ({detail})")]
    NoRigidBody {
        /// what was seen
        detail: String,
    },
    /// the sample interval is not positive and finite
    #[error("sample interval {0} s")]
    SampleInterval(f64),
    /// the lag or delay asked for is outside 0 … [`MAX_DRIVE_SAMPLES`]
    #[error("{what} of {value} samples is outside 0 … {MAX_DRIVE_SAMPLES}")]
    Drive {
        /// lag or delay
        what: &'static str,
        /// the value
        value: f64,
    },
    /// no start could be evaluated
    #[error("no start gave a finite cost")]
    NoStart,
}

/// A lag or delay as fitted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriveEstimate {
    /// value [samples]
    pub value: f64,
    /// standard deviation [samples] (0 when not estimated)
    pub std: f64,
    /// estimated (else fixed or left out by the model choice)
    pub estimated: bool,
}

/// Something about a fit the user must know.
#[derive(Clone, Debug, PartialEq)]
pub enum FitWarning {
    /// the refinement stopped at its iteration limit
    IterationLimit {
        /// iterations used
        iterations: usize,
    },
    /// parameters ended on a bound of the search
    AtBounds {
        /// their names
        names: Vec<String>,
    },
    /// the cost is far above what the noise explains: model errors dominate
    CostAboveNoise {
        /// cost / expected cost
        ratio: f64,
    },
    /// a clear resonance of the FRF has no model resonance near it
    MissedResonance {
        /// its frequency [Hz]
        freq_hz: f64,
        /// its prominence [dB]
        prominence_db: f64,
    },
    /// the model has a resonance where the FRF shows none
    ExtraResonance {
        /// its frequency [Hz]
        freq_hz: f64,
    },
    /// a parameter's standard deviation is a large share of its value
    PoorlyDetermined {
        /// its name
        name: String,
        /// σ / |value|
        rel_std: f64,
    },
    /// the FRF's top half-decade falls more slowly than the output kind
    /// allows (an acceleration output, say, fitted as an angle)
    OutputKind {
        /// measured slope [dB/decade]
        measured_db_per_decade: f64,
        /// the slope the model's output kind has there [dB/decade]
        expected_db_per_decade: f64,
    },
    /// the FIT reached is far below what a model following the FRF reaches
    FitBelowFrf {
        /// the model's FIT [%]
        fit: f64,
        /// the FRF's own FIT [%]
        frf_fit: f64,
    },
}

impl std::fmt::Display for FitWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FitWarning::IterationLimit { iterations } => write!(
                f,
                "the refinement stopped at its iteration limit ({iterations}); the estimate may not be a minimum"
            ),
            FitWarning::AtBounds { names } => write!(
                f,
                "{} ended on a bound of the search (three decades around the start): the model may not suit the data",
                names.join(", ")
            ),
            FitWarning::CostAboveNoise { ratio } => write!(
                f,
                "the cost is {ratio:.1} times what the measurement noise explains: the model misses part of the \
                 measured response (another structure, a nonlinearity, or a disturbance synchronous with the excitation)"
            ),
            FitWarning::MissedResonance { freq_hz, prominence_db } => write!(
                f,
                "the FRF has a resonance at {freq_hz:.2} Hz ({prominence_db:.1} dB high) that the model does not have"
            ),
            FitWarning::ExtraResonance { freq_hz } => write!(
                f,
                "the model has a resonance at {freq_hz:.2} Hz that the FRF does not show"
            ),
            FitWarning::PoorlyDetermined { name, rel_std } => write!(
                f,
                "{name} is poorly determined (σ = {:.0} % of its value): the data hardly constrain it",
                100.0 * rel_std
            ),
            FitWarning::OutputKind {
                measured_db_per_decade,
                expected_db_per_decade,
            } => write!(
                f,
                "the FRF falls by {:.0} dB/decade at the top of its band where this output kind falls by {:.0}: \
                 is the output an acceleration? Then fit a black box with --feedthrough (or give the right \
                 --output-kind)",
                -measured_db_per_decade, -expected_db_per_decade
            ),
            FitWarning::FitBelowFrf { fit, frf_fit } => write!(
                f,
                "its periodic steady-state FIT on the estimation data, {fit:.1} %, is far below the {frf_fit:.1} % \
                 the same model family fitted to the FRF reaches (--domain frequency): the time-domain fit \
                 followed something else than the joint (drift, a slow disturbance)"
            ),
        }
    }
}

/// A resonance read off the FRF: a peak of `|Ĝ| ω^k` over the reliable lines.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrfPeak {
    /// frequency [Hz]
    pub freq_hz: f64,
    /// topographic prominence [dB]
    pub prominence_db: f64,
}

/// Result of [`fit_frf`].
#[derive(Clone, Debug, PartialEq)]
pub struct FrfFit {
    /// model family (structure, output, gear ratio, sample interval)
    pub model: GreyBoxModel,
    /// estimated parameters (arm side, seed 000 Table 1) with σ and units
    pub params: Vec<PhysParam>,
    /// the start the best fit came from
    pub initial: Vec<PhysParam>,
    /// current-loop lag [samples]
    pub lag: DriveEstimate,
    /// transport delay [samples]
    pub delay: DriveEstimate,
    /// the final Levenberg–Marquardt result (θ: log-parameters, lag, delay)
    pub lm: LmFit,
    /// SML cost at the estimate
    pub cost: f64,
    /// degrees of freedom of each pooled noise variance
    pub noise_dof: f64,
    /// resonances read off the FRF
    pub peaks: Vec<FrfPeak>,
    /// model resonances [Hz]
    pub resonances_hz: Vec<f64>,
    /// model anti-resonances [Hz]
    pub anti_resonances_hz: Vec<f64>,
    /// what the user must know
    pub warnings: Vec<FitWarning>,
    /// starts tried
    pub starts: usize,
    /// lines used
    pub lines: usize,
}

impl FrfFit {
    /// Expected SML cost when the model is right: `(2F − p) ν/(ν − 2)`,
    /// `F` lines, `p` free parameters, `ν` the degrees of freedom of the
    /// noise variances (the inflation of a ratio to an estimated variance).
    pub fn expected_cost(&self) -> f64 {
        expected_sml_cost(self.lm.chi2().1, self.noise_dof)
    }

    /// cost / expected cost: about 1 when the noise explains the misfit
    pub fn cost_ratio(&self) -> f64 {
        self.cost / self.expected_cost()
    }

    /// parameter values in [`Structure::param_names`] order
    pub fn values(&self) -> Vec<f64> {
        self.params.iter().map(|p| p.value).collect()
    }

    /// continuous model (mechanics and lag; the delay is not in it) [s]
    pub fn continuous(&self) -> ContinuousSs {
        drive_model(&self.model, self.lag.value).continuous(&self.values())
    }

    /// Discrete model at the data's sample interval, the delay as a chain
    /// of held inputs (exact for a ZOH input).
    pub fn discrete(&self) -> StateSpace {
        let s = Sampled::new(&self.continuous(), self.model.ts, self.delay.value);
        s.state_space()
    }

    /// Frequency response at `f_hz` [Hz] of the sampled model.
    pub fn freq_response(&self, f_hz: &[f64]) -> Vec<Complex64> {
        let s = Sampled::new(&self.continuous(), self.model.ts, self.delay.value);
        let z = unit_circle(f_hz, self.model.ts);
        s.response(&z)
    }
}

fn drive_model(model: &GreyBoxModel, lag_samples: f64) -> DrivenModel {
    DrivenModel {
        mechanics: *model,
        // below 1e-7 samples the lag is numerically absent; kept above that
        // so that a difference quotient from zero sees it
        current_loop_tau: if lag_samples > 1e-7 {
            lag_samples * model.ts
        } else {
            0.0
        },
    }
}

pub(crate) fn unit_circle(f_hz: &[f64], ts: f64) -> Vec<Complex64> {
    f_hz.iter()
        .map(|f| Complex64::from_polar(1.0, 2.0 * std::f64::consts::PI * f * ts))
        .collect()
}

/// The continuous model sampled with a held, delayed input, in Hessenberg
/// form for cheap evaluation at many frequencies.
struct Sampled {
    /// `e^{FT}`, `Γ((1−φ)T)`, `e^{F(1−φ)T}Γ(φT)`, `H`
    a: DMatrix<f64>,
    b_new: DVector<f64>,
    b_old: DVector<f64>,
    c: DVector<f64>,
    d: f64,
    /// whole samples of delay
    n: usize,
    ts: f64,
    /// Hessenberg form `Qᵀ A Q` and the vectors in its basis
    h: DMatrix<f64>,
    hb_new: DVector<f64>,
    hb_old: DVector<f64>,
    hc: DVector<f64>,
}

/// `(e^{F h}, Γ(h))` by Van Loan's block exponential
fn hold_pair(f: &DMatrix<f64>, g: &DVector<f64>, h: f64) -> (DMatrix<f64>, DVector<f64>) {
    let n = f.nrows();
    if h <= 0.0 {
        return (DMatrix::identity(n, n), DVector::zeros(n));
    }
    let mut m = DMatrix::zeros(n + 1, n + 1);
    m.view_mut((0, 0), (n, n)).copy_from(&(f * h));
    m.view_mut((0, n), (n, 1)).copy_from(&(g * h));
    let e = m.exp();
    (
        e.view((0, 0), (n, n)).into_owned(),
        e.view((0, n), (n, 1)).column(0).into_owned(),
    )
}

impl Sampled {
    fn new(c: &ContinuousSs, ts: f64, delay_samples: f64) -> Sampled {
        let d = delay_samples.max(0.0);
        let n = d.floor() as usize;
        let phi = d - n as f64;
        let (e1, g1) = hold_pair(&c.f, &c.g, (1.0 - phi) * ts);
        let (e2, g2) = hold_pair(&c.f, &c.g, phi * ts);
        let a = &e1 * &e2;
        let b_old = &e1 * g2;
        let hess = a.clone().hessenberg();
        let (q, h) = hess.unpack();
        let qt = q.transpose();
        let cv: DVector<f64> = c.h.transpose();
        Sampled {
            hb_new: &qt * &g1,
            hb_old: &qt * &b_old,
            hc: &qt * &cv,
            h,
            a,
            b_new: g1,
            b_old,
            c: cv,
            d: c.d,
            n,
            ts,
        }
    }

    /// `G(z)` at each `z` on the unit circle; NaN where `zI − A` is singular
    fn response(&self, z: &[Complex64]) -> Vec<Complex64> {
        let nx = self.h.nrows();
        let mut m = vec![Complex64::new(0.0, 0.0); nx * nx];
        let mut rhs = vec![Complex64::new(0.0, 0.0); nx];
        z.iter()
            .map(|&zk| {
                let zi = zk.inv();
                for i in 0..nx {
                    for j in 0..nx {
                        let v = -self.h[(i, j)];
                        m[i * nx + j] = Complex64::new(v, 0.0);
                    }
                    m[i * nx + i] += zk;
                    rhs[i] = self.hb_new[i] + zi * self.hb_old[i];
                }
                match solve_hessenberg(&mut m, &mut rhs, nx) {
                    true => {
                        let g = rhs
                            .iter()
                            .zip(self.hc.iter())
                            .fold(Complex64::new(self.d, 0.0), |g, (x, c)| g + x * c);
                        g * zi.powi(self.n as i32)
                    }
                    false => Complex64::new(f64::NAN, f64::NAN),
                }
            })
            .collect()
    }

    /// state space with the delay as input-history states
    fn state_space(&self) -> StateSpace {
        let nx = self.a.nrows();
        let has_old = self.b_old.iter().any(|v| *v != 0.0);
        let hist = if self.n == 0 && !has_old {
            0
        } else {
            self.n + 1
        };
        let nt = nx + hist;
        let mut a = DMatrix::zeros(nt, nt);
        a.view_mut((0, 0), (nx, nx)).copy_from(&self.a);
        let mut b = DVector::zeros(nt);
        // history s_i(k) = u(k − i), i = 1 … hist
        if hist > 0 {
            b[nx] = 1.0;
            for i in 1..hist {
                a[(nx + i, nx + i - 1)] = 1.0;
            }
        }
        // v(k) = u(k − n), v(k − 1) = u(k − n − 1)
        if self.n == 0 {
            for r in 0..nx {
                b[r] += self.b_new[r];
            }
        } else {
            for r in 0..nx {
                a[(r, nx + self.n - 1)] += self.b_new[r];
            }
        }
        if hist > 0 {
            for r in 0..nx {
                a[(r, nx + self.n)] += self.b_old[r];
            }
        }
        let mut c = nalgebra::RowDVector::zeros(nt);
        for i in 0..nx {
            c[i] = self.c[i];
        }
        StateSpace::new(a, b, c, self.d, self.ts)
    }
}

/// Solves an upper Hessenberg system in place (row-major `m`, `n × n`) by
/// Gaussian elimination with pivoting between neighbouring rows; the
/// solution replaces `rhs`. False when singular.
pub(crate) fn solve_hessenberg(m: &mut [Complex64], rhs: &mut [Complex64], n: usize) -> bool {
    for j in 0..n.saturating_sub(1) {
        let (p, q) = (j * n, (j + 1) * n);
        if m[q + j].norm_sqr() > m[p + j].norm_sqr() {
            for c in j..n {
                m.swap(p + c, q + c);
            }
            rhs.swap(j, j + 1);
        }
        let piv = m[p + j];
        if piv.norm_sqr() == 0.0 {
            return false;
        }
        let l = m[q + j] / piv;
        if l.norm_sqr() != 0.0 {
            for c in j..n {
                let v = m[p + c];
                m[q + c] -= l * v;
            }
            let v = rhs[j];
            rhs[j + 1] -= l * v;
        }
    }
    for i in (0..n).rev() {
        let mut s = rhs[i];
        for c in i + 1..n {
            s -= m[i * n + c] * rhs[c];
        }
        let piv = m[i * n + i];
        if piv.norm_sqr() == 0.0 {
            return false;
        }
        rhs[i] = s / piv;
    }
    true
}

/// The data of one fit: lines, measured spectra and weights.
pub(crate) struct Lines {
    z: Vec<Complex64>,
    /// the noise lines of the spectra on the unit circle, and where each
    /// excited line sits among them
    z_noise: Vec<Complex64>,
    exc_in_noise: Vec<usize>,
    g: Vec<Complex64>,
    /// log-cost weight per line, `1/max(σ/|Ĝ|, 0.02)`
    w_log: Vec<f64>,
    spectra: Option<FrfSpectra>,
    sigma: Vec<f64>,
}

impl Lines {
    /// the lines of `frf` at sample interval `ts` [s]
    pub(crate) fn new(frf: &Frf, ts: f64) -> Lines {
        let sp = &frf.spectra;
        let exc_in_noise: Vec<usize> = frf
            .freq_hz
            .iter()
            .zip(&sp.pool)
            .filter_map(|(f, pool)| {
                pool.clone()
                    .find(|&j| (sp.noise_freq_hz[j] - f).abs() <= 1e-9 * f.abs().max(1e-300))
            })
            .collect();
        let usable = sp.periods >= 2
            && sp.u.len() == frf.g.len()
            && exc_in_noise.len() == frf.g.len()
            && sp.pool.iter().all(|p| p.end <= sp.var_u.len());
        let spectra = usable.then(|| sp.clone());
        Lines {
            z: unit_circle(&frf.freq_hz, ts),
            z_noise: unit_circle(&sp.noise_freq_hz, ts),
            exc_in_noise,
            g: frf.g.clone(),
            w_log: frf
                .g
                .iter()
                .zip(&frf.sigma)
                .map(|(g, s)| 1.0 / (s / g.norm().max(1e-300)).max(0.02))
                .collect(),
            sigma: frf.sigma.clone(),
            spectra,
        }
    }

    /// SML cost expected at the true model with `p` free parameters
    pub(crate) fn expected_cost(&self, p: usize) -> f64 {
        let nu = self.spectra.as_ref().map_or(0.0, FrfSpectra::dof);
        expected_sml_cost((2 * self.z.len()).saturating_sub(p), nu)
    }
}

/// SML cost expected at the true model with `dof` real residuals left after
/// the free parameters: `dof · ν/(ν − 2)`, the inflation of a ratio to a
/// variance estimated with `ν` degrees of freedom (none when `ν ≤ 2`).
fn expected_sml_cost(dof: usize, nu: f64) -> f64 {
    dof.max(1) as f64 * if nu > 2.0 { nu / (nu - 2.0) } else { 1.0 }
}

/// Which cost a problem evaluates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Cost {
    /// weighted log-FRF error (wide basin, for starts)
    Log,
    /// sample maximum likelihood (the estimate)
    Sml,
}

/// A model whose sampled frequency response a parameter vector gives.
pub(crate) trait FrfModel {
    /// number of parameters
    fn n_params(&self) -> usize;
    /// `G(z)` at each `z` (None when `theta` cannot be evaluated)
    fn response(&self, theta: &[f64], z: &[Complex64]) -> Option<Vec<Complex64>>;
    /// signed difference step for parameter `i` at `theta`
    fn step(&self, i: usize, theta: &[f64]) -> f64;
}

/// The physical model: log-parameters, then lag and delay [samples].
struct PhysicalFrf(GreyBoxModel);

impl PhysicalFrf {
    fn n_mech(&self) -> usize {
        self.0.structure.param_names().len()
    }
}

impl FrfModel for PhysicalFrf {
    fn n_params(&self) -> usize {
        self.n_mech() + 2
    }

    fn response(&self, theta: &[f64], z: &[Complex64]) -> Option<Vec<Complex64>> {
        let nm = self.n_mech();
        let p: Vec<f64> = theta[..nm].iter().map(|t| t.exp()).collect();
        if p.iter().any(|v| !v.is_finite() || *v <= 0.0) {
            return None;
        }
        let c = drive_model(&self.0, theta[nm]).continuous(&p);
        let s = Sampled::new(&c, self.0.ts, theta[nm + 1]);
        let g = s.response(z);
        g.iter().all(|v| v.is_finite()).then_some(g)
    }

    fn step(&self, i: usize, theta: &[f64]) -> f64 {
        if i < self.n_mech() {
            1e-6
        } else if theta[i] + 1e-4 > MAX_DRIVE_SAMPLES {
            // backward at the upper bound of the drive
            -1e-4
        } else {
            1e-4
        }
    }
}

pub(crate) struct Problem<'a, M: FrfModel> {
    pub(crate) model: &'a M,
    pub(crate) lines: &'a Lines,
    pub(crate) cost: Cost,
}

impl<M: FrfModel> Problem<'_, M> {
    fn response(&self, theta: &[f64], z: &[Complex64]) -> Option<Vec<Complex64>> {
        self.model.response(theta, z)
    }

    fn residuals(&self, theta: &[f64]) -> Option<Vec<f64>> {
        let l = self.lines;
        let mut r = Vec::with_capacity(2 * l.z.len());
        match (self.cost, &l.spectra) {
            (Cost::Log, _) => {
                let g = self.response(theta, &l.z)?;
                for ((gm, gh), w) in g.iter().zip(&l.g).zip(&l.w_log) {
                    let q = gm / gh;
                    r.push(w * q.norm().ln());
                    r.push(w * q.arg());
                }
            }
            (Cost::Sml, Some(s)) => {
                let gn = self.response(theta, &l.z_noise)?;
                for (k, &kn) in l.exc_in_noise.iter().enumerate() {
                    let gm = gn[kn];
                    let e = s.y[k] - gm * s.u[k];
                    // output-error noise pooled over the window, each line
                    // with its own model response (see `FrfSpectra`)
                    let pool = s.pool[k].clone();
                    let n = pool.len().max(1) as f64;
                    let var = pool
                        .map(|j| {
                            s.var_y[j] + gn[j].norm_sqr() * s.var_u[j]
                                - 2.0 * (gn[j].conj() * s.cov_yu[j]).re
                        })
                        .sum::<f64>()
                        / n;
                    let floor = (1e-4 * s.y[k].norm()).powi(2);
                    let sd = (var.max(floor) / 2.0).sqrt();
                    r.push(e.re / sd);
                    r.push(e.im / sd);
                }
            }
            (Cost::Sml, None) => {
                let g = self.response(theta, &l.z)?;
                for ((gm, gh), sg) in g.iter().zip(&l.g).zip(&l.sigma) {
                    let sd = (sg.max(1e-4 * gh.norm()) / 2f64.sqrt()).max(1e-300);
                    r.push((gh - gm).re / sd);
                    r.push((gh - gm).im / sd);
                }
            }
        }
        r.iter().all(|v| v.is_finite()).then_some(r)
    }
}

impl<M: FrfModel> LeastSquares for Problem<'_, M> {
    fn n_params(&self) -> usize {
        self.model.n_params()
    }

    fn n_residuals(&self) -> usize {
        2 * self.lines.z.len()
    }

    fn cost(&self, theta: &[f64]) -> f64 {
        self.residuals(theta)
            .map_or(f64::INFINITY, |r| r.iter().map(|v| v * v).sum())
    }

    fn normal_equations(&self, theta: &[f64], free: &[usize]) -> Normal {
        let p = free.len();
        let Some(r0) = self.residuals(theta) else {
            return Normal {
                jtj: DMatrix::identity(p, p),
                jte: DVector::zeros(p),
                ssr: f64::INFINITY,
            };
        };
        let nr = r0.len();
        let mut jac = DMatrix::zeros(nr, p);
        for (col, &i) in free.iter().enumerate() {
            let h = self.model.step(i, theta);
            let mut th = theta.to_vec();
            th[i] += h;
            if let Some(r1) = self.residuals(&th) {
                for k in 0..nr {
                    jac[(k, col)] = (r1[k] - r0[k]) / h;
                }
            }
        }
        let e = DVector::from_vec(r0);
        Normal {
            jtj: jac.transpose() * &jac,
            jte: -(jac.transpose() * &e),
            ssr: e.norm_squared(),
        }
    }
}

/// Lines whose FRF is reliable: `σ/|Ĝ| ≤` [`RELIABLE_REL_SIGMA`].
pub fn reliable_lines(frf: &Frf) -> Vec<usize> {
    (0..frf.g.len())
        .filter(|&i| {
            let a = frf.g[i].norm();
            a > 0.0 && frf.sigma[i] <= RELIABLE_REL_SIGMA * a
        })
        .collect()
}

fn rigid_power(output: Output) -> i32 {
    match output {
        Output::Angle => 2,
        Output::Velocity => 1,
    }
}

/// Resonances of the FRF: local maxima of `|Ĝ| ω^k` over the reliable lines
/// (`k` 2 for the angle, 1 for the velocity), with their topographic
/// prominence (height above the higher of the two lowest points that
/// separate the peak from higher ground on either side), at least 0.3 dB,
/// strongest first.
pub fn frf_peaks(frf: &Frf, output: Output) -> Vec<FrfPeak> {
    let idx = reliable_lines(frf);
    let k = rigid_power(output);
    let h: Vec<f64> = idx
        .iter()
        .map(|&i| {
            let w = 2.0 * std::f64::consts::PI * frf.freq_hz[i];
            20.0 * (frf.g[i].norm() * w.powi(k)).log10()
        })
        .collect();
    let mut peaks = Vec::new();
    for j in 1..h.len().saturating_sub(1) {
        if !(h[j] > h[j - 1] && h[j] >= h[j + 1]) {
            continue;
        }
        let mut left = h[j];
        let mut i = j;
        while i > 0 {
            i -= 1;
            if h[i] > h[j] {
                break;
            }
            left = left.min(h[i]);
        }
        let mut right = h[j];
        let mut i = j;
        while i + 1 < h.len() {
            i += 1;
            if h[i] > h[j] {
                break;
            }
            right = right.min(h[i]);
        }
        let prom = h[j] - left.max(right);
        if prom >= 0.3 {
            peaks.push(FrfPeak {
                freq_hz: frf.freq_hz[idx[j]],
                prominence_db: prom,
            });
        }
    }
    peaks.sort_by(|a, b| b.prominence_db.total_cmp(&a.prominence_db));
    peaks
}

/// Start features for chosen resonances: notches below each, the rigid
/// body from the lines below the first notch.
fn features(frf: &Frf, output: Output, res_hz: &[f64], zeta: f64) -> Result<Features, FrfFitError> {
    let idx = reliable_lines(frf);
    let k = rigid_power(output);
    let height = |i: usize| {
        let w = 2.0 * std::f64::consts::PI * frf.freq_hz[i];
        frf.g[i].norm() * w.powi(k)
    };
    let mut pairs = Vec::new();
    let mut lo = 0.0;
    for &p in res_hz {
        let z = idx
            .iter()
            .filter(|&&i| frf.freq_hz[i] > lo && frf.freq_hz[i] < p)
            .min_by(|&&a, &&b| height(a).total_cmp(&height(b)))
            .map(|&i| frf.freq_hz[i])
            .filter(|&z| z > lo)
            .unwrap_or(0.7 * p);
        pairs.push((z.max(0.3 * p), p));
        lo = p;
    }
    let top = pairs.first().map_or(f64::INFINITY, |p| 0.5 * p.0);
    let mut low: Vec<usize> = idx
        .iter()
        .copied()
        .filter(|&i| frf.freq_hz[i] < top)
        .collect();
    if low.len() < 3 {
        low = idx.iter().copied().take(3).collect();
    }
    let (mut js, mut fs) = (Vec::new(), Vec::new());
    for &i in &low {
        let w = 2.0 * std::f64::consts::PI * frf.freq_hz[i];
        let inv = frf.g[i].inv();
        match output {
            Output::Angle => {
                js.push(-inv.re / (w * w));
                fs.push(inv.im / w);
            }
            Output::Velocity => {
                js.push(inv.im / w);
                fs.push(inv.re);
            }
        }
    }
    let med = |v: &mut Vec<f64>| {
        if v.is_empty() {
            return f64::NAN;
        }
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let j_total = med(&mut js);
    if !(j_total > 0.0 && j_total.is_finite()) {
        return Err(FrfFitError::NoRigidBody {
            detail: format!(
                "median inertia {j_total:.3e} kg·m² over {} lines below {top:.2} Hz",
                low.len()
            ),
        });
    }
    let mut f_m = med(&mut fs);
    let w_low = 2.0 * std::f64::consts::PI * frf.freq_hz[low[0]];
    if !(f_m > 1e-3 * j_total * w_low && f_m.is_finite()) {
        // unresolved: a mechanical pole a decade below the lowest line
        f_m = 0.1 * j_total * w_low;
    }
    Ok(Features {
        j_total,
        f_m,
        pairs,
        zeta1: zeta,
        subspace_order: 0,
    })
}

/// all `k`-subsets of `0..n`, in lexicographic order
fn subsets(n: usize, k: usize) -> Vec<Vec<usize>> {
    if k == 0 {
        return vec![Vec::new()];
    }
    if k > n {
        return Vec::new();
    }
    let mut out = Vec::new();
    let mut cur: Vec<usize> = (0..k).collect();
    loop {
        out.push(cur.clone());
        let mut i = k;
        while i > 0 && cur[i - 1] == n - k + i - 1 {
            i -= 1;
        }
        if i == 0 {
            return out;
        }
        cur[i - 1] += 1;
        for j in i..k {
            cur[j] = cur[j - 1] + 1;
        }
    }
}

fn is_loss(name: &str) -> bool {
    name.starts_with('d') || name.starts_with('f') || name == "Fv"
}

struct Candidate {
    theta: Vec<f64>,
    start: Vec<f64>,
    fit: LmFit,
    cost: f64,
    opts: LmOptions,
}

/// Fits the physical model of `opts` to the FRF (module docs).
///
/// # Errors
/// [`FrfFitError`] when the FRF cannot carry the model or no start works.
pub fn fit_frf(frf: &Frf, opts: &FrfFitOptions) -> Result<FrfFit, FrfFitError> {
    if !(opts.ts > 0.0 && opts.ts.is_finite()) {
        return Err(FrfFitError::SampleInterval(opts.ts));
    }
    for (what, d) in [("lag", opts.lag), ("delay", opts.delay)] {
        if let Drive::Fixed(v) = d {
            if !(0.0..=MAX_DRIVE_SAMPLES).contains(&v) {
                return Err(FrfFitError::Drive { what, value: v });
            }
        }
    }
    let structure = opts.structure;
    let names = structure.param_names();
    let nm = names.len();
    let needed = nm + 2;
    if frf.g.len() < needed {
        return Err(FrfFitError::TooFewLines {
            lines: frf.g.len(),
            needed,
            structure: structure_name(structure),
        });
    }
    let model = GreyBoxModel {
        structure,
        output: opts.output,
        r: opts.r,
        ts: opts.ts,
    };
    let lines = Lines::new(frf, opts.ts);
    let peaks = frf_peaks(frf, opts.output);
    let n_res = structure.masses() - 1;
    let zetas: &[f64] = if n_res == 0 { &[0.05] } else { &[0.03, 0.12] };
    let expected = lines.expected_cost(needed);
    let drive0 = |d: Drive, start: f64| match d {
        Drive::Estimate => start,
        Drive::Fixed(v) => v,
    };
    let lag0 = drive0(opts.lag, 0.5);
    let delay0 = drive0(opts.delay, 0.5);
    let fixed_drive = [
        matches!(opts.lag, Drive::Fixed(_)),
        matches!(opts.delay, Drive::Fixed(_)),
    ];
    let bounds = |th0: &[f64]| -> (Vec<f64>, Vec<f64>) {
        let span = 1e3f64.ln();
        let mut lo: Vec<f64> = th0[..nm].iter().map(|t| t - span).collect();
        let mut hi: Vec<f64> = th0[..nm].iter().map(|t| t + span).collect();
        lo.extend([0.0, 0.0]);
        hi.extend([MAX_DRIVE_SAMPLES, MAX_DRIVE_SAMPLES]);
        (lo, hi)
    };
    let phys = PhysicalFrf(model);
    let log_p = Problem {
        model: &phys,
        lines: &lines,
        cost: Cost::Log,
    };
    let sml_p = Problem {
        model: &phys,
        lines: &lines,
        cost: Cost::Sml,
    };
    let mut pool: Vec<Candidate> = Vec::new();
    let mut starts = 0;
    let mut first_err = None;
    let mut tried: Vec<Vec<f64>> = Vec::new();
    // pass 0: the strongest peaks; pass 1, when the FRF shows fewer peaks
    // than the structure has modes (two modes close together, one a
    // shoulder of the other) or no start came near the noise level:
    // modes also placed around the strongest peaks. A start whose SML cost
    // is already within a few times the noise level ends the search: it is
    // in the basin of the estimate (a wrong mode costs orders of magnitude).
    'search: for pass in 0..2 {
        let cand = if pass == 0 {
            let mut c: Vec<f64> = peaks.iter().take(n_res + 2).map(|p| p.freq_hz).collect();
            c.sort_by(f64::total_cmp);
            c
        } else {
            let best = pool.iter().map(|c| c.cost).fold(f64::INFINITY, f64::min);
            if n_res == 0 || (peaks.len() >= n_res && best < 10.0 * expected) {
                break;
            }
            augmented_candidates(&peaks, n_res)
        };
        let zetas: &[f64] = if pass == 1 && n_res >= 3 {
            &[0.05]
        } else {
            zetas
        };
        for choice in subsets(cand.len(), n_res.min(cand.len())) {
            let res_hz: Vec<f64> = choice.iter().map(|&i| cand[i]).collect();
            if tried.contains(&res_hz) {
                continue;
            }
            tried.push(res_hz.clone());
            for &zeta in zetas {
                let feat = match features(frf, opts.output, &res_hz, zeta) {
                    Ok(f) => f,
                    Err(e) => {
                        first_err.get_or_insert(e);
                        continue;
                    }
                };
                let p0 = grey_box::initial_values(structure, opts.r, &feat);
                let mut th0: Vec<f64> = p0.iter().map(|v| v.max(1e-300).ln()).collect();
                th0.extend([lag0, delay0]);
                let (lower, upper) = bounds(&th0);
                starts += 1;
                // stage 1: losses and drive; stage 2: everything (log cost)
                let mut fixed: Vec<bool> = names.iter().map(|n| !is_loss(n)).collect();
                fixed.extend(fixed_drive);
                let mut o = LmOptions {
                    max_iter: 20,
                    rel_cost_tol: 1e-6,
                    lower,
                    upper,
                    fixed,
                    ..Default::default()
                };
                let Ok(f1) = lm::minimize(&log_p, &th0, &o) else {
                    continue;
                };
                o.fixed = vec![false; nm];
                o.fixed.extend(fixed_drive);
                o.max_iter = 40;
                let Ok(f2) = lm::minimize(&log_p, &f1.theta, &o) else {
                    continue;
                };
                let c = sml_p.cost(&f2.theta);
                if c.is_finite() {
                    pool.push(Candidate {
                        theta: f2.theta.clone(),
                        start: th0,
                        fit: f2,
                        cost: c,
                        opts: o,
                    });
                    if c < GOOD_START_RATIO * expected {
                        break 'search;
                    }
                }
            }
        }
    }
    if pool.is_empty() {
        return Err(first_err.unwrap_or(FrfFitError::NoStart));
    }
    pool.sort_by(|a, b| a.cost.total_cmp(&b.cost));
    pool.truncate(3);
    // SML refinement of the best starts with the drive as asked: a few
    // iterations each, then the best one to convergence
    let mut best: Option<Candidate> = None;
    for c in pool {
        let mut o = c.opts.clone();
        o.max_iter = 25;
        o.rel_cost_tol = 1e-10;
        if let Ok(f) = lm::minimize(&sml_p, &c.theta, &o) {
            let cost = f.ssr;
            if best.as_ref().is_none_or(|b| cost < b.cost) {
                best = Some(Candidate {
                    theta: f.theta.clone(),
                    start: c.start,
                    fit: f,
                    cost,
                    opts: o,
                });
            }
        }
    }
    let best = match best {
        Some(mut b) if b.fit.termination == Termination::MaxIterations => {
            b.opts.max_iter = opts.max_iter;
            if let Ok(f) = lm::minimize(&sml_p, &b.theta, &b.opts) {
                b.theta = f.theta.clone();
                b.cost = f.ssr;
                b.fit = f;
            }
            Some(b)
        }
        b => b.map(|mut b| {
            b.opts.max_iter = opts.max_iter;
            b
        }),
    };
    let mut best = best.ok_or(FrfFitError::NoStart)?;
    // drive variants: lag only, delay only (each where estimated), by AIC
    if !fixed_drive[0] && !fixed_drive[1] {
        let aic = |c: &Candidate| c.cost + 2.0 * c.fit.n_free as f64;
        for drop in [nm, nm + 1] {
            let mut th = best.theta.clone();
            th[drop] = 0.0;
            let mut o = best.opts.clone();
            o.fixed[drop] = true;
            if let Ok(f) = lm::minimize(&sml_p, &th, &o) {
                let c = Candidate {
                    theta: f.theta.clone(),
                    start: best.start.clone(),
                    cost: f.ssr,
                    fit: f,
                    opts: o,
                };
                if aic(&c) < aic(&best) {
                    best = c;
                }
            }
        }
    }
    Ok(finish(model, frf, best, peaks, starts, fixed_drive))
}

/// Candidate mode frequencies for a second search: the peaks, and around the
/// two strongest of them, frequencies where a mode hidden in their shoulder
/// may sit; at most nine, none within 3 % of another [Hz].
fn augmented_candidates(peaks: &[FrfPeak], n_res: usize) -> Vec<f64> {
    let mut c: Vec<f64> = peaks.iter().take(n_res + 2).map(|p| p.freq_hz).collect();
    for p in peaks.iter().take(2) {
        for m in [0.8, 1.2, 0.65, 1.45] {
            c.push(m * p.freq_hz);
        }
    }
    let mut out: Vec<f64> = Vec::new();
    for f in c {
        if out.len() < 9 && !out.iter().any(|g| (g - f).abs() < 0.03 * f) {
            out.push(f);
        }
    }
    out.sort_by(f64::total_cmp);
    out
}

fn structure_name(s: Structure) -> &'static str {
    match s {
        Structure::Rigid => "rigid",
        Structure::TwoMass => "two-mass",
        Structure::ThreeMass => "three-mass",
        Structure::FourMass => "four-mass",
    }
}

/// The reported order of the four-mass model's interchangeable branches
/// ([`grey_box::FOUR_MASS_BRANCHES`]), applied to a candidate with its
/// covariance.
fn canonical_four_mass(c: &mut Candidate) {
    let nm = Structure::FourMass.param_names().len();
    if !grey_box::four_mass_swapped(&c.theta[..nm.min(c.theta.len())]) {
        return;
    }
    for (i, j) in grey_box::FOUR_MASS_BRANCHES {
        c.theta.swap(i, j);
        c.start.swap(i, j);
        c.fit.theta.swap(i, j);
        c.fit.std.swap(i, j);
        c.fit.cov.swap_rows(i, j);
        c.fit.cov.swap_columns(i, j);
    }
}

fn finish(
    model: GreyBoxModel,
    frf: &Frf,
    mut best: Candidate,
    peaks: Vec<FrfPeak>,
    starts: usize,
    fixed_drive: [bool; 2],
) -> FrfFit {
    if model.structure == Structure::FourMass {
        canonical_four_mass(&mut best);
    }
    let names = model.structure.param_names();
    let nm = names.len();
    let th = &best.theta;
    let params = grey_box::phys_params(names, th, &best.fit.std);
    let initial = grey_box::phys_params(names, &best.start, &[]);
    let drive = |i: usize, fixed: bool| DriveEstimate {
        value: th[i],
        std: best.fit.std[i],
        estimated: !fixed && !best.opts.fixed[i],
    };
    let lag = drive(nm, fixed_drive[0]);
    let delay = drive(nm + 1, fixed_drive[1]);
    let spectra_dof = if frf.spectra.periods >= 2 {
        frf.spectra.dof()
    } else {
        0.0
    };
    let mut fit = FrfFit {
        model,
        params,
        initial,
        lag,
        delay,
        cost: best.cost,
        lm: best.fit,
        noise_dof: spectra_dof,
        peaks,
        resonances_hz: Vec::new(),
        anti_resonances_hz: Vec::new(),
        warnings: Vec::new(),
        starts,
        lines: frf.g.len(),
    };
    let c = fit.continuous();
    let f_min = frf.freq_hz.first().copied().unwrap_or(0.0);
    let rz = c.resonances(f_min, 0.5);
    fit.resonances_hz = rz.resonances.iter().map(|m| m.freq_hz).collect();
    fit.anti_resonances_hz = rz.anti_resonances.iter().map(|m| m.freq_hz).collect();
    fit.warnings = check(&fit, &best.opts, frf);
    fit
}

/// The checks of a finished fit (module docs; [`FitWarning`]).
fn check(fit: &FrfFit, opts: &LmOptions, frf: &Frf) -> Vec<FitWarning> {
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
    for p in &fit.peaks {
        if p.prominence_db >= MISSED_PEAK_DB
            && !fit
                .resonances_hz
                .iter()
                .any(|&m| (m - p.freq_hz).abs() <= tol(p.freq_hz))
        {
            w.push(FitWarning::MissedResonance {
                freq_hz: p.freq_hz,
                prominence_db: p.prominence_db,
            });
        }
    }
    // peaks the model would show at the measured lines but the FRF does not
    let seen = Frf {
        g: fit.freq_response(&frf.freq_hz),
        spectra: FrfSpectra::default(),
        ..frf.clone()
    };
    for m in frf_peaks(&seen, fit.model.output) {
        if m.prominence_db >= MISSED_PEAK_DB
            && !fit
                .peaks
                .iter()
                .any(|p| (m.freq_hz - p.freq_hz).abs() <= tol(m.freq_hz))
        {
            w.push(FitWarning::ExtraResonance { freq_hz: m.freq_hz });
        }
    }
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
    100.0 * (1.0 - (e / d).sqrt())
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

#[cfg(test)]
mod tests;
