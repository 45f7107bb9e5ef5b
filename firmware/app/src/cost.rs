//! Cost accounting for the 2 kHz tick and the transmit-side encoding, in the
//! board's cost unit (mps2-an386: SysTick counts under QEMU icount, which count
//! instructions; NUCLEO: DWT cycles). Plain counters shared between the tick
//! interrupt and the idle loop through a critical section.

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

/// what one run cost
#[derive(Clone, Copy, Default)]
pub struct Ledger {
    /// whole tick handler, per tick [units]
    pub tick: Stats,
    /// part of the tick spent in the simulated plant (emulated board only) [units]
    pub plant: Stats,
    /// encoding one frame in the idle loop, interrupts subtracted, per frame [units]
    pub encode: Stats,
    /// samples carried by the encoded frames
    pub encoded_samples: u32,
    /// cost units spent in tick handlers so far (to subtract from idle-loop measurements) [units]
    pub in_ticks: u64,
}

static LEDGER: Mutex<RefCell<Ledger>> = Mutex::new(RefCell::new(Ledger {
    tick: Stats {
        count: 0,
        sum: 0,
        max: 0,
    },
    plant: Stats {
        count: 0,
        sum: 0,
        max: 0,
    },
    encode: Stats {
        count: 0,
        sum: 0,
        max: 0,
    },
    encoded_samples: 0,
    in_ticks: 0,
}));

/// runs `f` on the ledger inside a critical section
pub fn with<R>(f: impl FnOnce(&mut Ledger) -> R) -> R {
    critical_section::with(|cs| f(&mut LEDGER.borrow_ref_mut(cs)))
}

/// a copy of the ledger
pub fn snapshot() -> Ledger {
    with(|l| *l)
}

/// what one run cost, converted to instructions (or cycles) per tick
#[derive(Clone, Copy, defmt::Format)]
pub struct Summary {
    /// ticks measured
    pub ticks: u32,
    /// tick handler without the simulated plant: mean [instructions]
    pub tick_mean: u32,
    /// tick handler without the simulated plant: max (max tick minus min plant share is not
    /// known per tick, so this is max tick − mean plant) [instructions]
    pub tick_max: u32,
    /// simulated plant inside the tick (emulated board only): mean [instructions]
    pub plant_mean: u32,
    /// encoding in the idle loop per sample: mean [instructions]
    pub encode_per_sample_mean: u32,
    /// encoding in the idle loop per sample: worst frame's cost divided by the mean samples per frame [instructions]
    pub encode_per_sample_max: u32,
    /// generation + sampling + encoding per tick: mean [instructions]
    pub per_tick_mean: u32,
    /// generation + sampling + encoding per tick: max [instructions]
    pub per_tick_max: u32,
}

/// converts a ledger to per-tick figures, `scale` instructions (or cycles) per cost unit
pub fn summary(l: &Ledger, scale: u32) -> Summary {
    let plant_mean = l.plant.mean();
    let tick_mean = l.tick.mean().saturating_sub(plant_mean);
    let tick_max = l.tick.max.saturating_sub(plant_mean);
    let (enc_mean, enc_max) = if l.encoded_samples == 0 || l.encode.count == 0 {
        (0, 0)
    } else {
        let per_frame = l.encoded_samples.div_ceil(l.encode.count).max(1);
        (
            (l.encode.sum / u64::from(l.encoded_samples)) as u32,
            l.encode.max.div_ceil(per_frame),
        )
    };
    Summary {
        ticks: l.tick.count,
        tick_mean: tick_mean * scale,
        tick_max: tick_max * scale,
        plant_mean: plant_mean * scale,
        encode_per_sample_mean: enc_mean * scale,
        encode_per_sample_max: enc_max * scale,
        per_tick_mean: (tick_mean + enc_mean) * scale,
        per_tick_max: (tick_max + enc_max) * scale,
    }
}

impl Summary {
    /// writes the summary to the defmt log
    pub fn log(&self) {
        defmt::info!("cost per tick: {}", self);
    }
}

impl core::fmt::Display for Summary {
    /// one machine-readable line: `jointid-cost key=value ...`
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "jointid-cost ticks={} per_tick_mean={} per_tick_max={} tick_mean={} tick_max={} \
             encode_per_sample_mean={} encode_per_sample_max={} plant_mean={}",
            self.ticks,
            self.per_tick_mean,
            self.per_tick_max,
            self.tick_mean,
            self.tick_max,
            self.encode_per_sample_mean,
            self.encode_per_sample_max,
            self.plant_mean
        )
    }
}
