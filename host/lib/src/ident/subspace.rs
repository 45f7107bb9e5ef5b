//! Subspace identification of black-box state-space models.
//!
//! Model: discrete-time innovations form `x(t+1) = A x + B u + K e`,
//! `y = C x + D u + e` (seed 000 eq. (9)), SISO (`u` motor torque, `y` motor
//! angle or velocity), orders 1 … 30 and more.
//!
//! Two methods:
//! - [`Method::Moesp`]: PO-MOESP (Verhaegen, "Identification of the
//!   deterministic part of MIMO state space models given in innovations form
//!   from input-output data", Automatica 30(1), 1994; section numbers not
//!   checked here): the LQ factor of
//!   `[U_f; U_p; Y_p; Y_f]`, SVD of the block `L32`, `A` and `C` from the
//!   shift invariance of the extended observability matrix, `B`, `D` and
//!   `x0` by linear least squares on the simulation error. Consistent in
//!   open loop only: under feedback the future inputs correlate with the
//!   future noise and `A` is biased.
//! - [`Method::Pbsid`]: predictor-based subspace identification (Chiuso,
//!   "The role of vector autoregressive modeling in predictor-based subspace
//!   identification", Automatica 43(6), 2007; the "PBSID" estimator with
//!   the product `Γ_f K_p` assembled from the VARX Markov parameters;
//!   section and equation numbers not checked here). A VARX of order `p` gives the predictor Markov
//!   parameters `Φ_k = C Ã^{k−1} [B̃ K]`, `Ã = A − K C`; their block
//!   Toeplitz arrangement is `Γ_f K_p`; its weighted SVD gives the state
//!   `x(t) = K̂_p z_p(t)`, and `C, D` then `A, B, K` follow by least squares
//!   on the state sequence. Consistent under feedback (the predictor form
//!   only regresses on past data), which is the normal case for a robot
//!   joint in its own position loop.
//!
//! Assumptions: the truncation `Ã^p ≈ 0` (choose the past horizon long
//! enough); noise uncorrelated with the reference. Memory is linear in `N`:
//! the data enter only through the Gram matrix of a sliding window
//! ([`crate::ident::linalg::window_gram`]); the LQ factor is the Cholesky factor of
//! that small matrix, so no `N × N` or `rows × N` matrix is ever formed.
//! Stability: a model with poles outside the unit circle has them reflected
//! ([`StateSpace::reflect_unstable`]) and a warning is returned.
//!
//! See also: [`crate::ident::pem`] to refine the model by prediction error.

use nalgebra::{DMatrix, DVector, RowDVector};
use thiserror::Error;

use crate::data::IdData;
use crate::ident::linalg::{solve_spd, window_gram};
use crate::ident::ss::StateSpace;

/// Which subspace estimator to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// PO-MOESP (open-loop consistent)
    Moesp,
    /// predictor-based PBSID (closed-loop consistent)
    Pbsid,
}

/// Model order choice.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Order {
    /// this order
    Fixed(usize),
    /// the order up to `max` at the largest gap of the log singular values
    Auto {
        /// highest order considered
        max: usize,
    },
}

/// Options of [`estimate`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SubspaceOptions {
    /// estimator
    pub method: Method,
    /// model order
    pub order: Order,
    /// past horizon `p` [samples]; 0 picks [`default_past`]
    pub past: usize,
    /// future horizon `f` [samples]; 0 picks the past horizon
    pub future: usize,
    /// estimate the direct feed-through `D` (false: `D = 0`, the usual
    /// choice for a torque → angle model)
    pub feedthrough: bool,
    /// how PBSID estimates `B`, `D` once `A`, `C` are known (MOESP always
    /// uses [`BdEstimate::SimulationLs`])
    pub bd: BdEstimate,
}

/// Second step of PBSID: where `B` and `D` come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BdEstimate {
    /// from the state regression `x(t+1) = A x + B u + K e` (consistent in
    /// closed loop; keeps `K`)
    StateRegression,
    /// least squares on the simulation error with `x0` ([`fit_b_d_x0`];
    /// best output-error fit, biased under feedback; keeps `K`)
    SimulationLs,
}

impl Default for SubspaceOptions {
    fn default() -> Self {
        Self {
            method: Method::Pbsid,
            order: Order::Auto { max: 12 },
            past: 0,
            future: 0,
            feedthrough: false,
            bd: BdEstimate::StateRegression,
        }
    }
}

/// Result of a subspace fit.
#[derive(Clone, Debug, PartialEq)]
pub struct SubspaceFit {
    /// the model in physical units of `u` and `y` (`K` set for PBSID)
    pub model: StateSpace,
    /// initial state that best explains the estimation data by simulation
    pub x0: DVector<f64>,
    /// singular values used for order selection, largest first
    pub singular_values: Vec<f64>,
    /// chosen order
    pub order: usize,
    /// past and future horizons used [samples]
    pub horizons: (usize, usize),
    /// what was done to the model that the caller should know (pole
    /// reflection, ridge regularisation)
    pub warnings: Vec<String>,
}

/// Why a subspace fit failed.
#[derive(Debug, Error, PartialEq)]
pub enum SubspaceError {
    /// not enough samples for the horizons
    #[error("too few samples: {got} given, at least {needed} needed for horizons past {past}, future {future}")]
    TooShort {
        /// samples given
        got: usize,
        /// samples needed
        needed: usize,
        /// past horizon
        past: usize,
        /// future horizon
        future: usize,
    },
    /// the order asked for exceeds what the horizons can reveal
    #[error("order {order} exceeds the largest identifiable order {max} for these horizons")]
    OrderTooHigh {
        /// order asked for
        order: usize,
        /// largest order
        max: usize,
    },
    /// input and output differ in length, contain non-finite values, or the sample
    /// interval is not positive
    #[error("bad data: {0}")]
    BadData(#[from] crate::data::RecordError),
    /// a least-squares step could not be solved
    #[error("singular least-squares problem in {0}")]
    Singular(&'static str),
}

fn rms(x: &[f64]) -> f64 {
    let m = x.iter().sum::<f64>() / x.len() as f64;
    let v = x.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / x.len() as f64;
    let s = v.sqrt();
    if s > 0.0 && s.is_finite() {
        s
    } else {
        1.0
    }
}

fn choose_order(sv: &[f64], order: Order, limit: usize) -> Result<usize, SubspaceError> {
    match order {
        Order::Fixed(n) => {
            if n == 0 || n > limit {
                Err(SubspaceError::OrderTooHigh {
                    order: n,
                    max: limit,
                })
            } else {
                Ok(n)
            }
        }
        Order::Auto { max } => {
            let max = max.min(limit).min(sv.len().saturating_sub(1)).max(1);
            let floor = sv[0] * 1e-14;
            let mut best = 1;
            let mut gap = f64::NEG_INFINITY;
            for n in 1..=max {
                let g = (sv[n - 1].max(floor)).ln() - (sv[n].max(floor)).ln();
                if g > gap {
                    gap = g;
                    best = n;
                }
            }
            Ok(best)
        }
    }
}

/// Default past horizon [samples]: `max(2 n + 2, 20, ⌈0.06 s / Ts⌉)`, the
/// time term at most 250, all at most `N / 20`. The time floor matters for
/// finely sampled joints: at 2 kHz a 9 Hz mode spans 220 samples, and a
/// horizon of a few tens of samples sees nearly collinear rows and loses it
/// (measured with `benches/ident.rs`: 24 samples fail, 120 recover 9–23 Hz
/// to 0.1 %). 60 ms is half a period of an 8 Hz mode; set
/// [`SubspaceOptions::past`] for slower dynamics.
pub fn default_past(order: usize, ts: f64, n_samples: usize) -> usize {
    let by_time = (0.06 / ts).ceil() as usize;
    (2 * order + 2)
        .max(20)
        .max(by_time.min(250))
        .min((n_samples / 20).max(2 * order + 2))
}

/// Identify a state-space model from one record; see the module docs for
/// the methods and their sources.
///
/// # Errors
/// [`SubspaceError`] when the data are too short for the horizons, contain
/// non-finite values, or the order exceeds the horizon.
pub fn estimate(data: &IdData, opts: &SubspaceOptions) -> Result<SubspaceFit, SubspaceError> {
    data.check(0)?;
    let n_hint = match opts.order {
        Order::Fixed(n) => n,
        Order::Auto { max } => max,
    };
    let past = if opts.past == 0 {
        default_past(n_hint, data.ts, data.u.len())
    } else {
        opts.past
    };
    let future = if opts.future == 0 { past } else { opts.future };
    match opts.method {
        Method::Moesp => moesp(data, opts, past, future),
        Method::Pbsid => pbsid(data, opts, past, future),
    }
}

/// PO-MOESP (Verhaegen 1994). Horizon `i = max(past, future)`.
fn moesp(
    data: &IdData,
    opts: &SubspaceOptions,
    past: usize,
    future: usize,
) -> Result<SubspaceFit, SubspaceError> {
    let i = past.max(future);
    let n_data = data.u.len();
    let needed = 2 * i + 4 * i + 10;
    if n_data < needed {
        return Err(SubspaceError::TooShort {
            got: n_data,
            needed,
            past: i,
            future: i,
        });
    }
    let (su, sy) = (rms(&data.u), rms(&data.y));
    let us: Vec<f64> = data.u.iter().map(|v| v / su).collect();
    let ys: Vec<f64> = data.y.iter().map(|v| v / sy).collect();
    let w = 2 * i;
    let g = window_gram(&[&us, &ys], w);
    // order [U_f; U_p; Y_p; Y_f]
    let perm: Vec<usize> = (i..w)
        .chain(0..i)
        .chain(w..w + i)
        .chain(w + i..2 * w)
        .collect();
    let gp = DMatrix::from_fn(2 * w, 2 * w, |r, c| g[(perm[r], perm[c])]);
    let (l, ridge_used) = chol_lower(&gp)?;
    let l32 = l.view((3 * i, i), (i, 2 * i)).into_owned();
    let svd = l32.svd(true, false);
    let (sv, u_mat) = sorted_svd(
        &svd.singular_values,
        svd.u.as_ref().ok_or(SubspaceError::Singular("moesp svd"))?,
    );
    let n = choose_order(&sv, opts.order, i - 1)?;
    let gamma = DMatrix::from_fn(i, n, |r, c| u_mat[(r, c)] * sv[c].sqrt());
    let (a_s, c_s) = a_c_from_gamma(&gamma)?;
    let mut warnings = Vec::new();
    if ridge_used {
        warnings.push("data Gram matrix was rank deficient; a ridge was added".to_string());
    }
    // A and C in physical units: states are scaled, y = sy * y_s
    let c = c_s * sy;
    let mut model = StateSpace::new(a_s, DVector::zeros(n), c, 0.0, data.ts);
    stabilise(&mut model, &mut warnings);
    let (b, d, x0) = fit_b_d_x0(&model.a, &model.c, &data.u, &data.y, opts.feedthrough)?;
    model.b = b;
    model.d = d;
    Ok(SubspaceFit {
        model,
        x0,
        singular_values: sv,
        order: n,
        horizons: (i, i),
        warnings,
    })
}

/// PBSID (Chiuso 2007).
fn pbsid(
    data: &IdData,
    opts: &SubspaceOptions,
    past: usize,
    future: usize,
) -> Result<SubspaceFit, SubspaceError> {
    let p = past;
    let f = future.min(p);
    let n_data = data.u.len();
    let needed = 2 * (p + 1) + 4 * p + 10;
    if n_data < needed {
        return Err(SubspaceError::TooShort {
            got: n_data,
            needed,
            past: p,
            future: f,
        });
    }
    let (su, sy) = (rms(&data.u), rms(&data.y));
    let us: Vec<f64> = data.u.iter().map(|v| v / su).collect();
    let ys: Vec<f64> = data.y.iter().map(|v| v / sy).collect();
    let wl = p + 1; // window: samples s .. s+p, current time t = s + p
    let g = window_gram(&[&us, &ys], wl);
    let cnt = (n_data - wl + 1) as f64;
    let g = g / cnt;
    // index maps into the window
    let iu = |a: usize| a;
    let iy = |a: usize| wl + a;
    let past_idx: Vec<usize> = (0..p).map(iu).chain((0..p).map(iy)).collect();
    let next_idx: Vec<usize> = (1..=p).map(iu).chain((1..=p).map(iy)).collect();
    let (iut, iyt) = (iu(p), iy(p));
    let mut warnings = Vec::new();

    // 1. VARX: y(t) on [z_p(t); u(t)]
    let mut reg_idx = past_idx.clone();
    if opts.feedthrough {
        reg_idx.push(iut);
    }
    let grr = DMatrix::from_fn(reg_idx.len(), reg_idx.len(), |r, c| {
        g[(reg_idx[r], reg_idx[c])]
    });
    let gry = DMatrix::from_fn(reg_idx.len(), 1, |r, _| g[(reg_idx[r], iyt)]);
    let theta = solve_spd(&grr, &gry, 1e-10).ok_or(SubspaceError::Singular("varx"))?;
    // coefficient of z(t-m): u at window offset p-m (column p-m), y at column p + (p-m)
    let phi_u = |m: usize| theta[(p - m, 0)];
    let phi_y = |m: usize| theta[(p + p - m, 0)];

    // 2. Γ_f K_p from the Markov parameters (Ã^p ≈ 0)
    let mut mk = DMatrix::zeros(f, 2 * p);
    for j in 0..f {
        for m in 1..=p {
            if j + m <= p {
                mk[(j, p - m)] = phi_u(j + m);
                mk[(j, p + p - m)] = phi_y(j + m);
            }
        }
    }
    // 3. weighted SVD: M W = U S Vᵀ with Σ_zz = W Wᵀ
    let gzz = DMatrix::from_fn(2 * p, 2 * p, |r, c| g[(past_idx[r], past_idx[c])]);
    let (wz, ridge_used) = chol_lower(&gzz)?;
    if ridge_used {
        warnings.push("past-data covariance was rank deficient; a ridge was added".to_string());
    }
    let mw = &mk * &wz;
    let svd = mw.svd(false, true);
    let vt = svd
        .v_t
        .as_ref()
        .ok_or(SubspaceError::Singular("pbsid svd"))?;
    let mut order_sv: Vec<(f64, usize)> = svd.singular_values.iter().copied().zip(0..).collect();
    order_sv.sort_by(|a, b| b.0.total_cmp(&a.0));
    let sv: Vec<f64> = order_sv.iter().map(|x| x.0).collect();
    let n = choose_order(&sv, opts.order, f.min(2 * p) - 1)?;
    // L = S_n^{1/2} V_nᵀ W^{-1}: x(t) = L z_p(t)
    let vn_s = DMatrix::from_fn(2 * p, n, |r, c| {
        vt[(order_sv[c].1, r)] * order_sv[c].0.sqrt()
    });
    let lt = wz
        .transpose()
        .solve_upper_triangular(&vn_s)
        .ok_or(SubspaceError::Singular("pbsid state map"))?;
    let lmat = lt.transpose(); // n × 2p
    let dim = 2 * wl;
    let mut tx = DMatrix::zeros(n, dim);
    let mut txn = DMatrix::zeros(n, dim);
    for (k, (&ip, &inx)) in past_idx.iter().zip(&next_idx).enumerate() {
        for r in 0..n {
            tx[(r, ip)] += lmat[(r, k)];
            txn[(r, inx)] += lmat[(r, k)];
        }
    }
    let mut eu = DMatrix::zeros(1, dim);
    eu[(0, iut)] = 1.0;
    let mut ey = DMatrix::zeros(1, dim);
    ey[(0, iyt)] = 1.0;

    // 4. C, D: y(t) on [x(t); u(t)]
    let rx = if opts.feedthrough {
        stack(&[&tx, &eu])
    } else {
        tx.clone()
    };
    let cd = regress(&rx, &ey, &g)?; // 1 × (n [+1])
    let c_s = RowDVector::from_fn(n, |_, j| cd[(0, j)]);
    let d_s = if opts.feedthrough { cd[(0, n)] } else { 0.0 };
    // innovation e(t) = y - C x - D u as a row over the window
    let te = &ey - &cd * &rx;
    // 5. A, B, K: x(t+1) on [x(t); u(t); e(t)]
    let rabk = stack(&[&tx, &eu, &te]);
    let abk = regress(&rabk, &txn, &g)?; // n × (n+2)
    let a = abk.view((0, 0), (n, n)).into_owned();
    let b_s = abk.column(n).into_owned();
    let k_s = abk.column(n + 1).into_owned();
    if ridge_used {
        warnings.push("state regression used a ridge".to_string());
    }
    let mut model = StateSpace::new(a, b_s / su, c_s * sy, d_s * sy / su, data.ts);
    model.k = Some(k_s / sy);
    stabilise(&mut model, &mut warnings);
    let x0 = if opts.bd == BdEstimate::SimulationLs {
        let (b, d, x0) = fit_b_d_x0(&model.a, &model.c, &data.u, &data.y, opts.feedthrough)?;
        model.b = b;
        model.d = d;
        x0
    } else {
        estimate_x0(&model, &data.u, &data.y)
    };
    Ok(SubspaceFit {
        model,
        x0,
        singular_values: sv,
        order: n,
        horizons: (p, f),
        warnings,
    })
}

fn stack(parts: &[&DMatrix<f64>]) -> DMatrix<f64> {
    let cols = parts[0].ncols();
    let rows: usize = parts.iter().map(|m| m.nrows()).sum();
    let mut out = DMatrix::zeros(rows, cols);
    let mut r0 = 0;
    for m in parts {
        out.view_mut((r0, 0), (m.nrows(), cols)).copy_from(m);
        r0 += m.nrows();
    }
    out
}

/// Least squares of `Y = Θ X` where `X = rx w`, `Y = ry w` over the window
/// covariance `g`: `Θ = (ry g rxᵀ)(rx g rxᵀ)^{-1}`.
fn regress(
    rx: &DMatrix<f64>,
    ry: &DMatrix<f64>,
    g: &DMatrix<f64>,
) -> Result<DMatrix<f64>, SubspaceError> {
    let gx = rx * g;
    let sxx = &gx * rx.transpose();
    let sxy = &gx * ry.transpose();
    let th = solve_spd(&sxx, &sxy, 1e-12).ok_or(SubspaceError::Singular("state regression"))?;
    Ok(th.transpose())
}

fn chol_lower(m: &DMatrix<f64>) -> Result<(DMatrix<f64>, bool), SubspaceError> {
    if let Some(ch) = m.clone().cholesky() {
        return Ok((ch.l(), false));
    }
    let n = m.nrows();
    let tr = m.trace() / n as f64;
    let mut reg = 1e-12;
    for _ in 0..8 {
        let mut mm = m.clone();
        for i in 0..n {
            mm[(i, i)] += reg * tr;
        }
        if let Some(ch) = mm.cholesky() {
            return Ok((ch.l(), true));
        }
        reg *= 100.0;
    }
    Err(SubspaceError::Singular("cholesky of the data covariance"))
}

fn sorted_svd(s: &DVector<f64>, u: &DMatrix<f64>) -> (Vec<f64>, DMatrix<f64>) {
    let mut idx: Vec<usize> = (0..s.len()).collect();
    idx.sort_by(|&a, &b| s[b].total_cmp(&s[a]));
    let sv = idx.iter().map(|&k| s[k]).collect();
    let um = DMatrix::from_fn(u.nrows(), idx.len(), |r, c| u[(r, idx[c])]);
    (sv, um)
}

/// `A = Γ_↑⁺ Γ_↓`, `C = Γ_0` (shift invariance of the extended observability
/// matrix, Verhaegen 1994; SISO so one row per block).
fn a_c_from_gamma(gamma: &DMatrix<f64>) -> Result<(DMatrix<f64>, RowDVector<f64>), SubspaceError> {
    let (rows, n) = gamma.shape();
    let up = gamma.rows(0, rows - 1).into_owned();
    let down = gamma.rows(1, rows - 1).into_owned();
    let a = up
        .svd(true, true)
        .solve(&down, 1e-14)
        .map_err(|_| SubspaceError::Singular("shift invariance"))?;
    let c = RowDVector::from_fn(n, |_, j| gamma[(0, j)]);
    Ok((a, c))
}

fn stabilise(model: &mut StateSpace, warnings: &mut Vec<String>) {
    let rho = model.spectral_radius();
    if !rho.is_finite() {
        warnings.push("eigenvalues of A could not be computed".to_string());
        return;
    }
    let k = model.reflect_unstable(1e-9);
    if k > 0 {
        warnings.push(format!(
            "{k} pole(s) outside the unit circle (spectral radius {rho:.6}) reflected to 1/conj(pole)"
        ));
    }
}

/// Least squares for `B`, `D` (when `feedthrough`) and `x0` given `A`, `C`:
/// `y(t) = C A^t x0 + Σ_{k<t} C A^{t−k−1} B u(k) + D u(t)`, linear in
/// `(x0, B, D)`. The regressors obey `w(t+1) = w(t) A` (`w(0) = C`) and
/// `v(t+1) = v(t) A + u(t) C` (`v(0) = 0`), so one pass costs `O(N n²)`.
///
/// # Errors
/// [`SubspaceError::Singular`] when the normal equations cannot be solved.
pub fn fit_b_d_x0(
    a: &DMatrix<f64>,
    c: &RowDVector<f64>,
    u: &[f64],
    y: &[f64],
    feedthrough: bool,
) -> Result<(DVector<f64>, f64, DVector<f64>), SubspaceError> {
    let n = a.nrows();
    let p = 2 * n + usize::from(feedthrough);
    let mut m = DMatrix::<f64>::zeros(p, p);
    let mut r = DMatrix::<f64>::zeros(p, 1);
    let mut w = c.clone();
    let mut v = RowDVector::<f64>::zeros(n);
    let mut phi = vec![0.0; p];
    // accumulate the upper triangle in a flat buffer for speed
    let mut acc = vec![0.0; p * p];
    for (&ut, &yt) in u.iter().zip(y) {
        phi[..n].copy_from_slice(w.as_slice());
        phi[n..2 * n].copy_from_slice(v.as_slice());
        if feedthrough {
            phi[2 * n] = ut;
        }
        for i in 0..p {
            let pi = phi[i];
            if pi == 0.0 {
                continue;
            }
            let row = &mut acc[i * p..(i + 1) * p];
            for j in i..p {
                row[j] += pi * phi[j];
            }
            r[(i, 0)] += pi * yt;
        }
        let vn = &v * a + c * ut;
        w = &w * a;
        v = vn;
    }
    for i in 0..p {
        for j in i..p {
            m[(i, j)] = acc[i * p + j];
            m[(j, i)] = acc[i * p + j];
        }
    }
    let th = solve_spd(&m, &r, 1e-13).ok_or(SubspaceError::Singular("b, d, x0 least squares"))?;
    let x0 = DVector::from_fn(n, |i, _| th[(i, 0)]);
    let b = DVector::from_fn(n, |i, _| th[(n + i, 0)]);
    let d = if feedthrough { th[(2 * n, 0)] } else { 0.0 };
    Ok((b, d, x0))
}

/// Initial state minimising the simulation error of `model` on `(u, y)`
/// (linear least squares on `y − ŷ_0 = C A^t x0`).
pub fn estimate_x0(model: &StateSpace, u: &[f64], y: &[f64]) -> DVector<f64> {
    let n = model.order();
    let y0 = model.simulate(u, None);
    let mut m = DMatrix::<f64>::zeros(n, n);
    let mut r = DMatrix::<f64>::zeros(n, 1);
    let mut w = model.c.clone();
    for (yt, y0t) in y.iter().zip(&y0) {
        let e = yt - y0t;
        for i in 0..n {
            for j in 0..n {
                m[(i, j)] += w[i] * w[j];
            }
            r[(i, 0)] += w[i] * e;
        }
        w = &w * &model.a;
        if w.norm() < 1e-300 {
            break;
        }
    }
    solve_spd(&m, &r, 1e-12)
        .map(|x| x.column(0).into_owned())
        .unwrap_or_else(|| DVector::zeros(n))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ident::linalg::GaussRng;
    use crate::test_support::two_mass::{closed_loop, two_mass_ct, LoopSpec};

    fn pole_error(est: &StateSpace, truth: &StateSpace) -> f64 {
        // each true pole matched to its nearest estimated pole
        let pe = est.poles();
        truth
            .poles()
            .iter()
            .map(|p| {
                pe.iter()
                    .map(|q| (q - p).norm())
                    .fold(f64::INFINITY, f64::min)
            })
            .fold(0.0, f64::max)
    }

    #[test]
    fn pbsid_recovers_order_4_poles_on_closed_loop() {
        let plant = two_mass_ct(true).zoh(2e-3);
        let spec = LoopSpec {
            kp: 2.0,
            kd: 0.05,
            noise: 1e-4,
            colour: 0.0,
            seed: 3,
            n: 8000,
            r_smooth: 0.9,
            u_dither: 0.05,
        };
        let data = closed_loop(&plant, &spec);
        let opts = SubspaceOptions {
            method: Method::Pbsid,
            order: Order::Fixed(4),
            past: 20,
            ..Default::default()
        };
        let fit = estimate(&data, &opts).unwrap();
        let err = pole_error(&fit.model, &plant);
        assert!(
            err < 5e-3,
            "max pole error {err}, {:?} vs {:?}",
            fit.model.poles(),
            plant.poles()
        );
        let res = fit.model.resonances(1.0, 0.3);
        let tr = plant.resonances(1.0, 0.3);
        assert!(
            (res.resonances[0].freq_hz - tr.resonances[0].freq_hz).abs()
                < 0.02 * tr.resonances[0].freq_hz,
            "{res:?} vs {tr:?} err {err} warn {:?}",
            fit.warnings
        );
        assert!(
            (res.anti_resonances[0].freq_hz - tr.anti_resonances[0].freq_hz).abs()
                < 0.02 * tr.anti_resonances[0].freq_hz
        );
    }

    #[test]
    fn moesp_recovers_order_3_poles_in_open_loop_with_auto_order() {
        let plant = two_mass_ct(false).zoh(2e-3);
        let mut rng = GaussRng::new(11);
        let u = rng.normals(6000, 1.0);
        let mut y = plant.simulate(&u, None);
        for v in &mut y {
            *v += 1e-3 * rng.normal();
        }
        let data = IdData {
            ts: plant.ts,
            u,
            y,
            r: None,
        };
        let opts = SubspaceOptions {
            method: Method::Moesp,
            order: Order::Auto { max: 8 },
            past: 15,
            ..Default::default()
        };
        let fit = estimate(&data, &opts).unwrap();
        assert_eq!(fit.order, 3, "sv {:?}", &fit.singular_values[..6]);
        let err = pole_error(&fit.model, &plant);
        assert!(err < 2e-3, "max pole error {err}");
    }

    fn resonance_error(est: &StateSpace, truth: &StateSpace) -> f64 {
        // largest relative error of the true resonance / anti-resonance
        // frequencies against the nearest estimated ones
        let (e, t) = (est.resonances(1.0, 0.3), truth.resonances(1.0, 0.3));
        let worst = |est: &[crate::ident::ss::Mode], tr: &[crate::ident::ss::Mode]| {
            tr.iter()
                .map(|m| {
                    est.iter()
                        .map(|q| (q.freq_hz - m.freq_hz).abs() / m.freq_hz)
                        .fold(f64::INFINITY, f64::min)
                })
                .fold(0.0, f64::max)
        };
        worst(&e.resonances, &t.resonances).max(worst(&e.anti_resonances, &t.anti_resonances))
    }

    /// The reference three-mass joint (angle output) sampled at 2 ms, and 20 s of
    /// it in a PD position loop with output noise 1e-4 rad and noise `seed`:
    /// (discrete plant, record).
    fn three_mass_closed_loop(seed: u64) -> (StateSpace, IdData) {
        use crate::ident::grey_box::{
            reference_three_mass, GreyBoxModel, Output, DEFAULT_GEAR_RATIO,
        };
        use crate::model::spec::Structure;
        let gm = GreyBoxModel {
            structure: Structure::ThreeMass,
            output: Output::Angle,
            r: DEFAULT_GEAR_RATIO,
            ts: 2e-3,
        };
        let plant = gm.continuous(&reference_three_mass()).zoh(2e-3);
        let spec = LoopSpec {
            kp: 1.0,
            kd: 0.02,
            noise: 1e-4,
            colour: 0.0,
            seed,
            n: 10_000,
            r_smooth: 0.8,
            u_dither: 0.02,
        };
        let data = closed_loop(&plant, &spec);
        (plant, data)
    }

    #[test]
    fn pbsid_recovers_order_6_three_mass_resonances_on_closed_loop() {
        let (plant, data) = three_mass_closed_loop(8);
        let opts = SubspaceOptions {
            method: Method::Pbsid,
            order: Order::Fixed(6),
            past: 30,
            ..Default::default()
        };
        let fit = estimate(&data, &opts).unwrap();
        let err = resonance_error(&fit.model, &plant);
        assert!(
            err < 0.01,
            "relative frequency error {err}: {:?} vs {:?}",
            fit.model.resonances(1.0, 0.3),
            plant.resonances(1.0, 0.3)
        );
    }

    #[test]
    fn pbsid_bias_smaller_than_moesp_under_feedback_with_coloured_noise() {
        let plant = two_mass_ct(true).zoh(2e-3);
        let mut e_moesp = 0.0;
        let mut e_pbsid = 0.0;
        for seed in 0..3 {
            let spec = LoopSpec {
                kp: 2.0,
                kd: 0.05,
                noise: 2e-3,
                colour: 0.95,
                seed: 40 + seed,
                n: 20_000,
                r_smooth: 0.9,
                u_dither: 0.0,
            };
            let data = closed_loop(&plant, &spec);
            for (method, acc) in [(Method::Moesp, &mut e_moesp), (Method::Pbsid, &mut e_pbsid)] {
                // order 5: the four plant states plus the state of the AR(1) noise
                let opts = SubspaceOptions {
                    method,
                    order: Order::Fixed(5),
                    past: 80,
                    ..Default::default()
                };
                let fit = estimate(&data, &opts).unwrap();
                *acc += resonance_error(&fit.model, &plant);
            }
        }
        eprintln!(
            "mean relative resonance error: MOESP {:.4}, PBSID {:.4}",
            e_moesp / 3.0,
            e_pbsid / 3.0
        );
        assert!(
            e_pbsid < 0.5 * e_moesp,
            "PBSID {e_pbsid} vs MOESP {e_moesp}"
        );
        assert!(e_pbsid / 3.0 < 0.03, "PBSID {e_pbsid}");
    }

    #[test]
    fn pbsid_order_20_keeps_three_mass_resonances() {
        let (plant, data) = three_mass_closed_loop(9);
        let fit = estimate(
            &data,
            &SubspaceOptions {
                order: Order::Fixed(20),
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(fit.model.order(), 20);
        assert!(fit.model.spectral_radius() <= 1.0 + 1e-9);
        let err = resonance_error(&fit.model, &plant);
        assert!(err < 0.01, "relative frequency error {err}");
    }
}
