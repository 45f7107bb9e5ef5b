//! jointid host library: from a capture of one robot joint to models a control
//! engineer can trust, and to where the simulation departs from the real joint.
//!
//! Modules follow the user's path: capture -> data -> frf -> subspace / pem /
//! grey_box -> validate -> diagnose -> report. Estimators do no IO: they take
//! an [`data::IdData`] and return values.

pub mod capture;
pub mod data;
pub mod experiment;
pub mod fit;
pub mod frf;
pub mod grey_box;
pub mod linalg;
pub mod lm;
pub mod pem;
pub mod plot;
pub mod sim;
pub mod ss;
pub mod subspace;
pub mod test_support;
pub mod validate;
