//! Whether a fitted effect has a size: the test every stage's judgement of a gain asks
//! ([`super::fits::Fitted::counts`]), below both the fits and the candidate table.

use crate::ident::nonlinear::{NlFit, NlParam, Owner};
use crate::model::effects::Effect;

/// The parameters whose nought together makes an effect vanish (the model is its nominal
/// again): the friction's levels (kinetic, static of a Stribeck law, the negative side's of
/// an asymmetric law), backlash width, cubic stiffness, delay, ripple amplitude, an extra
/// mode's inertia. A mode whose inertia the data do not fix is no mode of theirs: its
/// body trades with the mass it hangs on, on a spring so stiff or so soft that its
/// resonance lies outside the band (new other-joints round, `JOINTS=1 HARD=1 ROUNDS=6`
/// case 40, a motor that sticks on 89 % of the samples: a mode of 1000 ± 2100 kg·m²
/// gained +0.8 ± 0.3 points on a nominal at 1 % and was named; every mode named right on
/// the bench rounds has its inertia within 4.2 %).
fn size_parameters(e: &Effect) -> &'static [&'static str] {
    match e {
        Effect::CoulombFriction(_) => &["fc", "fs", "fc_neg"],
        Effect::Backlash(_) => &["width"],
        Effect::NonlinearStiffness(_) => &["k3"],
        Effect::TimeDelay(_) => &["samples"],
        Effect::TorqueRipple(_) => &["amplitude"],
        Effect::ExtraMode(_) => &["j"],
    }
}

/// The effects of `fit` every fitted size of which ([`size_parameters`]) came out on its
/// lower bound or within two standard deviations of nought (exactly nought where the
/// deviation is unknown), as `name size = value ± std unit`: the same two standard errors
/// the gains are judged by. A size on its lower bound is of no size whatever its deviation
/// says (bench, a none case: `fc` = 2.0e-7 ± 2.0e-13 N·m on the bound, the deviation
/// degenerate with the torque offset's). A Stribeck friction whose kinetic level is undetermined but
/// whose static level is not has a size (bench case, a parallel mode with friction that
/// sticks 56 % of the time: `fc` 2.1e-2 ± 4.2e-2 N·m, `fs` 3.9e-2 ± 1.3e-3 N·m, +25.6
/// points).
///
/// A transport delay trades against the current-loop lag (below the resonances the two
/// shift the phase alike), so its deviation in a time-domain fit measures how the phase is
/// shared between them, not whether a delay is there. Where the excited lines show one
/// (`delay_shown`: the structure's frequency-domain fit with the delay free against the one
/// with the lag alone, a likelihood-ratio test with the lag refitted,
/// [`crate::ident::nonlinear::DelayLines`]), the delay is of no size only on its lower
/// bound or at exactly nought (hard bench case 36, a stiffening spring behind a delay: the
/// pair refined in the loop put the delay at 3.5 ± 108 samples, trading with the lag, and
/// closes 6.7 points of the gap more than the spring alone; the lines' drop was 182 against
/// a 99 % point of 8).
pub(super) fn vanished_effects(fit: &NlFit, delay_shown: bool) -> Vec<String> {
    vanished(fit, delay_shown)
        .into_iter()
        .map(|i| {
            let e = &fit.model.effects[i];
            let said: Vec<String> = sizes_of(fit, i, e)
                .iter()
                .map(|p| format!("{} = {:.3e} ± {:.1e} {}", p.name, p.value, p.std, p.unit))
                .collect();
            format!("{} {}", e.name(), said.join(", "))
        })
        .collect()
}

/// The indices of the effects of `fit` that vanished ([`vanished_effects`]).
pub(super) fn vanished(fit: &NlFit, delay_shown: bool) -> Vec<usize> {
    let nought = |p: &NlParam, e: &Effect| {
        if on_nought_bound(p, e) {
            true
        } else if delay_shown && matches!(e, Effect::TimeDelay(_)) {
            p.value == 0.0
        } else if p.std.is_finite() && p.std > 0.0 {
            p.value.abs() <= 2.0 * p.std
        } else {
            p.value == 0.0
        }
    };
    fit.model
        .effects
        .iter()
        .enumerate()
        .filter_map(|(i, e)| {
            let sizes = sizes_of(fit, i, e);
            (!sizes.is_empty() && sizes.iter().all(|p| nought(p, e))).then_some(i)
        })
        .collect()
}

/// Whether every effect of `fit` came out exactly of no size: each of its sizes
/// ([`size_parameters`]) nought or on its lower bound. Such a fit is the nominal model
/// itself, refitted; an effect merely within its deviations of nought is not (bench case 36:
/// a 3.5-sample delay ± 108, its deviation spread by the current-loop lag it trades
/// against, gained 1.4 real points).
pub(super) fn exactly_of_no_size(fit: &NlFit) -> bool {
    fit.model.effects.iter().enumerate().all(|(i, e)| {
        let sizes = sizes_of(fit, i, e);
        !sizes.is_empty()
            && sizes
                .iter()
                .all(|p| on_nought_bound(p, e) || p.value == 0.0)
    })
}

/// Whether the size `p` of `e` lies on a lower bound that is nought: every size but the
/// ripple's amplitude, which is signed (`−A sin(nθ + φ)` is `A sin(nθ + φ + π)`), so that its
/// lower bound is the largest ripple the search allows, not none (Silverbox, measured: a
/// ripple fitted at −0.10 on that bound scored 19.9 points below the nominal and was taken
/// for the nominal refitted, which raised the significance floor to 19.9 points).
fn on_nought_bound(p: &NlParam, e: &Effect) -> bool {
    p.at_lower && !matches!(e, Effect::TorqueRipple(_))
}

/// The fitted size parameters ([`size_parameters`]) of effect `i`, `e`, of `fit`.
fn sizes_of<'f>(fit: &'f NlFit, i: usize, e: &Effect) -> Vec<&'f NlParam> {
    fit.params
        .iter()
        .filter(|p| p.owner == Owner::Effect(i) && size_parameters(e).contains(&p.name))
        .collect()
}
