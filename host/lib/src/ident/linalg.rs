//! Small numerical helpers shared by the estimators.
//!
//! What: the Gram (covariance) matrix of a sliding data window built in
//! `O(N · lags)` with the shift recurrence of Hankel products, regularised
//! symmetric solves, a zero-phase Butterworth low-pass, and a deterministic
//! Gaussian generator for tests and benches.
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

/// Second-order sections of a digital Butterworth low-pass of even `order`
/// with cut-off `fc_hz` at sample interval `ts` (bilinear transform with
/// pre-warping). Each section is `[b0, b1, b2, a1, a2]` (a0 = 1).
pub fn butter_lowpass_sos(order: usize, fc_hz: f64, ts: f64) -> Vec<[f64; 5]> {
    let order = order.max(2) & !1;
    let k = (std::f64::consts::PI * fc_hz * ts).tan();
    (0..order / 2)
        .map(|i| {
            let theta = std::f64::consts::PI * (2 * i + 1) as f64 / (2 * order) as f64;
            let q2 = 2.0 * theta.sin(); // s² + q2 s + 1 per analog section
            let a0 = 1.0 + q2 * k + k * k;
            let b0 = k * k / a0;
            [
                b0,
                2.0 * b0,
                b0,
                2.0 * (k * k - 1.0) / a0,
                (1.0 - q2 * k + k * k) / a0,
            ]
        })
        .collect()
}

/// Second-order sections of a digital Butterworth high-pass of even `order` with cut-off
/// `fc_hz` at sample interval `ts`: the low-pass prototype with `s → 1/s`, bilinear
/// transform with pre-warping; sections `[b0, b1, b2, a1, a2]` (a0 = 1).
pub fn butter_highpass_sos(order: usize, fc_hz: f64, ts: f64) -> Vec<[f64; 5]> {
    let order = order.max(2) & !1;
    let k = (std::f64::consts::PI * fc_hz * ts).tan();
    (0..order / 2)
        .map(|i| {
            let theta = std::f64::consts::PI * (2 * i + 1) as f64 / (2 * order) as f64;
            let q2 = 2.0 * theta.sin();
            let a0 = 1.0 + q2 * k + k * k;
            let b0 = 1.0 / a0;
            [
                b0,
                -2.0 * b0,
                b0,
                2.0 * (k * k - 1.0) / a0,
                (1.0 - q2 * k + k * k) / a0,
            ]
        })
        .collect()
}

/// A bank of identical causal filters (second-order sections, transposed direct form II),
/// one per channel, fed one sample of every channel at a time. Each channel starts in the
/// steady state of its first sample held constant.
#[derive(Clone, Debug)]
pub struct SosBank {
    sos: Vec<[f64; 5]>,
    /// `[z1, z2]` per section and channel
    state: Vec<[f64; 2]>,
    channels: usize,
    started: bool,
}

impl SosBank {
    /// `channels` filters of the sections `sos`.
    pub fn new(sos: Vec<[f64; 5]>, channels: usize) -> SosBank {
        let state = vec![[0.0; 2]; sos.len() * channels];
        SosBank {
            sos,
            state,
            channels,
            started: false,
        }
    }

    /// Filters one sample of every channel in place.
    pub fn push(&mut self, x: &mut [f64]) {
        debug_assert_eq!(x.len(), self.channels);
        for (si, s) in self.sos.iter().enumerate() {
            let gain = (s[0] + s[1] + s[2]) / (1.0 + s[3] + s[4]);
            for (c, v) in x.iter_mut().enumerate() {
                let z = &mut self.state[si * self.channels + c];
                if !self.started {
                    // steady state for the input held at v: output gain·v
                    let y = gain * *v;
                    z[1] = s[2] * *v - s[4] * y;
                    z[0] = y - s[0] * *v;
                }
                let xin = *v;
                let y = s[0] * xin + z[0];
                z[0] = s[1] * xin - s[3] * y + z[1];
                z[1] = s[2] * xin - s[4] * y;
                *v = y;
            }
        }
        self.started = true;
    }
}

fn sos_filter(sos: &[[f64; 5]], x: &mut [f64]) {
    for s in sos {
        let (mut z1, mut z2) = (0.0, 0.0);
        // transposed direct form II started in steady state for the first
        // sample (the DC gain of a low-pass section is 1)
        if let Some(&x0) = x.first() {
            z1 = x0 * (1.0 - s[0]);
            z2 = x0 * (s[2] - s[4]);
        }
        for v in x.iter_mut() {
            let xin = *v;
            let y = s[0] * xin + z1;
            z1 = s[1] * xin - s[3] * y + z2;
            z2 = s[2] * xin - s[4] * y;
            *v = y;
        }
    }
}

/// Zero-phase (forward-backward) Butterworth low-pass of even `order`: the
/// magnitude is squared, the phase is zero. Edges are padded by odd
/// reflection of `pad` samples to limit start-up transients.
pub fn filtfilt_lowpass(x: &[f64], order: usize, fc_hz: f64, ts: f64) -> Vec<f64> {
    let n = x.len();
    if n < 4 {
        return x.to_vec();
    }
    let sos = butter_lowpass_sos(order, fc_hz, ts);
    let pad = (3.0 / (fc_hz * ts)).ceil() as usize;
    let pad = pad.min(n - 1);
    let mut ext = Vec::with_capacity(n + 2 * pad);
    for i in (1..=pad).rev() {
        ext.push(2.0 * x[0] - x[i]);
    }
    ext.extend_from_slice(x);
    for i in 1..=pad {
        ext.push(2.0 * x[n - 1] - x[n - 1 - i]);
    }
    sos_filter(&sos, &mut ext);
    ext.reverse();
    sos_filter(&sos, &mut ext);
    ext.reverse();
    ext[pad..pad + n].to_vec()
}

/// Central difference `(x(t+1) − x(t−1)) / 2Ts`, one-sided at the ends.
pub fn central_diff(x: &[f64], ts: f64) -> Vec<f64> {
    let n = x.len();
    (0..n)
        .map(|t| match (t, n) {
            (_, 0 | 1) => 0.0,
            (0, _) => (x[1] - x[0]) / ts,
            (t, n) if t == n - 1 => (x[t] - x[t - 1]) / ts,
            (t, _) => (x[t + 1] - x[t - 1]) / (2.0 * ts),
        })
        .collect()
}

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
    fn highpass_bank_removes_a_constant_and_passes_a_fast_sine() {
        let ts = 5e-4;
        let mut bank = SosBank::new(butter_highpass_sos(2, 1.0, ts), 2);
        let mut peak: f64 = 0.0;
        for k in 0..20_000 {
            let t = k as f64 * ts;
            let mut x = [3.0, (2.0 * std::f64::consts::PI * 50.0 * t).sin()];
            bank.push(&mut x);
            assert!(x[0].abs() < 1e-9, "constant leaks: {}", x[0]);
            if k > 10_000 {
                peak = peak.max(x[1].abs());
            }
        }
        assert!((peak - 1.0).abs() < 1e-3, "gain at 50 Hz {peak}");
    }
    use super::*;

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
    fn filtfilt_passes_dc_and_removes_high_frequency() {
        let ts = 1e-3;
        let x: Vec<f64> = (0..4000)
            .map(|t| 1.0 + (2.0 * std::f64::consts::PI * 200.0 * t as f64 * ts).sin())
            .collect();
        let y = filtfilt_lowpass(&x, 4, 20.0, ts);
        for v in &y[200..3800] {
            assert!((v - 1.0).abs() < 1e-3, "{v}");
        }
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
