//! Preparation of a record before the estimators: detrending.
// Units in brackets (`[s]`, `[Hz]`, `[dB]`) are not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

/// How [`detrend`] removes the trend.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Detrend {
    /// subtract the mean
    Mean,
    /// subtract the least-squares straight line
    Linear,
}

/// Removes the mean or the least-squares line from `x` in place.
pub fn detrend(x: &mut [f64], how: Detrend) {
    let n = x.len();
    if n == 0 {
        return;
    }
    let nf = n as f64;
    let mean = x.iter().sum::<f64>() / nf;
    match how {
        Detrend::Mean => x.iter_mut().for_each(|v| *v -= mean),
        Detrend::Linear => {
            let tm = (nf - 1.0) / 2.0;
            let (mut sxy, mut sxx) = (0.0, 0.0);
            for (k, v) in x.iter().enumerate() {
                let dt = k as f64 - tm;
                sxy += dt * (v - mean);
                sxx += dt * dt;
            }
            let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
            for (k, v) in x.iter_mut().enumerate() {
                *v -= mean + slope * (k as f64 - tm);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn detrend_linear_removes_a_line_exactly() {
        let mut x: Vec<f64> = (0..50).map(|k| 3.0 - 0.2 * k as f64).collect();
        detrend(&mut x, Detrend::Linear);
        assert!(x.iter().all(|v| v.abs() < 1e-12));
        let mut m = vec![1.0, 2.0, 6.0];
        detrend(&mut m, Detrend::Mean);
        assert_eq!(m, vec![-2.0, -1.0, 3.0]);
    }
}
