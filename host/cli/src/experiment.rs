//! `jointid experiment`: seed 000 Table 2 on simulated IRB1400-like data, one table per
//! seed ([`jointid::scenario::paper::experiment`]: simulated runs through the simulated
//! board's wire and back, then the fits), and the mean FIT over the seeds.

use clap::Args;
use serde::Serialize;

use super::{print_json, CmdResult, Context, Outcome};
use jointid::data::Percent;
use jointid::scenario::paper::{experiment, write_table, ModelRow, Table};

/// Arguments of `jointid experiment`.
#[derive(Debug, Clone, Args)]
pub struct ExperimentArgs {
    /// seed of the first simulated experiment
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub seed: u64,
    /// number of experiments (seeds N, N+1, ...); the mean FIT is printed too
    #[arg(long, value_name = "K", default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=50))]
    pub runs: u64,
}

#[derive(Serialize)]
struct ExperimentReport {
    seeds: Vec<u64>,
    tables: Vec<Table>,
    /// one row per model, FIT averaged over the seeds
    mean_fit: Vec<MeanFit>,
}

/// A model's FIT averaged over the experiments [%].
#[derive(Serialize)]
struct MeanFit {
    model: String,
    fit_estimation: f64,
    fit_validation: f64,
}

/// Runs `jointid experiment`.
///
/// # Errors
/// Simulation, wire and fit errors.
pub fn run(args: &ExperimentArgs, ctx: &mut Context<'_>) -> CmdResult {
    let mut tables = Vec::new();
    let seeds: Vec<u64> = (0..args.runs).map(|i| args.seed + i).collect();
    for &seed in &seeds {
        let t = experiment(seed)?;
        if !ctx.json {
            writeln!(ctx.out, "experiment seed {seed}:")?;
            write_table(ctx.out, &t)?;
        }
        tables.push(t);
    }
    let mean = |f: &dyn Fn(&ModelRow) -> f64| -> Vec<(String, f64)> {
        (0..tables[0].rows.len())
            .map(|i| {
                let m = tables.iter().map(|t| f(&t.rows[i])).sum::<f64>() / tables.len() as f64;
                (tables[0].rows[i].model.clone(), m)
            })
            .collect()
    };
    let me = mean(&|r| r.fit_estimation);
    let mv = mean(&|r| r.fit_validation);
    if ctx.json {
        print_json(
            ctx.out,
            "experiment",
            &ExperimentReport {
                seeds,
                tables,
                mean_fit: me
                    .into_iter()
                    .zip(mv)
                    .map(|((model, e), (_, v))| MeanFit {
                        model,
                        fit_estimation: e,
                        fit_validation: v,
                    })
                    .collect(),
            },
        )?;
    } else if tables.len() > 1 {
        writeln!(ctx.out, "mean over {} experiments:", tables.len())?;
        for ((m, e), (_, v)) in me.iter().zip(&mv) {
            writeln!(
                ctx.out,
                "  {m:<14} est {:6.1}  val {:6.1}",
                Percent(*e),
                Percent(*v)
            )?;
        }
    }
    Ok(Outcome::Ok)
}
