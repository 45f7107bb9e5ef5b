//! jointid host library: from a capture of one robot joint to models a control
//! engineer can trust, and to where the simulation departs from the real joint.
//!
//! Modules are grouped by job, in the order of the user's path:
//!
//! ```text
//! capture -> data -> ident (frf, subspace, pem, grey_box, validate, fit) -> diagnose -> report
//!                    model (the joint's laws: parameters, mechanism, effects)
//!                      `-> sim (the closed loop around a model; the simulated board)
//!                    scenario (the paper's experiment on the simulated joint)
//! ```
//!
//! Estimators do no IO: they take an [`data::IdData`] and return values. The library
//! knows no command line; the `jointid` binary (package `jointid-cli`) is one.

#![deny(missing_docs)]
// The module docs map each stage to the private function that owns it (ARCHITECTURE.md);
// they are read with `cargo doc --document-private-items`, where those links resolve.
#![allow(rustdoc::private_intra_doc_links)]

pub mod capture;
pub mod data;
pub mod diagnose;
pub mod ident;
pub mod model;
pub mod report;
pub mod scenario;
pub mod sim;
/// Fixtures with a known truth for the tests of this crate, its benches and the command
/// line's tests (feature `test-support`): not part of the API.
#[cfg(any(test, feature = "test-support"))]
#[doc(hidden)]
pub mod test_support;
