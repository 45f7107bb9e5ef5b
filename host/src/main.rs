//! `jointid`: command-line entry point (placeholder dispatch until the `analysis` branch
//! lands the CLI skeleton).
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use jointid::cli;

#[derive(Parser)]
#[command(name = "jointid", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Record the board's stream into a .jcap capture
    Capture(cli::capture::CaptureArgs),
    /// Write a capture as the capture CSV
    Export(cli::export::ExportArgs),
    /// Show what a capture holds
    Info(cli::info::InfoArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result: anyhow::Result<u8> = match &cli.command {
        Command::Capture(a) => cli::capture::run(a).map_err(Into::into),
        Command::Export(a) => cli::export::run(a).map_err(Into::into),
        Command::Info(a) => cli::info::run(a).map_err(Into::into),
    };
    match result {
        Ok(code) => ExitCode::from(code),
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
