//! Forward-mode dual numbers for the output-error Jacobian: a value and its derivatives
//! with respect to up to `K − 1` parameters, `[f, ∂f/∂z_1, …]`, carried through the
//! simulation ([`super::model::Plant`]) by the chain rule.
//!
//! Why our own: the simulation multiplies and adds plain constants (step sizes, gear
//! factors) at every stage; [`Real`] lets it do so at the cost of the constant (one
//! multiply per slot), where a general dual type lifts the constant to a dual first and
//! pays a full product (three operations per slot). The slots are a plain array the
//! compiler vectorises. Semantics follow the usual convention for dual numbers: order and
//! `min`/`max` compare values; a number is finite when every slot is.

use std::num::FpCategory;
use std::ops::{Add, Div, Index, IndexMut, Mul, Neg, Rem, Sub};

use num_traits::{Float, Num, NumCast, One, ToPrimitive, Zero};

use crate::model::laws::{fast_tanh, LawFloat};

/// A scalar the simulation runs on: `f64` for the output, [`Dual`] for its derivatives,
/// with arithmetic against plain `f64` constants.
pub trait Real:
    LawFloat
    + Add<f64, Output = Self>
    + Sub<f64, Output = Self>
    + Mul<f64, Output = Self>
    + Div<f64, Output = Self>
{
    /// Whether the simulation inlines its per-sample steps for this scalar
    /// ([`super::model::Plant`]): for `f64`, whose cost evaluations a fit runs most and
    /// whose call per sample costs a sixth of them; not for the dual numbers, where the
    /// call is small beside the sample's work and inlining every width would triple the
    /// crate's compile time.
    const INLINE_STEPS: bool = false;
}

impl Real for f64 {
    const INLINE_STEPS: bool = true;
}

impl<const K: usize> Real for Dual<K> {}

impl<const K: usize> LawFloat for Dual<K> {
    #[inline(always)]
    fn tanh_law(self) -> Self {
        let t = fast_tanh(self.real());
        self.chain(t, 1.0 - t * t)
    }
}

/// `[f, ∂f/∂z_1, …, ∂f/∂z_{K−1}]`: slot 0 the value, the others its derivatives.
#[derive(Clone, Copy, Debug)]
pub struct Dual<const K: usize>(pub [f64; K]);

impl<const K: usize> Dual<K> {
    /// A constant (all derivatives nought).
    #[inline(always)]
    pub fn from_real(v: f64) -> Self {
        let mut s = [0.0; K];
        s[0] = v;
        Dual(s)
    }

    /// The value.
    #[inline(always)]
    pub fn real(&self) -> f64 {
        self.0[0]
    }

    /// Slots: the value and its `K − 1` derivatives.
    pub const fn len(&self) -> usize {
        K
    }

    /// Never empty (at least the value).
    pub const fn is_empty(&self) -> bool {
        K == 0
    }

    /// `f(x)` with derivative `f'(x)`: the value `f`, the derivatives scaled by `df`.
    #[inline(always)]
    fn chain(self, f: f64, df: f64) -> Self {
        let mut s = self.0;
        for v in s.iter_mut() {
            *v *= df;
        }
        s[0] = f;
        Dual(s)
    }

    /// `a·self + b·other` in the derivative slots, `value` in slot 0.
    #[inline(always)]
    fn combine(self, a: f64, other: Self, b: f64, value: f64) -> Self {
        let mut s = [0.0; K];
        for ((r, x), y) in s.iter_mut().zip(&self.0).zip(&other.0) {
            *r = a * x + b * y;
        }
        s[0] = value;
        Dual(s)
    }
}

impl<const K: usize> Index<usize> for Dual<K> {
    type Output = f64;
    #[inline(always)]
    fn index(&self, i: usize) -> &f64 {
        &self.0[i]
    }
}

impl<const K: usize> IndexMut<usize> for Dual<K> {
    #[inline(always)]
    fn index_mut(&mut self, i: usize) -> &mut f64 {
        &mut self.0[i]
    }
}

impl<const K: usize> PartialEq for Dual<K> {
    fn eq(&self, other: &Self) -> bool {
        self.0 == other.0
    }
}

impl<const K: usize> PartialOrd for Dual<K> {
    #[inline(always)]
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        self.real().partial_cmp(&other.real())
    }
}

impl<const K: usize> Neg for Dual<K> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        Dual(self.0.map(|v| -v))
    }
}

impl<const K: usize> Add for Dual<K> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        let mut s = self.0;
        for (a, b) in s.iter_mut().zip(&o.0) {
            *a += b;
        }
        Dual(s)
    }
}

impl<const K: usize> Sub for Dual<K> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        let mut s = self.0;
        for (a, b) in s.iter_mut().zip(&o.0) {
            *a -= b;
        }
        Dual(s)
    }
}

impl<const K: usize> Mul for Dual<K> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        let (a, b) = (self.real(), o.real());
        self.combine(b, o, a, a * b)
    }
}

impl<const K: usize> Div for Dual<K> {
    type Output = Self;
    #[inline(always)]
    fn div(self, o: Self) -> Self {
        let (a, b) = (self.real(), o.real());
        let d = b * b;
        // (a/b)' = (b a' − a b')/b²
        let mut s = [0.0; K];
        for ((r, x), y) in s.iter_mut().zip(&self.0).zip(&o.0) {
            *r = (b * x - a * y) / d;
        }
        s[0] = a / b;
        Dual(s)
    }
}

impl<const K: usize> Rem for Dual<K> {
    type Output = Self;
    /// `a − b·trunc(a/b)`, the truncation held constant.
    fn rem(self, o: Self) -> Self {
        let q = (self.real() / o.real()).trunc();
        self - o * Self::from_real(q)
    }
}

impl<const K: usize> Add<f64> for Dual<K> {
    type Output = Self;
    #[inline(always)]
    fn add(mut self, c: f64) -> Self {
        self.0[0] += c;
        self
    }
}

impl<const K: usize> Sub<f64> for Dual<K> {
    type Output = Self;
    #[inline(always)]
    fn sub(mut self, c: f64) -> Self {
        self.0[0] -= c;
        self
    }
}

impl<const K: usize> Mul<f64> for Dual<K> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, c: f64) -> Self {
        Dual(self.0.map(|v| v * c))
    }
}

impl<const K: usize> Div<f64> for Dual<K> {
    type Output = Self;
    #[inline(always)]
    fn div(self, c: f64) -> Self {
        Dual(self.0.map(|v| v / c))
    }
}

impl<const K: usize> Zero for Dual<K> {
    fn zero() -> Self {
        Self::from_real(0.0)
    }
    fn is_zero(&self) -> bool {
        self.real() == 0.0
    }
}

impl<const K: usize> One for Dual<K> {
    fn one() -> Self {
        Self::from_real(1.0)
    }
}

impl<const K: usize> Num for Dual<K> {
    type FromStrRadixErr = <f64 as Num>::FromStrRadixErr;
    fn from_str_radix(s: &str, radix: u32) -> Result<Self, Self::FromStrRadixErr> {
        f64::from_str_radix(s, radix).map(Self::from_real)
    }
}

impl<const K: usize> ToPrimitive for Dual<K> {
    fn to_i64(&self) -> Option<i64> {
        self.real().to_i64()
    }
    fn to_u64(&self) -> Option<u64> {
        self.real().to_u64()
    }
    fn to_f64(&self) -> Option<f64> {
        Some(self.real())
    }
}

impl<const K: usize> NumCast for Dual<K> {
    #[inline(always)]
    fn from<P: ToPrimitive>(n: P) -> Option<Self> {
        n.to_f64().map(Self::from_real)
    }
}

/// The value's own function: derivatives kept (`fract`) or nought (rounding).
macro_rules! piecewise_constant {
    ($($f:ident),*) => {
        $(fn $f(self) -> Self {
            Self::from_real(self.real().$f())
        })*
    };
}

impl<const K: usize> Float for Dual<K> {
    fn nan() -> Self {
        Self::from_real(f64::NAN)
    }
    fn infinity() -> Self {
        Self::from_real(f64::INFINITY)
    }
    fn neg_infinity() -> Self {
        Self::from_real(f64::NEG_INFINITY)
    }
    fn neg_zero() -> Self {
        Self::from_real(-0.0)
    }
    fn min_value() -> Self {
        Self::from_real(f64::MIN)
    }
    fn min_positive_value() -> Self {
        Self::from_real(f64::MIN_POSITIVE)
    }
    fn epsilon() -> Self {
        Self::from_real(f64::EPSILON)
    }
    fn max_value() -> Self {
        Self::from_real(f64::MAX)
    }
    fn is_nan(self) -> bool {
        self.0.iter().any(|v| v.is_nan())
    }
    fn is_infinite(self) -> bool {
        self.0.iter().any(|v| v.is_infinite())
    }
    #[inline(always)]
    fn is_finite(self) -> bool {
        self.0.iter().all(|v| v.is_finite())
    }
    fn is_normal(self) -> bool {
        self.0.iter().all(|v| v.is_normal())
    }
    fn classify(self) -> FpCategory {
        self.real().classify()
    }
    piecewise_constant!(floor, ceil, round, trunc, signum);
    fn fract(self) -> Self {
        let mut s = self;
        s.0[0] = self.real().fract();
        s
    }
    #[inline(always)]
    fn abs(self) -> Self {
        let sign = self.real().signum();
        self * sign
    }
    fn is_sign_positive(self) -> bool {
        self.real().is_sign_positive()
    }
    fn is_sign_negative(self) -> bool {
        self.real().is_sign_negative()
    }
    fn mul_add(self, a: Self, b: Self) -> Self {
        self * a + b
    }
    fn recip(self) -> Self {
        let r = 1.0 / self.real();
        self.chain(r, -r * r)
    }
    #[inline(always)]
    fn powi(self, n: i32) -> Self {
        let r = self.real().powi(n - 1);
        self.chain(self.real() * r, <f64 as From<i32>>::from(n) * r)
    }
    fn powf(self, n: Self) -> Self {
        let (x, y) = (self.real(), n.real());
        let value = x.powf(y);
        self.combine(y * x.powf(y - 1.0), n, value * x.ln(), value)
    }
    fn sqrt(self) -> Self {
        let r = self.real().sqrt();
        self.chain(r, 0.5 / r)
    }
    #[inline(always)]
    fn exp(self) -> Self {
        let e = self.real().exp();
        self.chain(e, e)
    }
    fn exp2(self) -> Self {
        let e = self.real().exp2();
        self.chain(e, e * std::f64::consts::LN_2)
    }
    fn ln(self) -> Self {
        self.chain(self.real().ln(), 1.0 / self.real())
    }
    fn log(self, base: Self) -> Self {
        self.ln() / base.ln()
    }
    fn log2(self) -> Self {
        let x = self.real();
        self.chain(x.log2(), 1.0 / (x * std::f64::consts::LN_2))
    }
    fn log10(self) -> Self {
        let x = self.real();
        self.chain(x.log10(), 1.0 / (x * std::f64::consts::LN_10))
    }
    fn max(self, other: Self) -> Self {
        if self.real() > other.real() {
            self
        } else {
            other
        }
    }
    fn min(self, other: Self) -> Self {
        if self.real() < other.real() {
            self
        } else {
            other
        }
    }
    fn abs_sub(self, other: Self) -> Self {
        if self.real() > other.real() {
            self - other
        } else {
            Self::zero()
        }
    }
    fn cbrt(self) -> Self {
        let r = self.real().cbrt();
        self.chain(r, 1.0 / (3.0 * r * r))
    }
    fn hypot(self, other: Self) -> Self {
        let (x, y) = (self.real(), other.real());
        let h = x.hypot(y);
        self.combine(x / h, other, y / h, h)
    }
    fn sin(self) -> Self {
        let (s, c) = self.real().sin_cos();
        self.chain(s, c)
    }
    fn cos(self) -> Self {
        let (s, c) = self.real().sin_cos();
        self.chain(c, -s)
    }
    fn tan(self) -> Self {
        let t = self.real().tan();
        self.chain(t, 1.0 + t * t)
    }
    fn asin(self) -> Self {
        let x = self.real();
        self.chain(x.asin(), 1.0 / (1.0 - x * x).sqrt())
    }
    fn acos(self) -> Self {
        let x = self.real();
        self.chain(x.acos(), -1.0 / (1.0 - x * x).sqrt())
    }
    fn atan(self) -> Self {
        let x = self.real();
        self.chain(x.atan(), 1.0 / (1.0 + x * x))
    }
    fn atan2(self, other: Self) -> Self {
        let (y, x) = (self.real(), other.real());
        let r2 = x * x + y * y;
        self.combine(x / r2, other, -y / r2, y.atan2(x))
    }
    fn sin_cos(self) -> (Self, Self) {
        let (s, c) = self.real().sin_cos();
        (self.chain(s, c), self.chain(c, -s))
    }
    fn exp_m1(self) -> Self {
        let x = self.real();
        self.chain(x.exp_m1(), x.exp())
    }
    fn ln_1p(self) -> Self {
        let x = self.real();
        self.chain(x.ln_1p(), 1.0 / (1.0 + x))
    }
    fn sinh(self) -> Self {
        let x = self.real();
        self.chain(x.sinh(), x.cosh())
    }
    fn cosh(self) -> Self {
        let x = self.real();
        self.chain(x.cosh(), x.sinh())
    }
    #[inline(always)]
    fn tanh(self) -> Self {
        let t = self.real().tanh();
        self.chain(t, 1.0 - t * t)
    }
    fn asinh(self) -> Self {
        let x = self.real();
        self.chain(x.asinh(), 1.0 / (x * x + 1.0).sqrt())
    }
    fn acosh(self) -> Self {
        let x = self.real();
        self.chain(x.acosh(), 1.0 / (x * x - 1.0).sqrt())
    }
    fn atanh(self) -> Self {
        let x = self.real();
        self.chain(x.atanh(), 1.0 / (1.0 - x * x))
    }
    fn integer_decode(self) -> (u64, i16, i8) {
        self.real().integer_decode()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `f` at `x` with derivative seeds, against central differences of `f` on `f64`.
    fn check(name: &str, x: f64, f: impl Fn(Dual<3>) -> Dual<3>, g: impl Fn(f64) -> f64) {
        let mut d = Dual::<3>::from_real(x);
        d[1] = 1.0;
        d[2] = -2.0;
        let y = f(d);
        let h = 1e-6 * x.abs().max(1.0);
        let fd = (g(x + h) - g(x - h)) / (2.0 * h);
        assert!(
            (y.real() - g(x)).abs() <= 1e-14 * g(x).abs().max(1.0),
            "{name} value"
        );
        assert!(
            (y[1] - fd).abs() <= 1e-6 * fd.abs().max(1.0),
            "{name}: {} vs {fd}",
            y[1]
        );
        assert!(
            (y[2] + 2.0 * fd).abs() <= 2e-6 * fd.abs().max(1.0),
            "{name} slot 2"
        );
    }

    #[test]
    fn derivatives_match_central_differences() {
        let x = 0.37;
        check("mul", x, |d| d * d * d, |v| v * v * v);
        check(
            "div",
            x,
            |d| (d + 1.0) / (d * d + 2.0),
            |v| (v + 1.0) / (v * v + 2.0),
        );
        check(
            "scalar",
            x,
            |d| (d * 3.0 - 1.5) / 2.0,
            |v| (v * 3.0 - 1.5) / 2.0,
        );
        check("exp", x, Float::exp, f64::exp);
        check("ln", x, Float::ln, f64::ln);
        check("tanh", x, Float::tanh, f64::tanh);
        check("tanh_law", x, LawFloat::tanh_law, f64::tanh);
        check("tanh_law", 3.0, LawFloat::tanh_law, f64::tanh);
        check("sqrt", x, Float::sqrt, f64::sqrt);
        check("powi", x, |d| d.powi(3), |v| v.powi(3));
        check("powf", x, |d| d.powf(Dual::from_real(2.5)), |v| v.powf(2.5));
        check("sin", x, Float::sin, f64::sin);
        check("cos", x, Float::cos, f64::cos);
        check(
            "atan2",
            x,
            |d| d.atan2(d * 2.0 + 1.0),
            |v| v.atan2(2.0 * v + 1.0),
        );
        check("hypot", x, |d| d.hypot(d * d), |v| v.hypot(v * v));
        check("abs", -x, Float::abs, f64::abs);
        check("recip", x, Float::recip, f64::recip);
        check("exp_m1", x, Float::exp_m1, f64::exp_m1);
        check("sinh", x, Float::sinh, f64::sinh);
        check("atanh", x, Float::atanh, f64::atanh);
    }

    #[test]
    fn order_compares_values_and_finiteness_every_slot() {
        let mut a = Dual::<3>::from_real(1.0);
        a[1] = 5.0;
        let b = Dual::<3>::from_real(2.0);
        assert!(a < b && a.max(b) == b && a.min(b) == a);
        a[2] = f64::INFINITY;
        assert!(!a.is_finite() && b.is_finite());
    }
}
