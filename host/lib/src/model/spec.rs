//! The description of a joint model that everything else is given: which mechanical
//! structure ([`Structure`]), which model family ([`Family`]: a black box or a structure)
//! and the whole description a fit is asked for ([`ModelSpec`]: family, effects, rigid
//! Coulomb friction, current-loop lag, delay). The command line resolves its model flags
//! into one [`ModelSpec`] once; the fit, the model file and `validate` take it from there.
//! The simulator's plant ([`crate::model::params::Plant`]) carries a [`Structure`].

use serde::{Deserialize, Serialize};
use thiserror::Error;

use super::effects::{parse_effects, Attach, Effect, EffectParseError, ExtraMode};

/// Mechanical structure of a joint model: the one list of structures the estimators fit
/// and the simulator simulates ([`crate::model::params::Plant::kind`]); serialised by its
/// [`Structure::name`] (`three_mass`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Structure {
    /// one inertia with viscous friction
    Rigid,
    /// motor and arm through the gearbox spring
    TwoMass,
    /// seed 000 eq. (6)
    ThreeMass,
    /// seed 000 eq. (7)
    FourMass,
    /// one mass held by a spring to ground (a flexure stage, a test bench, a balanced arm,
    /// an electrical analogue): a resonance with a finite static gain, no rigid-body mode
    Grounded,
}

impl Structure {
    /// Every structure: the free joints in the order of increasing complexity, then the
    /// grounded mass.
    pub const ALL: [Structure; 5] = [
        Structure::Rigid,
        Structure::TwoMass,
        Structure::ThreeMass,
        Structure::FourMass,
        Structure::Grounded,
    ];

    /// Whether the mechanism has a free rigid-body mode (every structure but the grounded
    /// mass): its angle drifts under a constant torque, its FRF rises as `1/ω²` at low
    /// frequencies.
    pub fn is_free(self) -> bool {
        self != Structure::Grounded
    }

    /// Name on the command line and in model files (`three-mass`).
    pub fn label(self) -> &'static str {
        match self {
            Structure::Rigid => "rigid",
            Structure::TwoMass => "two-mass",
            Structure::ThreeMass => "three-mass",
            Structure::FourMass => "four-mass",
            Structure::Grounded => "grounded",
        }
    }

    /// Name in JSON and in the capture CSV's `sim_plant` (`three_mass`); the command line
    /// takes it as an alias of [`Structure::label`].
    pub fn name(self) -> &'static str {
        match self {
            Structure::Rigid => "rigid",
            Structure::TwoMass => "two_mass",
            Structure::ThreeMass => "three_mass",
            Structure::FourMass => "four_mass",
            Structure::Grounded => "grounded",
        }
    }

    /// What the structure is, in a few words (the command line's help).
    pub fn describe(self) -> &'static str {
        match self {
            Structure::Rigid => "one rigid mass",
            Structure::TwoMass => "motor and one arm mass through the gearbox spring",
            Structure::ThreeMass => "seed 000 eq. (5)-(6): motor and two arm masses",
            Structure::FourMass => "seed 000 eq. (7)-(8): three-mass plus a parallel mass",
            Structure::Grounded => "one mass on a spring and damper to ground (flexure, bench)",
        }
    }

    /// The body the extra mode `x` hangs on, in a chain of `bodies` bodies of this
    /// structure (the motor first, the modes already hung counted): the grounded mass
    /// carries every mode; else the first arm mass (parallel; the motor of a rigid joint)
    /// or the chain's last (serial). The simulation, the estimator and the nonlinear start
    /// read it here.
    pub fn mode_host(self, x: &ExtraMode, bodies: usize) -> usize {
        match x.attach {
            _ if self == Structure::Grounded => 0,
            Attach::Parallel => usize::from(bodies > 1),
            Attach::Serial => bodies - 1,
        }
    }

    /// number of masses
    pub fn masses(self) -> usize {
        match self {
            Structure::Rigid => 1,
            Structure::TwoMass => 2,
            Structure::ThreeMass => 3,
            Structure::FourMass => 4,
            Structure::Grounded => 1,
        }
    }

    /// parameter names, seed 000 Table 1 (rigid: `J`, `Fv`; grounded: `J`, `Fv` and the
    /// stiffness to ground `k_0`)
    pub fn param_names(self) -> &'static [&'static str] {
        match self {
            Structure::Rigid => &["J", "Fv"],
            Structure::Grounded => &["J", "Fv", "k_0"],
            Structure::TwoMass => &["J_m", "J_a1", "k_g", "d_g", "f_m"],
            Structure::ThreeMass => &["J_m", "J_a1", "J_a2", "k_g", "k_a", "d_g", "d_a", "f_m"],
            Structure::FourMass => &[
                "J_m", "J_a1", "J_a2", "J_p", "k_g", "k_a", "k_p", "d_g", "d_a", "d_p", "f_m",
            ],
        }
    }
}

/// Model family: a discrete black box of an order, or a physical structure.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Family {
    /// discrete black box of this order
    BlackBox(usize),
    /// a physical model of this structure (seed 000 eq. (5)–(8))
    Physical(Structure),
}

impl Family {
    /// name as written on the command line and in model files (`black-box:11`, `three-mass`)
    pub fn name(&self) -> String {
        match self {
            Family::BlackBox(n) => format!("black-box:{n}"),
            Family::Physical(s) => s.label().into(),
        }
    }

    /// grey-box structure, `None` for a black box
    pub fn structure(&self) -> Option<Structure> {
        match self {
            Family::BlackBox(_) => None,
            Family::Physical(s) => Some(*s),
        }
    }
}

impl std::str::FromStr for Family {
    type Err = FamilyParseError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let s = s.trim().to_ascii_lowercase().replace('_', "-");
        if let Some(n) = s
            .strip_prefix("black-box:")
            .or_else(|| s.strip_prefix("blackbox:"))
        {
            return match n.parse::<usize>() {
                Ok(n) if (1..=40).contains(&n) => Ok(Family::BlackBox(n)),
                _ => Err(FamilyParseError::Order(n.to_string())),
            };
        }
        match Structure::ALL.into_iter().find(|st| st.label() == s) {
            Some(st) => Ok(Family::Physical(st)),
            None => Err(FamilyParseError::Unknown(s)),
        }
    }
}

impl Serialize for Family {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&self.name())
    }
}

impl<'de> Deserialize<'de> for Family {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        String::deserialize(d)?
            .parse()
            .map_err(serde::de::Error::custom)
    }
}

/// The one description of the model a fit is asked for, resolved once from the command
/// line's `--model`, `--effect`, `--friction`, `--current-loop-tau` and `--delay`
/// ([`ModelSpec::resolve`]) and stored in the model file (format 4).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelSpec {
    /// model family
    pub family: Family,
    /// `Some`: the physical model with these effects attached, fitted by the nonlinear
    /// engine (`--effect none`: none attached); `None`: a linear model
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub effects: Option<Vec<Effect>>,
    /// rigid model only: Coulomb friction and a torque offset beside the viscous friction
    #[serde(default)]
    pub coulomb: bool,
    /// with `coulomb`: friction that differs with the direction of motion (`F_v`, `F_c`
    /// forward, `F_v−`, `F_c−` backward, no offset; [`crate::ident::grey_box::IdimOptions`])
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub coulomb_asymmetric: bool,
    /// current-loop lag `tau_c` [s] held at this value; `None`: estimated in the frequency
    /// domain, neglected (0) in the time domain
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub current_loop_tau: Option<f64>,
    /// transport delay of the torque [samples] held at this value; `None`: estimated in
    /// the frequency domain
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delay: Option<f64>,
}

/// Why the model flags do not resolve into a [`ModelSpec`].
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum SpecError {
    /// an `--effect` spec that does not parse
    #[error("--effect: {0}")]
    Effect(#[from] EffectParseError),
}

/// A model family name that does not parse ([`Family`]'s `FromStr`).
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum FamilyParseError {
    /// `black-box:N` with `N` outside 1 … 40
    #[error("black-box order `{0}` must be an integer 1 … 40")]
    Order(String),
    /// no family of that name
    #[error(
        "unknown model `{0}` (known: black-box:ORDER, rigid, two-mass, three-mass, four-mass, grounded)"
    )]
    Unknown(String),
}

/// The name of seed 001's nonlinear two-mass on the command line: the two-mass with
/// `nonlinear_stiffness` and `coulomb_friction` attached.
pub const NONLINEAR_TWO_MASS: &str = "nonlinear-two-mass";

impl ModelSpec {
    /// A linear model of `family`: no effects, viscous friction, lag and delay free.
    pub fn linear(family: Family) -> ModelSpec {
        ModelSpec {
            family,
            effects: None,
            coulomb: false,
            coulomb_asymmetric: false,
            current_loop_tau: None,
            delay: None,
        }
    }

    /// The spec of the command line: `family`, seed 001's two effects first when
    /// `nonlinear_two_mass` (unless an `--effect` names them), then the `effects` specs
    /// (spelled as `simulate --effect`; any of them, even `none`, asks for the nonlinear
    /// engine). A Coulomb friction spec without a breakaway level `fs` is seed 001's pure
    /// law (`F_s = F_c`).
    ///
    /// # Errors
    /// [`SpecError::Effect`] for the first spec that does not parse.
    pub fn resolve(
        family: Family,
        nonlinear_two_mass: bool,
        effects: &[String],
        coulomb: bool,
        current_loop_tau: Option<f64>,
        delay: Option<f64>,
    ) -> Result<ModelSpec, SpecError> {
        let effects = if nonlinear_two_mass || !effects.is_empty() {
            let specs = Self::effect_specs(nonlinear_two_mass, effects);
            let mut parsed = parse_effects(&specs)?;
            // Coulomb friction is seed 001's pure law unless the spec names a breakaway
            // level `fs`: only then are `fs` and `v_stribeck` estimated beside `fc`
            for (e, spec) in parsed.iter_mut().zip(&specs) {
                if let Effect::CoulombFriction(c) = e {
                    let keys = spec.split_once(':').map_or("", |(_, k)| k);
                    if !keys
                        .split(',')
                        .any(|kv| kv.split('=').next().map(str::trim) == Some("fs"))
                    {
                        c.fs = c.fc;
                    }
                }
            }
            Some(parsed)
        } else {
            None
        };
        Ok(ModelSpec {
            family,
            effects,
            coulomb,
            coulomb_asymmetric: false,
            current_loop_tau,
            delay,
        })
    }

    /// The effect specs of [`ModelSpec::resolve`], in order: seed 001's two for the
    /// nonlinear two-mass (those `effects` does not name), then `effects`.
    pub fn effect_specs(nonlinear_two_mass: bool, effects: &[String]) -> Vec<String> {
        let mut specs: Vec<String> = Vec::new();
        if nonlinear_two_mass {
            for name in ["nonlinear_stiffness", "coulomb_friction"] {
                if !effects
                    .iter()
                    .any(|s| s.split(':').next().map(str::trim) == Some(name))
                {
                    specs.push(name.into());
                }
            }
        }
        specs.extend(effects.iter().cloned());
        specs
    }

    /// the nonlinear engine is asked for (effects attached, or `--effect none`)
    pub fn nonlinear(&self) -> bool {
        self.effects.is_some()
    }

    /// Name in reports and model files: the family, with the effects' names after `+`
    /// (`two-mass+nonlinear_stiffness+coulomb_friction`).
    pub fn name(&self) -> String {
        std::iter::once(self.family.name())
            .chain(self.effects.iter().flatten().map(|e| e.name().to_string()))
            .collect::<Vec<_>>()
            .join("+")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn family_parses_names_and_orders_and_refuses_the_rest() {
        assert_eq!("black-box:11".parse(), Ok(Family::BlackBox(11)));
        assert_eq!(
            "three_mass".parse(),
            Ok(Family::Physical(Structure::ThreeMass))
        );
        assert_eq!(
            "Four-Mass".parse(),
            Ok(Family::Physical(Structure::FourMass))
        );
        assert!("black-box:0".parse::<Family>().is_err());
        assert!("five-mass".parse::<Family>().is_err());
        for f in [Family::BlackBox(7), Family::Physical(Structure::Rigid)] {
            assert_eq!(f.name().parse(), Ok(f));
        }
    }

    #[test]
    fn nonlinear_two_mass_resolves_to_the_two_mass_with_seed_001_effects() {
        let s = ModelSpec::resolve(
            Family::Physical(Structure::TwoMass),
            true,
            &["backlash".into()],
            false,
            Some(1e-4),
            None,
        )
        .unwrap();
        let names: Vec<&str> = s.effects.iter().flatten().map(|e| e.name()).collect();
        assert_eq!(
            names,
            ["nonlinear_stiffness", "coulomb_friction", "backlash"]
        );
        match &s.effects.as_ref().unwrap()[1] {
            Effect::CoulombFriction(c) => assert_eq!(c.fs, c.fc),
            e => panic!("not Coulomb friction: {e:?}"),
        }
        assert_eq!(
            s.name(),
            "two-mass+nonlinear_stiffness+coulomb_friction+backlash"
        );
        assert_eq!(s.current_loop_tau, Some(1e-4));
    }

    #[test]
    fn a_linear_spec_has_no_effects_and_none_asks_for_the_nonlinear_engine() {
        let f = Family::Physical(Structure::Rigid);
        let lin = ModelSpec::resolve(f, false, &[], true, None, Some(1.5)).unwrap();
        assert!(!lin.nonlinear());
        assert!(lin.coulomb);
        let none = ModelSpec::resolve(f, false, &["none".into()], false, None, None).unwrap();
        assert_eq!(none.effects, Some(Vec::new()));
        assert!(ModelSpec::resolve(f, false, &["no_such".into()], false, None, None).is_err());
    }

    #[test]
    fn a_spec_round_trips_through_json() {
        let s = ModelSpec::resolve(
            Family::Physical(Structure::TwoMass),
            true,
            &[],
            false,
            None,
            Some(0.5),
        )
        .unwrap();
        let text = serde_json::to_string(&s).unwrap();
        assert_eq!(serde_json::from_str::<ModelSpec>(&text).unwrap(), s);
        let bb = ModelSpec::linear(Family::BlackBox(4));
        let text = serde_json::to_string(&bb).unwrap();
        assert!(text.contains("\"black-box:4\""), "{text}");
        assert_eq!(serde_json::from_str::<ModelSpec>(&text).unwrap(), bb);
    }
}
