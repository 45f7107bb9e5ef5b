//! The FRF of a record without whole excitation periods (band-limited noise cut anywhere,
//! a CSV file with no excitation comments: EMPS, DaISy): Welch's averaged spectra over
//! overlapping windowed segments (Welch 1967; Bendat & Piersol, *Random Data*, 4th ed.,
//! §9.2–9.3).
//!
//! Each segment of `L` samples is detrended (least-squares line), multiplied by a periodic
//! Hann window and transformed; the auto- and cross-spectra are the means over the `K`
//! segments, `S_ab(k) = mean(A_k B_k*)`. The FRF from `u` to `θ_m`:
//! - with a reference column (closed loop), the reference as instrument,
//!   `Ĝ = S_yr / S_ur`: noise and disturbance enter `u` and `θ_m` through the loop but are
//!   uncorrelated with `r`, so the feedback bias of `S_yu / S_uu` disappears (Pintelon &
//!   Schoukens, *System Identification: A Frequency Domain Approach*, 2nd ed., §2.6, the
//!   indirect/IV FRF of closed-loop data);
//! - without one, `H1 = S_yu / S_uu` (open loop, or the best that can be done).
//!
//! Its variance (first order): with `x` the instrument (`r`, or `u` for H1) and
//! `S_vv = S_yy − 2 Re(Ĝ* S_yu) + |Ĝ|² S_uu` the output-error noise spectrum,
//! `σ²(Ĝ) = S_vv S_xx / (K_eff |S_ux|²) = S_vv / (K_eff γ²_ux S_uu)` (Bendat & Piersol
//! eq. (9.73) for H1 written with the instrument's coherence `γ²_ux`), with
//! `K_eff = K / (1 + 2 Σ_j (1 − j/K) ρ_j²)` the independent averages of overlapping
//! segments, `ρ_j` the window's overlap correlation at `j` hops (Welch 1967, eq. (9)); for
//! Hann at 50 % overlap `ρ_1 = 0.167`, `K_eff ≈ K / 1.06`. `S_vv` is scaled by
//! `K_eff / (K_eff − 1)` for the one complex value per line fitted from it.
//!
//! Lines: 2 … L/2 − 1 (line 1 lies in the window's main lobe around DC, where the
//! detrending and the drift of the rigid body are), those whose instrument power is
//! within [`WelchOptions::band_db`] of the strongest. Neighbouring lines of a Hann window
//! are correlated; the σ of each line is its own, so a weighted fit over them counts the
//! information about 1.5 times (the windows' equivalent noise bandwidth); good enough for
//! a start, which is what [`crate::ident::fit`] takes it for.
//!
//! Bias: the window's main lobe (4 lines wide) smears a resonance narrower than a few
//! lines, so the damping read from this FRF is biased high and its peaks low; the
//! time-domain refinement that follows removes it.

use rustfft::num_complex::Complex64;
use rustfft::FftPlanner;

use super::{Frf, FrfError, Instrument};
use crate::data::IdData;

/// Options of [`welch_frf`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WelchOptions {
    /// segment length `L` [samples]; 0: the longest power of two that gives at least
    /// `min_segments` segments
    pub segment: usize,
    /// overlap of consecutive segments [-], in 0 … 0.75
    pub overlap: f64,
    /// least number of segments when `segment` is chosen (more averages, coarser lines)
    pub min_segments: usize,
    /// lines whose instrument power lies this far below the strongest line [dB] are left out
    pub band_db: f64,
}

impl Default for WelchOptions {
    fn default() -> Self {
        WelchOptions {
            segment: 0,
            overlap: 0.5,
            min_segments: 8,
            band_db: 40.0,
        }
    }
}

/// Result of [`welch_frf`].
#[derive(Clone, Debug, PartialEq)]
pub struct WelchFrf {
    /// FRF at the lines within the band, with its σ (no period spectra: `spectra` empty)
    pub frf: Frf,
    /// what the FRF ratio is correlated with
    pub instrument: Instrument,
    /// segment length `L` [samples]
    pub segment: usize,
    /// segments averaged `K`
    pub segments: usize,
    /// independent averages `K_eff`
    pub averages: f64,
    /// coherence `γ²_ux` between the instrument and `u` at each line of `frf` [-]
    pub coherence: Vec<f64>,
}

/// shortest segment considered [samples]
const MIN_SEGMENT: usize = 64;

/// The segment length for `n` samples (module documentation).
fn segment_length(n: usize, opts: &WelchOptions) -> usize {
    if opts.segment > 0 {
        return opts.segment;
    }
    let count = |l: usize| {
        let hop = hop_of(l, opts.overlap);
        if n < l {
            0
        } else {
            (n - l) / hop + 1
        }
    };
    let mut l = 1usize << (usize::BITS - 1 - n.max(1).leading_zeros());
    while l > MIN_SEGMENT && count(l) < opts.min_segments.max(2) {
        l /= 2;
    }
    l
}

/// samples between segment starts
fn hop_of(l: usize, overlap: f64) -> usize {
    ((l as f64 * (1.0 - overlap)).round() as usize).clamp(1, l)
}

/// `x` minus its least-squares line, times `w`
fn detrended_windowed(x: &[f64], w: &[f64]) -> Vec<Complex64> {
    let n = x.len() as f64;
    let tm = (n - 1.0) / 2.0;
    let xm = x.iter().sum::<f64>() / n;
    let (mut sxt, mut stt) = (0.0, 0.0);
    for (i, v) in x.iter().enumerate() {
        let t = i as f64 - tm;
        sxt += t * (v - xm);
        stt += t * t;
    }
    let slope = if stt > 0.0 { sxt / stt } else { 0.0 };
    x.iter()
        .zip(w)
        .enumerate()
        .map(|(i, (v, wi))| Complex64::new((v - xm - slope * (i as f64 - tm)) * wi, 0.0))
        .collect()
}

/// The FRF from `u` to `y` of `data` by Welch's method (module documentation).
///
/// # Errors
/// [`FrfError::TooFewSegments`] when the record holds fewer than two segments (of at least
/// 64 samples), [`FrfError::NoExcitedLines`] when no line carries the instrument's power.
pub fn welch_frf(data: &IdData, opts: &WelchOptions) -> Result<WelchFrf, FrfError> {
    let n = data.len();
    let overlap = opts.overlap.clamp(0.0, 0.75);
    let l = segment_length(n, &WelchOptions { overlap, ..*opts });
    let hop = hop_of(l, overlap);
    let k_seg = if n >= l { (n - l) / hop + 1 } else { 0 };
    if l < MIN_SEGMENT.min(opts.segment.max(8)) || k_seg < 2 {
        return Err(FrfError::TooFewSegments {
            samples: n,
            segment: l,
        });
    }
    let (x, instrument, name) = match &data.r {
        Some(r) => (r.as_slice(), Instrument::Reference, "theta_ref"),
        None => (data.u.as_slice(), Instrument::Input, "u"),
    };
    let w: Vec<f64> = (0..l)
        .map(|i| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / l as f64).cos())
        .collect();
    let fft = FftPlanner::<f64>::new().plan_fft_forward(l);
    let nl = l / 2 + 1;
    let zero = Complex64::new(0.0, 0.0);
    let (mut sxx, mut suu, mut syy) = (vec![0.0; nl], vec![0.0; nl], vec![0.0; nl]);
    let (mut syx, mut sux, mut syu) = (vec![zero; nl], vec![zero; nl], vec![zero; nl]);
    for s in 0..k_seg {
        let range = s * hop..s * hop + l;
        let spec = |v: &[f64]| {
            let mut b = detrended_windowed(&v[range.clone()], &w);
            fft.process(&mut b);
            b.truncate(nl);
            b
        };
        let (ys, us, xs) = (spec(&data.y), spec(&data.u), spec(x));
        for k in 0..nl {
            sxx[k] += xs[k].norm_sqr();
            suu[k] += us[k].norm_sqr();
            syy[k] += ys[k].norm_sqr();
            syx[k] += ys[k] * xs[k].conj();
            sux[k] += us[k] * xs[k].conj();
            syu[k] += ys[k] * us[k].conj();
        }
    }
    let averages = effective_averages(&w, hop, k_seg);
    let top = sxx.iter().skip(1).copied().fold(0.0, f64::max);
    let floor = top * 10f64.powf(-opts.band_db / 10.0);
    let fs = 1.0 / data.ts;
    let mut frf = Frf::default();
    let mut coherence = Vec::new();
    for k in 2..nl - 1 {
        if !(sxx[k] > floor && sxx[k] > 0.0 && sux[k].norm_sqr() > 0.0) {
            continue;
        }
        let g = syx[k] / sux[k];
        let svv = (syy[k] - 2.0 * (g.conj() * syu[k]).re + g.norm_sqr() * suu[k]).max(0.0)
            * averages
            / (averages - 1.0).max(1.0);
        let var = svv * sxx[k] / (averages * sux[k].norm_sqr());
        if !(g.re.is_finite() && g.im.is_finite() && var.is_finite()) {
            continue;
        }
        frf.lines.push(k as u32);
        frf.freq_hz.push(k as f64 * fs / l as f64);
        frf.g.push(g);
        frf.sigma.push(var.sqrt());
        coherence.push(sux[k].norm_sqr() / (suu[k] * sxx[k]).max(f64::MIN_POSITIVE));
    }
    if frf.g.is_empty() {
        return Err(FrfError::NoExcitedLines {
            signal: name.into(),
            max_line: nl - 1,
        });
    }
    Ok(WelchFrf {
        frf,
        instrument,
        segment: l,
        segments: k_seg,
        averages,
        coherence,
    })
}

/// `K_eff` of `k` segments of window `w` every `hop` samples (Welch 1967, eq. (9)).
fn effective_averages(w: &[f64], hop: usize, k: usize) -> f64 {
    let e: f64 = w.iter().map(|v| v * v).sum();
    let mut factor = 1.0;
    for j in 1..k {
        let shift = j * hop;
        if shift >= w.len() {
            break;
        }
        let rho: f64 = w.iter().zip(&w[shift..]).map(|(a, b)| a * b).sum::<f64>() / e;
        factor += 2.0 * (1.0 - j as f64 / k as f64) * rho * rho;
    }
    k as f64 / factor
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::{plant, Gauss};

    /// White reference through the test loop: the closed-loop FRF with the reference as
    /// instrument follows the plant within a few σ at every line, and the σ is right in
    /// the mean (normalised errors of unit mean square).
    #[test]
    fn closed_loop_welch_frf_follows_the_plant_within_its_sigma() {
        let lp = plant();
        let mut g = Gauss::new(3);
        let r: Vec<f64> = (0..40_000).map(|_| g.next()).collect();
        let data = lp.run(&r, 0.05, 0.0, 7);
        let w = welch_frf(&data, &WelchOptions::default()).unwrap();
        assert_eq!(w.instrument, Instrument::Reference);
        assert!(w.segments >= 8 && w.averages < w.segments as f64);
        let mut z2 = 0.0;
        for ((f, gh), s) in w.frf.freq_hz.iter().zip(&w.frf.g).zip(&w.frf.sigma) {
            let z = crate::ident::sml::unit_circle(&[*f], data.ts)[0];
            let e = (gh - lp.plant(z)).norm() / s;
            z2 += e * e;
        }
        let ms = z2 / w.frf.g.len() as f64;
        assert!(
            (0.5..2.0).contains(&ms),
            "mean square normalised error {ms}"
        );
    }

    /// The input as its own instrument (H1) on open-loop data, and the error of a record
    /// too short for two segments.
    #[test]
    fn h1_without_reference_and_a_short_record_refused() {
        let lp = plant();
        let mut g = Gauss::new(5);
        let r: Vec<f64> = (0..20_000).map(|_| g.next()).collect();
        let mut data = lp.run(&r, 0.0, 0.0, 1);
        data.r = None;
        let w = welch_frf(&data, &WelchOptions::default()).unwrap();
        assert_eq!(w.instrument, Instrument::Input);
        let short = data.slice(0..90);
        let e = welch_frf(&short, &WelchOptions::default()).unwrap_err();
        assert!(e.to_string().contains("2 segments"), "{e}");
    }
}
