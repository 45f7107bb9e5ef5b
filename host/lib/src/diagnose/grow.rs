//! The start of the Coulomb-friction candidates when the motor sticks: grown in the time
//! domain from the two-mass, not read off the FRF.
//!
//! **Why.** When the friction level is comparable to the torque, the motor rests for long
//! stretches (stick-slip) and the FRF at the excited lines is the friction's describing
//! function (a viscous-like damping), not the structure's: the linear fits see a motor on a
//! damper and no spring. Bench case 7 of `benches/diagnose.rs` (three-mass with an extra
//! mode and Stribeck friction `F_c` 0.043, `F_s` 0.058 N·m at 0.067 rad RMS, torque RMS
//! 0.059 N·m): the motor is at rest on 41 % of the samples. The three- and four-mass fits
//! to the raw FRF end at `k_g` 222 and 119 N·m/rad (truth 1.53e5) with `f_m` 0.18 and 0.20
//! N·m·s/rad (0.002); compensated as [`crate::ident::nonlinear::compensate`] does, at
//! 75–1.4e6 N·m/rad; even compensated with the true law at the true motor velocity, the
//! fits that find `k_g` keep `k_a` 2–25× off and `f_m` 3–10× high (a stuck motor carries
//! a friction torque no law of its velocity gives). Every nonlinear fit started there stays
//! in that basin: the basin around the truth spans about 1.5× per value (the pair started
//! 3× off ends at 47 %, 1.5× off at 90.5 %, as from the truth).
//!
//! **What.** The two-mass with Coulomb friction is fitted by output error from its automatic
//! start, whose step 3 grids the gearbox spring against the cost of the simulation with the
//! friction ([`crate::ident::nonlinear::automatic_start`]); the arm's second mass is then
//! found as an extra mode in series on that two-mass (the start's grid over the mode's
//! frequency), which is the three-mass chain; the candidates start from that chain. The
//! friction is the Stribeck law (`F_c`, `F_s`, `v_s` fitted, started at the default shape
//! [`CoulombFriction::default`] scaled by the automatic start): in stick-slip the motor
//! breaks away at every stick, and on case 7 the pure law leaves 4.4 FIT points
//! (90.6 % against 95.0 %, both started at the truth; true model 95.3 %).
//!
//! **When.** Stick-slip is taken as the measured torque staying below the friction level
//! of the compensation's regression ([`crate::ident::nonlinear::compensate::level`]) on
//! more than [`STICK_SHARE`] of the samples (case 7: 66 %; the other cases of the bench,
//! 0–8 %).

use crate::data::IdData;
use crate::ident::nonlinear::{identify_segments, NlFit, NlOptions, NlRequest};
use crate::model::effects::{Attach, CoulombFriction, Effect, ExtraMode};
use crate::model::spec::Structure;

/// Share of samples with `|u| < F̂_c` from which the motor is taken to stick.
pub const STICK_SHARE: f64 = 0.2;

/// Share of the samples of `data` whose torque magnitude is below `level` [N·m].
pub fn stick_share(data: &[IdData], level: f64) -> f64 {
    let n: usize = data.iter().map(|d| d.u.len()).sum();
    let below = data
        .iter()
        .flat_map(|d| d.u.iter())
        .filter(|u| u.abs() < level)
        .count();
    below as f64 / n.max(1) as f64
}

/// The grown start.
#[derive(Clone, Debug, PartialEq)]
pub struct Grown {
    /// the structure's values ([`Structure::param_names`] order)
    pub plant: Vec<f64>,
    /// current-loop lag [s] (0: none)
    pub tau_c: f64,
    /// input offset [N·m]
    pub offset: f64,
    /// the fitted friction (Stribeck law)
    pub coulomb: Effect,
}

/// The friction keys of a fit's Coulomb friction, to give a later start.
pub fn friction_keys(fit: &NlFit) -> Vec<(String, f64)> {
    fit.model
        .effects
        .iter()
        .find_map(|e| match e {
            Effect::CoulombFriction(c) => Some(vec![
                ("fc".to_string(), c.fc),
                ("fs".to_string(), c.fs),
                ("v_stribeck".to_string(), c.v_stribeck),
            ]),
            _ => None,
        })
        .unwrap_or_default()
}

/// The start of `structure` (two- or three-mass) with Stribeck friction grown from the
/// two-mass on the records `est` (module documentation); `tau_c` the lag to start from [s].
///
/// # Errors
/// Another structure, or a fit that fails.
pub fn grow(
    est: &[IdData],
    structure: Structure,
    r: f64,
    tau_c: f64,
    options: &NlOptions,
) -> Result<Grown, String> {
    if !matches!(structure, Structure::TwoMass | Structure::ThreeMass) {
        return Err(format!("no grown start for the {}", structure.label()));
    }
    let law = Effect::CoulombFriction(CoulombFriction::default());
    let two = NlRequest {
        tau_c,
        options: options.clone(),
        ..NlRequest::new(Structure::TwoMass, r, vec![law])
    };
    let a = identify_segments(est, &two).map_err(|e| e.to_string())?.fit;
    let done = |fit: &NlFit, plant: Vec<f64>| {
        let coulomb = fit
            .model
            .effects
            .iter()
            .find(|e| matches!(e, Effect::CoulombFriction(_)))
            .copied()
            .unwrap_or(law);
        Grown {
            plant,
            tau_c: fit.model.tau_c,
            offset: fit.get("offset").unwrap_or(0.0),
            coulomb,
        }
    };
    if structure == Structure::TwoMass {
        return Ok(done(&a, a.plant.clone()));
    }
    // the arm's second mass: an extra mode in series on the two-mass is the three-mass chain
    let mode = Effect::ExtraMode(ExtraMode {
        attach: Attach::Serial,
        ..ExtraMode::default()
    });
    let chain = NlRequest {
        tau_c: a.model.tau_c,
        linear: Some(a.plant.clone()),
        given: vec![Vec::new(), friction_keys(&a)],
        options: options.clone(),
        ..NlRequest::new(Structure::TwoMass, r, vec![mode, law])
    };
    let b = identify_segments(est, &chain)
        .map_err(|e| e.to_string())?
        .fit;
    let Some(Effect::ExtraMode(x)) = b.model.effects.first().copied() else {
        return Err("the chain's fit lost its extra mode".into());
    };
    // [J_m, J_a1, k_g, d_g, f_m] and the mode → [J_m, J_a1, J_a2, k_g, k_a, d_g, d_a, f_m]
    let p = &b.plant;
    let plant = vec![p[0], p[1], x.j, p[2], x.k, p[3], x.d, p[4]];
    Ok(done(&b, plant))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::metric::{DrivenModel, Measured};
    use crate::diagnose::{candidate, diagnose, DiagnoseOptions, DiagnoseRequest};
    use crate::sim::{ControllerConfig, JointParams, Plant, SimConfig};
    use jointid_core::excitation::ExcitationConfig;

    #[test]
    fn the_stick_share_counts_torques_below_the_level() {
        let d = IdData {
            ts: 1e-3,
            u: vec![0.01, -0.02, 0.05, -0.06, 0.0],
            y: vec![0.0; 5],
            r: None,
        };
        assert_eq!(stick_share(std::slice::from_ref(&d), 0.03), 0.6);
        assert_eq!(stick_share(&[d.clone(), d], 0.055), 0.8);
    }

    /// Bench case 7 (`benches/diagnose.rs`, the values as drawn): a three-mass joint with an
    /// extra mode and Stribeck friction under the soft tuning (`kp` 10, `kv` 0.1, `ti` 0.1)
    /// at 0.067 rad RMS, where the motor rests on 41 % of the samples. Before the grown
    /// start the answer was Coulomb friction alone, 30.5 points below the true model.
    #[test]
    fn a_sticking_motor_with_an_extra_mode_is_diagnosed_as_the_pair() {
        let friction = CoulombFriction {
            fc: 0.04342,
            fs: 0.05790,
            ..CoulombFriction::default()
        };
        let mode = ExtraMode {
            j: 2.834,
            k: 1.1146e4,
            d: 7.5,
            attach: Attach::Parallel,
        };
        let params = JointParams {
            j_m: 8.243e-4,
            j_a1: 9.609,
            j_a2: 0.6134,
            k_g: 1.5258e5,
            k_a: 5776.4,
            d_g: 67.51,
            d_a: 2.814,
            f_m: 1.953e-3,
            ..JointParams::default()
        };
        let cfg = SimConfig {
            plant: Plant {
                kind: Structure::ThreeMass,
                params,
            },
            effects: vec![Effect::ExtraMode(mode), Effect::CoulombFriction(friction)],
            controller: ControllerConfig {
                kp: 10.0,
                kv: 0.1,
                ti: 0.1,
                u_max: 1e3,
                ..ControllerConfig::default()
            },
            ..SimConfig::default()
        };
        let exc = ExcitationConfig {
            periods: 4,
            rms_rad: 0.06726,
            ..ExcitationConfig::paper_default()
        };
        let (est, val) = crate::test_support::est_val_captures(&cfg, &exc, 507);
        let req = DiagnoseRequest {
            r: params.r,
            candidates: ["coulomb_friction", "extra_mode"]
                .iter()
                .filter_map(|n| candidate(n))
                .collect(),
            ..DiagnoseRequest::default()
        };
        let d = diagnose(&[est], &val, &req).unwrap();
        let opts = DiagnoseOptions::default();
        let skip = ((opts.skip_s / val.data.ts).round() as usize).min(val.data.len() / 4);
        let true_fit = Measured::new(&val.data, opts.band_hz, skip)
            .score(
                &DrivenModel {
                    plant: cfg.plant,
                    effects: cfg.effects.clone(),
                    tau_c: cfg.controller.current_loop_tau,
                    offset: 0.0,
                },
                &val.data,
                1,
            )
            .unwrap()
            .fit;
        eprintln!("{}; true model {true_fit:.2} %; {:?}", d.verdict, d.pair);
        assert!(d.warnings.iter().any(|w| w.starts_with("the motor sticks")));
        assert_eq!(d.best, "coulomb_friction+extra_mode", "{}", d.verdict);
        assert!(
            (d.fit_augmented_val - true_fit).abs() < 3.0,
            "{:.2} % against the true model's {true_fit:.2} %",
            d.fit_augmented_val
        );
        let pair = d.pair.as_ref().unwrap();
        let off = |v: f64, t: f64| (v / t - 1.0).abs();
        let fc = pair.parameters["coulomb_friction.fc"].value;
        assert!(off(fc, friction.fc) < 0.2, "F_c = {fc}");
        // the mode on either branch of the first arm mass
        let (j, k) = (
            pair.parameters["extra_mode.j"].value,
            pair.parameters["extra_mode.k"].value,
        );
        let (j2, k2) = (
            pair.structure_parameters["J_a2"].value,
            pair.structure_parameters["k_a"].value,
        );
        let as_mode = off(j, mode.j).max(off(k, mode.k));
        let as_arm = off(j2, mode.j).max(off(k2, mode.k));
        assert!(
            as_mode.min(as_arm) < 0.2,
            "mode j {j:.3e} k {k:.3e}, arm J_a2 {j2:.3e} k_a {k2:.3e}; truth {mode:?}"
        );
    }
}
