//! Where the frequency-domain fit starts (module docs of [`super`]): the reliable lines,
//! the FRF's peaks, the features (resonances, anti-resonances, rigid-body gain) that give
//! the initial values of each candidate assignment of peaks to modes.

use super::*;

/// Lines whose FRF is reliable: the noise's `σ/|Ĝ| ≤` [`RELIABLE_REL_SIGMA`], and the odd
/// nonlinear distortion on the line ([`Frf::sigma_total`]) below half the response. A line
/// the distortion swamps (the lowest line of a joint that sticks on its friction) carries
/// no linear information and would fake a resonance; lines at the resonances of a
/// stiffening spring carry much distortion and still place the modes. When the distortion
/// leaves fewer than a quarter of the lines, the noise alone decides; the fit then carries
/// [`FitWarning::Distortion`].
pub fn reliable_lines(frf: &Frf) -> Vec<usize> {
    let total = frf.sigma_total();
    let by_noise: Vec<usize> = (0..frf.g.len())
        .filter(|&i| {
            let a = frf.g[i].norm();
            a > 0.0 && frf.sigma[i] <= RELIABLE_REL_SIGMA * a
        })
        .collect();
    let both: Vec<usize> = by_noise
        .iter()
        .copied()
        .filter(|&i| total[i] <= SWAMPED_REL_SIGMA * frf.g[i].norm())
        .collect();
    if 4 * both.len() >= frf.g.len() {
        both
    } else {
        by_noise
    }
}

pub(super) fn rigid_power(output: Output) -> i32 {
    match output {
        Output::Angle => 2,
        Output::Velocity => 1,
    }
}

/// Resonances of the FRF: local maxima of `|Ĝ| ω^k` over the reliable lines
/// (`k` 2 for the angle, 1 for the velocity), with their topographic
/// prominence (height above the higher of the two lowest points that
/// separate the peak from higher ground on either side), at least 0.3 dB,
/// strongest first.
pub fn frf_peaks(frf: &Frf, output: Output) -> Vec<FrfPeak> {
    let idx = reliable_lines(frf);
    let k = rigid_power(output);
    let h: Vec<f64> = idx
        .iter()
        .map(|&i| {
            let w = 2.0 * std::f64::consts::PI * frf.freq_hz[i];
            20.0 * (frf.g[i].norm() * w.powi(k)).log10()
        })
        .collect();
    let mut peaks = Vec::new();
    for j in 1..h.len().saturating_sub(1) {
        if !(h[j] > h[j - 1] && h[j] >= h[j + 1]) {
            continue;
        }
        let mut left = h[j];
        let mut i = j;
        while i > 0 {
            i -= 1;
            if h[i] > h[j] {
                break;
            }
            left = left.min(h[i]);
        }
        let mut right = h[j];
        let mut i = j;
        while i + 1 < h.len() {
            i += 1;
            if h[i] > h[j] {
                break;
            }
            right = right.min(h[i]);
        }
        let prom = h[j] - left.max(right);
        if prom >= 0.3 {
            peaks.push(FrfPeak {
                freq_hz: frf.freq_hz[idx[j]],
                prominence_db: prom,
            });
        }
    }
    peaks.sort_by(|a, b| b.prominence_db.total_cmp(&a.prominence_db));
    peaks
}

/// Start features for chosen resonances: notches below each, the rigid
/// body from the lines below the first notch.
pub(super) fn features(
    frf: &Frf,
    output: Output,
    res_hz: &[f64],
    zeta: f64,
) -> Result<Features, FrfFitError> {
    let idx = reliable_lines(frf);
    let k = rigid_power(output);
    let height = |i: usize| {
        let w = 2.0 * std::f64::consts::PI * frf.freq_hz[i];
        frf.g[i].norm() * w.powi(k)
    };
    let mut pairs = Vec::new();
    let mut lo = 0.0;
    for &p in res_hz {
        let z = idx
            .iter()
            .filter(|&&i| frf.freq_hz[i] > lo && frf.freq_hz[i] < p)
            .min_by(|&&a, &&b| height(a).total_cmp(&height(b)))
            .map(|&i| frf.freq_hz[i])
            .filter(|&z| z > lo)
            .unwrap_or(0.7 * p);
        pairs.push((z.max(0.3 * p), p));
        lo = p;
    }
    let top = pairs.first().map_or(f64::INFINITY, |p| 0.5 * p.0);
    let mut low: Vec<usize> = idx
        .iter()
        .copied()
        .filter(|&i| frf.freq_hz[i] < top)
        .collect();
    if low.len() < 3 {
        low = idx.iter().copied().take(3).collect();
    }
    let freqs: Vec<f64> = low.iter().map(|&i| frf.freq_hz[i]).collect();
    let g: Vec<Complex64> = low.iter().map(|&i| frf.g[i]).collect();
    let (j_total, f_m) = grey_box::rigid_from_response(&freqs, &g, output);
    if !(j_total > 0.0 && j_total.is_finite()) {
        // a negative inertia `−K/ω²` is a spring to the frame: the response levels off
        return Err(FrfFitError::NoRigidBody {
            detail: format!(
                "median inertia {j_total:.3e} kg·m² over {} lines below {top:.2} Hz{}",
                low.len(),
                if j_total < 0.0 {
                    ": the response levels off to a finite static gain there, as a mass on a \
                     spring to the frame does; try `--model grounded`"
                } else {
                    ""
                }
            ),
        });
    }
    let mut f_m = f_m;
    let w_low = 2.0 * std::f64::consts::PI * frf.freq_hz[low[0]];
    if !(f_m > 1e-3 * j_total * w_low && f_m.is_finite()) {
        // unresolved: a mechanical pole a decade below the lowest line
        f_m = 0.1 * j_total * w_low;
    }
    Ok(Features {
        j_total,
        f_m,
        pairs,
        zeta1: zeta,
        subspace_order: 0,
    })
}

/// Start of the grounded mass (`J`, `Fv`, `k_0`) from the reliable lines: the angle's
/// dynamic stiffness `1/G(jω) = k_0 − J ω² + j ω Fv` is linear in the three
/// values, so its real part gives `r² k_0` and `J` and its imaginary part `Fv` by least
/// squares, each line weighted by `|G|` (the relative error of the FRF is what the lines
/// share). A damping the lag's phase turns negative is started at 5 % of critical.
pub(super) fn grounded_start(frf: &Frf, output: Output) -> Result<Vec<f64>, FrfFitError> {
    let idx = reliable_lines(frf);
    // normal equations of Re: [1, −ω²]·[K, J]; Im: ω·Fv
    let (mut a11, mut a12, mut a22, mut b1, mut b2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    let (mut ww, mut wy) = (0.0, 0.0);
    for &i in &idx {
        let w = 2.0 * std::f64::consts::PI * frf.freq_hz[i];
        let g_angle = match output {
            Output::Angle => frf.g[i],
            Output::Velocity => frf.g[i] / Complex64::new(0.0, w),
        };
        if g_angle.norm() == 0.0 || !g_angle.norm().is_finite() {
            continue;
        }
        let z = g_angle.inv();
        let q = g_angle.norm_sqr();
        a11 += q;
        a12 -= q * w * w;
        a22 += q * w.powi(4);
        b1 += q * z.re;
        b2 -= q * w * w * z.re;
        ww += q * w * w;
        wy += q * w * z.im;
    }
    let det = a11 * a22 - a12 * a12;
    let (k, j) = ((a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det);
    if !(k > 0.0 && j > 0.0 && k.is_finite() && j.is_finite()) {
        return Err(FrfFitError::NoGroundedMass {
            detail: format!(
                "stiffness {k:.3e} N·m/rad and inertia {j:.3e} kg·m² over {} lines",
                idx.len()
            ),
        });
    }
    let fv = wy / ww;
    let fv = if fv > 0.0 && fv.is_finite() {
        fv
    } else {
        2.0 * 0.05 * (k * j).sqrt()
    };
    Ok(vec![j, fv, k])
}

/// all `k`-subsets of `0..n`, in lexicographic order
pub(super) fn subsets(n: usize, k: usize) -> Vec<Vec<usize>> {
    if k == 0 {
        return vec![Vec::new()];
    }
    if k > n {
        return Vec::new();
    }
    let mut out = Vec::new();
    let mut cur: Vec<usize> = (0..k).collect();
    loop {
        out.push(cur.clone());
        let mut i = k;
        while i > 0 && cur[i - 1] == n - k + i - 1 {
            i -= 1;
        }
        if i == 0 {
            return out;
        }
        cur[i - 1] += 1;
        for j in i..k {
            cur[j] = cur[j - 1] + 1;
        }
    }
}

pub(super) fn is_loss(name: &str) -> bool {
    name.starts_with('d') || name.starts_with('f') || name == "Fv"
}

#[derive(Clone)]
pub(super) struct Candidate {
    pub(super) theta: Vec<f64>,
    pub(super) start: Vec<f64>,
    pub(super) fit: LmFit,
    pub(super) cost: f64,
    pub(super) opts: LmOptions,
}

/// Candidate mode frequencies for a second search: the peaks, and around the
/// two strongest of them, frequencies where a mode hidden in their shoulder
/// may sit; at most nine, none within 3 % of another [Hz].
pub(super) fn augmented_candidates(peaks: &[FrfPeak], n_res: usize) -> Vec<f64> {
    let mut c: Vec<f64> = peaks.iter().take(n_res + 2).map(|p| p.freq_hz).collect();
    for p in peaks.iter().take(2) {
        for m in [0.8, 1.2, 0.65, 1.45] {
            c.push(m * p.freq_hz);
        }
    }
    let mut out: Vec<f64> = Vec::new();
    for f in c {
        if out.len() < 9 && !out.iter().any(|g| (g - f).abs() < 0.03 * f) {
            out.push(f);
        }
    }
    out.sort_by(f64::total_cmp);
    out
}

pub(super) fn structure_name(s: Structure) -> &'static str {
    match s {
        Structure::Rigid => "rigid",
        Structure::TwoMass => "two-mass",
        Structure::ThreeMass => "three-mass",
        Structure::FourMass => "four-mass",
        Structure::Grounded => "grounded",
    }
}

/// The reported order of the four-mass model's interchangeable branches
/// ([`grey_box::FOUR_MASS_BRANCHES`]), applied to a candidate with its
/// covariance.
pub(super) fn canonical_four_mass(c: &mut Candidate) {
    let nm = Structure::FourMass.param_names().len();
    if !grey_box::four_mass_swapped(&c.theta[..nm.min(c.theta.len())]) {
        return;
    }
    for (i, j) in grey_box::FOUR_MASS_BRANCHES {
        c.theta.swap(i, j);
        c.start.swap(i, j);
        c.fit.theta.swap(i, j);
        c.fit.std.swap(i, j);
        c.fit.cov.swap_rows(i, j);
        c.fit.cov.swap_columns(i, j);
    }
}
