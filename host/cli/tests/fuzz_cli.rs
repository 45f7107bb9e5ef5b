//! The command line fuzzed (issue 37, "Deliver"): random combinations of commands, flags
//! and values over small random files (valid captures of `jointid simulate`, truncated
//! and garbled copies of them, random bytes, CSVs of odd numbers, the capture CSV with a
//! glitch of 1e6 to 1e308 in a few cells), a few hundred cases from
//! a fixed seed, so every run of CI tries the same ones. Each run must
//! - not panic (exit 101, or `panicked` on standard error),
//! - end within [`LIMIT`] (else it is killed and the case fails),
//! - when it exits 0, hold no number that is not finite (`NaN`, `inf`) on standard output
//!   or in a file it wrote.
//!
//! A failing case is printed with its command line and kept in its scratch directory.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::Duration;

use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestCaseError, TestRng, TestRunner};

#[allow(dead_code)] // not every helper is used here
mod common;
use common::{jointid, jointid_within, json_of, non_finite_word, tmpdir};

/// Longest a case may run before it counts as a hang.
const LIMIT: Duration = Duration::from_secs(20);

/// The valid files every case starts from: captures of `jointid simulate` (CSV and
/// `.jcap`) and a model file of `jointid fit --save`.
struct Fixtures {
    dir: PathBuf,
    csv: Vec<u8>,
    jcap: Vec<u8>,
    model: Vec<u8>,
}

fn fixtures() -> &'static Fixtures {
    static F: OnceLock<Fixtures> = OnceLock::new();
    F.get_or_init(|| {
        let dir = tmpdir("fuzz-fixtures");
        let sim = |name: &str| {
            let out = dir.join(name);
            json_of(&jointid(&[
                "simulate",
                "--model",
                "two-mass",
                "--periods",
                "3",
                "--out",
                out.to_str().unwrap(),
                "--json",
            ]));
            std::fs::read(out).unwrap()
        };
        let (csv, jcap) = (sim("run.csv"), sim("run.jcap"));
        let model = dir.join("m.json");
        json_of(&jointid(&[
            "fit",
            dir.join("run.csv").to_str().unwrap(),
            "--model",
            "black-box:2",
            "--save",
            model.to_str().unwrap(),
            "--json",
        ]));
        let model = std::fs::read(model).unwrap();
        Fixtures {
            dir,
            csv,
            jcap,
            model,
        }
    })
}

/// A data or model file of one case.
#[derive(Clone, Debug)]
enum File {
    /// fixture 0 (CSV), 1 (`.jcap`) or 2 (model) as it is
    Valid(usize),
    /// the fixture cut at this share of its bytes
    Truncated(usize, f64),
    /// the fixture with bytes replaced: (share of the length, new byte)
    Garbled(usize, Vec<(f64, u8)>),
    /// random bytes
    Random(Vec<u8>),
    /// a CSV `t,u,y` of odd cells
    OddCsv(Vec<(String, String, String)>),
    /// the capture CSV with cells of its data rows replaced: (share of the rows, column
    /// 1..=3, cell): a logger's glitch in a record otherwise whole (`u = 1e300` passed
    /// `analyze` with `inf` and `NaN` printed, where random bytes never reached)
    Poked(Vec<(f64, usize, String)>),
}

/// Cells a logger might write and a parser might choke on.
const ODD_CELLS: [&str; 16] = [
    "0",
    "-0",
    "1e308",
    "-1e308",
    "1e-320",
    "nan",
    "inf",
    "-inf",
    "NaN",
    "",
    "abc",
    "1,5",
    "0x10",
    "9007199254740993",
    "1e100",
    "  2.5  ",
];

/// Numbers a glitch leaves in a record: far out, computable or not.
const GLITCHES: [&str; 8] = [
    "1e6", "-1e6", "1e99", "1e100", "1e300", "-1e300", "1e308", "-1e308",
];

fn file() -> impl Strategy<Value = File> {
    let cell = prop_oneof![
        3 => (-1e3f64..1e3).prop_map(|v| v.to_string()),
        1 => proptest::sample::select(&ODD_CELLS[..]).prop_map(str::to_string),
    ];
    let time = prop_oneof![
        4 => (0usize..4000).prop_map(|k| (k as f64 * 5e-4).to_string()),
        1 => proptest::sample::select(&ODD_CELLS[..]).prop_map(str::to_string),
    ];
    prop_oneof![
        8 => (0usize..3).prop_map(File::Valid),
        2 => (0usize..3, 0.0f64..1.0).prop_map(|(f, s)| File::Truncated(f, s)),
        3 => (0usize..3, proptest::collection::vec((0.0f64..1.0, any::<u8>()), 1..40))
            .prop_map(|(f, b)| File::Garbled(f, b)),
        1 => proptest::collection::vec(any::<u8>(), 0..3000).prop_map(File::Random),
        2 => proptest::collection::vec((time, cell.clone(), cell), 0..300).prop_map(File::OddCsv),
        4 => proptest::collection::vec(
            (
                0.0f64..1.0,
                1usize..4,
                proptest::sample::select(&GLITCHES[..]).prop_map(str::to_string),
            ),
            1..3,
        )
        .prop_map(File::Poked),
    ]
}

impl File {
    fn bytes(&self, f: &Fixtures) -> Vec<u8> {
        let fixture = |k: usize| match k {
            0 => f.csv.clone(),
            1 => f.jcap.clone(),
            _ => f.model.clone(),
        };
        match self {
            File::Valid(k) => fixture(*k),
            File::Truncated(k, s) => {
                let mut b = fixture(*k);
                b.truncate((b.len() as f64 * s) as usize);
                b
            }
            File::Garbled(k, edits) => {
                let mut b = fixture(*k);
                for (at, byte) in edits {
                    let i = ((b.len() as f64 * at) as usize).min(b.len().saturating_sub(1));
                    if let Some(x) = b.get_mut(i) {
                        *x = *byte;
                    }
                }
                b
            }
            File::Random(b) => b.clone(),
            File::Poked(edits) => {
                let text = String::from_utf8(f.csv.clone()).unwrap();
                let mut lines: Vec<String> = text.lines().map(String::from).collect();
                let header = lines.iter().position(|l| l.starts_with("t,")).unwrap();
                let rows = lines.len() - header - 1;
                for (at, col, cell) in edits {
                    let i = header + 1 + ((rows as f64 * at) as usize).min(rows - 1);
                    let mut cells: Vec<String> = lines[i].split(',').map(String::from).collect();
                    if let Some(c) = cells.get_mut(*col) {
                        c.clone_from(cell);
                    }
                    lines[i] = cells.join(",");
                }
                (lines.join("\n") + "\n").into_bytes()
            }
            File::OddCsv(rows) => {
                let mut s = String::from("t,u,y\n");
                for (t, u, y) in rows {
                    s += &format!("{t},{u},{y}\n");
                }
                s.into_bytes()
            }
        }
    }

    /// where a model file is read: a valid file is the model
    fn as_model(&self) -> File {
        match self {
            File::Valid(_) => File::Valid(2),
            f => f.clone(),
        }
    }

    /// where data are read: a valid file is a capture (CSV or `.jcap`)
    fn as_data(&self) -> File {
        match self {
            File::Valid(2) => File::Valid(0),
            f => f.clone(),
        }
    }

    /// where a `.jcap` is read: a valid file is the `.jcap`
    fn as_capture(&self) -> File {
        match self {
            File::Valid(_) => File::Valid(1),
            f => f.clone(),
        }
    }

    /// the columns of an odd CSV
    fn mapping(&self) -> &'static [&'static str] {
        match self {
            File::OddCsv(_) => &["--time", "t", "--input", "u", "--output", "y"],
            _ => &[],
        }
    }
}

/// Flags of each command with values to draw from; `OUT` is replaced by a file in the
/// case's directory.
fn flags(command: &str) -> Vec<(&'static str, Vec<&'static str>)> {
    let read = vec![
        (
            "--segment",
            vec!["longest", "all", "1", "2", "0", "99", "x"],
        ),
        ("--from", vec!["0", "1.5", "1p", "3p", "-1", "1e308", "nan"]),
        ("--to", vec!["0", "2", "2p", "100", "1e-9", "inf"]),
        ("--delimiter", vec![";", "tab", ","]),
        ("--json", vec![]),
    ];
    let prep = vec![
        ("--decimate", vec!["1", "2", "5", "0", "1000000"]),
        ("--detrend", vec!["none", "mean", "linear"]),
        ("--settle-periods", vec!["0", "1", "2", "1000"]),
        ("--lags", vec!["1", "25", "0", "100000"]),
    ];
    match command {
        "fit" => [
            read,
            prep,
            vec![
                (
                    "--model",
                    vec![
                        "black-box:1",
                        "black-box:4",
                        "black-box:0",
                        "black-box:99999",
                        "rigid",
                        "two-mass",
                        "grounded",
                        "nonsense",
                    ],
                ),
                ("--domain", vec!["auto", "time", "frequency"]),
                ("--estimation-fraction", vec!["0.5", "0.01", "0.99", "1.5"]),
                ("--current-loop-tau", vec!["0", "1e-4", "0.9", "-1"]),
                ("--delay", vec!["0", "2.5", "1e9"]),
                ("--gear-ratio", vec!["0.01", "0", "-1", "1e300"]),
                ("--friction", vec!["viscous", "coulomb"]),
                ("--output-kind", vec!["angle", "velocity"]),
                ("--method", vec!["pbsid", "moesp"]),
                ("--no-refine", vec![]),
                ("--feedthrough", vec![]),
                ("--strict", vec![]),
                ("--save", vec!["OUT.json", "OUT.mat"]),
            ],
        ]
        .concat(),
        "analyze" => [
            read,
            vec![
                ("--settle-periods", vec!["0", "1", "2", "1000"]),
                ("--require-linear", vec![]),
                ("--all-lines", vec![]),
            ],
        ]
        .concat(),
        "validate" => [
            read,
            prep,
            vec![("--require-fit", vec!["50", "-1e308", "nan"])],
        ]
        .concat(),
        "info" => vec![
            ("--strict", vec![]),
            ("--session", vec!["0", "1", "99"]),
            ("--json", vec![]),
        ],
        "export" => vec![
            ("--csv", vec!["OUT.csv"]),
            ("--mat", vec!["OUT.mat"]),
            ("--session", vec!["0", "1"]),
            ("--json", vec![]),
        ],
        "export-model" => vec![
            (
                "--format",
                vec!["json-ss", "json-tf", "python-control", "mat", "x"],
            ),
            ("--out", vec!["OUT.txt"]),
            ("--linear-axis", vec![]),
            ("--json", vec![]),
        ],
        _ => vec![
            (
                "--model",
                vec!["rigid", "two-mass", "three-mass", "grounded", "x"],
            ),
            (
                "--param",
                vec!["J_m=1e-30", "k_g=1e12", "J_m=nan", "x=1", "f_m=0"],
            ),
            (
                "--effect",
                vec![
                    "backlash",
                    "coulomb_friction:fc=1e9",
                    "time_delay:samples=1e9",
                    "torque_ripple",
                    "x",
                ],
            ),
            (
                "--excitation",
                vec!["odd-multisine", "noise", "random-odd", "x"],
            ),
            ("--rms", vec!["0.01", "1e9", "-1", "nan", "0"]),
            ("--periods", vec!["1", "2", "0", "100000000"]),
            ("--seed", vec!["0", "18446744073709551615", "-1"]),
            ("--substeps", vec!["1", "4", "0"]),
            ("--ideal-sensors", vec![]),
            ("--feedforward", vec![]),
            ("--params-out", vec!["OUT.json"]),
            ("--json", vec![]),
        ],
    }
}

/// One case: a command, its file (and a second one for `validate MODEL DATA`), and picks
/// among its flags (flag index, value index; a flag may come twice).
#[derive(Clone, Debug)]
struct Case {
    seed: u8,
    command: &'static str,
    file: File,
    data: File,
    picks: Vec<(usize, usize)>,
}

fn case(commands: &'static [&'static str], seed: u8) -> impl Strategy<Value = Case> {
    (
        proptest::sample::select(commands),
        file(),
        file(),
        proptest::collection::vec((0usize..64, 0usize..64), 0..5),
    )
        .prop_map(move |(command, file, data, picks)| Case {
            seed,
            command,
            file,
            data,
            picks,
        })
}

/// Exit codes 0, 1 and 2 of the cases run, in that order.
type Tally = std::sync::Mutex<[usize; 3]>;

fn run_case(c: &Case, n: usize, tally: &Tally) -> Result<(), TestCaseError> {
    let f = fixtures();
    // `n` counts the cases of one test, `seed` tells the tests apart
    let dir = f.dir.join(format!("{}-{}-{n}", c.command, c.seed));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let write = |name: &str, file: &File| {
        let p = dir.join(name);
        std::fs::write(&p, file.bytes(f)).unwrap();
        p.display().to_string()
    };
    let mut args: Vec<String> = vec![c.command.to_string()];
    let mut mapping: &[&str] = &[];
    match c.command {
        "simulate" => args.extend(["--out".into(), dir.join("sim.csv").display().to_string()]),
        "validate" => {
            args.push(write("model.json", &c.file.as_model()));
            args.push(write("data.csv", &c.data.as_data()));
            mapping = c.data.mapping();
        }
        "export-model" => args.push(write("model.json", &c.file.as_model())),
        "export" => args.push(write("data.jcap", &c.file.as_capture())),
        _ => {
            args.push(write("data.csv", &c.file.as_data()));
            mapping = c.file.mapping();
        }
    }
    if matches!(c.command, "fit" | "analyze" | "info" | "validate") {
        args.extend(mapping.iter().map(|s| s.to_string()));
    }
    let table = flags(c.command);
    // what the command requires comes first (its first flag), then the picks, each flag
    // once unless it is repeatable; `--flag=value`, so that `-1` is a value
    let needed = match c.command {
        "fit" => Some("--model"),
        "export" => Some(if n.is_multiple_of(2) {
            "--csv"
        } else {
            "--mat"
        }),
        "export-model" => Some("--format"),
        _ => None,
    };
    let required = needed.and_then(|name| {
        let i = table.iter().position(|(f, _)| *f == name)?;
        Some((i, c.picks.first().map_or(n, |p| p.1)))
    });
    let mut seen = Vec::new();
    for &(i, v) in required.iter().chain(&c.picks) {
        let (flag, values) = &table[i % table.len()];
        if seen.contains(flag) && !matches!(*flag, "--param" | "--effect") {
            continue;
        }
        seen.push(*flag);
        if values.is_empty() {
            args.push(flag.to_string());
            continue;
        }
        let v = values[v % values.len()];
        let v = match v.strip_prefix("OUT") {
            Some(ext) => dir.join(format!("out{n}{ext}")).display().to_string(),
            None => v.to_string(),
        };
        args.push(format!("{flag}={v}"));
    }
    let argv: Vec<&str> = args.iter().map(String::as_str).collect();
    let shown = format!("jointid {}", args.join(" "));
    let Some(out) = jointid_within(&argv, LIMIT) else {
        return Err(TestCaseError::fail(format!(
            "{shown}: still running after {LIMIT:?}"
        )));
    };
    let stderr = String::from_utf8_lossy(&out.stderr);
    if let Some(k) = out.status.code().filter(|k| (0..3).contains(k)) {
        tally.lock().unwrap()[k as usize] += 1;
    }
    prop_assert!(
        out.status.code() != Some(101) && !stderr.contains("panicked"),
        "{shown}: panicked ({:?}): {stderr}",
        out.status
    );
    prop_assert!(
        out.status.code().is_some(),
        "{shown}: ended by a signal ({:?}): {stderr}",
        out.status
    );
    if out.status.success() {
        let stdout = String::from_utf8_lossy(&out.stdout);
        if let Some(w) = non_finite_word(&stdout) {
            return Err(TestCaseError::fail(format!(
                "{shown}: exit 0 with `{w}` on standard output:\n{stdout}"
            )));
        }
        for entry in std::fs::read_dir(&dir).unwrap().flatten() {
            let p = entry.path();
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            if name.starts_with("out") || name.starts_with("sim") {
                check_written(&p, &shown)?;
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}

/// A file a successful run wrote holds no number that is not finite (text files; a
/// MATLAB file's doubles read as they are stored).
fn check_written(p: &Path, shown: &str) -> Result<(), TestCaseError> {
    let bytes = std::fs::read(p).unwrap();
    if p.extension().is_some_and(|e| e == "mat") {
        // uncompressed Level 5: the doubles of each miDOUBLE (type 9) element
        let mut i = 128;
        while i + 8 <= bytes.len() {
            let ty = u32::from_le_bytes(bytes[i..i + 4].try_into().unwrap());
            let len = u32::from_le_bytes(bytes[i + 4..i + 8].try_into().unwrap()) as usize;
            let body = &bytes[(i + 8).min(bytes.len())..(i + 8 + len).min(bytes.len())];
            if ty == 14 {
                // a matrix: its sub-elements follow in its body
                i += 8;
                continue;
            }
            if ty == 9 {
                for d in body.chunks_exact(8) {
                    let v = f64::from_le_bytes(d.try_into().unwrap());
                    prop_assert!(v.is_finite(), "{shown}: {} holds {v}", p.display());
                }
            }
            i += 8 + len.div_ceil(8) * 8;
        }
        return Ok(());
    }
    let text = String::from_utf8_lossy(&bytes);
    if let Some(w) = non_finite_word(&text) {
        return Err(TestCaseError::fail(format!(
            "{shown}: exit 0 with `{w}` in {}",
            p.display()
        )));
    }
    Ok(())
}

/// Runs `cases` cases of `commands` from the fixed `seed`.
fn fuzz(commands: &'static [&'static str], cases: u32, seed: u8) {
    let config = Config {
        cases,
        failure_persistence: None,
        max_shrink_iters: 16,
        ..Config::default()
    };
    let rng = TestRng::from_seed(RngAlgorithm::ChaCha, &[seed; 32]);
    let mut runner = TestRunner::new_with_rng(config, rng);
    let counter = std::sync::atomic::AtomicUsize::new(0);
    let tally = Tally::default();
    let result = runner.run(&case(commands, seed), |c| {
        let n = counter.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
        run_case(&c, n, &tally)
    });
    if let Err(e) = result {
        panic!("{e}");
    }
    // the cases reach the work, not only the parsers' refusals
    let [ok, failed, refused] = *tally.lock().unwrap();
    eprintln!("{commands:?}: {ok} ran (exit 0), {failed} failed a check, {refused} refused");
    assert!(
        ok >= cases as usize / 10,
        "{commands:?}: only {ok} of {cases} cases ran to the end ({refused} refused)"
    );
}

#[test]
fn data_commands_neither_panic_nor_hang_nor_print_non_finite_numbers() {
    fuzz(&["fit", "analyze", "info", "validate"], 300, 37);
}

#[test]
fn file_commands_neither_panic_nor_hang_nor_write_non_finite_numbers() {
    fuzz(&["export", "export-model", "simulate", "info"], 200, 38);
}

#[test]
fn the_checks_catch_non_finite_words_and_not_others() {
    assert_eq!(non_finite_word("FIT 12.5, -inf dB"), Some("inf".into()));
    assert_eq!(non_finite_word("{\"x\": NaN}"), Some("nan".into()));
    assert_eq!(non_finite_word("x,inf\n"), Some("inf".into()));
    assert_eq!(
        non_finite_word("info: not finite; informed; nano; 1e-5"),
        None
    );
}
