//! The torque ripple's order from the data (issue 11, step 3 of the start: "ripple order
//! and phase from the residual's spectrum against motor angle").
//!
//! The ripple `A sin(n θ_m + φ) = a sin(n θ_m) + b cos(n θ_m)` enters the model as a motor
//! torque at the measured angle ([`super::model`]), so for a given order `n` the simulated
//! velocity is `v̂_0 + a g_s + b g_c`, where `v̂_0` is the model without ripple and `g_s`,
//! `g_c` its responses to the torques `sin(n θ_m)`, `cos(n θ_m)` (exact for a linear
//! model, to first order with friction). The best `(a, b)` for each candidate order is then
//! one 2 × 2 least-squares problem on the cost's prefiltered velocity residual, and its
//! cost drop `d_n = eᵀ G (GᵀG)⁻¹ Gᵀ e` says how much of the residual the ripple of order `n`
//! explains. A torque error that is not a ripple (a poor linear start, a slow load) also
//! lowers the cost at every order a little; the true order stands out against that spread:
//! its robust z-score `(d_n − median d)/(1.4826 MAD d)` over the candidates.
//!
//! Candidates: the orders whose angular period `2π/n` the motor's travel (the 1st to 99th
//! percentile of `θ_m`) covers at least [`MIN_PERIODS`] times (over less, `sin(n θ)` is a
//! smooth function of the angle and catches any position-dependent error), and whose phase
//! `n θ_m` turns at most [`MAX_PHASE_STEP`] per sample at the 99th percentile of the speed,
//! at most [`MAX_ORDER`]. The phase is the measured angle times the order, so a fast ripple
//! is not aliased; but over a sample the torque a ripple exerts is its mean along the
//! motion, `sin(δ/2)/(δ/2)` of its amplitude at a phase step `δ`, nought at `2π`, so
//! beyond a step of `π` the fast samples no longer hold it. Bench case 35 of
//! `benches/diagnose.rs` with `HARD=1 SMALL=1` (order 72, the phase turning 1.6 rad per
//! sample at the 99th percentile): a limit of a quarter of that (the ripple's frequency
//! below a quarter of the Nyquist frequency) stopped the search at order 36, whose fit
//! gained 0.08 FIT point; the true order fitted gains 0.57.
//!
//! Short travel: the search also runs down to the orders whose period the travel covers
//! [`MIN_SHORT_PERIODS`] times. A small motion of a joint with a ripple feels a torque that
//! is a smooth function of the angle over its travel (a piece of the sine: a level, a slope,
//! a bend); no order is told from its neighbours there, but the torque is real and a ripple
//! of one of those orders models it. Such an order is taken when it beats every candidate
//! significantly, or when there are no candidates, when it removes at least
//! [`MIN_SHORT_SHARE`] of the cost with the same ripple along the record; the start then
//! says that the order stands for a torque against the angle, not a measured order. That
//! torque is a stiffness to the ground the linear structure has not got, so every linear
//! start from the raw torque is bent; the start also takes the structure's modal features
//! from the torque with the ripple found taken off ([`compensated`]). Bench case 25 of
//! `benches/diagnose.rs` (order 72, the travel 0.9 of its periods, the soft tuning): the
//! frequency-domain start put `J_m` at 3·10⁻⁷ kg·m² (truth 1.2·10⁻³); the ripple fit
//! reached a validation FIT of 71.7 % from the other starts and 95.9 % from the compensated
//! one, the true model 97.5 %.

use nalgebra::{Matrix2, Vector2};
use rustfft::num_complex::Complex64;
use rustfft::FftPlanner;

use super::model::NlModel;
use super::output_error::{interval_velocity, simulate_velocity, NlError};
use crate::data::dsp::{butter_highpass_sos, SosBank};
use crate::data::IdData;
use crate::model::effects::TorqueRipple;
use crate::model::laws::{ripple_interval_mean, ripple_phasor_mean};

/// Periods of the ripple the motor's travel must cover for its order to be a candidate.
pub const MIN_PERIODS: f64 = 2.0;

/// Phase the ripple of the highest order searched may turn per sample at the 99th
/// percentile of the motor speed [rad] (module documentation).
pub const MAX_PHASE_STEP: f64 = std::f64::consts::PI;

/// Highest order searched (periods per motor revolution).
pub const MAX_ORDER: u32 = 240;

/// Periods of the ripple the motor's travel must cover for its order to be searched at all
/// (module documentation, short travel): a quarter period still bends the torque.
pub const MIN_SHORT_PERIODS: f64 = 0.25;

/// Share of the prefiltered velocity cost an order below the candidates must remove when
/// there are no candidates to stand out against (module documentation, short travel) [-].
pub const MIN_SHORT_SHARE: f64 = 0.05;

/// Robust z-score from which the best order counts as found.
pub const SIGNIFICANT_Z: f64 = 8.0;

/// Parts of the record on which the ripple is fitted apart for [`OrderSearch::coherence`].
pub const COHERENCE_PARTS: usize = 4;

/// Coherence of the parts' ripples from which the order counts as a ripple of the angle.
pub const MIN_COHERENCE: f64 = 0.6;

/// Fewest candidate orders for the spread to mean anything.
const MIN_CANDIDATES: usize = 8;

/// Chance level below which the order found on one record counts as shown again on
/// another ([`replication`]): one order named in advance, a one-sided test at 1 %.
pub const REPLICATED_P: f64 = 0.01;

/// What the order search found.
#[derive(Clone, Debug, PartialEq)]
pub struct OrderSearch {
    /// the order found: the best candidate when it is significant ([`SIGNIFICANT_Z`]) and
    /// no order below the candidates ([`OrderSearch::below`]) beats it, else that order
    /// below ([`OrderSearch::short`])
    pub order: Option<u32>,
    /// the candidate whose ripple lowers the cost most (with no candidates, the order
    /// searched that does)
    pub best: u32,
    /// its robust z-score against the cost drops of the orders the travel tells apart from it
    /// (their ripples differ from its by a period or more over the travel) [-]
    pub z: f64,
    /// how alike its ripple is on [`COHERENCE_PARTS`] parts of the record (1: the same; at
    /// least [`MIN_COHERENCE`] for the order to be found) [-]
    pub coherence: f64,
    /// the share of the prefiltered velocity cost the ripple of the order found (else of
    /// `best`) removes [-]
    pub share: f64,
    /// its least-squares amplitude [N·m] and phase [rad]
    pub amplitude: f64,
    /// phase `φ` of `A sin(n θ + φ)` [rad]
    pub phase: f64,
    /// lowest and highest candidate; `None` when the travel covers [`MIN_PERIODS`] periods
    /// of too few orders
    pub range: Option<(u32, u32)>,
    /// lowest and highest order searched ([`MIN_SHORT_PERIODS`])
    pub searched: (u32, u32),
    /// the travel over the period of the order found (else of `best`) [-]
    pub periods: f64,
    /// the order below the candidates (the travel covers [`MIN_SHORT_PERIODS`] to
    /// [`MIN_PERIODS`] of its periods) that lowers the cost most, with its z-score against
    /// the candidates (0 without candidates) when it lowers the cost more than every
    /// candidate and its ripple is alike along the record
    pub below: Option<(u32, f64)>,
    /// each order's cost drop [(rad/s)²]
    pub drops: Vec<(u32, f64)>,
}

impl OrderSearch {
    /// This search with its best candidate taken as the order found when it found none and
    /// that candidate's ripple is alike along the record ([`MIN_COHERENCE`]): for a caller
    /// that tests the order on another record ([`replication`]).
    pub fn best_taken(self) -> OrderSearch {
        if self.order.is_some() || self.range.is_none() || self.coherence < MIN_COHERENCE {
            return self;
        }
        OrderSearch {
            order: Some(self.best),
            ..self
        }
    }

    /// Whether the order found lies below the candidates: the travel covers fewer than
    /// [`MIN_PERIODS`] of its periods, so it stands for a torque against the angle over the
    /// travel rather than a measured order (module documentation, short travel).
    pub fn short(&self) -> bool {
        self.below.is_some()
    }
}

/// The candidate orders for `data` ([`MIN_PERIODS`], [`MAX_PHASE_STEP`], [`MAX_ORDER`]);
/// `None` when no order qualifies.
pub fn order_range(data: &IdData) -> Option<(u32, u32)> {
    orders_covering(data, MIN_PERIODS)
}

/// The orders from those whose period the motor's travel covers `periods` times to the
/// speed's limit ([`MAX_PHASE_STEP`], [`MAX_ORDER`]), when at least [`MIN_CANDIDATES`].
fn orders_covering(data: &IdData, periods: f64) -> Option<(u32, u32)> {
    let span = span(data);
    let v: Vec<f64> = interval_velocity(&data.y, data.ts)
        .iter()
        .map(|x| x.abs())
        .collect();
    let w_hi = percentile(&v, 0.99);
    if !(span > 0.0 && w_hi > 0.0) {
        return None;
    }
    let lo = (periods * std::f64::consts::TAU / span).ceil().max(1.0);
    let hi = (MAX_PHASE_STEP / (w_hi * data.ts))
        .floor()
        .min(MAX_ORDER as f64);
    (hi >= lo + MIN_CANDIDATES as f64 - 1.0).then_some((lo as u32, hi as u32))
}

/// The motor's travel: the 1st to the 99th percentile of the measured angle [rad].
fn span(data: &IdData) -> f64 {
    percentile(&data.y, 0.99) - percentile(&data.y, 0.01)
}

/// Periods of a ripple of `order` per motor revolution the motor's travel on `data`
/// covers [-] (below [`MIN_PERIODS`] the data do not fix the order).
pub fn travel_periods(data: &IdData, order: f64) -> f64 {
    span(data) * order / std::f64::consts::TAU
}

/// The `q` quantile of `x` (nearest rank).
fn percentile(x: &[f64], q: f64) -> f64 {
    let mut s: Vec<f64> = x.iter().copied().filter(|v| v.is_finite()).collect();
    if s.is_empty() {
        return f64::NAN;
    }
    s.sort_by(f64::total_cmp);
    s[((s.len() - 1) as f64 * q).round() as usize]
}

/// Searches the ripple's order on `data` against `model` (no ripple attached) at its
/// physical values `values` (module documentation). `None` when the travel covers
/// [`MIN_SHORT_PERIODS`] periods of too few orders.
///
/// The responses `g_s`, `g_c` are those of the linear structure without effects or current
/// loop (the ripple acts on the motor after the current loop, and its frequencies lie far
/// below the loop's bandwidth), one convolution each by FFT with the pulse response of the
/// simulation, the ripple held over each sample interval at its mean along the motion
/// ([`ripple_phasor_mean`], the angle linear between samples, as the model's simulation
/// takes it).
///
/// # Errors
/// [`NlError::Unstable`] when the model does not simulate to finite values.
pub fn search_order(
    data: &IdData,
    model: &NlModel,
    values: &[f64],
) -> Result<Option<OrderSearch>, NlError> {
    let Some((floor, hi)) = orders_covering(data, MIN_SHORT_PERIODS) else {
        return Ok(None);
    };
    let range = order_range(data);
    // without candidates every order searched lies below them
    let lo = range.map_or(hi + 1, |r| r.0);
    let ts = data.ts;
    let len = data.len();
    let v = interval_velocity(&data.y, ts);
    let base = simulate_velocity(model, values, &data.u, ts, data.y[0], Some(&data.y))
        .ok_or(NlError::Unstable)?;
    let e = highpassed(
        &v.iter().zip(&base).map(|(a, b)| a - b).collect::<Vec<_>>(),
        ts,
    );
    let ssr: f64 = e.iter().map(|x| x * x).sum();
    // pulse response of the linear structure: a unit torque held over the first interval
    // moves the mean velocity of the intervals after it (`h[0]` = 0)
    let (_, plant) = model.with_values(values);
    let linear = NlModel {
        effects: Vec::new(),
        tau_c: 0.0,
        ..model.clone()
    };
    let mut pulse = vec![0.0; len];
    pulse[0] = 1.0;
    let mut h = simulate_velocity(
        &linear,
        &linear.values(&plant, 0.0, 0.0),
        &pulse,
        ts,
        0.0,
        None,
    )
    .ok_or(NlError::Unstable)?;
    h[0] = 0.0;
    let size = (2 * len).next_power_of_two();
    let mut planner = FftPlanner::<f64>::new();
    let fwd = planner.plan_fft_forward(size);
    let inv = planner.plan_fft_inverse(size);
    let mut hf: Vec<Complex64> = h.iter().map(|&x| Complex64::new(x, 0.0)).collect();
    hf.resize(size, Complex64::new(0.0, 0.0));
    fwd.process(&mut hf);
    // the prefiltered responses `[g_s, g_c]` to `sin(nθ)`, `cos(nθ)`, by one complex
    // convolution of `e^{i n θ}` held over interval k at its mean along the motion
    let mut buf = vec![Complex64::new(0.0, 0.0); size];
    let mut responses = |n: u32| -> [Vec<f64>; 2] {
        let nf = n as f64;
        for (k, b) in buf.iter_mut().enumerate() {
            *b = if k < len {
                let (c, s) = ripple_phasor_mean(nf, data.y[k], data.y[(k + 1).min(len - 1)]);
                Complex64::new(c, s)
            } else {
                Complex64::new(0.0, 0.0)
            };
        }
        fwd.process(&mut buf);
        for (b, hk) in buf.iter_mut().zip(&hf) {
            *b *= hk;
        }
        inv.process(&mut buf);
        let scale = 1.0 / size as f64;
        let gc: Vec<f64> = buf[..len].iter().map(|z| z.re * scale).collect();
        let gs: Vec<f64> = buf[..len].iter().map(|z| z.im * scale).collect();
        [highpassed(&gs, ts), highpassed(&gc, ts)]
    };
    // down to the orders of a quarter period over the travel: a ripple below the
    // candidates would otherwise show as the lowest candidate, a wrong order found
    let mut drops = Vec::with_capacity((hi - floor + 1) as usize);
    for n in floor..=hi {
        let g = responses(n);
        let (drop, ab) = least_squares(&g, &e, 0..e.len());
        drops.push((n, drop, ab));
    }
    let travel = span(data);
    // robust z-score of order `best`'s drop against the chance level: the candidates the
    // travel tells apart from it (their ripples differ by a period or more over it), whose
    // drops are what a ripple-free residual gives
    let pairs: Vec<(u32, f64)> = drops.iter().map(|d| (d.0, d.1)).collect();
    let z_of = |best: u32, drop: f64| {
        let sorted = told_apart(&pairs, lo, travel, best);
        if sorted.len() < MIN_CANDIDATES {
            return 0.0;
        }
        let median = sorted[sorted.len() / 2];
        let mut dev: Vec<f64> = sorted.iter().map(|d| (d - median).abs()).collect();
        dev.sort_by(f64::total_cmp);
        let mad = 1.4826 * dev[dev.len() / 2];
        if mad > 0.0 {
            (drop - median) / mad
        } else {
            0.0
        }
    };
    let top = |from: u32| {
        drops
            .iter()
            .filter(|d| d.0 >= from)
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .copied()
    };
    let share_of = |drop: f64| if ssr > 0.0 { drop / ssr } else { 0.0 };
    let (best, drop, ab) =
        top(range.map_or(floor, |r| r.0)).expect("at least MIN_CANDIDATES orders");
    let z = if range.is_some() {
        z_of(best, drop)
    } else {
        0.0
    };
    let mut coherence_of = |n: u32| coherence(&responses(n), &e);
    let best_coherence = coherence_of(best);
    // an order below the candidates that beats them all and stands out itself; without
    // candidates, the best order searched when its ripple is alike along the record and
    // removes a share of the cost that no chance correlation does
    let below_best = top(floor).filter(|d| d.0 < lo).and_then(|d| {
        let z = if range.is_some() { z_of(d.0, d.1) } else { 0.0 };
        let stands_out = if range.is_some() {
            z >= SIGNIFICANT_Z
        } else {
            share_of(d.1) >= MIN_SHORT_SHARE
        };
        (stands_out && coherence_of(d.0) >= MIN_COHERENCE).then_some((d.0, z, d.1, d.2))
    });
    let candidate_found = range.is_some() && z >= SIGNIFICANT_Z && best_coherence >= MIN_COHERENCE;
    let (order, drop, ab) = match below_best {
        Some((n, _, drop, ab)) => (Some(n), drop, ab),
        None if candidate_found => (Some(best), drop, ab),
        None => (None, drop, ab),
    };
    Ok(Some(OrderSearch {
        order,
        coherence: best_coherence,
        best,
        z,
        share: share_of(drop),
        amplitude: ab[0].hypot(ab[1]),
        phase: ab[1].atan2(ab[0]),
        range,
        searched: (floor, hi),
        periods: travel_periods(data, f64::from(order.unwrap_or(best))),
        below: below_best.map(|(n, z, _, _)| (n, z)),
        drops: pairs,
    }))
}

/// How likely a residual with no ripple of order `order` is to lower the cost of `data`
/// (another record than the one the order was found on: the validation record, whose
/// excitation has other phases) as much as that order does: `exp(−d_n ln 2 / median d)`,
/// with `d` the cost drops of the candidate orders the travel tells apart from it. A
/// ripple is a torque of the angle, so the order found on the estimation record lowers
/// the cost of any record that moves the motor over the angle. A record under a periodic
/// excitation repeats its angle against time from period to period, so a residual that
/// is periodic in time (the odd distortion of a gap or of friction) correlates with some
/// order alike on every part of it; on a record with another trajectory it falls on
/// other orders. For a residual with no ripple at the order, its drop is a least-squares
/// fit of two regressors, whose share of the cost is exponentially distributed over the
/// orders (a periodogram ordinate, Schuster's test), scaled by the median drop. `None` when
/// `data` does not move the motor over enough periods of the order to tell it apart
/// ([`MIN_PERIODS`]) or has too few candidates.
///
/// # Errors
/// [`NlError::Unstable`] when the model does not simulate to finite values on `data`.
pub fn replication(
    data: &IdData,
    model: &NlModel,
    values: &[f64],
    order: u32,
) -> Result<Option<f64>, NlError> {
    Ok(search_order(data, model, values)?.and_then(|found| chance_of(&found, data, order)))
}

/// The chance level of `order` in the search `found` made on `data` ([`replication`]).
pub fn chance_of(found: &OrderSearch, data: &IdData, order: u32) -> Option<f64> {
    let (lo, hi) = found.range?;
    let &(_, drop) = found.drops.iter().find(|d| d.0 == order)?;
    if !(lo..=hi).contains(&order) {
        return None;
    }
    let null = told_apart(&found.drops, lo, span(data), order);
    if null.len() < MIN_CANDIDATES {
        return None;
    }
    let median = null[null.len() / 2];
    Some(if median > 0.0 {
        (-drop * std::f64::consts::LN_2 / median).exp()
    } else {
        0.0
    })
}

/// Peak of the normalised cross-correlation of two records' motor velocities from which the
/// second repeats the first's trajectory ([`repeats_trajectory`]) [-].
pub const SAME_TRAJECTORY: f64 = 0.7;

/// Whether `b` moves the motor along the trajectory `a` moves it along, up to a shift in
/// time: the peak over the shifts of the cross-correlation of their motor velocities (the
/// first samples both records have, means taken off), over the square root of their
/// energies, at least [`SAME_TRAJECTORY`]. Two captures of the same multisine with the same
/// phases (the same excitation seed) give nearly 1 (1.000 in the test), less only by the noise and the part
/// of a period the shift leaves out of the overlap; with other phases, the lines' cosines
/// add at random phases at every shift and the peak stays a few tenths (0.32 in the test, a
/// record that shares only the start ramp). A record that
/// repeats the other's trajectory repeats its correlations with the angle too, so it
/// shows again whatever the other showed ([`replication`] is no test on it).
pub fn repeats_trajectory(a: &IdData, b: &IdData) -> bool {
    trajectory_likeness(a, b) >= SAME_TRAJECTORY
}

/// The peak of the normalised cross-correlation of the motor velocities of `a` and `b`
/// ([`repeats_trajectory`]), 0 for records too short or at rest [-].
pub fn trajectory_likeness(a: &IdData, b: &IdData) -> f64 {
    let n = a.len().min(b.len());
    if n < 3 {
        return 0.0;
    }
    let centred = |d: &IdData| {
        let v = interval_velocity(&d.y[..n], d.ts);
        let mean = v.iter().sum::<f64>() / n as f64;
        v.into_iter().map(|x| x - mean).collect::<Vec<_>>()
    };
    let (va, vb) = (centred(a), centred(b));
    let energy =
        (va.iter().map(|x| x * x).sum::<f64>() * vb.iter().map(|x| x * x).sum::<f64>()).sqrt();
    if energy <= 0.0 {
        return 0.0;
    }
    let size = (2 * n).next_power_of_two();
    let mut planner = FftPlanner::<f64>::new();
    let fwd = planner.plan_fft_forward(size);
    let inv = planner.plan_fft_inverse(size);
    let spectrum = |v: &[f64]| {
        let mut z: Vec<Complex64> = v.iter().map(|&x| Complex64::new(x, 0.0)).collect();
        z.resize(size, Complex64::new(0.0, 0.0));
        fwd.process(&mut z);
        z
    };
    let (fa, fb) = (spectrum(&va), spectrum(&vb));
    let mut r: Vec<Complex64> = fa.iter().zip(&fb).map(|(x, y)| x * y.conj()).collect();
    inv.process(&mut r);
    let peak = r.iter().map(|z| z.re.abs()).fold(0.0, f64::max) / size as f64;
    peak / energy
}

/// The model of the ripple fit `fit` with its ripple taken out (its structure, lag, offset
/// and other effects), laid out to simulate `data` from that record's own initial
/// velocity (the search's prefilter takes the start's transient off): the residual
/// [`replication`] searches on another record than the fit's.
pub fn without_ripple(fit: &super::NlFit, data: &IdData) -> (NlModel, Vec<f64>) {
    let model = NlModel {
        effects: fit
            .model
            .effects
            .iter()
            .filter(|e| !matches!(e, crate::model::effects::Effect::TorqueRipple(_)))
            .copied()
            .collect(),
        ..fit.model.clone()
    };
    let v0 = data.y.get(1).map_or(0.0, |y1| (y1 - data.y[0]) / data.ts);
    let values = model.values(&fit.plant, fit.get("offset").unwrap_or(0.0), v0);
    (model, values)
}

/// The cost drops of the candidate orders (from `lo`) the travel tells apart from `order`
/// (their ripples differ by a period or more over it), sorted: what a residual with no
/// ripple at `order` gives.
fn told_apart(drops: &[(u32, f64)], lo: u32, travel: f64, order: u32) -> Vec<f64> {
    let mut sorted: Vec<f64> = drops
        .iter()
        .filter(|d| d.0 >= lo && (d.0.abs_diff(order) as f64) * travel >= std::f64::consts::TAU)
        .map(|d| d.1)
        .collect();
    sorted.sort_by(f64::total_cmp);
    sorted
}

/// `data` with the ripple `A sin(n θ_m + φ)` at the measured angle taken off the motor:
/// its torque added to the torque reference, held over each sample interval at its mean
/// along the motion (as the search's responses hold it), so that what moves the motor from the
/// compensated torque is the linear structure (the ripple is a torque the reference does
/// not command; at a short travel, a stiffness to the ground that a linear fit otherwise
/// bends the structure to explain).
pub fn compensated(data: &IdData, ripple: &TorqueRipple) -> IdData {
    let y = &data.y;
    let mut out = data.clone();
    for (k, u) in out.u.iter_mut().enumerate() {
        let next = y[(k + 1).min(y.len() - 1)];
        *u += ripple_interval_mean(ripple.amplitude, ripple.order, ripple.phase, y[k], next);
    }
    out
}

/// The 2 × 2 least squares of `e` on the responses `g` over the samples `range`: the cost
/// drop and `(a, b)`.
fn least_squares(
    g: &[Vec<f64>; 2],
    e: &[f64],
    range: std::ops::Range<usize>,
) -> (f64, Vector2<f64>) {
    let dot = |a: &[f64], b: &[f64]| {
        a[range.clone()]
            .iter()
            .zip(&b[range.clone()])
            .map(|(x, y)| x * y)
            .sum::<f64>()
    };
    let gram = Matrix2::new(
        dot(&g[0], &g[0]),
        dot(&g[0], &g[1]),
        dot(&g[1], &g[0]),
        dot(&g[1], &g[1]),
    );
    let rhs = Vector2::new(dot(&g[0], e), dot(&g[1], e));
    match gram.try_inverse() {
        Some(inv) => {
            let ab = inv * rhs;
            (rhs.dot(&ab).max(0.0), ab)
        }
        None => (0.0, Vector2::zeros()),
    }
}

/// How alike the ripple `(a, b)` fitted on each of [`COHERENCE_PARTS`] equal parts of the
/// record is: `|Σ c_k|² / (K Σ |c_k|²)` with `c_k = a_k + i b_k`, 1 when every part
/// gives the same ripple, about `1/K` when the phase wanders (a torque that is periodic in
/// time, not in the angle, e.g. a slow load, correlates with `sin(n θ)` at the order where
/// `n |ω|` is its frequency, with a phase that drifts along the record).
fn coherence(g: &[Vec<f64>; 2], e: &[f64]) -> f64 {
    let part = e.len() / COHERENCE_PARTS;
    let (mut sum, mut power) = (Complex64::new(0.0, 0.0), 0.0);
    for k in 0..COHERENCE_PARTS {
        let (_, ab) = least_squares(g, e, k * part..(k + 1) * part);
        let c = Complex64::new(ab[0], ab[1]);
        sum += c;
        power += c.norm_sqr();
    }
    if power > 0.0 {
        sum.norm_sqr() / (COHERENCE_PARTS as f64 * power)
    } else {
        0.0
    }
}

/// `x[1..]` through the cost's prefilter (the default high-pass, [`super::output_error::cost_at`]).
fn highpassed(x: &[f64], ts: f64) -> Vec<f64> {
    let mut bank = SosBank::new(
        butter_highpass_sos(2, super::output_error::DEFAULT_HIGHPASS_HZ, ts),
        1,
    );
    x.iter()
        .skip(1)
        .map(|&a| {
            let mut s = [a];
            bank.push(&mut s);
            s[0]
        })
        .collect()
}
