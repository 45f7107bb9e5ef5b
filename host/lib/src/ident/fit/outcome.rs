//! What `jointid fit` returns ([`FitOutcome`]: the model, its headline FIT on each record,
//! the residual tests, the segments, warnings, notes and the figures' data) and why it
//! may fail ([`FitRunError`]).
// Units in brackets (`[s]`, `[Hz]`, `[%]`) are not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

use std::fmt;

use serde::Serialize;
use thiserror::Error;

use super::figures::{BodeFigure, CompareRecord, Compared, FigureError, VelocityFigure};
use super::request::{LagsError, RequestError, SampleRateDiffers};
use super::{FitError, Fitted};
use crate::data::segment::MIN_SEGMENT_SAMPLES;
use crate::data::InputTaken;
use crate::ident::frf::FrfError;
use crate::ident::nonlinear::{NlError, NlRun, NlRunError};
use crate::ident::ss::Resonances;
use crate::ident::validate::{ValidateError, Validation};
use crate::model::spec::Structure;

/// Name of the FIT a nonlinear fit reports first (the velocity FIT with the simulator's
/// exact laws, [`crate::ident::nonlinear::NlValidation::velocity_fit_percent`]).
pub const NL_FIT_NAME: &str = "velocity FIT [%] (interval-mean motor velocity through the \
     high-pass prefilter, simulator's exact laws)";

/// The FIT a fit reports first: one named headline on each record, the others only
/// beside it.
#[derive(Clone, Debug, PartialEq)]
pub struct FitFigures {
    /// its definition ([`crate::ident::validate::FIT_NAME`],
    /// [`crate::ident::sml::PERIODIC_FIT_NAME`], [`super::VELOCITY_FIT_NAME`],
    /// [`NL_FIT_NAME`])
    pub name: &'static str,
    /// its short name: `toolbox`, `periodic` or `velocity`
    pub metric: &'static str,
    /// on the estimation record(s), pooled over the segments [%]
    pub estimation: f64,
    /// on the validation record [%]
    pub validation: Option<f64>,
    /// the toolbox FIT of the output on estimation and validation records when the
    /// velocity FIT is the headline [%] (the drift of the rigid-body integrator dominates
    /// it)
    pub toolbox: Option<(f64, Option<f64>)>,
    /// why the FIT shown is not the one the fit's domain reports, and what it measures
    /// (a frequency-domain fit whose validation record holds no whole periods)
    pub note: Option<String>,
}

/// One estimation segment and the model's FIT on it alone (`fit --json`'s `segments`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SegmentJson {
    /// number of the segment (from 1, as `jointid info` lists them)
    pub segment: usize,
    /// its samples at the capture rate
    pub samples: usize,
    /// the model's FIT on this segment alone, the report's FIT definition [%] (`None` when
    /// it cannot be computed: a segment with fewer than two steady-state periods for the
    /// periodic FIT)
    pub fit: Option<f64>,
}

impl fmt::Display for SegmentJson {
    /// `segment 2 (15216 samples): 98.12`, or why its FIT is not computed
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.fit {
            Some(fit) => write!(
                f,
                "segment {} ({} samples): {fit:.2}",
                self.segment, self.samples
            ),
            None => write!(
                f,
                "segment {} ({} samples): not computed (fewer than two steady-state periods)",
                self.segment, self.samples
            ),
        }
    }
}

/// A linear model as `jointid fit` reports it.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearFit {
    /// the model
    pub fitted: Fitted,
    /// its lightly damped resonances and anti-resonances
    pub resonances: Resonances,
    /// residual tests on the estimation record (on one steady-state period and the line
    /// residuals for a frequency-domain fit)
    pub tests: Validation,
    /// residual tests on the validation record
    pub validation_tests: Option<Validation>,
    /// duration of the estimation record named [s] (the step response's horizon at most)
    pub record_s: f64,
    /// what `compare.svg` draws and its records (with [`super::FitRequest::figures`])
    pub compare: Option<(Compared, Vec<CompareRecord>)>,
    /// the Bode plot over the estimation record's FRF (with [`super::FitRequest::figures`])
    pub bode: Option<BodeFigure>,
}

/// A model with effects as `jointid fit` reports it.
#[derive(Clone, Debug, PartialEq)]
pub struct NonlinearFit {
    /// its mechanical structure
    pub structure: Structure,
    /// the fit (its start's steps, warnings, options, method) and its FITs
    pub run: NlRun,
    /// the motor velocity measured against the model's on the validation record, else
    /// the estimation record (with [`super::FitRequest::figures`])
    pub velocity: Option<VelocityFigure>,
}

/// The fitted model, linear or with effects.
#[derive(Clone, Debug, PartialEq)]
pub enum FittedModel {
    /// black box or physical model ([`Fitted`])
    Linear(Box<LinearFit>),
    /// a physical model with effects ([`crate::ident::nonlinear::NlFit`])
    Nonlinear(Box<NonlinearFit>),
}

/// Everything `jointid fit` prints, saves and draws.
#[derive(Clone, Debug, PartialEq)]
pub struct FitOutcome {
    /// the model
    pub model: FittedModel,
    /// the estimation record the fit is named after (the longest segment)
    pub name: String,
    /// the validation record's name (`FILE (last 30 %)` for a split record)
    pub validation_name: Option<String>,
    /// sample interval of the records compared [s]
    pub ts: f64,
    /// estimation samples (after preparation; summed over the segments)
    pub samples: usize,
    /// the segments fitted, each with the headline FIT on it alone
    pub segments: Vec<SegmentJson>,
    /// the headline FIT
    pub fit: FitFigures,
    /// what the estimators reported that makes the fit doubtful
    pub warnings: Vec<String>,
    /// what the user should know about the records used (segments left out, how they
    /// are used), each `NAME: ...`
    pub notes: Vec<String>,
    /// wall time of the fit alone [s]
    pub seconds: f64,
    /// how the records' input samples were read: held as they are, or taken as sampled
    /// (a measured analog input) when the fit with no lag and no delay scored higher so
    pub input: InputTaken,
}

/// Why [`super::run`] failed.
#[derive(Debug, Error)]
pub enum FitRunError {
    /// the request cannot be fitted
    #[error(transparent)]
    Request(#[from] RequestError),
    /// no estimation record
    #[error("no segment to fit")]
    NoSegment,
    /// the validation record's sample rate
    #[error("--validation {0}")]
    ValidationRate(#[source] SampleRateDiffers),
    /// a split of several segments
    #[error(
        "--estimation-fraction splits one record; {count} segments ({list}) were selected: \
         give --validation, or --segment longest or N"
    )]
    FractionOfSegments {
        /// segments selected
        count: usize,
        /// their numbers
        list: String,
    },
    /// Coulomb friction in the frequency domain
    #[error(
        "--friction coulomb is nonlinear: the rigid model with Coulomb friction is fitted in \
         the time domain"
    )]
    CoulombInFrequency,
    /// a split record in the frequency domain
    #[error(
        "--domain frequency takes the whole record: give --validation instead of \
         --estimation-fraction"
    )]
    FrequencyOfFraction,
    /// the frequency domain on data without whole periods
    #[error("{name}: --domain frequency needs periodic data: {source}")]
    NotPeriodic {
        /// the estimation record
        name: String,
        /// why its FRF failed
        #[source]
        source: FrfError,
    },
    /// the averaged FRF, but no segment for the residual tests
    #[error(
        "{name}: the FRF averages the segments, but no segment alone holds two steady-state \
         periods for the residual tests; give --domain time"
    )]
    NoSteadySegment {
        /// the estimation record
        name: String,
    },
    /// every segment too short for a time-domain fit
    #[error("{name}: no segment has {MIN_SEGMENT_SAMPLES} samples or more for a time-domain fit")]
    NoUsableSegment {
        /// the estimation record
        name: String,
    },
    /// `--lags` against a record
    #[error(transparent)]
    Lags(#[from] LagsError),
    /// the linear fit or its evaluation on a record
    #[error("{name}: {source}")]
    Record {
        /// the record
        name: String,
        /// what failed
        #[source]
        source: FitError,
    },
    /// the periodic steady state of a record
    #[error("{name}: {source}")]
    SteadyState {
        /// the record
        name: String,
        /// what failed
        #[source]
        source: FrfError,
    },
    /// the residual tests on a record's steady state
    #[error("{name}: {source}")]
    Tests {
        /// the record
        name: String,
        /// what failed
        #[source]
        source: ValidateError,
    },
    /// a record of `compare.svg`
    #[error(transparent)]
    Figure(#[from] FigureError),
    /// the nonlinear engine, on no particular record (a start of another model)
    #[error(transparent)]
    Nonlinear(Box<NlRunError>),
    /// the nonlinear engine on a record (its start, fit or validation)
    #[error("{record}: {source}")]
    NonlinearOn {
        /// the record
        record: String,
        /// what failed
        #[source]
        source: Box<NlRunError>,
    },
    /// the velocity figure's simulation
    #[error(transparent)]
    VelocityFigure(Box<NlError>),
}
