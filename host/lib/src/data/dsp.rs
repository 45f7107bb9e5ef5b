//! Signal processing on records: integer decimation with a zero-phase anti-alias
//! filter (seed 000 §6: 2 kHz data decimated by 10 before identification), Butterworth
//! low- and high-pass sections (causal banks and zero-phase), the central difference, and
//! the autocorrelation of a long record in bounded memory.
// Units in brackets (`[s]`, `[Hz]`, `[dB]`) are not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

use rustfft::num_complex::Complex64;
use rustfft::FftPlanner;

use super::DataError;

/// Anti-alias filter taps for decimation by `q`: windowed sinc (Blackman),
/// cut-off at the new Nyquist frequency `0.5/q` (cycles per input sample),
/// `28 q + 1` taps, unit DC gain.
///
/// The transition band `0.4/q … 0.6/q` keeps 80 % of the new band flat (as
/// MATLAB `decimate` does) while every component that would fold into it is
/// at least ~70 dB down.
pub fn decimation_taps(q: usize) -> Vec<f64> {
    let len = 28 * q + 1;
    let m = (len - 1) as f64;
    let fc = 0.5 / q as f64;
    let mut h: Vec<f64> = (0..len)
        .map(|i| {
            let x = i as f64 - m / 2.0;
            let sinc = if x == 0.0 {
                2.0 * fc
            } else {
                (2.0 * std::f64::consts::PI * fc * x).sin() / (std::f64::consts::PI * x)
            };
            let w = 0.42 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / m).cos()
                + 0.08 * (4.0 * std::f64::consts::PI * i as f64 / m).cos();
            sinc * w
        })
        .collect();
    let s: f64 = h.iter().sum();
    h.iter_mut().for_each(|v| *v /= s);
    h
}

/// Integer decimation by `q` with a zero-phase anti-alias filter.
///
/// The symmetric FIR of [`decimation_taps`] is applied centred on each kept
/// sample (no delay, no phase shift); the ends are extended by odd
/// reflection about the end samples, as `filtfilt` does, so a ramp passes
/// undistorted. Output sample `j` is at input sample `j q`.
///
/// # Errors
/// [`DataError::DecimationFactor`] when `q` is 0, [`DataError::DecimationTooShort`] when
/// `x` is shorter than the filter.
pub fn decimate(x: &[f64], q: usize) -> Result<Vec<f64>, DataError> {
    if q == 0 {
        return Err(DataError::DecimationFactor);
    }
    if q == 1 {
        return Ok(x.to_vec());
    }
    let h = decimation_taps(q);
    let half = (h.len() - 1) / 2;
    let n = x.len();
    if n <= half + 1 {
        return Err(DataError::DecimationTooShort {
            samples: n,
            taps: h.len(),
        });
    }
    let at = |k: isize| -> f64 {
        if k < 0 {
            2.0 * x[0] - x[(-k) as usize]
        } else if k as usize >= n {
            let over = k as usize - (n - 1);
            2.0 * x[n - 1] - x[n - 1 - over]
        } else {
            x[k as usize]
        }
    };
    Ok((0..n.div_ceil(q))
        .map(|j| {
            let c = (j * q) as isize;
            h.iter()
                .enumerate()
                .map(|(i, hi)| hi * at(c + i as isize - half as isize))
                .sum()
        })
        .collect())
}

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

/// Longest block [samples] of [`autocorrelation`]: its FFTs are twice as long.
pub const AUTOCORRELATION_BLOCK: usize = 1 << 18;

/// The autocorrelation `r(τ) = Σ_{t=0}^{n−1−τ} (x(t) − c)(x(t+τ) − c)` of `x` about `c`
/// for the lags `τ = 0 ..= max_lag` (at most `n − 1`; empty for an empty `x`).
///
/// By FFT in blocks, so that a record of ten million samples needs no transform of its
/// whole length (32 bytes a sample for the padded buffer, as much again for each plan and
/// its scratch): `x` is cut into blocks of [`AUTOCORRELATION_BLOCK`] samples (one block
/// when `x` is shorter), each zero-padded to twice its length; the cross-spectra of block
/// pairs `d` blocks apart are summed, and one inverse FFT per `d` gives the lags
/// `d·B − B < τ < d·B + B`. It keeps the half spectrum of every block (16 bytes a
/// sample) and `r`, and computes as many products as the whole-length FFT would, give or
/// take the sum over pairs. The same `r` as the whole-length circular FFT to round-off.
pub fn autocorrelation(x: &[f64], c: f64, max_lag: usize) -> Vec<f64> {
    let n = x.len();
    if n == 0 {
        return Vec::new();
    }
    let max_lag = max_lag.min(n - 1);
    let b = n.min(AUTOCORRELATION_BLOCK);
    let m = 2 * b;
    let blocks = n.div_ceil(b);
    let mut planner = FftPlanner::<f64>::new();
    let (forward, inverse) = (planner.plan_fft_forward(m), planner.plan_fft_inverse(m));
    let zero = Complex64::new(0.0, 0.0);
    let mut scratch = vec![
        zero;
        forward
            .get_inplace_scratch_len()
            .max(inverse.get_inplace_scratch_len())
    ];
    let mut work = vec![zero; m];
    // bins 0..=b of each block's spectrum (the rest are their conjugates: x is real)
    let mut spectra = Vec::with_capacity(blocks * (b + 1));
    for block in x.chunks(b) {
        let centred = block.iter().map(|v| v - c).chain(std::iter::repeat(0.0));
        for (w, v) in work.iter_mut().zip(centred) {
            *w = Complex64::new(v, 0.0);
        }
        forward.process_with_scratch(&mut work, &mut scratch);
        spectra.extend_from_slice(&work[..=b]);
    }
    let half = |i: usize| &spectra[i * (b + 1)..(i + 1) * (b + 1)];
    let mut r = vec![0.0; max_lag + 1];
    // lag τ = d·b + δ with |δ| < b: pairs d = ⌊τ/b⌋ and d + 1 apart hold it
    for d in 0..=(max_lag / b + 1).min(blocks - 1) {
        work.fill(zero);
        for i in 0..blocks - d {
            for ((w, p), q) in work.iter_mut().zip(half(i)).zip(half(i + d)) {
                *w += p.conj() * q;
            }
        }
        for f in 1..b {
            work[m - f] = work[f].conj();
        }
        inverse.process_with_scratch(&mut work, &mut scratch);
        // bin j: δ = j below b, j − m above (b itself: |δ| = b, never a pair's)
        for (j, w) in work.iter().enumerate().filter(|(j, _)| *j != b) {
            let tau = (d * b + j).checked_sub(if j > b { m } else { 0 });
            if let Some(tau) = tau.filter(|t| *t <= max_lag) {
                r[tau] += w.re / m as f64;
            }
        }
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;

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

    fn tone(n: usize, f: f64) -> Vec<f64> {
        (0..n)
            .map(|k| (2.0 * std::f64::consts::PI * f * k as f64).sin())
            .collect()
    }

    fn amp_at(x: &[f64], f: f64) -> f64 {
        let (mut c, mut s) = (0.0, 0.0);
        for (k, v) in x.iter().enumerate() {
            let ph = 2.0 * std::f64::consts::PI * f * k as f64;
            c += v * ph.cos();
            s += v * ph.sin();
        }
        2.0 * (c * c + s * s).sqrt() / x.len() as f64
    }

    #[test]
    fn decimate_keeps_in_band_amplitude_and_removes_aliases() {
        let q = 10;
        let n = 40_000;
        // in band: 0.03 cycles/sample = 0.3 of the new rate (below 0.4)
        let f_in = 0.03;
        let d = decimate(&tone(n, f_in), q).unwrap();
        assert_eq!(d.len(), n / q);
        let mid = &d[200..3800];
        let a = amp_at(mid, f_in * q as f64);
        assert!((a - 1.0).abs() < 1e-3, "in-band amplitude {a}");
        // a tone at 0.07 cycles/sample would alias to 0.3 of the new rate
        let f_out = 0.07;
        let d = decimate(&tone(n, f_out), q).unwrap();
        let alias = amp_at(&d[200..3800], 1.0 - f_out * q as f64);
        assert!(alias < 3e-4, "alias amplitude {alias}");
        // plain subsampling would keep it at full amplitude (sanity of the probe)
        let raw: Vec<f64> = tone(n, f_out).into_iter().step_by(q).collect();
        assert!(amp_at(&raw[200..3800], 1.0 - f_out * q as f64) > 0.99);
    }

    #[test]
    fn decimate_passes_a_ramp_at_the_edges() {
        let x: Vec<f64> = (0..500).map(|k| 0.5 * k as f64).collect();
        let d = decimate(&x, 5).unwrap();
        for (j, v) in d.iter().enumerate() {
            assert!((v - 2.5 * j as f64).abs() < 1e-9, "{j}: {v}");
        }
        assert!(matches!(
            decimate(&x[..10], 5),
            Err(DataError::DecimationTooShort { samples: 10, .. })
        ));
    }

    /// r(τ) by its definition, summed directly
    fn direct(x: &[f64], c: f64, max_lag: usize) -> Vec<f64> {
        (0..=max_lag)
            .map(|tau| {
                (0..x.len() - tau)
                    .map(|t| (x[t] - c) * (x[t + tau] - c))
                    .sum()
            })
            .collect()
    }

    #[test]
    fn autocorrelation_in_blocks_is_the_sum_over_every_pair_at_each_lag() {
        // a record of several blocks and a ragged last one, lags across block boundaries
        let n = 2 * AUTOCORRELATION_BLOCK + 1234;
        let x: Vec<f64> = (0..n)
            .map(|k| (0.013 * k as f64).sin() + 0.5 * ((k * 7919 % 1009) as f64 / 1009.0))
            .collect();
        let got = autocorrelation(&x, 0.25, n / 2 + 1);
        assert_eq!(got.len(), n / 2 + 2);
        let scale = got[0];
        let lags = [
            0,
            1,
            777,
            AUTOCORRELATION_BLOCK - 1,
            AUTOCORRELATION_BLOCK,
            AUTOCORRELATION_BLOCK + 1,
            n / 2 + 1,
        ];
        for tau in lags {
            let want: f64 = (0..n - tau)
                .map(|t| (x[t] - 0.25) * (x[t + tau] - 0.25))
                .sum();
            assert!(
                (got[tau] - want).abs() < 1e-9 * scale,
                "lag {tau}: {} vs {want}",
                got[tau]
            );
        }
        // one block: every lag against the direct sum
        let short = &x[..300];
        let (a, b) = (autocorrelation(short, 0.1, 299), direct(short, 0.1, 299));
        for (tau, (a, b)) in a.iter().zip(&b).enumerate() {
            assert!((a - b).abs() < 1e-10 * b.abs().max(1.0), "lag {tau}");
        }
        assert_eq!(autocorrelation(&x[..3], 0.0, 10).len(), 3);
        assert!(autocorrelation(&[], 0.0, 4).is_empty());
    }
}
