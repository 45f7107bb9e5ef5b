//! The capture CSV of ../shared/DESIGN.md §5, written from a [`CaptureRecord`].
//!
//! ```text
//! # format=jointid capture csv
//! # board_id=…            # session_id=…          # protocol_version=…
//! # sample_rate_hz=2000   # sample_interval_s=0.0005   # timer_hz=…
//! # torque_nm_per_count=… # angle_rad_per_count=…
//! # kind=special_odd_multisine  # fs_hz  # period_samples  # max_line  # cutoff_hz
//! # rms_rad  # seed  # ramp_samples  # periods      (the nine excitation keys `data` parses)
//! # samples=…  # first_seq=…  # last_seq=…  # missing_samples=…
//! # gaps=3..4;7..9        (inclusive missing seq ranges; `none` when there are none)
//! # damaged_frames=…  # overruns=…  # queue_drops=…  # tx_errors=…  # reference_mismatches=…
//! t,theta_ref,u,theta_m
//! ```
//!
//! One comment per line, `# key=value`. Rows: `t = seq / sample_rate_hz` [s], the
//! regenerated reference θref [rad], u = torque counts × scale [N·m], θm = angle counts ×
//! scale [rad]. Only the samples that arrived are written, in sequence order: a gap shows
//! as a jump in `t` (which a reader checking uniform sampling rejects, naming the line)
//! and is listed in `# gaps`. Numbers are written in their shortest form that reads back
//! to the same `f64` (f32 config values: the same `f32`).

use std::io::{self, Write};
use std::path::Path;

use jointid_core::excitation::SignalKind;

use super::{CaptureError, CaptureRecord};
use crate::data::write_table;

/// The name `data` uses for a signal kind in the `# kind=` comment.
pub fn kind_name(kind: SignalKind) -> &'static str {
    match kind {
        SignalKind::SpecialOddMultisine => "special_odd_multisine",
        SignalKind::RandomOddMultisine => "random_odd_multisine",
        SignalKind::BandLimitedNoise => "band_limited_noise",
    }
}

/// The `# key=value` pairs of a capture CSV, in order (the nine excitation keys among them).
pub fn comment_pairs(record: &CaptureRecord) -> Vec<(&'static str, String)> {
    let h = &record.header;
    let x = &h.excitation;
    let r = &record.report;
    let opt = |v: Option<u32>| v.map_or_else(|| "none".to_string(), |v| v.to_string());
    let gaps = if r.gaps.is_empty() {
        "none".to_string()
    } else {
        r.gaps
            .iter()
            .map(|g| format!("{}..{}", g.from, g.to))
            .collect::<Vec<_>>()
            .join(";")
    };
    vec![
        ("format", "jointid capture csv".to_string()),
        ("board_id", h.board_id.to_string()),
        ("session_id", h.session_id.to_string()),
        ("protocol_version", h.protocol_version.to_string()),
        ("sample_rate_hz", h.sample_rate_hz.to_string()),
        ("sample_interval_s", record.sample_interval_s().to_string()),
        ("timer_hz", h.timer_hz.to_string()),
        (
            "torque_nm_per_count",
            h.scale.torque_nm_per_count.to_string(),
        ),
        (
            "angle_rad_per_count",
            h.scale.angle_rad_per_count.to_string(),
        ),
        ("kind", kind_name(x.kind).to_string()),
        ("fs_hz", x.fs_hz.to_string()),
        ("period_samples", x.period_samples.to_string()),
        ("max_line", x.max_line.to_string()),
        ("cutoff_hz", x.cutoff_hz.to_string()),
        ("rms_rad", x.rms_rad.to_string()),
        ("seed", x.seed.to_string()),
        ("ramp_samples", x.ramp_samples.to_string()),
        ("periods", x.periods.to_string()),
        ("samples", record.samples.len().to_string()),
        ("first_seq", opt(r.first_seq)),
        ("last_seq", opt(r.last_seq)),
        ("missing_samples", r.missing_samples.to_string()),
        ("gaps", gaps),
        ("damaged_frames", r.damaged_frames.len().to_string()),
        ("overruns", r.board.overruns.to_string()),
        ("queue_drops", r.board.queue_drops.to_string()),
        ("tx_errors", r.board.tx_errors.to_string()),
        (
            "reference_mismatches",
            r.reference_mismatches.len().to_string(),
        ),
    ]
}

/// The `# key=value` comment block of a capture CSV (each line ends in `\n`).
pub fn comment_lines(record: &CaptureRecord) -> String {
    comment_pairs(record)
        .into_iter()
        .map(|(k, v)| format!("# {k}={v}\n"))
        .collect()
}

/// Writes the capture CSV of `record` to `out`.
///
/// # Errors
/// Whatever `out` returns.
pub fn write_csv(record: &CaptureRecord, out: &mut impl Write) -> io::Result<()> {
    write_table(
        out,
        &comment_lines(record),
        record
            .samples
            .iter()
            .map(|s| [s.t, s.theta_ref, s.u, s.theta_m]),
    )
}

/// Writes the capture CSV to `path` under the one rule of every output file
/// ([`crate::data::output`]): an existing file only with `overwrite`; written to a
/// temporary file in the same directory and renamed, so a reader never sees half an
/// export. A device such as `/dev/stdout` or a pipe is written in place; a symlink to a
/// regular file is followed (the file it names is replaced, not the link). Every write
/// and the final flush are checked.
///
/// # Errors
/// [`CaptureError::Output`] naming the file that could not be written.
pub fn export_csv(
    record: &CaptureRecord,
    path: &Path,
    overwrite: bool,
) -> Result<(), CaptureError> {
    crate::data::output::write_file(path, overwrite, |mut w| write_csv(record, &mut w))?;
    Ok(())
}

/// The capture as a Level-5 MAT-file ([`crate::data::mat`]): the column vectors `t` [s],
/// `theta_ref` [rad], `u` [N·m] and `theta_m` [rad] of the samples that arrived, and the
/// capture CSV's comment block as the text `comments` (which the loader reads back, so
/// the excitation config travels with the data). Written under the rule of every output
/// file, as [`export_csv`].
///
/// # Errors
/// [`CaptureError::Output`] naming the file that could not be written.
pub fn export_mat(
    record: &CaptureRecord,
    path: &Path,
    overwrite: bool,
) -> Result<(), CaptureError> {
    use crate::data::mat::{MatOut, MatWriter};
    let column = |f: fn(&super::CaptureSample) -> f64| {
        MatOut::column(&record.samples.iter().map(f).collect::<Vec<f64>>())
    };
    let mut w = MatWriter::new("jointid capture: t [s], theta_ref [rad], u [N m], theta_m [rad]");
    w.var("t", &column(|s| s.t))
        .var("theta_ref", &column(|s| s.theta_ref))
        .var("u", &column(|s| s.u))
        .var("theta_m", &column(|s| s.theta_m))
        .var(
            crate::data::mat::COMMENTS_VAR,
            &MatOut::Text(comment_lines(record)),
        );
    let bytes = w.finish();
    crate::data::output::write_file(path, overwrite, |w| w.write_all(&bytes))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::capture::{decode_stream, CaptureError};
    use crate::data::{parse_csv, ColumnMap, DataError};
    use crate::test_support::synth::{synth_stream, FrameContent, SynthOptions};

    #[test]
    fn exported_csv_reads_back_through_data_exactly_as_the_record() {
        let s = synth_stream(&SynthOptions::small());
        let rec = decode_stream(&s.bytes, &[]).unwrap();
        let mut csv = Vec::new();
        write_csv(&rec, &mut csv).unwrap();
        let ds = parse_csv(
            std::str::from_utf8(&csv).unwrap(),
            "run.csv",
            &ColumnMap::capture(),
        )
        .unwrap();
        assert_eq!(ds.excitation, Some(rec.header.excitation));
        assert_eq!(ds.data.ts, 1.0 / 200.0);
        assert_eq!(ds.t0, 0.0);
        assert_eq!(
            ds.data.u,
            rec.samples.iter().map(|x| x.u).collect::<Vec<_>>()
        );
        assert_eq!(
            ds.data.y,
            rec.samples.iter().map(|x| x.theta_m).collect::<Vec<_>>()
        );
        assert_eq!(
            ds.data.r.as_ref().unwrap(),
            &rec.samples.iter().map(|x| x.theta_ref).collect::<Vec<_>>()
        );
        assert_eq!(ds.meta["gaps"], "none");
        assert_eq!(ds.meta["session_id"], "7");
        // the loader path gives the same data straight from the capture
        let direct = rec.to_dataset(std::path::Path::new("run.jcap")).unwrap();
        assert_eq!(direct.data, ds.data);
        assert_eq!(direct.excitation, ds.excitation);
        assert_eq!(direct.meta, ds.meta);
    }

    #[test]
    fn a_gap_is_never_filled_the_csv_jumps_and_the_loader_refuses() {
        let s = synth_stream(&SynthOptions::small());
        let f = s
            .frames
            .iter()
            .filter(|f| matches!(f.content, FrameContent::Batch { .. }))
            .nth(3)
            .unwrap();
        let FrameContent::Batch { first, len } = f.content else {
            unreachable!()
        };
        let mut bytes = s.bytes[..f.offset as usize].to_vec();
        bytes.extend_from_slice(&s.bytes[(f.offset + f.len) as usize..]);
        let rec = decode_stream(&bytes, &[]).unwrap();
        assert_eq!(rec.samples.len(), 400 - len as usize);
        let mut csv = Vec::new();
        write_csv(&rec, &mut csv).unwrap();
        let text = String::from_utf8(csv).unwrap();
        assert!(text.contains(&format!("# gaps={}..{}\n", first, first + len - 1)));
        assert!(text.contains(&format!("# missing_samples={len}\n")));
        // the row after the gap jumps by len + 1 sample intervals; data names its line
        let err = parse_csv(&text, "gap.csv", &ColumnMap::capture()).unwrap_err();
        assert!(matches!(err, DataError::TimeGap { .. }), "{err}");
        let comments = text.lines().take_while(|l| l.starts_with('#')).count();
        let line = comments + 1 + first as usize + 1; // header, rows before the gap, the jump
        assert!(
            err.to_string().starts_with(&format!("gap.csv:{line}:")),
            "{err}"
        );
        // read as a record, the CSV and the capture give the same two pieces, each
        // placed on the excitation's time line
        let from_csv =
            crate::data::parse_csv_record(&text, "gap.jcap", &ColumnMap::capture()).unwrap();
        let from_jcap = rec.to_record(std::path::Path::new("gap.jcap")).unwrap();
        assert_eq!(from_jcap.pieces.len(), 2);
        assert_eq!(from_csv.pieces, from_jcap.pieces);
        assert_eq!(from_jcap.pieces[1].first_sample(), (first + len) as usize);
        assert_eq!(from_jcap.missing_samples(), u64::from(len));
        let err = rec
            .to_dataset(std::path::Path::new("gap.jcap"))
            .unwrap_err();
        assert!(matches!(err, CaptureError::NotUniform { .. }));
        assert_eq!(
            err.to_string(),
            format!(
                "gap.jcap: 1 gap, {len} samples missing (first seq {first}..={}); `jointid info` lists what is missing",
                first + len - 1
            )
        );
    }
}
