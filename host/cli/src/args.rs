//! Argument groups shared by subcommands: the data file with its column
//! mapping, and data preparation (detrend, decimation, split).

use std::path::PathBuf;

use clap::builder::{PossibleValue, TypedValueParser};
use clap::Args;

use jointid::data::{ColumnMap, DataError, Dataset, Detrend, IdData, Loaders, Prep};

/// A data file and, for CSV files that are not capture CSVs, its columns.
#[derive(Debug, Clone, Args)]
pub struct DataArgs {
    /// data file: capture CSV (`t,theta_ref,u,theta_m`), any CSV with
    /// --time/--input/--output, or a registered format
    #[arg(value_name = "DATA")]
    pub path: PathBuf,
    /// time column [s] (with --input and --output; default: capture CSV header)
    #[arg(long, value_name = "COL", requires_all = ["input", "output"])]
    pub time: Option<String>,
    /// input column (torque [N·m] or force [N])
    #[arg(long, value_name = "COL", requires_all = ["time", "output"])]
    pub input: Option<String>,
    /// output column (motor angle [rad] or position [m])
    #[arg(long, value_name = "COL", requires_all = ["time", "input"])]
    pub output: Option<String>,
    /// reference column (excitation); without a mapping the capture CSV's `theta_ref`
    #[arg(long, value_name = "COL")]
    pub reference: Option<String>,
}

impl DataArgs {
    /// the column mapping these arguments describe
    pub fn column_map(&self) -> ColumnMap {
        match (&self.time, &self.input, &self.output) {
            (Some(t), Some(i), Some(o)) => ColumnMap {
                time: t.clone(),
                input: i.clone(),
                output: o.clone(),
                reference: self.reference.clone(),
            },
            _ => {
                let mut m = ColumnMap::capture();
                if let Some(r) = &self.reference {
                    m.reference = Some(r.clone());
                }
                m
            }
        }
    }

    /// Loads the file through `loaders`.
    ///
    /// # Errors
    /// The loader's [`DataError`].
    pub fn load(&self, loaders: &Loaders) -> Result<Dataset, DataError> {
        loaders.load(&self.path, &self.column_map())
    }
}

/// The `--detrend` values, with the help of each ([`Detrend::ALL`]).
fn detrend_parser() -> impl clap::builder::TypedValueParser<Value = Detrend> {
    clap::builder::PossibleValuesParser::new(
        Detrend::ALL.map(|(_, name, help)| PossibleValue::new(name).help(help)),
    )
    .map(|name| Detrend::from_name(&name).expect("a possible value"))
}

/// Data preparation for time-domain estimators and validation.
#[derive(Debug, Clone, Args)]
pub struct PrepArgs {
    /// detrend u, y (and r) before use
    #[arg(long, value_parser = detrend_parser(), default_value = "none")]
    pub detrend: Detrend,
    /// decimate by this integer factor with a zero-phase anti-alias filter
    #[arg(long, value_name = "Q", default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    pub decimate: u32,
}

impl PrepArgs {
    /// The preparation these arguments describe.
    pub fn prep(&self) -> Prep {
        Prep {
            decimate: self.decimate as usize,
            detrend: self.detrend,
        }
    }

    /// Detrending, then decimation ([`Prep::apply`], the one order).
    ///
    /// # Errors
    /// [`DataError::Decimation`].
    pub fn apply(&self, data: &IdData) -> Result<IdData, DataError> {
        self.prep().apply(data)
    }
}
