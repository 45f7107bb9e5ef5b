//! Command-line tests of `jointid diagnose`: the simulator's joint with a hidden cubic
//! spring, diagnosed from its capture against a second run; the measured EMPS drive, whose
//! friction a rigid model lacks; and the refusals.

mod common;
use common::{jointid, json_of, shared, tmpdir};

fn simulate(dir: &std::path::Path, name: &str, seed: &str, exc_seed: &str) -> String {
    let out = dir.join(name);
    json_of(&jointid(&[
        "simulate",
        "--model",
        "three-mass",
        "--effect",
        "nonlinear_stiffness",
        "--seed",
        seed,
        "--excitation-seed",
        exc_seed,
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]));
    out.display().to_string()
}

/// `simulate --effect nonlinear_stiffness`, then `diagnose` with three candidates: the
/// cubic spring ranks first among the single effects, significant, with `k3` near the
/// simulator's value, and heads the best model.
#[test]
fn diagnose_finds_the_hidden_cubic_spring_of_a_simulated_capture() {
    let dir = tmpdir("cubic");
    let est = simulate(&dir, "est.jcap", "5", "7");
    let val = simulate(&dir, "val.jcap", "6", "8");
    let j = json_of(&jointid(&[
        "diagnose",
        &est,
        "--validation",
        &val,
        "--effects",
        "nonlinear_stiffness,time_delay,extra_mode",
        "--json",
    ]));
    // the best single; a pair with it may follow (the single's fit can stop at its
    // iteration limit, and a second effect then still gains)
    assert!(
        j["best"]
            .as_str()
            .unwrap()
            .starts_with("nonlinear_stiffness"),
        "{j}"
    );
    assert_eq!(j["effects"][0]["name"], "nonlinear_stiffness");
    assert_eq!(j["effects"][0]["significant"], true);
    let k3 = j["effects"][0]["parameters"]["k3"]["value"]
        .as_f64()
        .unwrap();
    assert!((k3 / 3.0e13 - 1.0).abs() < 0.2, "k3 = {k3:e}");
    assert!(j["fit_augmented_val"].as_f64().unwrap() > j["fit_nominal_val"].as_f64().unwrap());
    assert!(j["where"]["bands_hz"].as_array().unwrap().len() == 5);
    assert!(j["metric"]
        .as_str()
        .unwrap()
        .contains("band-passed motor-velocity FIT"));
}

/// EMPS (measured, `../shared/data/emps`): the nominal is the rigid model with viscous
/// friction; Coulomb friction is named, significant, closes most of the gap, and its level
/// is near the published 20.39 N (Janot et al. 2019, IDIM-LS). The gearbox effects are no
/// candidates of a rigid model and are said to be left out.
#[test]
fn diagnose_names_coulomb_friction_on_the_measured_emps_drive() {
    let j = json_of(&jointid(&[
        "diagnose",
        &shared("data/emps/emps_train_DATA_EMPS.csv"),
        "--validation",
        &shared("data/emps/emps_test_DATA_EMPS_PULSES.csv"),
        "--time",
        "t_s",
        "--input",
        "force_N",
        "--output",
        "qm_m",
        "--model",
        "rigid",
        "--gear-ratio",
        "1",
        "--effects",
        "coulomb_friction,time_delay,backlash",
        "--json",
    ]));
    assert!(
        j["best"].as_str().unwrap().starts_with("coulomb_friction"),
        "{j}"
    );
    assert_eq!(j["effects"][0]["name"], "coulomb_friction");
    assert_eq!(j["effects"][0]["significant"], true);
    let fc = j["effects"][0]["parameters"]["fc"]["value"]
        .as_f64()
        .unwrap();
    assert!((fc / 20.39 - 1.0).abs() < 0.10, "F_c = {fc}");
    let share = j["gap_closed_share"].as_f64().unwrap();
    assert!(share > 0.6, "closed share {share}");
    let notes = j["warnings"].to_string();
    assert!(
        notes.contains("backlash: not candidates of a rigid model"),
        "{notes}"
    );
}

#[test]
fn diagnose_refuses_an_unknown_effect_and_a_missing_file_naming_them() {
    let dir = tmpdir("refuse");
    let missing = dir.join("nope.csv");
    let out = jointid(&[
        "diagnose",
        missing.to_str().unwrap(),
        "--validation",
        missing.to_str().unwrap(),
        "--effects",
        "warp_drive",
    ]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--effects") && err.contains("warp_drive"),
        "{err}"
    );
    let out = jointid(&[
        "diagnose",
        missing.to_str().unwrap(),
        "--validation",
        missing.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("nope.csv"), "{err}");
}
