//! Sim-to-real gap diagnosis (../shared/DESIGN.md §7): which unmodelled effect makes the simulated
//! joint depart from the measured one, how much of the gap it closes, and where the gap
//! lies.
//!
//! [`diagnose`] takes one or two estimation captures and a validation capture:
//!
//! 1. **Nominal**: the linear physical model of the structure fitted on the (first)
//!    estimation capture by the nonlinear engine with no effect
//!    ([`crate::ident::nonlinear::identify`]), started from the frequency-domain linear
//!    fit ([`crate::ident::nonlinear::linear_start`]) when the capture is periodic. When
//!    that fit fails, the nominal is started automatically in the time domain, then from
//!    the structure of each candidate's fit (the best in-sample first), and a warning says
//!    so; the diagnosis stops only when no start fits. When the fit ends far below its
//!    frequency-domain start on the estimation data's gap metric (its output-error cost
//!    followed a slow disturbance), the start is the nominal (`nominal_at_start`).
//! 2. **Gap metric** ([`metric::METRIC_NAME`]): the toolbox FIT of the band-passed motor
//!    velocity (1–150 Hz) on the validation capture, the model simulated with the
//!    simulator's exact laws from the measured torque plus a slow torque input estimated
//!    below [`DiagnoseOptions::tracking_hz`] (2 Hz; [`metric::simulate_tracked`]), the
//!    disturbance the position loop rejected; the toolbox FIT of `θ_m` of the plain
//!    open-loop simulation is reported beside it for reference.
//! 3. **Candidates**: the nominal plus each candidate effect, linear parameters refitted
//!    jointly, on [`DiagnoseOptions::threads`] threads; the backlash also from the start
//!    grown from the linear two-mass ([`grow::grow_backlash`]: a gap as wide as the
//!    gearbox's deflection bends the linear structure away from the joint's), the fit of
//!    lower cost kept. Each is scored on the validation
//!    capture. **Significance test**: the scored range is split into K =
//!    [`DiagnoseOptions::segments`] (4) equal segments; the gain of the metric over the
//!    nominal is computed on each; the score is the mean gain; the candidate is
//!    *significant* only when `mean − 2·SE > ` [`DiagnoseOptions::min_gain`] (0.3 FIT
//!    point), SE the standard error of the mean over the segments. When none is
//!    significant the answer is `none`.
//! 4. **Pair**: when the best single effect is significant, it is refitted with each other
//!    significant candidate, started from the two singles' fitted values (the structure
//!    of the best single's fit, or of the partner's when that is an extra mode), and with
//!    each candidate whose single scored significantly *below* the nominal it contains
//!    (`mean + 2·SE < −min_gain`: a fit in a wrong basin, which says nothing of its
//!    effect), started from its candidate's size on the best single's fit; such a
//!    candidate is the partner of every other significant single too (its lead may be an
//!    effect that stood in for the pair), and such a pair, like one led by the second
//!    single, must beat the best single's validation FIT. Where the motor
//!    sticks, a pair of the friction and an extra mode takes the mode from the grid and
//!    the race of the growth ([`grow::fit_with_mode_raced`]) on the friction's fit. A pair is
//!    reported when it gains significantly over the single by the same test. When the
//!    second single ties with the best (within twice the standard error of their
//!    difference), the pairs it leads are tried too, and the pair with the highest
//!    validation FIT above the best single's is reported. The pair's effects are then each
//!    refitted alone from the pair's values (an extra mode in parallel on the first arm mass
//!    also as the three-mass's own arm branch, the same mechanism): when the pair does not
//!    gain significantly over one of them, that single is the answer.
//!
//! Every scored model is also simulated from a start angle 1 nrad away
//! ([`metric::Measured::start_sensitivity`]): a model whose open-loop response is chaotic
//! (a strongly stiffening spring at a large amplitude) is flagged, since no simulation
//! metric can score it.
//! 5. **Where** ([`locate`]): the nominal's validation residual by operating region and
//!    frequency band; the odd/even non-excited line levels of periodic captures
//!    ([`crate::ident::frf`]); with two estimation captures, how distortion and gap change
//!    with amplitude ([`crate::ident::frf::amplitude_trend`]). On a periodic validation
//!    capture, the share of the nominal's residual at the non-excited odd lines each model
//!    removes ([`locate::odd_explained`]): an answer that removes little of odd distortion
//!    standing well above the noise does not explain it, and a warning says so.
//! 6. **In the loop** ([`in_loop`]): such an answer, or `none` with that distortion left,
//!    has every fitted model scored again in the loop of the robot's controller, its law
//!    identified from the estimation record ([`crate::ident::controller`]); when the loop's
//!    answer removes the distortion it replaces the open-loop one, paired with another
//!    single significant in the loop when that gains significantly, and every FIT of the
//!    diagnosis is the loop's ([`metric::CLOSED_LOOP_METRIC_NAME`]).
//!
//! The second estimation capture serves the amplitude analysis only; the fits use the
//! first.
//!
//! A capture with gaps is given as its gap-free segments ([`diagnose_segments`]): the fits
//! take the first estimation capture's segments as separate experiments, the gap metric
//! simulates every validation segment from its own start and pools one sum of squares
//! over them ([`metric::score_segments`]).
//!
//! [`DiagnoseRequest::progress`] is told of each stage and candidate as it starts and ends
//! ([`progress`]); the command line draws it as progress lines on a terminal.

pub mod in_loop;
pub mod locate;
pub mod metric;
pub mod progress;
pub mod series;

#[cfg(test)]
mod tests;

use std::collections::BTreeMap;
use std::time::Instant;

use serde::Serialize;
use thiserror::Error;

use crate::data::{Dataset, IdData};
use crate::ident::frf::analyze_segments;
use crate::ident::frf::{
    amplitude_trend, analyze_dataset, AmplitudeTrend, FrfAnalysis, Linearity, TrendKind,
};
use crate::ident::grey_box::DEFAULT_GEAR_RATIO;
use crate::ident::lm::Termination;
use crate::ident::nonlinear::{grow, ripple};
use crate::ident::nonlinear::{
    identify_segments, linear_start_segments, model_of, NlError, NlFit, NlOptions, NlRequest,
    NlResult, NlRunError, NlStart, Owner,
};
use crate::ident::parallel::parallel;
use crate::model::effects::{Attach, Effect, ExtraMode};
use crate::model::params::{model_params, Plant};
use crate::model::spec::Structure;
use locate::{Band, Regions};
use metric::{
    score_segments, segment_gain, start_sensitivity_segments, DrivenModel, Measured, MetricError,
    Scored,
};
pub use progress::{Progress, ProgressEvent};
use series::DiagnosisSeries;

/// The user's simulation, for the parameter-against-structure split of the gap.
#[derive(Clone, Debug, PartialEq)]
pub struct UserSim {
    /// where it came from (a file name)
    pub name: String,
    /// the simulator's plant
    pub plant: Plant,
    /// its effects
    pub effects: Vec<Effect>,
    /// its current-loop lag [s]
    pub tau_c: f64,
}

/// Options of [`diagnose`].
#[derive(Clone, Debug, PartialEq)]
pub struct DiagnoseOptions {
    /// band of the gap metric [Hz]
    pub band_hz: (f64, f64),
    /// corner of the slow torque input each scored simulation estimates [Hz]
    /// ([`metric::simulate_tracked`]; 0: a plain open-loop simulation)
    pub tracking_hz: f64,
    /// segments K of the significance test
    pub segments: usize,
    /// smallest gain counted [FIT points]: significant when `mean − 2·SE` exceeds it
    pub min_gain: f64,
    /// threads fitting candidates
    pub threads: usize,
    /// try pairs of effects
    pub pairs: bool,
    /// scored range starts this long into the validation record [s]
    pub skip_s: f64,
    /// periods dropped before the FRF analyses
    pub settle_periods: usize,
    /// options of every nonlinear fit
    pub nl: NlOptions,
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        DiagnoseOptions {
            band_hz: metric::DEFAULT_BAND_HZ,
            tracking_hz: metric::DEFAULT_TRACKING_HZ,
            segments: 4,
            min_gain: 0.3,
            threads: 2,
            pairs: true,
            skip_s: 0.5,
            settle_periods: 1,
            nl: NlOptions::default(),
        }
    }
}

impl DiagnoseOptions {
    /// Samples of `data` before its scored range: [`DiagnoseOptions::skip_s`], at most a
    /// quarter of the record.
    pub fn skip_of(&self, data: &IdData) -> usize {
        ((self.skip_s / data.ts).round() as usize).min(data.len() / 4)
    }
}

/// What to diagnose.
#[derive(Clone, Debug, PartialEq)]
pub struct DiagnoseRequest {
    /// mechanical structure of the nominal model
    pub structure: Structure,
    /// gear ratio `r` [-]
    pub r: f64,
    /// candidate effects (their values are ignored: each fit starts automatically, at the
    /// values of [`DiagnoseRequest::given`] where it names them)
    pub candidates: Vec<Effect>,
    /// start values the user gives, by candidate name: the keys of the effect's spec
    /// ([`crate::model::effects::parse_given`]) that the single candidate's fit starts at,
    /// or takes as given (a ripple's `order`), as `fit --effect name:key=value` does
    /// ([`crate::ident::nonlinear::NlRequest::given`]); a pair starts from its singles'
    /// fits
    pub given: BTreeMap<String, Vec<(String, f64)>>,
    /// the user's simulation, when given
    pub user: Option<UserSim>,
    /// options
    pub options: DiagnoseOptions,
    /// who is told of each stage and candidate as it starts and ends (a terminal's progress
    /// lines); it never changes the answer
    pub progress: Option<Progress>,
}

impl Default for DiagnoseRequest {
    /// Three-mass, the default gear ratio, every candidate ([`all_candidates`]), no user
    /// simulation.
    fn default() -> Self {
        DiagnoseRequest {
            structure: Structure::ThreeMass,
            r: DEFAULT_GEAR_RATIO,
            candidates: all_candidates(),
            given: BTreeMap::new(),
            user: None,
            options: DiagnoseOptions::default(),
            progress: None,
        }
    }
}

/// Why a diagnosis could not run.
#[derive(Debug, Error)]
pub enum DiagnoseError {
    /// no estimation capture, or more than two (their number)
    #[error("{0} estimation captures: one or two are needed")]
    EstimationCount(usize),
    /// an estimation capture given as no segment
    #[error("an estimation capture with no segment")]
    NoEstimationSegment,
    /// the validation capture given as no segment
    #[error("a validation capture with no segment")]
    NoValidationSegment,
    /// no candidate effect applies to the structure
    #[error("no candidate effect")]
    NoCandidate,
    /// the gear ratio is not a finite positive number
    #[error("gear ratio {0}: must be finite and > 0")]
    GearRatio(f64),
    /// a capture cannot go to the estimators (too short, not finite)
    #[error("{capture}: {source}")]
    Record {
        /// the capture
        capture: String,
        /// what is wrong with its record
        #[source]
        source: crate::data::RecordError,
    },
    /// a capture sampled at another rate than the validation capture
    #[error("{capture}: sampled every {ts} s, the validation capture every {val_ts} s")]
    RateMismatch {
        /// the capture
        capture: String,
        /// its sample interval [s]
        ts: f64,
        /// the validation capture's [s]
        val_ts: f64,
    },
    /// the validation capture holds the very samples of an estimation capture
    #[error(
        "the validation capture {validation} holds the very samples of the estimation capture \
         {estimation}: validate on another run of the joint (another excitation or noise \
         realisation), or the gains of the candidates say nothing"
    )]
    SameSamples {
        /// the validation capture (segment)
        validation: String,
        /// the estimation capture (segment) it repeats
        estimation: String,
    },
    /// the nominal model could not be fitted or simulated from any start
    #[error("the nominal model: {capture}: {source}")]
    Nominal {
        /// the estimation capture
        capture: String,
        /// every start tried and why it failed
        #[source]
        source: NominalError,
    },
}

/// Why one candidate model (the nominal plus effects) could not be fitted or scored.
#[derive(Debug, Error)]
pub enum CandidateError {
    /// no estimation record
    #[error("no estimation record")]
    NoRecord,
    /// the fit (or the start grown for it) failed
    #[error(transparent)]
    Fit(#[from] NlRunError),
    /// its own start did not simulate, and the automatic start failed too (why)
    #[error("{unstable}; from the automatic start: {0}", unstable = NlError::Unstable)]
    AutomaticToo(#[source] NlRunError),
    /// the fitted model could not be scored
    #[error(transparent)]
    Score(#[from] MetricError),
}

/// A start the nominal was fitted from ([`NominalError`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum NominalStart {
    /// the linear fit in the frequency domain, the usual start
    FrequencyDomain,
    /// the automatic start in the time domain
    TimeDomain,
    /// the structure of the fit of the candidate named
    Candidate(String),
}

impl std::fmt::Display for NominalStart {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NominalStart::FrequencyDomain => f.write_str("from the frequency-domain start"),
            NominalStart::TimeDomain => f.write_str("automatically in the time domain"),
            NominalStart::Candidate(name) => write!(f, "from the {name} candidate's structure"),
        }
    }
}

/// Why no start of the nominal fits: each start tried, in order, and why it failed.
#[derive(Debug, Error)]
#[error("no start of the nominal fits ({})", attempts_text(.attempts))]
pub struct NominalError {
    /// the starts tried and their failures
    pub attempts: Vec<(NominalStart, CandidateError)>,
}

/// `start: why; start: why`.
fn attempts_text(attempts: &[(NominalStart, CandidateError)]) -> String {
    attempts
        .iter()
        .map(|(start, e)| format!("{start}: {e}"))
        .collect::<Vec<_>>()
        .join("; ")
}

/// One estimated parameter.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ParamValue {
    /// estimate [unit]
    pub value: f64,
    /// standard deviation [unit]
    pub std: f64,
    /// unit
    pub unit: String,
}

/// One candidate (an effect, or a pair `a+b`) scored on the validation capture.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Candidate {
    /// effect name, or `a+b` for a pair
    pub name: String,
    /// the fitted effects as `simulate --effect` specs
    pub specs: Vec<String>,
    /// mean over the segments of the gain of the gap metric over the nominal (over the
    /// single best for a pair) [FIT points]
    pub score: f64,
    /// standard error of that mean [FIT points]
    pub score_se: f64,
    /// gap metric on the whole validation range [%] (JSON `fit_val`, the diagnosis's
    /// name, and `fit_validation`, the name every command gives a FIT on validation data)
    pub fit_val: f64,
    /// toolbox FIT of `θ_m` on the validation capture [%]
    #[serde(rename = "fit_angle_validation")]
    pub fit_angle_val: f64,
    /// passes the significance test (module documentation)
    pub significant: bool,
    /// the effects' fitted parameters, `effect.key` for pairs
    pub parameters: BTreeMap<String, ParamValue>,
    /// share of the nominal's residual at the non-excited odd lines of the validation
    /// capture that this model's no longer holds [-] ([`locate::odd_explained`]); `None`
    /// when the capture is not periodic or the nominal's stands near the noise
    #[serde(rename = "odd_residual_explained")]
    pub odd_explained: Option<f64>,
    /// the structure's values, lag and offset refitted with the effect
    pub structure_parameters: BTreeMap<String, ParamValue>,
    /// the evidence in words
    pub reason: String,
    /// what makes the fit doubtful (engine warnings) or why it failed
    pub warnings: Vec<String>,
}

/// Distortion of `θ_m` at the non-excited lines of one periodic capture.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Distortion {
    /// capture name
    pub capture: String,
    /// the linearity check of `θ_m` ([`crate::ident::frf`])
    pub linearity: Linearity,
}

/// One estimation capture in the amplitude analysis.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AmplitudeLevel {
    /// capture name
    pub capture: String,
    /// RMS of the measured torque [N·m]
    pub u_rms: f64,
    /// gap `100 − ` the nominal's gap metric on this capture [FIT points] (in-sample on the
    /// first capture)
    pub gap: f64,
}

/// How distortion and gap change between the two estimation captures.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Amplitude {
    /// the captures, lower amplitude first
    pub levels: Vec<AmplitudeLevel>,
    /// the distortion trend of `θ_m` (both captures periodic)
    pub distortion: Option<AmplitudeTrend>,
    /// `grows`, `falls` or `unclear` (changes by less than 1 point)
    pub gap_trend: String,
}

impl Amplitude {
    /// The amplitude trend in one sentence, the gap's and the distortion's together. The two
    /// measure different things and may part: the gap is all the nominal misses of the
    /// band-passed velocity, fitted on the first estimation capture (in-sample there, out of
    /// sample on the second, so it also holds how the joint's best linear model moves with
    /// amplitude); the distortion is only what the nonlinearity puts on the lines the
    /// multisine leaves empty, relative to the excited ones, whose trend tells the kind of
    /// effect (seed 000 §3). When they part, the sentence says both with a `but` and why.
    pub fn summary(&self) -> String {
        let gap = match self.gap_trend.as_str() {
            "grows" => "the nominal's gap grows with amplitude",
            "falls" => "the nominal's gap falls as amplitude grows",
            _ => "the nominal's gap changes by less than 1 point with amplitude",
        };
        let Some(d) = &self.distortion else {
            return format!("{gap} (the distortion trend needs two periodic captures)");
        };
        let parted = matches!(
            (self.gap_trend.as_str(), d.kind),
            ("grows", TrendKind::FallsWithAmplitude) | ("falls", TrendKind::GrowsWithAmplitude)
        );
        let agreed = matches!(
            (self.gap_trend.as_str(), d.kind),
            ("grows", TrendKind::GrowsWithAmplitude) | ("falls", TrendKind::FallsWithAmplitude)
        );
        if parted {
            format!(
                "{gap}, but the distortion relative to the excited lines {}: the two measure \
                 different things (the gap is all the nominal misses of the band-passed \
                 velocity, and out of sample on the second estimation capture, as the nominal \
                 is fitted on the first; the distortion is only what the nonlinearity puts on \
                 the lines the excitation leaves empty, and its trend tells the kind of \
                 effect): {}",
                if d.kind == TrendKind::FallsWithAmplitude {
                    "falls"
                } else {
                    "grows"
                },
                d.verdict
            )
        } else if agreed {
            format!("{gap}, and so does the distortion: {}", d.verdict)
        } else {
            format!("{gap}; {}", d.verdict)
        }
    }
}

/// Where the nominal's residual lies.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Where {
    /// residual against measured energy by band
    pub bands_hz: Vec<Band>,
    /// residual by operating region
    pub regions: Regions,
    /// with two estimation captures
    pub amplitude: Option<Amplitude>,
    /// non-excited line levels of the periodic captures
    pub distortion: Vec<Distortion>,
}

/// One parameter of the user's simulation against the nominal fit.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Mismatch {
    /// parameter name (seed 000 Table 1)
    pub name: String,
    /// the user's value
    pub sim: f64,
    /// the nominal fit's value
    pub fitted: f64,
    /// `100·(fitted − sim)/sim` [%]
    pub percent: f64,
}

/// The user's simulation against the nominal and the best model.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ParameterMismatch {
    /// where the simulation came from
    pub sim: String,
    /// gap metric of the user's simulation on the validation capture [%]
    pub fit_sim_val: f64,
    /// FIT points the parameters alone account for (nominal − simulation)
    pub parameter_part: f64,
    /// FIT points the structure accounts for (best − nominal)
    pub structure_part: f64,
    /// parameter by parameter
    pub parameters: Vec<Mismatch>,
}

/// One gap-free segment of the validation capture, when it has several
/// ([`diagnose_segments`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ValidationSegment {
    /// its place among the validation segments given, from 1 (the command line puts the
    /// capture's own numbering here, as `jointid info` lists it)
    pub segment: usize,
    /// its samples
    pub samples: usize,
    /// the nominal's gap metric on its scored range [%]
    pub fit_nominal: f64,
    /// the best model's gap metric on it (the nominal's when `best` is `none`) [%]
    pub fit_augmented: f64,
}

/// Result of [`diagnose`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Diagnosis {
    /// the verdict in one sentence
    pub verdict: String,
    /// name of the gap metric
    pub metric: String,
    /// structure of the nominal model
    pub structure: String,
    /// the nominal's gap metric on the validation capture [%]
    pub fit_nominal_val: f64,
    /// the nominal's toolbox FIT of `θ_m` on the validation capture [%]
    pub fit_nominal_angle_val: f64,
    /// the nominal's structure values, lag and offset
    pub nominal_parameters: BTreeMap<String, ParamValue>,
    /// the best model's gap metric (the nominal's when `best` is `none`) [%]
    pub fit_augmented_val: f64,
    /// share of the gap `100 − fit_nominal_val` the best closes [-]
    pub gap_closed_share: f64,
    /// the best effect, `a+b` for a pair, or `none`
    pub best: String,
    /// the pair tried with the best single effect that passed the test, if any
    #[serde(serialize_with = "pair_json")]
    pub pair: Option<Candidate>,
    /// the candidates, best score first
    #[serde(serialize_with = "candidates_json")]
    pub effects: Vec<Candidate>,
    /// where the gap lies
    #[serde(rename = "where")]
    pub location: Where,
    /// with a user simulation
    pub parameter_mismatch: Option<ParameterMismatch>,
    /// the significance test in words
    pub test: String,
    /// with several validation segments: the gap metric on each (`fit_nominal_val` and
    /// `fit_augmented_val` pool them); empty, and left out of the JSON, for one
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub validation_segments: Vec<ValidationSegment>,
    /// wall time [s] (the `--json` document gives it as `elapsed_s` too, as every
    /// command's wall time)
    pub seconds: f64,
    /// notes
    pub warnings: Vec<String>,
}

/// A candidate in JSON: its fields, with its validation FIT also as `fit_validation`, the
/// name every command gives a FIT on validation data.
#[derive(Serialize)]
struct CandidateJson<'a> {
    #[serde(flatten)]
    candidate: &'a Candidate,
    fit_validation: f64,
}

impl<'a> From<&'a Candidate> for CandidateJson<'a> {
    fn from(candidate: &'a Candidate) -> Self {
        CandidateJson {
            candidate,
            fit_validation: candidate.fit_val,
        }
    }
}

fn candidates_json<S: serde::Serializer>(v: &[Candidate], s: S) -> Result<S::Ok, S::Error> {
    s.collect_seq(v.iter().map(CandidateJson::from))
}

fn pair_json<S: serde::Serializer>(v: &Option<Candidate>, s: S) -> Result<S::Ok, S::Error> {
    v.as_ref().map(CandidateJson::from).serialize(s)
}

/// Opening words of the warning on a model whose simulation does not forget its start.
const SENSITIVE: &str = "sensitive to its start";

/// The nominal's frequency-domain start replaces its time-domain fit when it scores this
/// many FIT points higher in-sample ([`nominal_at_start`]): a fit that went elsewhere, not
/// one whose output-error cost weighs the record a little differently from the metric
/// (EMPS, measured: the rigid fit 94.4 % in-sample, its start 96.2 %, with the Coulomb
/// friction the linear model bends to; bench case 88: 65.1 % against 84.1 %).
const NOMINAL_START_MARGIN: f64 = 5.0;

/// One fitted model with its score.
struct Fitted {
    fit: NlFit,
    scored: Scored,
    warnings: Vec<String>,
}

/// Fits `effects` on the records `est` (one, or the gap-free segments of one capture as
/// separate experiments) and scores on `val` (likewise, `parts` their measured sides).
/// `from`: a fit whose structure values, lag and offset start this one, the effects
/// starting at the values they carry (a pair, started from its singles' fits); `None`: the
/// automatic start, or the extra mode's.
#[allow(clippy::too_many_arguments)]
fn fit_and_score(
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
    let mut nl = NlRequest {
        tau_c: linear.as_ref().map_or(0.0, |l| l.1),
        linear: linear.as_ref().map(|l| l.0.clone()),
        given,
        options: req.options.nl.clone(),
        ..NlRequest::new(req.structure, req.r, effects)
    };
    let automatic = nl.clone();
    // an extra mode starts where the linear fit with one more mass put it
    let longest = est
        .iter()
        .enumerate()
        .max_by_key(|(i, d)| (d.len(), usize::MAX - i))
        .map(|(_, d)| d)
        .ok_or(CandidateError::NoRecord)?;
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
                // a pair: the lead's fitted friction, and the mode from the best point of
                // the growth's grid over it on the lead's structure (the automatic start's
                // grid keeps the lead's gearbox damper, which stood in for the mode: bench
                // case 17, a parallel mode at 10 Hz under friction that sticks 23 % of the
                // time, answered Coulomb friction alone, 20 points short of the truth), or
                // from the race over its frequency when that ends lower (case 67, a
                // parallel mode at 10 Hz, the motor stuck on 81 % of the samples: from the
                // grid the mode went to 50 Hz and the pair gained +0.4 ± 0.1 points over
                // the friction alone, 75.2 % against the true model's 92.3 %; from the race
                // it reached 92.7 %)
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
    } else if let (true, Some(i), Some((plant, mode, tau_c))) =
        (with_coulomb, extra_at, &starts.coulomb_extra_mode)
    {
        // Coulomb friction with an extra mode: the structure and the mode from the
        // friction-compensated FRF of the structure with one more mass, the friction's
        // level as given (a pair's: its single's fitted level)
        nl.effects[i] = Effect::ExtraMode(*mode);
        nl.tau_c = *tau_c;
        nl.linear = Some(plant.clone());
        let offset = from.and_then(|b| b.get("offset")).unwrap_or(0.0);
        nl.start = NlStart::Values(model_of(&nl, longest).values(plant, offset, 0.0));
    } else if let Some(base) = from {
        nl.tau_c = base.model.tau_c;
        nl.linear = Some(base.plant.clone());
        let offset = base.get("offset").unwrap_or(0.0);
        nl.start = NlStart::Values(model_of(&nl, longest).values(&base.plant, offset, 0.0));
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
    scored_fit(res?, val, parts, req)
}

/// The finished fit `res` scored on `val` (`parts` its measured sides), with its warnings
/// and its own sensitivity to its start.
fn scored_fit(
    res: NlResult,
    val: &[IdData],
    parts: &[Measured],
    req: &DiagnoseRequest,
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
    Ok(Fitted {
        fit: res.fit,
        scored,
        warnings,
    })
}

/// Most further iterations of an answer whose fit stopped at its iteration limit
/// ([`polish`]).
const POLISH_ITER: usize = 140;

/// The answer's fit `f` continued from its values for at most [`POLISH_ITER`] more
/// iterations when it stopped at its iteration limit, what it held still held, and scored
/// on `val`; `None` when it had converged, or the continuation fails, does not lower the
/// in-sample cost or lowers the validation FIT. Only the answer: its FIT is the closure
/// the diagnosis reports, and every candidate at once would slow each diagnosis (bench
/// case 21, a 16 µrad backlash at 0.014 rad RMS: the fit stopped at 60 iterations in a
/// flat valley with `f_m` ×4 and 76.9 % on validation against the true model's 80.4 %;
/// continued, it reaches 78.4 % at the limit of the 140 further iterations).
fn polish(
    f: &Fitted,
    est: &[IdData],
    val: &[IdData],
    parts: &[Measured],
    req: &DiagnoseRequest,
) -> Option<Fitted> {
    if f.fit.termination != Termination::MaxIterations {
        return None;
    }
    let mut options = req.options.nl.clone();
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
    let res = identify_segments(est, &nl).ok()?;
    if res.fit.ssr >= f.fit.ssr {
        return None;
    }
    let g = scored_fit(res, val, parts, req).ok()?;
    (g.scored.fit >= f.scored.fit).then_some(g)
}

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
    let g = grow::grow_backlash(est, req.structure, req.r, (plant, *lag), &req.options.nl).ok()?;
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

/// The nominal when its fit from the usual start (`failed` says why) fails: first started
/// automatically in the time domain (no frequency-domain start), then from the structure
/// of each candidate's fit (`singles`, the best in-sample velocity FIT first) with the
/// effect left out. The fit, and in words where it started; the reasons of every failure
/// when all fail.
fn recover_nominal(
    failed: CandidateError,
    est: &[IdData],
    val: &[IdData],
    parts: &[Measured],
    req: &DiagnoseRequest,
    singles: &[Result<Fitted, CandidateError>],
) -> Result<(Fitted, String), NominalError> {
    let none = LinearStarts {
        structure: None,
        extra_mode: None,
        coulomb: None,
        coulomb_extra_mode: None,
        grown: None,
        two_mass: None,
    };
    let mut why = vec![(NominalStart::FrequencyDomain, failed)];
    match fit_and_score(est, val, parts, req, Vec::new(), &none, None) {
        Ok(f) => return Ok((f, "started automatically in the time domain instead".into())),
        Err(e) => why.push((NominalStart::TimeDomain, e)),
    }
    let mut fits: Vec<&Fitted> = singles.iter().filter_map(|r| r.as_ref().ok()).collect();
    fits.sort_by(|a, b| {
        b.fit
            .fit_velocity_percent
            .total_cmp(&a.fit.fit_velocity_percent)
    });
    for f in fits {
        let name = f
            .fit
            .model
            .effects
            .iter()
            .map(|e| e.name())
            .collect::<Vec<_>>()
            .join("+");
        match fit_and_score(est, val, parts, req, Vec::new(), &none, Some(&f.fit)) {
            Ok(n) => {
                return Ok((
                    n,
                    format!("started from the structure of the {name} candidate's fit instead"),
                ))
            }
            Err(e) => why.push((NominalStart::Candidate(name), e)),
        }
    }
    Err(NominalError { attempts: why })
}

/// The linear nominal at its frequency-domain start `(values, lag)`, not moved by the time
/// domain (no iteration), scored on `val`; and the in-sample gap metric [%] on `est` of it
/// and of the fitted nominal `fitted`. Why: at a small amplitude under a soft position loop,
/// the slow disturbance the loop rejects stands in the output-error cost above its
/// high-pass, and the time-domain fit follows it away from a joint its frequency-domain
/// start matched (bench case 88, a linear joint at 0.011 rad RMS under `kp` 10: the fit
/// ended at 65.3 % on the validation data with `J_m` 0.5 % of the start's, the true model
/// scored 84.3 %).
fn nominal_at_start(
    (est, val, parts): (&[IdData], &[IdData], &[Measured]),
    req: &DiagnoseRequest,
    (plant, lag): &(Vec<f64>, f64),
    fitted: &NlFit,
) -> Option<(Fitted, f64, f64)> {
    let longest = est.iter().max_by_key(|d| d.len())?;
    let mut nl = NlRequest {
        tau_c: *lag,
        linear: Some(plant.clone()),
        options: req.options.nl.clone(),
        ..NlRequest::new(req.structure, req.r, Vec::new())
    };
    nl.options.max_iter = 0;
    nl.start = NlStart::Values(model_of(&nl, longest).values(plant, 0.0, 0.0));
    let res = identify_segments(est, &nl).ok()?;
    let model = DrivenModel::of_fit(&res.fit);
    let o = &req.options;
    let in_sample = |m: &DrivenModel| {
        let ms: Vec<Measured> = est
            .iter()
            .map(|d| Measured::new(d, o.band_hz, o.skip_of(d)).with_tracking(o.tracking_hz))
            .collect();
        score_segments(&ms, m, est, 1).map(|s| s.fit).ok()
    };
    let at_start = in_sample(&model)?;
    let after = in_sample(&DrivenModel::of_fit(fitted))?;
    let scored = score_segments(parts, &model, val, o.segments).ok()?;
    // no iteration was asked for, so none of "its iteration limit"
    let warnings = res
        .warnings
        .into_iter()
        .filter(|w| !w.contains("iteration limit"))
        .collect();
    Some((
        Fitted {
            fit: res.fit,
            scored,
            warnings,
        },
        at_start,
        after,
    ))
}

/// Whether a single's validation score `(mean, se)` [FIT points] lies significantly below
/// its nominal's: `mean + 2·SE < −min_gain`, the mirror of significance. Nominal + an
/// effect contains the nominal (the effect at nought), so only a fit in a wrong basin
/// scores there.
fn below_its_nominal((mean, se): (f64, f64), min_gain: f64) -> bool {
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

/// The candidate `name` of the fitted model `f`, judged `(score, score_se, significant)`
/// against its base; its effect parameters named `effect.key` for a pair.
fn scored_candidate(
    name: &str,
    f: &Fitted,
    judged: (f64, f64, bool),
    pair: bool,
    (reason, odd_explained): (String, Option<f64>),
) -> Candidate {
    let (score, score_se, significant) = judged;
    // an effect fitted to no size is the nominal again: whatever it gained came from the
    // refitted structure, not from the effect
    let vanished = vanished_effects(&f.fit);
    let (significant, reason) = if vanished.is_empty() {
        (significant, reason)
    } else {
        (
            false,
            format!(
                "{reason}; not an effect: {} fitted within its σ of nought",
                vanished.join(", ")
            ),
        )
    };
    Candidate {
        name: name.into(),
        specs: f.fit.model.effects.iter().map(|e| e.to_string()).collect(),
        score,
        score_se,
        fit_val: f.scored.fit,
        fit_angle_val: f.scored.angle_fit,
        significant,
        parameters: effect_parameters(&f.fit, pair),
        odd_explained,
        structure_parameters: linear_parameters(&f.fit),
        reason,
        warnings: f.warnings.clone(),
    }
}

/// The parameter whose nought makes an effect vanish (the model is its nominal again), if it
/// has one: friction level, backlash width, cubic stiffness, delay, ripple amplitude.
fn size_parameter(e: &Effect) -> Option<&'static str> {
    match e {
        Effect::CoulombFriction(_) => Some("fc"),
        Effect::Backlash(_) => Some("width"),
        Effect::NonlinearStiffness(_) => Some("k3"),
        Effect::TimeDelay(_) => Some("samples"),
        Effect::TorqueRipple(_) => Some("amplitude"),
        Effect::ExtraMode(_) => None,
    }
}

/// The effects of `fit` whose size ([`size_parameter`]) came out within its standard
/// deviation of nought (exactly nought where the deviation is unknown), as `name size`.
fn vanished_effects(fit: &NlFit) -> Vec<String> {
    fit.params
        .iter()
        .filter_map(|p| {
            let Owner::Effect(i) = p.owner else {
                return None;
            };
            let e = &fit.model.effects[i];
            let nought = if p.std.is_finite() && p.std > 0.0 {
                p.value.abs() <= p.std
            } else {
                p.value == 0.0
            };
            (size_parameter(e) == Some(p.name) && nought).then(|| {
                format!(
                    "{} {} = {:.3e} ± {:.1e} {}",
                    e.name(),
                    p.name,
                    p.value,
                    p.std,
                    p.unit
                )
            })
        })
        .collect()
}

/// The share of the nominal's odd-line residual a model removes, in words (empty when not
/// read).
fn odd_words(share: Option<f64>) -> String {
    match share {
        None => String::new(),
        Some(s) if s < -0.005 => format!(
            "; it leaves {:.0} % more than the nominal's residual at the non-excited odd lines",
            -100.0 * s
        ),
        Some(s) => format!(
            "; it removes {:.0} % of the nominal's residual at the non-excited odd lines",
            100.0 * s.max(0.0)
        ),
    }
}

/// A candidate's place in the ranking: its score, a failed fit last.
fn by_score(c: &Candidate) -> f64 {
    if c.score.is_finite() {
        c.score
    } else {
        f64::NEG_INFINITY
    }
}

/// The order [periods per revolution] of a torque ripple the search found: none held at
/// amplitude 0, whose order was never fitted.
fn found_order(e: &Effect) -> Option<f64> {
    match e {
        Effect::TorqueRipple(r) if r.amplitude != 0.0 => Some(r.order),
        _ => None,
    }
}

/// The effects' fitted parameters of a fit (keys `effect.key` when `prefix`), with a torque
/// ripple's order, found by its search and held in the fit (standard deviation 0; none
/// when the search found no order and the ripple was held at amplitude 0).
fn effect_parameters(fit: &NlFit, prefix: bool) -> BTreeMap<String, ParamValue> {
    let key = |e: &Effect, name: &str| {
        if prefix {
            format!("{}.{name}", e.name())
        } else {
            name.to_string()
        }
    };
    let orders = fit.model.effects.iter().filter_map(|e| {
        found_order(e).map(|order| {
            (
                key(e, "order"),
                ParamValue {
                    value: order,
                    std: 0.0,
                    unit: e
                        .bounds()
                        .iter()
                        .find(|b| b.0 == "order")
                        .map_or("", |b| b.3)
                        .into(),
                },
            )
        })
    });
    fit.params
        .iter()
        .filter_map(|p| match p.owner {
            Owner::Effect(i) => Some((
                key(&fit.model.effects[i], p.name),
                ParamValue {
                    value: p.value,
                    std: p.std,
                    unit: p.unit.to_string(),
                },
            )),
            _ => None,
        })
        .chain(orders)
        .collect()
}

/// The structure's values, lag and offset of a fit.
fn linear_parameters(fit: &NlFit) -> BTreeMap<String, ParamValue> {
    fit.params
        .iter()
        .filter(|p| matches!(p.owner, Owner::Plant | Owner::CurrentLoop | Owner::Offset))
        .map(|p| {
            (
                p.name.to_string(),
                ParamValue {
                    value: p.value,
                    std: p.std,
                    unit: p.unit.to_string(),
                },
            )
        })
        .collect()
}

fn rms(x: &[f64]) -> f64 {
    (x.iter().map(|v| v * v).sum::<f64>() / x.len().max(1) as f64).sqrt()
}

/// A fit's torque ripple: its order and the periods of it the motor's travel on the
/// longest of `est` covers; `None` without one, or held at amplitude 0 (no order found).
fn ripple_travel(fit: &NlFit, est: &[IdData]) -> Option<(f64, f64)> {
    let order = fit.model.effects.iter().find_map(found_order)?;
    let longest = est.iter().max_by_key(|d| d.len())?;
    Some((order, ripple::travel_periods(longest, order)))
}

/// The evidence for `effect` in the residual's location, in words; `fitted`: the fitted
/// ripple's order and the periods of it the travel covers ([`ripple_travel`]).
fn evidence(effect: &str, w: &Where, fitted: Option<(f64, f64)>) -> String {
    let times = |r: &locate::Region, what: &str| {
        if r.energy_ratio.is_finite() {
            format!("residual {:.1}× the average {what}", r.energy_ratio)
        } else {
            format!("no samples {what}")
        }
    };
    let top_band = w
        .bands_hz
        .iter()
        .filter(|b| b.residual_ratio.is_finite())
        .max_by(|a, b| a.residual_ratio.total_cmp(&b.residual_ratio));
    let band = |b: Option<&Band>| match b {
        Some(b) => format!(
            "residual {:.0} % of the measured motion at {}–{} Hz (its largest band)",
            100.0 * b.residual_ratio.sqrt(),
            b.lo_hz,
            b.hi_hz
        ),
        None => "no band to compare".into(),
    };
    let odd = w.distortion.first().map(|d| {
        format!(
            "odd non-excited lines {:.1} dB below the excited ones{}",
            -d.linearity.odd.vs_excited_db,
            if d.linearity.odd.detected {
                ""
            } else {
                " (noise level)"
            }
        )
    });
    let r = &w.regions;
    match effect {
        "coulomb_friction" => times(&r.near_zero_velocity, "near zero velocity"),
        "backlash" => times(&r.torque_sign_change, "at torque sign changes"),
        "nonlinear_stiffness" => {
            let mut s = times(&r.large_deflection, "at large gearbox deflection");
            if let Some(o) = odd {
                s = format!("{s}; {o}");
            }
            s
        }
        "torque_ripple" => {
            let pattern = format!(
                "the residual's strongest pattern against the motor angle, order {} per \
                 revolution, explains {:.1} % of it",
                r.angle_pattern.order,
                100.0 * r.angle_pattern.share
            );
            match fitted {
                Some((n, p)) if p < ripple::MIN_PERIODS => format!(
                    "the fitted ripple, order {n:.0}, spans {p:.2} of its periods over the \
                     motor's travel: a torque against the angle whose order these data do not \
                     fix; {pattern}"
                ),
                Some((n, p)) => format!(
                    "the fitted ripple has order {n:.0} per revolution ({p:.1} periods over \
                     the motor's travel); {pattern}"
                ),
                None => pattern,
            }
        }
        "extra_mode" => band(top_band),
        "time_delay" => band(w.bands_hz.last()),
        _ => String::new(),
    }
}

/// The loop's answer (the pair when there is one, else the best single) refined in the loop
/// on the estimation record `est` ([`in_loop::refine`]) and scored again on `val`
/// (`measured` its measured side); kept, with its candidate's FIT, parameters and score
/// updated, when its validation FIT in the loop rises. A refined pair whose partner no
/// longer gains significantly over its lead at the same values ([`drop_partner`]) gives
/// way to that lead. What happened goes into `l.words`.
fn refine_answer(
    l: &mut in_loop::InLoop,
    answer: in_loop::LoopAnswer<'_>,
    (est, val, measured): (&Dataset, &Dataset, &Measured),
    judge: in_loop::Judge<'_>,
    o: &DiagnoseOptions,
) {
    let is_pair = answer.pair.is_some();
    let Some(start) = answer
        .pair_fitted
        .as_ref()
        .or_else(|| answer.singles.first().and_then(|s| s.1.as_ref()))
        .map(|f| f.fit.clone())
    else {
        return;
    };
    let m_est = Measured::new(&est.data, o.band_hz, o.skip_of(&est.data));
    let in_loop::Refined {
        fit: refined,
        before,
        moved,
        after,
    } = match in_loop::refine(&start, &l.scores.law, (&est.data, &m_est), o.threads) {
        Ok(r) => r,
        Err(e) => {
            l.words
                .push_str(&format!("; refining the answer in the loop failed: {e}"));
            return;
        }
    };
    let before = match moved {
        Some((name, factor, at)) => format!(
            "{before:.1} %; the lowest cost came from a start with {name} ×{factor} ({at:.1} \
             %; each spring was moved up and down to let the refinement leave a mode on a \
             wrong frequency) → {after:.1} %"
        ),
        None => format!("{before:.1} → {after:.1} %"),
    };
    let window = (o.segments, o.settle_periods);
    let scored = l
        .scores
        .score(measured, &DrivenModel::of_fit(&refined), val, window);
    let Some((cs, odd)) = scored.ok().filter(|(cs, _)| cs.fit > l.best_fit) else {
        l.words.push_str(&format!(
            "; refined in the loop on the estimation record (in-sample {before}), the answer \
             did not score higher on validation, and its open-loop fit is kept"
        ));
        return;
    };
    l.words.push_str(&format!(
        "; the answer refined in the loop on the estimation record (in-sample {before}, every \
         parameter free) scores {:.1} % on validation, from {:.1} %: its parameters and FIT \
         are the refined fit's",
        cs.fit, l.best_fit
    ));
    let mut refined = (refined, cs, odd);
    if is_pair {
        if let Some(lead) = drop_partner(l, &refined, (val, measured), judge, o) {
            *answer.pair = None;
            *answer.pair_fitted = None;
            refined = lead;
        }
    }
    let (refined, cs, odd) = refined;
    let (cand, fitted) = match (answer.pair.as_mut(), answer.pair_fitted.as_mut()) {
        (Some(c), Some(f)) => (c, f),
        _ => {
            let name = refined.model.effects[0].name();
            let Some((c, Some(f))) = answer.singles.iter_mut().find(|s| s.0.name == name) else {
                return;
            };
            (c, f)
        }
    };
    let is_pair = refined.model.effects.len() > 1;
    if !is_pair {
        let (score, se, significant) = judge(&cs.segments, &l.scores.nominal.segments);
        (cand.score, cand.score_se, cand.significant) = (score, se, significant);
    }
    cand.reason = format!(
        "refined in the controller's loop on the estimation record: validation FIT {:.1} % in \
         the loop{}; before: {}",
        cs.fit,
        odd_words(odd),
        cand.reason
    );
    cand.fit_val = cs.fit;
    cand.fit_angle_val = cs.angle_fit;
    cand.odd_explained = odd;
    // the refined fit's own doubts; the open-loop fit's (and its sensitivity to its start,
    // which the loop removes) no longer apply
    cand.warnings = crate::ident::nonlinear::run::checks(&refined);
    cand.parameters = effect_parameters(&refined, is_pair);
    cand.structure_parameters = linear_parameters(&refined);
    cand.specs = refined
        .model
        .effects
        .iter()
        .map(|e| e.to_string())
        .collect();
    l.best = cand.name.clone();
    fitted.fit = refined;
    l.best_fit = cs.fit;
    l.best_segments.clone_from(&cs.segments);
    l.best_odd = odd;
    l.velocities.1 = metric::velocity_band(&cs.theta_m, val.data.ts, measured.band);
    answer
        .singles
        .sort_by(|a, b| by_score(&b.0).total_cmp(&by_score(&a.0)));
}

/// A refined pair `(fit, its scores in the loop, odd share)` without its partner: the lead
/// alone at the pair's refined values, scored in the loop on `val`, when the partner gains
/// nothing significant over it there (bench case 2: a stiffening spring whose backlash
/// partner refined to a width of 83 ± 60 nrad). The same test that admitted the pair
/// before its refinement.
fn drop_partner(
    l: &mut in_loop::InLoop,
    (pair, pair_cs, _): &(NlFit, metric::ClosedScored, Option<f64>),
    (val, measured): (&Dataset, &Measured),
    judge: in_loop::Judge<'_>,
    o: &DiagnoseOptions,
) -> Option<(NlFit, metric::ClosedScored, Option<f64>)> {
    let lead = in_loop::without_effect(pair, 1);
    let (cs, odd) = l
        .scores
        .score(
            measured,
            &DrivenModel::of_fit(&lead),
            val,
            (o.segments, o.settle_periods),
        )
        .ok()?;
    let (gain, se, significant) = judge(&pair_cs.segments, &cs.segments);
    if significant && pair_cs.fit > cs.fit {
        return None;
    }
    let partner: Vec<String> = pair
        .params
        .iter()
        .filter(|p| p.owner == Owner::Effect(1))
        .map(|p| format!("{} = {:.3e} ± {:.1e} {}", p.name, p.value, p.std, p.unit))
        .collect();
    l.words.push_str(&format!(
        "; refined, the partner {} ({}) adds {gain:+.1} ± {se:.1} points only to {} at the \
         same values ({:.2} %): the answer is {} alone",
        pair.model.effects[1].name(),
        partner.join(", "),
        pair.model.effects[0].name(),
        cs.fit,
        pair.model.effects[0].name()
    ));
    Some((lead, cs, odd))
}

/// Fits and scores one candidate model: nominal + effects, from a fit's values when given.
type FitJob<'f> =
    &'f (dyn Fn(&(Vec<Effect>, Option<&NlFit>)) -> Result<Fitted, CandidateError> + Sync);

/// The pair of the loop's best single `singles[0]` with the other single that gains most
/// over it in the loop ([`in_loop`]), each other single significant there tried as its
/// partner from the best's fit (fitted by `score`, judged by `judge` on the segments in the
/// loop); with its scores in the loop, `None` when no pair gains significantly.
fn pair_in_loop(
    singles: &[(Candidate, Option<Fitted>)],
    l: &in_loop::InLoop,
    (val, measured): (&Dataset, &Measured),
    (score, judge): (FitJob<'_>, in_loop::Judge<'_>),
    o: &DiagnoseOptions,
) -> Option<(Candidate, Fitted, metric::ClosedScored)> {
    let (Some(lead), true) = (singles.first()?.1.as_ref(), singles[0].0.significant) else {
        return None;
    };
    let first = lead.fit.model.effects[0];
    let jobs: Vec<(Vec<Effect>, Option<&NlFit>)> = singles[1..]
        .iter()
        .filter(|c| c.0.significant)
        .filter_map(|c| c.1.as_ref())
        .map(|p| (vec![first, p.fit.model.effects[0]], Some(&lead.fit)))
        .collect();
    if jobs.is_empty() {
        return None;
    }
    let mut best: Option<(Candidate, Fitted, metric::ClosedScored)> = None;
    for r in parallel(&jobs, o.threads, score) {
        let Ok(f) = r else { continue };
        let model = DrivenModel::of_fit(&f.fit);
        let Ok((cs, odd)) = l
            .scores
            .score(measured, &model, val, (o.segments, o.settle_periods))
        else {
            continue;
        };
        let (gain, se, significant) = judge(&cs.segments, &l.best_segments);
        if !significant
            || cs.fit <= l.best_fit
            || best.as_ref().is_some_and(|b| b.0.fit_val >= cs.fit)
        {
            continue;
        }
        let names: Vec<&str> = f.fit.model.effects.iter().map(|e| e.name()).collect();
        let mut c = scored_candidate(
            &names.join("+"),
            &f,
            (gain, se, significant),
            true,
            (
                format!(
                    "in the controller's loop: {} added to {}: validation FIT {gain:+.1} ± \
                     {se:.1} points over {} alone{}",
                    names[1],
                    names[0],
                    names[0],
                    odd_words(odd)
                ),
                odd,
            ),
        );
        c.fit_val = cs.fit;
        c.fit_angle_val = cs.angle_fit;
        best = Some((c, f, cs));
    }
    best
}

/// The report's series of one diagnosis ([`DiagnosisSeries`]); `residual` is the nominal's
/// over the scored range, `angle_order` the order of its pattern against the motor angle.
fn series_of(
    measured: &Measured,
    nominal: &Fitted,
    best: Option<(String, Vec<f64>)>,
    val: &Dataset,
    analyses: &[(String, FrfAnalysis)],
    residual: &[f64],
    angle_order: u32,
) -> DiagnosisSeries {
    use series::*;
    let s = measured.skip;
    let ts = val.data.ts;
    let meas = measured.velocity[s..].to_vec();
    let best = best.map(|(n, v)| (n, v[s..].to_vec()));
    let best_res: Option<Vec<f64>> = best
        .as_ref()
        .map(|(_, v)| meas.iter().zip(v).map(|(a, b)| a - b).collect());
    // 2 s segments: 0.5 Hz lines, below the metric's 1 Hz edge
    let seg = ((2.0 / ts) as usize).min(meas.len() / 2).max(16);
    let (freq_hz, measured_asd) = asd(&meas, ts, seg);
    let spectra = Spectra {
        freq_hz,
        measured: measured_asd,
        nominal: asd(residual, ts, seg).1,
        best: best_res.as_ref().map(|r| asd(r, ts, seg).1),
    };
    let model = DrivenModel::of_fit(&nominal.fit);
    let frf = analyses
        .iter()
        .rev()
        .find(|(n, _)| *n == val.name)
        .or(analyses.first())
        .and_then(|(name, a)| {
            let frf = crate::ident::validate::FrfBand::from(&a.frf);
            let pos = frf.freq_hz.iter().copied().filter(|f| *f > 0.0);
            let lo = pos.clone().fold(f64::INFINITY, f64::min);
            let hi = pos.fold(0.0, f64::max);
            if !(lo.is_finite() && hi > lo) {
                return None;
            }
            let grid = log_grid(lo / 1.1, (hi * 1.1).min(0.49 / ts), 400);
            let response = nominal_response(&model, ts, &grid);
            Some(FrfFigure {
                capture: name.clone(),
                frf,
                nominal: crate::ident::validate::BodeCurve {
                    name: format!("nominal {}", model.plant.kind.label()),
                    freq_hz: grid,
                    response,
                },
            })
        });
    let driven = &nominal.scored.driven;
    let mut maps = vec![residual_map(
        "motor velocity ω_m of the nominal [rad/s]",
        &driven.omega_m[s..],
        residual,
    )];
    if driven.gearbox_deflection[s..].iter().any(|d| *d != 0.0) {
        maps.push(residual_map(
            "gearbox deflection δ of the nominal [rad]",
            &driven.gearbox_deflection[s..],
            residual,
        ));
    }
    let (angle, label) = if angle_order > 0 {
        let p = 2.0 * std::f64::consts::PI / angle_order as f64;
        (
            val.data.y[s..].iter().map(|t| t.rem_euclid(p)).collect::<Vec<_>>(),
            format!("measured motor angle θ_m modulo 2π/{angle_order} (the residual's order-{angle_order} pattern) [rad]"),
        )
    } else {
        (
            val.data.y[s..].to_vec(),
            "measured motor angle θ_m [rad]".to_string(),
        )
    };
    maps.push(residual_map(&label, &angle, residual));
    let win = ((MOVING_RMS_S / ts).round() as usize).max(1);
    let step = (win / 2).max(1);
    DiagnosisSeries {
        ts,
        t0: s as f64 * ts,
        validation: val.name.clone(),
        nominal: nominal.scored.velocity[s..].to_vec(),
        best,
        frf,
        lines: analyses.to_vec(),
        spectra,
        maps,
        rms_step_s: step as f64 * ts,
        nominal_rms: moving_rms(residual, win, step),
        best_rms: best_res.as_ref().map(|r| moving_rms(r, win, step)),
        window: loudest_window(residual, (WINDOW_S / ts).round() as usize),
        measured: meas,
    }
}

/// The linear starts the candidate fits take from the frequency-domain fits.
struct LinearStarts {
    /// the structure's values and current-loop lag [s]
    structure: Option<(Vec<f64>, f64)>,
    /// the structure's values, the extra mode and the lag [s], from the structure with one
    /// more mass ([`extra_mode_start`])
    extra_mode: Option<(Vec<f64>, ExtraMode, f64)>,
    /// as `structure`, from the friction-compensated FRF
    /// ([`crate::ident::nonlinear::compensate`]), for candidates with Coulomb friction; `None`
    /// when the compensation was not used
    coulomb: Option<(Vec<f64>, f64)>,
    /// as `extra_mode`, from the friction-compensated FRF, for pairs of Coulomb friction and
    /// an extra mode
    coulomb_extra_mode: Option<(Vec<f64>, ExtraMode, f64)>,
    /// when the motor sticks, the start grown in the time domain ([`grow`]), which every
    /// candidate with Coulomb friction takes instead of the above
    grown: Option<grow::Grown>,
    /// the linear two-mass's values and lag [s] from the frequency-domain fit, from which
    /// the backlash candidate is also grown ([`grow::grow_backlash`])
    two_mass: Option<(Vec<f64>, f64)>,
}

/// The start of `structure` with an extra mode attached as `attach` says, from the
/// frequency-domain fit of the structure with one more mass where that is the same
/// mechanism: a two-mass joint with a mode on its arm is a three-mass chain, a three-mass
/// joint with a mode in parallel on its first arm mass is seed 000's four-mass model
/// (eq. (7), `J_p` on `k_p`). The automatic start's grid over the mode's frequency misses
/// it when the structure's own fit took the extra resonance for one of its modes.
fn extra_mode_start(
    ds: &[Dataset],
    structure: Structure,
    r: f64,
    attach: Attach,
    coulomb: Option<Effect>,
) -> Option<(Vec<f64>, ExtraMode, f64)> {
    // the bigger structure, and where its extra body's inertia, spring and damper sit
    let (bigger, keep, extra): (Structure, &[usize], [usize; 3]) = match (structure, attach) {
        // [J_m, J_a1, J_a2, k_g, k_a, d_g, d_a, f_m]
        (Structure::TwoMass, _) => (Structure::ThreeMass, &[0, 1, 3, 5, 7], [2, 4, 6]),
        // [J_m, J_a1, J_a2, J_p, k_g, k_a, k_p, d_g, d_a, d_p, f_m]
        (Structure::ThreeMass, Attach::Parallel) => {
            (Structure::FourMass, &[0, 1, 2, 4, 5, 7, 8, 10], [3, 6, 9])
        }
        _ => return None,
    };
    let l = linear_start_segments(
        ds,
        1,
        &NlRequest::new(bigger, r, coulomb.into_iter().collect()),
    )
    .ok()?;
    if coulomb.is_some() && !compensation_used(&l) {
        return None;
    }
    let plant = keep.iter().map(|&i| l.values[i]).collect();
    let [j, k, d] = extra.map(|i| l.values[i]);
    Some((plant, ExtraMode { j, k, d, attach }, l.tau_c))
}

/// Whether a linear start is the friction-compensated FRF's.
fn compensation_used(l: &crate::ident::nonlinear::LinearStart) -> bool {
    l.compensation
        .as_ref()
        .is_some_and(|c| c.values.iter().any(|(n, v, _)| n == "used" && *v > 0.0))
}

/// The linear start from the friction-compensated FRF ([`LinearStarts::coulomb`]), and the
/// friction level the compensation's regression found [N·m] (before its
/// [`crate::ident::nonlinear::compensate::SHARE`]).
#[allow(clippy::type_complexity)]
fn coulomb_linear_of(
    ds: &[Dataset],
    req: &DiagnoseRequest,
    coulomb: Effect,
) -> (Option<(Vec<f64>, f64)>, Option<f64>) {
    let Ok(l) = linear_start_segments(ds, 1, &NlRequest::new(req.structure, req.r, vec![coulomb]))
    else {
        return (None, None);
    };
    let level = l.compensation.as_ref().and_then(|c| {
        let taken = c.values.iter().find(|v| v.0 == "fc")?.1;
        let regressed = c.values.iter().any(|v| v.0 == "fc_std");
        regressed.then_some(taken / crate::ident::nonlinear::compensate::SHARE)
    });
    let start = compensation_used(&l).then_some((l.values, l.tau_c));
    (start, level)
}

fn linear_of(
    ds: &[Dataset],
    req: &DiagnoseRequest,
    warnings: &mut Vec<String>,
) -> Option<(Vec<f64>, f64)> {
    match linear_start_segments(ds, 1, &NlRequest::new(req.structure, req.r, Vec::new())) {
        Ok(l) => Some((l.values, l.tau_c)),
        Err(e) => {
            if ds.first().is_some_and(|d| d.excitation.is_some()) {
                warnings.push(format!(
                    "{}: the frequency-domain linear start failed ({e}); the fits start \
                     automatically in the time domain",
                    ds[0].name
                ));
            }
            None
        }
    }
}

/// The candidate `name` as the diagnosis fits it: the simulator's default, except Coulomb
/// friction, which is the pure law (`F_s = F_c`, seed 001's; one parameter, where the
/// Stribeck bump adds two that a short record rarely separates: on EMPS the bump's fit
/// ends at `F_c` ≈ 0 and `F_s` ≈ 19.7 N with `v_s` = 0.09 m/s, the published pure level
/// under another name). `None` for an unknown name.
pub fn candidate(name: &str) -> Option<Effect> {
    let mut e = Effect::default_by_name(name)?;
    if let Effect::CoulombFriction(c) = &mut e {
        c.fs = c.fc;
    }
    Some(e)
}

/// Every candidate of the vocabulary ([`candidate`]), in [`Effect::all_defaults`] order.
pub fn all_candidates() -> Vec<Effect> {
    Effect::all_defaults()
        .iter()
        .filter_map(|e| candidate(e.name()))
        .collect()
}

/// Diagnoses the gap between the nominal model of `req.structure` fitted on `est` and the
/// measured joint, on the validation capture `val` (module documentation).
///
/// # Errors
/// [`DiagnoseError`]: for no or more than two estimation captures, different sample rates,
/// short records, the validation capture repeating an estimation capture, no candidate or
/// a bad gear ratio, each its variant; [`DiagnoseError::Nominal`] when the nominal cannot
/// be fitted or simulated.
pub fn diagnose(
    est: &[Dataset],
    val: &Dataset,
    req: &DiagnoseRequest,
) -> Result<Diagnosis, DiagnoseError> {
    diagnose_with_series(est, val, req).map(|(d, _)| d)
}

/// [`diagnose`], with the series a report draws ([`DiagnosisSeries`]: FRF, spectra,
/// residual maps, time records), which the [`Diagnosis`] (and its JSON) leaves out.
///
/// # Errors
/// As [`diagnose`].
pub fn diagnose_with_series(
    est: &[Dataset],
    val: &Dataset,
    req: &DiagnoseRequest,
) -> Result<(Diagnosis, DiagnosisSeries), DiagnoseError> {
    let est: Vec<&[Dataset]> = est.iter().map(std::slice::from_ref).collect();
    diagnose_segments(&est, std::slice::from_ref(val), req)
}

/// [`diagnose_with_series`] on captures with gaps: each estimation capture and the
/// validation capture given as its gap-free segments (one or more, in order, as
/// [`crate::data::segment`] selects them). The fits take the first capture's segments as
/// separate experiments ([`identify_segments`], the linear start on the FRF averaged over
/// them, [`linear_start_segments`]); the gap metric simulates every validation segment
/// from its own start and pools it over their scored ranges, one sum of squares
/// ([`metric::score_segments`]); the significance test splits the joined scored ranges
/// into its equal segments, and the residual's location, the series and the time records
/// are over the joined scored ranges. One segment each is [`diagnose_with_series`],
/// number for number.
///
/// # Errors
/// As [`diagnose`]; [`DiagnoseError::NoEstimationSegment`] or
/// [`DiagnoseError::NoValidationSegment`] for a capture with no segment.
pub fn diagnose_segments(
    est: &[&[Dataset]],
    val: &[Dataset],
    req: &DiagnoseRequest,
) -> Result<(Diagnosis, DiagnosisSeries), DiagnoseError> {
    let t0 = Instant::now();
    let o = &req.options;
    if est.is_empty() || est.len() > 2 {
        return Err(DiagnoseError::EstimationCount(est.len()));
    }
    if est.iter().any(|c| c.is_empty()) {
        return Err(DiagnoseError::NoEstimationSegment);
    }
    let val_segs = val;
    let Some(val0) = val.first() else {
        return Err(DiagnoseError::NoValidationSegment);
    };
    // effects on the gearbox spring are no candidates of a rigid model
    let (candidates, inapplicable): (Vec<Effect>, Vec<Effect>) = req
        .candidates
        .iter()
        .partition(|e| req.structure != Structure::Rigid || !e.acts_on_gearbox());
    if candidates.is_empty() {
        return Err(DiagnoseError::NoCandidate);
    }
    if !(req.r.is_finite() && req.r > 0.0) {
        return Err(DiagnoseError::GearRatio(req.r));
    }
    let ts = val0.data.ts;
    for ds in est.iter().flat_map(|c| c.iter()).chain(val) {
        ds.data.check(200).map_err(|source| DiagnoseError::Record {
            capture: ds.name.clone(),
            source,
        })?;
        if !crate::data::same_rate(ds.data.ts, ts) {
            return Err(DiagnoseError::RateMismatch {
                capture: ds.name.clone(),
                ts: ds.data.ts,
                val_ts: ts,
            });
        }
    }
    // validation on the estimation record itself measures nothing the fits did not see:
    // every candidate's extra parameters gain there, so it would name effects on any joint
    for e in est.iter().flat_map(|c| c.iter()) {
        if let Some(v) = val
            .iter()
            .find(|v| v.data.u == e.data.u && v.data.y == e.data.y)
        {
            return Err(DiagnoseError::SameSamples {
                validation: v.name.clone(),
                estimation: e.name.clone(),
            });
        }
    }
    let skip_of = |d: &Dataset| o.skip_of(&d.data);
    // the measured side of every validation segment, and of them joined (one segment: itself)
    let parts: Vec<Measured> = val
        .iter()
        .map(|d| Measured::new(&d.data, o.band_hz, skip_of(d)).with_tracking(o.tracking_hz))
        .collect();
    let val_data: Vec<IdData> = val.iter().map(|d| d.data.clone()).collect();
    let measured = Measured::joined(&parts);
    // the validation record the location and the series read: the capture itself, or its
    // segments' scored ranges joined (then scored from its first sample, as `measured`)
    let joined_val;
    let val: &Dataset = if let [one] = val {
        one
    } else {
        let mut data = IdData {
            ts,
            u: Vec::new(),
            y: Vec::new(),
            r: None,
        };
        for (d, m) in val.iter().zip(&parts) {
            data.u.extend_from_slice(&d.data.u[m.skip..]);
            data.y.extend_from_slice(&d.data.y[m.skip..]);
        }
        joined_val = Dataset {
            name: val0.name.clone(),
            data,
            t0: val0.t0,
            excitation: None,
            meta: val0.meta.clone(),
        };
        &joined_val
    };
    let skip = measured.skip;
    let mut warnings = Vec::new();
    if !inapplicable.is_empty() {
        warnings.push(format!(
            "{}: not candidates of a rigid model (they act on the gearbox spring)",
            inapplicable
                .iter()
                .map(|e| e.name())
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    let coulomb = candidates
        .iter()
        .find(|e| matches!(e, Effect::CoulombFriction(_)))
        .copied();
    let extra = candidates.iter().find_map(|e| match e {
        Effect::ExtraMode(x) => Some(x.attach),
        _ => None,
    });
    let est_data: Vec<IdData> = est[0].iter().map(|d| d.data.clone()).collect();
    progress::started(
        req.progress.as_ref(),
        "the linear starts (FRF and frequency-domain fits)",
    );
    let (coulomb_start, level) = match coulomb {
        Some(c) => coulomb_linear_of(est[0], req, c),
        None => (None, None),
    };
    let mut starts = LinearStarts {
        structure: linear_of(est[0], req, &mut warnings),
        extra_mode: extra.and_then(|a| extra_mode_start(est[0], req.structure, req.r, a, None)),
        coulomb: coulomb_start,
        coulomb_extra_mode: match (coulomb, extra) {
            (Some(c), Some(a)) if o.pairs => {
                extra_mode_start(est[0], req.structure, req.r, a, Some(c))
            }
            _ => None,
        },
        grown: None,
        two_mass: None,
    };
    if candidates.iter().any(|e| matches!(e, Effect::Backlash(_)))
        && matches!(req.structure, Structure::TwoMass | Structure::ThreeMass)
    {
        starts.two_mass = linear_start_segments(
            est[0],
            1,
            &NlRequest::new(Structure::TwoMass, req.r, Vec::new()),
        )
        .ok()
        .map(|l| (l.values, l.tau_c));
    }
    // stick-slip: the Coulomb candidates start from the structure grown in the time domain
    if let Some(level) = level {
        let share = grow::stick_share(&est_data, level);
        if share > grow::STICK_SHARE
            && matches!(req.structure, Structure::TwoMass | Structure::ThreeMass)
        {
            let lag = match &starts.structure {
                Some((_, t)) if *t > 0.0 => *t,
                _ => ts,
            };
            let grown = progress::step(
                req.progress.as_ref(),
                "the structure grown in the time domain (the motor sticks)",
                || grow::grow(&est_data, req.structure, req.r, lag, &o.nl),
                |r| match r {
                    Ok(_) => "grown".to_string(),
                    Err(e) => format!("failed: {e}"),
                },
            );
            match grown {
                Ok(g) => {
                    warnings.push(format!(
                        "the motor sticks: the torque stays below the friction level \
                         {level:.3e} N·m on {:.0} % of the estimation samples, so the FRF is \
                         the friction's and not the structure's; the candidates with Coulomb \
                         friction (Stribeck law) start from the {} grown in the time domain \
                         from the two-mass",
                        100.0 * share,
                        req.structure.label()
                    ));
                    starts.grown = Some(g);
                }
                Err(e) => warnings.push(format!(
                    "the motor sticks (the torque below the friction level on {:.0} % of the \
                     samples) but the time-domain start failed: {e}",
                    100.0 * share
                )),
            }
        }
    }
    let starts = starts;

    // nominal and singles, in parallel
    let mut jobs: Vec<(Vec<Effect>, Option<&NlFit>)> = vec![(Vec::new(), None)];
    jobs.extend(candidates.iter().map(|e| (vec![*e], None)));
    // one candidate model (nominal + `effects`) fitted on the estimation data (started from
    // `from` when given) and scored
    let score = |(effects, from): &(Vec<Effect>, Option<&NlFit>)| {
        let label = if effects.is_empty() {
            "nominal".to_string()
        } else {
            effects
                .iter()
                .map(|e| e.name())
                .collect::<Vec<_>>()
                .join(" + ")
        };
        progress::step(
            req.progress.as_ref(),
            &label,
            || {
                fit_and_score(
                    &est_data,
                    &val_data,
                    &parts,
                    req,
                    effects.clone(),
                    &starts,
                    *from,
                )
            },
            |r| match r {
                Ok(_) => "fitted and scored".to_string(),
                Err(e) => format!("failed: {e}"),
            },
        )
    };
    let results = parallel(&jobs, o.threads, score);
    let mut results = results.into_iter();
    let first = results.next().expect("the nominal job");
    let results: Vec<Result<Fitted, CandidateError>> = results.collect();
    let nominal = match first {
        Ok(n) => n,
        Err(e) => {
            let usual = e.to_string();
            let (n, how) = recover_nominal(e, &est_data, &val_data, &parts, req, &results)
                .map_err(|source| DiagnoseError::Nominal {
                    capture: est[0][0].name.clone(),
                    source,
                })?;
            warnings.push(format!(
                "nominal: the fit from its usual start failed ({usual}); {how}, so the nominal \
                 is that fit's and not the one from the frequency-domain start"
            ));
            n
        }
    };
    // the nominal's time-domain fit must not end below its frequency-domain start in-sample
    let nominal = match starts
        .structure
        .as_ref()
        .and_then(|l| nominal_at_start((&est_data, &val_data, &parts), req, l, &nominal.fit))
    {
        Some((start, at_start, after)) if at_start > after + NOMINAL_START_MARGIN => {
            warnings.push(format!(
                "nominal: the time-domain fit ended at an in-sample band-passed velocity FIT of \
                 {after:.1} %, far below its frequency-domain start's {at_start:.1} %: its \
                 output-error cost followed what the metric does not weigh (at a small \
                 amplitude, the slow disturbance the position loop rejects), not the joint; \
                 the nominal is the frequency-domain fit, and the candidates, fitted in the \
                 time domain, may score below it for the same reason"
            ));
            start
        }
        _ => nominal,
    };
    warnings.extend(nominal.warnings.iter().map(|w| format!("nominal: {w}")));
    let mut nom_fit = nominal.scored.fit;

    // where the nominal's residual lies
    let s = skip;
    let residual: Vec<f64> = measured.velocity[s..]
        .iter()
        .zip(&nominal.scored.velocity[s..])
        .map(|(a, b)| a - b)
        .collect();
    let regions = locate::regions(
        &residual,
        &val.data.u[s..],
        &val.data.y[s..],
        &nominal.scored.driven.omega_m[s..],
        &nominal.scored.driven.gearbox_deflection[s..],
    );
    let bands = locate::bands(&residual, &measured.velocity[s..], ts);
    let mut distortion = Vec::new();
    let mut lin_of: Vec<Option<Linearity>> = Vec::new();
    let mut analyses: Vec<(String, FrfAnalysis)> = Vec::new();
    let captures: Vec<&[Dataset]> = est
        .iter()
        .copied()
        .chain(std::iter::once(val_segs))
        .collect();
    for segs in captures {
        let a = match segs {
            [ds] if ds.excitation.is_some() => analyze_dataset(ds, o.settle_periods).ok(),
            [first, ..] if first.excitation.is_some() => {
                analyze_segments(segs, o.settle_periods).ok()
            }
            _ => None,
        };
        let name = segs[0].name.clone();
        let lin = a.as_ref().map(|a| a.linearity_y.clone());
        if let Some(l) = &lin {
            distortion.push(Distortion {
                capture: name.clone(),
                linearity: l.clone(),
            });
        }
        if let Some(a) = a {
            analyses.push((name, a));
        }
        lin_of.push(lin);
    }
    let amplitude = if est.len() == 2 {
        let nom_model = DrivenModel::of_fit(&nominal.fit);
        let mut levels = Vec::new();
        for segs in est {
            let ms: Vec<Measured> = segs
                .iter()
                .map(|ds| {
                    Measured::new(&ds.data, o.band_hz, skip_of(val0).min(ds.data.len() / 4))
                        .with_tracking(o.tracking_hz)
                })
                .collect();
            let data: Vec<IdData> = segs.iter().map(|d| d.data.clone()).collect();
            let gap = score_segments(&ms, &nom_model, &data, 1)
                .map(|sc| 100.0 - sc.fit)
                .unwrap_or(f64::NAN);
            let u: Vec<f64> = segs.iter().flat_map(|d| d.data.u.iter().copied()).collect();
            levels.push(AmplitudeLevel {
                capture: segs[0].name.clone(),
                u_rms: rms(&u),
                gap,
            });
        }
        let swap = levels[0].u_rms > levels[1].u_rms;
        let (lo, hi) = if swap { (1, 0) } else { (0, 1) };
        let distortion = match (&lin_of[lo], &lin_of[hi]) {
            (Some(a), Some(b)) => Some(amplitude_trend(a, b)),
            _ => None,
        };
        let dg = levels[hi].gap - levels[lo].gap;
        let gap_trend = if dg > 1.0 {
            "grows"
        } else if dg < -1.0 {
            "falls"
        } else {
            "unclear"
        };
        if swap {
            levels.swap(0, 1);
        }
        Some(Amplitude {
            levels,
            distortion,
            gap_trend: gap_trend.into(),
        })
    } else {
        None
    };
    let location = Where {
        bands_hz: bands,
        regions,
        amplitude,
        distortion,
    };

    // the nominal's residual at the non-excited odd lines (one periodic validation record),
    // and the share of it each model removes
    let odd_nominal = match val_segs {
        [one] => locate::odd_residual(one, &nominal.scored.driven.theta_m, o.settle_periods),
        _ => None,
    };
    let odd_of = |f: &Fitted| -> Option<f64> {
        let n = odd_nominal.as_ref()?;
        let m = locate::odd_residual(val, &f.scored.driven.theta_m, o.settle_periods)?;
        locate::odd_explained(n, &m)
    };

    // the singles, scored
    let judge = |seg: &[f64], base: &[f64]| {
        let (m, se) = segment_gain(seg, base);
        (m, se, m - 2.0 * se > o.min_gain)
    };
    // a single's candidate, judged against the nominal
    let single_of = |effect: &Effect, f: &Fitted| {
        let judged = judge(&f.scored.segments, &nominal.scored.segments);
        let (score, score_se, significant) = judged;
        let odd = odd_of(f);
        let reason = format!(
            "{}; validation FIT {:+.1} ± {:.1} points{}{}",
            evidence(effect.name(), &location, ripple_travel(&f.fit, &est_data)),
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
    };
    // a pair's candidate, judged against its lead alone
    let pair_of = |effects: &[Effect], f: &Fitted, lead: &Fitted| {
        let judged = judge(&f.scored.segments, &lead.scored.segments);
        let (score, score_se, significant) = judged;
        let odd = odd_of(f);
        let reason = format!(
            "{} added to {}: validation FIT {score:+.1} ± {score_se:.1} points over {} alone{}{}",
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
    };
    let mut singles: Vec<(Candidate, Option<Fitted>)> = Vec::new();
    for (effect, r) in candidates.iter().zip(results) {
        let c = match r {
            Ok(mut f) => {
                let (score, score_se, _) = judge(&f.scored.segments, &nominal.scored.segments);
                if below_its_nominal((score, score_se), o.min_gain) {
                    f.warnings.insert(
                        0,
                        format!(
                            "it scores below the nominal it contains ({score:+.1} ± \
                             {score_se:.1} points), which the effect at nought would match: \
                             this fit took a wrong basin and is not to be trusted; the effect is \
                             still tried as a partner of the significant singles"
                        ),
                    );
                }
                (single_of(effect, &f), Some(f))
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
    singles.sort_by(|a, b| by_score(&b.0).total_cmp(&by_score(&a.0)));

    // the pair
    let mut pair: Option<Candidate> = None;
    let mut pair_fitted: Option<Fitted> = None;
    let mut best_fit = nom_fit;
    let mut best = "none".to_string();
    if let Some((top, Some(_))) = singles.first().filter(|c| c.0.significant) {
        best = top.name.clone();
        best_fit = top.fit_val;
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
        let top_fit_val = top.fit_val;
        let mut jobs: Vec<(Vec<Effect>, Option<&NlFit>)> = Vec::new();
        let mut led_by: Vec<&Fitted> = Vec::new();
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
            let grown_lead = starts.grown.is_some() && matches!(first, Effect::CoulombFriction(_));
            for (j, c) in singles.iter().enumerate() {
                if j == l || leaders.contains(&j) && j < l {
                    continue;
                }
                let (second, base) = match (c.1.as_ref(), c.0.significant) {
                    (Some(p), true) => {
                        let second = p.fit.model.effects[0];
                        let own = matches!(second, Effect::ExtraMode(_)) && !grown_lead;
                        (second, if own { &p.fit } else { &lead.fit })
                    }
                    // a single below the nominal it contains took a wrong basin, which
                    // says nothing of its effect (bench case 27, a parallel mode with Coulomb
                    // friction at 0.24 rad RMS: the friction alone ran to `F_c` = 0.96 N·m,
                    // 26 × the truth, traded against the offset, and scored −23.0 points, so
                    // the pair was never tried): the partner, from its candidate's size on
                    // the lead's fit
                    (Some(_), false)
                        if below_its_nominal((c.0.score, c.0.score_se), o.min_gain) =>
                    {
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
            }
        }
        // a single below its nominal is also the partner of every other significant single,
        // from its candidate's size on that single's fit: the leader may be an effect that
        // stood in for the pair (bench case 36, a stiffening spring behind a 2.2-sample
        // delay at 0.059 rad RMS: backlash alone +1.9 ± 0.1 led, the delay +1.3 ± 0.0 came
        // second, the stiffness alone scored −4.0 with `k3` −14 %; the answer was backlash
        // with the delay, 12 points below the true model)
        for (l, lead) in singles.iter().enumerate() {
            let (Some(lead), true) = (lead.1.as_ref(), lead.0.significant) else {
                continue;
            };
            if leaders.contains(&l) {
                continue;
            }
            let first = lead.fit.model.effects[0];
            for c in &singles {
                let (Some(own), false) = (c.1.as_ref(), c.0.significant) else {
                    continue;
                };
                if !below_its_nominal((c.0.score, c.0.score_se), o.min_gain) {
                    continue;
                }
                // from its candidate's size on the lead's fit, as above, and from its own
                // fit with the lead's effect (case 36: from the delay's fit the stiffness
                // stayed at its default size, 47.8 %; from the stiffness's own fit the pair
                // ended at 73.5 %, above backlash with the delay)
                if let Some(e) = candidates.iter().find(|e| e.name() == c.0.name) {
                    jobs.push((vec![first, *e], Some(&lead.fit)));
                    led_by.push(lead);
                }
                jobs.push((vec![first, own.fit.model.effects[0]], Some(&own.fit)));
                led_by.push(lead);
            }
        }
        if o.pairs && !jobs.is_empty() {
            let res = parallel(&jobs, o.threads, score);
            for (((effects, _), lead), r) in jobs.iter().zip(&led_by).zip(res) {
                let name = format!("{}+{}", effects[0].name(), effects[1].name());
                match r {
                    Ok(f) => {
                        let cand = pair_of(effects, &f, lead);
                        let significant = cand.significant;
                        // pairs of different leaders compare by their validation FIT,
                        // and one led by the second single must beat the best single too
                        let better = pair.as_ref().is_none_or(|p| cand.fit_val > p.fit_val)
                            && cand.fit_val > top_fit_val;
                        if significant && better {
                            pair = Some(cand);
                            pair_fitted = Some(f);
                        }
                    }
                    Err(e) => warnings.push(format!("pair {name}: {e}")),
                }
            }
        }
    }
    // each of the pair's effects alone, refitted from the pair's values: a pair is the
    // answer only when both its effects are needed (a single stuck in a poor basin of its own
    // start can be rescued by the partner's structure, and then does as well alone)
    if let (Some(p), Some(pf)) = (pair.as_ref(), pair_fitted.as_ref()) {
        let both = pf.fit.model.effects.clone();
        // an extra mode in parallel on the first arm mass is the mechanism of the arm's
        // second mass: dropped, it may be the structure's branch that goes (bench case 11,
        // backlash on a stiff loop: the pair's mode took the arm's mass and its `J_a2`
        // branch a spurious 86 Hz mode; backlash alone from there ends 15 points below it)
        let swapped = both.iter().enumerate().find_map(|(i, e)| match e {
            Effect::ExtraMode(m) if m.attach == Attach::Parallel => {
                arm_branch_as(&pf.fit, req.structure, m).map(|f| (1 - i, f))
            }
            _ => None,
        });
        let mut jobs: Vec<(Vec<Effect>, Option<&NlFit>)> = vec![
            (vec![both[1]], Some(&pf.fit)),
            (vec![both[0]], Some(&pf.fit)),
        ];
        if let Some((keep, f)) = &swapped {
            jobs.push((vec![both[*keep]], Some(f)));
        }
        let res = parallel(&jobs, o.threads, score);
        // the effect kept, its fit, and what the dropped one adds to it (mean, SE)
        let mut kept: Option<(Effect, Fitted, f64, f64)> = None;
        for ((effects, _), r) in jobs.iter().zip(res) {
            match r {
                Ok(f) => {
                    let (gain, se, needed) = judge(&pf.scored.segments, &f.scored.segments);
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
        if let Some((effect, f, gain, se)) = kept {
            let (score, score_se, significant) =
                judge(&f.scored.segments, &nominal.scored.segments);
            let at = singles.iter().position(|c| c.0.name == effect.name());
            if let (true, Some(i)) = (significant, at) {
                let dropped = both
                    .iter()
                    .find(|e| e.name() != effect.name())
                    .map_or("", |e| e.name());
                warnings.push(format!(
                    "pair {}: {} alone, refitted from the pair's values, does as well ({dropped} \
                     adds {gain:+.1} ± {se:.1} FIT points to it, not significant): the answer \
                     is {} alone",
                    p.name,
                    effect.name(),
                    effect.name()
                ));
                if singles[i].0.score.is_nan() || singles[i].0.score < score {
                    let odd = odd_of(&f);
                    singles[i] = (
                        scored_candidate(
                            effect.name(),
                            &f,
                            (score, score_se, significant),
                            false,
                            (
                                format!(
                                    "{}; validation FIT {score:+.1} ± {score_se:.1} points, \
                                     refitted from the values of the pair {}, to which it leaves \
                                     {gain:+.1} ± {se:.1} points{}",
                                    evidence(
                                        effect.name(),
                                        &location,
                                        ripple_travel(&f.fit, &est_data)
                                    ),
                                    p.name,
                                    odd_words(odd)
                                ),
                                odd,
                            ),
                        ),
                        Some(f),
                    );
                    singles.sort_by(|a, b| by_score(&b.0).total_cmp(&by_score(&a.0)));
                }
                pair = None;
                pair_fitted = None;
            }
        }
    }
    if let Some(p) = &pair {
        best = p.name.clone();
        best_fit = p.fit_val;
    } else if let Some((c, Some(_))) = singles.first().filter(|c| c.0.significant) {
        best = c.name.clone();
        best_fit = c.fit_val;
    }
    // the answer's fit continued when it stopped at its iteration limit
    let answer_fit = match &pair_fitted {
        Some(pf) if pair.is_some() => Some(pf),
        _ => singles
            .first()
            .filter(|c| c.0.significant)
            .and_then(|c| c.1.as_ref()),
    };
    if let Some((f, g)) = answer_fit.and_then(|f| {
        polish(f, &est_data, &val_data, &parts, req)
            .map(|g| ((f.fit.iterations, f.fit.ssr, f.scored.fit), g))
    }) {
        let (iterations, ssr, fit_before) = f;
        warnings.push(format!(
            "{best}: its fit stopped at its iteration limit ({iterations} iterations) and was \
             continued from there for {} more: in-sample cost {:+.1} %, validation FIT \
             {fit_before:.1} → {:.1} %",
            g.fit.iterations,
            100.0 * (g.fit.ssr / ssr - 1.0),
            g.scored.fit
        ));
        match (&mut pair, &mut pair_fitted) {
            (Some(p), Some(pf)) => {
                let effects = g.fit.model.effects.clone();
                let lead = singles
                    .iter()
                    .find(|c| c.0.name == effects[0].name())
                    .and_then(|c| c.1.as_ref());
                if let Some(lead) = lead {
                    *p = pair_of(&effects, &g, lead);
                    best_fit = p.fit_val;
                    *pf = g;
                }
            }
            _ => {
                let effect = g.fit.model.effects[0];
                singles[0] = (single_of(&effect, &g), Some(g));
                best_fit = singles[0].0.fit_val;
            }
        }
    }
    // the odd distortion the nominal leaves, and what the answer does with it
    let mut best_odd = match &pair {
        Some(p) => p.odd_explained,
        None => singles
            .first()
            .filter(|c| c.0.significant)
            .and_then(|c| c.0.odd_explained),
    };
    let odd_left = odd_nominal
        .as_ref()
        .filter(|n| n.vs_noise_db >= locate::ODD_RESIDUAL_ABOVE_NOISE_DB)
        .map(|n| n.vs_noise_db);
    // an answer that leaves it: the models scored in the controller's loop
    let mut in_loop: Option<in_loop::InLoop> = None;
    if let (Some(db), [one]) = (odd_left, val_segs) {
        if best == "none" || best_odd.is_some_and(|s| s < locate::ODD_EXPLAINED_DOUBT) {
            let answer = in_loop::LoopAnswer {
                singles: &mut singles,
                pair: &mut pair,
                pair_fitted: &mut pair_fitted,
            };
            match answer.rescore(
                (est[0], one, &parts[0]),
                &nominal,
                (&judge, o),
                (&best, best_odd, db),
            ) {
                Ok(mut l) => {
                    // the loop's best single with each other single significant there (the
                    // open-loop pair search was led by a single the loop does not keep)
                    let found = if o.pairs && pair.is_none() {
                        pair_in_loop(&singles, &l, (one, &parts[0]), (&score, &judge), o)
                    } else {
                        None
                    };
                    if let Some((c, f, cs)) = found {
                        l.words.push_str(&format!(
                            "; in the loop, {} adds {:+.1} ± {:.1} points to {} alone: the \
                             answer is the pair",
                            f.fit.model.effects[1].name(),
                            c.score,
                            c.score_se,
                            l.best
                        ));
                        l.best.clone_from(&c.name);
                        l.best_fit = c.fit_val;
                        l.best_odd = c.odd_explained;
                        l.velocities.1 = metric::velocity_band(&cs.theta_m, ts, o.band_hz);
                        l.best_segments = cs.segments;
                        pair = Some(c);
                        pair_fitted = Some(f);
                    }
                    // the answer refined in the loop
                    let ctx = (&est[0][0], one, &parts[0]);
                    let answer = in_loop::LoopAnswer {
                        singles: &mut singles,
                        pair: &mut pair,
                        pair_fitted: &mut pair_fitted,
                    };
                    progress::step(
                        req.progress.as_ref(),
                        "the answer refined in the controller's loop",
                        || refine_answer(&mut l, answer, ctx, &judge, o),
                        |_| "done".to_string(),
                    );
                    warnings.push(l.words.clone());
                    // the answer's own doubts, which no open-loop check covers here (bench
                    // case 61: an arm spring the loop's refinement leaves undetermined)
                    let answer = match &pair {
                        Some(p) => Some(p),
                        None => singles.first().map(|c| &c.0).filter(|c| c.name == l.best),
                    };
                    if let Some(c) = answer {
                        warnings.extend(c.warnings.iter().map(|w| format!("{}: {w}", c.name)));
                    }
                    nom_fit = l.scores.nominal.fit;
                    best.clone_from(&l.best);
                    best_fit = l.best_fit;
                    best_odd = l.best_odd;
                    in_loop = Some(l);
                }
                Err(e) => warnings.push(e.to_string()),
            }
        }
    }
    let gap = 100.0 - nom_fit;
    let gap_closed_share = if gap > 0.0 {
        (best_fit - nom_fit) / gap
    } else {
        0.0
    };

    // the user's simulation
    let parameter_mismatch = match &req.user {
        Some(u) => {
            let model = DrivenModel {
                plant: u.plant,
                effects: u.effects.clone(),
                tau_c: u.tau_c,
                offset: 0.0,
            };
            let fit_sim_val = match &in_loop {
                Some(l) => parts[0]
                    .score_closed(&model, &l.scores.law, &val_data[0], 1)
                    .map(|s| s.fit),
                None => score_segments(&parts, &model, &val_data, 1).map(|s| s.fit),
            }
            .unwrap_or_else(|e| {
                warnings.push(format!("{}: {e}", u.name));
                f64::NAN
            });
            let nom_plant = DrivenModel::of_fit(&nominal.fit).plant;
            let mut up = u.plant.params;
            let mut np = nom_plant.params;
            let user_names: Vec<&str> = model_params(u.plant.kind).iter().map(|p| p.0).collect();
            let parameters = model_params(nom_plant.kind)
                .into_iter()
                .filter(|(n, _)| user_names.contains(n))
                .map(|(name, field)| {
                    let sim = *field(&mut up);
                    let fitted = *field(&mut np);
                    Mismatch {
                        name: name.into(),
                        sim,
                        fitted,
                        percent: 100.0 * (fitted - sim) / sim,
                    }
                })
                .collect();
            Some(ParameterMismatch {
                sim: u.name.clone(),
                fit_sim_val,
                parameter_part: nom_fit - fit_sim_val,
                structure_part: best_fit - nom_fit,
                parameters,
            })
        }
        None => None,
    };

    let looped = if in_loop.is_some() {
        " in the controller's loop"
    } else {
        ""
    };
    let mut verdict = if best == "none" {
        format!(
            "no candidate effect closes a significant part of the gap: the nominal {} reaches \
             {nom_fit:.1} % (band-passed motor-velocity FIT on the validation data{looped}) and \
             no effect gains more than {} FIT point beyond twice its standard error",
            req.structure.label(),
            o.min_gain
        )
    } else {
        format!(
            "{best} closes {:.0} % of the gap: band-passed motor-velocity FIT on the validation \
             data{looped} {nom_fit:.1} % → {best_fit:.1} % ({:+.1} points)",
            100.0 * gap_closed_share,
            best_fit - nom_fit
        )
    };
    // in the loop, the open-loop sensitivity of the answer no longer matters
    if best != "none" && in_loop.is_none() {
        let best_warnings = match &pair {
            Some(p) => &p.warnings,
            None => &singles[0].0.warnings,
        };
        if let Some(w) = best_warnings.iter().find(|w| w.starts_with(SENSITIVE)) {
            warnings.push(format!("{best}: {w}"));
        }
    }
    if let Some(db) = odd_left.filter(|_| in_loop.is_none()) {
        let left = format!(
            "the nominal's residual at the non-excited odd lines of the validation capture \
             stands {db:.1} dB above the noise: odd nonlinear distortion (friction, backlash, a \
             stiffening spring) that a linear model cannot follow"
        );
        match best_odd {
            _ if best == "none" => warnings.push(format!(
                "{left}, and no candidate removes it significantly: the effect that makes it \
                 is not among the candidates, or its fit or its simulation failed (see each \
                 candidate's warnings)"
            )),
            Some(share) if share < locate::ODD_EXPLAINED_DOUBT => {
                let removed = if share > 0.005 {
                    format!("only {:.0} %", 100.0 * share)
                } else {
                    "none".into()
                };
                warnings.push(format!(
                    "{left}; {best} removes {removed} of it, so {best} does not explain the \
                     distortion and the answer is doubtful: the effect that makes it may be \
                     one whose simulation from the measured torque cannot be scored (a \
                     strongly stiffening spring, chaotic at this amplitude) or is not among \
                     the candidates"
                ));
                // the doubt goes with the verdict, where a reader of the top line sees it
                verdict = format!(
                    "{verdict}; doubtful: {best} removes {removed} of the odd nonlinear \
                     distortion the nominal leaves (see the notes)"
                );
            }
            _ => {}
        }
    }
    let nominal_parameters = linear_parameters(&nominal.fit);
    let validation_segments = if parts.len() > 1 {
        let best_records = match (&pair, &pair_fitted) {
            (Some(_), Some(f)) => f.scored.per_record.clone(),
            _ => singles
                .first()
                .filter(|c| c.0.significant)
                .and_then(|c| c.1.as_ref().map(|f| f.scored.per_record.clone()))
                .unwrap_or_else(|| nominal.scored.per_record.clone()),
        };
        val_segs
            .iter()
            .zip(&nominal.scored.per_record)
            .zip(&best_records)
            .enumerate()
            .map(|(i, ((d, &n), &b))| ValidationSegment {
                segment: i + 1,
                samples: d.data.len(),
                fit_nominal: n,
                fit_augmented: b,
            })
            .collect()
    } else {
        Vec::new()
    };
    let best_velocity = match (&pair, pair_fitted) {
        (Some(p), Some(f)) => Some((p.name.clone(), f.scored.velocity)),
        _ => singles.first().filter(|c| c.0.significant).and_then(|c| {
            c.1.as_ref()
                .map(|f| (c.0.name.clone(), f.scored.velocity.clone()))
        }),
    };
    // in the loop, the figures show the loop's simulations
    let (nominal, best_velocity, residual) = match &in_loop {
        Some(l) => {
            let mut n = nominal;
            n.scored.velocity.clone_from(&l.velocities.0);
            n.scored.angle_fit = l.scores.nominal.angle_fit;
            let residual: Vec<f64> = measured.velocity[s..]
                .iter()
                .zip(&l.velocities.0[s..])
                .map(|(a, b)| a - b)
                .collect();
            (n, Some((best.clone(), l.velocities.1.clone())), residual)
        }
        None => (nominal, best_velocity, residual),
    };
    let series = series_of(
        &measured,
        &nominal,
        best_velocity,
        val,
        &analyses,
        &residual,
        location.regions.angle_pattern.order,
    );
    let diagnosis = Diagnosis {
        verdict,
        metric: if in_loop.is_some() {
            metric::CLOSED_LOOP_METRIC_NAME
        } else {
            metric::METRIC_NAME
        }
        .into(),
        structure: req.structure.label().into(),
        fit_nominal_val: nom_fit,
        fit_nominal_angle_val: nominal.scored.angle_fit,
        nominal_parameters,
        fit_augmented_val: best_fit,
        gap_closed_share,
        best,
        pair,
        effects: singles.into_iter().map(|c| c.0).collect(),
        location,
        parameter_mismatch,
        test: if parts.len() == 1 {
            format!(
                "the validation record (after {:.2} s) is split into {} equal segments; the \
                 gain of the metric over the nominal is computed on each; score = mean gain; \
                 significant when mean − 2·(standard error over the segments) > {} FIT point",
                o.skip_s, o.segments, o.min_gain
            )
        } else {
            format!(
                "the validation capture's {} gap-free segments, each scored after {:.2} s, are \
                 joined and split into {} equal parts; the gain of the metric over the nominal \
                 is computed on each; score = mean gain; significant when mean − \
                 2·(standard error over the parts) > {} FIT point",
                parts.len(),
                o.skip_s,
                o.segments,
                o.min_gain
            )
        },
        validation_segments,
        seconds: t0.elapsed().as_secs_f64(),
        warnings,
    };
    Ok((diagnosis, series))
}
