//! Output that cannot be written, run on the built binary: a full device (issue 13 item 6)
//! and a closed pipe (item 18).
//!
//! The full device is `/dev/full`, reached through a symlink in the test's scratch
//! directory, so that a writer that replaced its target (write a temporary file, rename
//! it over the target) would replace the symlink, never the device.

use std::fs::OpenOptions;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

#[allow(dead_code)] // not every helper is used here
mod common;
use common::{jointid, tmpdir, BIN};

/// a two-period simulated capture in `dir` (the fewest a fit takes)
fn capture(dir: &Path) -> PathBuf {
    let jcap = dir.join("run.jcap");
    let o = jointid(&[
        "simulate",
        "--model",
        "two-mass",
        "--periods",
        "2",
        "--out",
        jcap.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    jcap
}

/// `dir/name`, a symlink to `/dev/full`
fn full_link(dir: &Path, name: &str) -> PathBuf {
    let link = dir.join(name);
    std::os::unix::fs::symlink("/dev/full", &link).unwrap();
    link
}

/// runs `jointid args` with its standard output on `/dev/full`
fn to_dev_full(args: &[&str]) -> Output {
    let full = OpenOptions::new().write(true).open("/dev/full").unwrap();
    Command::new(BIN)
        .args(args)
        .stdout(full)
        .output()
        .expect("run jointid")
}

/// exit 2, one line on stderr naming `file` and the device being full, no panic
fn assert_write_error(o: &Output, file: &str, what: &str) {
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{what}: {err}");
    assert!(!err.contains("panicked"), "{what}: {err}");
    assert_eq!(err.lines().count(), 1, "{what}: {err}");
    assert!(err.contains(file), "{what}: {err}");
    assert!(err.contains("o space left on device"), "{what}: {err}");
}

#[test]
fn a_full_device_ends_every_writer_with_exit_2_naming_the_file() {
    let dir = tmpdir("full");
    let jcap = capture(&dir);
    let jcap = jcap.to_str().unwrap();

    let csv = full_link(&dir, "full.csv");
    let o = jointid(&["export", jcap, "--csv", csv.to_str().unwrap()]);
    assert_write_error(&o, csv.to_str().unwrap(), "export --csv");
    assert!(
        std::fs::symlink_metadata(&csv)
            .unwrap()
            .file_type()
            .is_symlink(),
        "export replaced its target instead of writing to it"
    );
    let o = jointid(&["--json", "export", jcap, "--csv", csv.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(
        v["error"].as_str().unwrap().contains(csv.to_str().unwrap()),
        "{v}"
    );

    let o = to_dev_full(&["export", jcap, "--csv", "-"]);
    assert_write_error(&o, "standard output", "export --csv -");
    let o = to_dev_full(&["info", jcap]);
    assert_write_error(&o, "standard output", "info");
    let o = to_dev_full(&["--json", "info", jcap]);
    assert_write_error(&o, "standard output", "info --json");
    let o = to_dev_full(&["--json", "info", "/nonexistent/x.jcap"]);
    assert_eq!(o.status.code(), Some(2), "{o:?}");
    assert!(!String::from_utf8_lossy(&o.stderr).contains("panicked"));

    let out = full_link(&dir, "sim.csv");
    let o = jointid(&["simulate", "--periods", "1", "--out", out.to_str().unwrap()]);
    assert_write_error(&o, out.to_str().unwrap(), "simulate --out .csv");
    let out = full_link(&dir, "sim.jcap");
    let o = jointid(&["simulate", "--periods", "1", "--out", out.to_str().unwrap()]);
    assert_write_error(&o, out.to_str().unwrap(), "simulate --out .jcap");
    let params = full_link(&dir, "params.json");
    let o = jointid(&[
        "simulate",
        "--periods",
        "1",
        "--out",
        dir.join("p.csv").to_str().unwrap(),
        "--params-out",
        params.to_str().unwrap(),
    ]);
    assert_write_error(&o, params.to_str().unwrap(), "simulate --params-out");
    let o = to_dev_full(&[
        "simulate",
        "--periods",
        "1",
        "--out",
        dir.join("s.csv").to_str().unwrap(),
    ]);
    assert_write_error(&o, "standard output", "simulate summary");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// runs `jointid args` with its standard output on a pipe whose reader reads `keep`
/// bytes and then closes it (`| head -c keep`)
fn to_closed_pipe(args: &[&str], keep: usize) -> (std::process::ExitStatus, String) {
    use std::io::Read;
    let mut child = Command::new(BIN)
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("run jointid");
    let mut stdout = child.stdout.take().unwrap();
    let mut head = vec![0u8; keep];
    stdout.read_exact(&mut head).unwrap();
    drop(stdout);
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    (o.status, err)
}

/// exit 0 or killed by SIGPIPE
fn assert_quiet_end(status: std::process::ExitStatus, what: &str) {
    use std::os::unix::process::ExitStatusExt;
    assert!(
        status.code() == Some(0) || status.signal() == Some(13),
        "{what}: {status:?}"
    );
}

#[test]
fn a_closed_pipe_ends_quietly_without_a_panic() {
    let dir = tmpdir("pipe");
    let jcap = capture(&dir);
    let jcap = jcap.to_str().unwrap();
    let sim = dir.join("sim.jcap");
    let cases: [(&[&str], usize); 6] = [
        (&["export", jcap, "--csv", "-"], 10),
        // the run written to the pipe in place, by its device's name
        (&["simulate", "--periods", "1", "--out", "/dev/stdout"], 10),
        (&["export", jcap, "--csv", "-"], 0),
        (&["--json", "info", jcap], 0),
        (&["info", jcap], 0),
        (
            &[
                "--json",
                "simulate",
                "--periods",
                "1",
                "--out",
                sim.to_str().unwrap(),
            ],
            0,
        ),
    ];
    for (args, keep) in cases {
        let (status, err) = to_closed_pipe(args, keep);
        assert!(err.is_empty(), "{args:?}: {err}");
        assert_quiet_end(status, &format!("{args:?} | head -c {keep}"));
    }
    // a command that fails still fails (its message goes to standard error when the pipe
    // is already gone)
    let (status, _) = to_closed_pipe(&["--json", "info", "/nonexistent/x.jcap"], 0);
    assert_eq!(status.code(), Some(2));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// the names in `dir`, sorted
fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// exit 2 with one line on stderr naming `file` as existing, and `file` untouched
fn assert_kept(o: &Output, file: &Path, what: &str) {
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{what}: {err}");
    assert_eq!(err.lines().count(), 1, "{what}: {err}");
    assert!(
        err.contains(&format!(
            "{}: already exists (pass --force to overwrite)",
            file.display()
        )),
        "{what}: {err}"
    );
    assert_eq!(std::fs::read_to_string(file).unwrap(), "precious", "{what}");
}

/// Issue item 15: one rule for every writer (as `capture`): an existing file is refused
/// without `--force`, and a failed step leaves no half-written output behind.
#[test]
fn every_writer_refuses_an_existing_file_without_force_and_leaves_nothing_half_written() {
    let dir = tmpdir("overwrite");
    let jcap = capture(&dir);
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let precious = |name: &str| {
        let p = dir.join(name);
        std::fs::write(&p, "precious").unwrap();
        p
    };
    // simulate --out (csv and jcap) and --params-out; the params file is checked before
    // the run, so --out is not written either
    for name in ["sim.csv", "sim.jcap"] {
        let p = precious(name);
        let o = jointid(&["simulate", "--periods", "1", "--out", &s(&p)]);
        assert_kept(&o, &p, name);
    }
    let params = precious("p.json");
    let fresh = dir.join("fresh.csv");
    let o = jointid(&[
        "simulate",
        "--periods",
        "1",
        "--out",
        &s(&fresh),
        "--params-out",
        &s(&params),
    ]);
    assert_kept(&o, &params, "--params-out");
    assert!(!fresh.exists());
    // export --csv
    let csv = precious("run.csv");
    let o = jointid(&["export", &s(&jcap), "--csv", &s(&csv)]);
    assert_kept(&o, &csv, "export");
    // fit --save: refused before any fitting
    let model = precious("m.json");
    let o = jointid(&[
        "fit",
        &s(&jcap),
        "--model",
        "two-mass",
        "--save",
        &s(&model),
    ]);
    assert_kept(&o, &model, "fit --save");
    // the plot directories' files
    let plots = dir.join("plots");
    std::fs::create_dir(&plots).unwrap();
    let svg = plots.join("frf.svg");
    std::fs::write(&svg, "precious").unwrap();
    let o = jointid(&["analyze", &s(&jcap), "--plot", &s(&plots)]);
    assert_kept(&o, &svg, "analyze --plot");
    assert_eq!(names(&plots), ["frf.svg"], "nothing written beside it");
    let bode = plots.join("bode.svg");
    std::fs::write(&bode, "precious").unwrap();
    let o = jointid(&[
        "fit",
        &s(&jcap),
        "--model",
        "two-mass",
        "--plot",
        &s(&plots),
    ]);
    assert_kept(&o, &bode, "fit --plot");
    let demo = dir.join("demo");
    std::fs::create_dir(&demo).unwrap();
    let est = demo.join("estimation.jcap");
    std::fs::write(&est, "precious").unwrap();
    let o = jointid(&["demo", "--out", &s(&demo)]);
    assert_kept(&o, &est, "demo");
    // with --force each is replaced
    let o = jointid(&["export", &s(&jcap), "--csv", &s(&csv), "--force"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(std::fs::read_to_string(&csv)
        .unwrap()
        .contains("t,theta_ref,u,theta_m"));
    let o = jointid(&[
        "simulate",
        "--periods",
        "1",
        "--out",
        &s(&dir.join("sim.csv")),
        "--params-out",
        &s(&params),
        "--force",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(std::fs::read_to_string(&params)
        .unwrap()
        .contains("\"plant\""));
    let three = dir.join("three.jcap");
    let o = jointid(&["simulate", "--periods", "3", "--out", &s(&three)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = jointid(&["analyze", &s(&three), "--plot", &s(&plots), "--force"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(std::fs::read_to_string(&svg).unwrap().starts_with("<svg"));
    // a failed step leaves nothing behind: no output, no temporary file
    let before = names(&dir);
    for out in ["diverged.csv", "diverged.jcap"] {
        let o = jointid(&[
            "simulate",
            "--effect",
            "nonlinear_stiffness:k3=-1e16",
            "--periods",
            "1",
            "--out",
            &s(&dir.join(out)),
            "--params-out",
            &s(&dir.join("diverged.json")),
        ]);
        assert_eq!(o.status.code(), Some(2));
    }
    assert_eq!(names(&dir), before);
    let _ = std::fs::remove_dir_all(&dir);
}

/// `jointid args`, its exit status, stderr and how long it ran.
fn timed(args: &[&str]) -> (Option<i32>, String, std::time::Duration) {
    let t0 = std::time::Instant::now();
    let o = jointid(args);
    let took = t0.elapsed();
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
        took,
    )
}

/// The README's promise for `--plot DIR`: checked before the work. A directory that cannot
/// be created (a file in the way, a read-only parent) or is not writable is refused at once
/// with exit 2, naming it, by `analyze`, `fit`, `validate` and `diagnose` (one helper,
/// `check_plot_files`). Before: a missing directory was created only after the work, so
/// `diagnose --plot` failed there after the whole diagnosis.
#[test]
fn every_plot_directory_that_cannot_take_the_figures_is_refused_before_the_work() {
    let dir = tmpdir("plot-dir");
    let s = |p: &Path| p.display().to_string();
    let jcap = capture(&dir);
    let model = dir.join("m.json");
    let o = jointid(&[
        "fit",
        &s(&jcap),
        "--model",
        "two-mass",
        "--save",
        &s(&model),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let commands = |plots: &Path| -> Vec<Vec<String>> {
        let (j, p) = (s(&jcap), s(plots));
        [
            vec!["analyze", &j, "--plot", &p],
            vec!["fit", &j, "--model", "two-mass", "--plot", &p],
            vec!["validate", &s(&model), &j, "--plot", &p],
            vec!["diagnose", &j, "--validation", &j, "--plot", &p],
        ]
        .into_iter()
        .map(|v| v.into_iter().map(String::from).collect())
        .collect()
    };
    let refused = |args: &[String], what: &str| {
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        let (code, err, took) = timed(&a);
        assert_eq!(code, Some(2), "{a:?}: {err}");
        assert_eq!(err.lines().count(), 1, "{a:?}: {err}");
        assert!(err.contains(what), "{a:?}: {err}");
        assert!(took.as_secs_f64() < 0.5, "{a:?}: refused after {took:?}");
    };
    // a file where the directory should be: for every user, root too
    let file = dir.join("a-file");
    std::fs::write(&file, "x").unwrap();
    let under_file = file.join("plots");
    for args in commands(&under_file) {
        refused(
            &args,
            &format!(
                "{}: cannot create the directory: not a directory",
                s(&under_file)
            ),
        );
    }
    // a read-only directory: its missing subdirectory cannot be made, nor a file written
    // into it (root writes anyway: then only the file case above is checked)
    use std::os::unix::fs::PermissionsExt;
    let ro = dir.join("read-only");
    std::fs::create_dir(&ro).unwrap();
    std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o555)).unwrap();
    let root = std::fs::write(ro.join("probe"), "x").is_ok();
    if !root {
        let missing = ro.join("plots");
        for args in commands(&missing) {
            refused(
                &args,
                &format!(
                    "{}: cannot create the directory: permission denied",
                    s(&missing)
                ),
            );
        }
        for args in commands(&ro) {
            refused(&args, &format!("directory {} is not writable", s(&ro)));
        }
    }
    std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o755)).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// Two outputs of one command naming the same file are refused before the work, even with
/// `--force` (issue 37 item 7, a variant): `simulate --out s.csv --params-out ./s.csv`
/// exited 0 with the capture replaced by the parameters (the check compared the
/// spellings), `export --csv x --mat ./x` kept the MAT-file only, `fit --plot d --save
/// d/bode.svg` and `diagnose --plot d --report d/fig-frf.svg` were refused only after the
/// work, having written one of the two, and with `--force` replaced one by the other.
#[test]
fn two_outputs_naming_one_file_are_refused_before_the_work() {
    let dir = tmpdir("same-output");
    let s = |p: &Path| p.display().to_string();
    let jcap = capture(&dir);
    let (j, d) = (s(&jcap), s(&dir));
    let plots = dir.join("plots");
    std::fs::create_dir(&plots).unwrap();
    let p = s(&plots);
    let cases: Vec<(Vec<String>, String, PathBuf)> = vec![
        (
            vec!["simulate", "--model", "two-mass", "--periods", "1"]
                .into_iter()
                .map(String::from)
                .chain([
                    "--out".into(),
                    format!("{d}/s.csv"),
                    "--params-out".into(),
                    format!("{d}/./s.csv"),
                ])
                .collect(),
            "s.csv: is both --out and --params-out: one would replace the other".into(),
            dir.join("s.csv"),
        ),
        (
            vec![
                "export".into(),
                j.clone(),
                "--csv".into(),
                format!("{d}/x.out"),
                "--mat".into(),
                format!(
                    "{d}/../{}/x.out",
                    dir.file_name().unwrap().to_str().unwrap()
                ),
            ],
            "x.out: is both --csv and --mat".into(),
            dir.join("x.out"),
        ),
        (
            ["fit", &j, "--model", "two-mass", "--plot", &p, "--save"]
                .into_iter()
                .map(String::from)
                .chain([format!("{p}/bode.svg")])
                .collect(),
            "bode.svg: is both --save and --plot's bode.svg".into(),
            plots.join("bode.svg"),
        ),
        (
            ["diagnose", &j, "--validation", &j, "--plot", &p, "--report"]
                .into_iter()
                .map(String::from)
                .chain([format!("{p}/fig-frf.svg")])
                .collect(),
            "fig-frf.svg: is both --report and --plot's fig-frf.svg".into(),
            plots.join("fig-frf.svg"),
        ),
    ];
    for (args, msg, file) in cases {
        for force in [false, true] {
            let mut a: Vec<&str> = args.iter().map(String::as_str).collect();
            if force {
                a.push("--force");
            }
            let (code, err, took) = timed(&a);
            assert_eq!(code, Some(2), "{a:?}: {err}");
            assert_eq!(err.lines().count(), 1, "{a:?}: {err}");
            assert!(err.contains(&msg), "{a:?}: {err}");
            assert!(took.as_secs_f64() < 0.5, "{a:?}: refused after {took:?}");
            assert!(!file.exists(), "{a:?} wrote {}", file.display());
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Starts `jointid args` and sends it `signal` (`TERM`, `INT`) as soon as the temporary
/// file of its output `out` (`.NAME.PID.tmp`) holds data; returns its exit code (`None`:
/// ended by the signal itself) and the names left in `dir`.
fn interrupted_while_writing(
    args: &[&str],
    out: &Path,
    signal: &str,
) -> (Option<i32>, Vec<String>) {
    let mut child = Command::new(BIN)
        .args(args)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let name = out.file_name().unwrap().to_str().unwrap();
    let tmp = out
        .parent()
        .unwrap()
        .join(format!(".{name}.{}.tmp", child.id()));
    let t0 = std::time::Instant::now();
    while std::fs::metadata(&tmp).map_or(0, |m| m.len()) == 0 {
        assert!(
            child.try_wait().unwrap().is_none(),
            "{args:?} ended before its temporary file held data: make the output larger"
        );
        assert!(
            t0.elapsed().as_secs() < 60,
            "no temporary file {}",
            tmp.display()
        );
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    let kill = Command::new("kill")
        .args([format!("-{signal}"), child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let status = child.wait().unwrap();
    (status.code(), names(out.parent().unwrap()))
}

/// Issue 37 item 5: SIGTERM during `simulate` and Ctrl-C during `export` remove the
/// temporary file being written (exit 130) and leave the output absent: nothing half
/// written, no hidden file of hundreds of megabytes.
#[test]
fn an_interrupted_writer_leaves_no_temporary_file() {
    let dir = tmpdir("interrupted");
    let big = dir.join("big.csv");
    let (code, left) = interrupted_while_writing(
        &[
            "simulate",
            "--periods",
            "2000",
            "--out",
            big.to_str().unwrap(),
        ],
        &big,
        "TERM",
    );
    assert_eq!((code, left), (Some(130), vec![]), "simulate after SIGTERM");
    // a capture of 5 million samples, whose CSV takes a while to write
    let jcap = dir.join("run.jcap");
    let o = jointid(&[
        "simulate",
        "--periods",
        "1000",
        "--out",
        jcap.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let csv = dir.join("run.csv");
    let (code, left) = interrupted_while_writing(
        &[
            "export",
            jcap.to_str().unwrap(),
            "--csv",
            csv.to_str().unwrap(),
        ],
        &csv,
        "INT",
    );
    assert_eq!(
        (code, left),
        (Some(130), vec!["run.jcap".to_string()]),
        "export after Ctrl-C"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Issue 37 item 5: a temporary file that a process which no longer runs left beside an
/// output (killed by SIGKILL, a power cut) is removed by the next run that writes that
/// output, with a note naming it, its size and the process; one of a running process is
/// left alone.
#[test]
fn a_stale_temporary_file_of_a_dead_process_is_removed_by_the_next_writer() {
    let dir = tmpdir("stale");
    let jcap = capture(&dir);
    // the id of a process that has ended
    let mut gone = Command::new("true").spawn().unwrap();
    gone.wait().unwrap();
    let stale = dir.join(format!(".run.csv.{}.tmp", gone.id()));
    std::fs::write(&stale, vec![b'x'; 4321]).unwrap();
    // and one of a process that runs: this test's
    let live = dir.join(format!(".run.csv.{}.tmp", std::process::id()));
    std::fs::write(&live, "still being written").unwrap();
    let csv = dir.join("run.csv");
    let o = jointid(&[
        "export",
        jcap.to_str().unwrap(),
        "--csv",
        csv.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains(&format!(
            "note: {}: removed, a temporary file of 4.32 kB left by process {}, which no longer runs",
            stale.display(),
            gone.id()
        )),
        "{err}"
    );
    assert_eq!(
        names(&dir),
        [
            format!(".run.csv.{}.tmp", std::process::id()),
            "run.csv".to_string(),
            "run.jcap".to_string()
        ]
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
