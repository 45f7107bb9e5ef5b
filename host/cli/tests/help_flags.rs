//! The help text against the real flags: every `--flag` that the prose of `jointid --help`
//! and `jointid <command> --help` names is a flag of that command under its own name (an
//! alias works, and the help names the flag itself), or of the command named just before
//! it (`` `fit --save` ``, `` `simulate --effect` ``, `` `jointid fit --effect ... --save
//! FILE` ``). The flags are read from clap's own option list in the same help output; the
//! prose is everything else (descriptions, possible values, the command's about).
//!
//! And the column flags, declared once (`args::ColumnArgs`), read the same in every
//! command that takes them.

use std::collections::{BTreeMap, BTreeSet};

// only `jointid` of the shared helpers is used here
#[allow(dead_code)]
mod common;
use common::jointid;

/// `jointid ARGS` run to success; its standard output.
fn stdout(args: &[&str]) -> String {
    let out = jointid(args);
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

/// The subcommands `jointid --help` lists (without `help`).
fn commands() -> Vec<String> {
    let help = stdout(&["--help"]);
    let commands: Vec<String> = help
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|c| *c != "help")
        .map(str::to_string)
        .collect();
    assert!(commands.len() >= 10, "{help}");
    commands
}

/// One option of clap's list: its long names (the flag first, then its aliases) and its
/// description (every line under it, joined, the alias and default notes left out).
#[derive(Debug, Default)]
struct Flag {
    names: Vec<String>,
    description: String,
}

/// Help output split into clap's options and the prose.
#[derive(Debug, Default)]
struct Help {
    /// by the flag's own long name
    flags: BTreeMap<String, Flag>,
    /// every line of prose (the about, argument and option descriptions, possible values)
    prose: Vec<String>,
}

/// Every `--name` in `text`, with its byte position.
fn flags_in(text: &str) -> Vec<(usize, String)> {
    let b = text.as_bytes();
    let mut found = Vec::new();
    let mut i = 0;
    while let Some(k) = text[i..].find("--") {
        let at = i + k;
        let start = at + 2;
        let end = start
            + text[start..]
                .find(|c: char| !(c.is_ascii_alphanumeric() || c == '-'))
                .unwrap_or(text.len() - start);
        let before_ok = at == 0 || !(b[at - 1].is_ascii_alphanumeric() || b[at - 1] == b'-');
        let name = text[start..end].trim_end_matches('-');
        if before_ok && name.starts_with(|c: char| c.is_ascii_lowercase()) {
            found.push((at, format!("--{name}")));
        }
        i = end.max(at + 2);
    }
    found
}

/// The `[alias: --a]` / `[aliases: --a, --b]` notes of a description: the names, and the
/// description without them and without `[default: ...]`.
fn split_notes(text: &str) -> (Vec<String>, String) {
    let mut names = Vec::new();
    let mut rest = String::new();
    let mut s = text;
    while let Some(open) = s.find('[') {
        let close = s[open..].find(']').map_or(s.len(), |c| open + c + 1);
        let note = &s[open..close];
        rest.push_str(&s[..open]);
        if note.starts_with("[alias") {
            names.extend(flags_in(note).into_iter().map(|(_, n)| n));
        } else if !note.starts_with("[default") {
            rest.push_str(note);
        }
        s = &s[close..];
    }
    rest.push_str(s);
    (names, rest.split_whitespace().collect::<Vec<_>>().join(" "))
}

/// Parses clap's help output (short or long form): an option line starts with `-x, --name`
/// or `--name` at most six spaces in; what follows it on its line after two spaces, and
/// the lines under it up to the next option, are its description.
fn parse_help(text: &str) -> Help {
    let mut help = Help::default();
    let mut current: Option<(Vec<String>, Vec<String>)> = None;
    let finish = |cur: Option<(Vec<String>, Vec<String>)>, help: &mut Help| {
        if let Some((names, lines)) = cur {
            let (aliases, description) = split_notes(&lines.join(" "));
            help.prose.extend(lines.iter().map(|l| {
                // the prose without the notes clap writes
                split_notes(l).1
            }));
            let mut all = names.clone();
            all.extend(aliases);
            help.flags.insert(
                names[0].clone(),
                Flag {
                    names: all,
                    description,
                },
            );
        }
    };
    let mut in_options = false;
    for line in text.lines() {
        if line.starts_with("Usage:") {
            continue;
        }
        if !line.starts_with(' ') && line.ends_with(':') {
            finish(current.take(), &mut help);
            in_options = line == "Options:";
            continue;
        }
        let indent = line.len() - line.trim_start().len();
        let trimmed = line.trim_start();
        if in_options && indent <= 6 && trimmed.starts_with('-') {
            finish(current.take(), &mut help);
            // the definition ends at the first run of two spaces (short form)
            let (def, desc) = trimmed.split_once("  ").unwrap_or((trimmed, ""));
            let names: Vec<String> = flags_in(def).into_iter().map(|(_, n)| n).collect();
            assert!(!names.is_empty(), "no long name in `{line}`");
            let mut lines = Vec::new();
            if !desc.trim().is_empty() {
                lines.push(desc.trim().to_string());
            }
            current = Some((names, lines));
        } else if let Some((_, lines)) = current.as_mut() {
            if !trimmed.is_empty() {
                lines.push(trimmed.to_string());
            }
        } else if !trimmed.is_empty() {
            help.prose.push(trimmed.to_string());
        }
    }
    finish(current.take(), &mut help);
    help
}

/// The command a flag at byte `at` of `line` belongs to: the command that opens its
/// backtick span (`` `jointid fit ... --save` ``), else the word just before it
/// (`simulate --params-out`), else `own`.
fn owner<'a>(line: &str, at: usize, commands: &'a [String], own: &'a str) -> &'a str {
    let is_cmd = |w: &str| commands.iter().find(|c| c.as_str() == w);
    let head = &line[..at];
    if head.matches('`').count() % 2 == 1 {
        let span = &head[head.rfind('`').unwrap() + 1..];
        let mut words = span.split_whitespace();
        let first = match words.next() {
            Some("jointid") => words.next(),
            w => w,
        };
        if let Some(c) = first.and_then(is_cmd) {
            return c;
        }
    }
    let last = head
        .trim_end()
        .rsplit(|c: char| c.is_whitespace() || c == '`' || c == '(')
        .next()
        .unwrap_or("");
    is_cmd(last).map_or(own, String::as_str)
}

/// Every `--flag` the prose of `jointid --help` and of each command's `--help` names is a
/// flag of the command it belongs to, under the flag's own name.
#[test]
fn every_flag_the_help_names_is_a_flag_of_its_command() {
    let commands = commands();
    let mut helps: BTreeMap<String, Help> = BTreeMap::new();
    helps.insert(String::new(), parse_help(&stdout(&["--help"])));
    for c in &commands {
        let h = parse_help(&stdout(&[c, "--help"]));
        assert!(h.flags.contains_key("--json"), "{c}: {:?}", h.flags.keys());
        helps.insert(c.clone(), h);
    }
    let mut wrong = BTreeSet::new();
    for (c, h) in &helps {
        for line in &h.prose {
            for (at, flag) in flags_in(line) {
                let of = owner(line, at, &commands, c);
                let target = &helps[of];
                if target.flags.contains_key(&flag) {
                    continue;
                }
                let alias_of = target
                    .flags
                    .values()
                    .find(|f| f.names.contains(&flag))
                    .map(|f| f.names[0].clone());
                let cmd = if of.is_empty() { "jointid" } else { of };
                wrong.insert(format!(
                    "`jointid {c} --help` names {flag} of `{cmd}`, {}: {line}",
                    match alias_of {
                        Some(real) => format!("an alias of {real} (name the flag)"),
                        None => "which it does not have".to_string(),
                    }
                ));
            }
        }
    }
    assert!(wrong.is_empty(), "{wrong:#?}");
}

/// The parser reads both forms of clap's help, and the check finds a flag the prose names
/// wrongly: a flag of the command, an alias, another command's flag and one that exists
/// nowhere.
#[test]
fn the_help_parser_reads_options_and_finds_a_wrong_flag() {
    let short = "about: see --b and `fit --save`\n\nUsage: x [OPTIONS]\n\nOptions:\n      \
                 --a <X>     the a, as --b [alias: --aa]\n  -b, --b     the b [default: 1]\n";
    let h = parse_help(short);
    assert_eq!(h.flags["--a"].names, ["--a", "--aa"]);
    assert_eq!(h.flags["--a"].description, "the a, as --b");
    assert_eq!(h.flags["--b"].description, "the b");
    assert_eq!(h.prose.len(), 3, "{:?}", h.prose);
    let long = "Options:\n      --a <X>\n          the a, see --c\n\n          [alias: --aa]\n\n  \
                -h, --help\n          Print help\n";
    let h = parse_help(long);
    assert_eq!(h.flags["--a"].names, ["--a", "--aa"]);
    assert_eq!(h.flags["--a"].description, "the a, see --c");
    assert!(h.flags.contains_key("--help"));
    let cmds = vec!["fit".to_string(), "simulate".to_string()];
    let line = "as `jointid fit --effect x --save M` or simulate --params-out, see --c";
    let owners: Vec<&str> = flags_in(line)
        .into_iter()
        .map(|(at, _)| owner(line, at, &cmds, "own"))
        .collect();
    assert_eq!(owners, ["fit", "fit", "simulate", "own"]);
}

/// The column flags are declared once: `analyze`, `validate`, `diagnose` and `info` give
/// `--time`, `--input`, `--output` (alias `--output-col`) and `--reference` the same help.
#[test]
fn the_column_flags_read_the_same_in_every_command_that_takes_them() {
    let mut seen: BTreeMap<&str, (String, String)> = BTreeMap::new();
    for c in ["analyze", "validate", "diagnose", "info"] {
        let h = parse_help(&stdout(&[c, "--help"]));
        for f in ["--time", "--input", "--output", "--reference"] {
            let flag = h.flags.get(f).unwrap_or_else(|| panic!("`{c}` has no {f}"));
            let said = format!("{:?} {}", flag.names, flag.description);
            match seen.get(f) {
                None => {
                    seen.insert(f, (c.to_string(), said));
                }
                Some((first, was)) => {
                    assert_eq!(&said, was, "{f} in `{c}` and in `{first}`")
                }
            }
        }
    }
}
