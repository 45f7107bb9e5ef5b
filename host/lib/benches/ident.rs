//! Identification benchmark: speed and accuracy of the subspace and
//! grey-box estimators on a known three-mass joint (seed 000 eq. (6), angle
//! output, r = 1/118) in a discrete PD position loop at 2 kHz.
//!
//! Prints, per case: wall time, time relative to a baseline measured in the
//! same run (one simulation of an order-11 model over the same record),
//! validation FIT on a second record (toolbox definition
//! `100·(1 − ‖y − ŷ‖/‖y − ȳ‖)`, initial state estimated on the validation
//! record) and the identified resonance / anti-resonance frequencies
//! against the truth.
//!
//! The frequency-domain path ([`jointid::ident::sml`]) is measured on the
//! simulator's default closed-loop joint (quantised encoder, noise, slow
//! torque disturbance, 0.5 ms current loop) at 15,000 and 150,000 samples:
//! the FRF once, then the fit on its lines, with its time relative to the
//! time-domain grey-box fit of this bench's own 15,000-sample record (PD
//! loop, no disturbance) measured in the same run.
//!
//! Run: `cargo bench -p jointid --features test-support --bench ident`.

use std::hint::black_box;
use std::time::Instant;

use jointid::data::dsp::filtfilt_lowpass;
use jointid::data::IdData;
use jointid::ident::grey_box::{
    self, reference_three_mass, GreyBoxModel, GreyBoxOptions, Output, DEFAULT_GEAR_RATIO,
};
use jointid::ident::linalg::GaussRng;
use jointid::ident::pem::{self, FullSs, ParamModel, PemOptions};
use jointid::ident::ss::StateSpace;
use jointid::ident::subspace::{self, estimate_x0, Method, Order, SubspaceOptions};
use jointid::model::spec::Structure;
use nalgebra::DVector;

const TS: f64 = 5e-4;

/// PD position loop `u = kp (r − y_m) − kd ẏ_m + w`, output noise on y_m,
/// reference = low-passed Gaussian noise, small torque disturbance `w`.
fn closed_loop(plant: &StateSpace, n: usize, seed: u64) -> IdData {
    let mut rng = GaussRng::new(seed);
    let mut x = DVector::zeros(plant.order());
    let (mut r, mut w, mut y_prev) = (0.0, 0.0, 0.0);
    let (kp, kd) = (1.0, 0.02);
    let (mut u, mut y, mut rr) = (
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
    );
    for _ in 0..n {
        r = 0.95 * r + 0.05 * rng.normal();
        w = 0.99 * w + 0.002 * rng.normal();
        let ym = (&plant.c * &x)[0] + 2e-5 * rng.normal();
        let ut = kp * (r - ym) - kd * (ym - y_prev) / plant.ts + 0.02 * rng.normal() + w;
        y_prev = ym;
        u.push(ut);
        y.push(ym);
        rr.push(r);
        x = &plant.a * &x + &plant.b * ut;
    }
    IdData {
        ts: plant.ts,
        u,
        y,
        r: Some(rr),
    }
}

fn decimate(d: &IdData, k: usize) -> IdData {
    let fc = 0.4 / (d.ts * k as f64);
    let uf = filtfilt_lowpass(&d.u, 8, fc, d.ts);
    let yf = filtfilt_lowpass(&d.y, 8, fc, d.ts);
    IdData {
        ts: d.ts * k as f64,
        u: uf.iter().step_by(k).copied().collect(),
        y: yf.iter().step_by(k).copied().collect(),
        r: None,
    }
}

fn val_fit(m: &StateSpace, val: &IdData) -> f64 {
    let mut m = m.clone();
    m.k = None;
    let x0 = estimate_x0(&m, &val.u, &val.y);
    jointid::ident::validate::fit_percent(&val.y, &m.simulate(&val.u, Some(&x0))).unwrap()
}

fn freqs(m: &StateSpace) -> (Vec<f64>, Vec<f64>) {
    let r = m.resonances(2.0, 0.2);
    (
        r.resonances.iter().map(|x| x.freq_hz).collect(),
        r.anti_resonances.iter().map(|x| x.freq_hz).collect(),
    )
}

/// black-box output-error refinement (full parameterisation) of a subspace model
fn pem_line(m: &StateSpace, est: &IdData, val: &IdData) {
    let mut m0 = m.clone();
    m0.k = None;
    let (fs, th) = FullSs::from_ss(&m0, false, false);
    let t = Instant::now();
    match pem::fit(&fs, &th, est, &PemOptions::with_max_iter(20)) {
        Ok(pf) => {
            let dt = t.elapsed().as_secs_f64();
            let (r, a) = freqs(&pf.model);
            println!(
                "{:<34} {dt:>9.4} {:>9} {:>8.2} {:>8}  [{}] | [{}]  ({} iterations, {:?})",
                format!("  +PEM (OE, {} params)", fs.n_params()),
                "",
                val_fit(&pf.model, val),
                "",
                fmt(&r),
                fmt(&a),
                pf.iterations,
                pf.termination
            );
        }
        Err(e) => println!("  +PEM failed: {e}"),
    }
}

fn fmt(v: &[f64]) -> String {
    v.iter()
        .map(|f| format!("{f:.2}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// Frequency-domain three-mass fit on `n` samples of the simulator's
/// default joint: seconds for the FRF and the fit, largest parameter error.
fn frequency_domain_case(n: usize, td_seconds: f64) {
    use jointid::data::{Dataset, ExcitationConfig};
    use jointid::ident::fit::DrivenModel;
    use jointid::ident::frf::analyze_dataset;
    use jointid::ident::frf_subspace::{black_box_frf, black_box_frf_integrating};
    use jointid::ident::sml::{fit_frf, periodic_fit_percent, FrfFitOptions};
    use jointid::sim::{simulate_excitation, SimConfig};
    // the paper's multisine (f0 = 0.4 Hz, N = 5000, lines up to 121.6 Hz)
    // without its ramp: 15,000 samples are three periods, the first dropped
    let mut exc = ExcitationConfig::paper_default();
    exc.ramp_samples = 0;
    exc.periods = (n / 5000) as u32;
    let cfg = SimConfig::default();
    let record = |seed: u64| {
        let out = simulate_excitation(
            &SimConfig {
                seed,
                ..cfg.clone()
            },
            &exc,
        )
        .expect("simulation");
        Dataset {
            name: "sim".into(),
            data: out.to_id_data(),
            t0: 0.0,
            excitation: Some(exc),
            meta: Default::default(),
        }
    };
    let ds = record(1);
    let t = Instant::now();
    let a = analyze_dataset(&ds, 1).expect("frf");
    let t_frf = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let fit = fit_frf(&a.frf, &FrfFitOptions::new(Structure::ThreeMass, TS)).expect("fd fit");
    let t_fit = t.elapsed().as_secs_f64();
    let jp = cfg.plant.params;
    let truth = [
        jp.j_m, jp.j_a1, jp.j_a2, jp.k_g, jp.k_a, jp.d_g, jp.d_a, jp.f_m,
    ];
    let worst = fit
        .params
        .iter()
        .zip(truth)
        .take(7)
        .map(|(p, t)| (100.0 * (p.value - t) / t).abs())
        .fold(0.0, f64::max);
    println!(
        "frequency domain three-mass N={n:<7} FRF {t_frf:.4} s + fit {t_fit:.4} s = {:.4} s ({:.3} x the time-domain fit), \
         largest error of the 7 identifiable parameters {worst:.2} %, f_m {:+.1} %, lag {:.3} ms (truth 0.5), \
         cost ratio {:.2}, resonances [{}] Hz, {} warnings",
        t_frf + t_fit,
        (t_frf + t_fit) / td_seconds,
        100.0 * (fit.params[7].value - jp.f_m) / jp.f_m,
        1e3 * fit.lag.value * TS,
        fit.cost_ratio(),
        fmt(&fit.resonances_hz),
        fit.warnings.len()
    );
    // the 11th-order black box on the same lines, against the true model on
    // a second record
    let t = Instant::now();
    let bb = black_box_frf(&a.frf, 11, TS, false, 40).expect("black box");
    let t_bb = t.elapsed().as_secs_f64();
    let val = analyze_dataset(&record(2), 1).expect("frf").frf;
    let true_model = DrivenModel {
        mechanics: GreyBoxModel {
            structure: Structure::ThreeMass,
            output: Output::Angle,
            r: jp.r,
            ts: TS,
        },
        current_loop_tau: cfg.controller.current_loop_tau,
    }
    .continuous(&truth)
    .zoh(TS);
    let fit_bb = periodic_fit_percent(&val, &bb.model.freq_response(&val.freq_hz));
    let fit_true = periodic_fit_percent(&val, &true_model.freq_response(&val.freq_hz));
    println!(
        "frequency domain black box n=11 N={n:<7} FRF {t_frf:.4} s + fit {t_bb:.4} s ({:.3} x the time-domain grey-box fit), \
         validation FIT {fit_bb:.2} % (true model {fit_true:.2} %), cost ratio {:.2}, {} warnings",
        (t_frf + t_bb) / td_seconds,
        bb.cost_ratio(),
        bb.warnings.len()
    );
    for w in &bb.warnings {
        println!("    warning: {w}");
    }
    // the same order with the rigid-body integrator exact
    let t = Instant::now();
    let bi = black_box_frf_integrating(&a.frf, 11, TS, 40).expect("black box");
    let t_bi = t.elapsed().as_secs_f64();
    let fit_bi = periodic_fit_percent(&val, &bi.model.freq_response(&val.freq_hz));
    println!(
        "  with the integrator exact               fit {t_bi:.4} s, validation FIT {fit_bi:.2} %, \
         cost {:.1} ({} parameters) against {:.1} ({} parameters), {} warnings",
        bi.cost,
        bi.parameters,
        bb.cost,
        bb.parameters,
        bi.warnings.len()
    );
    for w in &bi.warnings {
        println!("    warning: {w}");
    }
}

fn main() {
    let gm = GreyBoxModel {
        structure: Structure::ThreeMass,
        output: Output::Angle,
        r: DEFAULT_GEAR_RATIO,
        ts: TS,
    };
    let p = reference_three_mass();
    let plant = gm.continuous(&p).zoh(TS);
    let (tr_res, tr_anti) = freqs(&plant);
    println!(
        "three-mass truth (fs = 2 kHz): resonances [{}] Hz, anti-resonances [{}] Hz",
        fmt(&tr_res),
        fmt(&tr_anti)
    );
    println!(
        "{:<34} {:>9} {:>9} {:>8} {:>8}  resonances [Hz] | anti-resonances [Hz]",
        "case", "time [s]", "x base", "FIT [%]", "warn"
    );
    for &n in &[15_000usize, 150_000] {
        let est_full = closed_loop(&plant, n, 1);
        let val_full = closed_loop(&plant, n.min(30_000), 2);
        // baseline: one simulation of an order-11 model over the same record
        let m11 = {
            let o = SubspaceOptions {
                method: Method::Pbsid,
                order: Order::Fixed(11),
                ..Default::default()
            };
            subspace::estimate(&est_full, &o)
                .expect("baseline model")
                .model
        };
        let t0 = Instant::now();
        black_box(m11.simulate(&est_full.u, None));
        let base = t0.elapsed().as_secs_f64();
        println!("baseline: simulate order 11 over {n} samples: {base:.4} s");
        for &dec in &[1usize, 10] {
            let (est, val) = if dec == 1 {
                (est_full.clone(), val_full.clone())
            } else {
                (decimate(&est_full, dec), decimate(&val_full, dec))
            };
            for &order in &[6usize, 11] {
                for method in [Method::Pbsid, Method::Moesp] {
                    let past: usize = std::env::var("PAST")
                        .ok()
                        .and_then(|v| v.parse().ok())
                        .unwrap_or(0);
                    let opts = SubspaceOptions {
                        method,
                        order: Order::Fixed(order),
                        past,
                        ..Default::default()
                    };
                    let t = Instant::now();
                    let fit = subspace::estimate(&est, &opts);
                    let dt = t.elapsed().as_secs_f64();
                    let name = format!("{method:?} n={order} N={} dec={dec}", est.u.len());
                    match fit {
                        Ok(f) => {
                            if dec == 10 && order == 11 && method == Method::Pbsid {
                                pem_line(&f.model, &est, &val);
                            }
                            let (r, a) = freqs(&f.model);
                            println!(
                                "{name:<34} {dt:>9.4} {:>9.2} {:>8.2} {:>8}  [{}] | [{}]",
                                dt / base,
                                val_fit(&f.model, &val),
                                f.warnings.len(),
                                fmt(&r),
                                fmt(&a)
                            );
                        }
                        Err(e) => println!("{name:<34} {dt:>9.4} failed: {e}"),
                    }
                }
            }
        }
    }
    // three-mass grey-box on 15 000 samples (undecimated)
    let est = closed_loop(&plant, 15_000, 1);
    let val = closed_loop(&plant, 15_000, 2);
    let t = Instant::now();
    let g = grey_box::fit(&est, &GreyBoxOptions::default()).expect("grey-box fit");
    let dt = t.elapsed().as_secs_f64();
    let (r, a) = freqs(&g.discrete);
    println!(
        "grey-box three-mass N=15000: {dt:.3} s, {} PEM iterations, FIT est {:.2} % val {:.2} %, resonances [{}] anti [{}]",
        g.pem.iterations,
        g.fit_percent,
        val_fit(&g.discrete, &val),
        fmt(&r),
        fmt(&a)
    );
    println!(
        "{:<6} {:>14} {:>14} {:>12} {:>10} {:>14}",
        "param", "truth", "estimate", "std", "err [%]", "initial"
    );
    for ((pp, t), i) in g.params.iter().zip(&p).zip(&g.initial) {
        println!(
            "{:<6} {:>14.6e} {:>14.6e} {:>12.3e} {:>10.3} {:>14.6e}",
            pp.name,
            t,
            pp.value,
            pp.std,
            100.0 * (pp.value - t) / t,
            i.value
        );
    }
    // the frequency-domain path against that time-domain fit (the baseline)
    for n in [15_000, 150_000] {
        frequency_domain_case(n, dt);
    }
}
