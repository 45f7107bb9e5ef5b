//! Unmodelled effects that can be switched on over any plant (../shared/DESIGN.md §6), and
//! the spec strings the CLI uses for them (`--effect backlash:width=0.002`).
//!
//! Each effect has its own parameters with documented defaults. The defaults are sized so
//! that the effect is clearly visible in the spectra of `u` and `θ_m` of the default
//! three-mass joint under the default excitation, core's `ExcitationConfig::paper_default()`
//! (special odd multisine, 0.02 rad RMS on the motor-angle reference). That amplitude is
//! small: it moves the motor by about 7 mrad RMS, deflects the gearbox by at most about
//! 6e-5 rad (arm side) and needs about 0.05 N·m RMS of torque, so the defaults are small in
//! absolute terms (4 arcsec of backlash, 0.03 N·m of Coulomb friction); scale them with the
//! excitation. Measured by the fingerprint tests in `crate::sim::tests` (power at the
//! non-excited odd lines relative to the excited ones, mean of 4 periods):
//! - backlash, Coulomb friction and the cubic spring raise the non-excited odd lines of `u`
//!   to 7e-3, 1.2e-2 and 1.4e-3 of the excited power (ideal sensors), 100–1000 times the
//!   floor of the default sensors (quantisation, noise, disturbance: 1.3e-5 in `u`);
//!   backlash and friction relatively more at small amplitude (at 4 times the amplitude:
//!   1.8e-4, 7.9e-4), the cubic spring more at large amplitude (2.5e-2);
//! - the extra mode adds a resonance near 10.4 Hz (anti-resonance 9.3 Hz), below the
//!   gearbox modes, where the motor-side FRF had none;
//! - the delay bends the phase of the `u → θ_m` FRF by −0.27° per Hz (1.5 samples);
//! - the torque ripple raises the even lines (it is not an odd function of the motion).
//!
//! Physics of each effect (where it acts in the plant):
//! - `coulomb_friction`: motor-side friction opposing the motor velocity ω with the
//!   Coulomb level plus a Stribeck bump, `τ_f = sgn(ω) [F_c + (F_s − F_c) e^{−(ω/v_s)²}]`
//!   while sliding, and set-valued at ω = 0: the motor sticks while the net torque on it is
//!   below the breakaway level `F_s` (friction balances it exactly) and breaks away when it
//!   exceeds it. The integrator treats sticking, stopping and breakaway as events (see
//!   [`crate::sim::integrate`]); no regularisation is used, so `v_ε` (`v_smooth`) only enters
//!   the smooth approximation [`CoulombFriction::torque`], kept for analysis.
//!   Optionally asymmetric (a drive whose friction differs with the direction of motion,
//!   EMPS: Janot, Gautier & Brunot 2019): `fc_neg` is the Coulomb level for ω < 0 (`fc`
//!   then holds for ω > 0; absent: `fc` both ways) and `fv_neg_extra` a viscous coefficient
//!   added to the plant's viscous friction `f_m` for ω < 0 only, so that `f_m` is the
//!   viscous coefficient `F_v+` of forward motion and `F_v− = f_m + fv_neg_extra` that of
//!   backward motion. The Stribeck bump `F_s − F_c` is the same both ways: backward the
//!   level is `fc_neg + (F_s − F_c) e^{−(ω/v_s)²} − fv_neg_extra ω` and the breakaway level
//!   `fc_neg + F_s − F_c`. While the motor moves, a constant torque offset equals half the
//!   difference of the two Coulomb levels; only the stuck phases tell them apart.
//! - `backlash`: dead zone of total width `w` in the gearbox spring: the spring torque is
//!   `k_g dz(δ) + k3 dz(δ)³ + d_g δ̇` in contact and 0 in the gap, `dz(δ) = δ − w/2` for
//!   `δ > w/2`, `δ + w/2` for `δ < −w/2`, 0 in between (δ = `r θ_m − θ_a1`, arm side). The
//!   contact edges are located exactly by the integrator (no smoothing).
//! - `nonlinear_stiffness`: cubic term `k3 δ³` added to the gearbox spring (seed 001 eq. (6)).
//! - `extra_mode`: one more mass `J` on a spring `k`, `d`, attached either in parallel to the
//!   first arm mass (as `J_p` in seed 000 eq. (7)) or in series after the last mass. Linear.
//! - `time_delay`: transport delay of the torque reference `u` before the current loop, in
//!   samples (whole and fractional). Because `u` is a zero-order-hold staircase, the
//!   delayed signal over sample `k` is `u[k−n−1]` for the first fraction φ of the sample and
//!   `u[k−n]` after it (`D = n + φ`). The simulator applies exactly this switch inside the
//!   sample (no linear interpolation, no Thiran approximation are needed): the delay of the
//!   continuous torque is exact. Linear.
//! - `torque_ripple`: `A sin(n θ_m + φ)` added to the motor torque (cogging / commutation
//!   ripple, `n` periods per motor revolution).
//!
//! Bounds of every parameter ([`Effect::bounds`], checked by [`Effect::check`] on every
//! spec and every configuration the simulator runs): physically sensible ranges for one
//! joint of an industrial robot, wide enough for any real one, narrow enough that the
//! simulator neither allocates without limit nor integrates numbers far outside physics.
//! Torques are on the motor side, where the controller's default limit `u_max` is 12 N·m.
//!
//! | effect | key | range | unit | why |
//! |---|---|---|---|---|
//! | `coulomb_friction` | `fc`, `fs` | 0 … 100 | N·m | eight times the default torque limit: a motor that cannot overcome its friction |
//! | | `v_stribeck`, `v_smooth` | 1e-6 … 1e3 | rad/s | 1e3 rad/s ≈ 9500 rpm, the motor's top speed |
//! | | `fc_neg` | 0 … 100 | N·m | as `fc` |
//! | | `fv_neg_extra` | −1e6 … 1e6 | N·m·s/rad | as an extra mode's damping, either sign |
//! | `backlash` | `width` | 0 … 0.1 | rad | 0.1 rad = 5.7° on the arm side, far beyond any gearbox |
//! | `nonlinear_stiffness` | `k3` | −1e16 … 1e16 | N·m/rad³ | 300 times the default 3e13; negative: softening |
//! | `extra_mode` | `j` | 1e-6 … 1e3 | kg·m² | |
//! | | `k` | 1e-3 … 1e9 | N·m/rad | |
//! | | `d` | 0 … 1e6 | N·m·s/rad | |
//! | `time_delay` | `samples` | 0 … 100 | samples | 50 ms at 2 kHz, far beyond a drive's dead time |
//! | `torque_ripple` | `amplitude` | −100 … 100 | N·m | as the friction levels |
//! | | `order` | −1e4 … 1e4 | periods per revolution | |
//! | | `phase` | −2π … 2π | rad | |
//!
//! `F_s ≥ F_c` is checked on a spec that names both; a spec that names `fc` above the
//! default `fs` and no `fs` (`coulomb_friction:fc=20`, EMPS's level in N) takes the
//! breakaway level up to `fc`: the pure law at that level, not an error.
//!
//! A configuration inside these bounds can still make the run diverge (a softening cubic
//! spring, say): the simulator then stops at the first non-finite sample and names it
//! with the effects (`SimError::NonFinite`).

use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// Coulomb friction with a Stribeck bump on the motor (smoothed near zero velocity).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CoulombFriction {
    /// Coulomb level `F_c` [N·m], motor side; default 0.03
    pub fc: f64,
    /// static (breakaway) level `F_s ≥ F_c` [N·m]; default 0.04
    pub fs: f64,
    /// Stribeck velocity `v_s` [rad/s], motor side; default 0.1
    pub v_stribeck: f64,
    /// regularisation velocity `v_ε` of the smooth approximation [`Self::torque`] [rad/s];
    /// default 0.01 (the simulator integrates the set-valued law and does not use it)
    pub v_smooth: f64,
    /// Coulomb level `F_c−` for negative motor velocity [N·m]; `None` (the default): `fc`
    /// both ways (symmetric)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fc_neg: Option<f64>,
    /// viscous friction added to the plant's `f_m` for negative motor velocity
    /// [N·m·s/rad], `F_v− = f_m + fv_neg_extra`; `None` (the default): none
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fv_neg_extra: Option<f64>,
}

impl Default for CoulombFriction {
    fn default() -> Self {
        CoulombFriction {
            fc: 0.03,
            fs: 0.04,
            v_stribeck: 0.1,
            v_smooth: 0.01,
            fc_neg: None,
            fv_neg_extra: None,
        }
    }
}

impl CoulombFriction {
    /// Coulomb level for negative velocity `F_c−` [N·m] (`fc` when symmetric).
    pub fn fc_backward(&self) -> f64 {
        self.fc_neg.unwrap_or(self.fc)
    }

    /// Whether the law differs with the direction of motion (`fc_neg` or `fv_neg_extra`
    /// given).
    pub fn is_asymmetric(&self) -> bool {
        self.fc_neg.is_some() || self.fv_neg_extra.is_some()
    }

    /// Breakaway levels `(F_s, F_c− + F_s − F_c)` [N·m] forward and backward: a stuck
    /// motor stays stuck while its net torque lies between `−backward` and `forward`.
    pub fn breakaway(&self) -> (f64, f64) {
        let bump = (self.fs - self.fc).max(0.0);
        (self.fs.max(self.fc), self.fc_backward() + bump)
    }

    /// Friction level while sliding forward (`backward` false) or backward at `omega`
    /// [rad/s] → [N·m]: forward `F_c + (F_s − F_c) e^{−(ω/v_s)²}`, backward
    /// `F_c− + (F_s − F_c) e^{−(ω/v_s)²} − fv_neg_extra ω` (the magnitude of the set-valued
    /// law the simulator integrates; the backward viscous term continued linearly through
    /// ω = 0, so that a step frozen in the backward mode sees a smooth law).
    pub fn level_dir(&self, omega: f64, backward: bool) -> f64 {
        let x = omega / self.v_stribeck;
        let bump = if x.abs() < 6.0 {
            (self.fs - self.fc) * (-x * x).exp()
        } else {
            0.0
        };
        if backward {
            self.fc_backward() + bump - self.fv_neg_extra.unwrap_or(0.0) * omega
        } else {
            self.fc + bump
        }
    }

    /// [`Self::level_dir`] in the direction of `omega` [rad/s] → [N·m].
    pub fn level(&self, omega: f64) -> f64 {
        self.level_dir(omega, omega < 0.0)
    }

    /// Regularised friction torque opposing the motor velocity `omega` [rad/s] → [N·m]:
    /// [`crate::model::laws::coulomb_smooth_asym`] with the levels of [`Self::level_dir`]
    /// and `v_ε`; a smooth approximation of the set-valued law, for analysis (the simulator
    /// does not use it). Symmetric: `level(ω) tanh(ω/v_ε)`.
    pub fn torque(&self, omega: f64) -> f64 {
        let x = omega / self.v_stribeck;
        let bump = if x.abs() < 6.0 {
            (self.fs - self.fc) * (-x * x).exp()
        } else {
            0.0
        };
        let s = omega / self.v_smooth;
        let s = if s.abs() < 20.0 { s.tanh() } else { s.signum() };
        crate::model::laws::coulomb_smooth_asym_tanh(
            self.fc + bump,
            self.fc_backward() + bump,
            self.fv_neg_extra.unwrap_or(0.0),
            omega,
            s,
        )
    }

    /// Derivative `dτ_f/dω` at `omega` [N·m·s/rad].
    pub fn slope(&self, omega: f64) -> f64 {
        let x = omega / self.v_stribeck;
        let (level, dlevel) = if x.abs() < 6.0 {
            let e = (-x * x).exp();
            (
                self.fc + (self.fs - self.fc) * e,
                -(self.fs - self.fc) * e * 2.0 * x / self.v_stribeck,
            )
        } else {
            (self.fc, 0.0)
        };
        let s = omega / self.v_smooth;
        if s.abs() >= 20.0 {
            return dlevel * s.signum();
        }
        let t = s.tanh();
        dlevel * t + level * (1.0 - t * t) / self.v_smooth
    }

    /// Upper bound of `|dτ_f/dω|` [N·m·s/rad], used to size refined steps.
    pub fn max_slope(&self) -> f64 {
        let (fwd, bwd) = self.breakaway();
        fwd.max(bwd) / self.v_smooth
            + (self.fs - self.fc).abs() * 0.86 / self.v_stribeck
            + self.fv_neg_extra.unwrap_or(0.0).abs()
    }
}

/// Dead zone in the gearbox spring.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Backlash {
    /// total width `w` of the dead zone [rad], arm side; default 2e-5 (4 arcsec)
    pub width: f64,
}

impl Default for Backlash {
    fn default() -> Self {
        Backlash { width: 2.0e-5 }
    }
}

/// Cubic stiffening of the gearbox spring.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct NonlinearStiffness {
    /// cubic coefficient `k3` [N·m/rad³]; default 2e13 (`k3 δ²` = 16 % of `k_g` at δ = 3e-5 rad)
    pub k3: f64,
}

impl Default for NonlinearStiffness {
    fn default() -> Self {
        NonlinearStiffness { k3: 3.0e13 }
    }
}

/// Where an extra mass is attached.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Attach {
    /// to the first arm mass, in parallel with the rest of the arm (like `J_p`, eq. (7))
    Parallel,
    /// to the last mass of the chain
    Serial,
}

/// One more mass on a spring.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ExtraMode {
    /// inertia `J` [kg·m²], arm side; default 3.0 (a quarter of `J_a1`)
    pub j: f64,
    /// stiffness `k` [N·m/rad]; default 1.18e4 (10 Hz with `J_a1` held still)
    pub k: f64,
    /// damping `d` [N·m·s/rad]; default 7.5 (2 % of critical)
    pub d: f64,
    /// attachment; default parallel
    pub attach: Attach,
}

impl Default for ExtraMode {
    fn default() -> Self {
        ExtraMode {
            j: 3.0,
            k: 1.18e4,
            d: 7.5,
            attach: Attach::Parallel,
        }
    }
}

/// Transport delay of the torque reference.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct TimeDelay {
    /// delay `D = n + φ` [samples] (≥ 0, fractional allowed); default 1.5 (0.75 ms at 2 kHz)
    pub samples: f64,
}

impl Default for TimeDelay {
    fn default() -> Self {
        TimeDelay { samples: 1.5 }
    }
}

/// Position-dependent motor torque `A sin(n θ_m + φ)`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct TorqueRipple {
    /// amplitude `A` [N·m]; default 0.02
    pub amplitude: f64,
    /// periods `n` per motor revolution [-]; default 72 (`jointid fit` finds it in the
    /// data unless given, [`crate::ident::nonlinear::ripple`])
    pub order: f64,
    /// phase `φ` [rad]; default 0.5
    pub phase: f64,
}

impl Default for TorqueRipple {
    fn default() -> Self {
        TorqueRipple {
            amplitude: 0.02,
            order: 72.0,
            phase: 0.5,
        }
    }
}

/// One switchable effect with its parameters.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "effect", rename_all = "snake_case")]
pub enum Effect {
    /// see [`CoulombFriction`]
    CoulombFriction(CoulombFriction),
    /// see [`Backlash`]
    Backlash(Backlash),
    /// see [`NonlinearStiffness`]
    NonlinearStiffness(NonlinearStiffness),
    /// see [`ExtraMode`]
    ExtraMode(ExtraMode),
    /// see [`TimeDelay`]
    TimeDelay(TimeDelay),
    /// see [`TorqueRipple`]
    TorqueRipple(TorqueRipple),
}

/// Effect names accepted by [`Effect::from_str`] (plus `none` in [`parse_effects`]).
pub const EFFECT_NAMES: [&str; 6] = [
    "coulomb_friction",
    "backlash",
    "nonlinear_stiffness",
    "extra_mode",
    "time_delay",
    "torque_ripple",
];

impl Effect {
    /// Whether the effect acts on the gearbox spring (backlash, cubic spring), which a
    /// rigid plant does not have.
    pub fn acts_on_gearbox(&self) -> bool {
        matches!(self, Effect::Backlash(_) | Effect::NonlinearStiffness(_))
    }

    /// Whether the joint with the effect is still linear (a delay, a further mode): its
    /// response to a periodic excitation stays at the excited lines.
    pub fn is_linear(&self) -> bool {
        matches!(self, Effect::TimeDelay(_) | Effect::ExtraMode(_))
    }

    /// Spec name of the effect (`backlash`, ...).
    pub fn name(&self) -> &'static str {
        match self {
            Effect::CoulombFriction(_) => "coulomb_friction",
            Effect::Backlash(_) => "backlash",
            Effect::NonlinearStiffness(_) => "nonlinear_stiffness",
            Effect::ExtraMode(_) => "extra_mode",
            Effect::TimeDelay(_) => "time_delay",
            Effect::TorqueRipple(_) => "torque_ripple",
        }
    }

    /// The effect with its default parameters, by spec name.
    pub fn default_by_name(name: &str) -> Option<Effect> {
        Some(match name {
            "coulomb_friction" => Effect::CoulombFriction(CoulombFriction::default()),
            "backlash" => Effect::Backlash(Backlash::default()),
            "nonlinear_stiffness" => Effect::NonlinearStiffness(NonlinearStiffness::default()),
            "extra_mode" => Effect::ExtraMode(ExtraMode::default()),
            "time_delay" => Effect::TimeDelay(TimeDelay::default()),
            "torque_ripple" => Effect::TorqueRipple(TorqueRipple::default()),
            _ => return None,
        })
    }

    /// Every default effect, in [`EFFECT_NAMES`] order.
    pub fn all_defaults() -> Vec<Effect> {
        EFFECT_NAMES
            .iter()
            .filter_map(|n| Effect::default_by_name(n))
            .collect()
    }

    /// True for effects that make the plant nonlinear (they need the nonlinear integrators).
    pub fn is_nonlinear(&self) -> bool {
        !matches!(self, Effect::ExtraMode(_) | Effect::TimeDelay(_))
    }

    /// Parameter keys accepted in a spec for this effect.
    pub fn keys(&self) -> &'static [&'static str] {
        match self {
            Effect::CoulombFriction(_) => &[
                "fc",
                "fs",
                "v_stribeck",
                "v_smooth",
                "fc_neg",
                "fv_neg_extra",
            ],
            Effect::Backlash(_) => &["width"],
            Effect::NonlinearStiffness(_) => &["k3"],
            Effect::ExtraMode(_) => &["j", "k", "d", "attach"],
            Effect::TimeDelay(_) => &["samples"],
            Effect::TorqueRipple(_) => &["amplitude", "order", "phase"],
        }
    }

    /// Sets one parameter from its text; `Err(reason)` when the value is not acceptable and
    /// `Ok(false)` when the key is unknown.
    fn set(&mut self, key: &str, value: &str) -> Result<bool, ValueError> {
        if let (Effect::ExtraMode(m), "attach") = (&mut *self, key) {
            m.attach = match value {
                "parallel" => Attach::Parallel,
                "serial" => Attach::Serial,
                _ => return Err(ValueError::Attach),
            };
            return Ok(true);
        }
        let v: f64 = value
            .parse()
            .map_err(|_| ValueError::NotNumber)
            .and_then(|v: f64| {
                if v.is_finite() {
                    Ok(v)
                } else {
                    Err(ValueError::NotFinite)
                }
            })?;
        let Some(&(_, lo, hi, unit)) = self.bounds().iter().find(|(k, ..)| *k == key) else {
            return Ok(false);
        };
        if !(lo..=hi).contains(&v) {
            return Err(ValueError::OutOfBounds(Bounds { lo, hi, unit }));
        }
        match (self, key) {
            (Effect::CoulombFriction(c), "fc") => c.fc = v,
            (Effect::CoulombFriction(c), "fs") => c.fs = v,
            (Effect::CoulombFriction(c), "v_stribeck") => c.v_stribeck = v,
            (Effect::CoulombFriction(c), "v_smooth") => c.v_smooth = v,
            (Effect::CoulombFriction(c), "fc_neg") => c.fc_neg = Some(v),
            (Effect::CoulombFriction(c), "fv_neg_extra") => c.fv_neg_extra = Some(v),
            (Effect::Backlash(b), "width") => b.width = v,
            (Effect::NonlinearStiffness(s), "k3") => s.k3 = v,
            (Effect::ExtraMode(m), "j") => m.j = v,
            (Effect::ExtraMode(m), "k") => m.k = v,
            (Effect::ExtraMode(m), "d") => m.d = v,
            (Effect::TimeDelay(t), "samples") => t.samples = v,
            (Effect::TorqueRipple(t), "amplitude") => t.amplitude = v,
            (Effect::TorqueRipple(t), "order") => t.order = v,
            (Effect::TorqueRipple(t), "phase") => t.phase = v,
            _ => return Ok(false),
        }
        Ok(true)
    }

    /// Every numeric parameter of this effect with its range `[lo, hi]` and unit (see the
    /// table in the module documentation).
    pub fn bounds(&self) -> &'static [(&'static str, f64, f64, &'static str)] {
        const TORQUE: f64 = 100.0;
        match self {
            Effect::CoulombFriction(_) => &[
                ("fc", 0.0, TORQUE, "N·m"),
                ("fs", 0.0, TORQUE, "N·m"),
                ("v_stribeck", 1e-6, 1e3, "rad/s"),
                ("v_smooth", 1e-6, 1e3, "rad/s"),
                ("fc_neg", 0.0, TORQUE, "N·m"),
                ("fv_neg_extra", -1e6, 1e6, "N·m·s/rad"),
            ],
            Effect::Backlash(_) => &[("width", 0.0, 0.1, "rad")],
            Effect::NonlinearStiffness(_) => &[("k3", -1e16, 1e16, "N·m/rad³")],
            Effect::ExtraMode(_) => &[
                ("j", 1e-6, 1e3, "kg·m²"),
                ("k", 1e-3, 1e9, "N·m/rad"),
                ("d", 0.0, 1e6, "N·m·s/rad"),
            ],
            Effect::TimeDelay(_) => &[("samples", 0.0, 100.0, "samples")],
            Effect::TorqueRipple(_) => &[
                ("amplitude", -TORQUE, TORQUE, "N·m"),
                ("order", -1e4, 1e4, "periods per revolution"),
                (
                    "phase",
                    -std::f64::consts::TAU,
                    std::f64::consts::TAU,
                    "rad",
                ),
            ],
        }
    }

    /// The current value of numeric parameter `key`.
    fn value(&self, key: &str) -> Option<f64> {
        Some(match (self, key) {
            (Effect::CoulombFriction(c), "fc") => c.fc,
            (Effect::CoulombFriction(c), "fs") => c.fs,
            (Effect::CoulombFriction(c), "v_stribeck") => c.v_stribeck,
            (Effect::CoulombFriction(c), "v_smooth") => c.v_smooth,
            (Effect::CoulombFriction(c), "fc_neg") => c.fc_backward(),
            (Effect::CoulombFriction(c), "fv_neg_extra") => c.fv_neg_extra.unwrap_or(0.0),
            (Effect::Backlash(b), "width") => b.width,
            (Effect::NonlinearStiffness(s), "k3") => s.k3,
            (Effect::ExtraMode(m), "j") => m.j,
            (Effect::ExtraMode(m), "k") => m.k,
            (Effect::ExtraMode(m), "d") => m.d,
            (Effect::TimeDelay(t), "samples") => t.samples,
            (Effect::TorqueRipple(t), "amplitude") => t.amplitude,
            (Effect::TorqueRipple(t), "order") => t.order,
            (Effect::TorqueRipple(t), "phase") => t.phase,
            _ => return None,
        })
    }

    /// Checks every parameter against its bounds ([`Effect::bounds`]) and the relations
    /// between parameters that single keys cannot (e.g. `F_s ≥ F_c`); the error names the
    /// parameter, its value and the bound.
    ///
    /// # Errors
    /// [`EffectCheckError`]: the parameter out of its bounds with its value, or the
    /// relation that does not hold.
    pub fn check(&self) -> Result<(), EffectCheckError> {
        for &(key, lo, hi, unit) in self.bounds() {
            let v = self.value(key).unwrap_or(f64::NAN);
            if !(lo..=hi).contains(&v) {
                return Err(EffectCheckError::OutOfBounds {
                    key,
                    value: v,
                    bounds: Bounds { lo, hi, unit },
                });
            }
        }
        match self {
            Effect::CoulombFriction(c) if c.fs < c.fc => {
                Err(EffectCheckError::BreakawayBelowLevel { fs: c.fs, fc: c.fc })
            }
            _ => Ok(()),
        }
    }
}

/// The range of a parameter ([`Effect::bounds`]); shown as `must be within [lo, hi] unit`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    /// lowest value
    pub lo: f64,
    /// highest value
    pub hi: f64,
    /// unit
    pub unit: &'static str,
}

impl fmt::Display for Bounds {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let num = |v: f64| {
            if v == 0.0 || (1e-3..1e5).contains(&v.abs()) {
                format!("{}", (v * 1e4).round() / 1e4)
            } else {
                format!("{v:e}")
            }
        };
        write!(
            f,
            "must be within [{}, {}] {}",
            num(self.lo),
            num(self.hi),
            self.unit
        )
    }
}

/// Why the text of one parameter's value in an effect spec was refused.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum ValueError {
    /// `attach` takes a word
    #[error("expected `parallel` or `serial`")]
    Attach,
    /// the text does not parse as a number
    #[error("not a number")]
    NotNumber,
    /// NaN or infinite
    #[error("not finite")]
    NotFinite,
    /// outside the parameter's range
    #[error("{0}")]
    OutOfBounds(Bounds),
}

/// Why an effect's parameters are not acceptable ([`Effect::check`]).
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum EffectCheckError {
    /// a parameter outside its range
    #[error("{key} = {value}: {bounds}")]
    OutOfBounds {
        /// the parameter
        key: &'static str,
        /// its value
        value: f64,
        /// its range
        bounds: Bounds,
    },
    /// Coulomb friction whose breakaway level is below its sliding level
    #[error("fs ({fs}) must be >= fc ({fc})")]
    BreakawayBelowLevel {
        /// breakaway level `F_s` [N·m]
        fs: f64,
        /// Coulomb level `F_c` [N·m]
        fc: f64,
    },
}

impl fmt::Display for Effect {
    /// The spec string that parses back to this effect (`backlash:width=0.0002`).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:", self.name())?;
        match self {
            Effect::CoulombFriction(c) => {
                write!(
                    f,
                    "fc={},fs={},v_stribeck={},v_smooth={}",
                    c.fc, c.fs, c.v_stribeck, c.v_smooth
                )?;
                if let Some(v) = c.fc_neg {
                    write!(f, ",fc_neg={v}")?;
                }
                if let Some(v) = c.fv_neg_extra {
                    write!(f, ",fv_neg_extra={v}")?;
                }
                Ok(())
            }
            Effect::Backlash(b) => write!(f, "width={}", b.width),
            Effect::NonlinearStiffness(s) => write!(f, "k3={}", s.k3),
            Effect::ExtraMode(m) => write!(
                f,
                "j={},k={},d={},attach={}",
                m.j,
                m.k,
                m.d,
                match m.attach {
                    Attach::Parallel => "parallel",
                    Attach::Serial => "serial",
                }
            ),
            Effect::TimeDelay(t) => write!(f, "samples={}", t.samples),
            Effect::TorqueRipple(t) => write!(
                f,
                "amplitude={},order={},phase={}",
                t.amplitude, t.order, t.phase
            ),
        }
    }
}

/// Why an effect spec was rejected; columns are 1-based byte columns in the spec string.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EffectParseError {
    /// the name before `:` is not an effect
    #[error("unknown effect `{name}` at column 1 (known: none, {known})")]
    UnknownEffect {
        /// the name given
        name: String,
        /// the accepted names, comma separated
        known: String,
    },
    /// a key is not a parameter of that effect
    #[error("effect `{effect}`: unknown key `{key}` at column {column} (known: {known})")]
    UnknownKey {
        /// effect name
        effect: &'static str,
        /// the key given
        key: String,
        /// 1-based column of the key
        column: usize,
        /// the accepted keys, comma separated
        known: String,
    },
    /// a value did not parse or is out of range
    #[error("effect `{effect}`: bad value `{value}` for `{key}` at column {column}: {reason}")]
    BadValue {
        /// effect name
        effect: &'static str,
        /// the key
        key: String,
        /// the value text
        value: String,
        /// 1-based column of the value
        column: usize,
        /// what is wrong with it
        #[source]
        reason: ValueError,
    },
    /// a parameter is not of the form `key=value`
    #[error("effect spec `{spec}`: expected key=value at column {column}")]
    Malformed {
        /// the whole spec
        spec: String,
        /// 1-based column of the offending item
        column: usize,
    },
    /// parameters that are individually fine but inconsistent together
    #[error("effect `{effect}`: {reason}")]
    Inconsistent {
        /// effect name
        effect: &'static str,
        /// what is inconsistent
        #[source]
        reason: EffectCheckError,
    },
    /// `none` given together with other effects
    #[error("effect `none` cannot be combined with other effects")]
    NoneCombined,
}

impl FromStr for Effect {
    type Err = EffectParseError;

    /// Parses `name` or `name:key=value,key=value` (whitespace around items is ignored).
    fn from_str(spec: &str) -> Result<Self, Self::Err> {
        parse_given(spec).map(|(effect, _)| effect)
    }
}

/// Parses `spec` as [`Effect`]'s `from_str` does (`name` or `name:key=value,...`), and
/// returns beside the effect the keys the spec gives a number, in the order given, with
/// that number [SI] (`k3` of `nonlinear_stiffness:k3=3e13`, `order` of
/// `torque_ripple:order=3`; `attach=parallel` is no number): what a fit starts those keys
/// at, or takes as given ([`crate::ident::nonlinear::NlRequest::given`]).
///
/// # Errors
/// As [`Effect`]'s `from_str`.
pub fn parse_given(spec: &str) -> Result<(Effect, Vec<(String, f64)>), EffectParseError> {
    let (name, rest, rest_col) = match spec.find(':') {
        Some(i) => (&spec[..i], Some(&spec[i + 1..]), i + 2),
        None => (spec, None, 0),
    };
    let name = name.trim();
    let mut effect =
        Effect::default_by_name(name).ok_or_else(|| EffectParseError::UnknownEffect {
            name: name.to_string(),
            known: EFFECT_NAMES.join(", "),
        })?;
    let mut given = Vec::new();
    let mut fs_named = false;
    if let Some(rest) = rest {
        let mut col = rest_col;
        for item in rest.split(',') {
            let item_col = col + (item.len() - item.trim_start().len());
            col += item.len() + 1;
            let trimmed = item.trim();
            if trimmed.is_empty() {
                continue;
            }
            let Some(eq) = trimmed.find('=') else {
                return Err(EffectParseError::Malformed {
                    spec: spec.to_string(),
                    column: item_col,
                });
            };
            let key = trimmed[..eq].trim();
            let value = trimmed[eq + 1..].trim();
            fs_named |= key == "fs";
            let value_col = item_col + eq + 1;
            match effect.set(key, value) {
                Ok(true) => {}
                Ok(false) => {
                    return Err(EffectParseError::UnknownKey {
                        effect: effect.name(),
                        key: key.to_string(),
                        column: item_col,
                        known: effect.keys().join(", "),
                    })
                }
                Err(reason) => {
                    return Err(EffectParseError::BadValue {
                        effect: effect.name(),
                        key: key.to_string(),
                        value: value.to_string(),
                        column: value_col,
                        reason,
                    })
                }
            }
            if let Ok(x) = value.parse::<f64>() {
                given.push((key.to_string(), x));
            }
        }
    }
    // a level named above the default breakaway level, and no breakaway level: the
    // pure law at that level (module documentation)
    if let Effect::CoulombFriction(c) = &mut effect {
        if !fs_named && c.fs < c.fc {
            c.fs = c.fc;
        }
    }
    effect
        .check()
        .map_err(|reason| EffectParseError::Inconsistent {
            effect: effect.name(),
            reason,
        })?;
    Ok((effect, given))
}

/// Parses several specs (one per `--effect` flag). `none` alone gives no effects.
///
/// # Errors
/// The first spec that does not parse, or `none` combined with anything else.
pub fn parse_effects<S: AsRef<str>>(specs: &[S]) -> Result<Vec<Effect>, EffectParseError> {
    let is_none = |s: &S| s.as_ref().trim() == "none";
    if specs.iter().any(is_none) {
        return if specs.len() == 1 {
            Ok(Vec::new())
        } else {
            Err(EffectParseError::NoneCombined)
        };
    }
    specs.iter().map(|s| s.as_ref().parse()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_given_returns_the_numbers_a_spec_gives_in_order() {
        let (e, given) = parse_given("torque_ripple:phase=0.5, order=3").unwrap();
        assert_eq!(
            e,
            "torque_ripple:phase=0.5,order=3".parse::<Effect>().unwrap()
        );
        assert_eq!(
            given,
            [("phase".to_string(), 0.5), ("order".to_string(), 3.0)]
        );
        let (_, given) = parse_given("extra_mode:attach=serial,k=2e4").unwrap();
        assert_eq!(given, [("k".to_string(), 2e4)]);
        assert_eq!(parse_given("backlash").unwrap().1, []);
        assert!(parse_given("backlash:gap=1").is_err());
    }

    #[test]
    fn parse_name_only_gives_defaults() {
        for name in EFFECT_NAMES {
            let e: Effect = name.parse().unwrap();
            assert_eq!(Some(e), Effect::default_by_name(name));
        }
        assert_eq!(
            "backlash".parse::<Effect>().unwrap(),
            Effect::Backlash(Backlash::default())
        );
    }

    #[test]
    fn parse_keys_set_values_and_keep_other_defaults() {
        let e: Effect = "backlash:width=0.002".parse().unwrap();
        assert_eq!(e, Effect::Backlash(Backlash { width: 0.002 }));
        let e: Effect = "coulomb_friction: fc=0.02 , v_smooth=0.05".parse().unwrap();
        let Effect::CoulombFriction(c) = e else {
            panic!("wrong effect {e:?}")
        };
        assert_eq!(c.fc, 0.02);
        assert_eq!(c.v_smooth, 0.05);
        assert_eq!(c.fs, CoulombFriction::default().fs);
        let e: Effect = "extra_mode:attach=serial,j=2".parse().unwrap();
        assert_eq!(
            e,
            Effect::ExtraMode(ExtraMode {
                j: 2.0,
                attach: Attach::Serial,
                ..ExtraMode::default()
            })
        );
    }

    #[test]
    fn parse_round_trips_display() {
        for e in Effect::all_defaults() {
            let back: Effect = e.to_string().parse().unwrap();
            assert_eq!(back, e);
        }
        let e = Effect::TimeDelay(TimeDelay { samples: 2.25 });
        assert_eq!(e.to_string().parse::<Effect>().unwrap(), e);
    }

    #[test]
    fn parse_rejects_unknown_effect_key_and_bad_values_with_columns() {
        let err = "backlsh:width=1".parse::<Effect>().unwrap_err();
        assert!(
            matches!(err, EffectParseError::UnknownEffect { ref name, .. } if name == "backlsh")
        );
        assert!(err.to_string().contains("known: none, coulomb_friction"));

        let err = "backlash:widht=1".parse::<Effect>().unwrap_err();
        assert_eq!(
            err,
            EffectParseError::UnknownKey {
                effect: "backlash",
                key: "widht".into(),
                column: 10,
                known: "width".into()
            }
        );

        let err = "backlash:width=abc".parse::<Effect>().unwrap_err();
        assert!(
            matches!(err, EffectParseError::BadValue { column: 16, ref reason, .. } if *reason == ValueError::NotNumber),
            "{err:?}"
        );
        let err = "time_delay:samples=-1".parse::<Effect>().unwrap_err();
        assert!(
            err.to_string().contains(
                "bad value `-1` for `samples` at column 20: must be within [0, 100] samples"
            ),
            "{err}"
        );
        let err = "backlash:width".parse::<Effect>().unwrap_err();
        assert_eq!(
            err,
            EffectParseError::Malformed {
                spec: "backlash:width".into(),
                column: 10
            }
        );
        let err = "coulomb_friction:fc=0.3,fs=0.2"
            .parse::<Effect>()
            .unwrap_err();
        assert!(matches!(err, EffectParseError::Inconsistent { .. }));
        // a level above the default breakaway level, with no breakaway level: the pure law
        match "coulomb_friction:fc=20".parse::<Effect>().unwrap() {
            Effect::CoulombFriction(c) => assert_eq!((c.fc, c.fs), (20.0, 20.0)),
            e => panic!("{e:?}"),
        }
        match "coulomb_friction:fc=0.02".parse::<Effect>().unwrap() {
            Effect::CoulombFriction(c) => assert_eq!((c.fc, c.fs), (0.02, 0.04)),
            e => panic!("{e:?}"),
        }
        let err = "extra_mode:attach=sideways".parse::<Effect>().unwrap_err();
        assert!(err.to_string().contains("parallel"), "{err}");
        let err = "torque_ripple:amplitude=inf".parse::<Effect>().unwrap_err();
        assert!(err.to_string().contains("not finite"), "{err}");
    }

    #[test]
    fn every_parameter_is_bounded_and_the_error_names_value_and_bound() {
        for (spec, msg) in [
            (
                "backlash:width=1e9",
                "`width` at column 16: must be within [0, 0.1] rad",
            ),
            ("time_delay:samples=1e12", "must be within [0, 100] samples"),
            (
                "torque_ripple:amplitude=1e30",
                "must be within [-100, 100] N·m",
            ),
            (
                "nonlinear_stiffness:k3=-1e20",
                "must be within [-1e16, 1e16] N·m/rad³",
            ),
            ("coulomb_friction:fc=1e6", "must be within [0, 100] N·m"),
            (
                "coulomb_friction:v_smooth=0",
                "must be within [1e-6, 1000] rad/s",
            ),
            ("extra_mode:k=1e12", "must be within [0.001, 1e9] N·m/rad"),
            (
                "torque_ripple:phase=100",
                "must be within [-6.2832, 6.2832] rad",
            ),
        ] {
            let err = spec.parse::<Effect>().unwrap_err();
            assert!(
                matches!(err, EffectParseError::BadValue { .. }) && err.to_string().contains(msg),
                "{spec}: {err}"
            );
        }
        // the bounds hold for effects built in code too, and every default is inside them
        for e in Effect::all_defaults() {
            assert_eq!(e.check(), Ok(()), "{e}");
            for (key, lo, hi, _) in e.bounds() {
                assert!(lo <= hi && e.keys().contains(key), "{e}: {key}");
            }
        }
        let e = Effect::TimeDelay(TimeDelay { samples: 1e12 });
        assert_eq!(
            e.check().unwrap_err().to_string(),
            "samples = 1000000000000: must be within [0, 100] samples"
        );
        assert_eq!(
            e.check(),
            Err(EffectCheckError::OutOfBounds {
                key: "samples",
                value: 1e12,
                bounds: Bounds {
                    lo: 0.0,
                    hi: 100.0,
                    unit: "samples"
                },
            })
        );
        let e = Effect::TorqueRipple(TorqueRipple {
            amplitude: f64::NAN,
            ..TorqueRipple::default()
        });
        assert!(e
            .check()
            .unwrap_err()
            .to_string()
            .starts_with("amplitude = NaN: "));
    }

    #[test]
    fn asymmetric_friction_keys_parse_print_and_check_like_the_others() {
        let e: Effect = "coulomb_friction:fc=0.2,fs=0.2,fc_neg=0.25,fv_neg_extra=-0.01"
            .parse()
            .unwrap();
        let Effect::CoulombFriction(c) = e else {
            panic!("{e:?}")
        };
        assert_eq!((c.fc_neg, c.fv_neg_extra), (Some(0.25), Some(-0.01)));
        assert!(c.is_asymmetric());
        assert_eq!(e.to_string().parse::<Effect>().unwrap(), e);
        let json = serde_json::to_string(&e).unwrap();
        assert_eq!(serde_json::from_str::<Effect>(&json).unwrap(), e);
        // symmetric by default: the keys are absent in print and JSON, and old files read
        let d = Effect::default_by_name("coulomb_friction").unwrap();
        assert!(
            !d.to_string().contains("neg") && !serde_json::to_string(&d).unwrap().contains("neg")
        );
        let old =
            r#"{"effect":"coulomb_friction","fc":0.1,"fs":0.1,"v_stribeck":0.1,"v_smooth":0.01}"#;
        let Effect::CoulombFriction(o) = serde_json::from_str::<Effect>(old).unwrap() else {
            panic!()
        };
        assert!(!o.is_asymmetric() && o.fc_backward() == 0.1);
        for (spec, msg) in [
            (
                "coulomb_friction:fc_neg=-1",
                "`fc_neg` at column 25: must be within [0, 100] N·m",
            ),
            (
                "coulomb_friction:fv_neg_extra=2e6",
                "must be within [-1e6, 1e6] N·m·s/rad",
            ),
        ] {
            let err = spec.parse::<Effect>().unwrap_err().to_string();
            assert!(err.contains(msg), "{spec}: {err}");
        }
        // the laws: backward level and breakaway, the smooth law far from rest
        // backward: 0.25 − (−0.01)(−2) = 0.23; the friction torque at −5 rad/s is −0.20
        assert!((c.level(-2.0) - 0.23).abs() < 1e-12, "{}", c.level(-2.0));
        assert!((c.level(2.0) - 0.2).abs() < 1e-12);
        assert_eq!(c.breakaway(), (0.2, 0.25));
        assert!((c.torque(-5.0) + 0.2).abs() < 1e-12, "{}", c.torque(-5.0));
        assert!((c.torque(5.0) - 0.2).abs() < 1e-12);
    }

    #[test]
    fn parse_effects_handles_none_and_lists() {
        assert!(parse_effects(&["none"]).unwrap().is_empty());
        assert_eq!(
            parse_effects(&["none", "backlash"]).unwrap_err(),
            EffectParseError::NoneCombined
        );
        let v = parse_effects(&["backlash", "time_delay:samples=3"]).unwrap();
        assert_eq!(v.len(), 2);
        assert_eq!(v[1], Effect::TimeDelay(TimeDelay { samples: 3.0 }));
        assert!(parse_effects::<&str>(&[]).unwrap().is_empty());
    }

    #[test]
    fn coulomb_torque_is_odd_regularised_and_has_stribeck_bump() {
        let c = CoulombFriction {
            fc: 0.15,
            fs: 0.2,
            v_stribeck: 2.0,
            v_smooth: 0.02,
            ..CoulombFriction::default()
        };
        assert_eq!(c.torque(0.0), 0.0);
        for w in [0.001, 0.01, 0.3, 1.0, 5.0, 100.0] {
            assert_eq!(c.torque(-w), -c.torque(w));
        }
        // far above v_smooth and v_stribeck: plain Coulomb level
        assert!((c.torque(50.0) - c.fc).abs() < 1e-12);
        // a little above v_smooth but far below v_stribeck: close to the static level
        assert!((c.torque(0.2) - c.fs).abs() < 0.01 * c.fs);
        // slope at zero is F_s / v_smooth
        let h = 1e-7;
        let slope = (c.torque(h) - c.torque(-h)) / (2.0 * h);
        assert!((slope - c.fs / c.v_smooth).abs() < 1e-6 * slope);
        assert!(slope <= c.max_slope());
        for w in [0.0, 0.003, 0.02, 0.05, 0.5, 3.0, -1.0] {
            let fd = (c.torque(w + h) - c.torque(w - h)) / (2.0 * h);
            assert!(
                (c.slope(w) - fd).abs() < 1e-6 * c.max_slope(),
                "{w}: {} vs {fd}",
                c.slope(w)
            );
        }
    }
}
