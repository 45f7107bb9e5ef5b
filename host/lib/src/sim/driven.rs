//! The plant driven by a given torque reference, open loop: no controller, no sensors.
//!
//! What: the motor angle `θ_m` (and the gearbox deflection and motor velocity) that a plant
//! with its effects gives when its torque reference is a given sequence `u[k]`, e.g. the
//! measured one. Why: the validation FIT of a fitted model, with effects or without, is
//! computed with the exact laws by simulating the model from the measured torque (the
//! estimators' smooth laws only serve the gradients). How: exactly as [`super::simulate`]
//! propagates the plant between samples, by the same stepper (exact ZOH when the plant is
//! linear, the exponential stepper with stick–slip and backlash events otherwise, see
//! [`super::integrate`]): `u[k]` is held over `[kT, (k + 1)T)`, goes through the transport
//! delay (whole and fractional samples) and the current-loop lag; the disturbance is 0.
//! Fed with the `u` of a closed-loop run with ideal sensors it gives that run's true motor
//! angle back (tests in `super::tests::driven`).

use super::integrate::State;
use super::{
    assemble_parts, at_rest, check_effects, check_integration, check_ranges, effects_text,
    plant_ranges, Effect, IntegrationConfig, Integrator, Plant, SimError, Stepper,
};
use crate::model::plant::{Mechanism, MAX_STATE};

/// The state the driven plant starts from at `t = 0`. The delay line holds zero torque
/// before the first sample, as in [`super::simulate`]: to start inside a record with a
/// delay, prepend the torque before it and drop as many output samples.
#[derive(Clone, Debug, PartialEq)]
pub enum DrivenStart {
    /// at rest: zero spring deflections, every velocity and the current-loop torque 0,
    /// the motor at `theta_m` [rad] (the arm bodies at `r θ_m`)
    Rest {
        /// motor angle [rad]
        theta_m: f64,
    },
    /// a full state in the simulator's layout (`SimOutput::state_names`, [`Mechanism::state_names`]:
    /// angles [rad], velocities [rad/s], then the current-loop torque `τ_a` [N·m]); the
    /// backlash contact region and the friction state follow from it
    State(Vec<f64>),
}

impl Default for DrivenStart {
    /// At rest with the motor at 0 rad.
    fn default() -> Self {
        DrivenStart::Rest { theta_m: 0.0 }
    }
}

/// Result of [`simulate_driven`]: one value per torque sample, at the sample times `k T`.
#[derive(Clone, Debug, PartialEq)]
pub struct DrivenOutput {
    /// sample interval `T` [s]
    pub sample_interval_s: f64,
    /// motor angle `θ_m(kT)` [rad]; `θ_m[0]` is the start angle, `θ_m[k]` the response to
    /// `u[..k]`
    pub theta_m: Vec<f64>,
    /// gearbox deflection `r θ_m − θ_a1` (arm side) at `kT` [rad]; 0 for the rigid plant
    pub gearbox_deflection: Vec<f64>,
    /// motor velocity `ω_m(kT)` [rad/s]
    pub omega_m: Vec<f64>,
    /// integrator used
    pub integrator: Integrator,
}

impl DrivenOutput {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.theta_m.len()
    }

    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.theta_m.is_empty()
    }
}

/// [`simulate_driven_with`] with the default integration ([`IntegrationConfig::default`]).
///
/// # Errors
/// As [`simulate_driven_with`].
pub fn simulate_driven(
    plant: &Plant,
    effects: &[Effect],
    current_loop_tau: f64,
    sample_interval_s: f64,
    u: &[f64],
    start: &DrivenStart,
) -> Result<DrivenOutput, SimError> {
    simulate_driven_with(
        plant,
        effects,
        current_loop_tau,
        sample_interval_s,
        u,
        start,
        &IntegrationConfig::default(),
    )
}

/// Simulates `plant` with `effects` driven open loop by the torque reference `u` [N·m],
/// sampled every `sample_interval_s` [s], through the current loop of time constant
/// `current_loop_tau` [s] (> 0), from `start`, with the stepper `integration` selects (as
/// [`super::simulate`]). Empty `u` gives an empty output (after the checks).
///
/// # Errors
/// [`SimError::InvalidParameter`], [`SimError::BadEffect`] and the other configuration
/// errors of [`super::SimConfig::validate`] for the plant, effects, time constant, sample
/// interval and integration; [`SimError::BadTorque`] for the first `u[k]` that is not
/// finite; [`SimError::BadStart`] for a start state of the wrong length or not finite;
/// [`SimError::NonFinite`] naming the first sample whose state is not finite.
pub fn simulate_driven_with(
    plant: &Plant,
    effects: &[Effect],
    current_loop_tau: f64,
    sample_interval_s: f64,
    u: &[f64],
    start: &DrivenStart,
    integration: &IntegrationConfig,
) -> Result<DrivenOutput, SimError> {
    simulate_driven_loaded(
        plant,
        effects,
        current_loop_tau,
        sample_interval_s,
        u,
        &[],
        start,
        integration,
    )
}

/// As [`simulate_driven_with`], with a torque `load[k]` [N·m] held over `[kT, (k + 1)T)`
/// and added to the motor torque after the delay and the current loop, where the
/// closed-loop simulator adds its disturbance (an empty `load` is none; a shorter one is 0
/// past its end). Why: a torque known as a function of a measured signal, e.g. the torque
/// ripple at the measured motor angle ([`crate::diagnose::metric`]), enters the motor
/// directly, not through the current loop.
///
/// # Errors
/// As [`simulate_driven_with`]; a non-finite `load` sample is a [`SimError::BadTorque`].
#[allow(clippy::too_many_arguments)]
pub fn simulate_driven_loaded(
    plant: &Plant,
    effects: &[Effect],
    current_loop_tau: f64,
    sample_interval_s: f64,
    u: &[f64],
    load: &[f64],
    start: &DrivenStart,
    integration: &IntegrationConfig,
) -> Result<DrivenOutput, SimError> {
    let (mut positive, nonneg) = plant_ranges(plant);
    positive.extend([
        ("current_loop_tau", current_loop_tau),
        ("sample_interval_s", sample_interval_s),
    ]);
    check_ranges(&positive, &nonneg)?;
    check_integration(integration)?;
    check_effects(plant, effects)?;
    for x in [u, load] {
        if let Some((index, &value)) = x.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(SimError::BadTorque { index, value });
        }
    }
    let ts = sample_interval_s;
    let a = assemble_parts(plant, effects, current_loop_tau);
    let stepper = Stepper::new(&a, current_loop_tau, ts, integration);
    let mut x = start_state(&a.mech, start)?;
    let mut mode = a.nonlinear.region(a.nonlinear.gearbox_deflection(&x));
    let (nb, nx, n) = (a.mech.n_bodies(), a.mech.n_state(), u.len());
    let mut out = DrivenOutput {
        sample_interval_s: ts,
        theta_m: Vec::with_capacity(n),
        gearbox_deflection: Vec::with_capacity(n),
        omega_m: Vec::with_capacity(n),
        integrator: stepper.integrator(),
    };
    for k in 0..n {
        if let Some(i) = x[..nx].iter().position(|v| !v.is_finite()) {
            return Err(SimError::NonFinite {
                index: k,
                t_s: k as f64 * ts,
                signal: a.mech.state_names()[i].clone(),
                value: x[i],
                plant: plant.kind.label(),
                effects: effects_text(effects),
            });
        }
        out.theta_m.push(x[0]);
        out.gearbox_deflection
            .push(a.nonlinear.gearbox_deflection(&x));
        out.omega_m.push(x[nb]);
        // the delayed torques: u[k − n − 1] until the switch, u[k − n] after it
        let past = |lag: usize| k.checked_sub(lag).map_or(0.0, |j| u[j]);
        let (u_old, u_new) = (past(a.delay_whole + 1), past(a.delay_whole));
        stepper.sample(
            &a,
            &mut x,
            &mut mode,
            u_old,
            u_new,
            load.get(k).copied().unwrap_or(0.0),
        );
    }
    Ok(out)
}

/// The state to start from, checked against the mechanism.
fn start_state(mech: &Mechanism, start: &DrivenStart) -> Result<State, SimError> {
    match start {
        DrivenStart::Rest { theta_m } if theta_m.is_finite() => Ok(at_rest(mech, *theta_m)),
        DrivenStart::Rest { theta_m } => Err(SimError::BadStart(format!(
            "motor angle {theta_m} is not finite"
        ))),
        DrivenStart::State(v) => {
            let names = mech.state_names();
            if v.len() != names.len() {
                return Err(SimError::BadStart(format!(
                    "{} values given, the plant has {} ({})",
                    v.len(),
                    names.len(),
                    names.join(", ")
                )));
            }
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                return Err(SimError::BadStart(format!(
                    "{} = {} is not finite",
                    names[i], v[i]
                )));
            }
            let mut x: State = [0.0; MAX_STATE];
            x[..v.len()].copy_from_slice(v);
            Ok(x)
        }
    }
}
