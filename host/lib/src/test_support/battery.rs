//! The diagnosis bench's battery (`benches/diagnose.rs`), drawn here so that a test can
//! rerun one of its cases as drawn: joints of the project's simulator with hidden effects,
//! their controllers and sensors, each case from its own seed.

use crate::data::Dataset;
use crate::ident::linalg::GaussRng;
use crate::model::effects::{Effect, EFFECT_NAMES};
use crate::model::spec::Structure;
use crate::sim::{ControllerConfig, Disturbance, JointParams, Plant, SensorConfig, SimConfig};
use jointid_core::excitation::{ExcitationConfig, SignalKind};

use super::{est_val_captures, random_joint};

/// One case of the battery.
pub struct Case {
    /// the hidden effects (none, one or two)
    pub hidden: Vec<Effect>,
    /// the three-mass joint
    pub params: JointParams,
    /// its controller
    pub controller: ControllerConfig,
    /// its sensors and disturbance
    pub sensors: SensorConfig,
    /// the reference's amplitude [rad RMS]
    pub rms: f64,
    /// the noise seed of the estimation capture (the validation's is `seed + 1000`)
    pub seed: u64,
    /// what the joint has besides the hidden effects and is no effect to name (weak
    /// friction, [`weak_friction`]); empty unless the bench asks for it
    pub background: Vec<Effect>,
}

/// The harder conditions of `HARD=1`, drawn for case `index` from a generator of its own
/// (the regular battery's draws are unchanged): a torque disturbance low-passed at 20–60 Hz
/// (inside the excitation's band, not only slow drift) of 0.5–2 mN·m, an encoder of
/// 2^14–2^17 counts per revolution, a current-loop lag of 0.25–1.5 ms, and the
/// controller's inertia feedforward on in half the cases.
pub fn hard(index: usize, controller: &mut ControllerConfig, sensors: &mut SensorConfig) {
    let mut rng = GaussRng::new(9090 + index as u64);
    let mut within = |lo: f64, hi: f64| lo * (hi / lo).powf(rng.uniform());
    sensors.disturbance = Disturbance {
        noise_std: within(5e-4, 2e-3),
        noise_cutoff_hz: within(20.0, 60.0),
        ..Disturbance::default()
    };
    sensors.counts_per_rev = Some(1 << (14 + index % 4));
    controller.current_loop_tau = within(2.5e-4, 1.5e-3);
    controller.feedforward = index % 2 == 1;
}

/// The hidden effects of case `index` moved off the estimators' own forms (`LAWS=1`), drawn
/// from a generator of their own, so that the bench tells whether the diagnosis is right
/// for the physics rather than for the laws it fits:
/// - Coulomb friction: a backward level `F_c−` of 0.6–1.4 × `F_c` (the candidate's law is
///   symmetric), a breakaway `F_s/F_c` of 1.0–2.0 (default 4/3) and a Stribeck velocity of
///   0.3–3 × its default;
/// - torque ripple: a second harmonic (order `2n`, 0.3–0.8 × the amplitude, its own phase)
///   beside the first, whose phase is drawn too (the candidate fits one order);
/// - extra mode: on the chain's end (`Attach::Serial`) instead of beside the first arm mass;
/// - time delay: whole samples (at least one), as a controller's cycle gives it, instead of
///   a fraction.
///
/// The backlash's dead zone and the cubic spring keep the estimators' laws (the simulator
/// has no other).
pub fn other_laws(index: usize, effects: &mut Vec<Effect>) {
    let mut rng = GaussRng::new(7070 + index as u64);
    let mut within = |lo: f64, hi: f64| lo * (hi / lo).powf(rng.uniform());
    let mut added = Vec::new();
    for e in effects.iter_mut() {
        match e {
            Effect::CoulombFriction(c) => {
                c.fc_neg = Some(c.fc * within(0.6, 1.4));
                c.fs = c.fc * within(1.0, 2.0);
                c.v_stribeck *= within(0.3, 3.0);
            }
            Effect::TorqueRipple(r) => {
                r.phase = within(0.1, 6.2);
                added.push(Effect::TorqueRipple(crate::model::effects::TorqueRipple {
                    amplitude: r.amplitude * within(0.3, 0.8),
                    order: 2.0 * r.order,
                    phase: within(0.1, 6.2),
                }));
            }
            Effect::ExtraMode(m) => m.attach = crate::model::effects::Attach::Serial,
            Effect::TimeDelay(d) => d.samples = d.samples.round().max(1.0),
            Effect::Backlash(_) | Effect::NonlinearStiffness(_) => {}
        }
    }
    effects.extend(added);
}

/// Weak Coulomb friction on the motor of case `index` (`FRICTION=1`), drawn from a
/// generator of its own: a sliding level `F_c` of 1–4 % of the default's (0.3–1.2 mN·m,
/// below the smallest hidden friction of `SMALL=1`, 3 mN·m), the default breakaway ratio.
/// Every real joint has some; the diagnosis is to name the effects beside it, and `none`
/// where there are none. A joint whose hidden effect is Coulomb friction has that one
/// alone (none is returned).
pub fn weak_friction(index: usize, hidden: &[Effect]) -> Vec<Effect> {
    if hidden
        .iter()
        .any(|e| matches!(e, Effect::CoulombFriction(_)))
    {
        return Vec::new();
    }
    let mut rng = GaussRng::new(6060 + index as u64);
    let share = 0.01 * 4f64.powf(rng.uniform());
    vec![scaled("coulomb_friction", share)]
}

/// Case `index`'s joint moved off the default's scale (`JOINTS=1`), drawn from a generator
/// of its own, so that the bench tells whether the diagnosis holds for other joints than
/// the one it was developed on:
/// - a torque scale `s`, log-uniform in 0.03–30: every inertia, stiffness, damping and
///   friction, the controller's torque gain, limit and feedforward inertia, the torque
///   noise and disturbance, and every effect's torque (friction levels, ripple amplitude,
///   cubic coefficient, extra mode) times `s`. The motion is the default-scale joint's: a
///   method with no torque constant of its own gives the same answer on it;
/// - a frequency scale `f`, log-uniform in 0.6–1.6: every stiffness (the cubic one and
///   the extra mode's too) times `f²`, every damping times `f`, so that the resonances move
///   by `f` at the same damping ratios against the same controller (a stiffer or a softer
///   joint under the same tuning).
///
/// Angles (the backlash's gap, the amplitude), times (the delay, the current loop) and
/// speeds (the Stribeck and smoothing velocities) keep their values.
///
/// With `resonances` false, `f` is 1: the joint is the default-scale joint in other torque
/// units, and every answer and FIT should be the default-scale case's.
pub fn other_joint(index: usize, case: &mut Case, resonances: bool) {
    let mut rng = GaussRng::new(8080 + index as u64);
    let mut within = |lo: f64, hi: f64| lo * (hi / lo).powf(rng.uniform());
    let (s, f) = (within(0.03, 30.0), within(0.6, 1.6));
    let f = if resonances { f } else { 1.0 };
    let p = &mut case.params;
    for j in [&mut p.j_m, &mut p.j_a1, &mut p.j_a2, &mut p.j_p] {
        *j *= s;
    }
    for k in [&mut p.k_g, &mut p.k_a, &mut p.k_p, &mut p.k_0, &mut p.k3] {
        *k *= s * f * f;
    }
    for d in [&mut p.d_g, &mut p.d_a, &mut p.d_p] {
        *d *= s * f;
    }
    p.f_m *= s;
    p.f_c *= s;
    let c = &mut case.controller;
    c.kv *= s;
    c.u_max *= s;
    c.ff_inertia *= s;
    let n = &mut case.sensors;
    n.u_noise_std *= s;
    n.disturbance.noise_std *= s;
    n.disturbance.sine_amplitude *= s;
    for e in case.hidden.iter_mut().chain(case.background.iter_mut()) {
        match e {
            Effect::CoulombFriction(c) => {
                c.fc *= s;
                c.fs *= s;
                c.fc_neg = c.fc_neg.map(|v| v * s);
                c.fv_neg_extra = c.fv_neg_extra.map(|v| v * s);
            }
            Effect::TorqueRipple(r) => r.amplitude *= s,
            Effect::NonlinearStiffness(k) => k.k3 *= s * f * f,
            Effect::ExtraMode(m) => {
                m.j *= s;
                m.k *= s * f * f;
                m.d *= s * f;
            }
            Effect::Backlash(_) | Effect::TimeDelay(_) => {}
        }
    }
}

/// The effect `name` at `scale` × its default size (the size parameters only).
pub fn scaled(name: &str, scale: f64) -> Effect {
    let mut e = Effect::default_by_name(name).expect("an effect name");
    match &mut e {
        Effect::CoulombFriction(c) => {
            c.fc *= scale;
            c.fs *= scale;
        }
        Effect::Backlash(b) => b.width *= scale,
        Effect::NonlinearStiffness(s) => s.k3 *= scale,
        Effect::ExtraMode(m) => {
            m.j *= scale;
            m.k *= scale;
        }
        Effect::TimeDelay(d) => d.samples *= scale,
        Effect::TorqueRipple(r) => r.amplitude *= scale,
    }
    e
}

/// Cases per round: each of the six effects alone, two pairs, two `none`.
pub const ROUND: usize = 10;

/// The battery: `rounds` rounds of [`ROUND`] cases, round `k` drawn with its own seed from
/// the same distributions (round 0 is the original battery). Case `k·ROUND + i` has the
/// controller tuning `(k·ROUND + i) mod 3`, so each effect meets other tunings in later
/// rounds.
pub fn cases(rounds: usize, small: bool, harder: bool) -> Vec<Case> {
    // the size's range as a multiple of the default
    let (lo, hi): (f64, f64) = if small { (0.1, 1.6) } else { (0.7, 1.6) };
    let mut hidden: Vec<Vec<&str>> = EFFECT_NAMES.iter().map(|n| vec![*n]).collect();
    hidden.push(vec!["nonlinear_stiffness", "time_delay"]);
    hidden.push(vec!["extra_mode", "coulomb_friction"]);
    hidden.push(vec![]);
    hidden.push(vec![]);
    assert_eq!(hidden.len(), ROUND);
    let mut out = Vec::new();
    for round in 0..rounds {
        let mut rng = GaussRng::new(1212 + 1000 * round as u64);
        for (i, names) in hidden.iter().enumerate() {
            let index = round * ROUND + i;
            let (params, mut controller, rms) = random_joint(&mut rng, index);
            let effects = names
                .iter()
                .map(|n| scaled(n, lo * (hi / lo).powf(rng.uniform())))
                .collect();
            let mut sensors = SensorConfig::default();
            if harder {
                hard(index, &mut controller, &mut sensors);
            }
            out.push(Case {
                hidden: effects,
                params,
                controller,
                sensors,
                rms,
                seed: 500 + index as u64,
                background: Vec::new(),
            });
        }
    }
    out
}

/// The simulation of `case`.
pub fn config(case: &Case) -> SimConfig {
    SimConfig {
        plant: Plant {
            kind: Structure::ThreeMass,
            params: case.params,
        },
        effects: case
            .hidden
            .iter()
            .chain(&case.background)
            .copied()
            .collect(),
        controller: case.controller,
        sensors: case.sensors,
        ..SimConfig::default()
    }
}

/// Estimation and validation captures of `case` with `periods` periods each (validation:
/// other phases and noise).
pub fn captures(case: &Case, periods: u32, rms: f64) -> (Dataset, Dataset) {
    let exc = ExcitationConfig {
        periods,
        rms_rad: rms as f32,
        ..ExcitationConfig::paper_default()
    };
    est_val_captures(&config(case), &exc, case.seed)
}

/// A second estimation capture of `case` at `rms` (other noise, other phases), for the
/// amplitude analysis of two captures.
pub fn second_capture(case: &Case, periods: u32, rms: f64) -> Dataset {
    let exc = ExcitationConfig {
        periods,
        rms_rad: rms as f32,
        seed: ExcitationConfig::paper_default().seed ^ 0x0F0F_7777,
        ..ExcitationConfig::paper_default()
    };
    est_val_captures(&config(case), &exc, case.seed + 7).0
}

/// As [`captures`], the validation capture driven by `val_kind` (a band-limited noise, as an
/// independent bench gives it).
pub fn captures_validated_by(
    case: &Case,
    periods: u32,
    rms: f64,
    val_kind: SignalKind,
) -> (Dataset, Dataset) {
    let exc = ExcitationConfig {
        periods,
        rms_rad: rms as f32,
        ..ExcitationConfig::paper_default()
    };
    crate::test_support::est_val_captures_with(&config(case), &exc, case.seed, val_kind)
}
