//! Every command's `--json` document against its JSON Schema file
//! (`host/cli/schema/<kind>.schema.json`, the kind named by the document's own `schema`
//! field, `jointid-<kind>/<version>`): each command runs on small simulated inputs (the simulator
//! through the binary, as the other command-line tests make theirs) and must print exactly
//! one JSON document that the schema accepts. The schemas declare every field
//! (`additionalProperties: false` on every object with properties), so a field the code
//! adds, renames or drops fails here until the schema says so too.
//!
//! The validator below covers the subset of JSON Schema (draft 2020-12) the files use; a
//! keyword outside it is refused, and `validator_rejects_*` shows that it fails documents.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Output;

use serde_json::{json, Value};

mod common;
use common::{jointid, json_of, tmpdir};

/// A validator for the subset of JSON Schema (draft 2020-12) the schema files use: `type`
/// (one or a list; `integer` is a number without a fraction), `properties`, `required`,
/// `additionalProperties` (false or a schema), `items`, `enum`, `const`, `minimum`,
/// `anyOf`, and `$ref` into the file's own `$defs`. A keyword outside this subset is an
/// error, so a schema file cannot rely on a check that is silently skipped.
mod validator {
    use serde_json::Value;

    /// keywords that only annotate
    const ANNOTATIONS: [&str; 5] = ["$schema", "$id", "title", "description", "$defs"];
    /// keywords that are checked
    const CHECKED: [&str; 10] = [
        "type",
        "properties",
        "required",
        "additionalProperties",
        "items",
        "enum",
        "const",
        "minimum",
        "anyOf",
        "$ref",
    ];

    /// Every way `doc` departs from `schema` (`root` resolves `$ref`), each naming the
    /// JSON pointer of the value; empty when `doc` is valid.
    pub fn validate(root: &Value, schema: &Value, doc: &Value, at: &str) -> Vec<String> {
        let mut errs = Vec::new();
        check(root, schema, doc, at, &mut errs);
        errs
    }

    fn type_ok(t: &str, v: &Value) -> bool {
        match t {
            "null" => v.is_null(),
            "boolean" => v.is_boolean(),
            "object" => v.is_object(),
            "array" => v.is_array(),
            "string" => v.is_string(),
            "number" => v.is_number(),
            "integer" => v.is_i64() || v.is_u64() || v.as_f64().is_some_and(|x| x.fract() == 0.0),
            other => panic!("unknown type {other:?} in a schema"),
        }
    }

    fn check(root: &Value, schema: &Value, v: &Value, at: &str, errs: &mut Vec<String>) {
        let s = match schema {
            Value::Bool(true) => return,
            Value::Bool(false) => {
                errs.push(format!("{at}: no value allowed here"));
                return;
            }
            Value::Object(s) => s,
            other => panic!("{at}: a schema is an object or a boolean, not {other}"),
        };
        for k in s.keys() {
            assert!(
                ANNOTATIONS.contains(&k.as_str()) || CHECKED.contains(&k.as_str()),
                "{at}: keyword {k:?} is outside the validator's subset"
            );
        }
        if let Some(r) = s.get("$ref") {
            let r = r.as_str().expect("$ref is a string");
            let name = r
                .strip_prefix("#/$defs/")
                .unwrap_or_else(|| panic!("{at}: only #/$defs/NAME references, not {r}"));
            let target = root
                .get("$defs")
                .and_then(|d| d.get(name))
                .unwrap_or_else(|| panic!("{at}: $ref {r} names no definition"));
            check(root, target, v, at, errs);
        }
        if let Some(t) = s.get("type") {
            let ok = match t {
                Value::String(t) => type_ok(t, v),
                Value::Array(ts) => ts
                    .iter()
                    .any(|t| type_ok(t.as_str().expect("type name"), v)),
                other => panic!("{at}: type {other}"),
            };
            if !ok {
                errs.push(format!("{at}: {v} is not of type {t}"));
                return;
            }
        }
        if let Some(c) = s.get("const") {
            if c != v {
                errs.push(format!("{at}: {v} is not {c}"));
            }
        }
        if let Some(e) = s.get("enum") {
            if !e.as_array().expect("enum is a list").contains(v) {
                errs.push(format!("{at}: {v} is not one of {e}"));
            }
        }
        if let (Some(m), Some(x)) = (s.get("minimum").and_then(Value::as_f64), v.as_f64()) {
            if x < m {
                errs.push(format!("{at}: {x} is below the minimum {m}"));
            }
        }
        if let Some(any) = s.get("anyOf") {
            let branches = any.as_array().expect("anyOf is a list");
            let all: Vec<Vec<String>> = branches.iter().map(|b| validate(root, b, v, at)).collect();
            if all.iter().all(|e| !e.is_empty()) {
                errs.push(format!(
                    "{at}: matches none of anyOf: {}",
                    all.concat().join("; ")
                ));
            }
        }
        if let Value::Object(o) = v {
            let props = s.get("properties").and_then(Value::as_object);
            if let Some(req) = s.get("required") {
                for name in req.as_array().expect("required is a list") {
                    let name = name.as_str().expect("required names are strings");
                    if !o.contains_key(name) {
                        errs.push(format!("{at}: required field {name:?} is missing"));
                    }
                }
            }
            for (k, x) in o {
                let here = format!("{at}/{k}");
                match (props.and_then(|p| p.get(k)), s.get("additionalProperties")) {
                    (Some(p), _) => check(root, p, x, &here, errs),
                    (None, Some(Value::Bool(false))) => {
                        errs.push(format!("{here}: field not declared by the schema"));
                    }
                    (None, Some(extra)) => check(root, extra, x, &here, errs),
                    (None, None) => {}
                }
            }
        }
        if let (Value::Array(a), Some(items)) = (v, s.get("items")) {
            for (i, x) in a.iter().enumerate() {
                check(root, items, x, &format!("{at}/{i}"), errs);
            }
        }
    }
}

/// the directory of the schema files
fn schema_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("schema")
}

/// the schema file of documents of kind `kind`
fn schema(kind: &str) -> Value {
    let path = schema_dir().join(format!("{kind}.schema.json"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// the kind of a document, from its `schema` field `jointid-<kind>/<version>`, the version
/// its kind's
fn kind_of(doc: &Value) -> &str {
    let name = doc["schema"]
        .as_str()
        .unwrap_or_else(|| panic!("no `schema` field: {doc}"));
    let (kind, version) = name
        .strip_prefix("jointid-")
        .and_then(|r| r.rsplit_once('/'))
        .unwrap_or_else(|| panic!("`schema` is not jointid-<kind>/<version>: {name}"));
    assert_eq!(
        version,
        jointid_cli::schema_version(kind).to_string(),
        "{name}"
    );
    kind
}

/// `doc` is valid against the schema file its `schema` field names, which must be `kind`
fn assert_valid(doc: &Value, kind: &str) {
    assert_eq!(kind_of(doc), kind, "{doc:.300}");
    let s = schema(kind);
    let errs = validator::validate(&s, &s, doc, "");
    assert!(
        errs.is_empty(),
        "{kind}: the document departs from schema/{kind}.schema.json:\n  {}",
        errs.join("\n  ")
    );
}

/// the one JSON document of `bytes`: exactly one, nothing after it but white space
fn one_document(bytes: &[u8], what: &str) -> Value {
    let mut docs = serde_json::Deserializer::from_slice(bytes).into_iter::<Value>();
    let doc = docs
        .next()
        .unwrap_or_else(|| panic!("{what}: no JSON document"))
        .unwrap_or_else(|e| panic!("{what}: not JSON: {e}: {}", String::from_utf8_lossy(bytes)));
    assert!(docs.next().is_none(), "{what}: more than one JSON document");
    doc
}

/// runs `jointid` with `args` (which hold `--json`), expects exit 0 and one document of
/// kind `kind` on stdout that its schema accepts; returns it
fn run_valid(args: &[&str], kind: &str) -> Value {
    let out: Output = jointid(args);
    // exit 0, and standard output is one JSON document (trailing text is refused)
    let doc = json_of(&out);
    assert_valid(&doc, kind);
    doc
}

/// `simulate` into `dir/name` (`.jcap` or `.csv`) with `extra` arguments; its own document
/// is checked too
fn simulate(dir: &Path, name: &str, extra: &[&str]) -> String {
    let out = dir.join(name).display().to_string();
    let mut args: Vec<&str> = vec!["simulate", "--out", &out, "--json"];
    args.extend_from_slice(extra);
    let doc = run_valid(&args, "simulate");
    assert_eq!(doc["out"], out.as_str());
    out
}

/// every object schema, at any depth of `v`
fn object_schemas<'a>(v: &'a Value, at: String, found: &mut Vec<(String, &'a Value)>) {
    match v {
        Value::Object(o) => {
            if o.contains_key("properties") {
                found.push((at.clone(), v));
            }
            for (k, x) in o {
                object_schemas(x, format!("{at}/{k}"), found);
            }
        }
        Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                object_schemas(x, format!("{at}/{i}"), found);
            }
        }
        _ => {}
    }
}

/// The schema files: one per document kind, each naming itself in `schema`, draft
/// 2020-12, and strict: every object with properties allows no other field and requires
/// each of them unless it is meant to be absent sometimes; every command of
/// `jointid --help` has at least one.
#[test]
fn schema_files_are_strict_and_cover_every_command() {
    let mut kinds = BTreeSet::new();
    for entry in std::fs::read_dir(schema_dir()).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_str().unwrap().to_string();
        let kind = name
            .strip_suffix(".schema.json")
            .unwrap_or_else(|| panic!("{name}: not <kind>.schema.json"));
        let s = schema(kind);
        assert_eq!(
            s["$schema"], "https://json-schema.org/draft/2020-12/schema",
            "{name}"
        );
        assert_eq!(
            s["properties"]["schema"]["const"],
            jointid_cli::schema_name(kind),
            "{name}"
        );
        assert_eq!(s["required"][0], "schema", "{name}");
        let mut objects = Vec::new();
        object_schemas(&s, String::new(), &mut objects);
        assert!(!objects.is_empty(), "{name}");
        for (at, o) in objects {
            assert_eq!(
                o["additionalProperties"],
                Value::Bool(false),
                "{name}{at}: an object with properties must refuse undeclared fields"
            );
            let props = o["properties"].as_object().unwrap();
            for r in o["required"].as_array().unwrap() {
                assert!(
                    props.contains_key(r.as_str().unwrap()),
                    "{name}{at}: required {r} is not declared"
                );
            }
        }
        kinds.insert(kind.to_string());
    }
    let help = jointid(&["--help"]);
    let help = String::from_utf8(help.stdout).unwrap();
    let commands: Vec<&str> = help
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|c| *c != "help")
        .collect();
    assert!(commands.len() >= 10, "{help}");
    for c in commands {
        assert!(
            kinds
                .iter()
                .any(|k| k == c || k.starts_with(&format!("{c}-"))),
            "`{c}` has no schema file (have {kinds:?})"
        );
    }
    assert!(kinds.contains("error"), "{kinds:?}");
}

/// The check can fail: a document without a required field, with a field of the wrong
/// type, with a field the schema does not declare (at the top or inside), or of another
/// schema version is refused, each with its place named.
#[test]
fn validator_rejects_missing_fields_wrong_types_and_undeclared_fields() {
    let s = schema("export");
    let good = json!({
        "schema": "jointid-export/1",
        "file": "run.jcap",
        "csv": "run.csv",
        "session_id": 1,
        "rows": 10,
        "samples": 10,
        "gaps": [{"from": 3, "to": 4}],
        "missing_samples": 2,
        "damaged_frames": [{"offset": 100, "len": 12, "kind": "crc", "error": "CRC mismatch"}],
        "overruns": 0,
        "notes": []
    });
    assert_eq!(validator::validate(&s, &s, &good, ""), Vec::<String>::new());
    let bad = |edit: &dyn Fn(&mut Value), want: &str| {
        let mut doc = good.clone();
        edit(&mut doc);
        let errs = validator::validate(&s, &s, &doc, "");
        assert!(
            errs.iter().any(|e| e.contains(want)),
            "wanted `{want}` in {errs:?}"
        );
    };
    bad(
        &|d| {
            d.as_object_mut().unwrap().remove("rows");
        },
        ": required field \"rows\" is missing",
    );
    bad(&|d| d["rows"] = json!("10"), "/rows: \"10\" is not of type");
    bad(&|d| d["rows"] = json!(1.5), "/rows: 1.5 is not of type");
    bad(&|d| d["rows"] = json!(-1), "/rows: -1 is below the minimum");
    bad(
        &|d| d["stream_bytes"] = json!([1, 2]),
        "/stream_bytes: field not declared by the schema",
    );
    bad(
        &|d| d["gaps"][0]["length"] = json!(2),
        "/gaps/0/length: field not declared by the schema",
    );
    bad(
        &|d| {
            d["damaged_frames"][0]
                .as_object_mut()
                .unwrap()
                .remove("offset");
        },
        "/damaged_frames/0: required field \"offset\" is missing",
    );
    bad(&|d| d["notes"] = json!([1]), "/notes/0: 1 is not of type");
    bad(
        &|d| d["schema"] = json!("jointid-export/2"),
        "/schema: \"jointid-export/2\" is not \"jointid-export/1\"",
    );
    // a nullable reference and an enum
    let s = schema("analyze");
    let doc = json!({"kind": "sideways"});
    let errs = validator::validate(&s, &s["$defs"]["amplitude_trend"], &doc, "");
    assert!(
        errs.iter()
            .any(|e| e.contains("/kind: \"sideways\" is not one of")),
        "{errs:?}"
    );
}

/// `simulate`, `capture --file`, `info` (of a capture, of a capture CSV and of another
/// CSV), `export` (to a file, and `--csv -`, where the CSV takes standard output and the
/// document goes to standard error) and an error.
#[test]
fn capture_info_export_simulate_and_error_documents_match_their_schemas() {
    let dir = tmpdir("capture");
    let jcap = simulate(
        &dir,
        "run.jcap",
        &[
            "--model",
            "two-mass",
            "--effect",
            "backlash:width=2e-5",
            "--periods",
            "2",
        ],
    );
    let run_csv = simulate(&dir, "run.csv", &["--periods", "2"]);
    let cap = dir.join("cap.jcap").display().to_string();
    let c = run_valid(
        &["capture", "--file", &jcap, "--out", &cap, "--json"],
        "capture",
    );
    assert!(c["samples"].as_u64().unwrap() > 0);
    let i = run_valid(&["info", &cap, "--json"], "info");
    assert!(!i["segments"].as_array().unwrap().is_empty());
    // a file that is no capture: read (the capture CSV), and described by its columns (a
    // CSV without the capture columns and without a mapping)
    let i = run_valid(&["info", &run_csv, "--json"], "info-data");
    assert!(i["excitation"].is_object() && i["samples"].as_u64().unwrap() > 0);
    let other = dir.join("other.csv");
    std::fs::write(&other, "time,force,pos\n0,1,2\n0.001,1,2\n").unwrap();
    let i = run_valid(&["info", other.to_str().unwrap(), "--json"], "info-data");
    assert!(i["read"].is_null() && i["rows"] == 2, "{i}");
    let csv = dir.join("cap.csv").display().to_string();
    let e = run_valid(&["export", &cap, "--csv", &csv, "--json"], "export");
    assert_eq!(e["rows"], c["samples"]);

    let o = jointid(&["export", &cap, "--csv", "-", "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        String::from_utf8_lossy(&o.stdout).starts_with("# format=jointid capture csv"),
        "standard output holds the CSV"
    );
    let doc = one_document(&o.stderr, "export --csv - --json: standard error");
    assert_valid(&doc, "export");
    assert_eq!(doc["csv"], "-");

    let missing = dir.join("missing.jcap").display().to_string();
    for args in [
        vec!["info", missing.as_str(), "--json"],
        vec!["export", missing.as_str(), "--csv", "-", "--json"],
        vec!["--json", "analyze", "--no-such-flag"],
    ] {
        let o = jointid(&args);
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        assert_valid(&one_document(&o.stdout, &format!("{args:?}")), "error");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `analyze` (with `--compare`, so the amplitude trend is there), `fit` of a linear model
/// with validation data, `validate` of its model file and `validate --simulated`.
#[test]
fn analyze_fit_and_validate_documents_match_their_schemas() {
    let dir = tmpdir("linear");
    let est = simulate(&dir, "est.csv", &["--model", "two-mass", "--periods", "4"]);
    let loud = simulate(
        &dir,
        "loud.csv",
        &["--model", "two-mass", "--periods", "4", "--rms", "0.04"],
    );
    let val = simulate(
        &dir,
        "val.csv",
        &[
            "--model",
            "two-mass",
            "--periods",
            "4",
            "--seed",
            "3",
            "--excitation-seed",
            "4",
        ],
    );
    let a = run_valid(&["analyze", &est, "--compare", &loud, "--json"], "analyze");
    assert_eq!(a["amplitude_trend"].as_array().unwrap().len(), 2);
    let model = dir.join("m.json").display().to_string();
    let f = run_valid(
        &[
            "fit",
            &est,
            "--model",
            "two-mass",
            "--validation",
            &val,
            "--save",
            &model,
            "--json",
        ],
        "fit",
    );
    assert!(f["fit_validation"].is_number(), "{f}");
    let v = run_valid(&["validate", &model, &val, "--json"], "validate");
    assert!(v["fit_ok"].as_bool().unwrap());
    run_valid(
        &["validate", &est, "--simulated", "theta_m", "--json"],
        "validate-simulated",
    );
    let py = dir.join("m.py").display().to_string();
    let e = run_valid(
        &[
            "export-model",
            &model,
            "--format",
            "python-control",
            "--out",
            &py,
            "--json",
        ],
        "export-model",
    );
    assert_eq!(
        (e["format"].as_str(), e["out"].as_str()),
        (Some("python-control"), Some(py.as_str()))
    );
    // to standard output the export goes there, the summary to standard error
    let o = jointid(&["export-model", &model, "--format", "json-tf", "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(one_document(&o.stdout, "export-model stdout")["continuous"].is_object());
    assert_valid(
        &one_document(&o.stderr, "export-model stderr"),
        "export-model",
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Estimation and validation captures (two periods each, other seeds) of the three-mass
/// joint with a stiffening gearbox spring.
fn stiffening_pair(dir: &std::path::Path) -> (String, String) {
    let three = ["--model", "three-mass", "--effect", "nonlinear_stiffness"];
    let est = simulate(
        dir,
        "est.jcap",
        &[&three[..], &["--periods", "2"][..]].concat(),
    );
    let val = simulate(
        dir,
        "val.jcap",
        &[
            &three[..],
            &["--periods", "2", "--seed", "6", "--excitation-seed", "8"][..],
        ]
        .concat(),
    );
    (est, val)
}

/// `fit --effect` (the nonlinear engine) with validation data, and `validate` of its
/// model file.
#[test]
fn nonlinear_fit_and_validate_documents_match_their_schemas() {
    let dir = tmpdir("nonlinear");
    let (est, val) = stiffening_pair(&dir);
    let model = dir.join("m.json").display().to_string();
    let f = run_valid(
        &[
            "fit",
            &est,
            "--model",
            "three-mass",
            "--effect",
            "nonlinear_stiffness",
            "--validation",
            &val,
            "--save",
            &model,
            "--json",
        ],
        "fit-nonlinear",
    );
    assert!(f["validation"].is_object(), "{f}");
    run_valid(&["validate", &model, &val, "--json"], "validate-nonlinear");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `diagnose` with one candidate, `demo` and `experiment`.
#[test]
fn diagnose_demo_and_experiment_documents_match_their_schemas() {
    let dir = tmpdir("whole");
    let (est, val) = stiffening_pair(&dir);
    run_valid(
        &[
            "diagnose",
            &est,
            "--validation",
            &val,
            "--effects",
            "nonlinear_stiffness",
            "--json",
        ],
        "diagnose",
    );
    let demo = dir.join("demo").display().to_string();
    run_valid(&["demo", "--out", &demo, "--json"], "demo");
    run_valid(&["experiment", "--json"], "experiment");
    let _ = std::fs::remove_dir_all(&dir);
}
