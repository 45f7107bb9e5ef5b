//! Black-box models from the FRF: frequency-domain subspace identification
//! at the excited lines, refined by the same sample maximum-likelihood cost
//! as the physical models ([`crate::ident::sml`]).
//!
//! Why: on undecimated 2 kHz data a time-domain subspace model of order 11
//! spends its order on the noise and the drift, and its simulation drifts
//! (validation FIT far below the true model's). The period-averaged FRF at
//! the excited lines carries neither.
//!
//! Subspace step (McKelvey, Akçay & Ljung, "Subspace-based multivariable
//! system identification from frequency response data", IEEE TAC 41(7),
//! 1996, Algorithm 1 for arbitrary frequencies): with `W_q(z) = [1, z, …,
//! z^{q−1}]ᵀ`, stack `W_q(z_k) Ĝ_k` and `W_q(z_k)` column by column (real and
//! imaginary parts side by side), remove the second from the first by an LQ
//! factorisation, and read the extended observability matrix `O_q` from the
//! `n` leading left singular vectors of what is left; `C` is its first row,
//! `A` solves the shift equation `O_q[1..] = O_q[..q−1] A`. `B`, `D` then
//! follow from the FRF by linear least squares weighted by `1/σ_k`.
//!
//! Refinement: Levenberg–Marquardt ([`crate::ident::lm`]) on every entry of
//! `A, B, C, D` (over-parameterised by the similarity transform; the
//! damping of the loop and the pseudo-inverse keep the steps finite) with
//! the SML cost, its Jacobian exact: `∂G/∂A_ij = v_i x_j` from two Hessenberg solves per
//! line for all `n² + 2n + 1` entries (order 11 on 15,000 samples: 0.25 → 0.03 s against
//! differences). No parameter covariance is reported for a black box.

use nalgebra::{DMatrix, DVector, RowDVector};
use rustfft::num_complex::Complex64;
use thiserror::Error;

use crate::ident::frf::Frf;
use crate::ident::lm::{self, LeastSquares, LmOptions, Termination};
use crate::ident::sml::{
    output_kind_check, solve_hessenberg, solve_pair, unit_circle, unsupported_modes, Cost,
    FitWarning, FrfModel, Jacobian, Lines, Problem, COST_RATIO_WARN,
};
use crate::ident::ss::StateSpace;

/// Why a black box could not be fitted to the FRF.
#[derive(Debug, Error, PartialEq)]
pub enum FrfSubspaceError {
    /// too few lines for the order
    #[error("order {order} needs at least {needed} excited lines, the FRF has {lines}")]
    TooFewLines {
        /// order asked for
        order: usize,
        /// lines needed
        needed: usize,
        /// lines in the FRF
        lines: usize,
    },
    /// the order is zero
    #[error("the order must be at least 1")]
    ZeroOrder,
    /// the subspace step gave no usable model
    #[error("the subspace step failed: {0}")]
    Subspace(&'static str),
}

/// Result of [`black_box_frf`].
#[derive(Clone, Debug, PartialEq)]
pub struct FrfBlackBox {
    /// the model at the data's sample interval
    pub model: StateSpace,
    /// SML cost after refinement (the subspace model's when not refined)
    pub cost: f64,
    /// the cost expected at the true model
    pub expected_cost: f64,
    /// SML cost of the subspace model before refinement
    pub subspace_cost: f64,
    /// iterations of the refinement (0: not refined)
    pub iterations: usize,
    /// parameters of a minimal form of the model (the similarity transform's left out)
    pub parameters: usize,
    /// what the user must know
    pub warnings: Vec<FitWarning>,
}

impl FrfBlackBox {
    /// cost / expected cost: about 1 when the noise explains the misfit
    pub fn cost_ratio(&self) -> f64 {
        self.cost / self.expected_cost
    }
}

/// The bilinear (Möbius) map `ζ = (a z + b)/(c z + d)` that spreads the
/// lines over the unit circle: Tustin `s = (2/T)(z − 1)/(z + 1)`, then
/// `ζ = (α + s)/(α − s)` with `α` the geometric mean of the lines' `s`
/// (McKelvey et al. 1996 §V; at 2 kHz the lines fill only the first 0.4 rad
/// of the `z` circle, where `[1, z, …, z^{q−1}]` is nearly rank one).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Mobius {
    a: f64,
    b: f64,
    c: f64,
    d: f64,
}

impl Mobius {
    fn new(freq_hz: &[f64], ts: f64) -> Mobius {
        let om: Vec<f64> = freq_hz
            .iter()
            .map(|f| (2.0 / ts) * (std::f64::consts::PI * f * ts).tan())
            .collect();
        let alpha =
            (om.iter().map(|w| w.max(1e-12).ln()).sum::<f64>() / om.len().max(1) as f64).exp();
        let e = alpha * ts / 2.0;
        Mobius {
            a: 1.0 + e,
            b: e - 1.0,
            c: e - 1.0,
            d: 1.0 + e,
        }
    }

    fn map(&self, z: Complex64) -> Complex64 {
        (z * self.a + self.b) / (z * self.c + self.d)
    }

    /// the `z`-domain state space of a `ζ`-domain one (same response)
    fn state_space_in_z(
        &self,
        a1: &DMatrix<f64>,
        b1: &DVector<f64>,
        c1: &RowDVector<f64>,
        d1: f64,
        ts: f64,
    ) -> Option<StateSpace> {
        let n = a1.nrows();
        let id = DMatrix::<f64>::identity(n, n);
        let e = &id * self.a - a1 * self.c;
        let f = a1 * self.d - &id * self.b;
        let ei = e.try_inverse()?;
        let a = &ei * f;
        let b = &ei * b1;
        let c = c1 * (&a * self.c + &id * self.d);
        let d = d1 + self.c * (c1 * &b)[0];
        Some(StateSpace::new(a, b, c, d, ts))
    }
}

/// Entries of `A` (row by row), `B`, `C` of the `ζ`-domain model, and `D`
/// when a feed-through is wanted (else `D` makes the `z`-domain model
/// strictly proper).
struct BlackBoxFrf {
    n: usize,
    mobius: Mobius,
    feedthrough: bool,
}

impl BlackBoxFrf {
    fn unpack(&self, th: &[f64]) -> (DMatrix<f64>, DVector<f64>, DVector<f64>, f64) {
        let n = self.n;
        let a = DMatrix::from_row_slice(n, n, &th[..n * n]);
        let b = DVector::from_column_slice(&th[n * n..n * n + n]);
        let c = DVector::from_column_slice(&th[n * n + n..n * n + 2 * n]);
        let d = if self.feedthrough {
            th[n * n + 2 * n]
        } else {
            // z-domain D = D' + c C' E⁻¹ B' = 0 (see `Mobius::state_space_in_z`)
            let e = DMatrix::<f64>::identity(n, n) * self.mobius.a - &a * self.mobius.c;
            match e.lu().solve(&b) {
                Some(x) => -self.mobius.c * c.dot(&x),
                None => f64::NAN,
            }
        };
        (a, b, c, d)
    }

    fn to_z(&self, th: &[f64], ts: f64) -> Option<StateSpace> {
        let (a, b, c, d) = self.unpack(th);
        let mut ss = self
            .mobius
            .state_space_in_z(&a, &b, &c.transpose(), d, ts)?;
        if !self.feedthrough {
            ss.d = 0.0;
        }
        Some(ss)
    }

    fn pack(a: &DMatrix<f64>, b: &DVector<f64>, c: &RowDVector<f64>, d: f64) -> Vec<f64> {
        let n = a.nrows();
        let mut th = Vec::with_capacity(n * n + 2 * n + 1);
        for i in 0..n {
            for j in 0..n {
                th.push(a[(i, j)]);
            }
        }
        th.extend(b.iter());
        th.extend(c.iter());
        th.push(d);
        th
    }
}

/// `C (zI − A)^{−1} B + D` at each `z`, through the Hessenberg form of `A`.
fn response(
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    c: &DVector<f64>,
    d: f64,
    z: &[Complex64],
) -> Vec<Complex64> {
    let n = a.nrows();
    let (q, h) = a.clone().hessenberg().unpack();
    let qt = q.transpose();
    let (hb, hc) = (&qt * b, &qt * c);
    let mut m = vec![Complex64::new(0.0, 0.0); n * n];
    let mut rhs = vec![Complex64::new(0.0, 0.0); n];
    z.iter()
        .map(|&zk| {
            for i in 0..n {
                for j in 0..n {
                    m[i * n + j] = Complex64::new(-h[(i, j)], 0.0);
                }
                m[i * n + i] += zk;
                rhs[i] = Complex64::new(hb[i], 0.0);
            }
            if solve_hessenberg(&mut m, &mut rhs, n) {
                rhs.iter()
                    .zip(hc.iter())
                    .fold(Complex64::new(d, 0.0), |g, (x, c)| g + x * c)
            } else {
                Complex64::new(f64::NAN, f64::NAN)
            }
        })
        .collect()
}

impl FrfModel for BlackBoxFrf {
    fn n_params(&self) -> usize {
        self.n * self.n + 2 * self.n + 1
    }

    fn response(&self, theta: &[f64], z: &[Complex64]) -> Option<Vec<Complex64>> {
        let (a, b, c, d) = self.unpack(theta);
        let zeta: Vec<Complex64> = z.iter().map(|&z| self.mobius.map(z)).collect();
        let g = response(&a, &b, &c, d, &zeta);
        g.iter().all(|v| v.is_finite()).then_some(g)
    }

    /// Exact: with `x = (ζI − A)^{−1}B` and `vᵀ = Cᵀ(ζI − A)^{−1}`, `∂G/∂A_ij = v_i x_j`,
    /// `∂G/∂B_i = v_i`, `∂G/∂C_j = x_j`; two Hessenberg solves per line for all
    /// `n² + 2n + 1` parameters, where differences cost one per line and parameter.
    /// Without a feed-through `D = −m_c Cᵀ E^{−1} B`, `E = m_a I − m_c A`, adds
    /// `∂D/∂A_ij = −m_c² p_i q_j`, `∂D/∂B_i = −m_c p_i`, `∂D/∂C_j = −m_c q_j` with
    /// `p = E^{−T} C`, `q = E^{−1} B`.
    fn response_jacobian(
        &self,
        theta: &[f64],
        z: &[Complex64],
        free: &[usize],
    ) -> Option<Jacobian> {
        let n = self.n;
        let (a, b, c, d) = self.unpack(theta);
        if !d.is_finite() {
            return None;
        }
        let (q, h) = a.clone().hessenberg().unpack();
        let qt = q.transpose();
        let (hb, hc) = (&qt * &b, &qt * &c);
        let (pd, qd) = if self.feedthrough {
            (DVector::zeros(n), DVector::zeros(n))
        } else {
            let mc = self.mobius.c;
            let e = DMatrix::<f64>::identity(n, n) * self.mobius.a - &a * mc;
            let lu = e.clone().lu();
            let qd = lu.solve(&b)?;
            let pd = e.transpose().lu().solve(&c)?;
            (pd * -mc, qd * -mc)
        };
        let zero = Complex64::new(0.0, 0.0);
        let mut m = vec![zero; n * n];
        let (mut x, mut v) = (vec![zero; n], vec![zero; n]);
        let (mut xo, mut vo) = (vec![zero; n], vec![zero; n]);
        let mut g = Vec::with_capacity(z.len());
        let mut cols = vec![Vec::with_capacity(z.len()); free.len()];
        for &zk in z {
            let zeta = self.mobius.map(zk);
            for i in 0..n {
                x[i] = Complex64::new(hb[i], 0.0);
                v[i] = Complex64::new(hc[i], 0.0);
            }
            if !solve_pair(&h, zeta, &mut m, &mut x, &mut v) {
                return None;
            }
            g.push(
                x.iter()
                    .zip(hc.iter())
                    .fold(Complex64::new(d, 0.0), |s, (x, c)| s + x * c),
            );
            // back to the basis of the parameters
            for i in 0..n {
                let (mut sx, mut sv) = (zero, zero);
                for j in 0..n {
                    sx += x[j] * q[(i, j)];
                    sv += v[j] * q[(i, j)];
                }
                xo[i] = sx;
                vo[i] = sv;
            }
            for (col, &i) in cols.iter_mut().zip(free) {
                col.push(if i < n * n {
                    let (r, k) = (i / n, i % n);
                    vo[r] * xo[k] - pd[r] * qd[k]
                } else if i < n * n + n {
                    vo[i - n * n] + pd[i - n * n]
                } else if i < n * n + 2 * n {
                    xo[i - n * n - n] + qd[i - n * n - n]
                } else if self.feedthrough {
                    Complex64::new(1.0, 0.0)
                } else {
                    zero
                });
            }
        }
        g.iter().all(|v| v.is_finite()).then_some((g, cols))
    }

    fn step(&self, i: usize, theta: &[f64]) -> f64 {
        // relative to the entry, floored at a share of its block's scale
        let n = self.n;
        let block = if i < n * n {
            0..n * n
        } else if i < n * n + n {
            n * n..n * n + n
        } else if i < n * n + 2 * n {
            n * n + n..n * n + 2 * n
        } else {
            i..i + 1
        };
        let scale = theta[block].iter().map(|v| v.abs()).fold(0.0, f64::max);
        1e-7 * theta[i].abs().max(1e-3 * scale).max(1e-300)
    }
}

/// The subspace model of order `n` in the `ζ` domain of `mobius` (module
/// docs), with its feed-through.
fn subspace(frf: &Frf, n: usize, ts: f64, mobius: &Mobius) -> Result<StateSpace, FrfSubspaceError> {
    let feedthrough = true;
    let z: Vec<Complex64> = unit_circle(&frf.freq_hz, ts)
        .into_iter()
        .map(|z| mobius.map(z))
        .collect();
    let m = z.len();
    let q = (2 * n).max(n + 2);
    // rows 0..q: W_q(z_k) (input), rows q..2q: W_q(z_k) G_k (output);
    // columns: real parts of the M lines, then imaginary parts
    let mut h = DMatrix::<f64>::zeros(2 * q, 2 * m);
    for (k, (&zk, &gk)) in z.iter().zip(&frf.g).enumerate() {
        let w = 1.0 / frf.sigma[k].max(1e-6 * gk.norm()).max(1e-300);
        let mut p = Complex64::new(1.0, 0.0);
        for i in 0..q {
            let (u, y) = (p * w, p * gk * w);
            h[(i, k)] = u.re;
            h[(i, m + k)] = u.im;
            h[(q + i, k)] = y.re;
            h[(q + i, m + k)] = y.im;
            p *= zk;
        }
    }
    // LQ: h = L Qᵀ, from the QR of hᵀ
    let r = h.transpose().qr().r();
    let l = r.transpose();
    let l22 = l.view((q, q), (q, q)).into_owned();
    let svd = l22.svd(true, false);
    let u = svd.u.ok_or(FrfSubspaceError::Subspace("no SVD"))?;
    let mut idx: Vec<usize> = (0..q).collect();
    idx.sort_by(|&a, &b| svd.singular_values[b].total_cmp(&svd.singular_values[a]));
    let o = DMatrix::from_fn(q, n, |i, j| u[(i, idx[j])]);
    let c = o.row(0).into_owned();
    let upper = o.rows(0, q - 1).into_owned();
    let lower = o.rows(1, q - 1).into_owned();
    let a = upper
        .svd(true, true)
        .solve(&lower, 1e-12)
        .map_err(|_| FrfSubspaceError::Subspace("the shift equation has no solution"))?;
    // B, D by weighted least squares over real and imaginary parts
    let nb = n + usize::from(feedthrough);
    let mut phi = DMatrix::<f64>::zeros(2 * m, nb);
    let mut rhs = DVector::<f64>::zeros(2 * m);
    let ct = c.transpose();
    for (k, (&zk, &gk)) in z.iter().zip(&frf.g).enumerate() {
        let w = 1.0 / frf.sigma[k].max(1e-6 * gk.norm()).max(1e-300);
        // row vector C (zI − A)^{-1}: solve (zI − A)ᵀ x = Cᵀ
        let mzt = DMatrix::<Complex64>::from_fn(n, n, |i, j| {
            let v = -a[(j, i)];
            if i == j {
                zk + v
            } else {
                Complex64::new(v, 0.0)
            }
        });
        let x = mzt
            .lu()
            .solve(&ct.map(|v| Complex64::new(v, 0.0)))
            .ok_or(FrfSubspaceError::Subspace("a line sits on a pole"))?;
        for i in 0..n {
            phi[(k, i)] = x[i].re * w;
            phi[(m + k, i)] = x[i].im * w;
        }
        if feedthrough {
            phi[(k, n)] = w;
        }
        rhs[k] = gk.re * w;
        rhs[m + k] = gk.im * w;
    }
    let sol = phi
        .svd(true, true)
        .solve(&rhs, 1e-12)
        .map_err(|_| FrfSubspaceError::Subspace("B, D least squares failed"))?;
    let b = sol.rows(0, n).into_owned();
    let d = if feedthrough { sol[n] } else { 0.0 };
    Ok(StateSpace::new(a, b, c, d, ts))
}

/// Black box of order `n` fitted to the FRF (module docs); `feedthrough`
/// estimates `D` (e.g. an acceleration output), else `D = 0`.
///
/// # Errors
/// [`FrfSubspaceError`] when the FRF cannot carry the order or the
/// subspace step fails.
pub fn black_box_frf(
    frf: &Frf,
    n: usize,
    ts: f64,
    feedthrough: bool,
    max_iter: usize,
) -> Result<FrfBlackBox, FrfSubspaceError> {
    fit(frf, n, ts, feedthrough, max_iter, false)
}

/// Black box of order `n` with the rigid-body integrator exact: `n − 1` free states for the
/// differenced output `(1 − z⁻¹) G` and the integrator `z / (z − 1)` (the structure of
/// [`crate::ident::fit`]'s time-domain black box of an angle, [`StateSpace::with_integrator`]).
/// The subspace start is read off the differenced FRF `(1 − e^{−jωTs}) Ĝ`, the refinement
/// is the SML cost of the FRF itself. Strictly proper (an angle).
///
/// # Errors
/// As [`black_box_frf`]; the order must be at least 2.
pub fn black_box_frf_integrating(
    frf: &Frf,
    n: usize,
    ts: f64,
    max_iter: usize,
) -> Result<FrfBlackBox, FrfSubspaceError> {
    if n < 2 {
        return Err(FrfSubspaceError::ZeroOrder);
    }
    fit(frf, n, ts, false, max_iter, true)
}

/// `inner` followed by the integrator `z / (z − 1)`
struct Integrating<'a> {
    inner: &'a BlackBoxFrf,
}

impl FrfModel for Integrating<'_> {
    fn n_params(&self) -> usize {
        self.inner.n_params()
    }

    fn response(&self, theta: &[f64], z: &[Complex64]) -> Option<Vec<Complex64>> {
        let g = self.inner.response(theta, z)?;
        let out: Vec<Complex64> = g.iter().zip(z).map(|(g, &z)| g * z / (z - 1.0)).collect();
        out.iter().all(|v| v.is_finite()).then_some(out)
    }

    fn step(&self, i: usize, theta: &[f64]) -> f64 {
        self.inner.step(i, theta)
    }

    fn response_jacobian(
        &self,
        theta: &[f64],
        z: &[Complex64],
        free: &[usize],
    ) -> Option<Jacobian> {
        let (mut g, mut cols) = self.inner.response_jacobian(theta, z, free)?;
        for (k, &zk) in z.iter().enumerate() {
            let f = zk / (zk - 1.0);
            g[k] *= f;
            for col in cols.iter_mut() {
                col[k] *= f;
            }
        }
        g.iter().all(|v| v.is_finite()).then_some((g, cols))
    }
}

/// `frf` times `1 − z⁻¹` at each line (the differenced output's FRF), for a start
fn differenced(frf: &Frf, ts: f64) -> Frf {
    let mut d = frf.clone();
    for ((g, s), &f) in d.g.iter_mut().zip(d.sigma.iter_mut()).zip(&frf.freq_hz) {
        let z = Complex64::from_polar(1.0, 2.0 * std::f64::consts::PI * f * ts);
        let k = Complex64::new(1.0, 0.0) - z.inv();
        *g *= k;
        *s *= k.norm();
    }
    d
}

/// [`black_box_frf`] and [`black_box_frf_integrating`]: order `n` in all.
fn fit(
    frf: &Frf,
    n: usize,
    ts: f64,
    feedthrough: bool,
    max_iter: usize,
    integrator: bool,
) -> Result<FrfBlackBox, FrfSubspaceError> {
    if n == 0 {
        return Err(FrfSubspaceError::ZeroOrder);
    }
    let needed = n + 2;
    if frf.g.len() < needed {
        return Err(FrfSubspaceError::TooFewLines {
            order: n,
            needed,
            lines: frf.g.len(),
        });
    }
    // the free part's order and the FRF its start is read from
    let (m, start_frf) = if integrator {
        (n - 1, std::borrow::Cow::Owned(differenced(frf, ts)))
    } else {
        (n, std::borrow::Cow::Borrowed(frf))
    };
    let mobius = Mobius::new(&frf.freq_hz, ts);
    let sub = subspace(&start_frf, m, ts, &mobius)?;
    let lines = Lines::new(frf, ts);
    let bb = BlackBoxFrf {
        n: m,
        mobius,
        feedthrough,
    };
    let with_integrator = Integrating { inner: &bb };
    let th0 = BlackBoxFrf::pack(&sub.a, &sub.b, &sub.c, sub.d);
    let np = bb.n_params();
    let mut fixed = vec![false; np];
    fixed[np - 1] = !feedthrough;
    let o = LmOptions {
        max_iter,
        rel_cost_tol: 1e-9,
        fixed,
        ..Default::default()
    };
    let (subspace_cost, result) = if integrator {
        let p = Problem {
            model: &with_integrator,
            lines: &lines,
            cost: Cost::Sml,
        };
        (p.cost(&th0), lm::minimize(&p, &th0, &o))
    } else {
        let p = Problem {
            model: &bb,
            lines: &lines,
            cost: Cost::Sml,
        };
        (p.cost(&th0), lm::minimize(&p, &th0, &o))
    };
    let free = np - usize::from(!feedthrough);
    let (theta, cost, iterations, limit) = match result {
        Ok(f) if f.ssr < subspace_cost => (
            f.theta.clone(),
            f.ssr,
            f.iterations,
            f.termination == Termination::MaxIterations && max_iter > 0,
        ),
        _ => (th0, subspace_cost, 0, false),
    };
    let model = bb
        .to_z(&theta, ts)
        .map(|f| if integrator { f.with_integrator() } else { f })
        .ok_or(FrfSubspaceError::Subspace(
            "the bilinear map back to z is singular",
        ))?;
    // the similarity transform leaves m² directions free: count the
    // parameters a minimal form would have
    let minimal = free
        .saturating_sub(m * m)
        .max(2 * m + usize::from(feedthrough));
    let expected_cost = lines.expected_cost(minimal);
    let mut warnings = Vec::new();
    if limit {
        warnings.push(FitWarning::IterationLimit { iterations });
    }
    let ratio = cost / expected_cost;
    if ratio > COST_RATIO_WARN {
        warnings.push(FitWarning::CostAboveNoise { ratio });
    }
    if !feedthrough {
        // a strictly proper mechanical response falls by at least 20 dB/decade
        warnings.extend(output_kind_check(frf, -20.0));
    }
    warnings.extend(unsupported_modes(frf, &model));
    Ok(FrfBlackBox {
        model,
        cost,
        expected_cost,
        subspace_cost,
        iterations,
        parameters: minimal,
        warnings,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::{Dataset, ExcitationConfig};
    use crate::ident::frf::analyze_dataset;
    use crate::ident::sml::periodic_fit_percent;
    use crate::sim::{simulate_excitation, SimConfig};

    fn frf_of(cfg: &SimConfig, seed: u64) -> Frf {
        frf_of_exc(cfg, seed, ExcitationConfig::paper_default())
    }

    /// FRF of `exc` on `cfg`'s joint (the first period dropped)
    fn frf_of_exc(cfg: &SimConfig, seed: u64, exc: ExcitationConfig) -> Frf {
        let out = simulate_excitation(
            &SimConfig {
                seed,
                ..cfg.clone()
            },
            &exc,
        )
        .unwrap();
        let ds = Dataset {
            name: "sim".into(),
            data: out.to_id_data(),
            t0: 0.0,
            excitation: Some(exc),
            meta: Default::default(),
        };
        analyze_dataset(&ds, 1).unwrap().frf
    }

    #[test]
    fn order_11_black_box_on_undecimated_default_data_finds_both_modes_and_validates() {
        // the simulator's default joint and sensors at 2 kHz, undecimated
        let cfg = SimConfig::default();
        let est = frf_of(&cfg, 1);
        let bb = black_box_frf(&est, 11, 5e-4, false, 100).unwrap();
        let res = bb.model.resonances(1.0, 0.2).resonances;
        let modes: Vec<f64> = res.iter().map(|m| m.freq_hz).collect();
        for truth in [17.006, 22.995] {
            assert!(
                modes.iter().any(|f| (f - truth).abs() < 0.005 * truth),
                "modes {modes:?}"
            );
        }
        assert!(bb.cost < bb.subspace_cost, "refinement did not help");
        assert!(bb.cost_ratio() < 3.0, "cost ratio {}", bb.cost_ratio());
        let val = frf_of(&cfg, 2);
        let fit = periodic_fit_percent(&val, &bb.model.freq_response(&val.freq_hz));
        assert!(fit > 95.0, "validation FIT {fit}");
    }

    #[test]
    fn a_mode_no_reliable_line_holds_is_reported() {
        // 15,000 samples, two periods after the first (the ident bench's
        // short record): the slow disturbance leaves the lines
        // below 3.6 Hz unreliable, and the four states the three-mass joint
        // does not need place a light mode there (0.80 Hz for this seed)
        let cfg = SimConfig::default();
        let unsupported = |bb: &FrfBlackBox| -> Vec<f64> {
            bb.warnings
                .iter()
                .filter_map(|w| match w {
                    FitWarning::UnsupportedMode { freq_hz, .. } => Some(*freq_hz),
                    _ => None,
                })
                .collect()
        };
        let exc = ExcitationConfig {
            periods: 3,
            ramp_samples: 0,
            ..ExcitationConfig::paper_default()
        };
        let short = black_box_frf(&frf_of_exc(&cfg, 1, exc), 11, 5e-4, false, 40).unwrap();
        let warned = unsupported(&short);
        assert!(!warned.is_empty(), "{:?}", short.warnings);
        // what is reported is none of the joint's modes (17.0 and 23.0 Hz)
        assert!(warned.iter().all(|f| *f < 3.0), "{warned:?}");
        // with the paper's record no mode is left outside the lines
        let long = black_box_frf(&frf_of(&cfg, 1), 11, 5e-4, false, 40).unwrap();
        assert!(unsupported(&long).is_empty(), "{:?}", long.warnings);
    }

    /// Issue 39 item 4 on the periodic path: on that short record the free model spends its
    /// surplus states below the lowest reliable line and validates 2.4 points below the true
    /// model (96.14 against 98.54 % in the ident bench); with the rigid-body integrator exact
    /// no mode is left there and it validates within a point of the three-mass model fitted
    /// to the same lines, at the noise level.
    #[test]
    fn the_integrator_structure_validates_where_the_free_model_does_not() {
        use crate::ident::sml::{fit_frf, FrfFitOptions};
        use crate::model::spec::Structure;
        let cfg = SimConfig::default();
        let exc = ExcitationConfig {
            periods: 3,
            ramp_samples: 0,
            ..ExcitationConfig::paper_default()
        };
        let est = frf_of_exc(&cfg, 1, exc);
        let val = frf_of_exc(&cfg, 2, exc);
        let free = black_box_frf(&est, 11, 5e-4, false, 40).unwrap();
        let bi = black_box_frf_integrating(&est, 11, 5e-4, 40).unwrap();
        let three = fit_frf(&est, &FrfFitOptions::new(Structure::ThreeMass, 5e-4)).unwrap();
        let fit = |g: Vec<Complex64>| periodic_fit_percent(&val, &g);
        let (f_free, f_bi) = (
            fit(free.model.freq_response(&val.freq_hz)),
            fit(bi.model.freq_response(&val.freq_hz)),
        );
        let f_three = fit(three.freq_response(&val.freq_hz));
        assert!(
            f_bi > f_three - 1.0,
            "integrator {f_bi:.2} % vs three-mass {f_three:.2} %"
        );
        assert!(
            f_free < f_three - 1.0,
            "free {f_free:.2} % vs three-mass {f_three:.2} %"
        );
        assert!(bi.cost_ratio() <= COST_RATIO_WARN, "{}", bi.cost_ratio());
        assert!(
            !bi.warnings
                .iter()
                .any(|w| matches!(w, FitWarning::UnsupportedMode { .. })),
            "{:?}",
            bi.warnings
        );
        // the integrator is exact
        let poles_at_one = bi
            .model
            .a
            .clone()
            .complex_eigenvalues()
            .iter()
            .filter(|p| (*p - Complex64::new(1.0, 0.0)).norm() < 1e-12)
            .count();
        assert_eq!(poles_at_one, 1);
    }

    #[test]
    fn exact_black_box_derivatives_match_central_differences_of_the_response() {
        // the subspace start of order 4 on the default joint, with and without the
        // feed-through, and behind the integrator: every column of the exact derivative
        // against central differences of the response
        let frf = frf_of(&SimConfig::default(), 1);
        let ts = 5e-4;
        let mobius = Mobius::new(&frf.freq_hz, ts);
        let sub = subspace(&frf, 4, ts, &mobius).unwrap();
        let th = BlackBoxFrf::pack(&sub.a, &sub.b, &sub.c, sub.d);
        let z = unit_circle(&frf.freq_hz, ts);
        for feedthrough in [true, false] {
            let bb = BlackBoxFrf {
                n: 4,
                mobius: Mobius::new(&frf.freq_hz, ts),
                feedthrough,
            };
            let integrating = Integrating { inner: &bb };
            let models: [&dyn FrfModel; 2] = [&bb, &integrating];
            for (k, model) in models.into_iter().enumerate() {
                let free: Vec<usize> = (0..model.n_params()).collect();
                let (g, cols) = model.response_jacobian(&th, &z, &free).unwrap();
                for (a, b) in g.iter().zip(model.response(&th, &z).unwrap()) {
                    assert!((a - b).norm() <= 1e-12 * b.norm(), "{a} against {b}");
                }
                for (&i, col) in free.iter().zip(&cols) {
                    let h = 1e-5 * th[i].abs().max(1e-2);
                    let at = |s: f64| {
                        let mut t = th.clone();
                        t[i] += s;
                        model.response(&t, &z).unwrap()
                    };
                    let (gp, gm) = (at(h), at(-h));
                    let scale = col.iter().map(|v| v.norm()).fold(1e-12, f64::max);
                    for (l, d) in col.iter().enumerate() {
                        let fd = (gp[l] - gm[l]) / (2.0 * h);
                        assert!(
                            (d - fd).norm() <= 1e-5 * scale,
                            "feed-through {feedthrough}, model {k}, parameter {i}, line {l}: \
                             {d} against {fd}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn bad_orders_are_refused() {
        let est = frf_of(&SimConfig::default(), 1);
        assert_eq!(
            black_box_frf(&est, 0, 5e-4, false, 10),
            Err(FrfSubspaceError::ZeroOrder)
        );
        assert!(matches!(
            black_box_frf(&est, 80, 5e-4, false, 10),
            Err(FrfSubspaceError::TooFewLines { .. })
        ));
    }
}
