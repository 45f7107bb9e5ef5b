//! A measured-like grounded mass–spring–damper with a hardening spring, open loop: the
//! electrical analogue of the nonlinear benchmarks (a mass on a cubic spring to the frame,
//! driven by a force, its position sampled at 610 Hz), simulated by the simulator's exact
//! laws with known truth.

use super::Gauss;
use crate::data::{rms_about_mean, Dataset, IdData};
use crate::model::effects::{Effect, NonlinearStiffness};
use crate::model::params::{JointParams, Plant};
use crate::model::spec::Structure;
use crate::sim::{simulate_driven, DrivenStart};

/// Sample rate [Hz].
pub const FS_HZ: f64 = 610.35;
/// Resonance of the linear part [Hz].
pub const F0_HZ: f64 = 60.0;
/// Damping ratio of the linear part [-].
pub const ZETA: f64 = 0.03;
/// Samples of one multisine period.
const PERIOD: usize = 4096;

/// The linear grounded mass (`r = 1`, unit mass, [`F0_HZ`], [`ZETA`]): `J` 1 kg·m², `k_0`
/// `(2π F0)²` N·m/rad, `Fv = 2ζ√(k_0 J)`.
pub fn plant() -> Plant {
    let k0 = (2.0 * std::f64::consts::PI * F0_HZ).powi(2);
    Plant {
        kind: Structure::Grounded,
        params: JointParams {
            j_m: 1.0,
            j_a1: 0.0,
            j_a2: 0.0,
            r: 1.0,
            k_0: k0,
            f_m: 2.0 * ZETA * k0.sqrt(),
            ..JointParams::default()
        },
    }
}

/// Estimation record (four periods of an odd multisine up to 200 Hz, unit RMS force) and
/// validation record (as long, smoothed white noise at 1.2 times that RMS) of the grounded
/// mass with a cubic spring `k3` [N·m/rad³], the position's noise 0.1 % of its RMS.
pub fn records(k3: f64, seed: u64) -> (Dataset, Dataset) {
    records_driven(k3, seed, 1)
}

/// [`records`] with a force that moves between its samples as a measured analog input
/// does (`sub` > 1): a band-limited signal, the mass simulated on `sub` steps per sample
/// interval and its position sampled at [`FS_HZ`]; the validation force then another
/// realisation of the estimation multisine (random phases, 1.2 times its RMS), each
/// evaluated between the samples as the sum of its sines. `sub` = 1: the force held over
/// each interval, as [`records`].
pub fn records_driven(k3: f64, seed: u64, sub: usize) -> (Dataset, Dataset) {
    let mut g = Gauss::new(seed);
    let lines: Vec<usize> = (1..(200.0 * PERIOD as f64 / FS_HZ) as usize)
        .filter(|l| l % 2 == 1)
        .collect();
    let mut phases = || -> Vec<f64> {
        lines
            .iter()
            .map(|_| 2.0 * std::f64::consts::PI * g.uniform())
            .collect()
    };
    let est_phases = phases();
    let sub = sub.max(1);
    // four periods of the multisine of `phases`, scaled to `rms` on its samples: the
    // samples, and the force the simulation holds over each fine step (1/`sub` sample),
    // the signal at the step's midpoint (no delay; `sub` = 1: the samples, held)
    let multisine = |phases: &[f64], rms: f64| -> (Vec<f64>, Vec<f64>) {
        let at = |t: f64| -> f64 {
            lines
                .iter()
                .zip(phases)
                .map(|(&l, p)| (2.0 * std::f64::consts::PI * l as f64 * t + p).cos())
                .sum()
        };
        let samples: Vec<f64> = (0..PERIOD).map(|k| at(k as f64 / PERIOD as f64)).collect();
        let (mean, scale) = (
            samples.iter().sum::<f64>() / PERIOD as f64,
            rms / rms_about_mean(&samples),
        );
        let fine: Vec<f64> = if sub == 1 {
            samples.clone()
        } else {
            (0..sub * PERIOD)
                .map(|i| at((i as f64 + 0.5) / (sub * PERIOD) as f64))
                .collect()
        };
        let four = |x: Vec<f64>, n: usize| -> Vec<f64> {
            x.iter()
                .cycle()
                .take(4 * n)
                .map(|v| (v - mean) * scale)
                .collect()
        };
        (four(samples, PERIOD), four(fine, sub * PERIOD))
    };
    let est = multisine(&est_phases, 1.0);
    let val = if sub > 1 {
        let p = phases();
        multisine(&p, 1.2)
    } else {
        let white: Vec<f64> = (0..4 * PERIOD + 2).map(|_| g.next()).collect();
        let mut v: Vec<f64> = white
            .windows(3)
            .map(|w| w.iter().sum::<f64>() / 3.0)
            .collect();
        normalise(&mut v, 1.2);
        (v.clone(), v)
    };
    let effects = [Effect::NonlinearStiffness(NonlinearStiffness { k3 })];
    let ts = 1.0 / FS_HZ;
    let mut run = |name: &str, (u, fine): (Vec<f64>, Vec<f64>)| {
        let step = ts / sub as f64;
        let out = simulate_driven(
            &plant(),
            &effects,
            1e-6,
            step,
            &fine,
            &DrivenStart::default(),
        )
        .expect("the grounded mass simulates");
        let theta: Vec<f64> = out.theta_m.iter().step_by(sub).copied().collect();
        let rms = (theta.iter().map(|y| y * y).sum::<f64>() / u.len() as f64).sqrt();
        let y: Vec<f64> = theta.iter().map(|y| y + 1e-3 * rms * g.next()).collect();
        Dataset {
            name: name.to_string(),
            data: IdData { ts, u, y, r: None },
            t0: 0.0,
            excitation: None,
            meta: Default::default(),
        }
    };
    let est = run("grounded-est", est);
    let val = run("grounded-val", val);
    (est, val)
}

/// The cubic coefficient at which the cubic spring's torque reaches `share` of the linear
/// one at three times the position RMS of the linear mass under [`records`]' estimation
/// force [N·m/rad³].
pub fn k3_at(share: f64) -> f64 {
    let (est, _) = records(0.0, 1);
    share * plant().params.k_0 / (3.0 * rms_about_mean(&est.data.y)).powi(2)
}

/// Scales `x` to zero mean and RMS `rms`.
fn normalise(x: &mut [f64], rms: f64) {
    let mean = x.iter().sum::<f64>() / x.len().max(1) as f64;
    let sd = rms_about_mean(x);
    for v in x.iter_mut() {
        *v = (*v - mean) * rms / sd;
    }
}
