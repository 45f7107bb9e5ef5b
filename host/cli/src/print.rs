//! Printing shared by the commands' text reports: the residual tests' lines (`fit`,
//! `validate`), a standard deviation in per cent, and the notes on standard error about
//! the segments a command uses.

use std::io::Write;

use jointid::data::segment::SegmentNotes;
use jointid::data::Dataset;
use jointid::ident::validate::{CorrelationTest, Validation};

/// The two residual tests of `v` (whiteness, input independence), one line each, under
/// the record's `label`.
pub(crate) fn print_tests(out: &mut dyn Write, label: &str, v: &Validation) -> std::io::Result<()> {
    for t in [&v.whiteness, &v.independence] {
        print_test(out, label, t)?;
    }
    Ok(())
}

fn print_test(out: &mut dyn Write, label: &str, t: &CorrelationTest) -> std::io::Result<()> {
    writeln!(
        out,
        "    {label:<10} {:<40} {}: max |r| {:.3} vs bound {:.3} ({} of {} {} outside, {} {} allowed), χ² {:.1} {} {:.1}",
        t.name,
        verdict(t),
        t.max_abs,
        t.bound,
        t.outside,
        t.lags.len(),
        t.unit,
        if t.outside <= t.allowed { "≤" } else { ">" },
        t.allowed,
        t.statistic,
        if t.statistic <= t.critical { "≤" } else { ">" },
        t.critical
    )
}

/// `pass`, `FAIL`, or `FAIL (N residual samples are NaN or infinite)`: the figures
/// printed beside it (lags outside against those allowed, χ² against its 99 % point)
/// say which criterion failed.
pub(crate) fn verdict(t: &CorrelationTest) -> String {
    match (t.pass, t.non_finite) {
        (true, _) => "pass".into(),
        (false, 0) => "FAIL".into(),
        (false, _) => format!("FAIL ({})", t.failure().unwrap_or_default()),
    }
}

/// The standard deviation `std` of `value` in per cent of it, two decimals.
pub(crate) fn std_percent(value: f64, std: f64) -> String {
    format!("{:.2}", 100.0 * std / value.abs().max(f64::MIN_POSITIVE))
}

/// Prints each note on standard error as `note: ...`.
pub(crate) fn print_notes(notes: &[String]) {
    for n in notes {
        let _ = writeln!(std::io::stderr(), "note: {n}");
    }
}

/// The segments of `segs` (numbered `numbers`, of the record `name`) that a time-domain
/// computation takes, and their numbers ([`jointid::data::segment::usable_segments`]);
/// prints its notes in the words of `notes`. `segs` is left empty.
pub(crate) fn usable_segments(
    segs: &mut Vec<Dataset>,
    numbers: &[usize],
    name: &str,
    notes: SegmentNotes,
) -> (Vec<Dataset>, Vec<usize>) {
    let u = jointid::data::segment::usable_segments(std::mem::take(segs), numbers, name, notes);
    print_notes(&u.notes);
    (u.datasets, u.segments)
}
