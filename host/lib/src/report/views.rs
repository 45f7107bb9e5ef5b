//! The toolbox's views of fitted models (MATLAB System Identification Toolbox
//! `compare`, `resid`, `pzmap`, `step`) as SVG: measured against simulated output
//! with the FIT in the legend ([`compare_svg`]), the residual tests with their 99 %
//! bands ([`resid_svg`]), poles and zeros in the s-plane ([`pzmap_svg`]) and step
//! responses ([`step_svg`]).
//!
//! Every legend sits in its own strip beside the plot area, so it hides no data; axes
//! carry the data's own units ([`Units`]). Long records are thinned to the smallest and
//! largest sample per pixel column ([`minmax_decimate`]), which keeps every peak.
// Units in brackets (`[s]`, `[Hz]`) are not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

use plotters::coord::Shift;
use plotters::prelude::*;
use rustfft::num_complex::Complex64;

use super::plot::PlotError;
use crate::ident::ss::{ContinuousSs, StateSpace};
use crate::ident::validate::CorrelationTest;

/// Units of the input and output signals as the data carry them.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Units {
    /// input unit (`N·m` for a rotary joint, `N` for a linear axis)
    pub input: String,
    /// output unit (`rad` or `m` for an angle/position, `rad/s` or `m/s` for a velocity)
    pub output: String,
}

impl Units {
    /// A rotary joint (`linear` false: torque [N·m], angle [rad]) or a linear axis
    /// (force [N], position [m]); `velocity` when the output is the motor velocity.
    pub fn joint(linear: bool, velocity: bool) -> Self {
        let (i, o) = if linear { ("N", "m") } else { ("N·m", "rad") };
        Units {
            input: i.into(),
            output: if velocity { format!("{o}/s") } else { o.into() },
        }
    }

    /// the unit of the output's time derivative (`rad` → `rad/s`, `rad/s` → `rad/s²`)
    pub fn output_rate(&self) -> String {
        match self.output.strip_suffix("/s") {
            Some(base) => format!("{base}/s²"),
            None => format!("{}/s", self.output),
        }
    }
}

const COLORS: [RGBColor; 6] = [
    RGBColor(200, 30, 30),
    RGBColor(30, 90, 200),
    RGBColor(20, 140, 60),
    RGBColor(150, 60, 170),
    RGBColor(220, 130, 0),
    RGBColor(0, 150, 160),
];

/// colour of the `i`-th model
fn color(i: usize) -> RGBColor {
    COLORS[i % COLORS.len()]
}

fn draw_err<E: std::fmt::Display>(what: &str) -> impl Fn(E) -> PlotError + '_ {
    move |e| PlotError::Draw {
        what: what.into(),
        msg: e.to_string(),
    }
}

/// At most two samples per column of `columns` columns: the smallest and the largest of
/// each run of `len / columns` samples, in time order, as `(index, value)`; every sample
/// when there are no more than `2 columns`. Non-finite samples are left out.
pub fn minmax_decimate(values: &[f64], columns: usize) -> Vec<(usize, f64)> {
    let finite = |&(_, v): &(usize, &f64)| v.is_finite();
    if values.len() <= 2 * columns.max(1) {
        return values
            .iter()
            .enumerate()
            .filter(finite)
            .map(|(k, v)| (k, *v))
            .collect();
    }
    let per = values.len().div_ceil(columns.max(1));
    let mut out = Vec::with_capacity(2 * columns + 2);
    for (c, chunk) in values.chunks(per).enumerate() {
        let base = c * per;
        let mut lo: Option<(usize, f64)> = None;
        let mut hi: Option<(usize, f64)> = None;
        for (k, v) in chunk.iter().enumerate().filter(finite) {
            if lo.is_none_or(|(_, l)| *v < l) {
                lo = Some((base + k, *v));
            }
            if hi.is_none_or(|(_, h)| *v > h) {
                hi = Some((base + k, *v));
            }
        }
        match (lo, hi) {
            (Some(a), Some(b)) if a.0 == b.0 => out.push(a),
            (Some(a), Some(b)) => {
                let (first, second) = if a.0 < b.0 { (a, b) } else { (b, a) };
                out.push(first);
                out.push(second);
            }
            _ => {}
        }
    }
    out
}

/// One legend entry: a line, a marker or both, and its text.
struct Entry {
    text: String,
    color: RGBColor,
    line: bool,
    /// `Some('x')` a cross, `Some('o')` a circle
    marker: Option<char>,
}

/// Draws `entries` one under the other into `area` (a strip beside the plot).
fn draw_legend(
    area: &DrawingArea<SVGBackend<'_>, Shift>,
    entries: &[Entry],
    what: &str,
) -> Result<(), PlotError> {
    let font = ("sans-serif", 14).into_font();
    for (i, e) in entries.iter().enumerate() {
        let y = 10 + 20 * i as i32;
        let style = e.color.stroke_width(2);
        if e.line {
            area.draw(&PathElement::new(vec![(6, y), (30, y)], style))
                .map_err(draw_err(what))?;
        }
        match e.marker {
            Some('x') => area
                .draw(&Cross::new((18, y), 4, style))
                .map_err(draw_err(what))?,
            Some(_) => area
                .draw(&Circle::new((18, y), 4, style))
                .map_err(draw_err(what))?,
            None => {}
        }
        area.draw(&Text::new(
            e.text.clone(),
            (38, y - 7),
            font.clone().color(&BLACK),
        ))
        .map_err(draw_err(what))?;
    }
    Ok(())
}

/// `lo..hi` padded by 5 % (a unit range around a constant), from finite values
fn padded_range(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if !lo.is_finite() {
        return None;
    }
    let span = if hi > lo { hi - lo } else { lo.abs().max(1.0) };
    Some((lo - 0.05 * span, hi + 0.05 * span))
}

/// One model's simulated output in a [`ComparePanel`].
#[derive(Clone, Copy, Debug)]
pub struct CompareModel<'a> {
    /// model name
    pub name: &'a str,
    /// simulated output, one value per measured sample [output unit]
    pub simulated: &'a [f64],
    /// its FIT [%], as the command prints it
    pub fit_percent: f64,
}

/// One record of [`compare_svg`]: the measured output and every model's simulation.
#[derive(Clone, Debug)]
pub struct ComparePanel<'a> {
    /// panel title (`estimation: FILE`, `validation: FILE`)
    pub title: String,
    /// time of the first sample [s]
    pub t0: f64,
    /// sample interval [s]
    pub ts: f64,
    /// measured output [output unit]
    pub measured: &'a [f64],
    /// the models
    pub models: Vec<CompareModel<'a>>,
}

/// Pixel columns of a compare/step panel's plot area: the decimation target.
const PLOT_COLUMNS: usize = 560;

/// The toolbox's `compare`: measured output against each model's simulated output over
/// time, one panel per record side by side (estimation | validation), each model's FIT
/// [%] (`fit_label`, e.g. `FIT`) in the legend under its panel; `y_desc` the output axis
/// label with its unit. Simulations leaving the measured range by more than its span are
/// clipped to it.
///
/// # Errors
/// [`PlotError::Empty`] without panels or measured samples, [`PlotError::Draw`].
pub fn compare_svg(
    title: &str,
    y_desc: &str,
    fit_label: &str,
    panels: &[ComparePanel<'_>],
) -> Result<String, PlotError> {
    const W: &str = "compare";
    if panels.is_empty() || panels.iter().any(|p| p.measured.len() < 2) {
        return Err(PlotError::Empty(W.into()));
    }
    let most = panels.iter().map(|p| p.models.len()).max().unwrap_or(0);
    let legend_h = 14 + 20 * (most as u32 + 1);
    let mut svg = String::new();
    {
        // one panel still leaves the title its width
        let w = (660 * panels.len() as u32).max(1000);
        let root = SVGBackend::with_string(&mut svg, (w, 440 + legend_h)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err(W))?;
        let root = root
            .titled(title, ("sans-serif", 18))
            .map_err(draw_err(W))?;
        for (area, p) in root.split_evenly((1, panels.len())).iter().zip(panels) {
            let (plot, legend) = area.split_vertically(area.dim_in_pixel().1 - legend_h);
            let (mlo, mhi) =
                padded_range(p.measured.iter().copied()).ok_or(PlotError::Empty(W.into()))?;
            let span = mhi - mlo;
            let sims = p.models.iter().flat_map(|m| m.simulated.iter().copied());
            let (slo, shi) = padded_range(sims).unwrap_or((mlo, mhi));
            let (lo, hi) = (slo.max(mlo - span).min(mlo), shi.min(mhi + span).max(mhi));
            let n = p
                .models
                .iter()
                .map(|m| m.simulated.len())
                .fold(p.measured.len(), usize::max);
            let t1 = p.t0 + (n - 1) as f64 * p.ts;
            let mut chart = ChartBuilder::on(&plot)
                .caption(&p.title, ("sans-serif", 15))
                .margin(10)
                .x_label_area_size(35)
                .y_label_area_size(70)
                .build_cartesian_2d(p.t0..t1, lo..hi)
                .map_err(draw_err(W))?;
            chart
                .configure_mesh()
                .x_desc("time [s]")
                .y_desc(y_desc)
                .light_line_style(WHITE.mix(0.0))
                .draw()
                .map_err(draw_err(W))?;
            let line = |v: &[f64]| -> Vec<(f64, f64)> {
                minmax_decimate(v, PLOT_COLUMNS)
                    .into_iter()
                    .map(|(k, y)| (p.t0 + k as f64 * p.ts, y.clamp(lo, hi)))
                    .collect()
            };
            chart
                .draw_series(LineSeries::new(line(p.measured), BLACK.stroke_width(2)))
                .map_err(draw_err(W))?;
            let mut entries = vec![Entry {
                text: "measured".into(),
                color: BLACK,
                line: true,
                marker: None,
            }];
            for (i, m) in p.models.iter().enumerate() {
                chart
                    .draw_series(LineSeries::new(line(m.simulated), color(i).stroke_width(1)))
                    .map_err(draw_err(W))?;
                entries.push(Entry {
                    text: format!("{}: {fit_label} {:.2} %", m.name, m.fit_percent),
                    color: color(i),
                    line: true,
                    marker: None,
                });
            }
            draw_legend(&legend.margin(4, 0, 70, 0), &entries, W)?;
        }
        root.present().map_err(draw_err(W))?;
    }
    Ok(svg)
}

/// One row of [`resid_svg`]: a model's residual tests on one record.
#[derive(Clone, Copy, Debug)]
pub struct ResidRow<'a> {
    /// `MODEL on RECORD`
    pub label: &'a str,
    /// residual autocorrelation ([`crate::ident::validate::whiteness_test`])
    pub whiteness: &'a CorrelationTest,
    /// input–residual cross-correlation
    /// ([`crate::ident::validate::input_independence_test`])
    pub independence: &'a CorrelationTest,
}

/// the test's figures and verdict in one short line
fn verdict(t: &CorrelationTest) -> String {
    if t.non_finite > 0 {
        return format!("FAIL: {} residual samples not finite", t.non_finite);
    }
    format!(
        "{}: {} of {} {} outside ({} allowed), ζ {:.1} {} {} {:.1}",
        if t.pass { "pass" } else { "FAIL" },
        t.outside,
        t.lags.len(),
        t.unit,
        t.allowed,
        t.statistic,
        if t.statistic <= t.critical {
            "≤"
        } else {
            ">"
        },
        if t.unit == "lines" {
            "2 × its mean"
        } else {
            "χ² 99 %"
        },
        t.critical
    )
}

/// The toolbox's `resid`: per row, the residual autocorrelation (left) and the
/// input–residual cross-correlation (right) at the lags the tests computed, as stems
/// (red outside the band), with the tests' 99 % band ±bound shaded and its edges drawn
/// dashed; the caption states the bound and the verdict.
///
/// # Errors
/// [`PlotError::Empty`] without rows, [`PlotError::Draw`].
pub fn resid_svg(title: &str, rows: &[ResidRow<'_>]) -> Result<String, PlotError> {
    const W: &str = "resid";
    if rows.is_empty() {
        return Err(PlotError::Empty(W.into()));
    }
    let mut svg = String::new();
    {
        let h = 40 + 300 * rows.len() as u32;
        let root = SVGBackend::with_string(&mut svg, (1200, h)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err(W))?;
        let root = root
            .titled(title, ("sans-serif", 18))
            .map_err(draw_err(W))?;
        let cells = root.split_evenly((rows.len(), 2));
        for (r, row) in rows.iter().enumerate() {
            for (c, t) in [row.whiteness, row.independence].into_iter().enumerate() {
                let area = &cells[2 * r + c];
                let (lag0, lag1) = (
                    t.lags.first().copied().unwrap_or(0),
                    t.lags.last().copied().unwrap_or(1),
                );
                // a correlation stays within ±1; a standardised line residual does not
                // (shown up to ten times its bound)
                let cap = if t.unit == "lines" {
                    10.0 * t.bound
                } else {
                    1.0
                };
                let top = t
                    .values
                    .iter()
                    .filter(|v| v.is_finite())
                    .fold(2.0 * t.bound, |a, v| a.max(v.abs()))
                    .min(cap)
                    * 1.15;
                let bottom = if t.unit == "lines" { 0.0 } else { -top };
                let (head, body) = area.split_vertically(40);
                for (k, (text, size)) in [
                    (format!("{}: {}", row.label, t.name), 14),
                    (format!("99 % band ±{:.4}; {}", t.bound, verdict(t)), 12),
                ]
                .into_iter()
                .enumerate()
                {
                    head.draw(&Text::new(
                        text,
                        (70, 4 + 18 * k as i32),
                        ("sans-serif", size).into_font().color(&BLACK),
                    ))
                    .map_err(draw_err(W))?;
                }
                let mut chart = ChartBuilder::on(&body)
                    .margin(8)
                    .x_label_area_size(32)
                    .y_label_area_size(60)
                    .build_cartesian_2d(lag0 as f64 - 0.8..lag1 as f64 + 0.8, bottom..top)
                    .map_err(draw_err(W))?;
                chart
                    .configure_mesh()
                    .x_desc(if c == 0 && t.unit == "lines" {
                        "excited line (index)"
                    } else if c == 0 {
                        "lag [samples]"
                    } else {
                        "lag τ [samples] (u(t − τ), past inputs)"
                    })
                    .y_desc(if t.unit == "lines" {
                        "|Ĝ − G| / σ"
                    } else {
                        "normalised correlation"
                    })
                    .light_line_style(WHITE.mix(0.0))
                    .draw()
                    .map_err(draw_err(W))?;
                let (x0, x1) = (lag0 as f64 - 0.8, lag1 as f64 + 0.8);
                chart
                    .draw_series(std::iter::once(Rectangle::new(
                        [(x0, -t.bound), (x1, t.bound)],
                        RGBColor(250, 220, 80).mix(0.35).filled(),
                    )))
                    .map_err(draw_err(W))?;
                for b in [t.bound, -t.bound] {
                    chart
                        .draw_series(DashedLineSeries::new(
                            [(x0, b), (x1, b)],
                            6,
                            4,
                            RGBColor(200, 120, 0).stroke_width(2),
                        ))
                        .map_err(draw_err(W))?;
                }
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        vec![(x0, 0.0), (x1, 0.0)],
                        BLACK.mix(0.5),
                    )))
                    .map_err(draw_err(W))?;
                let stems = t.lags.iter().zip(&t.values).filter(|(_, v)| v.is_finite());
                for (&k, &v) in stems {
                    let col = if v.abs() > t.bound {
                        RGBColor(200, 30, 30)
                    } else {
                        RGBColor(30, 90, 200)
                    };
                    let (x, y) = (k as f64, v.clamp(-top, top));
                    chart
                        .draw_series([
                            PathElement::new(vec![(x, 0.0), (x, y)], col.stroke_width(2))
                                .into_dyn(),
                            Circle::new((x, y), 3, col.filled()).into_dyn(),
                        ])
                        .map_err(draw_err(W))?;
                }
            }
        }
        root.present().map_err(draw_err(W))?;
    }
    Ok(svg)
}

/// Poles and zeros of one model for [`pzmap_svg`], in the s-plane divided by 2π [Hz].
#[derive(Clone, Debug)]
pub struct PzModel {
    /// model name
    pub name: String,
    /// poles s/2π [Hz]
    pub poles_hz: Vec<Complex64>,
    /// zeros s/2π [Hz]
    pub zeros_hz: Vec<Complex64>,
}

impl PzModel {
    /// The roots of a model as s/2π [Hz]: those of its continuous form when there is one,
    /// else the discrete model's mapped by `s = ln(z)/Ts` (the continuous equivalent).
    pub fn new(name: &str, model: &StateSpace, continuous: Option<&ContinuousSs>) -> Self {
        let two_pi = 2.0 * std::f64::consts::PI;
        let (poles, zeros) = match continuous {
            Some(c) => (c.poles(), c.zeros()),
            None => {
                let to_s = |z: Complex64| z.ln() / model.ts;
                (
                    model.poles().into_iter().map(to_s).collect(),
                    model.zeros().into_iter().map(to_s).collect(),
                )
            }
        };
        PzModel {
            name: name.into(),
            poles_hz: poles.into_iter().map(|s| s / two_pi).collect(),
            zeros_hz: zeros.into_iter().map(|s| s / two_pi).collect(),
        }
    }
}

/// The toolbox's `pzmap` in the s-plane, axes Re s/2π and Im s/2π [Hz]: poles as
/// crosses, zeros as circles, one colour per model. Roots with |s|/2π above `f_max_hz`
/// (beyond the band the data show, e.g. sampling zeros) or not finite are left out and
/// counted in the caption.
///
/// # Errors
/// [`PlotError::Empty`] when no root is left, [`PlotError::Draw`].
pub fn pzmap_svg(title: &str, models: &[PzModel], f_max_hz: f64) -> Result<String, PlotError> {
    const W: &str = "pzmap";
    let shown = |r: &Complex64| r.re.is_finite() && r.im.is_finite() && r.norm() <= f_max_hz;
    let all = || {
        models
            .iter()
            .flat_map(|m| m.poles_hz.iter().chain(&m.zeros_hz))
    };
    let left_out = all().filter(|r| !shown(r)).count();
    let (mut x0, mut x1, mut ym) = (0.0f64, 0.0f64, 0.0f64);
    let mut any = false;
    for r in all().filter(|r| shown(r)) {
        any = true;
        x0 = x0.min(r.re);
        x1 = x1.max(r.re);
        ym = ym.max(r.im.abs());
    }
    if !any {
        return Err(PlotError::Empty(W.into()));
    }
    let span = (x1 - x0).max(ym).max(1e-6);
    let (x0, x1, ym) = (x0 - 0.08 * span, x1 + 0.08 * span, ym * 1.1 + 0.05 * span);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1000, 620)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err(W))?;
        let root = root
            .titled(title, ("sans-serif", 18))
            .map_err(draw_err(W))?;
        let (plot, legend) = root.split_horizontally(700);
        let caption = if left_out > 0 {
            format!("{left_out} roots beyond {f_max_hz:.0} Hz or at infinity not drawn")
        } else {
            "every root drawn".into()
        };
        let mut chart = ChartBuilder::on(&plot)
            .caption(caption, ("sans-serif", 13))
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(70)
            .build_cartesian_2d(x0..x1, -ym..ym)
            .map_err(draw_err(W))?;
        chart
            .configure_mesh()
            .x_desc("Re s / 2π [Hz]")
            .y_desc("Im s / 2π [Hz]")
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(draw_err(W))?;
        chart
            .draw_series([
                PathElement::new(vec![(x0, 0.0), (x1, 0.0)], BLACK.mix(0.4)),
                PathElement::new(vec![(0.0, -ym), (0.0, ym)], BLACK.mix(0.4)),
            ])
            .map_err(draw_err(W))?;
        let mut entries = Vec::new();
        for (i, m) in models.iter().enumerate() {
            let col = color(i);
            chart
                .draw_series(
                    m.poles_hz
                        .iter()
                        .filter(|r| shown(r))
                        .map(|r| Cross::new((r.re, r.im), 5, col.stroke_width(2))),
                )
                .map_err(draw_err(W))?;
            chart
                .draw_series(
                    m.zeros_hz
                        .iter()
                        .filter(|r| shown(r))
                        .map(|r| Circle::new((r.re, r.im), 5, col.stroke_width(2))),
                )
                .map_err(draw_err(W))?;
            entries.push(Entry {
                text: format!("{}: poles", m.name),
                color: col,
                line: false,
                marker: Some('x'),
            });
            entries.push(Entry {
                text: format!("{}: zeros", m.name),
                color: col,
                line: false,
                marker: Some('o'),
            });
        }
        draw_legend(&legend.margin(60, 0, 10, 0), &entries, W)?;
        root.present().map_err(draw_err(W))?;
    }
    Ok(svg)
}

/// Response of `model` from rest to a step of `amplitude` input units at t = 0, `n`
/// samples (`y(0)` is the feed-through `D·amplitude`).
pub fn step_response(model: &StateSpace, amplitude: f64, n: usize) -> Vec<f64> {
    model.simulate(&vec![amplitude; n], None)
}

/// Backward differences `(y(k) − y(k−1)) / ts` from rest (`y(−1) = 0`): the mean
/// rate of change over each sample interval, exact for a zero-order-hold model.
pub fn interval_rate(y: &[f64], ts: f64) -> Vec<f64> {
    let mut prev = 0.0;
    y.iter()
        .map(|v| {
            let d = (v - prev) / ts;
            prev = *v;
            d
        })
        .collect()
}

/// A step-response horizon [s] for `models`: five times the slowest time constant
/// 1/|Re s| among the poles with |s| ≥ 2π/`record_s` (slower poles act as integrators
/// within the record), between 50 samples of the coarsest model and `record_s`.
pub fn step_horizon(models: &[PzModel], ts: f64, record_s: f64) -> f64 {
    let two_pi = 2.0 * std::f64::consts::PI;
    let slowest = models
        .iter()
        .flat_map(|m| &m.poles_hz)
        .filter(|p| p.norm() * two_pi >= two_pi / record_s && p.re < 0.0)
        .map(|p| 1.0 / (two_pi * -p.re))
        .fold(0.0, f64::max);
    let lo = 50.0 * ts;
    let hi = record_s.max(lo);
    if slowest > 0.0 {
        (5.0 * slowest).clamp(lo, hi)
    } else {
        hi.min(1000.0 * ts).max(lo)
    }
}

/// One curve of [`step_svg`].
#[derive(Clone, Copy, Debug)]
pub struct StepCurve<'a> {
    /// model name
    pub name: &'a str,
    /// sample interval [s]
    pub ts: f64,
    /// response per sample from t = 0 [`y_desc` unit]
    pub values: &'a [f64],
}

/// The toolbox's `step`: each model's response to a unit input step over time, legend
/// in a strip to the right; `y_desc` the response axis label with its unit.
///
/// # Errors
/// [`PlotError::Empty`] without a finite value, [`PlotError::Draw`].
pub fn step_svg(title: &str, y_desc: &str, curves: &[StepCurve<'_>]) -> Result<String, PlotError> {
    const W: &str = "step";
    let (lo, hi) = padded_range(
        curves
            .iter()
            .flat_map(|c| c.values.iter().copied())
            .chain([0.0]),
    )
    .ok_or(PlotError::Empty(W.into()))?;
    let t1 = curves
        .iter()
        .map(|c| c.values.len().saturating_sub(1) as f64 * c.ts)
        .fold(0.0, f64::max);
    if t1 <= 0.0 {
        return Err(PlotError::Empty(W.into()));
    }
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1000, 480)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err(W))?;
        let root = root
            .titled(title, ("sans-serif", 16))
            .map_err(draw_err(W))?;
        let (plot, legend) = root.split_horizontally(720);
        let mut chart = ChartBuilder::on(&plot)
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(80)
            .build_cartesian_2d(0.0..t1, lo..hi)
            .map_err(draw_err(W))?;
        chart
            .configure_mesh()
            .x_desc("time [s]")
            .y_desc(y_desc)
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(draw_err(W))?;
        let mut entries = Vec::new();
        for (i, c) in curves.iter().enumerate() {
            chart
                .draw_series(LineSeries::new(
                    minmax_decimate(c.values, PLOT_COLUMNS)
                        .into_iter()
                        .map(|(k, v)| (k as f64 * c.ts, v)),
                    color(i).stroke_width(2),
                ))
                .map_err(draw_err(W))?;
            entries.push(Entry {
                text: c.name.to_string(),
                color: color(i),
                line: true,
                marker: None,
            });
        }
        draw_legend(&legend.margin(30, 0, 10, 0), &entries, W)?;
        root.present().map_err(draw_err(W))?;
    }
    Ok(svg)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector, RowDVector};

    #[test]
    fn minmax_decimation_keeps_every_extreme_in_time_order() {
        // a slow sine with one-sample spikes that a plain every-k-th thinning drops
        let mut v: Vec<f64> = (0..10_000).map(|k| (k as f64 * 1e-3).sin()).collect();
        v[1234] = 5.0;
        v[7777] = -4.0;
        v[500] = f64::NAN;
        let d = minmax_decimate(&v, 100);
        assert!(d.len() <= 200, "{}", d.len());
        assert!(d.contains(&(1234, 5.0)) && d.contains(&(7777, -4.0)));
        assert!(d.windows(2).all(|w| w[0].0 < w[1].0));
        assert!(d.iter().all(|(_, y)| y.is_finite()));
        // short records stay whole
        assert_eq!(minmax_decimate(&[1.0, 2.0, 3.0], 100).len(), 3);
    }

    /// rigid body J θ̈ = τ − Fv θ̇, output θ, ZOH at `ts`
    fn rigid(j: f64, fv: f64, ts: f64) -> (StateSpace, ContinuousSs) {
        let c = ContinuousSs {
            f: DMatrix::from_row_slice(2, 2, &[0.0, 1.0, 0.0, -fv / j]),
            g: DVector::from_vec(vec![0.0, 1.0 / j]),
            h: RowDVector::from_vec(vec![1.0, 0.0]),
            d: 0.0,
        };
        (c.zoh(ts), c)
    }

    #[test]
    fn the_velocity_step_response_of_a_rigid_body_is_the_analytic_one() {
        // θ(t) = (t − T (1 − e^{−t/T})) / Fv for a unit torque step, T = J / Fv;
        // the interval-mean velocity is its backward difference over Ts
        let (j, fv, ts) = (0.02, 0.1, 1e-3);
        let (d, _) = rigid(j, fv, ts);
        let tc = j / fv;
        let theta = |t: f64| (t - tc * (1.0 - (-t / tc).exp())) / fv;
        let y = step_response(&d, 1.0, 2000);
        let v = interval_rate(&y, ts);
        for k in [0usize, 1, 10, 100, 999, 1999] {
            let t = k as f64 * ts;
            let exact_y = theta(t);
            let exact_v = if k == 0 {
                0.0
            } else {
                (theta(t) - theta(t - ts)) / ts
            };
            assert!(
                (y[k] - exact_y).abs() < 1e-9 * (1.0 + exact_y.abs()),
                "k {k}"
            );
            assert!(
                (v[k] - exact_v).abs() < 1e-8,
                "k {k}: {} vs {exact_v}",
                v[k]
            );
        }
        // after 10 time constants the velocity is 1/Fv
        assert!((v[1999] - 1.0 / fv).abs() < 1e-3 / fv);
    }

    #[test]
    fn pole_zero_map_puts_the_rigid_body_pole_at_its_corner_frequency() {
        let (j, fv, ts) = (0.02, 0.1, 1e-3);
        let (d, c) = rigid(j, fv, ts);
        let corner = fv / j / (2.0 * std::f64::consts::PI);
        for m in [PzModel::new("c", &d, Some(&c)), PzModel::new("d", &d, None)] {
            let mut re: Vec<f64> = m.poles_hz.iter().map(|p| p.re).collect();
            re.sort_by(f64::total_cmp);
            assert!((re[0] + corner).abs() < 1e-6 * corner, "{re:?}");
            assert!(re[1].abs() < 1e-6, "{re:?}");
            assert!(m.poles_hz.iter().all(|p| p.im.abs() < 1e-6));
        }
        let svg = pzmap_svg("pz", &[PzModel::new("rigid", &d, Some(&c))], 100.0).unwrap();
        assert!(svg.contains("Re s / 2π [Hz]") && svg.contains("rigid: poles"));
        // the horizon is five time constants J/Fv
        let h = step_horizon(&[PzModel::new("c", &d, Some(&c))], ts, 10.0);
        assert!((h - 5.0 * j / fv).abs() < 1e-9, "{h}");
    }

    #[test]
    fn compare_and_resid_show_the_fit_and_the_band_they_are_given() {
        let y: Vec<f64> = (0..5000).map(|k| (k as f64 * 0.01).sin()).collect();
        let yh: Vec<f64> = y.iter().map(|v| 0.9 * v).collect();
        let p = ComparePanel {
            title: "estimation: x.csv".into(),
            t0: 0.0,
            ts: 0.001,
            measured: &y,
            models: vec![CompareModel {
                name: "rigid",
                simulated: &yh,
                fit_percent: 90.0,
            }],
        };
        let svg = compare_svg("compare", "position [m]", "FIT", &[p.clone(), p]).unwrap();
        assert_eq!(svg.matches("rigid: FIT 90.00 %").count(), 2);
        assert!(svg.contains("position [m]"));
        // thinned: two panels × two lines × at most 2 × 560 points, not 5000
        assert!(svg.len() < 200_000, "{}", svg.len());
        let e: Vec<f64> = (0..1000)
            .map(|k| ((k * 7919) % 101) as f64 - 50.0)
            .collect();
        let u: Vec<f64> = (0..1000).map(|k| ((k * 104_729) % 97) as f64).collect();
        let w = crate::ident::validate::whiteness_test(&e, 25).unwrap();
        let i = crate::ident::validate::input_independence_test(&e, &u, 25).unwrap();
        let row = ResidRow {
            label: "rigid on x.csv",
            whiteness: &w,
            independence: &i,
        };
        let svg = resid_svg("resid", &[row]).unwrap();
        assert!(svg.contains(&format!("99 % band ±{:.4}", w.bound)));
        assert!(svg.contains(&format!("99 % band ±{:.4}", i.bound)));
        assert!(matches!(resid_svg("x", &[]), Err(PlotError::Empty(_))));
    }
}
