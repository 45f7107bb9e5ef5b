use jointid::data::{load_csv, ColumnMap};
use jointid::ident::nonlinear::*;
use jointid::ident::validate::fit_percent;
use jointid::model::effects::{CoulombFriction, Effect, NonlinearStiffness};
use jointid::model::spec::Structure;
use std::path::Path;
use std::time::Instant;

fn main() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/seed001-two-mass");
    let est = load_csv(&dir.join("est.csv"), &ColumnMap::capture())
        .unwrap()
        .data;
    let val = load_csv(&dir.join("val.csv"), &ColumnMap::capture())
        .unwrap()
        .data;
    let v_eps: f64 = std::env::args()
        .nth(1)
        .map(|s| s.parse().unwrap())
        .unwrap_or(0.05);
    let sub: usize = std::env::args()
        .nth(2)
        .map(|s| s.parse().unwrap())
        .unwrap_or(1);
    let model = NlModel {
        structure: Structure::TwoMass,
        r: 1.0 / 118.0,
        effects: vec![
            Effect::NonlinearStiffness(NonlinearStiffness { k3: 1.6e11 }),
            Effect::CoulombFriction(CoulombFriction {
                fc: 0.1,
                fs: 0.1,
                ..Default::default()
            }),
        ],
        tau_c: 0.0,
        v_eps,
        dz_eps: 1e-6,
        substeps: sub,
    };
    // J_m, J_a1, k_g, d_g, f_m
    let truth = model.values(&[1e-3, 14.6, 1.3e5, 80.0, 2e-3], 0.0, 0.0);
    let vv = interval_velocity(&val.y, val.ts);
    let vh = simulate_velocity(&model, &truth, &val.u, val.ts, val.y[0], Some(&val.y)).unwrap();
    println!(
        "truth val FIT (smooth law v_eps={v_eps}, sub {sub}): {:.3}",
        fit_percent(&vv[1..], &vh[1..]).unwrap()
    );
    for fc in [1.0, 2.0, 3.0, 5.0, 8.0] {
        let r = jointid::ident::grey_box::rigid_idim(
            &est,
            &jointid::ident::grey_box::IdimOptions {
                cutoff_hz: fc,
                coulomb: true,
                ..Default::default()
            },
        )
        .unwrap();
        println!(
            "cutoff {fc}: {:?} err {:.1}",
            r.params
                .iter()
                .map(|p| (p.name.clone(), p.value))
                .collect::<Vec<_>>(),
            r.rel_error_percent
        );
    }
    let t0 = Instant::now();
    let st = automatic_start(&est, &model, None).unwrap();
    println!("auto start {:.2}s", t0.elapsed().as_secs_f64());
    for step in &st.steps {
        println!("  {}: {:?} ({})", step.name, step.values, step.detail);
    }
    let f = fit_output_error(&est, &st.model, &st.values, &NlOptions::default()).unwrap();
    let vh =
        simulate_velocity(&f.model, &f.values, &val.u, val.ts, val.y[0], Some(&val.y)).unwrap();
    print!(
        "auto: {:.2}s total it {} {:?} val {:.3} |",
        t0.elapsed().as_secs_f64(),
        f.iterations,
        f.termination,
        fit_percent(&vv[1..], &vh[1..]).unwrap()
    );
    for p in &f.params {
        print!(" {}={:.4e}±{:.1e}", p.name, p.value, p.std);
    }
    println!();
    if std::env::var("AUTO_ONLY").is_ok() {
        return;
    }
    let mut s: u64 = 12345;
    for run in 0..10 {
        let start: Vec<f64> = truth
            .iter()
            .enumerate()
            .map(|(i, &t)| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let u = (s >> 11) as f64 / (1u64 << 53) as f64;
                if i >= 6 {
                    t
                } else {
                    t * (0.7 + 0.6 * u)
                }
            })
            .collect();
        let t0 = Instant::now();
        let f = fit_output_error(&est, &model, &start, &NlOptions::default()).unwrap();
        let dt = t0.elapsed().as_secs_f64();
        let vh =
            simulate_velocity(&f.model, &f.values, &val.u, val.ts, val.y[0], Some(&val.y)).unwrap();
        let vfit = fit_percent(&vv[1..], &vh[1..]).unwrap();
        print!(
            "run {run}: {dt:.2}s it {} {:?} est {:.3} val {vfit:.3} |",
            f.iterations, f.termination, f.fit_velocity_percent
        );
        for p in &f.params {
            print!(" {}={:.4e}±{:.1e}", p.name, p.value, p.std);
        }
        println!();
    }
}
#[allow(dead_code)]
fn auto() {}
