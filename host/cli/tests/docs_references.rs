//! What the README and the sources point to outside the repository: the README's examples
//! on measured data read `../shared/data/...`, which exists beside a clone only on the
//! project's machines, so the README says what that folder is and where each data set
//! comes from, and names a command that makes data instead (run here through the binary);
//! every path it names is there; and no source cites `DESIGN.md` as if it were in the
//! repository (it is `../shared/DESIGN.md`, beside the clone).

use std::path::{Path, PathBuf};

// `json_of` of the shared helpers is not used here
#[allow(dead_code)]
mod common;
use common::{jointid, shared, tmpdir};

/// The repository's root (two levels above this crate).
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .nth(2)
        .unwrap()
        .to_path_buf()
}

fn readme() -> String {
    std::fs::read_to_string(root().join("README.md")).unwrap()
}

/// Every `../shared/...` path the README names (up to the first character that cannot be
/// part of one).
fn shared_paths(text: &str) -> Vec<String> {
    let mut found: Vec<String> = text
        .match_indices("../shared/")
        .map(|(i, _)| {
            text[i..]
                .chars()
                .take_while(|c| c.is_alphanumeric() || "._-/".contains(*c))
                .collect::<String>()
                .trim_end_matches('.')
                .to_string()
        })
        .collect();
    found.sort();
    found.dedup();
    found
}

/// The README says what `../shared/` is where it first reads it, names the source of each
/// data set its examples read, and every path it names exists there.
#[test]
fn the_readme_says_where_its_shared_data_come_from() {
    let text = readme();
    let first = text
        .find("../shared/data")
        .expect("the README reads ../shared/data");
    let paragraph = &text[first..first + text[first..].find("\n\n").unwrap()];
    assert!(
        paragraph.contains("beside a clone") && paragraph.contains("README"),
        "{paragraph}"
    );
    let paths = shared_paths(&text);
    for folder in paths
        .iter()
        .filter_map(|p| p.strip_prefix("../shared/data/"))
        .filter_map(|p| p.split('/').next())
    {
        assert!(
            paragraph.contains(&format!("`{folder}/`")),
            "the data set {folder} is not introduced: {paragraph}"
        );
    }
    for p in &paths {
        let rel = p.strip_prefix("../shared/").unwrap();
        assert!(
            Path::new(&shared(rel)).exists(),
            "the README names {p}, which is not there"
        );
    }
}

/// The command the README gives for data without `../shared/` runs and writes its file.
#[test]
fn the_readmes_command_for_data_of_ones_own_runs() {
    let text = readme();
    let first = text.find("../shared/data").unwrap();
    let paragraph = &text[first..first + text[first..].find("\n\n").unwrap()];
    let command = paragraph
        .split('`')
        .find(|s| s.starts_with("jointid simulate "))
        .unwrap_or_else(|| panic!("no `jointid simulate ...` in: {paragraph}"));
    let args: Vec<&str> = command.split_whitespace().skip(1).collect();
    let out = args
        .iter()
        .skip_while(|a| **a != "--out")
        .nth(1)
        .expect("the command names its --out");
    let dir = tmpdir("readme-simulate");
    let o = std::process::Command::new(common::BIN)
        .args(&args)
        .current_dir(&dir)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(dir.join(out).is_file(), "{command} wrote no {out}");
    let o = jointid(&["info", dir.join(out).to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let _ = std::fs::remove_dir_all(&dir);
}

/// Every `.rs` and `.md` file of the repository (not `target/`, not hidden folders).
fn sources(dir: &Path, found: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if path.is_dir() {
            if !name.starts_with('.') && name != "target" {
                sources(&path, found);
            }
        } else if name.ends_with(".rs") || name.ends_with(".md") {
            found.push(path);
        }
    }
}

/// No source cites `DESIGN.md` but as `../shared/DESIGN.md`, the file beside the clone.
#[test]
fn sources_cite_the_design_beside_the_clone() {
    let mut files = Vec::new();
    sources(&root(), &mut files);
    assert!(files.len() > 50, "{} files", files.len());
    let mut bare = Vec::new();
    // this file names the bare form to look for it
    let me = Path::new(env!("CARGO_MANIFEST_DIR")).join(file!().trim_start_matches("host/cli/"));
    for f in files
        .into_iter()
        .filter(|f| !f.ends_with(me.strip_prefix(root()).unwrap()))
    {
        let text = std::fs::read_to_string(&f).unwrap_or_default();
        for (n, line) in text.lines().enumerate() {
            let cites = line.match_indices("DESIGN.md").any(|(i, _)| {
                !line[..i].ends_with("../shared/") && !line[..i].ends_with("shared/")
            });
            if cites {
                bare.push(format!("{}:{}: {line}", f.display(), n + 1));
            }
        }
    }
    assert!(bare.is_empty(), "{bare:#?}");
}
