//! Fixtures shared by the tests of several modules and crates (the command line's tests
//! use them too): signals and captures with a known truth. Not part of the
//! identification API; nothing here does IO.
//!
//! [`synth`]: board streams with known frame spans, for the capture path's tests and
//! benchmarks; the rest of this module: a closed loop around a lightly damped
//! resonance and its capture CSV, for the FRF's tests and the `analyze` command's.

use std::f64::consts::PI;

use jointid_core::excitation::{ExcitationConfig, SignalKind};
use rustfft::num_complex::Complex64;

use crate::data::IdData;

pub mod battery;
pub mod grounded;
pub mod sigma;
pub mod synth;
pub mod two_mass;

/// xorshift64* with Box–Muller: reproducible Gaussian noise for tests
pub struct Gauss(u64);

impl Gauss {
    /// the generator for `seed`
    pub fn new(seed: u64) -> Self {
        Gauss(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    /// uniform on (0, 1)
    pub fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        ((self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    /// standard normal
    #[allow(clippy::should_implement_trait)]
    pub fn next(&mut self) -> f64 {
        let (a, b) = (self.uniform(), self.uniform());
        (-2.0 * a.ln()).sqrt() * (2.0 * PI * b).cos()
    }
}

/// discrete plant P(q) = b1 q^-1 / (1 + a1 q^-1 + a2 q^-2) (lightly
/// damped resonance) under proportional feedback u = kp (r − y_meas);
/// `cubic` adds kp·c·e³ to the controller output; y_meas = y + v
pub struct Loop {
    /// `a1` of the denominator
    pub a1: f64,
    /// `a2` of the denominator
    pub a2: f64,
    /// `b1` of the numerator
    pub b1: f64,
    /// proportional gain of the controller
    pub kp: f64,
}

impl Loop {
    /// the plant's frequency response at `z`
    pub fn plant(&self, z: Complex64) -> Complex64 {
        let zi = z.inv();
        self.b1 * zi / (1.0 + self.a1 * zi + self.a2 * zi * zi)
    }

    /// closed-loop run on reference `r` with measurement noise of `noise_sd` and a cubic
    /// controller term `cubic`
    pub fn run(&self, r: &[f64], noise_sd: f64, cubic: f64, seed: u64) -> IdData {
        self.run_with(r, noise_sd, |e| e + cubic * e * e * e, seed)
    }

    /// controller u = kp · f(e)
    pub fn run_with(&self, r: &[f64], noise_sd: f64, f: impl Fn(f64) -> f64, seed: u64) -> IdData {
        let mut g = Gauss::new(seed);
        let (mut y1, mut y2, mut u1) = (0.0, 0.0, 0.0);
        let (mut u, mut y) = (Vec::new(), Vec::new());
        for &rk in r {
            let yk = -self.a1 * y1 - self.a2 * y2 + self.b1 * u1;
            let ym = yk + noise_sd * g.next();
            let e = rk - ym;
            let uk = self.kp * f(e);
            u.push(uk);
            y.push(ym);
            y2 = y1;
            y1 = yk;
            u1 = uk;
        }
        IdData {
            ts: 1e-3,
            u,
            y,
            r: Some(r.to_vec()),
        }
    }
}

/// the loop around a lightly damped resonance of the FRF tests
pub fn plant() -> Loop {
    // poles at 0.97 e^{±j 0.2}: resonance near 32 Hz at 1 kHz
    let (rho, th): (f64, f64) = (0.97, 0.2);
    Loop {
        a1: -2.0 * rho * th.cos(),
        a2: rho * rho,
        b1: 0.05,
        kp: 0.5,
    }
}

/// capture CSV text with the `# key=value` contract, reference from the
/// core generator, closed loop around [`plant`]
pub fn capture_csv(cubic: f64, seed: u64) -> String {
    let c = ExcitationConfig {
        kind: SignalKind::SpecialOddMultisine,
        fs_hz: 1000,
        period_samples: 500,
        max_line: 120,
        cutoff_hz: 50.0,
        rms_rad: 0.5,
        seed: 9,
        ramp_samples: 300,
        periods: 6,
    };
    let r: Vec<f64> = jointid_core::excitation::generate(&c)
        .unwrap()
        .into_iter()
        .map(f64::from)
        .collect();
    let d = plant().run(&r, 0.002, cubic, seed);
    let mut text = crate::data::excitation_comment_lines(&c);
    text.push_str("# sample_interval_s=0.001\nt,theta_ref,u,theta_m\n");
    for (k, ((rk, uk), yk)) in r.iter().zip(&d.u).zip(&d.y).enumerate() {
        text.push_str(&format!("{},{rk},{uk},{yk}\n", k as f64 * 1e-3));
    }
    text
}

/// The battery's three controller tunings: the default PI velocity loop; a softer one; a
/// stiffer P loop (no integrator) with a faster current loop.
pub fn bench_tunings() -> [crate::sim::ControllerConfig; 3] {
    use crate::sim::ControllerConfig;
    [
        ControllerConfig::default(),
        ControllerConfig {
            kp: 10.0,
            kv: 0.1,
            ti: 0.1,
            ..ControllerConfig::default()
        },
        ControllerConfig {
            kp: 30.0,
            kv: 0.35,
            ti: f64::INFINITY,
            current_loop_tau: 2.5e-4,
            ..ControllerConfig::default()
        },
    ]
}

/// One closed-loop joint of the robustness draws (the `fd_robustness` bench and
/// the frequency-domain fit's tests): the default joint's eight three-mass
/// parameters each scaled by U(0.7, 1.3), the controller tuning
/// [`bench_tunings`]`[index % 3]`, torque limit lifted, and a reference RMS
/// log-uniform in 0.01–0.4 rad.
pub fn random_joint(
    rng: &mut crate::ident::linalg::GaussRng,
    index: usize,
) -> (crate::sim::JointParams, crate::sim::ControllerConfig, f64) {
    use crate::sim::JointParams;
    let tunings = bench_tunings();
    let mut p = JointParams::default();
    for v in p.three_mass_values_mut() {
        *v *= 1.0 + 0.3 * (2.0 * rng.uniform() - 1.0);
    }
    let rms = 0.01 * 40f64.powf(rng.uniform());
    let mut controller = tunings[index % 3];
    controller.u_max = 1e3;
    (p, controller, rms)
}

/// `shared/data/<path>`: the first ancestor of this crate that holds `shared/data` (the
/// repository sits beside `shared/`, the reference data the tests and benches read).
///
/// # Panics
/// When no ancestor holds `shared/data`.
pub fn shared_data(path: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .map(|a| a.join("shared/data"))
        .find(|d| d.is_dir())
        .expect("shared/data beside the repository")
        .join(path)
}

/// The text of `shared/data/<path>` ([`shared_data`]).
///
/// # Panics
/// When the file cannot be read.
pub fn read_shared(path: &str) -> String {
    let p = shared_data(path);
    std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// An estimation and a validation capture of `cfg` driven by `exc` (`exc` as given, and
/// other excitation phases), with noise seeds `seed` and `seed + 1000`: the two records
/// `jointid diagnose` is given.
///
/// # Panics
/// When the simulation fails.
pub fn est_val_captures(
    cfg: &crate::sim::SimConfig,
    exc: &ExcitationConfig,
    seed: u64,
) -> (crate::data::Dataset, crate::data::Dataset) {
    est_val_captures_with(cfg, exc, seed, exc.kind)
}

/// As [`est_val_captures`], the validation capture driven by the signal `val_kind` (a
/// band-limited noise excites every line: no non-excited line is left to read distortion
/// at).
///
/// # Panics
/// When the simulation fails.
pub fn est_val_captures_with(
    cfg: &crate::sim::SimConfig,
    exc: &ExcitationConfig,
    seed: u64,
    val_kind: SignalKind,
) -> (crate::data::Dataset, crate::data::Dataset) {
    let run = |seed: u64, exc: ExcitationConfig, name: &str| {
        let cfg = crate::sim::SimConfig {
            seed,
            ..cfg.clone()
        };
        let out = crate::sim::simulate_excitation(&cfg, &exc).expect("simulation");
        crate::data::Dataset {
            name: name.into(),
            data: out.to_id_data(),
            t0: 0.0,
            excitation: Some(exc),
            meta: Default::default(),
        }
    };
    let val_exc = ExcitationConfig {
        seed: exc.seed ^ 0x5A5A_1234,
        kind: val_kind,
        ..*exc
    };
    (run(seed, *exc, "est"), run(seed + 1000, val_exc, "val"))
}

/// `ds` as the reader returns it when the samples `gap` were lost on the way (a serial
/// unplug): a [`crate::data::Record`] of the piece before the gap and the piece after it,
/// each placed on the excitation's time line by its `t0`. The joint kept running, so the
/// second piece starts in the state the first one left at `gap.end`.
///
/// # Panics
/// When `gap` is empty or does not lie inside the record.
pub fn with_gap(ds: &crate::data::Dataset, gap: std::ops::Range<usize>) -> crate::data::Record {
    let n = ds.data.len();
    assert!(
        0 < gap.start && gap.start < gap.end && gap.end < n,
        "gap {gap:?} inside 0..{n}"
    );
    let piece = |range: std::ops::Range<usize>| crate::data::Dataset {
        t0: ds.t0 + range.start as f64 * ds.data.ts,
        data: ds.data.slice(range),
        ..ds.clone()
    };
    crate::data::Record {
        pieces: vec![piece(0..gap.start), piece(gap.end..n)],
        notes: Vec::new(),
    }
}

/// The three-mass nonlinear model of `cfg`'s joint with `effect` (coarse smoothing,
/// `substeps` RK4 steps per sample, `cfg`'s current-loop lag) and its true values in
/// layout order (offset and initial velocity 0).
pub fn three_mass_truth(
    cfg: &crate::sim::SimConfig,
    effect: crate::model::effects::Effect,
    substeps: usize,
) -> (crate::ident::nonlinear::NlModel, Vec<f64>) {
    let p = cfg.plant.params;
    let model = crate::ident::nonlinear::NlModel {
        structure: crate::model::spec::Structure::ThreeMass,
        r: p.r,
        effects: vec![effect],
        tau_c: cfg.controller.current_loop_tau,
        v_eps: 0.05,
        dz_eps: 1e-7,
        substeps,
    };
    let plant = [p.j_m, p.j_a1, p.j_a2, p.k_g, p.k_a, p.d_g, p.d_a, p.f_m];
    let truth = model.values(&plant, 0.0, 0.0);
    (model, truth)
}

/// A start moved off `truth`: +20 % and −15 % in turn.
pub fn perturbed_start(truth: &[f64]) -> Vec<f64> {
    truth
        .iter()
        .enumerate()
        .map(|(i, &t)| if i % 2 == 0 { t * 1.2 } else { t * 0.85 })
        .collect()
}

/// A fit of `model` as the engine returns one, at the structure's values `plant` and an
/// offset of 1 mN·m, made by hand: each parameter's σ 1 % of its value, none on a bound,
/// converged in 3 iterations at a velocity FIT of 96 %.
pub fn nl_fit(
    model: crate::ident::nonlinear::NlModel,
    plant: Vec<f64>,
) -> crate::ident::nonlinear::NlFit {
    use crate::ident::nonlinear::{NlFit, NlParam};
    let values = model.values(&plant, 1e-3, 0.0);
    let params = model
        .layout()
        .iter()
        .zip(&values)
        .map(|(d, &value)| NlParam {
            name: d.name,
            owner: d.owner,
            value,
            std: 0.01 * value.abs(),
            unit: d.unit,
            fixed: false,
            at_bound: false,
            at_lower: false,
        })
        .collect();
    NlFit {
        model,
        plant,
        params,
        values,
        ssr: 1.0,
        lowpass_hz: 0.0,
        n_residuals: 10,
        iterations: 3,
        termination: crate::ident::lm::Termination::CostConverged,
        fit_velocity_percent: 96.0,
        correlated: Vec::new(),
    }
}
