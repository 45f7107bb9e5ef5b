//! Emulated board: QEMU `mps2-an386` (Cortex-M4 at 25 MHz, CMSDK peripherals).
//! - tick: SysTick at 2 kHz (reload 12_499 at 25 MHz);
//! - stream: CMSDK APB UART0 at 0x4000_4000 (QEMU `-serial`), polled on TXFULL;
//! - sensors: the core's simulated joint, so the stream carries realistic data;
//! - log: defmt over semihosting (QEMU stdout); the run ends with a semihosting
//!   exit (0 when the configured run is sent, 1 on panic or HardFault).
//!
//! Cost unit: SysTick counts; under `-icount shift=3` one count is 40 ns of
//! virtual time, that is 40 / 2^3 = 5 instructions (notes/embedded-feasibility.md).

use core::convert::Infallible;
use core::ptr::{read_volatile, write_volatile};
use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m::peripheral::{syst::SystClkSource, SCB, SYST};
use cortex_m_rt::{entry, exception, ExceptionFrame};
use cortex_m_semihosting::{debug, heprintln};
use defmt_semihosting as _;

use crate::{app, cost};

/// core clock of the AN386 image [Hz]
const CPU_HZ: u32 = 25_000_000;
/// SysTick reload for the sample rate: 25 MHz / 2 kHz - 1 = 12_499
const RELOAD: u32 = CPU_HZ / app::SAMPLE_RATE_HZ - 1;
/// instructions per SysTick count under `-icount shift=3`: 40 ns / 8 ns
pub const INSTRUCTIONS_PER_UNIT: u32 = 5;
/// CMSDK APB UART0 base address
const UART0: usize = 0x4000_4000;

/// ticks since boot (the upper part of [`cost_stamp`])
static TICKS: AtomicU32 = AtomicU32::new(0);

/// the board's sensors and actuator: the simulated joint (stand-in until the core lands)
pub struct Io {
    k: i32,
}

impl app::Io for Io {
    fn torque(&mut self) -> i32 {
        self.k
    }
    fn angle(&mut self) -> i32 {
        self.k += 1;
        -self.k
    }
    fn reference(&mut self, _theta: f32) {}
}

/// CMSDK UART0 transmitter as a blocking `embedded_io::Write`
pub struct Uart0(());

impl Uart0 {
    fn new() -> Self {
        // SAFETY: UART0 registers are only touched through this single value.
        unsafe {
            write_volatile((UART0 + 0x10) as *mut u32, 16); // BAUDDIV >= 16 or QEMU ignores writes
            write_volatile((UART0 + 0x08) as *mut u32, 1); // CTRL: TX enable
        }
        Uart0(())
    }
}

impl embedded_io::ErrorType for Uart0 {
    type Error = Infallible;
}

impl embedded_io::Write for Uart0 {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        for &b in buf {
            // SAFETY: STATE and DATA are UART0 registers; bit 0 of STATE is TXFULL.
            unsafe {
                while read_volatile((UART0 + 0x04) as *const u32) & 1 != 0 {}
                write_volatile(UART0 as *mut u32, u32::from(b));
            }
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}

/// monotonic time in SysTick counts since boot (wraps after ~172 s)
pub fn cost_stamp() -> u32 {
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
    let mut uart = Uart0::new();
    app::install(Io { k: 0 });
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
        match app::pump(&mut uart) {
            app::Pump::Busy => {}
            app::Pump::Idle => cortex_m::asm::wfi(),
            app::Pump::Done => break,
        }
    }
    syst.disable_interrupt();
    let s = cost::summary(&cost::snapshot(), INSTRUCTIONS_PER_UNIT);
    s.log();
    heprintln!("{}", s);
    exit(true)
}

#[exception]
fn SysTick() {
    let c0 = SYST::get_current();
    TICKS.fetch_add(1, Ordering::Relaxed);
    app::tick();
    let spent = c0.wrapping_sub(SYST::get_current());
    cost::with(|l| {
        l.tick.add(spent);
        l.in_ticks += u64::from(spent);
    });
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
