//! The robot's own controller, identified from the closed-loop record: a linear
//! discrete law from the reference `θ_ref` and the measured motor angle `θ_m` to the
//! torque reference `u`,
//!
//! `A(q) u[k] = B(q) θ_ref[k] − C(q) θ_m[k] + c₀`, `A = 1 + a₁q⁻¹ + … + a_na q⁻ⁿᵃ`,
//! `B = b₀ + … + b_nl q⁻ⁿˡ`, `C = c₀ + … + c_nl q⁻ⁿˡ`.
//!
//! Why: the commercial controller cannot be changed (seed 000 §2, Fig. 2), but all three of
//! its signals are recorded, so its law follows from least squares with no plant model: `u`
//! is a function of `θ_ref` and `θ_m` alone, whatever the joint does. A cascade
//! P/PI with velocity and torque feedforward (the simulator's, [`crate::sim::controller`])
//! is `na = 1`, `nl = 3`; a PID with a filtered derivative is `na = 2`, `nl = 2`. Several
//! orders are fitted and the one whose simulated `u` (driven by the measured `θ_ref` and
//! `θ_m`) matches best is kept; its FIT says how far the law can be trusted.
//!
//! What for: a model simulated in the loop through this law is stable where the open-loop
//! simulation from the measured torque is chaotic (a stiffening spring the loop damps; see
//! [`crate::diagnose::metric::simulate_closed`]).

use crate::data::IdData;
use crate::ident::validate::fit_percent;
use nalgebra::{DMatrix, DVector};

/// The orders `(na, nl)` tried, simplest first.
const ORDERS: [(usize, usize); 4] = [(1, 2), (1, 3), (2, 3), (2, 4)];

/// A more complex order is kept only when its FIT is this much higher [FIT points].
const ORDER_GAIN: f64 = 0.05;

/// A linear controller law identified from `θ_ref`, `θ_m` and `u`.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearController {
    /// `a₁ … a_na` of `A(q)` [-]
    pub a: Vec<f64>,
    /// `b₀ … b_nl` on the reference [N·m/rad]
    pub b: Vec<f64>,
    /// `c₀ … c_nl` on the motor angle (entering with a minus sign) [N·m/rad]
    pub c: Vec<f64>,
    /// constant term [N·m]
    pub bias: f64,
    /// FIT of `u` simulated through the law from the measured `θ_ref` and `θ_m` against the
    /// measured `u` [%]
    pub fit: f64,
}

/// How well an identified law holds on a record ([`LinearController::check_on`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LawCheck {
    /// FIT of the simulated `u` against the measured `u` [%]
    pub fit: f64,
    /// `var(Δe) / (2 var(e))` of the difference `e` between them [-]: 1 when `e` is white
    /// (the noise on the recorded `u`, which sets the FIT's ceiling when the torque is
    /// small), near 0 when it is smooth (a law that is wrong, or a controller that is not
    /// linear or not the same)
    pub whiteness: f64,
}

/// The running law: its past inputs and outputs, newest first.
#[derive(Clone, Debug)]
pub struct ControllerRun<'a> {
    law: &'a LinearController,
    u: Vec<f64>,
    r: Vec<f64>,
    y: Vec<f64>,
}

impl LinearController {
    /// The law started as if `θ_ref = r0`, `θ_m = y0` and `u = u0` had held forever.
    pub fn start(&self, r0: f64, y0: f64, u0: f64) -> ControllerRun<'_> {
        ControllerRun {
            law: self,
            u: vec![u0; self.a.len()],
            r: vec![r0; self.b.len()],
            y: vec![y0; self.c.len()],
        }
    }

    /// How well the law holds on `data` (a record it was not fitted on): `u` simulated
    /// through it from the measured `θ_ref` and `θ_m`, against the measured `u`.
    ///
    /// # Errors
    /// [`ControllerError`] when `data` has no reference or is too short, or the FIT cannot
    /// be computed.
    pub fn check_on(&self, data: &IdData) -> Result<LawCheck, ControllerError> {
        let r = data.r.as_deref().ok_or(ControllerError::NoReference)?;
        let lags = self.b.len().max(self.a.len());
        if data.len() < 200 || r.len() != data.len() {
            return Err(ControllerError::TooShort(data.len()));
        }
        let sim = self.simulate(r, data);
        let fit = fit_percent(&data.u[lags..], &sim[lags..]).map_err(ControllerError::Fit)?;
        let e: Vec<f64> = data.u[lags..]
            .iter()
            .zip(&sim[lags..])
            .map(|(u, s)| u - s)
            .collect();
        let mean = e.iter().sum::<f64>() / e.len() as f64;
        let var = e.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / e.len() as f64;
        let dvar = e.windows(2).map(|w| (w[1] - w[0]).powi(2)).sum::<f64>() / (e.len() - 1) as f64;
        Ok(LawCheck {
            fit,
            whiteness: if var > 0.0 { dvar / (2.0 * var) } else { 1.0 },
        })
    }

    /// `u` simulated through the law from the measured `θ_ref` and `θ_m` of `data`, its
    /// first `lags` samples the measured ones.
    fn simulate(&self, r: &[f64], data: &IdData) -> Vec<f64> {
        let lags = self.b.len().max(self.a.len());
        let mut out = data.u[..lags].to_vec();
        let mut run = ControllerRun {
            law: self,
            u: (0..self.a.len()).map(|i| data.u[lags - 1 - i]).collect(),
            r: (0..self.b.len()).map(|i| r[lags - 1 - i]).collect(),
            y: (0..self.c.len()).map(|i| data.y[lags - 1 - i]).collect(),
        };
        for (rk, yk) in r.iter().zip(&data.y).skip(lags) {
            out.push(run.step(*rk, *yk));
        }
        out
    }
}

impl ControllerRun<'_> {
    /// One sample: reference `r` [rad] and motor angle `y` [rad] → torque reference [N·m].
    pub fn step(&mut self, r: f64, y: f64) -> f64 {
        shift_in(&mut self.r, r);
        shift_in(&mut self.y, y);
        let l = self.law;
        let mut u = l.bias;
        u -= l.a.iter().zip(&self.u).map(|(a, u)| a * u).sum::<f64>();
        u += l.b.iter().zip(&self.r).map(|(b, r)| b * r).sum::<f64>();
        u -= l.c.iter().zip(&self.y).map(|(c, y)| c * y).sum::<f64>();
        shift_in(&mut self.u, u);
        u
    }
}

/// `x` with `v` put in front and its oldest value dropped.
fn shift_in(x: &mut [f64], v: f64) {
    if x.is_empty() {
        return;
    }
    x.rotate_right(1);
    x[0] = v;
}

/// Why no controller law was identified, or checked.
#[derive(Debug, PartialEq, thiserror::Error)]
pub enum ControllerError {
    /// the record holds no reference
    #[error("the record holds no reference θ_ref, from which the controller's law would follow")]
    NoReference,
    /// too short for the orders tried
    #[error("{0} samples: too few to identify the controller's law")]
    TooShort(usize),
    /// least squares failed or the simulated law blew up, for every order (the last one's
    /// failure)
    #[error("no order of the controller's law reproduces u: {0}")]
    NoFit(#[source] OrderError),
    /// the FIT of the law's simulated `u` cannot be computed (a constant torque)
    #[error("the FIT of the controller's law: {0}")]
    Fit(#[source] crate::ident::validate::ValidateError),
}

/// Why the law of one pair of orders was not identified.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum OrderError {
    /// the least-squares problem could not be solved (the solver's reason)
    #[error("orders ({na}, {nl}): least squares: {reason}")]
    LeastSquares {
        /// past torques
        na: usize,
        /// lags of the reference and the angle
        nl: usize,
        /// what the solver said
        reason: &'static str,
    },
    /// the law's simulated torque is not finite at any pass
    #[error("orders ({na}, {nl}): the simulated u is not finite")]
    NotFinite {
        /// past torques
        na: usize,
        /// lags of the reference and the angle
        nl: usize,
    },
}

/// The controller's law from the `θ_ref`, `θ_m` and `u` of `data` (least squares of the
/// equation error, each order of `ORDERS`; the simplest order within `ORDER_GAIN` of
/// the best simulated FIT).
///
/// # Errors
/// [`ControllerError`] when `data` has no reference, is too short, or no order reproduces
/// `u`.
pub fn identify(data: &IdData) -> Result<LinearController, ControllerError> {
    let r = data.r.as_deref().ok_or(ControllerError::NoReference)?;
    let n = data.len();
    if n < 200 || r.len() != n {
        return Err(ControllerError::TooShort(n));
    }
    let mut best: Option<LinearController> = None;
    // `ORDERS` is not empty: with no law, the last order's failure is set
    let mut last_err = OrderError::NotFinite { na: 0, nl: 0 };
    for (na, nl) in ORDERS {
        match fit_order(r, data, na, nl) {
            Ok(c) => {
                let better = best.as_ref().is_none_or(|b| c.fit > b.fit + ORDER_GAIN);
                if better {
                    best = Some(c);
                }
            }
            Err(e) => last_err = e,
        }
    }
    best.ok_or(ControllerError::NoFit(last_err))
}

/// Instrumental-variable passes after the least-squares start.
const IV_PASSES: usize = 2;

/// The law of orders `(na, nl)`: least squares of the equation error, then
/// [`IV_PASSES`] instrumental-variable passes whose instruments are the law's own simulated
/// `u` in place of the measured past `u` (Söderström & Stoica, *System Identification*,
/// 1989, §8: the noise on the recorded `u` biases least squares through its past values,
/// which leaves the integrator of a PI leaky at a small torque); the pass with the best
/// simulated FIT is kept.
fn fit_order(
    r: &[f64],
    data: &IdData,
    na: usize,
    nl: usize,
) -> Result<LinearController, OrderError> {
    let lags = na.max(nl + 1);
    let n = data.len();
    let rows = n - lags;
    let p = na + 2 * (nl + 1) + 1;
    let scale = |x: &[f64]| {
        let m = x.iter().sum::<f64>() / x.len() as f64;
        let s = (x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / x.len() as f64).sqrt();
        if s > 0.0 {
            s
        } else {
            1.0
        }
    };
    let (su, sr, sy) = (scale(&data.u), scale(r), scale(&data.y));
    // the regressors with `past` as the past torque
    let regressors = |past: &[f64]| {
        let mut phi = DMatrix::<f64>::zeros(rows, p);
        for (row, k) in (lags..n).enumerate() {
            for i in 1..=na {
                phi[(row, i - 1)] = -past[k - i] / su;
            }
            for i in 0..=nl {
                phi[(row, na + i)] = r[k - i] / sr;
                phi[(row, na + nl + 1 + i)] = -data.y[k - i] / sy;
            }
            phi[(row, p - 1)] = 1.0;
        }
        phi
    };
    let target = DVector::<f64>::from_iterator(rows, data.u[lags..].iter().map(|u| u / su));
    let law_of = |theta: &DVector<f64>| LinearController {
        a: (0..na).map(|i| theta[i]).collect(),
        b: (0..=nl).map(|i| theta[na + i] * su / sr).collect(),
        c: (0..=nl).map(|i| theta[na + nl + 1 + i] * su / sy).collect(),
        bias: theta[p - 1] * su,
        fit: f64::NAN,
    };
    // the law and its simulated u, scored
    let scored = |mut law: LinearController| -> Option<(LinearController, Vec<f64>)> {
        let sim = law.simulate(r, data);
        if sim.iter().any(|v| !v.is_finite()) {
            return None;
        }
        law.fit = fit_percent(&data.u[lags..], &sim[lags..]).ok()?;
        Some((law, sim))
    };
    let phi = regressors(&data.u);
    let theta = phi
        .clone()
        .svd(true, true)
        .solve(&target, 1e-12)
        .map_err(|reason| OrderError::LeastSquares { na, nl, reason })?;
    let mut best = scored(law_of(&theta));
    let mut current = best.clone();
    for _ in 0..IV_PASSES {
        let Some((_, sim)) = &current else { break };
        let z = regressors(sim);
        let lhs = z.transpose() * &phi;
        let rhs = z.transpose() * &target;
        let Ok(theta) = lhs.svd(true, true).solve(&rhs, 1e-12) else {
            break;
        };
        current = scored(law_of(&theta));
        if let Some((c, _)) = &current {
            if best.as_ref().is_none_or(|(b, _)| c.fit > b.fit) {
                best = current.clone();
            }
        }
    }
    best.map(|(law, _)| law)
        .ok_or(OrderError::NotFinite { na, nl })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::controller::{Controller, ControllerConfig};

    /// `θ_m` a multisine-like record and `u` the cascade's output on it.
    fn record(cfg: ControllerConfig, u_noise: f64) -> (IdData, Vec<f64>) {
        let ts = 5e-4;
        let n = 6000;
        // a multisine of 20 lines 0.5–40 Hz as the reference, the angle following it with a
        // lag and a resonance of its own
        let sines = |k: usize, amp: f64, phase: f64| {
            let t = k as f64 * ts;
            (1..=20)
                .map(|i| {
                    let f = 0.5 + 2.0 * (i - 1) as f64;
                    amp / i as f64
                        * (2.0 * std::f64::consts::PI * f * t + phase * (i * i) as f64).sin()
                })
                .sum::<f64>()
        };
        let r: Vec<f64> = (0..n).map(|k| sines(k, 0.03, 0.7)).collect();
        let mut g = crate::ident::linalg::GaussRng::new(3);
        let y: Vec<f64> = (0..n)
            .map(|k| 0.9 * r[k.saturating_sub(8)] + sines(k, 0.002, 1.9) + 1e-5 * g.normal())
            .collect();
        let mut c = Controller::new(cfg, ts);
        let clean: Vec<f64> = r.iter().zip(&y).map(|(r, y)| c.step(*r, *y)).collect();
        let u = clean.iter().map(|u| u + u_noise * g.normal()).collect();
        (
            IdData {
                ts,
                u,
                y,
                r: Some(r),
            },
            clean,
        )
    }

    #[test]
    fn the_cascade_is_recovered_from_its_three_signals() {
        for cfg in [
            ControllerConfig::default(),
            ControllerConfig {
                kp: 10.0,
                kv: 0.35,
                ti: 0.08,
                feedforward: true,
                ..ControllerConfig::default()
            },
        ] {
            let (data, clean) = record(cfg, 2e-3);
            let law = identify(&data).expect("a law");
            // the noise on the recorded u sets the ceiling: the cascade itself scores this
            let ceiling = fit_percent(&data.u, &clean).unwrap();
            assert!(
                law.fit > ceiling - 0.5,
                "{cfg:?}: FIT {:.3}, the cascade's {ceiling:.3}",
                law.fit
            );
            // the law run on new inputs gives the cascade's output
            let (fresh, fresh_clean) = record(cfg, 0.0);
            let r = fresh.r.as_deref().unwrap();
            let mut run = law.start(r[0], fresh.y[0], fresh_clean[0]);
            let mut c = Controller::new(cfg, fresh.ts);
            let mut worst: f64 = 0.0;
            for (k, (rk, yk)) in r.iter().zip(&fresh.y).enumerate() {
                let a = run.step(*rk, *yk);
                let b = c.step(*rk, *yk);
                if k > 10 {
                    worst = worst.max((a - b).abs());
                }
            }
            let u_rms = (clean.iter().map(|v| v * v).sum::<f64>() / clean.len() as f64).sqrt();
            assert!(
                worst < 0.02 * u_rms,
                "{cfg:?}: worst {worst:.3e} of {u_rms:.3e}"
            );
        }
    }

    #[test]
    fn a_record_without_reference_says_so() {
        let (mut data, _) = record(ControllerConfig::default(), 0.0);
        data.r = None;
        assert_eq!(identify(&data), Err(ControllerError::NoReference));
    }

    #[test]
    fn a_law_checked_on_a_constant_torque_says_the_fit_is_undefined() {
        let (mut data, _) = record(ControllerConfig::default(), 0.0);
        data.u = vec![0.5; data.u.len()];
        let law = LinearController {
            a: vec![-0.5],
            b: vec![1.0, 0.0],
            c: vec![1.0, 0.0],
            bias: 0.0,
            fit: f64::NAN,
        };
        let e = law.check_on(&data).unwrap_err();
        assert_eq!(
            e,
            ControllerError::Fit(crate::ident::validate::ValidateError::ConstantOutput)
        );
        assert_eq!(
            e.to_string(),
            "the FIT of the controller's law: measured output is constant: fit undefined"
        );
        let e = ControllerError::NoFit(OrderError::NotFinite { na: 2, nl: 4 });
        assert_eq!(
            e.to_string(),
            "no order of the controller's law reproduces u: orders (2, 4): the simulated u is \
             not finite"
        );
    }
}
