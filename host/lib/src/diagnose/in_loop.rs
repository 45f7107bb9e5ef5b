//! The models scored in the loop of the robot's controller, for a joint whose simulation
//! from the measured torque cannot be scored.
//!
//! Why: the gap metric simulates each model open loop from the measured torque
//! ([`super::metric::simulate_fit`]). A strongly stiffening spring answers that input
//! chaotically, so even the true model scores below the linear nominal (bench cases 12,
//! 72, 92: 0.5, 21 and −91 %), while the real joint, damped by its loop, repeats from
//! period to period. The diagnosis sees it as odd distortion its answer does not remove
//! ([`super::locate::odd_explained`]). Then the controller's law is identified from the
//! estimation record ([`crate::ident::controller`]) and every fitted model is run in that
//! loop from the validation reference ([`super::metric::simulate_closed`]): the same
//! true models score 99.2–99.8 % there.

use super::fits::Fitted;
use super::locate;
use super::metric::{
    simulate_closed, velocity_band, ClosedScored, DrivenModel, Measured, MetricError,
};
use super::table::{odd_words, ranked};
use super::{Candidate, DiagnoseOptions};
use crate::data::{Dataset, IdData};
use crate::ident::controller::{identify, ControllerError, LinearController};
use crate::ident::frf::ClassLevel;
use crate::ident::linalg::pinv_sym;
use crate::ident::lm::{minimize, LeastSquares, LmOptions, Normal};
use crate::ident::nonlinear::output_error::on_bounds;
use crate::ident::nonlinear::{sim_plant, NlFit, NlParam, Owner, ParamDef, Scale};
use crate::ident::validate::{centred_sum_of_squares, fit_from_sums};
use nalgebra::{DMatrix, DVector};
use std::sync::atomic::{AtomicUsize, Ordering};

/// Smallest FIT of the identified law's `u` on the validation record for the loop to be
/// used [%]. The simulator's cascade, identified at its default `u` noise: 98.4–99.8 % on
/// bench cases 3, 12, 72 and 92.
pub const LAW_FIT_MIN: f64 = 95.0;

/// Below [`LAW_FIT_MIN`], the law is still used when what it misses of the validation
/// torque is white ([`crate::ident::controller::LawCheck::whiteness`]): the noise on a
/// small recorded torque, not a wrong law.
pub const LAW_WHITE_MIN: f64 = 0.8;

/// Why the models could not be scored in the controller's loop ([`score_in_loop`]).
#[derive(Debug, thiserror::Error)]
pub enum LoopError {
    /// no estimation segment to identify the law on
    #[error("no estimation segment")]
    NoSegment,
    /// the law could not be identified on the estimation segment `capture` (the last tried)
    #[error("{capture}: {source}")]
    Law {
        /// the estimation segment
        capture: String,
        /// why
        #[source]
        source: ControllerError,
    },
    /// the law could not be checked on the validation capture `capture`
    #[error("{capture}: {source}")]
    Check {
        /// the validation capture
        capture: String,
        /// why
        #[source]
        source: ControllerError,
    },
    /// the law misses the validation torque, and not by white noise
    #[error(
        "the controller's law identified on the estimation record reproduces the torque of \
         the validation record to {fit:.1} % only (at least {LAW_FIT_MIN} % needed), and what \
         it misses is no white noise (whiteness {whiteness:.2}, at least {LAW_WHITE_MIN} \
         needed): the controller is not linear, or not the same"
    )]
    LawMisses {
        /// FIT of the law's torque on the validation record [%]
        fit: f64,
        /// whiteness of what it misses [-]
        whiteness: f64,
    },
    /// the nominal does not simulate in the loop
    #[error("the nominal in the loop: {0}")]
    Nominal(#[source] MetricError),
}

/// The models scored in the loop.
#[derive(Clone, Debug)]
pub struct LoopScores {
    /// the law, identified on the estimation record
    pub law: LinearController,
    /// its FIT on the validation record [%]
    pub law_fit_val: f64,
    /// whiteness of what it misses there [-]
    pub law_whiteness: f64,
    /// the nominal in the loop
    pub nominal: ClosedScored,
    /// the nominal's residual at the non-excited odd lines in the loop
    pub odd_nominal: Option<ClassLevel>,
    /// each model in the loop, in the order given, with the share of the nominal's
    /// odd-line residual (in the loop) it removes; `None` where it did not simulate
    pub models: Vec<Option<(ClosedScored, Option<f64>)>>,
}

/// Identifies the controller's law on the first estimation segment holding a reference,
/// checks it on `val`, and scores `nominal` and each of `models` in its loop on `val`
/// (`measured` its measured side, `k` equal segments).
///
/// # Errors
/// [`LoopError`]: no reference, a law that does not reproduce `u` on the validation record
/// ([`LAW_FIT_MIN`]), or a nominal that does not simulate in the loop.
pub fn score_in_loop(
    est: &[Dataset],
    val: &Dataset,
    measured: &Measured,
    nominal: &DrivenModel,
    models: &[DrivenModel],
    (k, settle_periods): (usize, usize),
) -> Result<LoopScores, LoopError> {
    let mut last = LoopError::NoSegment;
    let mut law = None;
    for d in est {
        match identify(&d.data) {
            Ok(l) => {
                law = Some(l);
                break;
            }
            Err(source) => {
                last = LoopError::Law {
                    capture: d.name.clone(),
                    source,
                }
            }
        }
    }
    let law = law.ok_or(last)?;
    let check = law.check_on(&val.data).map_err(|source| LoopError::Check {
        capture: val.name.clone(),
        source,
    })?;
    let law_fit_val = check.fit;
    if !(law_fit_val >= LAW_FIT_MIN || check.whiteness >= LAW_WHITE_MIN) {
        return Err(LoopError::LawMisses {
            fit: law_fit_val,
            whiteness: check.whiteness,
        });
    }
    let nominal = measured
        .score_closed(nominal, &law, &val.data, k)
        .map_err(LoopError::Nominal)?;
    let odd_nominal = locate::odd_residual(val, &nominal.theta_m, settle_periods);
    let mut scores = LoopScores {
        law,
        law_fit_val,
        law_whiteness: check.whiteness,
        nominal,
        odd_nominal,
        models: Vec::new(),
    };
    scores.models = models
        .iter()
        .map(|m| scores.score(measured, m, val, (k, settle_periods)).ok())
        .collect();
    Ok(scores)
}

impl LoopScores {
    /// `model` scored in the loop on `val` (`measured` its measured side, `k` equal
    /// segments), with the share of the nominal's odd-line residual in the loop it removes.
    ///
    /// # Errors
    /// As [`Measured::score_closed`].
    pub fn score(
        &self,
        measured: &Measured,
        model: &DrivenModel,
        val: &Dataset,
        (k, settle_periods): (usize, usize),
    ) -> Result<(ClosedScored, Option<f64>), MetricError> {
        let s = measured.score_closed(model, &self.law, &val.data, k)?;
        let odd = self.odd_nominal.as_ref().and_then(|n| {
            let c = locate::odd_residual(val, &s.theta_m, settle_periods)?;
            locate::odd_explained(n, &c)
        });
        Ok((s, odd))
    }
}

/// The controller's law in words: its orders, and how it reproduces the validation torque.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct LawSummary {
    /// past torques of the law
    pub na: usize,
    /// lags of the reference and the angle
    pub nl: usize,
    /// FIT of its torque on the validation record [%]
    pub fit: f64,
    /// whiteness of what it misses there [-]
    pub whiteness: f64,
}

impl LawSummary {
    fn of(scores: &LoopScores) -> LawSummary {
        LawSummary {
            na: scores.law.a.len(),
            nl: scores.law.b.len().saturating_sub(1),
            fit: scores.law_fit_val,
            whiteness: scores.law_whiteness,
        }
    }
}

impl std::fmt::Display for LawSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "the controller's law identified on the estimation record (θ_ref, θ_m → u; orders \
             na = {}, nl = {}) reproduces the validation torque to {:.1} % (what it misses \
             has whiteness {:.2}: 1 for white noise)",
            self.na, self.nl, self.fit, self.whiteness
        )
    }
}

/// Why the controller's loop did not change the diagnosis's answer ([`LoopAnswer::rescore`]);
/// the message is a note for the user.
#[derive(Debug, thiserror::Error)]
pub(super) enum LoopNote {
    /// the models could not be scored in the loop
    #[error("the models could not be scored in the controller's loop: {0}")]
    Unscored(#[source] LoopError),
    /// no candidate gains significantly in the loop either
    #[error(
        "in the loop of the controller ({law}), no candidate gains significantly over the \
         nominal's {nominal:.1} % either"
    )]
    NoGain {
        /// the law
        law: LawSummary,
        /// the nominal's gap metric in the loop [%]
        nominal: f64,
    },
    /// the best in the loop leaves the odd distortion too
    #[error(
        "in the loop of the controller ({law}), {best} scores {best_fit:.1} % against the \
         nominal's {nominal:.1} % but removes {removed:.0} % of the odd-line residual only: \
         the loop does not settle the answer",
        removed = 100.0 * .removed.max(0.0)
    )]
    OddLeft {
        /// the law
        law: LawSummary,
        /// the best model in the loop
        best: String,
        /// its gap metric in the loop [%]
        best_fit: f64,
        /// the nominal's [%]
        nominal: f64,
        /// the share of the nominal's odd-line residual it removes [-]
        removed: f64,
    },
}

/// A segment judge: `(segments, base segments, the single's fit when a single is judged
/// against the nominal)` → `(mean gain, its SE, significant)`
/// ([`super::fits::Fitter::judge_model`]).
pub(super) type Judge<'j> = &'j dyn Fn(&[f64], &[f64], Option<&Fitted>) -> (f64, f64, bool);

/// The diagnosis's answer as [`LoopAnswer::rescore`] changes it.
pub(super) struct LoopAnswer<'a> {
    /// the singles, best first, with their fits
    pub singles: &'a mut Vec<(Candidate, Option<Fitted>)>,
    /// the pair kept, if any
    pub pair: &'a mut Option<Candidate>,
    /// its fit
    pub pair_fitted: &'a mut Option<Fitted>,
}

/// The answer in the loop.
#[derive(Clone, Debug)]
pub(super) struct InLoop {
    /// the models' scores in the loop
    pub scores: LoopScores,
    /// the answer's name
    pub best: String,
    /// its gap metric in the loop [%]
    pub best_fit: f64,
    /// its gap metric on the equal segments in the loop [%]
    pub best_segments: Vec<f64>,
    /// the share of the nominal's odd-line residual it removes in the loop
    pub best_odd: Option<f64>,
    /// band-passed velocity of the nominal and of the answer in the loop [rad/s]
    pub velocities: (Vec<f64>, Vec<f64>),
    /// what was done, in words
    pub words: String,
    /// the answer's in-sample gap metric in the loop and what the noise from period to period
    /// leaves there [%], when the first stops short of the second by more than the
    /// significance floor ([`super::loop_answer::short_of_noise`])
    pub short_of_noise: Option<(f64, f64)>,
}

/// One model's judgement in the loop: `(gain, SE, significant)`, its scores, its odd share.
type Judged<'s> = ((f64, f64, bool), &'s ClosedScored, Option<f64>);

impl LoopAnswer<'_> {
    /// Scores the nominal, every fitted single and the pair in the controller's loop on the
    /// one validation record `val` and, when a significant single (or a pair significantly
    /// above it) removes at least [`locate::ODD_EXPLAINED_DOUBT`] of the nominal's odd-line
    /// residual there, makes that the answer: the singles rescored and re-ranked in the loop,
    /// the pair kept only when it is the answer. `was`: the open-loop answer, the share it
    /// removed and the nominal's odd residual against the noise [dB].
    ///
    /// # Errors
    /// [`LoopNote`], why the loop did not change the answer (a note for the user).
    pub fn rescore(
        self,
        (est, val, measured): (&[Dataset], &Dataset, &Measured),
        nominal: &Fitted,
        (judge, o): (Judge<'_>, &DiagnoseOptions),
        (was, was_odd, db): (&str, Option<f64>, f64),
    ) -> Result<InLoop, LoopNote> {
        let mut models = Vec::new();
        let mut at = Vec::new();
        for (i, (_, f)) in self.singles.iter().enumerate() {
            if let Some(f) = f {
                models.push(DrivenModel::of_fit(&f.fit));
                at.push(Some(i));
            }
        }
        if let Some(pf) = self.pair_fitted.as_ref() {
            models.push(DrivenModel::of_fit(&pf.fit));
            at.push(None);
        }
        let scores = score_in_loop(
            est,
            val,
            measured,
            &DrivenModel::of_fit(&nominal.fit),
            &models,
            (o.segments, o.settle_periods),
        )
        .map_err(LoopNote::Unscored)?;
        let base = &scores.nominal.segments;
        let mut single: Vec<Option<Judged>> = vec![None; self.singles.len()];
        let mut pair_scores: Option<(&ClosedScored, Option<f64>)> = None;
        for (m, a) in scores.models.iter().zip(&at) {
            let Some((cs, odd)) = m else { continue };
            match a {
                Some(i) => {
                    let f = self.singles[*i].1.as_ref();
                    single[*i] = Some((judge(&cs.segments, base, f), cs, *odd));
                }
                None => pair_scores = Some((cs, *odd)),
            }
        }
        let law = LawSummary::of(&scores);
        let top = single
            .iter()
            .enumerate()
            .filter_map(|(i, s)| s.as_ref().filter(|s| s.0 .2).map(|s| (i, s.1.fit)))
            .max_by(|a, b| a.1.total_cmp(&b.1));
        let Some((ti, top_fit)) = top else {
            return Err(LoopNote::NoGain {
                law,
                nominal: scores.nominal.fit,
            });
        };
        let top_cs = single[ti].as_ref().map(|s| s.1).expect("the top single");
        let pair_judged =
            pair_scores.map(|(cs, odd)| (judge(&cs.segments, &top_cs.segments, None), cs, odd));
        let pair_wins = pair_judged
            .as_ref()
            .is_some_and(|(j, cs, _)| j.2 && cs.fit > top_fit);
        let (best, best_cs, best_odd) = match (&pair_judged, pair_wins) {
            (Some((_, cs, odd)), true) => (
                self.pair
                    .as_ref()
                    .map_or_else(String::new, |p| p.name.clone()),
                *cs,
                *odd,
            ),
            _ => {
                let s = single[ti].as_ref().expect("the top single");
                (self.singles[ti].0.name.clone(), s.1, s.2)
            }
        };
        let (best_fit, best_segments) = (best_cs.fit, best_cs.segments.clone());
        let best_theta = &best_cs.theta_m;
        if best_odd.is_some_and(|s| s < locate::ODD_EXPLAINED_DOUBT) {
            return Err(LoopNote::OddLeft {
                law,
                best,
                best_fit,
                nominal: scores.nominal.fit,
                removed: best_odd.unwrap_or(0.0),
            });
        }
        let velocities = (
            velocity_band(&scores.nominal.theta_m, val.data.ts, measured.band),
            velocity_band(best_theta, val.data.ts, measured.band),
        );
        // the singles rescored and re-ranked in the loop
        for ((c, f), s) in self.singles.iter_mut().zip(&single) {
            match s {
                Some(((score, se, significant), cs, odd)) => {
                    c.reason = format!(
                        "in the controller's loop: validation FIT {score:+.1} ± {se:.1} \
                         points{}{}; open loop from the measured torque: {}",
                        if *significant {
                            ""
                        } else {
                            " (not significant)"
                        },
                        odd_words(*odd),
                        c.reason
                    );
                    let counts = f.as_ref().map_or(*significant, |f| f.counts(*significant));
                    (c.score, c.score_se, c.significant) = (*score, *se, counts);
                    c.fit_val = cs.fit;
                    c.fit_angle_val = cs.angle_fit;
                    c.odd_explained = *odd;
                }
                None if f.is_some() => {
                    c.reason = format!(
                        "it did not simulate in the controller's loop; open loop: {}",
                        c.reason
                    );
                    (c.score, c.score_se, c.significant) = (f64::NAN, f64::NAN, false);
                }
                None => {}
            }
        }
        self.singles.sort_by(|a, b| ranked(&a.0, &b.0));
        match (pair_judged, pair_wins, self.pair.as_mut()) {
            (Some(((score, se, significant), cs, odd)), true, Some(p)) => {
                p.reason = format!(
                    "in the controller's loop: {score:+.1} ± {se:.1} points over the best single \
                     {}; open loop: {}",
                    odd_words(odd),
                    p.reason
                );
                let counts = self
                    .pair_fitted
                    .as_ref()
                    .map_or(significant, |f| f.counts(significant));
                (p.score, p.score_se, p.significant) = (score, se, counts);
                p.fit_val = cs.fit;
                p.fit_angle_val = cs.angle_fit;
                p.odd_explained = odd;
            }
            _ => {
                *self.pair = None;
                *self.pair_fitted = None;
            }
        }
        let was_words = match was_odd {
            _ if was == "none" => "no open-loop candidate removed it".to_string(),
            Some(share) => format!(
                "the open-loop answer {was} removed {:.0} % of it",
                100.0 * share.max(0.0)
            ),
            None => format!("the open-loop answer {was} did not remove it"),
        };
        let words = format!(
            "the nominal's residual at the non-excited odd lines stands {db:.1} dB above the \
             noise and {was_words}: a simulation from the measured torque cannot score this \
             joint (a strongly stiffening spring answers it chaotically, while the joint in its \
             loop repeats from period to period). Every model is scored in the controller's \
             loop instead: {law}; there the nominal reaches {:.1} % and {best} {best_fit:.1} \
             %{}. The answer, the ranking, the FITs and the closure are those of the loop; where \
             the gap lies (bands, regions) is read on the open-loop nominal's residual",
            scores.nominal.fit,
            odd_words(best_odd)
        );
        Ok(InLoop {
            scores,
            best,
            best_fit,
            best_segments,
            best_odd,
            velocities,
            words,
            short_of_noise: None,
        })
    }
}

/// Iterations of [`refine`].
const REFINE_ITER: usize = 12;

/// Most simulations one start of [`refine`] runs (its Jacobians and trial steps): a bound on
/// its work whatever the model, counted, never timed, so that a busy machine gets the same
/// answer as an idle one.
const REFINE_SIMULATIONS: usize = 200;

/// Most simulations all the starts of one [`refine`] run together: past it no further start
/// is tried. Seventeen whole starts, what a three-mass answer's starts take (about 160
/// simulations each); a four-mass answer's later starts are left out.
const REFINE_TOTAL_SIMULATIONS: usize = 17 * REFINE_SIMULATIONS;

/// Finite-difference step of [`refine`]'s Jacobian in the layout's optimiser coordinate.
const REFINE_STEP: f64 = 1e-4;

/// The output error in the loop of a fit's parameters: the gap metric's band-passed motor
/// velocity of the record simulated in the loop of `law`, against the measured one.
struct LoopProblem<'a> {
    fit: &'a NlFit,
    layout: Vec<ParamDef>,
    law: &'a LinearController,
    data: &'a IdData,
    measured: &'a Measured,
    threads: usize,
    /// simulations run so far by this start; a cost or a Jacobian that would take it past
    /// [`REFINE_SIMULATIONS`] is not evaluated, and the step is rejected. Taken whole before
    /// the Jacobian's columns go to threads, so which evaluations run never depends on how
    /// the threads are scheduled.
    runs: AtomicUsize,
}

impl<'a> LoopProblem<'a> {
    /// The problem of `fit`'s parameters in the loop of `law` on `data` (`measured` its
    /// measured side), its Jacobian's columns on `threads`, with the optimiser coordinates
    /// of `fit`'s own values.
    fn at(
        fit: &'a NlFit,
        law: &'a LinearController,
        (data, measured): (&'a IdData, &'a Measured),
        threads: usize,
    ) -> (LoopProblem<'a>, Vec<f64>) {
        let layout = fit.model.layout();
        let z = layout
            .iter()
            .zip(&fit.values)
            .map(|(d, v)| d.to_z(*v))
            .collect();
        let problem = LoopProblem {
            fit,
            layout,
            law,
            data,
            measured,
            threads,
            runs: AtomicUsize::new(0),
        };
        (problem, z)
    }

    /// The driven model at optimiser coordinates `z` (layout order).
    fn model_at(&self, z: &[f64]) -> DrivenModel {
        let p: Vec<f64> = self
            .layout
            .iter()
            .zip(z)
            .map(|(d, z)| d.from_z(*z))
            .collect();
        let (model, plant) = self.fit.model.with_values(&p);
        let offset = self
            .layout
            .iter()
            .position(|d| d.name == "offset")
            .map_or(0.0, |i| p[i]);
        DrivenModel {
            plant: sim_plant(&model, &plant),
            effects: model.effects,
            tau_c: model.tau_c,
            offset,
        }
    }

    /// Takes `n` simulations from the start's budget ([`REFINE_SIMULATIONS`]); false, taking
    /// none, when fewer are left. Called from the minimisation's own thread only.
    fn take(&self, n: usize) -> bool {
        let used = self.runs.load(Ordering::Relaxed);
        let ok = used + n <= REFINE_SIMULATIONS;
        if ok {
            self.runs.store(used + n, Ordering::Relaxed);
        }
        ok
    }

    /// Band-passed simulated velocity over the scored range at `z`; `None` when the model
    /// does not simulate.
    fn simulated(&self, z: &[f64]) -> Option<Vec<f64>> {
        let theta = simulate_closed(&self.model_at(z), self.law, self.data).ok()?;
        let v = velocity_band(&theta, self.data.ts, self.measured.band);
        let v = v[self.measured.skip..].to_vec();
        v.iter().all(|x| x.is_finite()).then_some(v)
    }

    fn measured(&self) -> &[f64] {
        &self.measured.velocity[self.measured.skip..]
    }
}

impl LeastSquares for LoopProblem<'_> {
    fn n_params(&self) -> usize {
        self.layout.len()
    }

    fn n_residuals(&self) -> usize {
        self.measured().len()
    }

    fn cost(&self, theta: &[f64]) -> f64 {
        if !self.take(1) {
            return f64::NAN;
        }
        match self.simulated(theta) {
            Some(v) => self
                .measured()
                .iter()
                .zip(&v)
                .map(|(y, s)| (y - s).powi(2))
                .sum(),
            None => f64::NAN,
        }
    }

    fn normal_equations(&self, theta: &[f64], free: &[usize]) -> Normal {
        let y = self.measured();
        let n = y.len();
        if !self.take(1 + free.len()) {
            return Normal {
                jtj: DMatrix::zeros(free.len(), free.len()),
                jte: DVector::zeros(free.len()),
                ssr: f64::NAN,
            };
        }
        let base = self.simulated(theta);
        let columns = crate::ident::parallel::parallel(free, self.threads, |&j| {
            let mut z = theta.to_vec();
            z[j] += REFINE_STEP;
            self.simulated(&z)
        });
        let Some(base) = base else {
            return Normal {
                jtj: DMatrix::zeros(free.len(), free.len()),
                jte: DVector::zeros(free.len()),
                ssr: f64::NAN,
            };
        };
        let mut jac = DMatrix::<f64>::zeros(n, free.len());
        // a column that did not simulate (or past the bounds) is unknown, not nought
        for (c, col) in columns.iter().enumerate() {
            for i in 0..n {
                jac[(i, c)] = col
                    .as_ref()
                    .map_or(f64::NAN, |v| (v[i] - base[i]) / REFINE_STEP);
            }
        }
        let e = DVector::from_iterator(n, y.iter().zip(&base).map(|(y, s)| y - s));
        Normal {
            jtj: jac.transpose() * &jac,
            jte: jac.transpose() * &e,
            ssr: e.norm_squared(),
        }
    }
}

/// `fit` refined in the loop of `law` on the estimation record `data` (`measured` its
/// measured side): Levenberg–Marquardt on the loop's output error (`LoopProblem`), every
/// parameter of the layout free within its bounds but the initial velocity and the torque
/// offset (the law's constant takes a constant torque, and what is left of it the metric's
/// band leaves out: free, it came out correlated ±1 with every other parameter), the Jacobian by
/// forward differences on `threads` threads. It starts from `fit`'s values and from each of
/// `spring_starts` (within [`REFINE_TOTAL_SIMULATIONS`]) and keeps the lowest cost; the
/// search ends early when a start reaches the in-sample gap metric `enough` [%] (the noise's
/// floor, [`super::metric::Measured::noise_fit`], less the significance floor): no other
/// start could then lower the cost by what the data tell apart. Returns the refined fit
/// (values, standard deviations from the loop's covariance), its in-sample gap metric
/// before and after [%], the spring its winning start moved and the starts run.
///
/// Why: the answer's fit was made open loop, on a cost the chaotic simulation makes rough
/// (bench case 72: `k3` −13 % and `k_g` +24 % against the truth, 93.5 % in the loop where
/// the true model scores 99.4 %).
///
/// # Errors
/// [`RefineError`]: the model does not simulate in the loop, or the minimisation fails.
pub fn refine(
    fit: &NlFit,
    law: &LinearController,
    (data, measured): (&IdData, &Measured),
    (enough, from): (Option<f64>, RefineStarts<'_>),
    threads: usize,
) -> Result<Refined, RefineError> {
    let (problem, z0) = LoopProblem::at(fit, law, (data, measured), threads);
    let layout = problem.layout.clone();
    let opts = LmOptions {
        max_iter: REFINE_ITER,
        rel_cost_tol: 1e-6,
        lower: layout.iter().map(|d| d.to_z(d.lower)).collect(),
        upper: layout.iter().map(|d| d.to_z(d.upper)).collect(),
        fixed: layout
            .iter()
            .zip(&fit.params)
            .map(|(d, p)| d.name == "v0" || d.name == "offset" || p.fixed)
            .collect(),
        covariance: false,
        ..LmOptions::default()
    };
    let ss_tot = centred_sum_of_squares(problem.measured());
    let fit_of = |ssr: f64| fit_from_sums(ssr, ss_tot);
    let before = problem.cost(&z0);
    if !before.is_finite() {
        return Err(RefineError::NotSimulating);
    }
    // the answer's own values first, then each spring moved ([`spring_starts`]); the lowest
    // cost in the loop wins
    let mut total = 0;
    let mut best: Option<(crate::ident::lm::LmFit, Option<Moved>)> = None;
    let all = match from {
        RefineStarts::Springs => spring_starts(&layout, &opts.fixed, &z0),
        RefineStarts::Lead(lead, partner) => lead_starts(&layout, &z0, (lead, partner)),
        RefineStarts::Own => vec![(z0.clone(), None)],
    };
    let mut starts = (0, all.len());
    for (z, moved) in all {
        total += problem.runs.swap(0, Ordering::Relaxed);
        if best.is_some() && total >= REFINE_TOTAL_SIMULATIONS {
            break;
        }
        let done =
            |(b, _): &(crate::ident::lm::LmFit, _)| enough.is_some_and(|e| fit_of(b.ssr) >= e);
        if best.as_ref().is_some_and(done) {
            break;
        }
        starts.0 += 1;
        let Ok(lm) = minimize(&problem, &z, &opts) else {
            continue;
        };
        if best.as_ref().is_none_or(|(b, _)| lm.ssr < b.ssr) {
            // the start's cost is the first of the minimisation's history
            let start = lm.cost_history.first().copied().unwrap_or(f64::NAN);
            let at = moved.map(|(name, f)| (name, f, fit_of(start)));
            best = Some((lm, at));
        }
    }
    let (lm, moved) = best.ok_or(RefineError::EveryStartFailed)?;
    // the covariance at the end, past the bound on the minimisation's simulations but not
    // past its time (then the deviations are unknown: NaN)
    problem.runs.store(0, Ordering::Relaxed);
    let free: Vec<usize> = (0..layout.len()).filter(|&i| !opts.fixed[i]).collect();
    let mut std_z = vec![0.0; layout.len()];
    let ne = problem.normal_equations(&lm.theta, &free);
    if ne.ssr.is_finite() && ne.jtj.iter().all(|v| v.is_finite()) {
        let sigma2 = ne.ssr / (problem.n_residuals() as f64 - free.len() as f64).max(1.0);
        let cov = pinv_sym(&ne.jtj, 1e-13) * sigma2;
        for (a, &i) in free.iter().enumerate() {
            std_z[i] = cov[(a, a)].max(0.0).sqrt();
        }
    } else {
        for &i in &free {
            std_z[i] = f64::NAN;
        }
    }
    let values: Vec<f64> = layout
        .iter()
        .zip(&lm.theta)
        .map(|(d, z)| d.from_z(*z))
        .collect();
    let (model, plant) = fit.model.with_values(&values);
    let mut out = fit.clone();
    for (i, ((p, d), (v, s))) in out
        .params
        .iter_mut()
        .zip(&layout)
        .zip(values.iter().zip(&std_z))
        .enumerate()
    {
        p.value = *v;
        // a held parameter keeps its value and its deviation from `fit`, and is marked held
        if opts.fixed[i] {
            p.fixed = true;
            continue;
        }
        // where the refinement ended, not where the open-loop fit had: a partner refined
        // onto its lower bound is of no size ([`super::size::vanished`]; bench `HARD=1
        // SMALL=1` case 2, a stiffening spring alone, in a trial with every fit band-limited:
        // the pair's backlash refined in the loop to 1e-9 rad, its bound, kept the
        // open-loop flags and a deviation of 1e-17 from a covariance that drops the
        // direction it does not move, and the pair was named)
        (p.at_lower, p.at_bound) = on_bounds(lm.theta[i], (opts.lower[i], opts.upper[i]));
        // dp/dz: p for a log coordinate, the scale for a linear one
        p.std = match d.scale {
            Scale::Log => v.abs() * s,
            Scale::Linear(k) => k.abs() * s,
        };
    }
    out.model = model;
    out.plant = plant;
    // how the refinement ended, not the open-loop fit
    (out.termination, out.iterations) = (lm.termination, lm.iterations);
    out.values = values;
    Ok(Refined {
        fit: out,
        before: fit_of(before),
        moved,
        after: fit_of(lm.ssr),
        starts,
    })
}

/// The gap metric in the loop of `law` of `fit` at its own values, in sample on the record
/// `data` (`measured` its measured side) [%]: what [`refine`] starts from. `None` when the
/// model does not simulate in the loop.
pub fn fit_in_loop(
    fit: &NlFit,
    law: &LinearController,
    (data, measured): (&IdData, &Measured),
) -> Option<f64> {
    let (problem, z) = LoopProblem::at(fit, law, (data, measured), 1);
    let ssr = problem.cost(&z);
    ssr.is_finite()
        .then(|| fit_from_sums(ssr, centred_sum_of_squares(problem.measured())))
}

/// Why [`refine`] could not refine the answer in the loop.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum RefineError {
    /// the answer's values do not simulate in the loop
    #[error("the answer does not simulate in the loop on the estimation record")]
    NotSimulating,
    /// the minimisation refused every start
    #[error("the minimisation failed from every start")]
    EveryStartFailed,
}

/// What [`refine`] returns.
#[derive(Clone, Debug)]
pub struct Refined {
    /// the refined fit: values, and standard deviations from the loop's covariance
    pub fit: NlFit,
    /// the gap metric in the loop on the estimation record at the fit's values [%]
    pub before: f64,
    /// the spring the winning start moved, if any
    pub moved: Option<Moved>,
    /// the gap metric after the refinement [%]
    pub after: f64,
    /// the starts run, of those there were (fewer when one reached the noise's floor or the
    /// simulations' bound)
    pub starts: (usize, usize),
}

/// A spring moved by a start of [`refine`]: its name, the factor and the gap metric in the
/// loop on the estimation record there [%].
pub type Moved = (&'static str, f64, f64);

/// A start of [`refine`] in optimiser coordinates, with the spring it moved and the factor.
type SpringStart = (Vec<f64>, Option<(&'static str, f64)>);

/// Factors by which [`spring_starts`] multiplies each spring (its damper by their square
/// root, which keeps the mode's damping ratio): the mode's frequency moves by their square
/// root, from a third to three times, in steps of 19 to 41 %.
const SPRING_FACTORS: [f64; 8] = [0.125, 0.25, 0.5, 0.707, 1.414, 2.0, 4.0, 8.0];

/// The starts of [`refine`]: `z0`, then `z0` with each free spring of the structure
/// multiplied by each of [`SPRING_FACTORS`], with the spring's name and factor.
///
/// Why: an output-error cost has a local minimum wherever a lightly damped mode sits on a
/// wrong frequency, and a gradient step cannot carry the mode past it; nor does the cost at
/// the start tell which start ends lowest, nor a few iterations from each (on case 61 the
/// winning start was behind after 3 and 6 iterations of 12), so unlike
/// [`crate::ident::nonlinear::grow`]'s race over an extra mode's frequency, each start runs
/// the whole refinement. Bench case 61 (a backlash in the gearbox): the
/// open-loop fits put the weak arm mode (5 % of the arm's inertia) at 61 Hz, `k_a` 82,000
/// N·m/rad against the true 9,051. Refined in the loop from there, 87.5 % on validation; from
/// `k_a` × 1/8, which starts higher in cost, 96.7 %, as from the true values.
fn spring_starts(layout: &[ParamDef], fixed: &[bool], z0: &[f64]) -> Vec<SpringStart> {
    let mut starts = vec![(z0.to_vec(), None)];
    for (i, d) in layout.iter().enumerate() {
        if d.owner != Owner::Plant || !d.name.starts_with("k_") || fixed[i] {
            continue;
        }
        // the spring's damper: `d_g` for `k_g`
        let damper = layout.iter().position(|e| {
            e.owner == Owner::Plant && e.name.starts_with('d') && e.name[1..] == d.name[1..]
        });
        for f in SPRING_FACTORS {
            let mut z = z0.to_vec();
            let mut inside = true;
            let mut scale = |at: usize, by: f64| {
                let p = layout[at].from_z(z0[at]) * by;
                inside &= p >= layout[at].lower && p <= layout[at].upper;
                z[at] = layout[at].to_z(p);
            };
            scale(i, f);
            if let Some(j) = damper.filter(|&j| !fixed[j]) {
                scale(j, f.sqrt());
            }
            if inside {
                starts.push((z, Some((d.name, f))));
            }
        }
    }
    starts
}

/// Where the starts of [`refine`] come from.
#[derive(Clone, Copy, Debug)]
pub enum RefineStarts<'a> {
    /// the fit's own values and each spring moved ([`spring_starts`]): a fit made open
    /// loop, whose modes may sit on wrong frequencies
    Springs,
    /// the fit's own values and the fit with the structure's values of this lead, already
    /// refined in the loop from [`RefineStarts::Springs`] ([`lead_starts`]), and the
    /// partner's single as the loop left it: a pair whose lead's modes and whose effects'
    /// sizes the loop has placed
    Lead(&'a NlFit, &'a NlFit),
    /// the fit's own values alone: a model placed by a refinement in the loop already (a
    /// pair's lead at the refined pair's values, [`super::loop_answer`])
    Own,
}

/// The starts of [`refine`] for a pair whose lead `lead` was refined in the loop: `z0`;
/// `z0` with the structure's values (the inertias, springs, dampers and the lag) of the
/// lead; and that with each effect at its own single's value in the loop (the lead's effect
/// at `lead`'s, the partner's at `partner`'s), a delay with the lag of its own single.
///
/// Why the lead's structure: the spring search of [`spring_starts`] ran on the lead, whose
/// structure the pair shares; the pair's open-loop fit from the lead may have moved a mode
/// again, and the lead's values bring it back (bench, `HARD=1 SMALL=1` case 36: seventeen
/// starts for each of two pairs in the loop took 11 s of its 37 s). Why the singles' sizes,
/// and a delay's own lag: a single without a delay takes the delay's phase into its lag,
/// and the delay added to that lag puts twice the phase into the loop (bench, `HARD=1
/// LAWS=1` case 26, a stiffening spring with a delay of two whole samples: the pair from the
/// lead's values scored −2017 % in the loop, and its refinement from the first two starts
/// −1758 %; the delay's single held 2.29 samples beside its own lag and scored 80.8 %; the
/// pair from the third start refined to 98.1 %, the true model's 98.2 %).
fn lead_starts(
    layout: &[ParamDef],
    z0: &[f64],
    (lead, partner): (&NlFit, &NlFit),
) -> Vec<SpringStart> {
    // `z` with the values of `from`'s parameters of owner `of` put into those of owner `to`
    let take = |z: &mut Vec<f64>, from: &NlFit, of: Owner, to: Owner| {
        let from_layout = from.model.layout();
        for (i, d) in layout.iter().enumerate() {
            if d.owner != to {
                continue;
            }
            if let Some(j) = from_layout
                .iter()
                .position(|e| e.owner == of && e.name == d.name)
            {
                z[i] = d.to_z(from.values[j]);
            }
        }
    };
    let mut structure = z0.to_vec();
    for owner in [Owner::Plant, Owner::CurrentLoop] {
        take(&mut structure, lead, owner, owner);
    }
    let mut sizes = structure.clone();
    take(&mut sizes, lead, Owner::Effect(0), Owner::Effect(0));
    take(&mut sizes, partner, Owner::Effect(0), Owner::Effect(1));
    // the lag that goes with the delay: a single without one may have taken the delay's
    // phase into its lag
    if matches!(
        partner.model.effects[..],
        [crate::model::effects::Effect::TimeDelay(_)]
    ) {
        take(&mut sizes, partner, Owner::CurrentLoop, Owner::CurrentLoop);
    }
    let mut starts: Vec<SpringStart> = vec![(z0.to_vec(), None)];
    for z in [structure, sizes] {
        if !starts.iter().any(|s| s.0 == z) {
            starts.push((z, None));
        }
    }
    starts
}

/// `fit` without its effect at `index`, every other value, deviation and hold kept: a
/// pair's lead as the pair's fit has it, to judge whether the partner is needed.
pub fn without_effect(fit: &NlFit, index: usize) -> NlFit {
    let mut model = fit.model.clone();
    model.effects.remove(index);
    let values = model.values(
        &fit.plant,
        fit.get("offset").unwrap_or(0.0),
        fit.get("v0").unwrap_or(0.0),
    );
    let params = model
        .layout()
        .iter()
        .zip(&values)
        .map(|(d, v)| {
            // the effects after `index` move down by one
            let was = match d.owner {
                Owner::Effect(e) if e >= index => Owner::Effect(e + 1),
                o => o,
            };
            let old = fit
                .params
                .iter()
                .find(|p| p.name == d.name && p.owner == was);
            NlParam {
                name: d.name,
                owner: d.owner,
                value: *v,
                std: old.map_or(f64::NAN, |p| p.std),
                unit: d.unit,
                fixed: old.is_some_and(|p| p.fixed),
                at_bound: old.is_some_and(|p| p.at_bound),
                at_lower: old.is_some_and(|p| p.at_lower),
            }
        })
        .collect::<Vec<NlParam>>();
    let has = |n: &str| params.iter().any(|p| p.name == n);
    let correlated = fit
        .correlated
        .iter()
        .filter(|c| has(c.a) && has(c.b))
        .cloned()
        .collect();
    NlFit {
        model,
        params,
        values,
        correlated,
        ..fit.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn why_the_loop_did_not_settle_the_answer_names_the_law() {
        let law = LawSummary {
            na: 1,
            nl: 2,
            fit: 98.44,
            whiteness: 0.9,
        };
        let note = LoopNote::NoGain {
            law,
            nominal: 63.94,
        };
        assert_eq!(
            note.to_string(),
            "in the loop of the controller (the controller's law identified on the estimation \
             record (θ_ref, θ_m → u; orders na = 1, nl = 2) reproduces the validation torque to \
             98.4 % (what it misses has whiteness 0.90: 1 for white noise)), no candidate gains \
             significantly over the nominal's 63.9 % either"
        );
        let note = LoopNote::Unscored(LoopError::LawMisses {
            fit: 80.0,
            whiteness: 0.1,
        });
        assert!(
            note.to_string().starts_with(
                "the models could not be scored in the controller's loop: the controller's law \
                 identified on the estimation record reproduces the torque of the validation \
                 record to 80.0 % only"
            ),
            "{note}"
        );
    }
    use crate::ident::nonlinear::NlModel;
    use crate::model::spec::Structure;

    /// A fit of `effects` on the default three-mass at physical `values` (layout order):
    /// all [`lead_starts`] reads of a fit.
    fn fit_at(effects: Vec<crate::model::effects::Effect>, values: &[f64]) -> NlFit {
        let model = NlModel {
            structure: Structure::ThreeMass,
            r: 1.0 / 118.0,
            effects,
            tau_c: 5e-4,
            v_eps: 0.05,
            dz_eps: 1e-6,
            substeps: 1,
        };
        assert_eq!(model.layout().len(), values.len());
        NlFit {
            model,
            plant: values[..8].to_vec(),
            params: Vec::new(),
            values: values.to_vec(),
            ssr: 1.0,
            lowpass_hz: 0.0,
            n_residuals: 100,
            iterations: 1,
            termination: crate::ident::lm::Termination::CostConverged,
            fit_velocity_percent: 90.0,
            correlated: Vec::new(),
        }
    }

    /// A pair in the loop starts from its own values, from them with the lead's structure
    /// and lag, and from those with each effect at its single's size; a delay partner brings
    /// the lag of its own single, which a single without the delay took the delay's phase
    /// into. Another partner leaves the lead's lag.
    #[test]
    fn a_pair_in_the_loop_starts_from_its_singles_sizes_and_a_delay_from_its_own_lag() {
        use crate::model::effects::{Backlash, Effect, NonlinearStiffness, TimeDelay};
        let stiff = Effect::NonlinearStiffness(NonlinearStiffness::default());
        let delay = Effect::TimeDelay(TimeDelay::default());
        // J_m, J_a1, J_a2, k_g, k_a, d_g, d_a, f_m, tau_c, offset, [effects], v0
        let mech = |k_g: f64| [1e-3, 12.0, 0.6, k_g, 9e3, 65.0, 4.0, 2e-3];
        let with = |k_g: f64, tau_c: f64, sizes: &[f64]| {
            let mut v = mech(k_g).to_vec();
            v.extend([tau_c, 1e-3]);
            v.extend(sizes);
            v.push(0.0);
            v
        };
        let lead = fit_at(vec![stiff], &with(2e5, 2.5e-3, &[3e13]));
        let partner = fit_at(vec![delay], &with(1.4e5, 3e-4, &[2.29]));
        let pair = fit_at(vec![stiff, delay], &with(1e5, 1e-3, &[1e13, 4.7]));
        let layout = pair.model.layout();
        let z = |v: &[f64]| -> Vec<f64> { layout.iter().zip(v).map(|(d, x)| d.to_z(*x)).collect() };
        let z0 = z(&pair.values);
        let starts = lead_starts(&layout, &z0, (&lead, &partner));
        let expect = [
            pair.values.clone(),
            with(2e5, 2.5e-3, &[1e13, 4.7]),
            with(2e5, 3e-4, &[3e13, 2.29]),
        ];
        assert_eq!(starts.len(), expect.len());
        for ((got, moved), want) in starts.iter().zip(&expect) {
            assert!(moved.is_none());
            let want = z(want);
            assert!(
                got.iter().zip(&want).all(|(a, b)| (a - b).abs() < 1e-12),
                "{got:?} against {want:?}"
            );
        }
        // a backlash partner: the third start keeps the lead's lag
        let gap = Effect::Backlash(Backlash::default());
        let partner = fit_at(vec![gap], &with(1.4e5, 3e-4, &[3e-5]));
        let pair = fit_at(vec![stiff, gap], &with(1e5, 1e-3, &[1e13, 1e-5]));
        let layout = pair.model.layout();
        let z = |v: &[f64]| -> Vec<f64> { layout.iter().zip(v).map(|(d, x)| d.to_z(*x)).collect() };
        let starts = lead_starts(&layout, &z(&pair.values), (&lead, &partner));
        let third = z(&with(2e5, 2.5e-3, &[3e13, 3e-5]));
        assert!(starts[2]
            .0
            .iter()
            .zip(&third)
            .all(|(a, b)| (a - b).abs() < 1e-12));
    }

    /// The starts of the loop's refinement: the values given first, then each free spring
    /// by each factor with its damper by the factor's square root, everything else as given;
    /// a held spring is not moved.
    #[test]
    fn each_free_spring_is_moved_with_its_damper_and_a_held_one_is_not() {
        let model = NlModel {
            structure: Structure::ThreeMass,
            r: 1.0 / 118.0,
            effects: Vec::new(),
            tau_c: 5e-4,
            v_eps: 0.05,
            dz_eps: 1e-6,
            substeps: 1,
        };
        let layout = model.layout();
        // J_m, J_a1, J_a2, k_g, k_a, d_g, d_a, f_m, then tau_c, offset, v0
        let values = [1e-3, 12.0, 0.6, 1e5, 9e3, 65.0, 4.0, 2e-3, 5e-4, 0.0, 0.0];
        let z0: Vec<f64> = layout
            .iter()
            .zip(&values)
            .map(|(d, v)| d.to_z(*v))
            .collect();
        let at = |name: &str| layout.iter().position(|d| d.name == name).unwrap();
        let mut fixed = vec![false; layout.len()];
        fixed[at("k_a")] = true;
        let starts = spring_starts(&layout, &fixed, &z0);
        assert_eq!(starts[0], (z0.clone(), None));
        assert_eq!(starts.len(), 1 + SPRING_FACTORS.len());
        for ((z, moved), f) in starts[1..].iter().zip(SPRING_FACTORS) {
            assert_eq!(*moved, Some(("k_g", f)));
            for (i, d) in layout.iter().enumerate() {
                let want = match d.name {
                    "k_g" => values[i] * f,
                    "d_g" => values[i] * f.sqrt(),
                    _ => values[i],
                };
                let got = d.from_z(z[i]);
                assert!(
                    (got - want).abs() <= 1e-12 * want.abs(),
                    "{}: {got} against {want}",
                    d.name
                );
            }
        }
    }
}
