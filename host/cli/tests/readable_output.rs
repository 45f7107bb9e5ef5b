//! Command-line tests of the text output's vocabulary: an undefined percentage is a dash
//! and a huge one is short, one named headline FIT per command, and the files a command
//! wrote listed at the end of its output.

mod common;
use common::{jointid, json_of, stiffening_capture, tmpdir};

/// A black box of order 1 (`y[k+1] = a y[k] + u[k]`) saved as `fit --save` would, at the
/// rate of `jointid::test_support::capture_csv` (1 kHz).
fn black_box_model(a: f64) -> String {
    format!(
        r#"{{"format":"jointid-model/2","model":"black-box:1","method":"by hand","output":"angle",
            "ts":0.001,"prep":{{"decimate":1,"detrend":"none"}},"a":[[{a:e}]],"b":[1.0],
            "c":[1.0],"d":0.0,"parameters":{{}},"friction":null,"decimate_output":1,
            "fit_estimation":0.0,"source":"by hand"}}"#
    )
}

/// The lines of `text` that name a FIT.
fn fit_lines(text: &str) -> Vec<&str> {
    text.lines().filter(|l| l.contains("FIT")).collect()
}

/// `validate` of a model whose simulation overflows prints its FIT as `—` (it printed
/// `NaN`), and of one whose simulation grows to about 1e20 in scientific notation (it
/// printed every digit and two decimals); `--json` keeps `null` and the number.
#[test]
fn validate_prints_an_undefined_fit_as_a_dash_and_a_huge_one_short() {
    let dir = tmpdir("undefined");
    let data = dir.join("run.csv");
    std::fs::write(&data, jointid::test_support::capture_csv(0.0, 4)).unwrap();
    for a in [1e308, 1.02] {
        let model = dir.join("m.json");
        std::fs::write(&model, black_box_model(a)).unwrap();
        let o = jointid(&["validate", model.to_str().unwrap(), data.to_str().unwrap()]);
        assert_eq!(o.status.code(), Some(if a > 2.0 { 1 } else { 0 }));
        let text = String::from_utf8_lossy(&o.stdout);
        let fits = fit_lines(&text);
        assert!(!fits.is_empty(), "{text}");
        for l in &fits {
            assert!(
                !l.contains("NaN") && !l.contains("inf") && l.len() < 120,
                "a = {a:e}: {l}"
            );
        }
        // the figure after the name: `—`, or a mantissa and an exponent
        let figure = fits[0]
            .split("[%]: ")
            .nth(1)
            .and_then(|r| r.split_whitespace().next())
            .unwrap_or_default();
        if a > 2.0 {
            assert_eq!(figure, "—", "{}", fits[0]);
        } else {
            assert!(
                figure.starts_with("-") && figure.contains('e') && figure.len() <= 9,
                "{}",
                fits[0]
            );
        }
        let o = jointid(&[
            "validate",
            model.to_str().unwrap(),
            data.to_str().unwrap(),
            "--json",
        ]);
        let j: serde_json::Value = if a > 2.0 {
            serde_json::from_slice(&o.stdout).unwrap()
        } else {
            json_of(&o)
        };
        if a > 2.0 {
            assert!(j["fit"].is_null(), "{j}");
        } else {
            assert!(j["fit"].as_f64().unwrap() < -1e14, "{j}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `jointid simulate` of the two-mass joint into `dir/name` (a capture CSV), `seed` its
/// noise and excitation.
fn simulate(dir: &std::path::Path, name: &str, seed: &str) -> String {
    let out = dir.join(name);
    json_of(&jointid(&[
        "simulate",
        "--model",
        "two-mass",
        "--seed",
        seed,
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]));
    out.display().to_string()
}

/// The FIT lines of a text report that are not marked as given for reference.
fn headline_fits(text: &str) -> Vec<&str> {
    fit_lines(text)
        .into_iter()
        .filter(|l| !l.trim_start().starts_with("for reference"))
        .collect()
}

/// `validate` of a model fitted in the frequency domain, on periodic data: one headline
/// FIT (the periodic one, as `fit` reported it); the toolbox FIT beside it, far below
/// (the whole record simulated, drift included), is marked as given for reference and
/// says what it measures. Before, both stood as equals: `... [%]: 98.06` and `FIT
/// (toolbox compare, NRMSE) [%]: -2930.38`.
#[test]
fn validate_prints_one_headline_fit_and_explains_the_other() {
    let dir = tmpdir("headline");
    let est = simulate(&dir, "est.csv", "1");
    let val = simulate(&dir, "val.csv", "2");
    let model = dir.join("m.json");
    json_of(&jointid(&[
        "fit",
        &est,
        "--model",
        "two-mass",
        "--save",
        model.to_str().unwrap(),
        "--json",
    ]));
    let o = jointid(&["validate", model.to_str().unwrap(), &val]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    let head = headline_fits(&text);
    assert_eq!(head.len(), 1, "{text}");
    assert!(head[0].contains("period-averaged steady state"), "{text}");
    let other: Vec<&str> = fit_lines(&text)
        .into_iter()
        .filter(|l| !head.contains(l))
        .collect();
    assert_eq!(other.len(), 1, "{text}");
    assert!(
        other[0].contains("FIT (toolbox compare") && other[0].contains("(the whole record"),
        "{}",
        other[0]
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `diagnose`'s text report names one headline FIT, the gap metric, with the nominal's
/// and the best model's figures; the nominal's toolbox FIT of θ_m (-4503 % on these
/// captures, printed beside the 75 % of the gap metric before) is left to `--json` and the
/// HTML report, which says what it measures. It ends with the files it wrote, the report
/// and the SVG files of `--plot` (it named none).
#[test]
fn diagnose_prints_one_headline_fit_and_the_files_it_wrote() {
    let dir = tmpdir("diagnose");
    let est = stiffening_capture(&dir, "est.jcap", "5", "7");
    let val = stiffening_capture(&dir, "val.jcap", "6", "8");
    let report = dir.join("report.html");
    let plots = dir.join("svg");
    let o = jointid(&[
        "diagnose",
        &est,
        "--validation",
        &val,
        "--effects",
        "nonlinear_stiffness",
        "--report",
        report.to_str().unwrap(),
        "--plot",
        plots.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    let head: Vec<&str> = text.lines().take_while(|l| !l.contains("test:")).collect();
    let figures: Vec<&&str> = head.iter().filter(|l| l.contains(" %")).collect();
    assert!(
        !text.contains("motor-angle FIT") && !text.contains("FIT of θ_m"),
        "{text}"
    );
    let named = figures
        .iter()
        .find(|l| l.contains("nominal"))
        .unwrap_or_else(|| panic!("{text}"));
    assert!(
        named.contains("band-passed motor-velocity FIT on") && named.contains("best"),
        "{named}"
    );
    let html = std::fs::read_to_string(&report).unwrap();
    let row = html
        .lines()
        .find(|l| l.contains("toolbox FIT of θ_m"))
        .expect("the HTML report keeps the angle's FIT");
    assert!(
        row.contains("for reference") && row.contains("drift"),
        "{row}"
    );
    // the files it wrote, at the end: the report and every SVG
    let mut svgs: Vec<String> = std::fs::read_dir(&plots)
        .unwrap()
        .map(|e| e.unwrap().path().display().to_string())
        .collect();
    svgs.sort();
    assert!(svgs.len() >= 5, "{svgs:?}");
    let mut listed = written(&text);
    assert_eq!(listed.remove(0), report.display().to_string(), "{text}");
    listed.sort();
    assert_eq!(listed, svgs, "{text}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The files listed under the last `wrote:` line of `text`, which must end the output.
fn written(text: &str) -> Vec<String> {
    let lines: Vec<&str> = text.lines().collect();
    let at = lines
        .iter()
        .rposition(|l| *l == "wrote:")
        .unwrap_or_else(|| panic!("no `wrote:` list: {text}"));
    let files: Vec<String> = lines[at + 1..]
        .iter()
        .map(|l| {
            assert!(l.starts_with("  "), "after the list: `{l}`");
            l.trim().to_string()
        })
        .collect();
    assert!(!files.is_empty(), "{text}");
    files
}

/// `simulate`, `export`, `analyze --plot` and `capture` end their text output with the
/// files they wrote (simulate named its capture on its first line and the parameters on
/// another, export only on standard error, analyze its plots as `plot: ...` lines, capture
/// not its events sidecar).
#[test]
fn commands_that_write_files_list_them_at_the_end() {
    let dir = tmpdir("wrote");
    let p = |name: &str| dir.join(name).display().to_string();
    let run = |args: &[&str]| {
        let o = jointid(args);
        assert!(
            o.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        String::from_utf8(o.stdout).unwrap()
    };
    let text = run(&[
        "simulate",
        "--model",
        "two-mass",
        "--out",
        &p("run.jcap"),
        "--params-out",
        &p("params.json"),
    ]);
    assert_eq!(written(&text), [p("run.jcap"), p("params.json")], "{text}");
    let text = run(&[
        "export",
        &p("run.jcap"),
        "--csv",
        &p("run.csv"),
        "--mat",
        &p("run.mat"),
    ]);
    assert_eq!(written(&text), [p("run.csv"), p("run.mat")], "{text}");
    let text = run(&["analyze", &p("run.csv"), "--plot", &p("plots")]);
    assert_eq!(
        written(&text),
        [p("plots/spectrum.svg"), p("plots/frf.svg")],
        "{text}"
    );
    let text = run(&["capture", "--file", &p("run.jcap"), "--out", &p("cap.jcap")]);
    assert_eq!(
        written(&text),
        [p("cap.jcap"), p("cap.jcap.events")],
        "{text}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A time column in steps of 1e-99 s: `info` states the rate as `1e99 Hz`, not in a hundred
/// digits (it printed every one, and the interval with a hundred decimals).
#[test]
fn info_writes_a_rate_far_outside_hertz_in_scientific_notation() {
    let dir = tmpdir("tiny-ts");
    let data = dir.join("tiny.csv");
    let mut csv = String::from("t,u,theta_m\n");
    for k in 0..400 {
        csv.push_str(&format!(
            "{:e},{},{}\n",
            k as f64 * 1e-99,
            (k % 7) as f64 * 0.1,
            k as f64 * 1e-3
        ));
    }
    std::fs::write(&data, csv).unwrap();
    let o = jointid(&["info", data.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&o.stdout);
    let line = text
        .lines()
        .find(|l| l.starts_with("samples"))
        .unwrap_or_else(|| panic!("{text}"));
    assert!(line.contains("at 1e99 Hz (Ts = 1e-99 s)"), "{line}");
    assert!(text.lines().all(|l| l.len() < 120), "{text}");
}
