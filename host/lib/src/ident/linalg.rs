//! Small numerical helpers shared by the estimators.
//!
//! What: the Gram (covariance) matrix of a sliding data window built in
//! `O(N · lags)` with the shift recurrence of Hankel products, regularised
//! symmetric solves and a deterministic Gaussian generator for tests and benches
//! (filters on records are in [`crate::data::dsp`]).
//!
//! Why: subspace identification needs `H Hᵀ` of block Hankel matrices `H`
//! with `N` columns. Forming `H` costs memory `O(N · rows)`; `H Hᵀ` entries
//! `Σ_t x(t+a) y(t+b)` differ along a diagonal only by two boundary terms,
//! `S(a+1, b+1) = S(a, b) − x(a) y(b) + x(a+N) y(b+N)`, so only the first row
//! and column need sums over the data (Van Overschee & De Moor, "Subspace
//! Identification for Linear Systems", Kluwer 1996, exploit the same
//! structure for fast covariance computation).

use nalgebra::{DMatrix, DVector};

/// Gram matrix `Σ_{s=0}^{cols−1} w(s) w(s)ᵀ` of the window
/// `w(s) = [x_0(s .. s+len), x_1(s .. s+len), …]` (signal-major order: the
/// `len` lags of signal 0, then of signal 1, …), with
/// `cols = N − len + 1`. Cost `O(N · len · signals²)`.
///
/// # Panics
/// When the signals differ in length or are shorter than `len`.
pub fn window_gram(signals: &[&[f64]], len: usize) -> DMatrix<f64> {
    let ns = signals.len();
    let n = signals[0].len();
    assert!(
        signals.iter().all(|s| s.len() == n),
        "signals differ in length"
    );
    assert!(n >= len && len > 0, "window longer than data");
    let cols = n - len + 1;
    let dim = ns * len;
    let mut g = DMatrix::zeros(dim, dim);
    for (p, x) in signals.iter().enumerate() {
        for (q, y) in signals.iter().enumerate().skip(p) {
            // S(a, b) = Σ_{s<cols} x(s+a) y(s+b); first row a=0 and column b=0
            let mut s = DMatrix::zeros(len, len);
            for b in 0..len {
                s[(0, b)] = dot(&x[..cols], &y[b..b + cols]);
            }
            for a in 1..len {
                s[(a, 0)] = dot(&x[a..a + cols], &y[..cols]);
            }
            for a in 1..len {
                for b in 1..len {
                    s[(a, b)] =
                        s[(a - 1, b - 1)] - x[a - 1] * y[b - 1] + x[a - 1 + cols] * y[b - 1 + cols];
                }
            }
            g.view_mut((p * len, q * len), (len, len)).copy_from(&s);
            if q != p {
                g.view_mut((q * len, p * len), (len, len))
                    .copy_from(&s.transpose());
            }
        }
    }
    g
}

/// dot product of two equal-length slices, four accumulators
pub fn dot(x: &[f64], y: &[f64]) -> f64 {
    let mut acc = [0.0; 4];
    let chunks = x.len() / 4;
    for i in 0..chunks {
        let k = 4 * i;
        acc[0] += x[k] * y[k];
        acc[1] += x[k + 1] * y[k + 1];
        acc[2] += x[k + 2] * y[k + 2];
        acc[3] += x[k + 3] * y[k + 3];
    }
    let mut s = acc[0] + acc[1] + acc[2] + acc[3];
    for k in 4 * chunks..x.len() {
        s += x[k] * y[k];
    }
    s
}

/// Solve the symmetric positive semi-definite system `M x = r` with a
/// relative ridge `ridge · trace(M)/n` added when Cholesky fails or
/// `ridge > 0`. Returns `None` only when even the ridged matrix fails.
pub fn solve_spd(m: &DMatrix<f64>, r: &DMatrix<f64>, ridge: f64) -> Option<DMatrix<f64>> {
    let n = m.nrows();
    let tr = m.trace().abs() / n.max(1) as f64;
    let mut reg = ridge;
    for _ in 0..6 {
        let mut mm = m.clone();
        if reg > 0.0 {
            for i in 0..n {
                mm[(i, i)] += reg * tr.max(1e-300);
            }
        }
        if let Some(ch) = mm.cholesky() {
            return Some(ch.solve(r));
        }
        reg = if reg == 0.0 { 1e-12 } else { reg * 100.0 };
    }
    None
}

/// Inverse of a symmetric positive semi-definite matrix through its SVD,
/// dropping singular values below `rel_tol · σ_max` (pseudo-inverse). A matrix with a
/// non-finite entry gives NaN everywhere (nalgebra's unbounded SVD never ends on one), and
/// an SVD that has not converged in [`SVD_MAX_ITER`] sweeps gives zeros.
pub fn pinv_sym(m: &DMatrix<f64>, rel_tol: f64) -> DMatrix<f64> {
    if m.iter().any(|v| !v.is_finite()) {
        return DMatrix::from_element(m.ncols(), m.nrows(), f64::NAN);
    }
    let Some(svd) = m.clone().try_svd(true, true, f64::EPSILON, SVD_MAX_ITER) else {
        return DMatrix::zeros(m.ncols(), m.nrows());
    };
    let smax = svd.singular_values.max();
    svd.pseudo_inverse(rel_tol * smax.max(1e-300))
        .unwrap_or_else(|_| DMatrix::zeros(m.ncols(), m.nrows()))
}

/// Most iterations [`pinv_sym`]'s SVD takes.
pub const SVD_MAX_ITER: usize = 10_000;

/// Deterministic generator (SplitMix64 + Box–Muller) for reproducible test
/// and benchmark signals; not for cryptography.
#[derive(Clone, Debug)]
pub struct GaussRng {
    state: u64,
    spare: Option<f64>,
}

impl GaussRng {
    /// generator from a seed
    pub fn new(seed: u64) -> Self {
        Self {
            state: seed,
            spare: None,
        }
    }

    /// next uniform value in (0, 1)
    pub fn uniform(&mut self) -> f64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        ((z >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    /// next standard normal value
    pub fn normal(&mut self) -> f64 {
        if let Some(v) = self.spare.take() {
            return v;
        }
        let r = (-2.0 * self.uniform().ln()).sqrt();
        let th = 2.0 * std::f64::consts::PI * self.uniform();
        self.spare = Some(r * th.sin());
        r * th.cos()
    }

    /// vector of `n` standard normal values scaled by `sigma`
    pub fn normals(&mut self, n: usize, sigma: f64) -> Vec<f64> {
        (0..n).map(|_| sigma * self.normal()).collect()
    }
}

/// Euclidean norm of a slice
pub fn norm(x: &[f64]) -> f64 {
    dot(x, x).sqrt()
}

/// `DVector` from a slice
pub fn dvec(x: &[f64]) -> DVector<f64> {
    DVector::from_column_slice(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pinv_of_a_matrix_with_nan_ends_and_says_nan() {
        let mut m = DMatrix::<f64>::identity(3, 3);
        m[(1, 2)] = f64::NAN;
        m[(2, 1)] = f64::NAN;
        assert!(pinv_sym(&m, 1e-14).iter().all(|v| v.is_nan()));
        let inv = pinv_sym(&(DMatrix::<f64>::identity(3, 3) * 2.0), 1e-14);
        assert!((inv[(0, 0)] - 0.5).abs() < 1e-15);
    }

    #[test]
    fn window_gram_matches_explicit_hankel_product() {
        let mut rng = GaussRng::new(7);
        let x = rng.normals(40, 1.0);
        let y = rng.normals(40, 2.0);
        let len = 5;
        let g = window_gram(&[&x, &y], len);
        let cols = 40 - len + 1;
        let mut h = DMatrix::zeros(2 * len, cols);
        for s in 0..cols {
            for a in 0..len {
                h[(a, s)] = x[s + a];
                h[(len + a, s)] = y[s + a];
            }
        }
        let e = &h * h.transpose();
        assert!((g - &e).norm() < 1e-10 * e.norm());
    }

    #[test]
    fn gauss_rng_has_unit_variance() {
        let mut rng = GaussRng::new(1);
        let v = rng.normals(20_000, 1.0);
        let m = v.iter().sum::<f64>() / v.len() as f64;
        let var = v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / v.len() as f64;
        assert!(m.abs() < 0.03 && (var - 1.0).abs() < 0.03, "{m} {var}");
    }
}
