//! Sensors and disturbances: encoder quantisation of the motor angle, white measurement
//! noise on `θ_m` and `u`, and a low-frequency torque disturbance on the motor, all drawn
//! from a seeded generator so that a run is reproducible bit for bit.
//!
//! Order per sample: the controller sees `θ_m,meas = q(θ_m) + n_θ`, where `q` rounds to the
//! encoder count (`2π / counts_per_rev`); the recorded torque is `u + n_u` (the noise on
//! `u` is measurement only, the loop uses the clean `u`). The disturbance
//! `w[k] = A sin(2π f_d kT) + v[k]`, with `v` white noise through the first-order low-pass
//! `v[k+1] = a v[k] + σ√(1 − a²) e[k]`, `a = e^{−2π f_c T}` (stationary std σ, started
//! in its stationary distribution), is held over each sample and added to the motor torque.
//!
//! The generator is xoshiro256** (Blackman & Vigna) seeded through splitmix64, written here
//! from the published algorithm; each random stream (θ noise, u noise, disturbance) has its
//! own generator derived from `(seed, stream id)`, so switching one stream off leaves the
//! others unchanged. Normal deviates by the Box–Muller transform.

use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Sensor imperfections and the torque disturbance.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SensorConfig {
    /// encoder counts per motor revolution (`None`: no quantisation); default 2^17
    pub counts_per_rev: Option<u32>,
    /// standard deviation of white noise on the measured motor angle [rad]; default 1e-5
    pub theta_noise_std: f64,
    /// standard deviation of white noise on the recorded torque reference [N·m]; default 2e-3
    pub u_noise_std: f64,
    /// low-frequency torque disturbance on the motor
    pub disturbance: Disturbance,
}

/// Low-frequency torque disturbance on the motor.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Disturbance {
    /// amplitude of the sinusoidal part [N·m]; default 0
    pub sine_amplitude: f64,
    /// frequency of the sinusoidal part [Hz]; default 0.15
    pub sine_freq_hz: f64,
    /// stationary standard deviation of the low-pass noise [N·m]; default 1e-3
    pub noise_std: f64,
    /// cut-off of the noise low-pass [Hz]; default 1
    pub noise_cutoff_hz: f64,
}

impl Default for Disturbance {
    fn default() -> Self {
        Disturbance {
            sine_amplitude: 0.0,
            sine_freq_hz: 0.15,
            noise_std: 1e-3,
            noise_cutoff_hz: 1.0,
        }
    }
}

impl Disturbance {
    /// No disturbance.
    pub fn none() -> Self {
        Disturbance {
            sine_amplitude: 0.0,
            noise_std: 0.0,
            ..Disturbance::default()
        }
    }
}

impl Default for SensorConfig {
    fn default() -> Self {
        SensorConfig {
            counts_per_rev: Some(1 << 17),
            theta_noise_std: 1e-5,
            u_noise_std: 2e-3,
            disturbance: Disturbance::default(),
        }
    }
}

impl SensorConfig {
    /// Perfect sensors and no disturbance (for tests against exact solutions).
    pub fn ideal() -> Self {
        SensorConfig {
            counts_per_rev: None,
            theta_noise_std: 0.0,
            u_noise_std: 0.0,
            disturbance: Disturbance::none(),
        }
    }

    /// Encoder resolution [rad/count], `None` without quantisation.
    pub fn angle_resolution(&self) -> Option<f64> {
        self.counts_per_rev.map(|c| 2.0 * PI / f64::from(c))
    }
}

/// xoshiro256** pseudo-random generator.
#[derive(Clone, Debug)]
pub struct Rng {
    s: [u64; 4],
    spare: Option<f64>,
}

fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

impl Rng {
    /// Generator for stream `stream` of run seed `seed`.
    pub fn new(seed: u64, stream: u64) -> Self {
        let mut st = seed ^ stream.wrapping_mul(0xd1b5_4a32_d192_ed03);
        let s = [
            splitmix64(&mut st),
            splitmix64(&mut st),
            splitmix64(&mut st),
            splitmix64(&mut st),
        ];
        Rng { s, spare: None }
    }

    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        let result = self.s[1].wrapping_mul(5).rotate_left(7).wrapping_mul(9);
        let t = self.s[1] << 17;
        self.s[2] ^= self.s[0];
        self.s[3] ^= self.s[1];
        self.s[1] ^= self.s[2];
        self.s[0] ^= self.s[3];
        self.s[2] ^= t;
        self.s[3] = self.s[3].rotate_left(45);
        result
    }

    /// Uniform in [0, 1) with 53 random bits.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Standard normal deviate (Marsaglia's polar form of Box–Muller, both values used: a
    /// point uniform in the unit disc, accepted with probability π/4, replaces the sine and
    /// cosine).
    pub fn normal(&mut self) -> f64 {
        if let Some(z) = self.spare.take() {
            return z;
        }
        let (a, b, r2) = self.polar_point();
        let f = polar_factor(r2);
        self.spare = Some(b * f);
        a * f
    }

    /// The point of the polar method that gives the next pair of [`Self::normal`]: `(a, b)`
    /// uniform in the unit disc without its centre, and `r² = a² + b²` (as drawn by
    /// `Normals::draw_block`).
    #[inline]
    fn polar_point(&mut self) -> (f64, f64, f64) {
        loop {
            let a = 2.0 * self.uniform() - 1.0;
            let b = 2.0 * self.uniform() - 1.0;
            let r2 = a * a + b * b;
            if r2 > 0.0 && r2 < 1.0 {
                return (a, b, r2);
            }
        }
    }
}

/// The polar method's factor `√(−2 ln r² / r²)` that turns the point `(a, b)` into two
/// standard normal deviates `(a f, b f)`.
#[inline]
fn polar_factor(r2: f64) -> f64 {
    (-2.0 * r2.ln() / r2).sqrt()
}

/// Normal deviates drawn ahead in blocks per stream [-].
const NORMAL_BLOCK: usize = 32;

/// One stream's standard normal deviates, the sequence of [`Rng::normal`] on a fresh
/// generator, drawn [`NORMAL_BLOCK`] at a time and handed out in order. A block is drawn in
/// three passes: the polar method's accepted points (the same draws and rejections), then
/// their logarithms, then the factors and deviates (the same operations on each value, so
/// the same bits), which keeps the logarithms, divisions and square roots out of the closed
/// loop's chain of sample-to-sample dependencies and lets them overlap.
#[derive(Clone, Debug)]
struct Normals {
    /// never asked for a single deviate, so it holds no spare one
    rng: Rng,
    block: [f64; NORMAL_BLOCK],
    /// index of the next deviate in `block` (`NORMAL_BLOCK`: draw the next block)
    next: usize,
}

impl Normals {
    /// The deviates of stream `stream` of run seed `seed` ([`Rng::new`]).
    fn new(seed: u64, stream: u64) -> Self {
        Normals {
            rng: Rng::new(seed, stream),
            block: [0.0; NORMAL_BLOCK],
            next: NORMAL_BLOCK,
        }
    }

    /// The stream's next deviate.
    #[inline]
    fn next(&mut self) -> f64 {
        if self.next == NORMAL_BLOCK {
            self.draw_block();
        }
        let z = self.block[self.next];
        self.next += 1;
        z
    }

    /// The next [`NORMAL_BLOCK`] deviates: pairs `(a f, b f)` of [`Rng::normal`], its
    /// points drawn as [`Rng::polar_point`] draws them.
    fn draw_block(&mut self) {
        const PAIRS: usize = NORMAL_BLOCK / 2;
        // polar_point PAIRS times: every candidate stored, the count moved on by the
        // accepted ones only (no branch on the rejection, a coin toss of odds π/4)
        let mut points = [(0.0, 0.0, 0.0); PAIRS + 1];
        let mut n = 0;
        while n < PAIRS {
            let a = 2.0 * self.rng.uniform() - 1.0;
            let b = 2.0 * self.rng.uniform() - 1.0;
            let r2 = a * a + b * b;
            points[n] = (a, b, r2);
            n += usize::from(r2 > 0.0 && r2 < 1.0);
        }
        let mut logs = [0.0; PAIRS];
        for (l, p) in logs.iter_mut().zip(&points) {
            *l = p.2.ln();
        }
        for ((l, p), z) in logs.iter().zip(&points).zip(self.block.chunks_exact_mut(2)) {
            // polar_factor, with the logarithm taken above
            let f = (-2.0 * l / p.2).sqrt();
            z[0] = p.0 * f;
            z[1] = p.1 * f;
        }
        self.next = 0;
    }
}

/// Stream ids of [`Rng::new`].
const STREAM_THETA: u64 = 1;
const STREAM_U: u64 = 2;
const STREAM_DIST: u64 = 3;

/// Running sensor and disturbance state of one simulation.
#[derive(Clone, Debug)]
pub struct Sensors {
    cfg: SensorConfig,
    ts: f64,
    rng_theta: Normals,
    rng_u: Normals,
    rng_dist: Normals,
    lp_state: f64,
    lp_a: f64,
    lp_b: f64,
    k: u64,
    /// the encoder's resolution, [`SensorConfig::angle_resolution`] [rad/count]
    resolution: Option<f64>,
}

impl Sensors {
    /// Sensors for sample interval `ts` [s] and run seed `seed`.
    pub fn new(cfg: SensorConfig, ts: f64, seed: u64) -> Self {
        let lp_a = (-2.0 * PI * cfg.disturbance.noise_cutoff_hz * ts).exp();
        let lp_b = cfg.disturbance.noise_std * (1.0 - lp_a * lp_a).sqrt();
        let mut rng_dist = Normals::new(seed, STREAM_DIST);
        let lp_state = if cfg.disturbance.noise_std > 0.0 {
            cfg.disturbance.noise_std * rng_dist.next()
        } else {
            0.0
        };
        Sensors {
            cfg,
            ts,
            rng_theta: Normals::new(seed, STREAM_THETA),
            rng_u: Normals::new(seed, STREAM_U),
            rng_dist,
            lp_state,
            lp_a,
            lp_b,
            k: 0,
            resolution: cfg.angle_resolution(),
        }
    }

    /// Measured motor angle from the true one [rad].
    pub fn measure_theta(&mut self, theta: f64) -> f64 {
        let q = match self.resolution {
            Some(res) => (theta / res).round() * res,
            None => theta,
        };
        if self.cfg.theta_noise_std > 0.0 {
            q + self.cfg.theta_noise_std * self.rng_theta.next()
        } else {
            q
        }
    }

    /// Recorded torque reference from the true one [N·m].
    pub fn measure_u(&mut self, u: f64) -> f64 {
        if self.cfg.u_noise_std > 0.0 {
            u + self.cfg.u_noise_std * self.rng_u.next()
        } else {
            u
        }
    }

    /// Disturbance torque held over the current sample [N·m]; advances one sample.
    pub fn next_disturbance(&mut self) -> f64 {
        let d = &self.cfg.disturbance;
        let t = self.k as f64 * self.ts;
        let mut w = self.lp_state;
        if d.sine_amplitude != 0.0 {
            w += d.sine_amplitude * (2.0 * PI * d.sine_freq_hz * t).sin();
        }
        if d.noise_std > 0.0 {
            self.lp_state = self.lp_a * self.lp_state + self.lp_b * self.rng_dist.next();
        }
        self.k += 1;
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rng_is_reproducible_and_streams_differ() {
        let mut a = Rng::new(42, 1);
        let mut b = Rng::new(42, 1);
        let mut c = Rng::new(42, 2);
        let va: Vec<u64> = (0..8).map(|_| a.next_u64()).collect();
        let vb: Vec<u64> = (0..8).map(|_| b.next_u64()).collect();
        let vc: Vec<u64> = (0..8).map(|_| c.next_u64()).collect();
        assert_eq!(va, vb);
        assert_ne!(va, vc);
    }

    #[test]
    fn normals_in_blocks_are_the_generator_s_deviates_to_the_bit() {
        for (seed, stream) in [(1, STREAM_THETA), (7, STREAM_U), (u64::MAX, STREAM_DIST)] {
            let mut one = Rng::new(seed, stream);
            let mut blocks = Normals::new(seed, stream);
            for k in 0..5 * NORMAL_BLOCK + 3 {
                let (a, b) = (one.normal(), blocks.next());
                assert_eq!(
                    a.to_bits(),
                    b.to_bits(),
                    "seed {seed} stream {stream} deviate {k}"
                );
            }
        }
    }

    #[test]
    fn normal_has_zero_mean_unit_variance() {
        let mut r = Rng::new(7, 0);
        let n = 200_000;
        let v: Vec<f64> = (0..n).map(|_| r.normal()).collect();
        let mean = v.iter().sum::<f64>() / n as f64;
        let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
        // 5 standard errors
        assert!(mean.abs() < 5.0 / (n as f64).sqrt(), "mean {mean}");
        assert!(
            (var - 1.0).abs() < 5.0 * (2.0 / n as f64).sqrt(),
            "var {var}"
        );
    }

    #[test]
    fn quantisation_rounds_to_counts() {
        let cfg = SensorConfig {
            theta_noise_std: 0.0,
            ..SensorConfig::default()
        };
        let mut s = Sensors::new(cfg, 5e-4, 1);
        let res = 2.0 * PI / 131072.0;
        assert_eq!(s.measure_theta(3.4 * res), 3.0 * res);
        assert_eq!(s.measure_theta(-3.6 * res), -4.0 * res);
        assert_eq!(s.measure_theta(0.49 * res), 0.0);
    }

    #[test]
    fn disturbance_noise_has_stationary_std_and_low_pass_correlation() {
        let cfg = SensorConfig {
            disturbance: Disturbance {
                noise_std: 0.1,
                noise_cutoff_hz: 5.0,
                ..Disturbance::none()
            },
            ..SensorConfig::ideal()
        };
        let mut s = Sensors::new(cfg, 5e-4, 3);
        let n = 400_000;
        let w: Vec<f64> = (0..n).map(|_| s.next_disturbance()).collect();
        let var = w.iter().map(|x| x * x).sum::<f64>() / n as f64;
        // correlation time 1/(2π·5 Hz) = 32 ms = 64 samples: ~6000 independent samples
        assert!((var.sqrt() - 0.1).abs() < 0.01, "std {}", var.sqrt());
        let lag = 64;
        let r: f64 = w.windows(lag + 1).map(|p| p[0] * p[lag]).sum::<f64>() / (n - lag) as f64;
        let expected = (-2.0 * PI * 5.0 * 5e-4 * lag as f64).exp();
        assert!(
            (r / var - expected).abs() < 0.1,
            "rho {} vs {expected}",
            r / var
        );
    }
}
