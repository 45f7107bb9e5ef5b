//! Identification checks on data with known truth (the host's closed-loop
//! joint simulator, fixed seeds) (issue 5, items 6–9); the checks on
//! measured data through the command line are in
//! `host/cli/tests/fit_validate_demo_commands.rs`, where the binary exists.
//!
//! Simulated three-mass joint for the statistical checks: the default
//! three-mass plant of `jointid::sim` in its position loop, sampled at
//! 500 Hz so that the model's zero-order hold is exact (no decimation
//! filter between `u` and the model), excited by the special odd multisine
//! up to 224 Hz (0.9 × Nyquist, so no band of the model is left without
//! excitation), current loop 1 µs (inside the model
//! class), white noise on θm only (σ = 2e-5 rad), no encoder quantisation,
//! no torque disturbance, `u` recorded exactly (it is the controller's own
//! number, seed 000 Fig. 2). Under these conditions the output-error
//! criterion has the right noise model, so the direct closed-loop estimate
//! is consistent and `σ̂² (JᵀJ)⁻¹` is its asymptotic covariance (Ljung 1999,
//! §13.4 direct approach, §9.3); the tests check both.

use std::collections::BTreeMap;

use jointid::data::{Dataset, IdData};
use jointid::ident::fit::{fit_model, FitOptions};
use jointid::ident::grey_box::{GreyBoxModel, Output};
use jointid::ident::pem::{self, PemOptions};
use jointid::model::spec::{Family, ModelSpec, Structure};
use jointid::scenario::paper::{paper_runs, table, Table};
use jointid::sim::{self, Disturbance, SensorConfig, SimConfig};
use jointid_core::excitation::{ExcitationConfig, SignalKind};

const FS: u32 = 500;
const THREE_MASS: [&str; 8] = ["J_m", "J_a1", "J_a2", "k_g", "k_a", "d_g", "d_a", "f_m"];

fn excitation(seed: u64, periods: u32) -> ExcitationConfig {
    ExcitationConfig {
        kind: SignalKind::SpecialOddMultisine,
        fs_hz: FS,
        period_samples: 1250,
        max_line: 560,
        cutoff_hz: 50.0,
        rms_rad: 0.02,
        seed,
        ramp_samples: 250,
        periods,
    }
}

fn sim_config(params: sim::JointParams, seed: u64) -> SimConfig {
    let mut cfg = SimConfig {
        plant: sim::Plant {
            kind: Structure::ThreeMass,
            params,
        },
        sensors: SensorConfig {
            counts_per_rev: None,
            theta_noise_std: 2e-5,
            u_noise_std: 0.0,
            disturbance: Disturbance::none(),
        },
        seed,
        sample_rate_hz: f64::from(FS),
        ..SimConfig::default()
    };
    cfg.controller.current_loop_tau = 1e-6;
    cfg
}

/// steady periods (one settle period dropped) of a run, as identification data
fn run(cfg: &SimConfig, exc: &ExcitationConfig) -> IdData {
    let out = sim::simulate_excitation(cfg, exc).unwrap();
    let start = (exc.ramp_samples + exc.period_samples) as usize;
    let len = ((exc.periods - 1) * exc.period_samples) as usize;
    out.to_id_data().slice(start..start + len)
}

fn truth_vec(p: &sim::JointParams) -> Vec<f64> {
    let t = p.table();
    THREE_MASS
        .iter()
        .map(|n| t.iter().find(|(m, _, _)| m == n).unwrap().1)
        .collect()
}

fn model(ts: f64) -> GreyBoxModel {
    GreyBoxModel {
        structure: Structure::ThreeMass,
        output: Output::Angle,
        r: sim::JointParams::default().r,
        ts,
    }
}

/// output-error fit started from the true parameters (log scale)
fn fit_from_truth(data: &IdData, truth: &[f64]) -> pem::PemFit {
    let th0: Vec<f64> = truth.iter().map(|v| v.ln()).collect();
    pem::fit(&model(data.ts), &th0, data, &PemOptions::with_max_iter(40)).unwrap()
}

// Five noise seeds, automatic initial values: every parameter within 3
// reported standard deviations of the truth.
#[test]
fn three_mass_estimates_lie_within_3_sigma_on_closed_loop_data() {
    let p = sim::JointParams::default();
    let truth = truth_vec(&p);
    let exc = excitation(11, 3);
    for seed in 1..=5u64 {
        let data = run(&sim_config(p, seed), &exc);
        let f = fit_model(
            &data,
            &FitOptions {
                spec: ModelSpec::linear(Family::Physical(Structure::ThreeMass)),
                ..FitOptions::default()
            },
        )
        .unwrap();
        for (est, t) in f.params.iter().zip(&truth) {
            let z = (est.value - t) / est.std;
            eprintln!(
                "seed {seed} {:<5} {:.5e} ± {:.2e} (true {t:.5e}, z {z:+.2})",
                est.name, est.value, est.std
            );
            assert!(
                z.abs() <= 3.0,
                "seed {seed}: {} = {} ± {} vs true {t} (z = {z:.2})",
                est.name,
                est.value,
                est.std
            );
        }
    }
}

// 30 noise realisations on the same joint and excitation: the spread of the
// estimates (log parameters) against the mean reported standard deviation.
// With 30 realisations the sample standard deviation is within ±13 % (one
// sigma) of the true one, so a factor 1.5 either way is a 3-sigma band.
#[test]
fn three_mass_reported_sigma_matches_spread_over_noise_realisations() {
    let p = sim::JointParams::default();
    let truth = truth_vec(&p);
    let exc = excitation(12, 3);
    let reps = 30;
    let mut est: Vec<Vec<f64>> = Vec::new();
    let mut sig: Vec<Vec<f64>> = Vec::new();
    for seed in 0..reps {
        let data = run(&sim_config(p, 100 + seed), &exc);
        let f = fit_from_truth(&data, &truth);
        est.push(f.theta.clone());
        sig.push(f.std.clone());
    }
    for (i, name) in THREE_MASS.iter().enumerate() {
        let xs: Vec<f64> = est.iter().map(|t| t[i]).collect();
        let m = xs.iter().sum::<f64>() / reps as f64;
        let sd = (xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (reps as f64 - 1.0)).sqrt();
        let rep = sig.iter().map(|s| s[i]).sum::<f64>() / reps as f64;
        let ratio = sd / rep;
        eprintln!(
            "{name:<5} spread {sd:.3e}, reported {rep:.3e}, ratio {ratio:.2}, bias {:+.2} σ",
            (m - truth[i].ln()) / rep
        );
        assert!(
            (1.0 / 1.5..=1.5).contains(&ratio),
            "{name}: spread {sd:.3e} vs reported {rep:.3e} (ratio {ratio:.2})"
        );
    }
}

// 100 joints with every parameter drawn ±30 % around the defaults: the fit
// from the automatic initial values reaches the cost of the fit started at
// the truth (relative 1e-4) on at least 95 of them. The joints are drawn
// first and fitted on the machine's cores: each fit is a pure function of
// its joint, so the count is the same on any number of threads.
#[test]
fn three_mass_automatic_start_reaches_global_optimum_on_95_of_100_joints() {
    let mut rng = jointid::ident::linalg::GaussRng::new(2024);
    let exc = excitation(13, 2);
    let joints: Vec<(u64, sim::JointParams)> = (0..100u64)
        .map(|j| {
            let mut p = sim::JointParams::default();
            for v in p.three_mass_values_mut() {
                *v *= 0.7 + 0.6 * rng.uniform();
            }
            (j, p)
        })
        .collect();
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    // per joint: the automatic fit's cost over the cost from the truth, NaN when it failed
    let ratios = jointid::ident::parallel::parallel(&joints, threads, |&(j, p)| {
        let truth = truth_vec(&p);
        let data = run(&sim_config(p, 500 + j), &exc);
        let global = fit_from_truth(&data, &truth);
        let auto = fit_model(
            &data,
            &FitOptions {
                spec: ModelSpec::linear(Family::Physical(Structure::ThreeMass)),
                ..FitOptions::default()
            },
        );
        let c_global = *global.cost_history.last().unwrap();
        match auto {
            Ok(f) => {
                let yh = f.simulate(&data);
                let c_auto = data
                    .y
                    .iter()
                    .zip(&yh)
                    .map(|(a, b)| (a - b).powi(2))
                    .sum::<f64>()
                    / data.len() as f64;
                c_auto / c_global
            }
            Err(e) => {
                eprintln!("joint {j}: automatic fit failed: {e}");
                f64::NAN
            }
        }
    });
    let failures: Vec<(u64, f64)> = joints
        .iter()
        .zip(&ratios)
        .filter(|(_, r)| r.is_nan() || **r > 1.0 + 1e-4)
        .map(|((j, _), r)| (*j, *r))
        .collect();
    let ok = 100 - failures.len();
    eprintln!("global optimum reached on {ok} of 100; misses (joint, cost ratio): {failures:?}");
    assert!(ok >= 95, "{ok} of 100; misses {failures:?}");
}

/// Seed 000 §6 table for one model on the simulated paper experiment (noise
/// `seed`): estimation and validation runs as capture datasets, fitted and
/// compared with the true model.
fn paper_table(seed: u64, model: Family) -> Table {
    let runs = paper_runs(seed).unwrap();
    let ds = |out: &sim::SimOutput, exc: ExcitationConfig, name: &str| Dataset {
        name: name.into(),
        data: out.to_id_data(),
        t0: 0.0,
        excitation: Some(exc),
        meta: BTreeMap::new(),
    };
    let est = ds(&runs.est, runs.est_excitation, "est");
    let val = ds(&runs.val, runs.val_excitation, "val");
    table(&est, &val, &runs.sim, &[model]).unwrap().0
}

// Seed 000 §6 on the simulated IRB1400-like joint: the black box of order 11
// reaches a validation FIT within 1 point of the true model's.
#[test]
fn black_box_order_11_validation_fit_within_1_point_of_true_model() {
    let t = paper_table(3, Family::BlackBox(11));
    let bb = &t.rows[0];
    eprintln!(
        "black box 11: est {:.2}, val {:.2}; true model: est {:.2}, val {:.2}",
        bb.fit_estimation, bb.fit_validation, t.true_fit.0, t.true_fit.1
    );
    assert!(
        bb.fit_validation >= t.true_fit.1 - 1.0,
        "validation FIT {:.2} vs true model {:.2}",
        bb.fit_validation,
        t.true_fit.1
    );
}

// Seed 000 §6 on the simulated IRB1400-like joint, whose truth is a
// four-mass chain behind a 0.5 ms current loop: the four-mass model, started
// on the decimated data and refined at the capture rate with the known
// current-loop lag, reaches the true model's validation FIT within 1 point,
// every parameter within 2 % of the truth and within 4 reported standard
// deviations (measured on seed 3: at most 0.2 % and 1.3 σ).
#[test]
fn four_mass_on_paper_experiment_reaches_true_fit_and_parameters() {
    let t = paper_table(3, Family::Physical(Structure::FourMass));
    let row = &t.rows[0];
    eprintln!(
        "four-mass: est {:.2}, val {:.2}; true model: est {:.2}, val {:.2}",
        row.fit_estimation, row.fit_validation, t.true_fit.0, t.true_fit.1
    );
    assert!(
        row.fit_validation >= t.true_fit.1 - 1.0,
        "validation FIT {:.2} vs true model {:.2}",
        row.fit_validation,
        t.true_fit.1
    );
    assert_eq!(row.parameter_errors.len(), 11);
    for p in &row.parameter_errors {
        eprintln!("{:<5} {:+.2} % ({:+.2} σ)", p.name, p.error_percent, p.z());
        assert!(
            p.error_percent.abs() <= 2.0 && p.z().abs() <= 4.0,
            "{}: {} ± {} vs true {} ({:+.2} %, {:+.2} σ)",
            p.name,
            p.estimate,
            p.std,
            p.truth,
            p.error_percent,
            p.z()
        );
    }
}
