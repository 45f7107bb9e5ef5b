//! Captures with gaps (issue 13 item 2) and files told by their content (item 13), run on
//! the built binary: `info` lists the gap-free segments, every analysis command takes
//! `--segment longest|N|all` and `--from/--to`, and the export of a gapped capture reads
//! back as the same segments.
//!
//! The capture is synthesised with the core's encoder (`jointid::test_support::synth`)
//! and the gap is made by removing whole sample batches, so which samples are missing,
//! and how many whole periods each segment holds, is computed here from the frames.

use std::path::{Path, PathBuf};

use jointid::capture::jcap::MAGIC;
use jointid::test_support::synth::{synth_stream, FrameContent, SynthOptions};
use serde_json::Value;

mod common;
use common::{jointid, json_of, refused, simulated, tmpdir};

/// 2000 samples at 200 Hz of an endless multisine (period 100, ramp 50) with the batches
/// carrying samples 800..1104 removed: segment 1 is 0..800 (whole periods 50..750: 7),
/// segment 2 is 1104..2000 (whole periods from 1150 to 1950, the last 50 samples left
/// out as a possible ramp-out: 8).
fn gapped_capture(dir: &Path, name: &str) -> PathBuf {
    let mut opts = SynthOptions::small();
    opts.excitation.periods = 0;
    opts.samples = 2000;
    let s = synth_stream(&opts);
    let mut bytes = MAGIC.to_vec();
    let mut removed = 0;
    let mut at = 0usize;
    for f in &s.frames {
        let (start, end) = (f.offset as usize, (f.offset + f.len) as usize);
        bytes.extend_from_slice(&s.bytes[at..start]);
        at = end;
        match f.content {
            FrameContent::Batch { first, len } if (800..1104).contains(&first) => {
                removed += len;
            }
            _ => bytes.extend_from_slice(&s.bytes[start..end]),
        }
    }
    bytes.extend_from_slice(&s.bytes[at..]);
    assert_eq!(removed, 304, "the batches are 16 samples long");
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

fn stderr(out: &std::process::Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn info_lists_the_gap_free_segments_with_their_whole_periods() {
    let dir = tmpdir("info-segments");
    let cap = gapped_capture(&dir, "run.jcap");
    let v = json_of(&jointid(&["info", cap.to_str().unwrap(), "--json"]));
    let segs = v["segments"].as_array().unwrap();
    assert_eq!(segs.len(), 2, "{v}");
    let got: Vec<(f64, f64, u64, u64)> = segs
        .iter()
        .map(|s| {
            (
                (s["start_s"].as_f64().unwrap() * 1e6).round() / 1e6,
                (s["length_s"].as_f64().unwrap() * 1e6).round() / 1e6,
                s["samples"].as_u64().unwrap(),
                s["whole_periods"].as_u64().unwrap(),
            )
        })
        .collect();
    assert_eq!(got, vec![(0.0, 4.0, 800, 7), (5.52, 4.48, 896, 8)]);
    let out = jointid(&["info", cap.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("end message      received\nsegments         2 gap-free"),
        "{text}"
    );
    assert!(
        text.contains("2  from 5.52 s, 4.48 s, 896 samples, 8 whole periods"),
        "{text}"
    );
}

/// `analyze --json` of `args`: the periods used and the stderr notes.
fn analyze(args: &[&str]) -> (u64, u64, String) {
    let mut argv = vec!["analyze"];
    argv.extend_from_slice(args);
    argv.push("--json");
    let out = jointid(&argv);
    let v: Value = json_of(&out);
    let lay = &v["analysis"]["layout"];
    (
        lay["count"].as_u64().unwrap(),
        lay["start"].as_u64().unwrap(),
        stderr(&out),
    )
}

#[test]
fn analyze_uses_the_longest_segment_by_default_and_every_one_with_segment_all() {
    let dir = tmpdir("analyze-segments");
    let cap = gapped_capture(&dir, "run.jcap");
    let c = cap.to_str().unwrap();
    // before: "1 gap, 304 samples missing" and exit 2; now the longest, with a note
    let (count, start, note) = analyze(&[c]);
    assert_eq!((count, start), (8, 46), "{note}");
    assert!(
        note.contains("has 1 gap (304 samples missing); using the longest, segment 2"),
        "{note}"
    );
    assert!(note.contains("--segment all"), "{note}");
    // all: 7 − 1 settling period in segment 1, 8 in segment 2
    let (count, start, note) = analyze(&[c, "--segment", "all"]);
    assert_eq!((count, start), (14, 150), "{note}");
    // one segment by number, and a window in whole periods
    assert_eq!(analyze(&[c, "--segment", "1"]).0, 6);
    // from 2p = sample 250, after the transient: periods 250..750
    assert_eq!(analyze(&[c, "--segment", "1", "--from", "2p"]).0, 5);
    // a window that ends in segment 1: no ramp-out there, periods 150..750
    assert_eq!(
        analyze(&[c, "--segment", "all", "--from", "0", "--to", "3.75"]).0,
        6
    );
    // the exported CSV reads as the same segments
    let csv = dir.join("run.csv");
    let out = jointid(&["export", c, "--csv", csv.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(analyze(&[csv.to_str().unwrap(), "--segment", "all"]).0, 14);
    // a segment that does not exist is named with the ones that do
    let out = jointid(&["analyze", c, "--segment", "3"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("--segment 3: the file has 2 segments (1: 4 s from 0 s, 7 whole periods; 2: 4.48 s from 5.52 s, 8 whole periods)"),
        "{}",
        stderr(&out)
    );
}

/// `validate DATA --simulated COL` compares one record with its simulated column: it
/// refuses several segments and names the commands that take them all.
#[test]
fn commands_that_take_one_record_refuse_segment_all_naming_the_alternative() {
    let dir = tmpdir("simulated-segments");
    let cap = gapped_capture(&dir, "run.jcap");
    let c = cap.to_str().unwrap();
    let out = jointid(&["validate", c, "--simulated", "theta_m", "--segment", "all"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains(
            "--segment all: this command takes one gap-free record, and segments 1, 2 were \
             selected; give --segment longest or --segment N (`analyze`, `fit`, `validate \
             MODEL.json` and `diagnose` use all of them)"
        ),
        "{}",
        stderr(&out)
    );
}

/// A rigid joint with hidden Coulomb friction (the pure law, `F_s = F_c`), estimation and
/// validation captures each with a gap: `diagnose --segment all` fits the nominal and the
/// candidates on both estimation segments as separate experiments, scores them on both
/// validation segments pooled, names Coulomb friction with its level, and gives each
/// validation segment's figures. Before: refused ("this command takes one gap-free
/// record").
#[test]
fn diagnose_with_segment_all_names_the_hidden_friction_of_gapped_captures() {
    let dir = tmpdir("diagnose-segments");
    let sim = |name: &str, seed: &str| {
        gapped_simulation(
            &dir,
            name,
            &[
                "--model",
                "rigid",
                "--effect",
                "coulomb_friction:fc=0.03,fs=0.03",
                "--seed",
                seed,
                "--excitation-seed",
                seed,
            ],
        )
    };
    let (est, truth) = sim("est.jcap", "3");
    let (val, _) = sim("val.jcap", "4");
    let (e, v) = (est.to_str().unwrap(), val.to_str().unwrap());
    let out = jointid(&[
        "diagnose",
        e,
        "--validation",
        v,
        "--segment",
        "all",
        "--model",
        "rigid",
        "--effects",
        "coulomb_friction,time_delay",
        "--json",
    ]);
    let j = json_of(&out);
    assert!(
        stderr(&out).contains("diagnosing on segments 1, 2"),
        "{}",
        stderr(&out)
    );
    // the best single; a time delay may pair with it (the simulated current loop lags, and
    // with one whole period per segment no frequency-domain start gives the model a lag)
    assert!(
        j["best"].as_str().unwrap().starts_with("coulomb_friction"),
        "{j}"
    );
    assert_eq!(j["effects"][0]["name"], "coulomb_friction");
    assert_eq!(j["effects"][0]["significant"], true);
    let fc = num(&j["effects"][0]["parameters"]["fc"]["value"]);
    let true_fc = num(&truth["config"]["effects"][0]["fc"]);
    assert!(
        (fc / true_fc - 1.0).abs() < 0.05,
        "F_c = {fc}, truth {true_fc}"
    );
    // both validation segments, numbered and sized as `info` lists them; the pooled
    // figures (one sum of squares over both) lie between theirs
    let listed = json_of(&jointid(&["info", v, "--json"]));
    let listed = listed["segments"].as_array().unwrap();
    let per = j["validation_segments"].as_array().unwrap();
    assert_eq!(per.len(), 2, "{j}");
    for (k, (s, l)) in per.iter().zip(listed).enumerate() {
        assert_eq!(s["segment"], k + 1);
        assert_eq!(s["samples"], l["samples"]);
    }
    for (pooled, each) in [
        ("fit_nominal_val", "fit_nominal"),
        ("fit_augmented_val", "fit_augmented"),
    ] {
        let p = num(&j[pooled]);
        let (a, b) = (num(&per[0][each]), num(&per[1][each]));
        assert!(
            p >= a.min(b) - 1e-9 && p <= a.max(b) + 1e-9,
            "{pooled} {p} of {a}, {b}"
        );
    }
    assert!(
        num(&j["fit_augmented_val"]) > num(&j["fit_nominal_val"]) + 10.0,
        "{j}"
    );
}

/// `jointid simulate` with `args` written as a `.jcap`, then the frames that start between
/// 45 % and 55 % of its stream removed (cut at frame delimiters, as a serial unplug loses
/// them): a capture with one gap. Returns its path and the simulation's `--json` report.
fn gapped_simulation(dir: &Path, name: &str, args: &[&str]) -> (PathBuf, Value) {
    gapped_simulation_cut(dir, name, args, (0.45, 0.55))
}

/// As [`gapped_simulation`], the frames that start between the fractions `cut` of the
/// stream removed.
fn gapped_simulation_cut(
    dir: &Path,
    name: &str,
    args: &[&str],
    cut: (f64, f64),
) -> (PathBuf, Value) {
    let whole = dir.join(format!("whole-{name}"));
    let mut a = vec!["simulate", "--out", whole.to_str().unwrap(), "--json"];
    a.extend_from_slice(args);
    let report = json_of(&jointid(&a));
    let bytes = std::fs::read(&whole).unwrap();
    let body = &bytes[MAGIC.len()..];
    let at = |f: f64| {
        let from = (f * body.len() as f64) as usize;
        from + body[from..].iter().position(|b| *b == 0).unwrap()
    };
    let (a, b) = (at(cut.0), at(cut.1));
    let mut out = MAGIC.to_vec();
    out.extend_from_slice(&body[..a]);
    out.extend_from_slice(&body[b..]);
    let path = dir.join(name);
    std::fs::write(&path, out).unwrap();
    (path, report)
}

fn num(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

/// The relative error of `fit`'s parameter `name` against the simulation's `truth`.
fn rel_error(fit: &Value, truth: &Value, name: &str) -> f64 {
    let v = num(&fit["parameters"][name]["value"]);
    let t = num(&truth["config"]["plant"]["params"][name]);
    v / t - 1.0
}

#[test]
fn fit_with_segment_all_averages_the_frf_over_the_segments_of_a_gapped_capture() {
    let dir = tmpdir("fit-all-frequency");
    let (cap, sim) = gapped_simulation(&dir, "run.jcap", &["--periods", "6", "--seed", "3"]);
    let c = cap.to_str().unwrap();
    let info = json_of(&jointid(&["info", c, "--json"]));
    let listed = info["segments"].as_array().unwrap();
    assert_eq!(listed.len(), 2, "{info}");
    let model = dir.join("m.json");
    let m = model.to_str().unwrap();
    let out = jointid(&[
        "fit",
        c,
        "--model",
        "three-mass",
        "--segment",
        "all",
        "--save",
        m,
        "--json",
    ]);
    let all = json_of(&out);
    let note = stderr(&out);
    assert!(
        note.contains("the FRF averages the whole periods of segments 1, 2"),
        "{note}"
    );
    let segs = all["segments"].as_array().unwrap();
    assert_eq!(segs.len(), 2, "{all}");
    let total: u64 = listed.iter().map(|s| s["samples"].as_u64().unwrap()).sum();
    assert_eq!(all["samples"].as_u64().unwrap(), total);
    for (s, l) in segs.iter().zip(listed) {
        assert_eq!(s["samples"], l["samples"]);
    }
    let longest = json_of(&jointid(&[
        "fit",
        c,
        "--model",
        "three-mass",
        "--segment",
        "longest",
        "--json",
    ]));
    let names = ["J_m", "J_a1", "J_a2", "k_g", "k_a", "d_g", "d_a"];
    let (mut e_all, mut e_long) = (0.0, 0.0);
    for n in names {
        let (a, l) = (rel_error(&all, &sim, n), rel_error(&longest, &sim, n));
        assert!(
            a.abs() < 0.03,
            "{n}: {:+.2} % with --segment all",
            100.0 * a
        );
        e_all += a * a;
        e_long += l * l;
    }
    assert!(
        e_all <= e_long,
        "sum of squared relative errors {e_all:.2e} over all segments, {e_long:.2e} longest"
    );
    // validate on every segment: each one's FIT and the pooled one, which is the fit's
    let v = json_of(&jointid(&["validate", m, c, "--segment", "all", "--json"]));
    let per = v["segments"].as_array().unwrap();
    assert_eq!(per.len(), 2, "{v}");
    // a segment alone with fewer than two steady-state periods has no periodic FIT (null)
    assert!(
        per.iter()
            .all(|s| s["fit"].is_null() || num(&s["fit"]) > 90.0)
            && per.iter().any(|s| !s["fit"].is_null()),
        "{v}"
    );
    assert!(
        (num(&v["fit"]) - num(&all["fit_estimation"])).abs() < 1e-6,
        "{v} {all}"
    );
}

#[test]
fn nonlinear_fit_with_segment_all_takes_the_segments_as_separate_experiments() {
    let dir = tmpdir("fit-all-nonlinear");
    let (cap, sim) = gapped_simulation(
        &dir,
        "run.jcap",
        &[
            "--effect",
            "nonlinear_stiffness",
            "--periods",
            "6",
            "--seed",
            "2",
        ],
    );
    let c = cap.to_str().unwrap();
    let model = dir.join("m.json");
    let m = model.to_str().unwrap();
    let out = jointid(&[
        "fit",
        c,
        "--model",
        "three-mass",
        "--effect",
        "nonlinear_stiffness",
        "--segment",
        "all",
        "--save",
        m,
        "--json",
    ]);
    let all = json_of(&out);
    let note = stderr(&out);
    assert!(
        note.contains("fitting segments 1, 2 as separate experiments"),
        "{note}"
    );
    let segs = all["segments"].as_array().unwrap();
    assert_eq!(segs.len(), 2, "{all}");
    assert!(segs.iter().all(|s| num(&s["fit"]) > 50.0), "{all}");
    // the frequency-domain linear start averaged the FRF over both segments
    assert_eq!(all["steps"][0]["name"], "frequency-domain linear fit");
    for n in ["J_m", "J_a1", "k_g"] {
        let e = rel_error(&all, &sim, n);
        assert!(e.abs() < 0.03, "{n}: {:+.2} %", 100.0 * e);
    }
    let k3 = num(&all["effects"][0]["parameters"]["k3"]["value"]);
    let truth = num(&sim["config"]["effects"][0]["k3"]);
    assert!(
        (k3 / truth - 1.0).abs() < 0.05,
        "k3 = {k3:.4e}, truth {truth:.4e}"
    );
    // the saved model validated on every segment, each from its own first angle: the
    // pooled FIT is the fit's, and each segment's FIT is the fit's for that segment
    let out = jointid(&["validate", m, c, "--segment", "all", "--json"]);
    let v = json_of(&out);
    assert!(
        stderr(&out).contains("validating on segments 1, 2"),
        "{}",
        stderr(&out)
    );
    assert!(
        (num(&v["fit"]) - num(&all["fit_estimation"])).abs() < 0.01,
        "{v} {all}"
    );
    assert_eq!(v["samples"], all["samples"], "{v}");
    let per = v["segments"].as_array().unwrap();
    assert_eq!(per.len(), 2, "{v}");
    for (s, f) in per.iter().zip(segs) {
        assert_eq!(s["segment"], f["segment"]);
        assert_eq!(s["samples"], f["samples"]);
        assert!((num(&s["fit"]) - num(&f["fit"])).abs() < 0.01, "{v} {all}");
    }
    let text = jointid(&["validate", m, c, "--segment", "all"]);
    let text = String::from_utf8_lossy(&text.stdout);
    assert!(
        text.contains("per segment (the figures above pool them)"),
        "{text}"
    );
    assert!(text.contains("    segment 2 ("), "{text}");
}

#[test]
fn a_capture_named_csv_is_read_as_a_capture_and_a_mat_file_is_named() {
    let dir = tmpdir("by-content");
    let cap = gapped_capture(&dir, "x.csv");
    let (count, _, _) = analyze(&[cap.to_str().unwrap(), "--segment", "all"]);
    assert_eq!(count, 14);
    let mat = dir.join("run.mat");
    let mut v5 = b"MATLAB 5.0 MAT-file, Platform: PCWIN64, Created on: Tue Nov 25".to_vec();
    v5.resize(128, b' ');
    std::fs::write(&mat, v5).unwrap();
    let out = jointid(&["analyze", mat.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains(&format!(
            "{}: endian indicator \"  \" at byte 126 is neither `IM` nor `MI`: not a MATLAB \
             Level-5 MAT-file",
            mat.display()
        )),
        "{}",
        stderr(&out)
    );
}

/// The capture CSV of `test_support::capture_csv` as another logger writes it: its own
/// `# key=value` comments (some of the nine excitation keys, none of `kind`), its own
/// column names, `;` between the cells.
fn other_logger_csv() -> String {
    let text = jointid::test_support::capture_csv(0.0, 4);
    let mut out = String::from(
        "# logger=acme-daq 2.1\n# period_samples=500\n# f0_hz=2\n# excited_harmonics=1,3,9,11\n",
    );
    out.push_str("time;ref;torque;angle\n");
    for l in text.lines().filter(|l| !l.starts_with('#')).skip(1) {
        out.push_str(&l.replace(',', ";"));
        out.push('\n');
    }
    out
}

#[test]
fn another_loggers_csv_on_standard_input_is_read_with_a_mapping_and_notes() {
    use std::io::Write;
    let run = |args: &[&str], input: &str| {
        let mut child = std::process::Command::new(common::BIN)
            .args(args)
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        child
            .stdin
            .take()
            .unwrap()
            .write_all(input.as_bytes())
            .unwrap();
        child.wait_with_output().unwrap()
    };
    let csv = other_logger_csv();
    let map = [
        "--time",
        "time",
        "--input",
        "torque",
        "--output",
        "angle",
        "--reference",
        "ref",
    ];
    let mut argv = vec!["analyze", "-", "--json"];
    argv.extend_from_slice(&map);
    // before: "`kind`: missing: the excitation keys ... come together", exit 2
    let out = run(&argv, &csv);
    let v = json_of(&out);
    assert_eq!(v["file"], "standard input");
    assert_eq!(v["analysis"]["layout"]["period"], 500);
    let notes = stderr(&out);
    assert!(
        notes.contains("comment keys period_samples without `kind`"),
        "{notes}"
    );
    assert!(
        notes.contains("comment keys not used: excited_harmonics, logger"),
        "{notes}"
    );
    assert!(
        notes.contains("no `,` in the header line 5: columns split on `;`"),
        "{notes}"
    );
    // an explicit delimiter: no guess, no note about it
    argv.extend_from_slice(&["--delimiter", ";"]);
    let out = run(&argv, &csv);
    json_of(&out);
    assert!(
        !stderr(&out).contains("columns split on"),
        "{}",
        stderr(&out)
    );
    // a capture on standard input is a capture
    let dir = tmpdir("stdin-capture");
    let cap = gapped_capture(&dir, "run.jcap");
    let bytes = std::fs::read(&cap).unwrap();
    let mut child = std::process::Command::new(common::BIN)
        .args(["analyze", "-", "--segment", "all", "--json"])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    child.stdin.take().unwrap().write_all(&bytes).unwrap();
    let v = json_of(&child.wait_with_output().unwrap());
    assert_eq!(v["analysis"]["layout"]["count"], 14);
}

/// `--segment all` on a capture whose first segment is shorter than the ramp-in, the
/// settling period and one period (9600 samples of 2000 + 5000 + 5000): that segment is
/// left out of the FRF with a note naming it and why, and the command runs on the other.
/// Before: `analyze` exited 2 ("no whole excitation period: 9600 samples leave no whole
/// period of 5000 after 7000 transient samples") and `fit` fell back to the time domain.
#[test]
fn segment_all_leaves_out_a_segment_without_a_whole_period_after_the_transient() {
    let dir = tmpdir("all-short-segment");
    let (cap, _) = gapped_simulation_cut(
        &dir,
        "run.jcap",
        &["--periods", "6", "--seed", "3"],
        (0.28, 0.36),
    );
    let c = cap.to_str().unwrap();
    let info = json_of(&jointid(&["info", c, "--json"]));
    let listed = info["segments"].as_array().unwrap();
    assert_eq!(listed.len(), 2, "{info}");
    assert_eq!(listed[0]["samples"], 9600, "{info}");
    let why = "segment 1 left out of the FRF: 9600 samples leave no whole period of 5000 \
               after 7000 transient samples";
    let out = jointid(&["analyze", c, "--segment", "all", "--json"]);
    let a = json_of(&out);
    assert!(stderr(&out).contains(why), "{}", stderr(&out));
    // segment 2's three whole periods (it starts after the ramp: no settling dropped)
    assert_eq!(a["analysis"]["layout"]["count"], 3, "{a}");
    let out = jointid(&[
        "fit",
        c,
        "--model",
        "three-mass",
        "--segment",
        "all",
        "--domain",
        "frequency",
        "--json",
    ]);
    json_of(&out);
    let note = stderr(&out);
    assert!(note.contains(why), "{note}");
    assert!(
        note.contains("the FRF averages the whole periods of segments 2"),
        "{note}"
    );
    // no segment with a whole period: still refused
    let out = jointid(&["analyze", c, "--segment", "all", "--settle-periods", "6"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("no whole excitation period"),
        "{}",
        stderr(&out)
    );
}

/// Issue 37 item 4: a fit on the scrap of a damaged capture (1 % of its bytes flipped:
/// over a hundred segments, none with a whole period) is refused, naming the segment, its
/// periods and its share of the file; a fit on the longest segment of a capture with a
/// gap, enough periods but less than half the file, warns with the share (and `--strict`
/// fails on it).
#[test]
fn fit_refuses_a_scrap_of_a_damaged_capture_and_names_the_share_it_uses() {
    let dir = tmpdir("fit-scrap");
    let whole = dir.join("whole.jcap");
    json_of(&jointid(&[
        "simulate",
        "--model",
        "three-mass",
        "--out",
        whole.to_str().unwrap(),
        "--json",
    ]));
    let mut bytes = std::fs::read(&whole).unwrap();
    let mut rng = jointid_core::rng::SplitMix64::new(37);
    let body = bytes.len() - MAGIC.len();
    for _ in 0..body / 100 {
        let at = MAGIC.len() + (rng.next_u64() % body as u64) as usize;
        bytes[at] ^= 1 << (rng.next_u64() % 8);
    }
    let garbled = dir.join("garbled.jcap");
    std::fs::write(&garbled, bytes).unwrap();
    let g = garbled.to_str().unwrap();
    let info = json_of(&jointid(&["info", g, "--json"]));
    assert!(info["gaps"].as_array().unwrap().len() > 50, "{info}");
    let o = jointid(&["fit", g, "--model", "three-mass"]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    let last = err.lines().last().unwrap_or_default();
    assert!(
        last.starts_with(&format!("jointid: error: {g}: segment ")),
        "{err}"
    );
    assert!(
        last.contains(" holds 0 whole excitation periods of 5000 samples (")
            && last.contains(" % of the ")
            && last.contains(" its time span covers); ")
            && last.contains("a fit needs at least 2; the file has "),
        "{err}"
    );

    let (cap, _) = gapped_simulation(&dir, "gap.jcap", &["--model", "two-mass", "--periods", "8"]);
    let c = cap.to_str().unwrap();
    let v = json_of(&jointid(&["fit", c, "--model", "two-mass", "--json"]));
    let warnings: Vec<&str> = v["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(Value::as_str)
        .collect();
    let share = warnings
        .iter()
        .find(|w| w.contains("the fit uses segment"))
        .unwrap_or_else(|| panic!("no share warning: {warnings:?}"));
    assert!(
        share.starts_with(&format!("{c}: the fit uses segment "))
            && share.contains(" its time span covers; the rest lies in gaps")
            && share.contains("of the file's 2 gap-free segments"),
        "{share}"
    );
    let o = jointid(&["fit", c, "--model", "two-mass", "--strict"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));

    // the scrap as validation data (a variant): `fit --validation` printed a validation
    // FIT of 99.4 % on 96 samples (0.4 % of the file) and `validate` the same, exit 0,
    // neither naming the share
    let w = whole.to_str().unwrap();
    let m = dir.join("m.json");
    let v = json_of(&jointid(&[
        "fit",
        w,
        "--model",
        "three-mass",
        "--validation",
        g,
        "--save",
        m.to_str().unwrap(),
        "--json",
    ]));
    let warnings: Vec<&str> = v["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(Value::as_str)
        .collect();
    assert!(
        warnings.iter().any(
            |w| w.starts_with(&format!("{g}: the validation uses segment "))
                && w.contains(" its time span covers; the rest lies in gaps")
        ),
        "{warnings:?}"
    );
    let o = jointid(&["validate", m.to_str().unwrap(), g]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(
        stderr(&o).contains(&format!("note: {g}: the validation uses segment ")),
        "{}",
        stderr(&o)
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// An analysis refused for its periods names the file (a variant of issue 37 item 11):
/// `analyze` of a two-period capture (one whole period after the transient), or of a
/// gapped capture `--segment all --from 2p`, said only "1 whole period(s) of 5000 samples:
/// need at least 2 to estimate the noise".
#[test]
fn an_analysis_refused_for_its_periods_names_the_file() {
    let dir = tmpdir("analyze-periods");
    let cap = simulated(&dir, "two.csv", &["--model", "two-mass", "--periods", "2"]);
    refused(
        &["analyze", &cap],
        &[&format!(
            "jointid: error: {cap}: 1 whole period(s) of 5000 samples: need at least 2"
        )],
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
