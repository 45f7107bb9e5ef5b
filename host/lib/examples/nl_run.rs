use jointid::data::{load_csv, ColumnMap};
use jointid::ident::nonlinear::*;
use jointid::model::effects::Effect;
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
    let req = NlRequest {
        structure: Structure::TwoMass,
        r: 1.0 / 118.0,
        effects: vec![
            Effect::default_by_name("nonlinear_stiffness").unwrap(),
            Effect::default_by_name("coulomb_friction").unwrap(),
        ],
        tau_c: 0.0,
        start: None,
        linear: None,
        options: NlOptions::default(),
    };
    let t0 = Instant::now();
    let r = identify(&est, &req).unwrap();
    println!(
        "{:.2}s warnings {:?}",
        t0.elapsed().as_secs_f64(),
        r.warnings
    );
    for p in &r.fit.params {
        print!(" {}={:.4e}±{:.1e}", p.name, p.value, p.std);
    }
    println!();
    let v = validate(&r.fit, &val, &req.options).unwrap();
    println!("{v:?}");
    // truth through the same validation
    let mut t = r.fit.clone();
    let m = t.model.clone();
    let truth = m.values(&[1e-3, 14.6, 1.3e5, 80.0, 2e-3], 0.0, 0.0);
    let (mut tm, tp) = m.with_values(&truth);
    if let Effect::NonlinearStiffness(s) = &mut tm.effects[0] {
        s.k3 = 1.6e11
    }
    if let Effect::CoulombFriction(c) = &mut tm.effects[1] {
        c.fc = 0.1;
        c.fs = 0.1
    }
    t.values = tm.values(&tp, 0.0, 0.0);
    t.model = tm;
    t.plant = tp;
    for p in &mut t.params {
        if p.name == "offset" {
            p.value = 0.0
        }
    }
    println!("truth {:?}", validate(&t, &val, &req.options).unwrap());
}
