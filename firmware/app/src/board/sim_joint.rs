//! Sensors and actuator of the emulated board: the core's simulated joint
//! (`jointid_core::joint`), with each model step timed as plant cost so the
//! firmware's own cost per tick can be told apart from the stand-in hardware.

use jointid_core::joint::JointIo;
use jointid_core::sampler::{AngleInput, ReferenceOutput, TorqueInput};

use super::stamp;
use crate::cost;

/// The board's sensors and actuator: the core's simulated joint (three-mass
/// model under its P/PI cascade, default parameters); each step is timed as
/// plant cost, apart from the firmware's own.
pub struct Io(JointIo);

impl Io {
    /// wraps the core's joint adapter
    pub fn new(joint: JointIo) -> Self {
        Self(joint)
    }
}

impl TorqueInput for Io {
    fn read_torque(&mut self) -> i32 {
        self.0.read_torque()
    }
}

impl AngleInput for Io {
    fn read_angle(&mut self) -> i32 {
        self.0.read_angle()
    }
}

impl ReferenceOutput for Io {
    fn write_reference(&mut self, theta_ref: f32) {
        let t0 = stamp();
        self.0.write_reference(theta_ref);
        cost::book_plant(stamp().wrapping_sub(t0));
    }
}
