//! A saved model for other tools (`jointid export-model`, `fit --save model.mat`): the
//! discrete state space of the model file, the continuous-time state space it samples,
//! both as transfer functions (coefficients and poles, zeros, gain), the input and output
//! with units and the physical parameters.
//!
//! The continuous model is the zero-order-hold inverse of the discrete one:
//! `[[F, G], [0, 0]] Ts = log([[A, B], [0, 1]])` (the relation of seed 000 eq. (12)–(13)
//! read backwards; Van Loan 1978 for the augmented matrix). The principal logarithm is
//! real exactly when `A` has no eigenvalue on the closed negative real axis; it is
//! computed by inverse scaling and squaring (Kenney and Laub, "Condition estimates for
//! matrix functions", SIAM J. Matrix Anal. Appl. 10(2), 1989): square roots by the
//! Denman–Beavers iteration until the matrix is within 0.25 of `I`, then the series of
//! `log(I + X)`; the result is checked by `exp` (nalgebra) against the matrix it came
//! from. For a physical model this returns the physical matrices of the fit (sampling
//! keeps the state basis).
//!
//! Transfer functions come from the poles (eigenvalues of `A`), the zeros
//! ([`siso_zeros`]) and the gain, the first non-zero Markov parameter `C A^{ρ−1} B`
//! (or `D` when it is not zero): `G(x) = k ∏(x − z_i) / ∏(x − p_i)`.
//!
//! No number that is not finite is exported ([`ExportError`]): a model file whose
//! matrices or sample interval hold a number of magnitude [`MAX_MAGNITUDE`] (1e100) or
//! more is refused, naming the entry (the eigenvalues and the coefficients take products
//! and sums of squares of them, as the script's `control.ss` does: `A = 1e308` wrote
//! `NaN` and `-inf` into the script), and so is a model whose derived numbers (the
//! continuous matrices, the transfer functions' coefficients, roots and gain) overflow,
//! naming which.
// Units in brackets (`[s]`, `[Hz]`) are not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

use std::collections::BTreeMap;

use nalgebra::{Complex, DMatrix, DVector, RowDVector};
use serde::Serialize;

use crate::data::mat::{MatOut, MatWriter};
use crate::data::screen::MAX_MAGNITUDE;
use crate::data::InputTaken;
use crate::ident::fit::ParamJson;
use crate::ident::model_file::{ModelFileError, SavedModel};
use crate::ident::ss::{eigenvalues, siso_zeros, ContinuousSs, StateSpace};

/// A SISO state space as JSON: `A` row by row, `B` and `C` as lists, `D`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SsJson {
    /// `A` (n × n), row by row
    pub a: Vec<Vec<f64>>,
    /// `B` (n)
    pub b: Vec<f64>,
    /// `C` (n)
    pub c: Vec<f64>,
    /// `D`
    pub d: f64,
}

impl SsJson {
    fn new(a: &DMatrix<f64>, b: &DVector<f64>, c: &RowDVector<f64>, d: f64) -> SsJson {
        SsJson {
            a: a.row_iter().map(|r| r.iter().copied().collect()).collect(),
            b: b.iter().copied().collect(),
            c: c.iter().copied().collect(),
            d,
        }
    }

    fn a_matrix(&self) -> DMatrix<f64> {
        let n = self.a.len();
        DMatrix::from_fn(n, n, |i, j| self.a[i][j])
    }
}

/// A transfer function: coefficients (highest power first) and its roots.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TransferFunction {
    /// numerator coefficients, highest power of `s` (or `z`) first
    pub num: Vec<f64>,
    /// denominator coefficients, highest power first, monic
    pub den: Vec<f64>,
    /// zeros as `[re, im]`
    pub zeros: Vec<[f64; 2]>,
    /// poles as `[re, im]`
    pub poles: Vec<[f64; 2]>,
    /// gain `k` of `k ∏(x − z_i) / ∏(x − p_i)`
    pub gain: f64,
}

/// The polynomial with these roots, monic, highest power first; complex pairs give real
/// coefficients (the imaginary parts left by rounding are dropped).
fn poly(roots: &[Complex<f64>]) -> Vec<f64> {
    let mut c = vec![Complex::new(1.0, 0.0)];
    for r in roots {
        let mut next = c.clone();
        next.push(Complex::new(0.0, 0.0));
        for (i, ci) in c.iter().enumerate() {
            next[i + 1] -= ci * r;
        }
        c = next;
    }
    c.into_iter().map(|x| x.re).collect()
}

impl TransferFunction {
    /// `C (xI − A)^{−1} B + D` as poles, zeros and gain, and as coefficients.
    pub fn of(a: &DMatrix<f64>, b: &DVector<f64>, c: &RowDVector<f64>, d: f64) -> Self {
        let poles = eigenvalues(a);
        let zeros = siso_zeros(a, b, c, d);
        let rho = poles.len().saturating_sub(zeros.len());
        let gain = if rho == 0 {
            d
        } else {
            let mut x = b.clone();
            for _ in 1..rho {
                x = a * x;
            }
            (c * x)[0]
        };
        let num: Vec<f64> = poly(&zeros).into_iter().map(|v| v * gain).collect();
        let pair = |z: &Complex<f64>| [z.re, z.im];
        TransferFunction {
            num,
            den: poly(&poles),
            zeros: zeros.iter().map(pair).collect(),
            poles: poles.iter().map(pair).collect(),
            gain,
        }
    }

    /// The value at the complex point `x` (`s = jω`, or `z = e^{jωTs}`), from the roots.
    pub fn at(&self, x: Complex<f64>) -> Complex<f64> {
        let c = |r: &[f64; 2]| Complex::new(r[0], r[1]);
        let num: Complex<f64> = self.zeros.iter().map(|z| x - c(z)).product();
        let den: Complex<f64> = self.poles.iter().map(|p| x - c(p)).product();
        num * self.gain / den
    }

    /// The value at `x` from the coefficients (Horner).
    pub fn at_coefficients(&self, x: Complex<f64>) -> Complex<f64> {
        let h = |p: &[f64]| {
            p.iter().fold(Complex::new(0.0, 0.0), |acc, &v| {
                acc * x + Complex::new(v, 0.0)
            })
        };
        h(&self.num) / h(&self.den)
    }
}

/// Largest number of square roots taken before the logarithm's series.
const MAX_SQUARE_ROOTS: usize = 64;

/// Principal square root by the Denman–Beavers iteration; `None` when it does not
/// converge or a matrix is singular.
fn sqrtm(m: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let n = m.nrows();
    let mut y = m.clone();
    let mut z = DMatrix::<f64>::identity(n, n);
    for _ in 0..100 {
        let yi = y.clone().try_inverse()?;
        let zi = z.clone().try_inverse()?;
        let y1 = (&y + zi) * 0.5;
        let z1 = (&z + yi) * 0.5;
        let step = (&y1 - &y).norm();
        y = y1;
        z = z1;
        // quadratic convergence: the error left is of the order of the step squared
        if step <= 1e-12 * y.norm() {
            return Some(y);
        }
    }
    None
}

/// Why a discrete model has no continuous one ([`continuous_of`]).
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum ContinuousError {
    /// a real pole at or left of 0 (its value): no real logarithm
    #[error(
        "the discrete pole {0} lies on the negative real axis: no real continuous-time model \
         samples to it"
    )]
    NegativeRealPole(f64),
    /// the repeated square roots do not approach `I` within `MAX_SQUARE_ROOTS` of them
    #[error("the square roots do not approach the identity")]
    SquareRoots,
    /// a square root's iteration does not converge
    #[error("the square-root iteration does not converge")]
    SquareRoot,
    /// the logarithm, exponentiated, is this far from the matrix (relative)
    #[error("the matrix logarithm is off by {0:.1e} (relative) when exponentiated")]
    Check(f64),
}

/// Principal matrix logarithm (inverse scaling and squaring), or why there is no real one.
fn logm(m: &DMatrix<f64>) -> Result<DMatrix<f64>, ContinuousError> {
    let n = m.nrows();
    let eye = DMatrix::<f64>::identity(n, n);
    let mut r = m.clone();
    let mut k = 0;
    while (&r - &eye).norm() > 0.25 {
        if k == MAX_SQUARE_ROOTS {
            return Err(ContinuousError::SquareRoots);
        }
        r = sqrtm(&r).ok_or(ContinuousError::SquareRoot)?;
        k += 1;
    }
    let x = &r - &eye;
    // log(I + X) = X − X²/2 + X³/3 − …; ‖X‖ ≤ 0.25 leaves < 1e-19 after 30 terms
    let mut term = x.clone();
    let mut sum = x.clone();
    for j in 2..=30 {
        term = -(&term * &x);
        sum += &term / f64::from(j);
    }
    Ok(sum * 2f64.powi(k as i32))
}

/// The continuous model whose zero-order-hold sampling at `ss.ts` is `ss` (see the
/// module's doc).
///
/// # Errors
/// [`ContinuousError`], why there is none: an eigenvalue of `A` on the closed negative
/// real axis (no real logarithm), or the logarithm failing its check by `exp`.
pub fn continuous_of(ss: &StateSpace) -> Result<ContinuousSs, ContinuousError> {
    let n = ss.order();
    if let Some(l) = ss
        .poles()
        .into_iter()
        .find(|l| l.re <= 0.0 && l.im.abs() <= 1e-12 * l.norm().max(1e-300))
    {
        return Err(ContinuousError::NegativeRealPole(l.re));
    }
    // the input column scaled to a norm of 0.1 (`diag(I, 1/β)` is a similarity: the
    // logarithm's last column scales by β alike), so that its size does not add square
    // roots
    let bn = ss.b.norm();
    let beta = if bn > 0.0 { 0.1 / bn } else { 1.0 };
    let mut m = DMatrix::<f64>::identity(n + 1, n + 1);
    m.view_mut((0, 0), (n, n)).copy_from(&ss.a);
    m.view_mut((0, n), (n, 1)).copy_from(&(&ss.b * beta));
    let l = logm(&m)?;
    let back = l.clone().exp();
    let err = (&back - &m).norm() / m.norm();
    if err.is_nan() || err > 1e-9 {
        return Err(ContinuousError::Check(err));
    }
    Ok(ContinuousSs {
        f: l.view((0, 0), (n, n)).into_owned() / ss.ts,
        g: l.view((0, n), (n, 1)).column(0).into_owned() / (ss.ts * beta),
        h: ss.c.clone(),
        d: ss.d,
    })
}

/// One signal: name and unit.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Signal {
    /// name (`u`, `theta_m`)
    pub name: String,
    /// unit (`N m`, `rad`)
    pub unit: String,
}

/// Everything `export-model` writes, in every form.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ModelExport {
    /// model family (`two-mass`, `black-box:4`)
    pub model: String,
    /// how it was estimated
    pub method: String,
    /// the estimation data file
    pub source: String,
    /// the input (torque reference, or force on a linear axis)
    pub input: Signal,
    /// the output (motor angle or velocity, or position on a linear axis)
    pub output: Signal,
    /// sample interval of the discrete model [s]
    pub ts: f64,
    /// discrete state space at `ts` (`x(k+1) = A x(k) + B u(k)`, `y = C x + D u`)
    pub discrete: SsJson,
    /// continuous state space (`ẋ = A x + B u`), when one samples to the discrete one
    pub continuous: Option<SsJson>,
    /// why there is no continuous model, when there is none
    #[serde(skip_serializing_if = "Option::is_none")]
    pub continuous_note: Option<String>,
    /// discrete transfer function in `z`
    pub discrete_tf: TransferFunction,
    /// continuous transfer function in `s`
    pub continuous_tf: Option<TransferFunction>,
    /// physical parameters with σ and unit (empty for a black box)
    pub parameters: BTreeMap<String, ParamJson>,
    /// FIT on the estimation data [%]
    pub fit_estimation: f64,
    /// which FIT that is (the toolbox's when absent)
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fit_name: Option<String>,
    /// how the model reads its input samples (absent: held, as the discrete model's
    /// zero-order hold has them)
    #[serde(skip_serializing_if = "InputTaken::is_held")]
    pub input_taken: InputTaken,
}

/// Why a model file cannot be exported ([`ModelExport::of`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ExportError {
    /// the file does not read back as a linear model
    #[error(transparent)]
    Model(#[from] ModelFileError),
    /// a number of the model file no export computes with
    #[error(
        "{what} = {value:e}: the model's numbers must be finite and of magnitude below \
         {MAX_MAGNITUDE:e} (its eigenvalues and transfer functions, here and in the exported \
         script, multiply them)"
    )]
    Magnitude {
        /// where it is (`A row 1, column 2`, `parameter k_g (std)`)
        what: String,
        /// the number
        value: f64,
    },
    /// a parameter, or a number the export derives from the model, that is not finite
    /// (the derived ones overflow)
    #[error("{what} is {value}, not a finite number: the model cannot be exported")]
    NotFinite {
        /// which (`parameter `k_g` (std)`, `the discrete transfer function's denominator,
        /// coefficient 3`)
        what: String,
        /// the number (NaN or infinite)
        value: f64,
    },
}

/// The first entry of `values` (`(where, number)`) that is not finite, or whose magnitude
/// reaches `limit`.
fn first_beyond(
    values: impl IntoIterator<Item = (String, f64)>,
    limit: f64,
) -> Option<(String, f64)> {
    values
        .into_iter()
        .find(|(_, v)| !v.is_finite() || v.abs() >= limit)
}

/// Every number of a state space with where it is (`A row 1, column 2`, 1-based; `B entry
/// 3`), `prefix` naming the model.
fn ss_numbers(prefix: &str, s: &SsJson) -> Vec<(String, f64)> {
    let mut v = Vec::new();
    for (i, row) in s.a.iter().enumerate() {
        for (j, &x) in row.iter().enumerate() {
            v.push((format!("{prefix}A row {}, column {}", i + 1, j + 1), x));
        }
    }
    for (name, col) in [("B", &s.b), ("C", &s.c)] {
        for (i, &x) in col.iter().enumerate() {
            v.push((format!("{prefix}{name} entry {}", i + 1), x));
        }
    }
    v.push((format!("{prefix}D"), s.d));
    v
}

/// Every number of a transfer function with where it is, `what` naming it.
fn tf_numbers(what: &str, t: &TransferFunction) -> Vec<(String, f64)> {
    let mut v = Vec::new();
    for (part, coefficients) in [("numerator", &t.num), ("denominator", &t.den)] {
        for (i, &x) in coefficients.iter().enumerate() {
            v.push((format!("{what}'s {part}, coefficient {}", i + 1), x));
        }
    }
    for (part, roots) in [("zero", &t.zeros), ("pole", &t.poles)] {
        for (i, r) in roots.iter().enumerate() {
            v.push((format!("{what}'s {part} {}, real part", i + 1), r[0]));
            v.push((format!("{what}'s {part} {}, imaginary part", i + 1), r[1]));
        }
    }
    v.push((format!("{what}'s gain"), t.gain));
    v
}

/// The linear-axis unit of a rotary one (force [N] → position [m]).
pub fn linear_axis_unit(rotary: &str) -> &str {
    match rotary {
        "kg·m²" => "kg",
        "N·m·s/rad" => "N·s/m",
        "N·m/rad" => "N/m",
        "N·m" => "N",
        "rad" => "m",
        "rad/s" => "m/s",
        o => o,
    }
}

impl ModelExport {
    /// The export of a linear model file; `linear_axis`: units of force [N] and position
    /// [m] instead of torque and angle.
    ///
    /// # Errors
    /// [`ExportError::Model`] when the file is inconsistent or the model nonlinear (it has
    /// no state space); [`ExportError::Magnitude`] naming the first entry of `A`, `B`, `C`,
    /// `D` or `Ts` that is not finite or of magnitude [`MAX_MAGNITUDE`] or more;
    /// [`ExportError::NotFinite`] naming the first parameter value or σ that is not finite
    /// (they are written, not computed with), or the first derived number that overflows.
    pub fn of(saved: &SavedModel, linear_axis: bool) -> Result<ModelExport, ExportError> {
        let discrete = SsJson {
            a: saved.a.clone(),
            b: saved.b.clone(),
            c: saved.c.clone(),
            d: saved.d,
        };
        let own = ss_numbers("", &discrete)
            .into_iter()
            .chain(std::iter::once(("Ts".to_string(), saved.ts)));
        let params = saved.parameters.iter().flat_map(|(k, p)| {
            [
                (format!("parameter `{k}` (value)"), p.value),
                (format!("parameter `{k}` (std)"), p.std),
            ]
        });
        if let Some((what, value)) = first_beyond(own, MAX_MAGNITUDE) {
            return Err(ExportError::Magnitude { what, value });
        }
        if let Some((what, value)) = first_beyond(params, f64::INFINITY) {
            return Err(ExportError::NotFinite { what, value });
        }
        let fitted = saved.to_fitted()?;
        let ss = &fitted.model;
        let unit = |u: &str| {
            if linear_axis {
                linear_axis_unit(u).to_string()
            } else {
                u.to_string()
            }
        };
        let (out_name, out_unit) = match saved.output.as_str() {
            "velocity" => ("omega_m", "rad/s"),
            _ => ("theta_m", "rad"),
        };
        let (continuous, continuous_note) = match continuous_of(ss) {
            Ok(c) => (Some(c), None),
            Err(e) => (None, Some(e.to_string())),
        };
        let mut parameters = saved.parameters.clone();
        for p in parameters.values_mut() {
            p.unit = unit(&p.unit);
        }
        let ex = ModelExport {
            model: saved.model.clone(),
            method: saved.method.clone(),
            source: saved.source.clone(),
            input: Signal {
                name: "u".into(),
                unit: unit("N·m"),
            },
            output: Signal {
                name: out_name.into(),
                unit: unit(out_unit),
            },
            ts: ss.ts,
            discrete: SsJson::new(&ss.a, &ss.b, &ss.c, ss.d),
            continuous_tf: continuous
                .as_ref()
                .map(|c| TransferFunction::of(&c.f, &c.g, &c.h, c.d)),
            continuous: continuous.map(|c| SsJson::new(&c.f, &c.g, &c.h, c.d)),
            continuous_note,
            discrete_tf: TransferFunction::of(&ss.a, &ss.b, &ss.c, ss.d),
            parameters,
            fit_estimation: saved.fit_estimation,
            fit_name: saved.fit_name.clone(),
            input_taken: saved.input,
        };
        let derived = ex
            .continuous
            .iter()
            .flat_map(|c| ss_numbers("the continuous model's ", c))
            .chain(tf_numbers(
                "the discrete transfer function",
                &ex.discrete_tf,
            ))
            .chain(
                ex.continuous_tf
                    .iter()
                    .flat_map(|t| tf_numbers("the continuous transfer function", t)),
            )
            .map(|(what, v)| (format!("{what}, computed from the model's matrices,"), v));
        match first_beyond(derived, f64::INFINITY) {
            Some((what, value)) => Err(ExportError::NotFinite { what, value }),
            None => Ok(ex),
        }
    }

    /// The discrete model as a [`StateSpace`].
    pub fn discrete_ss(&self) -> StateSpace {
        let d = &self.discrete;
        StateSpace::new(
            d.a_matrix(),
            DVector::from_vec(d.b.clone()),
            RowDVector::from_vec(d.c.clone()),
            d.d,
            self.ts,
        )
    }

    /// The continuous model, when there is one.
    pub fn continuous_ss(&self) -> Option<ContinuousSs> {
        self.continuous.as_ref().map(|c| ContinuousSs {
            f: c.a_matrix(),
            g: DVector::from_vec(c.b.clone()),
            h: RowDVector::from_vec(c.c.clone()),
            d: c.d,
        })
    }

    /// A one-line description of the signals (`u [N·m] -> theta_m [rad]`).
    pub fn signals(&self) -> String {
        format!(
            "{} [{}] -> {} [{}]",
            self.input.name, self.input.unit, self.output.name, self.output.unit
        )
    }

    /// The MAT-file: `Ad, Bd, Cd, Dd, Ts`; `A, B, C, D` when continuous; `numd, dend` and
    /// `num, den`; `params` and `params_std` (structs of scalars), `FIT`, and the text
    /// `description` naming the signals, units and the model.
    pub fn to_mat(&self) -> Vec<u8> {
        let mut w = MatWriter::new(&format!("jointid model {}", self.model));
        put_ss(&mut w, &self.discrete, "d");
        w.var("Ts", &MatOut::scalar(self.ts));
        if let Some(c) = &self.continuous {
            put_ss(&mut w, c, "");
        }
        w.var("numd", &MatOut::row(&self.discrete_tf.num))
            .var("dend", &MatOut::row(&self.discrete_tf.den));
        if let Some(tf) = &self.continuous_tf {
            w.var("num", &MatOut::row(&tf.num))
                .var("den", &MatOut::row(&tf.den));
        }
        mat_params(&mut w, &self.parameters);
        w.var("FIT", &MatOut::scalar(self.fit_estimation));
        w.var("description", &MatOut::Text(self.description()));
        w.finish()
    }

    /// The text that says what the matrices are.
    pub fn description(&self) -> String {
        let units: Vec<String> = self
            .parameters
            .iter()
            .map(|(k, p)| format!("{k} [{}]", p.unit))
            .collect();
        format!(
            "jointid model {} ({}), {}; discrete Ad,Bd,Cd,Dd at Ts = {} s (zero-order hold){}{}; \
             FIT {} % on the estimation data {}{}",
            self.model,
            self.method,
            self.signals(),
            self.ts,
            match self.input_taken {
                InputTaken::Held => "",
                InputTaken::Sampled => {
                    ", fitted on its input taken as sampled: hold (7(u[k]+u[k+1]) - \
                     (u[k-1]+u[k+2]))/12, not u[k], over each interval"
                }
            },
            if self.continuous.is_some() {
                "; continuous A,B,C,D"
            } else {
                ""
            },
            self.fit_estimation,
            self.source,
            if units.is_empty() {
                String::new()
            } else {
                format!("; parameters {}", units.join(", "))
            }
        )
    }
}

fn put_ss(w: &mut MatWriter, s: &SsJson, suffix: &str) {
    w.var(&format!("A{suffix}"), &MatOut::from_rows(&s.a))
        .var(&format!("B{suffix}"), &MatOut::column(&s.b))
        .var(&format!("C{suffix}"), &MatOut::row(&s.c))
        .var(&format!("D{suffix}"), &MatOut::scalar(s.d));
}

/// `params` and `params_std`: structs of the parameters' values and σ, when there are any.
fn mat_params(w: &mut MatWriter, parameters: &BTreeMap<String, ParamJson>) {
    if parameters.is_empty() {
        return;
    }
    let fields = |f: fn(&ParamJson) -> f64| {
        MatOut::Struct(
            parameters
                .iter()
                .map(|(k, p)| (k.clone(), MatOut::scalar(f(p))))
                .collect(),
        )
    };
    w.var("params", &fields(|p| p.value))
        .var("params_std", &fields(|p| p.std));
}

/// The MAT-file of a model file that has no state space (a model with effects, simulated
/// with the exact laws): its parameters, FIT and a description only.
pub fn nonlinear_mat(saved: &SavedModel) -> Vec<u8> {
    let mut w = MatWriter::new(&format!("jointid model {}", saved.model));
    mat_params(&mut w, &saved.parameters);
    w.var("FIT", &MatOut::scalar(saved.fit_estimation));
    w.var(
        "description",
        &MatOut::Text(format!(
            "jointid model {} ({}): simulated with its nonlinear laws, no state space{}; \
             parameters {}; FIT {} % on {}",
            saved.model,
            saved.method,
            match saved.input {
                InputTaken::Held => "",
                InputTaken::Sampled => ", its input taken as sampled",
            },
            saved
                .parameters
                .iter()
                .map(|(k, p)| format!("{k} [{}]", p.unit))
                .collect::<Vec<_>>()
                .join(", "),
            saved.fit_estimation,
            saved.source
        )),
    );
    w.finish()
}

/// The MAT-file of any model file: [`ModelExport::to_mat`], or [`nonlinear_mat`] for a
/// model with effects.
///
/// # Errors
/// As [`ModelExport::of`] for a linear model file.
pub fn model_mat(saved: &SavedModel) -> Result<Vec<u8>, ExportError> {
    if saved.nonlinear.is_some() {
        return Ok(nonlinear_mat(saved));
    }
    Ok(ModelExport::of(saved, false)?.to_mat())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// motor and arm through a spring (angle output, an integrator), as the two-mass
    /// structure has it
    fn two_mass() -> ContinuousSs {
        let (jm, ja, k, d, fm) = (2e-3, 8e-3, 40.0, 0.02, 1e-3);
        ContinuousSs {
            f: DMatrix::from_row_slice(
                4,
                4,
                &[
                    0.0,
                    1.0,
                    0.0,
                    0.0, //
                    -k / jm,
                    -(d + fm) / jm,
                    k / jm,
                    d / jm, //
                    0.0,
                    0.0,
                    0.0,
                    1.0, //
                    k / ja,
                    d / ja,
                    -k / ja,
                    -d / ja,
                ],
            ),
            g: DVector::from_vec(vec![0.0, 1.0 / jm, 0.0, 0.0]),
            h: RowDVector::from_vec(vec![1.0, 0.0, 0.0, 0.0]),
            d: 0.0,
        }
    }

    #[test]
    fn continuous_of_inverts_the_zero_order_hold() {
        let c = two_mass();
        for ts in [5e-4, 1e-2] {
            let back = continuous_of(&c.zoh(ts)).unwrap();
            let rel = (&back.f - &c.f).norm() / c.f.norm();
            let relg = (&back.g - &c.g).norm() / c.g.norm();
            assert!(rel < 1e-8 && relg < 1e-8, "ts {ts}: F {rel:e}, G {relg:e}");
        }
        // a pole on the negative real axis has no real logarithm
        let s = StateSpace::new(
            DMatrix::from_element(1, 1, -0.5),
            DVector::from_element(1, 1.0),
            RowDVector::from_element(1, 1.0),
            0.0,
            0.01,
        );
        let e = continuous_of(&s).unwrap_err();
        assert_eq!(e, ContinuousError::NegativeRealPole(-0.5));
        assert!(
            e.to_string()
                .contains("-0.5 lies on the negative real axis"),
            "{e}"
        );
    }

    /// A one-state model file (`x(k+1) = a x + u`, `y = x`) with a parameter.
    fn one_state(a: f64) -> SavedModel {
        let mut m: SavedModel = serde_json::from_value(serde_json::json!({
            "format": crate::ident::model_file::MODEL_FORMAT, "model": "black-box:1",
            "method": "test", "output": "angle", "ts": 5e-4,
            "prep": {"decimate": 1, "detrend": "none"},
            "a": [[0.5]], "b": [1.0], "c": [1.0], "d": 0.0,
            "parameters": {"J": {"value": 2e-3, "std": 1e-5, "unit": "kg·m²"}},
            "friction": null, "fit_estimation": 90.0, "source": "test",
        }))
        .unwrap();
        // (JSON holds no NaN)
        m.a[0][0] = a;
        m
    }

    /// The description of a model fitted on its input taken as sampled says how to drive
    /// its zero-order-hold matrices; a held model's says nothing of it.
    #[test]
    fn a_sampled_input_model_says_how_to_drive_its_matrices() {
        let mut saved = one_state(0.5);
        let held = ModelExport::of(&saved, false).unwrap().description();
        assert!(!held.contains("taken as sampled"), "{held}");
        saved.input = InputTaken::Sampled;
        let sampled = ModelExport::of(&saved, false).unwrap().description();
        assert!(
            sampled.contains("taken as sampled: hold (7(u[k]+u[k+1])"),
            "{sampled}"
        );
    }

    #[test]
    fn a_model_with_a_number_beyond_computing_or_not_finite_is_refused_naming_it() {
        assert!(ModelExport::of(&one_state(0.5), false).is_ok());
        // `A = 1e308` wrote `NaN` and `-inf` into the python-control script
        for a in [1e308, 1e100, -1e100, f64::NAN] {
            let e = ModelExport::of(&one_state(a), false).unwrap_err();
            assert!(matches!(e, ExportError::Magnitude { .. }), "{a}: {e}");
            assert!(
                e.to_string().starts_with("A row 1, column 1 = "),
                "{a}: {e}"
            );
        }
        let mut m = one_state(0.5);
        m.ts = 1e200;
        let e = ModelExport::of(&m, false).unwrap_err().to_string();
        assert!(e.starts_with("Ts = 1e200: "), "{e}");
        // a parameter is written, not computed with: refused only when not finite
        let mut m = one_state(0.5);
        m.parameters.get_mut("J").unwrap().std = f64::INFINITY;
        let e = ModelExport::of(&m, false).unwrap_err().to_string();
        assert_eq!(
            e,
            "parameter `J` (std) is inf, not a finite number: the model cannot be exported"
        );
        m.parameters.get_mut("J").unwrap().std = 1e300;
        assert!(ModelExport::of(&m, false).is_ok());
    }

    #[test]
    fn transfer_functions_match_the_state_space_frequency_response() {
        let c = two_mass();
        let ts = 1e-3;
        let d = c.zoh(ts);
        let f = [0.5, 3.0, 12.0, 40.0, 200.0];
        let tc = TransferFunction::of(&c.f, &c.g, &c.h, c.d);
        let td = TransferFunction::of(&d.a, &d.b, &d.c, d.d);
        assert_eq!((tc.den.len(), tc.num.len()), (5, 3));
        assert_eq!((td.den.len(), td.num.len()), (5, 4));
        for (k, (gc, gd)) in c
            .freq_response(&f)
            .into_iter()
            .zip(d.freq_response(&f))
            .enumerate()
        {
            let w = 2.0 * std::f64::consts::PI * f[k];
            let s = Complex::new(0.0, w);
            let z = Complex::new((w * ts).cos(), (w * ts).sin());
            for (what, g, t) in [
                ("s roots", gc, tc.at(s)),
                ("s coefficients", gc, tc.at_coefficients(s)),
                ("z roots", gd, td.at(z)),
                ("z coefficients", gd, td.at_coefficients(z)),
            ] {
                let rel = (g - t).norm() / g.norm();
                assert!(rel < 1e-6, "{what} at {} Hz: {rel:e}", f[k]);
            }
        }
    }
}
