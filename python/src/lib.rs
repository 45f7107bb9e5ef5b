//! `jointid._native`: the Python package's native module. No estimator lives here: each
//! command runs through the command line's own [`jointid_cli::run`] with `--json` into a
//! buffer, so a result is the `--json` document the binary prints for the same arguments,
//! and an error is the line it prints ([`jointid_cli::error_message`]). Captures are read
//! and written by the library's loaders and capture CSV writer.

use std::collections::BTreeMap;

use clap::Parser;
use jointid::data::csv::{capture_csv_comments, write_table};
use jointid::data::{ColumnMap, ExcitationConfig, Record};
use jointid::ident::fit::Fitted;
use jointid_cli::{
    default_loaders, error_message, parse_error_message, run as run_cli, Cli, Context, Outcome,
};
use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};

create_exception!(
    jointid,
    JointidError,
    PyException,
    "An error of jointid, with the message the command line prints."
);

/// What one command run returned: its JSON document, exit code (0, or 1 for a check
/// that failed) and, for a linear fit, the fitted model.
struct Ran {
    json: Vec<u8>,
    code: u8,
    fitted: Option<Fitted>,
}

/// Runs `jointid --json ARGS...` in this process: the parse error, or the command's
/// error, as the message the binary prints.
fn run_args(args: Vec<String>) -> Result<Ran, String> {
    let argv = std::iter::once("jointid".to_string())
        .chain(std::iter::once("--json".to_string()))
        .chain(args);
    let cli = Cli::try_parse_from(argv).map_err(|e| {
        if e.use_stderr() {
            parse_error_message(&e)
        } else {
            // --help or --version: their text
            e.render().to_string()
        }
    })?;
    let loaders = default_loaders();
    let mut buf = Vec::new();
    let mut ctx = Context {
        json: true,
        loaders: &loaders,
        out: &mut buf,
        fitted: None,
    };
    let outcome = run_cli(&cli, &mut ctx).map_err(error_message)?;
    let fitted = ctx.fitted.take();
    Ok(Ran {
        json: buf,
        code: match outcome {
            Outcome::Ok => 0,
            Outcome::CheckFailed => 1,
        },
        fitted,
    })
}

fn rows(m: &nalgebra::DMatrix<f64>) -> Vec<Vec<f64>> {
    (0..m.nrows())
        .map(|i| (0..m.ncols()).map(|j| m[(i, j)]).collect())
        .collect()
}

/// The fitted model's matrices: `a`, `b`, `c`, `d`, `ts` (discrete) and `continuous`
/// (`f`, `g`, `h`, `d`, or None for a black box).
fn state_space<'py>(py: Python<'py>, f: &Fitted) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("model", f.spec.name())?;
    d.set_item("ts", f.ts)?;
    d.set_item("a", rows(&f.model.a))?;
    d.set_item("b", f.model.b.iter().copied().collect::<Vec<_>>())?;
    d.set_item("c", f.model.c.iter().copied().collect::<Vec<_>>())?;
    d.set_item("d", f.model.d)?;
    match &f.continuous {
        Some(c) => {
            let cd = PyDict::new(py);
            cd.set_item("f", rows(&c.f))?;
            cd.set_item("g", c.g.iter().copied().collect::<Vec<_>>())?;
            cd.set_item("h", c.h.iter().copied().collect::<Vec<_>>())?;
            cd.set_item("d", c.d)?;
            d.set_item("continuous", cd)?;
        }
        None => d.set_item("continuous", py.None())?,
    }
    Ok(d)
}

/// `run(args)`: runs `jointid --json ARGS...`; returns `(json_text, exit_code,
/// state_space_or_None)`. Raises `JointidError` with the command line's message.
#[pyfunction]
fn run<'py>(py: Python<'py>, args: Vec<String>) -> PyResult<(String, u8, PyObject)> {
    let ran = py
        .allow_threads(|| run_args(args))
        .map_err(JointidError::new_err)?;
    let text = String::from_utf8(ran.json)
        .map_err(|e| JointidError::new_err(format!("the JSON document is not UTF-8: {e}")))?;
    let ss = match &ran.fitted {
        Some(f) => state_space(py, f)?.into_any().unbind(),
        None => py.None(),
    };
    Ok((text, ran.code, ss))
}

fn f64_bytes<'py>(py: Python<'py>, v: impl Iterator<Item = f64>) -> Bound<'py, PyBytes> {
    let b: Vec<u8> = v.flat_map(f64::to_le_bytes).collect();
    PyBytes::new(py, &b)
}

/// The column mapping of `read_capture`: the capture CSV's, or the named columns.
fn column_map(
    time: Option<String>,
    input: Option<String>,
    output: Option<String>,
    reference: Option<String>,
) -> Result<ColumnMap, String> {
    let mut map = ColumnMap::capture();
    match (time, input, output) {
        (None, None, None) => {}
        (Some(t), Some(i), Some(o)) => {
            map.time = t;
            map.input = i;
            map.output = o;
            map.reference = None;
        }
        _ => return Err("time, input and output name the columns together: give all three".into()),
    }
    if reference.is_some() {
        map.reference = reference;
    }
    Ok(map)
}

/// `read_capture(path, time=None, input=None, output=None, reference=None)`: the file as
/// the analysis commands read it (a `.jcap`, a capture CSV, or a CSV with the named
/// columns). Returns `(columns, attrs_json)`: `columns` maps `t`, `u`, `theta_m`,
/// `theta_ref` (absent without a reference) and `segment` to little-endian `f64` bytes,
/// one value per sample of every gap-free segment in time order; `attrs_json` holds
/// `file`, `ts`, `excitation`, `meta`, `segments`, `gaps` and `notes`.
#[pyfunction]
#[pyo3(signature = (path, time=None, input=None, output=None, reference=None))]
fn read_capture<'py>(
    py: Python<'py>,
    path: std::path::PathBuf,
    time: Option<String>,
    input: Option<String>,
    output: Option<String>,
    reference: Option<String>,
) -> PyResult<(Bound<'py, PyDict>, String)> {
    let map = column_map(time, input, output, reference).map_err(JointidError::new_err)?;
    let record: Record = py
        .allow_threads(|| default_loaders().load_record(&path, &map))
        .map_err(|e| JointidError::new_err(error_message(Box::new(e))))?;
    let p = &record.pieces;
    let cols = PyDict::new(py);
    let t = p
        .iter()
        .flat_map(|d| (0..d.data.len()).map(|k| d.t0 + k as f64 * d.data.ts));
    cols.set_item("t", f64_bytes(py, t))?;
    let refs: Option<Vec<&Vec<f64>>> = p.iter().map(|d| d.data.r.as_ref()).collect();
    if let Some(refs) = refs {
        cols.set_item(
            "theta_ref",
            f64_bytes(py, refs.into_iter().flatten().copied()),
        )?;
    }
    let u = p.iter().flat_map(|d| d.data.u.iter().copied());
    cols.set_item("u", f64_bytes(py, u))?;
    let y = p.iter().flat_map(|d| d.data.y.iter().copied());
    cols.set_item("theta_m", f64_bytes(py, y))?;
    cols.set_item(
        "segment",
        f64_bytes(
            py,
            p.iter()
                .enumerate()
                .flat_map(|(i, d)| std::iter::repeat_n((i + 1) as f64, d.data.len())),
        ),
    )?;
    // a gap: the samples missing between two pieces (by their excitation sample index)
    let gaps: Vec<serde_json::Value> = p
        .windows(2)
        .enumerate()
        .map(|(i, w)| {
            let end = w[0].first_sample() + w[0].data.len();
            serde_json::json!({
                "after_segment": i + 1,
                "start_s": w[0].t0 + w[0].data.len() as f64 * w[0].data.ts,
                "end_s": w[1].t0,
                "samples": w[1].first_sample().saturating_sub(end),
            })
        })
        .collect();
    let first = p.first();
    let attrs = serde_json::json!({
        "file": record.name(),
        "ts": first.map(|d| d.data.ts),
        "excitation": first.and_then(|d| d.excitation.as_ref()),
        "meta": first.map(|d| d.meta.clone()).unwrap_or_default(),
        "segments": record.segments(),
        "gaps": gaps,
        "notes": record.notes,
    });
    Ok((cols, attrs.to_string()))
}

/// `write_capture_csv(path, t, theta_ref, u, theta_m, excitation_json, ts, meta)`: writes
/// a capture CSV (the library's comment lines and row writer, as `jointid export`), the
/// time column as given (a jump by whole sample intervals is a gap when read back). The
/// file is replaced when it exists.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (path, t, theta_ref, u, theta_m, excitation_json, ts, meta))]
fn write_capture_csv(
    path: std::path::PathBuf,
    t: Vec<f64>,
    theta_ref: Vec<f64>,
    u: Vec<f64>,
    theta_m: Vec<f64>,
    excitation_json: Option<String>,
    ts: f64,
    meta: BTreeMap<String, String>,
) -> PyResult<()> {
    let n = t.len();
    if theta_ref.len() != n || u.len() != n || theta_m.len() != n {
        return Err(JointidError::new_err(format!(
            "{}: columns of different lengths (t {n}, theta_ref {}, u {}, theta_m {})",
            path.display(),
            theta_ref.len(),
            u.len(),
            theta_m.len()
        )));
    }
    let excitation: Option<ExcitationConfig> = match excitation_json.as_deref() {
        Some(s) => Some(serde_json::from_str(s).map_err(|e| {
            JointidError::new_err(format!("attrs[\"excitation\"] is not an excitation: {e}"))
        })?),
        None => None,
    };
    let comments = capture_csv_comments(excitation.as_ref(), ts, &meta);
    let rows = (0..n).map(|k| [t[k], theta_ref[k], u[k], theta_m[k]]);
    jointid::data::output::write_file(&path, true, |w| write_table(w, &comments, rows))
        .map_err(|e| JointidError::new_err(error_message(Box::new(e))))
}

/// The native module of the `jointid` package.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("JointidError", m.py().get_type::<JointidError>())?;
    m.add_function(wrap_pyfunction!(run, m)?)?;
    m.add_function(wrap_pyfunction!(read_capture, m)?)?;
    m.add_function(wrap_pyfunction!(write_capture_csv, m)?)?;
    Ok(())
}
