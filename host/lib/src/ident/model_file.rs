//! The model file (`jointid fit --save`, read by `jointid validate`): the discrete
//! matrices at the sample interval of the model (the capture rate for a physical model
//! fitted with decimation), the preparation applied to the data (decimation,
//! detrending), the physical parameters with their standard deviations and units, and
//! for the Coulomb rigid model its four parameters: all that is needed to simulate the
//! model again on new data. Format `jointid-model/4`; formats 1, 2 and 3 are still read.
//! Format 3 adds the optional `nonlinear` section ([`SavedNonlinear`]): a physical model
//! with effects fitted by [`crate::ident::nonlinear`], which `validate` simulates with the
//! simulator's exact laws and `simulate --model-file` runs again (its matrices are empty).
//! Format 4 adds the [`ModelSpec`] the fit was asked for ([`SavedModel::spec`]; for the
//! older formats it is read from the family name, the friction and the nonlinear section).
//!
//! This module maps a [`Fitted`] to its file contents and back; the command line reads
//! and writes the JSON text.
// Units in brackets (`[s]`, `[Hz]`, `[%]`) are not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

use std::collections::BTreeMap;

use nalgebra::{DMatrix, DVector, RowDVector};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::data::InputTaken;
use crate::data::Prep;
use crate::ident::fit::{
    output_name, param_map, FitMetric, FitOutcome, Fitted, FittedModel, ParamJson, RigidFriction,
    NL_FIT_NAME, VELOCITY_FIT_NAME,
};
use crate::ident::grey_box::{Output, PhysParam};
use crate::ident::lm::Termination;
use crate::ident::nonlinear::{simulate_args, NlFit, NlModel, NlParam, Owner};
use crate::ident::sml::PERIODIC_FIT_NAME;
use crate::ident::ss::StateSpace;
use crate::model::effects::Effect;
use crate::model::params::unit_of;
use crate::model::spec::{Family, ModelSpec, Structure};

impl FitOutcome {
    /// The model file of `jointid fit --save`, the records prepared with `prep`: the
    /// linear model with its headline FIT on the estimation record (the periodic FIT named
    /// when it is the one reported, so that `validate` reports it too), or the model with
    /// effects with its velocity FIT ([`NL_FIT_NAME`]).
    pub fn to_saved(&self, prep: Prep) -> SavedModel {
        let mut saved = match &self.model {
            FittedModel::Linear(l) => {
                let mut saved = l.fitted.to_saved(prep, &self.name, self.fit.estimation);
                if self.fit.name == PERIODIC_FIT_NAME {
                    saved.fit_name = Some(PERIODIC_FIT_NAME.to_string());
                }
                saved
            }
            FittedModel::Nonlinear(n) => {
                let r = &n.run.result;
                SavedModel::from_nonlinear(
                    &r.fit,
                    self.ts,
                    &r.method,
                    &self.name,
                    self.fit.estimation,
                    NL_FIT_NAME,
                    r.options.highpass_hz,
                )
            }
        };
        saved.input = self.input;
        saved
    }
}

impl Fitted {
    /// The model file.
    pub fn to_saved(&self, prep: Prep, source: &str, fit_estimation: f64) -> SavedModel {
        let n = self.model.order();
        SavedModel {
            format: MODEL_FORMAT.into(),
            model: self.spec.name(),
            method: self.method.clone(),
            output: output_name(self.output).into(),
            ts: self.ts,
            prep,
            a: (0..n)
                .map(|i| (0..n).map(|j| self.model.a[(i, j)]).collect())
                .collect(),
            b: self.model.b.iter().copied().collect(),
            c: self.model.c.iter().copied().collect(),
            d: self.model.d,
            parameters: param_map(&self.params),
            friction: self.friction,
            decimate_output: self.decimate,
            input_hold: None,
            fit_estimation,
            fit_name: (self.fit_metric == FitMetric::Velocity).then(|| VELOCITY_FIT_NAME.into()),
            source: source.into(),
            input: InputTaken::Held,
            nonlinear: None,
            spec: Some(self.spec.clone()),
        }
    }
}

/// format tag of [`SavedModel`] (format 2: physical models at the capture
/// rate, [`SavedModel::decimate_output`]; format 3: the optional
/// [`SavedModel::nonlinear`] section; format 4: [`SavedModel::spec`])
pub const MODEL_FORMAT: &str = "jointid-model/4";
/// format 3, still read (a file of format 4 without `spec`)
pub const MODEL_FORMAT_3: &str = "jointid-model/3";
/// format 2, still read (a linear model file of format 3 without `nonlinear`)
pub const MODEL_FORMAT_2: &str = "jointid-model/2";
/// the earlier format, still read (its `interval_mean` hold excepted)
pub const MODEL_FORMAT_1: &str = "jointid-model/1";

fn one() -> usize {
    1
}

/// Everything needed to simulate a fitted model again (`--save`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SavedModel {
    /// [`MODEL_FORMAT`]
    pub format: String,
    /// model family (`black-box:11`, `three-mass`, ...)
    pub model: String,
    /// how it was estimated
    pub method: String,
    /// output signal (`angle` or `velocity`)
    pub output: String,
    /// sample interval of the model [s] (after decimation)
    pub ts: f64,
    /// preparation of raw data
    pub prep: Prep,
    /// `A`, row by row (empty for a nonlinear model)
    #[serde(default)]
    pub a: Vec<Vec<f64>>,
    /// `B`
    #[serde(default)]
    pub b: Vec<f64>,
    /// `C`
    #[serde(default)]
    pub c: Vec<f64>,
    /// `D`
    #[serde(default)]
    pub d: f64,
    /// physical parameters (empty for a black box)
    pub parameters: BTreeMap<String, ParamJson>,
    /// nonlinear rigid model (Coulomb friction), simulated instead of `A, B, C, D`
    pub friction: Option<RigidFriction>,
    /// decimation between the model's rate and the prepared data (1: the
    /// model runs at `ts` = the prepared data's interval; `q`: a physical
    /// model at the capture rate whose output is decimated, see
    /// [`FitData`]); absent in format-1 files: 1
    #[serde(default = "one")]
    pub decimate_output: usize,
    /// format 1 only: the held input of a physical model (`zoh` or
    /// `interval_mean`); format 2 never writes it
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input_hold: Option<String>,
    /// FIT on the estimation data [%] (toolbox definition)
    pub fit_estimation: f64,
    /// which FIT `fit_estimation` is, when not the toolbox's (a model fitted
    /// in the frequency domain: the periodic steady-state FIT,
    /// [`crate::ident::sml::PERIODIC_FIT_NAME`]; a model fitted on the motor
    /// velocity: [`crate::ident::fit::VELOCITY_FIT_NAME`]); `validate` reports the
    /// same one (the periodic one on periodic data)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fit_name: Option<String>,
    /// estimation data file
    pub source: String,
    /// how the model reads its input samples ([`InputTaken`]): `validate` reads its data
    /// so (absent: held, as every file before it)
    #[serde(default, skip_serializing_if = "InputTaken::is_held")]
    pub input: InputTaken,
    /// format 3: a physical model with effects ([`crate::ident::nonlinear`]), simulated
    /// with the simulator's exact laws instead of `A, B, C, D`
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nonlinear: Option<SavedNonlinear>,
    /// format 4: the model's description: family, effects with their fitted values,
    /// Coulomb friction of the rigid model, lag and delay when held (absent before:
    /// [`SavedModel::spec`] reads it from `model`, `friction` and `nonlinear`)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spec: Option<ModelSpec>,
}

/// Why a model file cannot be read back ([`SavedModel::to_fitted`]).
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum ModelFileError {
    /// a format this build does not read
    #[error(
        "model format `{format}` is none of `{MODEL_FORMAT}`, `{MODEL_FORMAT_3}`, `{MODEL_FORMAT_2}`, `{MODEL_FORMAT_1}`"
    )]
    Format {
        /// the file's format tag
        format: String,
    },
    /// format 1's input hold other than zero-order
    #[error(
        "input hold `{hold}` of format 1 is no longer supported: fit the model again \
         (physical models are now refined at the capture rate)"
    )]
    InputHold {
        /// the hold named in the file
        hold: String,
    },
    /// the output decimation disagrees with the preparation's
    #[error("output decimation {output} does not match the preparation's decimation {prep}")]
    Decimation {
        /// `decimate_output`
        output: usize,
        /// `prep.decimate`
        prep: usize,
    },
    /// the matrices do not have the sizes of one state space
    #[error("model matrices are inconsistent: A {a} rows, B {b}, C {c}")]
    Matrices {
        /// rows of A
        a: usize,
        /// entries of B
        b: usize,
        /// entries of C
        c: usize,
    },
    /// a sample interval that is not positive
    #[error("sample interval {ts} s")]
    Interval {
        /// the interval [s]
        ts: f64,
    },
    /// the model family does not parse
    #[error("{0}")]
    Model(#[from] crate::model::spec::FamilyParseError),
    /// an output other than `angle` or `velocity`
    #[error("unknown output `{output}`")]
    Output {
        /// the output named in the file
        output: String,
    },
    /// the nonlinear section is inconsistent (or asked of a linear model)
    #[error("nonlinear model: {0}")]
    Nonlinear(String),
}

impl SavedModel {
    /// The format tag is one this build reads.
    ///
    /// # Errors
    /// [`ModelFileError::Format`].
    pub fn check_format(&self) -> Result<(), ModelFileError> {
        if [MODEL_FORMAT, MODEL_FORMAT_3, MODEL_FORMAT_2, MODEL_FORMAT_1]
            .contains(&self.format.as_str())
        {
            Ok(())
        } else {
            Err(ModelFileError::Format {
                format: self.format.clone(),
            })
        }
    }

    /// The model's description: format 4 stores it; for formats 1–3 it is the
    /// family named in `model` (the structure of the `nonlinear` section and its effects
    /// for a model with effects), Coulomb friction when `friction` is there, lag and
    /// delay free.
    ///
    /// # Errors
    /// [`ModelFileError::Model`] when the family does not parse;
    /// [`ModelFileError::Nonlinear`] when the spec and the `nonlinear` section disagree.
    pub fn spec(&self) -> Result<ModelSpec, ModelFileError> {
        self.check_format()?;
        let spec = match (&self.spec, &self.nonlinear) {
            (Some(spec), _) => spec.clone(),
            (None, Some(nl)) => {
                let structure = parse_structure(&nl.structure)?;
                ModelSpec {
                    effects: Some(nl.effects.clone()),
                    ..ModelSpec::linear(Family::Physical(structure))
                }
            }
            (None, None) => ModelSpec {
                coulomb: self.friction.is_some(),
                ..ModelSpec::linear(self.model.parse().map_err(ModelFileError::Model)?)
            },
        };
        if spec.nonlinear() != self.nonlinear.is_some() {
            return Err(ModelFileError::Nonlinear(format!(
                "the spec `{}` {} effects but the file {} a nonlinear section",
                spec.name(),
                if spec.nonlinear() { "has" } else { "has no" },
                if self.nonlinear.is_some() {
                    "has"
                } else {
                    "has no"
                },
            )));
        }
        Ok(spec)
    }

    /// The model back as a [`Fitted`] (without continuous model).
    ///
    /// # Errors
    /// [`ModelFileError`] when the file is inconsistent.
    pub fn to_fitted(&self) -> Result<Fitted, ModelFileError> {
        self.check_format()?;
        if self.nonlinear.is_some() {
            return Err(ModelFileError::Nonlinear(
                "no state-space form; it is simulated with the exact laws".into(),
            ));
        }
        match self.input_hold.as_deref() {
            None | Some("zoh") => {}
            Some(h) => {
                return Err(ModelFileError::InputHold {
                    hold: h.to_string(),
                })
            }
        }
        if self.decimate_output == 0
            || self.decimate_output > 1 && self.prep.decimate != self.decimate_output
        {
            return Err(ModelFileError::Decimation {
                output: self.decimate_output,
                prep: self.prep.decimate,
            });
        }
        let n = self.a.len();
        if self.b.len() != n || self.c.len() != n || self.a.iter().any(|r| r.len() != n) {
            return Err(ModelFileError::Matrices {
                a: n,
                b: self.b.len(),
                c: self.c.len(),
            });
        }
        if self.ts.is_nan() || self.ts <= 0.0 {
            return Err(ModelFileError::Interval { ts: self.ts });
        }
        let spec = self.spec()?;
        let output = match self.output.as_str() {
            "angle" => Output::Angle,
            "velocity" => Output::Velocity,
            o => {
                return Err(ModelFileError::Output {
                    output: o.to_string(),
                })
            }
        };
        let a = DMatrix::from_fn(n, n, |i, j| self.a[i][j]);
        let model = StateSpace::new(
            a,
            DVector::from_vec(self.b.clone()),
            RowDVector::from_vec(self.c.clone()),
            self.d,
            self.ts,
        );
        let params = self
            .parameters
            .iter()
            .map(|(k, p)| PhysParam {
                name: k.clone(),
                value: p.value,
                std: p.std,
                unit: unit_of(k),
            })
            .collect();
        Ok(Fitted {
            spec,
            output,
            ts: self.ts,
            model,
            continuous: None,
            params,
            friction: self.friction,
            warnings: Vec::new(),
            method: self.method.clone(),
            decimate: self.decimate_output,
            fit_metric: if self.fit_name.as_deref() == Some(VELOCITY_FIT_NAME) {
                FitMetric::Velocity
            } else {
                FitMetric::Output
            },
        })
    }
}

/// A physical model with effects ([`crate::ident::nonlinear`]) in the model file (format
/// 3). The structure's values, `tau_c` and `offset` with their σ are in
/// [`SavedModel::parameters`]; the effects in the simulator's own form.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SavedNonlinear {
    /// mechanical structure (`two-mass`, ...)
    pub structure: String,
    /// gear ratio `r` [-]
    pub r: f64,
    /// current-loop lag `tau_c` [s]; 0: none
    pub tau_c: f64,
    /// constant torque offset on the motor [N·m]
    pub offset: f64,
    /// the effects with their fitted values, as the simulator reads them
    /// ([`crate::model::effects::Effect`]'s serde form)
    pub effects: Vec<Effect>,
    /// the estimated keys of each effect (same order) with σ and unit
    pub effect_parameters: Vec<BTreeMap<String, ParamJson>>,
    /// each effect as `jointid simulate --effect` spells it
    pub effect_specs: Vec<String>,
    /// smoothing velocity of the estimator's Coulomb law [rad/s]
    pub v_eps: f64,
    /// rounding of the estimator's smooth dead zone [rad]
    pub dz_eps: f64,
    /// RK4 steps per sample of the estimator
    pub substeps: usize,
    /// cut-off of the velocity FIT's high-pass prefilter [Hz]
    pub highpass_hz: f64,
    /// the `jointid simulate` arguments that rebuild the plant and effects
    pub simulate_args: Vec<String>,
}

/// The structure named `label` in a nonlinear section.
fn parse_structure(label: &str) -> Result<Structure, ModelFileError> {
    Structure::ALL
        .into_iter()
        .find(|s| s.label() == label)
        .ok_or_else(|| ModelFileError::Nonlinear(format!("unknown structure `{label}`")))
}

/// One estimated parameter as JSON.
fn param_json(p: &NlParam) -> ParamJson {
    ParamJson {
        value: p.value,
        std: p.std,
        unit: p.unit.into(),
    }
}

impl SavedModel {
    /// The model file of a nonlinear fit on data sampled every `ts` [s] from `source`,
    /// `fit_estimation` the velocity FIT on the estimation data [%] (`fit_name` names it),
    /// `highpass_hz` that FIT's prefilter.
    pub fn from_nonlinear(
        fit: &NlFit,
        ts: f64,
        method: &str,
        source: &str,
        fit_estimation: f64,
        fit_name: &str,
        highpass_hz: f64,
    ) -> SavedModel {
        let m = &fit.model;
        let parameters = fit
            .params
            .iter()
            .filter(|p| matches!(p.owner, Owner::Plant | Owner::CurrentLoop | Owner::Offset))
            .map(|p| (p.name.to_string(), param_json(p)))
            .collect();
        let effect_parameters = (0..m.effects.len())
            .map(|i| {
                fit.params
                    .iter()
                    .filter(|p| p.owner == Owner::Effect(i))
                    .map(|p| (p.name.to_string(), param_json(p)))
                    .collect()
            })
            .collect();
        let spec = ModelSpec {
            effects: Some(m.effects.clone()),
            ..ModelSpec::linear(Family::Physical(m.structure))
        };
        SavedModel {
            format: MODEL_FORMAT.into(),
            model: spec.name(),
            method: method.into(),
            output: "angle".into(),
            ts,
            prep: Prep::default(),
            a: Vec::new(),
            b: Vec::new(),
            c: Vec::new(),
            d: 0.0,
            parameters,
            friction: None,
            decimate_output: 1,
            input_hold: None,
            fit_estimation,
            fit_name: Some(fit_name.into()),
            source: source.into(),
            input: InputTaken::Held,
            nonlinear: Some(SavedNonlinear {
                structure: m.structure.label().into(),
                r: m.r,
                tau_c: m.tau_c,
                offset: fit.get("offset").unwrap_or(0.0),
                effects: m.effects.clone(),
                effect_parameters,
                effect_specs: m.effects.iter().map(|e| e.to_string()).collect(),
                v_eps: m.v_eps,
                dz_eps: m.dz_eps,
                substeps: m.substeps,
                highpass_hz,
                simulate_args: simulate_args(fit),
            }),
            spec: Some(spec),
        }
    }

    /// The nonlinear model back as an [`NlFit`] (the fit's statistics empty, σ as saved),
    /// ready for [`crate::ident::nonlinear::validate`].
    ///
    /// # Errors
    /// [`ModelFileError`] when the file has no nonlinear section or it is inconsistent.
    pub fn to_nonlinear(&self) -> Result<NlFit, ModelFileError> {
        self.check_format()?;
        let bad = |m: String| ModelFileError::Nonlinear(m);
        let nl = self
            .nonlinear
            .as_ref()
            .ok_or_else(|| bad("the file holds a linear model".into()))?;
        let structure = parse_structure(&nl.structure)?;
        let plant = structure
            .param_names()
            .iter()
            .map(|n| {
                self.parameters
                    .get(*n)
                    .map(|p| p.value)
                    .filter(|v| v.is_finite() && *v >= 0.0)
                    .ok_or_else(|| bad(format!("`{n}` missing or not a finite value ≥ 0")))
            })
            .collect::<Result<Vec<f64>, _>>()?;
        for e in &nl.effects {
            e.check()
                .map_err(|m| bad(format!("effect `{}`: {m}", e.name())))?;
        }
        let finite = [nl.r, nl.tau_c, nl.offset, nl.v_eps, nl.dz_eps];
        if finite.iter().any(|v| !v.is_finite()) || nl.r <= 0.0 || nl.tau_c < 0.0 {
            return Err(bad(format!(
                "r = {}, tau_c = {} s, offset = {} N·m: need finite values, r > 0, tau_c ≥ 0",
                nl.r, nl.tau_c, nl.offset
            )));
        }
        if nl.effect_parameters.len() != nl.effects.len() {
            return Err(bad(format!(
                "{} effects but {} sets of effect parameters",
                nl.effects.len(),
                nl.effect_parameters.len()
            )));
        }
        let model = NlModel {
            structure,
            r: nl.r,
            effects: nl.effects.clone(),
            tau_c: nl.tau_c,
            v_eps: nl.v_eps,
            dz_eps: nl.dz_eps,
            substeps: nl.substeps.max(1),
        };
        let values = model.values(&plant, nl.offset, 0.0);
        let params = model
            .layout()
            .iter()
            .zip(&values)
            .map(|(d, &value)| {
                let saved = match d.owner {
                    Owner::Effect(i) => nl.effect_parameters[i].get(d.name),
                    _ => self.parameters.get(d.name),
                };
                NlParam {
                    name: d.name,
                    owner: d.owner,
                    value,
                    std: saved.map_or(0.0, |p| p.std),
                    unit: d.unit,
                    fixed: false,
                    at_bound: false,
                    at_lower: false,
                }
            })
            .collect();
        Ok(NlFit {
            model,
            plant,
            params,
            values,
            ssr: f64::NAN,
            lowpass_hz: 0.0,
            n_residuals: 0,
            iterations: 0,
            termination: Termination::CostConverged,
            fit_velocity_percent: self.fit_estimation,
            correlated: Vec::new(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ident::nonlinear::NlModel;
    use crate::model::effects::{CoulombFriction, NonlinearStiffness};

    /// a nonlinear fit as the engine returns it (values by hand)
    fn nl_fit() -> NlFit {
        nl_fit_with(vec![1e-3, 14.6, 1.3e5, 80.0, 2e-3])
    }

    /// as [`nl_fit`] with the two-mass values `plant`
    fn nl_fit_with(plant: Vec<f64>) -> NlFit {
        let model = NlModel {
            structure: Structure::TwoMass,
            r: 1.0 / 118.0,
            effects: vec![
                Effect::NonlinearStiffness(NonlinearStiffness { k3: 1.6e11 }),
                Effect::CoulombFriction(CoulombFriction {
                    fc: 0.1,
                    fs: 0.1,
                    ..CoulombFriction::default()
                }),
            ],
            tau_c: 4e-4,
            v_eps: 0.05,
            dz_eps: 1e-7,
            substeps: 1,
        };
        crate::test_support::nl_fit(model, plant)
    }

    #[test]
    fn nonlinear_model_file_round_trips_and_has_no_state_space() {
        let fit = nl_fit();
        let saved = SavedModel::from_nonlinear(&fit, 5e-4, "by hand", "est.csv", 96.5, "v", 5.0);
        assert_eq!(saved.format, MODEL_FORMAT);
        assert_eq!(saved.model, "two-mass+nonlinear_stiffness+coulomb_friction");
        let text = serde_json::to_string(&saved).unwrap();
        // the effects in the simulator's own form
        assert!(text.contains(r#""effect":"nonlinear_stiffness","k3":160000000000.0"#));
        let back: SavedModel = serde_json::from_str(&text).unwrap();
        let nl = back.to_nonlinear().unwrap();
        assert_eq!(nl.model, fit.model);
        assert_eq!(nl.plant, fit.plant);
        assert_eq!(
            nl.values[..nl.values.len() - 1],
            fit.values[..fit.values.len() - 1]
        );
        for (a, b) in nl.params.iter().zip(&fit.params) {
            if b.name != "v0" {
                assert_eq!((a.name, a.value, a.std), (b.name, b.value, b.std));
            }
        }
        let e = back.to_fitted().unwrap_err().to_string();
        assert!(e.contains("nonlinear"), "{e}");
        // the simulate arguments name every parameter of the simulator's two-mass
        let args = &back.nonlinear.as_ref().unwrap().simulate_args;
        assert_eq!(args[..2], ["--model", "two-mass"]);
        assert!(args.contains(&"k_g=130000".to_string()), "{args:?}");
        assert!(args.contains(&"J_a2=0".to_string()), "{args:?}");
        assert!(args
            .iter()
            .any(|a| a.starts_with("nonlinear_stiffness:k3=")));
    }

    #[test]
    fn a_model_file_reads_back_the_very_values_written() {
        // values as a fit leaves them (every bit used), not round decimals
        let mut x = 0.123_456_789_f64;
        for _ in 0..400 {
            let mut plant = nl_fit().plant;
            for p in plant.iter_mut() {
                x = (x * 3.987_654_321 + 0.314_159).fract();
                *p *= 1.0 + x;
            }
            let fit = nl_fit_with(plant);
            let saved = SavedModel::from_nonlinear(&fit, 5e-4, "", "", 0.0, "v", 5.0);
            let text = serde_json::to_string(&saved).unwrap();
            let back: SavedModel = serde_json::from_str(&text).unwrap();
            let nl = back.to_nonlinear().unwrap();
            for (a, b) in nl.plant.iter().zip(&fit.plant) {
                assert_eq!(a.to_bits(), b.to_bits(), "{a:e} read back for {b:e}");
            }
        }
    }

    #[test]
    fn a_missing_plant_value_or_a_bad_format_is_named() {
        let mut saved = SavedModel::from_nonlinear(&nl_fit(), 5e-4, "", "", 0.0, "v", 5.0);
        saved.parameters.remove("k_g");
        let e = saved.to_nonlinear().unwrap_err().to_string();
        assert!(e.contains("`k_g`"), "{e}");
        saved.format = "jointid-model/9".into();
        let e = saved.to_nonlinear().unwrap_err().to_string();
        assert!(e.contains("jointid-model/9"), "{e}");
    }

    #[test]
    fn a_format_3_nonlinear_file_reads_with_its_spec_from_the_nonlinear_section() {
        let fit = nl_fit();
        let saved = SavedModel::from_nonlinear(&fit, 5e-4, "", "", 0.0, "v", 5.0);
        let mut v = serde_json::to_value(&saved).unwrap();
        let obj = v.as_object_mut().unwrap();
        assert!(obj.remove("spec").is_some());
        obj.insert("format".into(), MODEL_FORMAT_3.into());
        let old: SavedModel = serde_json::from_value(v).unwrap();
        assert_eq!(old.spec, None);
        assert_eq!(old.spec().unwrap(), saved.spec().unwrap());
        assert_eq!(old.to_nonlinear().unwrap().model, fit.model);
    }

    #[test]
    fn a_spec_that_disagrees_with_the_nonlinear_section_is_named() {
        let mut saved = SavedModel::from_nonlinear(&nl_fit(), 5e-4, "", "", 0.0, "v", 5.0);
        saved.spec = Some(ModelSpec::linear(Family::Physical(Structure::TwoMass)));
        let e = saved.spec().unwrap_err().to_string();
        assert!(e.contains("nonlinear section"), "{e}");
    }
}
