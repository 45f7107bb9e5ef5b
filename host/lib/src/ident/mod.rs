//! Identification: from an [`crate::data::IdData`] to models and how well they explain
//! the data. Nonparametric FRF ([`frf`]), black box ([`subspace`], refined by [`pem`]),
//! physical models ([`grey_box`]), one Levenberg–Marquardt loop ([`lm`]), validation
//! ([`validate`], the only FIT), the orchestration the command line and the
//! scenarios share ([`fit`]) and the model file ([`model_file`]). State-space algebra in [`ss`] and [`linalg`].
//!
//! Nothing here does IO.

pub mod controller;
pub mod fit;
pub mod frf;
pub mod frf_subspace;
pub mod grey_box;
pub mod linalg;
pub mod lm;
pub mod model_export;
pub mod model_file;
pub mod nonlinear;
pub mod parallel;
pub mod pem;
pub mod sml;
pub mod ss;
pub mod subspace;
pub mod validate;
