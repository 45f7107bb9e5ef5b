//! NUCLEO-G474RE sensors and actuator behind the core's sampler traits: motor
//! encoder on TIM4 (quadrature, 16-bit counter extended to 32 bits), torque on
//! ADC1 (one blocking 12-bit conversion per tick, 24.5 ADC cycles sampling),
//! reference on DAC1 channel 1 (12 bits, ±π rad full scale).

use embassy_stm32::adc::{Adc, SampleTime};
use embassy_stm32::dac::{DacChannel, Value};
use embassy_stm32::mode::Blocking;
use embassy_stm32::peripherals::{ADC1, PA0, TIM4};
use embassy_stm32::timer::qei::Qei;
use embassy_stm32::Peri;

use jointid_core::sampler::{AngleInput, ReferenceOutput, TorqueInput};

use crate::app;

/// the board's sensors and actuator
pub struct Io {
    adc: Adc<'static, ADC1>,
    torque_pin: Peri<'static, PA0>,
    encoder: Qei<'static, TIM4>,
    last_count: u16,
    angle: i32,
    dac: DacChannel<'static, Blocking>,
}

impl ReferenceOutput for Io {
    fn write_reference(&mut self, theta_ref: f32) {
        self.dac.set(Value::Bit12Right(app::dac_code(theta_ref)));
    }
}

impl TorqueInput for Io {
    fn read_torque(&mut self) -> i32 {
        i32::from(
            self.adc
                .blocking_read(&mut self.torque_pin, SampleTime::CYCLES24_5),
        )
    }
}

impl AngleInput for Io {
    fn read_angle(&mut self) -> i32 {
        // extend the 16-bit hardware counter by the signed difference since the last tick
        let now = self.encoder.count();
        self.angle = self
            .angle
            .wrapping_add(i32::from(now.wrapping_sub(self.last_count) as i16));
        self.last_count = now;
        self.angle
    }
}

impl Io {
    /// the sensors as wired on the board (see the board module)
    pub fn new(
        adc: Adc<'static, ADC1>,
        torque_pin: Peri<'static, PA0>,
        encoder: Qei<'static, TIM4>,
        dac: DacChannel<'static, Blocking>,
    ) -> Self {
        let last_count = encoder.count();
        Self {
            adc,
            torque_pin,
            encoder,
            last_count,
            angle: 0,
            dac,
        }
    }
}
