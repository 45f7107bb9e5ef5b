//! A physical model behind the drive's current loop: what the time- and frequency-domain
//! fits of the linear physical models estimate (seed 000 eq. (6)–(7) with the lag).

use nalgebra::{DMatrix, DVector, RowDVector};

use super::GreyBoxModel;
use crate::ident::pem::ParamModel;
use crate::ident::ss::{ContinuousSs, StateSpace};

/// A physical model driven through the current loop: the motor torque
/// follows the torque reference `u` through the first-order lag
/// `τ_c τ̇ = u − τ` (seed 000 §4.2 neglects the current controller; a
/// drive's closed current loop is close to this lag), then the mechanics of
/// [`GreyBoxModel`]. `τ_c` is fixed (known from the drive, like
/// the gear ratio); with `τ_c = 0` the model is the mechanics alone.
/// Parameters as [`GreyBoxModel`] (logarithms).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DrivenModel {
    /// the mechanical model (structure, output, gear ratio, sample interval)
    pub mechanics: GreyBoxModel,
    /// current-loop time constant `τ_c` [s]
    pub current_loop_tau: f64,
}

impl DrivenModel {
    /// `mechanics` behind a current loop of `current_loop_tau` [s] (negative: none).
    pub fn of(mechanics: GreyBoxModel, current_loop_tau: f64) -> Self {
        DrivenModel {
            mechanics,
            current_loop_tau: current_loop_tau.max(0.0),
        }
    }

    /// continuous model for parameter values `p` (not logarithms); the lag
    /// state is the last one
    pub fn continuous(&self, p: &[f64]) -> ContinuousSs {
        let c = self.mechanics.continuous(p);
        let tau = self.current_loop_tau;
        if tau <= 0.0 {
            return c;
        }
        let n = c.f.nrows();
        let mut f = DMatrix::zeros(n + 1, n + 1);
        f.view_mut((0, 0), (n, n)).copy_from(&c.f);
        for i in 0..n {
            f[(i, n)] = c.g[i];
        }
        f[(n, n)] = -1.0 / tau;
        let mut g = DVector::zeros(n + 1);
        g[n] = 1.0 / tau;
        let mut h = RowDVector::zeros(n + 1);
        h.columns_mut(0, n).copy_from(&c.h);
        ContinuousSs { f, g, h, d: c.d }
    }
}

impl ParamModel for DrivenModel {
    fn n_params(&self) -> usize {
        self.mechanics.n_params()
    }

    fn param_names(&self) -> Vec<String> {
        self.mechanics.param_names()
    }

    fn to_ss(&self, theta: &[f64]) -> StateSpace {
        let p: Vec<f64> = theta.iter().map(|t| t.exp()).collect();
        self.continuous(&p).zoh(self.mechanics.ts)
    }
}
