//! Printing shared by the commands' text reports: the residual tests' lines (`fit`,
//! `validate`), a standard deviation in per cent, and the notes on standard error about
//! the segments a command uses.

use std::io::Write;

use jointid::data::segment::{segment_list, SegmentNotes};
use jointid::data::{fmt_sig, Dataset, Selected};
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
        "    {label:<10} {:<40} {}: max |r| {:.3} vs bound {:.3} ({} of {} {} outside, {} {} allowed), χ² {} {} {}",
        t.name,
        verdict(t),
        t.max_abs,
        t.bound,
        t.outside,
        t.lags.len(),
        t.unit,
        if t.outside <= t.allowed { "≤" } else { ">" },
        t.allowed,
        one_decimal(t.statistic),
        if t.statistic <= t.critical { "≤" } else { ">" },
        one_decimal(t.critical)
    )
}

/// `x` with one decimal, or `—` when it is not finite (the χ² of a residual whose squares
/// overflow prints no `NaN`).
fn one_decimal(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.1}")
    } else {
        "—".into()
    }
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

/// The standard deviation `std` of `value` in per cent of it, two decimals, or `—` where
/// that is undefined (a value of 0, such as a delay fitted to none, or not finite).
pub(crate) fn std_percent(value: f64, std: f64) -> String {
    let p = 100.0 * std / value.abs();
    if value == 0.0 || !p.is_finite() {
        "—".into()
    } else {
        format!("{p:.2}")
    }
}

/// Prints each note on standard error as `note: ...`.
pub(crate) fn print_notes(notes: &[String]) {
    super::progress::clear();
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

/// The share of its file's time span below which a fit or a validation on a file with
/// gaps warns that it uses a part only.
pub(crate) const SHARE_WARNING: f64 = 0.5;

/// `segment 45` or `segments 3, 4`: the pieces of a selection.
pub(crate) fn pieces_phrase(sel: &Selected) -> String {
    match sel.segments.as_slice() {
        [k] => format!("segment {k}"),
        ks => format!("segments {}", segment_list(ks)),
    }
}

/// Samples the selection holds, and in words their share of the samples the file holds
/// and of those its time span covers (the missing ones included).
pub(crate) fn share(sel: &Selected) -> (usize, String) {
    let used: usize = sel.datasets.iter().map(|d| d.data.len()).sum();
    let pct = |of: usize| fmt_sig(100.0 * used as f64 / of.max(1) as f64, 2);
    let mut words = format!(
        "{} % of the {} samples the file holds",
        pct(sel.record_samples),
        sel.record_samples
    );
    if sel.record_span > sel.record_samples {
        words += &format!(
            ", {} % of the {} its time span covers",
            pct(sel.record_span),
            sel.record_span
        );
    }
    (used, words)
}

/// The warning of a fit or a validation (`role`) on less than [`SHARE_WARNING`] of the time span of a file with
/// gaps: which segments, how many samples, what share.
pub(crate) fn share_warning(sel: &Selected, role: &str) -> Option<String> {
    let (used, pct) = share(sel);
    if sel.record_pieces < 2 || used as f64 >= SHARE_WARNING * sel.record_span as f64 {
        return None;
    }
    Some(format!(
        "{}: the {role} uses {} of the file's {} gap-free segments, {used} samples: {pct}; the \
         rest lies in gaps and the other segments (`jointid info` lists them)",
        sel.datasets[0].name,
        pieces_phrase(sel),
        sel.record_pieces,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn std_percent_is_a_dash_where_it_is_undefined() {
        assert_eq!(std_percent(2.0, 0.02), "1.00");
        assert_eq!(std_percent(-4.0, 1.0), "25.00");
        assert_eq!(std_percent(0.0, 8e-6), "—");
        assert_eq!(std_percent(0.0, 0.0), "—");
        assert_eq!(std_percent(1.0, f64::NAN), "—");
    }
}
