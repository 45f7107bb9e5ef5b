//! [`super::run`], `jointid fit` as one call, on the simulated three-mass joint with known
//! truth (the simulator's default joint and sensors, special odd multisine): the
//! frequency-domain path on one record and on the segments of a capture with a gap, and
//! the refusals before the work.

use super::*;
use crate::data::{Dataset, IdData, InputTaken, Prep, SegmentChoice, Selection};
use crate::sim::SimConfig;
use crate::test_support::{est_val_captures, with_gap};
use jointid_core::excitation::ExcitationConfig;

/// The three-mass parameters the FRF determines, with the simulator's truth.
fn truth(cfg: &SimConfig) -> [(&'static str, f64); 7] {
    let p = cfg.plant.params;
    [
        ("J_m", p.j_m),
        ("J_a1", p.j_a1),
        ("J_a2", p.j_a2),
        ("k_g", p.k_g),
        ("k_a", p.k_a),
        ("d_g", p.d_g),
        ("d_a", p.d_a),
    ]
}

/// Every parameter of `truth` within `tol` (relative) in `fitted`.
fn assert_near_truth(fitted: &Fitted, truth: &[(&str, f64)], tol: f64) {
    for (name, t) in truth {
        let v = fitted
            .params
            .iter()
            .find(|p| p.name == *name)
            .unwrap_or_else(|| panic!("no {name}"))
            .value;
        assert!((v / t - 1.0).abs() < tol, "{name} = {v:.5e}, truth {t:.5e}");
    }
}

fn three_mass_request() -> FitRequest {
    FitRequest::new(FitOptions {
        spec: ModelSpec::linear(Family::Physical(Structure::ThreeMass)),
        ..FitOptions::default()
    })
}

/// [`run`] on the one estimation record `est` with the validation record `val`.
fn fit_on(req: &FitRequest, est: &Dataset, val: &Dataset) -> Result<FitOutcome, FitRunError> {
    run(
        req,
        FitRecords {
            estimation: std::slice::from_ref(est),
            numbers: &[1],
            validation: Some(val),
        },
    )
}

/// Tolerance on the seven parameters [-]: the command-line tests' 3 % on 3 periods
/// (2 after the settling one) with the default sensors.
const TOL: f64 = 0.03;

#[test]
fn run_fits_the_three_mass_joint_on_periodic_data_in_the_frequency_domain() {
    let exc = ExcitationConfig {
        periods: 3,
        ..ExcitationConfig::paper_default()
    };
    let cfg = SimConfig::default();
    let (est, val) = est_val_captures(&cfg, &exc, 1);
    let req = FitRequest {
        figures: true,
        ..three_mass_request()
    };
    let out = fit_on(&req, &est, &val).unwrap();
    let FittedModel::Linear(l) = &out.model else {
        panic!("a linear model")
    };
    assert!(
        l.fitted.method.contains("frequency domain"),
        "{}",
        l.fitted.method
    );
    assert_near_truth(&l.fitted, &truth(&cfg), TOL);
    // the current-loop lag is estimated in the frequency domain: within 10 %
    let tau = l.fitted.params.iter().find(|p| p.name == "tau_c").unwrap();
    let t = cfg.controller.current_loop_tau;
    assert!(
        (tau.value / t - 1.0).abs() < 0.1,
        "tau_c {} (truth {t})",
        tau.value
    );
    // one headline, the periodic FIT, on both records; the segment is the record
    assert_eq!(out.fit.name, crate::ident::sml::PERIODIC_FIT_NAME);
    assert_eq!(out.fit.metric, "periodic");
    assert!(out.fit.estimation > 95.0, "{:?}", out.fit);
    assert!(
        out.fit.validation.is_some_and(|f| f > 95.0),
        "{:?}",
        out.fit
    );
    assert!(out.fit.note.is_none() && out.fit.toolbox.is_none());
    assert_eq!(out.validation_name.as_deref(), Some("val"));
    assert_eq!(out.samples, est.data.len());
    assert_eq!(out.segments.len(), 1);
    assert_eq!(out.segments[0].segment, 1);
    assert!(out.warnings.is_empty(), "{:?}", out.warnings);
    // the figures: one averaged period per record under its periodic FIT, the Bode plot
    // over the FRF
    let (compared, records) = l.compare.as_ref().unwrap();
    assert_eq!(*compared, Compared::Periodic);
    assert_eq!(records.len(), 2);
    assert!((records[1].fit - out.fit.validation.unwrap()).abs() < 1e-12);
    let bode = l.bode.as_ref().unwrap();
    assert!(bode.band.is_some() && bode.curves.len() == 1);
    assert!(l.validation_tests.is_some());
    // the model file names the periodic FIT, so that `validate` reports the same one
    let saved = out.to_saved(req.prep);
    assert_eq!(saved.fit_name.as_deref(), Some(out.fit.name));

    // a validation record without a whole steady-state period: both records get the
    // toolbox FIT, and the note says why and what it measures
    let short = Dataset {
        name: "short".into(),
        data: val.data.slice(0..9_000),
        ..val.clone()
    };
    let out = run(
        &three_mass_request(),
        FitRecords {
            estimation: std::slice::from_ref(&est),
            numbers: &[1],
            validation: Some(&short),
        },
    )
    .unwrap();
    assert_eq!(out.fit.name, crate::ident::validate::FIT_NAME);
    assert_eq!(out.fit.metric, "toolbox");
    let note = out.fit.note.as_deref().unwrap_or_default();
    assert!(
        note.starts_with("short: ") && note.contains("the periodic FIT needs whole periods"),
        "{note}"
    );
}

#[test]
fn run_averages_the_frf_over_the_segments_of_a_capture_with_a_gap() {
    // 6 periods, 3,000 samples lost in the fourth: the first segment keeps two
    // steady-state periods of its own after the settling one for the residual tests
    let exc = ExcitationConfig {
        periods: 6,
        ..ExcitationConfig::paper_default()
    };
    let cfg = SimConfig::default();
    let (ds, _) = est_val_captures(&cfg, &exc, 3);
    let period = exc.period_samples as usize;
    let start = exc.ramp_samples as usize + 3 * period + 500;
    let sel = with_gap(&ds, start..start + 3_000)
        .select(&Selection {
            segment: Some(SegmentChoice::All),
            ..Selection::default()
        })
        .unwrap();
    assert_eq!(sel.datasets.len(), 2);
    let out = run(
        &three_mass_request(),
        FitRecords {
            estimation: &sel.datasets,
            numbers: &sel.segments,
            validation: None,
        },
    )
    .unwrap();
    let FittedModel::Linear(l) = &out.model else {
        panic!("a linear model")
    };
    assert_near_truth(&l.fitted, &truth(&cfg), TOL);
    assert_eq!(out.notes.len(), 1, "{:?}", out.notes);
    assert!(
        out.notes[0].ends_with("the FRF averages the whole periods of segments 1, 2"),
        "{:?}",
        out.notes
    );
    let numbers: Vec<usize> = out.segments.iter().map(|s| s.segment).collect();
    assert_eq!(numbers, [1, 2]);
    assert_eq!(
        out.samples,
        sel.datasets.iter().map(|d| d.data.len()).sum::<usize>()
    );
    assert!(
        l.compare.is_none() && l.bode.is_none(),
        "no figures asked for"
    );
}

/// A record of `n` samples at `ts` [s] named `name` (no excitation).
fn record(name: &str, n: usize, ts: f64) -> Dataset {
    Dataset {
        name: name.into(),
        data: IdData {
            ts,
            u: (0..n).map(|k| (k as f64 * 0.3).sin()).collect(),
            y: vec![0.0; n],
            r: None,
        },
        t0: 0.0,
        excitation: None,
        meta: Default::default(),
    }
}

#[test]
fn run_refuses_what_it_cannot_fit_before_the_work() {
    // the nonlinear fit's inputs on a linear model, effects on a black box
    let mut req = three_mass_request();
    req.nonlinear.fixed = vec![("k_g".into(), 1e5)];
    assert!(matches!(req.check(), Err(RequestError::NonlinearInputs)));
    let mut req = FitRequest::new(FitOptions {
        spec: ModelSpec {
            effects: Some(Vec::new()),
            ..ModelSpec::linear(Family::BlackBox(4))
        },
        ..FitOptions::default()
    });
    assert!(matches!(req.check(), Err(RequestError::EffectOnBlackBox)));
    req.options.spec.family = Family::Physical(Structure::TwoMass);
    req.prep.decimate = 2;
    assert!(matches!(
        req.check(),
        Err(RequestError::PreparedWithEffects)
    ));
    // the records: a validation record at another rate, a split of several segments
    let (a, b) = (record("a", 600, 1e-3), record("b", 600, 5e-4));
    let e = run(
        &three_mass_request(),
        FitRecords {
            estimation: std::slice::from_ref(&a),
            numbers: &[1],
            validation: Some(&b),
        },
    )
    .unwrap_err();
    assert_eq!(
        e.to_string(),
        "--validation b: sampled at 2000 Hz, a at 1000 Hz; the validation record needs the \
         estimation record's sample rate"
    );
    let split = FitRequest {
        estimation_fraction: Some(0.5),
        ..three_mass_request()
    };
    let segs = [a.clone(), record("a", 400, 1e-3)];
    let e = run(
        &split,
        FitRecords {
            estimation: &segs,
            numbers: &[1, 3],
            validation: None,
        },
    )
    .unwrap_err();
    assert!(
        matches!(&e, FitRunError::FractionOfSegments { count: 2, list } if list == "1, 3"),
        "{e}"
    );
    // --lags against the record before the fit
    let lags = FitRequest {
        domain: Domain::Time,
        lags: 400,
        ..three_mass_request()
    };
    let e = run(
        &lags,
        FitRecords {
            estimation: std::slice::from_ref(&a),
            numbers: &[1],
            validation: None,
        },
    )
    .unwrap_err();
    assert!(
        matches!(e, FitRunError::Lags(LagsError { samples: 600, .. })),
        "{e}"
    );
}

/// A grounded mass has no free body for the grey-box start to read: in the time domain it is
/// fitted by the nonlinear engine with no effect, its spring and inertia found (the linear
/// grounded mass of `test_support::grounded`, the record forced to the time domain), and
/// its force, held over each sample interval, taken as held.
#[test]
fn a_grounded_mass_is_fitted_in_the_time_domain() {
    let out = grounded_fit(1);
    assert_eq!(out.input, InputTaken::Held);
    assert!(
        !noted_as_sampled(&out),
        "a held force is held: {:?}",
        out.warnings
    );
}

/// A grounded mass driven by a force that moves between its samples, as a measured analog
/// input does: held, the fit's lag comes out nought and the model lags the data by half a
/// sample; the fit takes the input as sampled instead, says so, and finds the mass and the
/// spring as from a held force.
#[test]
fn a_force_that_moves_between_its_samples_is_fitted_as_sampled() {
    let out = grounded_fit(8);
    assert_eq!(out.input, InputTaken::Sampled);
    assert!(noted_as_sampled(&out), "{:?}", out.warnings);
}

/// The same grounded masses fitted in the frequency domain (their records are periodic):
/// the held force held (99.9 %); the force that moves between its samples taken as
/// sampled, which lifts the FIT from 78 % (a half-sample lag no lag or delay of the model
/// can take back) to above 95 %, the note saying so.
#[test]
fn a_force_that_moves_between_its_samples_is_taken_as_sampled_in_the_frequency_domain() {
    use crate::test_support::grounded;
    let req = grounded_request(Domain::Frequency);
    for (sub, input) in [(1, InputTaken::Held), (8, InputTaken::Sampled)] {
        let (est, val) = grounded::records_driven(0.0, 2, sub);
        let out = fit_on(&req, &est, &val).unwrap_or_else(|e| panic!("{e}"));
        let FittedModel::Linear(l) = &out.model else {
            panic!("{:?}", out.model)
        };
        assert!(l.fitted.in_frequency_domain(), "{}", l.fitted.method);
        assert_eq!(out.input, input, "sub {sub}: {:?}", out.fit);
        assert!(
            out.fit.validation.is_some_and(|v| v > 95.0),
            "sub {sub}: {:?}",
            out.fit
        );
        assert_eq!(
            noted_as_sampled(&out),
            input == InputTaken::Sampled,
            "{:?}",
            out.warnings
        );
    }
}

/// `fit --model grounded` in `domain` (gearless: `r` = 1).
fn grounded_request(domain: Domain) -> FitRequest {
    FitRequest {
        domain,
        ..FitRequest::new(FitOptions {
            spec: ModelSpec::linear(Family::Physical(Structure::Grounded)),
            r: 1.0,
            ..FitOptions::default()
        })
    }
}

/// Whether the fit's warnings say it took its input as sampled.
fn noted_as_sampled(out: &FitOutcome) -> bool {
    out.warnings
        .iter()
        .any(|w| w.contains("the input is taken as samples"))
}

/// `fit --model grounded` in the time domain on the grounded mass of
/// [`crate::test_support::grounded::records_driven`] (`sub` steps per sample of a force
/// linear between its samples): `J` and `k_0` within 2 % of the truth, validation FIT above
/// 95 %.
fn grounded_fit(sub: usize) -> FitOutcome {
    use crate::test_support::grounded;
    let (est, val) = grounded::records_driven(0.0, 2, sub);
    let req = grounded_request(Domain::Time);
    let out = fit_on(&req, &est, &val).unwrap_or_else(|e| panic!("{e}"));
    let FittedModel::Nonlinear(f) = &out.model else {
        panic!("{:?}", out.model)
    };
    let truth = grounded::plant().params;
    for (name, value) in [("J", truth.j_m), ("k_0", truth.k_0)] {
        let got = f.run.result.fit.get(name).expect(name);
        assert!((got / value - 1.0).abs() < 0.02, "{name} {got} vs {value}");
    }
    assert!(
        out.fit.validation.is_some_and(|v| v > 95.0),
        "{:?}",
        out.fit
    );
    // the model file says how the fit read its input, and the model read back and
    // validated on the record read so scores what the fit reported (`jointid validate`)
    let text = serde_json::to_string(&out.to_saved(Prep::default())).expect("serialises");
    let saved: crate::ident::model_file::SavedModel =
        serde_json::from_str(&text).expect("reads back");
    let nl = saved.nonlinear.as_ref().expect("a nonlinear section");
    assert_eq!(saved.input, out.input, "{text}");
    let opts = crate::ident::nonlinear::NlOptions {
        highpass_hz: nl.highpass_hz,
        ..Default::default()
    };
    let back = saved.to_nonlinear().expect("a nonlinear model");
    let v = crate::ident::nonlinear::validate(&back, &saved.input.record(val.data.clone()), &opts)
        .expect("validates");
    let reported = out.fit.validation.expect("a validation FIT");
    assert!(
        (v.velocity_fit_percent - reported).abs() < 1e-3,
        "the model file's validation {} % against the fit's {reported} %",
        v.velocity_fit_percent
    );
    out
}
