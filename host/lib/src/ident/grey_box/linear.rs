//! The linear grey-box model (seed 000 eq. (5)–(8)): the continuous and sampled state
//! space of each structure from its physical parameters, as a [`ParamModel`] over their
//! logarithms.

use super::*;

/// A grey-box model family: structure, output, gear ratio, sample interval;
/// parameters are the natural logarithms of the values of
/// [`Structure::param_names`] (arm-side, seed 000 Table 1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GreyBoxModel {
    /// mechanical structure
    pub structure: Structure,
    /// output signal
    pub output: Output,
    /// gear ratio `r` (arm angle per motor angle)
    pub r: f64,
    /// sample interval [s]
    pub ts: f64,
}

impl GreyBoxModel {
    /// Continuous model `ẋ = F x + G u`, `y = H x` for the parameter values
    /// `p` (not logarithms), in the order of [`Structure::param_names`].
    pub fn continuous(&self, p: &[f64]) -> ContinuousSs {
        let r = self.r;
        let (f, vel_state) = match self.structure {
            Structure::Rigid => (DMatrix::from_element(1, 1, -p[1] / p[0]), 0),
            Structure::Grounded => {
                // state [θ_m, ω_m]: J ω̇ = u − Fv ω − k_0 θ (no gearbox)
                let [j, fv, k0] = [p[0], p[1], p[2]];
                let f = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -k0 / j, -fv / j]);
                let g = DVector::from_column_slice(&[0.0, 1.0 / j]);
                let mut h = RowDVector::zeros(2);
                h[match self.output {
                    Output::Angle => 0,
                    Output::Velocity => 1,
                }] = 1.0;
                return ContinuousSs { f, g, h, d: 0.0 };
            }
            Structure::TwoMass => {
                let [jm, ja, kg, dg, fm] = [p[0], p[1], p[2], p[3], p[4]];
                (
                    DMatrix::from_row_slice(
                        3,
                        3,
                        &[
                            0.0,
                            r,
                            -1.0, //
                            -r * kg / jm,
                            -(fm + r * r * dg) / jm,
                            r * dg / jm, //
                            kg / ja,
                            r * dg / ja,
                            -dg / ja,
                        ],
                    ),
                    1,
                )
            }
            Structure::ThreeMass => {
                // seed 000 eq. (6)
                let [jm, ja1, ja2, kg, ka, dg, da, fm] =
                    [p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7]];
                (
                    DMatrix::from_row_slice(
                        5,
                        5,
                        &[
                            0.0,
                            0.0,
                            r,
                            -1.0,
                            0.0, //
                            0.0,
                            0.0,
                            0.0,
                            1.0,
                            -1.0, //
                            -kg * r / jm,
                            0.0,
                            -(fm + dg * r * r) / jm,
                            dg * r / jm,
                            0.0, //
                            kg / ja1,
                            -ka / ja1,
                            dg * r / ja1,
                            -(dg + da) / ja1,
                            da / ja1, //
                            0.0,
                            ka / ja2,
                            0.0,
                            da / ja2,
                            -da / ja2,
                        ],
                    ),
                    2,
                )
            }
            Structure::FourMass => {
                // seed 000 eq. (7)
                let [jm, ja1, ja2, jp, kg, ka, kp, dg, da, dp, fm] = [
                    p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7], p[8], p[9], p[10],
                ];
                let a44 = -(fm + dg * r * r) / jm;
                let a55 = -(dg + da + dp) / ja1;
                (
                    DMatrix::from_row_slice(
                        7,
                        7,
                        &[
                            0.0,
                            0.0,
                            0.0,
                            r,
                            -1.0,
                            0.0,
                            0.0, //
                            0.0,
                            0.0,
                            0.0,
                            0.0,
                            1.0,
                            -1.0,
                            0.0, //
                            0.0,
                            0.0,
                            0.0,
                            0.0,
                            1.0,
                            0.0,
                            -1.0, //
                            -kg * r / jm,
                            0.0,
                            0.0,
                            a44,
                            dg * r / jm,
                            0.0,
                            0.0, //
                            kg / ja1,
                            -ka / ja1,
                            -kp / ja1,
                            dg * r / ja1,
                            a55,
                            da / ja1,
                            dp / ja1, //
                            0.0,
                            ka / ja2,
                            0.0,
                            0.0,
                            da / ja2,
                            -da / ja2,
                            0.0, //
                            0.0,
                            0.0,
                            kp / jp,
                            0.0,
                            dp / jp,
                            0.0,
                            -dp / jp,
                        ],
                    ),
                    3,
                )
            }
        };
        let n = f.nrows();
        let mut g = DVector::zeros(n);
        g[vel_state] = 1.0 / p[0];
        match self.output {
            Output::Velocity => {
                let mut h = RowDVector::zeros(n);
                h[vel_state] = 1.0;
                ContinuousSs { f, g, h, d: 0.0 }
            }
            Output::Angle => {
                // prepend θ_m with dθ_m/dt = velocity state
                let mut fa = DMatrix::zeros(n + 1, n + 1);
                fa.view_mut((1, 1), (n, n)).copy_from(&f);
                fa[(0, vel_state + 1)] = 1.0;
                let mut ga = DVector::zeros(n + 1);
                ga.rows_mut(1, n).copy_from(&g);
                let mut h = RowDVector::zeros(n + 1);
                h[0] = 1.0;
                ContinuousSs {
                    f: fa,
                    g: ga,
                    h,
                    d: 0.0,
                }
            }
        }
    }
}

impl ParamModel for GreyBoxModel {
    fn n_params(&self) -> usize {
        self.structure.param_names().len()
    }

    fn param_names(&self) -> Vec<String> {
        self.structure
            .param_names()
            .iter()
            .map(|s| s.to_string())
            .collect()
    }

    fn to_ss(&self, theta: &[f64]) -> StateSpace {
        let p: Vec<f64> = theta.iter().map(|t| t.exp()).collect();
        self.continuous(&p).zoh(self.ts)
    }
}

// ---------------------------------------------------------------------------
// rigid body: inverse-dynamics least squares (IDIM-LS)
