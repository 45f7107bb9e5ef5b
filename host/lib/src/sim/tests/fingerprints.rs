//! Simulator tests: the spectral fingerprint of each effect.

use super::*;

const N: usize = 2000;
const F_MAX: usize = 120;
const DEFAULT_RMS: f64 = 0.02;
const LARGE_RMS: f64 = 0.08;

/// Power at the non-excited odd lines relative to the excited lines, `(θ_m, u)`, from the
/// mean of the last two of four periods of a special odd multisine.
fn odd_distortion(effects: Vec<Effect>, rms: f64, sensors: SensorConfig) -> (f64, f64) {
    let r = multisine(N, &special_odd_lines(F_MAX), rms, 6, 7);
    let cfg = SimConfig {
        sensors,
        ..ideal(Plant::default(), effects)
    };
    let out = simulate(&cfg, &r).unwrap();
    let th = mean_period(&out.theta_m, N, 4);
    let u = mean_period(&out.u, N, 4);
    let (exc, non) = (special_odd_lines(F_MAX), odd_non_excited_lines(F_MAX));
    (
        power(&th, &non) / power(&th, &exc),
        power(&u, &non) / power(&u, &exc),
    )
}

/// Checks visibility at the default amplitude with default sensors (10× the no-effect floor)
/// and returns the ideal-sensor distortion at the default and the large amplitude.
fn fingerprint(effect: Effect) -> ((f64, f64), (f64, f64)) {
    let floor = odd_distortion(vec![], DEFAULT_RMS, SensorConfig::default());
    let seen = odd_distortion(vec![effect], DEFAULT_RMS, SensorConfig::default());
    assert!(
        seen.0 > 10.0 * floor.0 && seen.1 > 10.0 * floor.1,
        "{}: {seen:?} vs floor {floor:?}",
        effect.name()
    );
    let small = odd_distortion(vec![effect], DEFAULT_RMS, SensorConfig::ideal());
    let large = odd_distortion(vec![effect], LARGE_RMS, SensorConfig::ideal());
    (small, large)
}

#[test]
fn backlash_raises_odd_lines_more_at_small_amplitude() {
    let (small, large) = fingerprint(Effect::Backlash(Backlash::default()));
    assert!(
        small.0 > 2.0 * large.0 && small.1 > 2.0 * large.1,
        "{small:?} {large:?}"
    );
}

#[test]
fn coulomb_friction_raises_odd_lines_more_at_small_amplitude() {
    let (small, large) = fingerprint(Effect::CoulombFriction(CoulombFriction::default()));
    assert!(
        small.0 > 2.0 * large.0 && small.1 > 2.0 * large.1,
        "{small:?} {large:?}"
    );
}

#[test]
fn cubic_spring_raises_odd_lines_more_at_large_amplitude() {
    let (small, large) = fingerprint(Effect::NonlinearStiffness(NonlinearStiffness::default()));
    assert!(
        large.0 > 2.0 * small.0 && large.1 > 2.0 * small.1,
        "{small:?} {large:?}"
    );
}

#[test]
fn linear_plant_leaves_non_excited_lines_empty() {
    let (th, u) = odd_distortion(vec![], DEFAULT_RMS, SensorConfig::ideal());
    assert!(th < 1e-12 && u < 1e-12, "{th:e} {u:e}");
}

/// FRF `u → θ_m` at lines `1..=F_MAX` of a full multisine (all lines excited), steady state;
/// noise-free, so the ratio of the period spectra is the plant FRF.
fn frf(effects: Vec<Effect>) -> Vec<Complex<f64>> {
    let lines: Vec<usize> = (1..=F_MAX).collect();
    let r = multisine(N, &lines, DEFAULT_RMS, 5, 12);
    let out = simulate(&ideal(Plant::default(), effects), &r).unwrap();
    let th = mean_period(&out.theta_m, N, 1);
    let u = mean_period(&out.u, N, 1);
    lines.iter().map(|&k| dft(&th, k) / dft(&u, k)).collect()
}

#[test]
fn time_delay_bends_the_frf_phase_linearly_with_frequency() {
    let d = TimeDelay::default();
    let g0 = frf(vec![]);
    let gd = frf(vec![Effect::TimeDelay(d)]);
    let expected_slope = -2.0 * PI * d.samples * TS; // rad per Hz
    let (mut sxy, mut sxx) = (0.0, 0.0);
    let mut resid = Vec::new();
    for (i, (a, b)) in g0.iter().zip(&gd).enumerate() {
        let f = (i + 1) as f64 * FS / N as f64;
        let dphi = (b / a).arg();
        sxy += f * dphi;
        sxx += f * f;
        resid.push((dphi - expected_slope * f).abs());
        // the magnitude is untouched by a pure delay
        assert!((b.norm() / a.norm() - 1.0).abs() < 1e-3, "{f} Hz");
    }
    let slope = sxy / sxx;
    assert!(
        (slope / expected_slope - 1.0).abs() < 0.01,
        "slope {slope} vs {expected_slope}"
    );
    let worst = resid.iter().fold(0.0f64, |a, &b| a.max(b));
    assert!(worst < 0.01, "phase residual {worst} rad");
}

#[test]
fn extra_mode_adds_a_resonance_peak_where_there_was_none() {
    let x = ExtraMode::default();
    let before = Mechanism::new(&Plant::default(), &[]).modal_frequencies();
    let after = Mechanism::new(&Plant::default(), &[Effect::ExtraMode(x)]).modal_frequencies();
    assert_eq!(after.resonances_hz.len(), before.resonances_hz.len() + 1);
    // the new resonance: the one farthest from every old one
    let distance = |f: f64| {
        before
            .resonances_hz
            .iter()
            .map(|g| (f - g).abs())
            .fold(f64::INFINITY, f64::min)
    };
    let f_new = after
        .resonances_hz
        .iter()
        .copied()
        .max_by(|a, b| distance(*a).total_cmp(&distance(*b)))
        .unwrap();
    assert!(distance(f_new) > 5.0, "{after:?}");
    let g0 = frf(vec![]);
    let gx = frf(vec![Effect::ExtraMode(x)]);
    // compensate the double integrator: |G| ω² is flat for a rigid body
    let shaped = |g: &[Complex<f64>]| -> Vec<f64> {
        g.iter()
            .enumerate()
            .map(|(i, v)| v.norm() * ((i + 1) as f64).powi(2))
            .collect()
    };
    let (s0, sx) = (shaped(&g0), shaped(&gx));
    let is_peak = |s: &[f64], i: usize| s[i] > s[i - 1] && s[i] > s[i + 1];
    // line i is (i + 1) Hz
    let ip = (1..F_MAX - 1)
        .filter(|&i| ((i + 1) as f64 - f_new).abs() <= 1.5)
        .find(|&i| is_peak(&sx, i));
    let Some(ip) = ip else {
        panic!("no peak near {f_new} Hz: {:?}", &sx[..30])
    };
    assert!(
        (ip - 5..=ip + 5).all(|i| !is_peak(&s0, i)),
        "{:?}",
        &s0[..30]
    );
    assert!(sx[ip] > 2.0 * s0[ip], "peak {} vs {}", sx[ip], s0[ip]);
}

#[test]
fn torque_ripple_puts_energy_on_even_lines() {
    // sin(n θ + φ) with φ ≠ 0 is not an odd function of the motion: even harmonics appear
    let even: Vec<usize> = (1..=F_MAX / 2).map(|k| 2 * k).collect();
    let even_ratio = |effects: Vec<Effect>, sensors: SensorConfig| {
        let r = multisine(N, &special_odd_lines(F_MAX), DEFAULT_RMS, 6, 7);
        let out = simulate(
            &SimConfig {
                sensors,
                ..ideal(Plant::default(), effects)
            },
            &r,
        )
        .unwrap();
        let u = mean_period(&out.u, N, 4);
        power(&u, &even) / power(&u, &special_odd_lines(F_MAX))
    };
    let floor = even_ratio(vec![], SensorConfig::default());
    let seen = even_ratio(
        vec![Effect::TorqueRipple(TorqueRipple::default())],
        SensorConfig::default(),
    );
    assert!(seen > 10.0 * floor, "even lines {seen:e}, floor {floor:e}");
}
