//! Stage 0, the inputs: the captures checked (count, length, rate, validation not the
//! estimation's own samples), the candidates that apply to the structure, and the measured
//! side of every validation segment, which every later stage scores against.

use crate::data::{excited_band_top, Dataset, IdData};
use crate::model::effects::Effect;
use crate::model::spec::Structure;

use super::metric::Measured;
use super::{DiagnoseError, DiagnoseRequest};

/// The checked inputs of one diagnosis.
pub(super) struct Records<'a> {
    /// every estimation capture as its segments (the fits take the first)
    pub est: &'a [&'a [Dataset]],
    /// the validation capture's segments
    pub val_segs: &'a [Dataset],
    /// the first estimation capture's records, the fits' experiments
    pub est_data: Vec<IdData>,
    /// the validation records
    pub val_data: Vec<IdData>,
    /// the measured side of each validation record
    pub parts: Vec<Measured>,
    /// the measured side of them joined (one segment: itself)
    pub measured: Measured,
    /// the validation record the location and the series read: the capture itself, or
    /// its segments' scored ranges joined (then scored from its first sample)
    pub val: Dataset,
    /// the candidates that apply to the structure
    pub candidates: Vec<Effect>,
    /// sample period [s]
    pub ts: f64,
}

/// The inputs of [`super::diagnose_segments`] checked and prepared; a note for the
/// candidates that do not apply to the structure goes into `warnings`.
pub(super) fn prepare<'a>(
    est: &'a [&'a [Dataset]],
    val: &'a [Dataset],
    req: &DiagnoseRequest,
    warnings: &mut Vec<String>,
) -> Result<Records<'a>, DiagnoseError> {
    let o = &req.options;
    if est.is_empty() || est.len() > 2 {
        return Err(DiagnoseError::EstimationCount(est.len()));
    }
    if est.iter().any(|c| c.is_empty()) {
        return Err(DiagnoseError::NoEstimationSegment);
    }
    let Some(val0) = val.first() else {
        return Err(DiagnoseError::NoValidationSegment);
    };
    // effects on the gearbox spring are no candidates of a rigid model
    let (candidates, inapplicable): (Vec<Effect>, Vec<Effect>) = req
        .candidates
        .iter()
        .partition(|e| req.structure != Structure::Rigid || !e.acts_on_gearbox());
    if candidates.is_empty() {
        return Err(DiagnoseError::NoCandidate);
    }
    if !(req.r.is_finite() && req.r > 0.0) {
        return Err(DiagnoseError::GearRatio(req.r));
    }
    let ts = val0.data.ts;
    for ds in est.iter().flat_map(|c| c.iter()).chain(val) {
        ds.data.check(200).map_err(|source| DiagnoseError::Record {
            capture: ds.name.clone(),
            source,
        })?;
        if !crate::data::same_rate(ds.data.ts, ts) {
            return Err(DiagnoseError::RateMismatch {
                capture: ds.name.clone(),
                ts: ds.data.ts,
                val_ts: ts,
            });
        }
    }
    // validation on the estimation record itself measures nothing the fits did not see:
    // every candidate's extra parameters gain there, so it would name effects on any joint
    for e in est.iter().flat_map(|c| c.iter()) {
        if let Some(v) = val
            .iter()
            .find(|v| v.data.u == e.data.u && v.data.y == e.data.y)
        {
            return Err(DiagnoseError::SameSamples {
                validation: v.name.clone(),
                estimation: e.name.clone(),
            });
        }
    }
    let parts: Vec<Measured> = val.iter().map(|d| o.measured(&d.data)).collect();
    let measured = Measured::joined(&parts);
    let joined = if let [one] = val {
        one.clone()
    } else {
        let mut data = IdData {
            ts,
            u: Vec::new(),
            y: Vec::new(),
            r: None,
        };
        for (d, m) in val.iter().zip(&parts) {
            data.u.extend_from_slice(&d.data.u[m.skip..]);
            data.y.extend_from_slice(&d.data.y[m.skip..]);
        }
        Dataset {
            name: val0.name.clone(),
            data,
            t0: val0.t0,
            excitation: None,
            meta: val0.meta.clone(),
        }
    };
    if !inapplicable.is_empty() {
        warnings.push(format!(
            "{}: not candidates of a rigid model (they act on the gearbox spring)",
            inapplicable
                .iter()
                .map(|e| e.name())
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    Ok(Records {
        est,
        val_segs: val,
        est_data: est[0].iter().map(|d| d.data.clone()).collect(),
        val_data: val.iter().map(|d| d.data.clone()).collect(),
        parts,
        measured,
        val: joined,
        candidates,
        ts,
    })
}

/// The request whose fits low-pass their residual at the top of the excited band of the
/// first estimation capture ([`super::DiagnoseOptions::band_limited`]); the request as it
/// is when that is off or the capture does not say its excitation.
pub(super) fn fit_options(req: &DiagnoseRequest, rec: &Records<'_>) -> DiagnoseRequest {
    let mut out = req.clone();
    if req.options.band_limited {
        if let Some(top) = rec.est[0]
            .iter()
            .find_map(|ds| ds.excitation)
            .and_then(|c| excited_band_top(&c, rec.ts))
        {
            out.options.nl.lowpass_hz = top;
        }
    }
    out
}

/// The options of a fit of the nominal with `effects`: the diagnosis's, without the band's
/// low-pass ([`crate::ident::nonlinear::NlOptions::lowpass_hz`]) when an effect makes the
/// joint nonlinear, unless the motor sticks (`sticks`, the share of the samples,
/// [`super::starts::LinearStarts::sticks`]).
///
/// Above the excited band a linear model has nothing to fit but the loop's reaction to the
/// encoder's quantisation, which biases it; a nonlinear effect has its own distortion
/// there, the signature the fit needs (measured on bench cases, the low-pass on every fit:
/// a parallel mode under stick-slip friction closed 4.7 points less of the gap, and a
/// chaotic stiffening spring's `k3` ended +43 % in open loop where it had been named in
/// the loop within 0.1 %; other joints bench `JOINTS=1 HARD=1` case 6, a chaotic spring
/// behind a 1.7-sample delay: the delay single at 4.5 samples band-limited, 1.7 over the
/// whole band, and the pair refined in the loop 3.2 points short of the true model's).
///
/// Where the motor sticks, the measured angle rests within an encoder count for long
/// stretches: its quantisation error is no longer white but coloured, and the loop's
/// reaction to it, in the measured torque above the band, is correlated with the angle's
/// error, which draws an output-error fit from the measured torque away from the joint.
/// Every fit is band-limited there (hard bench `HARD=1 SMALL=1` case 20, Stribeck friction
/// at 0.011 rad RMS, the motor stuck on 63 % of the samples, a 16384-count encoder: over
/// the whole band the friction's fit put the current-loop lag, 0.43 ms, on its bound and
/// left it out, 76.0 % on validation against the true model's 81.7 %; band-limited, the lag
/// at 0.49 ms, `F_c` +0.6 % and 81.65 %).
pub(super) fn nl_options(
    o: &super::DiagnoseOptions,
    effects: &[Effect],
    sticks: Option<f64>,
) -> crate::ident::nonlinear::NlOptions {
    let mut nl = o.nl.clone();
    if sticks.is_none() && !effects.iter().all(Effect::is_linear) {
        nl.lowpass_hz = 0.0;
    }
    nl
}

/// The captures with their input taken as samples of a band-limited signal, not as values
/// held over each sample interval ([`IdData::input_as_sampled`]). A robot's torque reference is held by the drive until the next sample, and the
/// models integrate it so; a measured analog input (a voltage, a force sensor) moves
/// between its samples, and holding it delays it by half a sample, a phase lag no lag of
/// the model can take back. A nominal whose current-loop lag comes out nought (left out or
/// on its lower bound) shows that the data ask for less delay than holding adds; the
/// nominal is then fitted again on these captures, and the diagnosis goes on from it when
/// it scores higher on the estimation record ([`super::diagnose_segments`]). Silverbox
/// (measured, an electronic mass–spring–damper with a hardening spring, 610 Hz, excited
/// to 200 Hz), `fit --model grounded` on realisations 1–9 scored on realisation 10: 70.4 %
/// with the input held, 85.8 % with it so (85.2 % held at the interval means).
pub(super) struct SampledInput {
    /// every estimation capture's segments
    pub est: Vec<Vec<Dataset>>,
    /// the validation capture's segments
    pub val: Vec<Dataset>,
}

impl SampledInput {
    /// `est` and `val` with their inputs so.
    pub fn of(est: &[&[Dataset]], val: &[Dataset]) -> SampledInput {
        let each = |c: &[Dataset]| c.iter().map(Dataset::input_as_sampled).collect::<Vec<_>>();
        SampledInput {
            est: est.iter().map(|c| each(c)).collect(),
            val: each(val),
        }
    }

    /// The note that says the diagnosis took the input so, with the nominal's in-sample
    /// gap metric held (`held`) and so (`sampled`) [%].
    pub fn note(held: f64, sampled: f64) -> String {
        crate::ident::nonlinear::sampled_input_note(
            "the nominal's in-sample gap metric",
            held,
            sampled,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The diagnosis's captures, estimation and validation, take their input as sampled
    /// ([`IdData::input_as_sampled`]: a ramp held at its intervals' midpoints); the output
    /// and everything else as they were.
    #[test]
    fn a_sampled_input_is_taken_so_in_every_capture() {
        let d = Dataset {
            name: "ramp".into(),
            data: IdData {
                ts: 0.5,
                u: vec![0.0, 1.0, 2.0, 3.0, 4.0],
                y: vec![1.0, 2.0, 3.0, 4.0, 5.0],
                r: None,
            },
            t0: 0.0,
            excitation: None,
            meta: Default::default(),
        };
        let s = SampledInput::of(&[std::slice::from_ref(&d)], std::slice::from_ref(&d));
        for c in s.est.iter().flatten().chain(&s.val) {
            assert_eq!(c.data.u[1..3], [1.5, 2.5]);
            assert_eq!(
                (&c.data.y, c.data.ts, &c.name),
                (&d.data.y, d.data.ts, &d.name)
            );
        }
    }
}
