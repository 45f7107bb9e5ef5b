//! Cost accounting for the 2 kHz tick and the transmit side, in the board's
//! stamp unit (mps2-an386: SysTick counts under QEMU icount, 5 instructions
//! each at shift 3; NUCLEO: DWT cycles). Counters shared between the tick
//! interrupt and the idle loop through a critical section.
//!
//! - tick: the whole tick handler (excitation, sensors, queue push) minus the
//!   simulated plant's step on the emulated board (that stands in for
//!   hardware, it is not firmware work);
//! - pump: each idle-loop poll (dequeue, batching, CRC, postcard, COBS) minus
//!   the link's write and the tick interrupts that preempted it.
//!
//! Reported per 2 kHz tick period: mean = tick mean + pump total / ticks;
//! max = largest tick + largest single poll (an upper bound: the two rarely
//! fall in the same period).

use core::cell::RefCell;
use critical_section::Mutex;

/// running mean and maximum of a cost [board cost units]
#[derive(Clone, Copy, Default, defmt::Format)]
pub struct Stats {
    /// number of measurements
    pub count: u32,
    /// sum of all measurements [units]
    pub sum: u64,
    /// largest measurement [units]
    pub max: u32,
}

impl Stats {
    /// add one measurement [units]
    pub fn add(&mut self, units: u32) {
        self.count += 1;
        self.sum += u64::from(units);
        self.max = self.max.max(units);
    }

    /// mean [units], 0 when empty
    pub fn mean(&self) -> u32 {
        if self.count == 0 {
            0
        } else {
            (self.sum / u64::from(self.count)) as u32
        }
    }
}

/// what one run cost [stamp units]
#[derive(Clone, Copy, Default)]
pub struct Ledger {
    /// tick handler without the simulated plant, per tick
    pub tick: Stats,
    /// simulated plant's step inside the tick (emulated board only), per tick
    pub plant: Stats,
    /// the plant's last step, subtracted from the tick that contains it
    pub plant_last: u32,
    /// idle-loop polls without the link and the preempting ticks, per poll
    pub pump: Stats,
    /// all time spent in tick handlers (subtracted from the polls they preempt)
    pub in_ticks: u64,
}

const EMPTY: Stats = Stats {
    count: 0,
    sum: 0,
    max: 0,
};
static LEDGER: Mutex<RefCell<Ledger>> = Mutex::new(RefCell::new(Ledger {
    tick: EMPTY,
    plant: EMPTY,
    plant_last: 0,
    pump: EMPTY,
    in_ticks: 0,
}));

/// runs `f` on the ledger inside a critical section
pub fn with<R>(f: impl FnOnce(&mut Ledger) -> R) -> R {
    critical_section::with(|cs| f(&mut LEDGER.borrow_ref_mut(cs)))
}

/// Books one tick handler that took `spent` units in all (plant included).
pub fn book_tick(spent: u32) {
    with(|l| {
        l.tick.add(spent.saturating_sub(l.plant_last));
        l.plant_last = 0;
        l.in_ticks += u64::from(spent);
    });
}

/// Books one step of the simulated plant [units].
#[cfg_attr(not(feature = "mps2-an386"), allow(dead_code))]
pub fn book_plant(spent: u32) {
    with(|l| {
        l.plant.add(spent);
        l.plant_last = spent;
    });
}

/// a run's cost per 2 kHz tick period, in instructions (emulated) or cycles (NUCLEO)
#[derive(Clone, Copy, defmt::Format)]
pub struct Summary {
    /// ticks measured
    pub ticks: u32,
    /// firmware work per tick period: tick + pump share, mean
    pub per_tick_mean: u32,
    /// firmware work per tick period: largest tick + largest poll (upper bound)
    pub per_tick_max: u32,
    /// tick handler (plant excluded), mean
    pub tick_mean: u32,
    /// tick handler (plant excluded), max
    pub tick_max: u32,
    /// idle-loop pump (batching + encoding) per tick, mean
    pub pump_per_tick_mean: u32,
    /// longest single poll (one batch encoded)
    pub pump_poll_max: u32,
    /// simulated plant per tick, mean (not firmware work)
    pub plant_mean: u32,
}

/// The ledger converted to per-tick figures with `scale` instructions (or cycles) per unit.
pub fn summary(scale: u32) -> Summary {
    let l = with(|l| *l);
    let ticks = l.tick.count.max(1);
    let pump_per_tick = (l.pump.sum / u64::from(ticks)) as u32;
    Summary {
        ticks: l.tick.count,
        per_tick_mean: (l.tick.mean() + pump_per_tick) * scale,
        per_tick_max: (l.tick.max + l.pump.max) * scale,
        tick_mean: l.tick.mean() * scale,
        tick_max: l.tick.max * scale,
        pump_per_tick_mean: pump_per_tick * scale,
        pump_poll_max: l.pump.max * scale,
        plant_mean: l.plant.mean() * scale,
    }
}

impl core::fmt::Display for Summary {
    /// one machine-readable line: `jointid-cost key=value ...`
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "jointid-cost ticks={} per_tick_mean={} per_tick_max={} tick_mean={} tick_max={} \
             pump_per_tick_mean={} pump_poll_max={} plant_mean={}",
            self.ticks,
            self.per_tick_mean,
            self.per_tick_max,
            self.tick_mean,
            self.tick_max,
            self.pump_per_tick_mean,
            self.pump_poll_max,
            self.plant_mean
        )
    }
}
