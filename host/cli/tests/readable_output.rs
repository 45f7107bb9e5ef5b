//! Command-line tests of the text output's vocabulary: an undefined percentage is a dash
//! and a huge one is short, one named headline FIT per command, and the files a command
//! wrote listed at the end of its output.

mod common;
use common::{jointid, json_of, tmpdir};

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
