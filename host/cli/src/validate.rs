//! `jointid validate`: two sources of the simulated output, one command.
//!
//! - `jointid validate MODEL.json DATA [--require-fit X]`: simulate a model
//!   saved by `jointid fit --save` on new data (prepared as at fitting:
//!   same decimation and detrending, initial state estimated as the
//!   toolbox's `compare` does; a physical model saved at the capture rate
//!   runs there and its output is decimated like the data,
//!   [`jointid::ident::fit::FitData`]), then FIT and the residual tests.
//! - `jointid validate DATA --simulated COL [--simulated-file FILE]`: the
//!   simulated output is a column ([`super::validate_simulated`]).
//!
//! Exit codes: 0 when it ran, whatever the residual verdicts (they are
//! reported, pass or fail: closed-loop data often fail the whiteness test
//! for a model that is still useful); 1 when the FIT or the residual is not
//! finite (the model's simulation diverged: `fit_ok` false, both residual
//! tests FAIL) or when `--require-fit X` was given and the FIT is below X;
//! 2 on any error.

use jointid::data::input::{input_name, path_text, read_input_text};
use jointid::data::output::io_msg;
use std::path::PathBuf;

use clap::Args;
use serde::Serialize;

use super::args::{check_columns, screen_for_fit, ColumnArgs, DataArgs, PrepArgs, ReadArgs};
use super::print::{print_notes, print_tests, share_warning, usable_segments};
use super::validate_simulated::{self, SimulatedColumn};
use super::views::{
    write_views, CompareRecord, Signals, Views, PERIODIC_COMPARED, VELOCITY_COMPARED, VIEW_FILES,
};
use super::{check_plot_files, print_json, print_written, CmdResult, Context, Outcome};
use jointid::data::segment::{longest_index, SegmentNotes, MIN_SEGMENT_SAMPLES};
use jointid::data::{IdData, InputTaken, Percent};
use jointid::ident::fit::{
    check_lags, velocity_record, FitData, FitMetric, SegmentJson, NL_FIT_NAME, VELOCITY_FIT_NAME,
};
use jointid::ident::frf::{analyze_dataset, analyze_segments};
use jointid::ident::grey_box::Output;
use jointid::ident::model_file::SavedModel;
use jointid::ident::nonlinear::{
    validate as nl_validate, validate_segments, NlOptions, NlValidation,
};
use jointid::ident::sml::{periodic_fit_percent, periodic_fit_signals, PERIODIC_FIT_NAME};
use jointid::ident::validate::{Validation, DEFAULT_LAGS, FIT_NAME};

/// Arguments of `jointid validate`, both forms (a model file, or a simulated column).
#[derive(Debug, Clone, Args)]
pub struct ValidateArgs {
    /// MODEL.json DATA (a model saved by `fit --save`), or DATA with --simulated; `-` for
    /// standard input
    #[arg(value_name = "FILE", num_args = 1..=2, required = true)]
    pub files: Vec<PathBuf>,
    /// the columns of DATA
    #[command(flatten)]
    pub columns: ColumnArgs,
    /// how to read DATA and which part to use
    #[command(flatten)]
    pub read: ReadArgs,
    /// column holding a simulated output ŷ (instead of a model file)
    #[arg(long, value_name = "COL")]
    pub simulated: Option<String>,
    /// CSV holding the simulated column (default: DATA)
    #[arg(long, value_name = "FILE", requires = "simulated")]
    pub simulated_file: Option<PathBuf>,
    /// lags M of the residual tests (DATA needs more than 2M samples after preparation)
    #[arg(long, value_name = "M", default_value_t = DEFAULT_LAGS,
          value_parser = super::args::parse_lags)]
    pub lags: usize,
    /// exit with 1 when the FIT [%] is below this
    #[arg(long, value_name = "X")]
    pub require_fit: Option<f64>,
    /// whole periods dropped as transient before the periodic FIT of a
    /// model fitted in the frequency domain (as `fit --settle-periods`)
    #[arg(long, value_name = "P", default_value_t = 1)]
    pub settle_periods: usize,
    /// preparation of DATA for --simulated (a model file carries its own)
    #[command(flatten)]
    pub prep: PrepArgs,
    /// write the toolbox's views of a linear model file into this directory: compare.svg
    /// (measured vs simulated output, FIT in the legend), resid.svg, pzmap.svg, step.svg
    #[arg(long, value_name = "DIR")]
    pub plot: Option<PathBuf>,
    /// replace the plot files when they exist
    #[arg(long)]
    pub force: bool,
    /// the axis is linear (force [N] → position [m]): the plots' units
    #[arg(long)]
    pub linear_axis: bool,
    /// the plots' units of input and output for other data, e.g. `V,m` (as `fit --units`)
    #[arg(long, value_name = "IN,OUT", value_parser = super::views::parse_units)]
    pub units: Option<(String, String)>,
}

/// The report's line for a model that reads its input as sampled ([`InputTaken`]).
const SAMPLED_LINE: &str =
    "the input taken as sampled (a signal that moves between its samples), as the model was fitted";

#[derive(Serialize)]
struct Report<'a> {
    model_file: String,
    model: &'a str,
    file: &'a str,
    samples: usize,
    ts: f64,
    fit_name: &'a str,
    /// how the data's input was read, as the model file says the model was fitted
    input: InputTaken,
    /// `toolbox`, `periodic` or `velocity` (as `fit --json`)
    fit_metric: &'a str,
    fit: f64,
    /// the toolbox FIT, also when `fit` is the periodic or the velocity one
    fit_toolbox: f64,
    fit_estimation: f64,
    require_fit: Option<f64>,
    fit_ok: bool,
    residual_tests: &'a Validation,
    /// with `--segment all` on a capture with gaps: each segment's FIT (`fit` pools them)
    segments: Vec<SegmentJson>,
    /// files written (`--plot`)
    files: Vec<String>,
}

/// Runs `jointid validate`.
///
/// # Errors
/// Loading, model-file, preparation and output errors.
pub fn run(args: &ValidateArgs, ctx: &mut Context<'_>) -> CmdResult {
    let data_args = |path: &PathBuf| DataArgs::new(path, &args.columns, &args.read);
    check_columns(&data_args(&args.files[0]))?;
    if args.plot.is_some() && args.simulated.is_some() {
        return Err(
            "--plot draws a model file's views: give MODEL.json DATA, not --simulated".into(),
        );
    }
    if let Some(sim) = &args.simulated {
        if args.files.len() != 1 {
            return Err("validate with --simulated takes one DATA file".into());
        }
        let a = SimulatedColumn {
            data: data_args(&args.files[0]),
            simulated: sim.clone(),
            simulated_file: args.simulated_file.clone(),
            lags: args.lags,
            prep: args.prep.clone(),
        };
        return validate_simulated::run(&a, ctx);
    }
    if args.files.len() != 2 {
        return Err(
            "validate needs MODEL.json DATA (a model saved by `jointid fit --save`), or DATA --simulated COL"
                .into(),
        );
    }
    let mpath = &args.files[0];
    let text =
        read_input_text(mpath).map_err(|e| format!("{}: {}", input_name(mpath), io_msg(&e)))?;
    let saved: SavedModel = serde_json::from_str(&text)
        .map_err(|e| format!("{}: not a jointid model file: {e}", input_name(mpath)))?;
    // the model's description says which engine simulates it
    let spec = saved
        .spec()
        .map_err(|e| format!("{}: {e}", input_name(mpath)))?;
    if spec.nonlinear() {
        if args.plot.is_some() {
            return Err(format!(
                "--plot: {} holds a model with effects; the views are drawn for linear models \
                 (`fit --effect ... --plot` draws the nonlinear fit's velocity)",
                input_name(mpath)
            )
            .into());
        }
        return run_nonlinear(args, ctx, &saved, mpath, &data_args(&args.files[1]));
    }
    if let Some(dir) = &args.plot {
        check_plot_files(dir, &VIEW_FILES, args.force)?;
    }
    let fitted = saved
        .to_fitted()
        .map_err(|e| format!("{}: {e}", input_name(mpath)))?;
    let sel = data_args(&args.files[1]).select(ctx.loaders)?;
    // data no simulation computes with refused as fit refuses them, a far spike noted
    let screened = screen_for_fit(&sel, &data_args(&args.files[1]).column_map(), "validation")?;
    print_notes(&screened.into_iter().collect::<Vec<_>>());
    // a FIT on a scrap of a damaged capture says little: the share it rests on, noted
    print_notes(
        &share_warning(&sel, "validation")
            .into_iter()
            .collect::<Vec<_>>(),
    );
    super::progress::step(format!(
        "validating on {} samples",
        sel.datasets.iter().map(|d| d.data.len()).sum::<usize>()
    ));
    let numbers = sel.segments.clone();
    // read as the model was fitted ([`InputTaken`])
    let mut segs: Vec<jointid::data::Dataset> = sel
        .datasets
        .into_iter()
        .map(|d| saved.input.capture(d))
        .collect();
    let longest = longest_index(&segs);
    let lens: Vec<usize> = segs.iter().map(|d| d.data.len()).collect();
    // the model runs at the rate it was fitted at: the capture rate (a physical model
    // with `decimate_output` > 1) or the capture rate decimated by the model's preparation
    let capture_ts = if saved.decimate_output > 1 {
        saved.ts
    } else {
        saved.ts / saved.prep.decimate.max(1) as f64
    };
    check_model_rate(&segs[longest], capture_ts, mpath)?;
    let ds_ts = segs[longest].data.ts;
    let periodic_model = saved.fit_name.as_deref() == Some(PERIODIC_FIT_NAME)
        && (fitted.ts - ds_ts).abs() <= 1e-9 * ds_ts;
    // a model fitted in the frequency domain is judged by the periodic
    // steady-state FIT on periodic data, as `fit` reported it; the
    // toolbox FIT (which drift and slow disturbances enter) stays beside it
    // (an unstable model has no periodic steady state: its FIT is NaN, never a number
    // read off a frequency response it never reaches; the rigid body's pole on z = 1 is
    // the integrator every physical model has)
    let steady = fitted.model.spectral_radius() <= 1.0 + 1e-9;
    let periodic_fit = |frf: &jointid::ident::frf::Frf| {
        if steady {
            periodic_fit_percent(frf, &fitted.model.freq_response(&frf.freq_hz))
        } else {
            f64::NAN
        }
    };
    let periodic_analysis = periodic_model
        .then(|| analyze_segments(&segs, args.settle_periods).ok())
        .flatten();
    let periodic = periodic_analysis.as_ref().map(|a| periodic_fit(&a.frf));
    // each segment's own, for the table
    let periodic_each: Vec<Option<f64>> = match periodic {
        Some(_) => segs
            .iter()
            .map(|d| {
                analyze_dataset(d, args.settle_periods)
                    .ok()
                    .map(|a| periodic_fit(&a.frf))
            })
            .collect(),
        None => Vec::new(),
    };
    // the records go into the model's prepared data (a long capture held once, not
    // twice: issue 37 item 9); `segs` keeps their names and rates
    // every selected segment (one unless --segment all on a capture with gaps), each
    // simulated with its own initial state; FIT and residual tests pooled over them
    let all: Vec<FitData> = segs
        .iter_mut()
        .map(|d| {
            FitData::from_owned(take_record(d), saved.prep).map_err(|e| format!("{}: {e}", d.name))
        })
        .collect::<Result<_, _>>()?;
    let ds = &segs[longest];
    let samples: usize = all.iter().map(|d| d.prepared().len()).sum();
    check_lags(args.lags, &ds.name, samples)?;
    let (v, each) = fitted
        .evaluate_segments(&all, args.lags)
        .map_err(|e| format!("{}: {e}", ds.name))?;
    let data = &all[0].prepared();
    // a model fitted on the motor velocity is judged by the velocity FIT, as `fit`
    // reported it (the angle's drift dominates the toolbox FIT)
    let velocity = if fitted.fit_metric == FitMetric::Velocity {
        Some(
            fitted
                .velocity_fit_segments(&all)
                .map_err(|e| format!("{}: {e}", ds.name))?,
        )
    } else {
        None
    };
    let segments: Vec<SegmentJson> = segs
        .iter()
        .zip(&numbers)
        .zip(&each)
        .enumerate()
        .map(|(i, ((_, &k), &f))| SegmentJson {
            segment: k,
            samples: lens[i],
            fit: match (&periodic, &velocity) {
                (Some(_), _) => periodic_each[i],
                (None, Some((_, vel))) => vel.get(i).copied(),
                (None, None) => Some(f),
            },
        })
        .collect();
    let (fit_name, fit) = match (periodic, &velocity) {
        (Some(f), _) => (PERIODIC_FIT_NAME, f),
        (None, Some((f, _))) => (VELOCITY_FIT_NAME, *f),
        (None, None) => (FIT_NAME, v.fit),
    };
    let mut files = Vec::new();
    if let Some(dir) = &args.plot {
        // the record drawn: the averaged period under the periodic FIT, else the longest
        // segment simulated under its toolbox FIT
        let i = (0..all.len())
            .max_by_key(|&i| (lens[i], usize::MAX - i))
            .unwrap_or(0);
        let periodic_record = periodic_analysis.as_ref().and_then(|a| {
            let g = fitted.model.freq_response(&a.frf.freq_hz);
            let (y, y_hat) = periodic_fit_signals(&a.frf, &g, a.layout.period)?;
            Some(CompareRecord {
                title: format!("data: {}", ds.name),
                ts: data.ts,
                y,
                y_hat,
                fit,
            })
        });
        let (record, fit_label, compared) = match periodic_record {
            Some(r) => (r, "periodic FIT", PERIODIC_COMPARED),
            None => {
                let d = &all[i];
                let title = if segs.len() > 1 {
                    format!("data: {} (segment {})", segs[i].name, numbers[i])
                } else {
                    format!("data: {}", ds.name)
                };
                if let Some((_, vel)) = &velocity {
                    let r = velocity_record(&fitted, d, title, vel[i])?;
                    (r, "velocity FIT", VELOCITY_COMPARED)
                } else {
                    let y_hat = fitted
                        .simulate_on(d)
                        .map_err(|e| format!("{}: {e}", segs[i].name))?;
                    let r = CompareRecord {
                        title,
                        ts: d.prepared().ts,
                        y: d.prepared().y.clone(),
                        y_hat,
                        fit: each[i],
                    };
                    (r, "FIT", "simulated")
                }
            }
        };
        let views = Views {
            fitted: &fitted,
            fit_label,
            compared,
            records: vec![record],
            compare_rate: compared == VELOCITY_COMPARED && fitted.output == Output::Angle,
            tests: vec![("data", &v)],
            signals: Signals::new(args.linear_axis, fitted.output, args.units.as_ref()),
            record_s: lens[longest] as f64 * ds.data.ts,
            file: &ds.name,
        };
        files = write_views(dir, &views, args.force)?
            .iter()
            .map(|p| path_text(p))
            .collect();
    }
    // a diverged simulation is never ok, with or without --require-fit
    let finite = fit.is_finite() && v.fit.is_finite() && v.whiteness.non_finite == 0;
    let fit_ok = finite && args.require_fit.is_none_or(|x| fit >= x);
    super::progress::finish();
    if ctx.json {
        print_json(
            ctx.out,
            "validate",
            &Report {
                model_file: input_name(mpath),
                model: &saved.model,
                file: &ds.name,
                samples,
                ts: data.ts,
                fit_name,
                input: saved.input,
                fit_metric: match (periodic, &velocity) {
                    (Some(_), _) => "periodic",
                    (None, Some(_)) => "velocity",
                    (None, None) => "toolbox",
                },
                fit,
                fit_toolbox: v.fit,
                fit_estimation: saved.fit_estimation,
                require_fit: args.require_fit,
                fit_ok,
                residual_tests: &v,
                segments,
                files,
            },
        )?;
    } else {
        let out = &mut *ctx.out;
        writeln!(out, "{}", title(mpath, &saved.model, &ds.name))?;
        writeln!(
            out,
            "  {} samples, Ts = {} s (decimation {})",
            samples,
            jointid::data::fmt_sig(data.ts, 4),
            saved.prep.decimate
        )?;
        if saved.input == InputTaken::Sampled {
            writeln!(out, "  {SAMPLED_LINE}")?;
        }
        writeln!(
            out,
            "  {fit_name}: {:.2} (estimation: {:.2})",
            Percent(fit),
            Percent(saved.fit_estimation)
        )?;
        // one headline FIT; the toolbox FIT beside it says what it measures
        if let Some(why) = match (periodic, &velocity) {
            (Some(_), _) => Some(
                "the whole record simulated from the measured input, drift and slow \
                 disturbances included; the headline averages whole periods at the excited lines",
            ),
            (None, Some(_)) => Some(
                "the motor angle simulated over the whole record, which its drift dominates; \
                 the headline compares the velocity",
            ),
            (None, None) => None,
        } {
            writeln!(
                out,
                "  for reference, {FIT_NAME}: {:.2} ({why})",
                Percent(v.fit)
            )?;
        }
        write_segments(out, fit_name, &segments)?;
        writeln!(out, "  residual tests (99 %):")?;
        print_tests(out, "data", &v)?;
        if !finite && v.whiteness.non_finite == 0 && !v.whiteness.statistic.is_finite() {
            // each residual finite, their squares summed beyond the largest f64
            writeln!(
                out,
                "  not ok: the model's simulated output on {} is too large to compute with: \
                 its residual's sums of squares overflow",
                ds.name
            )?;
        } else if !finite && v.whiteness.non_finite == 0 {
            writeln!(out, "  not ok: {fit_name} is undefined on {}", ds.name)?;
        } else if !finite {
            writeln!(
                out,
                "  not ok: the model's simulated output is not finite on {} ({} of {} residual samples NaN or infinite)",
                ds.name,
                v.whiteness.non_finite,
                data.len()
            )?;
        }
        required_fit_line(out, args.require_fit, fit_ok)?;
        print_written(out, &files)?;
    }
    Ok(outcome(fit_ok))
}

#[derive(Serialize)]
struct NlReport<'a> {
    model_file: String,
    model: &'a str,
    file: &'a str,
    samples: usize,
    ts: f64,
    fit_name: &'a str,
    /// how the records' input was read, as the model was fitted
    input: InputTaken,
    /// velocity FIT with the simulator's exact laws [%]
    fit: f64,
    fit_estimation: f64,
    require_fit: Option<f64>,
    fit_ok: bool,
    /// the three FITs of the model on DATA (pooled over the segments)
    validation: NlValidation,
    /// with `--segment all` on a capture with gaps: each segment's velocity FIT (`fit`
    /// pools them)
    segments: Vec<SegmentJson>,
}

/// The samples of `d`, taken out of it (its name, rate and metadata stay).
fn take_record(d: &mut jointid::data::Dataset) -> IdData {
    IdData {
        ts: d.data.ts,
        u: std::mem::take(&mut d.data.u),
        y: std::mem::take(&mut d.data.y),
        r: d.data.r.take(),
    }
}

/// `ds` is sampled at the rate `model_ts` [s] the model in `mpath` was fitted at.
fn check_model_rate(
    ds: &jointid::data::Dataset,
    model_ts: f64,
    mpath: &std::path::Path,
) -> Result<(), String> {
    if jointid::data::same_rate(ds.data.ts, model_ts) {
        return Ok(());
    }
    Err(format!(
        "{}: sampled at {} Hz, the model {} was fitted on data at {} Hz",
        ds.name,
        jointid::data::fmt_sig(1.0 / ds.data.ts, 6),
        input_name(mpath),
        jointid::data::fmt_sig(1.0 / model_ts, 6)
    ))
}

/// `validate MODEL.json DATA` for a model with effects (format 3's `nonlinear` section):
/// simulated from the measured torque with the simulator's exact laws
/// ([`jointid::ident::nonlinear::validate`]); the same FITs `fit` reports, the same exit
/// codes as for a linear model. With `--segment all` on a capture with gaps every segment
/// of [`MIN_SEGMENT_SAMPLES`] or more (those `fit` takes) is simulated from its own first
/// angle, the FITs pooled over them ([`validate_segments`]) and given per segment.
fn run_nonlinear(
    args: &ValidateArgs,
    ctx: &mut Context<'_>,
    saved: &SavedModel,
    mpath: &std::path::Path,
    data: &DataArgs,
) -> CmdResult {
    let fit = saved
        .to_nonlinear()
        .map_err(|e| format!("{}: {e}", input_name(mpath)))?;
    let nl = saved.nonlinear.as_ref().expect("a nonlinear section");
    let sel = data.select(ctx.loaders)?;
    let screened = screen_for_fit(&sel, &data.column_map(), "validation")?;
    print_notes(&screened.into_iter().collect::<Vec<_>>());
    print_notes(
        &share_warning(&sel, "validation")
            .into_iter()
            .collect::<Vec<_>>(),
    );
    let (segs, numbers) = if sel.datasets.len() > 1 {
        let name = sel.datasets[0].name.clone();
        let mut all = sel.datasets;
        let (segs, numbers) = usable_segments(&mut all, &sel.segments, &name, VALIDATING_NOTES);
        if segs.is_empty() {
            return Err(format!(
                "{name}: no segment has {MIN_SEGMENT_SAMPLES} samples or more to validate on"
            )
            .into());
        }
        (segs, numbers)
    } else {
        (sel.datasets, sel.segments)
    };
    let longest = longest_index(&segs);
    check_model_rate(&segs[longest], saved.ts, mpath)?;
    let opts = NlOptions {
        highpass_hz: nl.highpass_hz,
        ..NlOptions::default()
    };
    // the records taken out of the selection (a long capture held once, not twice: issue
    // 37 item 9); `segs` keeps their names and rates
    let mut segs = segs;
    // read as the model was fitted: a model fitted on its input taken as sampled lags by
    // half a sample on the input held as it is
    let records: Vec<IdData> = segs
        .iter_mut()
        .map(take_record)
        .map(|r| saved.input.record(r))
        .collect();
    let ds = &segs[longest];
    super::progress::step(format!(
        "validating on {} samples",
        records.iter().map(IdData::len).sum::<usize>()
    ));
    let v = validate_segments(&fit, &records, &opts).map_err(|e| format!("{}: {e}", ds.name))?;
    let segments: Vec<SegmentJson> = if segs.len() > 1 {
        segs.iter()
            .zip(&records)
            .zip(&numbers)
            .map(|((d, r), &k)| {
                nl_validate(&fit, r, &opts)
                    .map(|each| SegmentJson {
                        segment: k,
                        samples: r.len(),
                        fit: Some(each.velocity_fit_percent),
                    })
                    .map_err(|e| format!("{} segment {k}: {e}", d.name))
            })
            .collect::<Result<_, _>>()?
    } else {
        vec![SegmentJson {
            segment: numbers[0],
            samples: records[longest].len(),
            fit: Some(v.velocity_fit_percent),
        }]
    };
    let samples: usize = records.iter().map(IdData::len).sum();
    let fit_pct = v.velocity_fit_percent;
    let fit_name = saved.fit_name.as_deref().unwrap_or(NL_FIT_NAME);
    let finite = fit_pct.is_finite();
    let fit_ok = finite && args.require_fit.is_none_or(|x| fit_pct >= x);
    super::progress::finish();
    if ctx.json {
        print_json(
            ctx.out,
            "validate-nonlinear",
            &NlReport {
                model_file: input_name(mpath),
                model: &saved.model,
                file: &ds.name,
                samples,
                ts: ds.data.ts,
                fit_name,
                input: saved.input,
                fit: fit_pct,
                fit_estimation: saved.fit_estimation,
                require_fit: args.require_fit,
                fit_ok,
                validation: v,
                segments,
            },
        )?;
    } else {
        let out = &mut *ctx.out;
        writeln!(out, "{}", title(mpath, &saved.model, &ds.name))?;
        writeln!(
            out,
            "  {} samples, Ts = {} s; simulated from the measured torque with the simulator's exact laws",
            samples,
            jointid::data::fmt_sig(ds.data.ts, 4)
        )?;
        if saved.input == InputTaken::Sampled {
            writeln!(out, "  {SAMPLED_LINE}")?;
        }
        writeln!(
            out,
            "  {fit_name}: {:.2} (estimation: {:.2})",
            Percent(fit_pct),
            Percent(saved.fit_estimation)
        )?;
        writeln!(
            out,
            "  for reference, velocity FIT with the estimator's smooth laws [%]: {:.2} (the \
             fit's own cost; the headline simulates the exact laws)",
            Percent(v.velocity_fit_smooth_percent)
        )?;
        writeln!(
            out,
            "  for reference, motor-angle FIT [%] (toolbox compare, exact laws, unfiltered): \
             {:.2} (the angle sums every slow error of the velocity, drift included{})",
            Percent(v.angle_fit_percent),
            if nl.highpass_hz > 0.0 {
                format!(
                    "; the headline's velocity is high-passed at {} Hz",
                    jointid::data::fmt_sig(nl.highpass_hz, 3)
                )
            } else {
                String::new()
            }
        )?;
        write_segments(out, fit_name, &segments)?;
        if !finite {
            writeln!(
                out,
                "  not ok: the model's simulated velocity is not finite on {}",
                ds.name
            )?;
        }
        required_fit_line(out, args.require_fit, fit_ok)?;
    }
    Ok(outcome(fit_ok))
}

/// The notes of a nonlinear validation over several segments ([`usable_segments`]).
const VALIDATING_NOTES: SegmentNotes = SegmentNotes {
    leaving: |left| {
        format!(
            "the validation leaves out {left}: shorter than {MIN_SEGMENT_SAMPLES} samples, as \
             the nonlinear fit does"
        )
    },
    using: |list| {
        format!(
            "validating on segments {list}, each simulated from its own first angle, the FITs \
             pooled over them"
        )
    },
};

/// The `--require-fit` line of the text report, when one was asked for.
fn required_fit_line(
    out: &mut dyn std::io::Write,
    required: Option<f64>,
    fit_ok: bool,
) -> std::io::Result<()> {
    if let Some(x) = required {
        writeln!(
            out,
            "  required FIT {x:.2}: {}",
            if fit_ok { "met" } else { "NOT met" }
        )?;
    }
    Ok(())
}

/// The command's outcome from whether the FIT checks held.
fn outcome(fit_ok: bool) -> Outcome {
    if fit_ok {
        Outcome::Ok
    } else {
        Outcome::CheckFailed
    }
}

/// The first line of the text report: `jointid validate: MODEL (FAMILY) on DATA`.
fn title(mpath: &std::path::Path, model: &str, data: &str) -> String {
    format!(
        "jointid validate: {} ({model}) on {data}",
        input_name(mpath)
    )
}

/// The per-segment FITs under the pooled ones, when there are several segments.
fn write_segments(
    out: &mut dyn std::io::Write,
    fit_name: &str,
    segments: &[SegmentJson],
) -> std::io::Result<()> {
    if segments.len() > 1 {
        writeln!(
            out,
            "  {fit_name} per segment (the figures above pool them):"
        )?;
        for sg in segments {
            writeln!(out, "    {sg}")?;
        }
    }
    Ok(())
}
