//! `jointid`: command-line entry point. Exit codes: 0 ok, 1 a check failed,
//! 2 error (printed on one line, or as `{"error": ...}` with `--json`).
use std::process::ExitCode;

use clap::Parser;
use jointid::cli::{default_loaders, run, Cli, Context};

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) if e.use_stderr() && std::env::args().any(|a| a == "--json") => {
            let text = e.render().to_string();
            let lines: Vec<&str> = text
                .lines()
                .map(str::trim)
                .take_while(|l| !l.starts_with("Usage:"))
                .filter(|l| !l.is_empty())
                .collect();
            let msg = lines.join(" ");
            println!(
                "{}",
                serde_json::json!({ "error": msg.trim_start_matches("error: ") })
            );
            return ExitCode::from(2);
        }
        Err(e) => e.exit(),
    };
    let loaders = default_loaders();
    let mut stdout = std::io::stdout().lock();
    let result = run(
        &cli,
        &mut Context {
            json: cli.json,
            loaders: &loaders,
            out: &mut stdout,
        },
    );
    // output closed early (`jointid analyze x.csv | head`): stop quietly
    if let Err(e) = &result {
        let mut cur: Option<&(dyn std::error::Error + 'static)> = Some(e.as_ref());
        while let Some(c) = cur {
            if c.downcast_ref::<std::io::Error>()
                .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
            {
                return ExitCode::SUCCESS;
            }
            cur = c.source();
        }
    }
    match result.map_err(anyhow::Error::from_boxed) {
        Ok(outcome) => ExitCode::from(outcome.code()),
        Err(e) => {
            // the chain, skipping causes the message already states
            let mut msg = e.to_string();
            for cause in e.chain().skip(1) {
                let c = cause.to_string();
                if !msg.contains(&c) {
                    msg = format!("{msg}: {c}");
                }
            }
            let msg = msg.replace('\n', " ");
            if cli.json {
                println!("{}", serde_json::json!({ "error": msg }));
            } else {
                eprintln!("jointid: error: {msg}");
            }
            ExitCode::from(2)
        }
    }
}
