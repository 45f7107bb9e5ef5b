//! The progress line on large inputs (issue 37 item 9): on a terminal, `fit`, `analyze`
//! and `validate` name the step that runs (reading the file, the fit) on standard error
//! once it has lasted 2 s; never on a pipe, never with `--quiet`. The terminal is a pty of
//! `script` (util-linux); `JOINTID_PROGRESS_AFTER_MS=0` shows each step at once, so the
//! test does not depend on the machine's speed.

#[allow(dead_code)] // not every helper is used here
mod common;
use common::{simulated, tmpdir, BIN};

/// What `jointid ARGS` writes to its standard error on a terminal (standard output goes
/// to a file), the line shown at once.
fn on_a_terminal(args: &[&str], out: &std::path::Path) -> String {
    let cmd = format!(
        "JOINTID_PROGRESS_AFTER_MS=0 {BIN} {} > {}",
        args.join(" "),
        out.display()
    );
    let o = std::process::Command::new("script")
        .args(["-qec", &cmd, "/dev/null"])
        .output()
        .expect("`script` (util-linux) gives the command a terminal");
    assert!(o.status.success(), "{cmd}: {o:?}");
    String::from_utf8_lossy(&o.stdout).into_owned()
}

#[test]
fn a_long_step_shows_a_progress_line_on_a_terminal_only() {
    let dir = tmpdir("progress");
    let data = simulated(&dir, "run.csv", &["--model", "two-mass", "--periods", "3"]);
    let out = dir.join("out.txt");
    let shown = on_a_terminal(&["fit", &data, "--model", "black-box:4"], &out);
    assert!(shown.contains(&format!("reading {data} (")), "{shown}");
    assert!(shown.contains("fitting black-box:4 on "), "{shown}");
    // the result itself is whole on standard output
    let result = std::fs::read_to_string(&out).unwrap();
    assert!(result.starts_with("jointid fit: black-box:4"), "{result}");
    let shown = on_a_terminal(&["analyze", &data], &out);
    assert!(shown.contains("analysing "), "{shown}");
    // info reads the file too (a variant of item 9: a 532 MB CSV took 3 s in silence)
    let shown = on_a_terminal(&["info", &data], &out);
    assert!(shown.contains(&format!("reading {data} (")), "{shown}");
    // --quiet: nothing of it
    for args in [
        vec!["fit", &data, "--model", "black-box:4", "--quiet"],
        vec!["analyze", &data, "-q"],
        vec!["info", &data, "--quiet"],
    ] {
        let shown = on_a_terminal(&args, &out);
        assert!(
            !shown.contains("reading") && !shown.contains('…'),
            "{args:?}: {shown}"
        );
    }
    // a pipe: nothing either, even at once
    let o = std::process::Command::new(BIN)
        .args(["fit", &data, "--model", "black-box:4"])
        .env("JOINTID_PROGRESS_AFTER_MS", "0")
        .output()
        .unwrap();
    assert!(o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!err.contains("reading") && !err.contains('…'), "{err}");
}
