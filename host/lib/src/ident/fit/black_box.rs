//! The black box of order `n` in the time domain (seed 000 eq. (9)): subspace starts
//! ([`crate::ident::subspace`], PBSID and PO-MOESP), the best refined by output error of
//! every matrix entry ([`FullSs`], seed 000 eq. (14)–(15)).
//!
//! **The rigid-body integrator.** A joint driven by its torque has a free rigid-body mode,
//! so its motor angle integrates the motor velocity: seed 000 §4 counts that integrator as
//! the extra state of the angle output. A free order-`n` model has to find that pole at
//! `z = 1` from the data, at 2 kHz among poles that all lie near 1, and it does not: on a
//! closed-loop three-mass joint of 14,000 samples (`jointid simulate --periods 2
//! --ideal-sensors`, encoder-sized noise added) PBSID of order 11 put it at 0.99993 and
//! scored 95.4 % on validation against 99.7 % for the true model, and its output-error
//! refinement left the unit circle. So, for an angle output without feed-through, the
//! candidates include the *integrator structure*: `n − 1` free states for the differenced
//! angle `Δy(t) = y(t) − y(t − 1)` (the interval-mean motor velocity times `Ts`) and the
//! integrator that sums it ([`StateSpace::with_integrator`]; the pole at 1 is exact and stays there).
//!
//! **Which structure.** The data decide, by one criterion for every start: the output
//! error of `Δy` with its best initial state ([`delta_cost`]). It is the criterion the
//! integrator structure is refined by, and the one where a free model and an integrating
//! one meet on equal terms (on the angle, a slow drift would favour whichever follows it).
//! A grounded structure (a spring to ground, no free mode) keeps a free model.
//!
//! **Drift.** The torque the position loop spends against a slow disturbance drives the
//! simulated angle away from the measured one, whatever the model (the true model's
//! toolbox FIT of the angle is −3,000 % on the simulator's default sensors). When the
//! refined model's FIT of the angle on the estimation record is below
//! [`super::spectral::DRIFT_ANGLE_FIT`], the free part is fitted again on `u` and `Δy`
//! through the second-order high-pass of the physical fits
//! ([`crate::ident::nonlinear::output_error::DEFAULT_HIGHPASS_HZ`]) and the fit reports
//! the velocity FIT ([`FitMetric::Velocity`]), as a physical model on such data does.
//!
//! Measured (release, this module's test records and `jointid fit … --model black-box:11`
//! on 14,000-sample records with a noise validation): no drift, 99.70 % validation against
//! 99.69 % for the three-mass fit (was 95.35 %); default sensors, velocity FIT 81.1 %
//! against the three-mass fit's 79.9 % (the angle's FIT was 8.9 %, the true model's is
//! below −3,000 %). Refinement: 0.5 s for 20 iterations of 120 parameters on 14,000
//! samples ([`crate::ident::pem`]'s transposed sensitivity filter).

use nalgebra::{DMatrix, DVector, RowDVector};

use crate::data::IdData;
use crate::ident::grey_box::Output;
use crate::ident::nonlinear::output_error::{highpassed_pair, DEFAULT_HIGHPASS_HZ};
use crate::ident::pem::{self, FullSs, ParamModel, PemOptions};
use crate::ident::ss::StateSpace;
use crate::ident::subspace::{self, estimate_x0, Method, Order, SubspaceOptions};
use crate::ident::validate::fit_percent;

use super::spectral::DRIFT_ANGLE_FIT;
use super::{FitError, FitMetric, FitOptions, Fitted, PEM_BUDGET};

/// Iterations of the black box's output-error refinement.
const REFINE_ITERATIONS: usize = 40;

fn method_name(m: Method) -> &'static str {
    match m {
        Method::Pbsid => "PBSID",
        Method::Moesp => "PO-MOESP",
    }
}

/// Black box of order `n` on `data` (module docs): the integrator structure competes
/// with the free model for an angle output without feed-through; otherwise the chosen
/// subspace method and the other one, each refined, the lower output-error cost kept.
///
/// # Errors
/// [`FitError::Subspace`] when no subspace start can be made.
pub(super) fn fit_black_box(
    data: &IdData,
    n: usize,
    opts: &FitOptions,
) -> Result<Fitted, FitError> {
    let (model, method, warnings, metric) =
        if opts.output == Output::Angle && !opts.feedthrough && n >= 2 {
            angle_black_box(data, n, opts)?
        } else {
            let (model, desc, warnings) = free_black_box(data, n, opts)?;
            (model, desc, warnings, FitMetric::Output)
        };
    Ok(Fitted {
        spec: opts.spec.clone(),
        output: opts.output,
        ts: data.ts,
        model,
        continuous: None,
        params: Vec::new(),
        friction: None,
        warnings,
        method,
        decimate: 1,
        fit_metric: metric,
    })
}

/// The subspace model of `method` and order `n` on `data`, without a noise model.
fn subspace_model(
    data: &IdData,
    n: usize,
    method: Method,
    opts: &FitOptions,
) -> Result<(StateSpace, Vec<String>), FitError> {
    let sopts = SubspaceOptions {
        method,
        order: Order::Fixed(n),
        feedthrough: opts.feedthrough,
        ..SubspaceOptions::default()
    };
    let sf = subspace::estimate(data, &sopts)?;
    let mut model = sf.model;
    model.k = None;
    Ok((model, sf.warnings))
}

/// Mean squared simulation error of `m` on `data` with its best initial state (infinite
/// when it does not simulate).
fn sim_cost(m: &StateSpace, data: &IdData) -> f64 {
    let x0 = estimate_x0(m, &data.u, &data.y);
    let yh = m.simulate(&data.u, Some(&x0));
    let c = data
        .y
        .iter()
        .zip(&yh)
        .map(|(a, b)| (a - b) * (a - b))
        .sum::<f64>()
        / data.len().max(1) as f64;
    if c.is_finite() {
        c
    } else {
        f64::INFINITY
    }
}

/// `m` refined by output error on `data` when `opts.refine` and the problem is within
/// [`PEM_BUDGET`]; a refinement that leaves the unit circle or does not descend is
/// rejected. Returns the model, whether it was refined, and a note.
fn refined(
    m: &StateSpace,
    data: &IdData,
    opts: &FitOptions,
    what: &str,
) -> (StateSpace, bool, Option<String>) {
    if !opts.refine {
        return (m.clone(), false, None);
    }
    let (fam, th0) = FullSs::from_ss(m, opts.feedthrough, false);
    let np = fam.n_params() as f64;
    if (data.len() as f64) * np * np > PEM_BUDGET {
        return (
            m.clone(),
            false,
            Some(format!(
                "{what}: output-error refinement skipped: {} samples × {np} parameters exceed the budget",
                data.len()
            )),
        );
    }
    match pem::fit(
        &fam,
        &th0,
        data,
        &PemOptions::with_max_iter(REFINE_ITERATIONS),
    ) {
        Ok(pf) => {
            let start = pf.cost_history.first().copied().unwrap_or(f64::INFINITY);
            let end = pf.cost_history.last().copied().unwrap_or(f64::INFINITY);
            if pf.model.is_stable() && end <= start {
                let mut model = pf.model;
                model.k = None;
                (model, true, None)
            } else {
                (
                    m.clone(),
                    false,
                    Some(format!(
                        "{what}: output-error refinement rejected (unstable or no descent)"
                    )),
                )
            }
        }
        Err(e) => (
            m.clone(),
            false,
            Some(format!("{what}: output-error refinement failed: {e}")),
        ),
    }
}

/// The free black box: the chosen subspace method and the other one as a second start
/// (PO-MOESP is biased under feedback but can still be the better start for the
/// output-error criterion, and PBSID can give a marginal model the refinement cannot
/// leave), each refined; the lower output-error cost on the estimation data wins.
fn free_black_box(
    data: &IdData,
    n: usize,
    opts: &FitOptions,
) -> Result<(StateSpace, String, Vec<String>), FitError> {
    let other = match opts.method {
        Method::Pbsid => Method::Moesp,
        Method::Moesp => Method::Pbsid,
    };
    let start = |method: Method| -> Result<(StateSpace, f64, String, Vec<String>), FitError> {
        let (m, mut warnings) = subspace_model(data, n, method, opts)?;
        let name = method_name(method);
        let (model, done, note) = refined(&m, data, opts, name);
        warnings.extend(note);
        let desc = format!(
            "{name} order {n}{}",
            if done {
                " + output-error refinement"
            } else {
                ""
            }
        );
        Ok((model.clone(), sim_cost(&model, data), desc, warnings))
    };
    let first = start(opts.method)?;
    let (model, _, desc, mut warnings) = match start(other) {
        Ok(second) if second.1 < first.1 => {
            let mut w = second.3.clone();
            w.push(format!(
                "the {} start gave the lower output-error cost and was kept",
                second.2
            ));
            (second.0, second.1, second.2, w)
        }
        _ => first,
    };
    warnings.dedup();
    Ok((model, desc, warnings))
}

/// `u(t)`, `Δy(t) = y(t) − y(t − 1)` and the reference from the second sample on.
pub(super) fn differenced(data: &IdData) -> IdData {
    IdData {
        ts: data.ts,
        u: data.u[1..].to_vec(),
        y: data.y.windows(2).map(|w| w[1] - w[0]).collect(),
        r: data.r.as_ref().map(|r| r[1..].to_vec()),
    }
}

/// `Δy` of the angle model `m` (no feed-through) as a model of order `n + 1` on the
/// [`differenced`] record: `ξ = [x(t); C x(t − 1)]`, `Δŷ = C x(t) − C x(t − 1)`.
fn delta_of(m: &StateSpace) -> StateSpace {
    let n = m.order();
    let mut a = DMatrix::zeros(n + 1, n + 1);
    a.view_mut((0, 0), (n, n)).copy_from(&m.a);
    for j in 0..n {
        a[(n, j)] = m.c[j];
    }
    let mut b = DVector::zeros(n + 1);
    b.rows_mut(0, n).copy_from(&m.b);
    let mut c = RowDVector::zeros(n + 1);
    c.columns_mut(0, n).copy_from(&m.c);
    c[n] = -1.0;
    StateSpace::new(a, b, c, 0.0, m.ts)
}

/// The integrator structure as a parameterised model of the angle: `θ` is every entry of
/// the free part's `A` (row-major), `B` and `C` ([`FullSs`] order), the integrator held.
struct Integrating {
    free: FullSs,
}

impl ParamModel for Integrating {
    fn n_params(&self) -> usize {
        self.free.n_params()
    }

    fn param_names(&self) -> Vec<String> {
        self.free.param_names()
    }

    fn to_ss(&self, theta: &[f64]) -> StateSpace {
        self.free.to_ss(theta).with_integrator()
    }

    /// exact: an entry of `C` also sets the integrator's input from that state
    fn d_ss(&self, theta: &[f64], i: usize) -> pem::SsDerivative {
        let n = self.free.n;
        let f = self.free.d_ss(theta, i);
        let mut da = DMatrix::zeros(n + 1, n + 1);
        da.view_mut((0, 0), (n, n)).copy_from(&f.da);
        let mut db = DVector::zeros(n + 1);
        db.rows_mut(0, n).copy_from(&f.db);
        let mut dc = RowDVector::zeros(n + 1);
        dc.columns_mut(0, n).copy_from(&f.dc);
        for j in 0..n {
            da[(n, j)] = f.dc[j];
        }
        pem::SsDerivative {
            da,
            db,
            dc,
            dd: 0.0,
            dk: None,
        }
    }
}

/// The free part `f` refined by output error on the angle record `data` with the
/// integrator held, when affordable; kept only when its free part stays inside the unit
/// circle and the cost does not rise.
fn refined_on_angle(f: &StateSpace, data: &IdData, opts: &FitOptions) -> (StateSpace, bool) {
    let (free, th0) = FullSs::from_ss(f, false, false);
    let np = free.n_params() as f64;
    if !opts.refine || (data.len() as f64) * np * np > PEM_BUDGET {
        return (f.clone(), false);
    }
    let model = Integrating { free };
    match pem::fit(
        &model,
        &th0,
        data,
        &PemOptions::with_max_iter(REFINE_ITERATIONS),
    ) {
        Ok(pf) => {
            let start = pf.cost_history.first().copied().unwrap_or(f64::INFINITY);
            let end = pf.cost_history.last().copied().unwrap_or(f64::INFINITY);
            let g = model.free.to_ss(&pf.theta);
            if g.is_stable() && end <= start {
                (g, true)
            } else {
                (f.clone(), false)
            }
        }
        Err(_) => (f.clone(), false),
    }
}

/// The free part of a model made by [`StateSpace::with_integrator`] (None for any other model).
pub(super) fn integrator_part(m: &StateSpace) -> Option<StateSpace> {
    let n = m.order().checked_sub(1)?;
    let last_col_free = (0..n).all(|i| m.a[(i, n)] == 0.0);
    let sums = m.a[(n, n)] == 1.0
        && m.c[n] == 1.0
        && m.b[n] == 0.0
        && m.d == 0.0
        && (0..n).all(|j| m.a[(n, j)] == m.c[j]);
    (n > 0 && last_col_free && sums).then(|| {
        StateSpace::new(
            m.a.view((0, 0), (n, n)).into_owned(),
            m.b.rows(0, n).into_owned(),
            m.c.columns(0, n).into_owned(),
            0.0,
            m.ts,
        )
    })
}

/// The toolbox FIT [%] of the angle model `m` on `data` (initial state estimated).
fn angle_fit(m: &StateSpace, data: &IdData) -> f64 {
    let x0 = estimate_x0(m, &data.u, &data.y);
    fit_percent(&data.y, &m.simulate(&data.u, Some(&x0))).unwrap_or(f64::NEG_INFINITY)
}

/// `u` and `Δy` of `delta` through the same second-order high-pass.
fn highpassed(delta: &IdData) -> IdData {
    let (u, y) = highpassed_pair(&delta.u, &delta.y, delta.ts, DEFAULT_HIGHPASS_HZ);
    IdData {
        ts: delta.ts,
        u,
        y,
        r: None,
    }
}

/// A start of the angle black box: the free model of order `n` or the integrator
/// structure, with its [`delta_cost`].
struct Start {
    method: Method,
    integrator: bool,
    /// the angle model (free) or the model of `Δy` (integrator)
    model: StateSpace,
    cost: f64,
    warnings: Vec<String>,
}

/// Output error of `Δy` with the best initial state: the one criterion every start of
/// the angle black box is scored by (module docs).
fn delta_cost(s: &StateSpace, integrator: bool, delta: &IdData) -> f64 {
    if integrator {
        sim_cost(s, delta)
    } else {
        sim_cost(&delta_of(s), delta)
    }
}

/// The black box of an angle output (module docs): returns the angle model, the method,
/// the notes and the metric its FIT is reported in.
fn angle_black_box(
    data: &IdData,
    n: usize,
    opts: &FitOptions,
) -> Result<(StateSpace, String, Vec<String>, FitMetric), FitError> {
    let delta = differenced(data);
    let mut starts = Vec::new();
    let mut first_error = None;
    for integrator in [false, true] {
        for method in [opts.method, other_method(opts.method)] {
            let (rec, order) = if integrator {
                (&delta, n - 1)
            } else {
                (data, n)
            };
            match subspace_model(rec, order, method, opts) {
                Ok((model, warnings)) => starts.push(Start {
                    method,
                    integrator,
                    cost: delta_cost(&model, integrator, &delta),
                    model,
                    warnings,
                }),
                Err(e) => {
                    first_error.get_or_insert(e);
                }
            }
        }
    }
    // the lowest cost; the order of `starts` breaks ties
    let Some(best) = starts
        .into_iter()
        .reduce(|a, b| if b.cost < a.cost { b } else { a })
    else {
        return Err(
            first_error.unwrap_or(FitError::BadData(crate::data::RecordError::TooShort {
                samples: data.len(),
                min: 2,
            })),
        );
    };
    let name = method_name(best.method);
    // a start's notes (poles reflected into the circle) describe the model only when the
    // refinement did not replace it
    let start_notes = |done: bool, notes: Vec<String>| if done { Vec::new() } else { notes };
    if !best.integrator {
        let (model, done, note) = refined(&best.model, data, opts, name);
        let mut warnings = start_notes(done, best.warnings);
        warnings.extend(note);
        let desc =
            format!(
            "{name} order {n}{}; scored against the integrator structure by the output error of \
             the differenced output",
            if done { " + output-error refinement" } else { "" }
        );
        return Ok((model, desc, warnings, FitMetric::Output));
    }
    let (free, done, note) = refined(&best.model, &delta, opts, name);
    let mut warnings = start_notes(done, best.warnings);
    warnings.extend(note);
    let fit = angle_fit(&free.with_integrator(), data);
    if fit >= DRIFT_ANGLE_FIT {
        // no drift to follow: the angle's own output error, which FIT measures
        let (free, on_angle) = refined_on_angle(&free, data, opts);
        let desc = format!(
            "{name} order {} on the differenced angle{} and the rigid-body integrator \
             (order {n}){}",
            n - 1,
            if done {
                " + output-error refinement"
            } else {
                ""
            },
            if on_angle {
                ", refined by output error on the angle"
            } else {
                ""
            }
        );
        return Ok((free.with_integrator(), desc, warnings, FitMetric::Output));
    }
    // a drift dominates the angle: the free part from the high-passed pair
    let hp = highpassed(&delta);
    let (start, w) = subspace_model(&hp, n - 1, best.method, opts)?;
    let (free_hp, done_hp, note) = refined(&start, &hp, opts, name);
    let mut warnings = start_notes(done_hp, w);
    warnings.extend(note);
    let desc = format!(
        "{name} order {} on the differenced angle through the {DEFAULT_HIGHPASS_HZ} Hz \
         second-order high-pass{} and the rigid-body integrator (order {n}); the angle's \
         toolbox FIT ({fit:.1} %) is dominated by a drift the loop rejects, so the velocity \
         FIT is reported",
        n - 1,
        if done_hp {
            " + output-error refinement"
        } else {
            ""
        }
    );
    Ok((
        free_hp.with_integrator(),
        desc,
        warnings,
        FitMetric::Velocity,
    ))
}

fn other_method(m: Method) -> Method {
    match m {
        Method::Pbsid => Method::Moesp,
        Method::Moesp => Method::Pbsid,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ident::nonlinear::output_error::{interval_velocity, pooled_velocity_fit};
    use crate::ident::ss::ContinuousSs;
    use crate::model::spec::{Family, ModelSpec};
    use crate::sim::{simulate_excitation, Disturbance, Mechanism, SimConfig};
    use jointid_core::excitation::{ExcitationConfig, SignalKind};

    /// 14,000 samples at 2 kHz of the simulator's default closed-loop three-mass joint
    /// under band-limited noise with no repeated period (the time-domain path), `drift`
    /// with the default sensors, else with the encoder and its noise but no torque
    /// disturbance and no noise on `u` (seed 000 §6's conditions); and the true model.
    fn record(seed: u64, drift: bool) -> (IdData, StateSpace) {
        let mut cfg = SimConfig {
            seed,
            ..SimConfig::default()
        };
        if !drift {
            cfg.sensors.disturbance = Disturbance::none();
            cfg.sensors.u_noise_std = 0.0;
        }
        let exc = ExcitationConfig {
            kind: SignalKind::BandLimitedNoise,
            period_samples: 14_000,
            max_line: 851,
            periods: 1,
            seed: 200 + seed,
            ..ExcitationConfig::paper_default()
        };
        let data = simulate_excitation(&cfg, &exc)
            .expect("simulation")
            .to_id_data();
        let mech = Mechanism::new(&cfg.plant, &cfg.effects);
        let (f, g) = mech.linear_model(cfg.controller.current_loop_tau);
        let n = f.nrows();
        let mut h = RowDVector::zeros(n);
        h[0] = 1.0;
        let truth = ContinuousSs {
            f: DMatrix::from_fn(n, n, |i, j| f[(i, j)]),
            g: DVector::from_fn(n, |i, _| g[(i, 0)]),
            h,
            d: 0.0,
        }
        .zoh(data.ts);
        (data, truth)
    }

    fn options() -> FitOptions {
        FitOptions {
            spec: ModelSpec::linear(Family::BlackBox(11)),
            ..FitOptions::default()
        }
    }

    /// velocity FIT [%] of the angle model `m` on `d` (from rest, through the high-pass)
    fn velocity_fit(m: &StateSpace, d: &IdData) -> f64 {
        let v = interval_velocity(&d.y, d.ts);
        let vh = interval_velocity(&m.simulate(&d.u, None), d.ts);
        pooled_velocity_fit(
            &[(v[1..].to_vec(), vh[1..].to_vec())],
            d.ts,
            DEFAULT_HIGHPASS_HZ,
        )
        .unwrap()
    }

    /// Issue 39 item 4: the order-11 black box at 2 kHz, undecimated, is within 1 point of
    /// the true model's validation FIT, with the rigid-body integrator exact and the rest
    /// stable. The free model of the old path scored 95.4 % against 99.7 % on such a record.
    #[test]
    fn order_11_at_2_khz_is_within_a_point_of_the_true_model() {
        let (est, truth) = record(1, false);
        let (val, _) = record(2, false);
        let fit = fit_black_box(&est, 11, &options()).unwrap();
        assert_eq!(fit.fit_metric, FitMetric::Output, "{}", fit.method);
        let free = integrator_part(&fit.model).expect("the integrator structure");
        assert!(free.is_stable(), "{}", fit.method);
        let (bb, tr) = (angle_fit(&fit.model, &val), angle_fit(&truth, &val));
        assert!(
            bb >= tr - 1.0,
            "black box {bb:.2} % vs true model {tr:.2} %"
        );
    }

    /// With the simulator's slow torque disturbance the angle's FIT says nothing (the true
    /// model's is far below zero): the black box reports the velocity FIT, within a point
    /// of the true model's.
    #[test]
    fn with_a_drift_the_velocity_fit_is_reported_and_within_a_point_of_the_true_model() {
        let (est, truth) = record(3, true);
        let (val, _) = record(4, true);
        assert!(angle_fit(&truth, &val) < DRIFT_ANGLE_FIT);
        let fit = fit_black_box(&est, 11, &options()).unwrap();
        assert_eq!(fit.fit_metric, FitMetric::Velocity, "{}", fit.method);
        let (bb, tr) = (velocity_fit(&fit.model, &val), velocity_fit(&truth, &val));
        assert!(
            bb >= tr - 1.0,
            "black box {bb:.2} % vs true model {tr:.2} %"
        );
    }

    #[test]
    fn the_integrator_structure_round_trips() {
        let f = StateSpace::new(
            DMatrix::from_row_slice(2, 2, &[0.9, 0.1, -0.2, 0.8]),
            DVector::from_vec(vec![1.0, 0.5]),
            RowDVector::from_row_slice(&[0.3, -0.1]),
            0.0,
            1e-3,
        );
        let m = f.with_integrator();
        assert_eq!(integrator_part(&m), Some(f.clone()));
        // the angle is the running sum of the free part's output
        let u: Vec<f64> = (0..50).map(|t| ((t * 7) % 5) as f64 - 2.0).collect();
        let dy = f.simulate(&u, None);
        let y = m.simulate(&u, None);
        let mut sum = 0.0;
        for (a, b) in dy.iter().zip(&y) {
            sum += a;
            assert!((sum - b).abs() < 1e-12);
        }
        assert_eq!(integrator_part(&f), None);
    }
}
