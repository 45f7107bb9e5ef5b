//! `jointid simulate` run as a process: the `.jcap` it writes is byte for byte the stream
//! of the library chain (`sim::board::encode_session` on the configuration the binary
//! wrote with `--params-out`, checked end to end in the workspace test `tests/sil.rs`), and
//! `info`, `export` and `analyze` read it as a board capture; bad arguments end with one
//! line and exit code 2.

use jointid::data::{parse_csv, ColumnMap};
use jointid::sim::board::{encode_session, WireOptions};
use jointid::sim::{simulate_excitation, SimConfig};
use jointid_core::excitation::{ExcitationConfig, SignalKind};
use serde_json::Value;

mod common;
use common::{jointid, jointid_within, json_of, tmpdir};

#[test]
fn simulate_jcap_is_the_wire_stream_and_reads_like_a_board_capture() {
    let dir = tmpdir("jcap");
    let jcap = dir.join("run.jcap");
    let params = dir.join("params.json");
    let args = [
        "simulate",
        "--model",
        "two-mass",
        "--param",
        "k_g=1.3e5",
        "--effect",
        "backlash:width=2e-5",
        "--excitation",
        "odd-multisine",
        "--rms",
        "0.015",
        "--periods",
        "3",
        "--seed",
        "3",
        "--out",
        jcap.to_str().unwrap(),
        "--params-out",
        params.to_str().unwrap(),
    ];
    let mut with_json = vec!["--json"];
    with_json.extend_from_slice(&args);
    let summary = json_of(&jointid(&with_json));

    // the same run through the library: the configuration the binary wrote, the
    // excitation the arguments name; the file is the magic plus that stream
    let cfg: SimConfig = serde_json::from_str(&std::fs::read_to_string(&params).unwrap()).unwrap();
    let exc = ExcitationConfig {
        kind: SignalKind::SpecialOddMultisine,
        rms_rad: 0.015,
        periods: 3,
        seed: 3,
        ..ExcitationConfig::paper_default()
    };
    assert_eq!(cfg.plant.params.k_g, 1.3e5);
    assert_eq!(cfg.seed, 3);
    assert_eq!(cfg.sample_rate_hz, f64::from(exc.fs_hz));
    let sim = simulate_excitation(&cfg, &exc).unwrap();
    let stream = encode_session(&sim, &exc, &WireOptions::for_sim(&cfg)).unwrap();
    let file = std::fs::read(&jcap).unwrap();
    assert_eq!(file[..8], jointid::capture::jcap::MAGIC);
    assert_eq!(file[8..], stream[..]);

    assert_eq!(summary["samples"], sim.len());
    assert_eq!(summary["model"], "two-mass");
    assert_eq!(summary["format"], "jcap");
    assert_eq!(summary["effects"][0], "backlash:width=0.00002");
    assert_eq!(summary["out"], jcap.to_str().unwrap());
    let p: Value = serde_json::from_str(&std::fs::read_to_string(&params).unwrap()).unwrap();
    assert_eq!(p["plant"]["kind"], "two_mass");
    assert_eq!(p["plant"]["params"]["k_g"], 1.3e5);
    assert_eq!(p["seed"], 3);

    let info = json_of(&jointid(&["--json", "info", jcap.to_str().unwrap()]));
    assert_eq!(info["samples"], sim.len());
    assert_eq!(info["ended"], true);
    assert_eq!(info["damaged_frames"].as_array().unwrap().len(), 0);
    assert_eq!(info["header"]["excitation"]["periods"], 3);

    let csv = dir.join("run.csv");
    json_of(&jointid(&[
        "--json",
        "export",
        jcap.to_str().unwrap(),
        "--csv",
        csv.to_str().unwrap(),
    ]));
    let ds = parse_csv(
        &std::fs::read_to_string(&csv).unwrap(),
        "run.csv",
        &ColumnMap::capture(),
    )
    .unwrap();
    assert_eq!(ds.excitation, Some(exc));
    let r: Vec<f64> = jointid_core::excitation::generate(&exc)
        .unwrap()
        .into_iter()
        .map(f64::from)
        .collect();
    assert_eq!(ds.data.r.as_ref().unwrap(), &r);
    let tq = f64::from(WireOptions::for_sim(&cfg).scale.torque_nm_per_count);
    for (a, b) in ds.data.u.iter().zip(&sim.u) {
        assert!((a - b).abs() <= 0.5 * tq * (1.0 + 1e-9), "{a} vs {b}");
    }

    let analysis = json_of(&jointid(&["--json", "analyze", jcap.to_str().unwrap()]));
    assert_eq!(
        analysis["analysis"]["excited_source"], "config",
        "{analysis}"
    );
    assert_eq!(analysis["analysis"]["f0_hz"], 0.4);
    assert_eq!(
        analysis["analysis"]["layout"]["count"], 2,
        "3 periods, 1 settling"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn simulate_bad_arguments_end_with_one_line_and_exit_2() {
    let dir = tmpdir("errors");
    let out = dir.join("x.jcap");
    let out = out.to_str().unwrap();
    let cases: [(&[&str], &str); 4] = [
        (
            &["simulate", "--model", "three-mass", "--param", "J_p=2", "--out", out],
            "--param `J_p`: unknown parameter for three-mass (valid: J_m, J_a1, J_a2, k_g, d_g, k_a, d_a, f_m, r)",
        ),
        (
            &["simulate", "--model", "rigid", "--param", "r=fast", "--out", out],
            "--param `r`: `fast` is not a finite number (valid names for rigid: J_m, J_a1, J_a2, f_m, r)",
        ),
        (
            &["simulate", "--out", "x.txt"],
            "x.txt: --out must end in .jcap or .csv",
        ),
        (
            &["simulate", "--model", "three-mass", "--param", "k_g=-1", "--out", out],
            "--param `k_g`: `-1` is outside its physical range: must be within [0.001, 1e10] N·m/rad",
        ),
    ];
    for (args, msg) in cases {
        let o = jointid(args);
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8(o.stderr).unwrap();
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(err.contains(msg), "{args:?}: {err}");
    }
    assert!(!dir.join("x.jcap").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `jointid simulate args...` must end with exit 2 and one line on stderr containing every
/// one of `msgs`, leaving no `out`
fn assert_refused(args: &[&str], out: &std::path::Path, msgs: &[&str]) {
    let o = jointid(args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
    assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
    for m in msgs {
        assert!(err.contains(m), "{args:?}: `{m}` not in {err}");
    }
    assert!(!out.exists(), "{args:?} left {}", out.display());
}

#[test]
fn simulate_stops_at_the_first_non_finite_sample_and_never_clamps_to_the_wire() {
    let dir = tmpdir("nonfinite");
    // a softening cubic spring of -1e16 N·m/rad³ (inside the bounds) diverges: named
    // sample and effect, no file
    for name in ["nl.jcap", "nl.csv"] {
        let out = dir.join(name);
        assert_refused(
            &[
                "simulate",
                "--model",
                "nonlinear-two-mass",
                "--effect",
                "nonlinear_stiffness:k3=-1e16",
                "--periods",
                "1",
                "--out",
                out.to_str().unwrap(),
            ],
            &out,
            &[
                "not finite at sample ",
                "nonlinear_stiffness:k3=-10000000000000000",
            ],
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Issue item 10: `--rms 100` saturated 22,723 of 24,000 samples and exited 0; `--rms 0`,
/// `backlash:width=1e9`, `time_delay:samples=1e12`, `--substeps 100000000`,
/// `torque_ripple:amplitude=1e30`, `nonlinear_stiffness:k3=-1e20` were accepted.
#[test]
fn simulate_applies_the_boards_safety_limits_and_bounds_every_parameter() {
    let dir = tmpdir("bounds");
    let out = dir.join("run.jcap");
    let o = out.to_str().unwrap();
    let cases: [(&[&str], &[&str]); 6] = [
        (
            &["--rms", "100"],
            &[
                "excitation (--rms 100 rad): peak angle ",
                "exceeds the limit of 0.5 rad",
                "SafetyLimits",
            ],
        ),
        (
            &["--effect", "backlash:width=1e9"],
            &[
                "`backlash`",
                "`1e9` for `width`",
                "must be within [0, 0.1] rad",
            ],
        ),
        (
            &["--effect", "time_delay:samples=1e12"],
            &["`time_delay`", "`1e12`", "must be within [0, 100] samples"],
        ),
        (
            &["--effect", "torque_ripple:amplitude=1e30"],
            &[
                "`torque_ripple`",
                "`1e30` for `amplitude`",
                "[-100, 100] N·m",
            ],
        ),
        (
            &["--effect", "nonlinear_stiffness:k3=-1e20"],
            &["`-1e20` for `k3`", "must be within [-1e16, 1e16] N·m/rad³"],
        ),
        (
            &["--effect", "coulomb_friction:fs=1e9"],
            &["`coulomb_friction`", "`1e9` for `fs`", "[0, 100] N·m"],
        ),
    ];
    for (extra, msgs) in cases {
        let mut args = vec!["simulate", "--periods", "1", "--out", o];
        args.extend_from_slice(extra);
        assert_refused(&args, &out, msgs);
    }
    // refused by the argument parser (its usual error and usage lines)
    for (extra, msg) in [
        (
            ["--rms", "0"],
            "invalid value '0' for '--rms <RAD>': `0` is not an RMS in rad > 0",
        ),
        (
            ["--substeps", "100000000"],
            "invalid value '100000000' for '--substeps <M>': 100000000 is not in 1..=1000",
        ),
    ] {
        let mut args = vec!["simulate", "--periods", "1", "--out", o];
        args.extend_from_slice(&extra);
        let r = jointid(&args);
        let err = String::from_utf8_lossy(&r.stderr);
        assert_eq!(r.status.code(), Some(2), "{err}");
        assert!(err.contains(msg), "{err}");
        assert!(!out.exists());
    }
    // inside the limits: runs
    let mut args = vec!["simulate", "--periods", "1", "--out", o];
    args.extend_from_slice(&["--rms", "0.06", "--substeps", "1000"]);
    let r = jointid(&args);
    assert_eq!(
        r.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&r.stderr)
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A run larger than the free space of `--out`'s file system is refused before the
/// simulation, with both figures. Before: `--periods 100000000` was accepted and wrote
/// about 8 MB/s until killed (36 TB of CSV at the end).
#[test]
fn simulate_refuses_a_run_larger_than_the_free_space_before_simulating() {
    let dir = tmpdir("runaway");
    for name in ["x.csv", "x.jcap"] {
        let out = dir.join(name);
        let o = out.to_str().unwrap();
        let args = ["simulate", "--periods", "100000000", "--out", o];
        let Some(run) = jointid_within(&args, std::time::Duration::from_secs(10)) else {
            let _ = std::fs::remove_dir_all(&dir);
            panic!("{name}: still simulating after 10 s");
        };
        let err = String::from_utf8_lossy(&run.stderr).into_owned();
        assert_eq!(run.status.code(), Some(2), "{name}: {err}");
        // 2 ramps of 2000 samples and 1e8 periods of 5000
        let head = format!("--periods 100000000: 500000004000 samples: {o}: about ");
        assert!(err.contains(&head), "{err}");
        let size = if name.ends_with("csv") {
            "36.0 TB"
        } else {
            "2.75 TB"
        };
        assert!(
            err.contains(&format!("{size} to write, more than the ")),
            "{err}"
        );
        assert!(err.contains("free on the file system of"), "{err}");
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(
            std::fs::read_dir(&dir).unwrap().next().is_none(),
            "a file was left"
        );
    }
    // a device or pipe has no free space to bound the run: the stated maximum does, at
    // once (before: `--out /dev/null` simulated 100,000,000 periods for hours)
    for out in ["/dev/null", "/dev/stdout"] {
        let args = ["simulate", "--periods", "100000000", "--out", out];
        let Some(run) = jointid_within(&args, std::time::Duration::from_secs(10)) else {
            let _ = std::fs::remove_dir_all(&dir);
            panic!("{out}: still simulating after 10 s");
        };
        let err = String::from_utf8_lossy(&run.stderr).into_owned();
        assert_eq!(run.status.code(), Some(2), "{out}: {err}");
        assert_eq!(
            err.trim_end(),
            "jointid: error: --periods 100000000: 500000004000 samples, more than the \
             4294967296 a run may hold: a capture numbers its samples with the board's 32-bit \
             counter (seq), 24.9 days at 2000 Hz",
        );
        assert!(run.stdout.is_empty(), "{out}");
    }
    // a run that fits is still written
    let out = dir.join("small.jcap");
    let run = jointid(&["simulate", "--periods", "1", "--out", out.to_str().unwrap()]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let _ = std::fs::remove_dir_all(&dir);
}
