//! Real board: NUCLEO-G474RE (STM32G474RE, Cortex-M4F at 170 MHz) on embassy-stm32.
//! - clocks: HSI16 / 4 × 85 / 2 = 170 MHz (boost), PLL1_Q = 85 MHz for FDCAN;
//! - tick: TIM2 update interrupt at 2 kHz (raw ISR, highest priority in use);
//!   embassy's time driver runs on TIM3 so it never takes TIM2;
//! - stream: LPUART1 TX on PA2 (AF12), the ST-LINK/V3E virtual COM port, 921 600 baud 8N1;
//!   with feature `can`: FDCAN1 on PA11 (RX) / PA12 (TX), 1 Mbit/s nominal, 5 Mbit/s data (BRS);
//! - sensors: motor encoder on TIM4 (PB6 = CH1, PB7 = CH2, quadrature mode 3),
//!   torque on ADC1 IN1 (PA0, Arduino A0), reference out on DAC1 OUT1 (PA4, Arduino A2);
//! - log: defmt over RTT, panics through panic-probe (read both with `probe-rs run`).
//!
//! Time stamps and cost: DWT cycle counter (CYCCNT) at the 170 MHz core clock.
//! `scale()` below is a placeholder for a 16384-count/rev encoder and a 12-bit
//! torque ADC spanning ±2 N·m: set it for the real sensors.

use cortex_m::peripheral::{DCB, DWT};
use defmt_rtt as _;
use embassy_executor::Spawner;
use embassy_stm32::adc::{Adc, AdcConfig};
use embassy_stm32::dac::DacChannel;
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::low_level::{RoundTo, Timer};
use embassy_stm32::timer::qei::{Qei, QeiMode};
#[cfg(not(feature = "can"))]
use embassy_stm32::usart;
use embassy_stm32::{interrupt, pac, rcc, Config};
use jointid_core::sampler::PumpState;
use panic_probe as _;

#[cfg(not(feature = "can"))]
use jointid_core::transport::serial::SerialSink;
use jointid_core::wire::Scale;

pub use super::nucleo_io::Io;
use crate::{app, cost};

/// core clock = DWT cycle counter rate = rate of `RawSample::tick` [Hz]
pub const TIMER_HZ: u32 = 170_000_000;
/// one DWT count is one core cycle: the cost is reported in cycles
pub const COST_PER_UNIT: u32 = 1;
/// counts to SI units (placeholder sensors, see the module docs)
pub fn scale() -> Scale {
    Scale {
        torque_nm_per_count: 4.0 / 4096.0,
        angle_rad_per_count: core::f32::consts::TAU / 16384.0,
    }
}

#[cfg(not(feature = "can"))]
/// stream baud rate of the ST-LINK virtual COM port [bit/s]
const BAUD: u32 = 921_600;

/// the MCU's 96-bit unique id folded to 32 bits
pub fn board_id() -> u32 {
    let uid = embassy_stm32::uid::uid();
    uid.chunks(4).fold(0, |acc, w| {
        acc ^ u32::from_le_bytes([w[0], w[1], w[2], w[3]])
    })
}

/// cycle counter at the time the header is built (differs from run to run)
pub fn session_id() -> u32 {
    DWT::cycle_count()
}

/// core cycles since the counter was enabled (DWT CYCCNT, wraps after 25 s)
pub fn stamp() -> u32 {
    DWT::cycle_count()
}

fn clocks() -> Config {
    let mut c = Config::default();
    c.rcc.pll = Some(rcc::Pll {
        source: rcc::PllSource::HSI,
        prediv: rcc::PllPreDiv::DIV4,
        mul: rcc::PllMul::MUL85,
        divp: None,
        divq: Some(rcc::PllQDiv::DIV4),
        divr: Some(rcc::PllRDiv::DIV2),
    });
    c.rcc.sys = rcc::Sysclk::PLL1_R;
    c.rcc.boost = true;
    c.rcc.mux.fdcansel = rcc::mux::Fdcansel::PLL1_Q;
    c.rcc.mux.adc12sel = rcc::mux::Adcsel::SYS;
    c
}

#[embassy_executor::main]
async fn main(_spawner: Spawner) {
    let p = embassy_stm32::init(clocks());
    // SAFETY: DCB and DWT are used only here and by `cost_stamp` (a read-only register).
    let mut core = unsafe { cortex_m::Peripherals::steal() };
    DCB::enable_trace(&mut core.DCB);
    core.DWT.enable_cycle_counter();

    let qei_cfg = embassy_stm32::timer::qei::Config {
        mode: QeiMode::Mode3,
        ..Default::default()
    };
    let encoder = Qei::new(p.TIM4, p.PB6, p.PB7, qei_cfg);
    let adc = Adc::new(p.ADC1, AdcConfig::default());
    let io = Io::new(adc, p.PA0, encoder, DacChannel::new_blocking(p.DAC1, p.PA4));
    #[cfg(not(feature = "can"))]
    let link = {
        let mut cfg = usart::Config::default();
        cfg.baudrate = BAUD;
        SerialSink::new(usart::UartTx::new_blocking(p.LPUART1, p.PA2, cfg).unwrap())
    };
    #[cfg(feature = "can")]
    let link = super::nucleo_can::FdCanLink::new(p.FDCAN1, p.PA11, p.PA12);
    let mut streamer = app::start(io, link);

    let tick = Timer::new(p.TIM2);
    tick.set_frequency(Hertz(app::SAMPLE_RATE_HZ), RoundTo::Slower);
    tick.enable_update_interrupt(true);
    tick.start();
    // SAFETY: the TIM2 handler touches the application state only through critical sections.
    unsafe { cortex_m::peripheral::NVIC::unmask(pac::Interrupt::TIM2) };
    defmt::info!("nucleo-g474re: {=u32} Hz tick on TIM2", app::SAMPLE_RATE_HZ);
    loop {
        match streamer.poll() {
            PumpState::Busy => {}
            PumpState::Idle => cortex_m::asm::wfi(),
            PumpState::Done => break,
        }
    }
    tick.enable_update_interrupt(false);
    let summary = cost::summary(COST_PER_UNIT);
    defmt::info!(
        "end: {}; cost per tick [cycles]: {}",
        streamer.status(),
        summary
    );
}

#[interrupt]
fn TIM2() {
    pac::TIM2.sr().modify(|r| r.set_uif(false));
    let c0 = DWT::cycle_count();
    app::tick(c0);
    cost::book_tick(DWT::cycle_count().wrapping_sub(c0));
}
