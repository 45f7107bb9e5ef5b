//! Signal processing on records: integer decimation with a zero-phase anti-alias
//! filter (seed 000 §6: 2 kHz data decimated by 10 before identification).
// Units in brackets (`[s]`, `[Hz]`, `[dB]`) are not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

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
/// [`DataError::Decimation`] when `q` is 0 or `x` is shorter than the filter.
pub fn decimate(x: &[f64], q: usize) -> Result<Vec<f64>, DataError> {
    if q == 0 {
        return Err(DataError::Decimation("factor must be at least 1".into()));
    }
    if q == 1 {
        return Ok(x.to_vec());
    }
    let h = decimation_taps(q);
    let half = (h.len() - 1) / 2;
    let n = x.len();
    if n <= half + 1 {
        return Err(DataError::Decimation(format!(
            "record of {n} samples is shorter than the {}-tap anti-alias filter",
            h.len()
        )));
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

#[cfg(test)]
mod tests {
    use super::*;

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
            Err(DataError::Decimation(_))
        ));
    }
}
