//! Nonlinear grey-box benchmark (issue 11, item 6), side by side in one run:
//!
//! 1. Seed 001's reference problem (`../shared/data/seed001-two-mass/`, made outside this
//!    project): the two-mass joint with cubic spring and Coulomb friction from the README's
//!    10 kinds of start (the truth times U(0.7, 1.3) per parameter, drawn here with a fixed
//!    seed) and from the automatic start (seed 001's three steps, nothing from the truth).
//!    Per fit: CPU seconds of this thread, iterations, whether J_m, J_a, k1, k3, d, F_c are
//!    all within 5 % of the truth ("reached"), the validation FIT of the interval-mean motor
//!    velocity (unfiltered, as the README's peers report it) with the simulator's exact laws,
//!    and the true parameters' FIT through the same simulation.
//! 2. The reference in the same run: the same fits with central-difference Jacobians
//!    (`2 n + 1` simulations per iteration instead of one dual-number pass).
//! 3. The default three-mass joint of `jointid simulate` (default sensors: quantised
//!    encoder, noise on both signals, slow torque disturbance) with each effect alone,
//!    from the truth moved by +20 % / −15 %: seconds, iterations, the largest error of the
//!    identifiable parameters in per cent and in reported σ.
//!
//! Run: `cargo bench -p jointid --bench nonlinear`. Figures of the README's peers on the
//! same files (scipy TRF with finite differences 30.5 s, JAX + scipy 1.0 s, jax-sysid 6.1 s
//! median per fit; validation FIT 96.87 %) are printed beside ours.

use std::path::{Path, PathBuf};
use std::time::Instant;

use jointid::data::{load_csv, ColumnMap, IdData};
use jointid::ident::linalg::GaussRng;
use jointid::ident::nonlinear::{
    automatic_start, fit_output_error, validate, Gradient, NlFit, NlModel, NlOptions,
};
use jointid::model::effects::{CoulombFriction, Effect, NonlinearStiffness};
use jointid::model::spec::Structure;
use jointid::sim::{simulate_excitation, SimConfig};
use jointid_core::excitation::ExcitationConfig;

/// CPU time of this thread [s] (Linux `schedstat`), wall time otherwise.
fn cpu_s(wall: &Instant) -> f64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse::<f64>().ok())
        .map_or_else(|| wall.elapsed().as_secs_f64(), |ns| ns * 1e-9)
}

fn shared(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .map(|a| a.join("shared/data"))
        .find(|d| d.is_dir())
        .expect("shared/data beside the repository")
        .join(path)
}

/// J_m, J_a, k1, d, F_v (structure order), then k3, F_c.
const TRUTH: [f64; 7] = [1e-3, 14.6, 1.3e5, 80.0, 2e-3, 1.6e11, 0.1];

fn seed001_model(k3: f64, fc: f64) -> NlModel {
    NlModel {
        structure: Structure::TwoMass,
        r: 1.0 / 118.0,
        effects: vec![
            Effect::NonlinearStiffness(NonlinearStiffness { k3 }),
            Effect::CoulombFriction(CoulombFriction {
                fc,
                fs: fc,
                ..CoulombFriction::default()
            }),
        ],
        tau_c: 0.0,
        v_eps: 0.05,
        dz_eps: 1e-7,
        substeps: 1,
    }
}

fn reached(fit: &NlFit) -> bool {
    [
        ("J_m", TRUTH[0]),
        ("J_a1", TRUTH[1]),
        ("k_g", TRUTH[2]),
        ("d_g", TRUTH[3]),
        ("k3", TRUTH[5]),
        ("fc", TRUTH[6]),
    ]
    .iter()
    .all(|&(n, t)| fit.get(n).is_some_and(|v| (v / t - 1.0).abs() < 0.05))
}

fn unfiltered() -> NlOptions {
    NlOptions {
        highpass_hz: 0.0,
        ..NlOptions::default()
    }
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn seed001(est: &IdData, val: &IdData) {
    println!("== seed 001 reference problem (60,000 samples, 2 kHz)");
    let model = seed001_model(TRUTH[5], TRUTH[6]);
    let truth_values = model.values(&TRUTH[..5], 0.0, 0.0);
    let truth_fit = fit_output_error(
        est,
        &model,
        &truth_values,
        &NlOptions {
            max_iter: 0,
            ..NlOptions::default()
        },
    );
    let truth_val = truth_fit
        .ok()
        .and_then(|f| validate(&f, val, &unfiltered()).ok())
        .map_or(f64::NAN, |v| v.velocity_fit_percent);
    println!("true parameters: validation FIT {truth_val:.2} % (velocity, unfiltered, exact laws)");
    let mut rng = GaussRng::new(2026);
    let starts: Vec<Vec<f64>> = (0..10)
        .map(|_| {
            let s: Vec<f64> = TRUTH
                .iter()
                .map(|t| t * (0.7 + 0.6 * rng.uniform()))
                .collect();
            seed001_model(s[5], s[6]).values(&s[..5], 0.0, 0.0)
        })
        .collect();
    println!(
        "{:<26} {:>8} {:>8} {:>6} {:>10} {:>9}",
        "gradient / start", "cpu s", "iter", "reached", "val FIT %", "cost"
    );
    for (label, gradient, n) in [
        ("dual numbers", Gradient::Dual, 10),
        ("central differences", Gradient::CentralDifferences, 3),
    ] {
        let mut times = Vec::new();
        let mut ok = 0;
        for (i, s) in starts.iter().take(n).enumerate() {
            let m = seed001_model(s[6], s[7]);
            let wall = Instant::now();
            let c0 = cpu_s(&wall);
            let fit = fit_output_error(
                est,
                &m,
                s,
                &NlOptions {
                    gradient,
                    ..NlOptions::default()
                },
            )
            .expect("fit");
            let dt = cpu_s(&wall) - c0;
            times.push(dt);
            let vf =
                validate(&fit, val, &unfiltered()).map_or(f64::NAN, |v| v.velocity_fit_percent);
            ok += usize::from(reached(&fit));
            println!(
                "{:<26} {:>8.3} {:>8} {:>6} {:>10.2} {:>9.4e}",
                format!("{label} #{i}"),
                dt,
                fit.iterations,
                if reached(&fit) { "yes" } else { "no" },
                vf,
                fit.ssr
            );
        }
        println!(
            "{label}: reached {ok}/{n}, median {:.3} s per fit (one thread)",
            median(&mut times)
        );
    }
    let wall = Instant::now();
    let c0 = cpu_s(&wall);
    let m = seed001_model(1.0, 0.01);
    let start = automatic_start(est, &m, None).expect("automatic start");
    let t_start = cpu_s(&wall) - c0;
    let fit =
        fit_output_error(est, &start.model, &start.values, &NlOptions::default()).expect("fit");
    let dt = cpu_s(&wall) - c0;
    let vf = validate(&fit, val, &unfiltered()).map_or(f64::NAN, |v| v.velocity_fit_percent);
    println!(
        "automatic start: {t_start:.3} s for the three steps, {dt:.3} s with the fit, {} iterations, reached {}, validation FIT {vf:.2} %",
        fit.iterations,
        if reached(&fit) { "yes" } else { "no" }
    );
    for s in &start.steps {
        let vals: Vec<String> = s
            .values
            .iter()
            .map(|(n, v, u)| format!("{n} {v:.4e} {u}"))
            .collect();
        println!("  step {}: {} ({})", s.name, vals.join(", "), s.detail);
    }
    println!(
        "peers (README, same files): scipy TRF + finite differences 30.5 s, JAX + scipy 1.0 s, jax-sysid 6.1 s median per fit; validation FIT 96.87 %"
    );
}

fn three_mass_effects() {
    println!("== three-mass + one effect, default sensors and disturbance (24,000 samples)");
    println!(
        "{:<22} {:>8} {:>6} {:>10} {:>10}  {}",
        "effect", "cpu s", "iter", "max err %", "max |σ|", "(identifiable parameters)"
    );
    let cases: [(&str, &[&str], usize); 5] = [
        (
            "nonlinear_stiffness",
            &["J_m", "J_a1", "k_g", "d_g", "tau_c", "k3"],
            1,
        ),
        (
            "torque_ripple",
            &["J_m", "J_a1", "k_g", "d_g", "amplitude", "phase"],
            1,
        ),
        ("time_delay", &["J_m", "J_a1", "k_g", "d_g", "samples"], 2),
        ("extra_mode", &["J_m", "J_a1", "k_g", "d_g", "j", "k"], 1),
        ("backlash", &["J_m", "J_a1", "k_g", "d_g", "width"], 1),
    ];
    for (name, identifiable, substeps) in cases {
        let effect = Effect::default_by_name(name).expect("effect");
        let cfg = SimConfig {
            effects: vec![effect],
            seed: 3,
            ..SimConfig::default()
        };
        let out = simulate_excitation(&cfg, &ExcitationConfig::paper_default()).expect("sim");
        let data = IdData {
            ts: out.sample_interval_s,
            u: out.u,
            y: out.theta_m,
            r: None,
        };
        let p = cfg.plant.params;
        let model = NlModel {
            structure: Structure::ThreeMass,
            r: p.r,
            effects: vec![effect],
            tau_c: cfg.controller.current_loop_tau,
            v_eps: 0.05,
            dz_eps: 1e-7,
            substeps,
        };
        let truth = model.values(
            &[p.j_m, p.j_a1, p.j_a2, p.k_g, p.k_a, p.d_g, p.d_a, p.f_m],
            0.0,
            0.0,
        );
        let start: Vec<f64> = truth
            .iter()
            .enumerate()
            .map(|(i, &t)| if i % 2 == 0 { t * 1.2 } else { t * 0.85 })
            .collect();
        let wall = Instant::now();
        let c0 = cpu_s(&wall);
        let fit = fit_output_error(&data, &model, &start, &NlOptions::default()).expect("fit");
        let dt = cpu_s(&wall) - c0;
        let layout = model.layout();
        let (mut worst_pct, mut worst_sigma) = (0.0f64, 0.0f64);
        for n in identifiable {
            let i = layout.iter().position(|d| d.name == *n).expect("name");
            let (v, s, t) = (fit.params[i].value, fit.params[i].std, truth[i]);
            worst_pct = worst_pct.max(100.0 * (v / t - 1.0).abs());
            worst_sigma = worst_sigma.max((v - t).abs() / s);
        }
        println!(
            "{:<22} {:>8.3} {:>6} {:>10.2} {:>10.2}  {}",
            name,
            dt,
            fit.iterations,
            worst_pct,
            worst_sigma,
            identifiable.join(" ")
        );
    }
}

fn main() {
    let map = ColumnMap::capture();
    let est = load_csv(&shared("seed001-two-mass/est.csv"), &map)
        .expect("est.csv")
        .data;
    let val = load_csv(&shared("seed001-two-mass/val.csv"), &map)
        .expect("val.csv")
        .data;
    seed001(&est, &val);
    three_mass_effects();
}
