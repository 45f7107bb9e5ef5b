//! Emulated board: QEMU `mps2-an386` (Cortex-M4 at 25 MHz, CMSDK peripherals).
//! - tick: SysTick at 2 kHz (reload 12_499 at 25 MHz);
//! - stream: CMSDK APB UART0 at 0x4000_4000 (QEMU `-serial`), polled on TXFULL;
//! - sensors: the core's simulated joint, so the stream carries realistic data;
//! - log: defmt over semihosting (QEMU stdout); the run ends with a semihosting
//!   exit (0 when the configured run is sent, 1 on panic or HardFault), after
//!   a `jointid-cost ...` line on semihosting stderr.
//!
//! Time stamps and cost are SysTick counts (25 MHz). Under `-icount shift=3`
//! one count is 40 ns of virtual time = 40 / 2^3 = 5 instructions
//! (notes/embedded-feasibility.md §2).

use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m::peripheral::{syst::SystClkSource, SCB, SYST};
use cortex_m_rt::{entry, exception, ExceptionFrame};
use cortex_m_semihosting::{debug, heprintln};
use defmt_semihosting as _;
use jointid_core::joint::{JointIo, JointParams, JointSim};
use jointid_core::sampler::PumpState;
use jointid_core::transport::serial::SerialSink;
use jointid_core::wire::Scale;

use super::cmsdk_uart::CmsdkUartTx;
pub use super::sim_joint::Io;
use crate::{app, cost};

/// SysTick clock = core clock of the AN386 image [Hz]; also the rate of `RawSample::tick`
pub const TIMER_HZ: u32 = 25_000_000;
/// SysTick reload for the sample rate: 25 MHz / 2 kHz - 1 = 12_499
const RELOAD: u32 = TIMER_HZ / app::SAMPLE_RATE_HZ - 1;
/// instructions per SysTick count under `-icount shift=3`: 40 ns / 8 ns
pub const COST_PER_UNIT: u32 = 5;
/// the simulated joint (the same parameters the host test re-runs)
pub const JOINT: JointParams = JointParams::default_joint();

/// ticks since boot (the upper part of [`stamp`])
static TICKS: AtomicU32 = AtomicU32::new(0);

/// counts to SI units of the simulated joint's sensors
pub fn scale() -> Scale {
    JOINT.scale()
}

/// identifies the emulated board in the session header: 0x386 for AN386
pub fn board_id() -> u32 {
    0x386
}

/// the emulated run is deterministic, so is its session id
pub fn session_id() -> u32 {
    1
}

/// SysTick counts since boot (wraps after 172 s)
pub fn stamp() -> u32 {
    critical_section::with(|_| {
        let mut ticks = TICKS.load(Ordering::Relaxed);
        let mut cvr = SYST::get_current();
        if SCB::is_pendst_pending() {
            ticks = ticks.wrapping_add(1);
            cvr = SYST::get_current();
        }
        ticks.wrapping_mul(RELOAD + 1).wrapping_add(RELOAD - cvr)
    })
}

#[entry]
fn main() -> ! {
    let cp = cortex_m::Peripherals::take().unwrap();
    let mut syst = cp.SYST;
    // SAFETY: UART0 is used only here.
    let uart = unsafe { CmsdkUartTx::new(0x4000_4000, 16) };
    let io = Io::new(JointIo::new(JointSim::new(JOINT)));
    let mut streamer = app::start(io, SerialSink::new(uart));
    defmt::info!(
        "mps2-an386: {=u32} Hz tick, SysTick reload {=u32}",
        app::SAMPLE_RATE_HZ,
        RELOAD
    );
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(RELOAD);
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();
    loop {
        match streamer.poll() {
            PumpState::Busy => {}
            PumpState::Idle => cortex_m::asm::wfi(),
            PumpState::Done => break,
        }
    }
    syst.disable_interrupt();
    let s = cost::summary(COST_PER_UNIT);
    defmt::info!(
        "end: {}; cost per tick [instructions]: {}",
        streamer.status(),
        s
    );
    heprintln!("{}", s);
    exit(true)
}

#[exception]
fn SysTick() {
    let c0 = SYST::get_current();
    TICKS.fetch_add(1, Ordering::Relaxed);
    app::tick(stamp());
    cost::book_tick(c0.wrapping_sub(SYST::get_current()));
}

#[exception]
unsafe fn HardFault(ef: &ExceptionFrame) -> ! {
    defmt::error!("HardFault at pc {=u32:#010x}", ef.pc());
    exit(false)
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    defmt::error!("panic: {}", defmt::Display2Format(info));
    exit(false)
}

#[defmt::panic_handler]
fn defmt_panic() -> ! {
    exit(false)
}

/// ends the QEMU run with status 0 (`ok`) or 1 through semihosting
fn exit(ok: bool) -> ! {
    debug::exit(if ok {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    loop {
        cortex_m::asm::wfi();
    }
}
