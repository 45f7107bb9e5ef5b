//! Command-line tests of `jointid fit`, `validate` (model files) and `demo`,
//! run through the built binary so exit codes and stderr are checked too.
//!
//! Data: the simulated three-mass joint in its position loop (jointid::sim),
//! special odd multisine for estimation, band-limited noise for validation,
//! written as capture CSVs with their excitation comments; and measured data
//! from `../shared/data`: the EMPS drive (rigid model with Coulomb friction
//! against the published IDIM-LS values) and the DaISy robot arm (black box,
//! FIT on the held-out half).

use std::path::{Path, PathBuf};

use jointid::data::{write_capture_csv, Dataset};
use jointid::scenario::paper::{estimation_excitation, validation_excitation};
use jointid::sim::{self, Disturbance, SimConfig};
use jointid_core::excitation::ExcitationConfig;

mod common;
use common::{jointid, json_of, shared, tmpdir};

fn write_run(path: &Path, exc: &ExcitationConfig, seed: u64) {
    let mut cfg = SimConfig {
        seed,
        ..SimConfig::default()
    };
    cfg.sensors.disturbance = Disturbance::none();
    cfg.sensors.u_noise_std = 0.0;
    let out = sim::simulate_excitation(&cfg, exc).unwrap();
    let ds = Dataset {
        name: path.display().to_string(),
        data: out.to_id_data(),
        t0: 0.0,
        excitation: Some(*exc),
        meta: Default::default(),
    };
    let mut f = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    write_capture_csv(&mut f, &ds).unwrap();
}

/// estimation and validation capture CSVs (3 multisine periods; 7.5 s noise)
fn data(dir: &Path) -> (PathBuf, PathBuf) {
    let est_exc = ExcitationConfig {
        periods: 3,
        ..estimation_excitation(5)
    };
    let val_exc = validation_excitation(&est_exc);
    let (e, v) = (dir.join("est.csv"), dir.join("val.csv"));
    write_run(&e, &est_exc, 1);
    write_run(&v, &val_exc, 2);
    (e, v)
}

#[test]
fn fit_json_has_fields_and_validate_reproduces_saved_model_fit() {
    let dir = tmpdir("roundtrip");
    let (est, val) = data(&dir);
    let model = dir.join("m.json");
    let plots = dir.join("plots");
    let o = jointid(&[
        "fit",
        est.to_str().unwrap(),
        "--model",
        "three-mass",
        "--decimate",
        "10",
        "--validation",
        val.to_str().unwrap(),
        "--save",
        model.to_str().unwrap(),
        "--plot",
        plots.to_str().unwrap(),
        "--json",
    ]);
    let j = json_of(&o);
    for key in [
        "model",
        "parameters",
        "fit_estimation",
        "fit_validation",
        "elapsed_s",
        "resonances_hz",
        "antiresonances_hz",
        "residual_tests",
    ] {
        assert!(!j[key].is_null(), "missing {key}: {j}");
    }
    for name in ["J_m", "J_a1", "J_a2", "k_g", "k_a", "d_g", "d_a", "f_m"] {
        let p = &j["parameters"][name];
        assert!(p["value"].as_f64().unwrap() > 0.0, "{name}: {p}");
        assert!(p["std"].as_f64().unwrap() >= 0.0, "{name}: {p}");
        assert!(!p["unit"].as_str().unwrap().is_empty(), "{name}: {p}");
    }
    let fv = j["fit_validation"].as_f64().unwrap();
    assert!(fv > 80.0, "validation FIT {fv}");
    assert!(j["residual_tests"]["estimation"]["whiteness"]["bound"].is_number());
    assert!(plots.join("bode.svg").exists());
    // the physical model runs at the capture rate and is compared after the
    // same decimation (model format 2)
    let saved: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&model).unwrap()).unwrap();
    assert_eq!(saved["format"], "jointid-model/4");
    // format 4 stores the model's description, whose family names the model
    assert_eq!(saved["spec"]["family"], saved["model"], "{saved}");
    assert_eq!(saved["decimate_output"], 10);
    assert!(
        (saved["ts"].as_f64().unwrap() - 5e-4).abs() < 1e-12,
        "{saved}"
    );

    let o = jointid(&[
        "validate",
        model.to_str().unwrap(),
        val.to_str().unwrap(),
        "--json",
    ]);
    let v = json_of(&o);
    let f2 = v["fit"].as_f64().unwrap();
    assert!((f2 - fv).abs() < 1e-9, "validate {f2} vs fit {fv}");

    // an unmet --require-fit exits 1 (as does a diverging model, below)
    let o = jointid(&[
        "validate",
        model.to_str().unwrap(),
        val.to_str().unwrap(),
        "--require-fit",
        "99.999",
    ]);
    assert_eq!(
        o.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn fit_black_box_text_output_names_fit_and_resonances() {
    let dir = tmpdir("text");
    let (est, val) = data(&dir);
    let o = jointid(&[
        "fit",
        est.to_str().unwrap(),
        "--model",
        "black-box:8",
        "--decimate",
        "10",
        "--validation",
        val.to_str().unwrap(),
    ]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(text.contains("FIT (toolbox compare, NRMSE) [%]"), "{text}");
    assert!(text.contains("validation:"), "{text}");
    assert!(text.contains("resonances [Hz]: 1"), "{text}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_input_exits_2_with_one_line_naming_the_file() {
    let dir = tmpdir("bad");
    let missing = dir.join("missing.csv");
    let garbage = dir.join("garbage.csv");
    std::fs::write(&garbage, "t,theta_ref,u,theta_m\n0,0,x,0\n").unwrap();
    let model = dir.join("not-a-model.json");
    std::fs::write(&model, "{\"hello\": 1}").unwrap();
    for (args, file) in [
        (
            vec!["fit", missing.to_str().unwrap(), "--model", "rigid"],
            "missing.csv",
        ),
        (
            vec!["fit", garbage.to_str().unwrap(), "--model", "rigid"],
            "garbage.csv",
        ),
        (
            vec![
                "validate",
                model.to_str().unwrap(),
                garbage.to_str().unwrap(),
            ],
            "not-a-model.json",
        ),
    ] {
        let o = jointid(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
        assert!(err.contains(file), "{args:?}: {err}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue item 7: a model whose simulation overflows (A = 1e308) gave FIT NaN, both
/// residual tests "pass", `fit_ok: true` and exit 0.
#[test]
fn validate_of_a_diverging_model_fails_both_tests_and_exits_1() {
    let dir = tmpdir("diverge");
    let data = dir.join("run.csv");
    std::fs::write(&data, jointid::test_support::capture_csv(0.0, 4)).unwrap();
    let model = dir.join("m.json");
    std::fs::write(
        &model,
        r#"{"format":"jointid-model/2","model":"black-box:1","method":"by hand","output":"angle",
            "ts":0.001,"prep":{"decimate":1,"detrend":"none"},"a":[[1e308]],"b":[1.0],"c":[1.0],
            "d":0.0,"parameters":{},"friction":null,"decimate_output":1,"fit_estimation":0.0,
            "source":"by hand"}"#,
    )
    .unwrap();
    let o = jointid(&[
        "validate",
        model.to_str().unwrap(),
        data.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(
        o.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["fit_ok"], false, "{j}");
    assert!(j["fit"].is_null(), "NaN FIT: {j}");
    for t in ["whiteness", "independence"] {
        let t = &j["residual_tests"][t];
        assert_eq!(t["pass"], false, "{t}");
        assert!(t["non_finite"].as_u64().unwrap() > 0, "{t}");
        assert_eq!(t["outside"], t["lags"].as_array().unwrap().len(), "{t}");
    }
    assert_eq!(j["residual_tests"]["pass"], false);
    let o = jointid(&["validate", model.to_str().unwrap(), data.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(!text.contains(" pass"), "{text}");
    assert_eq!(text.matches("FAIL (").count(), 2, "{text}");
    assert!(
        text.contains("residual samples are NaN or infinite"),
        "{text}"
    );
    assert!(
        text.contains("not ok: the model's simulated output is not finite"),
        "{text}"
    );
    // the same model as if fitted in the frequency domain: an unstable model has no
    // periodic steady state, so that FIT is NaN too (it printed 0.00)
    let text = std::fs::read_to_string(&model).unwrap().replacen(
        "\"source\"",
        &format!(
            "\"fit_name\":{},\"source\"",
            serde_json::to_string(jointid::ident::sml::PERIODIC_FIT_NAME).unwrap()
        ),
        1,
    );
    std::fs::write(&model, text).unwrap();
    let o = jointid(&[
        "validate",
        model.to_str().unwrap(),
        data.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(o.status.code(), Some(1));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(
        j["fit_name"].as_str(),
        Some(jointid::ident::sml::PERIODIC_FIT_NAME),
        "{j}"
    );
    assert!(j["fit"].is_null(), "NaN periodic FIT: {j}");
    assert_eq!(j["fit_ok"], false, "{j}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn demo_writes_captures_plots_and_the_table() {
    let dir = tmpdir("demo");
    let o = jointid(&["demo", "--out", dir.to_str().unwrap(), "--json"]);
    let j = json_of(&o);
    for f in [
        "estimation.jcap",
        "validation.jcap",
        "spectrum.svg",
        "frf.svg",
        "bode_3mass.svg",
        "bode_4mass.svg",
    ] {
        assert!(dir.join(f).exists(), "{f} missing");
    }
    // the demo's captures load in every analysis command
    let est = dir.join("estimation.jcap");
    let f = json_of(&jointid(&[
        "fit",
        est.to_str().unwrap(),
        "--model",
        "black-box:6",
        "--decimate",
        "10",
        "--json",
    ]));
    assert!(f["fit_estimation"].as_f64().unwrap() > 50.0, "{f}");
    let rows = j["table"]["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 3);
    for r in rows {
        assert!(r["fit_validation"].as_f64().unwrap() > 50.0, "{r}");
    }
    // the simulated joint is linear; only the encoder's quantiser is a (static,
    // odd) nonlinearity, statistically visible but far below seed 000's
    // "about a factor 1/100" (−40 dB) of the real robot
    for key in ["odd_vs_excited_db", "even_vs_excited_db"] {
        for signal in ["u", "theta_m"] {
            let v = j[key][signal].as_f64().unwrap();
            assert!(v < -40.0, "{key}: {}", j[key]);
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

// EMPS through `jointid fit --model rigid --friction coulomb --json`: M, Fv,
// Fc within 3 % of the published IDIM-LS values (Janot et al. 2019).
#[test]
fn emps_rigid_coulomb_fit_via_cli_matches_published_within_3_percent() {
    let path = shared("data/emps/emps_train_DATA_EMPS.csv");
    let j = json_of(&jointid(&[
        "fit",
        &path,
        "--time",
        "t_s",
        "--input",
        "force_N",
        "--output",
        "qm_m",
        "--model",
        "rigid",
        "--friction",
        "coulomb",
        "--linear-axis",
        "--json",
    ]));
    eprintln!(
        "{}",
        serde_json::to_string_pretty(&j["parameters"]).unwrap()
    );
    for (name, published) in [("J", 95.1089), ("Fv", 203.5034), ("Fc", 20.3935)] {
        let v = j["parameters"][name]["value"].as_f64().unwrap();
        assert!(
            (v - published).abs() <= 0.03 * published,
            "{name}: {v} vs published {published}"
        );
    }
    assert_eq!(j["parameters"]["J"]["unit"], "kg");
    assert_eq!(j["parameters"]["Fv"]["unit"], "N·s/m");
    assert!(j["fit_estimation"].is_number());
}

// DaISy 96-009 through `jointid fit --model black-box:4 --estimation-fraction
// 0.5`: FIT on the second half reported. DaISy publishes no figure; the
// bound is a regression guard 8 points under the 88.4 % measured when the
// test was written (PO-MOESP start kept over PBSID on these open-loop data).
#[test]
fn daisy_order_4_fit_on_first_half_reports_second_half_fit_via_cli() {
    let path = shared("data/daisy-robot-arm/robot_arm.csv");
    let j = json_of(&jointid(&[
        "fit",
        &path,
        "--time",
        "t_assumed_s",
        "--input",
        "u_reaction_torque",
        "--output",
        "y_arm_acceleration",
        "--model",
        "black-box:4",
        "--estimation-fraction",
        "0.5",
        "--json",
    ]));
    let fe = j["fit_estimation"].as_f64().unwrap();
    let fv = j["fit_validation"].as_f64().unwrap();
    eprintln!("DaISy robot arm, order 4: FIT estimation {fe:.1} %, validation {fv:.1} %");
    assert_eq!(j["samples"].as_u64(), Some(512));
    assert!(fv > 80.0 && fv < 100.0, "validation FIT {fv}");
}

/// Issue 10, deliverable 2: `--domain time` on band-limited noise with the default sensors
/// (slow torque disturbance on). The angle's output error used to follow the drift (seed 1:
/// `k_g` 4,363 against 127,500); the fit checked against the record's Welch FRF now gives
/// the seven identifiable parameters within 3 % and both modes within 0.5 %.
#[test]
fn three_mass_time_domain_fit_on_noise_does_not_follow_the_drift() {
    let dir = tmpdir("td-noise");
    let est = dir.join("n.jcap");
    let o = jointid(&[
        "simulate",
        "--model",
        "three-mass",
        "--excitation",
        "noise",
        "--seed",
        "1",
        "--out",
        est.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let j = json_of(&jointid(&[
        "fit",
        est.to_str().unwrap(),
        "--model",
        "three-mass",
        "--domain",
        "time",
        "--json",
    ]));
    for (name, t) in [
        ("J_m", 1.0e-3),
        ("J_a1", 11.66),
        ("J_a2", 0.627),
        ("k_g", 1.275e5),
        ("k_a", 7.26e3),
        ("d_g", 80.0),
        ("d_a", 4.0),
    ] {
        let v = j["parameters"][name]["value"].as_f64().unwrap();
        assert!((v - t).abs() < 0.03 * t, "{name} {v} (truth {t}): {j}");
    }
    let modes: Vec<f64> = j["resonances_hz"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(modes.len(), 2, "{modes:?}");
    for (m, t) in modes.iter().zip([17.01, 23.00]) {
        assert!((m / t - 1.0).abs() < 0.005, "mode {m} Hz (truth {t} Hz)");
    }
}

/// The reproduction of issue 10: `jointid simulate` with its default sensors
/// (quantised encoder, white noise, slow torque disturbance, 0.5 ms current
/// loop), then `jointid fit --model three-mass` as the README writes it.
#[test]
fn three_mass_fit_on_default_simulation_is_right_in_the_frequency_domain() {
    let dir = tmpdir("fd");
    let (est, val) = (dir.join("lin.jcap"), dir.join("val.jcap"));
    for (path, seed) in [(&est, "1"), (&val, "2")] {
        let o = jointid(&[
            "simulate",
            "--model",
            "three-mass",
            "--seed",
            seed,
            "--out",
            path.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let model = dir.join("m3.json");
    let o = jointid(&[
        "fit",
        est.to_str().unwrap(),
        "--model",
        "three-mass",
        "--validation",
        val.to_str().unwrap(),
        "--save",
        model.to_str().unwrap(),
        "--strict",
        "--json",
    ]);
    let j = json_of(&o);
    // `validate` judges the saved model by the same FIT on the same file
    let v = json_of(&jointid(&[
        "validate",
        model.to_str().unwrap(),
        val.to_str().unwrap(),
        "--json",
    ]));
    assert_eq!(v["fit_name"], j["fit_name"]);
    let (a, b) = (
        v["fit"].as_f64().unwrap(),
        j["fit_validation"].as_f64().unwrap(),
    );
    assert!((a - b).abs() < 1e-6, "validate {a} vs fit {b}");
    let truth = [
        ("J_m", 1.0e-3),
        ("J_a1", 11.66),
        ("J_a2", 0.627),
        ("k_g", 1.275e5),
        ("k_a", 7.26e3),
        ("d_g", 80.0),
        ("d_a", 4.0),
    ];
    for (name, t) in truth {
        let v = j["parameters"][name]["value"].as_f64().unwrap();
        assert!((v - t).abs() < 0.03 * t, "{name} {v} (truth {t}): {j}");
    }
    let tau = j["parameters"]["tau_c"]["value"].as_f64().unwrap();
    assert!((tau - 5e-4).abs() < 5e-5, "current-loop lag {tau} s");
    assert!(j["fit_name"].as_str().unwrap().contains("period-averaged"));
    assert!(j["fit_validation"].as_f64().unwrap() > 95.0, "{j}");
    assert_eq!(j["warnings"].as_array().unwrap().len(), 0, "{j}");
    assert!(j["method"].as_str().unwrap().contains("frequency domain"));
    let fit_three_mass = j["fit_validation"].as_f64().unwrap();

    // the wrong structure is flagged, and --strict turns that into exit 1
    let o = jointid(&[
        "fit",
        est.to_str().unwrap(),
        "--model",
        "two-mass",
        "--strict",
        "--json",
    ]);
    assert_eq!(o.status.code(), Some(1));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let w = j["warnings"].as_array().unwrap();
    assert!(
        w.iter().any(|w| w
            .as_str()
            .unwrap()
            .contains("times what the measurement noise explains")),
        "{j}"
    );

    // the 11th-order black box on the undecimated 2 kHz record: fitted to the
    // FRF, it validates within a point of the physical model
    let o = jointid(&[
        "fit",
        est.to_str().unwrap(),
        "--model",
        "black-box:11",
        "--validation",
        val.to_str().unwrap(),
        "--json",
    ]);
    let b = json_of(&o);
    assert!(b["method"].as_str().unwrap().contains("frequency domain"));
    let fb = b["fit_validation"].as_f64().unwrap();
    assert!(fb > fit_three_mass - 1.0, "{fb} vs {fit_three_mass}: {b}");
    // Coulomb friction is nonlinear: no frequency-domain fit
    let o = jointid(&[
        "fit",
        est.to_str().unwrap(),
        "--model",
        "rigid",
        "--friction",
        "coulomb",
        "--domain",
        "frequency",
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("time domain"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue item 11: `fit` and `validate` check `--save`, `--lags`, the columns and the
/// validation file's sample rate before the work (they failed after 17 s of fitting).
#[test]
fn fit_and_validate_check_their_arguments_before_fitting() {
    let dir = tmpdir("prechecks");
    let run = dir.join("run.csv"); // 1 kHz
    std::fs::write(&run, jointid::test_support::capture_csv(0.0, 4)).unwrap();
    let other = dir.join("other.csv"); // 2 kHz
    let o = jointid(&[
        "simulate",
        "--periods",
        "3",
        "--out",
        other.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r = run.to_str().unwrap();
    let missing_dir = dir.join("no-such-dir").join("m.json");
    let cases: Vec<(Vec<&str>, String)> = vec![
        (
            vec!["--save", missing_dir.to_str().unwrap()],
            format!(
                "{}: directory {} does not exist",
                missing_dir.display(),
                dir.join("no-such-dir").display()
            ),
        ),
        (
            vec!["--save", dir.to_str().unwrap()],
            format!("{}: is a directory, not a file", dir.display()),
        ),
        (
            vec!["--validation", other.to_str().unwrap()],
            format!(
                "--validation {}: sampled at 2000 Hz, {r} at 1000 Hz",
                other.display()
            ),
        ),
        (
            vec!["--lags", "5000"],
            "--lags 5000: the residual tests on one period of".to_string(),
        ),
        (
            vec!["--domain", "time", "--lags", "5000"],
            format!("--lags 5000: the residual tests on {r} have 3600 samples, they need more than 2 × 5000 = 10000"),
        ),
        (
            vec!["--time", "t", "--input", "u", "--output", "u"],
            "--input and --output both name column `u`: one column cannot be two signals"
                .to_string(),
        ),
    ];
    for (extra, msg) in cases {
        let mut args = vec!["fit", r, "--model", "two-mass"];
        args.extend_from_slice(&extra);
        let t0 = std::time::Instant::now();
        let o = jointid(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        assert!(err.contains(&msg), "{args:?}: `{msg}` not in {err}");
        // refused before the fit: well under the fit's time
        assert!(t0.elapsed().as_secs_f64() < 5.0, "{args:?}");
    }
    let o = jointid(&["fit", r, "--model", "two-mass", "--lags", "0"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("`0` is not a number of lags ≥ 1"));

    // validate: the model's rate, the lags, the columns
    let model = dir.join("m.json");
    let o = jointid(&[
        "fit",
        r,
        "--model",
        "black-box:2",
        "--domain",
        "time",
        "--save",
        model.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let m = model.to_str().unwrap();
    for (args, msg) in [
        (
            vec!["validate", m, other.to_str().unwrap()],
            format!(
                "{}: sampled at 2000 Hz, the model {m} was fitted on data at 1000 Hz",
                other.display()
            ),
        ),
        (
            vec!["validate", m, r, "--lags", "5000"],
            format!("--lags 5000: the residual tests on {r} have 3600 samples"),
        ),
        (
            vec![
                "validate", m, r, "--time", "t", "--input", "t", "--output", "theta_m",
            ],
            "--time and --input both name column `t`".to_string(),
        ),
    ] {
        let o = jointid(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(&msg), "{args:?}: `{msg}` not in {err}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--domain time` on the simulator's default joint and sensors under noise excitation
/// (issue 10): the model fitted on the motor velocity reports the velocity FIT, with the
/// angle's toolbox FIT (which the drift dominates) beside it, and `validate` on the saved
/// model reports the same figures.
#[test]
fn time_domain_fit_on_the_velocity_reports_the_velocity_fit() {
    let dir = tmpdir("velocity_fit");
    let (est, val, model) = (dir.join("n1.jcap"), dir.join("n2.jcap"), dir.join("m.json"));
    for (seed, path) in [("1", &est), ("2", &val)] {
        let o = jointid(&[
            "simulate",
            "--model",
            "three-mass",
            "--excitation",
            "noise",
            "--seed",
            seed,
            "--out",
            path.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{o:?}");
    }
    let j = json_of(&jointid(&[
        "fit",
        est.to_str().unwrap(),
        "--model",
        "three-mass",
        "--domain",
        "time",
        "--validation",
        val.to_str().unwrap(),
        "--save",
        model.to_str().unwrap(),
        "--plot",
        dir.join("plots").to_str().unwrap(),
        "--json",
    ]));
    assert_eq!(j["fit_metric"], "velocity", "{j}");
    assert!(j["fit_name"].as_str().unwrap().starts_with("velocity FIT"));
    let (e, v) = (
        j["fit_estimation"].as_f64().unwrap(),
        j["fit_validation"].as_f64().unwrap(),
    );
    assert!(e > 75.0 && v > 75.0, "velocity FIT {e} / {v}");
    // compare.svg draws the headline FIT's signals: the velocities, under that FIT
    let compare = std::fs::read_to_string(dir.join("plots/compare.svg")).unwrap();
    for fit in [e, v] {
        let text = format!("three-mass: velocity FIT {fit:.2} %");
        assert!(compare.contains(&text), "{text} not in compare.svg");
    }
    assert!(compare.contains("motor velocity [rad/s]"));
    assert!(j["fit_toolbox_validation"].as_f64().unwrap() < 0.0, "{j}");
    let k_g = j["parameters"]["k_g"]["value"].as_f64().unwrap();
    assert!((k_g / 1.275e5 - 1.0).abs() < 0.03, "k_g {k_g}");
    let w = json_of(&jointid(&[
        "validate",
        model.to_str().unwrap(),
        val.to_str().unwrap(),
        "--json",
    ]));
    assert_eq!(w["fit_name"], j["fit_name"]);
    assert_eq!(w["fit_metric"], "velocity");
    let a = w["fit"].as_f64().unwrap();
    assert!((a - v).abs() < 1e-6, "validate {a} vs fit {v}");
    let t = w["fit_toolbox"].as_f64().unwrap();
    let tj = j["fit_toolbox_validation"].as_f64().unwrap();
    assert!((t - tj).abs() < 1e-6, "validate toolbox {t} vs fit {tj}");
}

/// `svg` is a whole SVG document that rsvg-convert renders (when it is installed)
fn assert_renders(path: &Path) {
    let text = std::fs::read_to_string(path).unwrap();
    assert!(
        text.starts_with("<svg") && text.trim_end().ends_with("</svg>"),
        "{}",
        path.display()
    );
    if let Ok(o) = std::process::Command::new("rsvg-convert")
        .arg("-o")
        .arg(path.with_extension("png"))
        .arg(path)
        .output()
    {
        assert!(
            o.status.success(),
            "rsvg-convert {}: {}",
            path.display(),
            String::from_utf8_lossy(&o.stderr)
        );
    }
}

// The toolbox's views on the EMPS drive (a linear axis: force [N] -> position [m]):
// `fit --plot` writes compare, resid, pzmap and step beside bode.svg, with the FITs it
// printed in the compare legend, the units of the data on the axes and the residual tests'
// bands; `validate --plot` writes the same views for the model on the pulses record.
#[test]
fn fit_and_validate_plot_the_toolbox_views_in_the_datas_units() {
    let train = shared("data/emps/emps_train_DATA_EMPS.csv");
    let test = shared("data/emps/emps_test_DATA_EMPS_PULSES.csv");
    let dir = tmpdir("views");
    let (plots, model) = (dir.join("fit"), dir.join("m.json"));
    let cols = [
        "--time",
        "t_s",
        "--input",
        "force_N",
        "--output",
        "qm_m",
        "--linear-axis",
    ];
    let mut argv = vec![
        "fit",
        &train,
        "--model",
        "rigid",
        "--estimation-fraction",
        "0.5",
    ];
    argv.extend(cols);
    let (p, m) = (plots.to_str().unwrap(), model.to_str().unwrap());
    argv.extend(["--plot", p, "--save", m, "--json"]);
    let j = json_of(&jointid(&argv));
    let files: Vec<&str> = j["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f.as_str().unwrap())
        .collect();
    for name in [
        "bode.svg",
        "compare.svg",
        "resid.svg",
        "pzmap.svg",
        "step.svg",
    ] {
        let path = plots.join(name);
        assert!(files.contains(&path.to_str().unwrap()), "{files:?}");
        assert_renders(&path);
    }
    let read = |name: &str| std::fs::read_to_string(plots.join(name)).unwrap();
    // the legend's FIT is the one printed: the toolbox FIT, the headline or beside it
    let (label, est, val) = if j["fit_metric"] == "toolbox" {
        ("FIT", &j["fit_estimation"], &j["fit_validation"])
    } else {
        (
            "toolbox FIT",
            &j["fit_toolbox_estimation"],
            &j["fit_toolbox_validation"],
        )
    };
    let compare = read("compare.svg");
    for fit in [est, val] {
        let text = format!("rigid: {label} {:.2} %", fit.as_f64().unwrap());
        assert!(compare.contains(&text), "{text} not in compare.svg");
    }
    assert!(compare.contains("estimation: ") && compare.contains("validation: "));
    assert!(compare.contains("position [m]") && compare.contains("time [s]"));
    let step = read("step.svg");
    assert!(step.contains("1 N force step") && step.contains("velocity [m/s]"));
    assert!(read("pzmap.svg").contains("Re s / 2π [Hz]"));
    let resid = read("resid.svg");
    for rec in ["estimation", "validation"] {
        for test in ["whiteness", "independence"] {
            let b = j["residual_tests"][rec][test]["bound"].as_f64().unwrap();
            let text = format!("99 % band ±{b:.4}");
            assert!(
                resid.contains(&text),
                "{rec} {test}: {text} not in resid.svg"
            );
        }
    }

    let vplots = dir.join("validate");
    let mut argv = vec!["validate", m, &test];
    argv.extend(cols);
    argv.extend(["--plot", vplots.to_str().unwrap(), "--json"]);
    let v = json_of(&jointid(&argv));
    assert_eq!(v["files"].as_array().unwrap().len(), 4, "{v}");
    for name in ["compare.svg", "resid.svg", "pzmap.svg", "step.svg"] {
        assert_renders(&vplots.join(name));
    }
    let compare = std::fs::read_to_string(vplots.join("compare.svg")).unwrap();
    let (label, fit) = if v["fit_metric"] == "toolbox" {
        ("FIT", &v["fit"])
    } else {
        ("toolbox FIT", &v["fit_toolbox"])
    };
    let text = format!("rigid: {label} {:.2} %", fit.as_f64().unwrap());
    assert!(
        compare.contains(&text),
        "{text} not in validate's compare.svg"
    );
    assert!(compare.contains("position [m]"));
    let resid = std::fs::read_to_string(vplots.join("resid.svg")).unwrap();
    let b = v["residual_tests"]["whiteness"]["bound"].as_f64().unwrap();
    assert!(resid.contains(&format!("99 % band ±{b:.4}")));
    // an existing view is refused before any work, unless --force
    let o = jointid(&argv);
    assert_eq!(o.status.code(), Some(2), "{o:?}");
    let _ = std::fs::remove_dir_all(&dir);
}
