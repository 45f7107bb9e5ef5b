//! Lumped mechanism: the plant of any kind, with its extra modes, as bodies joined by
//! spring–dampers, and the linear continuous-time model `ẋ = F x + G [u_d, w]ᵀ` built from it.
//!
//! Coordinates are absolute angles: body 0 is the motor (motor side, coordinate gain `r`
//! into a spring), the others are arm-side masses (gain 1). A spring between bodies `a` and
//! `b` has deflection `δ = g_a θ_a − g_b θ_b` and torque `τ = k δ + d δ̇`, acting `−g_a τ` on
//! `a` and `+g_b τ` on `b`. With the gearbox spring between motor and `J_a1` this reproduces
//! seed 000 eq. (6) (`x1 = θ_m r − θ_a1`) and eq. (7) for the four-mass structure; the state
//! differs from the paper's only by a change of coordinates (tests in [`super`] check the
//! simulated responses against eq. (6) and (7) built literally).
//!
//! State layout: `[θ_0 … θ_{n−1}, ω_0 … ω_{n−1}, τ_a]`: angles [rad], velocities [rad/s] and
//! the torque `τ_a` [N·m] out of the current loop (a first-order lag with time constant
//! `T_c` from the delayed torque reference `u_d`). The disturbance `w` [N·m] adds to the
//! motor torque directly.

use nalgebra::{DMatrix, SymmetricEigen};

use super::effects::Effect;
use super::params::Plant;
use super::spec::Structure;

/// Largest number of bodies the simulator accepts (four-mass plus four extra modes).
pub const MAX_BODIES: usize = 8;
/// Largest state dimension, `2 MAX_BODIES + 1`.
pub const MAX_STATE: usize = 2 * MAX_BODIES + 1;

/// The frame of the grounded structure: a body of infinite inertia that never moves
/// (every simulator divides by inertia, `1/∞ = 0`, and starts it at rest at angle 0).
fn ground() -> Body {
    Body {
        name: "ground".to_string(),
        inertia: f64::INFINITY,
        gain: 1.0,
        viscous: 0.0,
    }
}

/// One rigid body of the lumped mechanism.
#[derive(Clone, Debug, PartialEq)]
pub struct Body {
    /// name used for the state (`m`, `a1`, `a2`, `p`, `x1`, ...)
    pub name: String,
    /// inertia [kg·m²] on the body's own side of the gearbox
    pub inertia: f64,
    /// coordinate gain into springs: `r` for the motor, 1 for arm-side bodies [-]
    pub gain: f64,
    /// viscous friction to ground [N·m·s/rad]
    pub viscous: f64,
}

impl Body {
    /// Whether the body is the grounded mass's frame (infinite inertia): it never moves.
    pub fn is_frame(&self) -> bool {
        self.inertia.is_infinite()
    }
}

/// A spring–damper between two bodies.
#[derive(Clone, Debug, PartialEq)]
pub struct Spring {
    /// first body (deflection `g_a θ_a − g_b θ_b`)
    pub a: usize,
    /// second body
    pub b: usize,
    /// stiffness [N·m/rad]
    pub k: f64,
    /// damping [N·m·s/rad]
    pub d: f64,
}

/// Bodies and springs; spring 0 is always the gearbox when there is more than one body.
#[derive(Clone, Debug, PartialEq)]
pub struct Mechanism {
    /// bodies, motor first
    pub bodies: Vec<Body>,
    /// springs
    pub springs: Vec<Spring>,
}

/// Undamped modal frequencies seen from the motor.
#[derive(Clone, Debug, PartialEq)]
pub struct ModalFrequencies {
    /// resonances: nonzero natural frequencies of the free mechanism [Hz], ascending
    pub resonances_hz: Vec<f64>,
    /// anti-resonances: natural frequencies with the motor locked [Hz], ascending
    pub anti_resonances_hz: Vec<f64>,
}

impl Mechanism {
    /// Builds the mechanism of `plant` with the `extra_mode` effects in `effects` added.
    pub fn new(plant: &Plant, effects: &[Effect]) -> Mechanism {
        let p = &plant.params;
        let arm = |name: &str, inertia: f64| Body {
            name: name.to_string(),
            inertia,
            gain: 1.0,
            viscous: 0.0,
        };
        let motor = |inertia: f64| Body {
            name: "m".to_string(),
            inertia,
            gain: p.r,
            viscous: p.f_m,
        };
        let spring = |a, b, k, d| Spring { a, b, k, d };
        let (bodies, springs) = match plant.kind {
            Structure::Rigid => (vec![motor(p.rigid_inertia())], vec![]),
            // no gearbox: the mass on the motor angle itself (coordinate gain 1); the frame
            // as a body of infinite inertia (inverse 0) at rest at angle 0, the spring to it
            // spring 0, where the gearbox's effects act
            Structure::Grounded => (
                vec![
                    Body {
                        gain: 1.0,
                        ..motor(p.rigid_inertia())
                    },
                    ground(),
                ],
                vec![spring(0, 1, p.k_0, 0.0)],
            ),
            Structure::TwoMass => (
                vec![motor(p.j_m), arm("a", p.j_a1 + p.j_a2)],
                vec![spring(0, 1, p.k_g, p.d_g)],
            ),
            Structure::ThreeMass => (
                vec![motor(p.j_m), arm("a1", p.j_a1), arm("a2", p.j_a2)],
                vec![spring(0, 1, p.k_g, p.d_g), spring(1, 2, p.k_a, p.d_a)],
            ),
            Structure::FourMass => (
                vec![
                    motor(p.j_m),
                    arm("a1", p.j_a1),
                    arm("a2", p.j_a2),
                    arm("p", p.j_p),
                ],
                vec![
                    spring(0, 1, p.k_g, p.d_g),
                    spring(1, 2, p.k_a, p.d_a),
                    spring(1, 3, p.k_p, p.d_p),
                ],
            ),
        };
        let mut m = Mechanism { bodies, springs };
        let mut extra = 0;
        for e in effects {
            if let Effect::ExtraMode(x) = e {
                extra += 1;
                let to = plant.kind.mode_host(x, m.bodies.len());
                m.bodies.push(arm(&format!("x{extra}"), x.j));
                let new = m.bodies.len() - 1;
                m.springs.push(spring(to, new, x.k, x.d));
            }
        }
        m
    }

    /// Number of bodies.
    pub fn n_bodies(&self) -> usize {
        self.bodies.len()
    }

    /// State dimension `2n + 1`.
    pub fn n_state(&self) -> usize {
        2 * self.bodies.len() + 1
    }

    /// Names of the state components (`theta_m`, `omega_a1`, ..., `tau_a`).
    pub fn state_names(&self) -> Vec<String> {
        let mut v: Vec<String> = self
            .bodies
            .iter()
            .map(|b| format!("theta_{}", b.name))
            .collect();
        v.extend(self.bodies.iter().map(|b| format!("omega_{}", b.name)));
        v.push("tau_a".to_string());
        v
    }

    /// Continuous-time linear model `(F, G)`, inputs `[u_d, w]`, with the current-loop time
    /// constant `tc` [s] (> 0).
    pub fn linear_model(&self, tc: f64) -> (DMatrix<f64>, DMatrix<f64>) {
        let n = self.n_bodies();
        let nx = self.n_state();
        let mut f = DMatrix::zeros(nx, nx);
        let mut g = DMatrix::zeros(nx, 2);
        for i in 0..n {
            f[(i, n + i)] = 1.0;
            let b = &self.bodies[i];
            f[(n + i, n + i)] -= b.viscous / b.inertia;
        }
        for s in &self.springs {
            let (ga, gb) = (self.bodies[s.a].gain, self.bodies[s.b].gain);
            // torque tau = k (ga θa − gb θb) + d (ga ωa − gb ωb); on a: −ga tau, on b: +gb tau
            for (body, sign, gbody) in [(s.a, -1.0, ga), (s.b, 1.0, gb)] {
                let jinv = 1.0 / self.bodies[body].inertia;
                let c = sign * gbody * jinv;
                f[(n + body, s.a)] += c * s.k * ga;
                f[(n + body, s.b)] -= c * s.k * gb;
                f[(n + body, n + s.a)] += c * s.d * ga;
                f[(n + body, n + s.b)] -= c * s.d * gb;
            }
        }
        f[(n, 2 * n)] = 1.0 / self.bodies[0].inertia;
        f[(2 * n, 2 * n)] = -1.0 / tc;
        g[(2 * n, 0)] = 1.0 / tc;
        g[(n, 1)] = 1.0 / self.bodies[0].inertia;
        (f, g)
    }

    /// Stiffness matrix `K` (n×n) of the undamped mechanism, in the body coordinates.
    fn stiffness(&self) -> DMatrix<f64> {
        let n = self.n_bodies();
        let mut k = DMatrix::zeros(n, n);
        for s in &self.springs {
            let (ga, gb) = (self.bodies[s.a].gain, self.bodies[s.b].gain);
            k[(s.a, s.a)] += s.k * ga * ga;
            k[(s.b, s.b)] += s.k * gb * gb;
            k[(s.a, s.b)] -= s.k * ga * gb;
            k[(s.b, s.a)] -= s.k * ga * gb;
        }
        k
    }

    /// Undamped resonance and anti-resonance frequencies seen from the motor: the
    /// eigenvalues of `M^{-1/2} K M^{-1/2}` for the free mechanism, and for the mechanism
    /// with the motor locked.
    pub fn modal_frequencies(&self) -> ModalFrequencies {
        let k = self.stiffness();
        let inertias: Vec<f64> = self.bodies.iter().map(|b| b.inertia).collect();
        let freqs = |k: DMatrix<f64>, j: &[f64]| -> Vec<f64> {
            if j.is_empty() {
                return vec![];
            }
            let s = DMatrix::from_fn(j.len(), j.len(), |r, c| k[(r, c)] / (j[r] * j[c]).sqrt());
            let scale = s.amax().max(f64::MIN_POSITIVE);
            let mut v: Vec<f64> = SymmetricEigen::new(s)
                .eigenvalues
                .iter()
                .filter(|&&l| l > 1e-9 * scale)
                .map(|l| l.sqrt() / (2.0 * std::f64::consts::PI))
                .collect();
            v.sort_by(f64::total_cmp);
            v
        };
        let n = self.n_bodies();
        let locked = k.view((1, 1), (n - 1, n - 1)).into_owned();
        ModalFrequencies {
            resonances_hz: freqs(k, &inertias),
            anti_resonances_hz: freqs(locked, &inertias[1..]),
        }
    }

    /// Damped modes of the mechanism alone (no current loop): `(frequency [Hz], damping
    /// ratio [-])` of each complex pole pair, ascending in frequency.
    pub fn damped_modes(&self) -> Vec<(f64, f64)> {
        let (f, _) = self.linear_model(1.0);
        let nx = self.n_state() - 1;
        let fm = f.view((0, 0), (nx, nx)).into_owned();
        let mut v: Vec<(f64, f64)> = fm
            .complex_eigenvalues()
            .iter()
            .filter(|l| l.im > 1e-6)
            .map(|l| {
                let wn = l.norm();
                (wn / (2.0 * std::f64::consts::PI), -l.re / wn)
            })
            .collect();
        v.sort_by(|a, b| a.0.total_cmp(&b.0));
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::effects::ExtraMode;
    use crate::model::params::JointParams;

    fn close(a: &[f64], b: &[f64], tol: f64) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() < tol)
    }

    #[test]
    fn default_three_mass_has_the_designed_modal_frequencies() {
        let m = Mechanism::new(&Plant::default(), &[]);
        let mf = m.modal_frequencies();
        assert!(close(&mf.anti_resonances_hz, &[15.0, 19.0], 0.02), "{mf:?}");
        assert!(close(&mf.resonances_hz, &[17.0, 23.0], 0.02), "{mf:?}");
    }

    #[test]
    fn default_plants_modal_frequencies_match_the_documented_values() {
        let two = Mechanism::new(&Plant::new(Structure::TwoMass), &[]).modal_frequencies();
        assert!(close(&two.anti_resonances_hz, &[16.21], 0.01), "{two:?}");
        assert!(close(&two.resonances_hz, &[22.24], 0.01), "{two:?}");
        let four = Mechanism::new(&Plant::new(Structure::FourMass), &[]).modal_frequencies();
        assert!(
            close(&four.anti_resonances_hz, &[14.02, 18.12, 35.92], 0.01),
            "{four:?}"
        );
        assert!(
            close(&four.resonances_hz, &[17.00, 21.26, 36.14], 0.01),
            "{four:?}"
        );
        let rigid = Mechanism::new(&Plant::new(Structure::Rigid), &[]).modal_frequencies();
        assert!(rigid.resonances_hz.is_empty() && rigid.anti_resonances_hz.is_empty());
    }

    #[test]
    fn default_modes_are_lightly_damped() {
        for kind in [
            Structure::TwoMass,
            Structure::ThreeMass,
            Structure::FourMass,
        ] {
            let modes = Mechanism::new(&Plant::new(kind), &[]).damped_modes();
            assert!(!modes.is_empty());
            for (f, z) in modes {
                assert!((0.01..0.08).contains(&z), "{kind:?}: {f} Hz zeta {z}");
            }
        }
    }

    #[test]
    fn four_mass_equals_three_mass_with_parallel_extra_mode() {
        let p = JointParams::default();
        let x = Effect::ExtraMode(ExtraMode {
            j: p.j_p,
            k: p.k_p,
            d: p.d_p,
            attach: crate::model::effects::Attach::Parallel,
        });
        let a = Mechanism::new(&Plant::new(Structure::ThreeMass), &[x]);
        let b = Mechanism::new(&Plant::new(Structure::FourMass), &[]);
        assert_eq!(a.linear_model(5e-4).0, b.linear_model(5e-4).0);
    }

    #[test]
    fn rigid_linear_model_is_one_inertia_with_viscous_friction() {
        let plant = Plant::new(Structure::Rigid);
        let m = Mechanism::new(&plant, &[]);
        let (f, g) = m.linear_model(5e-4);
        let j = plant.params.rigid_inertia();
        assert_eq!(f.shape(), (3, 3));
        assert_eq!(f[(0, 1)], 1.0);
        assert!((f[(1, 1)] + plant.params.f_m / j).abs() < 1e-15);
        assert!((f[(1, 2)] - 1.0 / j).abs() < 1e-12);
        assert!((g[(2, 0)] - 2000.0).abs() < 1e-9);
    }
}
