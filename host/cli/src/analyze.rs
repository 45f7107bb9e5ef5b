//! `jointid analyze DATA`: nonparametric FRF u → theta_m with σ, noise level
//! and nonlinear distortion of a periodic experiment (see [`jointid::ident::frf`]).

use std::io::Write;
use std::path::PathBuf;

use clap::Args;
use serde::Serialize;

use super::args::{column_of, outlier_line, ColumnArgs, DataArgs, ReadArgs};
use super::{check_plot_files, print_json, write_svg, CmdResult, Context, Outcome};
use jointid::data::input::path_text;
use jointid::data::screen::{Outlier, MAX_MAGNITUDE, OUTLIER_SIGMAS};
use jointid::data::{fmt_sig, Dataset, Percent, Selected, SignalKind};
use jointid::ident::frf::{
    amplitude_trend, analyze_dataset, analyze_segments, AmplitudeTrend, ClassLevel, ExcitedSource,
    FrfAnalysis, Instrument,
};
use jointid::ident::validate::FrfBand;
use jointid::report::plot::{analysis_spectrum_svg, bode_svg};

/// Arguments of `jointid analyze`.
#[derive(Debug, Clone, Args)]
pub struct AnalyzeArgs {
    /// data file: capture CSV (`t,theta_ref,u,theta_m`), any CSV or MAT-file with
    /// --time/--input/--output, or a .jcap capture; `-`: standard input
    #[arg(value_name = "DATA")]
    pub path: PathBuf,
    /// the columns of DATA
    #[command(flatten)]
    pub columns: ColumnArgs,
    /// how to read DATA and which part to use
    #[command(flatten)]
    pub read: ReadArgs,
    /// whole periods dropped after the ramp-in as transient
    #[arg(long, value_name = "P", default_value_t = 1)]
    pub settle_periods: usize,
    /// write spectrum.svg (seed 000 Fig. 3) and frf.svg into this directory
    #[arg(long, value_name = "DIR")]
    pub plot: Option<PathBuf>,
    /// exit with 1 when significant nonlinear distortion is found: detected
    /// above the noise and within 40 dB of the excited lines (seed 000 §3)
    #[arg(long)]
    pub require_linear: bool,
    /// replace spectrum.svg and frf.svg when they exist in the --plot directory
    #[arg(long)]
    pub force: bool,
    /// print every FRF line (default: at most 60 rows)
    #[arg(long)]
    pub all_lines: bool,
    /// a second run of the same multisine at another amplitude (same
    /// columns): tells distortion that grows with amplitude from distortion
    /// that falls with it; refused unless both runs are the same multisine
    /// (kind, sample rate, period, excited lines; only the amplitude may differ)
    #[arg(long, value_name = "DATA2")]
    pub compare: Option<PathBuf>,
}

#[derive(Serialize)]
struct Report<'a> {
    file: &'a str,
    analysis: &'a FrfAnalysis,
    distortion_detected: bool,
    /// detected and within 40 dB of the excited lines
    distortion_significant: bool,
    /// files written (the plots), as every command's `files`
    #[serde(rename = "files")]
    plots: Vec<String>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    amplitude_trend: Vec<AmplitudeTrend>,
    /// samples far outside their column in the data analysed (at most [`LISTED_OUTLIERS`])
    outliers: Vec<OutlierDoc<'a>>,
    /// how many there are
    outlier_count: usize,
    /// the results that are not finite (no linearity verdict can rest on them)
    non_finite: Vec<String>,
}

/// An outlier in `--json`: its column's name, then the library's fields.
#[derive(Serialize)]
struct OutlierDoc<'a> {
    column: &'a str,
    #[serde(flatten)]
    outlier: &'a Outlier,
}

/// Most outliers `analyze` lists (`--json`; the text lists [`PRINTED_OUTLIERS`]).
const LISTED_OUTLIERS: usize = 100;
/// Most outliers the text output lists.
const PRINTED_OUTLIERS: usize = 5;

/// The results of `a` that are not finite, in words: the FRF and its σ at how many
/// lines, and each linearity level.
fn non_finite(a: &FrfAnalysis) -> Vec<String> {
    let mut found = Vec::new();
    let lines = a.frf.g.len();
    let g = a
        .frf
        .g
        .iter()
        .filter(|g| !(g.re.is_finite() && g.im.is_finite()))
        .count();
    if g > 0 {
        found.push(format!("the FRF at {g} of {lines} lines"));
    }
    let s = a.frf.sigma.iter().filter(|s| !s.is_finite()).count();
    if s > 0 {
        found.push(format!("the FRF's σ at {s} of {lines} lines"));
    }
    for lin in [&a.linearity_u, &a.linearity_y] {
        let mut levels = vec![("excited lines' level", lin.excited_db)];
        for (class, c) in [("odd non-excited", &lin.odd), ("even", &lin.even)] {
            if c.lines > 0 {
                levels.push((class, c.level_db));
                levels.push((class, c.vs_excited_db));
                levels.push((class, c.vs_noise_db));
            }
        }
        let mut bad: Vec<&str> = levels
            .iter()
            .filter(|(_, v)| !v.is_finite())
            .map(|(w, _)| *w)
            .collect();
        bad.dedup();
        if !bad.is_empty() {
            found.push(format!("{}: {}", lin.signal, bad.join(", ")));
        }
    }
    found
}

/// Runs `jointid analyze`.
///
/// # Errors
/// Loading, analysis, plotting and output errors.
pub fn run(args: &AnalyzeArgs, ctx: &mut Context<'_>) -> CmdResult {
    if let Some(dir) = &args.plot {
        check_plot_files(dir, &["spectrum.svg", "frf.svg"], args.force)?;
    }
    let data = DataArgs::new(&args.path, &args.columns, &args.read);
    let selected = data.select(ctx.loaders)?;
    let ds = &selected.datasets[0];
    super::progress::step(format!(
        "analysing {} samples",
        selected
            .datasets
            .iter()
            .map(|d| d.data.len())
            .sum::<usize>()
    ));
    let a = analyze_segments(&selected.datasets, args.settle_periods)
        .map_err(|e| named(&ds.name, e))?;
    super::progress::clear();
    let notes: Vec<String> = a
        .left_out
        .iter()
        .map(|l| {
            format!(
                "{}: segment {} left out of the FRF: {}",
                ds.name, selected.segments[l.index], l.reason
            )
        })
        .collect();
    super::print::print_notes(&notes);
    let mut plots = Vec::new();
    if let Some(dir) = &args.plot {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let spec = dir.join("spectrum.svg");
        write_svg(
            &spec,
            &analysis_spectrum_svg(&format!("line spectra: {}", ds.name), &a)?,
            args.force,
        )?;
        let frf = dir.join("frf.svg");
        let band = FrfBand::from(&a.frf);
        write_svg(
            &frf,
            &bode_svg(&format!("FRF u -> theta_m: {}", ds.name), Some(&band), &[])?,
            args.force,
        )?;
        plots = vec![path_text(&spec), path_text(&frf)];
    }
    let detected = a.distortion_detected();
    let significant = a.distortion_significant();
    let map = data.column_map();
    let not_finite = non_finite(&a);
    // the check cannot pass on outliers or on results that are not finite
    let refused = selected.outlier_count > 0 || !not_finite.is_empty();
    let mut trend = Vec::new();
    if let Some(other) = &args.compare {
        let other_ds = args
            .read
            .select_one(ctx.loaders, other, data.column_map())?;
        super::progress::step(format!("analysing {} samples", other_ds.data.len()));
        let b = analyze_dataset(&other_ds, args.settle_periods)
            .map_err(|e| named(&other_ds.name, e))?;
        same_multisine((ds, &a), (&other_ds, &b))?;
        trend.push(amplitude_trend(&a.linearity_u, &b.linearity_u));
        trend.push(amplitude_trend(&a.linearity_y, &b.linearity_y));
    }
    super::progress::finish();
    if ctx.json {
        print_json(
            ctx.out,
            "analyze",
            &Report {
                file: &ds.name,
                analysis: &a,
                distortion_detected: detected,
                distortion_significant: significant,
                plots,
                amplitude_trend: trend,
                outliers: selected
                    .outliers
                    .iter()
                    .take(LISTED_OUTLIERS)
                    .map(|o| OutlierDoc {
                        column: column_of(&map, o.signal),
                        outlier: o,
                    })
                    .collect(),
                outlier_count: selected.outlier_count,
                non_finite: not_finite,
            },
        )?;
    } else {
        print_table(ctx.out, &ds.name, &a, args.all_lines)?;
        print_data_check(ctx.out, &ds.name, &map, &selected, &not_finite)?;
        if let Some(other) = &args.compare {
            writeln!(ctx.out, "amplitude comparison with {}", other.display())?;
            for t in &trend {
                writeln!(ctx.out, "  {}", t.verdict)?;
            }
        }
        super::print_written(ctx.out, &plots)?;
    }
    Ok(if args.require_linear && (significant || refused) {
        Outcome::CheckFailed
    } else {
        Outcome::Ok
    })
}

/// The analysis's error `e` of the data `name`, the file named first (the library's
/// errors about periods name none: "1 whole period(s) of 5000 samples: need at least 2").
fn named(name: &str, e: impl std::fmt::Display) -> String {
    let m = e.to_string();
    if m.starts_with(name) {
        m
    } else {
        format!("{name}: {m}")
    }
}

/// The data check after the table: the outliers (the first [`PRINTED_OUTLIERS`], by file,
/// row and column) and the results that are not finite; on either no linearity verdict
/// holds, and `--require-linear` fails.
fn print_data_check(
    out: &mut dyn Write,
    name: &str,
    map: &jointid::data::ColumnMap,
    selected: &Selected,
    not_finite: &[String],
) -> std::io::Result<()> {
    let (outliers, count) = (&selected.outliers, selected.outlier_count);
    if count == 0 && not_finite.is_empty() {
        return Ok(());
    }
    writeln!(out)?;
    writeln!(
        out,
        "data check (no linearity verdict holds; --require-linear fails)"
    )?;
    if count > 0 {
        writeln!(
            out,
            "  {count} outlier{} (beyond {OUTLIER_SIGMAS} robust σ, 1.4826·MAD, of {} column's \
             median, of magnitude ≥ {MAX_MAGNITUDE:e}, or not finite):",
            if count == 1 { "" } else { "s" },
            if count == 1 { "its" } else { "their" }
        )?;
        for o in outliers.iter().take(PRINTED_OUTLIERS) {
            writeln!(out, "    {}", outlier_line(name, map, o))?;
        }
        if count > PRINTED_OUTLIERS {
            writeln!(
                out,
                "    and {} more (--json lists up to {LISTED_OUTLIERS})",
                count - PRINTED_OUTLIERS
            )?;
        }
    }
    if !not_finite.is_empty() {
        writeln!(out, "  not finite: {}", not_finite.join("; "))?;
    }
    Ok(())
}

/// Why two runs cannot be compared by amplitude: the runs of `--compare` must be the same
/// multisine (kind, sample rate, period, excited lines), only the amplitude may differ.
#[derive(Debug, thiserror::Error)]
#[error("--compare {other}: {what}; the amplitude comparison needs the same multisine as {first} at another amplitude")]
pub struct NotSameMultisine {
    /// the first run (DATA)
    first: String,
    /// the run given to `--compare`
    other: String,
    /// the difference
    what: String,
}

fn kind_name(kind: SignalKind) -> &'static str {
    match kind {
        SignalKind::SpecialOddMultisine => "special odd multisine",
        SignalKind::RandomOddMultisine => "random-phase odd multisine",
        SignalKind::BandLimitedNoise => "band-limited noise",
    }
}

/// Checks that `a` and `b` are analyses of the same multisine (see [`NotSameMultisine`]).
fn same_multisine(
    (da, a): (&Dataset, &FrfAnalysis),
    (db, b): (&Dataset, &FrfAnalysis),
) -> Result<(), NotSameMultisine> {
    let differ = |what: String| NotSameMultisine {
        first: da.name.clone(),
        other: db.name.clone(),
        what,
    };
    for (d, whose) in [(db, String::new()), (da, format!("{} is ", da.name))] {
        if let Some(c) = d
            .excitation
            .filter(|c| c.kind == SignalKind::BandLimitedNoise)
        {
            return Err(differ(format!(
                "{whose}excited by {}, not a multisine (every line 1..{} is excited)",
                kind_name(c.kind),
                c.max_line
            )));
        }
    }
    if let (Some(ca), Some(cb)) = (da.excitation, db.excitation) {
        if ca.kind != cb.kind {
            return Err(differ(format!(
                "excitation is a {}, {} has a {}",
                kind_name(cb.kind),
                da.name,
                kind_name(ca.kind)
            )));
        }
    }
    if (a.ts - b.ts).abs() > 1e-9 * a.ts {
        return Err(differ(format!(
            "sample rate {} Hz, {} has {} Hz",
            fmt_sig(1.0 / b.ts, 6),
            da.name,
            fmt_sig(1.0 / a.ts, 6)
        )));
    }
    if a.layout.period != b.layout.period {
        return Err(differ(format!(
            "period {} samples, {} has {} samples",
            b.layout.period, da.name, a.layout.period
        )));
    }
    if a.frf.lines != b.frf.lines {
        let only = |x: &FrfAnalysis, y: &FrfAnalysis| {
            x.frf
                .lines
                .iter()
                .filter(|l| !y.frf.lines.contains(l))
                .count()
        };
        let first_diff = a
            .frf
            .lines
            .iter()
            .zip(&b.frf.lines)
            .find(|(x, y)| x != y)
            .map_or_else(
                || {
                    let n = a.frf.lines.len().min(b.frf.lines.len());
                    a.frf
                        .lines
                        .get(n)
                        .or(b.frf.lines.get(n))
                        .copied()
                        .unwrap_or(0)
                },
                |(x, y)| (*x).min(*y),
            );
        return Err(differ(format!(
            "excites {} lines, {} excites {} ({} only in {}, {} only in {}, first difference at line {})",
            b.frf.lines.len(),
            da.name,
            a.frf.lines.len(),
            only(b, a),
            db.name,
            only(a, b),
            da.name,
            first_diff
        )));
    }
    Ok(())
}

fn print_table(out: &mut dyn Write, name: &str, a: &FrfAnalysis, all: bool) -> std::io::Result<()> {
    let l = &a.layout;
    writeln!(out, "jointid analyze: {name}")?;
    writeln!(
        out,
        "  periods    N = {} samples ({} s), P = {} from sample {}, fs = {} Hz, f0 = {} Hz",
        l.period,
        fmt_sig(l.period as f64 * a.ts, 4),
        l.count,
        l.start,
        fmt_sig(1.0 / a.ts, 4),
        fmt_sig(a.f0_hz, 4)
    )?;
    let (flo, fhi) = (
        a.frf.freq_hz.first().copied().unwrap_or(0.0),
        a.frf.freq_hz.last().copied().unwrap_or(0.0),
    );
    writeln!(
        out,
        "  excited    {} lines, {flo:.4} .. {fhi:.4} Hz ({}), band lines 1..{}",
        a.frf.lines.len(),
        match a.excited_source {
            ExcitedSource::Config => "from the excitation config",
            ExcitedSource::Detected => "detected from the spectrum",
        },
        a.band_max_line
    )?;
    writeln!(
        out,
        "  FRF        u -> theta_m, synchronous period averaging on {}",
        match a.instrument {
            Instrument::Reference => "the reference theta_ref (instrument)",
            Instrument::Input => "the input's own period (no reference column)",
        }
    )?;
    writeln!(out)?;
    writeln!(
        out,
        "linearity (seed 000 Fig. 3; one-sided 99 % test of the lines against the noise floor)"
    )?;
    writeln!(
        out,
        "  {:<8} {:<16} {:>5} {:>11} {:>15} {:>13} {:>14}  distortion",
        "signal",
        "class",
        "lines",
        "level [dB]",
        "vs excited [dB]",
        "vs noise [dB]",
        "threshold [dB]"
    )?;
    for lin in [&a.linearity_u, &a.linearity_y] {
        let excited = a.frf.lines.len();
        writeln!(
            out,
            "  {:<8} {:<16} {:>5} {:>11}",
            lin.signal,
            "excited",
            excited,
            fixed(lin.excited_db, 1, false)
        )?;
        let row = |out: &mut dyn Write, class: &str, c: &ClassLevel| {
            if c.lines == 0 {
                return writeln!(out, "  {:<8} {:<16} {:>5}", lin.signal, class, 0);
            }
            // against a noise floor that is not finite, the ratio is no figure either
            let vs_noise = if c.noise_db.is_finite() && c.level_db.is_finite() {
                c.vs_noise_db
            } else {
                f64::NAN
            };
            writeln!(
                out,
                "  {:<8} {:<16} {:>5} {:>11} {:>15} {:>13} {:>14}  {}",
                lin.signal,
                class,
                c.lines,
                fixed(c.level_db, 1, false),
                fixed(c.vs_excited_db, 1, false),
                fixed(vs_noise, 1, true),
                fixed(c.threshold_db, 1, false),
                match (c.detected, c.significant) {
                    _ if !class_finite(lin.excited_db, c) => "undetermined",
                    (true, true) => "DETECTED",
                    (true, false) => "detected, negligible",
                    _ => "no",
                }
            )
        };
        row(out, "odd non-excited", &lin.odd)?;
        row(out, "even", &lin.even)?;
    }
    for lin in [&a.linearity_u, &a.linearity_y] {
        if [&lin.odd, &lin.even]
            .iter()
            .all(|c| c.lines == 0 || class_finite(lin.excited_db, c))
        {
            writeln!(out, "  verdict  {}", lin.verdict)?;
        } else {
            // the library's verdict would rest on NaN levels ("not detected")
            writeln!(
                out,
                "  verdict  {}: undetermined: its line levels are not finite numbers \
                 (see the data check below)",
                lin.signal
            )?;
        }
    }
    writeln!(out)?;
    let n = a.frf.lines.len();
    let step = if all || n <= 60 { 1 } else { n.div_ceil(60) };
    writeln!(
        out,
        "FRF u -> theta_m at the excited lines{}",
        if step > 1 {
            format!(" (one line in {step}; --all-lines or --json for all)")
        } else {
            String::new()
        }
    )?;
    writeln!(
        out,
        "  {:>6} {:>12} {:>10} {:>11} {:>12}",
        "line", "f [Hz]", "|G| [dB]", "phase [deg]", "sigma/|G| %"
    )?;
    let (mag, ph) = (a.frf.mag_db(), a.frf.phase_deg());
    for i in (0..n).step_by(step) {
        writeln!(
            out,
            "  {:>6} {:>12.4} {:>10} {:>11} {:>12.2}",
            a.frf.lines[i],
            a.frf.freq_hz[i],
            fixed(mag[i], 2, false),
            fixed(ph[i], 1, false),
            Percent(100.0 * a.frf.sigma[i] / a.frf.g[i].norm())
        )?;
    }
    Ok(())
}

/// `x` with `prec` decimals (and its sign with `plus`), or [`jointid::data::UNDEFINED`]
/// when it is not finite: a level of a record holding 1e300 prints no `inf` or `NaN`.
fn fixed(x: f64, prec: usize, plus: bool) -> String {
    match (x.is_finite(), plus) {
        (false, _) => jointid::data::UNDEFINED.to_string(),
        (true, true) => format!("{x:+.prec$}"),
        (true, false) => format!("{x:.prec$}"),
    }
}

/// Whether a class's levels, and the excited lines' level they are compared with, are
/// finite: a distortion verdict on them means something.
fn class_finite(excited_db: f64, c: &ClassLevel) -> bool {
    [
        excited_db,
        c.level_db,
        c.vs_excited_db,
        c.noise_db,
        c.vs_noise_db,
    ]
    .iter()
    .all(|v| v.is_finite())
}

#[cfg(test)]
mod tests {
    use super::super::{run as run_cli, Cli};
    use super::*;
    use clap::Parser;

    fn run_args(argv: &[&str]) -> (Result<Outcome, String>, String) {
        let cli = Cli::try_parse_from(argv).unwrap();
        let loaders = super::super::default_loaders();
        let mut buf = Vec::new();
        let r = {
            let mut ctx = Context {
                json: cli.json,
                loaders: &loaders,
                out: &mut buf,
                fitted: None,
            };
            run_cli(&cli, &mut ctx).map_err(|e| e.to_string())
        };
        (r, String::from_utf8(buf).unwrap())
    }

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("jointid-analyze-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn analyze_prints_table_json_and_plots_for_a_capture_csv() {
        let dir = tmp("ok");
        let csv = dir.join("cap.csv");
        std::fs::write(&csv, jointid::test_support::capture_csv(0.0, 4)).unwrap();
        let csv_s = csv.to_str().unwrap();
        let (r, out) = run_args(&["jointid", "analyze", csv_s, "--require-linear"]);
        assert_eq!(r, Ok(Outcome::Ok), "{out}");
        assert!(
            out.contains("N = 500 samples (0.5 s), P = 5 from sample 800"),
            "{out}"
        );
        assert!(out.contains("30 lines"), "{out}");
        assert!(
            out.contains("odd nonlinear distortion not detected"),
            "{out}"
        );
        let plots = dir.join("plots");
        let (r, out) = run_args(&[
            "jointid",
            "--json",
            "analyze",
            csv_s,
            "--plot",
            plots.to_str().unwrap(),
        ]);
        assert_eq!(r, Ok(Outcome::Ok));
        let v: serde_json::Value = serde_json::from_str(&out).unwrap();
        assert_eq!(v["analysis"]["frf"]["lines"].as_array().unwrap().len(), 30);
        assert!(v["analysis"]["frf"]["g"][0]["re"].is_number(), "{v}");
        assert!(v["analysis"]["frf"]["g"][0]["im"].is_number(), "{v}");
        assert_eq!(v["distortion_detected"], false);
        assert!(std::fs::read_to_string(plots.join("spectrum.svg"))
            .unwrap()
            .starts_with("<svg"));
        assert!(std::fs::read_to_string(plots.join("frf.svg"))
            .unwrap()
            .starts_with("<svg"));
        // a cubic controller: --require-linear turns the detection into exit 1
        std::fs::write(&csv, jointid::test_support::capture_csv(0.5, 4)).unwrap();
        let (r, out) = run_args(&["jointid", "analyze", csv_s, "--require-linear"]);
        assert_eq!(r, Ok(Outcome::CheckFailed), "{out}");
        assert!(out.contains("DETECTED"));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn analyze_errors_name_the_file() {
        let dir = tmp("err");
        let csv = dir.join("bad.csv");
        std::fs::write(&csv, "t,theta_ref,u,theta_m\n0,0,0,0\n0.001,0,x,0\n").unwrap();
        let (r, _) = run_args(&["jointid", "analyze", csv.to_str().unwrap()]);
        assert_eq!(
            r,
            Err(format!(
                "{}:3: column `u`: `x` is not a number",
                csv.display()
            ))
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
