use jointid::data::IdData;
use jointid::ident::nonlinear::*;
use jointid::model::effects::Effect;
use jointid::model::spec::Structure;
use jointid::sim::{simulate_excitation, SimConfig};
use jointid_core::excitation::ExcitationConfig;
use std::time::Instant;

fn main() {
    let name = std::env::args()
        .nth(1)
        .unwrap_or("nonlinear_stiffness".into());
    let effects: Vec<Effect> = if name == "none" {
        vec![]
    } else {
        vec![Effect::default_by_name(&name).unwrap()]
    };
    let cfg = SimConfig {
        effects: effects.clone(),
        seed: 3,
        ..SimConfig::default()
    };
    let out = simulate_excitation(&cfg, &ExcitationConfig::paper_default()).unwrap();
    let data = IdData {
        ts: out.sample_interval_s,
        u: out.u,
        y: out.theta_m,
        r: None,
    };
    let p = cfg.plant.params;
    let exc = ExcitationConfig::paper_default();
    let ds = jointid::data::Dataset {
        name: "sim".into(),
        data: data.clone(),
        t0: 0.0,
        excitation: Some(exc),
        meta: Default::default(),
    };
    let t1 = Instant::now();
    let (lin, tau_c) = linear_start(&ds, Structure::ThreeMass, p.r).unwrap();
    println!(
        "FD linear start {:.2}s tau_c {tau_c:.3e} {:?}",
        t1.elapsed().as_secs_f64(),
        lin
    );
    let req = NlRequest {
        structure: Structure::ThreeMass,
        r: p.r,
        effects,
        tau_c,
        start: None,
        linear: Some(lin),
        options: NlOptions::default(),
    };
    let t0 = Instant::now();
    let r = identify(&data, &req).unwrap();
    println!(
        "{:.2}s it {} {:?} warnings {:?}",
        t0.elapsed().as_secs_f64(),
        r.fit.iterations,
        r.fit.termination,
        r.warnings
    );
    for s in &r.steps {
        println!("  {}: {} {:?}", s.name, s.detail, s.values);
    }
    let truth = [p.j_m, p.j_a1, p.j_a2, p.k_g, p.k_a, p.d_g, p.d_a, p.f_m];
    for (i, p) in r.fit.params.iter().enumerate() {
        if i < 8 {
            print!(
                " {}={:.4e} ({:+.1}%)",
                p.name,
                p.value,
                100.0 * (p.value / truth[i] - 1.0)
            );
        } else {
            print!(" {}={:.4e}", p.name, p.value);
        }
    }
    println!();
}
