//! Stages 3–6, the selection: each single candidate judged against the nominal it extends
//! ([`singles`]); the best single paired with the others, each pair judged against its lead
//! alone ([`pairs`]); a pair's effects refitted alone from the pair's values, the pair kept
//! only when both are needed ([`reduce`]); the answer's fit continued when it stopped at its
//! iteration limit ([`polish_answer`]). Every judgement is [`Fitter::judge`]: the
//! segment-wise validation gain over the model extended, significant when
//! `mean − 2·SE > min_gain`.

use std::collections::BTreeMap;

use crate::ident::nonlinear::NlFit;
use crate::model::effects::{Attach, Effect, ExtraMode};
use crate::model::spec::Structure;

use super::evidence::Evidence;
use super::fits::{makes_odd, Fitted, Fitter, Job};
use super::locate;
use super::metric::DrivenModel;
use super::table::{evidence, lag_and_delay, odd_words, ranked, ripple_travel, scored_candidate};
use super::{Candidate, CandidateError};
use crate::ident::parallel::parallel;

/// The candidates and the answer among them, as the stages leave them.
pub(super) struct Answer {
    /// the singles, best score first, each with its fit (`None`: the fit failed)
    pub singles: Vec<(Candidate, Option<Fitted>)>,
    /// the pair that passed, if any
    pub pair: Option<Candidate>,
    /// its fit
    pub pair_fitted: Option<Fitted>,
    /// every pair fitted in stage 4 as `(lead, partner, (mean, SE))`: its gain over its lead
    /// alone, the best of its starts
    pub beside: Vec<(String, String, (f64, f64))>,
}

impl Answer {
    /// The answer's candidate: the pair, else the best single when significant.
    pub fn best(&self) -> Option<&Candidate> {
        self.pair
            .as_ref()
            .or_else(|| self.singles.first().map(|c| &c.0).filter(|c| c.significant))
    }

    /// The answer's fit, as [`Answer::best`].
    pub fn best_fitted(&self) -> Option<&Fitted> {
        match &self.pair_fitted {
            Some(pf) if self.pair.is_some() => Some(pf),
            _ => self
                .singles
                .first()
                .filter(|c| c.0.significant)
                .and_then(|c| c.1.as_ref()),
        }
    }

    /// Every other scored model's gain over the answer's ([`Candidate::over_answer`]), by
    /// the same test: what a candidate adds to the leader, not to the nominal.
    pub fn judge_against_answer(&mut self, fitter: &Fitter<'_>) {
        let Some((name, base)) = self
            .best()
            .map(|c| c.name.clone())
            .zip(self.best_fitted().map(|f| f.scored.segments.clone()))
        else {
            return;
        };
        for (c, f) in self.fitted_mut().filter(|(c, _)| c.name != name) {
            let (mean, se, _) = fitter.judge(&f.scored.segments, &base);
            c.over_answer = Some((mean, se));
        }
    }

    /// The pair `(lead, partner)` scored `gain` over its lead, kept in [`Answer::beside`]
    /// when no start of the same pair scored higher.
    fn note_beside(&mut self, (lead, partner): (&str, &str), gain: (f64, f64)) {
        match self
            .beside
            .iter_mut()
            .find(|b| b.0 == lead && b.1 == partner)
        {
            Some(b) if gain.0 > b.2 .0 || b.2 .0.is_nan() => b.2 = gain,
            Some(_) => {}
            None => self.beside.push((lead.into(), partner.into(), gain)),
        }
    }

    /// What each other effect adds to the answer when the answer is a single that led
    /// pairs ([`Candidate::with_answer`], from [`Answer::beside`]).
    pub fn note_with_answer(&mut self, best: &str) {
        let Answer {
            singles, beside, ..
        } = self;
        for (c, _) in singles.iter_mut() {
            c.with_answer = beside
                .iter()
                .find(|b| b.0 == best && b.1 == c.name)
                .map(|b| b.2);
        }
    }

    /// Every fitted model's candidate with its fit: the singles', then the pair's.
    pub fn fitted_mut(&mut self) -> impl Iterator<Item = (&mut Candidate, &Fitted)> {
        let pair = self.pair.as_mut().zip(self.pair_fitted.as_ref());
        self.singles
            .iter_mut()
            .filter_map(|(c, f)| f.as_ref().map(|f| (c, f)))
            .chain(pair)
    }

    fn sort(&mut self) {
        self.singles.sort_by(|a, b| ranked(&a.0, &b.0));
    }
}

/// The single `f`, or its delay held at the size the excited lines show
/// ([`Fitted::at_lines`]) when the free fit is not significant against the nominal and the
/// held one is: the lines size a delay better than the records' output error, and the
/// metric judges what that delay gains (hard bench, `HARD=1` case 34, a 1.37-sample delay:
/// the lines 1.36 samples, the records 1.59 and +0.35 ± 0.05 points, not significant
/// against the floor; held at 1.36, +0.36 ± 0.04 against the spread). A free fit that is
/// significant on its own is kept.
pub(super) fn lines_sized(fitter: &Fitter<'_>, nominal: &Fitted, mut f: Fitted) -> Fitted {
    let Some(held) = f.at_lines.take() else {
        return f;
    };
    let judged = |g: &Fitted| {
        let (_, _, significant) =
            fitter.judge_model(&g.scored.segments, &nominal.scored.segments, Some(g));
        g.counts(significant)
    };
    if !judged(&f) && judged(&held) {
        *held
    } else {
        f
    }
}

/// A single's candidate, judged against the nominal; `odd`: the share of the nominal's
/// odd-line residual it removes ([`Evidence::odd_of`]).
pub(super) fn single_of(
    fitter: &Fitter<'_>,
    ev: &Evidence,
    nominal: &Fitted,
    (effect, odd): (&Effect, Option<f64>),
    f: &Fitted,
) -> Candidate {
    let judged = fitter.judge_model(&f.scored.segments, &nominal.scored.segments, Some(f));
    let (score, score_se, significant) = judged;
    let mut lag = lag_and_delay(&f.fit, nominal.fit.model.tau_c, fitter.rec.ts)
        .map_or(String::new(), |w| format!("; {w}"));
    // the data's own word on the effect, apart from the metric: the excited lines' on a
    // delay (when they do not show it, the row says so where it is not counted,
    // [`super::fits::delay_unsupported`]), the order search's on a ripple
    let shown = match (effect, fitter.starts.delay_lines, f.ripple_shown) {
        (Effect::TimeDelay(_), Some(l), _) if l.shown() => Some(format!(
            "the excited lines show a delay: beside the lag, a delay of {:.2} samples (99 % \
             interval {:.2}–{:.2}) lowers the SML cost of the structure's frequency-domain fit \
             by {:.1}, above the 99 % point {:.1} of a delay that is not there",
            l.delay,
            l.interval().0,
            l.interval().1,
            l.drop,
            l.threshold()
        )),
        (Effect::TorqueRipple(_), _, Some(r)) => {
            let z = crate::ident::nonlinear::ripple::SIGNIFICANT_Z;
            let found = format!(
                "the order search shows it: the ripple of order {} lowers the estimation cost \
                 at a robust z-score of {:.1} against the orders a period or more apart over \
                 the travel ({}), with the same ripple along the record",
                r.order,
                r.z,
                if r.z >= z {
                    format!("significant from {z}")
                } else {
                    format!("the best order, short of {z}")
                }
            );
            let p = crate::ident::nonlinear::ripple::REPLICATED_P;
            Some(match r.chance_val {
                Some(c) if r.replicated() => format!(
                    "{found}, and again on the validation record (chance {c:.1e}, shown from \
                     {p})"
                ),
                Some(c) => format!(
                    "{found}, but the validation record, along another trajectory, does not \
                     show it again (chance {c:.2}, shown below {p}): what it follows repeats \
                     with the excitation, not with the angle"
                ),
                None if r.repeats => format!(
                    "{found}, but the validation record repeats the estimation record's \
                     trajectory (the same excitation phases), so it cannot show the order \
                     again: capture validation with another excitation seed"
                ),
                None => format!(
                    "{found}, but the validation record's travel does not tell the order apart"
                ),
            })
        }
        _ if f.odd_shown => Some(format!(
            "the odd lines show it: it removes {:.0} % of the odd distortion the nominal leaves \
             at the validation capture's non-excited odd lines, more than any other single",
            100.0 * odd.unwrap_or(f64::NAN)
        )),
        _ => None,
    };
    if let Some(shown) = shown {
        let floor = fitter.floor.gain;
        lag.push_str(&match (f.shown_apart(), fitter.floor.spread) {
            (true, spread) if spread > 0.0 => format!(
                "; counted above the spread of the nominal's own refits ({spread:.3} points), \
                 not the {floor:.2}-point floor, because {shown}"
            ),
            (true, _) => format!(
                "; counted beyond twice its standard error, not the {floor:.2}-point floor (no \
                 refit of the nominal measured the metric's spread), because {shown}"
            ),
            (false, _) => match fitter.starts.delay_lines {
                Some(l) if matches!(effect, Effect::TimeDelay(_)) && !l.explains() => format!(
                    "; {shown}, but it removes only {:.0} % of the lines' misfit above the noise \
                     (a transport delay that explains them removes at least {:.0} %; a phase \
                     that another effect puts on the lines does not): judged against the \
                     {floor:.2}-point floor",
                    100.0 * l.share(),
                    100.0 * crate::ident::nonlinear::run::DELAY_MIN_SHARE
                ),
                _ => format!(
                    "; {shown}, but not at the size fitted here: judged against the \
                     {floor:.2}-point floor"
                ),
            },
        });
    }
    let reason = format!(
        "{}; validation FIT {:+.1} ± {:.1} points{}{}{lag}",
        evidence(
            effect.name(),
            &ev.location,
            ripple_travel(&f.fit, &fitter.rec.est_data)
        ),
        score,
        score_se,
        if significant {
            ""
        } else {
            " (not significant)"
        },
        odd_words(odd)
    );
    scored_candidate(effect.name(), f, judged, false, (reason, odd))
}

/// A pair's candidate, judged against its lead alone.
pub(super) fn pair_of(
    fitter: &Fitter<'_>,
    ev: &Evidence,
    effects: &[Effect],
    f: &Fitted,
    lead: &Fitted,
) -> Candidate {
    let judged = fitter.judge_model(&f.scored.segments, &lead.scored.segments, Some(f));
    let (score, score_se, significant) = judged;
    let odd = ev.odd_of(&fitter.rec.val, f);
    let shown = if f.shown_apart() {
        format!(
            "; counted above the spread of the nominal's own refits ({:.3} points), not the \
             {:.2}-point floor, because the odd lines show it: it removes most of the odd \
             distortion {} leaves at the validation capture's non-excited odd lines, more than \
             any other partner",
            fitter.floor.spread,
            fitter.floor.gain,
            effects[0].name()
        )
    } else {
        String::new()
    };
    let reason = format!(
        "{} added to {}: validation FIT {score:+.1} ± {score_se:.1} points over {} alone{}{}{shown}",
        effects[1].name(),
        effects[0].name(),
        effects[0].name(),
        if significant {
            ""
        } else {
            " (not significant)"
        },
        odd_words(odd)
    );
    let name = format!("{}+{}", effects[0].name(), effects[1].name());
    scored_candidate(&name, f, judged, true, (reason, odd))
}

/// Stage 3: each single (`results`, in the order of the candidates) judged against the
/// nominal, best score first. A single significantly below the nominal it contains took a
/// wrong basin ([`below_its_nominal`]) and says so.
pub(super) fn singles(
    fitter: &Fitter<'_>,
    nominal: &Fitted,
    ev: &Evidence,
    results: Vec<Result<Fitted, CandidateError>>,
) -> Answer {
    let min_gain = fitter.floor.gain;
    let mut results: Vec<Result<Fitted, CandidateError>> = results
        .into_iter()
        .map(|r| r.map(|f| lines_sized(fitter, nominal, f)))
        .collect();
    let shares: Vec<Option<f64>> = results
        .iter()
        .map(|r| r.as_ref().ok().and_then(|f| ev.odd_of(&fitter.rec.val, f)))
        .collect();
    if let Some(i) = odd_shown(&shares) {
        if let Ok(f) = results[i].as_mut() {
            f.odd_shown = true;
        }
    }
    let mut singles: Vec<(Candidate, Option<Fitted>)> = Vec::new();
    for ((effect, r), odd) in fitter.rec.candidates.iter().zip(results).zip(shares) {
        let c = match r {
            Ok(mut f) => {
                let (score, score_se, _) =
                    fitter.judge(&f.scored.segments, &nominal.scored.segments);
                if below_its_nominal((score, score_se), min_gain) {
                    // the refit from the nominal's values replaced it or scored lower
                    let refit = if f.own_start.is_some() {
                        "even refitted from the nominal's values"
                    } else {
                        "and its refit from the nominal's values scored no higher on the \
                         estimation records"
                    };
                    f.warnings.insert(
                        0,
                        format!(
                            "it scores below the nominal it contains ({score:+.1} ± \
                             {score_se:.1} points), which the effect at nought would match, \
                             {refit}: it follows something of the estimation record the \
                             validation record does not share, and is not to be trusted; the \
                             effect is still tried as a partner of the significant singles"
                        ),
                    );
                }
                (single_of(fitter, ev, nominal, (effect, odd), &f), Some(f))
            }
            Err(e) => (
                Candidate {
                    name: effect.name().into(),
                    specs: Vec::new(),
                    score: f64::NAN,
                    score_se: f64::NAN,
                    fit_val: f64::NAN,
                    fit_angle_val: f64::NAN,
                    significant: false,
                    over_answer: None,
                    with_answer: None,
                    parameters: BTreeMap::new(),
                    odd_explained: None,
                    structure_parameters: BTreeMap::new(),
                    reason: format!("the fit failed: {e}"),
                    warnings: vec![e.to_string()],
                },
                None,
            ),
        };
        singles.push(c);
    }
    let mut answer = Answer {
        singles,
        pair: None,
        pair_fitted: None,
        beside: Vec::new(),
    };
    answer.sort();
    answer
}

/// Which single, of the shares of the nominal's odd-line residual each removes
/// ([`Evidence::odd_of`], in the order of the singles), the odd lines show: the one that
/// removes the most, when that is most of it ([`locate::ODD_EXPLAINED_MOST`]). A periodic
/// capture whose odd non-excited lines stand [`locate::ODD_RESIDUAL_ABOVE_NOISE_DB`] above
/// the noise rejects a linear model by its own signature, as the excited lines do for a
/// delay; the effect whose law takes that distortion away is the one the lines point to,
/// and the metric has only to confirm that it closes part of the gap
/// ([`Fitted::shown_apart`]). Other-joints bench (`JOINTS=1 HARD=1`, case 1): a 15 µrad
/// backlash at 0.040 rad RMS costing the nominal 0.47 points; the odd residual stood 27 dB
/// above the noise, the backlash removed 99 % of it (the stiffening spring 75 %) and
/// gained +0.39 ± 0.06 points, short of the floor of the time (0.3 point) beyond twice its
/// error.
pub(super) fn odd_shown(shares: &[Option<f64>]) -> Option<usize> {
    shares
        .iter()
        .enumerate()
        .filter_map(|(i, s)| s.map(|s| (i, s)))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .filter(|&(_, s)| s >= locate::ODD_EXPLAINED_MOST)
        .map(|(i, _)| i)
}

/// Stage 3a: a single that ends significantly below the nominal it contains on validation
/// ([`below_its_nominal`]) fitted again on the nominal's own cost ([`Fitter::nested`]: the
/// residual band-limited as the nominal's) from the nominal's values with its own fitted
/// effect shrunk to [`NESTED_SHARE`] of its size ([`shrunk`]); an extra mode placed by the
/// automatic start's grid and at the nominal's residual peaks instead
/// ([`Fitter::nested_grid`]), since shrinking keeps the
/// frequency that is its basin (other-laws bench, `LAWS=1 HARD=1 SMALL=1 FRICTION=1` case
/// 13: a 10 Hz mode at the chain's end, which the candidate's mode in parallel on the first
/// arm mass stands for at other values; from the four-mass start the single scored −1.3
/// points, refitted shrunk +0.02, from the grid +0.67 of the true model's +0.88). An extra
/// mode is placed by the grid whatever it scored: its own start can end in another basin
/// above the nominal as well as below it (the same bench, case 7: that mode with a Coulomb
/// friction, the mode alone +0.03 points at 34 Hz, an arm-side spring 25 times the truth's).
/// A nonlinear effect's fit
/// takes the whole band unless the motor sticks ([`super::inputs::nl_options`]), where a closed loop's torque holds
/// the controller's reaction to the encoder and the disturbance; at a small amplitude that
/// draws the fit away from the joint (hard bench, a 1.1-sample delay at 0.015 rad RMS:
/// every nonlinear single 4.4–5.5 points below the nominal on validation, each at an
/// in-sample cost below its own refit from the nominal's values, so not a wrong basin of
/// its cost). The two fits weigh different bands, so their costs do not compare; the gap
/// metric on the estimation records does ([`Fitter::in_sample`]), and the refit replaces
/// the single when it scores higher there. Validation only says which singles to refit.
/// `results` in the order of the candidates, as [`singles`] takes them.
pub(super) fn nested_refits(
    fitter: &Fitter<'_>,
    nominal: &Fitted,
    mut results: Vec<Result<Fitted, CandidateError>>,
) -> Vec<Result<Fitted, CandidateError>> {
    let min_gain = fitter.floor.gain;
    let below: Vec<(usize, Effect, (f64, f64))> = results
        .iter()
        .enumerate()
        .filter_map(|(i, r)| {
            let f = r.as_ref().ok()?;
            let effect = *f.fit.model.effects.first()?;
            let (mean, se, _) = fitter.judge(&f.scored.segments, &nominal.scored.segments);
            // a mode is placed by the grid too when it scores above its nominal: a second
            // start over the frequency that is its basin
            let mode = matches!(effect, Effect::ExtraMode(_));
            (below_its_nominal((mean, se), min_gain) || mode).then_some((i, effect, (mean, se)))
        })
        .collect();
    let refits = parallel(&below, fitter.req.options.threads, |&(i, effect, _)| {
        let old = results[i].as_ref().ok()?;
        // a mode's basin is its frequency, which shrinking keeps: it is placed by the
        // automatic start's grid on the nominal's structure instead
        let new = match effect {
            Effect::ExtraMode(_) => fitter.nested_grid(&nominal.fit, effect),
            _ => fitter.nested(&nominal.fit, (shrunk(effect, NESTED_SHARE), effect)),
        }
        .ok()?;
        let at = |f: &Fitted| fitter.in_sample(&DrivenModel::of_fit(&f.fit));
        let (was, now) = (at(old)?, at(&new)?);
        (now > was).then_some((new, was, now))
    });
    for ((i, effect, (mean, se)), refit) in below.into_iter().zip(refits) {
        let (Some((mut new, was, now)), Ok(old)) = (refit, &results[i]) else {
            continue;
        };
        let below = below_its_nominal((mean, se), min_gain);
        let placed = match effect {
            Effect::ExtraMode(_) => {
                "the mode placed by the automatic start's grid over its frequency and at each peak \
                 of the nominal's residual, the lowest cost kept"
                    .to_string()
            }
            _ => format!("the effect at {NESTED_SHARE:e} of that fit's size"),
        };
        // the own fit is kept where it fell below the nominal: the pairs take it
        // ([`partner_anyway`], [`beside_the_leaders`]); a mode the grid placed better
        // while its own fit scored above the nominal is no such partner
        if below {
            new.own_start = Some(old.fit.clone());
        }
        // the refit keeps the ripple's order, and the search that found it holds
        new.ripple_shown = old.ripple_shown;
        let scored = if below {
            "it scored below the nominal it contains"
        } else {
            "it scored"
        };
        new.warnings.insert(
            0,
            format!(
                "fitted from its own start {scored} ({mean:+.1} ± {se:.1} points on \
                 validation); refitted from the nominal's \
                 values on the nominal's cost (the residual band-limited as the nominal's, \
                 {placed}) it scores higher on the estimation records ({was:.1} → {now:.1} \
                 %), and these are the refit's figures"
            ),
        );
        results[i] = Ok(new);
    }
    results
}

/// The share of a single's fitted effect its nested refit starts from ([`nested_refits`]):
/// small enough that the model is the nominal to within the noise, not nought, so that a
/// size fitted on a log scale can grow; its search bounds are those about the single's own
/// fit ([`Fitter::nested`]), so it can grow back to that size.
const NESTED_SHARE: f64 = 1e-3;

/// `effect` with its size (the level, width, coefficient, coupling, delay or amplitude)
/// times `share`, its shape (a ripple's order and phase, a mode's frequency and damping
/// ratio, the friction's Stribeck speed) kept.
fn shrunk(effect: Effect, share: f64) -> Effect {
    match effect {
        Effect::CoulombFriction(mut c) => {
            c.fc *= share;
            c.fs *= share;
            c.fc_neg = c.fc_neg.map(|f| f * share);
            c.fv_neg_extra = c.fv_neg_extra.map(|f| f * share);
            Effect::CoulombFriction(c)
        }
        Effect::Backlash(mut b) => {
            b.width *= share;
            Effect::Backlash(b)
        }
        Effect::NonlinearStiffness(mut n) => {
            n.k3 *= share;
            Effect::NonlinearStiffness(n)
        }
        Effect::ExtraMode(mut m) => {
            m.j *= share;
            m.k *= share;
            m.d *= share;
            Effect::ExtraMode(m)
        }
        Effect::TimeDelay(mut t) => {
            t.samples *= share;
            Effect::TimeDelay(t)
        }
        Effect::TorqueRipple(mut r) => {
            r.amplitude *= share;
            Effect::TorqueRipple(r)
        }
    }
}

/// The jobs of stage 4 and the single each pair is led by.
fn pair_jobs<'s>(
    fitter: &Fitter<'_>,
    singles: &'s [(Candidate, Option<Fitted>)],
) -> (Vec<Job<'s>>, Vec<&'s Fitted>) {
    let (candidates, min_gain) = (&fitter.rec.candidates, fitter.floor.gain);
    let mut jobs: Vec<Job<'s>> = Vec::new();
    let mut led_by: Vec<&Fitted> = Vec::new();
    let Some((top, Some(_))) = singles.first().filter(|c| c.0.significant) else {
        return (jobs, led_by);
    };
    // the singles that lead pairs: the best, and the second when the two tie within
    // twice the standard error of their difference (bench case 6, a stiffening spring
    // with a delay, while its nominal had no lag: the extra mode alone +12.4 ± 0.2, the
    // delay alone +11.9 ± 0.2, and only the pair led by the delay holds the truth)
    let mut leaders: Vec<usize> = vec![0];
    if let Some((second, Some(_))) = singles.get(1).filter(|c| c.0.significant) {
        let tie = 2.0 * (top.score_se.powi(2) + second.score_se.powi(2)).sqrt();
        if top.score - second.score <= tie {
            leaders.push(1);
        }
    }
    for &l in &leaders {
        let Some(lead) = singles[l].1.as_ref() else {
            continue;
        };
        let first = lead.fit.model.effects[0];
        // each pair starts from its singles' fitted values: the structure, lag and
        // offset of the leading single's fit, or of the partner's when that is an
        // extra mode (it changes what the structure's masses and springs stand for);
        // a pair of the two leaders is tried once, led by the best
        // a Coulomb friction fitted from the grown start ([`grow`]) takes the extra mode
        // whatever the mode's single scored: that single started from the FRF the
        // sticking motor spoils
        let grown_lead = fitter.grown_lead(&first);
        for (j, c) in singles.iter().enumerate() {
            if j == l || leaders.contains(&j) && j < l {
                continue;
            }
            let (second, base) = match (c.1.as_ref(), c.0.significant || adds_some(c)) {
                (Some(p), true) => {
                    let second = p.fit.model.effects[0];
                    let own = matches!(second, Effect::ExtraMode(_)) && !grown_lead;
                    (second, if own { &p.fit } else { &lead.fit })
                }
                // a single still below the nominal it contains after its nested refit
                // ([`nested_refits`]) follows what the validation record does not share,
                // which says nothing of its effect alone (bench case 27, a parallel mode with Coulomb
                // friction at 0.24 rad RMS: the friction alone ran to `F_c` = 0.96 N·m,
                // 26 × the truth, traded against the offset, and scored −23.0 points, so
                // the pair was never tried): the partner, from its candidate's size on
                // the lead's fit
                (Some(_), false) if partner_anyway(c, min_gain) => {
                    match candidates.iter().find(|e| e.name() == c.0.name) {
                        Some(e) => (*e, &lead.fit),
                        None => continue,
                    }
                }
                _ if grown_lead => {
                    match candidates
                        .iter()
                        .find(|e| matches!(e, Effect::ExtraMode(_)))
                    {
                        Some(e) if e.name() == c.0.name => (*e, &lead.fit),
                        _ => continue,
                    }
                }
                _ => continue,
            };
            jobs.push((vec![first, second], Some(base)));
            led_by.push(lead);
            // two significant singles: the pair from the data's own start too (the
            // structure's frequency-domain fit and seed 001's grids for both effects), the
            // one of the two that scores higher kept. Each single bent its structure to take
            // the other's part, and a pair from it can stay in that basin (`JOINTS=1` hard
            // bench, case 6: a stiffening spring behind a 1.7-sample delay, the stiffness
            // alone with `f_m` on its bound; the pair from it ended at `k_a` ≈ 0, 89.7 %
            // in the loop against the true model's 98.2 %, while `jointid fit` of the
            // pair from its automatic start found every parameter within 10 %)
            if c.0.significant && !grown_lead {
                jobs.push((vec![first, second], None));
                led_by.push(lead);
            }
        }
    }
    for (l, _, start) in beside_the_leaders(singles, &leaders, min_gain) {
        let Some(lead) = singles[l].1.as_ref() else {
            continue;
        };
        jobs.push((
            vec![lead.fit.model.effects[0], start.model.effects[0]],
            Some(start),
        ));
        led_by.push(lead);
    }
    (jobs, led_by)
}

/// The pairs [`pair_jobs`] adds beside the leaders' as `(lead, partner, start)`: `lead`
/// and `partner` indices into `singles`, `start` the partner's own fit, to which the pair
/// adds the lead's effect. Each significant single that leads no pair is paired with each
/// single that still scores below the nominal it contains ([`below_its_nominal`]), refitted
/// from the nominal's values ([`nested_refits`]) or not; the start is the fit from its own
/// start either way.
///
/// Why: the leader may be an effect that stood in for the pair, and a single that falls
/// below its nominal may hold its effect's size beside another effect (bench case 36, a
/// stiffening spring behind a 2.2-sample delay at 0.059 rad RMS: backlash alone +1.9 ± 0.1
/// led, the delay +1.3 ± 0.0 came second, the stiffness alone scored −4.0 with `k3` −14 %;
/// tried only with the leader, the answer was backlash with the delay, 12 points below the
/// true model). From the partner's own fit, not from its candidate's size on the lead's fit
/// as the leaders' pairs start: from the delay's fit the stiffness stayed at its default
/// size, 47.8 %; from the stiffness's own fit the pair ended at 73.5 %, above backlash with
/// the delay. A single whose refit from the nominal's values scores as the nominal does is
/// left out: on the nominal's basin its effect came to nothing, and its own fit is a basin
/// that its own cost ranked below that refit (the speed case of `benches/diagnose.rs`: the
/// extra mode and Coulomb friction, refitted to +0.0 points, each paired with the backlash
/// beside the leading stiffening spring: two pair fits, 1.8 s and 1.5 s of the stage
/// timeline, that changed no answer in any battery).
pub(super) fn beside_the_leaders<'s>(
    singles: &'s [(Candidate, Option<Fitted>)],
    leaders: &[usize],
    min_gain: f64,
) -> Vec<(usize, usize, &'s NlFit)> {
    let partners: Vec<(usize, &NlFit)> = singles
        .iter()
        .enumerate()
        .filter(|(_, c)| !c.0.significant && below_its_nominal((c.0.score, c.0.score_se), min_gain))
        .filter_map(|(p, c)| {
            let f = c.1.as_ref()?;
            Some((p, f.own_start.as_ref().unwrap_or(&f.fit)))
        })
        .collect();
    singles
        .iter()
        .enumerate()
        .filter(|(l, c)| c.0.significant && c.1.is_some() && !leaders.contains(l))
        .flat_map(|(l, _)| partners.iter().map(move |&(p, start)| (l, p, start)))
        .collect()
}

/// The pairs of stage 4 the odd lines ask for, when the best single leaves the odd
/// distortion of the validation capture standing at least
/// [`locate::ODD_RESIDUAL_ABOVE_NOISE_DB`] above the noise ([`pairs`] asks): the best single
/// with each candidate that makes such distortion ([`makes_odd`]) and that `jobs` does not
/// pair with it yet, from the best single's fit, the partner at its own single's fitted
/// size (its candidate's when that fit failed or its size vanished,
/// [`super::size::vanished`]).
///
/// Why: a partner whose single is not significant is otherwise never tried, and an effect
/// that makes odd distortion can be plain on the lines while the metric barely sees it
/// (hard bench, `HARD=1 SMALL=1` cases 27 and 37: a parallel mode with a 19 and a 13 mN·m
/// Coulomb friction; the mode alone +1.4 and +4.6 points, leaving the odd residual 16 and
/// 11 dB above the noise; the friction alone −0.01 and −0.02 points, its structure without
/// the mode, so the friction was in neither top two).
fn odd_partner_jobs<'s>(
    fitter: &Fitter<'_>,
    singles: &'s [(Candidate, Option<Fitted>)],
    jobs: &[Job<'s>],
) -> Vec<Job<'s>> {
    let Some((_, Some(lead))) = singles.first().filter(|c| c.0.significant) else {
        return Vec::new();
    };
    let first = lead.fit.model.effects[0];
    let paired = |e: &Effect| {
        jobs.iter().any(|(effects, _)| {
            effects[0].name() == first.name()
                && effects.get(1).is_some_and(|p| p.name() == e.name())
        })
    };
    fitter
        .rec
        .candidates
        .iter()
        .filter(|e| makes_odd(e) && e.name() != first.name() && !paired(e))
        .map(|e| {
            let own = singles
                .iter()
                .find(|c| c.0.name == e.name())
                .and_then(|c| c.1.as_ref())
                .filter(|f| super::size::vanished(&f.fit, false).is_empty())
                .map_or(*e, |f| f.fit.model.effects[0]);
            (vec![first, own], Some(&lead.fit))
        })
        .collect()
}

/// Stage 4: when the best single is significant, the pairs of [`pair_jobs`] and of
/// [`odd_partner_jobs`] fitted; the pair kept gains significantly over its lead alone and
/// scores above the best single, the highest validation FIT among such. A pair whose
/// partner removes most of the odd distortion the best single leaves, more than any other
/// partner ([`odd_shown`] on those shares), is shown by the odd lines and judged as a single
/// they show is ([`Fitted::shown_apart`]).
pub(super) fn pairs(
    fitter: &Fitter<'_>,
    ev: &Evidence,
    answer: &mut Answer,
    warnings: &mut Vec<String>,
) {
    if !fitter.req.options.pairs {
        return;
    }
    let (mut jobs, mut led_by) = pair_jobs(fitter, &answer.singles);
    let top = answer.singles.first().and_then(|c| c.1.as_ref());
    // what the best single leaves at the odd lines, when it stands above the noise
    let left = top
        .and_then(|t| ev.odd_level(&fitter.rec.val, t))
        .filter(|l| l.vs_noise_db >= locate::ODD_RESIDUAL_ABOVE_NOISE_DB);
    if let (Some(t), Some(_)) = (top, &left) {
        for job in odd_partner_jobs(fitter, &answer.singles, &jobs) {
            jobs.push(job);
            led_by.push(t);
        }
    }
    if jobs.is_empty() {
        return;
    }
    let top_fit_val = answer.singles[0].0.fit_val;
    let mut pair: Option<(Candidate, Fitted)> = None;
    let mut res = fitter.fit_all(&jobs);
    let mut tried = Vec::new();
    if let (Some(t), Some(left)) = (top, &left) {
        // the share of the best single's odd-line residual each of its pairs with an effect
        // that makes odd distortion removes; the pair that removes the most, and most of it,
        // is shown by the odd lines ([`Fitted::shown_apart`])
        let shares: Vec<Option<f64>> = jobs
            .iter()
            .zip(&led_by)
            .zip(&res)
            .map(|(((effects, _), lead), r)| {
                let f = r.as_ref().ok()?;
                (std::ptr::eq(*lead, t) && makes_odd(&effects[1]))
                    .then(|| locate::odd_explained(left, &ev.odd_level(&fitter.rec.val, f)?))?
            })
            .collect();
        if let Some(Ok(f)) = odd_shown(&shares).map(|i| &mut res[i]) {
            f.odd_shown = true;
        }
    }
    for (((effects, _), lead), r) in jobs.iter().zip(&led_by).zip(res) {
        match r {
            Ok(f) => {
                let cand = pair_of(fitter, ev, effects, &f, lead);
                tried.push((
                    effects[0].name(),
                    effects[1].name(),
                    (cand.score, cand.score_se),
                ));
                // pairs of different leaders compare by their validation FIT,
                // and one led by the second single must beat the best single too
                let better = pair.as_ref().is_none_or(|p| cand.fit_val > p.0.fit_val)
                    && cand.fit_val > top_fit_val;
                if cand.significant && better {
                    pair = Some((cand, f));
                }
            }
            Err(e) => warnings.push(format!(
                "pair {}+{}: {e}",
                effects[0].name(),
                effects[1].name()
            )),
        }
    }
    for (lead, partner, gain) in tried {
        answer.note_beside((lead, partner), gain);
    }
    if let Some((c, f)) = pair {
        answer.pair = Some(c);
        answer.pair_fitted = Some(f);
    }
}

/// Stage 6: each of the pair's effects alone, refitted from the pair's values: a pair is
/// the answer only when both its effects are needed (a single stuck in a poor basin of its
/// own start can be rescued by the partner's structure, and then does as well alone).
pub(super) fn reduce(
    fitter: &Fitter<'_>,
    nominal: &Fitted,
    ev: &Evidence,
    answer: &mut Answer,
    warnings: &mut Vec<String>,
) {
    let (Some(p), Some(pf)) = (answer.pair.as_ref(), answer.pair_fitted.as_ref()) else {
        return;
    };
    let both = pf.fit.model.effects.clone();
    // an extra mode in parallel on the first arm mass is the mechanism of the arm's
    // second mass: dropped, it may be the structure's branch that goes (bench case 11,
    // backlash on a stiff loop: the pair's mode took the arm's mass and its `J_a2`
    // branch a spurious 86 Hz mode; backlash alone from there ends 15 points below it)
    let swapped = both.iter().enumerate().find_map(|(i, e)| match e {
        Effect::ExtraMode(m) if m.attach == Attach::Parallel => {
            arm_branch_as(&pf.fit, fitter.req.structure, m).map(|f| (1 - i, f))
        }
        _ => None,
    });
    let mut jobs: Vec<Job<'_>> = vec![
        (vec![both[1]], Some(&pf.fit)),
        (vec![both[0]], Some(&pf.fit)),
    ];
    if let Some((keep, f)) = &swapped {
        jobs.push((vec![both[*keep]], Some(f)));
    }
    let res = fitter.fit_all(&jobs);
    // the effect kept, its fit, and what the dropped one adds to it (mean, SE)
    let mut kept: Option<(Effect, Fitted, f64, f64)> = None;
    for ((effects, _), r) in jobs.iter().zip(res) {
        match r {
            Ok(f) => {
                // judged as the pair was against its lead ([`pair_of`])
                let (gain, se, needed) =
                    fitter.judge_model(&pf.scored.segments, &f.scored.segments, Some(pf));
                if !needed && kept.as_ref().is_none_or(|k| f.scored.fit > k.1.scored.fit) {
                    kept = Some((effects[0], f, gain, se));
                }
            }
            Err(e) => warnings.push(format!(
                "pair {}: {} alone from the pair's values: {e}",
                p.name,
                effects[0].name()
            )),
        }
    }
    let Some((effect, f, gain, se)) = kept else {
        return;
    };
    let (score, score_se, significant) =
        fitter.judge_model(&f.scored.segments, &nominal.scored.segments, Some(&f));
    let at = answer
        .singles
        .iter()
        .position(|c| c.0.name == effect.name());
    let (true, Some(i)) = (significant, at) else {
        return;
    };
    let pair_name = p.name.clone();
    let dropped = both
        .iter()
        .find(|e| e.name() != effect.name())
        .map_or("", |e| e.name());
    warnings.push(format!(
        "pair {pair_name}: {} alone, refitted from the pair's values, does as well ({dropped} \
         adds {gain:+.1} ± {se:.1} FIT points to it, not significant): the answer is {} alone",
        effect.name(),
        effect.name()
    ));
    let singles = &mut answer.singles;
    if singles[i].0.score.is_nan() || singles[i].0.score < score {
        let odd = ev.odd_of(&fitter.rec.val, &f);
        let reason = format!(
            "{}; validation FIT {score:+.1} ± {score_se:.1} points, refitted from the values \
             of the pair {pair_name}, to which it leaves {gain:+.1} ± {se:.1} points{}",
            evidence(
                effect.name(),
                &ev.location,
                ripple_travel(&f.fit, &fitter.rec.est_data)
            ),
            odd_words(odd)
        );
        singles[i] = (
            scored_candidate(
                effect.name(),
                &f,
                (score, score_se, significant),
                false,
                (reason, odd),
            ),
            Some(f),
        );
        answer.sort();
    }
    answer.pair = None;
    answer.pair_fitted = None;
}

/// Stage 5: the answer's fit continued when it stopped at its iteration limit
/// ([`Fitter::polish`]), and judged again; a pair's before [`reduce`] (bench case 7 with the sizes drawn small, a parallel mode with a
/// Stribeck friction that sticks the motor 56 % of the time: the pair stopped at 60
/// iterations at 84.5 %, the friction alone refitted from it reached 85.3 % and was the
/// answer, 9.7 points below the true model's 95.0 %; continued, the pair reached 94.5 %).
pub(super) fn polish_answer(
    fitter: &Fitter<'_>,
    nominal: &Fitted,
    ev: &Evidence,
    answer: &mut Answer,
    warnings: &mut Vec<String>,
) {
    let Some(f) = answer.best_fitted() else {
        return;
    };
    let Some(g) = fitter.polish(f) else {
        return;
    };
    let best = answer.best().map_or("none", |c| c.name.as_str());
    warnings.push(format!(
        "{best}: its fit stopped at its iteration limit ({} iterations) and was continued \
         from there for {} more: in-sample cost {:+.1} %, validation FIT {:.1} → {:.1} %",
        f.fit.iterations,
        g.fit.iterations,
        100.0 * (g.fit.ssr / f.fit.ssr - 1.0),
        f.scored.fit,
        g.scored.fit
    ));
    if answer.pair.is_some() {
        let effects = g.fit.model.effects.clone();
        let lead = answer
            .singles
            .iter()
            .find(|c| c.0.name == effects[0].name())
            .and_then(|c| c.1.as_ref());
        if let Some(lead) = lead {
            answer.pair = Some(pair_of(fitter, ev, &effects, &g, lead));
            answer.pair_fitted = Some(g);
        }
    } else {
        let effect = g.fit.model.effects[0];
        let odd = ev.odd_of(&fitter.rec.val, &g);
        answer.singles[0] = (single_of(fitter, ev, nominal, (&effect, odd), &g), Some(g));
    }
}

/// Whether a single that is not significant gains over its nominal beyond twice its
/// standard error (`mean − 2·SE > 0`), under the floor, with an effect of some size that
/// the data support ([`Fitted::counts`]): the data hold some of its effect, and beside the
/// leader it may show more, or the pair's test may say what it adds. Tried as a partner
/// from its own fit, as a significant single is; what it adds to the answer ranks it
/// ([`super::table::ranked_after`]). Held-out hard bench case 66, a stiffening spring with
/// a delay of 0.19 samples beside a lag of 3 samples: the delay alone +0.054 ± 0.003
/// points, under the floor, and never tried beside the stiffness, while backlash (+1.4
/// alone, +0.000 beside it) ranked second (tried now, the delay adds +0.000 too: the
/// lag holds it). Not a single of no size: a refit from the
/// nominal's values whose effect stayed at nought gains a rounding's worth, and its fit is
/// no start for the pair (held-out default case 47, a mode with Coulomb friction: the
/// friction's refit at `fc` 3.5·10⁻⁷ N·m, paired from there, stayed on its bound, where
/// the friction's own start finds it within 0.1 %).
fn adds_some(c: &(Candidate, Option<Fitted>)) -> bool {
    c.0.score - 2.0 * c.0.score_se > 0.0 && c.1.as_ref().is_some_and(|f| f.counts(true))
}

/// Whether a single that is not significant is still tried as a partner of the significant
/// ones ([`pair_jobs`]): its fit scores below the nominal it contains, or its own start's
/// did and a refit from the nominal's values replaced it ([`nested_refits`]). Either way
/// its own fit said nothing of its effect, which may show only beside another (bench case
/// 27: the friction's own fit scored −23 points; refitted from the nominal, it scores
/// nought alone, and with the mode it closes the gap).
fn partner_anyway(c: &(Candidate, Option<Fitted>), min_gain: f64) -> bool {
    below_its_nominal((c.0.score, c.0.score_se), min_gain)
        || c.1.as_ref().is_some_and(|f| f.own_start.is_some())
}

/// Whether a single's validation score `(mean, se)` [FIT points] lies significantly below
/// its nominal's: `mean + 2·SE < −min_gain`, the mirror of significance. Nominal + an
/// effect contains the nominal (the effect at nought), so only a fit in a wrong basin
/// scores there.
pub(super) fn below_its_nominal((mean, se): (f64, f64), min_gain: f64) -> bool {
    mean + 2.0 * se < -min_gain
}

/// `fit` with its structure's second arm branch (`J_a2`, `k_a`, `d_a` of the three-mass)
/// replaced by the extra mode `mode` attached in parallel on the first arm mass, the same
/// mechanism; `None` for other structures.
fn arm_branch_as(fit: &NlFit, structure: Structure, mode: &ExtraMode) -> Option<NlFit> {
    if structure != Structure::ThreeMass || mode.attach != Attach::Parallel {
        return None;
    }
    let names = structure.param_names();
    let at = |n: &str| names.iter().position(|m| *m == n);
    let mut f = fit.clone();
    for (name, value) in [("J_a2", mode.j), ("k_a", mode.k), ("d_a", mode.d)] {
        *f.plant.get_mut(at(name)?)? = value;
    }
    Some(f)
}
