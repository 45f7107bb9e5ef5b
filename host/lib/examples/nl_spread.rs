use jointid::data::IdData;
use jointid::ident::nonlinear::*;
use jointid::model::effects::Effect;
use jointid::model::spec::Structure;
use jointid::sim::{simulate_excitation, SimConfig};
use jointid_core::excitation::ExcitationConfig;

fn main() {
    let name = std::env::args()
        .nth(1)
        .unwrap_or("nonlinear_stiffness".into());
    let runs: usize = std::env::args()
        .nth(2)
        .and_then(|v| v.parse().ok())
        .unwrap_or(10);
    let eff = Effect::default_by_name(&name).unwrap();
    let mut est_vals: Vec<Vec<f64>> = Vec::new();
    let mut stds: Vec<Vec<f64>> = Vec::new();
    let mut names = Vec::new();
    let mut truth = Vec::new();
    for seed in 0..runs as u64 {
        let cfg = SimConfig {
            effects: vec![eff],
            seed: 1000 + seed,
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
        let model = NlModel {
            structure: Structure::ThreeMass,
            r: p.r,
            effects: vec![eff],
            tau_c: cfg.controller.current_loop_tau,
            v_eps: 0.05,
            dz_eps: 1e-7,
            substeps: if name == "time_delay" { 2 } else { 1 },
        };
        truth = model.values(
            &[p.j_m, p.j_a1, p.j_a2, p.k_g, p.k_a, p.d_g, p.d_a, p.f_m],
            0.0,
            0.0,
        );
        let f = fit_output_error(&data, &model, &truth, &NlOptions::default()).unwrap();
        names = f.params.iter().map(|p| p.name).collect();
        est_vals.push(f.params.iter().map(|p| p.value).collect());
        stds.push(f.params.iter().map(|p| p.std).collect());
    }
    for (i, n) in names.iter().enumerate() {
        let v: Vec<f64> = est_vals.iter().map(|e| e[i]).collect();
        let m = v.iter().sum::<f64>() / runs as f64;
        let sd = (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (runs - 1) as f64).sqrt();
        let s = stds.iter().map(|e| e[i]).sum::<f64>() / runs as f64;
        println!(
            "{n:10} mean err {:+.3}% ({:+.2} spread)  spread {:.3e}  mean σ {:.3e}  σ/spread {:.2}",
            100.0 * (m / truth[i] - 1.0),
            (m - truth[i]) / sd,
            sd,
            s,
            s / sd
        );
    }
}
