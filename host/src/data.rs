//! Identification data: one input, one output, uniformly sampled.

/// Input/output record of one experiment, uniformly sampled.
#[derive(Clone, Debug, PartialEq)]
pub struct IdData {
    /// sample interval [s]
    pub ts: f64,
    /// input: motor torque reference `u` [N·m] (or force [N] for a linear axis)
    pub u: Vec<f64>,
    /// output: motor angle `theta_m` [rad] (or position [m])
    pub y: Vec<f64>,
    /// excitation reference `theta_ref` [rad], when recorded or regenerated
    pub r: Option<Vec<f64>>,
}
