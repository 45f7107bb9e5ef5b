//! Issue 14, items 2 and 5: MATLAB Level-5 files read by every analysis command and
//! written by `export --mat` and `fit --save MODEL.mat`; `export-model` in its four forms.
//!
//! What is written is checked by an independent reader, scipy's `loadmat`, and what is
//! read by files an independent writer made, scipy's `savemat` (with and without
//! compression); the python-control script is run by python-control. These tests need
//! python3 with scipy, numpy and control, which `.ci/setup` installs; without them they
//! fail and say so.

use std::path::PathBuf;
use std::process::Command;
use std::sync::OnceLock;

use jointid::data::mat::{MatOut, MatWriter};
use jointid::ident::model_export::ModelExport;
use jointid::ident::model_file::SavedModel;
use nalgebra::Complex;
use serde_json::Value;

mod common;
use common::{jointid, json_of, shared, tmpdir};

/// Runs `script` with python3 (arguments `args`) and returns its standard output as JSON.
///
/// # Panics
/// When python3 or one of its packages is missing (with what to install), or the script
/// fails.
fn python(script: &str, args: &[&str]) -> Value {
    let o = Command::new("python3")
        .arg("-c")
        .arg(script)
        .args(args)
        .output()
        .unwrap_or_else(|e| {
            panic!(
                "python3 cannot be run ({e}): these tests need python3 with scipy, numpy and \
                 control; `.ci/setup` installs them (python3 -m pip install scipy numpy control)"
            )
        });
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !err.contains("ModuleNotFoundError"),
        "{err}\nthese tests need python3 with scipy, numpy and control; `.ci/setup` installs \
         them (python3 -m pip install scipy numpy control)"
    );
    assert!(o.status.success(), "python3 failed: {err}");
    serde_json::from_slice(&o.stdout).expect("python prints JSON")
}

/// A two-mass run simulated and fitted once for the tests of this file: the directory with
/// `run.jcap`, `run.csv`, `run.mat` (export) and `m.json`, `m.mat` (fit --save).
fn fitted_run() -> &'static PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = tmpdir("run");
        let p = |n: &str| dir.join(n).display().to_string();
        let o = jointid(&[
            "simulate",
            "--model",
            "two-mass",
            "--periods",
            "4",
            "--out",
            &p("run.jcap"),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let o = jointid(&[
            "export",
            &p("run.jcap"),
            "--csv",
            &p("run.csv"),
            "--mat",
            &p("run.mat"),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        for save in ["m.json", "m.mat"] {
            let o = jointid(&[
                "fit",
                &p("run.csv"),
                "--model",
                "two-mass",
                "--save",
                &p(save),
            ]);
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        }
        dir
    })
}

/// Compares, in Python, the MAT-file's variables with the CSV's columns and the model
/// file's matrices, bit for bit (`float` parses the shortest decimal forms exactly).
const CHECK_WRITTEN: &str = r#"
import csv, json, sys
import numpy as np
from scipy.io import loadmat
run_csv, run_mat, model_json, model_mat = sys.argv[1:5]
bad = []
def same(name, a, b):
    a = np.asarray(a, dtype=np.float64); b = np.asarray(b, dtype=np.float64)
    if a.shape != b.shape or not np.array_equal(a.view(np.uint64), b.view(np.uint64)):
        bad.append(f"{name}: {a.shape} {a.ravel()[:3]} vs {b.shape} {b.ravel()[:3]}")
rows = [r for r in csv.reader(l for l in open(run_csv) if not l.startswith('#'))]
head, body = rows[0], rows[1:]
m = loadmat(run_mat)
for j, name in enumerate(head):
    same(name, m[name], np.array([[float(r[j])] for r in body]))
comments = str(m['comments'][0])
if 'kind=' not in comments:
    bad.append('comments: ' + comments[:80])
saved = json.load(open(model_json))
mm = loadmat(model_mat)
same('Ad', mm['Ad'], saved['a'])
same('Bd', mm['Bd'], np.array(saved['b']).reshape(-1, 1))
same('Cd', mm['Cd'], np.array(saved['c']).reshape(1, -1))
same('Dd', mm['Dd'], [[saved['d']]])
same('Ts', mm['Ts'], [[saved['ts']]])
same('FIT', mm['FIT'], [[saved['fit_estimation']]])
for k, p in saved['parameters'].items():
    same('params.' + k, mm['params'][0, 0][k], [[p['value']]])
    same('params_std.' + k, mm['params_std'][0, 0][k], [[p['std']]])
print(json.dumps({'bad': bad, 'samples': len(body), 'params': sorted(saved['parameters']),
                  'vars': sorted(k for k in mm if not k.startswith('__')),
                  'description': str(mm['description'][0])}))
"#;

#[test]
fn export_mat_and_fit_save_mat_load_in_scipy_bit_for_bit() {
    let dir = fitted_run();
    let p = |n: &str| dir.join(n).display().to_string();
    let v = python(
        CHECK_WRITTEN,
        &[&p("run.csv"), &p("run.mat"), &p("m.json"), &p("m.mat")],
    );
    assert_eq!(v["bad"], serde_json::json!([]), "{v}");
    assert!(v["samples"].as_u64().unwrap() > 1000, "{v}");
    assert_eq!(
        v["params"],
        serde_json::json!(["J_a1", "J_m", "d_g", "delay", "f_m", "k_g", "tau_c"])
    );
    for var in ["A", "B", "C", "D", "Ad", "num", "numd", "den", "dend"] {
        assert!(
            v["vars"].as_array().unwrap().iter().any(|x| x == var),
            "{v}"
        );
    }
    let d = v["description"].as_str().unwrap();
    assert!(
        d.contains("u [N m] -> theta_m [rad]") && d.contains("J_m [kg m^2]"),
        "{d}"
    );
}

/// The MAT-file exported from a capture reads back through every analysis command like
/// the CSV: same FRF (`analyze`), same fit.
#[test]
fn an_exported_mat_file_analyzes_and_fits_like_the_csv() {
    let dir = fitted_run();
    let p = |n: &str| dir.join(n).display().to_string();
    let strip = |mut v: Value| {
        v.as_object_mut().unwrap().remove("file");
        v
    };
    let a_csv = strip(json_of(&jointid(&["analyze", &p("run.csv"), "--json"])));
    let a_mat = strip(json_of(&jointid(&["analyze", &p("run.mat"), "--json"])));
    assert_eq!(a_csv, a_mat);
    let fit = |f: &str| {
        json_of(&jointid(&["fit", f, "--model", "two-mass", "--json"]))["parameters"].clone()
    };
    assert_eq!(fit(&p("run.csv")), fit(&p("run.mat")));
}

/// The EMPS columns in MAT-files written three ways (this writer; scipy's `savemat` as
/// column vectors; compressed, as row vectors) fit to the very values of the CSV. The
/// benchmark's own `.mat` files are not in `shared/data/emps` (only the CSVs made from
/// them), so the MAT-files are made here from the CSV's columns.
#[test]
fn emps_columns_in_mat_files_fit_to_the_same_values_as_the_csv() {
    let dir = tmpdir("emps");
    let csv = shared("data/emps/emps_train_DATA_EMPS.csv");
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| head.iter().position(|h| *h == name).unwrap();
    let (it, iu, iy) = (col("t_s"), col("force_N"), col("qm_m"));
    let (mut t, mut u, mut y) = (Vec::new(), Vec::new(), Vec::new());
    for l in lines {
        let c: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
        t.push(c[it]);
        u.push(c[iu]);
        y.push(c[iy]);
    }
    let ours = dir.join("jointid.mat");
    let mut w = MatWriter::new("EMPS");
    w.var("t", &MatOut::column(&t))
        .var("force", &MatOut::column(&u))
        .var("qm", &MatOut::column(&y));
    std::fs::write(&ours, w.finish()).unwrap();
    let v = python(
        r#"
import csv, json, sys
import numpy as np
from scipy.io import savemat
src, plain, packed = sys.argv[1:4]
rows = list(csv.DictReader(l for l in open(src) if not l.startswith('#')))
cols = {k: np.array([float(r[c]) for r in rows]) for k, c in
        [('t', 't_s'), ('force', 'force_N'), ('qm', 'qm_m'), ('vir', 'vir_V')]}
savemat(plain, cols, oned_as='column')
savemat(packed, cols, oned_as='row', do_compression=True)
print(json.dumps({'n': len(rows)}))
"#,
        &[
            &csv,
            &dir.join("scipy.mat").display().to_string(),
            &dir.join("scipy_z.mat").display().to_string(),
        ],
    );
    assert_eq!(v["n"].as_u64(), Some(t.len() as u64));
    let fit = |file: &str, time: &str, input: &str, output: &str| {
        let j = json_of(&jointid(&[
            "fit",
            file,
            "--time",
            time,
            "--input",
            input,
            "--output",
            output,
            "--model",
            "rigid",
            "--friction",
            "coulomb",
            "--linear-axis",
            "--json",
        ]));
        (j["parameters"].clone(), j["fit_estimation"].clone())
    };
    let from_csv = fit(&csv, "t_s", "force_N", "qm_m");
    // the published IDIM-LS values, as the CSV test checks them
    let m = from_csv.0["J"]["value"].as_f64().unwrap();
    assert!((m - 95.1089).abs() < 0.03 * 95.1089, "{:?}", from_csv);
    for f in ["jointid.mat", "scipy.mat", "scipy_z.mat"] {
        let got = fit(&dir.join(f).display().to_string(), "t", "force", "qm");
        assert_eq!(got, from_csv, "{f}");
    }
    // a variable that is not there is named, with the ones that are
    let o = jointid(&[
        "fit",
        &dir.join("scipy_z.mat").display().to_string(),
        "--time",
        "t",
        "--input",
        "u",
        "--output",
        "qm",
        "--model",
        "rigid",
    ]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("scipy_z.mat: variable `u` not found; variables are: t, force, qm, vir"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Frequencies [Hz] at which the model's forms are compared.
const FREQS: [f64; 6] = [1.0, 4.0, 15.0, 40.0, 120.0, 400.0];

fn rel(a: Complex<f64>, b: Complex<f64>) -> f64 {
    (a - b).norm() / b.norm()
}

fn complex_list(v: &Value) -> Vec<Complex<f64>> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|p| Complex::new(p[0].as_f64().unwrap(), p[1].as_f64().unwrap()))
        .collect()
}

/// Horner value of coefficients (highest power first) at `x`.
fn horner(p: &Value, x: Complex<f64>) -> Complex<f64> {
    p.as_array()
        .unwrap()
        .iter()
        .fold(Complex::new(0.0, 0.0), |acc, c| {
            acc * x + c.as_f64().unwrap()
        })
}

#[test]
fn export_model_forms_agree_and_python_control_rebuilds_the_model() {
    let dir = fitted_run();
    let p = |n: &str| dir.join(n).display().to_string();
    let saved: SavedModel =
        serde_json::from_str(&std::fs::read_to_string(dir.join("m.json")).unwrap()).unwrap();
    let lib_d = saved.to_fitted().unwrap().model.freq_response(&FREQS);
    let lib_c = ModelExport::of(&saved, false)
        .unwrap()
        .continuous_ss()
        .expect("a two-mass model has a continuous form")
        .freq_response(&FREQS);
    // json-ss and json-tf agree with each other and with the library's model
    let ss = json_of(&jointid(&[
        "export-model",
        &p("m.json"),
        "--format",
        "json-ss",
    ]));
    let tf = json_of(&jointid(&[
        "export-model",
        &p("m.json"),
        "--format",
        "json-tf",
    ]));
    assert_eq!(ss["input"]["unit"], "N·m");
    assert_eq!(ss["output"]["name"], "theta_m");
    assert_eq!(ss["parameters"]["k_g"]["unit"], "N·m/rad");
    assert_eq!(ss["discrete"]["a"], serde_json::json!(saved.a));
    let ts = ss["ts"].as_f64().unwrap();
    let ss_c = ModelExport::of(&saved, false).unwrap();
    for (k, &f) in FREQS.iter().enumerate() {
        let w = 2.0 * std::f64::consts::PI * f;
        let (s, z) = (Complex::new(0.0, w), Complex::new(0.0, w * ts).exp());
        let tf_d = horner(&tf["discrete"]["num"], z) / horner(&tf["discrete"]["den"], z);
        let tf_c = horner(&tf["continuous"]["num"], s) / horner(&tf["continuous"]["den"], s);
        assert!(
            rel(tf_d, lib_d[k]) < 1e-6,
            "{f} Hz: z-tf {tf_d} vs ss {}",
            lib_d[k]
        );
        assert!(
            rel(tf_c, lib_c[k]) < 1e-6,
            "{f} Hz: s-tf {tf_c} vs ss {}",
            lib_c[k]
        );
    }
    assert_eq!(
        complex_list(&tf["discrete"]["poles"]).len(),
        ss_c.discrete.a.len()
    );
    // the python-control script rebuilds the model: its frequency responses
    let script = dir.join("model.py");
    let o = jointid(&[
        "export-model",
        &p("m.json"),
        "--format",
        "python-control",
        "--out",
        &script.display().to_string(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let freqs: Vec<String> = FREQS.iter().map(f64::to_string).collect();
    let v = python(
        r#"
import json, runpy, sys
import numpy as np
g = runpy.run_path(sys.argv[1])
f = np.array([float(x) for x in sys.argv[2:]])
w = 2 * np.pi * f
out = {}
for name, x in [('sysd', np.exp(1j * w * g['Ts'])), ('tfd', np.exp(1j * w * g['Ts'])),
                ('sysc', 1j * w), ('tfc', 1j * w)]:
    h = [complex(np.squeeze(g[name](xi))) for xi in x]
    out[name] = [[c.real, c.imag] for c in h]
out['dt'] = g['sysd'].dt
out['params'] = sorted(g['params'])
print(json.dumps(out))
"#,
        &std::iter::once(script.display().to_string())
            .chain(freqs)
            .collect::<Vec<_>>()
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
    );
    assert_eq!(v["dt"].as_f64(), Some(ts));
    assert_eq!(
        v["params"],
        serde_json::json!(["J_a1", "J_m", "d_g", "delay", "f_m", "k_g", "tau_c"])
    );
    for (name, lib) in [
        ("sysd", &lib_d),
        ("tfd", &lib_d),
        ("sysc", &lib_c),
        ("tfc", &lib_c),
    ] {
        for (k, h) in complex_list(&v[name]).into_iter().enumerate() {
            assert!(
                rel(h, lib[k]) < 1e-6,
                "{name} at {} Hz: {h} vs library {}",
                FREQS[k],
                lib[k]
            );
        }
    }
    // run as a program it prints a short summary
    let o = Command::new("python3").arg(&script).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("states, Ts =") && text.contains("k_g ="),
        "{text}"
    );
    // --format mat: the same matrices as json-ss
    let mat = dir.join("model.mat");
    let o = jointid(&[
        "export-model",
        &p("m.json"),
        "--format",
        "mat",
        "--out",
        &mat.display().to_string(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // written by the command, read by Python's exact float parser
    let ss_file = dir.join("ss.json");
    let o = jointid(&[
        "export-model",
        &p("m.json"),
        "--format",
        "json-ss",
        "--out",
        &ss_file.display().to_string(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = python(
        r#"
import json, sys
import numpy as np
from scipy.io import loadmat
m = loadmat(sys.argv[1]); s = json.load(open(sys.argv[2]))
def same(a, b):
    a = np.asarray(a, dtype=np.float64); b = np.asarray(b, dtype=np.float64)
    return a.shape == b.shape and bool(np.array_equal(a.view(np.uint64), b.view(np.uint64)))
print(json.dumps({'Ad': same(m['Ad'], s['discrete']['a']),
                  'A': same(m['A'], s['continuous']['a']),
                  'B': same(m['B'], np.array(s['continuous']['b']).reshape(-1, 1))}))
"#,
        &[&mat.display().to_string(), &ss_file.display().to_string()],
    );
    assert_eq!(v, serde_json::json!({"Ad": true, "A": true, "B": true}));
    // mat needs a file; a model with no such file is named
    let o = jointid(&["export-model", &p("m.json"), "--format", "mat"]);
    assert_eq!(o.status.code(), Some(2));
    let o = jointid(&["export-model", &p("none.json"), "--format", "json-ss"]);
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("none.json"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
}
