//! Single-input single-output state-space models, discrete and continuous.
//!
//! What: the model type every estimator returns ([`StateSpace`], discrete
//! time, innovations form `x(t+1) = A x(t) + B u(t) + K e(t)`,
//! `y(t) = C x(t) + D u(t) + e(t)`, seed 000 eq. (9)) and the continuous-time
//! physical form `ẋ = F x + G u`, `y = H x + D u` ([`ContinuousSs`], seed 000
//! eq. (10)) with its zero-order-hold discretisation (seed 000 eq. (11)–(13)).
//!
//! Why: simulation (the output-error predictor of seed 000 eq. (15)),
//! frequency responses, poles, zeros and the resonance / anti-resonance
//! frequencies a control engineer reads from a joint model.
//!
//! Source: ZOH by the exponential of the augmented matrix
//! `exp([[F, G], [0, 0]] Ts) = [[A_T, B_T], [0, I]]` (Van Loan, "Computing
//! integrals involving the matrix exponential", IEEE TAC 23(3), 1978),
//! which gives eq. (12) and (13) of seed 000 in one call. Zeros of a SISO
//! model with relative degree `ρ` are the eigenvalues of
//! `A − B (C A^{ρ−1} B)^{−1} C A^ρ` other than the `ρ` eigenvalues that the
//! projection puts at the origin (the zero dynamics of the normal form,
//! Isidori, "Nonlinear Control Systems", 3rd ed., specialised to the
//! linear case).

use crate::sim::integrate::expm;
use nalgebra::{Complex, DMatrix, DVector, RowDVector, Schur};

/// Discrete-time SISO state-space model (seed 000 eq. (9)).
#[derive(Clone, Debug, PartialEq)]
pub struct StateSpace {
    /// state matrix `A` (n × n)
    pub a: DMatrix<f64>,
    /// input vector `B` (n), state units per input unit
    pub b: DVector<f64>,
    /// output row `C` (n), output units per state unit
    pub c: RowDVector<f64>,
    /// direct feed-through `D` [output unit / input unit]
    pub d: f64,
    /// innovations gain `K` (n), when the model carries a noise model
    pub k: Option<DVector<f64>>,
    /// sample interval [s]
    pub ts: f64,
}

/// Continuous-time SISO state-space model `ẋ = F x + G u`, `y = H x + D u`
/// (seed 000 eq. (10)).
#[derive(Clone, Debug, PartialEq)]
pub struct ContinuousSs {
    /// state matrix `F` (n × n) [1/s]
    pub f: DMatrix<f64>,
    /// input vector `G` (n)
    pub g: DVector<f64>,
    /// output row `H` (n)
    pub h: RowDVector<f64>,
    /// direct feed-through
    pub d: f64,
}

/// One complex pole or zero pair seen as a continuous-time mode.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mode {
    /// undamped natural frequency `|s| / 2π` [Hz]
    pub freq_hz: f64,
    /// relative damping `−Re(s) / |s|` [-]
    pub damping: f64,
    /// the root itself (z-plane for discrete models, s-plane for continuous)
    pub root: Complex<f64>,
}

/// Resonances (complex pole pairs) and anti-resonances (complex zero pairs)
/// of the u→y part of a model, sorted by frequency.
#[derive(Clone, Debug, PartialEq)]
pub struct Resonances {
    /// lightly damped complex pole pairs (one entry per pair)
    pub resonances: Vec<Mode>,
    /// lightly damped complex zero pairs (one entry per pair)
    pub anti_resonances: Vec<Mode>,
}

/// Largest number of QR sweeps the Schur decomposition may take.
const SCHUR_MAX_ITER: usize = 10_000;

/// Eigenvalues of a real square matrix (balanced first, Schur form).
///
/// Returns an empty vector for an empty matrix. If the Schur iteration fails
/// to converge the values are NaN, so callers see an unusable result rather
/// than a hang.
pub fn eigenvalues(m: &DMatrix<f64>) -> Vec<Complex<f64>> {
    let n = m.nrows();
    if n == 0 {
        return Vec::new();
    }
    // scaled by a power of two to entries of order one (exact; the eigenvalues scale
    // back): the balancing squares the entries and never ends once a norm overflows
    // (an entry of 1e308 hung `validate`)
    let largest = m.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    if !largest.is_finite() {
        return vec![Complex::new(f64::NAN, f64::NAN); n];
    }
    let scale = if largest > 0.0 {
        2f64.powi(largest.log2().round() as i32)
    } else {
        1.0
    };
    let mut bal = m / scale;
    nalgebra::linalg::balancing::balance_parlett_reinsch(&mut bal);
    match Schur::try_new(bal, f64::EPSILON, SCHUR_MAX_ITER) {
        Some(s) => s.complex_eigenvalues().iter().map(|&l| l * scale).collect(),
        None => vec![Complex::new(f64::NAN, f64::NAN); n],
    }
}

/// Transmission zeros of the SISO system `(A, B, C, D)`; works for discrete
/// and continuous matrices alike.
///
/// `D ≠ 0`: the eigenvalues of `A − B C / D`. `D = 0`: find the relative
/// degree `ρ` (first `k` with `C A^{k−1} B` not negligible) and return the
/// eigenvalues of `A − B (C A^{ρ−1} B)^{−1} C A^ρ` with the `ρ` roots nearest
/// the origin removed. A system whose Markov parameters all vanish has no
/// finite zeros.
pub fn siso_zeros(
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    c: &RowDVector<f64>,
    d: f64,
) -> Vec<Complex<f64>> {
    let n = a.nrows();
    if n == 0 {
        return Vec::new();
    }
    let scale = a.norm().max(1e-300);
    let bn = b.norm();
    let cn = c.norm();
    if d.abs() > 1e-12 * (bn * cn / scale).max(1e-300) && d != 0.0 {
        let m = a - b * c / d;
        return eigenvalues(&m);
    }
    // relative degree
    let mut cak = c.clone(); // C A^{k-1}
    for rho in 1..=n {
        let markov = (&cak * b)[0];
        let tol = 1e-10 * cak.norm() * bn;
        if markov.abs() > tol && markov != 0.0 {
            let ca_rho = &cak * a;
            let m = a - b * &ca_rho / markov;
            let mut ev = eigenvalues(&m);
            ev.sort_by(|x, y| x.norm().total_cmp(&y.norm()));
            return ev.split_off(rho.min(ev.len()));
        }
        cak = &cak * a;
    }
    Vec::new()
}

/// Complex roots with positive imaginary part as modes; `to_s` maps a root
/// to the s-plane.
fn complex_modes(
    roots: &[Complex<f64>],
    to_s: impl Fn(Complex<f64>) -> Complex<f64>,
    f_max_hz: f64,
) -> Vec<Mode> {
    let mut out: Vec<Mode> = roots
        .iter()
        .filter(|z| z.im > 1e-9 * z.norm().max(1e-300))
        .filter_map(|&z| {
            let s = to_s(z);
            let wn = s.norm();
            let f = wn / (2.0 * std::f64::consts::PI);
            if !(f.is_finite() && f > 0.0 && f < f_max_hz) {
                return None;
            }
            Some(Mode {
                freq_hz: f,
                damping: -s.re / wn,
                root: z,
            })
        })
        .collect();
    out.sort_by(|x, y| x.freq_hz.total_cmp(&y.freq_hz));
    out
}

impl StateSpace {
    /// Build a model without noise gain.
    ///
    /// # Panics
    /// When the dimensions of `a`, `b`, `c` disagree or `ts` is not positive.
    pub fn new(a: DMatrix<f64>, b: DVector<f64>, c: RowDVector<f64>, d: f64, ts: f64) -> Self {
        let n = a.nrows();
        assert!(
            a.ncols() == n && b.len() == n && c.len() == n,
            "state-space dimensions disagree"
        );
        assert!(ts > 0.0, "sample interval must be positive");
        Self {
            a,
            b,
            c,
            d,
            k: None,
            ts,
        }
    }

    /// model order `n`
    pub fn order(&self) -> usize {
        self.a.nrows()
    }

    /// Simulated output (seed 000 eq. (15) without the noise model) from the
    /// initial state `x0` (zero when `None`). One output sample per input
    /// sample; `y(t)` uses `x(t)` and `u(t)`.
    pub fn simulate(&self, u: &[f64], x0: Option<&DVector<f64>>) -> Vec<f64> {
        let n = self.order();
        let mut y = Vec::with_capacity(u.len());
        // row-major copy of A for a cache-friendly inner loop
        let ar: Vec<f64> = (0..n)
            .flat_map(|i| (0..n).map(move |j| (i, j)))
            .map(|(i, j)| self.a[(i, j)])
            .collect();
        let b = self.b.as_slice();
        let c = self.c.as_slice();
        let mut x = match x0 {
            Some(v) => v.as_slice().to_vec(),
            None => vec![0.0; n],
        };
        let mut xn = vec![0.0; n];
        for &ut in u {
            let mut yt = self.d * ut;
            for i in 0..n {
                yt += c[i] * x[i];
            }
            y.push(yt);
            for i in 0..n {
                let row = &ar[i * n..(i + 1) * n];
                let mut s = b[i] * ut;
                for j in 0..n {
                    s += row[j] * x[j];
                }
                xn[i] = s;
            }
            std::mem::swap(&mut x, &mut xn);
        }
        y
    }

    /// Frequency response `C (e^{jωTs} I − A)^{−1} B + D` at the given
    /// frequencies [Hz]; output units per input unit.
    pub fn freq_response(&self, f_hz: &[f64]) -> Vec<Complex<f64>> {
        let n = self.order();
        let ac: DMatrix<Complex<f64>> = self.a.map(|v| Complex::new(v, 0.0));
        let bc: DVector<Complex<f64>> = self.b.map(|v| Complex::new(v, 0.0));
        f_hz.iter()
            .map(|&f| {
                let w = 2.0 * std::f64::consts::PI * f * self.ts;
                let z = Complex::new(w.cos(), w.sin());
                let m = DMatrix::<Complex<f64>>::identity(n, n) * z - &ac;
                let x = m
                    .lu()
                    .solve(&bc)
                    .unwrap_or_else(|| DVector::from_element(n, Complex::new(f64::NAN, 0.0)));
                let mut g = Complex::new(self.d, 0.0);
                for i in 0..n {
                    g += x[i] * self.c[i];
                }
                g
            })
            .collect()
    }

    /// poles (eigenvalues of `A`), z-plane
    pub fn poles(&self) -> Vec<Complex<f64>> {
        eigenvalues(&self.a)
    }

    /// zeros of u→y, z-plane (see [`siso_zeros`])
    pub fn zeros(&self) -> Vec<Complex<f64>> {
        siso_zeros(&self.a, &self.b, &self.c, self.d)
    }

    /// spectral radius `max |λ(A)|`
    pub fn spectral_radius(&self) -> f64 {
        self.poles().iter().map(|p| p.norm()).fold(0.0, f64::max)
    }

    /// The model of `y` when `self` (no feed-through) is the model of the differenced output
    /// `Δy(t) = y(t) − y(t − 1)`: its states and the integrator `y(t) = y(t − 1) + Δy(t)`
    /// as the last state, which holds `y(t − 1)` (seed 000 §4: the angle's extra state).
    pub fn with_integrator(&self) -> StateSpace {
        let n = self.order();
        let mut a = DMatrix::zeros(n + 1, n + 1);
        a.view_mut((0, 0), (n, n)).copy_from(&self.a);
        for j in 0..n {
            a[(n, j)] = self.c[j];
        }
        a[(n, n)] = 1.0;
        let mut b = DVector::zeros(n + 1);
        b.rows_mut(0, n).copy_from(&self.b);
        let mut c = RowDVector::zeros(n + 1);
        c.columns_mut(0, n).copy_from(&self.c);
        c[n] = 1.0;
        StateSpace::new(a, b, c, 0.0, self.ts)
    }

    /// true when every pole lies strictly inside the unit circle
    pub fn is_stable(&self) -> bool {
        self.spectral_radius() < 1.0
    }

    /// Resonances (complex pole pairs) and anti-resonances (complex zero
    /// pairs) above `f_min_hz` [Hz] with damping below `max_damping`, mapped
    /// to continuous time by `s = ln(z)/Ts`; roots above 0.9 × Nyquist
    /// (sampling zeros) are left out. The integrator of a position output
    /// adds a real pole only, so the pairs are those of the velocity-type
    /// part; `f_min_hz` drops the near-rigid-body pairs an estimated double
    /// integrator may show.
    pub fn resonances(&self, f_min_hz: f64, max_damping: f64) -> Resonances {
        let ts = self.ts;
        let fmax = 0.45 / ts;
        let to_s = |z: Complex<f64>| z.ln() / ts;
        let keep = |m: &Mode| m.damping < max_damping && m.freq_hz >= f_min_hz;
        Resonances {
            resonances: complex_modes(&self.poles(), to_s, fmax)
                .into_iter()
                .filter(keep)
                .collect(),
            anti_resonances: complex_modes(&self.zeros(), to_s, fmax)
                .into_iter()
                .filter(keep)
                .collect(),
        }
    }

    /// Reflect poles outside the unit circle to `1/λ̄` through the real Schur
    /// form `A = Q T Qᵀ` (a 1×1 block `t` becomes `1/t`, a 2×2 block is
    /// divided by `|λ|²`); returns how many poles were reflected. Poles with
    /// `|λ| ≤ 1 + tol` are left alone (integrators).
    pub fn reflect_unstable(&mut self, tol: f64) -> usize {
        let n = self.order();
        if n == 0 || self.spectral_radius() <= 1.0 + tol {
            return 0;
        }
        let Some(s) = Schur::try_new(self.a.clone(), f64::EPSILON, SCHUR_MAX_ITER) else {
            return 0;
        };
        let (q, mut t) = s.unpack();
        let mut count = 0;
        let mut i = 0;
        while i < n {
            let two = i + 1 < n
                && t[(i + 1, i)].abs()
                    > 1e-14 * (t[(i, i)].abs() + t[(i + 1, i + 1)].abs()).max(1e-300);
            if two {
                let det = t[(i, i)] * t[(i + 1, i + 1)] - t[(i, i + 1)] * t[(i + 1, i)];
                // |λ|² of a complex pair equals the block determinant
                if det > (1.0 + tol) * (1.0 + tol) {
                    for r in i..i + 2 {
                        for cidx in i..i + 2 {
                            t[(r, cidx)] /= det;
                        }
                    }
                    count += 2;
                }
                i += 2;
            } else {
                if t[(i, i)].abs() > 1.0 + tol {
                    t[(i, i)] = 1.0 / t[(i, i)];
                    count += 1;
                }
                i += 1;
            }
        }
        self.a = &q * t * q.transpose();
        count
    }

    /// Apply the state transformation `x = T x̃`: returns the model in `x̃`.
    ///
    /// # Panics
    /// When `t` is singular.
    pub fn transform(&self, t: &DMatrix<f64>) -> StateSpace {
        let ti = t
            .clone()
            .try_inverse()
            .expect("state transformation must be invertible");
        StateSpace {
            a: &ti * &self.a * t,
            b: &ti * &self.b,
            c: &self.c * t,
            d: self.d,
            k: self.k.as_ref().map(|k| &ti * k),
            ts: self.ts,
        }
    }

    /// Steady-state gain `C (I − A)^{−1} B + D`; infinite for an integrator.
    pub fn dc_gain(&self) -> f64 {
        let n = self.order();
        let m = DMatrix::identity(n, n) - &self.a;
        match m.lu().solve(&self.b) {
            Some(x) => (&self.c * x)[0] + self.d,
            None => f64::INFINITY,
        }
    }
}

impl ContinuousSs {
    /// model order `n`
    pub fn order(&self) -> usize {
        self.f.nrows()
    }

    /// Zero-order-hold discretisation, seed 000 eq. (12)–(13):
    /// `A_T = e^{F Ts}`, `B_T = ∫_0^{Ts} e^{Fτ} G dτ`, both read from
    /// `exp([[F, G], [0, 0]] Ts)` (Van Loan 1978).
    pub fn zoh(&self, ts: f64) -> StateSpace {
        let n = self.order();
        let mut m = DMatrix::zeros(n + 1, n + 1);
        m.view_mut((0, 0), (n, n)).copy_from(&(&self.f * ts));
        m.view_mut((0, n), (n, 1)).copy_from(&(&self.g * ts));
        let e = expm(m);
        let a = e.view((0, 0), (n, n)).into_owned();
        let b = e.view((0, n), (n, 1)).column(0).into_owned();
        StateSpace::new(a, b, self.h.clone(), self.d, ts)
    }

    /// poles (eigenvalues of `F`), s-plane [rad/s]
    pub fn poles(&self) -> Vec<Complex<f64>> {
        eigenvalues(&self.f)
    }

    /// zeros of u→y, s-plane [rad/s]
    pub fn zeros(&self) -> Vec<Complex<f64>> {
        siso_zeros(&self.f, &self.g, &self.h, self.d)
    }

    /// Frequency response `H (jω I − F)^{−1} G + D` at the given frequencies [Hz].
    pub fn freq_response(&self, f_hz: &[f64]) -> Vec<Complex<f64>> {
        let n = self.order();
        let fc: DMatrix<Complex<f64>> = self.f.map(|v| Complex::new(v, 0.0));
        let gc: DVector<Complex<f64>> = self.g.map(|v| Complex::new(v, 0.0));
        f_hz.iter()
            .map(|&f| {
                let s = Complex::new(0.0, 2.0 * std::f64::consts::PI * f);
                let m = DMatrix::<Complex<f64>>::identity(n, n) * s - &fc;
                let x = m
                    .lu()
                    .solve(&gc)
                    .unwrap_or_else(|| DVector::from_element(n, Complex::new(f64::NAN, 0.0)));
                let mut g = Complex::new(self.d, 0.0);
                for i in 0..n {
                    g += x[i] * self.h[i];
                }
                g
            })
            .collect()
    }

    /// Resonances and anti-resonances (complex pole / zero pairs of the s-plane
    /// model) above `f_min_hz` [Hz] with damping below `max_damping`.
    pub fn resonances(&self, f_min_hz: f64, max_damping: f64) -> Resonances {
        let keep = |m: &Mode| m.damping < max_damping && m.freq_hz >= f_min_hz;
        Resonances {
            resonances: complex_modes(&self.poles(), |s| s, f64::INFINITY)
                .into_iter()
                .filter(keep)
                .collect(),
            anti_resonances: complex_modes(&self.zeros(), |s| s, f64::INFINITY)
                .into_iter()
                .filter(keep)
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eigenvalues_of_huge_and_tiny_matrices_end_and_scale() {
        // an entry of 1e308 overflowed the balancing's norms, which then never ended
        let m = DMatrix::from_row_slice(1, 1, &[1e308]);
        let l = eigenvalues(&m);
        assert!(
            (l[0].re / 1e308 - 1.0).abs() < 1e-12 && l[0].im == 0.0,
            "{l:?}"
        );
        let m = DMatrix::from_row_slice(2, 2, &[0.0, -4e300, 1e300, 0.0]);
        let l = eigenvalues(&m);
        assert!(
            l.iter().all(|z| (z.im.abs() / 2e300 - 1.0).abs() < 1e-12),
            "{l:?}"
        );
        let m = DMatrix::from_row_slice(2, 2, &[1e-300, 0.0, 0.0, -3e-300]);
        let mut l: Vec<f64> = eigenvalues(&m).iter().map(|z| z.re).collect();
        l.sort_by(f64::total_cmp);
        assert_eq!(l, vec![-3e-300, 1e-300]);
        let m = DMatrix::from_row_slice(1, 1, &[f64::INFINITY]);
        assert!(eigenvalues(&m)[0].re.is_nan());
    }

    fn two_mass() -> ContinuousSs {
        // motor J1=0.01, load J2=0.03, k=400 N·m/rad, d=0.02, friction 0.001, velocity output
        let (j1, j2, k, d, fm) = (0.01, 0.03, 400.0, 0.02, 0.001);
        let f = DMatrix::from_row_slice(
            3,
            3,
            &[
                0.0,
                1.0,
                -1.0,
                -k / j1,
                -(fm + d) / j1,
                d / j1,
                k / j2,
                d / j2,
                -d / j2,
            ],
        );
        ContinuousSs {
            f,
            g: DVector::from_vec(vec![0.0, 1.0 / j1, 0.0]),
            h: RowDVector::from_vec(vec![0.0, 1.0, 0.0]),
            d: 0.0,
        }
    }

    #[test]
    fn zoh_matches_scalar_closed_form_first_order() {
        let c = ContinuousSs {
            f: DMatrix::from_element(1, 1, -3.0),
            g: DVector::from_element(1, 2.0),
            h: RowDVector::from_element(1, 1.0),
            d: 0.0,
        };
        let d = c.zoh(0.1);
        let a = (-0.3f64).exp();
        assert!((d.a[(0, 0)] - a).abs() < 1e-14);
        assert!((d.b[0] - 2.0 * (1.0 - a) / 3.0).abs() < 1e-14);
    }

    #[test]
    fn zoh_of_double_integrator_is_exact() {
        let c = ContinuousSs {
            f: DMatrix::from_row_slice(2, 2, &[0.0, 1.0, 0.0, 0.0]),
            g: DVector::from_vec(vec![0.0, 1.0]),
            h: RowDVector::from_vec(vec![1.0, 0.0]),
            d: 0.0,
        };
        let ts = 0.01;
        let d = c.zoh(ts);
        assert!((d.a[(0, 1)] - ts).abs() < 1e-15);
        assert!((d.b[0] - ts * ts / 2.0).abs() < 1e-15);
        assert!((d.b[1] - ts).abs() < 1e-15);
    }

    #[test]
    fn resonances_of_two_mass_match_closed_form() {
        let c = two_mass();
        let (j1, j2, k): (f64, f64, f64) = (0.01, 0.03, 400.0);
        let fr = (k * (1.0 / j1 + 1.0 / j2)).sqrt() / (2.0 * std::f64::consts::PI);
        let fa = (k / j2).sqrt() / (2.0 * std::f64::consts::PI);
        for r in [c.resonances(1.0, 0.5), c.zoh(5e-4).resonances(1.0, 0.5)] {
            assert_eq!(r.resonances.len(), 1, "{r:?}");
            assert_eq!(r.anti_resonances.len(), 1, "{r:?}");
            assert!(
                (r.resonances[0].freq_hz - fr).abs() < 1e-3 * fr,
                "{r:?} vs {fr}"
            );
            assert!(
                (r.anti_resonances[0].freq_hz - fa).abs() < 1e-3 * fa,
                "{r:?} vs {fa}"
            );
        }
    }

    #[test]
    fn freq_response_discrete_matches_continuous_at_low_frequency() {
        let c = two_mass();
        let d = c.zoh(5e-4);
        let f = [1.0, 5.0, 30.0];
        let gc = c.freq_response(&f);
        let gd = d.freq_response(&f);
        for (a, b) in gc.iter().zip(&gd) {
            // ZOH adds a half-sample delay: compare magnitudes
            assert!((a.norm() - b.norm()).abs() < 1e-2 * a.norm(), "{a} vs {b}");
        }
    }

    #[test]
    fn simulate_matches_impulse_response_markov_parameters() {
        let d = two_mass().zoh(1e-3);
        let mut u = vec![0.0; 5];
        u[0] = 1.0;
        let y = d.simulate(&u, None);
        let mut x = d.b.clone();
        for yt in y.iter().skip(1) {
            assert!((yt - (&d.c * &x)[0]).abs() < 1e-12);
            x = &d.a * x;
        }
    }

    #[test]
    fn reflect_unstable_moves_poles_inside_and_keeps_frequency() {
        let th: f64 = 0.3;
        let r = 1.05;
        let a = DMatrix::from_row_slice(
            3,
            3,
            &[
                r * th.cos(),
                -r * th.sin(),
                0.2,
                r * th.sin(),
                r * th.cos(),
                0.1,
                0.0,
                0.0,
                1.2,
            ],
        );
        let mut s = StateSpace::new(
            a,
            DVector::from_element(3, 1.0),
            RowDVector::from_element(3, 1.0),
            0.0,
            1.0,
        );
        let n = s.reflect_unstable(1e-9);
        assert_eq!(n, 3);
        let mut p = s.poles();
        p.sort_by(|x, y| x.norm().total_cmp(&y.norm()));
        assert!((p[0].re - 1.0 / 1.2).abs() < 1e-10);
        assert!((p[1].norm() - 1.0 / r).abs() < 1e-10);
        assert!((p[1].arg().abs() - th).abs() < 1e-10);
    }
}
