//! The continuous model sampled exactly with a held, delayed input (module docs of
//! [`super`]: Van Loan's block exponential for the hold, the fractional delay inside the
//! sample), in Hessenberg form for cheap evaluation at many lines.

use super::*;
use crate::sim::integrate::expm;

pub(super) fn drive_model(model: &GreyBoxModel, lag_samples: f64) -> DrivenModel {
    DrivenModel {
        mechanics: *model,
        // below 1e-7 samples the lag is numerically absent; kept above that
        // so that a difference quotient from zero sees it
        current_loop_tau: if lag_samples > 1e-7 {
            lag_samples * model.ts
        } else {
            0.0
        },
    }
}

pub(crate) fn unit_circle(f_hz: &[f64], ts: f64) -> Vec<Complex64> {
    f_hz.iter()
        .map(|f| Complex64::from_polar(1.0, 2.0 * std::f64::consts::PI * f * ts))
        .collect()
}

/// The continuous model sampled with a held, delayed input, in Hessenberg
/// form for cheap evaluation at many frequencies.
pub(super) struct Sampled {
    /// the matrices in the state basis
    m: Discrete,
    ts: f64,
    /// Hessenberg form `Qᵀ A Q` and the vectors in its basis
    qt: DMatrix<f64>,
    h: DMatrix<f64>,
    hb_new: DVector<f64>,
    hb_old: DVector<f64>,
    hc: DVector<f64>,
}

/// `(e^{F h}, Γ(h))` by Van Loan's block exponential
fn hold_pair(f: &DMatrix<f64>, g: &DVector<f64>, h: f64) -> (DMatrix<f64>, DVector<f64>) {
    let n = f.nrows();
    if h <= 0.0 {
        return (DMatrix::identity(n, n), DVector::zeros(n));
    }
    let mut m = DMatrix::zeros(n + 1, n + 1);
    m.view_mut((0, 0), (n, n)).copy_from(&(f * h));
    m.view_mut((0, n), (n, 1)).copy_from(&(g * h));
    let e = expm(m);
    (
        e.view((0, 0), (n, n)).into_owned(),
        e.view((0, n), (n, 1)).column(0).into_owned(),
    )
}

/// The sampled model's matrices in the state basis, before the Hessenberg reduction:
/// `e^{FT}`, `Γ((1−φ)T)`, `e^{F(1−φ)T}Γ(φT)`, `H`, `D`.
pub(super) struct Discrete {
    a: DMatrix<f64>,
    b_new: DVector<f64>,
    b_old: DVector<f64>,
    c: DVector<f64>,
    d: f64,
    /// whole samples of delay
    n: usize,
}

impl Discrete {
    /// `c` sampled at `ts` [s] with a held input delayed by `delay_samples`
    pub(super) fn new(c: &ContinuousSs, ts: f64, delay_samples: f64) -> Discrete {
        let d = delay_samples.max(0.0);
        let n = d.floor() as usize;
        let phi = d - n as f64;
        let (e1, g1) = hold_pair(&c.f, &c.g, (1.0 - phi) * ts);
        let (e2, g2) = hold_pair(&c.f, &c.g, phi * ts);
        Discrete {
            a: &e1 * &e2,
            b_old: &e1 * g2,
            b_new: g1,
            c: c.h.transpose(),
            d: c.d,
            n,
        }
    }
}

impl Discrete {
    /// The continuous model itself in the same form (`F`, `G`, `H`, `D`, no delay), for
    /// evaluation at `s = jω` instead of `z` ([`super::HeldFrf`]).
    pub(super) fn continuous(c: &ContinuousSs) -> Discrete {
        Discrete {
            a: c.f.clone(),
            b_old: DVector::zeros(c.g.len()),
            b_new: c.g.clone(),
            c: c.h.transpose(),
            d: c.d,
            n: 0,
        }
    }
}

/// A direction of change of the sampled model, `(M(θ + h e_i) − M(θ))/h`, in the
/// Hessenberg basis of `M(θ)` ([`Sampled::tangent`]).
pub(super) struct Tangent {
    h: DMatrix<f64>,
    b_new: DVector<f64>,
    b_old: DVector<f64>,
    c: DVector<f64>,
    d: f64,
}

impl Sampled {
    pub(super) fn new(c: &ContinuousSs, ts: f64, delay_samples: f64) -> Sampled {
        Sampled::from_discrete(Discrete::new(c, ts, delay_samples), ts)
    }

    pub(super) fn from_discrete(m: Discrete, ts: f64) -> Sampled {
        let hess = m.a.clone().hessenberg();
        let (q, h) = hess.unpack();
        let qt = q.transpose();
        Sampled {
            hb_new: &qt * &m.b_new,
            hb_old: &qt * &m.b_old,
            hc: &qt * &m.c,
            qt,
            h,
            m,
            ts,
        }
    }

    /// The forward difference `(other − self)/step` in this model's Hessenberg basis;
    /// None when `other` has another whole delay or another number of states (a lag
    /// stepped from nought): its matrices then describe another input history or state,
    /// and only the responses compare.
    pub(super) fn tangent(&self, other: &Discrete, step: f64) -> Option<Tangent> {
        let m = &self.m;
        if other.n != m.n || other.a.nrows() != m.a.nrows() {
            return None;
        }
        let q = self.qt.transpose();
        let inv = 1.0 / step;
        Some(Tangent {
            h: &self.qt * (&other.a - &m.a) * q * inv,
            b_new: &self.qt * (&other.b_new - &m.b_new) * inv,
            b_old: &self.qt * (&other.b_old - &m.b_old) * inv,
            c: &self.qt * (&other.c - &m.c) * inv,
            d: (other.d - m.d) * inv,
        })
    }

    /// `G(z)` at each `z` and its change along each of `tangents`,
    /// `dG = z^{−n}(dd + dcᵀx + vᵀ(dA x + db_new + z^{−1} db_old))` with
    /// `x = (zI − A)^{−1}(b_new + z^{−1} b_old)` and `vᵀ = cᵀ(zI − A)^{−1}`: two Hessenberg
    /// solves per line for any number of directions. None where `zI − A` is singular.
    pub(super) fn response_and_tangents(
        &self,
        z: &[Complex64],
        tangents: &[&Tangent],
    ) -> Option<Jacobian> {
        let nx = self.h.nrows();
        let zero = Complex64::new(0.0, 0.0);
        let mut m = vec![zero; nx * nx];
        let mut x = vec![zero; nx];
        let mut v = vec![zero; nx];
        let mut t = vec![zero; nx];
        let mut g = Vec::with_capacity(z.len());
        let mut dg = vec![Vec::with_capacity(z.len()); tangents.len()];
        for &zk in z {
            let zi = zk.inv();
            for i in 0..nx {
                x[i] = self.hb_new[i] + zi * self.hb_old[i];
                v[i] = Complex64::new(self.hc[i], 0.0);
            }
            if !solve_pair(&self.h, zk, &mut m, &mut x, &mut v) {
                return None;
            }
            let shift = zi.powi(self.m.n as i32);
            let cx = x
                .iter()
                .zip(self.hc.iter())
                .fold(Complex64::new(self.m.d, 0.0), |s, (x, c)| s + x * c);
            g.push(cx * shift);
            for (tg, out) in tangents.iter().zip(dg.iter_mut()) {
                for (i, ti) in t.iter_mut().enumerate() {
                    let mut s = tg.b_new[i] + zi * tg.b_old[i];
                    for (j, xj) in x.iter().enumerate() {
                        s += xj * tg.h[(i, j)];
                    }
                    *ti = s;
                }
                let mut d = Complex64::new(tg.d, 0.0);
                for i in 0..nx {
                    d += v[i] * t[i] + x[i] * tg.c[i];
                }
                out.push(d * shift);
            }
        }
        Some((g, dg))
    }

    /// `G(z)` at each `z` on the unit circle; NaN where `zI − A` is singular
    pub(super) fn response(&self, z: &[Complex64]) -> Vec<Complex64> {
        let nx = self.h.nrows();
        let mut m = vec![Complex64::new(0.0, 0.0); nx * nx];
        let mut rhs = vec![Complex64::new(0.0, 0.0); nx];
        z.iter()
            .map(|&zk| {
                let zi = zk.inv();
                for i in 0..nx {
                    for j in 0..nx {
                        let v = -self.h[(i, j)];
                        m[i * nx + j] = Complex64::new(v, 0.0);
                    }
                    m[i * nx + i] += zk;
                    rhs[i] = self.hb_new[i] + zi * self.hb_old[i];
                }
                match solve_hessenberg(&mut m, &mut rhs, nx) {
                    true => {
                        let g = rhs
                            .iter()
                            .zip(self.hc.iter())
                            .fold(Complex64::new(self.m.d, 0.0), |g, (x, c)| g + x * c);
                        g * zi.powi(self.m.n as i32)
                    }
                    false => Complex64::new(f64::NAN, f64::NAN),
                }
            })
            .collect()
    }

    /// state space with the delay as input-history states
    pub(super) fn state_space(&self) -> StateSpace {
        let m = &self.m;
        let nx = m.a.nrows();
        let has_old = m.b_old.iter().any(|v| *v != 0.0);
        let hist = if m.n == 0 && !has_old { 0 } else { m.n + 1 };
        let nt = nx + hist;
        let mut a = DMatrix::zeros(nt, nt);
        a.view_mut((0, 0), (nx, nx)).copy_from(&m.a);
        let mut b = DVector::zeros(nt);
        // history s_i(k) = u(k − i), i = 1 … hist
        if hist > 0 {
            b[nx] = 1.0;
            for i in 1..hist {
                a[(nx + i, nx + i - 1)] = 1.0;
            }
        }
        // v(k) = u(k − n), v(k − 1) = u(k − n − 1)
        if m.n == 0 {
            for r in 0..nx {
                b[r] += m.b_new[r];
            }
        } else {
            for r in 0..nx {
                a[(r, nx + m.n - 1)] += m.b_new[r];
            }
        }
        if hist > 0 {
            for r in 0..nx {
                a[(r, nx + m.n)] += m.b_old[r];
            }
        }
        let mut c = nalgebra::RowDVector::zeros(nt);
        for i in 0..nx {
            c[i] = m.c[i];
        }
        StateSpace::new(a, b, c, m.d, self.ts)
    }
}

/// `x ← (zI − H)^{−1} x` and `v ← (zI − H)^{−T} v` for an upper Hessenberg `H`, with
/// `m` (`n²`) as workspace: the two solves a response's derivatives need (`x` the state's
/// response to the input, `vᵀ = cᵀ(zI − H)^{−1}` the output's to the state). The
/// transposed system is lower Hessenberg; reversed in rows and columns it is upper
/// Hessenberg again. False when singular.
pub(crate) fn solve_pair(
    h: &DMatrix<f64>,
    z: Complex64,
    m: &mut [Complex64],
    x: &mut [Complex64],
    v: &mut [Complex64],
) -> bool {
    let n = h.nrows();
    for i in 0..n {
        for j in 0..n {
            m[i * n + j] = Complex64::new(-h[(i, j)], 0.0);
        }
        m[i * n + i] += z;
    }
    if !solve_hessenberg(m, x, n) {
        return false;
    }
    for i in 0..n {
        for j in 0..n {
            m[i * n + j] = Complex64::new(-h[(n - 1 - j, n - 1 - i)], 0.0);
        }
        m[i * n + i] += z;
    }
    v.reverse();
    let ok = solve_hessenberg(m, v, n);
    v.reverse();
    ok
}

/// Solves an upper Hessenberg system in place (row-major `m`, `n × n`) by
/// Gaussian elimination with pivoting between neighbouring rows; the
/// solution replaces `rhs`. False when singular.
pub(crate) fn solve_hessenberg(m: &mut [Complex64], rhs: &mut [Complex64], n: usize) -> bool {
    for j in 0..n.saturating_sub(1) {
        let (p, q) = (j * n, (j + 1) * n);
        if m[q + j].norm_sqr() > m[p + j].norm_sqr() {
            for c in j..n {
                m.swap(p + c, q + c);
            }
            rhs.swap(j, j + 1);
        }
        let piv = m[p + j];
        if piv.norm_sqr() == 0.0 {
            return false;
        }
        let l = m[q + j] / piv;
        if l.norm_sqr() != 0.0 {
            for c in j..n {
                let v = m[p + c];
                m[q + c] -= l * v;
            }
            let v = rhs[j];
            rhs[j + 1] -= l * v;
        }
    }
    for i in (0..n).rev() {
        let mut s = rhs[i];
        for c in i + 1..n {
            s -= m[i * n + c] * rhs[c];
        }
        let piv = m[i * n + i];
        if piv.norm_sqr() == 0.0 {
            return false;
        }
        rhs[i] = s / piv;
    }
    true
}
