//! The robot's own joint controller, as seed 000 Fig. 2 describes it from outside: a
//! discrete cascade at the sample rate (2 kHz) from the reference `θ_ref` and the measured
//! motor angle to the torque reference `u` (what is measured as `u`), followed by a fast
//! current loop.
//!
//! Per sample `k` (period `T`):
//! - velocity estimate by backward difference: `ω̂[k] = (θ_m[k] − θ_m[k−1]) / T`;
//! - position P: `ω_ref = K_p (θ_ref[k] − θ_m[k]) + ω_ff`, with the optional velocity
//!   feedforward `ω_ff = (θ_ref[k] − θ_ref[k−1]) / T`;
//! - velocity PI (backward-Euler integral): `e = ω_ref − ω̂`, `I[k] = I[k−1] + K_v T/T_i e`,
//!   `u = sat(K_v e + I[k] + τ_ff, ±u_max)`, with the optional torque feedforward
//!   `τ_ff = J_ff (θ_ref[k] − 2θ_ref[k−1] + θ_ref[k−2]) / T²`;
//! - anti-windup by conditional integration: when the output saturates and `e` pushes
//!   further into the limit, the integral keeps its previous value.
//!
//! The current loop is modelled as a first-order lag `T_c τ̇_a = u_d − τ_a` (`T_c` ≈ 0.5 ms)
//! from the (possibly delayed) torque reference to the motor torque; being linear, it is
//! part of the plant state (see [`crate::model::plant`]).
//!
//! Default gains, tuned for the default three-mass joint (rigid inertia
//! `J = 1.882e-3 kg·m²` at the motor): `K_v = 0.2 N·m·s/rad` puts the rigid-body velocity
//! crossover at `K_v/J ≈ 106 rad/s ≈ 17 Hz`; `T_i = 0.05 s` puts the PI corner at 3.2 Hz;
//! `K_p = 18 1/s` gives a position bandwidth (−3 dB of `θ_ref → θ_m`) of 3.65 Hz with no
//! resonance peak (|T| ≤ 1), and the slowest closed-loop pole has modulus 0.9952 (about
//! 0.2 s time constant). The velocity loop is collocated (motor velocity, motor torque), so
//! the lightly damped arm modes at 17 and 23 Hz do not destabilise it. These numbers come
//! from the closed loop written out in `super::tests` (seed 000 eq. (6), current loop,
//! controller), which checks them. The torque limit `u_max = 12 N·m` is a typical peak
//! torque of a motor of this size.

use serde::{Deserialize, Serialize};

/// Gains and limits of the cascade controller and the current loop.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ControllerConfig {
    /// position gain `K_p` [1/s]
    pub kp: f64,
    /// velocity gain `K_v` [N·m·s/rad]
    pub kv: f64,
    /// integral time `T_i` of the velocity PI [s] (`f64::INFINITY` for P only)
    pub ti: f64,
    /// torque limit `u_max` [N·m]
    pub u_max: f64,
    /// velocity and torque feedforward from the reference on (default off)
    pub feedforward: bool,
    /// inertia `J_ff` used by the torque feedforward [kg·m²]
    pub ff_inertia: f64,
    /// current-loop time constant `T_c` [s] (> 0)
    pub current_loop_tau: f64,
}

impl Default for ControllerConfig {
    fn default() -> Self {
        ControllerConfig {
            kp: 18.0,
            kv: 0.2,
            ti: 0.05,
            u_max: 12.0,
            feedforward: false,
            ff_inertia: 1.882e-3,
            current_loop_tau: 5.0e-4,
        }
    }
}

/// Running state of the discrete controller.
#[derive(Clone, Debug)]
pub struct Controller {
    cfg: ControllerConfig,
    ts: f64,
    integral: f64,
    prev_theta: Option<f64>,
    prev_ref: [f64; 2],
    started: bool,
    saturated: u64,
    /// integral gain per sample `K_v T / T_i` (0 for P only)
    ki: f64,
}

impl Controller {
    /// New controller at rest, sample interval `ts` [s].
    pub fn new(cfg: ControllerConfig, ts: f64) -> Self {
        Controller {
            cfg,
            ts,
            integral: 0.0,
            prev_theta: None,
            prev_ref: [0.0; 2],
            started: false,
            saturated: 0,
            ki: if cfg.ti.is_finite() {
                cfg.kv * ts / cfg.ti
            } else {
                0.0
            },
        }
    }

    /// One sample: reference `theta_ref` [rad] and measured motor angle `theta_m` [rad] →
    /// torque reference `u` [N·m]. The first sample takes the velocity estimate as 0 and the
    /// reference history as constant.
    pub fn step(&mut self, theta_ref: f64, theta_m: f64) -> f64 {
        let c = &self.cfg;
        let t = self.ts;
        if !self.started {
            self.prev_ref = [theta_ref; 2];
            self.started = true;
        }
        let omega = match self.prev_theta {
            Some(p) => (theta_m - p) / t,
            None => 0.0,
        };
        self.prev_theta = Some(theta_m);
        let (w_ff, tau_ff) = if c.feedforward {
            (
                (theta_ref - self.prev_ref[0]) / t,
                c.ff_inertia * (theta_ref - 2.0 * self.prev_ref[0] + self.prev_ref[1]) / (t * t),
            )
        } else {
            (0.0, 0.0)
        };
        self.prev_ref = [theta_ref, self.prev_ref[0]];
        let e = c.kp * (theta_ref - theta_m) + w_ff - omega;
        let integral = self.integral + self.ki * e;
        let raw = c.kv * e + integral + tau_ff;
        let u = raw.clamp(-c.u_max, c.u_max);
        if u != raw {
            self.saturated += 1;
        }
        // conditional integration: keep the new integral unless it winds further into the limit
        if u == raw || e.signum() != raw.signum() {
            self.integral = integral;
        }
        u
    }

    /// Number of samples where `u` was limited so far.
    pub fn saturated_samples(&self) -> u64 {
        self.saturated
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn step_is_p_plus_pi_on_backward_difference() {
        let cfg = ControllerConfig::default();
        let mut c = Controller::new(cfg, 5e-4);
        let u0 = c.step(0.01, 0.0);
        let e0 = cfg.kp * 0.01;
        assert!((u0 - (cfg.kv * e0 + cfg.kv * 5e-4 / cfg.ti * e0)).abs() < 1e-15);
        let u1 = c.step(0.01, 0.001);
        let e1 = cfg.kp * 0.009 - 0.001 / 5e-4;
        let i1 = cfg.kv * 5e-4 / cfg.ti * (e0 + e1);
        assert!((u1 - (cfg.kv * e1 + i1)).abs() < 1e-15);
    }

    #[test]
    fn saturation_limits_u_and_stops_integral_windup() {
        let cfg = ControllerConfig {
            u_max: 0.5,
            ..ControllerConfig::default()
        };
        let mut c = Controller::new(cfg, 5e-4);
        for _ in 0..1000 {
            assert_eq!(c.step(10.0, 0.0), 0.5);
        }
        assert_eq!(c.saturated_samples(), 1000);
        // the integral did not grow: as soon as the error reverses, u leaves the limit
        let u = c.step(-0.1, 0.0);
        assert!(u < 0.0, "u = {u}");
    }

    #[test]
    fn feedforward_adds_velocity_and_torque_terms() {
        let base = ControllerConfig {
            ti: f64::INFINITY,
            ..ControllerConfig::default()
        };
        let ff = ControllerConfig {
            feedforward: true,
            ..base
        };
        let (mut a, mut b) = (Controller::new(base, 5e-4), Controller::new(ff, 5e-4));
        let refs = [0.0, 0.001, 0.003];
        let (mut ua, mut ub) = (0.0, 0.0);
        for r in refs {
            ua = a.step(r, 0.0);
            ub = b.step(r, 0.0);
        }
        let w_ff = 0.002 / 5e-4;
        let tau_ff = base.ff_inertia * (0.003 - 0.002 + 0.0) / 25e-8;
        assert!((ub - ua - (base.kv * w_ff + tau_ff)).abs() < 1e-12);
    }
}
