//! What a command reads and where it writes (hardening issue, item 10), run on the built
//! binary: a capture CSV whose comments state another rate than its time column is
//! refused naming both rates (it was read as a gap after every sample: "11999 gaps",
//! "--lags 25: … have 1 samples").

#[allow(dead_code)] // not every helper is used here
mod common;
use common::{jointid, simulated, tmpdir};

/// `jointid ARGS` must exit 2 with one line on standard error containing every one of
/// `msgs`; its text.
fn refused(args: &[&str], msgs: &[&str]) -> String {
    let o = jointid(args);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
    assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
    for m in msgs {
        assert!(err.contains(m), "{args:?}: `{m}` not in {err}");
    }
    err
}

/// The capture CSV `text` with its time column rewritten to `k · dt`.
fn retimed(text: &str, dt: f64) -> String {
    let mut k = 0;
    let mut header = false;
    let mut out = String::new();
    for line in text.lines() {
        if header && !line.starts_with('#') {
            let (_, rest) = line.split_once(',').unwrap();
            out.push_str(&format!("{},{rest}\n", k as f64 * dt));
            k += 1;
        } else {
            header |= line.starts_with("t,");
            out.push_str(line);
            out.push('\n');
        }
    }
    out
}

#[test]
fn a_capture_csv_whose_comments_state_another_rate_than_its_time_column_is_refused_naming_both() {
    let dir = tmpdir("rates");
    let run = simulated(&dir, "run.csv", &["--model", "two-mass", "--periods", "2"]);
    let text = std::fs::read_to_string(&run).unwrap();
    let line = 1 + text
        .lines()
        .position(|l| l.starts_with("# sample_interval_s=0.0005"))
        .unwrap();
    for (dt, column) in [
        (1e-3, "0.001 s apart (1000 Hz"),
        (2.5e-4, "0.00025 s apart (4000 Hz"),
    ] {
        let p = dir.join(format!("at-{dt}.csv"));
        std::fs::write(&p, retimed(&text, dt)).unwrap();
        let p = p.to_str().unwrap();
        let head = format!(
            "jointid: error: {p}:{line}: the comments give a sample interval of 0.0005 s (2000 \
             Hz), but the time column's samples are {column}, the median of its 13999 \
             intervals): one of them is wrong; correct `sample_interval_s` or the time column"
        );
        for args in [
            &["info", p][..],
            &["analyze", p][..],
            &["fit", p, "--model", "two-mass", "--lags", "25"][..],
        ] {
            assert_eq!(refused(args, &[]).trim_end(), head, "{args:?}");
        }
    }
    // the same file at its own rate reads
    let o = jointid(&["info", &run]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    std::fs::remove_dir_all(&dir).unwrap();
}
