//! σ calibration of the frequency-domain fit for every structure and noise condition: per
//! parameter, `ratio/z_rms/within` (spread of the estimates over the median σ the fit
//! reports; RMS of the standardised errors; share within 3 σ), 1/1/≥ 99.7 % for honest σ.
//! The library's test checks the three-mass joint; this prints the whole table.
//!
//! Run: `cargo bench -p jointid --features test-support --bench sigma` (`SIGMA_RUNS=N` realisations per row,
//! default 30; `SIGMA_ONLY="TwoMass"` for the rows whose name holds it; `SIGMA_VERBOSE=1`
//! for each run's errors).

use std::time::Instant;

use jointid::model::spec::Structure;
use jointid::test_support::sigma::{sigma_calibration, table_row, Noise};

fn main() {
    let runs: u64 = std::env::var("SIGMA_RUNS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(30);
    let only = std::env::var("SIGMA_ONLY").unwrap_or_default();
    let verbose = std::env::var("SIGMA_VERBOSE").is_ok();
    println!("σ calibration, {runs} runs per row: parameter ratio/z_rms/within 3σ");
    for structure in [
        Structure::ThreeMass,
        Structure::TwoMass,
        Structure::FourMass,
    ] {
        for noise in [Noise::Default, Noise::Coloured, Noise::Disturbance10] {
            let row = format!("{structure:?} {noise:?}");
            if !only.is_empty() && !row.contains(&only) {
                continue;
            }
            let wall = Instant::now();
            let t = sigma_calibration(structure, noise, runs, 4, |line| {
                if verbose {
                    println!("{line}");
                }
            });
            println!(
                "{row}: {}  ({:.1} s)",
                table_row(&t),
                wall.elapsed().as_secs_f64()
            );
        }
    }
}
