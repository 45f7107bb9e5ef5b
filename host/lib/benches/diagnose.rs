//! The diagnosis battery (issue 12, item 7): joints of the project's simulator with a
//! hidden effect (each of the six alone, two pairs, and none), drawn by a seed: the
//! three-mass parameters ±30 % around the default joint, one of three controller tunings,
//! the reference amplitude log-uniform in 0.01–0.4 rad RMS, the hidden effect's size
//! log-uniform in 0.7–1.6 × its default, the default sensors (quantised encoder, noise,
//! the slow torque disturbance). `diagnose` sees the captures and all six candidates, never
//! the truth. Prints, per case, the answer against the truth, then the confusion matrix,
//! top-1 accuracy, pair recovery, false alarms on `none`, the error of the fitted effect
//! parameters, and the reported closure against the true model's, on all cases and on
//! those whose gap lies in the band ([`IN_BAND`]); then the speed case:
//! 2 × 19,000 estimation and 19,000 validation samples (three periods after a 1 s ramp),
//! all six candidates, its CPU time against the nominal fit's alone in the same run.
//!
//! Every case's size, the true model's gain over the nominal on validation [FIT points],
//! puts it in a band ([`BANDS`]); the answers are counted by band too, and each diagnosis's
//! CPU time (user + system of the process, which load does not inflate) is printed beside
//! its wall time.
//!
//! Run: `cargo bench -p jointid --features test-support --bench diagnose` (`ROUNDS=N` draws N rounds of ten cases,
//! default 2, each round with its own seed; `SMALL=1` draws the hidden effects' sizes
//! log-uniform in 0.1–1.6 × their defaults instead, for effects that cost the nominal
//! about a point; `ONLY=K` or `ONLY=K,L` runs those cases alone, numbered across rounds
//! (round 2 is 10–19); `SPEED=0` skips the speed case, `DETAIL=1` prints every candidate,
//! `BATTERY=0` the battery, `STAGES=1` prints each stage's start and end as they come, at
//! their seconds from the case's start, `SAVE=dir` writes each case's captures there as CSV, `LOWPASS=0` leaves the fits' residuals unfiltered
//! above the excited band; `HARD=1` runs every case under harder conditions of a real
//! joint, drawn per case ([`Hard`]): a process disturbance inside the excited band, a
//! coarser encoder, a current-loop lag of 0.5–3 samples, the inertia feedforward on in
//! half the cases); `LAWS=1` moves the hidden effects off the estimators' own laws
//! (`other_laws`: asymmetric friction with another Stribeck bump, a ripple with a second
//! harmonic, an extra mode at the chain's end, whole-sample delays); `FRICTION=1` gives
//! every joint whose hidden effects hold no Coulomb friction a weak one of its own
//! (`weak_friction`: 0.3–1.2 mN·m), which is no effect to name; `JOINTS=1` moves every
//! joint off the default's scale (`other_joint`: torques × 0.03–30, resonances × 0.6–1.6;
//! `JOINTS=torque` the torques alone, the same motion in other units); `NOISE_VAL=1`
//! validates on a band-limited noise instead of a multisine (no non-excited lines), and
//! `EST2=1` adds a second estimation capture at twice the amplitude, as an independent
//! bench gives them.

use std::collections::BTreeMap;
use std::time::Instant;

use jointid::diagnose::metric::{true_fit, true_fit_in_loop, CLOSED_LOOP_METRIC_NAME};
use jointid::diagnose::{
    all_candidates, diagnose, DiagnoseRequest, Diagnosis, Progress, ProgressEvent,
};
use jointid::ident::nonlinear::{identify, NlRequest};
use jointid::model::effects::Effect;
use jointid::model::spec::Structure;
use jointid::sim::{ControllerConfig, JointParams, SensorConfig};
use jointid::test_support::battery::{
    captures, captures_validated_by, cases, config, other_joint, other_laws, second_capture,
    weak_friction, Case,
};
use jointid_core::excitation::SignalKind;

/// The parameters of `e` a user reads its size from, by key.
fn size_keys(e: &Effect) -> Vec<(&'static str, f64)> {
    match e {
        Effect::CoulombFriction(c) => vec![("fc", c.fc)],
        Effect::Backlash(b) => vec![("width", b.width)],
        Effect::NonlinearStiffness(s) => vec![("k3", s.k3)],
        Effect::ExtraMode(m) => vec![("j", m.j), ("k", m.k)],
        Effect::TimeDelay(d) => vec![("samples", d.samples)],
        Effect::TorqueRipple(r) => vec![("amplitude", r.amplitude)],
    }
}

/// The gap the battery draws its effects to open: the true model this many FIT
/// points above the nominal (issue 12, item 7: "the validation FIT drops 3–30 points").
const IN_BAND: std::ops::RangeInclusive<f64> = 3.0..=30.0;

/// The bands of effect size by which the answers are counted: the true model's gain over
/// the nominal on validation [FIT points].
const BANDS: [(f64, f64); 5] = [
    (f64::NEG_INFINITY, 1.0),
    (1.0, 3.0),
    (3.0, 6.0),
    (6.0, 12.0),
    (12.0, f64::INFINITY),
];

/// The band of a gain, as a label.
fn band_of(gain: f64) -> String {
    let (lo, hi) = BANDS
        .iter()
        .copied()
        .find(|(lo, hi)| gain >= *lo && gain < *hi)
        .unwrap_or(BANDS[0]);
    match (lo.is_finite(), hi.is_finite()) {
        (false, _) => format!("< {hi} points"),
        (_, false) => format!("≥ {lo} points"),
        _ => format!("{lo}–{hi} points"),
    }
}

/// CPU time of this process so far [s] (user + system, `/proc/self/stat`; NaN elsewhere).
/// `SAVE=dir`: writes case `i`'s captures to `dir/case{i}-est.csv` and `-val.csv`, to
/// look at a case with `jointid diagnose` itself, and its hidden joint, controller and
/// effects to `dir/case{i}-truth.txt`.
fn save(i: usize, case: &Case, est: &jointid::data::Dataset, val: &jointid::data::Dataset) {
    let Ok(dir) = std::env::var("SAVE") else {
        return;
    };
    let truth = std::path::Path::new(&dir).join(format!("case{i}-truth.txt"));
    let text = format!(
        "{:#?}\n{:#?}\nhidden {:#?}\nbackground {:#?}\n",
        case.params, case.controller, case.hidden, case.background
    );
    std::fs::write(&truth, text).expect("SAVE names a writable folder");
    for (part, ds) in [("est", est), ("val", val)] {
        let path = std::path::Path::new(&dir).join(format!("case{i}-{part}.csv"));
        let mut f = std::fs::File::create(&path).expect("SAVE names a writable folder");
        jointid::data::csv::write_capture_csv(&mut f, ds).expect("the capture is written");
    }
}

fn cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return f64::NAN;
    };
    // fields after the command name in parentheses; utime and stime are the 14th and 15th
    let rest = stat.rsplit_once(')').map_or("", |r| r.1);
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok());
    match (ticks(11), ticks(12)) {
        // the kernel's USER_HZ, 100 on Linux
        (Some(u), Some(s)) => (u + s) / 100.0,
        _ => f64::NAN,
    }
}

fn request(r: f64) -> DiagnoseRequest {
    // `STAGES=1`: each stage's and candidate's start and end, as they come, at their seconds
    let progress = std::env::var("STAGES").is_ok_and(|v| v == "1").then(|| {
        let began = std::time::Instant::now();
        Progress::new(move |e| {
            let at = began.elapsed().as_secs_f64();
            match e {
                ProgressEvent::Started(what) => println!("      {at:6.1} s  {what} …"),
                ProgressEvent::Finished(what, outcome) => {
                    println!("      {at:6.1} s  {what}: {outcome}")
                }
            }
        })
    });
    let mut req = DiagnoseRequest {
        r,
        candidates: all_candidates(),
        progress,
        ..DiagnoseRequest::default()
    };
    // `LOWPASS=0`: the fits' residuals not low-passed at the excited band's top
    req.options.band_limited = !std::env::var("LOWPASS").is_ok_and(|v| v == "0");
    // `MIN_GAIN=g`: the significance floor [FIT points] in place of the default's
    if let Some(g) = std::env::var("MIN_GAIN").ok().and_then(|v| v.parse().ok()) {
        req.options.min_gain = g;
    }
    req
}

/// Relative errors [%] of the answer's size parameters against the hidden effect of the
/// same name: the pair's fit (keys `effect.key`) when the answer is a pair, else the
/// single's (the extra mode may sit on the arm's branch: the smaller error of the two
/// readings is taken).
fn param_errors(d: &Diagnosis, hidden: &[Effect]) -> Vec<(String, f64)> {
    let mut out = Vec::new();
    let pair = d.pair.as_ref().filter(|p| p.name == d.best);
    for e in hidden {
        if !d.best.split('+').any(|b| b == e.name()) {
            continue;
        }
        let (c, prefix) = match pair {
            Some(p) => (p, format!("{}.", e.name())),
            None => match d.effects.iter().find(|c| c.name == e.name()) {
                Some(c) => (c, String::new()),
                None => continue,
            },
        };
        for (key, truth) in size_keys(e) {
            let Some(p) = c.parameters.get(&format!("{prefix}{key}")) else {
                continue;
            };
            let mut err = 100.0 * (p.value / truth - 1.0);
            if let Effect::ExtraMode(_) = e {
                let swapped = match key {
                    "j" => c.structure_parameters.get("J_a2"),
                    _ => c.structure_parameters.get("k_a"),
                };
                if let Some(s) = swapped {
                    let e2 = 100.0 * (s.value / truth - 1.0);
                    if e2.abs() < err.abs() {
                        err = e2;
                    }
                }
            }
            out.push((format!("{}.{key}", e.name()), err));
        }
    }
    out
}

fn battery() {
    let rounds = std::env::var("ROUNDS")
        .ok()
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or(2usize);
    let small = std::env::var("SMALL").is_ok_and(|v| v == "1");
    let harder = std::env::var("HARD").is_ok_and(|v| v == "1");
    let mut all = cases(rounds, small, harder);
    if std::env::var("LAWS").is_ok_and(|v| v == "1") {
        for (i, case) in all.iter_mut().enumerate() {
            other_laws(i, &mut case.hidden);
        }
    }
    if std::env::var("FRICTION").is_ok_and(|v| v == "1") {
        for (i, case) in all.iter_mut().enumerate() {
            case.background = weak_friction(i, &case.hidden);
        }
    }
    if let Ok(joints @ ("1" | "torque")) = std::env::var("JOINTS").as_deref() {
        for (i, case) in all.iter_mut().enumerate() {
            other_joint(i, case, joints == "1");
        }
    }
    // band -> (cases, right answers); right: a single's top-1, a pair's both effects in
    // the top two, `none` on none
    let mut by_band: BTreeMap<String, (usize, usize)> = BTreeMap::new();
    let mut cpu: Vec<f64> = Vec::new();
    let only: Option<Vec<usize>> = std::env::var("ONLY")
        .ok()
        .map(|v| v.split(',').filter_map(|k| k.trim().parse().ok()).collect());
    let r = JointParams::default().r;
    let noise_val = std::env::var("NOISE_VAL").is_ok_and(|v| v == "1");
    let est2 = std::env::var("EST2").is_ok_and(|v| v == "1");
    // hidden label -> answered label -> count
    let mut confusion: BTreeMap<String, BTreeMap<String, usize>> = BTreeMap::new();
    let (mut singles, mut singles_right) = (0, 0);
    // singles whose hidden effect the metric can see: the true model beats the nominal by
    // more than a point (a ripple at a large amplitude may not), and its own metric is
    // sound (the hidden slow disturbance is not in any driven model; with a stiffening
    // spring it can move the true model's deflection enough to spoil its metric)
    let (mut visible, mut visible_right) = (0, 0);
    let (mut pairs, mut pairs_found) = (0, 0);
    // cases of the battery: the hidden effects' true model 3–30 points above the
    // nominal ([`IN_BAND`]); right: a single's top-1, a pair's both effects in the top two
    let (mut in_band, mut in_band_right) = (0, 0);
    let mut in_band_closure: Vec<f64> = Vec::new();
    let (mut nones, mut false_alarms) = (0, 0);
    let mut perrs: Vec<f64> = Vec::new();
    let mut closure_errs: Vec<f64> = Vec::new();
    let mut times: Vec<f64> = Vec::new();
    for (i, case) in all.iter().enumerate() {
        if only.as_ref().is_some_and(|k| !k.contains(&i)) {
            continue;
        }
        // `NOISE_VAL=1`: validated on a band-limited noise, as an independent bench does
        let (est, val) = if noise_val {
            captures_validated_by(case, 4, case.rms, SignalKind::BandLimitedNoise)
        } else {
            captures(case, 4, case.rms)
        };
        // `EST2=1`: a second estimation capture at twice the amplitude (other phases, noise)
        let est2 = est2.then(|| second_capture(case, 4, 2.0 * case.rms));
        let ests: Vec<_> = std::iter::once(est.clone()).chain(est2).collect();
        save(i, case, &est, &val);
        // the effects by name (a ripple with a second harmonic is one effect)
        let mut kinds: Vec<&str> = Vec::new();
        for e in &case.hidden {
            if !kinds.contains(&e.name()) {
                kinds.push(e.name());
            }
        }
        let label = if kinds.is_empty() {
            "none".to_string()
        } else {
            kinds.join("+")
        };
        let truth = true_fit(&config(case), &val);
        let t = Instant::now();
        let c0 = cpu_seconds();
        let d = match diagnose(&ests, &val, &request(r)) {
            Ok(d) => d,
            Err(e) => {
                // a diagnosis that stops is a wrong answer of every kind
                println!("case {i:>2} {label:<34} failed: {e}");
                *confusion
                    .entry(label.clone())
                    .or_default()
                    .entry("failed".into())
                    .or_default() += 1;
                match kinds.len() {
                    0 => {
                        nones += 1;
                        false_alarms += 1;
                    }
                    1 => {
                        singles += 1;
                        // no nominal to compare: visible when the true model scores
                        if truth > 0.0 {
                            visible += 1;
                        }
                    }
                    _ => pairs += 1,
                }
                continue;
            }
        };
        let secs = t.elapsed().as_secs_f64();
        let cpu_s = cpu_seconds() - c0;
        times.push(secs);
        cpu.push(cpu_s);
        // a diagnosis scored in the controller's loop is compared with the truth in the loop
        let looped = d.metric == CLOSED_LOOP_METRIC_NAME;
        let truth = if looped {
            true_fit_in_loop(&config(case), &est, &val)
        } else {
            truth
        };
        let ranked: Vec<&str> = d.effects.iter().map(|c| c.name.as_str()).collect();
        let top: Vec<String> = d
            .effects
            .iter()
            .take(3)
            .map(|c| format!("{} {:+.1}±{:.1}", c.name, c.score, c.score_se))
            .collect();
        let errs = param_errors(&d, &case.hidden);
        let closure_err = d.fit_augmented_val - truth;
        println!(
            "case {i:>2} {label:<34} rms {:.3} rad: best {:<34} nominal {:6.2} → {:6.2} % (true model {:6.2} %, closure error {:+.2} points{}) top {:?} params {:?} {:.0} s wall, {cpu_s:.0} s CPU",
            case.rms,
            d.best,
            d.fit_nominal_val,
            d.fit_augmented_val,
            truth,
            closure_err,
            if looped { ", in the loop" } else { "" },
            top,
            errs.iter()
                .map(|(k, e)| format!("{k} {e:+.1} %"))
                .collect::<Vec<_>>(),
            secs
        );
        if std::env::var("DETAIL").is_ok_and(|v| v == "1") {
            for c in d.effects.iter().chain(d.pair.iter()) {
                let p: Vec<String> = c
                    .parameters
                    .iter()
                    .map(|(k, v)| format!("{k} {:.4e}±{:.1e}", v.value, v.std))
                    .collect();
                println!(
                    "    {}{} {:+.3}±{:.3} odd {} over the answer {} added to it {}: {} warnings {:?}",
                    c.name,
                    if c.significant { " (significant)" } else { "" },
                    c.score,
                    c.score_se,
                    c.odd_explained
                        .map_or("-".into(), |s| format!("{:.0} %", 100.0 * s)),
                    c.over_answer
                        .map_or("-".into(), |(m, se)| format!("{m:+.3}±{se:.3}")),
                    c.with_answer
                        .map_or("-".into(), |(m, se)| format!("{m:+.3}±{se:.3}")),
                    p.join(", "),
                    c.warnings
                );
            }
            println!("    verdict: {}", d.verdict);
            println!(
                "    hidden {:?}; background {:?}; warnings {:?}",
                case.hidden, case.background, d.warnings
            );
            let nominal: Vec<String> = d
                .nominal_parameters
                .iter()
                .map(|(k, v)| format!("{k} {:.4e}", v.value))
                .collect();
            println!(
                "    nominal {}; truth {:?}; lag {:.3e} s, feedforward {}, sensors {:?}",
                nominal.join(", "),
                case.params,
                case.controller.current_loop_tau,
                case.controller.feedforward,
                case.sensors
            );
        }
        let answered = d.best.clone();
        let right = match kinds.len() {
            0 => answered == "none",
            1 => answered.split('+').next() == Some(kinds[0]),
            _ => {
                let top2: Vec<&str> = ranked.iter().take(2).copied().collect();
                case.hidden
                    .iter()
                    .all(|e| top2.contains(&e.name()) || answered.split('+').any(|b| b == e.name()))
            }
        };
        let band = if case.hidden.is_empty() {
            "none".to_string()
        } else {
            band_of(truth - d.fit_nominal_val)
        };
        let cell = by_band.entry(band).or_default();
        cell.0 += 1;
        cell.1 += usize::from(right);
        *confusion
            .entry(label.clone())
            .or_default()
            .entry(answered.clone())
            .or_default() += 1;
        match kinds.len() {
            0 => {
                nones += 1;
                if answered != "none" {
                    false_alarms += 1;
                }
            }
            1 => {
                singles += 1;
                let right = answered.split('+').next() == Some(kinds[0]);
                if right {
                    singles_right += 1;
                }
                if IN_BAND.contains(&(truth - d.fit_nominal_val)) {
                    in_band += 1;
                    in_band_right += usize::from(right);
                    in_band_closure.push(closure_err);
                }
                if truth - d.fit_nominal_val > 1.0 && truth > 0.0 {
                    visible += 1;
                    if right {
                        visible_right += 1;
                    }
                }
                perrs.extend(errs.iter().map(|(_, e)| e.abs()));
                closure_errs.push(closure_err);
            }
            _ => {
                pairs += 1;
                let top2: Vec<&str> = ranked.iter().take(2).copied().collect();
                let found = case.hidden.iter().all(|e| {
                    top2.contains(&e.name()) || answered.split('+').any(|b| b == e.name())
                });
                if found {
                    pairs_found += 1;
                }
                if IN_BAND.contains(&(truth - d.fit_nominal_val)) {
                    in_band += 1;
                    in_band_right += usize::from(found);
                    in_band_closure.push(closure_err);
                }
                perrs.extend(errs.iter().map(|(_, e)| e.abs()));
                closure_errs.push(closure_err);
            }
        }
    }
    println!("\nconfusion (rows: hidden; columns: answered best)");
    for (hidden, row) in &confusion {
        let cells: Vec<String> = row.iter().map(|(a, n)| format!("{a}: {n}")).collect();
        println!("  {hidden:<34} {}", cells.join(", "));
    }
    println!(
        "top-1 (single effects): {singles_right}/{singles}, of which visible to the metric (true model > nominal + 1 point): {visible_right}/{visible}; pairs with both effects in the top two: {pairs_found}/{pairs}; false alarms on none: {false_alarms}/{nones}"
    );
    println!(
        "cases in the issue's band (the true model {}–{} points above the nominal): right {in_band_right}/{in_band} (singles top-1, pairs both in the top two), reported closure worst {:.2} points",
        IN_BAND.start(),
        IN_BAND.end(),
        in_band_closure.iter().fold(0.0f64, |m, e| m.max(e.abs()))
    );
    if !perrs.is_empty() {
        perrs.sort_by(f64::total_cmp);
        println!(
            "effect size parameters of right answers: median |error| {:.1} %, worst {:.1} % ({} values; target 20 %)",
            perrs[perrs.len() / 2],
            perrs[perrs.len() - 1],
            perrs.len()
        );
    }
    if !closure_errs.is_empty() {
        let worst = closure_errs.iter().fold(0.0f64, |m, e| m.max(e.abs()));
        println!(
            "reported closure against the true model's validation metric: worst {worst:.2} points (target 3)"
        );
    }
    println!(
        "right answers by effect size (the true model's gain over the nominal on validation):"
    );
    for (band, (n, right)) in &by_band {
        println!("  {band:<16} {right}/{n}");
    }
    if !cpu.is_empty() {
        cpu.sort_by(f64::total_cmp);
        println!(
            "CPU time per diagnosis (user + system): median {:.1} s, worst {:.1} s, total {:.0} s",
            cpu[cpu.len() / 2],
            cpu[cpu.len() - 1],
            cpu.iter().sum::<f64>()
        );
    }
    if !times.is_empty() {
        times.sort_by(f64::total_cmp);
        println!(
            "wall time per diagnosis (all six candidates, 2 threads, 22,000 + 22,000 samples): median {:.1} s, worst {:.1} s",
            times[times.len() / 2],
            times[times.len() - 1]
        );
    }
}

/// The speed case of issue 12 item 9: two estimation captures (small and large amplitude,
/// 15,000 samples each) and a 15,000-sample validation capture of the default joint with a
/// cubic spring, all six candidates, against the nominal fit alone.
fn speed() {
    let case = Case {
        hidden: vec![Effect::default_by_name("nonlinear_stiffness").unwrap()],
        params: JointParams::default(),
        controller: ControllerConfig::default(),
        sensors: SensorConfig::default(),
        rms: 0.02,
        seed: 77,
        background: Vec::new(),
    };
    let (small, val) = captures(&case, 3, 0.02);
    let (large, _) = captures(&case, 3, 0.04);
    let r = JointParams::default().r;
    let lens = (small.data.len(), large.data.len(), val.data.len());
    let (t, c) = (Instant::now(), cpu_seconds());
    let nominal = identify(
        &small.data,
        &NlRequest::new(Structure::ThreeMass, r, Vec::new()),
    );
    let (t_nominal, c_nominal) = (t.elapsed().as_secs_f64(), cpu_seconds() - c);
    let (t, c) = (Instant::now(), cpu_seconds());
    let d = diagnose(&[small, large], &val, &request(r)).expect("diagnosis");
    let (t_all, c_all) = (t.elapsed().as_secs_f64(), cpu_seconds() - c);
    println!(
        "\nspeed: {} + {} + {} samples (each with a 1 s ramp); nominal fit alone {t_nominal:.1} s wall, {c_nominal:.1} s CPU ({}); diagnosis with all six candidates {t_all:.1} s wall on 2 threads, {c_all:.1} s CPU = {:.1}× the nominal's CPU (target 20 s CPU); best {}",
        lens.0,
        lens.1,
        lens.2,
        if nominal.is_ok() { "ok" } else { "failed" },
        c_all / c_nominal,
        d.best
    );
}

fn main() {
    if std::env::var("BATTERY").map_or(true, |v| v != "0") {
        battery();
    }
    if std::env::var("SPEED").map_or(true, |v| v != "0") {
        speed();
    }
}
