//! The σ calibration of the frequency-domain fit ([`crate::ident::sml`]): repeated noise
//! realisations of a simulated joint, the spread of the estimates against the σ the fit
//! reports. Shared by the library's test (three-mass, 30 runs) and the `sigma` bench
//! (every structure).

use crate::data::{Dataset, ExcitationConfig};
use crate::ident::frf::{analyze_dataset, Frf};
use crate::ident::linalg::GaussRng;
use crate::ident::sml::{fit_frf, FrfFitOptions};
use crate::model::spec::Structure;
use crate::sim::{simulate_excitation, JointParams, Plant, SimConfig};

/// excitation of `jointid simulate` with `periods` full periods
pub fn excitation(periods: u32, rms: f32) -> ExcitationConfig {
    let mut e = ExcitationConfig::paper_default();
    e.periods = periods;
    e.rms_rad = rms;
    e
}

/// The true values of `s`'s parameters (in [`Structure::param_names`] order) of the
/// simulator's joint `p`.
pub fn truth(p: &JointParams, s: Structure) -> Vec<f64> {
    let all = [
        ("J_m", p.j_m),
        ("J_a1", p.j_a1),
        ("J_a2", p.j_a2),
        ("J_p", p.j_p),
        ("k_g", p.k_g),
        ("k_a", p.k_a),
        ("k_p", p.k_p),
        ("d_g", p.d_g),
        ("d_a", p.d_a),
        ("d_p", p.d_p),
        ("f_m", p.f_m),
    ];
    s.param_names()
        .iter()
        .map(|n| {
            if s == Structure::TwoMass && *n == "J_a1" {
                // the simulator's two-mass arm is J_a1 + J_a2
                p.j_a1 + p.j_a2
            } else {
                all.iter().find(|(m, _)| m == n).unwrap().1
            }
        })
        .collect()
}

/// noise conditions of the σ calibration
#[derive(Clone, Copy, Debug)]
pub enum Noise {
    /// the simulator's default sensors
    Default,
    /// default, plus coloured noise in the band: the disturbance's low-pass
    /// at 30 Hz, and AR(1) noise (pole 0.95) added to the measured angle
    Coloured,
    /// default with the slow disturbance ten times stronger
    Disturbance10,
}

/// FRF of one run of `structure`'s default joint under `noise`
pub fn noisy_frf(
    structure: Structure,
    noise: Noise,
    seed: u64,
    periods: u32,
) -> (Frf, JointParams) {
    let mut cfg = SimConfig {
        plant: Plant::new(structure),
        seed,
        ..SimConfig::default()
    };
    match noise {
        Noise::Default => {}
        Noise::Coloured => cfg.sensors.disturbance.noise_cutoff_hz = 30.0,
        Noise::Disturbance10 => cfg.sensors.disturbance.noise_std *= 10.0,
    }
    let exc = excitation(periods, 0.02);
    let out = simulate_excitation(&cfg, &exc).expect("simulation");
    let mut data = out.to_id_data();
    if let Noise::Coloured = noise {
        let mut rng = GaussRng::new(seed ^ 0xC0102ED);
        let (a, sd) = (0.95, 1e-5);
        let b = sd * (1.0f64 - a * a).sqrt();
        let mut e = 0.0;
        for y in &mut data.y {
            e = a * e + b * rng.normal();
            *y += e;
        }
    }
    let ds = Dataset {
        name: "sim".into(),
        data,
        t0: 0.0,
        excitation: Some(exc),
        meta: Default::default(),
    };
    (analyze_dataset(&ds, 1).expect("frf").frf, cfg.plant.params)
}

/// One parameter's calibration over repeated noise realisations.
pub struct Calibration {
    /// parameter name (and `lag`)
    pub name: String,
    /// spread of ln p over the runs / median reported σ(ln p)
    pub ratio: f64,
    /// share of runs within 3 σ of the truth
    pub within: f64,
    /// RMS over the runs of the standardised error (ln p − ln p₀)/σ(ln p): 1
    /// for honest σ, also where σ changes from run to run
    pub z_rms: f64,
}

/// Per parameter (and the lag), its [`Calibration`] over `runs` noise realisations of
/// `periods` periods; `each_run` gets a line with each run's errors and σ.
pub fn sigma_calibration(
    structure: Structure,
    noise: Noise,
    runs: u64,
    periods: u32,
    mut each_run: impl FnMut(String),
) -> Vec<Calibration> {
    let mut vals: Vec<Vec<f64>> = Vec::new();
    let mut stds: Vec<Vec<f64>> = Vec::new();
    let mut within: Vec<usize> = Vec::new();
    let mut z2: Vec<f64> = Vec::new();
    let mut names: Vec<String> = Vec::new();
    for seed in 0..runs {
        let (frf, p) = noisy_frf(structure, noise, 900 + seed, periods);
        let fit = fit_frf(&frf, &FrfFitOptions::new(structure, 5e-4)).unwrap();
        let mut t = truth(&p, structure);
        t.push(1.0); // the simulator's lag: 0.5 ms = 1 sample
        let mut v: Vec<f64> = fit.params.iter().map(|q| q.value.ln()).collect();
        let mut s: Vec<f64> = fit.params.iter().map(|q| q.std / q.value).collect();
        let lag = fit.lag;
        v.push(lag.value.max(1e-9).ln());
        s.push(lag.std / lag.value.max(1e-9));
        if names.is_empty() {
            names = fit.params.iter().map(|q| q.name.clone()).collect();
            names.push("lag".into());
            within = vec![0; names.len()];
            z2 = vec![0.0; names.len()];
        }
        for (i, w) in within.iter_mut().enumerate() {
            if (v[i] - t[i].ln()).abs() <= 3.0 * s[i] {
                *w += 1;
            }
            z2[i] += ((v[i] - t[i].ln()) / s[i]).powi(2);
        }
        let errs: Vec<String> = (0..v.len())
            .map(|i| format!("{:+.1}", 100.0 * (v[i] - t[i].ln())))
            .collect();
        each_run(format!(
            "  seed {seed}: log errors [%] {} σ [%] {} delay {:.2} cost {:.3e} warnings {:?}",
            errs.join(" "),
            s.iter()
                .map(|x| format!("{:.2}", 100.0 * x))
                .collect::<Vec<_>>()
                .join(" "),
            fit.delay.value,
            fit.cost,
            fit.warnings
        ));
        vals.push(v);
        stds.push(s);
    }
    let n = runs as f64;
    (0..names.len())
        .map(|i| {
            let m = vals.iter().map(|v| v[i]).sum::<f64>() / n;
            let spread = (vals.iter().map(|v| (v[i] - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
            let mut s: Vec<f64> = stds.iter().map(|s| s[i]).collect();
            s.sort_by(f64::total_cmp);
            let med = s[s.len() / 2];
            Calibration {
                name: names[i].clone(),
                ratio: spread / med,
                within: within[i] as f64 / n,
                z_rms: (z2[i] / n).sqrt(),
            }
        })
        .collect()
}

/// `name ratio/z_rms/within%` for each parameter.
pub fn table_row(t: &[Calibration]) -> String {
    t.iter()
        .map(|c| {
            format!(
                "{} {:.2}/{:.2}/{:.0}%",
                c.name,
                c.ratio,
                c.z_rms,
                100.0 * c.within
            )
        })
        .collect::<Vec<_>>()
        .join("  ")
}
