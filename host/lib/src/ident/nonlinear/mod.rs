//! Nonlinear grey-box identification: a physical model (rigid, two-, three-, four-mass)
//! with any of the simulator's effects attached ([`crate::model::effects`]), fitted by
//! output error from the measured torque with exact derivatives ([`output_error`]), from starting
//! values found in the data ([`init`], seed 001's three steps; when the motor sticks, grown in
//! the time domain, [`grow`]). The equations are the
//! simulator's ([`crate::model::laws`]); the non-smooth ones (Coulomb friction, backlash)
//! enter the fit in their documented smooth form ([`model`]).

pub mod compensate;
pub mod dual;
pub mod export;
pub mod grow;
pub mod init;
pub mod model;
pub mod output_error;
pub mod ripple;
pub mod run;

pub use export::{simulate_args, simulate_exact};
pub use grow::{grow_with, stick_share, Grown, Seed, STICK_SHARE};
pub use init::{automatic_start, automatic_start_with, LinearFit, RippleOrder, Start, Step};
pub use model::{sim_plant, NlModel, Owner, ParamDef, Scale};
pub use output_error::{
    cost_at, fit_output_error, fit_output_error_segments, interval_velocity, pooled_velocity_fit,
    simulate_velocity, Correlation, Gradient, NlError, NlFit, NlOptions, NlParam,
};
pub use run::{
    friction_level, identify, identify_segments, linear_start, linear_start_segments,
    linear_start_shared, model_name, model_of, run, sampled_input_note, validate,
    validate_segments, DelayLines, LinearStart, LinearStartError, NlData, NlRequest, NlResult,
    NlRun, NlRunError, NlStart, NlValidation, RawFrfFits, StartSearch, CANDIDATE_PATIENCE,
    UNRESOLVED_LAG,
};

#[cfg(test)]
mod ripple_tests;
#[cfg(test)]
mod segments_tests;
#[cfg(test)]
mod tests;
