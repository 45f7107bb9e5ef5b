//! Progress of a running diagnosis, for the user who waits: each stage and each
//! candidate's fit reports when it starts and when it ends, from the thread that does the
//! work. The observer sees no result and changes none, so a diagnosis with one gives the
//! same answer as without.

use std::fmt;
use std::sync::Arc;
use std::time::Instant;

/// One step of a diagnosis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProgressEvent<'a> {
    /// a stage or a candidate's fit begins (`"nominal"`, `"backlash"`, …)
    Started(&'a str),
    /// it ended, with a short outcome (`"fitted"`, or why it failed)
    Finished(&'a str, &'a str),
}

/// The observer of a diagnosis's progress ([`crate::diagnose::DiagnoseRequest::progress`]).
#[derive(Clone)]
pub struct Progress(pub Arc<dyn Fn(ProgressEvent<'_>) + Send + Sync>);

impl Progress {
    /// An observer that calls `f`.
    pub fn new(f: impl Fn(ProgressEvent<'_>) + Send + Sync + 'static) -> Progress {
        Progress(Arc::new(f))
    }
}

impl fmt::Debug for Progress {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("Progress(..)")
    }
}

/// Observers never differ in what a request asks: two requests that differ only in their
/// observer are the same diagnosis.
impl PartialEq for Progress {
    fn eq(&self, _: &Progress) -> bool {
        true
    }
}

/// Reports that `what` started to `progress` (if any): a stage whose end the next report
/// marks.
pub(crate) fn started(progress: Option<&Progress>, what: &str) {
    if let Some(p) = progress {
        (p.0)(ProgressEvent::Started(what));
    }
}

/// Reports `what` started to `progress` (if any), runs `work`, and reports it finished
/// with the outcome `outcome` gives of the result and the seconds it took.
pub(crate) fn step<T>(
    progress: Option<&Progress>,
    what: &str,
    work: impl FnOnce() -> T,
    outcome: impl FnOnce(&T) -> String,
) -> T {
    let Some(p) = progress else {
        return work();
    };
    (p.0)(ProgressEvent::Started(what));
    let began = Instant::now();
    let out = work();
    let said = format!("{} ({:.1} s)", outcome(&out), began.elapsed().as_secs_f64());
    (p.0)(ProgressEvent::Finished(what, &said));
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    #[test]
    fn a_step_reports_its_start_and_its_outcome_and_returns_the_work() {
        let seen = Arc::new(Mutex::new(Vec::new()));
        let log = seen.clone();
        let p = Progress::new(move |e| {
            log.lock().unwrap().push(match e {
                ProgressEvent::Started(w) => format!("start {w}"),
                ProgressEvent::Finished(w, o) => {
                    format!("end {w}: {}", o.split(" (").next().unwrap())
                }
            })
        });
        let v = step(Some(&p), "nominal", || 41 + 1, |v| format!("got {v}"));
        assert_eq!(v, 42);
        assert_eq!(
            *seen.lock().unwrap(),
            ["start nominal", "end nominal: got 42"]
        );
        assert_eq!(step(None, "quiet", || 7, |_| unreachable!()), 7);
    }
}
