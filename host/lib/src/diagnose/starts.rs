//! The linear starts: the frequency-domain fits the candidates start from (the structure,
//! the structure with one more mass for an extra mode, the friction-compensated FRF for
//! Coulomb friction), and where the motor sticks, the structure grown in the time domain
//! ([`grow`]), since the FRF is then the friction's and not the structure's.

use std::sync::{Arc, OnceLock};

use crate::data::{Dataset, IdData};
use crate::ident::frf::FrfAnalysis;
use crate::ident::nonlinear::{
    friction_level, grow, linear_start_segments, linear_start_shared, DelayLines, NlRequest,
    RawFrfFits, StartSearch,
};
use crate::ident::parallel::parallel;
use crate::ident::sml::{FrfStart, GOOD_START_RATIO};
use crate::model::effects::{Attach, Effect, ExtraMode};
use crate::model::spec::Structure;

use super::inputs::Records;
use super::linearity::{capture_analyses, Nonlinearity};
use super::{progress, DiagnoseRequest};

/// The starts of the candidates in `rec` (notes into `warnings`).
pub(super) fn linear_starts(
    rec: &Records<'_>,
    req: &DiagnoseRequest,
    warnings: &mut Vec<String>,
) -> LinearStarts {
    let o = &req.options;
    let est0 = rec.est[0];
    let coulomb = rec
        .candidates
        .iter()
        .find(|e| matches!(e, Effect::CoulombFriction(_)))
        .copied();
    let extra = rec.candidates.iter().find_map(|e| match e {
        Effect::ExtraMode(x) => Some(x.attach),
        _ => None,
    });
    progress::started(
        req.progress.as_ref(),
        "the linear starts (FRF and frequency-domain fits)",
    );
    // the independent frequency-domain fits on the threads, the slowest (one more mass)
    // first; each is a pure function of the record, so the starts are the same on any
    // number of threads
    let backlash = rec
        .candidates
        .iter()
        .any(|e| matches!(e, Effect::Backlash(_)))
        && matches!(req.structure, Structure::TwoMass | Structure::ThreeMass);
    let mut jobs = Vec::new();
    if let Some(a) = extra {
        jobs.push(StartJob::ExtraMode(a));
    }
    if let Some(c) = coulomb {
        jobs.push(StartJob::Coulomb(c));
    }
    jobs.push(StartJob::Structure);
    if backlash {
        jobs.push(StartJob::TwoMass);
    }
    // the raw fits of the structure's FRF, and of the structure with one more mass, each
    // made once for the starts that begin with them ([`RawFrfFits`]); the same values
    // whichever start makes them
    let (raw, bigger) = (RawFrfFits::default(), RawFrfFits::default());
    let done = parallel(&jobs, o.threads, |j| match *j {
        StartJob::ExtraMode(a) => {
            let from = quiet_mode_start(est0, (req.structure, req.r), a, &raw);
            let start = extra_mode_start(
                est0,
                (req.structure, req.r),
                a,
                None,
                (&bigger, from.clone()),
            );
            StartDone::ExtraMode(start, from)
        }
        StartJob::Coulomb(c) => {
            StartDone::Coulomb(coulomb_linear_of(est0, &rec.est_data, req, c, &raw))
        }
        StartJob::Structure => {
            let mut said = Vec::new();
            let (start, lines) = structure_start(est0, req, &mut said, &raw);
            StartDone::Structure(start, lines, said)
        }
        StartJob::TwoMass => StartDone::TwoMass(
            linear_start_segments(
                est0,
                1,
                &NlRequest::new(Structure::TwoMass, req.r, Vec::new()),
            )
            .ok()
            .map(|l| (l.values, l.tau_c)),
        ),
    });
    let analyses = capture_analyses(rec, o.settle_periods);
    let mut starts = LinearStarts {
        structure: None,
        extra_mode: None,
        coulomb: None,
        coulomb_extra_mode: LazyStart::none(),
        grown: None,
        two_mass: None,
        delay_lines: None,
        nonlinearity: Nonlinearity::of(&analyses, rec.est.len()),
        analyses: Arc::new(analyses),
        sticks: None,
        lag_start: None,
    };
    let mut level = None;
    let mut quiet = None;
    for d in done {
        match d {
            StartDone::ExtraMode(x, from) => (starts.extra_mode, quiet) = (x, from),
            StartDone::Coulomb((c, l)) => (starts.coulomb, level) = (c, l),
            StartDone::Structure(x, lines, said) => {
                starts.structure = x;
                starts.delay_lines = lines;
                warnings.extend(said);
            }
            StartDone::TwoMass(x) => starts.two_mass = x,
        }
    }
    // fitted only when a pair of the friction and the mode asks for it
    if let (Some(c), Some(a), true) = (coulomb, extra, o.pairs) {
        starts.coulomb_extra_mode = LazyStart::of(est0, req, (a, c), (bigger, quiet));
    }
    // stick-slip: the Coulomb candidates start from the structure grown in the time domain
    let Some(level) = level else {
        return starts;
    };
    let share = grow::stick_share(&rec.est_data, level);
    if share <= grow::STICK_SHARE {
        return starts;
    }
    starts.sticks = Some(share);
    if !matches!(req.structure, Structure::TwoMass | Structure::ThreeMass) {
        return starts;
    }
    let lag = match &starts.structure {
        Some((_, t)) if *t > 0.0 => *t,
        _ => rec.ts,
    };
    let grown = progress::step(
        req.progress.as_ref(),
        "the structure grown in the time domain (the motor sticks)",
        || {
            // band-limited: the motor sticks ([`super::inputs::nl_options`])
            let options = super::inputs::nl_options(o, coulomb.as_slice(), Some(share));
            grow::grow(&rec.est_data, req.structure, req.r, lag, &options)
        },
        |r| match r {
            Ok(_) => "grown".to_string(),
            Err(e) => format!("failed: {e}"),
        },
    );
    match grown {
        Ok(g) => {
            // the level is a regression's, which reads high where the motor rests within a
            // count (new-laws case 40: 5.8e-2 N·m against a true 1.2e-2); the grown start's
            // own level says how often the torque really stays below it
            let grown_share = match g.coulomb {
                Effect::CoulombFriction(c) => format!(
                    " (below the grown start's F_c = {:.3e} N·m on {:.0} %)",
                    c.fc,
                    100.0 * grow::stick_share(&rec.est_data, c.fc)
                ),
                _ => String::new(),
            };
            warnings.push(format!(
                "the motor sticks: the torque stays below the friction level {level:.3e} N·m \
                 on {:.0} % of the estimation samples{grown_share}, so the FRF is the \
                 friction's and not the structure's; the candidates with Coulomb friction \
                 (Stribeck law) start from the {} grown in the time domain from the two-mass",
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
    starts
}

/// One frequency-domain fit of [`linear_starts`].
enum StartJob {
    ExtraMode(Attach),
    Coulomb(Effect),
    Structure,
    TwoMass,
}

/// What a [`StartJob`] gave.
#[allow(clippy::type_complexity)]
enum StartDone {
    ExtraMode(Option<(Vec<f64>, ExtraMode, f64)>, Option<FrfStart>),
    Coulomb((Option<(Vec<f64>, f64)>, Option<f64>)),
    Structure(Option<(Vec<f64>, f64)>, Option<DelayLines>, Vec<String>),
    TwoMass(Option<(Vec<f64>, f64)>),
}

/// The start of a pair of Coulomb friction and an extra mode ([`extra_mode_start`] on the
/// friction-compensated FRF), fitted the first time a pair asks for it: one more mass with
/// the compensation is the slowest of the frequency-domain fits (a three-mass joint's
/// four-mass fit, bench hard case 13: 18 of the diagnosis's 50 s of CPU), and most
/// diagnoses never try that pair.
pub(super) struct LazyStart {
    /// the estimation capture's segments, the structure, the ratio, where the mode sits and
    /// the friction; `None`: no such start
    args: Option<(Vec<Dataset>, Structure, f64, Attach, Effect)>,
    cell: OnceLock<Option<(Vec<f64>, ExtraMode, f64)>>,
    /// the raw fits of the bigger structure's FRF, shared with the extra mode's start, and
    /// the start they were made from ([`quiet_mode_start`])
    raw: (RawFrfFits, Option<FrfStart>),
}

impl LazyStart {
    /// No start.
    pub fn none() -> LazyStart {
        LazyStart {
            args: None,
            cell: OnceLock::new(),
            raw: (RawFrfFits::default(), None),
        }
    }

    fn of(
        ds: &[Dataset],
        req: &DiagnoseRequest,
        (a, c): (Attach, Effect),
        raw: (RawFrfFits, Option<FrfStart>),
    ) -> LazyStart {
        LazyStart {
            args: Some((ds.to_vec(), req.structure, req.r, a, c)),
            cell: OnceLock::new(),
            raw,
        }
    }

    /// The start: the structure's values, the mode and the lag [s]; fitted on the first call.
    pub fn get(&self) -> Option<&(Vec<f64>, ExtraMode, f64)> {
        let (ds, structure, r, a, c) = self.args.as_ref()?;
        self.cell
            .get_or_init(|| {
                let raw = (&self.raw.0, self.raw.1.clone());
                extra_mode_start(ds, (*structure, *r), *a, Some(*c), raw)
            })
            .as_ref()
    }
}

impl LinearStarts {
    /// These starts with `structure` (values and lag [s]) in place of the structure's
    /// frequency-domain start, and no start of a pair of the friction and the mode (it is
    /// the frequency domain's too).
    pub(super) fn with_structure(&self, structure: (Vec<f64>, f64)) -> LinearStarts {
        LinearStarts {
            structure: Some(structure),
            extra_mode: self.extra_mode.clone(),
            coulomb: self.coulomb.clone(),
            coulomb_extra_mode: LazyStart::none(),
            grown: self.grown.clone(),
            two_mass: self.two_mass.clone(),
            delay_lines: self.delay_lines,
            nonlinearity: self.nonlinearity.clone(),
            analyses: Arc::clone(&self.analyses),
            sticks: self.sticks,
            lag_start: self.lag_start,
        }
    }
}

/// The linear starts the candidate fits take from the frequency-domain fits.
pub(super) struct LinearStarts {
    /// the structure's values and current-loop lag [s]
    pub structure: Option<(Vec<f64>, f64)>,
    /// the structure's values, the extra mode and the lag [s], from the structure with one
    /// more mass ([`extra_mode_start`])
    pub extra_mode: Option<(Vec<f64>, ExtraMode, f64)>,
    /// as `structure`, from the friction-compensated FRF
    /// ([`crate::ident::nonlinear::compensate`]), for candidates with Coulomb friction; `None`
    /// when the compensation was not used
    pub coulomb: Option<(Vec<f64>, f64)>,
    /// as `extra_mode`, from the friction-compensated FRF, for pairs of Coulomb friction and
    /// an extra mode
    pub coulomb_extra_mode: LazyStart,
    /// when the motor sticks, the start grown in the time domain ([`grow`]), which every
    /// candidate with Coulomb friction takes instead of the above
    pub grown: Option<grow::Grown>,
    /// the linear two-mass's values and lag [s] from the frequency-domain fit, from which
    /// the backlash candidate is also grown ([`grow::grow_backlash`])
    pub two_mass: Option<(Vec<f64>, f64)>,
    /// the excited lines' evidence of a transport delay beside the lag, from the structure's
    /// frequency-domain fits ([`DelayLines`])
    pub delay_lines: Option<DelayLines>,
    /// the data's own evidence of a nonlinearity ([`Nonlinearity`]); `None` when no capture
    /// is periodic
    pub nonlinearity: Option<Nonlinearity>,
    /// the FRF analysis of each capture ([`capture_analyses`]), made once for the
    /// nonlinearity's evidence here and the report's distortion
    /// ([`super::evidence::gather`])
    pub analyses: Arc<Vec<(String, Option<FrfAnalysis>)>>,
    /// the share of the estimation samples on which the motor sticks (the torque below the
    /// friction level, [`grow::stick_share`]) when above [`grow::STICK_SHARE`]: every fit
    /// is then band-limited ([`super::inputs::nl_options`])
    pub sticks: Option<f64>,
    /// where the current-loop lag starts when no frequency-domain fit gives it [s]: `None`,
    /// one sample; nought (left out) when the input is taken as sampled
    /// ([`super::inputs::SampledInput`]), whose trigger is a nominal with no lag
    pub lag_start: Option<f64>,
}

/// The start of `structure` with an extra mode attached as `attach` says, from the
/// frequency-domain fit of the structure with one more mass where that is the same
/// mechanism: a two-mass joint with a mode on its arm is a three-mass chain, a three-mass
/// joint with a mode in parallel on its first arm mass is seed 000's four-mass model
/// (eq. (7), `J_p` on `k_p`). The automatic start's grid over the mode's frequency misses
/// it when the structure's own fit took the extra resonance for one of its modes.
fn extra_mode_start(
    ds: &[Dataset],
    (structure, r): (Structure, f64),
    attach: Attach,
    coulomb: Option<Effect>,
    raw: (&RawFrfFits, Option<FrfStart>),
) -> Option<(Vec<f64>, ExtraMode, f64)> {
    // the bigger structure, and where its extra body's inertia, spring and damper sit
    let (bigger, keep, extra) = bigger_structure(structure, attach)?;
    // the lag alone: the structure's start reads the lines' delay, and the candidates'
    // fits take the FRF's delay on the lag
    let l = linear_start_shared(
        ds,
        1,
        &NlRequest::new(bigger, r, coulomb.into_iter().collect()),
        raw,
        StartSearch::Candidate,
    )
    .ok()?;
    if coulomb.is_some() && !compensation_used(&l) {
        return None;
    }
    let plant = keep.iter().map(|&i| l.values[i]).collect();
    let [j, k, d] = extra.map(|i| l.values[i]);
    Some((plant, ExtraMode { j, k, d, attach }, l.tau_c))
}

/// The structure with one more mass for an extra mode at `attach` on `structure`, where
/// the structure's values sit among the bigger one's, and where the extra body's inertia,
/// spring and damper sit.
fn bigger_structure(
    structure: Structure,
    attach: Attach,
) -> Option<(Structure, &'static [usize], [usize; 3])> {
    match (structure, attach) {
        // [J_m, J_a1, J_a2, k_g, k_a, d_g, d_a, f_m]
        (Structure::TwoMass, _) => Some((Structure::ThreeMass, &[0, 1, 3, 5, 7], [2, 4, 6])),
        // [J_m, J_a1, J_a2, J_p, k_g, k_a, k_p, d_g, d_a, d_p, f_m]
        (Structure::ThreeMass, Attach::Parallel) => {
            Some((Structure::FourMass, &[0, 1, 2, 4, 5, 7, 8, 10], [3, 6, 9]))
        }
        _ => None,
    }
}

/// Where the structure's own frequency-domain fit (made once, `raw`) is within a few times
/// the noise's cost ([`crate::ident::nonlinear::LinearStart::at_noise`]), the bigger
/// structure's start from it: the optimiser's coordinates (log values, lag and delay
/// [samples]) with the extra body a thousandth of the first arm's inertia on its own
/// motor-side frequency, lightly damped, which leaves the FRF as the structure's. The
/// bigger structure holds the structure, so its fit from there is also at the noise's cost,
/// and its search over the FRF's peaks (a three-mass joint's four-mass fits: 254 starts
/// each, 13 of hard bench case 8's 41 s of CPU) is not made: where the lines hold no more
/// than the structure, no start found by searching could show more. `None` elsewhere:
/// the search is made as before.
fn quiet_mode_start(
    ds: &[Dataset],
    (structure, r): (Structure, f64),
    attach: Attach,
    raw: &RawFrfFits,
) -> Option<FrfStart> {
    let (bigger, keep, extra) = bigger_structure(structure, attach)?;
    let l = linear_start_shared(
        ds,
        1,
        &NlRequest::new(structure, r, Vec::new()),
        (raw, None),
        StartSearch::Full,
    )
    .ok()
    .filter(|l| l.at_noise)?;
    let ts = ds.first()?.data.ts;
    let v = &l.values;
    // [J_m, J_a1, …, k_g, …]: the motor on the gear spring, the highest of the modes
    let (j_m, j_a1, k_g) = (
        v[0],
        v[1],
        v[if structure == Structure::TwoMass {
            2
        } else {
            3
        }],
    );
    let j = 1e-3 * j_a1;
    let w2 = k_g / j_m;
    let k = j * w2;
    let d = 2.0 * 0.1 * (k * j).sqrt();
    let mut theta = vec![0.0; keep.len() + 3];
    for (&i, x) in keep.iter().zip(v) {
        theta[i] = x.max(f64::MIN_POSITIVE).ln();
    }
    for (&i, x) in extra.iter().zip([j, k, d]) {
        theta[i] = x.ln();
    }
    debug_assert_eq!(bigger.param_names().len(), theta.len());
    theta.extend([l.tau_c / ts, 0.0]);
    // the structure's fit reached the noise's cost (at most `GOOD_START_RATIO` times it),
    // and the bigger structure's from here reaches it too
    theta.iter().all(|t| t.is_finite()).then_some(FrfStart {
        theta,
        reached: GOOD_START_RATIO,
    })
}

/// Whether a linear start is the friction-compensated FRF's.
fn compensation_used(l: &crate::ident::nonlinear::LinearStart) -> bool {
    l.compensation
        .as_ref()
        .is_some_and(|c| c.values.iter().any(|(n, v, _)| n == "used" && *v > 0.0))
}

/// The linear start from the friction-compensated FRF ([`LinearStarts::coulomb`]), and the
/// friction level stick-slip is judged against [N·m], as `jointid fit` judges it
/// ([`friction_level`]): the compensation's regression, or, where the FRF took no
/// compensation, the regression itself on the longest estimation record `data`.
/// Held-out new-laws case 40 (an asymmetric Stribeck friction at 0.014 rad RMS, the torque
/// below the level on 61 % of the samples): no compensation, so no level was read, the
/// grown start never made, and the friction's fit from the FRF's start ended at
/// `k_a` = 7.8 N·m/rad (truth 6.9e3) and scored below the nominal; `jointid fit` of the
/// same capture grew its start within 30 % of every true value.
#[allow(clippy::type_complexity)]
pub(super) fn coulomb_linear_of(
    ds: &[Dataset],
    data: &[IdData],
    req: &DiagnoseRequest,
    coulomb: Effect,
    raw: &RawFrfFits,
) -> (Option<(Vec<f64>, f64)>, Option<f64>) {
    let req_c = NlRequest::new(req.structure, req.r, vec![coulomb]);
    let l = linear_start_shared(ds, 1, &req_c, (raw, None), StartSearch::Full).ok();
    let level = friction_level(
        data,
        &req_c,
        l.as_ref().and_then(|l| l.compensation.as_ref()),
    );
    let start = l.filter(compensation_used).map(|l| (l.values, l.tau_c));
    (start, level)
}

/// The structure's frequency-domain start (values and lag [s]), with the excited lines'
/// evidence of a transport delay beside the lag ([`DelayLines`]).
pub(super) fn structure_start(
    ds: &[Dataset],
    req: &DiagnoseRequest,
    warnings: &mut Vec<String>,
    raw: &RawFrfFits,
) -> (Option<(Vec<f64>, f64)>, Option<DelayLines>) {
    match linear_start_shared(
        ds,
        1,
        &NlRequest::new(req.structure, req.r, Vec::new()),
        (raw, None),
        StartSearch::Full,
    ) {
        Ok(l) => (Some((l.values, l.tau_c)), l.delay_lines),
        Err(e) => {
            if ds.first().is_some_and(|d| d.excitation.is_some()) {
                warnings.push(format!(
                    "{}: the frequency-domain linear start failed ({e}); the fits start \
                     automatically in the time domain",
                    ds[0].name
                ));
            }
            (None, None)
        }
    }
}
