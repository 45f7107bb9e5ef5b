//! Output-error fit of a [`NlModel`] driven by the measured torque: Levenberg–Marquardt
//! ([`crate::ident::lm`]) on the interval-mean motor velocity, with exact derivatives of
//! the discrete simulation by forward-mode automatic differentiation (dual numbers carry
//! one derivative per free parameter through every RK4 stage: the forward sensitivities of
//! the integrator as it is, not of the ODE), and the parameter covariance corrected for
//! coloured residuals.
//!
//! Why velocity: the rigid-body mode integrates every unmodelled low-frequency torque (a
//! slow load, an offset, friction the model lacks) into a drift of the motor angle, and a
//! least-squares cost on the angle then fits the drift. On the velocity the drift is one
//! integration smaller, the torque offset is estimated, and the initial rigid-body velocity
//! `v0` is a nuisance parameter. What is left of a slow disturbance is a low-frequency
//! velocity error, which the residual's prefilter removes: a second-order Butterworth
//! high-pass (default [`DEFAULT_HIGHPASS_HZ`]) applied alike to the residual and to its
//! derivatives, i.e. a frequency weighting of the cost (Ljung, *System Identification*,
//! 2nd ed., §14.4, prefiltering). Seed 001 fits the same output, unfiltered, on data
//! without disturbance.
//!
//! Band limit ([`NlOptions::lowpass_hz`]): a fourth-order Butterworth low-pass at the top of
//! the band the excitation and the joint's response to it occupy
//! ([`crate::data::excited_band_top`]) joins the high-pass in the prefilter. Above it a
//! closed-loop record holds no excitation: the measured torque there is the controller's
//! reaction to the encoder's quantisation and to the disturbance, and the angle that
//! reaction's response plus the quantisation itself, so the fit from the measured torque is
//! drawn there towards the inverse of the controller (the direct method's bias, Ljung,
//! *System Identification*, 2nd ed., §13.4). Measured on the default three-mass joint at
//! 0.015 rad RMS with a 2¹⁴-count encoder and nothing else: `J_m` −4.7 %, `k_g` −7.0 % and
//! the lag on its bound without the low-pass; +0.2 %, +0.3 % and 0.34 ms (the truth 0.26 ms)
//! with it at 150 Hz; the bias grows with the cut-off (−1.0 % at 240 Hz, −3.7 % at 490 Hz).
//! The disturbance inside the band and white noise on either signal moved no parameter by
//! more than 0.6 % on that joint, with or without it. The callers set it for models that
//! stay linear (no effect, a delay, a further mode): a nonlinear effect puts its own
//! distortion above the band, and its fit needs it (stick-slip, a chaotic spring).
//!
//! Covariance: `H⁻¹ S H⁻¹` with `H = JᵀJ` and `S = Σ_τ w_τ r_e(τ) Σ_t J_t J_{t+τ}ᵀ` over
//! lags `|τ| ≤ L` with Bartlett weights `w_τ = 1 − |τ|/(L + 1)` (Ljung, *System
//! Identification*, 2nd ed., §9.3, the asymptotic covariance of a prediction-error estimate
//! with correlated residuals; Newey & West 1987 for the weights). A differenced quantised
//! angle is not white (its errors are negatively correlated at lag 1), so the plain
//! `σ̂² H⁻¹` would misstate the standard deviations.
//!
//! Exact-law correction ([`NlOptions::exact_correction`]): the smooth Coulomb law
//! `F_c tanh(ω/v_ε)` is not the set-valued law that made the data (nor the one the
//! validation FIT simulates): near reversals it creeps where the exact law sticks, and the
//! least-squares estimate absorbs the difference (on the default three-mass joint with
//! pure Coulomb friction, `v_ε` = 0.0037 rad/s: F_c +2.4 %, 12 σ). The σ of the sandwich
//! covariance is the noise's and cannot show this bias, so it is removed instead: after
//! the smooth fit, Gauss–Newton steps on the cost of the **exact** law (the residual of
//! [`crate::sim::simulate_driven`] from the estimator's initial state, through the same
//! prefilter), with the smooth law's Jacobian `J` at the estimate as the model's
//! sensitivity, `Δz = (JᵀJ)⁻¹ Jᵀ e_exact`; each step is kept only when it lowers the
//! exact-law cost. The covariance is then evaluated with the exact-law residuals. Skipped
//! with a torque ripple attached (the simulator evaluates it at the simulated angle, the
//! estimator at the measured one, a difference the steps would fit). The steps remove only
//! part of the bias (the smooth law's Jacobian is a poor guide to the exact cost's valley:
//! on that joint F_c +3.1 % → +2.2 %), so what is left is put into the σ:
//!
//! Smoothing term of the σ ([`NlOptions::smoothing_sigma`]): one Gauss–Newton step of the
//! fit with `v_ε` doubled, from the estimate, and each parameter's change times
//! [`SMOOTHING_BIAS_FACTOR`] is the size of the smooth law's bias at `v_ε`, added in
//! quadrature to its σ. The factor is `1/(2^p − 1)` for a bias growing as `v_ε^p`;
//! measured on the default three-mass joint with pure Coulomb friction, F_c +14 % at
//! `v_ε` = 0.05 rad/s and +2.4 % at 0.0037: `p` = 0.68, factor 1.66.

use nalgebra::{DMatrix, DVector};
use thiserror::Error;

use super::dual::Dual;
use super::model::{NlModel, Owner, ParamDef, Plant, Scale};
use crate::data::dsp::{butter_highpass_sos, SosBank};
use crate::data::IdData;
use crate::ident::linalg::pinv_sym;
use crate::ident::lm::{self, LeastSquares, LmOptions, Normal, Termination};
use crate::ident::parallel::{join, machine_threads};
use crate::ident::validate::{centred_sum_of_squares, fit_from_sums, fit_percent};

/// Why a nonlinear fit could not run.
#[derive(Debug, Error)]
pub enum NlError {
    /// a record is too short or not finite
    #[error(transparent)]
    Record(#[from] crate::data::RecordError),
    /// no record given to fit
    #[error("no record to fit")]
    NoRecord,
    /// no record given to validate on
    #[error("no record to validate on")]
    NoValidationRecord,
    /// the start's values do not match the model's parameters
    #[error("{values} start values for {params} parameters")]
    StartLength {
        /// values given
        values: usize,
        /// parameters of the model
        params: usize,
    },
    /// a step of the automatic start could not read the data
    #[error(transparent)]
    StartStep(#[from] crate::ident::grey_box::GreyBoxError),
    /// step 1 of the automatic start found no positive inertia
    #[error(
        "no positive rigid-body inertia in the data (step 1 of the start){}",
        if *grounded {
            ": the torque holds the angle like a spring to the frame (a mass and a stiffness to \
             ground fit the same regression, both positive): try `--model grounded`"
        } else {
            ""
        }
    )]
    NoInertia {
        /// the regression with a stiffness to ground finds a positive mass and stiffness
        grounded: bool,
    },
    /// step 3 of the automatic start found no linear start for a flexible structure
    #[error("no linear start for the flexible structure (step 3 of the start)")]
    NoFlexibleStart,
    /// the simulator refused the model or the record (the exact laws)
    #[error("simulation with the exact laws: {0}")]
    Simulation(#[source] crate::sim::SimError),
    /// the simulator refused the model or the validation record
    #[error("validation simulation: {0}")]
    ValidationSimulation(#[source] crate::sim::SimError),
    /// the start does not simulate to finite values
    #[error("the start of the nonlinear fit does not simulate to finite values")]
    Unstable,
    /// too many free parameters for the derivative type
    #[error("{0} free parameters; at most 32 can be estimated together")]
    TooManyParameters(usize),
    /// the optimiser refused the problem
    #[error(transparent)]
    Optimiser(#[from] crate::ident::lm::LmError),
}

/// Default cut-off of the residual's high-pass prefilter [Hz]: above the slow torque
/// disturbances a position loop rejects (and the drift they leave in an open-loop
/// simulation), below the resonances of a robot joint (10–30 Hz for the IRB1400's axis 1,
/// seed 000). Measured on the project's default three-mass joint with its default slow
/// disturbance (1 mN·m, 1 Hz; the cubic spring attached): `d_g` −20 %, `f_m` +330 % at
/// 1 Hz; −1.0 % and +11 % (1.5 σ) at 5 Hz. The viscous friction `f_m`, whose rigid-body
/// corner lies far below the cut-off, is then weakly determined, and its σ says so.
pub const DEFAULT_HIGHPASS_HZ: f64 = 5.0;

/// Options of [`fit_output_error`].
#[derive(Clone, Debug, PartialEq)]
pub struct NlOptions {
    /// most Levenberg–Marquardt iterations
    pub max_iter: usize,
    /// parameters held at their start, by layout name
    pub fixed: Vec<String>,
    /// plant parameters may move this factor either way from their start [-]
    pub plant_range: f64,
    /// the values (layout order) `plant_range` is measured from, when not the start (the
    /// bounds then still hold the start): a fit continued from where an earlier one
    /// stopped keeps that one's bounds; a nested refit whose effect starts shrunk can grow
    /// it back to its own fit's size (the diagnosis's nested refits)
    pub range_from: Option<Vec<f64>>,
    /// most lags `L` of the covariance correction
    pub cov_lags: usize,
    /// samples at the start left out of the cost (transient of the flexible modes)
    pub skip: usize,
    /// cut-off of the high-pass prefilter of the residual [Hz]; 0: none
    pub highpass_hz: f64,
    /// order of that Butterworth high-pass (even)
    pub highpass_order: usize,
    /// which motor signal the residual compares
    pub residual: Residual,
    /// how the Jacobian is computed
    pub gradient: Gradient,
    /// with Coulomb friction attached: Gauss–Newton steps on the exact law's cost after the
    /// smooth fit (module documentation; not with `max_iter` 0)
    pub exact_correction: bool,
    /// with Coulomb friction attached: the smoothing term of the σ (module documentation;
    /// not with `max_iter` 0)
    pub smoothing_sigma: bool,
    /// stop when an accepted step lowers the cost by less than this share of it (the
    /// optimiser's default: 10⁻⁹, a converged estimate)
    pub rel_cost_tol: f64,
    /// stop when the Gauss–Newton step would lower the cost by less than this many
    /// residual variances ([`LmOptions::within_noise`]; [`WITHIN_NOISE`]); 0: off
    pub within_noise: f64,
    /// cut-off of the prefilter's fourth-order Butterworth low-pass, the top of the excited
    /// band (module documentation, band limit) [Hz]; 0: none
    pub lowpass_hz: f64,
    /// the optimiser's active set ([`LmOptions::active_set`])
    pub active_set: bool,
}

/// The default [`NlOptions::within_noise`]: a Gauss–Newton step worth less than a hundredth
/// of a residual variance moves the estimate by less than a tenth of its white-noise σ,
/// and the output error's coloured residual makes its reported σ larger still. The fits
/// that stopped at 10⁻⁹ of the cost crawled on for tens of iterations at 0.01–0.05 σ̂²
/// each (a three-mass joint with friction and a mode: 31 iterations of which 27 gained
/// 0.05 σ̂² together).
pub const WITHIN_NOISE: f64 = 0.01;

/// Size of the smooth Coulomb law's bias at `v_ε` over the change of the estimate when
/// `v_ε` is doubled, `1/(2^0.68 − 1)` (module documentation).
pub const SMOOTHING_BIAS_FACTOR: f64 = 1.66;

/// How the fit differentiates the simulation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Gradient {
    /// forward-mode automatic differentiation (dual numbers): exact, one pass (the default)
    Dual,
    /// central differences of the simulation, `2 n + 1` passes: the reference of the
    /// benchmark
    CentralDifferences,
}

/// The motor signal the output-error cost compares.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Residual {
    /// the measured motor angle against the simulated one (white encoder noise stays white;
    /// the default)
    Angle,
    /// the interval-mean motor velocity `(θ_m[k] − θ_m[k−1])/T` (seed 001's output)
    Velocity,
}

impl Default for NlOptions {
    fn default() -> Self {
        NlOptions {
            max_iter: 60,
            fixed: Vec::new(),
            plant_range: 100.0,
            range_from: None,
            cov_lags: 40,
            skip: 0,
            highpass_hz: DEFAULT_HIGHPASS_HZ,
            highpass_order: 2,
            residual: Residual::Velocity,
            gradient: Gradient::Dual,
            exact_correction: true,
            smoothing_sigma: true,
            rel_cost_tol: LmOptions::default().rel_cost_tol,
            within_noise: WITHIN_NOISE,
            lowpass_hz: 0.0,
            active_set: false,
        }
    }
}

impl NlOptions {
    /// The options fitted for `structure`: a rigid body is fitted without the high-pass
    /// prefilter, since its inertia and friction show at the low frequencies the prefilter
    /// would remove (EMPS moves below 5 Hz); its torque offset is estimated instead. So is
    /// the grounded mass: it does not drift, and its spring shows below its resonance.
    pub fn for_structure(mut self, structure: crate::model::spec::Structure) -> Self {
        use crate::model::spec::Structure;
        if matches!(structure, Structure::Rigid | Structure::Grounded) {
            self.highpass_hz = 0.0;
        }
        self
    }
}

/// One estimated parameter.
#[derive(Clone, Debug, PartialEq)]
pub struct NlParam {
    /// layout name
    pub name: &'static str,
    /// what it belongs to
    pub owner: Owner,
    /// estimate [unit]
    pub value: f64,
    /// standard deviation [unit] (0 when fixed)
    pub std: f64,
    /// unit
    pub unit: &'static str,
    /// held at its start
    pub fixed: bool,
    /// on or next to one of its bounds
    pub at_bound: bool,
    /// on or next to its lower bound (an effect's size there is of no size)
    pub at_lower: bool,
}

/// Result of [`fit_output_error`].
#[derive(Clone, Debug, PartialEq)]
pub struct NlFit {
    /// the model with the estimated effect values and current loop
    pub model: NlModel,
    /// the structure's values ([`crate::model::spec::Structure::param_names`] order)
    pub plant: Vec<f64>,
    /// every parameter of the layout
    pub params: Vec<NlParam>,
    /// physical values in layout order
    pub values: Vec<f64>,
    /// `Σ e²` of the prefiltered residual [rad² or (rad/s)²]
    pub ssr: f64,
    /// the band's low-pass in that prefilter [Hz] ([`NlOptions::lowpass_hz`]; 0: none): the
    /// cost `ssr` is of, which a continuation of the fit must keep to compare with it
    pub lowpass_hz: f64,
    /// residuals in the cost
    pub n_residuals: usize,
    /// iterations used
    pub iterations: usize,
    /// why the iteration stopped
    pub termination: Termination,
    /// toolbox FIT of the interval-mean motor velocity on the estimation data, both
    /// signals through the cost's high-pass prefilter, with the estimator's (smooth) laws
    /// [%] ([`velocity_fit`])
    pub fit_velocity_percent: f64,
    /// pairs of free parameters whose estimates are strongly correlated
    /// (`|ρ| ≥` [`CORRELATED`]), from the sandwich covariance; the initial velocity is left out
    pub correlated: Vec<Correlation>,
}

/// `|ρ|` from which two estimates are reported as correlated ([`NlFit::correlated`]).
pub const CORRELATED: f64 = 0.95;

/// Correlation of two estimates.
#[derive(Clone, Debug, PartialEq)]
pub struct Correlation {
    /// layout name of the first parameter
    pub a: &'static str,
    /// layout name of the second parameter
    pub b: &'static str,
    /// correlation coefficient of their estimates [-]
    pub rho: f64,
}

impl NlFit {
    /// Estimated value of a parameter by its layout name and owner.
    pub fn get(&self, name: &str) -> Option<f64> {
        self.params.iter().find(|p| p.name == name).map(|p| p.value)
    }

    /// Whether the fit holds no current-loop lag it estimated: none fitted (a lag to start
    /// from below [`super::UNRESOLVED_LAG`] of a sample is left out), or one on its lower
    /// bound. The data then ask for no more delay than holding each input sample over its
    /// interval adds, or less ([`crate::data::IdData::input_as_sampled`]).
    pub fn holds_no_lag(&self) -> bool {
        self.params
            .iter()
            .find(|p| p.name == "tau_c")
            .is_none_or(|p| !p.fixed && p.at_lower)
    }
}

/// Interval-mean velocity `(y[k] − y[k−1])/T` (sample 0 repeats sample 1).
pub fn interval_velocity(y: &[f64], ts: f64) -> Vec<f64> {
    // sized once: an insert at the front of a full vector would double its capacity
    let mut v = Vec::with_capacity(y.len());
    v.extend(interval_velocities(y, ts).take(1));
    v.extend(interval_velocities(y, ts));
    v
}

/// [`interval_velocity`] from sample 1 on, computed as it is read [rad/s].
pub fn interval_velocities(y: &[f64], ts: f64) -> impl ExactSizeIterator<Item = f64> + '_ {
    y.windows(2).map(move |w| (w[1] - w[0]) / ts)
}

/// Simulated interval-mean motor velocity of `model` at physical values `p` driven by `u`
/// from the motor angle `theta0` [rad] (sample 0 repeats sample 1), the torque ripple at
/// the `measured` motor angle when given; `None` when the simulation is not finite.
pub fn simulate_velocity(
    model: &NlModel,
    p: &[f64],
    u: &[f64],
    ts: f64,
    theta0: f64,
    measured: Option<&[f64]>,
) -> Option<Vec<f64>> {
    let plant = Plant::<f64>::new(model, p);
    let mut v = vec![0.0; u.len()];
    let ok = plant.simulate(u, ts, theta0, measured, model.substeps, |k, _, x| v[k] = x);
    if !ok || u.is_empty() {
        return None;
    }
    if v.len() > 1 {
        v[0] = v[1];
    }
    Some(v)
}

/// Toolbox FIT `100 (1 − ‖v − v̂‖/‖v − mean v‖)` [%] of the measured interval-mean
/// velocity `v` against the simulated `v̂`, both through the second-order Butterworth
/// high-pass at `highpass_hz` (0: unfiltered) that the fit's cost uses, so that the slow
/// disturbance the loop rejects does not count as model error.
///
/// # Errors
/// As [`fit_percent`].
pub fn velocity_fit(
    v: &[f64],
    vh: &[f64],
    ts: f64,
    highpass_hz: f64,
) -> Result<f64, crate::ident::validate::ValidateError> {
    let (mut a, mut b) = (Vec::with_capacity(v.len()), Vec::with_capacity(v.len()));
    highpass_pair(v, vh, ts, highpass_hz, &mut a, &mut b);
    fit_percent(&a, &b)
}

/// `v` and `v̂` through the fit's prefilter (a second-order Butterworth high-pass at
/// `highpass_hz` started afresh; 0: unfiltered), appended to `a` and `b`.
fn highpass_pair(
    v: &[f64],
    vh: &[f64],
    ts: f64,
    highpass_hz: f64,
    a: &mut Vec<f64>,
    b: &mut Vec<f64>,
) {
    if highpass_hz <= 0.0 {
        a.extend_from_slice(v);
        b.extend_from_slice(vh);
        return;
    }
    let mut bank = SosBank::new(butter_highpass_sos(2, highpass_hz, ts), 2);
    for (&x, &y) in v.iter().zip(vh) {
        let mut s = [x, y];
        bank.push(&mut s);
        a.push(s[0]);
        b.push(s[1]);
    }
}

/// `Σ e²` of the velocity residual of `model` at physical values `values` on `data`, through
/// the default prefilter ([`DEFAULT_HIGHPASS_HZ`]);
/// `None` when the simulation is not finite.
pub fn cost_at(data: &IdData, model: &NlModel, values: &[f64]) -> Option<f64> {
    let v = interval_velocity(&data.y, data.ts);
    let vh = simulate_velocity(model, values, &data.u, data.ts, data.y[0], Some(&data.y))?;
    let mut bank = SosBank::new(butter_highpass_sos(2, DEFAULT_HIGHPASS_HZ, data.ts), 1);
    let mut ssr = 0.0;
    for (a, b) in v[1..].iter().zip(&vh[1..]) {
        let mut e = [a - b];
        bank.push(&mut e);
        ssr += e[0] * e[0];
    }
    ssr.is_finite().then_some(ssr)
}

struct Problem<'a> {
    model: &'a NlModel,
    layout: &'a [ParamDef],
    u: &'a [f64],
    /// measured output: the angle from its first sample or the interval-mean velocity
    v: &'a [f64],
    output: Residual,
    /// measured motor angle at sample 0 [rad]
    theta0: f64,
    /// measured motor angle [rad] (for the ripple)
    y: &'a [f64],
    gradient: Gradient,
    ts: f64,
    first: usize,
    /// high-pass sections applied to the residual and its derivatives alike
    highpass: Vec<[f64; 5]>,
}

/// Runs `$body` with `$d` a [`Dual`] that holds `$n` derivatives, its slots a multiple of
/// four: the simulation's cost grows with the registers its slots fill, four to an AVX2
/// register ([`super::model::Plant::simulate`]), so a fit of 8 parameters pays for 12
/// slots either way, and each width is compiled twice (plain and AVX2). Slots beyond the
/// parameters stay nought and never touch the others.
macro_rules! with_dual {
    ($n:expr, $d:ident => $body:expr) => {
        match $n {
            0..=3 => {
                type $d = Dual<4>;
                $body
            }
            4..=7 => {
                type $d = Dual<8>;
                $body
            }
            8..=11 => {
                type $d = Dual<12>;
                $body
            }
            12..=15 => {
                type $d = Dual<16>;
                $body
            }
            16..=19 => {
                type $d = Dual<20>;
                $body
            }
            20..=23 => {
                type $d = Dual<24>;
                $body
            }
            _ => {
                type $d = Dual<33>;
                $body
            }
        }
    };
}

impl Problem<'_> {
    fn physical(&self, z: &[f64]) -> Vec<f64> {
        self.layout
            .iter()
            .zip(z)
            .map(|(d, &z)| d.from_z(z))
            .collect()
    }

    /// The simulated output (angle or velocity, per `self.output`) at samples `k ≥ 1`
    /// (sample 0 repeats sample 1), `None` when not finite.
    fn output_f64(&self, z: &[f64]) -> Option<Vec<f64>> {
        let p = self.physical(z);
        let plant = Plant::<f64>::new(self.model, &p);
        let mut out = vec![0.0; self.u.len()];
        let ok = plant.simulate(
            self.u,
            self.ts,
            self.theta0,
            Some(self.y),
            self.model.substeps,
            |k, th, vel| {
                out[k] = match self.output {
                    Residual::Angle => th,
                    Residual::Velocity => vel,
                };
            },
        );
        ok.then_some(out)
    }

    /// [`Self::jacobian_rows`] by central differences of the `f64` simulation (step
    /// `1e-6 max(|z|, 1)` in the optimiser's coordinates): the reference the dual numbers are
    /// measured against, `2 n_free + 1` simulations per evaluation.
    fn jacobian_rows_fd(
        &self,
        z: &[f64],
        free: &[usize],
        mut visit: impl FnMut(usize, f64, &[f64]),
    ) -> bool {
        let nf = free.len();
        let Some(base) = self.output_f64(z) else {
            return false;
        };
        let mut cols = Vec::with_capacity(nf);
        for &i in free {
            let h = 1e-6 * z[i].abs().max(1.0);
            let mut zp = z.to_vec();
            zp[i] += h;
            let mut zm = z.to_vec();
            zm[i] -= h;
            let (Some(a), Some(b)) = (self.output_f64(&zp), self.output_f64(&zm)) else {
                return false;
            };
            cols.push(
                a.iter()
                    .zip(&b)
                    .map(|(a, b)| (a - b) / (2.0 * h))
                    .collect::<Vec<f64>>(),
            );
        }
        let mut buf = vec![0.0; nf + 1];
        let mut bank = SosBank::new(self.highpass.clone(), nf + 1);
        for k in self.first..self.u.len() {
            buf[0] = self.v[k] - base[k];
            for j in 0..nf {
                buf[j + 1] = cols[j][k];
            }
            bank.push(&mut buf);
            visit(k, buf[0], &buf[1..]);
        }
        true
    }

    /// Visits `(k, e_k, ∂ŷ_k/∂z_free)` for every residual; false when not finite.
    fn jacobian_rows(
        &self,
        z: &[f64],
        free: &[usize],
        mut visit: impl FnMut(usize, f64, &[f64]),
    ) -> bool {
        let nf = free.len();
        if self.gradient == Gradient::CentralDifferences {
            return self.jacobian_rows_fd(z, free, visit);
        }
        with_dual!(nf, D => {
            let width = D::from_real(0.0).len() - 1;
            debug_assert!(nf <= width);
            let p: Vec<D> = self
                .layout
                .iter()
                .zip(z)
                .enumerate()
                .map(|(i, (d, &zi))| {
                    let mut x = D::from_real(zi);
                    if let Some(j) = free.iter().position(|&f| f == i) {
                        x[j + 1] = 1.0;
                    }
                    d.from_z(x)
                })
                .collect();
            let plant = Plant::<D>::new(self.model, &p);
            // channel 0: the residual; 1..: the derivatives of the simulated output
            let mut buf = vec![0.0; nf + 1];
            let mut bank = SosBank::new(self.highpass.clone(), nf + 1);
            plant.simulate(self.u, self.ts, self.theta0, Some(self.y), self.model.substeps, |k, th, vel| {
                let vh = match self.output {
                    Residual::Angle => th,
                    Residual::Velocity => vel,
                };
                if k >= self.first {
                    buf[0] = self.v[k] - vh[0];
                    for j in 0..nf {
                        buf[j + 1] = vh[j + 1];
                    }
                    bank.push(&mut buf);
                    visit(k, buf[0], &buf[1..]);
                }
            })
        })
    }
}

impl LeastSquares for Problem<'_> {
    fn n_params(&self) -> usize {
        self.layout.len()
    }

    fn n_residuals(&self) -> usize {
        self.v.len().saturating_sub(self.first)
    }

    fn cost(&self, z: &[f64]) -> f64 {
        let p = self.physical(z);
        let plant = Plant::<f64>::new(self.model, &p);
        let mut ssr = 0.0;
        let mut bank = SosBank::new(self.highpass.clone(), 1);
        let ok = plant.simulate(
            self.u,
            self.ts,
            self.theta0,
            Some(self.y),
            self.model.substeps,
            |k, th, vel| {
                let vh = match self.output {
                    Residual::Angle => th,
                    Residual::Velocity => vel,
                };
                if k >= self.first {
                    let mut e = [self.v[k] - vh];
                    bank.push(&mut e);
                    ssr += e[0] * e[0];
                }
            },
        );
        if ok && ssr.is_finite() {
            ssr
        } else {
            f64::NAN
        }
    }

    fn normal_equations(&self, z: &[f64], free: &[usize]) -> Normal {
        let nf = free.len();
        let mut jtj = DMatrix::zeros(nf, nf);
        let mut jte = DVector::zeros(nf);
        let mut ssr = 0.0;
        let ok = self.jacobian_rows(z, free, |_, e, row| {
            ssr += e * e;
            for a in 0..nf {
                jte[a] += row[a] * e;
            }
            // the upper triangle column by column: a column is contiguous (nalgebra stores
            // by columns), so its products are taken a vector register at a time
            for (b, col) in jtj.as_mut_slice().chunks_exact_mut(nf).enumerate() {
                let rb = row[b];
                for (j, ra) in col[..=b].iter_mut().zip(&row[..=b]) {
                    *j += ra * rb;
                }
            }
        });
        for a in 0..nf {
            for b in 0..a {
                jtj[(a, b)] = jtj[(b, a)];
            }
        }
        Normal {
            jtj,
            jte,
            ssr: if ok { ssr } else { f64::NAN },
        }
    }
}

/// Several records (the gap-free segments of one capture) as separate experiments: one
/// parameter vector `z` in layout order whose initial velocity is the first record's,
/// followed by the initial velocity of every further record; each record simulated from its
/// own first angle and initial velocity, its prefilter started afresh and its first `skip`
/// samples left out, the costs summed.
struct Segments<'a> {
    parts: Vec<Problem<'a>>,
    /// layout length
    n: usize,
    /// layout index of the initial velocity
    v0: Option<usize>,
}

impl Segments<'_> {
    /// The layout vector record `e` is simulated with.
    fn part_z(&self, z: &[f64], e: usize) -> Vec<f64> {
        let mut ze = z[..self.n].to_vec();
        if let (Some(i), true) = (self.v0, e > 0) {
            ze[i] = z[self.n + e - 1];
        }
        ze
    }

    /// For record `e`: its free layout indices and where each sits in `free`.
    fn part_free(&self, free: &[usize], e: usize) -> (Vec<usize>, Vec<usize>) {
        let mut idx = Vec::new();
        let mut at = Vec::new();
        for (j, &f) in free.iter().enumerate() {
            let layout_index = if f < self.n {
                (Some(f) != self.v0 || e == 0).then_some(f)
            } else {
                (e > 0 && f == self.n + e - 1).then_some(self.v0).flatten()
            };
            if let Some(i) = layout_index {
                idx.push(i);
                at.push(j);
            }
        }
        (idx, at)
    }

    /// `H = Σ_e J_eᵀJ_e` and the sandwich's middle `S = Σ_e S_e` over `free` (module
    /// documentation; no lag crosses from one record into another).
    /// `residual`: one record's residual to use instead of the smooth law's (ignored with
    /// several records).
    /// `single`: the exact law's residual and the Jacobian already evaluated, used when
    /// there is one record.
    fn sandwich(
        &self,
        z: &[f64],
        free: &[usize],
        lags: usize,
        single: (Option<&[f64]>, Option<&JacobianTable>),
    ) -> DMatrix<f64> {
        let nf = free.len();
        let mut h = DMatrix::zeros(nf, nf);
        let mut s = DMatrix::zeros(nf, nf);
        for (e, part) in self.parts.iter().enumerate() {
            let (idx, at) = self.part_free(free, e);
            let own = if self.parts.len() == 1 {
                single
            } else {
                (None, None)
            };
            let (he, se) = sandwich_parts(part, &self.part_z(z, e), &idx, lags, own);
            for (a, &ia) in at.iter().enumerate() {
                for (b, &ib) in at.iter().enumerate() {
                    h[(ia, ib)] += he[(a, b)];
                    s[(ia, ib)] += se[(a, b)];
                }
            }
        }
        let hinv = pinv_sym(&h, 1e-14);
        &hinv * s * &hinv
    }
}

impl LeastSquares for Segments<'_> {
    fn n_params(&self) -> usize {
        self.n + self.v0.map_or(0, |_| self.parts.len() - 1)
    }

    fn n_residuals(&self) -> usize {
        self.parts.iter().map(LeastSquares::n_residuals).sum()
    }

    fn cost(&self, z: &[f64]) -> f64 {
        self.parts
            .iter()
            .enumerate()
            .map(|(e, p)| p.cost(&self.part_z(z, e)))
            .sum()
    }

    fn normal_equations(&self, z: &[f64], free: &[usize]) -> Normal {
        let nf = free.len();
        let mut jtj = DMatrix::zeros(nf, nf);
        let mut jte = DVector::zeros(nf);
        let mut ssr = 0.0;
        for (e, part) in self.parts.iter().enumerate() {
            let (idx, at) = self.part_free(free, e);
            let ne = part.normal_equations(&self.part_z(z, e), &idx);
            for (a, &ia) in at.iter().enumerate() {
                jte[ia] += ne.jte[a];
                for (b, &ib) in at.iter().enumerate() {
                    jtj[(ia, ib)] += ne.jtj[(a, b)];
                }
            }
            ssr += ne.ssr;
        }
        Normal { jtj, jte, ssr }
    }
}

/// The sections of the residual's prefilter at sample interval `ts` [s]: the high-pass at
/// `highpass_hz`, then the band's low-pass at `lowpass_hz` (module documentation), each
/// where it is set.
fn prefilter(opts: &NlOptions, ts: f64) -> Vec<[f64; 5]> {
    let mut sos = Vec::new();
    if opts.highpass_hz > 0.0 {
        sos.extend(butter_highpass_sos(
            opts.highpass_order,
            opts.highpass_hz,
            ts,
        ));
    }
    if opts.lowpass_hz > 0.0 {
        sos.extend(crate::data::dsp::butter_lowpass_sos(4, opts.lowpass_hz, ts));
    }
    sos
}

/// Fits `model` to `data` (input `u` [N·m], output `θ_m` [rad]) from the physical start
/// `start` (layout order, [`NlModel::layout`]).
///
/// # Errors
/// [`NlError`] when the data are short or not finite, the start does not simulate, or more
/// than 32 parameters are free.
pub fn fit_output_error(
    data: &IdData,
    model: &NlModel,
    start: &[f64],
    opts: &NlOptions,
) -> Result<NlFit, NlError> {
    fit_output_error_segments(std::slice::from_ref(data), model, start, opts)
}

/// As [`fit_output_error`] on several records taken as separate experiments of one joint
/// (the gap-free segments of a capture): the costs summed, each record simulated from its
/// own first angle with its own initial velocity (a nuisance parameter per record), its
/// own prefilter start-up and its own `skip`; one parameter vector, the covariance from all
/// records. The fit's values carry the first record's initial velocity; its
/// `fit_velocity_percent` pools the records ([`pooled_velocity_fit`]).
///
/// # Errors
/// As [`fit_output_error`], for any of the records; [`NlError::NoRecord`] for no record.
pub fn fit_output_error_segments(
    data: &[IdData],
    model: &NlModel,
    start: &[f64],
    opts: &NlOptions,
) -> Result<NlFit, NlError> {
    if data.is_empty() {
        return Err(NlError::NoRecord);
    }
    for d in data {
        d.check(20)?;
    }
    let layout = model.layout();
    if start.len() != layout.len() {
        return Err(NlError::StartLength {
            values: start.len(),
            params: layout.len(),
        });
    }
    let velocities: Vec<Vec<f64>> = data.iter().map(|d| interval_velocity(&d.y, d.ts)).collect();
    let firsts: Vec<usize> = velocities
        .iter()
        .map(|v| opts.skip.max(1).min(v.len() - 1))
        .collect();
    let targets: Vec<Vec<f64>> = data
        .iter()
        .zip(&velocities)
        .map(|(d, v)| match opts.residual {
            Residual::Angle => d.y.iter().map(|y| y - d.y[0]).collect(),
            Residual::Velocity => v.clone(),
        })
        .collect();
    let parts: Vec<Problem> = data
        .iter()
        .zip(&targets)
        .zip(&firsts)
        .map(|((d, target), &first)| Problem {
            model,
            layout: &layout,
            u: &d.u,
            v: target,
            output: opts.residual,
            theta0: d.y[0],
            y: &d.y,
            gradient: opts.gradient,
            ts: d.ts,
            first,
            highpass: prefilter(opts, d.ts),
        })
        .collect();
    let v0_index = layout
        .iter()
        .position(|d| d.owner == Owner::InitialVelocity);
    let problem = Segments {
        parts,
        n: layout.len(),
        v0: v0_index,
    };
    let z0: Vec<f64> = layout.iter().zip(start).map(|(d, &p)| d.to_z(p)).collect();
    let fixed: Vec<bool> = layout
        .iter()
        .map(|d| opts.fixed.iter().any(|f| f == d.name))
        .collect();
    let n_free = fixed.iter().filter(|f| !**f).count();
    if n_free > 32 {
        return Err(NlError::TooManyParameters(n_free));
    }
    // a Coulomb level or a ripple above the largest torque applied would hold the motor
    // still for good: the smooth law then mimics a stiff viscous term, a false minimum
    let u_max = data
        .iter()
        .flat_map(|d| &d.u)
        .fold(0.0f64, |m, u| m.max(u.abs()));
    let v_max = velocities
        .iter()
        .flatten()
        .fold(0.0f64, |m, x| m.max(x.abs()));
    let (lower, upper) = search_bounds(&layout, start, opts, (u_max, v_max));
    // the further records' initial velocities: the first one's start, bounds and flag
    let (mut z0, mut lower, mut upper, mut fixed_all) = (z0, lower, upper, fixed.clone());
    if let Some(i) = v0_index {
        for _ in 1..data.len() {
            z0.push(z0[i]);
            lower.push(lower[i]);
            upper.push(upper[i]);
            fixed_all.push(fixed[i]);
        }
    }
    if !problem.cost(&z0).is_finite() {
        return Err(NlError::Unstable);
    }
    let lm_opts = LmOptions {
        max_iter: opts.max_iter,
        lower: lower.clone(),
        upper: upper.clone(),
        fixed: fixed_all.clone(),
        // v0 is bounded (see above), so it is not one of the loop's unbounded nuisances
        nuisance: 0,
        // the covariance is the sandwich below
        covariance: false,
        rel_cost_tol: opts.rel_cost_tol,
        within_noise: opts.within_noise,
        active_set: opts.active_set,
        ..LmOptions::default()
    };
    let res = lm::minimize(&problem, &z0, &lm_opts)?;
    let mut z = res.theta.clone();
    let free: Vec<usize> = (0..z.len()).filter(|&i| !fixed_all[i]).collect();
    // the smoothing term of the σ and the exact-law correction (module documentation) on
    // one record; with several segments the smooth law's estimate and σ stand as they are
    let single = (problem.parts.len() == 1).then(|| (&problem.parts[0], &data[0]));
    let mut smoothing = vec![0.0; layout.len()];
    let mut exact_e = None;
    let mut table = None;
    if let Some((part, record)) = single {
        // (no iteration asked: the caller evaluates the start as it is, neither of these)
        let wants_smoothing =
            opts.smoothing_sigma && opts.max_iter > 0 && has_coulomb(model) && !free.is_empty();
        let corrects = opts.exact_correction
            && opts.max_iter > 0
            && opts.residual == Residual::Velocity
            && corrects(model);
        // three passes that need only this estimate, side by side: the smoothing term's
        // Gauss–Newton step and the exact law's residual here on one thread, the smooth
        // law's Jacobian table the correction steps take on the other
        let ((moved, exact_here), t) = join(
            machine_threads(),
            || {
                let moved = wants_smoothing
                    .then(|| smoothing_move(part, model, &z, &free))
                    .flatten();
                let here = corrects.then(|| exact_residual(part, record, &z)).flatten();
                (moved, here)
            },
            || corrects.then(|| JacobianTable::at(part, &z, &free)),
        );
        if let Some(moved) = moved {
            for &i in &free {
                smoothing[i] = SMOOTHING_BIAS_FACTOR * moved[i];
            }
        }
        if let Some(t) = t {
            if let Some((zc, e)) = exact_here.and_then(|here| {
                exact_law_steps(part, record, (&z, here), (&free, &t), (&lower, &upper))
            }) {
                z = zc;
                exact_e = Some(e);
            }
            table = Some(t);
        }
    }
    let mut values = problem.parts[0].physical(&z[..layout.len()]);
    // a ripple's phase reported within one turn, as its model takes it
    for (v, d) in values.iter_mut().zip(&layout) {
        if d.name == "phase" {
            *v = super::model::within_a_turn(*v);
        }
    }
    let cov_z = problem.sandwich(
        &z,
        &free,
        opts.cov_lags,
        (exact_e.as_deref(), table.as_ref()),
    );
    let mut params = Vec::with_capacity(layout.len());
    for (i, d) in layout.iter().enumerate() {
        let std = match free.iter().position(|&f| f == i) {
            Some(j) => {
                let sz = cov_z[(j, j)].max(0.0).sqrt();
                let noise = match d.scale {
                    Scale::Log => values[i] * sz,
                    Scale::Linear(s) => s * sz,
                };
                noise.hypot(smoothing[i])
            }
            None => 0.0,
        };
        let (at_lower, at_bound) = if fixed[i] {
            (false, false)
        } else {
            on_bounds(z[i], (lower[i], upper[i]))
        };
        params.push(NlParam {
            name: d.name,
            owner: d.owner,
            value: values[i],
            std,
            unit: d.unit,
            fixed: fixed[i],
            at_bound,
            at_lower,
        });
    }
    let mut correlated = Vec::new();
    let in_layout: Vec<(usize, usize)> = free
        .iter()
        .enumerate()
        .filter(|(_, &f)| f < layout.len() && layout[f].owner != Owner::InitialVelocity)
        .map(|(j, &f)| (j, f))
        .collect();
    for (k, &(ja, a)) in in_layout.iter().enumerate() {
        for &(jb, b) in &in_layout[k + 1..] {
            if let Some(rho) = correlation(&cov_z, ja, jb).filter(|r| r.abs() >= CORRELATED) {
                correlated.push(Correlation {
                    a: layout[a].name,
                    b: layout[b].name,
                    rho,
                });
            }
        }
    }
    let (fitted, plant) = model.with_values(&values);
    let mut pairs = Vec::with_capacity(data.len());
    for (e, (d, v)) in data.iter().zip(&velocities).enumerate() {
        let ve = problem.parts[e].physical(&problem.part_z(&z, e));
        let vh = simulate_velocity(model, &ve, &d.u, d.ts, d.y[0], Some(&d.y))
            .ok_or(NlError::Unstable)?;
        pairs.push((v[firsts[e]..].to_vec(), vh[firsts[e]..].to_vec()));
    }
    let fit_velocity_percent =
        pooled_velocity_fit(&pairs, data[0].ts, opts.highpass_hz).unwrap_or(f64::NAN);
    Ok(NlFit {
        model: fitted,
        plant,
        params,
        values,
        ssr: res.ssr,
        lowpass_hz: opts.lowpass_hz,
        n_residuals: problem.n_residuals(),
        iterations: res.iterations,
        termination: res.termination,
        fit_velocity_percent,
        correlated,
    })
}

/// `v` and `vh` through the second-order high-pass at `highpass_hz` (none at 0) that
/// [`pooled_velocity_fit`] compares them through: the signals behind its figure.
pub fn highpassed_pair(v: &[f64], vh: &[f64], ts: f64, highpass_hz: f64) -> (Vec<f64>, Vec<f64>) {
    let (mut a, mut b) = (Vec::new(), Vec::new());
    highpass_pair(v, vh, ts, highpass_hz, &mut a, &mut b);
    (a, b)
}

/// [`velocity_fit`] pooled over records: each pair `(v, v̂)` through its own prefilter
/// (started afresh), then one toolbox FIT over all of them [%].
///
/// # Errors
/// As [`fit_percent`].
pub fn pooled_velocity_fit(
    pairs: &[(Vec<f64>, Vec<f64>)],
    ts: f64,
    highpass_hz: f64,
) -> Result<f64, crate::ident::validate::ValidateError> {
    let mut sums = VelocityFitSums::new(ts, highpass_hz);
    for (v, vh) in pairs {
        sums.push(v.iter().copied().zip(vh.iter().copied()));
    }
    sums.pooled()
}

/// [`pooled_velocity_fit`] and each record's FIT from records given one at a time, sample
/// by sample: only the prefiltered measured velocity is kept (the FIT's denominator needs
/// its mean), the squared residual is summed as it comes. The sums run in the order of
/// [`fit_percent`] on the records laid end to end, so the FITs are its own to the last
/// bit, and a long record costs one vector, not the five of the pairs and their
/// prefiltered copies.
#[derive(Clone, Debug)]
pub struct VelocityFitSums {
    ts: f64,
    highpass_hz: f64,
    /// each record's measured velocity through the prefilter [rad/s]
    measured: Vec<Vec<f64>>,
    /// `Σ (v − v̂)²` through the prefilter over every record so far, in sample order
    ssr: f64,
    /// the same per record
    each_ssr: Vec<f64>,
}

impl VelocityFitSums {
    /// No record yet; sample interval `ts` [s], the prefilter's high-pass at
    /// `highpass_hz` [Hz] (0: unfiltered), started afresh on each record.
    pub fn new(ts: f64, highpass_hz: f64) -> Self {
        Self {
            ts,
            highpass_hz,
            measured: Vec::new(),
            ssr: 0.0,
            each_ssr: Vec::new(),
        }
    }

    /// Adds one record's `(v_k, v̂_k)`, measured and simulated velocity [rad/s].
    pub fn push(&mut self, pairs: impl ExactSizeIterator<Item = (f64, f64)>) {
        let mut a = Vec::with_capacity(pairs.len());
        let mut bank = (self.highpass_hz > 0.0)
            .then(|| SosBank::new(butter_highpass_sos(2, self.highpass_hz, self.ts), 2));
        let mut own = 0.0;
        for (x, y) in pairs {
            let mut s = [x, y];
            if let Some(b) = bank.as_mut() {
                b.push(&mut s);
            }
            let e2 = (s[0] - s[1]).powi(2);
            self.ssr += e2;
            own += e2;
            a.push(s[0]);
        }
        self.measured.push(a);
        self.each_ssr.push(own);
    }

    /// The FIT of every record so far laid end to end [%].
    ///
    /// # Errors
    /// [`crate::ident::validate::ValidateError::ConstantOutput`] when the measured
    /// velocity is constant.
    pub fn pooled(&self) -> Result<f64, crate::ident::validate::ValidateError> {
        let n = self.measured.iter().map(Vec::len).sum::<usize>();
        let all = || self.measured.iter().flatten();
        let mean = all().sum::<f64>() / n.max(1) as f64;
        let den: f64 = all().map(|v| (v - mean).powi(2)).sum();
        fit_of(self.ssr, den)
    }

    /// Each record's FIT [%], in the order they came.
    ///
    /// # Errors
    /// As [`Self::pooled`], for any record.
    pub fn each(&self) -> Result<Vec<f64>, crate::ident::validate::ValidateError> {
        self.measured
            .iter()
            .zip(&self.each_ssr)
            .map(|(a, &ssr)| fit_of(ssr, centred_sum_of_squares(a)))
            .collect()
    }
}

/// [`fit_from_sums`] with [`fit_percent`]'s refusal of a constant output.
fn fit_of(ssr: f64, den: f64) -> Result<f64, crate::ident::validate::ValidateError> {
    if den == 0.0 {
        return Err(crate::ident::validate::ValidateError::ConstantOutput);
    }
    Ok(fit_from_sums(ssr, den))
}

/// `∂v̂_k/∂z` of the unfiltered velocity at sample `k` by the dual numbers, every
/// parameter free (for the tests of the derivatives).
#[cfg(test)]
pub(crate) fn jacobian_probe(data: &IdData, model: &NlModel, z: &[f64], k: usize) -> Vec<f64> {
    let layout = model.layout();
    let v = interval_velocity(&data.y, data.ts);
    let problem = Problem {
        model,
        layout: &layout,
        u: &data.u,
        v: &v,
        output: Residual::Velocity,
        theta0: data.y[0],
        y: &data.y,
        gradient: Gradient::Dual,
        ts: data.ts,
        first: 1,
        highpass: Vec::new(),
    };
    let free: Vec<usize> = (0..layout.len()).collect();
    let mut out = vec![0.0; free.len()];
    problem.jacobian_rows(z, &free, |i, _, row| {
        if i == k {
            out.copy_from_slice(row);
        }
    });
    out
}

/// Whether `model` has Coulomb friction attached.
fn has_coulomb(model: &NlModel) -> bool {
    model
        .effects
        .iter()
        .any(|e| matches!(e, crate::model::effects::Effect::CoulombFriction(_)))
}

/// Whether the exact-law correction applies to `model`: Coulomb friction attached, no
/// torque ripple (module documentation).
fn corrects(model: &NlModel) -> bool {
    use crate::model::effects::Effect;
    has_coulomb(model)
        && !model
            .effects
            .iter()
            .any(|e| matches!(e, Effect::TorqueRipple(_)))
}

/// Most Gauss–Newton steps of the exact-law correction.
const EXACT_STEPS: usize = 8;

/// How far each physical value (layout order) of the fit at `z` moves with the smooth law's
/// `v_ε` doubled, by one Gauss–Newton step of that fit from `z` over `free` (one pass of
/// the dual numbers); `None` when that fit's residual is not finite.
fn smoothing_move(part: &Problem, model: &NlModel, z: &[f64], free: &[usize]) -> Option<Vec<f64>> {
    let wide = NlModel {
        v_eps: 2.0 * model.v_eps,
        ..model.clone()
    };
    let wide_problem = Problem {
        model: &wide,
        highpass: part.highpass.clone(),
        ..*part
    };
    let ne = wide_problem.normal_equations(z, free);
    if !ne.ssr.is_finite() {
        return None;
    }
    let dz = pinv_sym(&ne.jtj, 1e-14) * &ne.jte;
    let mut zw = z.to_vec();
    for (j, &i) in free.iter().enumerate() {
        zw[i] += dz[j];
    }
    let (here, there) = (part.physical(z), part.physical(&zw));
    Some(
        here.iter()
            .zip(&there)
            .map(|(a, b)| (b - a).abs())
            .collect(),
    )
}

/// The interval-mean motor velocity (sample 0 repeats sample 1) of the problem's model at
/// optimiser coordinates `z`, simulated with the simulator's exact laws
/// ([`crate::sim::simulate_driven`]) from the estimator's initial state: the motor at the
/// first measured angle, the springs unloaded, every body at the rigid velocity `v0`, the
/// current loop at the first torque, the offset added to the torque.
fn exact_velocity(problem: &Problem, data: &IdData, z: &[f64]) -> Option<Vec<f64>> {
    let values = problem.physical(z);
    let (m, plant_values) = problem.model.with_values(&values);
    let (offset, v0) = super::model::offset_and_v0(problem.layout, &values);
    let plant = super::model::sim_plant(&m, &plant_values);
    let mech = crate::model::plant::Mechanism::new(&plant, &m.effects);
    let n = mech.n_bodies();
    let u: Vec<f64> = data.u.iter().map(|u| u + offset).collect();
    let mut x = vec![0.0; 2 * n + 1];
    for i in 0..n {
        // the springs unloaded (a body at the motor's coordinate over its own); the frame
        // of the grounded mass (infinite inertia) stays at rest at 0
        let g = match i {
            0 => 1.0,
            _ if mech.bodies[i].is_frame() => 0.0,
            _ => mech.bodies[0].gain / mech.bodies[i].gain,
        };
        x[i] = g * data.y[0];
        x[n + i] = g * v0;
    }
    x[2 * n] = u[0];
    let tc = if m.tau_c > 0.0 { m.tau_c } else { 1e-9 };
    let out = crate::sim::simulate_driven(
        &plant,
        &m.effects,
        tc,
        data.ts,
        &u,
        &crate::sim::DrivenStart::State(x),
    )
    .ok()?;
    let v = interval_velocity(&out.theta_m, data.ts);
    v.iter().all(|x| x.is_finite()).then_some(v)
}

/// The exact-law residual `v − v̂_exact` at `z` through the problem's prefilter, from its
/// first sample, and its `Σ e²`.
fn exact_residual(problem: &Problem, data: &IdData, z: &[f64]) -> Option<(Vec<f64>, f64)> {
    let vh = exact_velocity(problem, data, z)?;
    let mut bank = SosBank::new(problem.highpass.clone(), 1);
    let e: Vec<f64> = (problem.first..problem.u.len())
        .map(|k| {
            let mut x = [problem.v[k] - vh[k]];
            bank.push(&mut x);
            x[0]
        })
        .collect();
    let ssr = e.iter().map(|x| x * x).sum::<f64>();
    ssr.is_finite().then_some((e, ssr))
}

/// The Jacobian rows (free parameters, optimiser coordinates) and residuals of one record
/// at a point, kept for the steps after the optimiser.
struct JacobianTable {
    /// `∂ê_t/∂z` row after row, `free.len()` values a row
    rows: Vec<f64>,
    /// the residual of each row
    e: Vec<f64>,
}

impl JacobianTable {
    /// One pass of the problem's Jacobian at `z` over `free`.
    fn at(problem: &Problem, z: &[f64], free: &[usize]) -> Self {
        let (mut rows, mut e) = (Vec::new(), Vec::new());
        problem.jacobian_rows(z, free, |_, ek, row| {
            e.push(ek);
            rows.extend_from_slice(row);
        });
        Self { rows, e }
    }
}

/// Gauss–Newton steps on the exact law's cost from the smooth fit's `z` (`here`: the exact
/// law's residual and its `Σ e²` there) with the smooth law's Jacobian there (module
/// documentation), inside the bounds `(lower, upper)`; the last accepted point and its
/// exact-law residual, `None` when no step lowered the cost. Each trial point's exact and
/// smooth simulations run side by side.
fn exact_law_steps(
    problem: &Problem,
    data: &IdData,
    (z, here): (&[f64], (Vec<f64>, f64)),
    (free, table): (&[usize], &JacobianTable),
    (lower, upper): (&[f64], &[f64]),
) -> Option<(Vec<f64>, Vec<f64>)> {
    let nf = free.len();
    let rows = &table.rows;
    let n = rows.len() / nf.max(1);
    if nf == 0 || n <= nf {
        return None;
    }
    let mut h = DMatrix::zeros(nf, nf);
    for t in 0..n {
        let r = &rows[t * nf..(t + 1) * nf];
        for a in 0..nf {
            for b in 0..nf {
                h[(a, b)] += r[a] * r[b];
            }
        }
    }
    let (mut e, mut cost) = here;
    let mut best: Option<Vec<f64>> = None;
    let mut zc = z.to_vec();
    for _ in 0..EXACT_STEPS {
        if e.len() != n {
            break;
        }
        let mut g = DVector::zeros(nf);
        for (t, et) in e.iter().enumerate() {
            for a in 0..nf {
                g[a] += rows[t * nf + a] * et;
            }
        }
        // Marquardt's damping: the directions the data hardly determine (a viscous
        // friction below the prefilter's cut-off) must not take the whole step
        let mut accepted = None;
        for lambda in [1e-4, 1e-2, 1.0] {
            let mut hd = h.clone();
            for a in 0..nf {
                hd[(a, a)] += lambda * h[(a, a)];
            }
            let dz = pinv_sym(&hd, 1e-14) * &g;
            let mut zn = zc.clone();
            for (j, &i) in free.iter().enumerate() {
                let lo = lower.get(i).copied().unwrap_or(f64::NEG_INFINITY);
                let hi = upper.get(i).copied().unwrap_or(f64::INFINITY);
                zn[i] = (zc[i] + dz[j]).clamp(lo, hi);
            }
            // the smooth law must still simulate there: the fit's figures and covariance
            // are the smooth law's (bench case 60 of `benches/diagnose.rs`, a stick-slip
            // joint: a step that lowered the exact cost left the smooth simulation unstable)
            let (exact, smooth) = join(
                machine_threads(),
                || exact_residual(problem, data, &zn),
                || problem.cost(&zn),
            );
            if let Some((en, cn)) = exact.filter(|(_, c)| *c < cost && smooth.is_finite()) {
                accepted = Some((zn, en, cn));
                break;
            }
        }
        let Some((zn, en, cn)) = accepted else {
            break;
        };
        let small = 1.0 - cn / cost < 1e-6;
        (zc, e, cost) = (zn, en, cn);
        best = Some(zc.clone());
        if small {
            break;
        }
    }
    best.map(|b| (b, e))
}

/// `H = JᵀJ` and the sandwich's middle `S` of one record over the free parameters in
/// optimiser coordinates (module documentation); `H⁻¹ S H⁻¹` is the covariance.
/// `residual`: the residual to use instead of the smooth law's (the exact law's after the
/// correction), one per row.
/// `table`: the Jacobian already evaluated over these `free` parameters (by the exact-law
/// correction, a step away from `z`: the covariance does not tell the two apart), else one
/// pass of the dual numbers here.
/// The correlation of entries `a` and `b` of the covariance `cov`; `None` when a variance
/// is nought or the ratio lies beyond ±1: a covariance is positive semi-definite, so that
/// is round-off on a variance at nought (a degenerate direction, which the fit's checks
/// report), not a trade between two parameters (a nominal with `tau_c` on its bound
/// reported correlations of −12.1 and +1.11).
fn correlation(cov: &DMatrix<f64>, a: usize, b: usize) -> Option<f64> {
    let den = (cov[(a, a)] * cov[(b, b)]).sqrt();
    let rho = cov[(a, b)] / den;
    (den > 0.0 && rho.abs() <= 1.0 + 1e-9).then(|| rho.clamp(-1.0, 1.0))
}

fn sandwich_parts(
    problem: &Problem,
    z: &[f64],
    free: &[usize],
    lags: usize,
    (residual, table): (Option<&[f64]>, Option<&JacobianTable>),
) -> (DMatrix<f64>, DMatrix<f64>) {
    let nf = free.len();
    let own;
    let JacobianTable { rows, e } = match table {
        Some(t) => t,
        None => {
            own = JacobianTable::at(problem, z, free);
            &own
        }
    };
    let mut e = e.clone();
    if let Some(r) = residual.filter(|r| r.len() == e.len()) {
        e.copy_from_slice(r);
    }
    let n = e.len();
    if n <= nf || nf == 0 {
        return (DMatrix::zeros(nf, nf), DMatrix::zeros(nf, nf));
    }
    let row = |t: usize| &rows[t * nf..(t + 1) * nf];
    let mut h = DMatrix::zeros(nf, nf);
    for t in 0..n {
        let r = row(t);
        for a in 0..nf {
            for b in 0..nf {
                h[(a, b)] += r[a] * r[b];
            }
        }
    }
    let lags = lags.min(n / 10);
    // weighted residual autocovariance w_τ r_e(τ), then S = Jᵀ R J with R the banded
    // Toeplitz matrix of it: Y = R J row by row, S = Jᵀ Y
    let wr: Vec<f64> = (0..=lags)
        .map(|tau| {
            let re: f64 = (0..n - tau).map(|t| e[t] * e[t + tau]).sum::<f64>() / n as f64;
            re * (1.0 - tau as f64 / (lags + 1) as f64)
        })
        .collect();
    // the rows' share of S, two halves side by side, added in a fixed order (the same bits
    // on any number of threads)
    let share = |rows_t: std::ops::Range<usize>| {
        let mut s = DMatrix::zeros(nf, nf);
        let mut y = vec![0.0; nf];
        for t in rows_t {
            y.iter_mut().for_each(|v| *v = 0.0);
            let lo = t.saturating_sub(lags);
            let hi = (t + lags).min(n - 1);
            for (tt, w) in (lo..=hi).map(|tt| (tt, wr[tt.abs_diff(t)])) {
                for (yv, r) in y.iter_mut().zip(row(tt)) {
                    *yv += w * r;
                }
            }
            let r = row(t);
            for a in 0..nf {
                for b in 0..nf {
                    s[(a, b)] += r[a] * y[b];
                }
            }
        }
        s
    };
    let (first, second) = join(machine_threads(), || share(0..n / 2), || share(n / 2..n));
    (h, first + second)
}

/// The search's bounds in optimiser coordinates (layout order) for a fit from `start`:
/// each parameter's physical bounds, a structure parameter or a log-scaled effect size
/// narrowed to [`NlOptions::plant_range`] either way of its centre
/// ([`NlOptions::range_from`], else the start) and never shutting the start out, the
/// initial velocity to ten times the largest measured `v_max` [rad/s], and a Coulomb level
/// or ripple amplitude to the largest torque `u_max` [N·m] applied.
fn search_bounds(
    layout: &[ParamDef],
    start: &[f64],
    opts: &NlOptions,
    (u_max, v_max): (f64, f64),
) -> (Vec<f64>, Vec<f64>) {
    let centre = opts
        .range_from
        .as_deref()
        .filter(|c| c.len() == start.len())
        .unwrap_or(start);
    layout
        .iter()
        .zip(centre.iter().zip(start))
        .map(|(d, (&p, &at))| {
            let (mut lo, mut hi) = (d.lower, d.upper);
            let log_effect = matches!(d.owner, Owner::Effect(_)) && d.scale == Scale::Log;
            if d.owner == Owner::Plant || log_effect {
                lo = lo.max((p / opts.plant_range).min(at));
                hi = hi.min((p * opts.plant_range).max(at));
            }
            if d.owner == Owner::InitialVelocity {
                // the motion never exceeds its measured range by much
                hi = 10.0 * v_max.max(1e-6);
                lo = -hi;
            }
            if matches!(d.owner, Owner::Effect(_))
                && matches!(d.name, "fc" | "fc_neg" | "amplitude")
            {
                hi = hi.min(u_max.max(p.abs()).max(at.abs()));
                lo = lo.max(-hi);
            }
            match d.scale {
                Scale::Log => (if lo > 0.0 { lo.ln() } else { f64::NEG_INFINITY }, hi.ln()),
                Scale::Linear(s) => (lo / s, hi / s),
            }
        })
        .unzip()
}

/// Whether an estimated value at optimiser coordinate `z` sits on its lower bound, and
/// on either bound, of the search `(lower, upper)` (within a millionth of the bound's
/// scale): what [`NlParam::at_lower`] and [`NlParam::at_bound`] say, for every fit that
/// reports them (the output-error fit, and the diagnosis's refinement in the loop).
pub fn on_bounds(z: f64, (lower, upper): (f64, f64)) -> (bool, bool) {
    let at_lower = lower.is_finite() && z - lower < 1e-6 * (1.0 + lower.abs());
    let at_upper = upper.is_finite() && upper - z < 1e-6 * (1.0 + upper.abs());
    (at_lower, at_lower || at_upper)
}

#[cfg(test)]
mod error_tests {
    use super::*;
    use crate::model::effects::{CoulombFriction, Effect};
    use crate::model::spec::Structure;

    /// A size fitted on a log scale (a backlash's width, bounded below at 1e-9 rad) that
    /// ends on its bound is flagged there, so that the diagnosis counts the effect of no
    /// size; a ten-thousandth above it, or inside the range, it is not; an infinite bound
    /// is never reached.
    #[test]
    fn a_value_on_its_bound_is_flagged_and_one_inside_is_not() {
        let (lo, hi) = (1e-9_f64.ln(), 1e-1_f64.ln());
        assert_eq!(on_bounds(lo, (lo, hi)), (true, true));
        assert_eq!(on_bounds(1.0001e-9_f64.ln(), (lo, hi)), (false, false));
        assert_eq!(on_bounds(1e-5_f64.ln(), (lo, hi)), (false, false));
        assert_eq!(on_bounds(hi, (lo, hi)), (false, true));
        assert_eq!(
            on_bounds(-1e300, (f64::NEG_INFINITY, f64::INFINITY)),
            (false, false)
        );
    }

    /// A nested refit starts its effect at a small share of the single's own fit, its
    /// bounds measured about that fit (`range_from`): the Coulomb level can grow back to
    /// the own fit's size and a hundredfold beyond (up to the largest torque applied),
    /// and the bounds still hold the start below. Measured about the start, the level
    /// could not pass a hundred times the start, a tenth of the own fit's.
    #[test]
    fn a_size_started_shrunk_may_grow_back_past_its_own_fit() {
        let at = |fc: f64| {
            two_mass(vec![Effect::CoulombFriction(CoulombFriction {
                fc,
                fs: fc,
                ..CoulombFriction::default()
            })])
        };
        let plant = [1e-3, 0.1, 1e4, 5.0, 1e-3];
        let (own, start) = (at(2.7e-3), at(2.7e-6));
        let layout = start.layout();
        let fc = layout.iter().position(|d| d.name == "fc").unwrap();
        let u_max = 0.5;
        let centred = NlOptions {
            range_from: Some(own.values(&plant, 0.0, 0.0)),
            ..NlOptions::default()
        };
        let z_start = start.values(&plant, 0.0, 0.0);
        let (lo, hi) = search_bounds(&layout, &z_start, &centred, (u_max, 1.0));
        assert!(lo[fc] <= 2.7e-6_f64.ln() && hi[fc] > 2.7e-3_f64.ln());
        assert!((hi[fc] - 0.27_f64.ln()).abs() < 1e-12, "{}", hi[fc].exp());
        // the structure's bounds are those about the nominal's values either way
        let (lo_s, hi_s) = search_bounds(&layout, &z_start, &NlOptions::default(), (u_max, 1.0));
        assert_eq!((lo[0], hi[0]), (lo_s[0], hi_s[0]));
        assert!(
            (hi_s[fc] - 2.7e-4_f64.ln()).abs() < 1e-12,
            "{}",
            hi_s[fc].exp()
        );
    }

    #[test]
    fn a_correlation_is_within_one_or_not_reported() {
        // a covariance of two parameters correlated at −0.99, and a third whose variance
        // is round-off beside its covariances
        let cov = DMatrix::from_row_slice(
            3,
            3,
            &[4.0, -1.98, 1e-9, -1.98, 1.0, -1e-9, 1e-9, -1e-9, 1e-20],
        );
        let rho = correlation(&cov, 0, 1).unwrap();
        assert!((rho + 0.99).abs() < 1e-12, "{rho}");
        assert_eq!(correlation(&cov, 0, 2), None);
        assert_eq!(correlation(&cov, 1, 2), None);
        let flat = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, 0.0]);
        assert_eq!(correlation(&flat, 0, 1), None);
    }

    /// A two-mass joint's model with `effects`, no current loop.
    fn two_mass(effects: Vec<Effect>) -> NlModel {
        NlModel {
            structure: Structure::TwoMass,
            r: 1.0 / 118.0,
            effects,
            tau_c: 0.0,
            v_eps: 0.05,
            dz_eps: 1e-7,
            substeps: 1,
        }
    }

    #[test]
    fn a_fit_that_cannot_start_says_why() {
        let model = two_mass(Vec::new());
        let opts = NlOptions::default();
        let e = fit_output_error_segments(&[], &model, &[], &opts).unwrap_err();
        assert!(matches!(e, NlError::NoRecord), "{e:?}");
        let short = IdData {
            ts: 1e-3,
            u: vec![0.0; 5],
            y: vec![0.0; 5],
            r: None,
        };
        let e = fit_output_error_segments(&[short], &model, &[], &opts).unwrap_err();
        assert!(matches!(e, NlError::Record(_)), "{e:?}");
        let data = IdData {
            ts: 1e-3,
            u: (0..400).map(|k| (k as f64 * 0.05).sin()).collect(),
            y: (0..400).map(|k| 1e-3 * (k as f64 * 0.05).cos()).collect(),
            r: None,
        };
        let e = fit_output_error_segments(&[data], &model, &[1.0], &opts).unwrap_err();
        assert_eq!(
            e.to_string(),
            format!("1 start values for {} parameters", model.layout().len())
        );
    }
}
