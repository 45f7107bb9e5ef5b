//! Propagation of the plant over one sample: exactly when it is linear, by an exponential
//! stepper with stick–slip and backlash events when it is not.
//!
//! **Linear plant** (no nonlinear effect active): the continuous model `ẋ = F x + G v` with
//! `v = [u_d, w]` held over the sample is propagated with the zero-order-hold discretisation
//! of seed 000 eq. (12)–(13), `A_T = e^{F T}`, `B_T = ∫_0^T e^{Fτ} G dτ`, both read off the
//! exponential of the augmented matrix `[[F, G], [0, 0]] T` (Van Loan's construction),
//! computed once per run with nalgebra's `Matrix::exp` (Padé approximation with scaling and
//! squaring). The current-loop lag is part of `F`, so it is exact too. A fractional time
//! delay switches `u_d` once inside the sample; the sample is then split at that instant into
//! two exact steps of lengths `φT` and `(1 − φ)T`.
//!
//! **Nonlinear plant**: the plant is piecewise smooth. Its *modes* are the backlash contact
//! state (negative flank, gap, positive flank) and the friction state of the motor under
//! Coulomb friction, which is set-valued at zero velocity (no regularisation): *stuck*
//! (`ω_m = 0` held while the net motor torque without friction stays below the breakaway
//! level `Σ F_s`, friction balancing it) or *sliding* forward/backward (friction
//! `∓[F_c + (F_s − F_c) e^{−(ω/v_s)²}]`). Within a mode the right-hand side is smooth and
//! non-stiff (the fastest mode is the 23 Hz resonance; the current-loop lag is exact, see
//! below), so large steps are accurate; the mode changes are *events*.
//! - **Exponential stepper** (default, [`SampleStepper`], [`LawsonStep`]): one Lawson
//!   (integrating-factor) RK4 step per sample. The linear part of the current mode (springs,
//!   dampers, viscous friction, current loop, inputs; in the stuck mode with the
//!   motor-velocity row removed; in the gap without the gearbox spring) is propagated exactly
//!   by zero-order-hold matrices `e^{F t}` and input matrices precomputed once per run for
//!   each mode (Van Loan's construction, as below). A fractional delay's switch of the input
//!   inside the sample is part of that exact propagation (the input matrices have one column
//!   for the value before the switch and one for the value after it), so it needs no extra
//!   step. RK4 only integrates the small residual torques (sliding friction, ripple, the
//!   cubic term and backlash offset of the gearbox spring) in the integrating-factor
//!   variables. A step is refused, and the sample cut into two Lawson substeps (the
//!   event-aware RK4 in a substep that still contains an event), when
//!   - an event lies inside it: checked at its end and in between, where a mode can be left
//!     and re-entered within one sample: the motor speed at `T/4`, `T/2`, `3T/4` and the
//!     vertex of the parabola through its smallest values (a stop), the net torque of a
//!     stuck motor at `T/2`, at the input switch and at the end (a breakaway), the gearbox
//!     deflection at `T/2` and the end (a contact edge);
//!   - the motor speed, predicted from the linear flow, sweeps the Stribeck bump so fast that
//!     the bump's level varies by more than `STRIBECK_VARIATION` of itself over the sample:
//!     the current-loop lag, as slow as the sample, curves the speed within it and one RK4
//!     quadrature of the friction torque is then not accurate to 1e-6.
//! - **Event-aware RK4** (`IntegrationConfig::substeps` per sample, default 5): classical
//!   RK4 with inputs held and the modes frozen; the current-loop lag is not left to RK4:
//!   with `u_d` held its output is known in closed form and is set exactly at the stage
//!   times. When the end state of a substep lies past an event (contact edge, motor
//!   velocity through zero, breakaway `|τ_net| = Σ F_s`), the earliest event is located by
//!   the Illinois variant of regula falsi on its event function along the substep's cubic
//!   Hermite dense output (fourth order like the step, the current-loop torque in closed
//!   form), the substep is cut there, the mode switched (the motor velocity set to exactly 0
//!   at a friction event, then stuck or sliding decided from the net torque) and the rest
//!   integrated.
//!
//! Convergence (tests in `super::tests`, 2 periods of the default-amplitude multisine,
//! relative 2-norm over the run of θ_m, u and the gearbox deflection, against the
//! event-aware RK4 at 50 substeps per sample): every effect on, 3.1e-7, 9.4e-7 and 9.1e-7;
//! Coulomb friction alone behind the 1.5-sample delay 4.3e-7, 9.8e-7, 9.1e-7 (without the
//! Stribeck refinement 1.1e-6, 3.7e-6, 2.2e-6); backlash, cubic spring and ripple alone
//! below 3e-7. The margin under 1e-6 is thin for Coulomb friction with a Stribeck bump:
//! `STRIBECK_VARIATION` trades it against speed. The reference differs from the same RK4 at 500 substeps by below 1e-10
//! (4e-8 for a Stribeck bump of 3 % of the Coulomb level, where stick–slip decisions are
//! delicate). Not resolved at 2 kHz: a Stribeck velocity far below the default (0.01 rad/s
//! on the motor: 5e-5, and 5e-6 for the event-aware RK4 at 5 substeps); raise
//! `IntegrationConfig::substeps` and turn `exponential` off for such joints.
//!
//! The cubic spring and the torque ripple are smooth and need nothing special.
//!
//! **The laws.** Every pointwise law is evaluated by [`crate::model::laws`], the one place
//! that says what it is: the gearbox and arm springs by [`laws::spring_torque`] (on the
//! contact deflection [`laws::dead_zone_in`] of the frozen contact region, which
//! [`laws::contact`] classifies), the current-loop torque at stage times and along the dense
//! output by [`laws::current_loop`], the ripple by [`laws::ripple_torque`] (within a step by
//! the angle-sum rule from its value at the step's start, `RippleBase`). Coulomb friction's
//! sliding level is [`CoulombFriction::level`].

use nalgebra::DMatrix;

use crate::model::effects::{CoulombFriction, TorqueRipple};
use crate::model::laws;
use crate::model::plant::{Mechanism, MAX_BODIES, MAX_STATE};

pub use crate::model::laws::Contact;

/// Calls a const-generic method with the number of bodies known at compile time, so that
/// the state loops are unrolled (the body count is at most [`crate::model::plant::MAX_BODIES`]).
macro_rules! dispatch {
    ($n:expr, $nb:ident => $call:expr) => {
        match $n {
            1 => {
                const $nb: usize = 1;
                $call
            }
            2 => {
                const $nb: usize = 2;
                $call
            }
            3 => {
                const $nb: usize = 3;
                $call
            }
            4 => {
                const $nb: usize = 4;
                $call
            }
            5 => {
                const $nb: usize = 5;
                $call
            }
            6 => {
                const $nb: usize = 6;
                $call
            }
            7 => {
                const $nb: usize = 7;
                $call
            }
            _ => {
                const $nb: usize = 8;
                $call
            }
        }
    };
}

/// Most mode switches (contact and friction events) handled inside one step.
const MAX_SWITCHES: usize = 12;

/// State vector storage.
pub type State = [f64; MAX_STATE];

/// One exact zero-order-hold step `x ← Φ x + Γ v`, computed once per run and applied per
/// sample without allocating.
///
/// `Φ` and `Γ` are stored column by column, so that one pass over a column updates every
/// row at once (the compiler vectorises across rows); each row still sums
/// `0 + Φ_i0 x_0 + … + Φ_i(n−1) x_(n−1) + Γ_i0 v_0 + …` in that order, so the result is
/// the same to the bit as the row-by-row product. The state dimensions of the structures
/// (`2 · bodies + 1`) are dispatched to fixed-size loops.
#[derive(Clone, Debug)]
pub struct ZohStep {
    n: usize,
    /// `Φ[i][j]` at `j n + i`
    phi: Vec<f64>,
    /// `Γ[i][j]` at `j n + i`
    gamma: Vec<f64>,
}

impl ZohStep {
    /// Discretises `(F, G)` over a hold of `t` [s].
    pub fn new(f: &DMatrix<f64>, g: &DMatrix<f64>, t: f64) -> ZohStep {
        let (phi, gamma) = zoh(f, g, t);
        let (n, m) = g.shape();
        ZohStep {
            n,
            phi: (0..n * n).map(|k| phi[(k % n, k / n)]).collect(),
            gamma: (0..n * m).map(|k| gamma[(k % n, k / n)]).collect(),
        }
    }

    /// `x ← Φ x + Γ v` (`v` the inputs, one per column of `Γ`).
    #[inline]
    pub fn apply(&self, x: &mut State, v: &[f64]) {
        match self.n {
            3 => self.apply_n::<3>(x, v),
            5 => self.apply_n::<5>(x, v),
            7 => self.apply_n::<7>(x, v),
            9 => self.apply_n::<9>(x, v),
            11 => self.apply_n::<11>(x, v),
            13 => self.apply_n::<13>(x, v),
            15 => self.apply_n::<15>(x, v),
            17 => self.apply_n::<17>(x, v),
            _ => self.apply_any(x, v),
        }
    }

    /// [`Self::apply`] for `n == N`.
    #[inline]
    fn apply_n<const N: usize>(&self, x: &mut State, v: &[f64]) {
        let mut y = [0.0; N];
        for (col, &xj) in self.phi[..N * N].chunks_exact(N).zip(&x[..N]) {
            for (yi, &a) in y.iter_mut().zip(col) {
                *yi += a * xj;
            }
        }
        for (col, &vj) in self.gamma.chunks_exact(N).zip(v) {
            for (yi, &a) in y.iter_mut().zip(col) {
                *yi += a * vj;
            }
        }
        x[..N].copy_from_slice(&y);
    }

    /// [`Self::apply`] for any `n`.
    fn apply_any(&self, x: &mut State, v: &[f64]) {
        let n = self.n;
        let mut y = [0.0; MAX_STATE];
        for (col, &xj) in self.phi.chunks_exact(n).zip(x.iter()) {
            for (yi, &a) in y.iter_mut().zip(col) {
                *yi += a * xj;
            }
        }
        for (col, &vj) in self.gamma.chunks_exact(n).zip(v) {
            for (yi, &a) in y.iter_mut().zip(col) {
                *yi += a * vj;
            }
        }
        x[..n].copy_from_slice(&y[..n]);
    }
}

/// One-norm up to which [`expm`] leaves the scaling to nalgebra: its powers up to `M^27`
/// stay finite there.
const EXPM_NALGEBRA_NORM: f64 = (1u64 << 20) as f64;

/// Most squarings [`expm`] adds: a matrix of one-norm up to `2^220`.
const EXPM_MAX_SQUARINGS: i32 = 200;

/// The matrix exponential `e^M`, all NaN when `M` is not finite or its one-norm passes
/// `2^220`.
///
/// Past a one-norm of `2^20`, `M` is scaled down to it and the exponential squared back
/// here. Why: nalgebra counts its squarings from norms of powers of `M`, which overflow for
/// a stiff `M` (a spring of 10¹⁷ N·m/rad on a small inertia, tried by a fit near its
/// bounds) and make the count unbounded: one simulation then ran for minutes. Each squaring
/// doubles the relative error of the slow modes, as in any scaling and squaring.
pub fn expm(m: DMatrix<f64>) -> DMatrix<f64> {
    let norm = m.column_iter().map(|c| c.lp_norm(1)).fold(0.0, f64::max);
    if !norm.is_finite() {
        return DMatrix::from_element(m.nrows(), m.ncols(), f64::NAN);
    }
    if norm <= EXPM_NALGEBRA_NORM {
        return m.exp();
    }
    let squarings = (norm / EXPM_NALGEBRA_NORM).log2().ceil();
    if squarings > f64::from(EXPM_MAX_SQUARINGS) {
        return DMatrix::from_element(m.nrows(), m.ncols(), f64::NAN);
    }
    let squarings = squarings as i32;
    let mut e = (m * 2f64.powi(-squarings)).exp();
    for _ in 0..squarings {
        e = &e * &e;
    }
    e
}

/// Zero-order-hold discretisation `(e^{F t}, ∫_0^t e^{Fτ} G dτ)` via the augmented
/// exponential (seed 000 eq. (12)–(13)); NaN where it does not exist in floating point
/// ([`expm`]).
pub fn zoh(f: &DMatrix<f64>, g: &DMatrix<f64>, t: f64) -> (DMatrix<f64>, DMatrix<f64>) {
    let (n, m) = g.shape();
    let mut aug = DMatrix::zeros(n + m, n + m);
    aug.view_mut((0, 0), (n, n)).copy_from(&(f * t));
    aug.view_mut((0, n), (n, m)).copy_from(&(g * t));
    let e = expm(aug);
    (
        e.view((0, 0), (n, n)).into_owned(),
        e.view((0, n), (n, m)).into_owned(),
    )
}

#[derive(Clone, Copy, Debug, Default)]
struct FastSpring {
    a: usize,
    b: usize,
    ga: f64,
    gb: f64,
    k: f64,
    d: f64,
}

/// Right-hand side of the (possibly nonlinear) plant and its event-aware RK4 stepper.
#[derive(Clone, Debug)]
pub struct NonlinearPlant {
    n: usize,
    inv_j: [f64; MAX_STATE],
    viscous: [f64; MAX_STATE],
    /// springs; a chain or tree of `n` bodies has exactly `n − 1`
    springs: [FastSpring; MAX_BODIES],
    /// current-loop time constant `T_c` [s] and its inverse [1/s]
    tc: f64,
    inv_tc: f64,
    /// cubic coefficient of the gearbox spring (spring 0) [N·m/rad³]
    k3: f64,
    /// half width of the backlash dead zone [rad], when active
    half_gap: Option<f64>,
    coulomb: Vec<CoulombFriction>,
    ripple: Vec<TorqueRipple>,
    /// total static (breakaway) friction `(Σ F_s, Σ F_s−)` [N·m] forward and backward
    /// ([`CoulombFriction::breakaway`])
    f_static: (f64, f64),
    /// variation of the Stribeck bump's level over a whole-sample step above which the
    /// sample is cut into substeps [N·m] (infinite without a bump)
    stribeck_tol: f64,
    /// `3 max v_s` [rad/s]: motor speeds where a Stribeck bump is still felt
    stribeck_near: f64,
}

/// Friction state of the motor under Coulomb friction (set-valued at zero velocity).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Motion {
    /// no Coulomb friction on the motor
    Free,
    /// stuck: `ω_m = 0` held while |net motor torque| < `Σ F_s`
    Stick,
    /// sliding forward: friction `−level(ω_m)`
    SlipPos,
    /// sliding backward: friction `+level(ω_m)`
    SlipNeg,
}

impl NonlinearPlant {
    /// Plant from a mechanism, current-loop time constant `tc` [s] and the nonlinear parts.
    pub fn new(
        mech: &Mechanism,
        tc: f64,
        k3: f64,
        backlash_width: Option<f64>,
        coulomb: Vec<CoulombFriction>,
        ripple: Vec<TorqueRipple>,
    ) -> NonlinearPlant {
        let n = mech.n_bodies();
        let mut inv_j = [0.0; MAX_STATE];
        let mut viscous = [0.0; MAX_STATE];
        for (i, b) in mech.bodies.iter().enumerate() {
            inv_j[i] = 1.0 / b.inertia;
            viscous[i] = b.viscous;
        }
        assert_eq!(mech.springs.len() + 1, n, "mechanism must be a tree");
        let mut springs = [FastSpring::default(); MAX_BODIES];
        for (f, s) in springs.iter_mut().zip(&mech.springs) {
            *f = FastSpring {
                a: s.a,
                b: s.b,
                ga: mech.bodies[s.a].gain,
                gb: mech.bodies[s.b].gain,
                k: s.k,
                d: s.d,
            };
        }
        let f_static = coulomb.iter().fold((0.0, 0.0), |(a, b), c| {
            let (p, n) = c.breakaway();
            (a + p, b + n)
        });
        let bump: f64 = coulomb.iter().map(|c| (c.fs - c.fc).abs()).sum();
        let stribeck_near = 3.0 * coulomb.iter().fold(0.0, |m: f64, c| m.max(c.v_stribeck));
        NonlinearPlant {
            n,
            inv_j,
            viscous,
            springs,
            tc,
            inv_tc: 1.0 / tc,
            k3,
            half_gap: backlash_width.map(|w| 0.5 * w),
            coulomb,
            ripple,
            f_static,
            stribeck_near,
            stribeck_tol: if bump > 0.0 {
                STRIBECK_VARIATION * bump
            } else {
                f64::INFINITY
            },
        }
    }

    /// State dimension.
    pub fn n_state(&self) -> usize {
        2 * self.n + 1
    }

    /// Gearbox deflection `δ = r θ_m − θ_a1` [rad] (0 without a gearbox spring).
    pub fn gearbox_deflection(&self, x: &State) -> f64 {
        if self.n > 1 {
            let s = &self.springs[0];
            s.ga * x[s.a] - s.gb * x[s.b]
        } else {
            0.0
        }
    }

    /// Contact region of a deflection ([`laws::contact`]; always in contact without backlash).
    pub fn region(&self, delta: f64) -> Contact {
        match self.half_gap {
            Some(h) => laws::contact(delta, h),
            None => Contact::Pos,
        }
    }

    /// Friction state implied by the state: sliding in the direction of `ω_m` when it is
    /// not zero; at `ω_m = 0`, stuck when the net motor torque without Coulomb friction is
    /// below the breakaway level `Σ F_s`, else sliding in its direction.
    pub fn motion(&self, x: &State, mode: Contact, w: f64) -> Motion {
        dispatch!(self.n, NB => self.motion_n::<NB>(x, mode, w))
    }

    /// Right-hand side with the contact mode frozen and the friction state of [`Self::motion`];
    /// `u_d` delayed torque reference, `w` disturbance [N·m].
    pub fn rhs(&self, x: &State, mode: Contact, u_d: f64, w: f64, dx: &mut State) {
        dispatch!(self.n, NB => {
            let motion = self.motion_n::<NB>(x, mode, w);
            self.rhs_n::<NB>(x, mode, motion, u_d, w, None, dx)
        })
    }

    /// One classical RK4 step of length `h` [s] with the contact mode and the friction state
    /// at the start frozen.
    pub fn rk4(&self, x: &State, mode: Contact, h: f64, u_d: f64, w: f64) -> State {
        dispatch!(self.n, NB => {
            let motion = self.motion_n::<NB>(x, mode, w);
            self.rk4_n::<NB>(x, mode, motion, h, u_d, w)
        })
    }

    /// Advances `x` by `h` [s] with inputs held, locating backlash contact events and the
    /// stick–slip events of Coulomb friction (see the module documentation).
    pub fn advance(&self, x: &mut State, mode: &mut Contact, h: f64, u_d: f64, w: f64) {
        dispatch!(self.n, NB => self.advance_n::<NB>(x, mode, h, u_d, w))
    }

    fn motion_n<const NB: usize>(&self, x: &State, mode: Contact, w: f64) -> Motion {
        if self.coulomb.is_empty() {
            return Motion::Free;
        }
        let v = x[NB];
        if v > 0.0 {
            Motion::SlipPos
        } else if v < 0.0 {
            Motion::SlipNeg
        } else {
            let t = self.motor_net_n::<NB>(x, mode, w);
            if self.stick_margin(t) < 0.0 {
                Motion::Stick
            } else if t > 0.0 {
                Motion::SlipPos
            } else {
                Motion::SlipNeg
            }
        }
    }

    /// How far the net motor torque `t` [N·m] of a stuck motor lies beyond its breakaway
    /// levels, `max(t − F_s, −t − F_s−)`: negative while it stays stuck.
    #[inline(always)]
    fn stick_margin(&self, t: f64) -> f64 {
        (t - self.f_static.0).max(-t - self.f_static.1)
    }

    /// Torques on every body except Coulomb friction [N·m]: viscous friction, current-loop
    /// torque, disturbance and ripple on the motor, springs.
    #[inline(always)]
    fn torques_n<const NB: usize>(
        &self,
        x: &State,
        mode: Contact,
        w: f64,
        base: Option<&RippleBase>,
    ) -> State {
        let n = NB;
        let mut acc = [0.0; MAX_STATE];
        for i in 0..n {
            acc[i] = -self.viscous[i] * x[n + i];
        }
        let mut motor = x[2 * n] + w;
        for (i, r) in self.ripple.iter().enumerate() {
            motor += match base {
                Some(b) => b.torque(i, r, x[0]),
                None => laws::ripple_torque(r.amplitude, r.order, r.phase, x[0]),
            };
        }
        acc[0] += motor;
        for (si, s) in self.springs[..NB - 1].iter().enumerate() {
            let delta = s.ga * x[s.a] - s.gb * x[s.b];
            let ddelta = s.ga * x[n + s.a] - s.gb * x[n + s.b];
            let tau = if si == 0 {
                // the gearbox: cubic spring on the contact deflection of the frozen region,
                // nothing (spring nor damper) in the gap
                let e = match (self.half_gap, mode) {
                    (Some(_), Contact::Gap) => None,
                    (Some(h), _) => Some(laws::dead_zone_in(delta, h, mode)),
                    (None, _) => Some(delta),
                };
                match e {
                    Some(e) => laws::spring_torque(s.k, self.k3, s.d, e, ddelta),
                    None => 0.0,
                }
            } else {
                laws::spring_torque(s.k, 0.0, s.d, delta, ddelta)
            };
            acc[s.a] -= s.ga * tau;
            acc[s.b] += s.gb * tau;
        }
        acc
    }

    /// Net motor torque without Coulomb friction [N·m].
    fn motor_net_n<const NB: usize>(&self, x: &State, mode: Contact, w: f64) -> f64 {
        self.torques_n::<NB>(x, mode, w, None)[0]
    }

    /// Right-hand side with frozen modes; `base` gives the ripple by the angle-sum rule.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn rhs_n<const NB: usize>(
        &self,
        x: &State,
        mode: Contact,
        motion: Motion,
        u_d: f64,
        w: f64,
        base: Option<&RippleBase>,
        dx: &mut State,
    ) {
        let n = NB;
        let mut acc = self.torques_n::<NB>(x, mode, w, base);
        match motion {
            Motion::Free => {}
            Motion::Stick => acc[0] = 0.0,
            Motion::SlipPos => acc[0] -= self.sliding_level(x[n], false),
            Motion::SlipNeg => acc[0] += self.sliding_level(x[n], true),
        }
        for i in 0..n {
            dx[i] = x[n + i];
            dx[n + i] = acc[i] * self.inv_j[i];
        }
        // the current loop's lag in differential form (its solution: `laws::current_loop`)
        dx[2 * n] = (u_d - x[2 * n]) * self.inv_tc;
    }

    /// One classical RK4 step of length `h` [s] with the modes frozen. The current-loop
    /// torque `τ_a` is not integrated by RK4: with `u_d` held it is known in closed form,
    /// [`laws::current_loop`], and is set exactly at the stage times (so the fast lag does
    /// not limit the step; RK4 sees a smooth known input).
    fn rk4_n<const NB: usize>(
        &self,
        x: &State,
        mode: Contact,
        motion: Motion,
        h: f64,
        u_d: f64,
        w: f64,
    ) -> State {
        let nx = 2 * NB + 1;
        let it = 2 * NB;
        let base = RippleBase::new(&self.ripple, x[0]);
        // over h the lag's decay is the square of its decay over h/2
        let e_half = laws::current_loop_decay(self.tc, 0.5 * h);
        let ta_half = laws::current_loop_decayed(x[it], u_d, e_half);
        let ta_full = laws::current_loop_decayed(x[it], u_d, e_half * e_half);
        let mut k1 = [0.0; MAX_STATE];
        let mut k2 = [0.0; MAX_STATE];
        let mut k3 = [0.0; MAX_STATE];
        let mut k4 = [0.0; MAX_STATE];
        let mut tmp = [0.0; MAX_STATE];
        self.rhs_n::<NB>(x, mode, motion, u_d, w, Some(&base), &mut k1);
        for i in 0..nx {
            tmp[i] = x[i] + 0.5 * h * k1[i];
        }
        tmp[it] = ta_half;
        self.rhs_n::<NB>(&tmp, mode, motion, u_d, w, Some(&base), &mut k2);
        for i in 0..nx {
            tmp[i] = x[i] + 0.5 * h * k2[i];
        }
        tmp[it] = ta_half;
        self.rhs_n::<NB>(&tmp, mode, motion, u_d, w, Some(&base), &mut k3);
        for i in 0..nx {
            tmp[i] = x[i] + h * k3[i];
        }
        tmp[it] = ta_full;
        self.rhs_n::<NB>(&tmp, mode, motion, u_d, w, Some(&base), &mut k4);
        let mut out = *x;
        for i in 0..nx {
            out[i] = x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
        out[it] = ta_full;
        out
    }

    /// Event function of the friction state: negative while the state lasts, crossing zero
    /// at its end (`None` without Coulomb friction).
    fn friction_event_n<const NB: usize>(
        &self,
        x: &State,
        mode: Contact,
        motion: Motion,
        w: f64,
    ) -> Option<f64> {
        match motion {
            Motion::Free => None,
            Motion::Stick => Some(self.stick_margin(self.motor_net_n::<NB>(x, mode, w))),
            Motion::SlipPos => Some(-x[NB]),
            Motion::SlipNeg => Some(x[NB]),
        }
    }

    /// Time in `(0, t1]` at which the event function `g` reaches zero from below along the
    /// frozen-mode step from `x` to `x1 = RK4(x, t1)`, given `g(x1) = g1 ≥ 0`; the returned
    /// time is on the far side (`g ≥ 0`). The step's path is its cubic Hermite dense output
    /// (end states and their derivatives, fourth-order like the step; the current-loop
    /// torque in closed form), so the search costs two right-hand sides instead of an RK4
    /// step per iterate. Illinois variant of regula falsi. When `g(x) ≥ 0` already (the
    /// state just entered the mode on its boundary), the bracket starts at the first dyadic
    /// fraction of `t1` where `g < 0`; 0 when there is none.
    #[allow(clippy::too_many_arguments)]
    fn locate_n<const NB: usize>(
        &self,
        (x, x1): (&State, &State),
        mode: Contact,
        motion: Motion,
        t1: f64,
        g1: f64,
        u_d: f64,
        w: f64,
        g: impl Fn(&State) -> f64,
    ) -> f64 {
        let (nx, it) = (2 * NB + 1, 2 * NB);
        let mut f0 = [0.0; MAX_STATE];
        let mut f1 = [0.0; MAX_STATE];
        self.rhs_n::<NB>(x, mode, motion, u_d, w, None, &mut f0);
        self.rhs_n::<NB>(x1, mode, motion, u_d, w, None, &mut f1);
        let at = |t: f64| {
            let s = t / t1;
            let (s2, s3) = (s * s, s * s * s);
            let (h00, h10) = (2.0 * s3 - 3.0 * s2 + 1.0, (s3 - 2.0 * s2 + s) * t1);
            let (h01, h11) = (3.0 * s2 - 2.0 * s3, (s3 - s2) * t1);
            let mut o = [0.0; MAX_STATE];
            for i in 0..nx {
                o[i] = h00 * x[i] + h10 * f0[i] + h01 * x1[i] + h11 * f1[i];
            }
            o[it] = laws::current_loop(x[it], u_d, self.tc, t);
            g(&o)
        };
        let (mut lo, mut flo) = (0.0, g(x));
        if flo >= 0.0 {
            let mut t = t1;
            let mut found = false;
            for _ in 0..30 {
                t *= 0.5;
                let f = at(t);
                if f < 0.0 {
                    (lo, flo, found) = (t, f, true);
                    break;
                }
            }
            if !found {
                return 0.0;
            }
        }
        let (mut hi, mut fhi) = (t1, g1);
        let mut side = 0i8;
        for _ in 0..60 {
            if hi - lo <= 1e-12 * t1 {
                break;
            }
            let c = (lo * fhi - hi * flo) / (fhi - flo);
            let c = if c > lo && c < hi { c } else { 0.5 * (lo + hi) };
            let fc = at(c);
            if fc >= 0.0 {
                hi = c;
                fhi = fc;
                if fc == 0.0 {
                    break;
                }
                if side == 1 {
                    flo *= 0.5;
                }
                side = 1;
            } else {
                lo = c;
                flo = fc;
                if side == -1 {
                    fhi *= 0.5;
                }
                side = -1;
            }
        }
        hi
    }

    /// Advances `x` by `h` [s] with inputs held: RK4 over the whole `h` with contact mode and
    /// friction state frozen; when the end state lies past an event (contact edge, motor
    /// velocity through zero, breakaway), the earliest event is located, the step cut there,
    /// the mode switched and the rest integrated.
    fn advance_n<const NB: usize>(
        &self,
        x: &mut State,
        mode: &mut Contact,
        h: f64,
        u_d: f64,
        w: f64,
    ) {
        let mut motion = self.motion_n::<NB>(x, *mode, w);
        if self.half_gap.is_none() && motion == Motion::Free {
            *x = self.rk4_n::<NB>(x, *mode, motion, h, u_d, w);
            return;
        }
        let mut remaining = h;
        for _switch in 0..MAX_SWITCHES {
            let x1 = self.rk4_n::<NB>(x, *mode, motion, remaining, u_d, w);
            // contact event
            let mut first: Option<(f64, bool, Contact)> = None;
            if let Some(half) = self.half_gap {
                let region = self.region(self.gearbox_deflection(&x1));
                if region != *mode {
                    // g < 0 inside the current mode, g ≥ 0 past the edge
                    let (sign, edge, new_mode) = match (*mode, region) {
                        (Contact::Pos, _) => (-1.0, half, Contact::Gap),
                        (Contact::Neg, _) => (1.0, -half, Contact::Gap),
                        (Contact::Gap, Contact::Pos) => (1.0, half, Contact::Pos),
                        (Contact::Gap, _) => (-1.0, -half, Contact::Neg),
                    };
                    let g = |s: &State| sign * (self.gearbox_deflection(s) - edge);
                    let g1 = g(&x1).max(0.0);
                    let path = (&*x, &x1);
                    let t = self.locate_n::<NB>(path, *mode, motion, remaining, g1, u_d, w, g);
                    first = Some((t, false, new_mode));
                }
            }
            if let Some(g1) = self.friction_event_n::<NB>(&x1, *mode, motion, w) {
                if g1 >= 0.0 {
                    let g = |s: &State| {
                        self.friction_event_n::<NB>(s, *mode, motion, w)
                            .unwrap_or(-1.0)
                    };
                    let path = (&*x, &x1);
                    let t = self.locate_n::<NB>(path, *mode, motion, remaining, g1, u_d, w, g);
                    if first.is_none_or(|(tf, _, _)| t < tf) {
                        first = Some((t, true, *mode));
                    }
                }
            }
            let Some((t, friction, new_mode)) = first else {
                *x = x1;
                return;
            };
            if t > 0.0 {
                *x = self.rk4_n::<NB>(x, *mode, motion, t, u_d, w);
            }
            if friction {
                // the motor stops (or reverses, or breaks away) exactly at rest
                x[NB] = 0.0;
            } else {
                *mode = new_mode;
            }
            motion = self.motion_n::<NB>(x, *mode, w);
            remaining -= t;
            if remaining <= 1e-12 * h {
                return;
            }
        }
        // grazing events that keep switching: finish the step in the current modes
        *mode = self.region(self.gearbox_deflection(x));
        let motion = self.motion_n::<NB>(x, *mode, w);
        *x = self.rk4_n::<NB>(x, *mode, motion, remaining, u_d, w);
    }
}

/// Tables of one linear mode for the exponential stepper: `Φ(h)`, `Γ(h)`, `Φ(h/2)`,
/// `Γ(h/2)`. `Γ(t)` has the three columns `u_old`, `u_new`, `w`: the forced response at
/// `t` to the delayed torque reference held at `u_old` until the switch `s` and at `u_new`
/// after it, and to the disturbance `w` held over the step.
#[derive(Clone, Debug)]
struct ModeTables {
    phi: [[f64; MAX_STATE]; MAX_STATE],
    gam: [[f64; 3]; MAX_STATE],
    phi2: [[f64; MAX_STATE]; MAX_STATE],
    gam2: [[f64; 3]; MAX_STATE],
    /// `Φ(s)`, `Γ(s)` at the switch `s`, where the stuck motor's net torque can peak
    phis: [[f64; MAX_STATE]; MAX_STATE],
    gams: [[f64; 3]; MAX_STATE],
    /// motor-speed rows of `[Φ(t) | Γ(t)]` at `t = h/4` and `3h/4`, for the quadrature check
    quarter: [([f64; MAX_STATE], [f64; 3]); 2],
}

/// `sin(n θ + φ)` of the first ripples at the start `θ_0` of a step, so that the stages
/// evaluate the ripple law [`laws::ripple_torque`], `A sin(n θ + φ)`, by the angle-sum rule
/// `sin(n θ_0 + φ + d) = sin(n θ_0 + φ) cos d + cos(n θ_0 + φ) sin d` with short series in
/// `d = n (θ − θ_0)` instead of a `sin` per stage (agreement with the law: a test below).
struct RippleBase {
    theta0: f64,
    /// `(sin, cos)` of `n θ_0 + φ` for the first [`RIPPLE_BASES`] ripples
    sc: [(f64, f64); RIPPLE_BASES],
}

/// Ripples whose stage values use the angle-sum rule (others call the law directly).
const RIPPLE_BASES: usize = 4;

impl RippleBase {
    #[inline(always)]
    fn new(ripple: &[TorqueRipple], theta0: f64) -> RippleBase {
        let mut sc = [(0.0, 1.0); RIPPLE_BASES];
        for (o, r) in sc.iter_mut().zip(ripple) {
            *o = (r.order * theta0 + r.phase).sin_cos();
        }
        RippleBase { theta0, sc }
    }

    /// Ripple torque [`laws::ripple_torque`] of ripple `i` (`r`) at motor angle `theta`
    /// [rad] → [N·m].
    #[inline(always)]
    fn torque(&self, i: usize, r: &TorqueRipple, theta: f64) -> f64 {
        let d = r.order * (theta - self.theta0);
        if i >= RIPPLE_BASES || d.abs() > 0.5 {
            return laws::ripple_torque(r.amplitude, r.order, r.phase, theta);
        }
        // Taylor series, products with reciprocals folded at compile time: to d⁵ and d⁶ for
        // |d| ≤ 0.05 (the usual case within one step; truncation below 2e-13), to d⁹ and d¹⁰
        // for |d| ≤ 0.5 (below 3e-11)
        let d2 = d * d;
        let (sin_d, cos_d) = if d2 <= 0.0025 {
            (
                d * (1.0 - d2 * (1.0 / 6.0) * (1.0 - d2 * (1.0 / 20.0))),
                1.0 - d2 * 0.5 * (1.0 - d2 * (1.0 / 12.0) * (1.0 - d2 * (1.0 / 30.0))),
            )
        } else {
            (
                d * (1.0
                    - d2 * (1.0 / 6.0)
                        * (1.0
                            - d2 * (1.0 / 20.0)
                                * (1.0 - d2 * (1.0 / 42.0) * (1.0 - d2 * (1.0 / 72.0))))),
                1.0 - d2
                    * 0.5
                    * (1.0
                        - d2 * (1.0 / 12.0)
                            * (1.0
                                - d2 * (1.0 / 30.0)
                                    * (1.0 - d2 * (1.0 / 56.0) * (1.0 - d2 * (1.0 / 90.0))))),
            )
        };
        let (s0, c0) = self.sc[i];
        r.amplitude * (s0 * cos_d + c0 * sin_d)
    }
}

/// `Φ y + Γ v` over the first `2 NB + 1` states.
#[inline(always)]
fn propagate<const NB: usize>(
    phi: &[[f64; MAX_STATE]; MAX_STATE],
    gam: &[[f64; 3]; MAX_STATE],
    y: &State,
    v: [f64; 3],
) -> State {
    let nx = 2 * NB + 1;
    let mut o = [0.0; MAX_STATE];
    for i in 0..nx {
        let row = &phi[i];
        let mut acc = gam[i][0] * v[0] + gam[i][1] * v[1] + gam[i][2] * v[2];
        for j in 0..nx {
            acc += row[j] * y[j];
        }
        o[i] = acc;
    }
    o
}

/// `o += c Φ k` for `k` nonzero only at `ω_m` (index `NB`) and `ω_a1` (index `NB + 1`).
#[inline(always)]
fn add_columns<const NB: usize>(
    o: &mut State,
    phi: &[[f64; MAX_STATE]; MAX_STATE],
    c: f64,
    k: (f64, f64),
) {
    let nx = 2 * NB + 1;
    let (km, ka) = (c * k.0, c * k.1);
    for i in 0..nx {
        let mut v = phi[i][NB] * km;
        if NB > 1 {
            v += phi[i][NB + 1] * ka;
        }
        o[i] += v;
    }
}

/// Exponential (Lawson) RK4 step of one fixed length `h` for the nonlinear plant: the linear
/// part of the current mode, inputs included, is propagated exactly, the residual nonlinear
/// torques by RK4 in the integrating-factor variables (see the module documentation).
#[derive(Clone, Debug)]
pub struct LawsonStep {
    h: f64,
    nx: usize,
    /// the delayed input switches strictly inside the step
    switch: bool,
    refine: bool,
    /// index `2 gap + stick`
    modes: Vec<Option<Box<ModeTables>>>,
}

impl LawsonStep {
    /// Tables for step `h` [s] of the linear modes the plant can be in: contact or gap (when
    /// it has backlash) × sliding or stuck (when it has Coulomb friction). The delayed torque
    /// reference switches from `u_old` to `u_new` at `switch · h` (`switch` in `[0, 1]`; 0 when
    /// it is held at `u_new` over the whole step).
    pub fn new(
        mech: &Mechanism,
        tc: f64,
        plant: &NonlinearPlant,
        h: f64,
        switch: f64,
    ) -> LawsonStep {
        let n = mech.n_bodies();
        let nx = mech.n_state();
        let s = switch.clamp(0.0, 1.0) * h;
        let mut modes = vec![None, None, None, None];
        for gap in [false, true] {
            if gap && plant.half_gap.is_none() {
                continue;
            }
            for stick in [false, true] {
                if stick && plant.coulomb.is_empty() {
                    continue;
                }
                let mut m = mech.clone();
                if gap {
                    m.springs[0].k = 0.0;
                    m.springs[0].d = 0.0;
                }
                let (mut f, mut g) = m.linear_model(tc);
                if stick {
                    // ω_m is held at zero: its row vanishes
                    f.row_mut(n).fill(0.0);
                    g.row_mut(n).fill(0.0);
                }
                let square = |a: &DMatrix<f64>| {
                    let mut o = [[0.0; MAX_STATE]; MAX_STATE];
                    for (i, row) in o.iter_mut().enumerate().take(nx) {
                        for (j, v) in row.iter_mut().enumerate().take(nx) {
                            *v = a[(i, j)];
                        }
                    }
                    o
                };
                // (Φ(t), Γ(t)) with the columns u_old, u_new, w: before the switch the
                // reference input acts as u_old; after it, the part accumulated up to the
                // switch is propagated by Φ(t − s) and the rest acts as u_new
                let tables = |t: f64| {
                    let (phi, gam) = zoh(&f, &g, t);
                    let (old, new) = if t <= s {
                        (gam.column(0).into_owned(), gam.column(0) * 0.0)
                    } else {
                        let (_, gam_s) = zoh(&f, &g, s);
                        let (phi_rest, gam_rest) = zoh(&f, &g, t - s);
                        (phi_rest * gam_s.column(0), gam_rest.column(0).into_owned())
                    };
                    let mut o = [[0.0; 3]; MAX_STATE];
                    for (i, row) in o.iter_mut().enumerate().take(nx) {
                        *row = [old[i], new[i], gam[(i, 1)]];
                    }
                    (square(&phi), o)
                };
                let (phi, gam) = tables(h);
                let (phi2, gam2) = tables(0.5 * h);
                let (phis, gams) = tables(s);
                let row = |t: f64| {
                    let (p, g) = tables(t);
                    (p[n], g[n])
                };
                let quarter = [row(0.25 * h), row(0.75 * h)];
                modes[2 * usize::from(gap) + usize::from(stick)] = Some(Box::new(ModeTables {
                    phi,
                    gam,
                    phi2,
                    gam2,
                    phis,
                    gams,
                    quarter,
                }));
            }
        }
        LawsonStep {
            h,
            nx,
            switch: s > 0.0 && s < h,
            refine: false,
            modes,
        }
    }

    /// Step length [s].
    pub fn h(&self) -> f64 {
        self.h
    }
}

impl NonlinearPlant {
    /// Accelerations `(ω̇_m, ω̇_a1)` [rad/s²] of the torques the linear model of the mode
    /// leaves out: ripple and sliding friction on the motor, the cubic term and the backlash
    /// offset of the gearbox spring (the rest is in the mode's exact propagation).
    #[inline(always)]
    fn residual_n<const NB: usize>(
        &self,
        x: &State,
        mode: Contact,
        motion: Motion,
        base: &RippleBase,
    ) -> (f64, f64) {
        let n = NB;
        // the gearbox spring's law on the contact deflection `e` of the frozen region, less
        // the linear spring `k δ` the mode's exact part carries (its damper is there whole;
        // in the gap the mode has no gearbox spring and the law gives nothing)
        let tau = if NB > 1 {
            let s = &self.springs[0];
            let delta = s.ga * x[s.a] - s.gb * x[s.b];
            let e = match (self.half_gap, mode) {
                (Some(_), Contact::Gap) => None,
                (Some(h), _) => Some(laws::dead_zone_in(delta, h, mode)),
                (None, _) => Some(delta),
            };
            match e {
                Some(e) => {
                    laws::spring_torque(s.k, self.k3, 0.0, e, 0.0)
                        - laws::spring_torque(s.k, 0.0, 0.0, delta, 0.0)
                }
                None => 0.0,
            }
        } else {
            0.0
        };
        let mut motor = 0.0;
        for (i, r) in self.ripple.iter().enumerate() {
            motor += base.torque(i, r, x[0]);
        }
        match motion {
            Motion::SlipPos => motor -= self.sliding_level(x[n], false),
            Motion::SlipNeg => motor += self.sliding_level(x[n], true),
            Motion::Free | Motion::Stick => {}
        }
        let (ga, gb) = if NB > 1 {
            (self.springs[0].ga, self.springs[0].gb)
        } else {
            (0.0, 0.0)
        };
        let am = if motion == Motion::Stick {
            0.0
        } else {
            (motor - ga * tau) * self.inv_j[0]
        };
        let aa = if NB > 1 {
            gb * tau * self.inv_j[1]
        } else {
            0.0
        };
        (am, aa)
    }

    /// Level of the Stribeck bumps alone, `Σ (F_s − F_c) e^{−(ω/v_s)²}`, at motor speed
    /// `omega` [rad/s] → [N·m].
    fn bump_level(&self, omega: f64) -> f64 {
        self.coulomb
            .iter()
            .map(|c| {
                let x = omega / c.v_stribeck;
                if x.abs() < 6.0 {
                    (c.fs - c.fc) * (-x * x).exp()
                } else {
                    0.0
                }
            })
            .sum()
    }

    /// Total sliding-friction level at motor speed `omega` [rad/s], sliding `backward` or
    /// forward → [N·m] ([`CoulombFriction::level_dir`]).
    #[inline(always)]
    fn sliding_level(&self, omega: f64, backward: bool) -> f64 {
        self.coulomb
            .iter()
            .map(|c| c.level_dir(omega, backward))
            .sum()
    }

    /// One Lawson RK4 step of `step.h()` with the modes frozen, inputs `v = [u_old, u_new,
    /// w]` (delayed torque reference before and after the step's switch, disturbance held)
    /// [N·m]; `None` when an event (contact edge, motor velocity through zero, breakaway)
    /// lies inside the step, or the mode has no table.
    pub fn lawson(
        &self,
        step: &LawsonStep,
        x: &State,
        mode: Contact,
        v: [f64; 3],
    ) -> Option<State> {
        dispatch!(self.n, NB => self.lawson_n::<NB>(step, x, mode, v))
    }

    fn lawson_n<const NB: usize>(
        &self,
        step: &LawsonStep,
        x: &State,
        mode: Contact,
        v: [f64; 3],
    ) -> Option<State> {
        let w = v[2];
        let n = NB;
        debug_assert_eq!(2 * NB + 1, step.nx);
        let motion = self.motion_n::<NB>(x, mode, w);
        let gap = mode == Contact::Gap && self.half_gap.is_some();
        let t = step.modes[2 * usize::from(gap) + usize::from(motion == Motion::Stick)].as_ref()?;
        let h = step.h;
        let add = |o: &mut State, c: f64, k: (f64, f64)| {
            o[n] += c * k.0;
            if NB > 1 {
                o[n + 1] += c * k.1;
            }
        };
        let base = RippleBase::new(&self.ripple, x[0]);
        let k1 = self.residual_n::<NB>(x, mode, motion, &base);
        let sliding = matches!(motion, Motion::SlipPos | Motion::SlipNeg);
        // motor speed at t from the linear flow plus the first residual
        let speed = |row: &[f64; MAX_STATE], g: &[f64; 3], t: f64| {
            let mut o = g[0] * v[0] + g[1] * v[1] + g[2] * v[2] + t * k1.0;
            for j in 0..2 * NB + 1 {
                o += row[j] * x[j];
            }
            o
        };
        let (q1, q3) = if sliding {
            let ([r1, r3], [g1, g3]) = (&t.quarter, &t.quarter);
            (speed(&r1.0, &g1.1, 0.25 * h), speed(&r3.0, &g3.1, 0.75 * h))
        } else {
            (0.0, 0.0)
        };
        if sliding && step.refine {
            // the whole-sample step predicted from the linear flow: skip it when it would be
            // refused (the motor speed reaching zero) or too coarse (the Stribeck bump crossed
            // too fast for one quadrature)
            let q2 = speed(&t.phi2[n], &t.gam2[n], 0.5 * h);
            let q4 = speed(&t.phi[n], &t.gam[n], h);
            let q = [x[n], q1, q2, q3, q4];
            if q.iter().any(|&o| o * x[n] <= 0.0) && x[n] != 0.0 {
                return None;
            }
            // beyond 3 v_s the bump varies by less than e^{-9} of itself
            if q.iter().any(|o| o.abs() < self.stribeck_near) {
                let l = [q[0], q[2], q[4]].map(|o| self.bump_level(o));
                let lo = l.iter().fold(f64::INFINITY, |m, &o| m.min(o));
                let hi = l.iter().fold(f64::NEG_INFINITY, |m, &o| m.max(o));
                if hi - lo > self.stribeck_tol {
                    return None;
                }
            }
        }
        let ex2 = propagate::<NB>(&t.phi2, &t.gam2, x, v);
        let mut a = ex2;
        add_columns::<NB>(&mut a, &t.phi2, 0.5 * h, k1);
        let k2 = self.residual_n::<NB>(&a, mode, motion, &base);
        let mut b = ex2;
        add(&mut b, 0.5 * h, k2);
        let k3 = self.residual_n::<NB>(&b, mode, motion, &base);
        let ex = propagate::<NB>(&t.phi, &t.gam, x, v);
        let mut c = ex;
        add_columns::<NB>(&mut c, &t.phi2, h, k3);
        let k4 = self.residual_n::<NB>(&c, mode, motion, &base);
        let mut out = ex;
        add_columns::<NB>(&mut out, &t.phi, h / 6.0, k1);
        add_columns::<NB>(&mut out, &t.phi2, h / 3.0, (k2.0 + k3.0, k2.1 + k3.1));
        add(&mut out, h / 6.0, k4);
        // events inside the step: at its end, and in between where a mode can be left and
        // re-entered within one sample (the motor speed dipping through zero and back, the
        // net torque of a stuck motor peaking above breakaway, a contact opening and closing);
        // `past`: the stuck motor's net torque at breakaway (ripple from the step's base)
        let past =
            |y: &State| self.stick_margin(self.torques_n::<NB>(y, mode, w, Some(&base))[0]) >= 0.0;
        match motion {
            Motion::Stick => {
                out[n] = 0.0;
                // the delayed input turns at the switch, where the net torque can peak
                if past(&b) || past(&out) {
                    return None;
                }
                if step.switch {
                    let xs = propagate::<NB>(&t.phis, &t.gams, x, v);
                    if past(&xs) {
                        return None;
                    }
                }
            }
            Motion::SlipPos | Motion::SlipNeg => {
                let sign = if motion == Motion::SlipPos { 1.0 } else { -1.0 };
                let y = [x[n], q1, b[n], q3, out[n]].map(|o| sign * o);
                if y.iter().any(|&o| o <= 0.0) || dips_below_zero(&y) {
                    return None;
                }
            }
            Motion::Free => {}
        }
        if self.half_gap.is_some()
            && (self.region(self.gearbox_deflection(&b)) != mode
                || self.region(self.gearbox_deflection(&out)) != mode)
        {
            return None;
        }
        Some(out)
    }

    /// Advances `x` over `[t0, t1]` of a sample with the event-aware RK4, the delayed torque
    /// reference switching from `u_old` to `u_new` at `s` [s from the sample start].
    #[allow(clippy::too_many_arguments)]
    fn advance_across(
        &self,
        x: &mut State,
        mode: &mut Contact,
        (t0, t1): (f64, f64),
        s: f64,
        u_old: f64,
        u_new: f64,
        w: f64,
    ) {
        if s > t0 && s < t1 {
            self.advance(x, mode, s - t0, u_old, w);
            self.advance(x, mode, t1 - s, u_new, w);
        } else {
            let u = if t1 <= s { u_old } else { u_new };
            self.advance(x, mode, t1 - t0, u, w);
        }
    }

    /// One sample by the event-aware RK4 at `parts` equal substeps (see
    /// [`SampleStepper`] for the arguments).
    #[allow(clippy::too_many_arguments)]
    pub fn rk4_sample(
        &self,
        x: &mut State,
        mode: &mut Contact,
        ts: f64,
        switch: f64,
        parts: usize,
        u_old: f64,
        u_new: f64,
        w: f64,
    ) {
        let h = ts / parts as f64;
        for j in 0..parts {
            let span = (j as f64 * h, (j + 1) as f64 * h);
            self.advance_across(x, mode, span, switch * ts, u_old, u_new, w);
        }
    }

    /// One sample with the exponential stepper (see [`SampleStepper`]): delayed torque
    /// reference `u_old` until the switch, `u_new` after it; disturbance `w` [N·m].
    pub fn sample(
        &self,
        st: &SampleStepper,
        x: &mut State,
        mode: &mut Contact,
        u_old: f64,
        u_new: f64,
        w: f64,
    ) {
        if let Some(x1) = self.lawson(&st.full, x, *mode, [u_old, u_new, w]) {
            *x = x1;
            return;
        }
        let m = SUBSTEPS;
        let hs = st.ts / m as f64;
        let s = st.switch * st.ts;
        // position of the switch in substeps
        let at = st.switch * m as f64;
        for j in 0..m {
            let (step, v) = match &st.sub_switch {
                Some((js, step)) if *js == j => (step, [u_old, u_new, w]),
                _ => {
                    let u = if (j + 1) as f64 <= at + 1e-9 {
                        u_old
                    } else {
                        u_new
                    };
                    (&st.sub, [0.0, u, w])
                }
            };
            match self.lawson(step, x, *mode, v) {
                Some(x1) => *x = x1,
                None => {
                    let hp = hs / st.event_parts as f64;
                    for p in 0..st.event_parts {
                        let t0 = j as f64 * hs + p as f64 * hp;
                        self.advance_across(x, mode, (t0, t0 + hp), s, u_old, u_new, w);
                    }
                }
            }
        }
    }
}

/// Whether the parabola through the smallest of the equally spaced samples `y` (all
/// positive), when it is an interior one, and its two neighbours reaches zero between them.
fn dips_below_zero(y: &[f64; 5]) -> bool {
    let i = (1..5).fold(0, |m, i| if y[i] < y[m] { i } else { m });
    if i == 0 || i == 4 {
        return false;
    }
    let (a, b, c) = (y[i - 1], y[i], y[i + 1]);
    let curvature = a - 2.0 * b + c;
    curvature > 0.0 && b - (c - a) * (c - a) / (8.0 * curvature) <= 0.0
}

/// Variation of the Stribeck bump's level over a whole-sample step, as a fraction of the bump
/// `Σ |F_s − F_c|`, above which the sample is cut into [`SUBSTEPS`] Lawson substeps. The
/// motor can sweep the bump within one sample while the current-loop lag (as slow as the
/// sample) curves its speed, and one RK4 quadrature of the friction torque is then not
/// accurate to 1e-6; the figure is the largest that keeps Coulomb friction alone converged
/// to 1e-6 in u on the default joint (measured: no refinement 2.8e-6, 0.3 → 1.6e-6,
/// 0.15 → 1.07e-6, 0.1 → 9.2e-7, 0.01 → 3.3e-7 at twice the cost).
const STRIBECK_VARIATION: f64 = 0.1;

/// Lawson substeps per sample when the whole-sample step is refused (an event inside, or a
/// fast sweep of the Stribeck bump).
const SUBSTEPS: usize = 2;

/// Exponential stepping of one sample of the nonlinear plant: one Lawson step over the whole
/// sample (the delayed input's switch inside it exact in the linear part); when that step
/// contains an event or sweeps the Stribeck bump too fast, `SUBSTEPS` Lawson substeps, and
/// the event-aware RK4 in the substeps that contain an event.
#[derive(Clone, Debug)]
pub struct SampleStepper {
    full: LawsonStep,
    /// a substep without a switch
    sub: LawsonStep,
    /// the substep that contains the switch strictly inside, with its tables
    sub_switch: Option<(usize, LawsonStep)>,
    /// sample interval [s]
    ts: f64,
    /// switch of the delayed input as a fraction of the sample, in `[0, 1)`
    switch: f64,
    /// event-aware RK4 parts for a substep that contains an event
    event_parts: usize,
}

impl SampleStepper {
    /// Tables for sample interval `ts` [s], delayed input switching at `switch · ts`, and
    /// `substeps` event-aware RK4 substeps per sample where there is an event (shared among
    /// the Lawson substeps).
    pub fn new(
        mech: &Mechanism,
        tc: f64,
        plant: &NonlinearPlant,
        ts: f64,
        switch: f64,
        substeps: u32,
    ) -> SampleStepper {
        let m = SUBSTEPS;
        let hs = ts / m as f64;
        let at = switch * m as f64;
        let js = at.floor();
        let sub_switch = (at - js > 1e-9 && at - js < 1.0 - 1e-9)
            .then(|| (js as usize, LawsonStep::new(mech, tc, plant, hs, at - js)));
        SampleStepper {
            full: LawsonStep {
                refine: true,
                ..LawsonStep::new(mech, tc, plant, ts, switch)
            },
            sub: LawsonStep::new(mech, tc, plant, hs, 0.0),
            sub_switch,
            ts,
            switch,
            event_parts: (substeps as usize / m).max(1),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ripple_by_the_angle_sum_rule_agrees_with_the_law() {
        let ripple = [
            TorqueRipple::default(),
            TorqueRipple {
                amplitude: -0.5,
                order: 7.0,
                phase: -2.0,
            },
        ];
        for theta0 in [-3.0, -0.01, 0.0, 0.4, 25.0] {
            let base = RippleBase::new(&ripple, theta0);
            // |d| = n |θ − θ_0| from 0 through both series to beyond 0.5 (the law itself)
            for dtheta in [0.0, 1e-7, -3e-4, 6.9e-4, -2e-3, 5e-3, 7e-3, -0.02, 0.1] {
                let theta = theta0 + dtheta;
                for (i, r) in ripple.iter().enumerate() {
                    let law = laws::ripple_torque(r.amplitude, r.order, r.phase, theta);
                    let got = base.torque(i, r, theta);
                    assert!(
                        (got - law).abs() <= 1e-12 * r.amplitude.abs(),
                        "θ0 {theta0}, dθ {dtheta}, ripple {i}: {got} vs {law}"
                    );
                }
            }
        }
    }

    #[test]
    fn a_dip_is_found_between_positive_samples_only_when_the_parabola_crosses_zero() {
        // speed falling, touching below zero between samples 2 and 3, rising again
        assert!(dips_below_zero(&[0.3, 0.1, 0.004, 0.02, 0.2]));
        // the same shape staying above zero
        assert!(!dips_below_zero(&[0.3, 0.15, 0.06, 0.08, 0.2]));
        // monotone: the smallest sample is at an end, no interior minimum
        assert!(!dips_below_zero(&[0.5, 0.4, 0.3, 0.2, 0.01]));
    }
    use crate::model::params::Plant;
    use crate::model::spec::Structure;

    #[test]
    fn expm_of_a_stiff_matrix_is_finite_and_right_and_of_a_non_finite_one_nan() {
        // |M|^27 overflows: nalgebra alone counts unbounded squarings here
        let m = DMatrix::from_row_slice(2, 2, &[-1e12, 0.0, 3.0, -1.0]);
        let e = expm(m);
        assert!(e[(0, 0)].abs() < 1e-300 && e[(0, 1)].abs() < 1e-300);
        // 40 squarings in all: the slow mode to about 2^40 ε
        assert!((e[(1, 1)] / (-1.0f64).exp() - 1.0).abs() < 1e-3, "{e}");
        // e^{Ft} of an undamped oscillator, ωt = 1.3 rad
        let w = 2.0e3;
        let t = 6.5e-4;
        let m = DMatrix::from_row_slice(2, 2, &[0.0, t, -w * w * t, 0.0]);
        let e = expm(m);
        let (s, c) = (w * t).sin_cos();
        for (got, want) in e.iter().zip([c, -w * s, s / w, c]) {
            assert!((got - want).abs() < 1e-12 * want.abs().max(1.0), "{e}");
        }
        let m = DMatrix::from_row_slice(2, 2, &[f64::INFINITY, 0.0, 0.0, 1.0]);
        assert!(expm(m).iter().all(|v| v.is_nan()));
    }

    #[test]
    fn zoh_of_double_integrator_matches_closed_form() {
        let f = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, 0.0, 0.0]);
        let g = DMatrix::from_row_slice(2, 1, &[0.0, 2.0]);
        let (phi, gam) = zoh(&f, &g, 0.1);
        assert!((phi[(0, 1)] - 0.1).abs() < 1e-15 && (phi[(0, 0)] - 1.0).abs() < 1e-15);
        assert!((gam[(0, 0)] - 2.0 * 0.005).abs() < 1e-15);
        assert!((gam[(1, 0)] - 0.2).abs() < 1e-15);
    }

    #[test]
    fn rk4_on_linear_plant_matches_exact_zoh() {
        let mech = Mechanism::new(&Plant::new(Structure::ThreeMass), &[]);
        let (f, g) = mech.linear_model(5e-4);
        let t = 5e-4;
        let step = ZohStep::new(&f, &g, t);
        let nl = NonlinearPlant::new(&mech, 5e-4, 0.0, None, vec![], vec![]);
        let mut xe = [0.0; MAX_STATE];
        let mut xr = [0.0; MAX_STATE];
        let mut mode = Contact::Pos;
        for k in 0..400 {
            let u = if k < 200 { 1.0 } else { -0.5 };
            step.apply(&mut xe, &[u, 0.1]);
            for _ in 0..10 {
                nl.advance(&mut xr, &mut mode, t / 10.0, u, 0.1);
            }
        }
        let nx = mech.n_state();
        let err: f64 = (0..nx).map(|i| (xe[i] - xr[i]).powi(2)).sum::<f64>().sqrt();
        let norm: f64 = (0..nx).map(|i| xe[i].powi(2)).sum::<f64>().sqrt();
        assert!(err / norm < 1e-7, "relative error {}", err / norm);
    }

    #[test]
    fn backlash_event_lands_on_the_edge() {
        // two-mass, motor pushed from rest inside the gap: the first contact must be located
        let mech = Mechanism::new(&Plant::new(Structure::TwoMass), &[]);
        let width = 1e-3;
        let nl = NonlinearPlant::new(&mech, 5e-4, 0.0, Some(width), vec![], vec![]);
        let mut x = [0.0; MAX_STATE];
        x[2] = 1.0; // motor velocity 1 rad/s: δ grows at r rad/s
        let mut mode = nl.region(0.0);
        assert_eq!(mode, Contact::Gap);
        let h = 5e-5;
        let mut steps = 0;
        while mode == Contact::Gap {
            let before = nl.gearbox_deflection(&x);
            nl.advance(&mut x, &mut mode, h, 0.0, 0.0);
            steps += 1;
            assert!(steps < 10_000);
            if mode == Contact::Pos {
                assert!(before < 0.5 * width);
            }
        }
        let delta = nl.gearbox_deflection(&x);
        assert!(delta >= 0.5 * width, "delta {delta}");
        // the step in which contact happened continued in contact: δ passed the edge a bit
        assert!(delta - 0.5 * width < 2.0 * h * x[2] * (1.0 / 118.0) + 1e-12);
    }

    #[test]
    fn coulomb_motor_sticks_below_breakaway_and_slides_at_the_located_instant() {
        // rigid joint at rest, current loop T_c = 0.5 ms: u_d = 0.03 N·m (below F_s = 0.04)
        // holds it exactly; then u_d = 0.05 from τ_a ≈ 0.03 reaches F_s at
        // T_c ln((0.05 − τ_a) / 0.01) ≈ T_c ln 2
        let mech = Mechanism::new(&Plant::new(Structure::Rigid), &[]);
        let fric = CoulombFriction::default();
        let tc = 5e-4;
        let nl = NonlinearPlant::new(&mech, tc, 0.0, None, vec![fric], vec![]);
        let mut x = [0.0; MAX_STATE];
        let mut mode = Contact::Pos;
        let h = 1e-4;
        for _ in 0..50 {
            nl.advance(&mut x, &mut mode, h, 0.03, 0.0);
        }
        assert_eq!((x[0], x[1]), (0.0, 0.0));
        assert!((x[2] - 0.03).abs() < 1e-5);
        let t_break = tc * ((0.05 - x[2]) / 0.01).ln();
        let mut t = 0.0;
        while t + h < t_break {
            nl.advance(&mut x, &mut mode, h, 0.05, 0.0);
            t += h;
            assert_eq!(x[1], 0.0, "moved at {t} s before breakaway at {t_break} s");
        }
        nl.advance(&mut x, &mut mode, h, 0.05, 0.0);
        t += h;
        assert!(x[1] > 0.0);
        // just after breakaway the net torque τ_a − F_s grows linearly from 0:
        // ω ≈ (τ̇_a / 2J)(t − t_b)², τ̇_a = 0.01 / T_c at the breakaway
        let j = mech.bodies[0].inertia;
        let dt = t - t_break;
        let approx = 0.01 / tc / (2.0 * j) * dt * dt;
        assert!((x[1] / approx - 1.0).abs() < 0.1, "{} vs {approx}", x[1]);
    }
}
