//! Physical parameters of the simulated joint and the plant structures built from them.
//!
//! Names follow seed 000 (Norrlöf et al., "Modeling and identification of a mechanical
//! industrial manipulator"), Table 1 and eq. (5)–(8): motor inertia `J_m`, arm inertias
//! `J_a1`, `J_a2`, parallel inertia `J_p`, spring constants `k_g` (gearbox), `k_a` (arm),
//! `k_p` (parallel mass), the matching dampings `d_g`, `d_a`, `d_p`, viscous motor
//! friction `f_m` and the gear ratio `r = 1/118`. The nonlinear two-mass model of seed 001
//! (eq. (4)–(9), ../shared/DESIGN.md §6) adds the cubic spring coefficient `k3` and the Coulomb
//! friction level `F_c`; its `k1`, `d`, `F_v`, `J_a` are `k_g`, `d_g`, `f_m` and
//! `J_a1 + J_a2` here.
//!
//! # Units and sides of the gearbox
//! Motor quantities are on the motor side (`J_m` [kg·m²], `f_m` [N·m·s/rad], motor angle
//! [rad]); arm quantities are on the arm side (`J_a1` [kg·m²], `k_g` [N·m/rad] acting on the
//! arm-side deflection `r·θ_m − θ_a1` [rad]). This is exactly the convention of seed 000
//! eq. (6), where `x1 = θ_m r − θ_a1`.
//!
//! # Default joint (IRB1400-like axis 1): derivation
//! Seed 000 gives no parameter values. What it gives is qualitative: the motor-side frequency
//! response of axis 1 of an ABB IRB1400 (r = 1/118) shows two notches between 15 and 20 Hz
//! (its Fig. 5–6, "the double notch around 17 Hz"), a three-mass model is the least that
//! explains it, and the regulator leaves little input energy below 10 Hz. The defaults are
//! therefore *constructed*, not measured: we chose the undamped motor-side spectrum of the
//! three-mass model to have anti-resonances at 15 and 19 Hz and resonances at 17 and 23 Hz
//! (inside the band of those figures), and a motor inertia typical of a 1–2 kW servo motor,
//! `J_m = 1.0e-3 kg·m²`. For a free–free chain seen from the motor, with motor-side masses
//! `m0 = J_m`, `m1 = r²J_a1`, `m2 = r²J_a2`, springs `c1 = r²k_g`, `c2 = r²k_a` and
//! `ω = 2πf`:
//! - product rule: `(p1 p2 / (z1 z2))² = (m0 + m1 + m2) / m0`, so the reflected arm
//!   inertia is `0.882 J_m`;
//! - trace rule: `p1² + p2² − z1² − z2² = c1 / m0`, which fixes `k_g`;
//! - the two remaining relations of the locked-motor (anti-resonance) problem,
//!   `z1² z2² = c1 c2 / (m1 m2)` and `z1² + z2² = c2/m2 + (c1 + c2)/m1`, give
//!   `m1 = c1 / (z1² + z2² − z1²z2²(m1 + m2)/c1)`, then `m2` and `c2`.
//!
//! Result (rounded): `J_a1 = 11.66 kg·m²`, `J_a2 = 0.627 kg·m²`, `k_g = 1.275e5 N·m/rad`,
//! `k_a = 7.26e3 N·m/rad`. A gearbox stiffness of ~1e5 N·m/rad is the catalogue range of
//! the cycloidal reducers used on robots of this size, and an arm inertia of ~12 kg·m² about
//! axis 1 is plausible for a 1.4 m reach arm; the distal mass `J_a2` is light (5 % of
//! `J_a1`), a consequence of putting both notches so close together. The computed undamped
//! modal frequencies of the rounded defaults (checked by unit tests in `plant.rs`) are:
//! - three-mass: anti-resonances 15.00, 19.00 Hz; resonances 17.00, 23.00 Hz;
//! - two-mass (arm lumped): anti-resonance 16.21 Hz, resonance 22.24 Hz;
//! - four-mass (three-mass plus the parallel mass below): anti-resonances 14.02, 18.12,
//!   35.92 Hz; resonances 17.00, 21.26, 36.14 Hz (the parallel mass on the heavy `J_a1` is
//!   weakly seen from the motor: its pair nearly cancels).
//!
//! The firmware's on-target joint (`jointid_core::joint`, streamed by the emulated board) is
//! this same three-mass joint with the same controller gains: the three-mass values are
//! held there, in `JointParams::default_joint()`, and read from there by
//! [`JointParams::default`] (a unit test pins them and the controller gains).
//!
//! Damping is chosen for 1.5–5 % modal damping, the usual range for gearbox/arm
//! structures: `d_g = 80 N·m·s/rad`, `d_a = 4 N·m·s/rad`, `d_p = 7 N·m·s/rad` give
//! ζ = 3.0 % at 17 Hz and 4.8 % at 23 Hz (three-mass) and 1.4 % at 36 Hz (four-mass).
//! Viscous motor friction `f_m = 2e-3 N·m·s/rad` (0.6 N·m at 3000 rpm). The parallel mass of
//! the four-mass model (seed 000 eq. (7)) is an assumed 20 % of `J_a1` with a locked
//! frequency of 32 Hz: `J_p = 2.33 kg·m²`, `k_p = 9.42e4 N·m/rad`. Seed 001 defaults use the
//! defaults of the matching effects (see [`super::effects`]): `k3 = 3e13 N·m/rad³` and
//! `F_c = 0.03 N·m`, sized to be visible at the small default excitation (0.02 rad RMS).
//!
//! # Physical ranges
//! A value given on the command line (`simulate --param NAME=VALUE`) must lie in its
//! parameter's range ([`param_range`]), as an effect's keys must lie in theirs
//! ([`super::effects`]): wide enough for any real joint (and for a linear axis fitted
//! with `--linear-axis`, whose masses in kg, stiffnesses in N/m and dampings in N·s/m take
//! the same numbers), narrow enough that the simulator integrates physics, not numbers
//! far outside it (`J_m = 1e-30` made the motor's own mode so fast that the angle grew to
//! 1e69 rad over a run, and exited 0).
//!
//! | name | range | unit | why |
//! |---|---|---|---|
//! | `J_m` | 1e-7 … 1e4 | kg·m² | 1 g·cm² is below the rotor of the smallest servo motor; 1e4: a 10 t linear axis |
//! | `J_a1`, `J_a2`, `J_p` | 0, or 1e-6 … 1e5 | kg·m² | 0: no such mass (the rigid and grounded structures, a lumped two-mass); 1e5: a tonne at 10 m |
//! | `k_g`, `k_a`, `k_p` | 1e-3 … 1e10 | N·m/rad | as an extra mode's `k`, ten times wider above: a ball screw in N/m |
//! | `k_0` | 1e-6 … 1e10 | N·m/rad | a flexure's spring to ground, from a thousandth of a hertz |
//! | `d_g`, `d_a`, `d_p`, `f_m` | 0 … 1e6 | N·m·s/rad | as an extra mode's `d` |
//! | `r` | 1e-4 … 100 | - | 1:10 000, beyond any reducer, to a 100:1 step-up; 1 is direct drive |
//! | `k3` | −1e16 … 1e16 | N·m/rad³ | `nonlinear_stiffness`'s `k3` |
//! | `F_c` | 0 … 100 | N·m | `coulomb_friction`'s `fc` |

use serde::{Deserialize, Serialize};

use super::effects::{parse_effects, Bounds, CoulombFriction, Effect, NonlinearStiffness};
use super::spec::{Family, ModelSpec, SpecError, Structure};

/// Named physical parameters, seed 000 Table 1 plus seed 001's `k3`, `F_c`.
///
/// Each structure uses the subset it needs; unused ones are carried along so one set
/// describes all structures (and is printed whole by [`crate::sim::SimConfig::params_json`]).
/// `k3` and `F_c` are the values of seed 001's two effects of the `nonlinear-two-mass`
/// alias ([`sim_spec`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct JointParams {
    /// motor inertia `J_m` [kg·m²], motor side
    #[serde(rename = "J_m")]
    pub j_m: f64,
    /// first arm inertia `J_a1` [kg·m²], arm side
    #[serde(rename = "J_a1")]
    pub j_a1: f64,
    /// second arm inertia `J_a2` [kg·m²], arm side
    #[serde(rename = "J_a2")]
    pub j_a2: f64,
    /// parallel inertia `J_p` of the four-mass model [kg·m²], arm side
    #[serde(rename = "J_p")]
    pub j_p: f64,
    /// gearbox stiffness `k_g` [N·m/rad] on the arm-side deflection `r θ_m − θ_a1`
    pub k_g: f64,
    /// arm stiffness `k_a` between `J_a1` and `J_a2` [N·m/rad]
    pub k_a: f64,
    /// stiffness `k_p` between `J_a1` and `J_p` [N·m/rad]
    pub k_p: f64,
    /// gearbox damping `d_g` [N·m·s/rad], arm side
    pub d_g: f64,
    /// arm damping `d_a` [N·m·s/rad]
    pub d_a: f64,
    /// parallel-mass damping `d_p` [N·m·s/rad]
    pub d_p: f64,
    /// viscous motor friction `f_m` [N·m·s/rad], motor side
    pub f_m: f64,
    /// gear ratio `r` [-] (arm angle per motor angle, 1/118 on the IRB1400 axis 1)
    pub r: f64,
    /// stiffness to ground `k_0` of the grounded structure [N·m/rad] on the motor angle
    /// `θ_m` (the grounded mass has no gearbox: `r` is not used); the default puts the
    /// default joint's rigid inertia at 5.0 Hz
    #[serde(default = "default_k_0")]
    pub k_0: f64,
    /// cubic spring coefficient `k3` of the nonlinear two-mass model [N·m/rad³] (its
    /// `nonlinear_stiffness` effect)
    pub k3: f64,
    /// Coulomb friction level `F_c` of the nonlinear two-mass model [N·m], motor side (its
    /// `coulomb_friction` effect, pure: `F_s = F_c`)
    #[serde(rename = "F_c")]
    pub f_c: f64,
}

impl Default for JointParams {
    /// The IRB1400-like axis 1 derived in the module documentation. The three-mass values
    /// (`J_m`, `J_a1`, `J_a2`, `k_g`, `k_a`, `d_g`, `d_a`, `f_m`, `r`) are read from the
    /// firmware's on-target joint, `jointid_core::joint::JointParams::default_joint()`, the
    /// single source of truth of the default joint; the emulated board streams that joint.
    fn default() -> Self {
        let core = jointid_core::joint::JointParams::default_joint();
        JointParams {
            j_m: core.j_m,
            j_a1: core.j_a1,
            j_a2: core.j_a2,
            j_p: 2.33,
            k_g: core.k_g,
            k_a: core.k_a,
            k_p: 9.42e4,
            d_g: core.d_g,
            d_a: core.d_a,
            d_p: 7.0,
            f_m: core.f_m,
            r: core.gear_ratio,
            k_0: default_k_0(),
            k3: 3.0e13,
            f_c: 0.03,
        }
    }
}

/// `k_0` of the default grounded joint [N·m/rad]: `J ω²` with the default rigid inertia
/// `J = 1.882e-3 kg·m²` and `ω = 2π · 5.0 Hz` (a test of the simulator checks the
/// frequency).
fn default_k_0() -> f64 {
    1.86
}

impl JointParams {
    /// The eight values of the three-mass model (seed 000 Table 1: `J_m`, `J_a1`, `J_a2`,
    /// `k_g`, `k_a`, `d_g`, `d_a`, `f_m`), for a caller that draws or scales them together.
    pub fn three_mass_values_mut(&mut self) -> [&mut f64; 8] {
        [
            &mut self.j_m,
            &mut self.j_a1,
            &mut self.j_a2,
            &mut self.k_g,
            &mut self.k_a,
            &mut self.d_g,
            &mut self.d_a,
            &mut self.f_m,
        ]
    }

    /// Total inertia seen at the motor when the joint is rigid,
    /// `J_m + r²(J_a1 + J_a2)` [kg·m²] (the parallel mass is not included).
    pub fn rigid_inertia(&self) -> f64 {
        self.j_m + self.r * self.r * (self.j_a1 + self.j_a2)
    }

    /// Every parameter as (name, value, unit), names as in seed 000 Table 1, units from
    /// [`unit_of`].
    pub fn table(&self) -> [(&'static str, f64, &'static str); 15] {
        [
            ("J_m", self.j_m),
            ("J_a1", self.j_a1),
            ("J_a2", self.j_a2),
            ("J_p", self.j_p),
            ("k_g", self.k_g),
            ("k_a", self.k_a),
            ("k_p", self.k_p),
            ("d_g", self.d_g),
            ("d_a", self.d_a),
            ("d_p", self.d_p),
            ("f_m", self.f_m),
            ("r", self.r),
            ("k_0", self.k_0),
            ("k3", self.k3),
            ("F_c", self.f_c),
        ]
        .map(|(name, value)| (name, value, unit_of(name)))
    }
}

/// Access to one field of [`JointParams`] (its unit is the field's, [`unit_of`] its name).
pub type ParamField = fn(&mut JointParams) -> &mut f64;

/// The physical parameters a plant of `structure` uses, as (name, field) pairs, names as in
/// [`JointParams::table`] (seed 000 Table 1).
pub fn model_params(structure: Structure) -> Vec<(&'static str, ParamField)> {
    type Field = ParamField;
    let mut v: Vec<(&'static str, Field)> = vec![
        ("J_m", |p| &mut p.j_m),
        ("J_a1", |p| &mut p.j_a1),
        ("J_a2", |p| &mut p.j_a2),
    ];
    let gearbox: [(&'static str, Field); 2] = [("k_g", |p| &mut p.k_g), ("d_g", |p| &mut p.d_g)];
    let arm: [(&'static str, Field); 2] = [("k_a", |p| &mut p.k_a), ("d_a", |p| &mut p.d_a)];
    match structure {
        Structure::Rigid => {}
        Structure::Grounded => v.push(("k_0", |p| &mut p.k_0)),
        Structure::TwoMass => v.extend(gearbox),
        Structure::ThreeMass => v.extend(gearbox.into_iter().chain(arm)),
        Structure::FourMass => {
            v.push(("J_p", |p| &mut p.j_p));
            v.extend(gearbox.into_iter().chain(arm));
            v.extend::<[(&'static str, Field); 2]>([
                ("k_p", |p| &mut p.k_p),
                ("d_p", |p| &mut p.d_p),
            ]);
        }
    }
    v.extend::<[(&'static str, Field); 2]>([("f_m", |p| &mut p.f_m), ("r", |p| &mut p.r)]);
    v
}

/// The parameters of seed 001's two effects that the `nonlinear-two-mass` alias adds
/// ([`sim_spec`]): `k3` [N·m/rad³] and `F_c` [N·m], after [`model_params`] of the two-mass.
pub fn seed_001_params() -> [(&'static str, ParamField); 2] {
    [("k3", |p| &mut p.k3), ("F_c", |p| &mut p.f_c)]
}

/// The physical range of a plant parameter ([`param_range`]; the table in the module
/// documentation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParamRange {
    /// lowest and highest value, in the parameter's unit ([`unit_of`])
    pub bounds: Bounds,
    /// 0 is taken too, outside the range: a mass the structure may lack (an arm inertia)
    pub zero: bool,
}

impl ParamRange {
    /// Whether `v` is in the range (NaN never is).
    pub fn contains(&self, v: f64) -> bool {
        (self.zero && v == 0.0) || (self.bounds.lo..=self.bounds.hi).contains(&v)
    }
}

impl std::fmt::Display for ParamRange {
    /// `must be within [lo, hi] unit`, or `must be 0 or within …` when 0 is taken.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let within = self.bounds.to_string();
        match within.strip_prefix("must be ").filter(|_| self.zero) {
            Some(rest) => write!(f, "must be 0 or {rest}"),
            None => f.write_str(&within),
        }
    }
}

/// The physical range of the plant parameter `name` (names as in [`JointParams::table`];
/// the table and the reasons in the module documentation); `None` for a name that is
/// not one. `k3` and `F_c` take the bounds of the effects they value
/// (`nonlinear_stiffness`'s `k3`, `coulomb_friction`'s `fc`).
pub fn param_range(name: &str) -> Option<ParamRange> {
    let effect_key = |e: Effect, key: &str| {
        e.bounds()
            .iter()
            .find(|(k, ..)| *k == key)
            .map(|&(_, lo, hi, unit)| Bounds { lo, hi, unit })
    };
    let range = |lo: f64, hi: f64| Bounds {
        lo,
        hi,
        unit: unit_of(name),
    };
    let (bounds, zero) = match name {
        "J_m" => (range(1e-7, 1e4), false),
        "J_a1" | "J_a2" | "J_p" => (range(1e-6, 1e5), true),
        "k_g" | "k_a" | "k_p" => (range(1e-3, 1e10), false),
        "k_0" => (range(1e-6, 1e10), false),
        "d_g" | "d_a" | "d_p" | "f_m" => (range(0.0, 1e6), false),
        "r" => (range(1e-4, 100.0), false),
        "k3" => (
            effect_key(
                Effect::NonlinearStiffness(NonlinearStiffness::default()),
                "k3",
            )?,
            false,
        ),
        "F_c" => (
            effect_key(Effect::CoulombFriction(CoulombFriction::default()), "fc")?,
            false,
        ),
        _ => return None,
    };
    Some(ParamRange { bounds, zero })
}

/// The simulator's model description: the [`ModelSpec`] of `structure` with the effects
/// `effects` (specs as `simulate --effect`), through the one list of effect specs the fit
/// resolves ([`ModelSpec::effect_specs`]): with `nonlinear_two_mass`, seed 001's
/// `nonlinear_stiffness` and `coulomb_friction` first (those `effects` does not name),
/// valued from `params` (`k3`, and pure Coulomb friction `F_s = F_c` of `F_c`). Unlike the
/// fit, a `coulomb_friction` spec of `effects` keeps its own breakaway level: the
/// simulator simulates what it is given. `effects` is `None` when there are none.
///
/// # Errors
/// [`SpecError::Effect`] for the first spec that does not parse.
pub fn sim_spec(
    structure: Structure,
    nonlinear_two_mass: bool,
    effects: &[String],
    params: &JointParams,
) -> Result<ModelSpec, SpecError> {
    let specs = ModelSpec::effect_specs(nonlinear_two_mass, effects);
    let mut parsed = parse_effects(&specs)?;
    // the specs the alias added come first (seed 001 eq. (6)-(7), from `params`)
    let added = specs.len() - effects.len();
    for e in &mut parsed[..added] {
        match e {
            Effect::NonlinearStiffness(s) => *s = NonlinearStiffness { k3: params.k3 },
            Effect::CoulombFriction(c) => {
                *c = CoulombFriction {
                    fc: params.f_c,
                    fs: params.f_c,
                    ..CoulombFriction::default()
                }
            }
            _ => {}
        }
    }
    Ok(ModelSpec {
        effects: (!parsed.is_empty()).then_some(parsed),
        ..ModelSpec::linear(Family::Physical(structure))
    })
}

/// The one unit table of the joint's physical parameters (rotary joint, SI): every name
/// the simulator and the estimators use, with its unit. Seed 000 Table 1 (`J_*` [kg·m²],
/// `k_*` [N·m/rad], `d_*` and `f_m` [N·m·s/rad]), the gear ratio `r` [-], the grounded
/// structure's stiffness to ground `k_0` [N·m/rad], seed 001's cubic
/// spring `k3` [N·m/rad³] and Coulomb level `F_c` [N·m], and the rigid model of the
/// estimators: `J` [kg·m²], viscous `Fv` [N·m·s/rad], Coulomb `Fc` and `offset` [N·m],
/// the motor-side stiffness to ground `K` [N·m/rad].
pub const UNITS: [(&str, &str); 22] = [
    ("J_m", "kg·m²"),
    ("J_a1", "kg·m²"),
    ("J_a2", "kg·m²"),
    ("J_p", "kg·m²"),
    ("k_g", "N·m/rad"),
    ("k_a", "N·m/rad"),
    ("k_p", "N·m/rad"),
    ("d_g", "N·m·s/rad"),
    ("d_a", "N·m·s/rad"),
    ("d_p", "N·m·s/rad"),
    ("f_m", "N·m·s/rad"),
    ("r", "-"),
    ("k_0", "N·m/rad"),
    ("k3", "N·m/rad³"),
    ("F_c", "N·m"),
    ("J", "kg·m²"),
    ("Fv", "N·m·s/rad"),
    ("Fc", "N·m"),
    ("Fv_neg", "N·m·s/rad"),
    ("Fc_neg", "N·m"),
    ("offset", "N·m"),
    ("K", "N·m/rad"),
];

/// Unit of the physical parameter `name` from [`UNITS`]; `""` for a name not there.
pub fn unit_of(name: &str) -> &'static str {
    UNITS
        .iter()
        .find(|(n, _)| *n == name)
        .map_or("", |(_, u)| u)
}

/// A plant: its structure and its physical parameters.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Plant {
    /// mechanical structure (JSON: [`Structure::name`])
    pub kind: Structure,
    /// physical parameters (each structure uses the subset it needs)
    pub params: JointParams,
}

impl Default for Plant {
    /// The three-mass default joint.
    fn default() -> Self {
        Plant {
            kind: Structure::ThreeMass,
            params: JointParams::default(),
        }
    }
}

impl Plant {
    /// Plant of structure `kind` with the default parameters.
    pub fn new(kind: Structure) -> Self {
        Plant {
            kind,
            params: JointParams::default(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::ControllerConfig;

    #[test]
    fn default_joint_is_the_firmware_joint_with_the_same_controller() {
        let core = jointid_core::joint::JointParams::default_joint();
        let p = JointParams::default();
        // the values the module documentation derives, as the firmware holds them
        let expected = [
            (p.j_m, 1.0e-3),
            (p.j_a1, 11.66),
            (p.j_a2, 0.627),
            (p.k_g, 1.275e5),
            (p.k_a, 7.26e3),
            (p.d_g, 80.0),
            (p.d_a, 4.0),
            (p.f_m, 2.0e-3),
            (p.r, 1.0 / 118.0),
        ];
        for (got, want) in expected {
            assert_eq!(got, want);
        }
        // the board's cascade has the host controller's gains (in f32); its velocity PI
        // integrates K_i e T with K_i = K_v / T_i
        let c = ControllerConfig::default();
        assert_eq!(core.kp, c.kp as f32);
        assert_eq!(core.kv, c.kv as f32);
        assert_eq!(core.ki, (c.kv / c.ti) as f32);
        assert_eq!(core.u_max, c.u_max as f32);
        assert_eq!(
            f64::from(core.fs_hz),
            crate::sim::SimConfig::default().sample_rate_hz
        );
    }

    #[test]
    fn the_nonlinear_two_mass_is_the_two_mass_with_seed_001_effects_valued_from_the_params() {
        let p = JointParams {
            k3: 1e12,
            f_c: 0.05,
            ..JointParams::default()
        };
        let spec = sim_spec(Structure::TwoMass, true, &["backlash".into()], &p).unwrap();
        assert_eq!(spec.family, Family::Physical(Structure::TwoMass));
        // the same list of specs, in the same order, as the fit resolves
        let fit =
            ModelSpec::resolve(spec.family, true, &["backlash".into()], false, None, None).unwrap();
        let names =
            |s: &ModelSpec| -> Vec<&str> { s.effects.iter().flatten().map(|e| e.name()).collect() };
        assert_eq!(names(&spec), names(&fit));
        let e = spec.effects.unwrap();
        assert_eq!(
            e[0],
            Effect::NonlinearStiffness(NonlinearStiffness { k3: 1e12 })
        );
        let Effect::CoulombFriction(c) = e[1] else {
            panic!("{:?}", e[1])
        };
        assert_eq!((c.fc, c.fs), (0.05, 0.05));
        // an effect the user names replaces the alias's and keeps its own values
        // (the Stribeck level of `coulomb_friction` included)
        let own = sim_spec(Structure::TwoMass, true, &["coulomb_friction".into()], &p).unwrap();
        let own = own.effects.unwrap();
        assert_eq!(own.len(), 2);
        assert_eq!(own[1], Effect::CoulombFriction(CoulombFriction::default()));
        // a structure without effects is a linear spec
        let lin = sim_spec(Structure::FourMass, false, &[], &p).unwrap();
        assert_eq!(
            lin,
            ModelSpec::linear(Family::Physical(Structure::FourMass))
        );
        assert!(sim_spec(Structure::Rigid, false, &["nope".into()], &p).is_err());
    }

    #[test]
    fn every_parameter_has_a_physical_range_holding_its_default_and_refusing_the_absurd() {
        let mut defaults = JointParams::default();
        for (name, value, unit) in JointParams::default().table() {
            let range = param_range(name).unwrap_or_else(|| panic!("{name} has no range"));
            assert_eq!(range.bounds.unit, unit, "{name}");
            assert!(range.contains(value), "{name} = {value}: {range}");
            assert!(!range.contains(f64::NAN), "{name}");
            assert!(!range.contains(1e30) && !range.contains(-1e30), "{name}");
        }
        // what `simulate --param J_m=1e-30` ran before: the motor's mode beyond any physics
        let j_m = param_range("J_m").unwrap();
        assert!(!j_m.contains(1e-30));
        assert_eq!(j_m.to_string(), "must be within [1e-7, 10000] kg·m²");
        // an arm inertia may be absent, not absurdly small
        let j_a2 = param_range("J_a2").unwrap();
        assert!(j_a2.contains(0.0) && !j_a2.contains(1e-300));
        assert_eq!(j_a2.to_string(), "must be 0 or within [1e-6, 1e5] kg·m²");
        // seed 001's two take their effects' bounds
        assert_eq!(
            param_range("k3").unwrap().to_string(),
            "must be within [-1e16, 1e16] N·m/rad³"
        );
        assert_eq!(
            param_range("F_c").unwrap().to_string(),
            "must be within [0, 100] N·m"
        );
        assert_eq!(param_range("nope"), None);
        // every name `--param` takes for every structure has one
        for kind in Structure::ALL {
            for (name, field) in model_params(kind).into_iter().chain(seed_001_params()) {
                assert!(param_range(name).unwrap().contains(*field(&mut defaults)));
            }
        }
    }

    #[test]
    fn every_parameter_of_every_plant_has_a_unit_and_the_nonlinear_ones_theirs() {
        for kind in Structure::ALL {
            for (name, _) in model_params(kind).into_iter().chain(seed_001_params()) {
                assert_ne!(unit_of(name), "", "{name}");
            }
        }
        assert_eq!(unit_of("k3"), "N·m/rad³");
        assert_eq!(unit_of("F_c"), "N·m");
        assert_eq!(unit_of("k_g"), "N·m/rad");
        assert_eq!(unit_of("Fc"), "N·m");
        assert_eq!(unit_of("nope"), "");
    }
}
