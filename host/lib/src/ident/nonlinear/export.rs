//! A fitted nonlinear model handed back to the simulator: the arguments of `jointid
//! simulate` that rebuild its plant and effects ([`simulate_args`]), and its motor angle
//! simulated with the simulator's exact laws from a measured torque
//! ([`simulate_exact`], the series behind [`super::validate`]'s FITs, for plots).

use super::model::sim_plant;
use super::output_error::{NlError, NlFit};
use crate::data::IdData;
use crate::model::params::model_params;
use crate::sim::{simulate_driven, DrivenStart};

/// The `jointid simulate` arguments (`--model KIND`, one `--param NAME=VALUE` per
/// parameter the simulator's plant uses, one `--effect SPEC` per effect) that rebuild the
/// fitted plant and effects. Values are printed in Rust's shortest round-trip form, so
/// they parse back to the same `f64`. The simulator closes its own position loop and
/// current loop around the plant: the fitted current-loop lag and torque offset are not
/// among its arguments.
pub fn simulate_args(fit: &NlFit) -> Vec<String> {
    let plant = sim_plant(&fit.model, &fit.plant);
    let mut p = plant.params;
    let mut args = vec!["--model".to_string(), plant.kind.label().to_string()];
    for (name, field) in model_params(plant.kind) {
        args.push("--param".into());
        args.push(format!("{name}={}", *field(&mut p)));
    }
    for e in &fit.model.effects {
        args.push("--effect".into());
        args.push(e.to_string());
    }
    args
}

/// The motor angle [rad] of `fit` simulated with the simulator's exact laws, driven by the
/// measured torque of `data` plus the fitted offset, from rest at the first measured angle
/// (as [`super::validate`] does).
///
/// # Errors
/// [`NlError::Simulation`] when the simulator refuses the model or the record.
pub fn simulate_exact(fit: &NlFit, data: &IdData) -> Result<Vec<f64>, NlError> {
    let offset = fit.get("offset").unwrap_or(0.0);
    let u: Vec<f64> = data.u.iter().map(|u| u + offset).collect();
    let plant = sim_plant(&fit.model, &fit.plant);
    let tc = if fit.model.tau_c > 0.0 {
        fit.model.tau_c
    } else {
        1e-9
    };
    let start = DrivenStart::Rest {
        theta_m: data.y.first().copied().unwrap_or(0.0),
    };
    simulate_driven(&plant, &fit.model.effects, tc, data.ts, &u, &start)
        .map(|o| o.theta_m)
        .map_err(NlError::Simulation)
}
