//! Ctrl-C, SIGTERM and SIGHUP: the process's one handler (`ctrlc` takes one). An
//! interrupted command leaves no temporary file behind
//! ([`jointid::data::output::remove_temporaries`]) and ends with status 130; `capture`,
//! which stops cleanly on its own, asks for the first signal as a flag instead
//! ([`graceful`]), and a second one ends it at once as any other command.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Once;

/// Set by the first signal while a command stops on its own ([`graceful`]).
static INTERRUPTED: AtomicBool = AtomicBool::new(false);
/// A command that stops on its own runs ([`graceful`]).
static GRACEFUL: AtomicBool = AtomicBool::new(false);

/// Installs the handler, once per process (the binary's `main`; not the Python module,
/// whose own Ctrl-C handling stays). A handler installed by someone else before is kept.
pub fn install() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let _ = ctrlc::set_handler(on_signal);
    });
}

fn on_signal() {
    if GRACEFUL.load(Ordering::SeqCst) && !INTERRUPTED.swap(true, Ordering::SeqCst) {
        return;
    }
    // held until the process ends: no temporary file is made after these are gone
    let _held = jointid::data::output::remove_temporaries();
    std::process::exit(130);
}

/// For a command that stops cleanly on its own (`capture`): installs the handler and
/// returns the flag the first signal sets; a second signal ends the process at once.
pub fn graceful() -> &'static AtomicBool {
    install();
    GRACEFUL.store(true, Ordering::SeqCst);
    &INTERRUPTED
}
