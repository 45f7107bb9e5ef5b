use jointid::data::{load_csv, ColumnMap};
use jointid::ident::nonlinear::*;
use jointid::model::effects::Effect;
use jointid::model::spec::Structure;
use std::path::Path;
use std::time::Instant;

fn main() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/emps");
    let map = ColumnMap {
        time: "t_s".into(),
        input: "force_N".into(),
        output: "qm_m".into(),
        reference: None,
    };
    let est = load_csv(&dir.join("emps_train_DATA_EMPS.csv"), &map)
        .unwrap()
        .data;
    let val = load_csv(&dir.join("emps_test_DATA_EMPS_PULSES.csv"), &map)
        .unwrap()
        .data;
    let hp: f64 = std::env::var("HP")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0.0);
    let opts = NlOptions {
        highpass_hz: hp,
        ..NlOptions::default()
    };
    let req = NlRequest {
        structure: Structure::Rigid,
        r: 1.0,
        effects: vec![Effect::default_by_name("coulomb_friction").unwrap()],
        tau_c: 0.0,
        start: None,
        linear: None,
        options: opts.clone(),
    };
    let t0 = Instant::now();
    let mut r = identify(&est, &req).unwrap();
    if let Ok(ve) = std::env::var("VEPS") {
        let mut m = r.fit.model.clone();
        m.v_eps = ve.parse().unwrap();
        m.substeps = std::env::var("SUBS")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(1);
        r.fit = fit_output_error(&est, &m, &r.fit.values, &opts).unwrap();
        println!("v_eps {}", m.v_eps);
    }
    println!(
        "{:.2}s it {} {:?} warnings {:?}",
        t0.elapsed().as_secs_f64(),
        r.fit.iterations,
        r.fit.termination,
        r.warnings
    );
    for s in &r.steps {
        println!("  {}: {:?}", s.name, s.values);
    }
    for p in &r.fit.params {
        print!(" {}={:.4e}±{:.1e}", p.name, p.value, p.std);
    }
    println!();
    println!("{:?}", validate(&r.fit, &val, &opts).unwrap());
}
