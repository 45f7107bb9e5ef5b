//! The architecture invariants of ARCHITECTURE.md, checked on the library's sources as
//! absences: the library names no command-line parser, writes nothing to the terminal,
//! touches files only in `data`, `capture` and the model file, and its module groups
//! depend on each other only downwards (no arrow against the layering, so no cycle).
//!
//! Scanned: every `.rs` file under `src/`, without comment lines and without the test
//! code at the end of a file (from the `#[cfg(test)]` that opens `mod tests`; files named
//! `tests.rs` or `*_tests.rs` and the files of a `tests/` folder are test code as a whole).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The module groups each group may name (`crate::<group>`), besides itself.
const ALLOWED: [(&str, &[&str]); 9] = [
    ("data", &[]),
    ("capture", &["data"]),
    ("model", &[]),
    ("sim", &["data", "model"]),
    // the nonlinear models are validated with the simulator's exact laws (ident::nonlinear)
    ("ident", &["data", "model", "sim"]),
    ("diagnose", &["data", "model", "sim", "ident"]),
    // the diagnosis report draws a `Diagnosis` (report/html.rs)
    ("report", &["data", "model", "ident", "diagnose"]),
    (
        "scenario",
        &["data", "capture", "model", "sim", "ident", "report"],
    ),
    (
        "test_support",
        &["data", "capture", "model", "sim", "ident"],
    ),
];

/// Where files may be opened, created, read or written (relative to `src/`).
const FILE_IO: [&str; 3] = ["data/", "capture/", "ident/model_file.rs"];

fn src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The non-test code lines of every source file, by path relative to `src/` (with `/`).
fn code() -> BTreeMap<String, Vec<(usize, String)>> {
    let root = src();
    let mut files = Vec::new();
    rust_files(&root, &mut files);
    let mut out = BTreeMap::new();
    for f in files {
        let rel = f
            .strip_prefix(&root)
            .unwrap()
            .to_string_lossy()
            .replace('\\', "/");
        if rel.ends_with("/tests.rs") || rel.ends_with("_tests.rs") || rel.contains("/tests/") {
            continue;
        }
        let text = std::fs::read_to_string(&f).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        let mut kept = Vec::new();
        for (i, line) in lines.iter().enumerate() {
            let next = lines.get(i + 1).map_or("", |l| l.trim_start());
            if line.trim() == "#[cfg(test)]"
                && (next.starts_with("mod tests") || next.starts_with("pub(crate) mod tests"))
            {
                break;
            }
            let t = line.trim_start();
            if !t.starts_with("//") {
                kept.push((i + 1, line.to_string()));
            }
        }
        out.insert(rel, kept);
    }
    out
}

fn group_of(rel: &str) -> &str {
    rel.split('/').next().unwrap().trim_end_matches(".rs")
}

/// `name` as a whole identifier path segment in `line` (not part of a longer name).
fn names(line: &str, name: &str) -> bool {
    line.match_indices(name).any(|(i, _)| {
        let before = line[..i].chars().next_back();
        let after = line[i + name.len()..].chars().next();
        let ident = |c: Option<char>| c.is_some_and(|c| c.is_alphanumeric() || c == '_');
        !ident(before) && !ident(after)
    })
}

#[test]
fn library_names_no_command_line_parser_and_depends_on_none() {
    let mut found = Vec::new();
    for (rel, lines) in code() {
        for (n, l) in lines {
            if names(&l, "clap") {
                found.push(format!("src/{rel}:{n}: {}", l.trim()));
            }
        }
    }
    assert!(
        found.is_empty(),
        "clap in the library:\n{}",
        found.join("\n")
    );
    let manifest =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("Cargo.toml")).unwrap();
    for dep in ["clap", "anyhow", "indicatif", "ctrlc"] {
        assert!(
            !manifest.lines().any(|l| l.trim_start().starts_with(dep)),
            "the library depends on {dep}"
        );
    }
}

#[test]
fn library_touches_files_only_in_data_capture_and_the_model_file() {
    let mut found = Vec::new();
    for (rel, lines) in code() {
        if FILE_IO.iter().any(|p| rel.starts_with(p)) {
            continue;
        }
        for (n, l) in lines {
            if ["std::fs", "fs::", "File", "OpenOptions"]
                .iter()
                .any(|w| names(&l, w))
            {
                found.push(format!("src/{rel}:{n}: {}", l.trim()));
            }
        }
    }
    assert!(
        found.is_empty(),
        "file IO outside {FILE_IO:?}:\n{}",
        found.join("\n")
    );
}

#[test]
fn library_writes_nothing_to_the_terminal() {
    let mut found = Vec::new();
    for (rel, lines) in code() {
        for (n, l) in lines {
            if [
                "println!",
                "eprintln!",
                "print!",
                "eprint!",
                "dbg!",
                "stdout",
                "stderr",
            ]
            .iter()
            .any(|w| l.contains(w))
            {
                found.push(format!("src/{rel}:{n}: {}", l.trim()));
            }
        }
    }
    assert!(
        found.is_empty(),
        "terminal output in the library:\n{}",
        found.join("\n")
    );
}

#[test]
fn module_groups_depend_only_downwards() {
    let allowed: BTreeMap<&str, &[&str]> = ALLOWED.into_iter().collect();
    let mut found = Vec::new();
    for (rel, lines) in code() {
        let group = group_of(&rel);
        if group == "lib" {
            continue;
        }
        let Some(ok) = allowed.get(group) else {
            found.push(format!("src/{rel}: group `{group}` is not in the layering"));
            continue;
        };
        for (n, l) in lines {
            for (i, _) in l.match_indices("crate::") {
                let rest = &l[i + "crate::".len()..];
                let target: String = rest
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_' || *c == '{')
                    .collect();
                if target != group && !ok.contains(&target.as_str()) {
                    found.push(format!("src/{rel}:{n}: {group} -> {target}: {}", l.trim()));
                }
            }
        }
    }
    assert!(
        found.is_empty(),
        "arrows against the layering:\n{}",
        found.join("\n")
    );
}

#[test]
fn the_scan_sees_what_it_must_refuse() {
    assert!(names("use clap::Parser;", "clap"));
    assert!(!names("let clapper = 1;", "clap"));
    assert!(names("std::fs::write(p, s)", "std::fs"));
    assert!(!names("FileError::Io", "File"));
    let c = code();
    assert!(c.contains_key("lib.rs") && c.contains_key("ident/fit.rs"));
    assert!(
        c["data/csv.rs"].iter().any(|(_, l)| l.contains("std::fs")),
        "the scan reads the code of data/csv.rs"
    );
    assert!(
        !c["data/csv.rs"]
            .iter()
            .any(|(_, l)| l.contains("fn parse_csv_reads_capture_header")),
        "the scan stops at the tests"
    );
}
