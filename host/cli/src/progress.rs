//! The progress line of a command that reads or fits a large record: on standard error, a
//! spinner with the time since the step began and what runs (`reading run.csv (532 MB)`,
//! `fitting black-box:4 on 10004000 samples`), shown once a step has lasted
//! [`SHOW_AFTER`], so a quick command prints nothing. As `capture` and `diagnose` do, it
//! is hidden when standard error is not a terminal and with `--quiet`.
//!
//! One per process: a command calls [`start`] and names each step with [`step`]; a note
//! goes through [`clear`] first, so it never lands in the middle of the line; [`finish`]
//! (which [`crate::run`] calls after every command) removes it. `JOINTID_PROGRESS_AFTER_MS`
//! sets the delay in milliseconds in place of [`SHOW_AFTER`] (the tests show it at once).

use std::io::IsTerminal;
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressStyle};

/// How long a step runs before its line shows.
pub const SHOW_AFTER: Duration = Duration::from_secs(2);

/// How often the watcher looks whether a step's line is due.
const LOOK_EVERY: Duration = Duration::from_millis(100);

/// The step that runs, and its line once shown.
struct Step {
    what: String,
    since: Instant,
    after: Duration,
    bar: Option<ProgressBar>,
}

/// `None`: no progress (quiet, not a terminal, or no command running).
static STATE: Mutex<Option<Step>> = Mutex::new(None);

fn state() -> MutexGuard<'static, Option<Step>> {
    STATE.lock().unwrap_or_else(|e| e.into_inner())
}

/// Shows progress for the command that starts, unless `quiet` or standard error is not
/// a terminal.
pub fn start(quiet: bool) {
    if quiet || !std::io::stderr().is_terminal() {
        return;
    }
    let after = std::env::var("JOINTID_PROGRESS_AFTER_MS")
        .ok()
        .and_then(|v| v.parse().ok())
        .map_or(SHOW_AFTER, Duration::from_millis);
    let mut s = state();
    if s.is_some() {
        return;
    }
    *s = Some(Step {
        what: String::new(),
        since: Instant::now(),
        after,
        bar: None,
    });
    // the watcher ends with the command (`finish` leaves no state)
    std::thread::spawn(|| loop {
        std::thread::sleep(LOOK_EVERY);
        let mut s = state();
        let Some(step) = s.as_mut() else {
            return;
        };
        show_when_due(step);
    });
}

/// Shows the line of `step` when it has lasted long enough and is not shown yet.
fn show_when_due(step: &mut Step) {
    if step.bar.is_some() || step.what.is_empty() || step.since.elapsed() < step.after {
        return;
    }
    let bar = ProgressBar::new_spinner().with_elapsed(step.since.elapsed());
    if let Ok(style) = ProgressStyle::with_template("{spinner} {elapsed_precise} {msg}") {
        bar.set_style(style);
    }
    bar.set_message(format!("{} …", step.what));
    bar.enable_steady_tick(Duration::from_millis(200));
    step.bar = Some(bar);
}

/// `what` begins (the step before it ended): its line shows once it has lasted
/// [`SHOW_AFTER`].
pub fn step(what: impl Into<String>) {
    if let Some(s) = state().as_mut() {
        if let Some(bar) = s.bar.take() {
            bar.finish_and_clear();
        }
        s.what = what.into();
        s.since = Instant::now();
        // a delay of 0 shows it at once
        show_when_due(s);
    }
}

/// Removes the line, if shown, before something else is written to standard error; the
/// step goes on (its line shows again after [`SHOW_AFTER`]).
pub fn clear() {
    if let Some(s) = state().as_mut() {
        if let Some(bar) = s.bar.take() {
            bar.finish_and_clear();
        }
        s.since = Instant::now();
    }
}

/// The command's steps are over: the line goes, and no other shows.
pub fn finish() {
    if let Some(mut s) = state().take() {
        if let Some(bar) = s.bar.take() {
            bar.finish_and_clear();
        }
    }
}
