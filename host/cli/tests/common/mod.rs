//! Helpers shared by the command-line test binaries (`capture_info_export_commands`,
//! `simulate_command`, `fit_validate_demo_commands`): a fresh scratch directory per test,
//! running the built `jointid` binary and reading its `--json` output.

use std::path::PathBuf;
use std::process::{Command, Output};

use serde_json::Value;

/// path of the `jointid` binary built for these tests
pub const BIN: &str = env!("CARGO_BIN_EXE_jointid");

/// Writes the record of `ds` into `dir/name` as any measured CSV: columns `time` [s],
/// `force` and `position`, no reference and no excitation header. The file's path.
#[allow(dead_code)]
pub fn open_loop_csv(dir: &std::path::Path, name: &str, ds: &jointid::data::Dataset) -> String {
    let mut s = String::from("time,force,position\n");
    for (k, (u, y)) in ds.data.u.iter().zip(&ds.data.y).enumerate() {
        s.push_str(&format!("{:e},{u:e},{y:e}\n", k as f64 * ds.data.ts));
    }
    let p = dir.join(name);
    std::fs::write(&p, s).unwrap();
    p.display().to_string()
}

/// empty scratch directory for one test, unique per test binary, process and `name`
pub fn tmpdir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "jointid-{}-{}-{name}",
        env!("CARGO_CRATE_NAME"),
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// runs `jointid` with `args` to completion
pub fn jointid(args: &[&str]) -> Output {
    Command::new(BIN).args(args).output().expect("run jointid")
}

/// runs `jointid` with `args` and `input` on its standard input, to completion
#[allow(dead_code)]
pub fn jointid_stdin(args: &[&str], input: &[u8]) -> Output {
    use std::io::Write;
    use std::process::Stdio;
    let mut child = Command::new(BIN)
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run jointid");
    let mut stdin = child.stdin.take().expect("jointid's standard input");
    // written from a thread: a large input would fill the pipe while jointid writes its
    // own output; a command that stops reading early closes the pipe (not an error here)
    let input = input.to_vec();
    let writer = std::thread::spawn(move || {
        let _ = stdin.write_all(&input);
    });
    let out = child.wait_with_output().expect("jointid's output");
    writer
        .join()
        .expect("the writer of jointid's standard input");
    out
}

/// runs `jointid` with `args`, killed after `limit`: its output, or `None` when it had to
/// be killed (a hang is a test failure, never a runaway process). Its output is read while
/// it runs, so a command that writes much never waits on a full pipe.
#[allow(dead_code)]
pub fn jointid_within(args: &[&str], limit: std::time::Duration) -> Option<Output> {
    use std::io::Read;
    let mut child = Command::new(BIN)
        .args(args)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("run jointid");
    let drain = |mut r: Box<dyn Read + Send>| {
        std::thread::spawn(move || {
            let mut b = Vec::new();
            let _ = r.read_to_end(&mut b);
            b
        })
    };
    let out = drain(Box::new(
        child.stdout.take().expect("jointid's standard output"),
    ));
    let err = drain(Box::new(
        child.stderr.take().expect("jointid's standard error"),
    ));
    let t0 = std::time::Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().expect("wait for jointid") {
            break Some(status);
        }
        if t0.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    let (stdout, stderr) = (
        out.join().unwrap_or_default(),
        err.join().unwrap_or_default(),
    );
    status.map(|status| Output {
        status,
        stdout,
        stderr,
    })
}

/// stdout of a successful run parsed as JSON; fails the test with the exit status and
/// stderr when the run failed
pub fn json_of(out: &Output) -> Value {
    assert!(
        out.status.success(),
        "status {:?}, stderr: {}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("stdout is JSON")
}

/// a file of `shared/` (the reference data beside the repository): the first ancestor of
/// this crate that holds it
///
/// # Panics
/// When no ancestor holds `shared/`.
#[allow(dead_code)]
pub fn shared(rel: &str) -> String {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .map(|a| a.join("shared"))
        .find(|d| d.is_dir())
        .expect("shared/ beside the repository")
        .join(rel)
        .display()
        .to_string()
}

/// `jointid simulate ARGS --out DIR/NAME --json`, the capture's path.
#[allow(dead_code)]
pub fn simulated(dir: &std::path::Path, name: &str, args: &[&str]) -> String {
    let out = dir.join(name);
    let mut all = vec!["simulate"];
    all.extend(args);
    all.extend(["--out", out.to_str().unwrap(), "--json"]);
    json_of(&jointid(&all));
    out.display().to_string()
}

/// `jointid simulate` of the three-mass joint with the default cubic spring into
/// `dir/name` (noise seed `seed`, excitation phases `exc_seed`): a capture whose hidden
/// effect `diagnose` must name. Returns its path.
#[allow(dead_code)]
pub fn stiffening_capture(dir: &std::path::Path, name: &str, seed: &str, exc_seed: &str) -> String {
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

/// `jointid ARGS` must exit 2 with one line on standard error containing every one of
/// `msgs`, and nothing on standard output; its text.
#[allow(dead_code)]
pub fn refused(args: &[&str], msgs: &[&str]) -> String {
    let o = jointid(args);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
    assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
    for m in msgs {
        assert!(err.contains(m), "{args:?}: `{m}` not in {err}");
    }
    assert!(o.stdout.is_empty(), "{args:?} wrote to standard output");
    err
}

/// A number that is not finite among the words of `text`: `NaN`, `inf`, `-inf`,
/// `Infinity` as a word of their own.
#[allow(dead_code)]
pub fn non_finite_word(text: &str) -> Option<String> {
    text.split(|c: char| !(c.is_ascii_alphanumeric() || "._+-".contains(c)))
        .map(|w| w.trim_start_matches(['+', '-']).to_ascii_lowercase())
        .find(|w| matches!(w.as_str(), "nan" | "inf" | "infinity" | "+inf" | "-nan"))
}
