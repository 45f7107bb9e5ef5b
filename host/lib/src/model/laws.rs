//! The pointwise laws of the plant and its effects, written once over any real scalar so
//! that the simulator (`f64`) and the estimators (dual numbers, for exact forward-mode
//! derivatives) evaluate the same equations ([`crate::model::effects`] says what each
//! effect is and where it acts).
//!
//! Two laws are non-smooth and have a smooth counterpart for gradient-based estimation:
//! - Coulomb friction: the simulator integrates the set-valued law (stick at `ω = 0` while
//!   the net torque is below the breakaway level, see [`crate::sim::integrate`]); the
//!   estimator uses [`coulomb_smooth`], `F_c tanh(ω/v_ε)`, which tends to it as `v_ε → 0`.
//! - Backlash: the simulator locates the contact edges of [`dead_zone`] exactly; the
//!   estimator uses [`dead_zone_smooth`], whose kink is rounded over `±ε` around each edge.
//!
//! The validation FIT of a fitted model is always computed with the exact laws (the
//! simulator), never with the smooth ones.

use num_traits::Float;

/// `f64` constant as the scalar type.
#[inline(always)]
fn c<T: Float>(v: f64) -> T {
    T::from(v).expect("f64 converts to every Float")
}

/// Torque of a spring–damper with a cubic stiffening term (seed 001 eq. (6)):
/// `k e + k3 e³ + d ė`, with `e` the (contact) deflection [rad] and `de` its rate [rad/s]
/// → [N·m]. The linear spring is `k3 = 0`.
#[inline(always)]
pub fn spring_torque<T: Float>(k: T, k3: T, d: T, e: T, de: T) -> T {
    k * e + k3 * e * e * e + d * de
}

/// Contact region of the backlash dead zone.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Contact {
    /// `δ < −h`: negative flank in contact
    Neg,
    /// `|δ| ≤ h`: free in the gap
    Gap,
    /// `δ > h`: positive flank in contact
    Pos,
}

/// Contact region of the deflection `delta` in a dead zone of half width `half` [rad].
#[inline(always)]
pub fn contact<T: Float>(delta: T, half: T) -> Contact {
    if delta > half {
        Contact::Pos
    } else if delta < -half {
        Contact::Neg
    } else {
        Contact::Gap
    }
}

/// The dead zone's branch for the region `region`, whatever `delta` is: `δ − h` on the
/// positive flank, `δ + h` on the negative one, 0 in the gap [rad]. An integrator that keeps
/// the contact region fixed over a step (and locates the edges as events) evaluates this.
#[inline(always)]
pub fn dead_zone_in<T: Float>(delta: T, half: T, region: Contact) -> T {
    match region {
        Contact::Pos => delta - half,
        Contact::Neg => delta + half,
        Contact::Gap => T::zero(),
    }
}

/// Backlash dead zone of half width `half` [rad]: the contact deflection `δ − h` beyond
/// the positive flank, `δ + h` beyond the negative one, 0 in the gap (exact law):
/// [`dead_zone_in`] of the region [`contact`] of `delta`.
#[inline(always)]
pub fn dead_zone<T: Float>(delta: T, half: T) -> T {
    dead_zone_in(delta, half, contact(delta, half))
}

/// Smooth dead zone for the estimator: `½[(δ − h) + s(δ − h)] + ½[(δ + h) − s(δ + h)]`
/// with `s(x) = √(x² + ε²)`, which equals [`dead_zone`] to within `ε/2` and has a
/// continuous slope (0 in the gap, 1 in contact) [rad].
#[inline(always)]
pub fn dead_zone_smooth<T: Float>(delta: T, half: T, eps: T) -> T {
    let half_t: T = c(0.5);
    let p = delta - half;
    let n = delta + half;
    half_t * (p + smooth_abs(p, eps)) + half_t * (n - smooth_abs(n, eps))
}

/// `√(x² + ε²)`, the smooth `|x|` of [`dead_zone_smooth`] (inlined into the simulation's
/// steps, which a closure was not).
#[inline(always)]
fn smooth_abs<T: Float>(x: T, eps: T) -> T {
    (x * x + eps * eps).sqrt()
}

/// Slope `d/dδ` of [`dead_zone_smooth`]: 0 deep in the gap, 1 in contact; it scales the
/// gearbox damping, which acts only in contact.
#[inline(always)]
pub fn dead_zone_smooth_slope<T: Float>(delta: T, half: T, eps: T) -> T {
    let half_t: T = c(0.5);
    let p = delta - half;
    let n = delta + half;
    half_t * (T::one() + p / smooth_abs(p, eps)) + half_t * (T::one() - n / smooth_abs(n, eps))
}

/// Smooth Coulomb friction for the estimator, `F_c tanh(ω/v_ε)` [N·m], opposing the motor
/// velocity `omega` [rad/s]; the level `fc` [N·m], the smoothing velocity `v_eps` [rad/s].
#[inline(always)]
pub fn coulomb_smooth<T: LawFloat>(fc: T, omega: T, v_eps: T) -> T {
    fc * (omega / v_eps).tanh_law()
}

/// A scalar the smooth laws run on: `f64`, or the estimator's dual numbers
/// (`crate::ident::nonlinear::dual`), whose `tanh` is [`fast_tanh`] on the value.
pub trait LawFloat: Float {
    /// [`fast_tanh`]
    fn tanh_law(self) -> Self;
}

impl LawFloat for f64 {
    #[inline(always)]
    fn tanh_law(self) -> f64 {
        fast_tanh(self)
    }
}

/// `tanh(x)` through one `exp`, `(e − 1)/(e + 1)` with `e = exp(2|x|)` and the sign of `x`,
/// and `±1` without any call beyond `|x| = 20` (where `tanh` rounds to `±1`). Its absolute
/// error is below 4·10⁻¹⁶ (a few ulps of 1; relative to `tanh(x)` itself it grows as `x`
/// goes to nought); a force law needs no more. Why: the smooth Coulomb law calls it at
/// every RK4 stage of every estimation run, and the library's `tanh` goes through `expm1`,
/// which costs several times `exp` (half of a friction model's simulation time).
#[inline(always)]
pub fn fast_tanh(x: f64) -> f64 {
    let a = x.abs();
    if a > 20.0 {
        return x.signum();
    }
    let e = (2.0 * a).exp();
    ((e - 1.0) / (e + 1.0)).copysign(x)
}

/// Smooth Coulomb friction with direction-dependent levels for the estimator [N·m],
/// opposing the motor velocity `omega` [rad/s]: with `s = tanh(ω/v_ε)` and the weights
/// `w± = (1 ± s)/2` of forward and backward motion,
/// `s (w+ L+ + w− L−) + w− f_v− ω`, where `level_pos` `L+` and `level_neg` `L−` are the
/// sliding levels forward and backward [N·m] and `extra_neg` `f_v−` the viscous friction
/// acting backward only [N·m·s/rad]. Far from rest it is the exact sliding law (`L+`
/// forward, `−L− + f_v− ω` backward, [`crate::model::effects::CoulombFriction::level_dir`]);
/// with `L+ = L−` and `f_v− = 0` it is [`coulomb_smooth`].
#[inline(always)]
pub fn coulomb_smooth_asym<T: LawFloat>(
    level_pos: T,
    level_neg: T,
    extra_neg: T,
    omega: T,
    v_eps: T,
) -> T {
    coulomb_smooth_asym_tanh(
        level_pos,
        level_neg,
        extra_neg,
        omega,
        (omega / v_eps).tanh_law(),
    )
}

/// [`coulomb_smooth_asym`] with `s = tanh(ω/v_ε)` given.
#[inline(always)]
pub fn coulomb_smooth_asym_tanh<T: Float>(
    level_pos: T,
    level_neg: T,
    extra_neg: T,
    omega: T,
    s: T,
) -> T {
    let half: T = c(0.5);
    let wp = half * (T::one() + s);
    let wn = half * (T::one() - s);
    s * (wp * level_pos + wn * level_neg) + wn * extra_neg * omega
}

/// Friction level with a Stribeck bump, `F_c + (F_s − F_c) e^{−(ω/v_s)²}` [N·m] at motor
/// velocity `omega` [rad/s] (the magnitude of the sliding friction; seed 000's joint,
/// [`crate::model::effects::CoulombFriction::level`] evaluates the same law).
#[inline(always)]
pub fn stribeck_level<T: Float>(fc: T, fs: T, v_stribeck: T, omega: T) -> T {
    let x = omega / v_stribeck;
    fc + (fs - fc) * (-(x * x)).exp()
}

/// Position-dependent torque ripple `A sin(n θ + φ)` [N·m] at motor angle `theta` [rad].
#[inline(always)]
pub fn ripple_torque<T: Float>(amplitude: T, order: T, phase: T, theta: T) -> T {
    amplitude * (order * theta + phase).sin()
}

/// Mean over a sample interval of the unit phasor `e^{i n θ}` of a ripple of order `order`,
/// the motor angle moving linearly from `theta0` to `theta1` [rad]: `(e^{i n θ₁} − e^{i n
/// θ₀}) / (i n (θ₁ − θ₀))`, its real part the mean of `cos(n θ)`, its imaginary part that
/// of `sin(n θ)`. Its magnitude `sin(δ/2)/(δ/2)` at the phase step `δ = n |θ₁ − θ₀|` is
/// what a sample keeps of the ripple's torque: 2/π at a step of π, nought at 2π.
pub fn ripple_phasor_mean(order: f64, theta0: f64, theta1: f64) -> (f64, f64) {
    let (a0, a1) = (order * theta0, order * theta1);
    let d = a1 - a0;
    if d.abs() < 1e-6 {
        let (s, c) = (0.5 * (a0 + a1)).sin_cos();
        (c, s)
    } else {
        ((a1.sin() - a0.sin()) / d, (a0.cos() - a1.cos()) / d)
    }
}

/// Mean of the ripple `A sin(n θ + φ)` [N·m] over a sample interval, the motor angle moving
/// linearly from `theta0` to `theta1` [rad] ([`ripple_phasor_mean`]).
pub fn ripple_interval_mean(
    amplitude: f64,
    order: f64,
    phase: f64,
    theta0: f64,
    theta1: f64,
) -> f64 {
    let (c, s) = ripple_phasor_mean(order, theta0, theta1);
    let (sp, cp) = phase.sin_cos();
    // sin(nθ + φ) = sin(nθ) cos φ + cos(nθ) sin φ
    amplitude * (s * cp + c * sp)
}

/// Output of the current loop (first-order lag with time constant `tc` [s]) after `t` [s]
/// with its input held at `target` from the value `start` [N·m]: `target + (start −
/// target) e^{−t/tc}`; `tc = 0` is no lag (the target at once).
#[inline(always)]
pub fn current_loop<T: Float>(start: T, target: T, tc: T, t: T) -> T {
    current_loop_decayed(start, target, current_loop_decay(tc, t))
}

/// Share of the current loop's initial error left after `t` [s], `e^{−t/tc}` [-] (0 for
/// `tc = 0`, no lag). Over `t₁ + t₂` it is the product of the shares over `t₁` and `t₂`, so
/// a stepper can square the half-step share instead of calling `exp` again.
#[inline(always)]
pub fn current_loop_decay<T: Float>(tc: T, t: T) -> T {
    if tc > T::zero() {
        (-t / tc).exp()
    } else {
        T::zero()
    }
}

/// [`current_loop`] with its decay `e^{−t/tc}` given ([`current_loop_decay`]):
/// `target + (start − target) decay` [N·m].
#[inline(always)]
pub fn current_loop_decayed<T: Float>(start: T, target: T, decay: T) -> T {
    target + (start - target) * decay
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_tanh_is_tanh_within_a_few_ulps_odd_and_exactly_one_when_saturated() {
        let mut worst: f64 = 0.0;
        for i in 0..=200_000 {
            let x = i as f64 * 1.3e-4 - 13.0;
            worst = worst.max((fast_tanh(x) - x.tanh()).abs());
            assert_eq!(
                fast_tanh(-x).to_bits(),
                (-fast_tanh(x)).to_bits(),
                "x = {x}"
            );
        }
        assert!(worst < 4e-16, "worst absolute error {worst:e}");
        for x in [1e-300, 1e-12, 1e-6] {
            assert!((fast_tanh(x) - x).abs() <= 4e-16, "x = {x}");
        }
        for x in [19.5, 20.0, 20.5, 1e3, f64::INFINITY] {
            assert_eq!(fast_tanh(x), x.tanh(), "x = {x}");
        }
        assert_eq!(fast_tanh(0.0), 0.0);
        assert!(fast_tanh(f64::NAN).is_nan());
    }

    #[test]
    fn smooth_dead_zone_is_within_half_eps_of_the_exact_one_and_zero_in_the_gap() {
        let (h, eps) = (1e-3, 1e-5);
        for i in -300..=300 {
            let d = i as f64 * 1e-5;
            let exact = dead_zone(d, h);
            let smooth = dead_zone_smooth(d, h, eps);
            assert!((exact - smooth).abs() <= 0.5 * eps + 1e-15, "δ = {d}");
        }
        assert!(dead_zone_smooth(0.0, h, eps).abs() < 1e-12);
        assert_eq!(dead_zone(2e-3, h), 1e-3);
        assert_eq!(dead_zone(-2e-3, h), -1e-3);
    }

    #[test]
    fn dead_zone_is_the_branch_of_its_region() {
        let h = 1e-3;
        for d in [-2e-3, -1e-3, -5e-4, 0.0, 5e-4, 1e-3, 2e-3] {
            let region = contact(d, h);
            assert_eq!(dead_zone(d, h), dead_zone_in(d, h, region), "δ = {d}");
        }
        assert_eq!(contact(1e-3, h), Contact::Gap);
        assert_eq!(contact(-1.5e-3, h), Contact::Neg);
        // a frozen region keeps its branch past the edge
        assert_eq!(dead_zone_in(5e-4, h, Contact::Pos), 5e-4 - h);
    }

    #[test]
    fn smooth_coulomb_tends_to_the_sign_law() {
        assert!((coulomb_smooth(0.1, 1.0, 1e-3) - 0.1).abs() < 1e-12);
        assert!((coulomb_smooth(0.1, -1.0, 1e-3) + 0.1).abs() < 1e-12);
        assert_eq!(coulomb_smooth(0.1, 0.0, 1e-3), 0.0);
    }

    #[test]
    fn asymmetric_smooth_coulomb_tends_to_each_side_and_reduces_to_the_symmetric_law() {
        let (lp, ln, fv) = (0.2, 0.3, 0.05);
        assert!((coulomb_smooth_asym(lp, ln, fv, 2.0, 1e-3) - lp).abs() < 1e-12);
        assert!((coulomb_smooth_asym(lp, ln, fv, -2.0, 1e-3) - (-ln - fv * 2.0)).abs() < 1e-12);
        assert_eq!(coulomb_smooth_asym(lp, ln, fv, 0.0, 1e-3), 0.0);
        for w in [-0.01, -1e-3, 2e-4, 0.05] {
            let a = coulomb_smooth_asym(lp, lp, 0.0, w, 1e-3);
            assert!((a - coulomb_smooth(lp, w, 1e-3)).abs() < 1e-15, "{w}");
        }
    }

    #[test]
    fn current_loop_lag_decays_to_its_target() {
        let tc = 5e-4;
        let v = current_loop(0.0, 1.0, tc, tc);
        assert!((v - (1.0 - (-1.0f64).exp())).abs() < 1e-15);
        assert_eq!(current_loop(0.3, 1.0, 0.0, 1e-4), 1.0);
    }

    #[test]
    fn cubic_spring_adds_to_the_linear_one() {
        let t = spring_torque(1.0e5, 1.6e11, 80.0, 1e-3, 0.01);
        assert!((t - (100.0 + 160.0 + 0.8)).abs() < 1e-9);
    }
}
