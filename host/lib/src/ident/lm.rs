//! Levenberg–Marquardt for nonlinear least squares, over any problem that can
//! evaluate its cost and its normal equations.
//!
//! Problem: `θ̂ = argmin Σ_t e²(t, θ)`, `e = y − ŷ(θ)` (real residuals; a
//! complex residual enters as its real and imaginary parts). The problem
//! ([`LeastSquares`]) owns how `ŷ` and `J = ∂ŷ/∂θ` are computed (forward
//! sensitivities of a state-space simulation in [`crate::ident::pem`], analytic
//! derivatives of a frequency response, …) and hands back `JᵀJ`, `Jᵀe` and
//! `Σe²` accumulated in whatever memory it likes; the loop here never holds
//! the Jacobian, so memory stays linear in the number of residuals only if
//! the problem's accumulation is.
//!
//! Method: Levenberg–Marquardt with Marquardt's diagonal scaling,
//! `(JᵀJ + λ diag JᵀJ) δ = Jᵀe` (Nocedal & Wright, *Numerical
//! Optimization*, 2nd ed., §10.3), each step projected onto box bounds (with
//! [`LmOptions::active_set`], a parameter on its bound whose gradient points out of the box
//! held for that step and the step solved without it); a step is accepted only when it lowers the cost, then `λ ← λ/5`, otherwise
//! `λ ← 8λ` until `λ > 1e12`. Some parameters may be fixed. Trailing
//! *nuisance* parameters (an initial state, say) are free and unbounded and
//! take no part in the step-size test. Optionally ([`LmOptions::within_noise`]) the loop
//! stops when the Gauss–Newton step would lower the cost by less than a share of one
//! residual variance: the Newton decrement `gᵀ(JᵀJ)⁻¹g` is the cost the linearised problem
//! has left to lose, `σ²` times the squared distance to its minimum in standard deviations
//! (Boyd & Vandenberghe, *Convex Optimization*, §9.5.1, for the decrement as a stopping
//! rule).
//!
//! Uncertainty: `cov(θ̂) = σ̂² (JᵀJ)^{−1}` with `σ̂² = Σe² / (N − p)`
//! (Ljung, *System Identification*, 2nd ed., §9.3; valid for white
//! residuals of equal variance: a problem whose residuals are weighted by
//! their standard deviations gets `σ̂² ≈ 1`, and its cost is then a χ²
//! statistic, see [`LmFit::chi2`]).
//!
//! See also: [`crate::ident::pem`] (prediction error of a parameterised state
//! space, built on this loop).

use nalgebra::{DMatrix, DVector};
use thiserror::Error;

use crate::ident::linalg::pinv_sym;

/// Normal equations of a least-squares problem at one parameter vector,
/// over the free parameters in the order the loop asked for them.
#[derive(Clone, Debug, PartialEq)]
pub struct Normal {
    /// `JᵀJ` with `J = ∂ŷ/∂θ_free`
    pub jtj: DMatrix<f64>,
    /// `Jᵀe` with `e = y − ŷ`
    pub jte: DVector<f64>,
    /// `Σ e²`
    pub ssr: f64,
}

/// A nonlinear least-squares problem `min Σ e²(θ)`.
pub trait LeastSquares {
    /// number of parameters (fixed and nuisance ones included)
    fn n_params(&self) -> usize;
    /// number of real residuals `N` (for `σ̂² = Σe²/(N − p)`)
    fn n_residuals(&self) -> usize;
    /// the cost at `theta`, any positive multiple of `Σ e²` (the loop only
    /// compares costs); non-finite when `theta` cannot be evaluated, which
    /// rejects the step
    fn cost(&self, theta: &[f64]) -> f64;
    /// `JᵀJ`, `Jᵀe` over the parameters `free` (in that order) and `Σ e²`
    fn normal_equations(&self, theta: &[f64], free: &[usize]) -> Normal;
}

/// Options of [`minimize`].
#[derive(Clone, Debug, PartialEq)]
pub struct LmOptions {
    /// largest number of normal-equation evaluations (iterations)
    pub max_iter: usize,
    /// stop when an accepted step lowers the cost by less than this share
    pub rel_cost_tol: f64,
    /// stop when the step is below this share of the parameter norm
    pub step_tol: f64,
    /// lower bounds per parameter (−∞ for none); empty: none
    pub lower: Vec<f64>,
    /// upper bounds per parameter (+∞ for none); empty: none
    pub upper: Vec<f64>,
    /// `fixed[i]` keeps `θ_i` at its initial value; empty: all free
    pub fixed: Vec<bool>,
    /// the last `nuisance` parameters are free, unbounded, and left out of
    /// the step-size test (e.g. an initial state)
    pub nuisance: usize,
    /// initial Marquardt damping `λ`
    pub lambda0: f64,
    /// stop when the Gauss–Newton step from the current point would lower the cost by
    /// less than this many residual variances `σ̂² = Σe²/(N − p)` (the Newton decrement:
    /// the point is then within `√τ` standard deviations, by the white-noise covariance,
    /// of the linearised problem's minimum, so no further step can move it by a
    /// distance the data resolve); parameters held on a bound by the step are left out;
    /// 0: off
    pub within_noise: f64,
    /// hold a free parameter on its bound whose gradient points out of the box for the
    /// step, and solve the step over the others (an active set), instead of solving over
    /// every parameter and clamping: the fit then moves along the bound instead of
    /// crawling against it
    pub active_set: bool,
    /// evaluate the normal equations once more at the end for `std` and `cov` (one
    /// Jacobian); off for callers that form their own covariance: `std` and `cov` are then
    /// zero and `ssr` is the final cost (the problem's cost must be `Σ e²`)
    pub covariance: bool,
}

impl Default for LmOptions {
    fn default() -> Self {
        Self {
            max_iter: 50,
            rel_cost_tol: 1e-9,
            step_tol: 1e-10,
            lower: Vec::new(),
            upper: Vec::new(),
            fixed: Vec::new(),
            nuisance: 0,
            lambda0: 1e-3,
            within_noise: 0.0,
            active_set: false,
            covariance: true,
        }
    }
}

/// Why the iteration stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Termination {
    /// relative cost decrease below `rel_cost_tol`
    CostConverged,
    /// step below `step_tol`
    StepConverged,
    /// `max_iter` reached
    MaxIterations,
    /// no step lowered the cost even with very strong damping (a minimum
    /// within the problem's numerical resolution, or a bound)
    NoDescent,
    /// the Gauss–Newton step would lower the cost by less than `within_noise` residual
    /// variances
    WithinNoise,
}

impl Termination {
    /// a few words for reports
    pub fn describe(self) -> &'static str {
        match self {
            Termination::CostConverged => "cost converged",
            Termination::StepConverged => "step converged",
            Termination::MaxIterations => "iteration limit reached",
            Termination::NoDescent => "no further descent",
            Termination::WithinNoise => "within the noise of the minimum",
        }
    }
}

/// Result of [`minimize`].
#[derive(Clone, Debug, PartialEq)]
pub struct LmFit {
    /// parameters (fixed ones unchanged)
    pub theta: Vec<f64>,
    /// standard deviation per parameter (0 for fixed ones)
    pub std: Vec<f64>,
    /// covariance of all parameters (zero rows and columns for fixed ones)
    pub cov: DMatrix<f64>,
    /// cost after each accepted step (first entry: the start)
    pub cost_history: Vec<f64>,
    /// `Σ e²` at the end
    pub ssr: f64,
    /// residual variance `σ̂² = Σe² / (N − p)`, `p` the free parameters
    pub sigma2: f64,
    /// free parameters `p`
    pub n_free: usize,
    /// residuals `N`
    pub n_residuals: usize,
    /// why the iteration stopped
    pub termination: Termination,
    /// normal-equation evaluations used
    pub iterations: usize,
}

impl LmFit {
    /// The final cost as a χ² statistic with `N − p` degrees of freedom,
    /// `(Σe², N − p)`: meaningful when the residuals were divided by their
    /// standard deviations (a frequency-domain fit weighted by the per-line
    /// variance); its expected value is then `N − p`.
    pub fn chi2(&self) -> (f64, usize) {
        (self.ssr, self.n_residuals.saturating_sub(self.n_free))
    }

    /// indices of the parameters that ended on a bound (relative tolerance
    /// 1e-9 of the bound's magnitude, at least 1e-12; infinite bounds never)
    pub fn at_bounds(&self, opts: &LmOptions) -> Vec<usize> {
        let near = |a: f64, b: f64| b.is_finite() && (a - b).abs() <= 1e-9 * b.abs().max(1e-3);
        (0..self.theta.len())
            .filter(|&i| !opts.fixed.get(i).copied().unwrap_or(false))
            .filter(|&i| {
                opts.lower.get(i).is_some_and(|&l| near(self.theta[i], l))
                    || opts.upper.get(i).is_some_and(|&u| near(self.theta[i], u))
            })
            .collect()
    }
}

/// Why a minimisation could not start.
#[derive(Debug, Error, PartialEq)]
pub enum LmError {
    /// an option vector does not match the number of parameters
    #[error("{what} has {got} entries, the problem has {expected} parameters")]
    Length {
        /// which vector
        what: &'static str,
        /// its length
        got: usize,
        /// the number of parameters
        expected: usize,
    },
    /// the start gives a non-finite cost
    #[error("the initial parameters give a non-finite cost")]
    NonFiniteStart,
}

/// The cost decrease `gᵀ H⁻¹ g` the Gauss–Newton step (`H = JᵀJ`, `g` the step's right
/// side) predicts, over the parameters not `held` that the step does not push against
/// their bound (`pushed(j, step_j)`): those are dropped one at a time and the step solved
/// again.
fn newton_decrement(ne: &Normal, held: &[bool], pushed: impl Fn(usize, f64) -> bool) -> f64 {
    let mut keep: Vec<usize> = (0..ne.jtj.nrows()).filter(|&j| !held[j]).collect();
    loop {
        let h = ne.jtj.select_rows(&keep).select_columns(&keep);
        let g = ne.jte.select_rows(&keep);
        let step = pinv_sym(&h, 1e-12) * &g;
        match (0..keep.len()).find(|&a| pushed(keep[a], step[a])) {
            Some(a) => {
                keep.remove(a);
            }
            None => return g.dot(&step),
        }
    }
}

/// The Levenberg–Marquardt step `(JᵀJ + λ diag) δ = Jᵀe` with the `held` parameters'
/// components nought, solved over the others: the active set of a projected Newton method
/// (Bertsekas, *Nonlinear Programming*, 2nd ed., §2.3).
fn damped_step(ne: &Normal, lambda: f64, diag: &[f64], held: &[bool]) -> DVector<f64> {
    let keep: Vec<usize> = (0..ne.jtj.nrows()).filter(|&j| !held[j]).collect();
    let mut a = ne.jtj.select_rows(&keep).select_columns(&keep);
    let g = ne.jte.select_rows(&keep);
    for (r, &j) in keep.iter().enumerate() {
        a[(r, r)] += lambda * diag[j];
    }
    let sub = match a.clone().cholesky() {
        Some(ch) => ch.solve(&g),
        None => pinv_sym(&a, 1e-14) * &g,
    };
    let mut step = DVector::zeros(ne.jtj.nrows());
    for (r, &j) in keep.iter().enumerate() {
        step[j] = sub[r];
    }
    step
}

fn clamp(theta: &mut [f64], lower: &[f64], upper: &[f64]) {
    for (i, t) in theta.iter_mut().enumerate() {
        if let Some(&l) = lower.get(i) {
            *t = t.max(l);
        }
        if let Some(&u) = upper.get(i) {
            *t = t.min(u);
        }
    }
}

/// Minimises the problem's cost from `theta0` (module docs).
///
/// # Errors
/// [`LmError::Length`] when `theta0`, bounds or `fixed` do not match
/// [`LeastSquares::n_params`], [`LmError::NonFiniteStart`] when the start
/// cannot be evaluated.
pub fn minimize<P: LeastSquares + ?Sized>(
    problem: &P,
    theta0: &[f64],
    opts: &LmOptions,
) -> Result<LmFit, LmError> {
    let np = problem.n_params();
    let check = |what: &'static str, got: usize, may_be_empty: bool| {
        if got == np || (may_be_empty && got == 0) {
            Ok(())
        } else {
            Err(LmError::Length {
                what,
                got,
                expected: np,
            })
        }
    };
    check("the start", theta0.len(), false)?;
    check("the lower bounds", opts.lower.len(), true)?;
    check("the upper bounds", opts.upper.len(), true)?;
    check("the fixed flags", opts.fixed.len(), true)?;
    let n_main = np.saturating_sub(opts.nuisance);
    let free: Vec<usize> = (0..np)
        .filter(|&i| i >= n_main || !opts.fixed.get(i).copied().unwrap_or(false))
        .collect();
    // bounds never apply to nuisance parameters
    let bound = |v: &[f64]| -> Vec<f64> { v.iter().take(n_main).copied().collect() };
    let (lower, upper) = (bound(&opts.lower), bound(&opts.upper));
    let mut theta = theta0.to_vec();
    clamp(&mut theta, &lower, &upper);
    let mut cost = problem.cost(&theta);
    if !cost.is_finite() {
        return Err(LmError::NonFiniteStart);
    }
    let mut history = vec![cost];
    let mut lambda = opts.lambda0;
    let mut termination = Termination::MaxIterations;
    let mut iterations = 0;
    let main_free: Vec<usize> = free.iter().copied().filter(|&i| i < n_main).collect();
    'outer: while iterations < opts.max_iter {
        iterations += 1;
        let ne = problem.normal_equations(&theta, &free);
        if ne.jtj.iter().chain(ne.jte.iter()).any(|v| !v.is_finite()) {
            // a derivative is not finite here: no step can be computed from it
            termination = Termination::NoDescent;
            break;
        }
        let p = ne.jtj.nrows();
        // with `active_set`, a free parameter on its bound whose gradient points out of the
        // box is held for this step: clamping it after the solve would leave the other
        // components fitted to a move it cannot make
        let at_bound = |i: usize, dir: f64| {
            i < n_main
                && ((dir < 0.0 && lower.get(i).is_some_and(|&l| theta[i] <= l))
                    || (dir > 0.0 && upper.get(i).is_some_and(|&u| theta[i] >= u)))
        };
        let held: Vec<bool> = free
            .iter()
            .zip(ne.jte.iter())
            .map(|(&i, &g)| opts.active_set && at_bound(i, g))
            .collect();
        if opts.within_noise > 0.0 {
            let dof = (problem.n_residuals() as f64 - p as f64).max(1.0);
            let pushed = |j: usize, step: f64| at_bound(free[j], step);
            if newton_decrement(&ne, &held, pushed) < opts.within_noise * ne.ssr / dof {
                termination = Termination::WithinNoise;
                break;
            }
        }
        let diag: Vec<f64> = (0..p).map(|i| ne.jtj[(i, i)].max(1e-300)).collect();
        loop {
            let step = damped_step(&ne, lambda, &diag, &held);
            let mut cand = theta.clone();
            for (j, &i) in free.iter().enumerate() {
                cand[i] += step[j];
            }
            clamp(&mut cand, &lower, &upper);
            let c = problem.cost(&cand);
            if c.is_finite() && c < cost {
                let rel = (cost - c) / cost;
                let step_norm: f64 = main_free
                    .iter()
                    .map(|&i| (cand[i] - theta[i]).powi(2))
                    .sum::<f64>()
                    .sqrt();
                let th_norm: f64 = main_free
                    .iter()
                    .map(|&i| theta[i].powi(2))
                    .sum::<f64>()
                    .sqrt();
                theta = cand;
                cost = c;
                history.push(cost);
                lambda = (lambda / 5.0).max(1e-12);
                if rel < opts.rel_cost_tol {
                    termination = Termination::CostConverged;
                    break 'outer;
                }
                if step_norm <= opts.step_tol * th_norm.max(1e-300) {
                    termination = Termination::StepConverged;
                    break 'outer;
                }
                break;
            }
            lambda *= 8.0;
            if lambda > 1e12 {
                termination = Termination::NoDescent;
                break 'outer;
            }
        }
    }
    // covariance at the final point
    let p = free.len();
    let n_res = problem.n_residuals();
    let mut cov = DMatrix::zeros(np, np);
    let mut std = vec![0.0; np];
    let mut ssr = cost;
    if opts.covariance {
        let ne = problem.normal_equations(&theta, &free);
        ssr = ne.ssr;
        let sigma2 = ssr / (n_res as f64 - p as f64).max(1.0);
        let cinv = pinv_sym(&ne.jtj, 1e-13) * sigma2;
        for (a, &i) in free.iter().enumerate() {
            for (b, &j) in free.iter().enumerate() {
                cov[(i, j)] = cinv[(a, b)];
            }
            std[i] = cinv[(a, a)].max(0.0).sqrt();
        }
    }
    let sigma2 = ssr / (n_res as f64 - p as f64).max(1.0);
    Ok(LmFit {
        theta,
        std,
        cov,
        cost_history: history,
        ssr,
        sigma2,
        n_free: p,
        n_residuals: n_res,
        termination,
        iterations,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `y = a e^{−b t}` sampled at `t = 0, 0.1, …`: residuals and the
    /// analytic Jacobian, accumulated into normal equations.
    struct Exponential {
        t: Vec<f64>,
        y: Vec<f64>,
    }

    impl LeastSquares for Exponential {
        fn n_params(&self) -> usize {
            2
        }
        fn n_residuals(&self) -> usize {
            self.t.len()
        }
        fn cost(&self, th: &[f64]) -> f64 {
            self.t
                .iter()
                .zip(&self.y)
                .map(|(t, y)| (y - th[0] * (-th[1] * t).exp()).powi(2))
                .sum()
        }
        fn normal_equations(&self, th: &[f64], free: &[usize]) -> Normal {
            let p = free.len();
            let mut jtj = DMatrix::zeros(p, p);
            let mut jte = DVector::zeros(p);
            let mut ssr = 0.0;
            for (t, y) in self.t.iter().zip(&self.y) {
                let e = (-th[1] * t).exp();
                let r = y - th[0] * e;
                let full = [e, -th[0] * t * e];
                let row: Vec<f64> = free.iter().map(|&i| full[i]).collect();
                for i in 0..p {
                    for j in 0..p {
                        jtj[(i, j)] += row[i] * row[j];
                    }
                    jte[i] += row[i] * r;
                }
                ssr += r * r;
            }
            Normal { jtj, jte, ssr }
        }
    }

    fn exponential(a: f64, b: f64, noise: &[f64]) -> Exponential {
        let t: Vec<f64> = (0..noise.len()).map(|k| 0.1 * k as f64).collect();
        let y = t
            .iter()
            .zip(noise)
            .map(|(t, n)| a * (-b * t).exp() + n)
            .collect();
        Exponential { t, y }
    }

    #[test]
    fn minimize_recovers_exponential_from_a_distant_start() {
        let p = exponential(3.0, 0.7, &[0.0; 40]);
        let f = minimize(&p, &[1.0, 3.0], &LmOptions::default()).unwrap();
        assert!((f.theta[0] - 3.0).abs() < 1e-8, "{:?}", f.theta);
        assert!((f.theta[1] - 0.7).abs() < 1e-8, "{:?}", f.theta);
        assert!(f.termination != Termination::MaxIterations);
        assert!(f.cost_history.windows(2).all(|w| w[1] < w[0]));
    }

    /// Stopping within the noise ends a fit whose steps no longer move it by what the data
    /// resolve: the estimate stands within a tenth of its σ of the fully converged one, in
    /// fewer iterations; a bound the step pushes against does not keep it going.
    #[test]
    fn a_fit_within_the_noise_of_its_minimum_stops_there() {
        let mut rng = crate::ident::linalg::GaussRng::new(7);
        let noise = rng.normals(400, 0.05);
        let p = exponential(3.0, 0.7, &noise);
        let tight = LmOptions {
            rel_cost_tol: 1e-15,
            step_tol: 0.0,
            ..LmOptions::default()
        };
        let full = minimize(&p, &[1.0, 3.0], &tight).unwrap();
        let noisy = LmOptions {
            within_noise: 0.01,
            ..tight.clone()
        };
        let f = minimize(&p, &[1.0, 3.0], &noisy).unwrap();
        assert_eq!(f.termination, Termination::WithinNoise);
        assert!(
            f.iterations < full.iterations,
            "{} vs {}",
            f.iterations,
            full.iterations
        );
        for i in 0..2 {
            let moved = (f.theta[i] - full.theta[i]).abs() / full.std[i];
            assert!(moved < 0.1, "parameter {i} {moved} σ from the minimum");
        }
        // the amplitude held on a bound below its value, the rate at its best for it:
        // the step that pushes the amplitude out is left out, and nothing else is left
        let held = LmOptions {
            fixed: vec![true, false],
            ..tight
        };
        let at = minimize(&p, &[2.5, 3.0], &held).unwrap().theta;
        let ne = p.normal_equations(&at, &[0, 1]);
        let none = [false, false];
        let pushed = newton_decrement(&ne, &none, |j, step| j == 0 && step > 0.0);
        let free = newton_decrement(&ne, &none, |_, _| false);
        assert!(pushed < 1e-6 * full.sigma2, "{pushed}");
        assert!(free > 100.0 * full.sigma2, "{free}");
    }

    /// A parameter held on its bound by the data costs no more iterations than the same
    /// parameter fixed there: the step is solved without it, not solved with it and then
    /// clamped, which leaves the other parameters fitted to a move the bound forbids.
    #[test]
    fn a_parameter_on_its_bound_is_left_out_of_the_step() {
        let p = exponential(3.0, 0.7, &[0.0; 40]);
        let bounded = LmOptions {
            upper: vec![2.0, f64::INFINITY],
            rel_cost_tol: 1e-12,
            max_iter: 200,
            active_set: true,
            ..LmOptions::default()
        };
        let fixed = LmOptions {
            fixed: vec![true, false],
            ..bounded.clone()
        };
        let b = minimize(&p, &[2.0, 3.0], &bounded).unwrap();
        let f = minimize(&p, &[2.0, 3.0], &fixed).unwrap();
        assert_eq!(b.theta[0], 2.0);
        assert!(
            (b.theta[1] - f.theta[1]).abs() < 1e-6,
            "{:?} {:?}",
            b.theta,
            f.theta
        );
        assert!(
            b.iterations <= f.iterations + 1,
            "{} iterations on the bound, {} fixed",
            b.iterations,
            f.iterations
        );
    }

    #[test]
    fn minimize_honours_bounds_fixed_and_reports_them() {
        let p = exponential(3.0, 0.7, &[0.0; 40]);
        let opts = LmOptions {
            upper: vec![2.5, f64::INFINITY],
            ..LmOptions::default()
        };
        let f = minimize(&p, &[1.0, 3.0], &opts).unwrap();
        assert_eq!(f.theta[0], 2.5);
        assert_eq!(f.at_bounds(&opts), vec![0]);
        let opts = LmOptions {
            fixed: vec![true, false],
            ..LmOptions::default()
        };
        let f = minimize(&p, &[3.0, 2.0], &opts).unwrap();
        assert_eq!(f.theta[0], 3.0);
        assert_eq!(f.std[0], 0.0);
        assert!((f.theta[1] - 0.7).abs() < 1e-8);
        assert_eq!(f.n_free, 1);
    }

    #[test]
    fn weighted_residuals_give_a_chi2_near_its_degrees_of_freedom() {
        // unit-variance noise: Σe² at the optimum ≈ N − p
        let mut rng = crate::ident::linalg::GaussRng::new(7);
        let noise = rng.normals(2000, 1.0);
        let p = exponential(300.0, 0.01, &noise);
        let f = minimize(&p, &[200.0, 0.02], &LmOptions::default()).unwrap();
        let (chi2, dof) = f.chi2();
        assert_eq!(dof, 1998);
        // χ²(1998) has σ = √(2·1998) ≈ 63
        assert!((chi2 - dof as f64).abs() < 4.0 * 63.0, "χ² {chi2}");
        assert!((f.sigma2 - 1.0).abs() < 0.1, "σ² {}", f.sigma2);
    }

    #[test]
    fn minimize_rejects_wrong_lengths_and_non_finite_start() {
        let p = exponential(3.0, 0.7, &[0.0; 10]);
        let e = minimize(&p, &[1.0], &LmOptions::default()).unwrap_err();
        assert!(matches!(e, LmError::Length { got: 1, .. }), "{e}");
        let opts = LmOptions {
            fixed: vec![true],
            ..LmOptions::default()
        };
        assert!(minimize(&p, &[1.0, 1.0], &opts).is_err());
        let e = minimize(&p, &[f64::NAN, 1.0], &LmOptions::default()).unwrap_err();
        assert_eq!(e, LmError::NonFiniteStart);
    }
}
