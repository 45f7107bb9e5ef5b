//! Sim-to-real gap diagnosis: where the simulated joint departs from the measured one.
//!
//! Reserved: empty until the diagnosis issue lands. It will take identified models and
//! the model description of [`crate::model`], and do no IO.
