//! One candidate model (the nominal plus its effects) fitted on the estimation records and
//! scored on the validation records: the unit every stage calls, through [`Fitter`], which
//! also holds the one significance test ([`Fitter::judge`]).

use crate::data::IdData;
use crate::ident::lm::Termination;
use crate::ident::nonlinear::{
    grow, identify_segments, model_of, DelayLines, NlError, NlFit, NlRequest, NlResult, NlRunError,
    NlStart, Owner,
};
use crate::ident::parallel::parallel;
use crate::model::effects::Effect;

use super::inputs::{nl_options, Records};
use super::metric::{
    self, score_segments, segment_gain, start_sensitivity_segments, DrivenModel, Measured, Scored,
};
use super::starts::LinearStarts;
use super::{progress, CandidateError, DiagnoseRequest, SENSITIVE};

/// One model to fit: the nominal's effects added, and the fit whose values start it
/// (`None`: the candidate's own start).
pub(super) type Job<'f> = (Vec<Effect>, Option<&'f NlFit>);

/// What every stage fits and judges with: the request, the checked records, the starts and
/// the significance test's floor.
pub(super) struct Fitter<'a> {
    pub req: &'a DiagnoseRequest,
    pub rec: &'a Records<'a>,
    pub starts: &'a LinearStarts,
    pub floor: Floor,
}

/// The smallest gain [FIT points] the significance test counts: the option's
/// [`super::DiagnoseOptions::min_gain`], or the spread of the nominal's own refits when that
/// is larger ([`super::nominal::refit_spread`]).
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Floor {
    /// the floor [FIT points]
    pub gain: f64,
    /// why it is above the option's, in words
    pub why: Option<String>,
    /// the spread of the nominal's own refits [FIT points] (0 when no single came out of
    /// no size at the nominal's cost): the finest gain the validation metric tells from a
    /// refit of the nominal elsewhere
    pub spread: f64,
}

impl Floor {
    /// The floor [FIT points] for the model `single` (a single against the nominal, `None`
    /// for any other comparison), as [`Fitter::judge_model`] explains: the spread alone
    /// for a single whose effect the data show apart from the metric, else the floor.
    pub fn of_model(&self, single: Option<&Fitted>) -> f64 {
        if single.is_some_and(Fitted::shown_apart) {
            self.spread
        } else {
            self.gain
        }
    }

    /// The option's floor alone.
    pub fn of(req: &DiagnoseRequest) -> Floor {
        Floor {
            gain: req.options.min_gain,
            why: None,
            spread: 0.0,
        }
    }
}

impl Fitter<'_> {
    /// The model of `job` fitted and scored, its start and end told to the progress
    /// observer.
    pub fn fit(&self, (effects, from): &Job<'_>) -> Result<Fitted, CandidateError> {
        let label = if effects.is_empty() {
            "nominal".to_string()
        } else {
            effects
                .iter()
                .map(|e| e.name())
                .collect::<Vec<_>>()
                .join(" + ")
        };
        let r = self.rec;
        progress::step(
            self.req.progress.as_ref(),
            &label,
            || {
                fit_and_score(
                    &r.est_data,
                    &r.val_data,
                    &r.parts,
                    self.req,
                    effects.clone(),
                    self.starts,
                    *from,
                )
            },
            |r| match r {
                Ok(_) => "fitted and scored".to_string(),
                Err(e) => format!("failed: {e}"),
            },
        )
    }

    /// Whether a pair led by `lead`'s effect starts from the structure grown in the time
    /// domain ([`super::starts::LinearStarts::grown`]): a Coulomb friction where the motor
    /// sticks. Such a pair is fitted from its lead's values only: the data's own start of a
    /// pair with the friction is the grown structure the lead started from already, and
    /// the frequency-domain fits of its partner started from the FRF the sticking motor
    /// spoils.
    pub fn grown_lead(&self, lead: &Effect) -> bool {
        self.starts.grown.is_some() && matches!(lead, Effect::CoulombFriction(_))
    }

    /// Every job of `jobs`, on the request's threads, the results in order.
    pub fn fit_all(&self, jobs: &[Job<'_>]) -> Vec<Result<Fitted, CandidateError>> {
        parallel(jobs, self.req.options.threads, |j| self.fit(j))
    }

    /// The significance test: the gain `(mean, SE)` [FIT points] of the segment-wise metric
    /// `seg` over the model it extends, `base`, and whether `mean − 2·SE` exceeds the floor
    /// ([`Floor`]).
    pub fn judge(&self, seg: &[f64], base: &[f64]) -> (f64, f64, bool) {
        self.judge_model(seg, base, None)
    }

    /// As [`Fitter::judge`], for the model `single` (a single against the nominal, `None`
    /// for any other comparison): a single whose effect the data show apart from the
    /// metric ([`Fitted::shown_apart`]) needs no more than the spread of the nominal's own
    /// refits ([`Floor::spread`]). The option's floor stands for what the time-domain
    /// metric alone cannot tell from a wrong model that absorbs a little of the nominal's
    /// misfit; where a test of the effect's own signature already rejects the nominal, the
    /// metric has only to confirm that the fitted effect closes part of the gap, beyond
    /// twice its standard error and the metric's own resolution. Hard bench (`HARD=1
    /// SMALL=1`): delays of 0.2–0.4 samples beside the lag, the lines' drop 24–1200 against
    /// a 99 % point of 8, the validation gain 0.03–0.15 points; a ripple of order 72 whose
    /// order stood out at a robust z-score of 9.4 (significant from 8), the validation gain
    /// 0.17 ± 0.01 points (case 15).
    pub fn judge_model(
        &self,
        seg: &[f64],
        base: &[f64],
        single: Option<&Fitted>,
    ) -> (f64, f64, bool) {
        let (m, se) = segment_gain(seg, base);
        (m, se, m - 2.0 * se > self.floor.of_model(single))
    }

    /// The answer's fit `f` continued ([`Fitter::continued`]), kept when its validation FIT
    /// does not drop. Only the answer: its FIT is the closure the diagnosis reports, and
    /// every candidate at once would slow each diagnosis (bench case 21, a 16 µrad backlash
    /// at 0.014 rad RMS: the fit stopped at 60 iterations in a flat valley with `f_m` ×4 and
    /// 76.9 % on validation against the true model's 80.4 %; continued, it reaches 78.4 % at
    /// the limit of the 140 further iterations).
    pub fn polish(&self, f: &Fitted) -> Option<Fitted> {
        let g = self.continued(f)?;
        (g.scored.fit >= f.scored.fit).then_some(g)
    }

    /// The fit `f` continued from its values for at most [`POLISH_ITER`] more iterations
    /// when it stopped at its iteration limit, what it held still held, and scored on the
    /// validation records; `None` when it had converged, or the continuation fails or does
    /// not lower the in-sample cost (the only criterion).
    pub fn continued(&self, f: &Fitted) -> Option<Fitted> {
        if f.fit.termination != Termination::MaxIterations {
            return None;
        }
        let req = self.req;
        let mut options = nl_options(&req.options, &f.fit.model.effects, self.starts.sticks);
        // on the cost the fit ended on, which its `ssr` is of (a nested refit's is the
        // nominal's band-limited one, [`super::select::nested_refits`])
        options.lowpass_hz = f.fit.lowpass_hz;
        options.max_iter = POLISH_ITER;
        options.fixed = f
            .fit
            .params
            .iter()
            .filter(|p| p.fixed && p.owner != Owner::InitialVelocity)
            .map(|p| p.name.to_string())
            .collect();
        let nl = NlRequest {
            tau_c: f.fit.model.tau_c,
            linear: Some(f.fit.plant.clone()),
            start: NlStart::Values(f.fit.values.clone()),
            options,
            ..NlRequest::new(req.structure, req.r, f.fit.model.effects.clone())
        };
        let r = self.rec;
        let res = identify_segments(&r.est_data, &nl).ok()?;
        if res.fit.ssr >= f.fit.ssr {
            return None;
        }
        let mut g = scored_fit(res, (&r.est_data, &r.val_data, &r.parts), req, self.starts).ok()?;
        // the same model further down its cost: what the odd lines showed of it holds
        g.odd_shown = f.odd_shown;
        Some(g)
    }

    /// The nominal `base` with an effect added, fitted from the nominal's values (structure,
    /// lag, offset; the effect at `start`) on the nominal's own cost: the residual
    /// band-limited as the nominal's, whatever the effect
    /// ([`super::select::nested_refits`]). The effect's search bounds are measured about
    /// `about` (the single's own fit) and hold `start`: a size started small can grow back
    /// to its own fit's and beyond, where bounds about the start would stop it a factor of
    /// [`NlOptions::plant_range`] above (hard bench, `HARD=1 SMALL=1` case 100, a 3.1 mN·m
    /// Coulomb friction: refitted from 1e-3 of its own fit's 2.7 mN·m, the level ended on
    /// that bound at 0.26 mN·m and the single at +0.18 points of the true model's +1.32).
    pub fn nested(
        &self,
        base: &NlFit,
        (start, about): (Effect, Effect),
    ) -> Result<Fitted, CandidateError> {
        self.refit_from(base, (vec![start], Some(vec![about])))
    }

    /// The nominal, with no effect, fitted from the structure, lag and offset of the fit
    /// `from` on the nominal's own cost ([`super::nominal::from_singles`]).
    pub fn linear_from(&self, from: &NlFit) -> Result<Fitted, CandidateError> {
        self.refit_from(from, (Vec::new(), None))
    }

    /// The structure with `effects` fitted from the values of `base` (structure, lag,
    /// offset; the effects at the values they carry) on the nominal's own cost, and scored;
    /// the search bounds measured about `base` with the effects `about` when given
    /// ([`NlOptions::range_from`]), else about the start.
    fn refit_from(
        &self,
        base: &NlFit,
        (effects, about): (Vec<Effect>, Option<Vec<Effect>>),
    ) -> Result<Fitted, CandidateError> {
        let req = self.req;
        let r = self.rec;
        let longest = longest(&r.est_data).ok_or(CandidateError::NoRecord)?;
        let mut nl = NlRequest {
            options: req.options.nl.clone(),
            ..NlRequest::new(req.structure, req.r, effects)
        };
        start_from(&mut nl, base, longest);
        if let Some(effects) = about {
            let centre = NlRequest {
                effects,
                ..nl.clone()
            };
            let centre = model_of(&centre, longest).values(&base.plant, offset_of(base), 0.0);
            nl.options.range_from = Some(centre);
        }
        let res = identify_segments(&r.est_data, &nl).map_err(CandidateError::Fit)?;
        scored_fit(res, (&r.est_data, &r.val_data, &r.parts), req, self.starts)
    }

    /// As [`Fitter::nested`], the effect placed by the automatic start's third step (seed
    /// 001: a grid on the output-error cost over the effect's parameters, for an extra mode
    /// its frequency) on the nominal's structure, lag and cost, instead of at the size and
    /// shape it carries; a mode is also fitted from each peak of the nominal's residual,
    /// the lowest cost kept ([`crate::ident::nonlinear::Start::at_peaks`]).
    pub fn nested_grid(&self, base: &NlFit, effect: Effect) -> Result<Fitted, CandidateError> {
        let req = self.req;
        let r = self.rec;
        let nl = NlRequest {
            tau_c: base.model.tau_c,
            linear: Some(base.plant.clone()),
            options: req.options.nl.clone(),
            ..NlRequest::new(req.structure, req.r, vec![effect])
        };
        let res = identify_segments(&r.est_data, &nl).map_err(CandidateError::Fit)?;
        scored_fit(res, (&r.est_data, &r.val_data, &r.parts), req, self.starts)
    }

    /// The gap metric [%] of `model` on the estimation records themselves (in-sample),
    /// scored as on validation; `None` when it does not simulate.
    pub fn in_sample(&self, model: &DrivenModel) -> Option<f64> {
        let o = &self.req.options;
        let est = &self.rec.est_data;
        let ms: Vec<Measured> = est.iter().map(|d| o.measured(d)).collect();
        score_segments(&ms, model, est, 1).map(|s| s.fit).ok()
    }
}

/// One fitted model with its score.
pub(super) struct Fitted {
    pub fit: NlFit,
    pub scored: Scored,
    pub warnings: Vec<String>,
    /// the single's fit from its own start, when its refit from the nominal's values
    /// replaced it ([`super::select::nested_refits`]); the pairs take it as they take a
    /// single below its nominal
    pub own_start: Option<NlFit>,
    /// why the data do not support an effect of the model however it scores: it is then
    /// never significant ([`delay_unsupported`], [`nonlinear_unsupported`])
    pub unsupported: Option<Unsupported>,
    /// the excited lines' likelihood-ratio evidence of a transport delay beside the lag
    /// ([`crate::ident::nonlinear::DelayLines`]); when they show one, a delay's size is
    /// judged by them, not by its deviation, which the lag it trades with spreads
    /// ([`super::size::vanished_effects`])
    pub delay_lines: Option<DelayLines>,
    /// the torque ripple's order the order search found on the estimation data among the
    /// candidates the travel tells apart, coherent along the record, and how the validation
    /// record shows it again ([`RippleShown`]); none when it found no order or only one
    /// below the candidates
    pub ripple_shown: Option<RippleShown>,
    /// a single delay refitted with its size held at the delay the excited lines show,
    /// when its free fit came out outside their interval ([`at_lines_delay`]); the single
    /// is this one when the free fit is not significant and this one is
    /// ([`super::select::lines_sized`])
    pub at_lines: Option<Box<Fitted>>,
    /// the single's effect makes odd distortion and the model removes more of the
    /// nominal's odd-line residual than any other single, and most of it
    /// ([`super::select::odd_shown`]); for a pair, its partner's, of what its lead leaves,
    /// more than any other partner of that lead ([`super::select::pairs`])
    pub odd_shown: bool,
}

impl Fitted {
    /// Whether the data show this model's one effect by its own signature, apart from the
    /// validation metric: a transport delay the excited lines show beside the lag (a
    /// likelihood-ratio test at 99 %, [`crate::ident::nonlinear::DelayLines`]) at the size
    /// fitted (within [`crate::ident::nonlinear::DelayLines::interval`]), or a torque
    /// ripple at the order the search against the motor angle found (its cost drop a
    /// robust z-score of [`crate::ident::nonlinear::ripple::SIGNIFICANT_Z`] above those of
    /// the orders a period or more apart over the travel, the same ripple on each part of
    /// the record), or a friction, a gap or a stiffening spring that removes most of the
    /// odd distortion the nominal leaves on the validation capture's non-excited odd lines
    /// (standing at least [`super::locate::ODD_RESIDUAL_ABOVE_NOISE_DB`] above the noise),
    /// more than any other single does ([`super::select::odd_shown`]). Any of those three
    /// follows part of such distortion, so only the one that explains the most is shown by
    /// it. An extra mode is a linear structure the lines' fit of more masses would need. A
    /// pair whose partner is such an effect is shown when the partner removes most of what
    /// its lead leaves, more than any other partner of that lead.
    pub fn shown_apart(&self) -> bool {
        match self.fit.model.effects[..] {
            [Effect::TimeDelay(d)] => self.delay_lines.is_some_and(|l| l.holds(d.samples)),
            [Effect::TorqueRipple(r)] => self
                .ripple_shown
                .is_some_and(|s| s.replicated() && f64::from(s.order) == r.order),
            // a single, or a pair's partner, whose law makes odd distortion
            [e] | [_, e] if makes_odd(&e) => self.odd_shown,
            _ => false,
        }
    }

    /// Whether the excited lines show a transport delay beside the lag
    /// ([`crate::ident::nonlinear::DelayLines::shown`]).
    pub fn delay_shown(&self) -> bool {
        self.delay_lines.is_some_and(|l| l.shown())
    }

    /// Whether a gain judged `significant` counts for this model: not when the data do not
    /// support one of its effects ([`Fitted::unsupported`]), nor when one of its effects
    /// came out of no size ([`super::size::vanished_effects`]). Every stage that judges a
    /// gain, open loop and in the controller's loop, asks here, so that a refit (in the
    /// loop, with its own deviations) is held to the same test as the first fit.
    pub fn counts(&self, significant: bool) -> bool {
        significant
            && self.unsupported.is_none()
            && super::size::vanished(&self.fit, self.delay_shown()).is_empty()
    }
}

/// Whether `e`'s law makes odd distortion at the non-excited odd lines of a periodic
/// capture (seed 000 §3): friction, a gap and a stiffening spring do; a mode, a delay and a
/// ripple against the angle do not.
pub(super) fn makes_odd(e: &Effect) -> bool {
    matches!(
        e,
        Effect::CoulombFriction(_) | Effect::Backlash(_) | Effect::NonlinearStiffness(_)
    )
}

/// Why the data do not support an effect of a model, whatever the model scores.
#[derive(Clone, Debug, PartialEq)]
pub(super) enum Unsupported {
    /// a transport delay the excited lines do not show beside the lag, in words
    /// ([`delay_unsupported`])
    Delay(String),
    /// a nonlinear law on data that show no nonlinearity, in words
    /// ([`nonlinear_unsupported`]): it stands in for a linear mismatch
    Linear(String),
}

impl std::fmt::Display for Unsupported {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Unsupported::Delay(why) | Unsupported::Linear(why) => f.write_str(why),
        }
    }
}

/// Why a model with a nonlinear law is not supported by the data: when they show no
/// nonlinearity at all ([`super::linearity::Nonlinearity::none_shown`]), a friction, a gap
/// or a stiffening spring, and a ripple that the order search does not show by its own
/// signature (`ripple_shown`), gain only through their linear part.
pub(super) fn nonlinear_unsupported(
    fit: &NlFit,
    starts: &LinearStarts,
    ripple_shown: bool,
) -> Option<Unsupported> {
    let law = fit
        .model
        .effects
        .iter()
        .find(|e| makes_odd(e) || (matches!(e, Effect::TorqueRipple(_)) && !ripple_shown))?;
    let why = starts.nonlinearity.as_ref()?.none_shown()?;
    Some(Unsupported::Linear(format!("{}: {why}", law.name())))
}

/// Why a model with a transport delay is not supported by the data, when the excited lines
/// hold no evidence of a delay beside the lag ([`crate::ident::nonlinear::DelayLines`]).
/// The gap metric simulates from the measured torque, which in a closed loop holds the
/// controller's reaction to the disturbance; where the disturbance dominates the motion a
/// delay follows that reaction, on validation as on estimation (hard bench, a joint with no
/// delay at 0.017 rad RMS and a nominal of 51.6 %: a 2.2-sample delay scored +0.65 ± 0.06
/// points, above the true model). The lines, read through the periodic reference, are
/// consistent in the loop: there the delay lowered the cost by 0.0.
///
/// A record with no lines (too few whole periods for the frequency-domain fit) cannot
/// test a delay that way, and a delay counts there only beside a lag: one whose fit put
/// the current-loop lag on its lower bound took the lag's phase rather than adding to it,
/// and the time-domain metric alone does not tell a first-order lag from a delay of the
/// same phase (`jointid simulate --periods 2` of the default three-mass joint, which has
/// the drive's 0.5 ms lag and no delay: the delay's fit put the lag at 0.001 ms and the
/// delay at 1.01 samples, +0.34 ± 0.04 points on a nominal its fit left short of a
/// minimum).
pub(super) fn delay_unsupported(fit: &NlFit, starts: &LinearStarts) -> Option<String> {
    if !fit
        .model
        .effects
        .iter()
        .any(|e| matches!(e, Effect::TimeDelay(_)))
    {
        return None;
    }
    let Some(l) = starts.delay_lines else {
        let lag = fit
            .params
            .iter()
            .find(|p| p.name == "tau_c" && !p.fixed && p.at_lower)?;
        return Some(format!(
            "the record holds too few whole periods for the excited lines to test a delay, \
             and the delay's fit put the current-loop lag on its lower bound (τ_c = {:.3} ms): \
             the delay took the lag's phase instead of adding to it, which the records alone do \
             not tell from a lag, and it is not counted",
            lag.value * 1e3
        ));
    };
    if l.shown() {
        return None;
    }
    Some(format!(
        "the excited lines show no transport delay beside the current-loop lag: fitted with one \
         ({:.2} samples), the structure's frequency-domain fit lowers its SML cost by {:.1}, \
         where {:.1} is the 99 % point for a delay that is not there; what the delay gains on the \
         records follows the disturbance the loop feeds back into the torque, and it is not \
         counted",
        l.delay,
        l.drop,
        l.threshold()
    ))
}

/// Fits `effects` on the records `est` (one, or the gap-free segments of one capture as
/// separate experiments) and scores on `val` (likewise, `parts` their measured sides).
/// `from`: a fit whose structure values, lag and offset start this one, the effects
/// starting at the values they carry (a pair, started from its singles' fits); `None`: the
/// automatic start, or the extra mode's.
#[allow(clippy::too_many_arguments)]
pub(super) fn fit_and_score(
    est: &[IdData],
    val: &[IdData],
    parts: &[Measured],
    req: &DiagnoseRequest,
    effects: Vec<Effect>,
    starts: &LinearStarts,
    from: Option<&NlFit>,
) -> Result<Fitted, CandidateError> {
    let linear = &starts.structure;
    // a single's keys the user gave start there (a pair starts from its singles' fits)
    let given = match from {
        None => effects
            .iter()
            .map(|e| req.given.get(e.name()).cloned().unwrap_or_default())
            .collect(),
        Some(_) => Vec::new(),
    };
    // the drive's current-loop lag belongs to the nominal and to every candidate: without a
    // frequency-domain start to take it from, it starts at one sample and is fitted
    // (`nominal::tests`, a three-mass joint over two periods: a nominal with no lag left a
    // delay candidate to take the 0.5 ms lag for a delay of a sample, +21.8 points)
    let ts = est.first().map_or(0.0, |d| d.ts);
    let mut nl = NlRequest {
        tau_c: linear
            .as_ref()
            .map_or(starts.lag_start.unwrap_or(ts), |l| l.1),
        linear: linear.as_ref().map(|l| l.0.clone()),
        given,
        options: nl_options(&req.options, &effects, starts.sticks),
        ..NlRequest::new(req.structure, req.r, effects)
    };
    let automatic = nl.clone();
    // an extra mode starts where the linear fit with one more mass put it
    let longest = longest(est).ok_or(CandidateError::NoRecord)?;
    let extra_at = nl
        .effects
        .iter()
        .position(|e| matches!(e, Effect::ExtraMode(_)));
    let with_coulomb = nl
        .effects
        .iter()
        .any(|e| matches!(e, Effect::CoulombFriction(_)));
    let coulomb_at = nl
        .effects
        .iter()
        .position(|e| matches!(e, Effect::CoulombFriction(_)));
    // the friction-compensated start with one more mass, fitted on its first call: asked
    // only when the job holds both effects and the motor does not stick
    let coulomb_mode = || {
        extra_at
            .filter(|_| with_coulomb)
            .and_then(|i| starts.coulomb_extra_mode.get().map(|s| (i, s)))
    };
    if let (Some(ci), Some(g)) = (coulomb_at, &starts.grown) {
        // the motor sticks: the structure grown in the time domain ([`grow`]); with an
        // extra mode, the mode from the start's grid on it and the friction as given (a
        // pair's: its single's fitted law); else the grown friction, or a pair's start
        let (plant, tau_c, keys) = match from {
            Some(b) => (b.plant.clone(), b.model.tau_c, grow::friction_keys(b)),
            None => {
                nl.effects[ci] = g.coulomb;
                (g.plant.clone(), g.tau_c, Vec::new())
            }
        };
        nl.tau_c = tau_c;
        nl.linear = Some(plant.clone());
        if extra_at.is_some() {
            let mut given = nl.given.clone();
            given.resize(nl.effects.len(), Vec::new());
            given[ci].extend(keys);
            nl.given = given;
            if let Some(b) = from {
                // a pair: the lead's fitted friction, and the mode from the growth's race
                // over its grid on the lead's structure (the automatic start's grid keeps
                // the lead's gearbox damper, which stood in for the mode: bench case 17, a
                // parallel mode at 10 Hz under friction that sticks 23 % of the time,
                // answered Coulomb friction alone, 20 points short of the truth; and the
                // grid's best point alone puts the mode out of the way: case 67, a parallel
                // mode at 10 Hz, the motor stuck on 81 % of the samples, the mode went to
                // 50 Hz and the pair gained +0.4 ± 0.1 points over the friction alone, 75.2
                // % against the true model's 92.3 %; from the race it reached 92.7 %)
                if let Some(c) = b
                    .model
                    .effects
                    .iter()
                    .find(|e| matches!(e, Effect::CoulombFriction(_)))
                {
                    nl.effects[ci] = *c;
                }
                let offset = b.get("offset").unwrap_or(0.0);
                let screened = grow::fit_with_mode_raced(est, &nl, &plant, offset)?;
                nl.start = NlStart::Values(screened.values);
            }
        } else if let Some(b) = from {
            let offset = b.get("offset").unwrap_or(0.0);
            nl.start = NlStart::Values(model_of(&nl, longest).values(&plant, offset, 0.0));
        } else {
            nl.start = NlStart::Values(model_of(&nl, longest).values(&plant, g.offset, 0.0));
        }
    } else if let Some((i, (plant, mode, tau_c))) = coulomb_mode() {
        // Coulomb friction with an extra mode: the structure and the mode from the
        // friction-compensated FRF of the structure with one more mass, the friction's
        // level as given (a pair's: its single's fitted level)
        nl.effects[i] = Effect::ExtraMode(*mode);
        nl.tau_c = *tau_c;
        nl.linear = Some(plant.clone());
        let offset = from.and_then(|b| b.get("offset")).unwrap_or(0.0);
        nl.start = NlStart::Values(model_of(&nl, longest).values(plant, offset, 0.0));
    } else if let Some(base) = from {
        start_from(&mut nl, base, longest);
    } else if let (Some(i), Some((plant, mode, tau_c))) = (extra_at, &starts.extra_mode) {
        nl.effects[i] = Effect::ExtraMode(*mode);
        nl.tau_c = *tau_c;
        nl.linear = Some(plant.clone());
        nl.start = NlStart::Values(model_of(&nl, longest).values(plant, 0.0, 0.0));
    } else if let (true, Some((plant, tau_c))) = (with_coulomb, &starts.coulomb) {
        // Coulomb friction: the linear start from the friction-compensated FRF
        nl.tau_c = *tau_c;
        nl.linear = Some(plant.clone());
    }
    // a start of its own that does not simulate gives way to the automatic start (bench
    // case 57, a parallel mode at 10 Hz with Coulomb friction at 0.073 rad RMS: the mode's
    // start from the four-mass linear fit did not simulate, the mode was no candidate, and
    // the answer was the friction alone, 10 points below the true model)
    let mut res = match identify_segments(est, &nl) {
        Err(NlRunError::Estimation(NlError::Unstable)) if nl != automatic => {
            identify_segments(est, &automatic).map_err(CandidateError::AutomaticToo)
        }
        r => r.map_err(CandidateError::Fit),
    };
    if let ([Effect::Backlash(_)], None, Some(two)) = (&nl.effects[..], from, &starts.two_mass) {
        // a gap as wide as the deflection bends the linear structure away from the joint's:
        // the start grown from the two-mass too, the lower cost kept ([`grow::grow_backlash`])
        let beat = res.as_ref().ok().map(|r| r.fit.ssr);
        if let Some(g) = backlash_grown(est, req, &nl, two, (longest, beat)) {
            if res.as_ref().map_or(true, |r| g.fit.ssr < r.fit.ssr) {
                res = Ok(g);
            }
        }
    }
    let res = ripple_at_best_order(est, val, &nl, res?);
    let held = at_lines_delay(est, &nl, &res, starts);
    let mut fitted = scored_fit(res, (est, val, parts), req, starts)?;
    if let Some(h) = held {
        fitted.at_lines = scored_fit(h, (est, val, parts), req, starts)
            .ok()
            .map(Box::new);
    }
    Ok(fitted)
}

/// The single delay `res` refitted with its size held at the delay the excited lines show
/// ([`DelayLines::delay`]), when they show one and `res` came out outside their interval
/// ([`DelayLines::holds`]); `None` otherwise or when the refit fails. It stands in for the
/// free fit only where that is not significant ([`super::select::lines_sized`]): where the
/// delay is one effect of several, the single's free delay takes some of the others' part,
/// and held at the lines' size it scored below the nominal (hard bench, `HARD=1 SMALL=1`
/// case 26, a stiffening spring and a 0.76-sample delay: free, 1.14 samples and +8.0
/// points; held at the lines' 0.78, −7.8 points, and the pair was lost).
///
/// Why: the lines read the delay through the periodic reference, consistent in the loop,
/// and tell it from the lag by the lag's fall in magnitude; the records' output error reads
/// it from the measured torque, which holds the controller's reaction to the disturbance,
/// and shares the phase between lag and delay otherwise. Hard bench (`HARD=1`) case 34, a
/// 1.37-sample delay behind a 0.76 ms lag: the lines gave 1.36 samples (interval 1.23–1.49),
/// the records 1.59 samples with the lag at 0.69 ms. So the lines size the delay, and the
/// metric judges what that delay gains. Where the lines show a phase that is not a delay,
/// that is not enough: the default joint with a 2 mN·m ripple and no delay shows 0.07
/// samples on the lines (the ripple's describing function; the records fitted 0.35), and
/// held there the delay gains +0.02 ± 0.00 points, which counts when no refit of the
/// nominal measured the metric's spread ([`Floor::spread`] nought).
fn at_lines_delay(
    est: &[IdData],
    nl: &NlRequest,
    res: &NlResult,
    starts: &LinearStarts,
) -> Option<NlResult> {
    let ([Effect::TimeDelay(d)], Some(l)) = (&res.fit.model.effects[..], starts.delay_lines) else {
        return None;
    };
    // a delay the user held stays where it is
    // only where the lines' delay explains them: elsewhere the held delay would be judged
    // against the floor like the free one ([`Fitted::shown_apart`])
    if !l.explains() || l.holds(d.samples) || nl.fixed.iter().any(|(n, _)| n == "samples") {
        return None;
    }
    let held = NlRequest {
        fixed: nl
            .fixed
            .iter()
            .cloned()
            .chain([("samples".to_string(), l.delay)])
            .collect(),
        start: NlStart::Values(res.fit.values.clone()),
        ..nl.clone()
    };
    let mut out = identify_segments(est, &held).ok()?;
    let (lo, hi) = l.interval();
    out.warnings.insert(
        0,
        format!(
            "the delay is held at the {:.2} samples the excited lines show (99 % interval \
             {lo:.2}–{hi:.2}); fitted free on the records it came out at {:.2} samples, the \
             lag taking the rest of the phase",
            l.delay, d.samples
        ),
    );
    Some(out)
}

/// The finished fit `res` on `est` scored on `val` (`parts` its measured sides), with its
/// warnings, its own sensitivity to its start and whether the starts' evidence supports its
/// effects ([`delay_unsupported`]).
pub(super) fn scored_fit(
    res: NlResult,
    (est, val, parts): (&[IdData], &[IdData], &[Measured]),
    req: &DiagnoseRequest,
    starts: &LinearStarts,
) -> Result<Fitted, CandidateError> {
    let model = DrivenModel::of_fit(&res.fit);
    let scored = score_segments(parts, &model, val, req.options.segments)?;
    let mut warnings = res.warnings;
    let own = start_sensitivity_segments(parts, &model, val, &scored)?;
    if own < metric::SENSITIVE_BELOW {
        warnings.push(format!(
            "{SENSITIVE}: moving its start angle by {:e} rad moves its simulation to a \
             band-passed velocity FIT of {own:.1} % against itself, so its response is chaotic \
             at this amplitude and no simulation metric can score it; diagnose on captures at \
             a smaller amplitude",
            metric::START_PERTURBATION_RAD
        ));
    }
    let ripple_shown = res
        .ripple_search
        .as_ref()
        .and_then(|f| f.order.filter(|_| !f.short()).map(|n| (n, f.z)))
        .map(|(order, z)| {
            let (chance_val, repeats) = ripple_on_validation(&res.fit, est, val, order);
            RippleShown {
                order,
                z,
                chance_val,
                repeats,
            }
        });
    let unsupported = delay_unsupported(&res.fit, starts)
        .map(Unsupported::Delay)
        .or_else(|| nonlinear_unsupported(&res.fit, starts, ripple_shown.is_some()));
    Ok(Fitted {
        fit: res.fit,
        scored,
        warnings,
        own_start: None,
        unsupported,
        delay_lines: starts.delay_lines,
        at_lines: None,
        odd_shown: false,
        ripple_shown,
    })
}

/// The ripple single `res` (fitted by `nl`, its order searched in the data) refitted at
/// the best order of the estimation search when that search left it short of its z-score
/// and the validation record shows that order again at
/// [`crate::ident::nonlinear::ripple::REPLICATED_P`]: the order is then found, chosen on
/// one record and tested on another. A strong ripple spreads over the drops of the orders
/// it is tested against (the travel does not cover a whole number of its periods, and the
/// second harmonic leaks), and its z-score falls as it grows. Hard bench under
/// `JOINTS=1`, case 15 (order 72, 0.30 points): the search's best, 73, removed 64 % of the
/// cost at z-score 5.1, coherent along the record, and the ripple was held at nought.
/// `res` as it is otherwise, or when the refit fails.
fn ripple_at_best_order(est: &[IdData], val: &[IdData], nl: &NlRequest, res: NlResult) -> NlResult {
    use crate::ident::nonlinear::ripple::{MIN_COHERENCE, REPLICATED_P};
    let ([Effect::TorqueRipple(_)], Some(search)) = (&nl.effects[..], &res.ripple_search) else {
        return res;
    };
    if search.order.is_some() || search.range.is_none() || search.coherence < MIN_COHERENCE {
        return res;
    }
    let best = search.best;
    let Some(chance) = ripple_on_validation(&res.fit, est, val, best)
        .0
        .filter(|p| *p <= REPLICATED_P)
    else {
        return res;
    };
    let at_best = NlRequest {
        ripple_best_order: true,
        ..nl.clone()
    };
    let Ok(mut out) = identify_segments(est, &at_best) else {
        return res;
    };
    out.warnings.insert(
        0,
        format!(
            "the order search's best order {best} on the estimation record (z-score {:.1}, \
             short of {}; removing {:.0} % of the cost with the same ripple along the record) \
             is shown again on the validation record (chance {chance:.1e}): the ripple is \
             fitted at the search's best order",
            search.z,
            crate::ident::nonlinear::ripple::SIGNIFICANT_Z,
            100.0 * search.share
        ),
    );
    out
}

/// What the order search says of a fitted ripple: the order it found on the estimation
/// record and its robust z-score there, and the chance that the validation record, whose
/// excitation moves the motor along another trajectory, shows that order again without
/// a ripple ([`crate::ident::nonlinear::ripple::replication`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct RippleShown {
    /// the order found [periods per motor revolution]
    pub order: u32,
    /// its robust z-score on the estimation record [-]
    pub z: f64,
    /// the chance level on the validation record; `None` when its travel does not tell the
    /// order apart, or it repeats the estimation record's trajectory [-]
    pub chance_val: Option<f64>,
    /// the validation record moves the motor along the estimation record's trajectory
    /// ([`crate::ident::nonlinear::ripple::repeats_trajectory`]), so it cannot show the
    /// order again
    pub repeats: bool,
}

impl RippleShown {
    /// Whether the validation record shows the order again
    /// ([`crate::ident::nonlinear::ripple::REPLICATED_P`]). Hard bench under `JOINTS=1`,
    /// case 1 (a 0.47-point backlash): the search found order 31 on the estimation record at
    /// a z-score above 8 with the same ripple on each of its four periods (the gap's
    /// distortion repeats with the excitation, and so does the angle), the ripple gained
    /// +0.05 ± 0.02 points and, counted against the refits' spread, became the answer.
    pub fn replicated(&self) -> bool {
        self.chance_val
            .is_some_and(|p| p <= crate::ident::nonlinear::ripple::REPLICATED_P)
    }
}

/// The chance level of order `order` on the longest validation record, with the ripple
/// fit's structure, lag and offset and no ripple ([`RippleShown::chance_val`]), and whether
/// that record repeats the longest estimation record's trajectory (then no chance level).
fn ripple_on_validation(
    fit: &NlFit,
    est: &[IdData],
    val: &[IdData],
    order: u32,
) -> (Option<f64>, bool) {
    use crate::ident::nonlinear::ripple::{repeats_trajectory, replication, without_ripple};
    let (Some(data), Some(from)) = (longest(val), longest(est)) else {
        return (None, false);
    };
    if repeats_trajectory(from, data) {
        return (None, true);
    }
    let (model, values) = without_ripple(fit, data);
    (
        replication(data, &model, &values, order).ok().flatten(),
        false,
    )
}

/// `nl` started from the fit `base`: its structure's values, lag and offset, the effects at
/// the values `nl` carries (laid out for the record `longest`).
fn start_from(nl: &mut NlRequest, base: &NlFit, longest: &IdData) {
    nl.tau_c = base.model.tau_c;
    nl.linear = Some(base.plant.clone());
    nl.start = NlStart::Values(model_of(nl, longest).values(&base.plant, offset_of(base), 0.0));
}

/// The torque offset [N·m] the fit `f` ended at (nought when it has none).
fn offset_of(f: &NlFit) -> f64 {
    f.get("offset").unwrap_or(0.0)
}

/// The first of the longest records, the one a start's values are laid out for.
pub(super) fn longest(est: &[IdData]) -> Option<&IdData> {
    est.iter()
        .enumerate()
        .max_by_key(|(i, d)| (d.len(), usize::MAX - i))
        .map(|(_, d)| d)
}

/// Most further iterations of a fit that stopped at its iteration limit
/// ([`Fitter::continued`]).
const POLISH_ITER: usize = 140;

/// The backlash candidate `nl` fitted from the start grown from the linear two-mass (its
/// values and lag [s], [`grow::grow_backlash`]); `None` when the growth or the fit fails,
/// or the grown start's cost is not below `beat` (the usual fit's).
fn backlash_grown(
    est: &[IdData],
    req: &DiagnoseRequest,
    nl: &NlRequest,
    (plant, lag): &(Vec<f64>, f64),
    (longest, beat): (&IdData, Option<f64>),
) -> Option<NlResult> {
    // on the candidate's own cost ([`nl_options`])
    let g = grow::grow_backlash(est, req.structure, req.r, (plant, *lag), &nl.options).ok()?;
    if beat.is_some_and(|b| g.ssr >= b) {
        return None;
    }
    let mut n = nl.clone();
    n.effects = vec![g.backlash];
    n.tau_c = g.tau_c;
    n.linear = Some(g.plant.clone());
    n.start = NlStart::Values(model_of(&n, longest).values(&g.plant, g.offset, 0.0));
    identify_segments(est, &n).ok()
}
