//! Command-line tests of `jointid diagnose`: the simulator's joint with a hidden cubic
//! spring, diagnosed from its capture against a second run (and its HTML report opened in
//! headless Chromium); the measured EMPS drive, whose friction a rigid model lacks; and the
//! refusals.

mod common;
use common::{jointid, json_of, open_loop_csv, shared, simulated, stiffening_capture, tmpdir};

/// `simulate --effect nonlinear_stiffness`, then `diagnose` with three candidates: the
/// cubic spring ranks first among the single effects, significant, with `k3` near the
/// simulator's value, and heads the best model.
#[test]
fn diagnose_finds_the_hidden_cubic_spring_of_a_simulated_capture() {
    let dir = tmpdir("cubic");
    let est = stiffening_capture(&dir, "est.jcap", "5", "7");
    let val = stiffening_capture(&dir, "val.jcap", "6", "8");
    let out = jointid(&[
        "diagnose",
        &est,
        "--validation",
        &val,
        "--effects",
        "nonlinear_stiffness,time_delay,extra_mode",
        "--json",
    ]);
    // the progress lines are for a terminal: none on a pipe
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("fitted and scored"), "{err}");
    let j = json_of(&out);
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
/// is near the published 20.39 N (Janot et al. 2019, IDIM-LS), in N with `--linear-axis`.
/// The gearbox effects are no candidates of a rigid model and are said to be left out.
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
        "--linear-axis",
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
    // a linear axis's friction is a force, its inertia a mass
    assert_eq!(j["effects"][0]["parameters"]["fc"]["unit"], "N", "{j}");
    assert_eq!(j["nominal_parameters"]["J"]["unit"], "kg", "{j}");
    assert!(!j.to_string().contains("N·m"), "{j}");
    let share = j["gap_closed_share"].as_f64().unwrap();
    assert!(share > 0.6, "closed share {share}");
    let notes = j["warnings"].to_string();
    assert!(
        notes.contains("backlash: not candidates of a rigid model"),
        "{notes}"
    );
}

/// `--effect SPEC` spelled as `fit --effect` and `simulate --effect`, values included: a
/// value given is where the candidate's fit starts, and a ripple's `order` is taken as
/// given (from the data alone this capture's ripple candidate takes order 72); `--model`
/// takes every name `fit --model` takes (`three_mass`, through `ModelSpec::resolve`).
#[test]
fn diagnose_takes_effect_specs_with_values_and_the_model_names_of_fit() {
    let dir = tmpdir("specs");
    let est = stiffening_capture(&dir, "est.jcap", "5", "7");
    let val = stiffening_capture(&dir, "val.jcap", "6", "8");
    let j = json_of(&jointid(&[
        "diagnose",
        &est,
        "--validation",
        &val,
        "--model",
        "three_mass",
        "--effect",
        "torque_ripple:order=11",
        "--json",
        "--quiet",
    ]));
    assert_eq!(j["structure"], "three-mass", "{j}");
    assert_eq!(j["effects"][0]["name"], "torque_ripple", "{j}");
    let spec = j["effects"][0]["specs"][0].as_str().unwrap();
    assert!(spec.contains("order=11"), "{spec}");
}

/// Two estimation captures of a joint with backlash, at 0.01 and 0.03 rad RMS: the
/// nominal, fitted on the first, misses more of the second (36 → 51 gap points, out of
/// sample there), while the distortion relative to the excited lines falls (-12.9 dB), as
/// backlash's does. The text and the report say both in one sentence, with a `but` and
/// what each measures; before, they said "the gap grows with amplitude" and "distortion
/// falls as amplitude grows" side by side.
#[test]
fn diagnose_says_the_gaps_and_the_distortions_amplitude_trends_in_one_sentence() {
    let dir = tmpdir("amplitude");
    let run = |name: &str, rms: &str, seed: &str, exc: &str| {
        let out = dir.join(name);
        json_of(&jointid(&[
            "simulate",
            "--model",
            "three-mass",
            "--effect",
            "backlash",
            "--rms",
            rms,
            "--periods",
            "3",
            "--seed",
            seed,
            "--excitation-seed",
            exc,
            "--out",
            out.to_str().unwrap(),
            "--json",
        ]));
        out.display().to_string()
    };
    let low = run("low.jcap", "0.01", "3", "3");
    let high = run("high.jcap", "0.03", "3", "3");
    let val = run("val.jcap", "0.02", "4", "9");
    let report = dir.join("report.html");
    let o = jointid(&[
        "diagnose",
        &low,
        &high,
        "--validation",
        &val,
        "--effects",
        "time_delay",
        "--report",
        report.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    let html = std::fs::read_to_string(&report).unwrap();
    let paragraph = html
        .lines()
        .find(|l| l.starts_with("<p id=\"amplitude\">"))
        .expect("the report's amplitude paragraph");
    for said in [text.as_str(), paragraph] {
        assert!(
            said.contains(
                "gap grows with amplitude, but the distortion relative to the excited lines falls"
            ) && said.contains("measure different things")
                && said.contains("out of sample"),
            "{said}"
        );
        assert!(!said.contains("the gap grows with amplitude;"), "{said}");
        // and the best linear approximation's change with amplitude, after the trends
        assert!(
            said.contains("; the best linear approximation moves between the two captures"),
            "{said}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
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
        err.contains("--effect") && err.contains("warp_drive"),
        "{err}"
    );
    // the model flags as `fit` resolves them: a black box is no nominal of a diagnosis,
    // and a candidate is named once
    for (flags, says) in [
        (
            &["--model", "black-box:4"][..],
            "diagnose fits a physical model",
        ),
        (
            &["--effect", "backlash", "--effect", "backlash:width=1e-5"][..],
            "--effect backlash: named twice",
        ),
        (&["--effect", "none"][..], "at least one candidate"),
    ] {
        let mut args = vec![
            "diagnose",
            missing.to_str().unwrap(),
            "--validation",
            missing.to_str().unwrap(),
        ];
        args.extend(flags);
        let out = jointid(&args);
        assert_eq!(out.status.code(), Some(2), "{flags:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(says), "{flags:?}: {err}");
    }
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

/// A nominal fitted on one joint (three-mass) and validated on the record of another (a
/// rigid one) describes nothing there: the diagnosis says so first, names no effect, and
/// `--strict` exits 1 (without it, 0).
#[test]
fn diagnose_refuses_a_validation_record_of_another_plant() {
    let dir = tmpdir("mismatch");
    let capture = |model: &str, seed: &str, name: &str| {
        simulated(
            &dir,
            name,
            &["--model", model, "--periods", "2", "--seed", seed],
        )
    };
    let est = capture("three-mass", "22", "est.csv");
    let val = capture("rigid", "23", "val.csv");
    let args = [
        "diagnose",
        &est,
        "--validation",
        &val,
        "--effect",
        "coulomb_friction",
    ];
    let out = jointid(&args);
    assert_eq!(out.status.code(), Some(0));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.starts_with("jointid diagnose: not diagnosed: the nominal does not describe"),
        "{text}"
    );
    let mut strict = args.to_vec();
    strict.extend(["--strict", "--json"]);
    let out = jointid(&strict);
    assert_eq!(out.status.code(), Some(1));
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).expect("stdout is JSON");
    assert_eq!(j["best"], "none", "{j}");
    assert!(j["refused"].as_str().is_some(), "{j}");
    assert_eq!(j["effects"][0]["significant"], false, "{j}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The ids of the report's figures (`jointid::report::html::FIGURE_IDS`).
const FIGURES: [&str; 5] = [
    "fig-frf",
    "fig-residual-spectrum",
    "fig-distortion",
    "fig-residual-maps",
    "fig-time",
];

/// Chromium on the PATH; fails the test, saying how to install it, when there is none.
fn chromium() -> std::path::PathBuf {
    std::env::var_os("PATH")
        .iter()
        .flat_map(std::env::split_paths)
        .map(|d| d.join("chromium"))
        .find(|p| p.is_file())
        .expect("chromium is not installed: run .ci/setup (it installs Debian's `chromium`)")
}

/// Runs headless Chromium on the page `html` with `extra` arguments (`--dump-dom`,
/// `--screenshot=...`), a profile in `dir`; (stdout, stderr), both through files in `dir`
/// (a pipe would fill with the DOM and stall it). Fails the test after 120 s.
fn headless(dir: &std::path::Path, html: &std::path::Path, extra: &str) -> (String, String) {
    use std::process::Command;
    let tag = if extra.starts_with("--dump-dom") {
        "dom"
    } else {
        "shot"
    };
    let name = html.file_stem().unwrap().to_string_lossy();
    let profile = dir.join(format!("chromium-profile-{name}-{tag}"));
    let out_path = dir.join(format!("chromium-{name}-{tag}.out"));
    let err_path = dir.join(format!("chromium-{name}-{tag}.log"));
    let mut child = Command::new(chromium())
        .args([
            "--headless=new",
            "--no-sandbox",
            "--disable-gpu",
            "--enable-logging=stderr",
            "--v=0",
            "--window-size=1200,3000",
            &format!("--user-data-dir={}", profile.display()),
            extra,
            &format!("file://{}", html.display()),
        ])
        .stdout(std::fs::File::create(&out_path).unwrap())
        .stderr(std::fs::File::create(&err_path).unwrap())
        .spawn()
        .expect("start chromium");
    let t0 = std::time::Instant::now();
    while child.try_wait().expect("wait for chromium").is_none() {
        if t0.elapsed() > std::time::Duration::from_secs(120) {
            let _ = child.kill();
            panic!("chromium did not finish within 120 s on {}", html.display());
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    let status = child.wait().expect("chromium status");
    let read =
        |p: &std::path::Path| String::from_utf8_lossy(&std::fs::read(p).unwrap()).into_owned();
    assert!(
        status.success(),
        "chromium: {status:?}: {}",
        read(&err_path)
    );
    (read(&out_path), read(&err_path))
}

/// What the page did wrong as Chromium saw it: console messages (a script error is logged
/// as `INFO:CONSOLE`) and loads from anywhere (a self-contained page references no file,
/// so any `src`, `href`, `<link>`, `url(` or `@import` in its DOM is a load that can fail).
fn page_problems(dom: &str, log: &str) -> Vec<String> {
    let mut found: Vec<String> = log
        .lines()
        .filter(|l| l.contains(":CONSOLE") || l.contains("Failed to load resource"))
        .map(str::to_string)
        .collect();
    let lower = dom.to_lowercase();
    for what in [" src=", " href=", "<link", "url(", "@import"] {
        if lower.contains(what) {
            found.push(format!("the DOM loads something: `{what}`"));
        }
    }
    found
}

/// The cubic-spring case with `--report` and `--plot`: the report opens in headless
/// Chromium without console errors and loads nothing; its DOM holds the verdict (the one of
/// `--json`) at the top and every figure with an inline SVG and a caption; a screenshot is
/// saved; `--plot` writes the same figures as SVG files; the JSON has no report data. The
/// log scan is shown to catch a page with a script error and a missing image.
#[test]
fn diagnose_report_renders_in_headless_chromium_with_the_verdict_and_every_figure() {
    let dir = tmpdir("report");
    // the check first: a page that must fail it
    let bad = dir.join("bad.html");
    std::fs::write(
        &bad,
        "<!DOCTYPE html><html><body><p>x</p><script>undefined_fn()</script>\
         <img src=\"missing.png\"></body></html>",
    )
    .unwrap();
    let (dom, log) = headless(&dir, &bad, "--dump-dom");
    let problems = page_problems(&dom, &log);
    assert!(
        problems.iter().any(|p| p.contains("undefined_fn"))
            && problems.iter().any(|p| p.contains("src=")),
        "the scan misses a script error or a load: {problems:?}"
    );

    let est = stiffening_capture(&dir, "est.jcap", "5", "7");
    let val = stiffening_capture(&dir, "val.jcap", "6", "8");
    let report = dir.join("report.html");
    let plots = dir.join("svg");
    let j = json_of(&jointid(&[
        "diagnose",
        &est,
        "--validation",
        &val,
        "--effects",
        "nonlinear_stiffness,time_delay,extra_mode",
        "--report",
        report.to_str().unwrap(),
        "--plot",
        plots.to_str().unwrap(),
        "--json",
    ]));
    let keys: Vec<&str> = j.as_object().unwrap().keys().map(String::as_str).collect();
    assert!(
        !keys
            .iter()
            .any(|k| k.contains("series") || k.contains("svg")),
        "{keys:?}"
    );
    let verdict = j["verdict"].as_str().unwrap();
    assert!(verdict.starts_with("nonlinear_stiffness"), "{verdict}");

    let (dom, log) = headless(&dir, &report, "--dump-dom");
    let problems = page_problems(&dom, &log);
    assert!(problems.is_empty(), "{problems:#?}");
    let at = |what: &str| {
        dom.find(what)
            .unwrap_or_else(|| panic!("no `{what}` in the DOM"))
    };
    let v = at("id=\"verdict\"");
    assert!(
        dom[v..].find(verdict).is_some(),
        "the verdict `{verdict}` is not in the DOM"
    );
    for id in FIGURES {
        let f = at(&format!("<figure id=\"{id}\""));
        assert!(f > v, "{id} above the verdict");
        let end = f + dom[f..].find("</figure>").expect("figure closed");
        let fig = &dom[f..end];
        assert!(
            fig.contains("<svg") && fig.contains("<figcaption>"),
            "{id}: {fig:.300}"
        );
    }
    assert!(at("id=\"candidates\"") > v);
    assert!(dom.contains("nonlinear_stiffness") && dom.contains("k3 ="));
    // the runner-up's gain over the answer, beside its gain over the nominal
    let table = &dom[at("id=\"candidates\"")..];
    assert!(table.contains("over the answer ± SE"), "{table:.400}");
    let second = &table[table.find("<tr><td>2</td>").expect("a second candidate")..];
    let cells: Vec<&str> = second.split("<td>").skip(1).take(5).collect();
    assert!(cells[4].contains(" ± "), "{cells:?}");

    let png = dir.join("report.png");
    let (_, log) = headless(&dir, &report, &format!("--screenshot={}", png.display()));
    assert!(page_problems("", &log).is_empty(), "{log}");
    let bytes = std::fs::read(&png).expect("the screenshot is written");
    assert!(
        bytes.len() > 20_000 && bytes.starts_with(b"\x89PNG"),
        "screenshot {} bytes",
        bytes.len()
    );
    eprintln!("screenshot of the report: {}", png.display());

    for id in FIGURES {
        let n = std::fs::read_dir(&plots)
            .unwrap()
            .filter_map(Result::ok)
            .filter(|e| e.file_name().to_string_lossy().starts_with(id))
            .count();
        assert!(n >= 1, "--plot wrote no {id}*.svg");
    }
}

/// Issue 36 item 7: a mass on a hardening spring to the frame, measured open loop as any
/// CSV with `--time/--input/--output` (no reference, no `--model`). The default structure
/// assumes a free joint and finds no inertia; the diagnosis takes the grounded mass, says
/// so, and names the spring. `fit --model two-mass` refuses, saying what the data show and
/// which structure to try.
#[test]
fn diagnose_takes_a_mass_on_a_spring_to_ground_and_names_its_hardening() {
    use jointid::test_support::grounded;
    let dir = tmpdir("grounded");
    let k3 = grounded::k3_at(0.1);
    let (est, val) = grounded::records(k3, 11);
    let (est, val) = (
        open_loop_csv(&dir, "est.csv", &est),
        open_loop_csv(&dir, "val.csv", &val),
    );
    let cols = ["--time", "time", "--input", "force", "--output", "position"];
    let mut args = vec!["diagnose", &est, "--validation", &val];
    args.extend(cols);
    args.extend([
        "--effects",
        "nonlinear_stiffness,coulomb_friction",
        "--json",
    ]);
    let out = jointid(&args);
    let j = json_of(&out);
    assert_eq!(j["structure"], "grounded", "{j}");
    assert_eq!(j["best"], "nonlinear_stiffness", "{j}");
    assert!(
        j["warnings"][0]
            .as_str()
            .unwrap()
            .contains("diagnosed as the grounded mass"),
        "{j}"
    );
    let mut args = vec!["fit", &est, "--model", "two-mass"];
    args.extend(cols);
    let out = jointid(&args);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("finite static gain") && err.contains("--model grounded"),
        "{err}"
    );
}
