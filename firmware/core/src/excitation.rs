//! Excitation signals for identifying a robot joint in closed loop.
//!
//! The main signal is the *special odd multisine* of seed 000 (Norrlöf et al.,
//! "Modeling and identification of a mechanical industrial manipulator",
//! eq. (1) and (4)): sines at `k·f0` for `k ≡ 1 or 3 (mod 8)`, `1 ≤ k ≤ F`
//! (Matlab `[1:8:F] ∪ [3:8:F]`), amplitudes following the magnitude of a
//! first-order Butterworth low-pass `|H(jf)| = 1/sqrt(1 + (f/fc)²)`, phases
//! uniform in [0, 2π). The paper used f0 = 0.4 Hz, F = 304 (76 lines up to
//! 121.6 Hz) and fc = 50 Hz; here the default sample rate is 2 kHz, so one
//! period is N = 5000 samples. Lines left out (even and the other odd ones)
//! show the nonlinear distortion (paper section 3).
//!
//! Two validation signals share the design: [`SignalKind::RandomOddMultisine`]
//! (every odd line, other phases) and [`SignalKind::BandLimitedNoise`].
//!
//! # Generation
//! One period is computed once into a caller-supplied table (no allocation)
//! and replayed sample by sample with integer indexing, so the signal repeats
//! bit-exactly every period. Line by line (increasing k) and in chunks of
//! [`CHUNK`] samples, the phasor `e^{j2π((k·n0) mod N)/N}` at the chunk start
//! `n0` comes from the exact integer phase (f64 `libm::sincos`), is rounded
//! to f32 and rotated by the f32 phasor `e^{j2πk/N}` within the chunk; each
//! line's contribution is added to the f32 table. Only IEEE operations that
//! are correctly rounded on every target are used (f32/f64 `+ − ×`, no fused
//! multiply-add, libm's portable code), in a fixed order, so the board and
//! the host produce the same table bit for bit (pinned by a test against a
//! Cortex-M4 run). The error of 64 f32 rotations stays near 1e-6 relative to
//! a line, i.e. well over 100 dB below it; micromath's `sin`, off by 1e-3, is
//! never used here (it would leave a −60 dB floor on the lines the linearity
//! check reads). Cost on a Cortex-M4: about N·lines·15 instructions plus
//! one f64 `sincos` per line and chunk.
//!
//! # Amplitude
//! Every signal is scaled so that the RMS over one full-amplitude period
//! equals `rms_rad` exactly (up to f32 rounding): for lines on the DFT grid,
//! away from DC and Nyquist, RMS² = Σ |X_k|²/2.
//!
//! # Ramp
//! The run starts and ends with a raised-cosine ramp of `ramp_samples`
//! samples: weight `(1 - cos(π i/R))/2` on the way in (exactly 0 at the first
//! sample), `(1 + cos(π (i+1)/R))/2` on the way out (the mirror image, exactly
//! 0 at the last sample), and exactly 1 in between, so the reference never
//! steps. The weight is evaluated in f32 from a polynomial (`ramp_rise`),
//! within a few f32 ulps of the cosine and bit-identical on board and host;
//! it costs a few dozen instructions per ramp sample on a Cortex-M4F, where an
//! f64 `cos` costs thousands. The table index runs on through the ramps, so
//! the full-amplitude part starts at table index `R mod N`.

use serde::{Deserialize, Serialize};

use crate::rng::SplitMix64;

/// Samples per generation chunk (phasors are re-anchored at each chunk start).
pub const CHUNK: usize = 64;

/// RNG stream separators, so each signal kind uses its own phases for one seed.
const STREAM_SPECIAL_ODD: u64 = 0x5350_4543_4941_4C31; // "SPECIAL1"
const STREAM_RANDOM_ODD: u64 = 0x5241_4E44_4F44_4431; // "RANDODD1"
const STREAM_NOISE: u64 = 0x4E4F_4953_4542_4C31; // "NOISEBL1"

/// Which signal the generator produces.
#[derive(Serialize, Deserialize, Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SignalKind {
    /// Lines `k ≡ 1 or 3 (mod 8)`, `1 ≤ k ≤ F`, Butterworth amplitudes, random phases (seed 000 eq. (4)).
    SpecialOddMultisine,
    /// Every odd line `1 ≤ k ≤ F`, Butterworth amplitudes, random phases (a different stream).
    RandomOddMultisine,
    /// Periodic band-limited Gaussian noise: every line `1 ≤ k ≤ F` with a
    /// complex Gaussian coefficient times the Butterworth magnitude. This is
    /// exactly white Gaussian noise of period N, circularly filtered by the
    /// ideal band-pass `1..F` times `|H|`; scaled to the same RMS.
    BandLimitedNoise,
}

/// Complete, small description of an excitation; the host regenerates the
/// signal bit-exactly from it.
#[derive(Serialize, Deserialize, Clone, Copy, PartialEq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ExcitationConfig {
    /// Signal kind.
    pub kind: SignalKind,
    /// Sample rate [Hz].
    pub fs_hz: u32,
    /// Period N = fs / f0 [samples].
    pub period_samples: u32,
    /// F: highest excited harmonic index (frequency `F·f0`).
    pub max_line: u32,
    /// Cut-off of the first-order Butterworth amplitude shape [Hz].
    pub cutoff_hz: f32,
    /// RMS of the full-amplitude reference [rad].
    pub rms_rad: f32,
    /// Seed of the phases / noise.
    pub seed: u64,
    /// Length of the raised-cosine ramp in and out [samples].
    pub ramp_samples: u32,
    /// Full-amplitude periods after the ramp-in (0 = endless).
    pub periods: u32,
}

/// Limits an excitation must respect before it may drive a joint.
#[derive(Clone, Copy, PartialEq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SafetyLimits {
    /// Largest allowed |θ_ref| [rad].
    pub peak_angle_rad: f32,
    /// Largest allowed |dθ_ref/dt| [rad/s], including the ramp's contribution.
    pub peak_velocity_rad_s: f32,
    /// Highest line may be at most this fraction of the Nyquist frequency (default 1/2.5).
    pub max_line_fraction_of_nyquist: f32,
}

impl SafetyLimits {
    /// Defaults for the motor side of a small industrial joint: 0.5 rad,
    /// 100 rad/s, highest line below Nyquist/2.5.
    pub const fn default_joint() -> Self {
        Self {
            peak_angle_rad: 0.5,
            peak_velocity_rad_s: 100.0,
            max_line_fraction_of_nyquist: 0.4,
        }
    }
}

impl Default for SafetyLimits {
    fn default() -> Self {
        Self::default_joint()
    }
}

/// Why an excitation was refused. Each variant carries the offending value and the limit.
#[derive(Clone, Copy, PartialEq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ExcitationError {
    /// The sample rate is zero.
    ZeroSampleRate,
    /// `fs / f0` is not an integer number of samples.
    NonIntegerPeriod {
        /// sample rate [Hz]
        fs_hz: u32,
        /// requested base frequency [Hz]
        f0_hz: f64,
        /// fs / f0 [samples]
        ratio: f64,
    },
    /// The period is too short to hold the lines (N must exceed 2F).
    PeriodTooShort {
        /// period [samples]
        period_samples: u32,
        /// smallest period accepted for this F [samples]
        min_samples: u32,
    },
    /// No line is excited (F = 0, or F < 1 for the chosen kind).
    NoLines {
        /// F
        max_line: u32,
    },
    /// The highest line is above the allowed fraction of Nyquist.
    LineAboveLimit {
        /// F
        line: u32,
        /// frequency of line F [Hz]
        freq_hz: f32,
        /// largest allowed frequency [Hz]
        limit_hz: f32,
    },
    /// The amplitude shape cut-off is not a positive finite frequency.
    BadCutoff {
        /// cut-off [Hz]
        cutoff_hz: f32,
    },
    /// The RMS is negative or not finite.
    BadRms {
        /// requested RMS [rad]
        rms_rad: f32,
    },
    /// The peak |θ_ref| exceeds the limit.
    PeakAngle {
        /// peak of the generated signal [rad]
        value_rad: f32,
        /// limit [rad]
        limit_rad: f32,
    },
    /// The peak |dθ_ref/dt| exceeds the limit.
    PeakVelocity {
        /// peak velocity of the generated signal incl. ramp [rad/s]
        value_rad_s: f32,
        /// limit [rad/s]
        limit_rad_s: f32,
    },
    /// The caller's table cannot hold one period.
    TableTooSmall {
        /// table length [samples]
        len: usize,
        /// one period [samples]
        needed: usize,
    },
    /// A whole run was requested for an endless configuration (`periods == 0`).
    Endless,
}

impl core::fmt::Display for ExcitationError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::ZeroSampleRate => write!(f, "sample rate is zero"),
            Self::NonIntegerPeriod {
                fs_hz,
                f0_hz,
                ratio,
            } => write!(
                f,
                "period is not an integer number of samples: fs {fs_hz} Hz / f0 {f0_hz} Hz = {ratio}"
            ),
            Self::PeriodTooShort {
                period_samples,
                min_samples,
            } => write!(
                f,
                "period of {period_samples} samples is shorter than the {min_samples} samples the lines need"
            ),
            Self::NoLines { max_line } => write!(f, "no excited line up to F = {max_line}"),
            Self::LineAboveLimit {
                line,
                freq_hz,
                limit_hz,
            } => write!(
                f,
                "highest line {line} at {freq_hz} Hz is above the limit of {limit_hz} Hz"
            ),
            Self::BadCutoff { cutoff_hz } => {
                write!(f, "amplitude cut-off {cutoff_hz} Hz is not a positive frequency")
            }
            Self::BadRms { rms_rad } => write!(f, "rms {rms_rad} rad is negative or not finite"),
            Self::PeakAngle {
                value_rad,
                limit_rad,
            } => write!(
                f,
                "peak angle {value_rad} rad exceeds the limit of {limit_rad} rad"
            ),
            Self::PeakVelocity {
                value_rad_s,
                limit_rad_s,
            } => write!(
                f,
                "peak velocity {value_rad_s} rad/s exceeds the limit of {limit_rad_s} rad/s"
            ),
            Self::TableTooSmall { len, needed } => write!(
                f,
                "table of {len} samples cannot hold one period of {needed} samples"
            ),
            Self::Endless => write!(f, "the configuration is endless (periods = 0)"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for ExcitationError {}

/// Peaks of one full-amplitude period.
#[derive(Clone, Copy, PartialEq, Debug)]
pub struct SignalPeaks {
    /// max |θ_ref| over one period [rad]
    pub angle_rad: f32,
    /// max |θ_ref(n+1) - θ_ref(n)|·fs over one period, wrapping around [rad/s]
    pub velocity_rad_s: f32,
    /// velocity bound including the raised-cosine ramp: `velocity + angle·π·fs/(2R)`,
    /// or `velocity + angle·fs` without a ramp (a jump from rest) [rad/s]
    pub velocity_with_ramp_rad_s: f32,
}

impl ExcitationConfig {
    /// The seed-000 experiment at 2 kHz: special odd multisine, f0 = 0.4 Hz
    /// (N = 5000), F = 304 (76 lines up to 121.6 Hz), Butterworth cut-off
    /// 50 Hz, RMS 0.02 rad on the motor side, 1 s ramps, 4 periods (the first
    /// one for transients, three to analyse as in the paper).
    pub const fn paper_default() -> Self {
        Self {
            kind: SignalKind::SpecialOddMultisine,
            fs_hz: 2000,
            period_samples: 5000,
            max_line: 304,
            cutoff_hz: 50.0,
            rms_rad: 0.02,
            seed: 0x000D_5EED_65E5_93A5,
            ramp_samples: 2000,
            periods: 4,
        }
    }

    /// The paper default with base frequency `f0_hz` at `fs_hz`.
    ///
    /// # Errors
    /// [`ExcitationError::NonIntegerPeriod`] unless `fs/f0` is an integer
    /// (relative tolerance 1e-9), [`ExcitationError::ZeroSampleRate`].
    pub fn from_f0(fs_hz: u32, f0_hz: f64) -> Result<Self, ExcitationError> {
        if fs_hz == 0 {
            return Err(ExcitationError::ZeroSampleRate);
        }
        let ratio = fs_hz as f64 / f0_hz;
        let rounded = libm::round(ratio);
        if !ratio.is_finite()
            || rounded < 1.0
            || rounded > u32::MAX as f64
            || libm::fabs(ratio - rounded) > 1e-9 * rounded
        {
            return Err(ExcitationError::NonIntegerPeriod {
                fs_hz,
                f0_hz,
                ratio,
            });
        }
        Ok(Self {
            fs_hz,
            period_samples: rounded as u32,
            ..Self::paper_default()
        })
    }

    /// Base frequency f0 = fs / N [Hz] (0 for a zero period).
    pub fn f0_hz(&self) -> f64 {
        if self.period_samples == 0 {
            0.0
        } else {
            self.fs_hz as f64 / self.period_samples as f64
        }
    }

    /// Whether harmonic `line` carries energy: `k ≡ 1 or 3 (mod 8)` for the
    /// special odd multisine, every odd `k` for the random odd multisine,
    /// every `k` for the noise; always `1 ≤ k ≤ F`.
    pub fn is_excited(&self, line: u32) -> bool {
        if line == 0 || line > self.max_line {
            return false;
        }
        match self.kind {
            SignalKind::SpecialOddMultisine => line % 8 == 1 || line % 8 == 3,
            SignalKind::RandomOddMultisine => line % 2 == 1,
            SignalKind::BandLimitedNoise => true,
        }
    }

    /// Number of excited lines.
    pub fn line_count(&self) -> u32 {
        match self.kind {
            SignalKind::SpecialOddMultisine => {
                let f = self.max_line;
                // k = 8m+1 ≤ F and k = 8m+3 ≤ F
                let ones = if f >= 1 { (f - 1) / 8 + 1 } else { 0 };
                let threes = if f >= 3 { (f - 3) / 8 + 1 } else { 0 };
                ones + threes
            }
            SignalKind::RandomOddMultisine => self.max_line.div_ceil(2),
            SignalKind::BandLimitedNoise => self.max_line,
        }
    }

    /// Total length of a finite run: ramp-in + periods·N + ramp-out
    /// [samples]; `None` when endless.
    pub fn total_samples(&self) -> Option<u64> {
        if self.periods == 0 {
            None
        } else {
            Some(2 * self.ramp_samples as u64 + self.periods as u64 * self.period_samples as u64)
        }
    }

    /// Structural checks that need no signal: sample rate, period, lines,
    /// Nyquist fraction, cut-off, RMS.
    ///
    /// # Errors
    /// The first violated rule, with value and limit.
    pub fn validate_structure(&self, limits: &SafetyLimits) -> Result<(), ExcitationError> {
        if self.fs_hz == 0 {
            return Err(ExcitationError::ZeroSampleRate);
        }
        if self.line_count() == 0 {
            return Err(ExcitationError::NoLines {
                max_line: self.max_line,
            });
        }
        let min_samples = self.max_line.saturating_mul(2).saturating_add(1);
        if self.period_samples < min_samples {
            return Err(ExcitationError::PeriodTooShort {
                period_samples: self.period_samples,
                min_samples,
            });
        }
        let freq = self.max_line as f64 * self.f0_hz();
        let limit = limits.max_line_fraction_of_nyquist as f64 * self.fs_hz as f64 / 2.0;
        if freq > limit {
            return Err(ExcitationError::LineAboveLimit {
                line: self.max_line,
                freq_hz: freq as f32,
                limit_hz: limit as f32,
            });
        }
        if !(self.cutoff_hz.is_finite() && self.cutoff_hz > 0.0) {
            return Err(ExcitationError::BadCutoff {
                cutoff_hz: self.cutoff_hz,
            });
        }
        if !(self.rms_rad.is_finite() && self.rms_rad >= 0.0) {
            return Err(ExcitationError::BadRms {
                rms_rad: self.rms_rad,
            });
        }
        Ok(())
    }

    /// Full check: [`validate_structure`](Self::validate_structure), then the
    /// peak angle and the peak velocity (ramp included) of the signal.
    ///
    /// This evaluates one period (N·lines phasor rotations, no storage); on
    /// the board prefer [`Excitation::new_checked`], which checks the table it
    /// has just generated and gives the same figures.
    ///
    /// # Errors
    /// The first violated limit, with value and limit.
    pub fn validate(&self, limits: &SafetyLimits) -> Result<(), ExcitationError> {
        self.validate_structure(limits)?;
        let mut tracker = PeakTracker::new(self);
        for_each_period_sample(self, |_, x| tracker.push(x));
        check_peaks(&tracker.finish(self), limits)
    }

    /// Peaks of one full-amplitude period (see [`SignalPeaks`]).
    ///
    /// # Errors
    /// Structural errors as in [`validate_structure`](Self::validate_structure) with permissive limits.
    pub fn peaks(&self) -> Result<SignalPeaks, ExcitationError> {
        self.validate_structure(&SafetyLimits {
            peak_angle_rad: f32::INFINITY,
            peak_velocity_rad_s: f32::INFINITY,
            max_line_fraction_of_nyquist: 1.0,
        })?;
        let mut tracker = PeakTracker::new(self);
        for_each_period_sample(self, |_, x| tracker.push(x));
        Ok(tracker.finish(self))
    }

    /// Unscaled amplitude shape at harmonic `k`: `1/sqrt(1 + (k·f0/fc)²)`.
    fn shape(&self, k: u32) -> f64 {
        let ratio = k as f64 * self.f0_hz() / self.cutoff_hz as f64;
        1.0 / libm::sqrt(1.0 + ratio * ratio)
    }
}

fn check_peaks(peaks: &SignalPeaks, limits: &SafetyLimits) -> Result<(), ExcitationError> {
    if peaks.angle_rad > limits.peak_angle_rad {
        return Err(ExcitationError::PeakAngle {
            value_rad: peaks.angle_rad,
            limit_rad: limits.peak_angle_rad,
        });
    }
    if peaks.velocity_with_ramp_rad_s > limits.peak_velocity_rad_s {
        return Err(ExcitationError::PeakVelocity {
            value_rad_s: peaks.velocity_with_ramp_rad_s,
            limit_rad_s: limits.peak_velocity_rad_s,
        });
    }
    Ok(())
}

/// Running peak angle / finite-difference velocity over one period.
struct PeakTracker {
    first: f32,
    prev: Option<f32>,
    peak_angle: f32,
    peak_step: f32,
}

impl PeakTracker {
    fn new(_cfg: &ExcitationConfig) -> Self {
        Self {
            first: 0.0,
            prev: None,
            peak_angle: 0.0,
            peak_step: 0.0,
        }
    }

    fn push(&mut self, x: f32) {
        match self.prev {
            None => self.first = x,
            Some(p) => self.peak_step = self.peak_step.max((x - p).abs()),
        }
        self.peak_angle = self.peak_angle.max(x.abs());
        self.prev = Some(x);
    }

    fn finish(mut self, cfg: &ExcitationConfig) -> SignalPeaks {
        if let Some(p) = self.prev {
            // the period wraps around: last sample to first
            self.peak_step = self.peak_step.max((self.first - p).abs());
        }
        let fs = cfg.fs_hz as f32;
        let velocity = self.peak_step * fs;
        // d/dt of w(t)·x(t) ≤ max|x'| + max|w'|·max|x|, max|w'| = π·fs/(2R)
        let ramp = if cfg.ramp_samples > 0 {
            self.peak_angle * core::f32::consts::PI * fs / (2.0 * cfg.ramp_samples as f32)
        } else {
            // no ramp: the reference jumps from rest to the table, up to
            // the peak within one sample
            self.peak_angle * fs
        };
        SignalPeaks {
            angle_rad: self.peak_angle,
            velocity_rad_s: velocity,
            velocity_with_ramp_rad_s: velocity + ramp,
        }
    }
}

/// One line of the design: harmonic `k`, coefficients of `sin` and `cos`
/// (so the line is `s·sin(2πkn/N) + c·cos(2πkn/N)`), before RMS scaling.
#[derive(Clone, Copy, Debug)]
struct Line {
    k: u32,
    s: f64,
    c: f64,
}

/// Iterator over the design lines in increasing `k`; replaying it from the
/// start gives the same values (the PRNG is re-seeded).
struct Lines<'c> {
    cfg: &'c ExcitationConfig,
    rng: SplitMix64,
    k: u32,
}

impl<'c> Lines<'c> {
    fn new(cfg: &'c ExcitationConfig) -> Self {
        let stream = match cfg.kind {
            SignalKind::SpecialOddMultisine => STREAM_SPECIAL_ODD,
            SignalKind::RandomOddMultisine => STREAM_RANDOM_ODD,
            SignalKind::BandLimitedNoise => STREAM_NOISE,
        };
        Self {
            cfg,
            rng: SplitMix64::new(cfg.seed ^ stream),
            k: 0,
        }
    }
}

impl Iterator for Lines<'_> {
    type Item = Line;

    fn next(&mut self) -> Option<Line> {
        loop {
            self.k = self.k.checked_add(1)?;
            if self.k > self.cfg.max_line {
                return None;
            }
            if !self.cfg.is_excited(self.k) {
                continue;
            }
            let shape = self.cfg.shape(self.k);
            return Some(match self.cfg.kind {
                SignalKind::SpecialOddMultisine | SignalKind::RandomOddMultisine => {
                    // shape·sin(θ + φ) = shape·cos φ·sin θ + shape·sin φ·cos θ
                    let phi = core::f64::consts::TAU * self.rng.next_f64();
                    Line {
                        k: self.k,
                        s: shape * libm::cos(phi),
                        c: shape * libm::sin(phi),
                    }
                }
                SignalKind::BandLimitedNoise => {
                    let (g1, g2) = self.rng.next_gaussian_pair();
                    Line {
                        k: self.k,
                        s: shape * g1,
                        c: shape * g2,
                    }
                }
            });
        }
    }
}

/// Factor that brings the design to `rms_rad`: `rms / sqrt(Σ (s²+c²)/2)`.
fn rms_scale(cfg: &ExcitationConfig) -> f64 {
    let mut power = 0.0;
    for line in Lines::new(cfg) {
        power += (line.s * line.s + line.c * line.c) / 2.0;
    }
    if power > 0.0 {
        cfg.rms_rad as f64 / libm::sqrt(power)
    } else {
        0.0
    }
}

/// One line rounded for generation: f32 coefficients and the f32 phasor
/// `e^{j2πk/N}` that advances it by one sample.
#[derive(Clone, Copy, Debug)]
struct LineF32 {
    k: u32,
    s: f32,
    c: f32,
    ws: f32,
    wc: f32,
}

impl LineF32 {
    fn new(line: &Line, scale: f64, tau_over_n: f64) -> Self {
        let (ws, wc) = libm::sincos(line.k as f64 * tau_over_n);
        Self {
            k: line.k,
            s: (line.s * scale) as f32,
            c: (line.c * scale) as f32,
            ws: ws as f32,
            wc: wc as f32,
        }
    }

    /// Adds this line to `acc[i]` = sample `n0 + i` (`acc.len() ≤ CHUNK`):
    /// phasor from the exact integer phase `(k·n0) mod N` (f64 `sincos`),
    /// then rotated in f32 sample by sample.
    fn add_chunk(&self, n0: usize, n: u64, tau_over_n: f64, acc: &mut [f32]) {
        let m = (self.k as u64 * n0 as u64) % n;
        let (sn0, cs0) = libm::sincos(m as f64 * tau_over_n);
        let (mut sn, mut cs) = (sn0 as f32, cs0 as f32);
        for a in acc.iter_mut() {
            let v = self.s * sn + self.c * cs;
            *a += v;
            let next_cs = cs * self.wc - sn * self.ws;
            let next_sn = sn * self.wc + cs * self.ws;
            cs = next_cs;
            sn = next_sn;
        }
    }
}

/// Computes one full-amplitude period and hands each sample `(n, x[n])` to `f`
/// in order `n = 0..N`, without a table (the lines are replayed per chunk).
/// Bit-identical to [`fill_period`]: every sample sees the same f32
/// operations in the same order (lines in increasing `k`).
fn for_each_period_sample(cfg: &ExcitationConfig, mut f: impl FnMut(usize, f32)) {
    let n_total = cfg.period_samples as usize;
    let scale = rms_scale(cfg);
    let tau_over_n = core::f64::consts::TAU / cfg.period_samples as f64;
    let mut acc = [0.0f32; CHUNK];
    let mut n0 = 0usize;
    while n0 < n_total {
        let len = CHUNK.min(n_total - n0);
        acc.iter_mut().for_each(|a| *a = 0.0);
        for line in Lines::new(cfg) {
            LineF32::new(&line, scale, tau_over_n).add_chunk(
                n0,
                n_total as u64,
                tau_over_n,
                &mut acc[..len],
            );
        }
        for (i, a) in acc.iter().take(len).enumerate() {
            f(n0 + i, *a);
        }
        n0 += len;
    }
}

/// Fills `table[..N]` with one full-amplitude period: line by line, each
/// added over the whole period in chunks of [`CHUNK`] samples (module docs).
///
/// # Errors
/// [`ExcitationError::TableTooSmall`] and the structural errors of
/// [`ExcitationConfig::validate_structure`] (Nyquist limit not applied).
pub fn fill_period(cfg: &ExcitationConfig, table: &mut [f32]) -> Result<(), ExcitationError> {
    let needed = cfg.period_samples as usize;
    if table.len() < needed {
        return Err(ExcitationError::TableTooSmall {
            len: table.len(),
            needed,
        });
    }
    cfg.validate_structure(&SafetyLimits {
        peak_angle_rad: f32::INFINITY,
        peak_velocity_rad_s: f32::INFINITY,
        max_line_fraction_of_nyquist: 1.0,
    })?;
    let table = &mut table[..needed];
    table.iter_mut().for_each(|x| *x = 0.0);
    let scale = rms_scale(cfg);
    let tau_over_n = core::f64::consts::TAU / cfg.period_samples as f64;
    for line in Lines::new(cfg) {
        let l = LineF32::new(&line, scale, tau_over_n);
        for (chunk_index, chunk) in table.chunks_mut(CHUNK).enumerate() {
            l.add_chunk(chunk_index * CHUNK, needed as u64, tau_over_n, chunk);
        }
    }
    Ok(())
}

/// Crest factor `max|x| / rms(x)` of a signal (0 for an empty or all-zero one).
pub fn crest_factor(signal: &[f32]) -> f32 {
    let mut peak = 0.0f64;
    let mut sum_sq = 0.0f64;
    for &x in signal {
        let x = x as f64;
        peak = peak.max(x.abs());
        sum_sq += x * x;
    }
    if sum_sq == 0.0 {
        return 0.0;
    }
    (peak / libm::sqrt(sum_sq / signal.len() as f64)) as f32
}

/// Rising raised-cosine weight `h(j/r) = (1 - cos(π j/r))/2` for `0 ≤ j ≤ r`,
/// in f32 `+ − × ÷` only (correctly rounded on every target, no fused
/// multiply-add), so the board and the host agree bit for bit; cheap on a
/// single-precision FPU (a `cos` in f64 or `libm::cosf`, which works in f64
/// inside, is software floating point on a Cortex-M4F).
///
/// Uses `h(u) = sin²(πu/2)` for `u ≤ 1/2` and the mirror `h(u) = 1 - h(1 - u)`
/// above, with `1 - u = (r - j)/r` taken in integers, so `h` is exactly 0 at
/// `j = 0` and exactly 1 at `j = r`. `sin t` for `t ≤ π/4` is its Taylor
/// polynomial to `t⁹` (truncation below 3e-9); the weight is within a few
/// f32 ulps of the raised cosine.
fn ramp_rise(j: u32, r: u32) -> f32 {
    let (m, mirrored) = if j <= r - j {
        (j, false)
    } else {
        (r - j, true)
    };
    let t = core::f32::consts::FRAC_PI_2 * (m as f32 / r as f32);
    let t2 = t * t;
    let poly = 1.0
        + t2 * (-1.0 / 6.0 + t2 * (1.0 / 120.0 + t2 * (-1.0 / 5040.0 + t2 * (1.0 / 362_880.0))));
    let s = t * poly;
    let h = s * s;
    if mirrored {
        1.0 - h
    } else {
        h
    }
}

/// Generator: ramp-in, full-amplitude periods, ramp-out. Storage for one
/// period is supplied by the caller (no allocation).
#[derive(Debug)]
pub struct Excitation<'a> {
    table: &'a [f32],
    ramp: u32,
    /// sample index k of the next output
    k: u64,
    /// k mod N, kept alongside k (no 64-bit division per sample)
    index: usize,
    /// first sample of the ramp-out, if known
    ramp_out_start: Option<u64>,
}

impl<'a> Excitation<'a> {
    /// Generates one period of `cfg` into `table` (`table.len() >= N`).
    ///
    /// # Errors
    /// [`ExcitationError::TableTooSmall`] and the structural errors; safety
    /// limits are not applied (see [`Excitation::new_checked`]).
    pub fn new(cfg: &ExcitationConfig, table: &'a mut [f32]) -> Result<Self, ExcitationError> {
        fill_period(cfg, table)?;
        let n = cfg.period_samples as usize;
        let ramp_out_start = cfg
            .total_samples()
            .map(|total| total - cfg.ramp_samples as u64);
        Ok(Self {
            table: &table[..n],
            ramp: cfg.ramp_samples,
            k: 0,
            index: 0,
            ramp_out_start,
        })
    }

    /// As [`Excitation::new`], then checks all of `limits` on the generated
    /// table (same figures as [`ExcitationConfig::validate`]).
    ///
    /// # Errors
    /// The first violated limit.
    pub fn new_checked(
        cfg: &ExcitationConfig,
        table: &'a mut [f32],
        limits: &SafetyLimits,
    ) -> Result<Self, ExcitationError> {
        cfg.validate_structure(limits)?;
        let this = Self::new(cfg, table)?;
        let mut tracker = PeakTracker::new(cfg);
        this.table.iter().for_each(|&x| tracker.push(x));
        check_peaks(&tracker.finish(cfg), limits)?;
        Ok(this)
    }

    /// One full-amplitude period [rad].
    pub fn period(&self) -> &[f32] {
        self.table
    }

    /// Index k of the next sample.
    pub fn position(&self) -> u64 {
        self.k
    }

    /// Starts the ramp-out at the next sample (for endless runs; a finite run
    /// ends earlier if its own ramp-out comes first). Has no effect while the
    /// ramp-in is running: the ramp-out then starts right after it.
    pub fn begin_ramp_out(&mut self) {
        let start = self.k.max(self.ramp as u64);
        self.ramp_out_start = Some(match self.ramp_out_start {
            Some(s) => s.min(start),
            None => start,
        });
    }

    /// Whether every sample has been produced.
    pub fn is_finished(&self) -> bool {
        matches!(self.ramp_out_start, Some(s) if self.k >= s + self.ramp as u64)
    }

    /// Next reference sample θ_ref(k) [rad], ramp applied; `None` after the end.
    #[allow(clippy::should_implement_trait)]
    pub fn next(&mut self) -> Option<f32> {
        if self.is_finished() || self.table.is_empty() {
            return None;
        }
        let k = self.k;
        let x = self.table.get(self.index).copied().unwrap_or(0.0);
        // ramp-in: h(k/R); ramp-out, its mirror: h((R-1-i)/R) at i = k - start
        // (the raised cosine (1 + cos(π(i+1)/R))/2), 0 at the last sample
        let w = match self.ramp_out_start {
            Some(start) if k >= start => {
                // k - start < R here (otherwise finished)
                Some(ramp_rise(self.ramp - 1 - (k - start) as u32, self.ramp))
            }
            _ if k < self.ramp as u64 => Some(ramp_rise(k as u32, self.ramp)),
            _ => None,
        };
        self.k += 1;
        self.index += 1;
        if self.index == self.table.len() {
            self.index = 0;
        }
        Some(match w {
            Some(w) => w * x,
            None => x,
        })
    }
}

/// Whole finite run of `cfg` (ramps included), as `Excitation::next` produces it.
///
/// # Errors
/// [`ExcitationError::Endless`] when `periods == 0`, and the errors of [`Excitation::new`].
#[cfg(any(feature = "std", test))]
pub fn generate(cfg: &ExcitationConfig) -> Result<Vec<f32>, ExcitationError> {
    let total = cfg.total_samples().ok_or(ExcitationError::Endless)?;
    let mut table = vec![0.0f32; cfg.period_samples as usize];
    let mut exc = Excitation::new(cfg, &mut table)?;
    let mut out = Vec::with_capacity(total as usize);
    while let Some(x) = exc.next() {
        out.push(x);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Plain DFT of one period at bins `0..=max_bin`: amplitude of each line,
    /// `|X_k|·2/N`, with an exact integer-phase cosine/sine table.
    fn line_amplitudes(x: &[f32], max_bin: usize) -> Vec<f64> {
        let n = x.len();
        let cos: Vec<f64> = (0..n)
            .map(|m| (std::f64::consts::TAU * m as f64 / n as f64).cos())
            .collect();
        let sin: Vec<f64> = (0..n)
            .map(|m| (std::f64::consts::TAU * m as f64 / n as f64).sin())
            .collect();
        (0..=max_bin)
            .map(|k| {
                let (mut re, mut im) = (0.0, 0.0);
                for (i, &v) in x.iter().enumerate() {
                    let m = (k * i) % n;
                    re += v as f64 * cos[m];
                    im -= v as f64 * sin[m];
                }
                (re * re + im * im).sqrt() * 2.0 / n as f64
            })
            .collect()
    }

    fn period_of(cfg: &ExcitationConfig) -> Vec<f32> {
        let mut table = vec![0.0f32; cfg.period_samples as usize];
        fill_period(cfg, &mut table).unwrap();
        table
    }

    fn db(x: f64) -> f64 {
        20.0 * x.log10()
    }

    #[test]
    fn special_odd_multisine_has_designed_lines_and_clean_gaps() {
        let cfg = ExcitationConfig::paper_default();
        assert_eq!(cfg.line_count(), 76);
        let x = period_of(&cfg);
        let amps = line_amplitudes(&x, cfg.period_samples as usize / 2 - 1);
        // designed amplitudes: shape·scale
        let scale = rms_scale(&cfg);
        let largest = amps.iter().cloned().fold(0.0, f64::max);
        let mut excited = 0;
        let mut worst_gap = f64::NEG_INFINITY;
        let mut worst_amp_err = 0.0f64;
        for (k, &a) in amps.iter().enumerate() {
            if cfg.is_excited(k as u32) {
                excited += 1;
                let designed = cfg.shape(k as u32) * scale;
                let err_db = (db(a) - db(designed)).abs();
                worst_amp_err = worst_amp_err.max(err_db);
                assert!(
                    err_db < 0.05,
                    "line {k}: {a} vs designed {designed} ({err_db} dB)"
                );
            } else {
                worst_gap = worst_gap.max(db(a) - db(largest));
                assert!(
                    db(a) - db(largest) <= -100.0,
                    "line {k} at {} dB below the largest",
                    db(a) - db(largest)
                );
            }
        }
        assert_eq!(excited, 76);
        eprintln!("worst non-excited line {worst_gap:.1} dB, worst amplitude error {worst_amp_err:.2e} dB");
        // 1, 3, 9, 11, ... 297, 299 and 304 is even: F itself not excited
        assert!(cfg.is_excited(1) && cfg.is_excited(3) && cfg.is_excited(9));
        assert!(!cfg.is_excited(5) && !cfg.is_excited(7) && !cfg.is_excited(2));
    }

    #[test]
    fn period_rms_equals_requested_rms_within_1e5() {
        for kind in [
            SignalKind::SpecialOddMultisine,
            SignalKind::RandomOddMultisine,
            SignalKind::BandLimitedNoise,
        ] {
            let cfg = ExcitationConfig {
                kind,
                ..ExcitationConfig::paper_default()
            };
            let x = period_of(&cfg);
            let rms = (x.iter().map(|&v| (v as f64).powi(2)).sum::<f64>() / x.len() as f64).sqrt();
            assert!(
                (rms / cfg.rms_rad as f64 - 1.0).abs() < 1e-5,
                "{kind:?}: rms {rms}"
            );
        }
    }

    #[test]
    fn random_odd_multisine_excites_every_odd_line_only() {
        let cfg = ExcitationConfig {
            kind: SignalKind::RandomOddMultisine,
            max_line: 60,
            period_samples: 1000,
            ..ExcitationConfig::paper_default()
        };
        let x = period_of(&cfg);
        let amps = line_amplitudes(&x, 200);
        let scale = rms_scale(&cfg);
        for (k, &a) in amps.iter().enumerate().skip(1) {
            if k % 2 == 1 && k <= 60 {
                let designed = cfg.shape(k as u32) * scale;
                assert!((db(a) - db(designed)).abs() < 0.05, "line {k}");
            } else {
                assert!(a < 1e-5 * cfg.rms_rad as f64, "line {k}: {a}");
            }
        }
        // phases differ from the special odd design with the same seed
        let special = period_of(&ExcitationConfig {
            kind: SignalKind::SpecialOddMultisine,
            ..cfg
        });
        assert_ne!(x, special);
    }

    #[test]
    fn band_limited_noise_is_gaussian_and_band_limited() {
        let cfg = ExcitationConfig {
            kind: SignalKind::BandLimitedNoise,
            ..ExcitationConfig::paper_default()
        };
        let x = period_of(&cfg);
        let amps = line_amplitudes(&x, 400);
        for (k, &a) in amps.iter().enumerate() {
            if k == 0 || k > 304 {
                assert!(a < 1e-5 * cfg.rms_rad as f64, "line {k}: {a}");
            }
        }
        // Gaussian: kurtosis near 3 (stated tolerance ±0.3 for 5000 samples
        // of a process with ~300 degrees of freedom)
        let n = x.len() as f64;
        let mean = x.iter().map(|&v| v as f64).sum::<f64>() / n;
        let m2 = x.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / n;
        let m4 = x.iter().map(|&v| (v as f64 - mean).powi(4)).sum::<f64>() / n;
        let kurtosis = m4 / (m2 * m2);
        assert!((kurtosis - 3.0).abs() < 0.3, "kurtosis {kurtosis}");
    }

    #[test]
    fn consecutive_periods_are_bit_identical() {
        let cfg = ExcitationConfig {
            ramp_samples: 777,
            periods: 3,
            ..ExcitationConfig::paper_default()
        };
        let run = generate(&cfg).unwrap();
        let n = cfg.period_samples as usize;
        let r = cfg.ramp_samples as usize;
        let p1 = &run[r..r + n];
        let p2 = &run[r + n..r + 2 * n];
        let p3 = &run[r + 2 * n..r + 3 * n];
        assert!(p1.iter().zip(p2).all(|(a, b)| a.to_bits() == b.to_bits()));
        assert!(p2.iter().zip(p3).all(|(a, b)| a.to_bits() == b.to_bits()));
        // and the full-amplitude part is the table, indexed by k mod N
        let table = period_of(&cfg);
        for (i, v) in p1.iter().enumerate() {
            assert_eq!(v.to_bits(), table[(r + i) % n].to_bits());
        }
    }

    #[test]
    fn generate_equals_next_sequence() {
        let cfg = ExcitationConfig {
            kind: SignalKind::RandomOddMultisine,
            periods: 2,
            ramp_samples: 1500,
            ..ExcitationConfig::paper_default()
        };
        let run = generate(&cfg).unwrap();
        assert_eq!(run.len() as u64, cfg.total_samples().unwrap());
        let mut table = vec![0.0f32; 6000];
        let mut exc = Excitation::new(&cfg, &mut table).unwrap();
        let mut count = 0;
        while let Some(v) = exc.next() {
            assert_eq!(v.to_bits(), run[count].to_bits(), "sample {count}");
            count += 1;
        }
        assert_eq!(count, run.len());
        assert_eq!(exc.next(), None);
        assert!(exc.is_finished());
    }

    #[test]
    fn table_matches_pinned_bits() {
        // Pins the generator's arithmetic: a change here changes what the
        // host regenerates for captures already taken (bump PROTOCOL_VERSION).
        let x = period_of(&ExcitationConfig::paper_default());
        let pinned: Vec<u32> = [0usize, 1, 2, 1234, 4999]
            .iter()
            .map(|&i| x[i].to_bits())
            .collect();
        let expected: [u32; 5] = PINNED_BITS;
        assert_eq!(
            pinned,
            expected,
            "values {:?}",
            pinned
                .iter()
                .map(|&b| f32::from_bits(b))
                .collect::<Vec<_>>()
        );
    }

    /// CRC-32 of the little-endian f32 bits of (one period, the whole run)
    /// of `paper_default()` with each kind, as computed on a Cortex-M4
    /// (thumbv7em-none-eabihf, firmware profile, qemu-system-arm 7.2
    /// mps2-an386; run CRCs re-measured for the f32 ramp weight).
    /// Equality on the host shows the table is bit-identical on both.
    const CORTEX_M4_CRCS: [(SignalKind, u32, u32); 3] = [
        (SignalKind::SpecialOddMultisine, 0xdf67_d099, 0xa06c_367e),
        (SignalKind::RandomOddMultisine, 0xd7f2_b943, 0xd3e2_648a),
        (SignalKind::BandLimitedNoise, 0x00f0_7402, 0x8bd7_0a2b),
    ];

    #[test]
    fn host_table_and_run_match_cortex_m4_bits() {
        for (kind, table_crc, run_crc) in CORTEX_M4_CRCS {
            let cfg = ExcitationConfig {
                kind,
                ..ExcitationConfig::paper_default()
            };
            let mut table = vec![0.0f32; 5000];
            let mut exc = Excitation::new(&cfg, &mut table).unwrap();
            let mut run = crate::wire::Crc32::new();
            let mut n = 0;
            while let Some(x) = exc.next() {
                run.update(&x.to_le_bytes());
                n += 1;
            }
            assert_eq!(n, 24_000);
            assert_eq!(
                crate::wire::reference_crc(exc.period()),
                table_crc,
                "{kind:?} table"
            );
            assert_eq!(run.finish(), run_crc, "{kind:?} run");
        }
    }

    const PINNED_BITS: [u32; 5] = [1009278708, 1011488412, 1014297114, 3162960695, 1007787986];

    #[test]
    fn ramps_start_and_end_at_zero_without_steps() {
        let cfg = ExcitationConfig {
            ramp_samples: 2000,
            periods: 1,
            ..ExcitationConfig::paper_default()
        };
        let run = generate(&cfg).unwrap();
        assert_eq!(run[0], 0.0);
        assert_eq!(*run.last().unwrap(), 0.0);
        let peaks = cfg.peaks().unwrap();
        let max_step = run
            .windows(2)
            .map(|w| (w[1] - w[0]).abs())
            .fold(0.0f32, f32::max);
        // no sample-to-sample change larger than the bound used by validate
        assert!(max_step * cfg.fs_hz as f32 <= peaks.velocity_with_ramp_rad_s * 1.000_01);
        // first step is tiny: w(1)·x(1) with w(1) = (1-cos(π/R))/2 ≈ 6e-7
        assert!(run[1].abs() < 1e-6 * peaks.angle_rad);
        // weights are monotone during the ramps
        let table = period_of(&cfg);
        let n = cfg.period_samples as usize;
        let mut prev_w = 0.0;
        for (k, &v) in run.iter().enumerate().take(2000).skip(1) {
            let t = table[k % n];
            if t.abs() > 1e-3 {
                let w = v / t;
                assert!(w >= prev_w - 1e-6, "ramp-in weight fell at {k}");
                prev_w = w;
            }
        }
    }

    #[test]
    fn ramp_weight_is_the_raised_cosine_within_3e7_and_exact_at_the_ends() {
        for r in [1u32, 2, 3, 7, 100, 2000, 4001, 100_000] {
            assert_eq!(ramp_rise(0, r).to_bits(), 0.0f32.to_bits(), "r {r}");
            assert_eq!(ramp_rise(r, r), 1.0, "r {r}");
            let mut prev = 0.0f32;
            for j in 0..=r {
                let w = ramp_rise(j, r);
                let exact = 0.5 - 0.5 * (std::f64::consts::PI * j as f64 / r as f64).cos();
                assert!(
                    (w as f64 - exact).abs() < 3e-7,
                    "r {r}, j {j}: {w} vs {exact}"
                );
                assert!((0.0..=1.0).contains(&w), "r {r}, j {j}: {w}");
                // monotone up to one rounding step
                assert!(w >= prev - 1.2e-7, "r {r}, j {j}: {w} after {prev}");
                prev = w;
            }
        }
        // the ramp-out is the ramp-in reversed, sample for sample
        let cfg = ExcitationConfig {
            ramp_samples: 300,
            periods: 1,
            period_samples: 1000,
            max_line: 80,
            ..ExcitationConfig::paper_default()
        };
        let run = generate(&cfg).unwrap();
        let table = period_of(&cfg);
        let (r, n, total) = (300usize, 1000usize, run.len());
        for i in 0..r {
            let w_in = ramp_rise(i as u32, 300);
            let w_out = ramp_rise((r - 1 - i) as u32, 300);
            assert_eq!(run[i].to_bits(), (w_in * table[i % n]).to_bits());
            let k = total - r + i;
            assert_eq!(run[k].to_bits(), (w_out * table[k % n]).to_bits());
        }
    }

    #[test]
    fn begin_ramp_out_ends_an_endless_run_smoothly() {
        let cfg = ExcitationConfig {
            periods: 0,
            ramp_samples: 100,
            period_samples: 1000,
            max_line: 80,
            ..ExcitationConfig::paper_default()
        };
        assert_eq!(cfg.total_samples(), None);
        let mut table = [0.0f32; 1000];
        let mut exc = Excitation::new(&cfg, &mut table).unwrap();
        for _ in 0..5000 {
            assert!(exc.next().is_some());
        }
        exc.begin_ramp_out();
        let mut last = 1.0;
        let mut count = 0;
        while let Some(v) = exc.next() {
            last = v;
            count += 1;
        }
        assert_eq!(count, 100);
        assert_eq!(last, 0.0);
    }

    #[test]
    fn limits_report_their_figures() {
        let limits = SafetyLimits::default();
        let cfg = ExcitationConfig::paper_default();
        assert_eq!(cfg.validate(&limits), Ok(()));
        let peaks = cfg.peaks().unwrap();

        // peak angle
        let tight = SafetyLimits {
            peak_angle_rad: 0.03,
            ..limits
        };
        assert_eq!(
            cfg.validate(&tight),
            Err(ExcitationError::PeakAngle {
                value_rad: peaks.angle_rad,
                limit_rad: 0.03
            })
        );
        // crest factor of a multisine with random phases is between 2.5 and 5
        assert!(peaks.angle_rad > 2.5 * cfg.rms_rad && peaks.angle_rad < 5.0 * cfg.rms_rad);

        // peak velocity
        let slow = SafetyLimits {
            peak_velocity_rad_s: 1.0,
            ..limits
        };
        match cfg.validate(&slow) {
            Err(ExcitationError::PeakVelocity {
                value_rad_s,
                limit_rad_s,
            }) => {
                assert_eq!(limit_rad_s, 1.0);
                assert_eq!(value_rad_s, peaks.velocity_with_ramp_rad_s);
            }
            other => panic!("expected PeakVelocity, got {other:?}"),
        }
        // same figures from the table on the board path
        let mut table = vec![0.0f32; 5000];
        assert_eq!(
            Excitation::new_checked(&cfg, &mut table, &slow).err(),
            cfg.validate(&slow).err()
        );

        // highest line above Nyquist/2.5: F = 1251 at 0.4 Hz = 500.4 Hz > 400 Hz
        let high = ExcitationConfig {
            max_line: 1251,
            ..cfg
        };
        match high.validate(&limits) {
            Err(ExcitationError::LineAboveLimit {
                line,
                freq_hz,
                limit_hz,
            }) => {
                assert_eq!(line, 1251);
                assert!((freq_hz - 500.4).abs() < 1e-3);
                assert_eq!(limit_hz, 400.0);
            }
            other => panic!("expected LineAboveLimit, got {other:?}"),
        }

        // no lines
        let none = ExcitationConfig { max_line: 0, ..cfg };
        assert_eq!(
            none.validate(&limits),
            Err(ExcitationError::NoLines { max_line: 0 })
        );

        // table too small
        let mut small = [0.0f32; 4999];
        assert_eq!(
            Excitation::new(&cfg, &mut small).err(),
            Some(ExcitationError::TableTooSmall {
                len: 4999,
                needed: 5000
            })
        );

        // period too short for the lines
        let short = ExcitationConfig {
            period_samples: 600,
            ..cfg
        };
        assert_eq!(
            short.validate(&limits),
            Err(ExcitationError::PeriodTooShort {
                period_samples: 600,
                min_samples: 609
            })
        );
    }

    #[test]
    fn bad_shape_rms_and_rate_are_refused_with_their_values() {
        let limits = SafetyLimits::default();
        let cfg = ExcitationConfig::paper_default();
        for cutoff_hz in [0.0, -5.0, f32::NAN] {
            match (ExcitationConfig { cutoff_hz, ..cfg }).validate(&limits) {
                Err(ExcitationError::BadCutoff { cutoff_hz: got }) => {
                    assert_eq!(got.to_bits(), cutoff_hz.to_bits())
                }
                other => panic!("cut-off {cutoff_hz}: {other:?}"),
            }
        }
        assert_eq!(
            ExcitationConfig {
                rms_rad: -0.1,
                ..cfg
            }
            .validate(&limits),
            Err(ExcitationError::BadRms { rms_rad: -0.1 })
        );
        assert_eq!(
            ExcitationConfig { fs_hz: 0, ..cfg }.validate(&limits),
            Err(ExcitationError::ZeroSampleRate)
        );
        // no ramp means a jump from rest: refused by the velocity limit
        let no_ramp = ExcitationConfig {
            ramp_samples: 0,
            ..cfg
        };
        let peaks = no_ramp.peaks().unwrap();
        assert_eq!(
            no_ramp.validate(&limits),
            Err(ExcitationError::PeakVelocity {
                value_rad_s: peaks.velocity_rad_s + peaks.angle_rad * 2000.0,
                limit_rad_s: limits.peak_velocity_rad_s
            })
        );
        // rms 0 is allowed: an all-zero run (a dry run of the whole chain)
        let zero = ExcitationConfig {
            rms_rad: 0.0,
            ..cfg
        };
        assert_eq!(zero.validate(&limits), Ok(()));
        assert!(period_of(&zero).iter().all(|&x| x == 0.0));
        // messages name value and limit
        let msg = format!(
            "{}",
            ExcitationError::PeakAngle {
                value_rad: 0.7,
                limit_rad: 0.5
            }
        );
        assert_eq!(msg, "peak angle 0.7 rad exceeds the limit of 0.5 rad");
    }

    #[test]
    fn from_f0_refuses_non_integer_periods() {
        assert_eq!(
            ExcitationConfig::from_f0(2000, 0.4).unwrap(),
            ExcitationConfig::paper_default()
        );
        assert_eq!(
            ExcitationConfig::from_f0(2000, 0.25)
                .unwrap()
                .period_samples,
            8000
        );
        match ExcitationConfig::from_f0(2000, 0.7) {
            Err(ExcitationError::NonIntegerPeriod {
                fs_hz,
                f0_hz,
                ratio,
            }) => {
                assert_eq!(fs_hz, 2000);
                assert_eq!(f0_hz, 0.7);
                assert!((ratio - 2857.142857).abs() < 1e-5);
            }
            other => panic!("expected NonIntegerPeriod, got {other:?}"),
        }
        assert_eq!(
            ExcitationConfig::from_f0(0, 0.4),
            Err(ExcitationError::ZeroSampleRate)
        );
    }

    #[test]
    fn crest_factor_of_a_sine_is_sqrt_two() {
        let x: Vec<f32> = (0..1000)
            .map(|n| (std::f64::consts::TAU * 7.0 * n as f64 / 1000.0).sin() as f32)
            .collect();
        assert!((crest_factor(&x) - std::f32::consts::SQRT_2).abs() < 1e-4);
        assert_eq!(crest_factor(&[0.0; 4]), 0.0);
    }
}
