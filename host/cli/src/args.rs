//! Argument groups shared by subcommands: the data file with its column
//! mapping, how to read it and which part to use (segment, time window), and data
//! preparation (detrend, decimation, split).

use std::io::Write;
use std::path::{Path, PathBuf};

use clap::builder::{PossibleValue, TypedValueParser};
use clap::Args;

use jointid::data::screen::{Outlier, Signal, MAX_MAGNITUDE, OUTLIER_SIGMAS};
use jointid::data::{
    fmt_sig, ColumnMap, DataError, Dataset, Detrend, IdData, Loaders, Prep, Record, SegmentChoice,
    Selected, Selection, TimeBound,
};

/// How to read a data file and which part of it to use: declared once, flattened into
/// every analysis command (analyze, fit, validate, diagnose).
#[derive(Debug, Clone, Default, Args)]
pub struct ReadArgs {
    /// gap-free segment to use: longest, N (from 1, as `jointid info` lists them) or all
    /// (analyze and the frequency-domain fit average the FRF over them, time-domain and
    /// nonlinear fits take them as separate experiments, validate and diagnose simulate
    /// each from its own start and pool the FIT); default: the whole file, or its longest
    /// segment with a note when it has gaps
    #[arg(long, value_name = "longest|N|all")]
    pub segment: Option<SegmentChoice>,
    /// start of the time window: seconds of the time column (`12.5`) or whole excitation
    /// periods after the ramp-in (`3p`)
    #[arg(long, value_name = "T|Np")]
    pub from: Option<TimeBound>,
    /// end of the time window (exclusive), as --from
    #[arg(long, value_name = "T|Np")]
    pub to: Option<TimeBound>,
    /// how a CSV's columns are split
    #[command(flatten)]
    pub csv: DelimiterArg,
    /// no progress line on standard error (shown only when it is a terminal, for a step
    /// that lasts over 2 s: reading a large file, a fit, a diagnosis's stages)
    #[arg(long, short)]
    pub quiet: bool,
}

/// `--delimiter`: how a CSV's columns are split; declared once, in [`ReadArgs`] and in
/// `info` (which reads a file whole, without a segment or window).
#[derive(Debug, Clone, Copy, Default, Args)]
pub struct DelimiterArg {
    /// CSV column delimiter, one character (`;`, `tab`); default `,`, or `;` or a tab
    /// when the header holds no `,` (with a note)
    #[arg(long, value_name = "CHAR", value_parser = parse_delimiter)]
    pub delimiter: Option<char>,
}

/// The columns of a data file that is not a capture CSV: declared once, flattened into
/// every command that reads data through a column mapping (analyze, validate, diagnose,
/// info), and into `fit`'s [`FitDataArgs`].
#[derive(Debug, Clone, Default, Args)]
pub struct ColumnArgs {
    /// time column [s] (with --input and --output; default: the capture CSV's `t`)
    #[arg(long, value_name = "COL", requires_all = ["input", "output"])]
    pub time: Option<String>,
    /// input column (torque [N·m] or force [N])
    #[arg(long, value_name = "COL", requires_all = ["time", "output"])]
    pub input: Option<String>,
    /// output column (motor angle [rad] or position [m])
    #[arg(
        long,
        visible_alias = "output-col",
        value_name = "COL",
        requires_all = ["time", "input"]
    )]
    pub output: Option<String>,
    /// reference column (excitation); without a mapping the capture CSV's `theta_ref`
    #[arg(long, value_name = "COL")]
    pub reference: Option<String>,
}

impl ColumnArgs {
    /// A column mapping was given (`--time`, `--input` and `--output`, which clap requires
    /// together).
    pub fn mapped(&self) -> bool {
        self.time.is_some()
    }
}

fn parse_delimiter(s: &str) -> Result<char, String> {
    match s {
        "tab" | "\\t" => return Ok('\t'),
        "space" => return Ok(' '),
        _ => {}
    }
    let mut c = s.chars();
    match (c.next(), c.next()) {
        (Some(d), None) if d != '"' && d != '#' && !d.is_alphanumeric() && d != '.' && d != '-' => {
            Ok(d)
        }
        _ => Err(format!(
            "`{s}`: one character that cannot be part of a number, or `tab`"
        )),
    }
}

impl ReadArgs {
    /// The `--delimiter` given.
    pub fn delimiter(&self) -> Option<char> {
        self.csv.delimiter
    }

    /// The selection these arguments describe.
    pub fn selection(&self) -> Selection {
        Selection {
            segment: self.segment,
            from: self.from,
            to: self.to,
        }
    }

    /// Reads `path` (`-`: standard input) with `map` and this delimiter, and selects the
    /// part asked for; prints the reader's and the selection's notes on standard error.
    ///
    /// # Errors
    /// The loader's or the selection's [`DataError`].
    pub fn select(
        &self,
        loaders: &Loaders,
        path: &Path,
        mut map: ColumnMap,
    ) -> Result<Selected, DataError> {
        map.delimiter = self.delimiter();
        super::progress::start(self.quiet);
        let size = std::fs::metadata(path)
            .ok()
            .filter(|m| m.is_file())
            .map_or_else(String::new, |m| {
                format!(" ({} MB)", fmt_sig(m.len() as f64 / 1e6, 3))
            });
        super::progress::step(format!(
            "reading {}{size}",
            jointid::data::input::input_name(path)
        ));
        let record: Record = loaders.load_record(path, &map)?;
        let sel = record.select(&self.selection())?;
        super::progress::clear();
        for n in &sel.notes {
            let _ = writeln!(std::io::stderr(), "note: {n}");
        }
        Ok(sel)
    }

    /// As [`ReadArgs::select`], for a command that takes one record.
    ///
    /// # Errors
    /// As [`ReadArgs::select`]; [`DataError::Selection`] for `--segment all` when the
    /// selection holds more than one segment.
    pub fn select_one(
        &self,
        loaders: &Loaders,
        path: &Path,
        map: ColumnMap,
    ) -> Result<Dataset, DataError> {
        one_of(self.select(loaders, path, map)?)
    }
}

/// The one record of a selection, for a command that takes one.
///
/// # Errors
/// [`DataError::Selection`] for `--segment all` when the selection holds more than one
/// segment.
pub fn one_of(mut sel: Selected) -> Result<Dataset, DataError> {
    if sel.datasets.len() > 1 {
        let name = sel.datasets[0].name.clone();
        return Err(DataError::Selection {
            file: name,
            reason: format!(
                "--segment all: this command takes one gap-free record, and segments {} \
                 were selected; give --segment longest or --segment N (`analyze`, `fit`, \
                 `validate MODEL.json` and `diagnose` use all of them)",
                sel.segments
                    .iter()
                    .map(usize::to_string)
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        });
    }
    Ok(sel.datasets.remove(0))
}

/// The column of `map` that holds `signal` (a capture's `u`, `theta_m`, `theta_ref`).
pub fn column_of(map: &ColumnMap, signal: Signal) -> &str {
    match signal {
        Signal::Input => &map.input,
        Signal::Output => &map.output,
        Signal::Reference => map.reference.as_deref().unwrap_or("theta_ref"),
    }
}

/// An outlier of the file `file` in words: `FILE: data row R (t = T s), column `C`: value V
/// lies N robust σ from ...`.
pub fn outlier_line(file: &str, map: &ColumnMap, o: &Outlier) -> String {
    format!(
        "{file}: data row {} (t = {} s), column `{}`: value {:e}: {}",
        o.row,
        fmt_sig(o.t_s, 8),
        column_of(map, o.signal),
        o.value,
        o.why()
    )
}

/// Screens a selection for a fit or a validation (`role`) ([`jointid::data::screen`]): refuses one that holds a
/// sample no fit can compute with (not finite, or of magnitude ≥ [`MAX_MAGNITUDE`]: sums
/// of squares overflow and an iteration may never end), naming the first by file, row and
/// column; a sample beyond [`OUTLIER_SIGMAS`] robust σ is a warning, not a refusal (a
/// glitch, or real data a robust scale misreads: a sparse pulse train, an axis parked
/// far away for part of the record), returned in words.
///
/// # Errors
/// The first unusable sample in words ([`outlier_line`]), how many there are and how to
/// leave them out.
pub fn screen_for_fit(
    sel: &Selected,
    map: &ColumnMap,
    role: &str,
) -> Result<Option<String>, String> {
    let name = sel.datasets.first().map_or("", |d| d.name.as_str());
    let unusable = |o: &&Outlier| !o.value.is_finite() || o.value.abs() >= MAX_MAGNITUDE;
    let n = sel.outliers.iter().filter(unusable).count();
    if let Some(first) = sel.outliers.iter().find(unusable) {
        return Err(format!(
            "{}; a {role} takes no sample of magnitude ≥ {MAX_MAGNITUDE:e} or not finite, and the \
             data selected hold {n}: leave {} out with --from/--to or --segment",
            outlier_line(name, map, first),
            if n == 1 { "it" } else { "them" }
        ));
    }
    Ok(sel.outliers.first().map(|first| {
        let more = sel.outlier_count - 1;
        format!(
            "{}{}; the {role} takes {} as measured (beyond {OUTLIER_SIGMAS} robust σ: a glitch \
             pulls the {role} towards it; leave {} out with --from/--to or --segment)",
            outlier_line(name, map, first),
            if more > 0 {
                format!(
                    ", and {more} more such sample{}",
                    if more == 1 { "" } else { "s" }
                )
            } else {
                String::new()
            },
            if more > 0 { "them" } else { "it" },
            if more > 0 { "them" } else { "it" }
        )
    }))
}

/// A data file, its column mapping and how to read it: what an analysis command loads,
/// built from its flags ([`DataArgs::new`] from [`ColumnArgs`] and [`ReadArgs`]).
#[derive(Debug, Clone)]
pub struct DataArgs {
    /// data file: capture CSV (`t,theta_ref,u,theta_m`), any CSV or MAT-file with
    /// --time/--input/--output, or a registered format; `-`: standard input
    pub path: PathBuf,
    /// time column [s]
    pub time: Option<String>,
    /// input column
    pub input: Option<String>,
    /// output column
    pub output: Option<String>,
    /// reference column
    pub reference: Option<String>,
    /// how to read the file and which part to use
    pub read: ReadArgs,
}

impl DataArgs {
    /// `path` read with the columns and the reading of these flags.
    pub fn new(path: &Path, columns: &ColumnArgs, read: &ReadArgs) -> Self {
        DataArgs {
            path: path.to_path_buf(),
            time: columns.time.clone(),
            input: columns.input.clone(),
            output: columns.output.clone(),
            reference: columns.reference.clone(),
            read: read.clone(),
        }
    }

    /// the column mapping these arguments describe
    pub fn column_map(&self) -> ColumnMap {
        match (&self.time, &self.input, &self.output) {
            (Some(t), Some(i), Some(o)) => ColumnMap {
                time: t.clone(),
                input: i.clone(),
                output: o.clone(),
                reference: self.reference.clone(),
                delimiter: self.read.delimiter(),
            },
            _ => {
                let mut m = ColumnMap::capture();
                if let Some(r) = &self.reference {
                    m.reference = Some(r.clone());
                }
                m.delimiter = self.read.delimiter();
                m
            }
        }
    }

    /// Loads the part of the file the command line selects, as one record ([`ReadArgs::select_one`]).
    ///
    /// # Errors
    /// The loader's or the selection's [`DataError`].
    pub fn load(&self, loaders: &Loaders) -> Result<Dataset, DataError> {
        self.read.select_one(loaders, &self.path, self.column_map())
    }

    /// Loads the part of the file the command line selects: one record, or every segment
    /// with `--segment all` ([`ReadArgs::select`]).
    ///
    /// # Errors
    /// The loader's or the selection's [`DataError`].
    pub fn select(&self, loaders: &Loaders) -> Result<Selected, DataError> {
        self.read.select(loaders, &self.path, self.column_map())
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
    /// [`DataError::DecimationTooShort`].
    pub fn apply(&self, data: &IdData) -> Result<IdData, DataError> {
        self.prep().apply(data)
    }
}

/// A data file with the column mapping of `fit`: the same flags as every
/// analysis command, `--output-col` accepted as another name of `--output`.
#[derive(Debug, Clone, Args)]
pub struct FitDataArgs {
    /// data file: capture CSV (`t,theta_ref,u,theta_m`), a mapped CSV, or `.jcap`; `-`
    /// for standard input
    #[arg(value_name = "DATA")]
    pub path: PathBuf,
    /// which columns hold the signals
    #[command(flatten)]
    pub columns: ColumnArgs,
    /// how to read the files and which part to use
    #[command(flatten)]
    pub read: ReadArgs,
}

impl FitDataArgs {
    /// the same mapping as analysis' [`DataArgs`] for `path`
    pub fn data_args(&self, path: &Path) -> DataArgs {
        DataArgs::new(path, &self.columns, &self.read)
    }
}

/// `--lags M`: at least 1 (the residual tests need one lag)
pub(crate) fn parse_lags(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(m) if m >= 1 => Ok(m),
        _ => Err(format!("`{s}` is not a number of lags ≥ 1")),
    }
}

/// The column mapping names three (or four) different columns: one column cannot be two
/// signals.
pub(crate) fn check_columns(data: &DataArgs) -> Result<(), String> {
    let named = [
        ("--time", &data.time),
        ("--input", &data.input),
        ("--output", &data.output),
        ("--reference", &data.reference),
    ];
    for (i, (fa, a)) in named.iter().enumerate() {
        for (fb, b) in &named[i + 1..] {
            if let (Some(a), Some(b)) = (a, b) {
                if a == b {
                    return Err(format!(
                        "{fa} and {fb} both name column `{a}`: one column cannot be two signals"
                    ));
                }
            }
        }
    }
    Ok(())
}

/// `other` (a validation record, given by `flag`) has the sample interval of the estimation
/// record `first` ([`jointid::ident::fit::check_same_rate`]).
pub(crate) fn check_same_rate(first: &Dataset, other: &Dataset, flag: &str) -> Result<(), String> {
    jointid::ident::fit::check_same_rate(first, other).map_err(|e| format!("{flag} {e}"))
}
