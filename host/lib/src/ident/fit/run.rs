//! `jointid fit` as one call ([`run`]): from the selected records and a [`FitRequest`] to
//! a [`FitOutcome`] that holds everything the command prints, saves and draws.
//!
//! Which path a request takes (ARCHITECTURE.md, "Which domain fits what"):
//! - a model with effects ([`crate::model::spec::ModelSpec::nonlinear`]) goes to the
//!   nonlinear engine ([`crate::ident::nonlinear::run`]: on periodic data the
//!   frequency-domain linear start, output error on the motor velocity, validation with
//!   the simulator's exact laws); several segments are separate experiments
//!   ([`usable_segments`]);
//! - a linear model on periodic data ([`Domain::Auto`]) or with [`Domain::Frequency`]
//!   is fitted to the FRF at the excited lines ([`fit_frequency_domain`]; with several
//!   segments the FRF averaged over their whole periods) and judged by the periodic FIT
//!   ([`PERIODIC_FIT_NAME`]) and the line residuals;
//! - otherwise in the time domain ([`fit_prepared`], [`fit_prepared_segments`]), judged
//!   by the toolbox FIT, or by the velocity FIT for a model fitted on the motor velocity
//!   ([`FitMetric::Velocity`]).
//!
//! Why here: the command line only parses, calls, prints and writes; the paths, their
//! checks and their figures are one library function that tests can call with known
//! truth. Nothing here prints: what the user should know comes back as
//! [`FitOutcome::notes`] and [`FitFigures::note`].
// Units in brackets (`[s]`, `[Hz]`, `[%]`) are not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

use std::time::Instant;

use super::figures::{simulated_record, velocity_record, CompareRecord, Compared, VelocityFigure};
use super::outcome::{
    FitFigures, FitOutcome, FitRunError, FittedModel, LinearFit, NonlinearFit, SegmentJson,
    NL_FIT_NAME,
};
use super::request::{
    check_lags, check_same_rate, Domain, FitRecords, FitRequest, LagsError, RequestError,
};
use super::{
    below_frf, bode_figure, default_f_min, fit_frequency_domain, fit_prepared,
    fit_prepared_segments, FitData, FitError, FitMetric, Fitted, VELOCITY_FIT_NAME,
};
use crate::data::segment::{longest_segment, segment_list, usable_segments, FITTING_NOTES};
use crate::data::{Dataset, IdData, InputTaken};
use crate::ident::frf::{analyze_dataset, analyze_segments, FrfAnalysis, FrfError};
use crate::ident::nonlinear::{self, NlData, NlRequest, NlRunError};
use crate::ident::sml::{self, PERIODIC_FIT_NAME};
use crate::ident::ss::Resonances;
use crate::ident::validate::{validate_periodic, Validation, FIT_NAME};
use crate::model::spec::Family;

/// Fits the model of `req` to `data` as `jointid fit` does (module documentation):
/// checks the request, the validation record's rate and the lags before the work, takes
/// the path the model and the data call for, and returns the model, its FITs on
/// estimation and validation records, the residual tests, the segments, the warnings and
/// notes, and (with [`FitRequest::figures`]) the figures' data.
///
/// # Errors
/// [`FitRunError`]: the request, the records, or an estimator.
pub fn run(req: &FitRequest, data: FitRecords<'_>) -> Result<FitOutcome, FitRunError> {
    let held = run_held(req, data)?;
    if !drive_free_in_frequency(req, &held) {
        return Ok(held);
    }
    // no lag and no delay where both were free: the input is tried as sampled, as the
    // time-domain path does ([`run_nonlinear`]), and kept when that fit holds neither
    // either and its FIT on the estimation record is higher. A fit on the input taken as
    // sampled that grows a lag asks for the hold's half sample back: the input is held
    // (seed 001, linear two-mass: sampled, a lag of 0.26 ms at Ts = 0.5 ms and the SML
    // cost 198.1 against 198.5 held, the same to the noise, while its periodic FIT read
    // 81.1 % against 80.8 %)
    let est: Vec<Dataset> = data
        .estimation
        .iter()
        .map(Dataset::input_as_sampled)
        .collect();
    let val = data.validation.map(Dataset::input_as_sampled);
    let records = FitRecords {
        estimation: &est,
        numbers: data.numbers,
        validation: val.as_ref(),
    };
    match run_held(req, records) {
        Ok(mut s)
            if drive_free_in_frequency(req, &s)
                && s.fit.name == held.fit.name
                && s.fit.estimation > held.fit.estimation =>
        {
            let note = nonlinear::sampled_input_note(
                "the FIT on the estimation record",
                held.fit.estimation,
                s.fit.estimation,
            );
            s.warnings.insert(0, note);
            s.input = InputTaken::Sampled;
            Ok(s)
        }
        _ => Ok(held),
    }
}

/// Whether `out` is a linear physical model fitted in the frequency domain that holds
/// neither a current-loop lag nor a transport delay (left out, or under
/// [`nonlinear::UNRESOLVED_LAG`] of a sample) where the request left both free. Its input
/// held over each sample interval then asks for no more delay than the hold adds, or
/// less: a measured analog input that moves between its samples, which the hold delays by
/// half a sample ([`IdData::input_as_sampled`]).
/// Bench: a grounded mass driven by a band-limited force at 610 Hz, lines to 200 Hz:
/// held, a periodic FIT of 78.3 % at 338,000 times the noise's cost; taken as sampled,
/// 96.1 % with a delay of 0.002 samples; the same mass driven by a held force, 99.9 % held
/// and 99.4 % taken as sampled.
fn drive_free_in_frequency(req: &FitRequest, out: &FitOutcome) -> bool {
    let spec = &req.options.spec;
    let FittedModel::Linear(l) = &out.model else {
        return false;
    };
    let nought = |name: &str| {
        l.fitted
            .params
            .iter()
            .find(|p| p.name == name)
            .is_none_or(|p| p.value < nonlinear::UNRESOLVED_LAG * l.fitted.ts)
    };
    // the time-domain grey box neglects the lag by design
    matches!(spec.family, Family::Physical(_))
        && l.fitted.in_frequency_domain()
        && spec.current_loop_tau.is_none()
        && spec.delay.is_none()
        && nought("tau_c")
        && nought("delay")
}

/// [`run`] with the input held as it is.
fn run_held(req: &FitRequest, data: FitRecords<'_>) -> Result<FitOutcome, FitRunError> {
    let nl = req.nl_request()?;
    let segs = data.estimation;
    if segs.is_empty() {
        return Err(FitRunError::NoSegment);
    }
    let ds = longest_segment(segs);
    if let Some(v) = data.validation {
        check_same_rate(ds, v).map_err(FitRunError::ValidationRate)?;
    }
    if segs.len() > 1 && req.estimation_fraction.is_some() {
        return Err(FitRunError::FractionOfSegments {
            count: segs.len(),
            list: segment_list(data.numbers),
        });
    }
    if let Some(nl) = nl {
        return run_nonlinear(req, nl, data);
    }
    // the single record's FRF analysis before its preparation copies it: its period
    // detection's transform and the copies are then never held at once (item 9 of issue
    // 37: memory on large inputs); its errors still come after the preparation's
    let spec = &req.options.spec;
    let analysed = match (req.domain, req.estimation_fraction) {
        (Domain::Frequency | Domain::Auto, None) if segs.len() == 1 && !spec.coulomb => {
            Some(analyze_dataset(ds, req.settle_periods))
        }
        _ => None,
    };
    let prepare = |d: &IdData, name: &str| {
        FitData::new(d, req.prep).map_err(|source| FitRunError::Record {
            name: name.to_string(),
            source,
        })
    };
    let (est, val) = match (req.estimation_fraction, data.validation) {
        (Some(frac), _) => {
            // split at the capture rate, then prepare each part
            let (a, b) = ds.data.split(frac);
            let vn = format!("{} (last {:.0} %)", ds.name, 100.0 * (1.0 - frac));
            let b = prepare(&b, &vn)?;
            (prepare(&a, &ds.name)?, Some((b, vn)))
        }
        (None, Some(v)) => (
            prepare(&ds.data, &ds.name)?,
            Some((prepare(&v.data, &v.name)?, v.name.clone())),
        ),
        (None, None) => (prepare(&ds.data, &ds.name)?, None),
    };
    let val = val.as_ref().map(|(d, n)| Record { data: d, name: n });
    if segs.len() > 1 {
        return run_segments(req, segs, data.numbers, val, data.validation);
    }
    let periodic = match (req.domain, req.estimation_fraction, analysed) {
        (Domain::Time, _, _) => None,
        (Domain::Frequency, _, _) if spec.coulomb => return Err(FitRunError::CoulombInFrequency),
        (Domain::Frequency, Some(_), _) => return Err(FitRunError::FrequencyOfFraction),
        (Domain::Frequency, None, analysed) => Some(
            analysed
                .unwrap_or_else(|| analyze_dataset(ds, req.settle_periods))
                .map_err(|source| FitRunError::NotPeriodic {
                    name: ds.name.clone(),
                    source,
                })?,
        ),
        (Domain::Auto, None, analysed) if !spec.coulomb => analysed
            .unwrap_or_else(|| analyze_dataset(ds, req.settle_periods))
            .ok(),
        (Domain::Auto, _, _) => None,
    };
    if let Some(a) = &periodic {
        // a validation record that is not periodic (band-limited noise, say) is compared
        // in the time domain, and so is the estimation record then, so that both FITs
        // share one definition
        let vp = data
            .validation
            .map(|v| analyze_dataset(v, req.settle_periods));
        match (data.validation, &vp) {
            // residual tests on one period of the steady state
            (Some(v), Some(Ok(p))) => {
                check_lags(
                    req.lags,
                    &format!("one period of {}", ds.name),
                    a.layout.period,
                )?;
                check_lags(
                    req.lags,
                    &format!("one period of {}", v.name),
                    p.layout.period,
                )?;
            }
            (Some(_), _) => check_records_lags(req.lags, &ds.name, &est, val)?,
            (None, _) => {
                check_lags(
                    req.lags,
                    &format!("one period of {}", ds.name),
                    a.layout.period,
                )?;
            }
        }
        let frequency = Frequency {
            segs: std::slice::from_ref(ds),
            numbers: data.numbers,
            pooled: a,
            analysis: a,
            est: &est,
            val,
            val_ds: data.validation,
            val_analysis: vp,
        };
        return run_frequency_domain(req, frequency);
    }
    // a grounded mass has no free body for the grey-box start to read its inertia from
    // (the low-frequency response of a free mass): in the time domain it is fitted by the
    // nonlinear engine with no effect, as `--effect none` asks (Silverbox, measured: the
    // grey-box start refused it with "no positive rigid-body inertia")
    if spec.family == Family::Physical(crate::model::spec::Structure::Grounded) {
        let mut engine = req.clone();
        engine.options.spec.effects = Some(Vec::new());
        if let Ok(Some(nl)) = engine.nl_request() {
            return run_nonlinear(&engine, nl, data);
        }
    }
    check_records_lags(req.lags, &ds.name, &est, val)?;
    run_time_domain(req, ds, data.numbers[0], &est, val)
}

/// The time-domain path on one record (`number`, prepared as `est`; the prepared
/// validation record `val`): [`fit_prepared`], checked against the record's FRF when it
/// has one ([`below_frf`]), the toolbox FIT or the velocity FIT ([`time_domain_figures`]).
fn run_time_domain(
    req: &FitRequest,
    ds: &Dataset,
    number: usize,
    est: &FitData,
    val: Option<Record<'_>>,
) -> Result<FitOutcome, FitRunError> {
    let on = |name: &str| {
        let name = name.to_string();
        move |source| FitRunError::Record { name, source }
    };
    let t0 = Instant::now();
    let mut fitted = fit_prepared(est, &req.options).map_err(on(&ds.name))?;
    let seconds = t0.elapsed().as_secs_f64();
    if req.options.spec.coulomb {
        // nonlinear: no frequency-domain reference
    } else if let Some(w) = analyze_dataset(ds, req.settle_periods)
        .ok()
        .and_then(|a| below_frf(&a, ds.data.ts, &req.options, &fitted))
    {
        fitted.warnings.push(w.to_string());
    }
    let ev = fitted.evaluate_on(est, req.lags).map_err(on(&ds.name))?;
    let vv = on_validation(&fitted, val, req.lags)?;
    let fig = time_domain_figures(&fitted, std::slice::from_ref(est), val, (&ev, vv.as_ref()))
        .map_err(on(&ds.name))?;
    let on_velocity = fig.metric == "velocity";
    let compare = if req.figures {
        // the headline FIT's signals: the velocity's, else the output's
        let record =
            |d: &FitData, title: String, toolbox: f64, velocity: Option<f64>| match velocity {
                Some(fit) if on_velocity => velocity_record(&fitted, d, title, fit),
                _ => simulated_record(&fitted, d, title, toolbox),
            };
        let title = format!("estimation: {}", ds.name);
        let mut records = vec![record(est, title, ev.fit, Some(fig.estimation))?];
        if let (Some(v), Some(vv)) = (val, &vv) {
            let title = format!("validation: {}", v.name);
            records.push(record(v.data, title, vv.fit, fig.validation)?);
        }
        let compared = if on_velocity {
            Compared::Velocity
        } else {
            Compared::Simulated
        };
        Some((compared, records))
    } else {
        None
    };
    let prepared = est.prepared();
    let measured = Measured {
        segments: vec![SegmentJson {
            segment: number,
            samples: ds.data.len(),
            fit: Some(fig.estimation),
        }],
        validation_name: val.map(|v| v.name.to_string()),
        ts: prepared.ts,
        samples: prepared.len(),
        fit: fig.into_figures(),
        resonances: fitted.resonances(default_f_min(prepared.len(), prepared.ts)),
        tests: ev,
        validation_tests: vv,
        compare,
        notes: Vec::new(),
        seconds,
    };
    Ok(finish(req, ds, fitted, measured))
}

/// A prepared validation record and its name.
#[derive(Clone, Copy)]
struct Record<'a> {
    data: &'a FitData,
    name: &'a str,
}

/// What a linear path measured, for [`finish`].
struct Measured {
    segments: Vec<SegmentJson>,
    validation_name: Option<String>,
    ts: f64,
    samples: usize,
    fit: FitFigures,
    resonances: Resonances,
    tests: Validation,
    validation_tests: Option<Validation>,
    compare: Option<(Compared, Vec<CompareRecord>)>,
    notes: Vec<String>,
    seconds: f64,
}

/// The one end of the linear paths: the outcome named after `ds`, with its Bode plot when
/// the figures are asked for.
fn finish(req: &FitRequest, ds: &Dataset, fitted: Fitted, m: Measured) -> FitOutcome {
    let bode = req
        .figures
        .then(|| bode_figure(ds, req.settle_periods, &[&fitted]));
    FitOutcome {
        name: ds.name.clone(),
        validation_name: m.validation_name,
        ts: m.ts,
        samples: m.samples,
        segments: m.segments,
        fit: m.fit,
        warnings: fitted.warnings.clone(),
        notes: m.notes,
        seconds: m.seconds,
        input: InputTaken::Held,
        model: FittedModel::Linear(Box::new(LinearFit {
            resonances: m.resonances,
            tests: m.tests,
            validation_tests: m.validation_tests,
            record_s: ds.data.len() as f64 * ds.data.ts,
            compare: m.compare,
            bode,
            fitted,
        })),
    }
}

/// `--lags` against the prepared estimation and validation records.
fn check_records_lags(
    lags: usize,
    name: &str,
    est: &FitData,
    val: Option<Record<'_>>,
) -> Result<(), LagsError> {
    check_lags(lags, name, est.prepared().len())?;
    if let Some(v) = val {
        check_lags(lags, v.name, v.data.prepared().len())?;
    }
    Ok(())
}

/// `fitted` evaluated on the validation record, when there is one (errors name it).
fn on_validation(
    fitted: &Fitted,
    val: Option<Record<'_>>,
    lags: usize,
) -> Result<Option<Validation>, FitRunError> {
    match val {
        Some(v) => fitted
            .evaluate_on(v.data, lags)
            .map(Some)
            .map_err(|source| FitRunError::Record {
                name: v.name.to_string(),
                source,
            }),
        None => Ok(None),
    }
}

/// The FIT figures of a time-domain fit ([`time_domain_figures`]).
struct TimeFigures {
    name: &'static str,
    metric: &'static str,
    estimation: f64,
    validation: Option<f64>,
    /// each estimation record's, when not the toolbox FIT's
    each: Option<Vec<f64>>,
    /// the toolbox FIT on estimation and validation data, when it is not the headline
    toolbox: Option<(f64, Option<f64>)>,
}

impl TimeFigures {
    fn into_figures(self) -> FitFigures {
        FitFigures {
            name: self.name,
            metric: self.metric,
            estimation: self.estimation,
            validation: self.validation,
            toolbox: self.toolbox,
            note: None,
        }
    }
}

/// The FIT a time-domain fit reports on `est` and `val`: the toolbox FIT (`toolbox`: its
/// residual tests there), or for a model fitted on the motor velocity
/// ([`FitMetric::Velocity`]) the velocity FIT, the toolbox FIT beside it.
fn time_domain_figures(
    fitted: &Fitted,
    est: &[FitData],
    val: Option<Record<'_>>,
    toolbox: (&Validation, Option<&Validation>),
) -> Result<TimeFigures, FitError> {
    let (ev, vv) = (toolbox.0.fit, toolbox.1.map(|v| v.fit));
    if fitted.fit_metric != FitMetric::Velocity {
        return Ok(TimeFigures {
            name: FIT_NAME,
            metric: "toolbox",
            estimation: ev,
            validation: vv,
            each: None,
            toolbox: None,
        });
    }
    let (estimation, each) = fitted.velocity_fit_segments(est)?;
    let validation = match val {
        Some(v) => Some(
            fitted
                .velocity_fit_segments(std::slice::from_ref(v.data))?
                .0,
        ),
        None => None,
    };
    Ok(TimeFigures {
        name: VELOCITY_FIT_NAME,
        metric: "velocity",
        estimation,
        validation,
        each: Some(each),
        toolbox: Some((ev, vv)),
    })
}

/// `--segment all` with more than one segment, linear models: the frequency-domain fit on
/// the FRF averaged over every segment's whole periods ([`analyze_segments`]), or the
/// time-domain fit with the segments as separate experiments ([`fit_prepared_segments`]);
/// FIT pooled and per segment.
fn run_segments(
    req: &FitRequest,
    segs: &[Dataset],
    numbers: &[usize],
    val: Option<Record<'_>>,
    val_ds: Option<&Dataset>,
) -> Result<FitOutcome, FitRunError> {
    let name = longest_segment(segs).name.clone();
    let opts = &req.options;
    let pooled = match req.domain {
        Domain::Time => None,
        Domain::Frequency if opts.spec.coulomb => return Err(FitRunError::CoulombInFrequency),
        Domain::Frequency => Some(analyze_segments(segs, req.settle_periods).map_err(
            |source| FitRunError::NotPeriodic {
                name: name.clone(),
                source,
            },
        )?),
        Domain::Auto if !opts.spec.coulomb => analyze_segments(segs, req.settle_periods).ok(),
        Domain::Auto => None,
    };
    if let Some(pooled) = &pooled {
        // the residual tests run on one period of one segment's steady state: the segment
        // with the most steady-state periods of its own
        let Some((ds, own)) = segs
            .iter()
            .filter_map(|d| analyze_dataset(d, req.settle_periods).ok().map(|a| (d, a)))
            .max_by_key(|(_, a)| a.layout.count)
        else {
            return Err(FitRunError::NoSteadySegment { name });
        };
        let vp = val_ds.map(|v| analyze_dataset(v, req.settle_periods));
        check_lags(
            req.lags,
            &format!("one period of {}", ds.name),
            own.layout.period,
        )?;
        let est = FitData::new(&ds.data, req.prep).map_err(|source| FitRunError::Record {
            name: ds.name.clone(),
            source,
        })?;
        if matches!(vp, Some(Err(_))) {
            check_records_lags(req.lags, &ds.name, &est, val)?;
        }
        let mut out = run_frequency_domain(
            req,
            Frequency {
                segs,
                numbers,
                pooled,
                analysis: &own,
                est: &est,
                val,
                val_ds,
                val_analysis: vp,
            },
        )?;
        let left: Vec<usize> = pooled.left_out.iter().map(|l| l.index).collect();
        let averaged: Vec<usize> = (0..numbers.len())
            .filter(|i| !left.contains(i))
            .map(|i| numbers[i])
            .collect();
        out.notes.insert(
            0,
            format!(
                "{name}: the FRF averages the whole periods of segments {}",
                segment_list(&averaged)
            ),
        );
        for (k, l) in pooled.left_out.iter().enumerate() {
            out.notes.insert(
                k,
                format!(
                    "{name}: segment {} left out of the FRF: {}",
                    numbers[l.index], l.reason
                ),
            );
        }
        return Ok(out);
    }
    let usable = usable_segments(segs.to_vec(), numbers, &name, FITTING_NOTES);
    let (used, used_numbers) = (usable.datasets, usable.segments);
    if used.is_empty() {
        return Err(FitRunError::NoUsableSegment { name });
    }
    let est: Vec<FitData> = used
        .iter()
        .map(|d| {
            FitData::new(&d.data, req.prep).map_err(|source| FitRunError::Record {
                name: d.name.clone(),
                source,
            })
        })
        .collect::<Result<_, _>>()?;
    let total: usize = est.iter().map(|e| e.prepared().len()).sum();
    check_lags(req.lags, &name, total)?;
    if let Some(v) = val {
        check_lags(req.lags, v.name, v.data.prepared().len())?;
    }
    let on = |source| FitRunError::Record {
        name: name.clone(),
        source,
    };
    let t0 = Instant::now();
    let mut fitted = fit_prepared_segments(&est, opts).map_err(on)?;
    let seconds = t0.elapsed().as_secs_f64();
    if !opts.spec.coulomb {
        if let Some(w) = analyze_segments(&used, req.settle_periods)
            .ok()
            .and_then(|a| below_frf(&a, used[0].data.ts, opts, &fitted))
        {
            fitted.warnings.push(w.to_string());
        }
    }
    let (ev, each) = fitted.evaluate_segments(&est, req.lags).map_err(on)?;
    let vv = on_validation(&fitted, val, req.lags)?;
    let ts = est[0].prepared().ts;
    let mut fig = time_domain_figures(&fitted, &est, val, (&ev, vv.as_ref())).map_err(on)?;
    let compare = if req.figures {
        // the longest segment, under the toolbox FIT printed for it
        let i = (0..used.len())
            .max_by_key(|&i| (used[i].data.len(), usize::MAX - i))
            .unwrap_or(0);
        let title = format!("estimation: {} (segment {})", used[i].name, used_numbers[i]);
        let mut records = vec![simulated_record(&fitted, &est[i], title, each[i])?];
        if let (Some(v), Some(vv)) = (val, &vv) {
            let title = format!("validation: {}", v.name);
            records.push(simulated_record(&fitted, v.data, title, vv.fit)?);
        }
        let compared = if fig.each.is_some() {
            Compared::SimulatedToolbox
        } else {
            Compared::Simulated
        };
        Some((compared, records))
    } else {
        None
    };
    let each = fig.each.take().unwrap_or(each);
    let measured = Measured {
        segments: used
            .iter()
            .zip(&used_numbers)
            .zip(&each)
            .map(|((d, &k), &f)| SegmentJson {
                segment: k,
                samples: d.data.len(),
                fit: Some(f),
            })
            .collect(),
        validation_name: val.map(|v| v.name.to_string()),
        ts,
        samples: total,
        fit: fig.into_figures(),
        resonances: fitted.resonances(default_f_min(total, ts)),
        tests: ev,
        validation_tests: vv,
        compare,
        notes: usable.notes,
        seconds,
    };
    Ok(finish(req, longest_segment(&used), fitted, measured))
}

/// The records of the frequency-domain path ([`run_frequency_domain`]).
struct Frequency<'a> {
    /// the estimation segments (one without gaps)
    segs: &'a [Dataset],
    /// their numbers
    numbers: &'a [usize],
    /// the FRF averaged over every segment's whole periods (the fit and its FIT)
    pooled: &'a FrfAnalysis,
    /// the FRF of the segment the residual tests run on
    analysis: &'a FrfAnalysis,
    /// that segment, prepared (the toolbox FIT when the validation record is not
    /// periodic)
    est: &'a FitData,
    /// the prepared validation record
    val: Option<Record<'a>>,
    /// the validation record as read
    val_ds: Option<&'a Dataset>,
    /// its FRF, or why it has none
    val_analysis: Option<Result<FrfAnalysis, FrfError>>,
}

/// What the periodic FIT needs of the validation record `name`, which has no FRF
/// (`why`), and what is shown instead.
fn not_periodic_note(name: &str, why: &FrfError) -> String {
    let why = why.to_string();
    let why = if why.starts_with(name) {
        why
    } else {
        format!("{name}: {why}")
    };
    format!(
        "{why}: the periodic FIT needs whole periods on the validation record too, so both \
         FITs above are the toolbox FIT of the output simulated from the measured torque \
         over each whole record (initial state fitted, as the toolbox's `compare`); drift \
         and slow disturbances enter it, so a model right at the excited lines can score \
         far below its periodic FIT, even below 0"
    )
}

/// The frequency-domain path ([`crate::ident::sml`], [`fit_frequency_domain`]).
fn run_frequency_domain(req: &FitRequest, f: Frequency<'_>) -> Result<FitOutcome, FitRunError> {
    let Frequency {
        segs,
        numbers,
        pooled,
        analysis,
        est,
        val,
        val_ds,
        val_analysis,
    } = f;
    // `analysis` is the FRF of the segment of the residual tests; `ds`, the longest
    // segment, names the fit
    let ds = longest_segment(segs);
    let ts = ds.data.ts;
    let t0 = Instant::now();
    let fitted =
        fit_frequency_domain(pooled, ts, &req.options, est.decimate).map_err(|source| {
            FitRunError::Record {
                name: ds.name.clone(),
                source,
            }
        })?;
    let seconds = t0.elapsed().as_secs_f64();
    let respond = |f: &[f64]| fitted.model.freq_response(f);
    let f_min = pooled.frf.freq_hz.first().copied().unwrap_or(0.0);
    let resonances = fitted.resonances(f_min);
    // residual tests: input independence on one period of the steady state (slow
    // disturbances and drift averaged out), at the capture rate; the residuals the fit
    // weighted, line by line, against their bound
    let tests = |d: &Dataset, a: &FrfAnalysis| -> Result<Validation, FitRunError> {
        let s = sml::periodic_steady_state(&d.data, &a.layout, respond).map_err(|source| {
            FitRunError::SteadyState {
                name: d.name.clone(),
                source,
            }
        })?;
        let (line_e, nu) = sml::line_residuals(&a.frf, respond);
        validate_periodic(&s.u, &s.y, &s.y_hat, &line_e, nu, req.lags).map_err(|source| {
            FitRunError::Tests {
                name: d.name.clone(),
                source,
            }
        })
    };
    let periodic_fit =
        |a: &FrfAnalysis| sml::periodic_fit_percent(&a.frf, &respond(&a.frf.freq_hz));
    let (val_analysis, not_periodic) = match val_analysis {
        Some(Ok(a)) => (Some(a), None),
        Some(Err(e)) => (None, Some(e)),
        None => (None, None),
    };
    let periodic = not_periodic.is_none();
    let mut records = Vec::new();
    let (ev, vv) = if periodic {
        // what the periodic FIT printed for each record compares: one averaged period
        // at the reliable lines, measured against the model's response
        let mut record = |title: String, a: &FrfAnalysis, period: usize| {
            let g = respond(&a.frf.freq_hz);
            if let Some((y, y_hat)) = sml::periodic_fit_signals(&a.frf, &g, period) {
                records.push(CompareRecord {
                    title,
                    ts,
                    y,
                    y_hat,
                    fit: periodic_fit(a),
                });
            }
        };
        if req.figures {
            let title = format!("estimation: {}", ds.name);
            record(title, pooled, analysis.layout.period);
        }
        let vv = match (val_ds, &val_analysis) {
            (Some(v), Some(a)) => {
                if req.figures {
                    record(format!("validation: {}", v.name), a, a.layout.period);
                }
                Some(tests(v, a)?)
            }
            _ => None,
        };
        (tests(ds, analysis)?, vv)
    } else {
        let ev = fitted
            .evaluate_on(est, req.lags)
            .map_err(|source| FitRunError::Record {
                name: ds.name.clone(),
                source,
            })?;
        let vv = on_validation(&fitted, val, req.lags)?;
        if req.figures {
            let title = format!("estimation: {}", ds.name);
            records.push(simulated_record(&fitted, est, title, ev.fit)?);
            if let (Some(v), Some(vv)) = (val, &vv) {
                let title = format!("validation: {}", v.name);
                records.push(simulated_record(&fitted, v.data, title, vv.fit)?);
            }
        }
        (ev, vv)
    };
    let fit = if periodic {
        FitFigures {
            name: PERIODIC_FIT_NAME,
            metric: "periodic",
            estimation: periodic_fit(pooled),
            validation: val_analysis.as_ref().map(periodic_fit),
            toolbox: None,
            note: None,
        }
    } else {
        FitFigures {
            name: FIT_NAME,
            metric: "toolbox",
            estimation: ev.fit,
            validation: vv.as_ref().map(|v| v.fit),
            toolbox: None,
            note: match (val, &not_periodic) {
                (Some(v), Some(e)) => Some(not_periodic_note(v.name, e)),
                _ => None,
            },
        }
    };
    let segments = if segs.len() == 1 {
        vec![SegmentJson {
            segment: numbers[0],
            samples: ds.data.len(),
            fit: Some(if periodic {
                periodic_fit(analysis)
            } else {
                ev.fit
            }),
        }]
    } else {
        segs.iter()
            .zip(numbers)
            .map(|(d, &k)| SegmentJson {
                segment: k,
                samples: d.data.len(),
                fit: analyze_dataset(d, req.settle_periods)
                    .ok()
                    .map(|a| periodic_fit(&a)),
            })
            .collect()
    };
    let compared = if periodic {
        Compared::Periodic
    } else {
        Compared::Simulated
    };
    let measured = Measured {
        segments,
        validation_name: val.map(|v| v.name.to_string()),
        ts,
        samples: segs.iter().map(|d| d.data.len()).sum(),
        fit,
        resonances,
        tests: ev,
        validation_tests: vv,
        compare: req.figures.then_some((compared, records)),
        notes: Vec::new(),
        seconds,
    };
    Ok(finish(req, ds, fitted, measured))
}

/// The nonlinear path: the segments of [`MIN_SEGMENT_SAMPLES`] or more as separate
/// experiments, [`crate::ident::nonlinear::run`] with the frequency-domain linear start
/// on periodic data (not on a split record), the validation with the exact laws. When the
/// fit's current-loop lag comes out nought where it was free, the run is made again on the
/// records with their input taken as sampled ([`IdData::input_as_sampled`], a measured
/// analog input) and kept when it scores higher on the estimation records.
fn run_nonlinear(
    req: &FitRequest,
    nl: NlRequest,
    data: FitRecords<'_>,
) -> Result<FitOutcome, FitRunError> {
    let Family::Physical(structure) = req.options.spec.family else {
        return Err(RequestError::EffectOnBlackBox.into());
    };
    let (segs, numbers, notes) = if data.estimation.len() > 1 {
        let name = &longest_segment(data.estimation).name;
        let u = usable_segments(data.estimation.to_vec(), data.numbers, name, FITTING_NOTES);
        (u.datasets, u.segments, u.notes)
    } else {
        (data.estimation.to_vec(), data.numbers.to_vec(), Vec::new())
    };
    if segs.is_empty() {
        return Err(FitRunError::NoSegment);
    }
    let ds = longest_segment(&segs);
    // the estimation and validation records (`estimation_fraction` splits the record)
    let (est, val) = match (req.estimation_fraction, data.validation) {
        (Some(f), _) => {
            let (a, b) = ds.data.split(f);
            let vn = format!("{} (last {:.0} %)", ds.name, 100.0 * (1.0 - f));
            (a, Some((b, vn)))
        }
        (None, Some(v)) => (ds.data.clone(), Some((v.data.clone(), v.name.clone()))),
        (None, None) => (ds.data.clone(), None),
    };
    // the segments as separate experiments (one record: `est` alone)
    let est_all: Vec<IdData> = if segs.len() > 1 {
        segs.iter().map(|d| d.data.clone()).collect()
    } else {
        vec![est.clone()]
    };
    let val_name = val.as_ref().map_or("validation", |(_, n)| n.as_str());
    let why = |e: NlRunError| match e {
        NlRunError::Estimation(_) => FitRunError::NonlinearOn {
            record: ds.name.clone(),
            source: Box::new(e),
        },
        NlRunError::Validation(_) => FitRunError::NonlinearOn {
            record: val_name.to_string(),
            source: Box::new(e),
        },
        e => FitRunError::Nonlinear(Box::new(e)),
    };
    let t0 = Instant::now();
    let run_on = |est_all: &[IdData], segs: &[Dataset], val: Option<&IdData>| {
        nonlinear::run(
            NlData {
                estimation: est_all,
                // whole periods of the record: the frequency-domain fit gives the linear start
                periodic: req
                    .estimation_fraction
                    .is_none()
                    .then_some((segs, req.settle_periods)),
                validation: val,
            },
            &nl,
        )
    };
    let mut done = run_on(&est_all, &segs, val.as_ref().map(|(v, _)| v)).map_err(why)?;
    // no lag where one was free: the input is tried as sampled, as `diagnose` does, and
    // kept when the fit scores higher on the estimation records
    let (mut val, mut est) = (val, est);
    let mut input = InputTaken::Held;
    if nl.held().is_none() && done.result.fit.holds_no_lag() {
        let segs_s: Vec<Dataset> = segs.iter().map(Dataset::input_as_sampled).collect();
        let est_s: Vec<IdData> = est_all.iter().map(IdData::input_as_sampled).collect();
        let val_s = val.as_ref().map(|(v, n)| (v.input_as_sampled(), n.clone()));
        let (held, s) = (
            done.estimation.velocity_fit_percent,
            run_on(&est_s, &segs_s, val_s.as_ref().map(|(v, _)| v)),
        );
        match s {
            Ok(mut s) if s.estimation.velocity_fit_percent > held => {
                let sampled = s.estimation.velocity_fit_percent;
                let note = nonlinear::sampled_input_note(
                    "the fit's velocity FIT on the estimation record",
                    held,
                    sampled,
                );
                s.result.warnings.insert(0, note);
                (done, val, est) = (s, val_s, est.input_as_sampled());
                input = InputTaken::Sampled;
            }
            _ => {}
        }
    }
    let seconds = t0.elapsed().as_secs_f64();
    let segments = segs
        .iter()
        .zip(&numbers)
        .zip(&done.estimation_segments)
        .map(|((d, &k), v)| SegmentJson {
            segment: k,
            samples: d.data.len(),
            fit: Some(v.velocity_fit_percent),
        })
        .collect();
    let velocity = if req.figures {
        let (d, n) = match &val {
            Some((v, n)) => (v, n.as_str()),
            None => (&est, ds.name.as_str()),
        };
        Some(
            VelocityFigure::new(&done.result.fit, d, n)
                .map_err(|e| FitRunError::VelocityFigure(Box::new(e)))?,
        )
    } else {
        None
    };
    Ok(FitOutcome {
        name: ds.name.clone(),
        validation_name: val.as_ref().map(|(_, n)| n.clone()),
        ts: est.ts,
        samples: est_all.iter().map(IdData::len).sum(),
        segments,
        fit: FitFigures {
            name: NL_FIT_NAME,
            metric: "velocity",
            estimation: done.estimation.velocity_fit_percent,
            validation: done.validation.map(|v| v.velocity_fit_percent),
            toolbox: None,
            note: None,
        },
        warnings: done.result.warnings.clone(),
        notes,
        seconds,
        model: FittedModel::Nonlinear(Box::new(NonlinearFit {
            structure,
            run: done,
            velocity,
        })),
        input,
    })
}
