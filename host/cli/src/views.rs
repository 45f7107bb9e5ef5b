//! The toolbox's views that `fit --plot` and `validate --plot` write beside the Bode
//! plot ([`jointid::report::views`]): `compare.svg` (measured against simulated output,
//! FIT in the legend, one panel per record), `resid.svg` (the residual tests with their
//! 99 % bands), `pzmap.svg` (poles and zeros, s-plane in Hz) and `step.svg` (response to
//! a unit input step). Axes carry the data's units ([`Units`]).

use std::path::{Path, PathBuf};

use jointid::data::Dataset;
pub use jointid::ident::fit::CompareRecord;
use jointid::ident::fit::{bode_figure, BodeFigure, Fitted};
use jointid::ident::grey_box::Output;
use jointid::ident::validate::Validation;
use jointid::report::plot::bode_svg_in;
use jointid::report::views::{
    compare_svg, interval_rate, pzmap_svg, resid_svg, step_horizon, step_response, step_svg,
    CompareModel, ComparePanel, PzModel, ResidRow, StepCurve, Units,
};

use super::write_svg;

/// What `compare.svg` draws against the measured output on periodic data: the record's
/// period under the periodic FIT ([`jointid::ident::sml::periodic_fit_signals`]).
pub const PERIODIC_COMPARED: &str = "the model's (one averaged period, reliable excited lines)";

/// What `compare.svg` draws against the measured output's rate under the velocity FIT
/// ([`jointid::ident::fit::Fitted::velocity_fit_signals`]).
pub const VELOCITY_COMPARED: &str = "simulated from rest, both through the fit's 5 Hz high-pass";

/// The files [`write_views`] writes.
pub const VIEW_FILES: [&str; 4] = ["compare.svg", "resid.svg", "pzmap.svg", "step.svg"];

/// What the views of one model show.
pub struct Views<'a> {
    /// the model
    pub fitted: &'a Fitted,
    /// name of the FIT in the legend (`FIT`, `periodic FIT`, `toolbox FIT`)
    pub fit_label: &'a str,
    /// whose output is drawn against the measured one (`simulated`, `the model's: one
    /// period averaged ...`)
    pub compared: &'a str,
    /// the records compared
    pub records: Vec<CompareRecord>,
    /// the records hold the output's rate (the velocity FIT's signals), not the output
    pub compare_rate: bool,
    /// residual tests per record (`estimation`, `validation`, `data`)
    pub tests: Vec<(&'a str, &'a Validation)>,
    /// the data's signals and units
    pub signals: Signals,
    /// duration of the estimation record [s] (the step response's horizon at most)
    pub record_s: f64,
    /// the data file named in the titles
    pub file: &'a str,
}

/// names of the input, the output and the output's rate
fn quantities(linear: bool, output: Output) -> (&'static str, &'static str, &'static str) {
    match (linear, output) {
        (false, Output::Angle) => ("torque", "motor angle", "motor velocity"),
        (false, Output::Velocity) => ("torque", "motor velocity", "motor acceleration"),
        (true, Output::Angle) => ("force", "position", "velocity"),
        (true, Output::Velocity) => ("force", "velocity", "acceleration"),
    }
}

/// The plots' names and units of the input, the output and the output's rate.
#[derive(Clone, Debug)]
pub struct Signals {
    /// units of input and output
    pub units: Units,
    /// name of the input (`torque`, `force`, `input`)
    pub input: &'static str,
    /// name of the output (`motor angle`, `position`, `output`)
    pub output: &'static str,
    /// name of the output's rate (`motor velocity`, `velocity`, `output rate`)
    pub rate: &'static str,
}

impl Signals {
    /// A rotary joint or (`linear`) a linear axis with the output `output`; `units`
    /// (`--units IN,OUT`) names the units of other data, whose signals are then called
    /// input and output.
    pub fn new(linear: bool, output: Output, units: Option<&(String, String)>) -> Self {
        match units {
            Some((i, o)) => Signals {
                units: Units {
                    input: i.clone(),
                    output: o.clone(),
                },
                input: "input",
                output: "output",
                rate: "output rate",
            },
            None => {
                let (input, output_name, rate) = quantities(linear, output);
                Signals {
                    units: Units::joint(linear, output == Output::Velocity),
                    input,
                    output: output_name,
                    rate,
                }
            }
        }
    }
}

/// `--units IN,OUT`: two non-empty units separated by a comma
pub fn parse_units(s: &str) -> Result<(String, String), String> {
    match s.split_once(',') {
        Some((i, o)) if !i.trim().is_empty() && !o.trim().is_empty() && !o.contains(',') => {
            Ok((i.trim().to_string(), o.trim().to_string()))
        }
        _ => Err(format!(
            "`{s}` is not IN,OUT: the input's and the output's unit, e.g. `N,m` or `V,rad`"
        )),
    }
}

/// The FRF's signals with their units for a Bode plot, `("force [N] -> position [m]",
/// "m/N")`: the title's, and the gain's unit.
pub fn frf_label(s: &Signals) -> (String, String) {
    let (i, o) = (&s.units.input, &s.units.output);
    (
        format!("{} [{i}] -> {} [{o}]", s.input, s.output),
        format!("{o}/{i}"),
    )
}

/// the last component of a data file's name, for titles
pub fn short_name(name: &str) -> &str {
    Path::new(name)
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or(name)
}

/// Writes [`VIEW_FILES`] into `dir` (created when missing; existing files only with
/// `force`) and returns their paths.
///
/// # Errors
/// Directory, plot and write errors.
pub fn write_views(
    dir: &Path,
    v: &Views<'_>,
    force: bool,
) -> Result<Vec<PathBuf>, Box<dyn std::error::Error + Send + Sync>> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let f = v.fitted;
    let name = f.spec.name();
    let (inp, out, rate) = (v.signals.input, v.signals.output, v.signals.rate);
    let units = &v.signals.units;
    let mut written = Vec::new();
    let mut put =
        |file: &str, svg: String| -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
            let p = dir.join(file);
            write_svg(&p, &svg, force)?;
            written.push(p);
            Ok(())
        };

    let panels: Vec<ComparePanel<'_>> = v
        .records
        .iter()
        .map(|r| ComparePanel {
            title: r.title.clone(),
            t0: 0.0,
            ts: r.ts,
            measured: &r.y,
            models: vec![CompareModel {
                name: &name,
                simulated: &r.y_hat,
                fit_percent: r.fit,
            }],
        })
        .collect();
    put(
        "compare.svg",
        compare_svg(
            &format!(
                "{}, measured and {}: {}",
                if v.compare_rate { rate } else { out },
                v.compared,
                short_name(v.file)
            ),
            &if v.compare_rate {
                format!("{rate} [{}]", units.output_rate())
            } else {
                format!("{out} [{}]", units.output)
            },
            v.fit_label,
            &panels,
        )?,
    )?;

    let labels: Vec<String> = v
        .tests
        .iter()
        .map(|(r, _)| format!("{name}, {r}"))
        .collect();
    let rows: Vec<ResidRow<'_>> = v
        .tests
        .iter()
        .zip(&labels)
        .map(|((_, t), l)| ResidRow {
            label: l,
            whiteness: &t.whiteness,
            independence: &t.independence,
        })
        .collect();
    put(
        "resid.svg",
        resid_svg(
            &format!("residual tests (99 %): {}", short_name(v.file)),
            &rows,
        )?,
    )?;

    let pz = PzModel::new(&name, &f.model, f.continuous.as_ref());
    put(
        "pzmap.svg",
        pzmap_svg(
            &format!(
                "poles (x) and zeros (o), {inp} -> {out}, s-plane{}",
                if f.continuous.is_some() {
                    ""
                } else {
                    " (s = ln z / Ts)"
                }
            ),
            std::slice::from_ref(&pz),
            0.45 / f.ts,
        )?,
    )?;

    // a pole slower than the record acts as an integrator there: the output ramps, so
    // its rate is what settles
    let two_pi = 2.0 * std::f64::consts::PI;
    let integrating = pz
        .poles_hz
        .iter()
        .any(|p| p.norm() * two_pi < two_pi / v.record_s);
    let horizon = step_horizon(std::slice::from_ref(&pz), f.ts, v.record_s);
    let n = ((horizon / f.ts).round() as usize).max(2);
    let y = step_response(&f.model, 1.0, n);
    let (values, shown, unit) = if integrating {
        (interval_rate(&y, f.ts), rate, units.output_rate())
    } else {
        (y, out, units.output.clone())
    };
    let title = if integrating {
        format!(
            "step response: {rate} (mean over each sample) after a 1 {} {inp} step; the {out} integrates it",
            units.input
        )
    } else {
        format!("step response: {out} after a 1 {} {inp} step", units.input)
    };
    put(
        "step.svg",
        step_svg(
            &title,
            &format!("{shown} [{unit}]"),
            &[StepCurve {
                name: &name,
                ts: f.ts,
                values: &values,
            }],
        )?,
    )?;
    Ok(written)
}

/// Writes `name` into `dir`: Bode plot of `models` over the FRF of `ds` (its signals and
/// units `io`, [`frf_label`]) (when `ds` is periodic) with ±2σ, up to 0.45 / Ts of the
/// coarsest model ([`jointid::ident::fit::bode_figure`]); an existing file only with
/// `force`.
///
/// # Errors
/// Directory, plot and write errors.
pub fn write_bode(
    dir: &Path,
    name: &str,
    ds: &Dataset,
    settle_periods: usize,
    models: &[&Fitted],
    io: &(String, String),
    force: bool,
) -> Result<PathBuf, Box<dyn std::error::Error + Send + Sync>> {
    let fig = bode_figure(ds, settle_periods, models);
    write_bode_figure(dir, name, &fig, &ds.name, io, force)
}

/// Writes `name` into `dir`: the Bode plot `fig` over the FRF of the record `record` (its
/// signals and units `io`, [`frf_label`]); an existing file only with `force`.
///
/// # Errors
/// Directory, plot and write errors.
pub fn write_bode_figure(
    dir: &Path,
    name: &str,
    fig: &BodeFigure,
    record: &str,
    io: &(String, String),
    force: bool,
) -> Result<PathBuf, Box<dyn std::error::Error + Send + Sync>> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let path = dir.join(name);
    let title = format!("models over the FRF {}: {}", io.0, short_name(record));
    write_svg(
        &path,
        &bode_svg_in(&title, Some(&io.1), fig.band.as_ref(), &fig.curves)?,
        force,
    )?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_name_the_signals_of_a_joint_an_axis_or_other_data() {
        let s = Signals::new(true, Output::Angle, None);
        assert_eq!(
            (s.input, s.output, s.rate),
            ("force", "position", "velocity")
        );
        assert_eq!(
            frf_label(&s),
            ("force [N] -> position [m]".into(), "m/N".into())
        );
        let s = Signals::new(false, Output::Velocity, None);
        assert_eq!(s.units.output, "rad/s");
        assert_eq!(s.units.output_rate(), "rad/s²");
        let u = parse_units(" V , m ").unwrap();
        assert_eq!(u, ("V".to_string(), "m".to_string()));
        let s = Signals::new(true, Output::Angle, Some(&u));
        assert_eq!(frf_label(&s).0, "input [V] -> output [m]");
        for bad in ["N", "N,", ",m", "N,m,s"] {
            assert!(parse_units(bad).unwrap_err().contains("IN,OUT"), "{bad}");
        }
        assert_eq!(short_name("/a/b/robot_arm.csv"), "robot_arm.csv");
    }
}
