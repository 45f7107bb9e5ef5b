//! SVG plots: the line spectrum of a periodic experiment (seed 000 Fig. 3)
//! and Bode plots of models over a measured FRF with its ±2σ band (seed 000
//! Figs. 5–6).
//!
//! Functions take plain data (frequencies, amplitudes, complex responses),
//! so any command can call them; they render to a `String` (testable, no
//! IO) that the caller stores. Only SVG: PNG would need a font
//! rasteriser and system font files, which this crate does not pull in.
// Units in brackets (`[s]`, `[Hz]`, `[dB]`) are not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

use plotters::prelude::*;
use rustfft::num_complex::Complex64;

use crate::ident::frf::{unwrap_deg, FrfAnalysis, LineClass, SignalSpectrum};
use crate::ident::validate::{BodeCurve, FrfBand};

/// Errors of plotting.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// the drawing backend failed
    #[error("plot `{what}`: {msg}")]
    Draw {
        /// plot name
        what: String,
        /// backend message
        msg: String,
    },
    /// nothing to plot
    #[error("plot `{0}`: no data")]
    Empty(String),
}

fn draw_err<E: std::fmt::Display>(what: &str) -> impl Fn(E) -> PlotError + '_ {
    move |e| PlotError::Draw {
        what: what.into(),
        msg: e.to_string(),
    }
}

/// One panel of the spectrum plot: a signal's period-averaged amplitude per
/// line, its noise level and the class of each line.
#[derive(Clone, Copy, Debug)]
pub struct SpectrumPanel<'a> {
    /// panel title (signal name and unit)
    pub title: &'a str,
    /// frequency of each line [Hz]
    pub freq_hz: &'a [f64],
    /// amplitude per line [signal unit]
    pub amplitude: &'a [f64],
    /// noise level (standard deviation of the mean) per line [signal unit]
    pub noise: &'a [f64],
    /// class per line
    pub classes: &'a [LineClass],
}

fn to_db(x: f64) -> f64 {
    20.0 * x.max(1e-300).log10()
}

/// Fig. 3 of seed 000 for one analysis: θm, u and (when present) θref
/// panels in that order, as the paper stacks them.
///
/// # Errors
/// As [`spectrum_svg`].
pub fn analysis_spectrum_svg(title: &str, a: &FrfAnalysis) -> Result<String, PlotError> {
    let freq: Vec<f64> = (0..a.classes.len()).map(|k| a.freq_hz(k)).collect();
    fn panel<'a>(
        title: &'a str,
        freq_hz: &'a [f64],
        s: &'a SignalSpectrum,
        classes: &'a [LineClass],
    ) -> SpectrumPanel<'a> {
        SpectrumPanel {
            title,
            freq_hz,
            amplitude: &s.amplitude,
            noise: &s.noise,
            classes,
        }
    }
    let mut panels = vec![
        panel("theta_m [rad]", &freq, &a.y, &a.classes),
        panel("u [N·m]", &freq, &a.u, &a.classes),
    ];
    if let Some(r) = &a.r {
        panels.push(panel("theta_ref [rad]", &freq, r, &a.classes));
    }
    spectrum_svg(title, &panels)
}

/// Fig. 3 of seed 000: one panel per signal (top to bottom as given),
/// amplitude [dB] against frequency [Hz]; excited lines '+', non-excited
/// odd lines 'x', even lines 'o', noise level as a grey line. Lines of class
/// `Dc` and `OutOfBand` are left out.
///
/// # Errors
/// [`PlotError::Empty`] without panels or lines, [`PlotError::Draw`].
pub fn spectrum_svg(title: &str, panels: &[SpectrumPanel<'_>]) -> Result<String, PlotError> {
    const W: &str = "spectrum";
    if panels.is_empty() {
        return Err(PlotError::Empty(W.into()));
    }
    let mut svg = String::new();
    {
        let h = 40 + 260 * panels.len() as u32;
        let root = SVGBackend::with_string(&mut svg, (900, h)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err(W))?;
        let root = root
            .titled(title, ("sans-serif", 20))
            .map_err(draw_err(W))?;
        let last = panels.len() - 1;
        for (i, (area, p)) in root
            .split_evenly((panels.len(), 1))
            .iter()
            .zip(panels)
            .enumerate()
        {
            let shown: Vec<usize> = (0..p.freq_hz.len())
                .filter(|&k| {
                    !matches!(
                        p.classes.get(k),
                        None | Some(LineClass::Dc | LineClass::OutOfBand)
                    )
                })
                .collect();
            if shown.is_empty() {
                return Err(PlotError::Empty(W.into()));
            }
            let fmax = shown.iter().map(|&k| p.freq_hz[k]).fold(0.0, f64::max) * 1.02;
            let vals = shown
                .iter()
                .flat_map(|&k| [to_db(p.amplitude[k]), to_db(p.noise[k])]);
            let top = vals.clone().fold(f64::NEG_INFINITY, f64::max) + 5.0;
            let excited_min = shown
                .iter()
                .filter(|&&k| p.classes[k] == LineClass::Excited)
                .map(|&k| to_db(p.amplitude[k]))
                .fold(f64::INFINITY, f64::min);
            let bottom = vals
                .fold(f64::INFINITY, f64::min)
                .max(excited_min.min(top) - 120.0)
                - 5.0;
            let mut chart = ChartBuilder::on(area)
                .caption(p.title, ("sans-serif", 16))
                .margin(8)
                .x_label_area_size(30)
                .y_label_area_size(55)
                .build_cartesian_2d(0.0..fmax, bottom..top)
                .map_err(draw_err(W))?;
            chart
                .configure_mesh()
                .x_desc("frequency [Hz]")
                .y_desc("amplitude [dB]")
                .light_line_style(WHITE.mix(0.0))
                .draw()
                .map_err(draw_err(W))?;
            chart
                .draw_series(LineSeries::new(
                    shown
                        .iter()
                        .map(|&k| (p.freq_hz[k], to_db(p.noise[k]).max(bottom))),
                    BLACK.mix(0.35),
                ))
                .map_err(draw_err(W))?
                .label("noise level")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], BLACK.mix(0.35)));
            let at = |k: usize| (p.freq_hz[k], to_db(p.amplitude[k]).max(bottom));
            let of = |c: LineClass| shown.iter().copied().filter(move |&k| p.classes[k] == c);
            chart
                .draw_series(of(LineClass::Excited).map(|k| {
                    EmptyElement::at(at(k))
                        + PathElement::new(vec![(-4, 0), (4, 0)], BLUE)
                        + PathElement::new(vec![(0, -4), (0, 4)], BLUE)
                }))
                .map_err(draw_err(W))?
                .label("excited (+)")
                .legend(|(x, y)| {
                    EmptyElement::at((x + 4, y))
                        + PathElement::new(vec![(-4, 0), (4, 0)], BLUE)
                        + PathElement::new(vec![(0, -4), (0, 4)], BLUE)
                });
            chart
                .draw_series(of(LineClass::OddNonExcited).map(|k| Cross::new(at(k), 3, RED)))
                .map_err(draw_err(W))?
                .label("odd non-excited (x)")
                .legend(|(x, y)| Cross::new((x + 4, y), 3, RED));
            chart
                .draw_series(
                    of(LineClass::Even).map(|k| Circle::new(at(k), 3, GREEN.stroke_width(1))),
                )
                .map_err(draw_err(W))?
                .label("even (o)")
                .legend(|(x, y)| Circle::new((x + 4, y), 3, GREEN.stroke_width(1)));
            if i == last {
                chart
                    .configure_series_labels()
                    .background_style(WHITE.mix(0.8))
                    .border_style(BLACK)
                    .position(SeriesLabelPosition::MiddleRight)
                    .draw()
                    .map_err(draw_err(W))?;
            }
        }
        root.present().map_err(draw_err(W))?;
    }
    Ok(svg)
}

/// colour of the FRF's ±2σ band and bars
const BAND: RGBColor = RGBColor(40, 110, 210);

/// The corner of a plot (upper right, upper left, lower left, lower right, in that order
/// of preference) whose box of 35 % × 30 % of the plot holds the fewest of `points`
/// (coordinates scaled to 0 … 1 across the plot): where a legend hides the least data.
pub fn least_covered_corner(points: impl Iterator<Item = (f64, f64)>) -> SeriesLabelPosition {
    let (w, h) = (0.35, 0.3);
    let mut count = [0usize; 4];
    for (x, y) in points.filter(|(x, y)| x.is_finite() && y.is_finite()) {
        let (right, left, top, low) = (x >= 1.0 - w, x <= w, y >= 1.0 - h, y <= h);
        count[0] += usize::from(right && top);
        count[1] += usize::from(left && top);
        count[2] += usize::from(left && low);
        count[3] += usize::from(right && low);
    }
    let best = (0..4).min_by_key(|&i| (count[i], i)).unwrap_or(0);
    [
        SeriesLabelPosition::UpperRight,
        SeriesLabelPosition::UpperLeft,
        SeriesLabelPosition::LowerLeft,
        SeriesLabelPosition::LowerRight,
    ][best]
        .clone()
}

const PALETTE: [RGBColor; 5] = [
    RGBColor(0, 0, 0),
    RGBColor(200, 30, 30),
    RGBColor(30, 90, 200),
    RGBColor(20, 140, 60),
    RGBColor(150, 60, 170),
];

/// The phases [deg] a Bode plot draws: the FRF's unwrapped continuously from its lowest
/// line ([`unwrap_deg`], the phase `analyze` prints), and each model's unwrapped along
/// its own grid, then moved by whole turns onto the FRF's branch (the median of its
/// differences from the FRF at the FRF's lines within ±180°), so that a model that
/// follows the FRF is drawn over it, never 360° away.
pub fn bode_phases(
    frf: Option<&FrfBand>,
    models: &[BodeCurve],
) -> (Option<Vec<f64>>, Vec<Vec<f64>>) {
    let frf_phase = frf.map(|f| unwrap_deg(f.g.iter().map(|g| g.arg().to_degrees())));
    let model_phase = models
        .iter()
        .map(|m| {
            let mut mp = unwrap_deg(m.response.iter().map(|g| g.arg().to_degrees()));
            if let (Some(f), Some(fp)) = (frf, &frf_phase) {
                let mut d: Vec<f64> = f
                    .freq_hz
                    .iter()
                    .zip(fp)
                    .filter_map(|(fr, p)| {
                        let i = m.freq_hz.partition_point(|x| x < fr);
                        let j = if i == 0 {
                            0
                        } else if i >= m.freq_hz.len() || fr - m.freq_hz[i - 1] < m.freq_hz[i] - fr
                        {
                            i - 1
                        } else {
                            i
                        };
                        mp.get(j).map(|q| p - q).filter(|x| x.is_finite())
                    })
                    .collect();
                if !d.is_empty() {
                    d.sort_by(f64::total_cmp);
                    let turns = (d[d.len() / 2] / 360.0).round();
                    mp.iter_mut().for_each(|q| *q += 360.0 * turns);
                }
            }
            mp
        })
        .collect();
    (frf_phase, model_phase)
}

/// Bode plot (magnitude [dB] and phase [deg] against log frequency [Hz]) of
/// `models` over a measured FRF drawn as points with capped ±2σ bars and a translucent
/// band joining them (magnitude: |Ĝ| ± 2σ; phase: ± asin(2σ/|Ĝ|), a full ±180° when
/// 2σ ≥ |Ĝ|), on top of the model lines; the legend in the magnitude panel's corner
/// that the data cover least ([`least_covered_corner`]).
///
/// # Errors
/// [`PlotError::Empty`] when there is nothing with a positive frequency,
/// [`PlotError::Draw`].
pub fn bode_svg(
    title: &str,
    frf: Option<&FrfBand>,
    models: &[BodeCurve],
) -> Result<String, PlotError> {
    bode_svg_in(title, None, frf, models)
}

/// [`bode_svg`] with the magnitude axis in dB re 1 `gain_unit` (e.g. `m/N`) when given.
///
/// # Errors
/// As [`bode_svg`].
pub fn bode_svg_in(
    title: &str,
    gain_unit: Option<&str>,
    frf: Option<&FrfBand>,
    models: &[BodeCurve],
) -> Result<String, PlotError> {
    const W: &str = "bode";
    let mag_desc = match gain_unit {
        Some(u) => format!("magnitude [dB re 1 {u}]"),
        None => "magnitude [dB]".to_string(),
    };
    let freqs = frf
        .map(|f| f.freq_hz.clone())
        .into_iter()
        .chain(models.iter().map(|m| m.freq_hz.clone()))
        .flatten()
        .filter(|f| *f > 0.0);
    let (fmin, fmax) = freqs.fold((f64::INFINITY, 0.0f64), |(a, b), f| (a.min(f), b.max(f)));
    if !fmin.is_finite() || fmax <= 0.0 {
        return Err(PlotError::Empty(W.into()));
    }
    let (fmin, fmax) = (fmin / 1.1, fmax * 1.1);
    let mag = |g: &Complex64| to_db(g.norm());
    let mut mags: Vec<f64> = models
        .iter()
        .flat_map(|m| m.response.iter().map(mag))
        .collect();
    let mut phs: Vec<f64> = Vec::new();
    let (frf_phase, model_phase) = bode_phases(frf, models);
    model_phase.iter().for_each(|p| phs.extend(p));
    if let (Some(f), Some(ph)) = (frf, &frf_phase) {
        for (g, s) in f.g.iter().zip(&f.sigma) {
            mags.push(mag(g));
            mags.push(to_db(g.norm() + 2.0 * s));
        }
        phs.extend(ph);
    }
    let finite = |v: &Vec<f64>| {
        v.iter()
            .copied()
            .filter(|x| x.is_finite() && *x > -600.0)
            .collect::<Vec<_>>()
    };
    let (mags, phs) = (finite(&mags), finite(&phs));
    let range = |v: &[f64], pad: f64| {
        let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if lo.is_finite() {
            (lo - pad, hi + pad)
        } else {
            (-1.0, 1.0)
        }
    };
    let (mlo, mhi) = range(&mags, 5.0);
    let (plo, phi) = range(&phs, 20.0);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (900, 700)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err(W))?;
        let root = root
            .titled(title, ("sans-serif", 20))
            .map_err(draw_err(W))?;
        let (top, bottom) = root.split_vertically(370);
        // the legend goes to the corner of the magnitude panel that the data cover least
        let legend_corner = {
            let (l0, l1) = (fmin.ln(), fmax.ln());
            let nx = |f: f64| (f.ln() - l0) / (l1 - l0);
            let ny = |v: f64| (v - mlo) / (mhi - mlo);
            let model_pts = models.iter().flat_map(|m| {
                m.freq_hz
                    .iter()
                    .zip(&m.response)
                    .filter(|(f, _)| **f > 0.0)
                    .map(|(f, g)| (nx(*f), ny(mag(g))))
            });
            let frf_pts = frf.into_iter().flat_map(|f| {
                f.freq_hz
                    .iter()
                    .zip(&f.g)
                    .zip(&f.sigma)
                    .flat_map(|((fr, g), s)| {
                        let m = g.norm();
                        [m, m + 2.0 * s, (m - 2.0 * s).max(m * 1e-3)]
                            .map(|v| (nx(*fr), ny(to_db(v))))
                    })
            });
            least_covered_corner(model_pts.chain(frf_pts))
        };
        let fmt_hz = |f: &f64| format!("{}", (f * 1e6).round() / 1e6);
        for (area, is_mag) in [(top, true), (bottom, false)] {
            let (lo, hi) = if is_mag { (mlo, mhi) } else { (plo, phi) };
            let mut chart = ChartBuilder::on(&area)
                .margin(8)
                .x_label_area_size(30)
                .y_label_area_size(55)
                .build_cartesian_2d((fmin..fmax).log_scale(), lo..hi)
                .map_err(draw_err(W))?;
            chart
                .configure_mesh()
                .x_desc("frequency [Hz]")
                .y_desc(if is_mag {
                    mag_desc.as_str()
                } else {
                    "phase [deg]"
                })
                .x_label_formatter(&fmt_hz)
                .light_line_style(WHITE.mix(0.0))
                .draw()
                .map_err(draw_err(W))?;
            // the FRF's ±2σ interval per line: (f, centre, low, high), clipped to the panel
            let intervals: Vec<(f64, f64, f64, f64)> = match (frf, &frf_phase) {
                (Some(f), Some(ph)) => f
                    .freq_hz
                    .iter()
                    .zip(&f.g)
                    .zip(&f.sigma)
                    .zip(ph)
                    .map(|(((fr, g), s), p)| {
                        let (c, a, b) = if is_mag {
                            let m = g.norm();
                            (
                                mag(g),
                                to_db((m - 2.0 * s).max(m * 1e-3)),
                                to_db(m + 2.0 * s),
                            )
                        } else {
                            let d = if 2.0 * s >= g.norm() {
                                180.0
                            } else {
                                (2.0 * s / g.norm()).asin().to_degrees()
                            };
                            (*p, p - d, p + d)
                        };
                        (*fr, c, a.clamp(lo, hi), b.clamp(lo, hi))
                    })
                    .collect(),
                _ => Vec::new(),
            };
            if !intervals.is_empty() {
                // the band between the lines, translucent, under everything else
                let band: Vec<(f64, f64)> = intervals
                    .iter()
                    .map(|i| (i.0, i.3))
                    .chain(intervals.iter().rev().map(|i| (i.0, i.2)))
                    .collect();
                chart
                    .draw_series(std::iter::once(Polygon::new(band, BAND.mix(0.25).filled())))
                    .map_err(draw_err(W))?;
            }
            for (i, (m, mp)) in models.iter().zip(&model_phase).enumerate() {
                let color = PALETTE[(i + 1) % PALETTE.len()];
                let pts = m
                    .freq_hz
                    .iter()
                    .zip(&m.response)
                    .zip(mp)
                    .filter(|((f, _), _)| **f > 0.0);
                chart
                    .draw_series(LineSeries::new(
                        pts.map(|((f, g), p)| {
                            (
                                *f,
                                if is_mag {
                                    mag(g).clamp(lo, hi)
                                } else {
                                    p.clamp(lo, hi)
                                },
                            )
                        }),
                        color.stroke_width(2),
                    ))
                    .map_err(draw_err(W))?
                    .label(m.name.as_str())
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 15, y)], color.stroke_width(2))
                    });
            }
            if !intervals.is_empty() {
                // capped ±2σ bars and the points, over the model lines
                chart
                    .draw_series(intervals.iter().map(|&(fr, _, a, b)| {
                        PathElement::new(vec![(fr, a), (fr, b)], BAND.stroke_width(2))
                    }))
                    .map_err(draw_err(W))?;
                chart
                    .draw_series(intervals.iter().flat_map(|&(fr, _, a, b)| {
                        [a, b].map(|v| {
                            EmptyElement::at((fr, v))
                                + PathElement::new(vec![(-3, 0), (3, 0)], BAND.stroke_width(2))
                        })
                    }))
                    .map_err(draw_err(W))?;
                chart
                    .draw_series(
                        intervals
                            .iter()
                            .map(|&(fr, c, _, _)| Circle::new((fr, c), 2, BLACK.filled())),
                    )
                    .map_err(draw_err(W))?
                    .label("FRF ± 2σ (band and bars)")
                    .legend(|(x, y)| {
                        EmptyElement::at((x + 4, y))
                            + Rectangle::new([(-4, -6), (4, 6)], BAND.mix(0.25).filled())
                            + PathElement::new(vec![(0, -6), (0, 6)], BAND.stroke_width(2))
                            + Circle::new((0, 0), 2, BLACK.filled())
                    });
            }
            if is_mag {
                chart
                    .configure_series_labels()
                    .background_style(WHITE.mix(0.8))
                    .border_style(BLACK)
                    .position(legend_corner.clone())
                    .draw()
                    .map_err(draw_err(W))?;
            }
        }
        root.present().map_err(draw_err(W))?;
    }
    Ok(svg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spectrum_svg_draws_one_marker_per_line_class() {
        let freq: Vec<f64> = (0..20).map(|k| k as f64 * 0.5).collect();
        let classes: Vec<LineClass> = (0..20)
            .map(|k| match k {
                0 => LineClass::Dc,
                1 | 3 | 9 | 11 => LineClass::Excited,
                k if k > 12 => LineClass::OutOfBand,
                k if k % 2 == 0 => LineClass::Even,
                _ => LineClass::OddNonExcited,
            })
            .collect();
        let amp: Vec<f64> = classes
            .iter()
            .map(|c| if *c == LineClass::Excited { 1.0 } else { 1e-3 })
            .collect();
        let noise = vec![1e-4; 20];
        let p = SpectrumPanel {
            title: "u [N·m]",
            freq_hz: &freq,
            amplitude: &amp,
            noise: &noise,
            classes: &classes,
        };
        let svg = spectrum_svg("test", &[p, p, p]).unwrap();
        assert!(svg.starts_with("<svg"));
        // 3 panels × 6 even lines (2..12) drawn as circles, plus one legend circle
        assert_eq!(svg.matches("<circle").count(), 3 * 6 + 1, "{svg}");
        assert!(svg.contains("odd non-excited (x)"));
        assert!(matches!(spectrum_svg("x", &[]), Err(PlotError::Empty(_))));
    }

    #[test]
    fn the_legend_goes_to_the_emptiest_corner() {
        // a line falling from upper left to lower right leaves the other two corners;
        // upper right is preferred
        let falling = (0..100).map(|k| (k as f64 / 99.0, 1.0 - k as f64 / 99.0));
        assert!(matches!(
            least_covered_corner(falling),
            SeriesLabelPosition::UpperRight
        ));
        // a rising one fills upper right and lower left: upper left is next
        let rising = (0..100).map(|k| (k as f64 / 99.0, k as f64 / 99.0));
        assert!(matches!(
            least_covered_corner(rising),
            SeriesLabelPosition::UpperLeft
        ));
        // data in every corner but the lower right
        let pts = [(0.9, 0.9), (0.1, 0.9), (0.1, 0.1)].into_iter();
        assert!(matches!(
            least_covered_corner(pts),
            SeriesLabelPosition::LowerRight
        ));
    }

    #[test]
    fn bode_svg_draws_frf_points_and_model_lines() {
        let f: Vec<f64> = (1..=30).map(|k| k as f64).collect();
        let g: Vec<Complex64> = f
            .iter()
            .map(|x| Complex64::new(1.0, 0.0) / Complex64::new(1.0, x / 10.0))
            .collect();
        let band = FrfBand {
            freq_hz: f.clone(),
            g: g.clone(),
            sigma: vec![0.01; 30],
        };
        let m = BodeCurve {
            name: "first order".into(),
            freq_hz: f.clone(),
            response: g,
        };
        let svg = bode_svg("bode", Some(&band), &[m]).unwrap();
        // 30 points in each of two panels + 1 legend marker
        assert_eq!(svg.matches("<circle").count(), 61);
        assert!(svg.contains("first order") && svg.contains("phase [deg]"));
        assert!(matches!(bode_svg("x", None, &[]), Err(PlotError::Empty(_))));
    }

    #[test]
    fn the_model_is_drawn_on_the_frfs_branch_and_both_are_continuous() {
        // an integrator behind a 58.3 ms delay: −90° at 0 Hz, −300° at 10 Hz, where the
        // FRF's lowest line is put on the branch (−270°, 90°] at +60°; the model,
        // unwrapped from 0.1 Hz, would be drawn 360° below it
        let tau = 210.0 / 360.0 / 10.0;
        let resp = |f: f64| {
            let w = 2.0 * std::f64::consts::PI * f;
            Complex64::from_polar(1.0 / w, -w * tau - std::f64::consts::FRAC_PI_2)
        };
        let lines: Vec<f64> = (10..=40).map(f64::from).collect();
        let grid: Vec<f64> = (0..560).map(|k| 0.1 * 1.0116f64.powi(k)).collect();
        let band = FrfBand {
            freq_hz: lines.clone(),
            g: lines.iter().map(|f| resp(*f)).collect(),
            sigma: vec![1e-4; lines.len()],
        };
        let model = BodeCurve {
            name: "delay".into(),
            freq_hz: grid.clone(),
            response: grid.iter().map(|f| resp(*f)).collect(),
        };
        let (fp, mp) = bode_phases(Some(&band), &[model]);
        let (fp, mp) = (fp.unwrap(), &mp[0]);
        assert!((fp[0] - 60.0).abs() < 1e-6, "{}", fp[0]);
        for (f, p) in lines.iter().zip(&fp) {
            let i = grid.partition_point(|x| x < f);
            // the grid point just above the line, up to 1.2 % higher: at most 10° lower
            assert!((mp[i] - p).abs() < 15.0, "{f} Hz: model {} FRF {p}", mp[i]);
        }
        assert!(mp.windows(2).all(|w| (w[1] - w[0]).abs() < 180.0));
        assert!(fp.windows(2).all(|w| (w[1] - w[0]).abs() < 180.0));
    }
}

/// One signal of a [`time_svg`] plot.
#[derive(Clone, Copy, Debug)]
pub struct TimeSeries<'a> {
    /// legend
    pub name: &'a str,
    /// value per sample (time from `t0` in steps of `ts`)
    pub values: &'a [f64],
}

/// Signals over time in one panel (e.g. measured against simulated motor velocity):
/// sample `k` at `t0 + k ts` [s], `y_desc` the axis label with its unit.
///
/// # Errors
/// [`PlotError::Empty`] without finite samples, [`PlotError::Draw`].
pub fn time_svg(
    title: &str,
    y_desc: &str,
    t0: f64,
    ts: f64,
    series: &[TimeSeries<'_>],
) -> Result<String, PlotError> {
    const W: &str = "time";
    let n = series.iter().map(|s| s.values.len()).max().unwrap_or(0);
    let finite = series
        .iter()
        .flat_map(|s| s.values.iter().copied())
        .filter(|v| v.is_finite());
    let (lo, hi) = finite.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    if n < 2 || !lo.is_finite() {
        return Err(PlotError::Empty(W.into()));
    }
    let pad = 0.05 * (hi - lo).max(1e-12);
    // headroom above the data for the legend
    let (lo, hi) = (lo - pad, hi + 5.0 * pad);
    let t1 = t0 + (n - 1) as f64 * ts;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (900, 450)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err(W))?;
        let root = root
            .titled(title, ("sans-serif", 18))
            .map_err(draw_err(W))?;
        let mut chart = ChartBuilder::on(&root)
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(65)
            .build_cartesian_2d(t0..t1, lo..hi)
            .map_err(draw_err(W))?;
        chart
            .configure_mesh()
            .x_desc("time [s]")
            .y_desc(y_desc)
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(draw_err(W))?;
        for (i, s) in series.iter().enumerate() {
            let color = PALETTE[i % PALETTE.len()];
            let width = if i == 0 { 2 } else { 1 };
            chart
                .draw_series(LineSeries::new(
                    s.values
                        .iter()
                        .enumerate()
                        .filter(|(_, v)| v.is_finite())
                        .map(|(k, v)| (t0 + k as f64 * ts, v.clamp(lo, hi))),
                    color.stroke_width(width),
                ))
                .map_err(draw_err(W))?
                .label(s.name)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 15, y)], color.stroke_width(2))
                });
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(draw_err(W))?;
        root.present().map_err(draw_err(W))?;
    }
    Ok(svg)
}

/// One curve of an [`xy_svg`] plot.
#[derive(Clone, Copy, Debug)]
pub struct XySeries<'a> {
    /// legend
    pub name: &'a str,
    /// abscissae [x unit]
    pub x: &'a [f64],
    /// ordinates [y unit]; non-finite values are left out
    pub y: &'a [f64],
    /// draw markers at the points as well as the line
    pub markers: bool,
}

/// Curves `y(x)` in one panel, `x_desc` and `y_desc` the axis labels with their units, the
/// x axis logarithmic when `log_x` (points at x ≤ 0 are then left out).
///
/// # Errors
/// [`PlotError::Empty`] without a finite point, [`PlotError::Draw`].
pub fn xy_svg(
    title: &str,
    x_desc: &str,
    y_desc: &str,
    log_x: bool,
    series: &[XySeries<'_>],
) -> Result<String, PlotError> {
    const W: &str = "xy";
    let keep = |x: f64, y: f64| x.is_finite() && y.is_finite() && (!log_x || x > 0.0);
    let pts = || {
        series.iter().flat_map(|s| {
            s.x.iter()
                .zip(s.y)
                .map(|(x, y)| (*x, *y))
                .filter(|&(x, y)| keep(x, y))
        })
    };
    let (x0, x1, y0, y1) = pts().fold(
        (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ),
        |(a, b, c, d), (x, y)| (a.min(x), b.max(x), c.min(y), d.max(y)),
    );
    if !x0.is_finite() || !y0.is_finite() {
        return Err(PlotError::Empty(W.into()));
    }
    let (x1, y1) = (
        if x1 > x0 { x1 } else { x0 + 1.0 },
        if y1 > y0 { y1 } else { y0 + 1.0 },
    );
    let pad = 0.05 * (y1 - y0);
    // headroom above the data for the legend
    let (y0, y1) = (y0 - pad, y1 + 6.0 * pad);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (900, 420)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err(W))?;
        let root = root
            .titled(title, ("sans-serif", 18))
            .map_err(draw_err(W))?;
        let mut builder = ChartBuilder::on(&root);
        builder
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(70);
        // one drawing routine over either x axis
        macro_rules! draw {
            ($chart:expr) => {{
                let mut chart = $chart;
                chart
                    .configure_mesh()
                    .x_desc(x_desc)
                    .y_desc(y_desc)
                    .light_line_style(WHITE.mix(0.0))
                    .draw()
                    .map_err(draw_err(W))?;
                for (i, s) in series.iter().enumerate() {
                    let color = PALETTE[i % PALETTE.len()];
                    // a non-finite value breaks the line
                    let mut runs: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
                    for (x, y) in s.x.iter().zip(s.y) {
                        if keep(*x, *y) {
                            runs.last_mut().expect("one run").push((*x, *y));
                        } else if !runs.last().expect("one run").is_empty() {
                            runs.push(Vec::new());
                        }
                    }
                    let line: Vec<(f64, f64)> = runs.iter().flatten().copied().collect();
                    for (k, run) in runs.iter().enumerate() {
                        let drawn = chart
                            .draw_series(LineSeries::new(
                                run.iter().copied(),
                                color.stroke_width(2),
                            ))
                            .map_err(draw_err(W))?;
                        if k == 0 {
                            drawn.label(s.name).legend(move |(x, y)| {
                                PathElement::new(vec![(x, y), (x + 15, y)], color.stroke_width(2))
                            });
                        }
                    }
                    if s.markers {
                        chart
                            .draw_series(line.iter().map(|&p| Circle::new(p, 2, color.filled())))
                            .map_err(draw_err(W))?;
                    }
                }
                chart
                    .configure_series_labels()
                    .background_style(WHITE.mix(0.8))
                    .border_style(BLACK)
                    .position(SeriesLabelPosition::UpperRight)
                    .draw()
                    .map_err(draw_err(W))?;
            }};
        }
        if log_x {
            draw!(builder
                .build_cartesian_2d((x0..x1).log_scale(), y0..y1)
                .map_err(draw_err(W))?);
        } else {
            draw!(builder
                .build_cartesian_2d(x0..x1, y0..y1)
                .map_err(draw_err(W))?);
        }
        root.present().map_err(draw_err(W))?;
    }
    Ok(svg)
}
