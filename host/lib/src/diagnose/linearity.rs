//! The data's own evidence of a nonlinearity, apart from any model (stage 0, beside the
//! excited lines' evidence of a delay): the non-excited lines of each periodic capture
//! (seed 000 §3) and, with two estimation captures, how the best linear approximation moves
//! with amplitude ([`crate::ident::frf::bla_change`]). Where the data show none, a nonlinear
//! law gains only through its linear part ([`super::fits::nonlinear_unsupported`]).

use crate::ident::frf::{analyze_dataset, analyze_segments, bla_change, BlaChange, FrfAnalysis};

use super::inputs::Records;

/// The FRF analysis ([`crate::ident::frf`]) of each capture of `rec`, the estimation
/// captures first and the validation capture last, by name; `None` for a capture that is
/// not periodic (no excitation stated, or too few whole periods).
pub(super) fn capture_analyses(
    rec: &Records<'_>,
    settle_periods: usize,
) -> Vec<(String, Option<FrfAnalysis>)> {
    rec.est
        .iter()
        .copied()
        .chain(std::iter::once(rec.val_segs))
        .map(|segs| {
            let a = match segs {
                [ds] if ds.excitation.is_some() => analyze_dataset(ds, settle_periods).ok(),
                [first, ..] if first.excitation.is_some() => {
                    analyze_segments(segs, settle_periods).ok()
                }
                _ => None,
            };
            (segs[0].name.clone(), a)
        })
        .collect()
}

/// The data's own evidence of a nonlinearity, apart from any model: the non-excited lines
/// of the periodic captures (seed 000 §3) and, with two estimation captures, how the best
/// linear approximation moves with amplitude ([`bla_change`]).
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Nonlinearity {
    /// the periodic captures analysed
    pub captures: usize,
    /// where a non-excited line class stands above the noise, in words
    /// (`est: θ_m odd lines`)
    pub shown: Vec<String>,
    /// the change of the best linear approximation between the two estimation captures
    pub bla: Option<BlaChange>,
}

impl Nonlinearity {
    /// The data's evidence read from `analyses` ([`capture_analyses`], the first `est`
    /// of them the estimation captures); `None` when no capture is periodic: the data
    /// then hold no such evidence either way.
    pub fn of(analyses: &[(String, Option<FrfAnalysis>)], est: usize) -> Option<Nonlinearity> {
        // a noise excites every line and has none to read
        let has_lines = |a: &FrfAnalysis| a.linearity_y.odd.lines + a.linearity_y.even.lines > 0;
        let captures = analyses
            .iter()
            .filter(|(_, a)| a.as_ref().is_some_and(has_lines))
            .count();
        if captures == 0 {
            return None;
        }
        let mut shown = Vec::new();
        for (name, a) in analyses {
            let Some(a) = a else { continue };
            for (signal, l) in [("θ_m", &a.linearity_y), ("u", &a.linearity_u)] {
                for (class, c) in [("odd", &l.odd), ("even", &l.even)] {
                    if c.detected {
                        shown.push(format!(
                            "{name}: {signal} {class} lines {:.1} dB above the noise",
                            c.vs_noise_db
                        ));
                    }
                }
            }
        }
        let bla = match analyses {
            [(_, Some(a)), (_, Some(b)), ..] if est == 2 => bla_change(&a.frf, &b.frf),
            _ => None,
        };
        Some(Nonlinearity {
            captures,
            shown,
            bla,
        })
    }

    /// Why a nonlinear law is not supported, in words, when the data show no nonlinearity
    /// at all: no non-excited line stands above the noise, and the best linear
    /// approximation does not move with amplitude (when two amplitudes tell). A friction,
    /// a gap, a stiffening spring or a ripple fitted to such data gains through its linear
    /// part: it stands in for a linear mismatch, a body or a mode the structure lacks
    /// (a four-body joint under the three-mass structure, bench `JOINTS=1`, case 59: a
    /// gap of 7.7 µrad scored +0.52 ± 0.05 points and changed nothing at the odd lines).
    pub fn none_shown(&self) -> Option<String> {
        if !self.shown.is_empty() || self.bla.as_ref().is_some_and(|b| b.changed) {
            return None;
        }
        let bla = self.bla.as_ref().map_or(String::new(), |b| {
            format!(
                ", and the best linear approximation is the same on the two estimation \
                 captures (the median ratio of its change to its noise over {} lines is \
                 {:.2}, {:.2} for a linear joint)",
                b.lines, b.median_ratio, b.linear_median
            )
        });
        Some(format!(
            "the data show no nonlinearity: no non-excited line of the {} periodic \
             capture{} stands above the noise in θ_m or u (99 % detection){bla}; a \
             nonlinear law gains here through its linear part, standing in for a linear \
             mismatch (a body or a mode the structure lacks)",
            self.captures,
            if self.captures == 1 { "" } else { "s" }
        ))
    }
}
