//! The diagnosis report: one self-contained HTML page ([`diagnosis_html`]) with the
//! verdict at the top, the figures as inline SVG ([`diagnosis_figures`]) and the ranked
//! candidates as a table. No script, no style sheet, font or image from elsewhere: the
//! page opens from disk and shows everything without JavaScript. Pure: it returns a
//! `String` that the caller stores.
// Units in brackets (`[s]`, `[Hz]`, `[dB]`) are not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

use std::fmt::Write;

use super::plot::{bode_svg, spectrum_svg, time_svg, xy_svg, PlotError, SpectrumPanel};
use super::plot::{TimeSeries, XySeries};
use crate::data::{fmt_sig, Percent};
use crate::diagnose::series::DiagnosisSeries;
use crate::diagnose::{Candidate, Diagnosis};

/// One figure of the report.
#[derive(Clone, Debug, PartialEq)]
pub struct Figure {
    /// element id in the page (`fig-frf`, …), also the stem of its SVG files
    pub id: &'static str,
    /// the caption in words
    pub caption: String,
    /// its panels as SVG documents (none when the data do not allow it)
    pub svgs: Vec<String>,
    /// why there is no panel (a capture that is not periodic), shown in its place
    pub note: Option<String>,
}

impl Figure {
    /// The file names of its panels: `<id>.svg`, or `<id>-1.svg`, `<id>-2.svg`, … [-]
    pub fn file_names(&self) -> Vec<String> {
        match self.svgs.len() {
            1 => vec![format!("{}.svg", self.id)],
            n => (1..=n).map(|i| format!("{}-{i}.svg", self.id)).collect(),
        }
    }
}

/// Ids of the figures [`diagnosis_figures`] returns, in order.
pub const FIGURE_IDS: [&str; 5] = [
    "fig-frf",
    "fig-residual-spectrum",
    "fig-distortion",
    "fig-residual-maps",
    "fig-time",
];

/// Most panels one figure has (the residual maps: velocity, deflection, angle).
pub const MAX_PANELS: usize = 3;

/// `text` with `&`, `<`, `>` and `"` escaped for HTML.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            c => out.push(c),
        }
    }
    out
}

fn db(x: f64) -> f64 {
    20.0 * x.max(1e-300).log10()
}

/// The figures of a diagnosis ([`FIGURE_IDS`], in that order).
///
/// # Errors
/// [`PlotError`] of a plot that cannot be drawn.
pub fn diagnosis_figures(d: &Diagnosis, s: &DiagnosisSeries) -> Result<Vec<Figure>, PlotError> {
    let not_periodic = |what: &str| {
        Some(format!(
            "no {what}: none of the captures is periodic (a periodic excitation with whole \
             periods is needed for per-line averages and their σ)"
        ))
    };
    let mut figs = Vec::new();

    // FRF and the nominal's response
    figs.push(match &s.frf {
        Some(f) => Figure {
            id: FIGURE_IDS[0],
            caption: format!(
                "Measured FRF u → θ_m of {} at the excited lines (points) with its ±2σ \
                 confidence region (bars; σ from the period-to-period spread), and the \
                 response of the {} (line).",
                f.capture, f.nominal.name
            ),
            svgs: vec![bode_svg(
                &format!("FRF u -> theta_m [rad/(N·m)]: {}", f.capture),
                Some(&f.frf),
                std::slice::from_ref(&f.nominal),
            )?],
            note: None,
        },
        None => Figure {
            id: FIGURE_IDS[0],
            caption: "Measured FRF with its confidence region and the nominal's response.".into(),
            svgs: Vec::new(),
            note: not_periodic("FRF"),
        },
    });

    // residual spectrum against the measured motion
    let sp = &s.spectra;
    let nyq = 0.5 / s.ts;
    // the metric's band with an octave either side
    let (flo, fhi) = band_of(d);
    let keep: Vec<usize> = (0..sp.freq_hz.len())
        .filter(|&k| sp.freq_hz[k] >= 0.5 * flo && sp.freq_hz[k] <= (2.0 * fhi).min(nyq))
        .collect();
    let top = keep
        .iter()
        .map(|&k| db(sp.measured[k]))
        .fold(f64::NEG_INFINITY, f64::max);
    // 80 dB below the motion's peak is floor enough
    let pick = |v: &[f64]| {
        keep.iter()
            .map(|&k| db(v[k]).max(top - 80.0))
            .collect::<Vec<_>>()
    };
    let f: Vec<f64> = keep.iter().map(|&k| sp.freq_hz[k]).collect();
    let (m, n) = (pick(&sp.measured), pick(&sp.nominal));
    let b = sp.best.as_ref().map(|v| pick(v));
    let best_label = s
        .best
        .as_ref()
        .map(|(name, _)| format!("residual of nominal + {name}"));
    let mut series = vec![
        XySeries {
            name: "measured motion",
            x: &f,
            y: &m,
            markers: false,
        },
        XySeries {
            name: "residual of the nominal",
            x: &f,
            y: &n,
            markers: false,
        },
    ];
    if let (Some(b), Some(l)) = (&b, &best_label) {
        series.push(XySeries {
            name: l,
            x: &f,
            y: b,
            markers: false,
        });
    }
    figs.push(Figure {
        id: FIGURE_IDS[1],
        caption: format!(
            "Amplitude spectral density of the band-passed motor velocity ({}–{} Hz, the gap \
             metric's band) on the validation capture {}: the measured motion against the \
             residual it leaves (Welch, Hann, 2 s segments). Where the residual comes close \
             to the motion, the model misses that band.",
            fmt_sig(band_of(d).0, 3),
            fmt_sig(band_of(d).1, 3),
            s.validation
        ),
        svgs: vec![xy_svg(
            "residual spectrum against the measured motion",
            "frequency [Hz]",
            "amplitude spectral density [dB re 1 rad/s/√Hz]",
            true,
            &series,
        )?],
        note: None,
    });

    // distortion lines
    let freqs: Vec<Vec<f64>> = s
        .lines
        .iter()
        .map(|(_, a)| (0..a.classes.len()).map(|k| a.freq_hz(k)).collect())
        .collect();
    let titles: Vec<String> = s
        .lines
        .iter()
        .map(|(name, _)| format!("theta_m [rad]: {name}"))
        .collect();
    let panels: Vec<SpectrumPanel<'_>> = s
        .lines
        .iter()
        .zip(&freqs)
        .zip(&titles)
        .map(|(((_, a), f), t)| SpectrumPanel {
            title: t,
            freq_hz: f,
            amplitude: &a.y.amplitude,
            noise: &a.y.noise,
            classes: &a.classes,
        })
        .collect();
    figs.push(if panels.is_empty() {
        Figure {
            id: FIGURE_IDS[2],
            caption: "Non-excited odd and even lines of θ_m (nonlinear distortion).".into(),
            svgs: Vec::new(),
            note: not_periodic("line spectrum"),
        }
    } else {
        Figure {
            id: FIGURE_IDS[2],
            caption: format!(
                "Line spectra of θ_m, one panel per periodic capture: excited lines (+), \
                 non-excited odd lines (x: odd nonlinearities such as friction, backlash, a \
                 cubic spring), even lines (o: even nonlinearities), and the noise level \
                 (grey). {}",
                d.location
                    .distortion
                    .iter()
                    .map(|x| format!("{}: {}", x.capture, x.linearity.verdict))
                    .collect::<Vec<_>>()
                    .join(" ")
            ),
            svgs: vec![spectrum_svg(
                "nonlinear distortion: non-excited lines of theta_m",
                &panels,
            )?],
            note: None,
        }
    });

    // residual maps
    let mut maps = Vec::new();
    for m in &s.maps {
        let flat = vec![m.overall_rms; m.centers.len()];
        maps.push(xy_svg(
            &format!("nominal's residual against {}", short(&m.variable)),
            &m.variable,
            "velocity residual [rad/s]",
            false,
            &[
                XySeries {
                    name: "RMS per bin",
                    x: &m.centers,
                    y: &m.rms,
                    markers: true,
                },
                XySeries {
                    name: "mean per bin",
                    x: &m.centers,
                    y: &m.mean,
                    markers: false,
                },
                XySeries {
                    name: "RMS over the record",
                    x: &m.centers,
                    y: &flat,
                    markers: false,
                },
            ],
        )?);
    }
    let r = &d.location.regions;
    figs.push(Figure {
        id: FIGURE_IDS[3],
        caption: format!(
            "The nominal's band-passed velocity residual on the validation capture, binned \
             against the operating point: a bin's RMS well above the record's RMS marks where \
             the model fails. Residual energy over its average: near zero velocity {}, at \
             torque sign changes {}, at large gearbox deflection {}; the best pattern against \
             the motor angle has order {} per revolution and explains {} % of the residual.",
            fmt_sig(r.near_zero_velocity.energy_ratio, 3),
            fmt_sig(r.torque_sign_change.energy_ratio, 3),
            fmt_sig(r.large_deflection.energy_ratio, 3),
            r.angle_pattern.order,
            fmt_sig(100.0 * r.angle_pattern.share, 3)
        ),
        svgs: maps,
        note: None,
    });

    // before / after in time
    let w = s.window.clone();
    let mut ts_series = vec![
        TimeSeries {
            name: "measured",
            values: &s.measured[w.clone()],
        },
        TimeSeries {
            name: "nominal",
            values: &s.nominal[w.clone()],
        },
    ];
    let best_name = s.best.as_ref().map(|(n, _)| format!("nominal + {n}"));
    if let (Some((_, v)), Some(name)) = (&s.best, &best_name) {
        ts_series.push(TimeSeries {
            name,
            values: &v[w.clone()],
        });
    }
    let mut time = vec![time_svg(
        "validation: band-passed motor velocity where the nominal's residual is largest",
        "band-passed motor velocity [rad/s]",
        s.t0 + w.start as f64 * s.ts,
        s.ts,
        &ts_series,
    )?];
    let mut rms_series = vec![TimeSeries {
        name: "nominal",
        values: &s.nominal_rms,
    }];
    if let (Some(v), Some(name)) = (&s.best_rms, &best_name) {
        rms_series.push(TimeSeries { name, values: v });
    }
    time.push(time_svg(
        "validation: moving RMS (50 ms) of the velocity residual over the record",
        "residual RMS [rad/s]",
        s.t0 + 0.5 * crate::diagnose::series::MOVING_RMS_S,
        s.rms_step_s,
        &rms_series,
    )?);
    figs.push(Figure {
        id: FIGURE_IDS[4],
        caption: format!(
            "Before and after on the validation capture {}: the measured band-passed motor \
             velocity against the nominal's{} over the {} s where the nominal's residual is \
             largest (top), and the residual's moving RMS over the whole scored record \
             (bottom).",
            s.validation,
            match &s.best {
                Some((n, _)) => format!(" and the best model's (nominal + {n})"),
                None => " (no effect is named, so there is no best model)".into(),
            },
            fmt_sig(w.len() as f64 * s.ts, 3)
        ),
        svgs: time,
        note: None,
    });
    Ok(figs)
}

/// The metric's band [Hz], read from the bands of the location (first lower edge, last
/// upper edge).
fn band_of(d: &Diagnosis) -> (f64, f64) {
    let b = &d.location.bands_hz;
    match (b.first(), b.last()) {
        (Some(a), Some(z)) => (a.lo_hz, z.hi_hz),
        _ => crate::diagnose::metric::DEFAULT_BAND_HZ,
    }
}

/// An axis label without its unit and qualifiers, for a title.
fn short(label: &str) -> &str {
    let end = [" of ", " modulo ", " ["]
        .iter()
        .filter_map(|p| label.find(p))
        .min()
        .unwrap_or(label.len());
    &label[..end]
}

/// `x` to `digits` significant digits, in exponent form outside 10⁻³ … 10⁵.
fn num(x: f64, digits: usize) -> String {
    let a = x.abs();
    if x == 0.0 || !x.is_finite() || (1e-3..1e5).contains(&a) {
        fmt_sig(x, digits)
    } else {
        format!("{:.*e}", digits.saturating_sub(1), x)
    }
}

fn cell(out: &mut String, text: &str) {
    let _ = write!(out, "<td>{}</td>", escape(text));
}

fn candidate_row(out: &mut String, rank: &str, c: &Candidate) {
    out.push_str("<tr>");
    cell(out, rank);
    let _ = write!(out, "<td><b>{}</b></td>", escape(&c.name));
    cell(
        out,
        &format!("{:+.2} ± {:.2}", c.score, c.score_se).replace("NaN", "–"),
    );
    cell(out, if c.significant { "yes" } else { "no" });
    cell(
        out,
        &c.over_answer.map_or("–".to_string(), |(m, se)| {
            format!("{m:+.2} ± {se:.2}").replace("NaN", "–")
        }),
    );
    cell(
        out,
        &c.with_answer.map_or("–".to_string(), |(m, se)| {
            format!("{m:+.2} ± {se:.2}").replace("NaN", "–")
        }),
    );
    cell(out, &format!("{:.2}", c.fit_val).replace("NaN", "–"));
    let params: Vec<String> = c
        .parameters
        .iter()
        .map(|(k, v)| format!("{k} = {} ± {} {}", num(v.value, 4), num(v.std, 2), v.unit))
        .collect();
    let _ = write!(
        out,
        "<td>{}</td>",
        params
            .iter()
            .map(|p| escape(p))
            .collect::<Vec<_>>()
            .join("<br>")
    );
    cell(out, &c.reason);
    out.push_str("</tr>\n");
}

/// What the nominal's toolbox FIT of `θ_m` beside the gap metric measures, and why it
/// differs from it (the report shows one headline FIT, the gap metric).
pub const ANGLE_FIT_NOTE: &str = "the motor angle unfiltered, which sums every slow error of \
     the velocity (drift, the slow disturbance the position loop rejected) that the gap \
     metric's band-pass and estimated slow torque leave out";

const STYLE: &str = "body{font-family:sans-serif;max-width:1150px;margin:1em auto;padding:0 1em;\
color:#111}h1{font-size:1.4em}.verdict{font-size:1.25em;font-weight:bold;background:#eef4ff;\
border-left:6px solid #1e5ac8;padding:.6em .8em}table{border-collapse:collapse;margin:.5em 0;\
font-size:.9em}td,th{border:1px solid #bbb;padding:.25em .5em;vertical-align:top;text-align:left}\
th{background:#f0f0f0}figure{margin:1.5em 0;border-top:1px solid #ccc;padding-top:.5em}\
figure svg{width:100%;height:auto;display:block;margin:.3em 0}figcaption{font-size:.95em;\
color:#333;margin:.3em 0}.note{color:#a03000;font-style:italic}.small{font-size:.85em;color:#444}";

/// `svg` with a `viewBox` from its `width` and `height` (so that CSS can scale it) when it
/// has none.
fn scalable(svg: &str) -> String {
    if svg.contains("viewBox") {
        return svg.to_string();
    }
    let attr = |name: &str| -> Option<String> {
        let i = svg.find(&format!("{name}=\""))? + name.len() + 2;
        let j = svg[i..].find('"')? + i;
        Some(svg[i..j].to_string())
    };
    match (attr("width"), attr("height")) {
        (Some(w), Some(h)) => svg.replacen("<svg ", &format!("<svg viewBox=\"0 0 {w} {h}\" "), 1),
        _ => svg.to_string(),
    }
}

/// The report of a diagnosis as one HTML page: `title`, the verdict, the figures of
/// [`diagnosis_figures`] inline, the ranked candidates, where the gap lies, the notes.
///
/// # Errors
/// [`PlotError`] of a figure that cannot be drawn.
pub fn diagnosis_html(
    title: &str,
    d: &Diagnosis,
    s: &DiagnosisSeries,
) -> Result<String, PlotError> {
    let figs = diagnosis_figures(d, s)?;
    let mut h = String::new();
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <title>{}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n<h1>{}</h1>\n\
         <p id=\"verdict\" class=\"verdict\">{}</p>\n",
        escape(title),
        escape(title),
        escape(&d.verdict)
    );
    let _ = write!(
        h,
        "<table id=\"summary\">\n<tr><th>gap metric</th><td>{}</td></tr>\n\
         <tr><th>nominal ({})</th><td>{:.2} %</td></tr>\n\
         <tr><th>best: {}</th><td>{:.2} %, {:.0} % of the gap closed</td></tr>\n{}\
         <tr><th>significance test</th><td>{}</td></tr>\n\
         <tr><th>for reference: the nominal's toolbox FIT of θ_m</th><td>{:.2} %: {}</td></tr>\n\
         <tr><th>time</th><td>{:.1} s</td></tr>\n</table>\n",
        escape(&d.metric),
        escape(&d.structure),
        Percent(d.fit_nominal_val),
        escape(&d.best),
        Percent(d.fit_augmented_val),
        Percent(100.0 * d.gap_closed_share),
        d.fit_noise_val.map_or(String::new(), |n| format!(
            "<tr><th>what the noise from period to period leaves</th><td>{:.2} %</td></tr>\n",
            Percent(n)
        )),
        escape(&d.test),
        Percent(d.fit_nominal_angle_val),
        ANGLE_FIT_NOTE,
        d.seconds
    );

    h.push_str(
        "<h2>Candidates</h2>\n<table id=\"candidates\">\n<tr><th>rank</th><th>effect</th>\
         <th>score ± SE [FIT points]</th><th>significant</th>\
         <th>over the answer ± SE [FIT points]</th><th>added to the answer ± SE [FIT points]</th>\
         <th>validation FIT [%]</th>\
         <th>parameters (± σ) [unit]</th><th>reason</th></tr>\n",
    );
    for (i, c) in d.effects.iter().enumerate() {
        candidate_row(&mut h, &(i + 1).to_string(), c);
    }
    if let Some(p) = &d.pair {
        candidate_row(&mut h, "pair", p);
    }
    h.push_str(
        "</table>\n<p class=\"small\">Score: gain of the gap metric over the nominal (a pair: \
         over its first effect alone), mean over the segments ± its standard error.</p>\n",
    );

    let _ = write!(
        h,
        "<h2>Where the gap lies</h2>\n<table id=\"bands\">\n<tr><th>band [Hz]</th>\
         <th>residual / measured energy [-]</th></tr>\n{}</table>\n",
        d.location
            .bands_hz
            .iter()
            .map(|b| format!(
                "<tr><td>{}–{}</td><td>{}</td></tr>\n",
                fmt_sig(b.lo_hz, 3),
                fmt_sig(b.hi_hz, 3),
                fmt_sig(b.residual_ratio, 3)
            ))
            .collect::<String>()
    );
    if let Some(a) = &d.location.amplitude {
        let _ = writeln!(
            h,
            "<p id=\"amplitude\">With amplitude: {}; {}.</p>",
            a.levels
                .iter()
                .map(|l| format!(
                    "{} (u RMS {} N·m) gap {:.2} points",
                    escape(&l.capture),
                    fmt_sig(l.u_rms, 3),
                    Percent(l.gap)
                ))
                .collect::<Vec<_>>()
                .join(", "),
            escape(&a.summary())
        );
    }
    if let Some(m) = &d.parameter_mismatch {
        let _ = write!(
            h,
            "<h2>The simulation {}</h2>\n<p>{:.2} % on the validation data; the parameters \
             account for {:+.2} points, the structure for {:+.2}.</p>\n<table id=\"mismatch\">\
             <tr><th>parameter</th><th>simulation</th><th>fitted</th><th>[%]</th></tr>\n{}\
             </table>\n",
            escape(&m.sim),
            m.fit_sim_val,
            m.parameter_part,
            m.structure_part,
            m.parameters
                .iter()
                .map(|p| format!(
                    "<tr><td>{}</td><td>{}</td><td>{}</td><td>{:+.1}</td></tr>\n",
                    escape(&p.name),
                    fmt_sig(p.sim, 4),
                    fmt_sig(p.fitted, 4),
                    p.percent
                ))
                .collect::<String>()
        );
    }

    h.push_str("<h2>Figures</h2>\n");
    for f in &figs {
        let _ = writeln!(h, "<figure id=\"{}\">", f.id);
        for svg in &f.svgs {
            h.push_str(&scalable(svg));
            h.push('\n');
        }
        if let Some(n) = &f.note {
            let _ = writeln!(h, "<p class=\"note\">{}</p>", escape(n));
        }
        let _ = write!(
            h,
            "<figcaption>{}</figcaption>\n</figure>\n",
            escape(&f.caption)
        );
    }
    if !d.warnings.is_empty() {
        let _ = write!(
            h,
            "<h2>Notes</h2>\n<ul id=\"notes\">\n{}</ul>\n",
            d.warnings
                .iter()
                .map(|w| format!("<li>{}</li>\n", escape(w)))
                .collect::<String>()
        );
    }
    h.push_str("</body>\n</html>\n");
    Ok(h)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escape_leaves_no_markup_in_text() {
        assert_eq!(
            escape("a < b && \"c\" > d"),
            "a &lt; b &amp;&amp; &quot;c&quot; &gt; d"
        );
        assert_eq!(
            short("motor velocity ω_m of the nominal [rad/s]"),
            "motor velocity ω_m"
        );
        assert_eq!(num(3.008e13, 4), "3.008e13");
        assert_eq!(num(2.573, 4), "2.573");
    }

    #[test]
    fn scalable_adds_a_view_box_from_the_size() {
        let svg = xy_svg(
            "t",
            "x [s]",
            "y [m]",
            false,
            &[XySeries {
                name: "a",
                x: &[0.0, 1.0],
                y: &[1.0, 2.0],
                markers: true,
            }],
        )
        .unwrap();
        let s = scalable(&svg);
        assert!(s.contains("viewBox=\"0 0 900 420\""), "{}", &s[..200]);
        assert_eq!(scalable(&s), s);
    }
}
