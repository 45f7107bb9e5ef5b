//! `jointid`: the command line of the `jointid` library (the commands live in the
//! `jointid_cli` library, [`jointid_cli::run`]). Exit codes 0 ok, 1 a check failed, 2
//! error (printed on one line, or as `{"error": ...}` with `--json`).

use std::io::Write;
use std::process::ExitCode;

use clap::Parser;
use jointid_cli::{
    default_loaders, error_json, error_message, is_broken_pipe, parse_error_message, run, Cli,
    Context,
};

/// The binary's standard output: every write and flush error names it ("standard
/// output: ..."), keeping the error's kind (a closed pipe is still
/// [`std::io::ErrorKind::BrokenPipe`]).
struct StdOut<W>(W);

impl<W: Write> StdOut<W> {
    fn named(e: std::io::Error) -> std::io::Error {
        let mut msg = e.to_string();
        if let Some(i) = msg.find(" (os error ") {
            msg.truncate(i);
        }
        std::io::Error::new(e.kind(), format!("standard output: {msg}"))
    }
}

impl<W: Write> Write for StdOut<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.write(buf).map_err(Self::named)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.0.flush().map_err(Self::named)
    }
}

/// Prints one line of the program's own (an error) on standard output, or on standard
/// error when standard output cannot take it; never panics.
fn print_line_stdout(line: &str) {
    let mut out = std::io::stdout().lock();
    if writeln!(out, "{line}").and_then(|()| out.flush()).is_err() {
        let _ = writeln!(std::io::stderr(), "{line}");
    }
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) if e.use_stderr() && std::env::args().any(|a| a == "--json") => {
            print_line_stdout(&error_json(&parse_error_message(&e)));
            return ExitCode::from(2);
        }
        Err(e) => e.exit(),
    };
    jointid_cli::interrupt::install();
    let loaders = default_loaders();
    let mut stdout = StdOut(std::io::stdout().lock());
    let mut result = run(
        &cli,
        &mut Context {
            json: cli.json,
            loaders: &loaders,
            out: &mut stdout,
            fitted: None,
        },
    );
    // what is still buffered must reach the output too: a failed flush is an error
    if let Err(e) = stdout.flush() {
        if result.is_ok() {
            result = Err(e.into());
        }
    }
    drop(stdout);
    // temporary files of earlier runs that were killed, removed on the way
    if !cli.json {
        for stale in jointid::data::output::take_stale_removed() {
            let _ = writeln!(std::io::stderr(), "note: {stale}");
        }
    }
    // output closed early (`jointid analyze x.csv | head`): stop quietly
    if let Err(e) = &result {
        if is_broken_pipe(e.as_ref()) {
            return ExitCode::SUCCESS;
        }
    }
    match result {
        Ok(outcome) => ExitCode::from(outcome.code()),
        Err(e) => {
            let msg = error_message(e);
            if cli.json {
                print_line_stdout(&error_json(&msg));
            } else {
                let _ = writeln!(std::io::stderr(), "jointid: error: {msg}");
            }
            ExitCode::from(2)
        }
    }
}
