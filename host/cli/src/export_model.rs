//! `jointid export-model MODEL.json --format json-ss|json-tf|mat|python-control`: a model
//! file of `fit --save` for other tools ([`jointid::ident::model_export`]): the continuous-
//! and discrete-time state space (`json-ss`), the transfer functions (`json-tf`), both in
//! a MATLAB file (`mat`), or a Python script that rebuilds the model in python-control
//! (`python-control`), each with the input and output, their units and the physical
//! parameters. Written to `--out FILE` (an existing one only with `--force`) or to
//! standard output (not `mat`). A model whose numbers overflow in the export (an entry of
//! magnitude 1e100 or more, a transfer function whose coefficients overflow) is refused,
//! naming the entry, and nothing is written
//! ([`jointid::ident::model_export::ExportError`]).

use std::fmt::Write as _;
use std::io::Write;
use std::path::PathBuf;

use jointid::data::input::{input_name, path_text, read_input_text};
use jointid::data::output::{check_output, io_msg, names_standard_output, write_file};
use jointid::ident::model_export::{ModelExport, SsJson, TransferFunction};
use jointid::ident::model_file::SavedModel;
use serde_json::json;

use super::{CmdResult, Context, Outcome};

/// What `export-model` writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ModelFormat {
    /// state space, continuous and discrete, as JSON
    JsonSs,
    /// transfer functions, continuous and discrete, as JSON
    JsonTf,
    /// a MATLAB Level-5 file (state space, transfer functions, parameters)
    Mat,
    /// a Python script that builds the model with the `control` package
    PythonControl,
}

/// Arguments of `jointid export-model`.
#[derive(Clone, Debug, PartialEq, clap::Args)]
pub struct ExportModelArgs {
    /// Model file written by `jointid fit --save` (`-` for standard input)
    #[arg(value_name = "MODEL.json")]
    pub model: PathBuf,
    /// Output form
    #[arg(long, value_enum)]
    pub format: ModelFormat,
    /// File to write (default: standard output; required for `mat`)
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// The axis is linear: force [N] in, position [m] out (units kg, N·s/m, N/m)
    #[arg(long)]
    pub linear_axis: bool,
    /// Replace an existing output file
    #[arg(long)]
    pub force: bool,
}

/// Runs `jointid export-model`.
///
/// # Errors
/// Reading the model file, a model without state space (fitted with effects), a model
/// whose numbers overflow, `mat` to standard output, and output errors naming the file.
pub fn run(args: &ExportModelArgs, ctx: &mut Context<'_>) -> CmdResult {
    if let Some(out) = &args.out {
        check_output(out, args.force)?;
    } else if args.format == ModelFormat::Mat {
        return Err("--format mat writes a binary file: name it with --out FILE".into());
    }
    let name = input_name(&args.model);
    let text = read_input_text(&args.model).map_err(|e| format!("{name}: {}", io_msg(&e)))?;
    let saved: SavedModel = serde_json::from_str(&text)
        .map_err(|e| format!("{name}: not a model file of `jointid fit --save`: {e}"))?;
    if saved.nonlinear.is_some() {
        return Err(format!(
            "{name}: a model with effects has no state space (it is simulated with its \
             nonlinear laws); `fit --save MODEL.mat` writes its parameters"
        )
        .into());
    }
    let ex = ModelExport::of(&saved, args.linear_axis).map_err(|e| format!("{name}: {e}"))?;
    let bytes = match args.format {
        ModelFormat::JsonSs => json_text(&ss_doc(&ex))?,
        ModelFormat::JsonTf => json_text(&tf_doc(&ex))?,
        ModelFormat::Mat => ex.to_mat(),
        ModelFormat::PythonControl => python_control(&ex).into_bytes(),
    };
    match &args.out {
        Some(out) => {
            write_file(out, args.force, |w| w.write_all(&bytes))?;
            if !ctx.json {
                let _ = writeln!(
                    std::io::stderr(),
                    "wrote {} ({}{})",
                    out.display(),
                    ex.signals(),
                    if ex.continuous.is_none() {
                        ", discrete only"
                    } else {
                        ""
                    }
                );
            }
        }
        None => ctx.out.write_all(&bytes)?,
    }
    if ctx.json {
        let summary = Summary {
            file: name,
            format: args.format,
            out: args.out.as_ref().map(|p| path_text(p)),
            input: &ex.input,
            output: &ex.output,
            ts: ex.ts,
            states: ex.discrete.a.len(),
            continuous: ex.continuous.is_some(),
            continuous_note: ex.continuous_note.as_deref(),
        };
        // with the export itself on standard output, the summary goes to standard error
        if args.out.as_ref().is_some_and(|o| !names_standard_output(o)) {
            super::print_json(ctx.out, "export-model", &summary)?;
        } else {
            super::print_json(&mut std::io::stderr().lock(), "export-model", &summary)?;
        }
    }
    Ok(Outcome::Ok)
}

/// What `export-model --json` prints: on standard output with `--out`, else on standard
/// error (standard output then carries the export).
#[derive(serde::Serialize)]
struct Summary<'a> {
    /// the model file read
    file: String,
    /// the form written
    format: ModelFormat,
    /// the file written (absent: standard output)
    #[serde(skip_serializing_if = "Option::is_none")]
    out: Option<String>,
    input: &'a jointid::ident::model_export::Signal,
    output: &'a jointid::ident::model_export::Signal,
    /// sample interval of the discrete model [s]
    ts: f64,
    /// model order
    states: usize,
    /// whether a continuous model was written
    continuous: bool,
    /// why not, when not
    #[serde(skip_serializing_if = "Option::is_none")]
    continuous_note: Option<&'a str>,
}

fn json_text(v: &serde_json::Value) -> Result<Vec<u8>, serde_json::Error> {
    Ok((serde_json::to_string_pretty(v)? + "\n").into_bytes())
}

/// What both JSON forms share.
fn common(ex: &ModelExport, schema: &str) -> serde_json::Value {
    json!({
        "schema": schema,
        "model": ex.model,
        "method": ex.method,
        "source": ex.source,
        "input": ex.input,
        "output": ex.output,
        "ts": ex.ts,
        "parameters": ex.parameters,
        "fit_estimation": ex.fit_estimation,
        "fit_name": ex.fit_name,
        "continuous_note": ex.continuous_note,
    })
}

fn ss_doc(ex: &ModelExport) -> serde_json::Value {
    let mut v = common(ex, "jointid-model-ss/1");
    v["discrete"] = json!(ex.discrete);
    v["continuous"] = json!(ex.continuous);
    v
}

fn tf_doc(ex: &ModelExport) -> serde_json::Value {
    let mut v = common(ex, "jointid-model-tf/1");
    v["discrete"] = json!(ex.discrete_tf);
    v["continuous"] = json!(ex.continuous_tf);
    v
}

/// `[a, b, …]` with every number in its shortest form that reads back to the same `f64`.
fn py_list(x: &[f64]) -> String {
    let items: Vec<String> = x.iter().map(|v| format!("{v:?}")).collect();
    format!("[{}]", items.join(", "))
}

fn py_matrix(rows: &[Vec<f64>]) -> String {
    let items: Vec<String> = rows.iter().map(|r| py_list(r)).collect();
    format!("[{}]", items.join(", "))
}

fn py_ss(s: &SsJson) -> String {
    format!(
        "np.array({}), np.array({}).reshape(-1, 1), np.array({}).reshape(1, -1), {:?}",
        py_matrix(&s.a),
        py_list(&s.b),
        py_list(&s.c),
        s.d
    )
}

fn py_tf(t: &TransferFunction) -> String {
    format!("{}, {}", py_list(&t.num), py_list(&t.den))
}

/// A Python string literal of `s` (JSON's escaping is valid Python).
fn py_str(s: &str) -> String {
    serde_json::Value::from(s).to_string()
}

/// The python-control script: `sysd`, `tfd` (discrete), `sysc`, `tfc` (continuous, `None`
/// when there is none) and `params`; run as a program it prints a short summary.
fn python_control(ex: &ModelExport) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "\"\"\"jointid model {}: {} (built by `jointid export-model --format python-control`).\n\n\
         sysd, tfd: discrete at Ts = {} s (zero-order hold); sysc, tfc: continuous time, or\n\
         None when no continuous model samples to it; params: name -> (value, std, unit).\n\"\"\"",
        ex.model,
        ex.signals(),
        ex.ts
    );
    s.push_str("import numpy as np\nimport control\n\n");
    let io = format!(
        "inputs=[{}], outputs=[{}]",
        py_str(&ex.input.name),
        py_str(&ex.output.name)
    );
    let _ = writeln!(s, "Ts = {:?}", ex.ts);
    let _ = writeln!(s, "source = {}", py_str(&ex.source));
    let _ = writeln!(
        s,
        "units = {{{}: {}, {}: {}}}",
        py_str(&ex.input.name),
        py_str(&ex.input.unit),
        py_str(&ex.output.name),
        py_str(&ex.output.unit)
    );
    let _ = writeln!(
        s,
        "sysd = control.ss({}, Ts, {io}, name={})",
        py_ss(&ex.discrete),
        py_str("jointid_d")
    );
    let _ = writeln!(s, "tfd = control.tf({}, Ts, {io})", py_tf(&ex.discrete_tf));
    match (&ex.continuous, &ex.continuous_tf) {
        (Some(c), Some(t)) => {
            let _ = writeln!(
                s,
                "sysc = control.ss({}, {io}, name={})",
                py_ss(c),
                py_str("jointid_c")
            );
            let _ = writeln!(s, "tfc = control.tf({}, {io})", py_tf(t));
        }
        _ => {
            let _ = writeln!(
                s,
                "# {}\nsysc = None\ntfc = None",
                ex.continuous_note
                    .as_deref()
                    .unwrap_or("no continuous model")
            );
        }
    }
    s.push_str("params = {\n");
    for (k, p) in &ex.parameters {
        let _ = writeln!(
            s,
            "    {}: ({:?}, {:?}, {}),",
            py_str(k),
            p.value,
            p.std,
            py_str(&p.unit)
        );
    }
    s.push_str("}\n");
    let _ = writeln!(s, "fit_estimation = {:?}", ex.fit_estimation);
    s.push_str(
        "\nif __name__ == \"__main__\":\n    \
         print(f\"{sysd.nstates} states, Ts = {Ts} s, poles {np.round(sysd.poles(), 6)}\")\n    \
         for name, (value, std, unit) in params.items():\n        \
         print(f\"{name} = {value:.6g} +/- {std:.2g} {unit}\")\n",
    );
    s
}
