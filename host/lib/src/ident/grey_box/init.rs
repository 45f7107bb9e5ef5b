//! Initial values of the physical parameters from the data (module docs of [`super`]):
//! the features of a subspace model (resonances, anti-resonances, rigid-body gain) and the
//! chain whose undamped eigenfrequencies match them.

use super::*;

/// Rigid-body and modal features read from the data for the initial values.
#[derive(Clone, Debug, PartialEq)]
pub struct Features {
    /// total inertia seen by the motor `J_m + r²(J_a1 + …)` [kg·m²]
    pub j_total: f64,
    /// motor viscous friction [N·m·s/rad]
    pub f_m: f64,
    /// anti-resonance / resonance pairs `(z_i, p_i)` [Hz], ascending
    pub pairs: Vec<(f64, f64)>,
    /// damping ratio of the lowest resonance [-]
    pub zeta1: f64,
    /// order of the subspace model the frequencies came from
    pub subspace_order: usize,
}

/// Motor-side chain values (all multiplied by `r²` on the arm side).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Chain {
    pub(super) jm: f64,
    pub(super) j1: f64,
    pub(super) j2: f64,
    pub(super) jp: f64,
    pub(super) kg: f64,
    pub(super) ka: f64,
    pub(super) kp: f64,
}

impl Chain {
    /// mass and stiffness matrices of the undamped chain, DOFs
    /// `[motor, a1, a2, p]` truncated to `masses`
    pub(super) fn mk(&self, masses: usize) -> (Vec<f64>, DMatrix<f64>) {
        let mut k = DMatrix::zeros(masses, masses);
        let mut add = |i: usize, j: usize, s: f64| {
            k[(i, i)] += s;
            k[(j, j)] += s;
            k[(i, j)] -= s;
            k[(j, i)] -= s;
        };
        let mut m = vec![self.jm];
        if masses >= 2 {
            add(0, 1, self.kg);
            m.push(self.j1);
        }
        if masses >= 3 {
            add(1, 2, self.ka);
            m.push(self.j2);
        }
        if masses >= 4 {
            add(1, 3, self.kp);
            m.push(self.jp);
        }
        (m, k)
    }

    /// undamped eigenfrequencies [rad/s]: free chain (rigid mode dropped)
    /// and motor held
    pub(super) fn frequencies(&self, masses: usize) -> (Vec<f64>, Vec<f64>) {
        let (m, k) = self.mk(masses);
        let eig = |m: &[f64], k: DMatrix<f64>| -> Vec<f64> {
            let s = DMatrix::from_fn(m.len(), m.len(), |i, j| k[(i, j)] / (m[i] * m[j]).sqrt());
            let mut v: Vec<f64> = SymmetricEigen::new(s)
                .eigenvalues
                .iter()
                .map(|l| l.max(0.0).sqrt())
                .collect();
            v.sort_by(f64::total_cmp);
            v
        };
        let mut free = eig(&m, k.clone());
        free.remove(0);
        let held = eig(
            &m[1..],
            k.view((1, 1), (masses - 1, masses - 1)).into_owned(),
        );
        (free, held)
    }

    pub(super) fn log_vec(&self, masses: usize) -> Vec<f64> {
        let all = [
            self.jm, self.j1, self.j2, self.jp, self.kg, self.ka, self.kp,
        ];
        let idx: &[usize] = match masses {
            2 => &[0, 1, 4],
            3 => &[0, 1, 2, 4, 5],
            _ => &[0, 1, 2, 3, 4, 5, 6],
        };
        idx.iter().map(|&i| all[i].ln()).collect()
    }

    pub(super) fn with_log(&self, masses: usize, v: &[f64]) -> Chain {
        let mut c = *self;
        let e: Vec<f64> = v.iter().map(|x| x.exp()).collect();
        match masses {
            2 => {
                c.jm = e[0];
                c.j1 = e[1];
                c.kg = e[2];
            }
            3 => {
                c.jm = e[0];
                c.j1 = e[1];
                c.j2 = e[2];
                c.kg = e[3];
                c.ka = e[4];
            }
            _ => {
                c.jm = e[0];
                c.j1 = e[1];
                c.j2 = e[2];
                c.jp = e[3];
                c.kg = e[4];
                c.ka = e[5];
                c.kp = e[6];
            }
        }
        c
    }
}

/// Closed-form motor-side chain from `J` and the pairs (module docs, step 3).
pub(super) fn chain_closed_form(masses: usize, j: f64, pairs: &[(f64, f64)]) -> Chain {
    let w = |f: f64| 2.0 * std::f64::consts::PI * f;
    let mut c = Chain {
        jm: j,
        j1: 0.0,
        j2: 0.0,
        jp: 0.0,
        kg: 0.0,
        ka: 0.0,
        kp: 0.0,
    };
    match masses {
        2 => {
            let (z, p) = (w(pairs[0].0), w(pairs[0].1));
            c.jm = j * z * z / (p * p);
            c.kg = c.jm * (p * p - z * z);
            c.j1 = j - c.jm;
        }
        _ => {
            let (z1, p1, z2, p2) = (w(pairs[0].0), w(pairs[0].1), w(pairs[1].0), w(pairs[1].1));
            c.jm = j * (z1 * z2 / (p1 * p2)).powi(2);
            c.kg = c.jm * (p1 * p1 + p2 * p2 - z1 * z1 - z2 * z2);
            let jarm = j - c.jm;
            let (pz, sz) = ((z1 * z2).powi(2), z1 * z1 + z2 * z2);
            let den = sz - pz * jarm / c.kg;
            c.j1 = if den > 0.0 { c.kg / den } else { 0.5 * jarm };
            if !(c.j1 > 0.0 && c.j1 < jarm) {
                c.j1 = 0.5 * jarm;
            }
            c.j2 = jarm - c.j1;
            c.ka = pz * c.j1 * c.j2 / c.kg;
            if masses >= 4 {
                // parallel mass: a fifth of the second arm mass, tuned to the third anti-resonance
                let z3 = pairs.get(2).map(|p| w(p.0)).unwrap_or(1.5 * z2);
                c.jp = 0.2 * c.j2;
                c.j2 -= c.jp;
                c.kp = c.jp * z3 * z3;
            }
        }
    }
    // guard against non-physical values before the Gauss–Newton pass
    let floor = 1e-3 * j;
    c.jm = c.jm.max(floor);
    c.j1 = c.j1.max(floor);
    c.j2 = c.j2.max(floor);
    c.jp = c.jp.max(floor);
    let kfloor = 1e-6 * j * w(pairs[0].1).powi(2);
    c.kg = c.kg.max(kfloor);
    c.ka = c.ka.max(kfloor);
    c.kp = c.kp.max(kfloor);
    c
}

/// Gauss–Newton on log-frequency residuals (module docs, step 3).
pub(super) fn chain_match(masses: usize, j: f64, pairs: &[(f64, f64)], start: Chain) -> Chain {
    let w = |f: f64| 2.0 * std::f64::consts::PI * f;
    let res = |c: &Chain| -> Vec<f64> {
        let (free, held) = c.frequencies(masses);
        let mut r = Vec::new();
        for (i, &(z, p)) in pairs.iter().enumerate().take(masses - 1) {
            r.push(free[i].max(1e-12).ln() - w(p).ln());
            r.push(held[i].max(1e-12).ln() - w(z).ln());
        }
        let jt = c.jm
            + c.j1
            + if masses >= 3 { c.j2 } else { 0.0 }
            + if masses >= 4 { c.jp } else { 0.0 };
        r.push(jt.ln() - j.ln());
        r
    };
    let mut v = start.log_vec(masses);
    let mut cur = start;
    let mut r0 = res(&cur);
    let mut cost: f64 = r0.iter().map(|x| x * x).sum();
    let mut lambda = 1e-3;
    for _ in 0..100 {
        if cost < 1e-20 {
            break;
        }
        let np = v.len();
        let mut jac = DMatrix::zeros(r0.len(), np);
        for k in 0..np {
            let mut vp = v.clone();
            vp[k] += 1e-6;
            let rp = res(&start.with_log(masses, &vp));
            for i in 0..r0.len() {
                jac[(i, k)] = (rp[i] - r0[i]) / 1e-6;
            }
        }
        let jtj = jac.transpose() * &jac;
        let jtr = jac.transpose() * DVector::from_vec(r0.clone());
        let mut improved = false;
        for _ in 0..10 {
            let mut a = jtj.clone();
            for i in 0..np {
                a[(i, i)] += lambda * (1.0 + jtj[(i, i)]);
            }
            let Some(step) = a.cholesky().map(|c| c.solve(&jtr)) else {
                break;
            };
            let vn: Vec<f64> = v
                .iter()
                .zip(step.iter())
                .map(|(a, s)| a - s.clamp(-1.0, 1.0))
                .collect();
            let cn = start.with_log(masses, &vn);
            let rn = res(&cn);
            let c: f64 = rn.iter().map(|x| x * x).sum();
            if c.is_finite() && c < cost {
                v = vn;
                cur = cn;
                r0 = rn;
                cost = c;
                lambda = (lambda / 5.0).max(1e-12);
                improved = true;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    cur
}

pub(super) fn clamp_vec(v: &mut [f64], lo: &[f64], hi: &[f64]) {
    for (i, x) in v.iter_mut().enumerate() {
        *x = x.max(lo[i]).min(hi[i]);
    }
}

/// Read `J`, `f_m`, resonance / anti-resonance pairs from the data (module
/// docs, steps 1–2) with a PBSID model of order `order`.
///
/// # Errors
/// When the subspace model cannot be built.
pub fn features(
    data: &IdData,
    output: Output,
    masses: usize,
    order: usize,
    f_min_hz: f64,
) -> Result<(Features, Vec<String>), GreyBoxError> {
    let mut warnings = Vec::new();
    let order = if order == 0 { 2 * masses + 2 } else { order };
    let opts = SubspaceOptions {
        method: Method::Pbsid,
        order: Order::Fixed(order),
        ..Default::default()
    };
    let sid = subspace::estimate(data, &opts)?;
    warnings.extend(sid.warnings.iter().cloned());
    let f_min = if f_min_hz > 0.0 {
        f_min_hz
    } else {
        20.0 / (data.u.len() as f64 * data.ts)
    };
    let rz = sid.model.resonances(f_min, 0.3);
    // rank by the height over the rigid-body line, |G(f)| ω^k (k = 2 for the
    // angle, 1 for the velocity): real resonances peak, noise-fitted
    // pole/zero pairs that nearly cancel do not; J is a common factor
    let k = match output {
        Output::Angle => 2,
        Output::Velocity => 1,
    };
    let height = |f: f64| {
        let g = sid.model.freq_response(&[f])[0].norm();
        g * (2.0 * std::f64::consts::PI * f).powi(k)
    };
    let mut res: Vec<(crate::ident::ss::Mode, f64)> = rz
        .resonances
        .iter()
        .map(|m| (*m, height(m.freq_hz)))
        .collect();
    res.sort_by(|a, b| b.1.total_cmp(&a.1));
    res.truncate(masses - 1);
    let mut res: Vec<crate::ident::ss::Mode> = res.into_iter().map(|x| x.0).collect();
    res.sort_by(|a, b| a.freq_hz.total_cmp(&b.freq_hz));
    let mut pairs = Vec::new();
    let mut lo = f_min;
    for p in &res {
        // the deepest notch between the previous resonance and this one
        let z = rz
            .anti_resonances
            .iter()
            .filter(|z| z.freq_hz > lo && z.freq_hz < p.freq_hz)
            .map(|z| (z.freq_hz, height(z.freq_hz)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|z| z.0);
        let z = z.unwrap_or_else(|| {
            warnings.push(format!(
                "no anti-resonance found below the resonance at {:.2} Hz; using 0.7 of it",
                p.freq_hz
            ));
            (0.7 * p.freq_hz).max(lo * 1.01)
        });
        pairs.push((z, p.freq_hz));
        lo = p.freq_hz;
    }
    let zeta1 = res
        .first()
        .map(|m| m.damping)
        .filter(|z| *z > 0.0)
        .unwrap_or(0.05);
    // rigid body from the low-frequency response: 1/G ≈ −J ω² + j f ω (angle),
    // J j ω + f (velocity); median over a few frequencies below the first pair
    let f_top = pairs.first().map(|p| 0.4 * p.0).unwrap_or(0.1 / data.ts);
    let freqs: Vec<f64> = (0..8).map(|i| f_top * (0.3 + 0.1 * i as f64)).collect();
    let g = sid.model.freq_response(&freqs);
    let (mut j_total, mut f_m) = rigid_from_response(&freqs, &g, output);
    // inverse-dynamics LS below the first anti-resonance as a cross-check / fallback
    let idim = rigid_idim(
        data,
        &IdimOptions {
            output,
            cutoff_hz: f_top,
            coulomb: false,
            offset: true,
            ..Default::default()
        },
    );
    if let Ok(rf) = &idim {
        let (ji, fi) = (
            rf.get("J").unwrap_or(f64::NAN),
            rf.get("Fv").unwrap_or(f64::NAN),
        );
        if !(j_total > 0.0 && j_total.is_finite()) && ji > 0.0 {
            warnings.push(
                "inertia from the frequency response unusable; taken from inverse dynamics".into(),
            );
            j_total = ji;
        }
        if !(f_m > 0.0 && f_m.is_finite()) && fi > 0.0 {
            f_m = fi;
        }
    }
    if !(j_total > 0.0 && j_total.is_finite()) {
        return Err(GreyBoxError::NoInertia);
    }
    if !(f_m > 0.0 && f_m.is_finite()) {
        // one tenth of a 1 Hz mechanical pole: small but positive
        f_m = 0.1 * j_total * 2.0 * std::f64::consts::PI;
        warnings.push("viscous friction not resolved by the data; started small".into());
    }
    if pairs.len() < masses - 1 {
        warnings.push(format!(
            "found {} resonances, the structure needs {}",
            pairs.len(),
            masses - 1
        ));
    }
    Ok((
        Features {
            j_total,
            f_m,
            pairs,
            zeta1,
            subspace_order: order,
        },
        warnings,
    ))
}

/// Rigid body from a low-frequency response `g` at `freqs_hz` [Hz]: `1/G ≈ −J ω² + j f ω`
/// for the angle, `J j ω + f` for the velocity; the medians over the frequencies of the
/// inertia `J` [kg·m²] and the viscous friction `f` [N·m·s/rad] (NaN without frequencies).
pub fn rigid_from_response(
    freqs_hz: &[f64],
    g: &[nalgebra::Complex<f64>],
    output: Output,
) -> (f64, f64) {
    let (mut js, mut fs) = (Vec::new(), Vec::new());
    for (f, g) in freqs_hz.iter().zip(g) {
        let w = 2.0 * std::f64::consts::PI * f;
        let inv = g.inv();
        match output {
            Output::Angle => {
                js.push(-inv.re / (w * w));
                fs.push(inv.im / w);
            }
            Output::Velocity => {
                js.push(inv.im / w);
                fs.push(inv.re);
            }
        }
    }
    let med = |v: &mut Vec<f64>| {
        if v.is_empty() {
            return f64::NAN;
        }
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    (med(&mut js), med(&mut fs))
}

/// Initial parameter values (arm-side, seed 000 Table 1 order) from features.
pub fn initial_values(structure: Structure, r: f64, feat: &Features) -> Vec<f64> {
    let masses = structure.masses();
    if masses == 1 {
        return vec![feat.j_total, feat.f_m];
    }
    let mut pairs = feat.pairs.clone();
    // missing pairs: spread above the last one
    while pairs.len() < masses - 1 {
        let last = pairs.last().copied().unwrap_or((5.0, 8.0));
        pairs.push((last.1 * 1.3, last.1 * 1.7));
    }
    let c0 = chain_closed_form(masses, feat.j_total, &pairs);
    let c = chain_match(masses, feat.j_total, &pairs, c0);
    let w1 = 2.0 * std::f64::consts::PI * pairs[0].1;
    let beta = 2.0 * feat.zeta1.clamp(1e-3, 0.5) / w1;
    let r2 = r * r;
    match structure {
        Structure::TwoMass => vec![c.jm, c.j1 / r2, c.kg / r2, beta * c.kg / r2, feat.f_m],
        Structure::ThreeMass => vec![
            c.jm,
            c.j1 / r2,
            c.j2 / r2,
            c.kg / r2,
            c.ka / r2,
            beta * c.kg / r2,
            beta * c.ka / r2,
            feat.f_m,
        ],
        _ => vec![
            c.jm,
            c.j1 / r2,
            c.j2 / r2,
            c.jp / r2,
            c.kg / r2,
            c.ka / r2,
            c.kp / r2,
            beta * c.kg / r2,
            beta * c.ka / r2,
            beta * c.kp / r2,
            feat.f_m,
        ],
    }
}
