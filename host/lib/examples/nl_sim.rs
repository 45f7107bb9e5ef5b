use jointid::data::IdData;
use jointid::ident::nonlinear::*;
use jointid::model::effects::Effect;
use jointid::model::spec::Structure;
use jointid::sim::{simulate_excitation, SensorConfig, SimConfig};
use jointid_core::excitation::ExcitationConfig;
use std::time::Instant;

fn main() {
    let name = std::env::args()
        .nth(1)
        .unwrap_or("nonlinear_stiffness".into());
    let ideal = std::env::args().nth(2).is_some();
    let eff = Effect::default_by_name(&name).unwrap();
    let mut cfg = SimConfig {
        effects: vec![eff],
        ..SimConfig::default()
    };
    if ideal {
        cfg.sensors = SensorConfig::ideal();
        cfg.sensors.theta_noise_std = 1e-5;
    }
    match std::env::var("ONLY").as_deref() {
        Ok("quant") => {
            cfg.sensors = SensorConfig::ideal();
            cfg.sensors.counts_per_rev = Some(1 << 17);
        }
        Ok("unoise") => {
            cfg.sensors = SensorConfig::ideal();
            cfg.sensors.u_noise_std = 2e-3;
        }
        Ok("dist") => {
            cfg.sensors = SensorConfig::ideal();
            cfg.sensors.disturbance = Default::default();
        }
        _ => {}
    }
    let mut exc = ExcitationConfig::paper_default();
    let out = simulate_excitation(&cfg, &exc).unwrap();
    let est = IdData {
        ts: out.sample_interval_s,
        u: out.u.clone(),
        y: out.theta_m.clone(),
        r: None,
    };
    cfg.seed = 2;
    exc.seed = 99;
    let out2 = simulate_excitation(&cfg, &exc).unwrap();
    let val = IdData {
        ts: out2.sample_interval_s,
        u: out2.u.clone(),
        y: out2.theta_m.clone(),
        r: None,
    };
    let p = cfg.plant.params;
    let model = NlModel {
        structure: Structure::ThreeMass,
        r: p.r,
        effects: vec![eff],
        tau_c: cfg.controller.current_loop_tau,
        v_eps: 0.05,
        dz_eps: 1e-7,
        substeps: 1,
    };
    let plant = [p.j_m, p.j_a1, p.j_a2, p.k_g, p.k_a, p.d_g, p.d_a, p.f_m];
    let truth = model.values(&plant, 0.0, 0.0);
    let vv = interval_velocity(&val.y, val.ts);
    let vh = simulate_velocity(&model, &truth, &val.u, val.ts, val.y[0], Some(&val.y)).unwrap();
    println!(
        "N {} truth val FIT {:.3}",
        est.u.len(),
        jointid::ident::validate::fit_percent(&vv[1..], &vh[1..]).unwrap()
    );
    let start: Vec<f64> = truth
        .iter()
        .enumerate()
        .map(|(i, &t)| if i % 2 == 0 { t * 1.2 } else { t * 0.85 })
        .collect();
    let t0 = Instant::now();
    let hp: f64 = std::env::var("HP")
        .ok()
        .map(|s| s.parse().unwrap())
        .unwrap_or(1.0);
    let ord: usize = std::env::var("ORD")
        .ok()
        .map(|s| s.parse().unwrap())
        .unwrap_or(2);
    let f = fit_output_error(
        &est,
        &model,
        &start,
        &NlOptions {
            highpass_hz: hp,
            highpass_order: ord,
            ..Default::default()
        },
    )
    .unwrap();
    let vh =
        simulate_velocity(&f.model, &f.values, &val.u, val.ts, val.y[0], Some(&val.y)).unwrap();
    println!(
        "{:.2}s it {} {:?} est {:.3} val {:.3}",
        t0.elapsed().as_secs_f64(),
        f.iterations,
        f.termination,
        f.fit_velocity_percent,
        jointid::ident::validate::fit_percent(&vv[1..], &vh[1..]).unwrap()
    );
    for (p, t) in f.params.iter().zip(&truth) {
        println!(
            "  {:8} {:>12.5e} ± {:.2e}  truth {:>12.5e}  err {:+.2}%  {:+.1}σ",
            p.name,
            p.value,
            p.std,
            t,
            100.0 * (p.value / t - 1.0),
            (p.value - t) / p.std
        );
    }
}
