//! The description of a joint model that everything else is given: which mechanical
//! structure ([`Structure`]). The simulator's plants ([`crate::model::params::PlantKind`])
//! and the estimators' model families (`crate::ident::fit::ModelKind`) are built on it.

/// Mechanical structure of a joint model: the one list of structures the estimators fit
/// and the simulator's plants are built on ([`crate::model::params::PlantKind::structure`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Structure {
    /// one inertia with viscous friction
    Rigid,
    /// motor and arm through the gearbox spring
    TwoMass,
    /// seed 000 eq. (6)
    ThreeMass,
    /// seed 000 eq. (7)
    FourMass,
}

impl Structure {
    /// Every structure, in the order of increasing complexity.
    pub const ALL: [Structure; 4] = [
        Structure::Rigid,
        Structure::TwoMass,
        Structure::ThreeMass,
        Structure::FourMass,
    ];

    /// Name on the command line and in model files (`three-mass`).
    pub fn label(self) -> &'static str {
        match self {
            Structure::Rigid => "rigid",
            Structure::TwoMass => "two-mass",
            Structure::ThreeMass => "three-mass",
            Structure::FourMass => "four-mass",
        }
    }

    /// number of masses
    pub fn masses(self) -> usize {
        match self {
            Structure::Rigid => 1,
            Structure::TwoMass => 2,
            Structure::ThreeMass => 3,
            Structure::FourMass => 4,
        }
    }

    /// parameter names, seed 000 Table 1 (rigid: `J`, `Fv`)
    pub fn param_names(self) -> &'static [&'static str] {
        match self {
            Structure::Rigid => &["J", "Fv"],
            Structure::TwoMass => &["J_m", "J_a1", "k_g", "d_g", "f_m"],
            Structure::ThreeMass => &["J_m", "J_a1", "J_a2", "k_g", "k_a", "d_g", "d_a", "f_m"],
            Structure::FourMass => &[
                "J_m", "J_a1", "J_a2", "J_p", "k_g", "k_a", "k_p", "d_g", "d_a", "d_p", "f_m",
            ],
        }
    }
}
