//! Sim-to-real gap diagnosis (../shared/DESIGN.md §7): which unmodelled effect makes the simulated
//! joint depart from the measured one, how much of the gap it closes, and where the gap
//! lies.
//!
//! **Gap metric** ([`metric::METRIC_NAME`]): the toolbox FIT of the band-passed motor
//! velocity (1–150 Hz) on the validation capture, the model simulated with the simulator's
//! exact laws from the measured torque plus a slow torque input estimated below
//! [`DiagnoseOptions::tracking_hz`] (2 Hz; [`metric::simulate_tracked`]), the disturbance
//! the position loop rejected; the toolbox FIT of `θ_m` of the plain open-loop simulation is
//! reported beside it.
//!
//! **Significance test** ([`fits::Fitter::judge`], the one criterion of every stage): the
//! scored range is split into K = [`DiagnoseOptions::segments`] (4) equal segments; the gain
//! of the metric of a model over the model it extends is computed on each; the score is the
//! mean gain; the model is *significant* only when `mean − 2·SE` exceeds the floor, SE the
//! standard error of the mean over the segments. The floor ([`fits::Floor`]) is
//! [`DiagnoseOptions::min_gain`] (0.1 FIT point), or, when larger, the spread of the
//! nominal's own refits ([`nominal::refit_spread`]): how far a single whose effect came out
//! of no size moved the validation FIT at the nominal's in-sample cost. A single whose
//! effect the data show by its own signature needs only that spread
//! ([`fits::Fitted::shown_apart`], [`fits::Fitter::judge_model`]): a transport delay that
//! the excited lines show beside the lag (their likelihood-ratio test at 99 %,
//! [`crate::ident::nonlinear::DelayLines`]) and that explains them (it removes at least a
//! third of their misfit above the noise, [`crate::ident::nonlinear::DelayLines::explains`]:
//! another effect's phase on the lines removes little of it), a torque ripple whose order stands out of the
//! search against the motor angle ([`crate::ident::nonlinear::ripple::search_order`]) and
//! that the validation record, along another trajectory, shows again
//! ([`crate::ident::nonlinear::ripple::replication`], [`fits::RippleShown`]), and a
//! friction, a gap or a stiffening spring that removes most of the odd distortion the
//! nominal leaves at the validation capture's non-excited odd lines (an estimation
//! capture's when the validation capture has none, [`evidence::Evidence::odd_in_sample`]; standing
//! [`locate::ODD_RESIDUAL_ABOVE_NOISE_DB`] above the noise), more than any other single
//! ([`select::odd_shown`]).
//! That test has already rejected the nominal, and the metric has only to confirm the gain. The candidates are
//! ranked significant first, each group by score ([`table::ranked`]); the answer is the
//! first when significant. Once it is chosen, the others follow it in the order of what
//! each adds to it ([`table::ranked_after`]). An effect whose
//! size comes out on its lower bound or within 2σ of nought is never significant, in any
//! stage, open loop or in the loop ([`fits::Fitted::counts`]; a transport delay, whose
//! deviation the lag it trades with spreads, is judged there by the excited lines when
//! they show one, [`size::vanished_effects`]), nor a
//! transport delay the excited lines do not show beside the lag
//! ([`fits::delay_unsupported`]: the gap metric, simulated from a closed loop's measured
//! torque, lets a delay follow the disturbance the loop feeds back), nor a nonlinear law (a
//! friction, a gap, a stiffening spring, a ripple the order search does not show) where
//! the data show no nonlinearity: no non-excited line of a periodic capture above the
//! noise, and, with two estimation captures, the same best linear approximation at both
//! amplitudes ([`fits::nonlinear_unsupported`], [`linearity::Nonlinearity`]).
//!
//! [`diagnose_segments`] is a pipeline of stages, one module each:
//!
//! 0. **Inputs** ([`inputs`]): the captures checked (the validation capture must not hold
//!    the estimation's samples), the candidates that apply to the structure, the measured
//!    side of each validation segment; every fit's residual low-passed at the top of the
//!    excited band ([`inputs::fit_options`]): above it the torque of a closed loop is the
//!    controller's reaction to the encoder's quantisation and the disturbance, and a fit
//!    from the measured torque that scores it is drawn towards the inverse controller.
//!    The input is taken as held over each sample interval (a drive's torque reference);
//!    when the nominal's current-loop lag comes out nought, the nominal is fitted again
//!    with the input taken as samples of a signal that moves between them
//!    ([`inputs::SampledInput`], a measured analog input), and when it scores higher
//!    in-sample the diagnosis goes on from it, its singles fitted on that input.
//!    **Starts** ([`starts`]): the frequency-domain linear fits the candidates start from;
//!    where the motor sticks, the structure grown in the time domain
//!    ([`crate::ident::nonlinear::grow`]); the data's own evidence of a delay
//!    ([`crate::ident::nonlinear::DelayLines`]) and of a nonlinearity
//!    ([`linearity::Nonlinearity`], [`crate::ident::frf::bla_change`]).
//! 1. **Nominal** ([`nominal`]): the linear physical model of the structure with no effect,
//!    fitted on the (first) estimation capture by the nonlinear engine
//!    ([`crate::ident::nonlinear::identify`]) together with the singles ([`fits`], on
//!    [`DiagnoseOptions::threads`] threads); restarted elsewhere when it fails; its
//!    frequency-domain start kept when the fit ends far below it in-sample. When it came
//!    apart where the motor does not stick (no minimum, a spring on the lower bound of its
//!    search, [`nominal::came_apart`]), it and every single are fitted again from the
//!    structure fitted to the record's own Welch FRF ([`nominal::restarted`]). No base for
//!    an answer ([`nominal::trust`]) when it came apart from there too, or describes the
//!    validation data far worse than its own. Refitted from the structure of each single
//!    significant over it, and replaced by the refit that scores higher in sample
//!    ([`nominal::from_singles`]): the nominal is the best linear model found from any
//!    start, so that no candidate gains on it by a better minimum of the linear part alone.
//! 2. **Evidence** ([`evidence`]): where the nominal's residual lies (operating regions,
//!    bands, [`locate`]); the odd/even non-excited lines of periodic captures
//!    ([`crate::ident::frf`]); with two estimation captures, how distortion and gap change
//!    with amplitude; the nominal's residual at the odd lines each model's share is read
//!    against ([`locate::odd_explained`]): the validation capture's, or, when a noise
//!    validation excites every line, the first estimation capture's in sample.
//! 3. **Singles** ([`select::singles`]): each candidate effect added to the nominal, the
//!    structure refitted jointly, judged against the nominal. A single significantly below
//!    the nominal it contains is refitted from the nominal's values on the nominal's cost
//!    ([`select::nested_refits`]) and replaced when that scores higher on the estimation
//!    records; an extra mode is so refitted whatever it scored, placed by the automatic
//!    start's grid and at each peak of the nominal's residual
//!    ([`crate::ident::nonlinear::Start::at_peaks`]). Every scored model is also simulated
//!    from a start angle 1 nrad away ([`metric::Measured::start_sensitivity`]): a chaotic
//!    open-loop response is flagged,
//!    since no simulation metric can score it.
//! 4. **Pairs** ([`select::pairs`]): the best single (and the second when they tie) with
//!    each other significant single, and each that gains beyond twice its standard error
//!    under the floor, started from the singles' fits and, for two
//!    significant singles, from the data's own start too (seed 001's three steps: a single
//!    bends its structure to take its partner's part), judged against its lead alone
//!    (nested); a significant single that leads no pair with each single below its nominal
//!    ([`select::beside_the_leaders`]), since the leader may stand in for the pair. When
//!    the best single leaves the odd distortion standing above the noise, it is also paired
//!    with each effect that makes such distortion ([`fits::makes_odd`]); the partner that
//!    removes most of what it leaves, more than any other, is shown by the odd lines and
//!    judged as a single they show ([`fits::Fitted::shown_apart`]). What each partner
//!    adds to its lead is kept: it ranks the candidates after the answer
//!    ([`table::ranked_after`], [`Candidate::with_answer`]).
//! 5. **Refinement** ([`select::polish_answer`]): the answer's fit continued when it
//!    stopped at its iteration limit; a pair's before its reduction, since a pair stopped
//!    short of its minimum is no measure of what its second effect adds.
//! 6. **Reduction** ([`select::reduce`]): a pair's effects each refitted alone from the
//!    pair's values; a single that does as well is the answer (and is refined in turn).
//! 7. **In the loop** ([`loop_answer`], [`in_loop`]): an answer that leaves the odd
//!    distortion standing at least [`locate::ODD_RESIDUAL_ABOVE_NOISE_DB`] above the noise
//!    ([`locate::odd_left_db`]), or `none` with it left, has every fitted model scored
//!    again in the loop of the robot's controller, its law identified from the estimation
//!    record ([`crate::ident::controller`]); every single significant there, and every pair
//!    of the loop's best with another significant there (from the best's fit and from the
//!    data's own start; with any other of a size where the best misses in sample what the
//!    noise leaves, a delay then counted on the loop's test whatever the excited lines say),
//!    is refined in the loop before they are ranked, until
//!    one reaches in-sample what the noise from period to period leaves
//!    ([`metric::Measured::noise_fit`]); the loop's answer replaces the open-loop one when it
//!    removes the distortion. Before that, a gap or a stiffening spring whose open-loop fit
//!    came out of no size is sized again in the loop ([`loop_answer::seed_vanished`]): the
//!    automatic start's grid of its sizes scored there, the best refined; such a law can
//!    make the simulation from the measured torque follow a course of its own (a gap the
//!    motor rattles in), which the open-loop cost cannot size.
//! 8. **Verdict** ([`verdict`]): the closure of the gap in one sentence with its doubts (an
//!    answer in the loop that stops short in sample of what the noise leaves closes at least
//!    what it says, [`loop_answer::short_of_noise`]), the
//!    user's simulation split into parameter and structure parts, the report's series.
//!
//! The second estimation capture serves the amplitude analysis only; the fits use the
//! first. A capture with gaps is given as its gap-free segments ([`diagnose_segments`]):
//! the fits take the first estimation capture's segments as separate experiments, the gap
//! metric simulates every validation segment from its own start and pools one sum of
//! squares over them ([`metric::score_segments`]).
//!
//! [`DiagnoseRequest::progress`] is told of each stage and candidate as it starts and ends
//! ([`progress`]); the command line draws it as progress lines on a terminal.

mod evidence;
mod fits;
pub mod in_loop;
mod inputs;
mod linearity;
pub mod locate;
mod loop_answer;
pub mod metric;
mod nominal;
pub mod progress;
mod select;
pub mod series;
mod size;
mod starts;
mod table;
mod units;
mod verdict;

#[cfg(test)]
mod tests;

use std::collections::BTreeMap;
use std::time::Instant;

use serde::Serialize;
use thiserror::Error;

use crate::data::{Dataset, IdData};
use crate::ident::frf::{AmplitudeTrend, Linearity, TrendKind};
use crate::ident::grey_box::DEFAULT_GEAR_RATIO;
use crate::ident::nonlinear::{NlError, NlOptions, NlRunError};
use crate::model::effects::Effect;
use crate::model::params::Plant;
use crate::model::spec::Structure;
use fits::{Fitter, Job};
use locate::{Band, Regions};
use metric::MetricError;
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
    /// smallest gain counted [FIT points]: significant when `mean − 2·SE` exceeds it (or the
    /// spread of the nominal's own refits, when larger: [`nominal::refit_spread`]). It stands
    /// for what the segments' spread does not see: a wrong model that absorbs a little of
    /// the nominal's misfit alike on every segment. 0.1: on the bench's rounds at
    /// `MIN_GAIN=0.1` (160 cases, 32 of them `none`, most with weak Coulomb friction in the
    /// background), no `none` case had a candidate above 0.02 beyond twice its error but a
    /// delay the excited lines reject, while effects of 0.13–0.38 points cleared 0.1 and not
    /// 0.3 (an extra mode, a ripple, two Coulomb frictions, and an effect of each of three
    /// pairs), which at 0.3 (stop 77) were answered `none`
    pub min_gain: f64,
    /// threads fitting candidates
    pub threads: usize,
    /// try pairs of effects
    pub pairs: bool,
    /// scored range starts this long into the validation record [s]
    pub skip_s: f64,
    /// periods dropped before the FRF analyses
    pub settle_periods: usize,
    /// low-pass every fit's residual at the top of the excited band
    /// ([`crate::ident::nonlinear::NlOptions::lowpass_hz`]): above it the measured torque
    /// and angle hold only the loop's reaction to the encoder's quantisation and the
    /// disturbance, which draws a fit from the measured torque towards the inverse
    /// controller
    pub band_limited: bool,
    /// options of every nonlinear fit; the diagnosis's default holds a parameter the data
    /// push against its bound out of the step ([`NlOptions::active_set`]): its fits sit on
    /// bounds often (a friction or a lag at nought, a range's edge), and clamped steps
    /// crawled there (a Coulomb diagnosis of three 24,000-row captures: 50.1 s of CPU;
    /// held, 25.5 s, the same answer)
    pub nl: NlOptions,
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        DiagnoseOptions {
            band_hz: metric::DEFAULT_BAND_HZ,
            tracking_hz: metric::DEFAULT_TRACKING_HZ,
            segments: 4,
            min_gain: 0.1,
            threads: 2,
            pairs: true,
            skip_s: 0.5,
            settle_periods: 1,
            band_limited: true,
            nl: NlOptions {
                active_set: true,
                ..NlOptions::default()
            },
        }
    }
}

impl DiagnoseOptions {
    /// Samples of `data` before its scored range: [`DiagnoseOptions::skip_s`], at most a
    /// quarter of the record.
    pub fn skip_of(&self, data: &IdData) -> usize {
        ((self.skip_s / data.ts).round() as usize).min(data.len() / 4)
    }

    /// The measured side of the gap metric on `data` as these options score it: their band,
    /// their skip, their slow torque input ([`metric::Measured`]).
    pub fn measured(&self, data: &IdData) -> metric::Measured {
        metric::Measured::new(data, self.band_hz, self.skip_of(data))
            .with_tracking(self.tracking_hz)
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

impl NominalError {
    /// Whether every start failed on a record whose torque holds the angle like a spring to
    /// the frame ([`NlError::NoInertia`] with `grounded`): the structure to try is the
    /// grounded mass.
    pub fn suggests_grounded(&self) -> bool {
        !self.attempts.is_empty()
            && self.attempts.iter().any(|(_, e)| {
                matches!(
                    e,
                    CandidateError::Fit(NlRunError::Estimation(NlError::NoInertia {
                        grounded: true
                    })) | CandidateError::AutomaticToo(NlRunError::Estimation(
                        NlError::NoInertia { grounded: true }
                    ))
                )
            })
    }
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
    /// mean and standard error of the gain of the gap metric over the answer's model
    /// (negative: below it) [FIT points], in the controller's loop when the answer was
    /// scored there; `None` for the answer itself, with no answer, or a failed fit
    #[serde(skip_serializing_if = "Option::is_none")]
    pub over_answer: Option<(f64, f64)>,
    /// mean and standard error of the gain of the answer with this effect added over the
    /// answer alone [FIT points]: the pair's test (stage 4), on the open-loop metric, when
    /// the answer is a single that led that pair; `None` otherwise. What the effect adds to
    /// the answer, where [`Candidate::over_answer`] is what it does in the answer's place
    #[serde(skip_serializing_if = "Option::is_none")]
    pub with_answer: Option<(f64, f64)>,
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
    /// how far the FRF at the excited lines moves between the two captures against its
    /// noise ([`crate::ident::frf::bla_change`]; both captures periodic, on the same lines)
    pub bla: Option<crate::ident::frf::BlaChange>,
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
        let trends = self.trends();
        match &self.bla {
            Some(b) => format!(
                "{trends}; the best linear approximation {} between the two captures (the \
                 median ratio of its change to its noise over {} lines is {:.2}, {:.2} for a \
                 linear joint)",
                if b.changed { "moves" } else { "does not move" },
                b.lines,
                b.median_ratio,
                b.linear_median
            ),
            None => trends,
        }
    }

    /// The gap's and the distortion's trends of [`Amplitude::summary`].
    fn trends(&self) -> String {
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
    /// the nominal's gap metric on the (first) estimation capture, in-sample [%] (NaN:
    /// it did not simulate there)
    pub fit_nominal_est: f64,
    /// why no effect is named though the candidates were scored: the nominal every effect
    /// is measured against is not to be trusted (`none` otherwise)
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refused: Option<String>,
    /// the nominal's toolbox FIT of `θ_m` on the validation capture [%]
    pub fit_nominal_angle_val: f64,
    /// the nominal's structure values, lag and offset
    pub nominal_parameters: BTreeMap<String, ParamValue>,
    /// the best model's gap metric (the nominal's when `best` is `none`) [%]
    pub fit_augmented_val: f64,
    /// share of the gap `100 − fit_nominal_val` the best closes [-]
    pub gap_closed_share: f64,
    /// the gap metric the noise alone leaves a model on the validation capture [%]: the
    /// measured velocity's variance from period to period (the sensors' noise and the
    /// process disturbance, which no model driven by the reference repeats;
    /// [`metric::Measured::noise_fit`]); `None` without two whole periods
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fit_noise_val: Option<f64>,
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
/// separate experiments ([`crate::ident::nonlinear::identify_segments`], the linear start on the FRF averaged over
/// them, [`crate::ident::nonlinear::linear_start_segments`]); the gap metric simulates every validation segment
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
    let held = Prepared::of(est, val, req, false)?;
    let fitter = held.fitter();
    // the nominal and the singles, fitted together on the threads
    let mut jobs: Vec<Job<'_>> = vec![(Vec::new(), None)];
    jobs.extend(held.rec.candidates.iter().map(|e| (vec![*e], None)));
    let mut results = fitter.fit_all(&jobs).into_iter();
    let first = results.next().expect("the nominal job");
    let results: Vec<_> = results.collect();
    let mut warnings = held.warnings.clone();
    let nominal = nominal::settle(&fitter, first, &results, &mut warnings)?;
    // a nominal that came apart: every fit again from the structure fitted to the record's
    // own FRF instead of the frequency-domain start
    let welch;
    let (fitter, nominal, results, warnings) =
        match nominal::came_apart(&nominal.fit, held.starts.sticks)
            .and_then(|why| Some((why, fits::longest(&held.rec.est_data)?)))
            .and_then(|(why, d)| {
                Some((
                    why,
                    crate::ident::fit::welch_structure(d, req.structure, req.r)?,
                ))
            }) {
            Some((why, structure)) => {
                welch = held.starts.with_structure(structure);
                let again = Fitter {
                    req: fitter.req,
                    rec: fitter.rec,
                    starts: &welch,
                    floor: fitter.floor.clone(),
                };
                match nominal::restarted(&again, &jobs, &held.warnings, &why) {
                    Some((n, r, w)) => (again, n, r, w),
                    None => (fitter, nominal, results, warnings),
                }
            }
            None => (fitter, nominal, results, warnings),
        };
    if !nominal.fit.holds_no_lag() {
        return Ok(answer(&fitter, nominal, results, warnings, t0));
    }
    // the data ask for less delay than holding the input adds: its nominal again, on the
    // input taken as sampled, and the singles refitted on it when that scores higher
    let s = inputs::SampledInput::of(est, val);
    let est_s: Vec<&[Dataset]> = s.est.iter().map(Vec::as_slice).collect();
    let Ok(sampled) = Prepared::of(&est_s, &s.val, req, true) else {
        return Ok(answer(&fitter, nominal, results, warnings, t0));
    };
    let s_fitter = sampled.fitter();
    let mut s_warnings = sampled.warnings.clone();
    let in_sample = |f: &Fitter<'_>, n: &fits::Fitted| {
        f.in_sample(&metric::DrivenModel::of_fit(&n.fit))
            .unwrap_or(f64::NAN)
    };
    let s_nominal = nominal::settle(&s_fitter, s_fitter.fit(&jobs[0]), &[], &mut s_warnings);
    let (held_est, s_nominal) = (in_sample(&fitter, &nominal), s_nominal.ok());
    match s_nominal.map(|n| (in_sample(&s_fitter, &n), n)) {
        Some((s_est, s_nominal)) if s_est > held_est => {
            s_warnings.insert(0, inputs::SampledInput::note(held_est, s_est));
            let results = s_fitter.fit_all(&jobs[1..]);
            Ok(answer(&s_fitter, s_nominal, results, s_warnings, t0))
        }
        _ => Ok(answer(&fitter, nominal, results, warnings, t0)),
    }
}

/// Stage 0 on the records as given or with their input taken as sampled
/// ([`inputs::SampledInput`]): the checked records, the fits' options, the linear starts
/// and the notes so far.
struct Prepared<'a> {
    rec: inputs::Records<'a>,
    req: DiagnoseRequest,
    starts: starts::LinearStarts,
    warnings: Vec<String>,
}

impl<'a> Prepared<'a> {
    /// Stage 0 on `est` and `val` (`sampled`: their input taken as samples of a signal,
    /// whose nominal starts with no current-loop lag).
    fn of(
        est: &'a [&'a [Dataset]],
        val: &'a [Dataset],
        req: &DiagnoseRequest,
        sampled: bool,
    ) -> Result<Prepared<'a>, DiagnoseError> {
        let mut warnings = Vec::new();
        let rec = inputs::prepare(est, val, req, &mut warnings)?;
        let req = inputs::fit_options(req, &rec);
        let mut starts = starts::linear_starts(&rec, &req, &mut warnings);
        if sampled {
            starts.lag_start = Some(0.0);
        }
        Ok(Prepared {
            rec,
            req,
            starts,
            warnings,
        })
    }

    /// The fitter of these records, at the option's floor.
    fn fitter(&self) -> Fitter<'_> {
        Fitter {
            req: &self.req,
            rec: &self.rec,
            starts: &self.starts,
            floor: fits::Floor::of(&self.req),
        }
    }
}

/// Stages 3 to 7 from the settled `nominal` and the singles' fits `results`: the answer and
/// its verdict; `t0` the diagnosis's start.
fn answer(
    fitter: &Fitter<'_>,
    nominal: fits::Fitted,
    results: Vec<Result<fits::Fitted, CandidateError>>,
    mut warnings: Vec<String>,
    t0: Instant,
) -> (Diagnosis, DiagnosisSeries) {
    let nominal = nominal::from_singles(fitter, nominal, &results, &mut warnings);
    let results = select::nested_refits(fitter, &nominal, results);
    let fitter = Fitter {
        floor: nominal::refit_spread(fitter, &nominal, &results),
        ..*fitter
    };
    let ev = evidence::gather(&fitter, &nominal);
    let mut answer = select::singles(&fitter, &nominal, &ev, results);
    let top = answer.singles.first().and_then(|s| s.1.as_ref());
    let trust = nominal::trust(&fitter, &nominal, top);
    // a nominal not to be trusted is no base to build an answer on
    let in_loop = if trust.1.is_none() {
        select::pairs(&fitter, &ev, &mut answer, &mut warnings);
        // a pair is refined before its effects are judged apart, a single after
        let pair = answer.pair.is_some();
        if pair {
            select::polish_answer(&fitter, &nominal, &ev, &mut answer, &mut warnings);
        }
        select::reduce(&fitter, &nominal, &ev, &mut answer, &mut warnings);
        if !pair || answer.pair.is_none() {
            select::polish_answer(&fitter, &nominal, &ev, &mut answer, &mut warnings);
        }
        loop_answer::rescore(&fitter, &nominal, &ev, &mut answer, &mut warnings)
    } else {
        None
    };
    verdict::conclude(&fitter, nominal, trust, ev, answer, in_loop, warnings, t0)
}
