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
    /// `e^{FT}`, `Γ((1−φ)T)`, `e^{F(1−φ)T}Γ(φT)`, `H`
    a: DMatrix<f64>,
    b_new: DVector<f64>,
    b_old: DVector<f64>,
    c: DVector<f64>,
    d: f64,
    /// whole samples of delay
    n: usize,
    ts: f64,
    /// Hessenberg form `Qᵀ A Q` and the vectors in its basis
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

impl Sampled {
    pub(super) fn new(c: &ContinuousSs, ts: f64, delay_samples: f64) -> Sampled {
        let d = delay_samples.max(0.0);
        let n = d.floor() as usize;
        let phi = d - n as f64;
        let (e1, g1) = hold_pair(&c.f, &c.g, (1.0 - phi) * ts);
        let (e2, g2) = hold_pair(&c.f, &c.g, phi * ts);
        let a = &e1 * &e2;
        let b_old = &e1 * g2;
        let hess = a.clone().hessenberg();
        let (q, h) = hess.unpack();
        let qt = q.transpose();
        let cv: DVector<f64> = c.h.transpose();
        Sampled {
            hb_new: &qt * &g1,
            hb_old: &qt * &b_old,
            hc: &qt * &cv,
            h,
            a,
            b_new: g1,
            b_old,
            c: cv,
            d: c.d,
            n,
            ts,
        }
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
                            .fold(Complex64::new(self.d, 0.0), |g, (x, c)| g + x * c);
                        g * zi.powi(self.n as i32)
                    }
                    false => Complex64::new(f64::NAN, f64::NAN),
                }
            })
            .collect()
    }

    /// state space with the delay as input-history states
    pub(super) fn state_space(&self) -> StateSpace {
        let nx = self.a.nrows();
        let has_old = self.b_old.iter().any(|v| *v != 0.0);
        let hist = if self.n == 0 && !has_old {
            0
        } else {
            self.n + 1
        };
        let nt = nx + hist;
        let mut a = DMatrix::zeros(nt, nt);
        a.view_mut((0, 0), (nx, nx)).copy_from(&self.a);
        let mut b = DVector::zeros(nt);
        // history s_i(k) = u(k − i), i = 1 … hist
        if hist > 0 {
            b[nx] = 1.0;
            for i in 1..hist {
                a[(nx + i, nx + i - 1)] = 1.0;
            }
        }
        // v(k) = u(k − n), v(k − 1) = u(k − n − 1)
        if self.n == 0 {
            for r in 0..nx {
                b[r] += self.b_new[r];
            }
        } else {
            for r in 0..nx {
                a[(r, nx + self.n - 1)] += self.b_new[r];
            }
        }
        if hist > 0 {
            for r in 0..nx {
                a[(r, nx + self.n)] += self.b_old[r];
            }
        }
        let mut c = nalgebra::RowDVector::zeros(nt);
        for i in 0..nx {
            c[i] = self.c[i];
        }
        StateSpace::new(a, b, c, self.d, self.ts)
    }
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
