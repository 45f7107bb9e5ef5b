//! `jointid diagnose EST [EST2] --validation VAL`: which unmodelled effect makes the
//! simulated joint depart from the measured one ([`jointid::diagnose`]): the nominal
//! physical model fitted on EST, each candidate effect added and refitted, ranked by the
//! gain of the band-passed motor-velocity FIT on VAL with a significance test over
//! segments, and where the nominal's residual lies. With `--segment all` every capture
//! comes as its gap-free segments ([`jointid::diagnose::diagnose_segments`]).

use std::collections::BTreeMap;
use std::io::{IsTerminal, Write};
use std::path::PathBuf;

use clap::Args;

use super::args::{check_same_rate, screen_for_fit, ColumnArgs, DataArgs, ReadArgs};
use super::print::usable_segments;
use super::{check_plot_files, print_json, print_written, write_svg, CmdResult, Context, Outcome};
use jointid::data::input::path_text;
use jointid::data::output::{check_distinct, check_output, write_file};
use jointid::data::segment::{SegmentNotes, MIN_SEGMENT_SAMPLES};
use jointid::data::{Dataset, Percent};
use jointid::diagnose::{
    diagnose_segments, DiagnoseError, DiagnoseRequest, Diagnosis, Progress, ProgressEvent, UserSim,
};
use jointid::ident::grey_box::DEFAULT_GEAR_RATIO;
use jointid::ident::model_file::SavedModel;
use jointid::ident::nonlinear::sim_plant;
use jointid::model::effects::{parse_given, Effect};
use jointid::model::spec::{Family, ModelSpec, Structure};
use jointid::report::html::{diagnosis_figures, diagnosis_html, FIGURE_IDS, MAX_PANELS};
use jointid::sim::SimConfig;

/// Arguments of `jointid diagnose`.
#[derive(Debug, Clone, Args)]
pub struct DiagnoseArgs {
    /// estimation capture: a .jcap capture, a capture CSV, or any CSV or MAT-file with
    /// --time/--input/--output
    #[arg(value_name = "EST")]
    pub path: PathBuf,
    /// the columns of every capture (EST, EST2 and VAL alike)
    #[command(flatten)]
    pub columns: ColumnArgs,
    /// how to read the captures and which part to use
    #[command(flatten)]
    pub read: ReadArgs,
    /// a second estimation capture at another amplitude (amplitude analysis)
    #[arg(value_name = "EST2")]
    pub second: Option<PathBuf>,
    /// validation capture (same columns), on which every candidate is scored
    #[arg(long, value_name = "VAL")]
    pub validation: PathBuf,
    /// the user's simulation: `simulate --params-out` output or a jointid model file (`-`
    /// for standard input)
    #[arg(long, value_name = "SIM.json", conflicts_with = "model")]
    pub sim: Option<PathBuf>,
    /// the axis is linear (force [N] → position [m]): the report's units kg, N·s/m, N, N/m,
    /// m, m/s
    #[arg(long)]
    pub linear_axis: bool,
    /// structure of the nominal model, as `fit --model`: rigid, two-mass, three-mass,
    /// four-mass, grounded (default: the --sim file's, else three-mass, or grounded with a
    /// note when the data show a mass on a spring to the frame)
    #[arg(long, value_name = "STRUCTURE")]
    pub model: Option<String>,
    /// candidate effect, repeatable, spelled as `fit --effect` and `simulate --effect`:
    /// `name` or `name:key=value,...` (names: coulomb_friction, backlash,
    /// nonlinear_stiffness, extra_mode, time_delay, torque_ripple), or `all` (the
    /// default). A value given is where that candidate's fit starts, as in `fit` (a ripple's
    /// `order` is taken as given); a pair starts from its singles' fits. One flag may list
    /// several, comma-separated (`--effect backlash,coulomb_friction:fc=0.1`)
    #[arg(
        long = "effect",
        visible_alias = "effects",
        value_name = "SPEC",
        value_parser = clap::builder::NonEmptyStringValueParser::new()
    )]
    pub effects: Vec<String>,
    /// gear ratio r = arm angle / motor angle
    #[arg(long, value_name = "R", default_value_t = DEFAULT_GEAR_RATIO)]
    pub gear_ratio: f64,
    /// write the report as one self-contained HTML file (verdict, figures, candidates)
    #[arg(long, value_name = "REPORT.html")]
    pub report: Option<PathBuf>,
    /// write the report's figures as SVG files into DIR (created when missing)
    #[arg(long, value_name = "DIR")]
    pub plot: Option<PathBuf>,
    /// replace the report and the SVG files when they exist
    #[arg(long)]
    pub force: bool,
    /// exit 1 when the diagnosis names no effect because its nominal is not to be trusted
    /// (it does not describe the validation data)
    #[arg(long)]
    pub strict: bool,
}

/// The effect specs of `--effect` flags: each flag's value split on commas, an item that
/// is only `key=value` continuing the spec before it (`backlash,coulomb_friction:fc=0.1,
/// fs=0.2` is two specs), `all` replaced by every effect's name; none given: all.
fn effect_specs(flags: &[String]) -> Vec<String> {
    let mut specs: Vec<String> = Vec::new();
    for item in flags.iter().flat_map(|f| f.split(',')).map(str::trim) {
        match specs.last_mut() {
            Some(last) if !item.contains(':') && item.contains('=') => {
                last.push(',');
                last.push_str(item);
            }
            _ if item.is_empty() => {}
            _ => specs.push(item.to_string()),
        }
    }
    if specs.is_empty() {
        specs.push("all".into());
    }
    specs
        .into_iter()
        .flat_map(|s| {
            if s == "all" {
                Effect::all_defaults()
                    .iter()
                    .map(|e| e.name().to_string())
                    .collect()
            } else {
                vec![s]
            }
        })
        .collect()
}

/// What `--model` and `--effect` ask for: the nominal structure (`None`: not given) and
/// the candidates, with the values each candidate's spec gives.
type Resolved = (
    Option<Structure>,
    Vec<Effect>,
    BTreeMap<String, Vec<(String, f64)>>,
);

/// The nominal structure and the candidates, resolved from `--model` and `--effect` as
/// `fit` resolves its model flags ([`ModelSpec::resolve`]), with the values each
/// candidate's spec gives ([`parse_given`]).
fn resolve(model: Option<&str>, flags: &[String]) -> Result<Resolved, String> {
    let family = match model {
        Some(m) => m.parse::<Family>().map_err(|e| format!("--model: {e}"))?,
        None => Family::Physical(Structure::ThreeMass),
    };
    let specs = effect_specs(flags);
    let spec =
        ModelSpec::resolve(family, false, &specs, false, None, None).map_err(|e| e.to_string())?;
    let structure = spec.family.structure().ok_or_else(|| {
        format!(
            "--model {}: diagnose fits a physical model ({})",
            spec.family.name(),
            Structure::ALL.map(Structure::label).join(", ")
        )
    })?;
    let candidates = spec.effects.unwrap_or_default();
    if candidates.is_empty() {
        return Err("--effect none: diagnose needs at least one candidate effect".into());
    }
    let mut given = BTreeMap::new();
    for (s, e) in specs.iter().zip(&candidates) {
        let (_, keys) = parse_given(s).map_err(|err| format!("--effect: {err}"))?;
        if given.insert(e.name().to_string(), keys).is_some() {
            return Err(format!(
                "--effect {}: named twice (each candidate once, its values in one spec)",
                e.name()
            ));
        }
    }
    given.retain(|_, keys: &mut Vec<(String, f64)>| !keys.is_empty());
    Ok((model.map(|_| structure), candidates, given))
}

/// The user's simulation from `simulate --params-json` output or a model file.
fn user_sim(path: &std::path::Path) -> Result<UserSim, String> {
    let name = jointid::data::input::input_name(path);
    let text = jointid::data::input::read_input_text(path)
        .map_err(|e| format!("--sim {name}: {}", jointid::data::output::io_msg(&e)))?;
    if let Ok(cfg) = serde_json::from_str::<SimConfig>(&text) {
        return Ok(UserSim {
            name,
            plant: cfg.plant,
            effects: cfg.effects,
            tau_c: cfg.controller.current_loop_tau,
        });
    }
    let saved: SavedModel = serde_json::from_str(&text).map_err(|e| {
        format!(
            "--sim {name}: neither `simulate --params-json` output nor a jointid model file: {e}"
        )
    })?;
    let fit = saved
        .to_nonlinear()
        .map_err(|e| format!("--sim {name}: {e}"))?;
    Ok(UserSim {
        name,
        plant: sim_plant(&fit.model, &fit.plant),
        effects: fit.model.effects.clone(),
        tau_c: fit.model.tau_c,
    })
}

/// Runs `jointid diagnose`.
///
/// # Errors
/// Bad flags or files (exit 2 naming them), the diagnosis' errors, output errors.
pub fn run(args: &DiagnoseArgs, ctx: &mut Context<'_>) -> CmdResult {
    if !(args.gear_ratio.is_finite() && args.gear_ratio > 0.0) {
        return Err(format!("--gear-ratio {}: must be finite and > 0", args.gear_ratio).into());
    }
    let (model, cands, given) = resolve(args.model.as_deref(), &args.effects)?;
    if let Some(path) = &args.report {
        check_output(path, args.force)?;
    }
    if let Some(dir) = &args.plot {
        // before the work: every name a figure's panels may take
        let names: Vec<String> = FIGURE_IDS
            .iter()
            .flat_map(|id| {
                std::iter::once(format!("{id}.svg"))
                    .chain((1..=MAX_PANELS).map(move |i| format!("{id}-{i}.svg")))
            })
            .collect();
        check_plot_files(
            dir,
            &names.iter().map(String::as_str).collect::<Vec<_>>(),
            args.force,
        )?;
        if let Some(path) = &args.report {
            // the report is no figure of the plot directory
            let mut outputs = vec![("--report".to_string(), path.clone())];
            outputs.extend(names.iter().map(|n| (format!("--plot's {n}"), dir.join(n))));
            check_distinct(&outputs)?;
        }
    }
    let user = args.sim.as_deref().map(user_sim).transpose()?;
    let structure = model
        .or(user.as_ref().map(|u| u.plant.kind))
        .unwrap_or(Structure::ThreeMass);
    // every capture as its gap-free segments: one, or all of them with --segment all
    // (those shorter than a time-domain fit takes left out, with a note)
    // samples far beyond their record, noted (the diagnosis fits them as measured)
    let mut screened: Vec<String> = Vec::new();
    let mut capture = |p: &PathBuf, what: &str| -> Result<(Vec<Dataset>, Vec<usize>), String> {
        let data = DataArgs::new(p, &args.columns, &args.read);
        let sel = data
            .select(ctx.loaders)
            .map_err(|e| format!("{what}{}: {e}", p.display()))?;
        // a sample no fit computes with is refused before the work
        screened.extend(
            screen_for_fit(&sel, &data.column_map(), "fit").map_err(|e| format!("{what}{e}"))?,
        );
        if sel.datasets.len() == 1 {
            return Ok((sel.datasets, sel.segments));
        }
        let name = sel.datasets[0].name.clone();
        let mut all = sel.datasets;
        let (segs, numbers) = usable_segments(&mut all, &sel.segments, &name, DIAGNOSING_NOTES);
        if segs.is_empty() {
            return Err(format!(
                "{what}{name}: no segment has {MIN_SEGMENT_SAMPLES} samples or more"
            ));
        }
        Ok((segs, numbers))
    };
    let mut est: Vec<Vec<Dataset>> = vec![capture(&args.path, "")?.0];
    if let Some(p) = &args.second {
        let (segs, _) = capture(p, "")?;
        check_same_rate(&est[0][0], &segs[0], "EST2")?;
        est.push(segs);
    }
    let (val, val_numbers) = capture(&args.validation, "--validation ")?;
    check_same_rate(&est[0][0], &val[0], "--validation")?;
    // the diagnosis's own lines take over from the reading's
    super::progress::finish();
    let bar = progress_bar(args.read.quiet);
    let shown = bar.clone();
    let mut req = DiagnoseRequest {
        structure,
        r: args.gear_ratio,
        candidates: cands,
        given,
        user,
        progress: (!bar.is_hidden()).then(|| {
            Progress::new(move |e| match e {
                ProgressEvent::Started(what) => shown.set_message(format!("{what} …")),
                ProgressEvent::Finished(what, outcome) => {
                    shown.println(format!("{what}: {outcome}"))
                }
            })
        }),
        ..DiagnoseRequest::default()
    };
    let est_refs: Vec<&[Dataset]> = est.iter().map(Vec::as_slice).collect();
    let mut diagnosed = diagnose_segments(&est_refs, &val, &req);
    // the default structure assumed a free joint; data whose torque holds the angle like a
    // spring to the frame are diagnosed as the grounded mass, and the report says so
    let defaulted = model.is_none() && args.sim.is_none();
    let mut switched = None;
    if let Err(DiagnoseError::Nominal { source, .. }) = &diagnosed {
        if defaulted && source.suggests_grounded() {
            switched = Some(source.to_string());
            req.structure = Structure::Grounded;
            diagnosed = diagnose_segments(&est_refs, &val, &req);
        }
    }
    bar.finish_and_clear();
    let (mut d, series) = diagnosed?;
    d.warnings.extend(screened);
    if args.linear_axis {
        d.in_linear_axis_units();
    }
    if let Some(why) = switched {
        d.warnings.insert(
            0,
            format!(
                "diagnosed as the grounded mass (`--model grounded`): the default structure \
                 {} found no start ({why}); give --model to choose",
                structure.label()
            ),
        );
    }
    // the capture's own numbering of the validation segments
    for (s, &k) in d.validation_segments.iter_mut().zip(&val_numbers) {
        s.segment = k;
    }
    let val_name = val[0].name.clone();
    let mut files = Vec::new();
    if let Some(path) = &args.report {
        let title = format!(
            "jointid diagnose: {} against {}",
            est.iter()
                .map(|e| e[0].name.as_str())
                .collect::<Vec<_>>()
                .join(" and "),
            val_name
        );
        let html = diagnosis_html(&title, &d, &series)?;
        write_file(path, args.force, |w| w.write_all(html.as_bytes()))?;
        files.push(path_text(path));
    }
    if let Some(dir) = &args.plot {
        let figs = diagnosis_figures(&d, &series)?;
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        for f in &figs {
            for (svg, name) in f.svgs.iter().zip(f.file_names()) {
                let path = dir.join(name);
                write_svg(&path, svg, args.force)?;
                files.push(path_text(&path));
            }
        }
    }
    if ctx.json {
        let doc = DiagnoseJson {
            diagnosis: &d,
            elapsed_s: d.seconds,
        };
        print_json(ctx.out, "diagnose", &doc)?;
    } else {
        print_summary(ctx.out, &d, &val_name)?;
        print_written(ctx.out, &files)?;
    }
    Ok(if args.strict && d.refused.is_some() {
        Outcome::CheckFailed
    } else {
        Outcome::Ok
    })
}

/// The `--json` document: the diagnosis, its wall time also as `elapsed_s`, the name
/// every command's document gives it (`seconds` is the diagnosis's own name).
#[derive(serde::Serialize)]
struct DiagnoseJson<'a> {
    #[serde(flatten)]
    diagnosis: &'a Diagnosis,
    elapsed_s: f64,
}

/// The gap metric's name, the head of its description (`band-passed motor-velocity FIT`
/// of `band-passed motor-velocity FIT [%]: toolbox FIT of ...`).
fn metric_name(metric: &str) -> String {
    let head = metric.split(':').next().unwrap_or(metric);
    head.replace(" [%]", "").trim().to_string()
}

/// The text report: one headline FIT, the gap metric (the nominal's toolbox FIT of `θ_m`
/// is in `--json` and, with what it measures, in the HTML report).
fn print_summary(out: &mut dyn Write, d: &Diagnosis, val: &str) -> std::io::Result<()> {
    writeln!(out, "jointid diagnose: {}", d.verdict)?;
    writeln!(out, "  metric: {}", d.metric)?;
    writeln!(
        out,
        "  {} on {val}: nominal {} {:.2} % (in-sample {:.2} %), best {} {:.2} % ({:.0} % of \
         the gap closed){}",
        metric_name(&d.metric),
        d.structure,
        Percent(d.fit_nominal_val),
        Percent(d.fit_nominal_est),
        d.best,
        Percent(d.fit_augmented_val),
        Percent(100.0 * d.gap_closed_share),
        d.fit_noise_val.map_or(String::new(), |n| format!(
            "; the noise from period to period leaves {:.2} %",
            Percent(n)
        ))
    )?;
    if !d.validation_segments.is_empty() {
        writeln!(
            out,
            "  per validation segment (the figures above pool them): nominal → best, %"
        )?;
        for s in &d.validation_segments {
            writeln!(
                out,
                "    segment {} ({} samples): {:.2} → {:.2}",
                s.segment,
                s.samples,
                Percent(s.fit_nominal),
                Percent(s.fit_augmented)
            )?;
        }
    }
    writeln!(out, "  test: {}", d.test)?;
    writeln!(
        out,
        "  candidates (gain over the nominal; over the answer {}; added to it, FIT points):",
        d.best
    )?;
    for c in &d.effects {
        let over = match c.over_answer {
            Some((m, se)) => format!("{:+7.2} ± {:5.2}", Percent(m), Percent(se)),
            None if c.name == d.best => format!("{:>15}", "answer"),
            None => format!("{:>15}", "—"),
        };
        let added = match c.with_answer {
            Some((m, se)) => format!("{:+7.2} ± {:5.2}", Percent(m), Percent(se)),
            None => format!("{:>15}", "—"),
        };
        writeln!(
            out,
            "    {:<20} {:+7.2} ± {:5.2} {:<16} {over} {added}  {}",
            c.name,
            Percent(c.score),
            Percent(c.score_se),
            if c.significant {
                "significant"
            } else {
                "not significant"
            },
            c.parameters
                .iter()
                .map(|(k, v)| format!("{k} = {:.4e} {}", v.value, v.unit))
                .collect::<Vec<_>>()
                .join(", ")
        )?;
        writeln!(out, "      {}", c.reason)?;
    }
    if let Some(p) = &d.pair {
        writeln!(out, "  pair {}: {}", p.name, p.reason)?;
    }
    let w = &d.location;
    writeln!(out, "  where the nominal's residual lies:")?;
    let r = &w.regions;
    writeln!(
        out,
        "    residual energy / average: near zero velocity {:.2}, at torque sign changes \
         {:.2}, at large deflection {:.2}; angle pattern order {} explains {:.1} %",
        r.near_zero_velocity.energy_ratio,
        r.torque_sign_change.energy_ratio,
        r.large_deflection.energy_ratio,
        r.angle_pattern.order,
        Percent(100.0 * r.angle_pattern.share)
    )?;
    writeln!(
        out,
        "    residual / measured energy by band: {}",
        w.bands_hz
            .iter()
            .map(|b| format!("{}–{} Hz {:.3}", b.lo_hz, b.hi_hz, b.residual_ratio))
            .collect::<Vec<_>>()
            .join(", ")
    )?;
    for dist in &w.distortion {
        writeln!(out, "    {}: {}", dist.capture, dist.linearity.verdict)?;
    }
    if let Some(a) = &w.amplitude {
        for l in &a.levels {
            writeln!(
                out,
                "    amplitude: {} u RMS {:.3e} N·m, gap {:.2} points",
                l.capture,
                l.u_rms,
                Percent(l.gap)
            )?;
        }
        writeln!(out, "    {}", a.summary())?;
    }
    if let Some(m) = &d.parameter_mismatch {
        writeln!(
            out,
            "  {}: {:.2} % on the validation data; parameters account for {:+.2} points, \
             structure for {:+.2}",
            m.sim,
            Percent(m.fit_sim_val),
            Percent(m.parameter_part),
            Percent(m.structure_part)
        )?;
        for p in &m.parameters {
            writeln!(
                out,
                "    {:<6} sim {:.4e}, fitted {:.4e} ({:+.1} %)",
                p.name,
                p.sim,
                p.fitted,
                Percent(p.percent)
            )?;
        }
    }
    writeln!(out, "  {:.1} s", d.seconds)?;
    for n in &d.warnings {
        writeln!(out, "  note: {n}")?;
    }
    Ok(())
}

/// The notes of a diagnosis over several segments of a capture
/// ([`usable_segments`]).
const DIAGNOSING_NOTES: SegmentNotes = SegmentNotes {
    leaving: |left| {
        format!(
            "the diagnosis leaves out {left}: shorter than {MIN_SEGMENT_SAMPLES} samples, as \
             the time-domain fits do"
        )
    },
    using: |list| {
        format!(
            "diagnosing on segments {list} (an estimation capture's fitted as separate \
             experiments; the validation capture's each simulated from its own start, the \
             metric pooled over them)"
        )
    },
};

/// One line per stage and candidate on standard error while the diagnosis runs (a spinner
/// with the one running, the finished ones printed above it); hidden with `--quiet` or
/// when standard error is not a terminal.
fn progress_bar(quiet: bool) -> indicatif::ProgressBar {
    if quiet || !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new_spinner();
    if let Ok(style) = indicatif::ProgressStyle::with_template("{spinner} {elapsed_precise} {msg}")
    {
        bar.set_style(style);
    }
    bar.set_message("diagnosing …");
    bar.enable_steady_tick(std::time::Duration::from_millis(200));
    bar
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn effect_specs_split_comma_lists_and_keep_a_specs_own_keys_together() {
        let flags = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        assert_eq!(
            effect_specs(&flags(&[
                "backlash,coulomb_friction:fc=0.1, fs=0.2",
                "time_delay"
            ])),
            ["backlash", "coulomb_friction:fc=0.1,fs=0.2", "time_delay"]
        );
        let all = effect_specs(&[]);
        assert_eq!(all.len(), Effect::all_defaults().len());
        assert_eq!(effect_specs(&flags(&["all"])), all);
    }

    #[test]
    fn resolve_gives_the_candidates_and_the_values_their_specs_give() {
        let (model, cands, given) = resolve(
            Some("Two_Mass"),
            &["backlash,coulomb_friction:fc=0.1".to_string()],
        )
        .unwrap();
        assert_eq!(model, Some(Structure::TwoMass));
        let names: Vec<&str> = cands.iter().map(Effect::name).collect();
        assert_eq!(names, ["backlash", "coulomb_friction"]);
        match cands[1] {
            // the pure law, as `fit --effect coulomb_friction:fc=0.1` resolves it
            Effect::CoulombFriction(c) => assert_eq!((c.fc, c.fs), (0.1, 0.1)),
            e => panic!("{e:?}"),
        }
        assert_eq!(given.len(), 1);
        assert_eq!(given["coulomb_friction"], [("fc".to_string(), 0.1)]);
        assert!(resolve(Some("five-mass"), &[]).is_err());
    }
}
