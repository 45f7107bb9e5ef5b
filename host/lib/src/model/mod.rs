//! The joint as physics: the parameters of the plant family and their table
//! ([`params`]), the mechanism of masses, springs and dampers ([`plant`]) and the laws
//! of the effects beyond it ([`effects`]: friction, backlash, cubic spring, extra mode,
//! delay, ripple), their pointwise equations written once for the simulator and the
//! estimators ([`laws`]), and the mechanical structures of the model families ([`spec`]). The
//! simulator ([`crate::sim`]) integrates them in its closed loop;
//! the estimators take their laws, not the simulator's integrator.

pub mod effects;
pub mod laws;
pub mod params;
pub mod plant;
pub mod spec;
