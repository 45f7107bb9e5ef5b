//! What the user reads (issue 13 item 16), run on the built binary: no Rust debug text,
//! each file named once in a message, no `(os error N)` suffix, negative numbers accepted
//! where they make sense.

#[allow(dead_code)] // not every helper is used here
mod common;
use common::{jointid, tmpdir};

fn text(o: &std::process::Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

#[test]
fn simulate_names_its_integrator_in_words_and_takes_negative_effect_values() {
    let dir = tmpdir("integrator");
    let csv = dir.join("run.csv");
    let o = jointid(&[
        "simulate",
        "--effect",
        "nonlinear_stiffness:k3=-1e3",
        "--effect",
        "torque_ripple:amplitude=0.01,phase=-1",
        "--periods",
        "1",
        "--out",
        csv.to_str().unwrap(),
    ]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(0), "{t}");
    assert!(!t.contains('{') && !t.contains("Rk4"), "{t}");
    assert!(
        t.contains("integrator exponential RK4 (5 RK4 substeps per sample at events)"),
        "{t}"
    );
    let o = jointid(&[
        "simulate",
        "--model",
        "nonlinear-two-mass",
        "--param",
        "k3=-1e3",
        "--periods",
        "1",
        "--out",
        dir.join("nl.csv").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_file_that_cannot_be_read_is_named_once_without_os_error_codes() {
    let dir = tmpdir("names");
    let bad = dir.join("bad.jcap");
    std::fs::write(&bad, "hi\n").unwrap();
    let missing = dir.join("missing.csv");
    for (file, args) in [
        (&bad, vec!["analyze", bad.to_str().unwrap()]),
        (&missing, vec!["analyze", missing.to_str().unwrap()]),
    ] {
        let o = jointid(&args);
        assert_eq!(o.status.code(), Some(2));
        let err = String::from_utf8_lossy(&o.stderr);
        let name = file.to_str().unwrap();
        assert_eq!(err.matches(name).count(), 1, "{err}");
        assert!(!err.contains("os error"), "{err}");
    }
    // a CSV the simulator cannot create
    let out = dir.join("no-such-dir").join("x.csv");
    let o = jointid(&["simulate", "--periods", "1", "--out", out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.matches(out.to_str().unwrap()).count(), 1, "{err}");
    assert!(!err.contains("os error"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn analyze_prints_times_and_rates_rounded() {
    let dir = tmpdir("rounded");
    let csv = dir.join("run.csv");
    let o = jointid(&[
        "simulate",
        "--model",
        "two-mass",
        "--periods",
        "3",
        "--out",
        csv.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let o = jointid(&["analyze", csv.to_str().unwrap()]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(0), "{t}");
    assert!(
        t.contains("N = 5000 samples (2.5 s)") && t.contains("fs = 2000 Hz, f0 = 0.4 Hz"),
        "{t}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn info_names_link_events_in_words() {
    let dir = tmpdir("events");
    let jcap = dir.join("run.jcap");
    let o = jointid(&[
        "simulate",
        "--model",
        "two-mass",
        "--periods",
        "1",
        "--out",
        jcap.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    std::fs::write(
        dir.join("run.jcap.events"),
        "{\"offset\":100,\"unix_ms\":0,\"utc\":\"1970-01-01T00:00:00.000Z\",\"event\":\"link_lost\",\"detail\":\"unplugged\"}\n\
         {\"offset\":100,\"unix_ms\":5,\"utc\":\"1970-01-01T00:00:00.005Z\",\"event\":\"link_resumed\"}\n",
    )
    .unwrap();
    let o = jointid(&["info", jcap.to_str().unwrap()]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(0), "{t}");
    assert!(t.contains("link lost at byte 100 unplugged"), "{t}");
    assert!(t.contains("link resumed at byte 100"), "{t}");
    assert!(!t.contains("LinkLost") && !t.contains("LinkResumed"), "{t}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue item 8: `analyze run --compare val` with a noise validation run printed
/// "odd lines −2930 dB … distortion grows with amplitude" and exited 0.
#[test]
fn analyze_compare_refuses_runs_that_are_not_the_same_multisine() {
    let dir = tmpdir("compare");
    let sim = |name: &str, extra: &[&str]| {
        let path = dir.join(name);
        let mut args = vec![
            "simulate",
            "--periods",
            "3",
            "--out",
            path.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let o = jointid(&args);
        assert_eq!(o.status.code(), Some(0), "{}", text(&o));
        path
    };
    let run = sim("run.csv", &[]);
    let loud = sim("loud.csv", &["--rms", "0.06"]);
    let noise = sim("noise.csv", &["--excitation", "noise"]);
    let random = sim("random.csv", &["--excitation", "random-odd"]);
    let analyze = |other: &std::path::Path| {
        jointid(&[
            "analyze",
            run.to_str().unwrap(),
            "--compare",
            other.to_str().unwrap(),
        ])
    };
    // the same multisine at three times the amplitude: compared
    let o = analyze(&loud);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(
        text(&o).contains("amplitude comparison with"),
        "{}",
        text(&o)
    );
    for (other, what) in [
        (
            &noise,
            "noise.csv: excited by band-limited noise, not a multisine (every line 1..",
        ),
        (
            &random,
            "random.csv: excitation is a random-phase odd multisine, ",
        ),
    ] {
        let o = analyze(other);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(2), "{t}");
        assert!(!t.contains("amplitude comparison with"), "{t}");
        assert_eq!(t.trim_end().lines().count(), 1, "{t}");
        assert!(t.contains("--compare ") && t.contains(what), "{t}");
        assert!(
            t.contains("run.csv has a special odd multisine") || other.ends_with("noise.csv"),
            "{t}"
        );
        assert!(t.contains("same multisine as"), "{t}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
