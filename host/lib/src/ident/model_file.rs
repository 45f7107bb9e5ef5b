//! The model file (`jointid fit --save`, read by `jointid validate`): the discrete
//! matrices at the sample interval of the model (the capture rate for a physical model
//! fitted with decimation), the preparation applied to the data (decimation,
//! detrending), the physical parameters with their standard deviations and units, and
//! for the Coulomb rigid model its four parameters: all that is needed to simulate the
//! model again on new data. Format `jointid-model/2`; format 1 is still read.
//!
//! This module maps a [`Fitted`] to its file contents and back; the command line reads
//! and writes the JSON text.
// Units in brackets (`[s]`, `[Hz]`, `[%]`) are not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

use std::collections::BTreeMap;

use nalgebra::{DMatrix, DVector, RowDVector};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::data::Prep;
use crate::ident::fit::{output_name, param_map, Fitted, ModelKind, ParamJson, RigidFriction};
use crate::ident::grey_box::{Output, PhysParam};
use crate::ident::ss::StateSpace;
use crate::model::params::unit_of;

impl Fitted {
    /// The model file.
    pub fn to_saved(&self, prep: Prep, source: &str, fit_estimation: f64) -> SavedModel {
        let n = self.model.order();
        SavedModel {
            format: MODEL_FORMAT.into(),
            model: self.kind.name(),
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
            fit_name: None,
            source: source.into(),
        }
    }
}

/// format tag of [`SavedModel`] (format 2: physical models at the capture
/// rate, [`SavedModel::decimate_output`])
pub const MODEL_FORMAT: &str = "jointid-model/2";
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
    /// `A`, row by row
    pub a: Vec<Vec<f64>>,
    /// `B`
    pub b: Vec<f64>,
    /// `C`
    pub c: Vec<f64>,
    /// `D`
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
    /// [`crate::ident::frf_fit::PERIODIC_FIT_NAME`]); `validate` reports the
    /// same one on periodic data
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fit_name: Option<String>,
    /// estimation data file
    pub source: String,
}

/// Why a model file cannot be read back ([`SavedModel::to_fitted`]).
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum ModelFileError {
    /// a format this build does not read
    #[error("model format `{format}` is neither `{MODEL_FORMAT}` nor `{MODEL_FORMAT_1}`")]
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
    Model(String),
    /// an output other than `angle` or `velocity`
    #[error("unknown output `{output}`")]
    Output {
        /// the output named in the file
        output: String,
    },
}

impl SavedModel {
    /// The model back as a [`Fitted`] (without continuous model).
    ///
    /// # Errors
    /// [`ModelFileError`] when the file is inconsistent.
    pub fn to_fitted(&self) -> Result<Fitted, ModelFileError> {
        if self.format != MODEL_FORMAT && self.format != MODEL_FORMAT_1 {
            return Err(ModelFileError::Format {
                format: self.format.clone(),
            });
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
        let kind: ModelKind = self.model.parse().map_err(ModelFileError::Model)?;
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
            kind,
            output,
            ts: self.ts,
            model,
            continuous: None,
            params,
            friction: self.friction,
            warnings: Vec::new(),
            method: self.method.clone(),
            decimate: self.decimate_output,
        })
    }
}
