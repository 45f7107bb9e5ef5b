//! The capture CSV of DESIGN.md §5, written from a [`CaptureRecord`].
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

/// The name `data` uses for a signal kind in the `# kind=` comment.
pub fn kind_name(kind: SignalKind) -> &'static str {
    match kind {
        SignalKind::SpecialOddMultisine => "special_odd_multisine",
        SignalKind::RandomOddMultisine => "random_odd_multisine",
        SignalKind::BandLimitedNoise => "band_limited_noise",
    }
}

/// The `# key=value` comment block of a capture CSV (each line ends in `\n`).
pub fn comment_lines(record: &CaptureRecord) -> String {
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
    let mut s = String::new();
    let mut kv = |k: &str, v: &dyn std::fmt::Display| s.push_str(&format!("# {k}={v}\n"));
    kv("format", &"jointid capture csv");
    kv("board_id", &h.board_id);
    kv("session_id", &h.session_id);
    kv("protocol_version", &h.protocol_version);
    kv("sample_rate_hz", &h.sample_rate_hz);
    kv("sample_interval_s", &record.sample_interval_s());
    kv("timer_hz", &h.timer_hz);
    kv("torque_nm_per_count", &h.scale.torque_nm_per_count);
    kv("angle_rad_per_count", &h.scale.angle_rad_per_count);
    kv("kind", &kind_name(x.kind));
    kv("fs_hz", &x.fs_hz);
    kv("period_samples", &x.period_samples);
    kv("max_line", &x.max_line);
    kv("cutoff_hz", &x.cutoff_hz);
    kv("rms_rad", &x.rms_rad);
    kv("seed", &x.seed);
    kv("ramp_samples", &x.ramp_samples);
    kv("periods", &x.periods);
    kv("samples", &record.samples.len());
    kv("first_seq", &opt(r.first_seq));
    kv("last_seq", &opt(r.last_seq));
    kv("missing_samples", &r.missing_samples);
    kv("gaps", &gaps);
    kv("damaged_frames", &r.damaged_frames.len());
    kv("overruns", &r.board.overruns);
    kv("queue_drops", &r.board.queue_drops);
    kv("tx_errors", &r.board.tx_errors);
    kv("reference_mismatches", &r.reference_mismatches.len());
    s
}

/// Writes the capture CSV of `record` to `out`.
///
/// # Errors
/// Whatever `out` returns.
pub fn write_csv(record: &CaptureRecord, out: &mut impl Write) -> io::Result<()> {
    out.write_all(comment_lines(record).as_bytes())?;
    out.write_all(b"t,theta_ref,u,theta_m\n")?;
    let mut fmt = zmij::Buffer::new();
    let mut line = Vec::with_capacity(128);
    let mut block = Vec::with_capacity(1 << 16);
    for s in &record.samples {
        line.clear();
        for (i, v) in [s.t, s.theta_ref, s.u, s.theta_m].into_iter().enumerate() {
            if i > 0 {
                line.push(b',');
            }
            // values are finite: counts times a finite scale, a bounded generator
            line.extend_from_slice(fmt.format(v).as_bytes());
        }
        line.push(b'\n');
        block.extend_from_slice(&line);
        if block.len() >= (1 << 16) - 128 {
            out.write_all(&block)?;
            block.clear();
        }
    }
    out.write_all(&block)?;
    out.flush()
}

/// Writes the capture CSV to `path` atomically: into `path.tmp`, then renamed, so a
/// reader never sees half an export.
///
/// # Errors
/// [`CaptureError::Export`] naming the file that could not be written.
pub fn export_csv(record: &CaptureRecord, path: &Path) -> Result<(), CaptureError> {
    let mut tmp = path.as_os_str().to_os_string();
    tmp.push(".tmp");
    let tmp = std::path::PathBuf::from(tmp);
    let err = |source| CaptureError::Export {
        path: path.to_path_buf(),
        err: source,
    };
    let result = (|| {
        let file = std::fs::File::create(&tmp)?;
        let mut w = io::BufWriter::with_capacity(1 << 16, file);
        write_csv(record, &mut w)?;
        w.into_inner().map_err(|e| e.into_error())?.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(err(e));
    }
    Ok(())
}
