//! What `jointid fit` asks for ([`FitRequest`]: the model, where and how to fit and judge
//! it) and the records it is fitted to ([`FitRecords`]), with the checks that need no fit:
//! the request itself ([`FitRequest::check`], before any data are read), the validation
//! record's sample rate ([`check_same_rate`]) and the residual tests' lags against a
//! record ([`check_lags`]).
// Units in brackets (`[s]`, `[Hz]`, `[%]`) are not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

use thiserror::Error;

use super::FitOptions;
use crate::data::{fmt_sig, same_rate, Dataset, Detrend, Prep};
use crate::ident::grey_box::Output;
use crate::ident::nonlinear::{NlFit, NlOptions, NlRequest, NlRunError, NlStart};
use crate::model::spec::Family;

/// Where a linear model is fitted (`--domain`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Domain {
    /// the frequency domain for a model without Coulomb friction on periodic data, else
    /// the time domain
    #[default]
    Auto,
    /// the FRF at the excited lines (periodic data)
    Frequency,
    /// output error on the time record
    Time,
}

/// What only the nonlinear fit reads (`--fix`, the keys given in `--effect`, `--start`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct NlInputs {
    /// values held by name: a structure's parameter, `tau_c`, `offset` or an effect's key
    /// [SI]
    pub fixed: Vec<(String, f64)>,
    /// per effect (in the order of [`crate::model::spec::ModelSpec::effects`]), keys given
    /// a start value [SI]
    pub given: Vec<Vec<(String, f64)>>,
    /// a previous fit of the same model to start from instead of the automatic start
    pub start: Option<NlFit>,
}

/// What `jointid fit` asks for: the model and how to fit and judge it (the records come
/// apart, [`FitRecords`]).
#[derive(Clone, Debug, PartialEq)]
pub struct FitRequest {
    /// the model ([`FitOptions::spec`]) and the linear estimators' options
    pub options: FitOptions,
    /// detrending and decimation of the linear fits (the nonlinear fit takes none)
    pub prep: Prep,
    /// where a linear model is fitted
    pub domain: Domain,
    /// whole periods dropped as transient before an FRF
    pub settle_periods: usize,
    /// lags of the residual tests (every record they run on needs more than twice as many
    /// samples)
    pub lags: usize,
    /// without a validation record: estimate on this first fraction of the estimation
    /// record (0 < f < 1) and validate on the rest
    pub estimation_fraction: Option<f64>,
    /// the nonlinear fit's own inputs (refused for a linear model)
    pub nonlinear: NlInputs,
    /// compute the figures' data ([`super::LinearFit::compare`], [`super::LinearFit::bode`],
    /// [`super::NonlinearFit::velocity`]); they cost simulations
    pub figures: bool,
}

impl FitRequest {
    /// The request for `options` with the defaults of `jointid fit`: no preparation,
    /// [`Domain::Auto`], one settling period, [`crate::ident::validate::DEFAULT_LAGS`],
    /// no split, no figures.
    pub fn new(options: FitOptions) -> Self {
        FitRequest {
            options,
            prep: Prep {
                decimate: 1,
                detrend: Detrend::None,
            },
            domain: Domain::Auto,
            settle_periods: 1,
            lags: crate::ident::validate::DEFAULT_LAGS,
            estimation_fraction: None,
            nonlinear: NlInputs::default(),
            figures: false,
        }
    }

    /// Checks what can be checked before any data are read: that the nonlinear inputs
    /// come with a model with effects, and that such a model is asked for in a way the
    /// nonlinear engine fits (a physical structure, the motor angle, the raw record, no
    /// frequency-domain delay, a positive gear ratio, held names of its parameters).
    ///
    /// # Errors
    /// [`RequestError`] naming the flag.
    pub fn check(&self) -> Result<(), RequestError> {
        self.nl_request().map(|_| ())
    }

    /// The nonlinear engine's request of a model with effects (`None` for a linear model),
    /// checked ([`FitRequest::check`]).
    pub(super) fn nl_request(&self) -> Result<Option<NlRequest>, RequestError> {
        let spec = &self.options.spec;
        let nl = &self.nonlinear;
        if !spec.nonlinear() {
            if !nl.fixed.is_empty() || nl.start.is_some() {
                return Err(RequestError::NonlinearInputs);
            }
            return Ok(None);
        }
        let Family::Physical(structure) = spec.family else {
            return Err(RequestError::EffectOnBlackBox);
        };
        let refuse = |cond: bool, e: RequestError| if cond { Err(e) } else { Ok(()) };
        refuse(spec.coulomb, RequestError::CoulombWithEffects)?;
        refuse(
            self.domain == Domain::Frequency,
            RequestError::FrequencyWithEffects,
        )?;
        refuse(
            self.options.output != Output::Angle,
            RequestError::VelocityWithEffects,
        )?;
        refuse(
            self.prep.decimate > 1 || self.prep.detrend != Detrend::None,
            RequestError::PreparedWithEffects,
        )?;
        refuse(spec.delay.is_some(), RequestError::DelayWithEffects)?;
        let r = self.options.r;
        refuse(!(r.is_finite() && r > 0.0), RequestError::GearRatio(r))?;
        let req = NlRequest {
            held_tau_c: spec.current_loop_tau,
            fixed: nl.fixed.clone(),
            given: nl.given.clone(),
            options: NlOptions::default(),
            start: match &nl.start {
                Some(prev) => NlStart::Previous(Box::new(prev.clone())),
                None => NlStart::Automatic,
            },
            ..NlRequest::new(structure, r, spec.effects.clone().unwrap_or_default())
        };
        req.check().map_err(RequestError::Nonlinear)?;
        Ok(Some(req))
    }
}

/// The records of [`super::run`].
#[derive(Clone, Copy, Debug)]
pub struct FitRecords<'a> {
    /// the estimation record: one, or the gap-free segments of one capture
    /// (`--segment all`), in time order
    pub estimation: &'a [Dataset],
    /// their segment numbers (from 1, as `jointid info` lists them)
    pub numbers: &'a [usize],
    /// the validation record, at the estimation record's sample rate
    pub validation: Option<&'a Dataset>,
}

/// A request that cannot be fitted, found before any data are read
/// ([`FitRequest::check`]).
#[derive(Debug, Error)]
pub enum RequestError {
    /// `--fix` or `--start` without an effect
    #[error(
        "--fix and --start belong to the nonlinear fit: attach an effect with --effect \
         NAME[:key=value,...] or use --model nonlinear-two-mass"
    )]
    NonlinearInputs,
    /// effects on a black box
    #[error(
        "--effect attaches to a physical model: --model rigid, two-mass, three-mass or \
         four-mass"
    )]
    EffectOnBlackBox,
    /// the linear engine's Coulomb friction with effects
    #[error(
        "--friction coulomb is the linear engine's rigid model; with effects use --effect \
         coulomb_friction"
    )]
    CoulombWithEffects,
    /// effects in the frequency domain
    #[error(
        "a model with effects is fitted in the time domain (--domain frequency is linear only)"
    )]
    FrequencyWithEffects,
    /// effects on a velocity output
    #[error("the nonlinear fit needs the motor angle as output (--output-kind angle)")]
    VelocityWithEffects,
    /// effects on a decimated or detrended record
    #[error(
        "the nonlinear fit runs on the raw record at the capture rate: --decimate and \
         --detrend are not available with effects"
    )]
    PreparedWithEffects,
    /// the frequency-domain delay with effects
    #[error("--delay belongs to the frequency-domain fit; with effects use --effect time_delay")]
    DelayWithEffects,
    /// a gear ratio that is not finite and positive
    #[error("--gear-ratio {0}: must be finite and > 0")]
    GearRatio(f64),
    /// the nonlinear engine's request (a held name that is no parameter, the lag's range)
    #[error(transparent)]
    Nonlinear(NlRunError),
}

/// `--lags` against a record the residual tests run on ([`check_lags`]).
#[derive(Debug, Error)]
#[error(
    "--lags {lags}: the residual tests on {what} have {samples} samples, they need more than \
     2 × {lags} = {}", 2 * lags
)]
pub struct LagsError {
    /// the lags asked for
    pub lags: usize,
    /// the record (`FILE`, `one period of FILE`)
    pub what: String,
    /// its samples
    pub samples: usize,
}

/// `--lags M` against a record of `samples` samples that the residual tests run on
/// (`what`): they need more than 2M.
///
/// # Errors
/// [`LagsError`] when the record is too short.
pub fn check_lags(lags: usize, what: &str, samples: usize) -> Result<(), LagsError> {
    if samples > 2 * lags {
        return Ok(());
    }
    Err(LagsError {
        lags,
        what: what.to_string(),
        samples,
    })
}

/// A record sampled at another rate than the estimation record ([`check_same_rate`]).
#[derive(Debug, Error)]
#[error(
    "{record}: sampled at {} Hz, {estimation} at {} Hz; the validation record needs the \
     estimation record's sample rate",
    fmt_sig(*record_hz, 6),
    fmt_sig(*estimation_hz, 6)
)]
pub struct SampleRateDiffers {
    /// the other record
    pub record: String,
    /// its sample rate [Hz]
    pub record_hz: f64,
    /// the estimation record
    pub estimation: String,
    /// its sample rate [Hz]
    pub estimation_hz: f64,
}

/// `other` (a validation record) has the sample interval of `estimation`
/// ([`crate::data::same_rate`]): a model is simulated at the rate it was fitted at.
///
/// # Errors
/// [`SampleRateDiffers`] naming both records and their rates.
pub fn check_same_rate(estimation: &Dataset, other: &Dataset) -> Result<(), SampleRateDiffers> {
    let (a, b) = (estimation.data.ts, other.data.ts);
    if same_rate(a, b) {
        return Ok(());
    }
    Err(SampleRateDiffers {
        record: other.name.clone(),
        record_hz: 1.0 / b,
        estimation: estimation.name.clone(),
        estimation_hz: 1.0 / a,
    })
}
