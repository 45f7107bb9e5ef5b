//! Closed-loop simulator of one flexible robot joint with switchable unmodelled effects.
//!
//! What: the joint of seed 000 (Norrlöf et al., "Modeling and identification of a
//! mechanical industrial manipulator", Fig. 2): a reference `θ_ref` goes into the robot's
//! own controller, whose torque reference `u` drives the motor through a fast current loop;
//! `u` and the motor angle `θ_m` are measured. The mechanics is one of the structures of
//! [`crate::model::spec::Structure`] (rigid, two-mass, three-mass eq. (5)–(6), four-mass
//! eq. (7)–(8); seed 001's nonlinear two-mass eq. (4)–(9) is the two-mass with two of the
//! effects, [`crate::model::params::sim_spec`]), optionally with the effects of
//! [`crate::model::effects::Effect`] (Coulomb/Stribeck friction, backlash, cubic spring, extra mode,
//! transport delay, torque ripple).
//!
//! Why: identification and gap diagnosis need data with a known truth. The simulator gives
//! the same three signals the robot gives (`θ_ref`, `u`, `θ_m`, sampled at 2 kHz, with
//! encoder quantisation, noise and a torque disturbance), plus the true states.
//!
//! How: per sample `k` the sensors read the true state, the discrete controller computes
//! `u[k]` ([`controller`]), and the plant is propagated over the sample with the inputs held
//! ([`integrate`]): exactly (zero-order hold, seed 000 eq. (12)–(13)) when the plant is
//! linear; when an effect makes it nonlinear, by one exponential (Lawson) RK4 step per sample
//! with the linear part of the current mode exact, cut into two substeps (and event-aware
//! RK4 where backlash contact edges or stick–slip of Coulomb friction fall) in the samples
//! with events or a fast sweep of the Stribeck bump. Everything random is drawn from
//! generators seeded by [`SimConfig::seed`], so a run is reproducible bit for bit.
//!
//! Open loop: [`simulate_driven`] propagates the same plant with the same stepper, driven by
//! a given torque reference (e.g. the measured one) with no controller and no sensors; the
//! estimators compute a fitted model's validation FIT with the exact laws by it.
//!
//! See also: [`crate::model::params`] for the default joint and its modal frequencies,
//! [`crate::model::effects`] for the physics and defaults of each effect.
//!
//! ```
//! use jointid::sim::{parse_effects, simulate, SimConfig};
//!
//! let cfg = SimConfig {
//!     effects: parse_effects(&["backlash:width=2e-5", "time_delay"]).unwrap(),
//!     ..SimConfig::default()
//! };
//! // 0.5 s of a 2 Hz reference [rad]
//! let r: Vec<f64> = (0..1000).map(|k| 0.01 * (2.0 * 3.14159 * 2.0 * k as f64 / 2000.0).sin()).collect();
//! let out = simulate(&cfg, &r).unwrap();
//! assert_eq!(out.u.len(), 1000);
//! println!("{}", cfg.params_json().unwrap());
//! ```
#![deny(missing_docs)]

pub mod board;
pub mod controller;
mod driven;
pub mod integrate;
pub mod sensors;

use jointid_core::excitation::{ExcitationConfig, ExcitationError};
use jointid_core::wire::{RawSample, Scale};
use serde::{Deserialize, Serialize};

pub use crate::model::effects::{parse_effects, Effect, EffectParseError};
pub use crate::model::params::{JointParams, Plant};
pub use crate::model::plant::{Mechanism, ModalFrequencies};
pub use crate::model::spec::Structure;
pub use controller::{Controller, ControllerConfig};
pub use driven::{
    simulate_driven, simulate_driven_loaded, simulate_driven_with, DrivenOutput, DrivenStart,
};
pub use sensors::{Disturbance, SensorConfig};

use crate::model::plant::{MAX_BODIES, MAX_STATE};
use integrate::{Contact, NonlinearPlant, SampleStepper, State, ZohStep};
use sensors::Sensors;

/// How the plant is integrated between samples.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct IntegrationConfig {
    /// RK4 substeps `M` per sample of the event-aware RK4 [-]; default 5 (10 kHz). Used for
    /// every sample when `exponential` is off or `force_rk4` on; with the exponential
    /// stepper `⌊M/2⌋` (at least 1) in a half sample that contains an event (contact edge,
    /// stick–slip transition); at most [`MAX_SUBSTEPS`]
    pub substeps: u32,
    /// use RK4 even when the plant is linear, and for nonlinear plants instead of the
    /// exponential stepper (for checks); default false
    pub force_rk4: bool,
    /// nonlinear plants: exponential (Lawson) RK4, one step per sample with the linear part
    /// of the current mode exact, two substeps and event-aware RK4 only in samples with
    /// events; default true
    #[serde(default = "default_true")]
    pub exponential: bool,
}

/// Largest `IntegrationConfig::substeps`: 1000 RK4 substeps per sample (2 MHz at 2 kHz)
/// is 200 times the default and far below any step the joint's fastest mode needs; more
/// only costs time.
pub const MAX_SUBSTEPS: u32 = 1000;

fn default_true() -> bool {
    true
}

impl Default for IntegrationConfig {
    fn default() -> Self {
        IntegrationConfig {
            substeps: 5,
            force_rk4: false,
            exponential: true,
        }
    }
}

/// Everything that defines a simulation run (serialised whole by [`Self::params_json`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SimConfig {
    /// mechanical structure and physical parameters
    pub plant: Plant,
    /// unmodelled effects switched on (any combination; empty for none)
    pub effects: Vec<Effect>,
    /// the robot's controller and current loop
    pub controller: ControllerConfig,
    /// sensors and torque disturbance
    pub sensors: SensorConfig,
    /// seed of every random stream of the run
    pub seed: u64,
    /// sample rate of controller and measurements [Hz]; default 2000
    pub sample_rate_hz: f64,
    /// integration of the plant between samples
    pub integration: IntegrationConfig,
}

impl Default for SimConfig {
    /// Default three-mass joint, no effects, default controller and sensors, seed 1.
    fn default() -> Self {
        SimConfig {
            plant: Plant::default(),
            effects: Vec::new(),
            controller: ControllerConfig::default(),
            sensors: SensorConfig::default(),
            seed: 1,
            sample_rate_hz: 2000.0,
            integration: IntegrationConfig::default(),
        }
    }
}

/// Which integrator a run used.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Integrator {
    /// exact zero-order-hold propagation of the linear plant
    ExactZoh,
    /// RK4 with this many substeps per sample
    Rk4 {
        /// substeps per sample
        substeps: u32,
    },
    /// exponential (Lawson) RK4, one step per sample (two in samples with events or a fast
    /// Stribeck sweep); event-aware RK4 with this many substeps per sample (pro rata) where
    /// an event falls
    ExponentialRk4 {
        /// RK4 substeps per sample in samples with events
        substeps: u32,
    },
}

impl std::fmt::Display for Integrator {
    /// In words, for the user: `exact ZOH`, `RK4 (5 substeps per sample)`,
    /// `exponential RK4 (5 RK4 substeps per sample at events)`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::ExactZoh => write!(f, "exact ZOH"),
            Self::Rk4 { substeps } => write!(f, "RK4 ({substeps} substeps per sample)"),
            Self::ExponentialRk4 { substeps } => write!(
                f,
                "exponential RK4 ({substeps} RK4 substeps per sample at events)"
            ),
        }
    }
}

/// Result of [`simulate`]: measured signals as the robot would give them, and the truth.
#[derive(Clone, Debug, PartialEq)]
pub struct SimOutput {
    /// sample interval `T` [s]
    pub sample_interval_s: f64,
    /// time of each sample, `k T` [s]
    pub t: Vec<f64>,
    /// motor-angle reference `θ_ref` [rad]
    pub theta_ref: Vec<f64>,
    /// recorded torque reference `u` (with measurement noise) [N·m]
    pub u: Vec<f64>,
    /// measured motor angle `θ_m` (quantised, with noise) [rad]
    pub theta_m: Vec<f64>,
    /// torque reference as the controller computed it (no noise) [N·m]
    pub u_true: Vec<f64>,
    /// true motor angle [rad]
    pub theta_m_true: Vec<f64>,
    /// torque out of the current loop, `τ_a` [N·m]
    pub tau_motor: Vec<f64>,
    /// disturbance torque held over each sample [N·m]
    pub disturbance: Vec<f64>,
    /// names of the true state components (see [`crate::model::plant`] for the layout)
    pub state_names: Vec<String>,
    /// true state at each sample, row-major, `state_names.len()` values per sample
    pub states: Vec<f64>,
    /// samples where the controller output was limited
    pub saturated_samples: u64,
    /// integrator used
    pub integrator: Integrator,
}

impl SimOutput {
    /// No samples yet, room for `n` of `nx` states each (interval 0, no state names,
    /// [`Integrator::ExactZoh`] until set).
    pub fn with_capacity(n: usize, nx: usize) -> SimOutput {
        SimOutput {
            sample_interval_s: 0.0,
            t: Vec::with_capacity(n),
            theta_ref: Vec::with_capacity(n),
            u: Vec::with_capacity(n),
            theta_m: Vec::with_capacity(n),
            u_true: Vec::with_capacity(n),
            theta_m_true: Vec::with_capacity(n),
            tau_motor: Vec::with_capacity(n),
            disturbance: Vec::with_capacity(n),
            state_names: Vec::new(),
            states: Vec::with_capacity(n * nx),
            saturated_samples: 0,
            integrator: Integrator::ExactZoh,
        }
    }

    /// Appends one sample of a [`Simulation`].
    pub fn push(&mut self, s: &Sample<'_>) {
        self.t.push(s.t_s);
        self.theta_ref.push(s.theta_ref);
        self.u.push(s.u);
        self.theta_m.push(s.theta_m);
        self.u_true.push(s.u_true);
        self.theta_m_true.push(s.states[0]);
        self.tau_motor.push(s.tau_motor);
        self.disturbance.push(s.disturbance);
        self.states.extend_from_slice(s.states);
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// True state at sample `k`.
    pub fn state(&self, k: usize) -> &[f64] {
        let n = self.state_names.len();
        &self.states[k * n..(k + 1) * n]
    }

    /// One true state component over time, by name (`theta_a1`, `omega_m`, ...).
    pub fn state_series(&self, name: &str) -> Option<Vec<f64>> {
        let i = self.state_names.iter().position(|s| s == name)?;
        let n = self.state_names.len();
        Some(self.states.iter().skip(i).step_by(n).copied().collect())
    }

    /// The measured signals as the board would stream them: `seq = k`, `tick = k ·
    /// timer_hz / fs` (wrapping), `torque = round(u / torque_nm_per_count)`,
    /// `angle = round(θ_m / angle_rad_per_count)`.
    /// `timer_hz` is the tick rate of [`jointid_core::wire::SessionHeader::timer_hz`].
    ///
    /// # Errors
    /// [`WireRangeError`] for the first value that is not finite or whose count does not
    /// fit an `i32`: nothing is clamped.
    pub fn to_raw_samples(
        &self,
        scale: &Scale,
        timer_hz: u32,
    ) -> Result<Vec<RawSample>, WireRangeError> {
        let step = tick_step(timer_hz, self.sample_interval_s);
        (0..self.len())
            .map(|k| raw_sample(k, self.u[k], self.theta_m[k], scale, step))
            .collect()
    }

    /// Identification data `u → θ_m` with the reference (measured signals).
    pub fn to_id_data(&self) -> crate::data::IdData {
        crate::data::IdData {
            ts: self.sample_interval_s,
            u: self.u.clone(),
            y: self.theta_m.clone(),
            r: Some(self.theta_ref.clone()),
        }
    }
}

/// Timer ticks per sample: `timer_hz · T`, rounded.
pub fn tick_step(timer_hz: u32, sample_interval_s: f64) -> u64 {
    (f64::from(timer_hz) * sample_interval_s).round() as u64
}

/// Sample `k` as the board streams it ([`SimOutput::to_raw_samples`]): `seq = k`,
/// `tick = k · step` (wrapping), `torque = round(u / torque_nm_per_count)` of `u` [N·m],
/// `angle = round(θ_m / angle_rad_per_count)` of `theta_m` [rad].
///
/// # Errors
/// [`WireRangeError`] for a value that is not finite or whose count does not fit an
/// `i32`: nothing is clamped.
pub fn raw_sample(
    k: usize,
    u: f64,
    theta_m: f64,
    scale: &Scale,
    step: u64,
) -> Result<RawSample, WireRangeError> {
    let counts = |signal: &'static str, unit: &'static str, v: f64, per: f32| {
        let per = f64::from(per);
        let c = (v / per).round();
        if c.is_finite() && c >= f64::from(i32::MIN) && c <= f64::from(i32::MAX) {
            Ok(c as i32)
        } else {
            Err(WireRangeError {
                index: k,
                signal,
                value: v,
                unit,
                per_count: per,
            })
        }
    };
    Ok(RawSample {
        seq: k as u32,
        tick: (k as u64).wrapping_mul(step) as u32,
        torque: counts("u", "N·m", u, scale.torque_nm_per_count)?,
        angle: counts("theta_m", "rad", theta_m, scale.angle_rad_per_count)?,
    })
}

/// A measured value the wire cannot carry: not finite, or beyond the `i32` counts of its
/// scale.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error(
    "sample {index}: {signal} = {value:e} {unit} is outside the wire's range \
     (|{signal}| ≤ {max:.4e} {unit}: i32 counts of {per_count:e} {unit}/count)",
    max = f64::from(i32::MAX) * per_count.abs()
)]
pub struct WireRangeError {
    /// sample index
    pub index: usize,
    /// `u` or `theta_m`
    pub signal: &'static str,
    /// the value in SI units
    pub value: f64,
    /// its unit
    pub unit: &'static str,
    /// the scale of one count [unit/count]
    pub per_count: f64,
}

/// Why a configuration cannot be simulated.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// a parameter is out of its range
    #[error("parameter `{name}` = {value}: {reason}")]
    InvalidParameter {
        /// parameter name (as in the JSON of the config)
        name: String,
        /// its value
        value: f64,
        /// the accepted range
        reason: &'static str,
    },
    /// an effect that must be unique is given twice
    #[error("effect `{0}` given more than once")]
    DuplicateEffect(&'static str),
    /// an effect acts on the gearbox spring, which a rigid plant does not have
    #[error("effect `{effect}` needs a gearbox spring; plant `{plant}` has none")]
    NeedsGearbox {
        /// effect name
        effect: &'static str,
        /// plant name
        plant: &'static str,
    },
    /// more bodies than the simulator supports
    #[error("{bodies} bodies (plant plus extra modes), at most {max} supported")]
    TooManyBodies {
        /// bodies requested
        bodies: usize,
        /// limit
        max: usize,
    },
    /// the reference contains a value that is not finite
    #[error("reference sample {index} is not finite ({value})")]
    BadReference {
        /// sample index
        index: usize,
        /// its value
        value: f64,
    },
    /// a torque reference (or load) given to [`simulate_driven`] is not finite
    #[error("torque sample {index} is not finite ({value})")]
    BadTorque {
        /// sample index
        index: usize,
        /// its value
        value: f64,
    },
    /// the start state given to [`simulate_driven`] does not fit the plant
    #[error("start state: {0}")]
    BadStart(String),
    /// the run diverged: a state or a measured signal is NaN or infinite
    #[error(
        "simulation not finite at sample {index} (t = {t_s} s): {signal} = {value} \
         (plant {plant}, effects: {effects})"
    )]
    NonFinite {
        /// index of the first sample with a non-finite value
        index: usize,
        /// its time [s]
        t_s: f64,
        /// the state component or signal (`theta_m`, `u`, a state name)
        signal: String,
        /// its value
        value: f64,
        /// the plant's name
        plant: &'static str,
        /// the effects of the run with their parameters (`none` without effects)
        effects: String,
    },
    /// invalid effect parameters (see [`Effect::check`])
    #[error("effect `{effect}`: {reason}")]
    BadEffect {
        /// effect name
        effect: &'static str,
        /// what is wrong
        reason: String,
    },
    /// the excitation could not be generated
    #[error("excitation: {0}")]
    Excitation(#[from] ExcitationError),
    /// the excitation's sample rate differs from the simulator's
    #[error("excitation sample rate {excitation_hz} Hz differs from the simulator's {sim_hz} Hz")]
    RateMismatch {
        /// `ExcitationConfig::fs_hz`
        excitation_hz: u32,
        /// `SimConfig::sample_rate_hz`
        sim_hz: f64,
    },
    /// serialisation of the configuration failed
    #[error("cannot serialise the configuration: {0}")]
    Json(#[from] serde_json::Error),
}

impl SimConfig {
    /// The whole configuration (plant parameters, effects with every parameter, controller,
    /// sensors, seed, rates) as pretty JSON, names as in seed 000 Table 1.
    ///
    /// # Errors
    /// [`SimError::Json`] if serialisation fails.
    pub fn params_json(&self) -> Result<String, SimError> {
        Ok(serde_json::to_string_pretty(self)?)
    }

    /// Checks ranges and combinations.
    ///
    /// # Errors
    /// The first problem found.
    pub fn validate(&self) -> Result<(), SimError> {
        let (mut positive, mut nonneg) = plant_ranges(&self.plant);
        let c = &self.controller;
        positive.extend([
            ("sample_rate_hz", self.sample_rate_hz),
            ("controller.ti", c.ti),
            ("controller.u_max", c.u_max),
            ("controller.current_loop_tau", c.current_loop_tau),
        ]);
        nonneg.extend([
            ("controller.kp", c.kp),
            ("controller.kv", c.kv),
            ("controller.ff_inertia", c.ff_inertia),
            ("sensors.theta_noise_std", self.sensors.theta_noise_std),
            ("sensors.u_noise_std", self.sensors.u_noise_std),
            (
                "sensors.disturbance.noise_std",
                self.sensors.disturbance.noise_std,
            ),
            (
                "sensors.disturbance.noise_cutoff_hz",
                self.sensors.disturbance.noise_cutoff_hz,
            ),
        ]);
        check_ranges(&positive, &nonneg)?;
        if self.sensors.counts_per_rev == Some(0) {
            return Err(bad("sensors.counts_per_rev", 0.0, "must be > 0"));
        }
        check_integration(&self.integration)?;
        check_effects(&self.plant, &self.effects)
    }
}

/// `SimError::InvalidParameter`.
fn bad(name: &str, value: f64, reason: &'static str) -> SimError {
    SimError::InvalidParameter {
        name: name.to_string(),
        value,
        reason,
    }
}

/// A parameter's name and value.
type Named = (&'static str, f64);

/// The plant's parameters that must be positive and those that must be non-negative, in the
/// order they are checked.
fn plant_ranges(plant: &Plant) -> (Vec<Named>, Vec<Named>) {
    let p = &plant.params;
    let kind = plant.kind;
    let mut positive = vec![("J_m", p.j_m), ("r", p.r)];
    let mut nonneg = vec![("f_m", p.f_m)];
    match kind {
        Structure::Rigid => nonneg.push(("J_a1 + J_a2", p.j_a1 + p.j_a2)),
        Structure::Grounded => {
            nonneg.push(("J_a1 + J_a2", p.j_a1 + p.j_a2));
            positive.push(("k_0", p.k_0));
        }
        Structure::TwoMass => {
            positive.extend([("J_a1 + J_a2", p.j_a1 + p.j_a2), ("k_g", p.k_g)]);
            nonneg.push(("d_g", p.d_g));
        }
        Structure::ThreeMass | Structure::FourMass => {
            positive.extend([
                ("J_a1", p.j_a1),
                ("J_a2", p.j_a2),
                ("k_g", p.k_g),
                ("k_a", p.k_a),
            ]);
            nonneg.extend([("d_g", p.d_g), ("d_a", p.d_a)]);
        }
    }
    if kind == Structure::FourMass {
        positive.extend([("J_p", p.j_p), ("k_p", p.k_p)]);
        nonneg.push(("d_p", p.d_p));
    }
    (positive, nonneg)
}

/// Checks that the `positive` values are finite and > 0 (`controller.ti` may be +inf: P
/// only) and the `nonneg` ones finite and ≥ 0.
fn check_ranges(positive: &[Named], nonneg: &[Named]) -> Result<(), SimError> {
    for &(name, v) in positive {
        let ok = v > 0.0 && (v.is_finite() || name == "controller.ti");
        if !ok {
            return Err(bad(name, v, "must be finite and > 0"));
        }
    }
    for &(name, v) in nonneg {
        let ok = v.is_finite() && v >= 0.0;
        if !ok {
            return Err(bad(name, v, "must be finite and >= 0"));
        }
    }
    Ok(())
}

fn check_integration(integration: &IntegrationConfig) -> Result<(), SimError> {
    if !(1..=MAX_SUBSTEPS).contains(&integration.substeps) {
        return Err(bad(
            "integration.substeps",
            f64::from(integration.substeps),
            "must be within [1, 1000]",
        ));
    }
    Ok(())
}

/// Checks the effects on `plant`: each one's parameters, uniqueness, a gearbox for those
/// that act on it, and the number of bodies.
fn check_effects(plant: &Plant, effects: &[Effect]) -> Result<(), SimError> {
    let kind = plant.kind;
    let mut seen = Vec::new();
    for e in effects {
        e.check().map_err(|reason| SimError::BadEffect {
            effect: e.name(),
            reason: reason.to_string(),
        })?;
        let unique = matches!(
            e,
            Effect::Backlash(_) | Effect::TimeDelay(_) | Effect::CoulombFriction(_)
        );
        if unique && seen.contains(&e.name()) {
            return Err(SimError::DuplicateEffect(e.name()));
        }
        seen.push(e.name());
        if e.acts_on_gearbox() && kind == Structure::Rigid {
            return Err(SimError::NeedsGearbox {
                effect: e.name(),
                plant: kind.name(),
            });
        }
    }
    let bodies = Mechanism::new(plant, effects).n_bodies();
    if bodies > MAX_BODIES {
        return Err(SimError::TooManyBodies {
            bodies,
            max: MAX_BODIES,
        });
    }
    Ok(())
}

/// The plant as the integrator needs it, assembled from plant kind and effects.
struct Assembled {
    mech: Mechanism,
    nonlinear: NonlinearPlant,
    is_nonlinear: bool,
    delay_whole: usize,
    delay_frac: f64,
}

fn assemble(cfg: &SimConfig) -> Assembled {
    assemble_parts(&cfg.plant, &cfg.effects, cfg.controller.current_loop_tau)
}

/// [`Assembled`] from the plant, its effects and the current-loop time constant `tc` [s].
fn assemble_parts(plant: &Plant, effects: &[Effect], tc: f64) -> Assembled {
    let mech = Mechanism::new(plant, effects);
    let mut k3 = 0.0;
    let mut backlash = None;
    let mut coulomb = Vec::new();
    let mut ripple = Vec::new();
    let mut delay = 0.0;
    for e in effects {
        match *e {
            Effect::CoulombFriction(c) if c.fs > 0.0 || c.fc_backward() > 0.0 => coulomb.push(c),
            Effect::Backlash(b) if b.width > 0.0 => backlash = Some(b.width),
            Effect::NonlinearStiffness(s) => k3 += s.k3,
            Effect::TimeDelay(d) => delay += d.samples,
            Effect::TorqueRipple(r) if r.amplitude != 0.0 => ripple.push(r),
            _ => {}
        }
    }
    let is_nonlinear = k3 != 0.0 || backlash.is_some() || !coulomb.is_empty() || !ripple.is_empty();
    let mut delay_whole = delay.floor() as usize;
    let mut delay_frac = delay - delay.floor();
    if delay_frac < 1e-12 {
        delay_frac = 0.0;
    } else if delay_frac > 1.0 - 1e-12 {
        delay_frac = 0.0;
        delay_whole += 1;
    }
    let nonlinear = NonlinearPlant::new(&mech, tc, k3, backlash, coulomb, ripple);
    Assembled {
        mech,
        nonlinear,
        is_nonlinear,
        delay_whole,
        delay_frac,
    }
}

/// Simulates the closed loop over `reference.len()` samples of `θ_ref` [rad].
///
/// The joint starts at rest with zero spring deflections and the motor at `reference[0]`.
/// Sample `k` is taken at `t = k T`: the measured angle is read, `u[k]` computed and held
/// (after the optional delay and through the current loop) until `t = (k + 1) T`. A
/// collector over [`Simulation`], the one simulator loop.
///
/// # Errors
/// [`SimError`] when the configuration is invalid ([`SimConfig::validate`]) or the
/// reference is not finite.
pub fn simulate(cfg: &SimConfig, reference: &[f64]) -> Result<SimOutput, SimError> {
    cfg.validate()?;
    if let Some((index, &value)) = reference.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(SimError::BadReference { index, value });
    }
    let theta0 = reference.first().copied().unwrap_or(0.0);
    let mut sim = Simulation::new(cfg, theta0)?;
    let mut out = sim.output(reference.len());
    for &r in reference {
        out.push(&sim.step(r)?);
    }
    out.saturated_samples = sim.saturated_samples();
    Ok(out)
}

/// One sample of a run at `t = k T`: what the sensors and the controller gave, the
/// reference, and the true state before the sample's propagation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample<'a> {
    /// sample index `k`
    pub k: usize,
    /// time `k T` [s]
    pub t_s: f64,
    /// motor-angle reference `θ_ref` [rad]
    pub theta_ref: f64,
    /// recorded torque reference (with measurement noise) [N·m]
    pub u: f64,
    /// measured motor angle (quantised, with noise) [rad]
    pub theta_m: f64,
    /// torque reference as the controller computed it [N·m]
    pub u_true: f64,
    /// torque out of the current loop [N·m]
    pub tau_motor: f64,
    /// disturbance torque held over the sample [N·m]
    pub disturbance: f64,
    /// true state, [`SimOutput::state_names`] order (`states[0]` the motor angle [rad])
    pub states: &'a [f64],
}

/// The closed loop advanced one reference sample at a time, in constant memory: the one
/// simulator loop behind [`simulate`], [`simulate_excitation`] and the streaming
/// [`stream_excitation`]. The transport delay's past torques are kept in a ring of
/// `⌊delay⌋ + 2` samples.
pub struct Simulation {
    a: Assembled,
    stepper: Stepper,
    x: State,
    before: State,
    mode: Contact,
    controller: Controller,
    sensors: Sensors,
    ts: f64,
    nx: usize,
    nb: usize,
    k: usize,
    /// the last `⌊delay⌋ + 2` torque references `u_true` [N·m], newest at `(head − 1)`
    past_u: Vec<f64>,
    head: usize,
    state_names: Vec<String>,
    plant: &'static str,
    effects: String,
}

impl Simulation {
    /// The run of `cfg` (checked by [`SimConfig::validate`]) from rest with zero spring
    /// deflections and the motor at `theta0` [rad] (the first reference sample).
    ///
    /// # Errors
    /// [`SimError`] when the configuration is invalid.
    pub fn new(cfg: &SimConfig, theta0: f64) -> Result<Simulation, SimError> {
        cfg.validate()?;
        let ts = 1.0 / cfg.sample_rate_hz;
        let a = assemble(cfg);
        let stepper = Stepper::new(&a, cfg.controller.current_loop_tau, ts, &cfg.integration);
        let x = at_rest(&a.mech, theta0);
        let mode = a.nonlinear.region(a.nonlinear.gearbox_deflection(&x));
        Ok(Simulation {
            stepper,
            x,
            before: x,
            mode,
            controller: Controller::new(cfg.controller, ts),
            sensors: Sensors::new(cfg.sensors, ts, cfg.seed),
            ts,
            nx: a.mech.n_state(),
            nb: a.mech.n_bodies(),
            k: 0,
            past_u: vec![0.0; a.delay_whole + 2],
            head: 0,
            state_names: a.mech.state_names(),
            plant: cfg.plant.kind.label(),
            effects: effects_text(&cfg.effects),
            a,
        })
    }

    /// Sample interval `T` [s].
    pub fn sample_interval_s(&self) -> f64 {
        self.ts
    }

    /// Integrator of the run.
    pub fn integrator(&self) -> Integrator {
        self.stepper.integrator()
    }

    /// Samples where the controller output was limited, so far.
    pub fn saturated_samples(&self) -> u64 {
        self.controller.saturated_samples()
    }

    /// An empty [`SimOutput`] of this run with room for `n` samples.
    pub fn output(&self, n: usize) -> SimOutput {
        SimOutput {
            sample_interval_s: self.ts,
            state_names: self.state_names.clone(),
            integrator: self.integrator(),
            ..SimOutput::with_capacity(n, self.nx)
        }
    }

    /// Torque reference `lag` samples before the newest (0 before the first sample).
    #[inline]
    fn past(&self, lag: usize) -> f64 {
        if lag > self.k {
            return 0.0;
        }
        // lag < n and head < n: the index is below 2n − 1 before the wrap
        let n = self.past_u.len();
        let i = self.head + n - 1 - lag;
        self.past_u[if i >= n { i - n } else { i }]
    }

    /// Sample `k` with reference `r` [rad]: sensors, controller, then the plant propagated
    /// to `(k + 1) T`.
    ///
    /// # Errors
    /// [`SimError::BadReference`] for a reference that is not finite,
    /// [`SimError::NonFinite`] naming the first state or signal that is not finite.
    pub fn step(&mut self, r: f64) -> Result<Sample<'_>, SimError> {
        let signals = self.advance(r, 0.0, |c, meas| c.step(r, meas))?;
        Ok(self.sample_of(signals))
    }

    /// [`Self::step`] with the torque reference from `law` (measured motor angle [rad] →
    /// `u` [N·m]) in place of the configured controller, and a constant torque `load`
    /// [N·m] added to the disturbance on the motor: a model run in the loop of a
    /// controller identified from a record ([`crate::ident::controller`]).
    ///
    /// # Errors
    /// As [`Self::step`].
    pub fn step_with(
        &mut self,
        r: f64,
        load: f64,
        law: impl FnOnce(f64) -> f64,
    ) -> Result<Sample<'_>, SimError> {
        let signals = self.advance(r, load, |_, meas| law(meas))?;
        Ok(self.sample_of(signals))
    }

    /// The sample of the signals [`Self::advance`] returned, with the state before it.
    fn sample_of(&self, s: Signals) -> Sample<'_> {
        Sample {
            k: s.k,
            t_s: s.k as f64 * self.ts,
            theta_ref: s.r,
            u: s.u_rec,
            theta_m: s.meas,
            u_true: s.u,
            tau_motor: self.before[2 * self.nb],
            disturbance: s.w,
            states: &self.before[..self.nx],
        }
    }

    /// Sensors, `law` (the run's controller and the measured motor angle [rad] → `u`
    /// [N·m]), then the plant propagated to `(k + 1) T` with `load` added to the
    /// disturbance.
    #[inline]
    fn advance(
        &mut self,
        r: f64,
        load: f64,
        law: impl FnOnce(&mut Controller, f64) -> f64,
    ) -> Result<Signals, SimError> {
        let k = self.k;
        if !r.is_finite() {
            return Err(SimError::BadReference { index: k, value: r });
        }
        let nx = self.nx;
        let x = &mut self.x;
        let meas = self.sensors.measure_theta(x[0]);
        let u = law(&mut self.controller, meas);
        let u_rec = self.sensors.measure_u(u);
        let bad_state = x[..nx]
            .iter()
            .position(|v| !v.is_finite())
            .map(|i| (self.state_names[i].clone(), x[i]));
        let bad = bad_state.or_else(|| {
            [("theta_m", meas), ("u", u_rec), ("u_true", u)]
                .into_iter()
                .find(|(_, v)| !v.is_finite())
                .map(|(n, v)| (n.to_string(), v))
        });
        if let Some((signal, value)) = bad {
            return Err(SimError::NonFinite {
                index: k,
                t_s: k as f64 * self.ts,
                signal,
                value,
                plant: self.plant,
                effects: self.effects.clone(),
            });
        }
        let w = self.sensors.next_disturbance() + load;
        self.before = *x;
        self.past_u[self.head] = u;
        self.head += 1;
        if self.head == self.past_u.len() {
            self.head = 0;
        }
        let u_new = self.past(self.a.delay_whole);
        let u_old = self.past(self.a.delay_whole + 1);
        self.stepper
            .sample(&self.a, &mut self.x, &mut self.mode, u_old, u_new, w);
        self.k += 1;
        Ok(Signals {
            k,
            r,
            meas,
            u,
            u_rec,
            w,
        })
    }
}

/// The signals of one simulated sample, before the state is attached.
struct Signals {
    k: usize,
    r: f64,
    meas: f64,
    u: f64,
    u_rec: f64,
    w: f64,
}

/// What a streamed run leaves besides its samples.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RunSummary {
    /// samples simulated
    pub samples: usize,
    /// sample interval `T` [s]
    pub sample_interval_s: f64,
    /// samples where the controller output was limited
    pub saturated_samples: u64,
    /// integrator used
    pub integrator: Integrator,
}

/// Simulates `cfg` on the reference the firmware's generator produces for `excitation`,
/// sample by sample (`jointid_core::excitation::Excitation`, bit-exact with the board),
/// handing each sample to `each` and keeping nothing: memory independent of the length.
///
/// # Errors
/// As [`simulate_excitation`], and whatever `each` returns (the run stops there).
pub fn stream_excitation<E: From<SimError>>(
    cfg: &SimConfig,
    excitation: &ExcitationConfig,
    mut each: impl FnMut(&Sample<'_>) -> Result<(), E>,
) -> Result<RunSummary, E> {
    if f64::from(excitation.fs_hz) != cfg.sample_rate_hz {
        return Err(SimError::RateMismatch {
            excitation_hz: excitation.fs_hz,
            sim_hz: cfg.sample_rate_hz,
        }
        .into());
    }
    excitation
        .total_samples()
        .ok_or(SimError::Excitation(ExcitationError::Endless))?;
    let mut table = vec![0.0f32; excitation.period_samples as usize];
    let mut gen = jointid_core::excitation::Excitation::new(excitation, &mut table)
        .map_err(SimError::Excitation)?;
    let first = gen.next();
    let mut sim = Simulation::new(cfg, first.map_or(0.0, f64::from))?;
    let mut samples = 0;
    let mut r = first;
    while let Some(v) = r {
        each(&sim.step(f64::from(v))?)?;
        samples += 1;
        r = gen.next();
    }
    Ok(RunSummary {
        samples,
        sample_interval_s: sim.sample_interval_s(),
        saturated_samples: sim.saturated_samples(),
        integrator: sim.integrator(),
    })
}

/// The effects as their spec strings, space separated (`none` without effects).
fn effects_text(effects: &[Effect]) -> String {
    if effects.is_empty() {
        "none".to_string()
    } else {
        effects
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(" ")
    }
}

/// State at rest with zero spring deflections and the motor at `theta0` [rad]: arm-side
/// bodies at `r θ_m`, every velocity and the current-loop torque 0.
fn at_rest(mech: &Mechanism, theta0: f64) -> State {
    let mut x: State = [0.0; MAX_STATE];
    for (i, b) in mech.bodies.iter().enumerate() {
        x[i] = if i == 0 {
            theta0
        } else if b.is_frame() {
            // the frame of a grounded mass: at 0, its spring deflected by `r θ_0`
            0.0
        } else {
            mech.bodies[0].gain * theta0 / b.gain
        };
    }
    x
}

/// How a run propagates the plant over one sample, chosen once per run: the one place that
/// picks the integrator, shared by [`simulate`] and [`simulate_driven`].
enum Stepper {
    /// linear plant: exact ZOH over the sample, split at a fractional delay's switch
    Exact {
        full: ZohStep,
        split: Option<(ZohStep, ZohStep)>,
    },
    /// event-aware RK4 at `substeps` per sample (forced, or exponential off)
    Rk4 { substeps: u32, ts: f64, switch: f64 },
    /// exponential (Lawson) RK4, event-aware RK4 at `substeps` per sample at events
    Exponential {
        stepper: SampleStepper,
        substeps: u32,
    },
}

impl Stepper {
    /// The stepper of the assembled plant `a` with current-loop time constant `tc` [s] and
    /// sample interval `ts` [s].
    fn new(a: &Assembled, tc: f64, ts: f64, integration: &IntegrationConfig) -> Stepper {
        if integration.force_rk4 || (a.is_nonlinear && !integration.exponential) {
            Stepper::Rk4 {
                substeps: integration.substeps,
                ts,
                switch: a.delay_frac,
            }
        } else if a.is_nonlinear {
            // one step per sample: the linear part, the delayed input's switch inside the
            // sample included, is exact, so only the small residual torques see the switch
            Stepper::Exponential {
                stepper: SampleStepper::new(
                    &a.mech,
                    tc,
                    &a.nonlinear,
                    ts,
                    a.delay_frac,
                    integration.substeps,
                ),
                substeps: integration.substeps,
            }
        } else {
            let (f, g) = a.mech.linear_model(tc);
            let split = (a.delay_frac > 0.0).then(|| {
                (
                    ZohStep::new(&f, &g, a.delay_frac * ts),
                    ZohStep::new(&f, &g, (1.0 - a.delay_frac) * ts),
                )
            });
            Stepper::Exact {
                full: ZohStep::new(&f, &g, ts),
                split,
            }
        }
    }

    fn integrator(&self) -> Integrator {
        match *self {
            Stepper::Exact { .. } => Integrator::ExactZoh,
            Stepper::Rk4 { substeps, .. } => Integrator::Rk4 { substeps },
            Stepper::Exponential { substeps, .. } => Integrator::ExponentialRk4 { substeps },
        }
    }

    /// Propagates `x` over one sample, from `k T` to `(k + 1) T`: the torque reference
    /// `u_old = u[k − n − 1]` [N·m] until the delay's switch and `u_new = u[k − n]` after
    /// it (0 before the first sample; delay `n + φ` samples), through the current loop,
    /// with the disturbance `w` [N·m] held.
    #[inline]
    fn sample(
        &self,
        a: &Assembled,
        x: &mut State,
        mode: &mut Contact,
        u_old: f64,
        u_new: f64,
        w: f64,
    ) {
        match self {
            Stepper::Exact { full, split: None } => full.apply(x, &[u_new, w]),
            Stepper::Exact {
                split: Some((first, second)),
                ..
            } => {
                first.apply(x, &[u_old, w]);
                second.apply(x, &[u_new, w]);
            }
            Stepper::Exponential { stepper, .. } => {
                a.nonlinear.sample(stepper, x, mode, u_old, u_new, w)
            }
            Stepper::Rk4 {
                substeps,
                ts,
                switch,
            } => a
                .nonlinear
                .rk4_sample(x, mode, *ts, *switch, *substeps as usize, u_old, u_new, w),
        }
    }
}

/// [`simulate`] with the reference the firmware's generator produces for `excitation`
/// (`jointid_core::excitation::generate`, bit-exact with the board).
///
/// # Errors
/// As [`simulate`], plus [`SimError::Excitation`] when the excitation cannot be generated
/// (e.g. endless) and [`SimError::RateMismatch`] when its sample rate differs.
pub fn simulate_excitation(
    cfg: &SimConfig,
    excitation: &ExcitationConfig,
) -> Result<SimOutput, SimError> {
    let n = excitation.total_samples().unwrap_or(0) as usize;
    let mut out = SimOutput::with_capacity(0, 0);
    let summary = stream_excitation(cfg, excitation, |s: &Sample<'_>| {
        if s.k == 0 {
            out = SimOutput::with_capacity(n, s.states.len());
        }
        out.push(s);
        Ok::<(), SimError>(())
    })?;
    out.state_names = Mechanism::new(&cfg.plant, &cfg.effects).state_names();
    out.sample_interval_s = summary.sample_interval_s;
    out.saturated_samples = summary.saturated_samples;
    out.integrator = summary.integrator;
    Ok(out)
}

/// [`simulate`] with an `f32` reference (as the firmware's excitation generator produces it).
///
/// # Errors
/// As [`simulate`].
pub fn simulate_f32(cfg: &SimConfig, reference: &[f32]) -> Result<SimOutput, SimError> {
    let r: Vec<f64> = reference.iter().map(|&v| f64::from(v)).collect();
    simulate(cfg, &r)
}

#[cfg(test)]
mod tests;
