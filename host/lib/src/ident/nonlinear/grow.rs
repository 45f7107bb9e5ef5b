//! The start of a flexible model with Coulomb friction when the motor sticks: grown in the
//! time domain from the two-mass, not read off the FRF.
//!
//! **Why.** When the friction level is comparable to the torque, the motor rests for long
//! stretches (stick-slip) and the FRF at the excited lines is the friction's describing
//! function (a viscous-like damping), not the structure's: the linear fits see a motor on a
//! damper and no spring. Bench case 7 of `benches/diagnose.rs` (three-mass with an extra
//! mode and Stribeck friction `F_c` 0.043, `F_s` 0.058 N·m at 0.067 rad RMS, torque RMS
//! 0.059 N·m): the motor is at rest on 41 % of the samples. The three- and four-mass fits
//! to the raw FRF end at `k_g` 222 and 119 N·m/rad (truth 1.53e5) with `f_m` 0.18 and 0.20
//! N·m·s/rad (0.002); compensated as [`super::compensate`] does, at 75–1.4e6 N·m/rad; even
//! compensated with the true law at the true motor velocity, the fits that find `k_g` keep
//! `k_a` 2–25× off and `f_m` 3–10× high (a stuck motor carries a friction torque no law of
//! its velocity gives). Every nonlinear fit started there stays in that basin: the basin
//! around the truth spans about 1.5× per value (the pair started 3× off ends at 47 %, 1.5×
//! off at 90.5 %, as from the truth).
//!
//! **What** ([`grow_with`]). The two-mass with the Coulomb friction is fitted by output
//! error from its automatic start, whose step 3 grids the gearbox spring against the cost
//! of the simulation with the friction ([`super::automatic_start`]); for the three-mass the
//! arm's second mass is then found as an extra mode in series on that two-mass, which is
//! the three-mass chain; for the four-mass the parallel mass `J_p` as an extra mode in
//! parallel on that three-mass's first arm mass (seed 000 eq. (7)). Each stage starts from
//! the previous one's plant, lag and friction, the mode from a grid over its mass, its
//! frequency and the gearbox damping: its best point of each frequency and of each damper
//! share fitted briefly on a piece of the record, the lowest on to the stage's fit
//! (`fit_with_mode_raced`; judged before any fit, the grid keeps a mode that changes
//! nothing, bench case 10 of `benches/diagnose.rs`). On the
//! three-mass with `F_c` = 0.06 N·m (`jointid simulate --model three-mass --effect
//! coulomb_friction:fc=0.06,fs=0.06 --seed 4`, the torque below the level on 79 % of the
//! samples) the fit from the grown start reaches the truth (validation FIT 72.15 %, the
//! true model's; from the frequency-domain start 65.1 % with `k_g` −24 %, `k_a` −48 %).
//! The four-mass is grown the same way but not as well: on the same joint as a four-mass
//! the chain's mode takes the parallel mass's place and the fit ends at 69.7 % against
//! the true model's 72.2 % (from the frequency-domain start the fit did not simulate).
//! Values held by the caller are held in every stage where they mean the same (the
//! motor side, the gearbox, the lag, the offset and the friction's keys; the arm's
//! masses once the stage has them, the mode's `j`, `k`, `d` as the mass it stands for).
//!
//! **Who.** [`super::run()`] (`jointid fit`), with the request's own law, when the request
//! has Coulomb friction, the automatic start and a flexible structure; the diagnosis for its
//! Coulomb candidates ([`grow`]), with the Stribeck law (`F_c`, `F_s`, `v_s` fitted, started
//! at the default shape [`CoulombFriction::default`] scaled by the automatic start): in
//! stick-slip the motor breaks away at every stick, and on case 7 the pure law leaves 4.4
//! FIT points (90.6 % against 95.0 %, both started at the truth; true model 95.3 %).
//!
//! **When.** Stick-slip is taken as the measured torque staying below the friction level
//! (the compensation's regression, [`super::compensate::level`], or a held `fc`) on more
//! than [`STICK_SHARE`] of the samples (case 7: 66 %; the other cases of the bench, 0–8 %;
//! seed 001's reference problem: 13 %).
//!
//! **The bump.** With a Stribeck law the first stage is fitted twice, with the bump free
//! and with the level alone (`F_s = F_c`), and the level alone goes on only at a clearly
//! lower cost (`LEVEL_ALONE_SHARE`); when the level
//! alone wins, the stages after it fit the level alone and the grown law takes the seed's
//! shape back (`F_s/F_c`, `v_s`) at the grown level, for the caller's fit to free. Neither
//! start is the better one on every joint: bench case 60 of `benches/diagnose.rs`
//! (Stribeck friction `F_c` 0.022 N·m, the motor stuck on 40 % of the samples) ends the
//! two-mass with the bump free at `k_g` 1.3·10³ N·m/rad (truth 1.2·10⁵) and a velocity FIT
//! of 27 %, with the level alone at `k_g` −0.5 % and 74.8 %; the Coulomb candidate grown
//! from the first scored 35.7 points below the nominal, from the second +24.9 (94.41 %, the
//! true model's 94.38 %). Case 17 goes the other way: grown with the level alone in every
//! case, its answer became backlash, 24 points below the pair of friction and mode it
//! finds from the bump. A bump the free fit let vanish (`F_s` down to `F_c`, which takes
//! `F_s` and `v_s` out of the later stages) is given back the same way: the stages are a
//! start, and the caller's fit decides the law's shape.

use super::init::Step;
use super::model::has_bump;
use super::{identify_segments, NlFit, NlOptions, NlRequest, NlRunError};
use crate::data::IdData;
use crate::ident::grey_box;
use crate::ident::lm::Termination;
use crate::ident::parallel::{machine_threads, parallel};
use crate::model::effects::{Attach, CoulombFriction, Effect, ExtraMode};
use crate::model::spec::Structure;

/// Share of samples with `|u| < F̂_c` from which the motor is taken to stick.
pub const STICK_SHARE: f64 = 0.2;

/// Why a start could not be grown.
#[derive(Debug, thiserror::Error)]
pub enum GrowError {
    /// the stick-slip growth does not build this structure
    #[error("no grown start for the {}", .0.label())]
    Structure(Structure),
    /// the backlash growth does not build this structure
    #[error("no grown backlash start for the {}", .0.label())]
    BacklashStructure(Structure),
    /// no record given
    #[error("no estimation record")]
    NoRecord,
    /// the linear two-mass gives no gearbox deflection to size the backlash by (its value
    /// [rad]: not finite or not positive)
    #[error("no gearbox deflection on the linear two-mass")]
    NoDeflection(f64),
    /// no point of the backlash grid simulates, or no fit from one converges
    #[error("no point of the backlash grid simulates")]
    NoGridPoint,
    /// a stage's fit ended without the extra mode it was to add
    #[error("{stage}: the fit lost its extra mode")]
    LostMode {
        /// the stage
        stage: &'static str,
    },
    /// a stage's fit failed
    #[error(transparent)]
    Fit(#[from] NlRunError),
}

/// Share of the samples of `data` whose torque magnitude is below `level` [N·m].
pub fn stick_share(data: &[IdData], level: f64) -> f64 {
    let n: usize = data.iter().map(|d| d.u.len()).sum();
    let below = data
        .iter()
        .flat_map(|d| d.u.iter())
        .filter(|u| u.abs() < level)
        .count();
    below as f64 / n.max(1) as f64
}

/// The grown start.
#[derive(Clone, Debug, PartialEq)]
pub struct Grown {
    /// the structure's values ([`Structure::param_names`] order)
    pub plant: Vec<f64>,
    /// current-loop lag [s] (0: none)
    pub tau_c: f64,
    /// input offset [N·m]
    pub offset: f64,
    /// the fitted friction (the law asked for)
    pub coulomb: Effect,
    /// each stage's fit, as the start's steps report them
    pub steps: Vec<Step>,
}

/// What a growth starts from besides the records.
#[derive(Clone, Debug, PartialEq)]
pub struct Seed {
    /// the structure to grow (two-, three- or four-mass)
    pub structure: Structure,
    /// gear ratio `r` [-]
    pub r: f64,
    /// current-loop lag to start from [s]
    pub tau_c: f64,
    /// the current-loop lag held [s] (0: none); `None`: estimated
    pub held_tau_c: Option<f64>,
    /// the friction's law (its shape: pure, Stribeck bump, asymmetric levels)
    pub law: CoulombFriction,
    /// the law's keys given a start value for the first stage [SI]
    pub given: Vec<(String, f64)>,
    /// values held by name, in the grown structure's names [SI]
    pub fixed: Vec<(String, f64)>,
    /// options of the fits
    pub options: NlOptions,
}

/// The friction keys of a fit's Coulomb friction, to give a later start.
pub fn friction_keys(fit: &NlFit) -> Vec<(String, f64)> {
    fit.model
        .effects
        .iter()
        .find(|e| matches!(e, Effect::CoulombFriction(_)))
        .map(friction_keys_of)
        .unwrap_or_default()
}

/// The keys of a Coulomb friction (none for another effect), to give a later start.
pub fn friction_keys_of(e: &Effect) -> Vec<(String, f64)> {
    let Effect::CoulombFriction(c) = e else {
        return Vec::new();
    };
    let mut k = vec![
        ("fc".to_string(), c.fc),
        ("fs".to_string(), c.fs),
        ("v_stribeck".to_string(), c.v_stribeck),
    ];
    k.extend(c.fc_neg.map(|v| ("fc_neg".to_string(), v)));
    k.extend(c.fv_neg_extra.map(|v| ("fv_neg_extra".to_string(), v)));
    k
}

/// The start of `structure` (two- or three-mass) with Stribeck friction grown from the
/// two-mass on the records `est`, as the diagnosis takes it (module documentation);
/// `tau_c` the lag to start from [s].
///
/// # Errors
/// [`GrowError::Structure`] for another structure, or the fit that fails.
pub fn grow(
    est: &[IdData],
    structure: Structure,
    r: f64,
    tau_c: f64,
    options: &NlOptions,
) -> Result<Grown, GrowError> {
    if structure == Structure::FourMass {
        return Err(GrowError::Structure(structure));
    }
    grow_with(
        est,
        &Seed {
            structure,
            r,
            tau_c,
            held_tau_c: None,
            law: CoulombFriction::default(),
            given: Vec::new(),
            fixed: Vec::new(),
            options: options.clone(),
        },
    )
}

/// Most the cost of the growth's first stage with the friction level alone may be, as a
/// share of the cost with the seed's Stribeck bump free, for the level alone to go on
/// (module documentation, the bump). The bump law contains the level alone, so a lower
/// cost means the bump's fit ended in another basin (case 60: 12 % of it); a tie means
/// both found the same minimum (case 17 rounded to five digits, as its test draws it: the
/// same cost to 10⁻⁹, and the level alone going on lost the pair), and the seed's law goes
/// on.
const LEVEL_ALONE_SHARE: f64 = 0.9;

/// Names that are no structure's: held in every stage.
const ALWAYS: [&str; 7] = [
    "tau_c",
    "offset",
    "fc",
    "fs",
    "v_stribeck",
    "fc_neg",
    "fv_neg_extra",
];

/// The values of `fixed` a stage holds: those named in `same` (the stage's structure
/// parameters that mean what the grown structure's do), those of [`ALWAYS`], and the
/// grown structure's names in `mode` renamed to the stage's extra-mode keys.
fn held_in(fixed: &[(String, f64)], same: &[&str], mode: [&str; 3]) -> Vec<(String, f64)> {
    fixed
        .iter()
        .filter_map(|(n, v)| {
            if same.contains(&n.as_str()) || ALWAYS.contains(&n.as_str()) {
                return Some((n.clone(), *v));
            }
            let i = mode.iter().position(|m| m == n)?;
            Some((["j", "k", "d"][i].to_string(), *v))
        })
        .collect()
}

/// The step that reports a stage's fit.
fn stage_step(name: &str, what: &str, fit: &NlFit) -> Step {
    Step {
        name: name.into(),
        values: Step::values_of(fit),
        detail: format!(
            "{what} by output error ({} iterations, velocity FIT {:.2} %)",
            fit.iterations, fit.fit_velocity_percent
        ),
    }
}

/// The start of `seed.structure` (two-, three- or four-mass) with the Coulomb friction
/// `seed.law` grown from the two-mass on the records `est` (module documentation).
///
/// # Errors
/// [`GrowError::Structure`] for the rigid structure, or the stage that fails.
pub fn grow_with(est: &[IdData], seed: &Seed) -> Result<Grown, GrowError> {
    let structure = seed.structure;
    if structure == Structure::Rigid {
        return Err(GrowError::Structure(structure));
    }
    let law = Effect::CoulombFriction(seed.law);
    let fit = |req: NlRequest| identify_segments(est, &req).map(|r| r.fit);
    // a start: the smooth law's minimum, no covariance (the final fit corrects and
    // covers it)
    let options = NlOptions {
        cov_lags: 0,
        exact_correction: false,
        smoothing_sigma: false,
        ..seed.options.clone()
    };
    let request = |s: Structure, effects: Vec<Effect>, prev: Option<&NlFit>| NlRequest {
        tau_c: prev.map_or(seed.tau_c, |p| p.model.tau_c),
        held_tau_c: seed.held_tau_c,
        linear: prev.map(|p| p.plant.clone()),
        options: options.clone(),
        ..NlRequest::new(s, seed.r, effects)
    };
    // stage 1: the two-mass with the friction from its automatic start; with a Stribeck
    // bump also with the level alone (`F_s = F_c`), kept at a clearly lower cost, the bump
    // then given back at the seed's shape for the caller's fit (module documentation, the
    // bump)
    let two_names: &[&str] = if structure == Structure::TwoMass {
        Structure::TwoMass.param_names()
    } else {
        &["J_m", "k_g", "d_g", "f_m"]
    };
    let stage_one = |law: CoulombFriction, given: Vec<(String, f64)>| {
        fit(NlRequest {
            fixed: held_in(&seed.fixed, two_names, ["", "", ""]),
            given: vec![given],
            ..request(Structure::TwoMass, vec![Effect::CoulombFriction(law)], None)
        })
    };
    let mut a = stage_one(seed.law, seed.given.clone());
    let shape_held = seed
        .fixed
        .iter()
        .chain(&seed.given)
        .any(|(n, _)| n == "fs" || n == "v_stribeck");
    // the seed's bump is the growth's to set aside and give back (its shape `F_s/F_c`
    // needs a level): not where the caller holds or gives the shape
    let bump_free = has_bump(&seed.law) && seed.law.fc > 0.0 && !shape_held;
    let mut level_alone = false;
    if bump_free {
        let pure = CoulombFriction {
            fs: seed.law.fc,
            ..seed.law
        };
        if let Ok(p) = stage_one(pure, seed.given.clone()) {
            if a.as_ref()
                .map_or(true, |a| p.ssr < LEVEL_ALONE_SHARE * a.ssr)
            {
                a = Ok(p);
                level_alone = true;
            }
        }
    }
    let a = a?;
    let mut steps = vec![stage_step(
        "stick-slip start: two-mass",
        if level_alone {
            "the two-mass with Coulomb friction from its automatic start, the friction's level \
             alone (with the Stribeck bump free the fit ended at a higher cost)"
        } else {
            "the two-mass with Coulomb friction from its automatic start"
        },
        &a,
    )];
    let coulomb_of = |fit: &NlFit| {
        fit.model
            .effects
            .iter()
            .find(|e| matches!(e, Effect::CoulombFriction(_)))
            .copied()
            .unwrap_or(law)
    };
    // the seed's bump at the grown level, when the stages fitted the level alone, or when
    // the bump's fit let the bump vanish (`F_s` down to `F_c`, which takes `F_s` and `v_s`
    // out of every later fit's layout): the caller's fit frees it again (default bench
    // case 37, Stribeck friction with `F_s` 1.33 `F_c` beside a parallel mode, the motor
    // stuck on 51 % of the samples: the growth ended at `F_s` = `F_c`, and the candidate,
    // fitting the level alone, closed 3.7 points short of the true model)
    let bumped = |e: Effect| match e {
        Effect::CoulombFriction(c) if level_alone || (bump_free && !has_bump(&c)) => {
            Effect::CoulombFriction(CoulombFriction {
                fs: c.fc * seed.law.fs / seed.law.fc,
                v_stribeck: seed.law.v_stribeck,
                ..c
            })
        }
        e => e,
    };
    let done = |fit: &NlFit, plant: Vec<f64>, steps: Vec<Step>| Grown {
        plant,
        tau_c: fit.model.tau_c,
        offset: fit.get("offset").unwrap_or(0.0),
        coulomb: bumped(coulomb_of(fit)),
        steps,
    };
    if structure == Structure::TwoMass {
        return Ok(done(&a, a.plant.clone(), steps));
    }
    // a stage: the mode attached as `attach` on `from` (its plant in the names of `s`),
    // from the grid of `fit_with_mode`, the values held that mean the same (`same`, and
    // the grown structure's `names` as the mode's keys); its fit, its mode and its step
    let add_mode = |from: &NlFit,
                    s: Structure,
                    same: &[&str],
                    attach: Attach,
                    names: [&str; 3],
                    (name, what): (&'static str, &str)|
     -> Result<(NlFit, ExtraMode, Step), GrowError> {
        let mode = Effect::ExtraMode(ExtraMode {
            attach,
            ..ExtraMode::default()
        });
        let req = NlRequest {
            fixed: held_in(&seed.fixed, same, names),
            given: vec![Vec::new(), friction_keys(from)],
            ..request(s, vec![mode, coulomb_of(from)], Some(from))
        };
        let offset = from.get("offset").unwrap_or(0.0);
        let f = fit_with_mode_raced(est, &req, &from.plant, offset)?;
        let Some(Effect::ExtraMode(x)) = f.model.effects.first().copied() else {
            return Err(GrowError::LostMode { stage: name });
        };
        let step = stage_step(name, what, &f);
        Ok((f, x, step))
    };
    // stage 2: the arm's second mass, an extra mode in series on the two-mass (the
    // three-mass chain)
    let (b, x, step) = add_mode(
        &a,
        Structure::TwoMass,
        &["J_m", "J_a1", "k_g", "d_g", "f_m"],
        Attach::Serial,
        ["J_a2", "k_a", "d_a"],
        (
            "stick-slip start: three-mass chain",
            "the two-mass with an extra mode in series (the arm's second mass) and the \
             friction, from the two-mass and the best point of a grid over the mode (the best \
             of three short fits and of a race over its frequency)",
        ),
    )?;
    steps.push(step);
    // [J_m, J_a1, k_g, d_g, f_m] and the mode → [J_m, J_a1, J_a2, k_g, k_a, d_g, d_a, f_m]
    let p = &b.plant;
    let three = vec![p[0], p[1], x.j, p[2], x.k, p[3], x.d, p[4]];
    if structure == Structure::ThreeMass {
        return Ok(done(&b, three, steps));
    }
    // stage 3: the parallel mass, an extra mode in parallel on the three-mass's first arm
    // mass (seed 000 eq. (7))
    let mut from_b = b.clone();
    from_b.plant = three;
    let (c, x, step) = add_mode(
        &from_b,
        Structure::ThreeMass,
        Structure::ThreeMass.param_names(),
        Attach::Parallel,
        ["J_p", "k_p", "d_p"],
        (
            "stick-slip start: four-mass",
            "the three-mass with an extra mode in parallel on the first arm mass (J_p) and the \
             friction, from the three-mass chain and the best point of a grid over the mode \
             (the best of three short fits and of a race over its frequency)",
        ),
    )?;
    steps.push(step);
    // [J_m, J_a1, J_a2, k_g, k_a, d_g, d_a, f_m] and the mode →
    // [J_m, J_a1, J_a2, J_p, k_g, k_a, k_p, d_g, d_a, d_p, f_m]
    let p = &c.plant;
    let mut four = vec![
        p[0], p[1], p[2], x.j, p[3], p[4], x.k, p[5], p[6], x.d, p[7],
    ];
    // the two branches on `J_a1` are the same mechanism: the softer one is reported as
    // `(J_a2, k_a, d_a)`, as the linear fits do, unless the caller holds a value of either
    let branch_held = ["J_a2", "J_p", "k_a", "k_p", "d_a", "d_p"]
        .iter()
        .any(|n| seed.fixed.iter().any(|(m, _)| m == n));
    if !branch_held && grey_box::four_mass_swapped(&four) {
        for (i, j) in grey_box::FOUR_MASS_BRANCHES {
            four.swap(i, j);
        }
    }
    Ok(done(&c, four, steps))
}

/// The start of `structure` (two- or three-mass) with backlash grown from the two-mass.
#[derive(Clone, Debug, PartialEq)]
pub struct GrownBacklash {
    /// the structure's values ([`Structure::param_names`] order)
    pub plant: Vec<f64>,
    /// current-loop lag [s] (0: none)
    pub tau_c: f64,
    /// input offset [N·m]
    pub offset: f64,
    /// the fitted backlash
    pub backlash: Effect,
    /// the last stage's sum of squares (smooth law, prefiltered velocity)
    pub ssr: f64,
}

/// Widths of the grid over the backlash on the linear two-mass, as a share of the rms
/// deflection `δ = u_rms / r / k_g` of its gearbox.
const BACKLASH_SHARES: [f64; 5] = [0.01, 0.03, 0.1, 0.3, 1.0];

/// Iterations of the two-mass fit with the backlash (a start; the mode's stage and the
/// caller's fit go on from it).
const BACKLASH_ITER: usize = 30;

/// The gearbox damper of the grid over the backlash, as a share of the linear two-mass's.
const BACKLASH_DAMPER_SHARES: [f64; 2] = [1.0, 0.3];

/// Most the contact stiffness of the grid may exceed the linear `k_g` [-].
const MAX_CONTACT_GAIN: f64 = 4.0;

/// Describing gain of a dead-zone spring of half width `h` on a sinusoidal deflection of
/// amplitude `a` [rad]: the linear stiffness it shows, as a share of its contact stiffness
/// [-]. 1 without a gap, 0 when the deflection stays inside it.
pub fn dead_zone_gain(h: f64, a: f64) -> f64 {
    if a.is_nan() || a <= 0.0 || h >= a {
        return 0.0;
    }
    let x = (h / a).max(0.0);
    1.0 - 2.0 / std::f64::consts::PI * (x.asin() + x * (1.0 - x * x).sqrt())
}

/// The start of `structure` (two- or three-mass) with backlash grown from the linear
/// two-mass `linear` (its values and lag [s], the frequency-domain fit) on the records
/// `est`.
///
/// **Why.** A gap as wide as the gearbox's rms deflection decouples the motor from the arm
/// for much of the time, and its impacts take energy: the linear fits see a lighter motor,
/// a heavily damped gearbox and, with a second arm mass to spend, a structure that is no
/// longer the joint's. Bench case 21 of `benches/diagnose.rs` (gap 16.4 µrad, rms
/// deflection of the true gearbox 38 µrad): the three-mass's linear fit has `J_m` −62 %,
/// `k_g` 4.3×, `d_g` 41×, `J_a2` 21× (11.5 kg·m², truth 0.54) and a lag 5× the truth; on
/// it every width costs more than none (the cost rises from 126.5 at 0.01 `δ` to 332 at 2
/// `δ`), with the stiffness, the damper and the lag scaled too (72 points, each fitted for
/// five iterations: the best end at `J_a2` ≈ 11 and 126.3), and the fit ends at a width
/// of 0.4 µrad, 0 FIT points above the nominal (from the truth, 72.8 against 126.5). The
/// two-mass cannot spend a mass that way: its frequency-domain fit keeps `J_m` (−1 %) and
/// the lag (+4 %) and shows the softened gearbox (`k_g` −33 %).
///
/// **What.** The backlash on the two-mass from the best point of a grid (widths
/// `BACKLASH_SHARES` of the rms deflection `δ`, each at the linear `k_g` and at the
/// contact stiffness whose describing gain at the deflection `√2 δ` gives the linear
/// one, [`dead_zone_gain`], at most `MAX_CONTACT_GAIN`×), for each share
/// `BACKLASH_DAMPER_SHARES` of the linear gearbox damper (it held the impacts' losses),
/// the shares' points raced ([`race`]: five iterations each, the lower cost on to
/// `BACKLASH_ITER`); for the three-mass the arm's second mass then added
/// as an extra mode in series ([`fit_with_mode`]), as the stick-slip growth does. Case 21
/// with its joint rounded to five digits: from the damper as it is the two-mass ends at
/// 3.9 µrad and a cost of 126.7, from a third of it at 17.5 µrad and 115.0; the diagnosis
/// answers backlash at 77.9 % (the nominal's 63.9 %, the true model's about 80 %).
///
/// The fits are a start: the smooth law's minimum, no covariance.
///
/// # Errors
/// [`GrowError::BacklashStructure`] for another structure, [`GrowError::NoRecord`],
/// [`GrowError::NoDeflection`], [`GrowError::NoGridPoint`], or the fit that fails.
pub fn grow_backlash(
    est: &[IdData],
    structure: Structure,
    r: f64,
    (linear, tau_c): (&[f64], f64),
    options: &NlOptions,
) -> Result<GrownBacklash, GrowError> {
    if !matches!(structure, Structure::TwoMass | Structure::ThreeMass) {
        return Err(GrowError::BacklashStructure(structure));
    }
    let data = est
        .iter()
        .max_by_key(|d| d.len())
        .ok_or(GrowError::NoRecord)?;
    let options = NlOptions {
        cov_lags: 0,
        exact_correction: false,
        smoothing_sigma: false,
        ..options.clone()
    };
    let backlash = Effect::Backlash(crate::model::effects::Backlash::default());
    let req = NlRequest {
        tau_c,
        linear: Some(linear.to_vec()),
        options: options.clone(),
        ..NlRequest::new(Structure::TwoMass, r, vec![backlash])
    };
    let model = super::model_of(&req, data);
    // [J_m, J_a1, k_g, d_g, f_m]
    let kg = linear.get(2).copied().unwrap_or(0.0);
    let delta = super::init::torque_rms(data) / r / kg;
    if !(delta > 0.0 && delta.is_finite()) {
        return Err(GrowError::NoDeflection(delta));
    }
    // the grid's best point at each damper share, the shares' fits raced ([`race`])
    let mut starts: Vec<NlRequest> = Vec::new();
    for dg_share in BACKLASH_DAMPER_SHARES {
        let mut best: Option<(f64, Vec<f64>)> = None;
        for share in BACKLASH_SHARES {
            let width = share * delta;
            let gain = dead_zone_gain(0.5 * width, std::f64::consts::SQRT_2 * delta);
            let contact = (1.0 / gain.max(1.0 / MAX_CONTACT_GAIN)) * kg;
            for k in [kg, contact] {
                let mut m = model.clone();
                m.effects = vec![Effect::Backlash(crate::model::effects::Backlash { width })];
                let mut p = linear.to_vec();
                p[2] = k;
                p[3] *= dg_share;
                let values = m.values(&p, 0.0, 0.0);
                if let Some(c) = super::cost_at(data, &m, &values) {
                    if best.as_ref().is_none_or(|(b, _)| c < *b) {
                        best = Some((c, values));
                    }
                }
            }
        }
        if let Some((_, start)) = best {
            starts.push(NlRequest {
                start: super::NlStart::Values(start),
                ..req.clone()
            });
        }
    }
    if starts.is_empty() {
        return Err(GrowError::NoGridPoint);
    }
    let a = race(est, &starts, BACKLASH_ITER)?;
    let width_of = |f: &NlFit| {
        f.model
            .effects
            .iter()
            .find(|e| matches!(e, Effect::Backlash(_)))
            .copied()
            .unwrap_or(backlash)
    };
    if structure == Structure::TwoMass {
        return Ok(GrownBacklash {
            plant: a.plant.clone(),
            tau_c: a.model.tau_c,
            offset: a.get("offset").unwrap_or(0.0),
            backlash: width_of(&a),
            ssr: a.ssr,
        });
    }
    // the arm's second mass, an extra mode in series on the two-mass (the three-mass chain)
    let mode = Effect::ExtraMode(ExtraMode {
        attach: Attach::Serial,
        ..ExtraMode::default()
    });
    let req = NlRequest {
        tau_c: a.model.tau_c,
        linear: Some(a.plant.clone()),
        options,
        ..NlRequest::new(Structure::TwoMass, r, vec![mode, width_of(&a)])
    };
    let b = fit_with_mode(est, &req, &a.plant, a.get("offset").unwrap_or(0.0))?;
    let Some(Effect::ExtraMode(x)) = b.model.effects.first().copied() else {
        return Err(GrowError::LostMode {
            stage: "the grown backlash start",
        });
    };
    // [J_m, J_a1, k_g, d_g, f_m] and the mode → [J_m, J_a1, J_a2, k_g, k_a, d_g, d_a, f_m]
    let p = &b.plant;
    Ok(GrownBacklash {
        plant: vec![p[0], p[1], x.j, p[2], x.k, p[3], x.d, p[4]],
        tau_c: b.model.tau_c,
        offset: b.get("offset").unwrap_or(0.0),
        backlash: width_of(&b),
        ssr: b.ssr,
    })
}

/// Iterations of each screening fit of a stage with an extra mode.
const SCREEN_ITER: usize = 20;

/// The fit of `req` (one of its effects an extra mode, attached as it says, on the
/// structure's values `plant`, with `offset` [N·m]) from the best of a grid
/// (`best_point`): the mode's mass split off the first arm mass `J_a1` (5, 10, 20, 40 %)
/// or a quarter of it added (the automatic start's grid), its frequency with the arm held
/// still from 3 to 60 Hz (9 steps), 5 % damping, the gearbox damper `d_g` at its value, a
/// third and a tenth of it;
/// the point of lowest output-error cost for each `d_g` fitted for `RACE_ITER` iterations
/// (smooth law), the lowest of them on to `SCREEN_ITER` (a race, as the automatic start's
/// over its linear starts: the three screening fits took 44 % of the CPU of a diagnosis of a
/// sticking joint, `jointid diagnose e1.csv e2.csv --validation e3.csv` on three 24,000-row
/// simulated captures, before). The split keeps the arm's inertia, which
/// the smaller structure fitted; the mass is a free axis because the mode's coupling, not
/// its frequency alone, shapes the motor's response (`jointid simulate --model three-mass`
/// hangs 5 % of the arm on the second spring); and the smaller structure's damper stands in
/// for the mode it lacks (on the three-mass with `F_c` = 0.06 N·m, seed 4: `d_g` 260
/// N·m·s/rad on the two-mass, truth 80), so at its value the grid prefers a mode that
/// stays out of the way, while a third of it puts the best point at 19 Hz with 5 % of
/// the arm (truth 17 Hz, 5 %), from where the fit reaches the truth. `req` as given
/// when no point of the grid can be simulated. The screening fits are a start: the smooth
/// law's minimum without covariance, whatever `req` asks; the kept one is returned as it is
/// (the caller's final fit corrects and covers it).
pub fn fit_with_mode(
    est: &[IdData],
    req: &NlRequest,
    plant: &[f64],
    offset: f64,
) -> Result<NlFit, NlRunError> {
    let fit = |req: &NlRequest| identify_segments(est, req).map(|r| r.fit);
    let at = req
        .effects
        .iter()
        .position(|e| matches!(e, Effect::ExtraMode(_)));
    let (Some(data), Some(at)) = (est.iter().max_by_key(|d| d.len()), at) else {
        return fit(req);
    };
    let Effect::ExtraMode(mode) = req.effects[at] else {
        return fit(req);
    };
    let base = super::model_of(req, data);
    let dg = req.structure.param_names().iter().position(|n| *n == "d_g");
    let mut starts: Vec<NlRequest> = Vec::new();
    for dg_share in DAMPER_SHARES {
        let points = MODE_SHARES
            .iter()
            .flat_map(|&s| mode_frequencies().map(move |f| (dg_share, s, f)));
        let best = best_point(data, &base, at, (plant, dg, offset), mode, points);
        if let Some((_, p, m)) = best {
            let mut r = req.clone();
            r.effects[at] = Effect::ExtraMode(m);
            let model = super::model_of(&r, data);
            r.start = super::NlStart::Values(model.values(&p, offset, 0.0));
            r.options = NlOptions {
                max_iter: SCREEN_ITER,
                cov_lags: 0,
                exact_correction: false,
                smoothing_sigma: false,
                ..req.options.clone()
            };
            starts.push(r);
        }
    }
    if starts.is_empty() {
        return fit(req);
    }
    race(est, &starts, SCREEN_ITER)
}

/// A race, as the automatic start runs its linear starts: each of `starts` (not empty)
/// fitted for [`RACE_ITER`] iterations (independent: on the machine's threads, judged in
/// their order, the same choice on any number of threads), the lowest cost then on to
/// `total` iterations; the first failure when none fits.
fn race(est: &[IdData], starts: &[NlRequest], total: usize) -> Result<NlFit, NlRunError> {
    let fit = |req: &NlRequest| identify_segments(est, req).map(|r| r.fit);
    let short: Vec<NlRequest> = starts
        .iter()
        .map(|r| {
            let mut r = r.clone();
            r.options.max_iter = RACE_ITER;
            r
        })
        .collect();
    let mut kept: Option<(usize, NlFit)> = None;
    let mut first = None;
    for (i, r) in parallel(&short, machine_threads(), fit)
        .into_iter()
        .enumerate()
    {
        match r {
            Ok(f) if kept.as_ref().is_none_or(|(_, k)| f.ssr < k.ssr) => kept = Some((i, f)),
            Ok(_) => {}
            Err(e) => {
                first.get_or_insert(e);
            }
        }
    }
    match (kept, first) {
        (Some((_, f)), _) if f.termination != Termination::MaxIterations => Ok(f),
        (Some((i, f)), _) => {
            let r = continued(&starts[i], &f, total.saturating_sub(RACE_ITER));
            Ok(fit(&r).ok().filter(|g| g.ssr <= f.ssr).unwrap_or(f))
        }
        (None, Some(e)) => Err(e),
        (None, None) => Err(NlRunError::Estimation(super::NlError::NoRecord)),
    }
}

/// The fit of `req` (one of its effects an extra mode, attached as it says, on the
/// structure's values `plant`, with `offset` [N·m]) from a race over the grid of
/// [`fit_with_mode`]: every point of the grid costed on a piece of the longest record (its
/// first quarter, at least [`RACE_MIN_SAMPLES`]); its runners, the point of lowest cost of
/// each frequency and of each damper share (twelve at most), each fitted for [`RACE_ITER`]
/// iterations on the piece (on the machine's threads, judged in their order: the same
/// lead on any number of threads); the lead fitted for [`SCREEN_ITER`] iterations on all
/// records. A start, as [`fit_with_mode`]'s: the smooth law's minimum without covariance.
///
/// **Why the frequencies.** Before any fit, a mode in the band where it acts costs more
/// than one out of the way: the smaller structure has bent its values to stand in for the
/// mode it lacks. Bench case 10 of `benches/diagnose.rs` (the arm's second mass 4.3 % of
/// the arm, 22.7 Hz with the arm held still, the motor stuck on 93 % of the samples): on
/// the grown two-mass (`k_g` −14 %, `f_m` 14×, `F_c` −30 %) the grid's cost is 32.53 for a
/// mode at 60 Hz, 32.74 at 28 Hz, 36.1 at 19.5 Hz, so each damper share's best point is a
/// mode that changes nothing, and the fit from it ends with `F_c` −32 %. Fitted for five
/// iterations on a quarter of the record, the points at 19.5 and 28 Hz lead (7.44 against ≥
/// 7.56 for the others), and from either the fit reaches the truth's basin (`F_c` +1 %, the
/// mode at 22.8 Hz, the cost 31.23 against 32.0).
///
/// **Why one race on a piece.** The damper shares' points and the frequencies' points ran
/// as two races before, the first on all records, each with its own continuation, and the
/// loser's continuation was work thrown away. Judged alike, on the same piece after the
/// same iterations, one continuation serves: the `HARD=1 SMALL=1` bench of
/// `benches/diagnose.rs` gives the same answers, and the growth tests take a quarter less
/// time (`a_sticking_three_mass_joint_starts_from_the_structure_grown_in_the_time_domain`
/// 16.2 and 14.9 s before, 12.0 and 11.1 s after, runs alternated).
///
/// # Errors
/// As [`identify_segments`], when no runner could be fitted and `req` from its own start
/// fails too.
pub fn fit_with_mode_raced(
    est: &[IdData],
    req: &NlRequest,
    plant: &[f64],
    offset: f64,
) -> Result<NlFit, NlRunError> {
    let fit = |r: &NlRequest, on: &[IdData]| identify_segments(on, r).map(|r| r.fit);
    let at = req
        .effects
        .iter()
        .position(|e| matches!(e, Effect::ExtraMode(_)));
    let (Some(data), Some(at)) = (est.iter().max_by_key(|d| d.len()), at) else {
        return fit(req, est);
    };
    let Effect::ExtraMode(mode) = req.effects[at] else {
        return fit(req, est);
    };
    let n = (data.len() / 4).max(RACE_MIN_SAMPLES).min(data.len());
    let piece = [data.slice(0..n)];
    let base = super::model_of(req, data);
    let dg = req.structure.param_names().iter().position(|n| *n == "d_g");
    // the grid costed on the piece: for each frequency, each damper share's best mass
    let frequencies: Vec<f64> = mode_frequencies().collect();
    let grid = parallel(&frequencies, machine_threads(), |&f_hz| {
        DAMPER_SHARES.map(|d| {
            let points = MODE_SHARES.iter().map(move |&s| (d, s, f_hz));
            best_point(&piece[0], &base, at, (plant, dg, offset), mode, points)
        })
    });
    let lowest = |points: &mut dyn Iterator<Item = &Option<Point>>| {
        points
            .flatten()
            .fold(None::<&Point>, |m, p| match m {
                Some(m) if m.0 <= p.0 => Some(m),
                _ => Some(p),
            })
            .cloned()
    };
    let mut runners: Vec<Point> = Vec::new();
    let by_frequency = grid.iter().map(|row| lowest(&mut row.iter()));
    let by_damper = (0..DAMPER_SHARES.len()).map(|i| lowest(&mut grid.iter().map(|row| &row[i])));
    for p in by_frequency.chain(by_damper).flatten() {
        if !runners.iter().any(|r| r.1 == p.1 && r.2 == p.2) {
            runners.push(p);
        }
    }
    let screening = NlOptions {
        cov_lags: 0,
        exact_correction: false,
        smoothing_sigma: false,
        ..req.options.clone()
    };
    let short: Vec<NlRequest> = runners
        .iter()
        .map(|(_, p, m)| {
            let mut r = req.clone();
            r.effects[at] = Effect::ExtraMode(*m);
            r.start = super::NlStart::Values(super::model_of(&r, data).values(p, offset, 0.0));
            r.options = NlOptions {
                max_iter: RACE_ITER,
                ..screening.clone()
            };
            r
        })
        .collect();
    let mut lead: Option<NlFit> = None;
    for f in parallel(&short, machine_threads(), |r| fit(r, &piece))
        .into_iter()
        .flatten()
    {
        if lead.as_ref().is_none_or(|l| f.ssr < l.ssr) {
            lead = Some(f);
        }
    }
    let Some(lead) = lead else {
        return fit(req, est);
    };
    let mut r = continued(req, &lead, SCREEN_ITER);
    r.options = NlOptions {
        max_iter: SCREEN_ITER,
        ..screening
    };
    fit(&r, est)
}

/// A point of the grid over an added mode ([`best_point`]): its output-error cost, the
/// structure's values and the mode.
type Point = (f64, Vec<f64>, ExtraMode);

/// Frequencies of the grid over an added mode (the arm held still) [Hz]: 3 to 60 Hz, 9
/// steps.
fn mode_frequencies() -> impl Iterator<Item = f64> {
    (0..9).map(|i| 3.0 * 20f64.powf(f64::from(i) / 8.0))
}

/// Masses of the grid over an added mode, as a share of the first arm mass, split off it
/// (`true`) or added (`false`).
const MODE_SHARES: [(f64, bool); 5] = [
    (0.05, true),
    (0.1, true),
    (0.2, true),
    (0.4, true),
    (0.25, false),
];

/// The gearbox damper `d_g` of the grid over an added mode, as a share of the smaller
/// structure's.
const DAMPER_SHARES: [f64; 3] = [1.0, 0.3, 0.1];

/// The point of lowest output-error cost on `data` among `points` (damper share, (mass
/// share, split), frequency [Hz]) of the grid over the mode `mode` at index `at` of the
/// effects of `base`, on the structure's values `plant` (`d_g` at index `dg`) with
/// `offset` [N·m]: its cost, its structure's values and its mode (5 % damping).
fn best_point(
    data: &IdData,
    base: &super::NlModel,
    at: usize,
    (plant, dg, offset): (&[f64], Option<usize>, f64),
    mode: ExtraMode,
    points: impl Iterator<Item = (f64, (f64, bool), f64)>,
) -> Option<Point> {
    let mut best: Option<Point> = None;
    for (dg_share, (share, split), f_hz) in points {
        let j = share * plant[1];
        let mut p = plant.to_vec();
        if split {
            p[1] -= j;
        }
        if let Some(i) = dg {
            p[i] *= dg_share;
        }
        let w = 2.0 * std::f64::consts::PI * f_hz;
        let k = j * w * w;
        let m = ExtraMode {
            j,
            k,
            d: 2.0 * 0.05 * (k * j).sqrt(),
            ..mode
        };
        let mut model = base.clone();
        model.effects[at] = Effect::ExtraMode(m);
        let values = model.values(&p, offset, 0.0);
        if let Some(c) = super::cost_at(data, &model, &values) {
            if best.as_ref().is_none_or(|(b, _, _)| c < *b) {
                best = Some((c, p, m));
            }
        }
    }
    best
}

/// Iterations of each runner of the race ([`fit_with_mode_raced`]).
const RACE_ITER: usize = 5;

/// Fewest samples of the piece the race runs on (2 s at 2 kHz).
const RACE_MIN_SAMPLES: usize = 4000;

/// `req` continued from a race's runner `fit` for `max_iter` iterations: its effects,
/// lag and values (its friction among them), nothing given.
fn continued(req: &NlRequest, fit: &NlFit, max_iter: usize) -> NlRequest {
    let mut r = req.clone();
    r.effects.clone_from(&fit.model.effects);
    r.tau_c = fit.model.tau_c;
    r.given = Vec::new();
    r.start = super::NlStart::Values(fit.values.clone());
    r.options.max_iter = max_iter;
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_structure_that_is_not_grown_is_named() {
        let opts = NlOptions::default();
        let e = grow(&[], Structure::FourMass, 1.0, 0.0, &opts).unwrap_err();
        assert!(
            matches!(e, GrowError::Structure(Structure::FourMass)),
            "{e:?}"
        );
        assert_eq!(e.to_string(), "no grown start for the four-mass");
        let e = grow_backlash(&[], Structure::Rigid, 1.0, (&[], 0.0), &opts).unwrap_err();
        assert_eq!(e.to_string(), "no grown backlash start for the rigid");
        let e = grow_backlash(&[], Structure::TwoMass, 1.0, (&[], 0.0), &opts).unwrap_err();
        assert!(matches!(e, GrowError::NoRecord), "{e:?}");
    }

    #[test]
    fn the_stick_share_counts_torques_below_the_level() {
        let d = IdData {
            ts: 1e-3,
            u: vec![0.01, -0.02, 0.05, -0.06, 0.0],
            y: vec![0.0; 5],
            r: None,
        };
        assert_eq!(stick_share(std::slice::from_ref(&d), 0.03), 0.6);
        assert_eq!(stick_share(&[d.clone(), d], 0.055), 0.8);
    }

    #[test]
    fn the_dead_zone_gain_falls_from_one_to_zero_as_the_gap_covers_the_deflection() {
        assert_eq!(dead_zone_gain(0.0, 1e-5), 1.0);
        assert_eq!(dead_zone_gain(1e-5, 1e-5), 0.0);
        assert_eq!(dead_zone_gain(2e-5, 1e-5), 0.0);
        // half the amplitude: 1 − (2/π)(π/6 + √3/4)
        let half =
            1.0 - 2.0 / std::f64::consts::PI * (std::f64::consts::FRAC_PI_6 + 0.75f64.sqrt() / 2.0);
        assert!((dead_zone_gain(0.5e-5, 1e-5) - half).abs() < 1e-12);
        let g: Vec<f64> = (0..10)
            .map(|i| dead_zone_gain(f64::from(i) * 1e-6, 1e-5))
            .collect();
        assert!(g.windows(2).all(|w| w[1] < w[0]), "{g:?}");
    }

    #[test]
    fn held_values_are_held_where_they_mean_the_same() {
        let fixed: Vec<(String, f64)> = [("J_m", 1e-3), ("J_a1", 11.0), ("k_a", 7e3), ("fc", 0.05)]
            .iter()
            .map(|(n, v)| (n.to_string(), *v))
            .collect();
        let names = |h: Vec<(String, f64)>| h.into_iter().map(|(n, _)| n).collect::<Vec<_>>();
        assert_eq!(
            names(held_in(&fixed, &["J_m", "k_g", "d_g", "f_m"], ["", "", ""])),
            ["J_m", "fc"]
        );
        assert_eq!(
            names(held_in(
                &fixed,
                &["J_m", "J_a1", "k_g", "d_g", "f_m"],
                ["J_a2", "k_a", "d_a"]
            )),
            ["J_m", "J_a1", "k", "fc"]
        );
    }
}
