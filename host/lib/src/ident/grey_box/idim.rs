//! Inverse-dynamics least squares of the rigid body (seed 001 step 1–2): inertia,
//! viscous and Coulomb friction and a torque offset from the filtered acceleration.

use super::*;

/// Options of [`rigid_idim`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IdimOptions {
    /// output signal of the data
    pub output: Output,
    /// cut-off of the zero-phase Butterworth low-pass applied to output and
    /// input alike before differentiation [Hz]; 0 picks `0.02 / Ts`
    pub cutoff_hz: f64,
    /// order of that low-pass (even; applied forward and backward)
    pub filter_order: usize,
    /// include Coulomb friction `F_c sgn(q̇)`
    pub coulomb: bool,
    /// include a constant torque offset (not with `asymmetric`)
    pub offset: bool,
    /// with `coulomb`: friction that differs with the direction of motion (Janot, Gautier
    /// & Brunot 2019, EMPS reference model): `F_v q̇` and `F_c` for `q̇ > 0`, `F_v− q̇` and
    /// `−F_c−` for `q̇ < 0`, names `Fv`, `Fc`, `Fv_neg`, `Fc_neg`. The offset is left out:
    /// while the axis moves it equals half the difference of the Coulomb levels, and the
    /// regressors would be collinear.
    pub asymmetric: bool,
    /// keep one sample in `decimate` after filtering (1: all)
    pub decimate: usize,
    /// include a stiffness to ground `K q` (name `K` [N·m/rad]: `k_0` of the grounded
    /// structure); angle output only
    pub spring: bool,
}

impl Default for IdimOptions {
    fn default() -> Self {
        Self {
            output: Output::Angle,
            cutoff_hz: 0.0,
            filter_order: 4,
            coulomb: true,
            offset: true,
            asymmetric: false,
            decimate: 1,
            spring: false,
        }
    }
}

/// Result of [`rigid_idim`].
#[derive(Clone, Debug, PartialEq)]
pub struct RigidFit {
    /// `J`, `Fv`, then `Fc` and `offset` when asked for
    pub params: Vec<PhysParam>,
    /// relative torque error `100 ‖u − û‖ / ‖u‖` [%] on the filtered data
    pub rel_error_percent: f64,
    /// samples used in the regression
    pub samples: usize,
}

impl RigidFit {
    /// value of a parameter by name
    pub fn get(&self, name: &str) -> Option<f64> {
        self.params.iter().find(|p| p.name == name).map(|p| p.value)
    }
}

/// Inverse-dynamics least squares of the rigid body (seed 001 steps 1–2):
/// `u = J q̈ + F_v q̇ + F_c sgn(q̇) + offset` (or the asymmetric friction of
/// [`IdimOptions::asymmetric`]; `+ K q` with [`IdimOptions::spring`]), with `q̇`, `q̈` from central
/// differences of the zero-phase low-passed output and `u` low-passed by the
/// same filter ("parallel filtering", which keeps the equation exact for
/// the filtered signals). Standard deviations from `σ̂² (ΦᵀΦ)^{−1}`
/// (optimistic: the filtered residuals are coloured).
///
/// # Errors
/// [`GreyBoxError::BadData`] for short or non-finite data,
/// [`GreyBoxError::TooFewAfterTrim`],
/// [`GreyBoxError::Singular`] when the regressors are collinear.
pub fn rigid_idim(data: &IdData, opts: &IdimOptions) -> Result<RigidFit, GreyBoxError> {
    data.check(50)?;
    let n = data.u.len();
    let ts = data.ts;
    let fc = if opts.cutoff_hz > 0.0 {
        opts.cutoff_hz
    } else {
        0.02 / ts
    };
    let yf = filtfilt_lowpass(&data.y, opts.filter_order, fc, ts);
    let uf = filtfilt_lowpass(&data.u, opts.filter_order, fc, ts);
    let (qd, qdd) = match opts.output {
        Output::Angle => {
            let qd = central_diff(&yf, ts);
            let qdd = central_diff(&qd, ts);
            (qd, qdd)
        }
        Output::Velocity => {
            let qdd = central_diff(&yf, ts);
            (yf.clone(), qdd)
        }
    };
    let edge = ((2.0 / (fc * ts)).ceil() as usize).min(n / 4);
    let asym = opts.coulomb && opts.asymmetric;
    let mut names = vec!["J", "Fv"];
    if opts.coulomb {
        names.push("Fc");
    }
    if asym {
        names.extend(["Fv_neg", "Fc_neg"]);
    }
    let offset = opts.offset && !asym;
    if offset {
        names.push("offset");
    }
    let spring = opts.spring && opts.output == Output::Angle;
    if spring {
        names.push("K");
    }
    let p = names.len();
    let mut m = DMatrix::<f64>::zeros(p, p);
    let mut rhs = DMatrix::<f64>::zeros(p, 1);
    let mut uu = 0.0;
    let mut count = 0;
    let step = opts.decimate.max(1);
    let mut phi = vec![0.0; p];
    let mut rows = Vec::new();
    for t in (edge..n - edge).step_by(step) {
        phi[0] = qdd[t];
        phi[1] = qd[t];
        let mut k = 2;
        if asym {
            let (pos, neg) = (qd[t] > 0.0, qd[t] < 0.0);
            phi[1] = if pos { qd[t] } else { 0.0 };
            phi[2] = f64::from(u8::from(pos));
            phi[3] = if neg { qd[t] } else { 0.0 };
            phi[4] = -f64::from(u8::from(neg));
            k = 5;
        } else if opts.coulomb {
            phi[k] = qd[t].signum() * f64::from(u8::from(qd[t] != 0.0));
            k += 1;
        }
        if offset {
            phi[k] = 1.0;
            k += 1;
        }
        if spring {
            phi[k] = yf[t];
        }
        for i in 0..p {
            for j in 0..p {
                m[(i, j)] += phi[i] * phi[j];
            }
            rhs[(i, 0)] += phi[i] * uf[t];
        }
        uu += uf[t] * uf[t];
        count += 1;
        rows.push((phi.clone(), uf[t]));
    }
    if count <= p {
        return Err(GreyBoxError::TooFewAfterTrim {
            left: count,
            params: p,
        });
    }
    let th = solve_spd(&m, &rhs, 0.0).ok_or(GreyBoxError::Singular("rigid inverse dynamics"))?;
    let mut ssr = 0.0;
    for (phi, u) in &rows {
        let pred: f64 = phi.iter().enumerate().map(|(i, v)| v * th[(i, 0)]).sum();
        ssr += (u - pred) * (u - pred);
    }
    let s2 = ssr / (count - p) as f64;
    let inv = m
        .clone()
        .try_inverse()
        .unwrap_or_else(|| crate::ident::linalg::pinv_sym(&m, 1e-14));
    let params = names
        .iter()
        .enumerate()
        .map(|(i, name)| PhysParam {
            name: name.to_string(),
            value: th[(i, 0)],
            std: (s2 * inv[(i, i)]).max(0.0).sqrt(),
            unit: unit_of(name),
        })
        .collect();
    Ok(RigidFit {
        params,
        rel_error_percent: 100.0 * (ssr / uu).sqrt(),
        samples: count,
    })
}

// ---------------------------------------------------------------------------
// initial values
