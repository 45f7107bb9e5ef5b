//! A capture with a gap fitted with every gap-free segment (issue 13 item 2): the
//! time-domain fit takes the segments as separate experiments
//! ([`super::fit_prepared_segments`]), the frequency-domain fit the FRF averaged over their
//! whole periods ([`crate::ident::frf::analyze_segments`]); both reach the truth at least
//! as closely as the longest segment alone.

use super::*;
use crate::data::SegmentChoice;
use crate::data::{Dataset, Detrend, Selection};
use crate::ident::frf::{analyze_dataset, analyze_segments};
use crate::sim::{simulate_excitation, SimConfig};
use crate::test_support::{with_gap, Gauss};
use jointid_core::excitation::ExcitationConfig;

/// RMS of the relative errors [-] of `names` in `params` against `truth` (same order).
fn rms_error(params: &[PhysParam], names: &[&str], truth: &[f64]) -> f64 {
    let s: f64 = names
        .iter()
        .zip(truth)
        .map(|(n, t)| {
            let v = params.iter().find(|p| p.name == *n).expect(n).value;
            (v / t - 1.0).powi(2)
        })
        .sum();
    (s / names.len() as f64).sqrt()
}

/// The pieces of `record` that `--segment all` selects.
fn all_segments(record: &crate::data::Record) -> Vec<Dataset> {
    record
        .select(&Selection {
            segment: Some(SegmentChoice::All),
            ..Selection::default()
        })
        .unwrap()
        .datasets
}

/// Open-loop two-mass at 2 kHz (resonance near 32 Hz) driven by white torque, the angle
/// measured with white noise (1 % of its spread); 14,000 samples of which 5,000..7,000 are
/// lost: the pieces before and after the gap, and the truth.
fn gapped_two_mass(seed: u64) -> (Vec<FitData>, [f64; 5]) {
    let ts = 5e-4;
    let r2 = grey_box::DEFAULT_GEAR_RATIO.powi(2);
    let truth = [1e-3, 1e-3 / r2, 20.0 / r2, 0.004 / r2, 2e-2];
    let gm = DrivenModel {
        mechanics: grey_box::GreyBoxModel {
            structure: Structure::TwoMass,
            output: Output::Angle,
            r: grey_box::DEFAULT_GEAR_RATIO,
            ts,
        },
        current_loop_tau: 0.0,
    };
    let th: Vec<f64> = truth.iter().map(|v| v.ln()).collect();
    let m = gm.to_ss(&th);
    let mut rng = Gauss::new(seed);
    let n = 14_000;
    let u: Vec<f64> = (0..n).map(|_| 0.05 * rng.next()).collect();
    let y0 = m.simulate(&u, None);
    let sd = {
        let mean = y0.iter().sum::<f64>() / n as f64;
        (y0.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64).sqrt()
    };
    let y: Vec<f64> = y0.iter().map(|v| v + 0.01 * sd * rng.next()).collect();
    let ds = Dataset {
        name: "gapped".into(),
        data: IdData { ts, u, y, r: None },
        t0: 0.0,
        excitation: None,
        meta: Default::default(),
    };
    let segs = all_segments(&with_gap(&ds, 5_000..7_000));
    assert_eq!(segs.len(), 2);
    let prep = Prep {
        decimate: 1,
        detrend: Detrend::None,
    };
    let data = segs
        .iter()
        .map(|d| FitData::new(&d.data, prep).unwrap())
        .collect();
    (data, truth)
}

#[test]
fn time_domain_fit_takes_the_segments_as_separate_experiments() {
    let names = Structure::TwoMass.param_names();
    let opts = FitOptions {
        spec: ModelSpec::linear(Family::Physical(Structure::TwoMass)),
        ..FitOptions::default()
    };
    // over four noise realisations: every parameter within 3 % and 3 σ, its σ below the
    // longest piece's, and the mean squared relative error no larger
    let (mut e_all, mut e_long) = (0.0, 0.0);
    for seed in 21..25 {
        let (data, truth) = gapped_two_mass(seed);
        let all = fit_prepared_segments(&data, &opts).unwrap();
        let longest = fit_prepared(&data[1], &opts).unwrap();
        assert!(
            all.method.contains("2 records as separate experiments"),
            "{}",
            all.method
        );
        for (i, name) in names.iter().enumerate() {
            let p = all.params.iter().find(|p| p.name == *name).unwrap();
            let q = longest.params.iter().find(|p| p.name == *name).unwrap();
            assert!(
                (p.value / truth[i] - 1.0).abs() < 0.03 && (p.value - truth[i]).abs() < 3.0 * p.std,
                "seed {seed}: {name} = {:.5e} ± {:.1e}, truth {:.5e}",
                p.value,
                p.std,
                truth[i]
            );
            // 12,000 samples against 7,000: the reported σ shrinks with the data
            assert!(
                p.std < q.std,
                "{name}: σ {:.2e} over all, {:.2e} longest",
                p.std,
                q.std
            );
        }
        e_all += rms_error(&all.params, names, &truth).powi(2);
        e_long += rms_error(&longest.params, names, &truth).powi(2);
        // the pooled FIT and each segment's, each with its own initial state
        let (v, each) = all.evaluate_segments(&data, 20).unwrap();
        assert_eq!(each.len(), 2);
        assert!(
            v.fit > 95.0 && each.iter().all(|f| *f > 95.0),
            "{} {each:?}",
            v.fit
        );
    }
    let (e_all, e_long) = ((e_all / 4.0).sqrt(), (e_long / 4.0).sqrt());
    eprintln!("RMS relative error: {e_all:.2e} over all segments, {e_long:.2e} longest alone");
    assert!(
        e_all <= e_long,
        "RMS relative error {e_all:.2e} over all segments, {e_long:.2e} longest alone"
    );
}

#[test]
fn frequency_domain_fit_averages_the_frf_over_the_segments() {
    // the default three-mass joint, default sensors, 8 periods; 3,000 samples lost in the
    // fifth period
    let exc = ExcitationConfig {
        periods: 8,
        ..ExcitationConfig::paper_default()
    };
    let cfg = SimConfig {
        seed: 4,
        ..SimConfig::default()
    };
    let out = simulate_excitation(&cfg, &exc).unwrap();
    let ds = Dataset {
        name: "gapped".into(),
        data: out.to_id_data(),
        t0: 0.0,
        excitation: Some(exc),
        meta: Default::default(),
    };
    let start = exc.ramp_samples as usize + 4 * exc.period_samples as usize + 1_000;
    let segs = all_segments(&with_gap(&ds, start..start + 3_000));
    assert_eq!(segs.len(), 2);
    let ts = ds.data.ts;
    let opts = FitOptions {
        spec: ModelSpec::linear(Family::Physical(Structure::ThreeMass)),
        ..FitOptions::default()
    };
    let pooled = analyze_segments(&segs, 1).unwrap();
    let own = analyze_dataset(&segs[0], 1).unwrap();
    assert!(
        pooled.layout.count > own.layout.count,
        "{:?} {:?}",
        pooled.layout,
        own.layout
    );
    let all = fit_frequency_domain(&pooled, ts, &opts, 1).unwrap();
    let longest = fit_frequency_domain(&own, ts, &opts, 1).unwrap();
    let p = cfg.plant.params;
    let names = ["J_m", "J_a1", "J_a2", "k_g", "k_a", "d_g", "d_a"];
    let truth = [p.j_m, p.j_a1, p.j_a2, p.k_g, p.k_a, p.d_g, p.d_a];
    for (name, t) in names.iter().zip(&truth) {
        let v = all.params.iter().find(|q| q.name == *name).unwrap().value;
        assert!(
            (v / t - 1.0).abs() < 0.03,
            "{name} = {v:.5e}, truth {t:.5e}"
        );
    }
    let (e_all, e_long) = (
        rms_error(&all.params, &names, &truth),
        rms_error(&longest.params, &names, &truth),
    );
    eprintln!("RMS relative error: {e_all:.2e} over all segments, {e_long:.2e} longest alone");
    assert!(
        e_all <= e_long,
        "RMS relative error {e_all:.2e} over all segments, {e_long:.2e} longest alone"
    );
}
