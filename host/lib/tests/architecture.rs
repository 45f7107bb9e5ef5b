//! The architecture invariants of ARCHITECTURE.md, checked on the library's sources as
//! absences: the library names no command-line parser, writes nothing to the terminal,
//! touches files only in `data`, `capture` and the model file, its module groups depend on
//! each other only downwards (no arrow against the layering), and no module imports itself
//! through others: at every level of the module tree of the library, the command line and
//! the firmware core, the modules beside each other name each other without a circle.
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

/// Where files may be opened, created, read or written (relative to `src/`); the test
/// fixtures read the reference data beside the repository (`shared/data`).
const FILE_IO: [&str; 4] = ["data/", "capture/", "ident/model_file.rs", "test_support/"];

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
    code_in(&src())
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

/// The non-test code lines of every source file under `root`, by path relative to it:
/// without comment lines and without the test code at the end of a file.
fn code_in(root: &Path) -> BTreeMap<String, Vec<(usize, String)>> {
    let mut files = Vec::new();
    rust_files(root, &mut files);
    let mut out = BTreeMap::new();
    for f in files {
        let rel = f
            .strip_prefix(root)
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
            if !line.trim_start().starts_with("//") {
                kept.push((i + 1, line.to_string()));
            }
        }
        out.insert(rel, kept);
    }
    out
}

/// The module path of a source file relative to its crate's `src/` (`ident/sml.rs` is
/// `[ident, sml]`, `ident/mod.rs` is `[ident]`, `lib.rs` and `main.rs` are `[]`).
fn module_of(rel: &str) -> Vec<String> {
    let mut parts: Vec<String> = rel
        .trim_end_matches(".rs")
        .split('/')
        .map(String::from)
        .collect();
    if parts.len() == 1 && (parts[0] == "lib" || parts[0] == "main") {
        parts.clear();
    } else if parts.last().is_some_and(|p| p == "mod") {
        parts.pop();
    }
    parts
}

/// Every path a `use` tree names, its braces expanded (`a::{b, c::{d, e}}` is `a::b`,
/// `a::c::d`, `a::c::e`).
fn expand_use(tree: &str) -> Vec<String> {
    let tree: String = tree.split_whitespace().collect::<Vec<_>>().join(" ");
    let Some(open) = tree.find('{') else {
        return vec![tree.split(" as ").next().unwrap_or("").trim().to_string()];
    };
    let (prefix, body) = (
        &tree[..open],
        tree[open + 1..].trim_end().trim_end_matches('}'),
    );
    let mut parts = Vec::new();
    let (mut depth, mut start) = (0, 0);
    for (i, c) in body.char_indices() {
        match c {
            '{' => depth += 1,
            '}' => depth -= 1,
            ',' if depth == 0 => {
                parts.push(&body[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    parts.push(&body[start..]);
    parts
        .into_iter()
        .filter(|p| !p.trim().is_empty())
        .flat_map(|p| expand_use(p.trim()))
        .map(|p| format!("{prefix}{p}"))
        .collect()
}

/// The file a path names from the module `from`: the longest prefix of the path that is
/// a module of `modules`; `None` for paths outside the crate (other crates, `std`).
fn file_named<'m>(
    modules: &'m BTreeMap<Vec<String>, String>,
    from: &[String],
    path: &str,
) -> Option<&'m String> {
    let segs: Vec<&str> = path
        .split("::")
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .collect();
    let (mut base, mut rest) = (from.to_vec(), &segs[..]);
    match rest.first() {
        Some(&"crate") => {
            base.clear();
            rest = &rest[1..];
        }
        Some(&"super") | Some(&"self") => {
            while let Some(&s) = rest.first() {
                match s {
                    "super" => {
                        base.pop();
                    }
                    "self" => {}
                    _ => break,
                }
                rest = &rest[1..];
            }
        }
        _ => return None,
    }
    let full: Vec<String> = base
        .into_iter()
        .chain(rest.iter().map(|s| s.to_string()))
        .collect();
    (0..=full.len()).rev().find_map(|n| modules.get(&full[..n]))
}

/// The files each file names (`use` items and inline `crate::`/`super::`/`self::` paths),
/// with the line that names it first.
fn file_graph(
    code: &BTreeMap<String, Vec<(usize, String)>>,
) -> BTreeMap<String, BTreeMap<String, usize>> {
    let modules: BTreeMap<Vec<String>, String> = code
        .keys()
        .map(|rel| (module_of(rel), rel.clone()))
        .collect();
    let mut graph = BTreeMap::new();
    for (rel, lines) in code {
        let from = module_of(rel);
        let mut edges: BTreeMap<String, usize> = BTreeMap::new();
        let mut add = |path: &str, line: usize| {
            if let Some(to) = file_named(&modules, &from, path) {
                if to != rel {
                    edges.entry(to.clone()).or_insert(line);
                }
            }
        };
        // `use` statements, which may span lines
        let mut pending: Option<(usize, String)> = None;
        for (n, l) in lines {
            let t = l.trim_start();
            let t = t.strip_prefix("pub ").unwrap_or(t);
            let t = t.strip_prefix("pub(crate) ").unwrap_or(t);
            let t = t.strip_prefix("pub(super) ").unwrap_or(t);
            if let Some((_, stmt)) = &mut pending {
                stmt.push_str(l);
            } else if let Some(u) = t.strip_prefix("use ") {
                pending = Some((*n, u.to_string()));
            } else {
                // inline paths
                for start in ["crate::", "super::", "self::"] {
                    for (i, _) in l.match_indices(start) {
                        if l[..i]
                            .chars()
                            .next_back()
                            .is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':')
                        {
                            continue;
                        }
                        let path: String = l[i..]
                            .chars()
                            .take_while(|c| c.is_alphanumeric() || *c == '_' || *c == ':')
                            .collect();
                        add(&path, *n);
                    }
                }
                continue;
            }
            if let Some((line, stmt)) = pending.take_if(|(_, s)| s.contains(';')) {
                let tree = stmt.split(';').next().unwrap_or("");
                for path in expand_use(tree) {
                    add(&path, line);
                }
            }
        }
        graph.insert(rel.clone(), edges);
    }
    graph
}

/// For each module of the tree, the graph among its child modules, each taken with its
/// own submodules: child `a` names child `b` when a file of `a` names a file of `b`, with the
/// first such place as `file:line names file`. A file naming its ancestors' items (a child
/// using its parent's vocabulary) or its descendants' (a parent re-exporting its children)
/// stays within one node: a module and its submodules are one unit to the modules beside it.
type Levels = BTreeMap<Vec<String>, BTreeMap<String, BTreeMap<String, String>>>;

fn levels(graph: &BTreeMap<String, BTreeMap<String, usize>>) -> Levels {
    let mut out: Levels = BTreeMap::new();
    for (from, edges) in graph {
        let a = module_of(from);
        for (to, line) in edges {
            let b = module_of(to);
            let common = a.iter().zip(&b).take_while(|(x, y)| x == y).count();
            if common == a.len() || common == b.len() {
                continue;
            }
            out.entry(a[..common].to_vec())
                .or_default()
                .entry(a[common].clone())
                .or_default()
                .entry(b[common].clone())
                .or_insert_with(|| format!("{from}:{line} names {to}"));
        }
    }
    out
}

/// A shortest circle in `graph` (node -> node -> where), as `a -> b -> a` with where each
/// step is made, if there is one.
fn circle(graph: &BTreeMap<String, BTreeMap<String, String>>) -> Option<String> {
    let mut best: Option<Vec<&String>> = None;
    for start in graph.keys() {
        // breadth-first from `start` back to it
        let mut prev: BTreeMap<&String, &String> = BTreeMap::new();
        let mut queue = std::collections::VecDeque::from([start]);
        let mut closing = None;
        'search: while let Some(f) = queue.pop_front() {
            for to in graph.get(f).into_iter().flat_map(|e| e.keys()) {
                if to == start {
                    closing = Some(f);
                    break 'search;
                }
                if !prev.contains_key(to) {
                    prev.insert(to, f);
                    queue.push_back(to);
                }
            }
        }
        if let Some(mut f) = closing {
            let mut path = vec![f];
            while f != start {
                f = prev[f];
                path.push(f);
            }
            path.reverse();
            path.push(start);
            if best.as_ref().is_none_or(|b| path.len() < b.len()) {
                best = Some(path);
            }
        }
    }
    best.map(|p| {
        let steps: Vec<String> = p
            .windows(2)
            .map(|w| format!("{} -> {} ({})", w[0], w[1], graph[w[0]][w[1]]))
            .collect();
        steps.join(", ")
    })
}

/// Every import circle among the modules beside each other under `root`, one a line.
fn import_circles(root: &Path) -> Vec<String> {
    levels(&file_graph(&code_in(root)))
        .iter()
        .filter_map(|(parent, g)| {
            let at = if parent.is_empty() {
                "crate".to_string()
            } else {
                parent.join("::")
            };
            circle(g).map(|c| format!("in {at}: {c}"))
        })
        .collect()
}

#[test]
fn no_module_imports_itself_through_others() {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut found = Vec::new();
    for root in [
        manifest.join("src"),
        manifest.join("../cli/src"),
        manifest.join("../../firmware/core/src"),
    ] {
        assert!(
            code_in(&root).len() > 5,
            "the scan reads {}",
            root.display()
        );
        found.extend(
            import_circles(&root)
                .into_iter()
                .map(|c| format!("{}: {c}", root.display())),
        );
    }
    assert!(
        found.is_empty(),
        "import circles (move what both sides need below both):\n{}",
        found.join("\n")
    );
}

#[test]
fn the_circle_scan_finds_a_circle_and_reads_use_trees() {
    assert_eq!(
        expand_use("crate::ident::{fit::{self, A}, frf as f}"),
        [
            "crate::ident::fit::self",
            "crate::ident::fit::A",
            "crate::ident::frf"
        ]
    );
    let code = |files: &[(&str, &str)]| -> BTreeMap<String, Vec<(usize, String)>> {
        files
            .iter()
            .map(|(f, l)| (f.to_string(), vec![(1, l.to_string())]))
            .collect()
    };
    let three = code(&[
        ("lib.rs", "mod a; mod b; mod c;"),
        ("a.rs", "use crate::b::X;"),
        ("b/inner.rs", "fn f() { crate::c::g() }"),
        ("b.rs", "mod inner; pub use inner::f;"),
        ("c.rs", "use crate::{a::{self, Y}};"),
    ]);
    let found = levels(&file_graph(&three));
    assert_eq!(
        circle(&found[&Vec::<String>::new()]).as_deref(),
        Some(
            "a -> b (a.rs:1 names b.rs), b -> c (b/inner.rs:1 names c.rs), \
             c -> a (c.rs:1 names a.rs)"
        )
    );
    // a parent and its child naming each other are one unit, not a circle
    let facade = code(&[
        ("lib.rs", "mod p;"),
        ("p.rs", "mod q; pub use self::q::Z;"),
        ("p/q.rs", "use super::Y;"),
    ]);
    assert!(levels(&file_graph(&facade))
        .values()
        .all(|g| circle(g).is_none()));
}
