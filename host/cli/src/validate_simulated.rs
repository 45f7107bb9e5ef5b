//! `jointid validate DATA --simulated COL`, the second form of `jointid validate`
//! ([`super::validate`] parses the command and hands this form over): FIT (toolbox
//! `compare` definition) and residual tests of a simulated output against measured data
//! (see [`jointid::ident::validate`]).
//!
//! The simulated output ŷ is a column of DATA or of another CSV with the same time column
//! (`--simulated-file`).

use std::io::Write;
use std::path::PathBuf;

use serde::Serialize;

use super::args::{DataArgs, PrepArgs};
use super::{print_json, CmdResult, Context, Outcome};
use jointid::data::{ColumnMap, Percent};
use jointid::ident::validate::{validate, CorrelationTest, Validation, FIT_NAME};

/// What `jointid validate DATA --simulated COL` compares: the measured data and the
/// column of the simulated output, from the flags of [`super::validate::ValidateArgs`].
#[derive(Debug, Clone)]
pub struct SimulatedColumn {
    /// measured data file and columns
    pub data: DataArgs,
    /// column holding the simulated output ŷ
    pub simulated: String,
    /// CSV holding the simulated column (default: DATA); same time column
    pub simulated_file: Option<PathBuf>,
    /// lags M of the residual tests
    pub lags: usize,
    /// preparation applied to measured and simulated data alike
    pub prep: PrepArgs,
}

#[derive(Serialize)]
struct Report<'a> {
    file: &'a str,
    simulated: &'a str,
    /// as `validate MODEL DATA --json`'s `residual_tests`
    #[serde(rename = "residual_tests")]
    validation: &'a Validation,
}

/// Runs `jointid validate DATA --simulated COL`.
///
/// # Errors
/// Loading, length mismatch and output errors.
pub fn run(args: &SimulatedColumn, ctx: &mut Context<'_>) -> CmdResult {
    let map = args.data.column_map();
    let ds = args.data.load(ctx.loaders)?;
    let sim_path = args
        .simulated_file
        .clone()
        .unwrap_or_else(|| args.data.path.clone());
    let sim_map = ColumnMap {
        time: map.time.clone(),
        input: args.simulated.clone(),
        output: args.simulated.clone(),
        reference: None,
        delimiter: map.delimiter,
    };
    // the same segment and window of the simulated file
    let sim = args.data.read.select_one(ctx.loaders, &sim_path, sim_map)?;
    let meas = args.prep.apply(&ds.data)?;
    let yhat = args.prep.apply(&sim.data)?.y;
    let v = validate(&meas.u, &meas.y, &yhat, args.lags)?;
    if ctx.json {
        print_json(
            ctx.out,
            "validate-simulated",
            &Report {
                file: &ds.name,
                simulated: &args.simulated,
                validation: &v,
            },
        )?;
    } else {
        writeln!(
            ctx.out,
            "jointid validate: {} (simulated: {})",
            ds.name, args.simulated
        )?;
        writeln!(ctx.out, "  {FIT_NAME}: {:.2}", Percent(v.fit))?;
        test_line(ctx.out, &v.whiteness)?;
        test_line(ctx.out, &v.independence)?;
        writeln!(
            ctx.out,
            "  result: {}",
            if v.pass { "pass" } else { "FAIL" }
        )?;
    }
    Ok(if v.pass {
        Outcome::Ok
    } else {
        Outcome::CheckFailed
    })
}

fn test_line(out: &mut dyn Write, t: &CorrelationTest) -> std::io::Result<()> {
    writeln!(
        out,
        "  {}: lags {}..{}, 99 % bound ±{:.4}, {} lag(s) outside {} {} allowed, max |r| {:.4}, ζ = {:.1} {} χ²({}) 99 % = {:.1}: {}",
        t.name,
        t.lags.first().copied().unwrap_or(0),
        t.lags.last().copied().unwrap_or(0),
        t.bound,
        t.outside,
        if t.outside <= t.allowed { "≤" } else { ">" },
        t.allowed,
        t.max_abs,
        t.statistic,
        if t.statistic <= t.critical { "≤" } else { ">" },
        t.dof,
        t.critical,
        super::print::verdict(t)
    )
}

#[cfg(test)]
mod tests {
    use super::super::{default_loaders, run as run_cli, Cli};
    use super::*;
    use clap::Parser;

    #[test]
    fn validate_reports_fit_and_fails_on_a_wrong_model() {
        let dir =
            std::env::temp_dir().join(format!("jointid-validate-simulated-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let csv = dir.join("v.csv");
        // y(t) = 0.8 u(t−1) + small white noise; `good` is the true model,
        // `bad` has the wrong gain
        let mut state = 7u64;
        let mut rnd = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        let u: Vec<f64> = (0..3000).map(|_| rnd()).collect();
        let mut text = String::from("time,force,pos,good,bad\n");
        for t in 0..3000 {
            let ytrue = if t > 0 { 0.8 * u[t - 1] } else { 0.0 };
            text.push_str(&format!(
                "{},{},{},{},{}\n",
                t as f64 * 0.01,
                u[t],
                ytrue + 0.01 * rnd(),
                ytrue,
                0.5 * ytrue
            ));
        }
        std::fs::write(&csv, text).unwrap();
        let loaders = default_loaders();
        let go = |col: &str, json: bool| {
            let mut argv = vec![
                "jointid",
                "validate",
                csv.to_str().unwrap(),
                "--time",
                "time",
                "--input",
                "force",
                "--output",
                "pos",
                "--simulated",
                col,
            ];
            if json {
                argv.push("--json");
            }
            let cli = Cli::try_parse_from(argv).unwrap();
            let mut buf = Vec::new();
            let r = run_cli(
                &cli,
                &mut Context {
                    json: cli.json,
                    loaders: &loaders,
                    out: &mut buf,
                    fitted: None,
                },
            )
            .unwrap();
            (r, String::from_utf8(buf).unwrap())
        };
        let (r, out) = go("good", false);
        assert_eq!(r, Outcome::Ok, "{out}");
        assert!(out.contains("FIT (toolbox compare, NRMSE) [%]: 9"), "{out}");
        let (r, out) = go("bad", true);
        assert_eq!(r, Outcome::CheckFailed, "{out}");
        let v: serde_json::Value = serde_json::from_str(&out).unwrap();
        assert_eq!(v["residual_tests"]["independence"]["pass"], false);
        assert!(v["residual_tests"]["fit"].as_f64().unwrap() < 60.0);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
