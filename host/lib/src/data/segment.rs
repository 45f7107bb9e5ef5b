//! Records with gaps: the gap-free segments of a file, and which of them (and which
//! time window) an analysis uses.
//!
//! A capture that lost samples (a serial unplug, a dropped frame) or a capture CSV with a
//! jump in its time column is read as a [`Record`]: its gap-free pieces in time order,
//! each a uniformly sampled [`Dataset`] whose `t0` places it on the excitation's time
//! line. Nothing is interpolated and nothing is dropped without being counted:
//! [`Record::select`] returns the chosen pieces and a note that names what was left out.
//!
//! Selection ([`Selection`]): first the window `from..to` (seconds of the file's time
//! column, or whole excitation periods after the ramp-in, `3p`), then the segment:
//! the longest (by whole periods when the excitation is known, else by samples), the
//! N-th (numbered from 1, in time order, as [`Record::segments`] lists them), or all of
//! them. A file without gaps is one segment.
// Units in brackets (`[s]`) are not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

use std::fmt;
use std::str::FromStr;

use serde::Serialize;
use thiserror::Error;

use super::screen::Outlier;
use super::{fmt_sig, DataError, Dataset, ExcitationConfig, PeriodLayout};

/// Which gap-free segment(s) of a record to use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SegmentChoice {
    /// the longest one (whole periods, then samples)
    Longest,
    /// the N-th in time order, numbered from 1
    Index(usize),
    /// every segment (each with at least one whole period when the excitation is known)
    All,
}

/// A `--segment`, `--from` or `--to` value that does not parse.
#[derive(Clone, Debug, PartialEq, Eq, Error)]
pub enum SelectionParseError {
    /// `--segment 0`
    #[error("segments are numbered from 1")]
    SegmentZero,
    /// neither `longest`, `all` nor a number
    #[error("`{0}`: expected longest, all or a segment number")]
    Segment(String),
    /// `Np` with a non-integer `N`
    #[error("`{0}`: whole periods are written as an integer and `p` (`3p`)")]
    Periods(String),
    /// not a time ≥ 0
    #[error("`{0}`: expected seconds (`12.5`) or whole periods (`3p`), not negative")]
    Seconds(String),
}

impl FromStr for SegmentChoice {
    type Err = SelectionParseError;
    fn from_str(s: &str) -> Result<Self, SelectionParseError> {
        match s.trim() {
            "longest" => Ok(SegmentChoice::Longest),
            "all" => Ok(SegmentChoice::All),
            n => match n.parse::<usize>() {
                Ok(0) => Err(SelectionParseError::SegmentZero),
                Ok(k) => Ok(SegmentChoice::Index(k)),
                Err(_) => Err(SelectionParseError::Segment(n.to_string())),
            },
        }
    }
}

impl fmt::Display for SegmentChoice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SegmentChoice::Longest => write!(f, "longest"),
            SegmentChoice::All => write!(f, "all"),
            SegmentChoice::Index(k) => write!(f, "{k}"),
        }
    }
}

/// One end of a time window.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TimeBound {
    /// a time of the file's time column [s]
    Seconds(f64),
    /// this many whole excitation periods after the end of the ramp-in (`3p`)
    Periods(u64),
}

impl FromStr for TimeBound {
    type Err = SelectionParseError;
    fn from_str(s: &str) -> Result<Self, SelectionParseError> {
        let s = s.trim();
        if let Some(p) = s.strip_suffix('p') {
            return p
                .trim()
                .parse::<u64>()
                .map(TimeBound::Periods)
                .map_err(|_| SelectionParseError::Periods(s.to_string()));
        }
        let secs = s.strip_suffix('s').unwrap_or(s).trim();
        match secs.parse::<f64>() {
            Ok(t) if t.is_finite() && t >= 0.0 => Ok(TimeBound::Seconds(t)),
            _ => Err(SelectionParseError::Seconds(s.to_string())),
        }
    }
}

impl fmt::Display for TimeBound {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TimeBound::Seconds(t) => write!(f, "{} s", fmt_sig(*t, 6)),
            TimeBound::Periods(p) => write!(f, "{p}p"),
        }
    }
}

/// Which part of a record an analysis uses; the default is the whole file, and on a file
/// with gaps its longest segment (with a note).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Selection {
    /// the segment(s); `None`: the only one, or the longest with a note when there are gaps
    pub segment: Option<SegmentChoice>,
    /// start of the window (inclusive)
    pub from: Option<TimeBound>,
    /// end of the window (exclusive)
    pub to: Option<TimeBound>,
}

/// A gap-free segment of a record, as `info` lists it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SegmentInfo {
    /// number of the segment, from 1, in time order
    pub index: usize,
    /// time of its first sample [s]
    pub start_s: f64,
    /// its length, samples × sample interval [s]
    pub length_s: f64,
    /// its samples
    pub samples: usize,
    /// whole excitation periods in it after the ramp-in (`None` when the excitation is
    /// not known)
    pub whole_periods: Option<usize>,
}

impl SegmentInfo {
    /// Segment `index` of `samples` samples from excitation sample `first_sample`, sampled
    /// every `ts` seconds, with its whole periods after the ramp-in when `excitation` is
    /// known (in a run whose last sample is `run_last`, [`PeriodLayout::in_run`]).
    pub fn new(
        index: usize,
        first_sample: usize,
        samples: usize,
        ts: f64,
        excitation: Option<&ExcitationConfig>,
        run_last: Option<usize>,
    ) -> Self {
        SegmentInfo {
            index,
            start_s: first_sample as f64 * ts,
            length_s: samples as f64 * ts,
            samples,
            whole_periods: excitation.map(|c| {
                PeriodLayout::in_run(c, first_sample, samples, 0, run_last).map_or(0, |l| l.count)
            }),
        }
    }
}

/// A file's data as read: its gap-free pieces in time order (one when nothing is
/// missing), and notes on what the reader ignored.
#[derive(Clone, Debug, PartialEq)]
pub struct Record {
    /// the pieces, each uniformly sampled, same name, sample interval and excitation
    pub pieces: Vec<Dataset>,
    /// what the reader ignored or guessed (unknown comment keys, the delimiter it chose)
    pub notes: Vec<String>,
}

/// The pieces an analysis gets from [`Record::select`].
#[derive(Clone, Debug, PartialEq)]
pub struct Selected {
    /// the chosen pieces (one unless `--segment all`), each cut to the window
    pub datasets: Vec<Dataset>,
    /// numbers (from 1) of the segments used, as [`Record::segments`] lists them
    pub segments: Vec<usize>,
    /// what the user should know: the reader's notes, and the segments left out
    pub notes: Vec<String>,
    /// samples the whole record holds (every piece, before the window): what the chosen
    /// pieces are a share of
    pub record_samples: usize,
    /// samples the whole record spans from its first to its last, the missing ones
    /// included
    pub record_span: usize,
    /// gap-free pieces of the whole record
    pub record_pieces: usize,
    /// the samples of the chosen pieces far outside their signal over the whole record
    /// ([`super::screen::outliers`]), in signal and row order: the first
    /// [`super::screen::MAX_KEPT`]
    pub outliers: Vec<Outlier>,
    /// how many there are
    pub outlier_count: usize,
}

impl Record {
    /// A record with one piece and no notes.
    pub fn single(ds: Dataset) -> Self {
        Record {
            pieces: vec![ds],
            notes: Vec::new(),
        }
    }

    /// The file's name (of its first piece).
    pub fn name(&self) -> &str {
        self.pieces.first().map_or("", |p| p.name.as_str())
    }

    /// Samples missing between the pieces (the sum of the gaps).
    pub fn missing_samples(&self) -> u64 {
        self.pieces
            .windows(2)
            .map(|w| {
                let step = (first_sample_f(&w[1]) - first_sample_f(&w[0])).round() as i64;
                (step - w[0].data.len() as i64).max(0) as u64
            })
            .sum()
    }

    /// The gap-free segments, numbered from 1, with their whole periods.
    pub fn segments(&self) -> Vec<SegmentInfo> {
        self.pieces
            .iter()
            .enumerate()
            .map(|(i, p)| SegmentInfo {
                start_s: p.t0,
                ..SegmentInfo::new(
                    i + 1,
                    p.first_sample(),
                    p.data.len(),
                    p.data.ts,
                    p.excitation.as_ref(),
                    p.last_sample_of_run(),
                )
            })
            .collect()
    }

    /// The record as one uniformly sampled dataset.
    ///
    /// # Errors
    /// [`DataError::Gaps`] naming the segments when the record has more than one piece.
    pub fn into_single(mut self) -> Result<Dataset, DataError> {
        if self.pieces.len() == 1 {
            return Ok(self.pieces.remove(0));
        }
        Err(self.gaps_error())
    }

    fn gaps_error(&self) -> DataError {
        DataError::Gaps {
            file: self.name().to_string(),
            gaps: self.pieces.len().saturating_sub(1),
            missing: self.missing_samples(),
            segments: describe_segments(&self.segments()),
        }
    }

    /// The pieces `sel` asks for, cut to its window, with notes on what is left out.
    ///
    /// # Errors
    /// [`DataError::Selection`] when the window is empty or outside the record, a segment
    /// number does not exist, whole periods are asked for without a known excitation, or
    /// nothing with a whole period is left for `all`.
    pub fn select(&self, sel: &Selection) -> Result<Selected, DataError> {
        let name = self.name().to_string();
        let bad = |reason: String| DataError::Selection {
            file: name.clone(),
            reason,
        };
        let first = self.pieces.first().ok_or_else(|| bad("no data".into()))?;
        let ts = first.data.ts;
        let to_time = |b: TimeBound, flag: &str| -> Result<f64, DataError> {
            match b {
                TimeBound::Seconds(t) => Ok(t),
                TimeBound::Periods(p) => {
                    let cfg = first.excitation.ok_or_else(|| {
                        bad(format!(
                            "{flag} {b}: whole periods need the excitation (period and ramp), \
                             and this file does not state it; give seconds"
                        ))
                    })?;
                    let k = u64::from(cfg.ramp_samples) + p * u64::from(cfg.period_samples);
                    Ok(k as f64 * ts)
                }
            }
        };
        let from = sel.from.map(|b| to_time(b, "--from")).transpose()?;
        let to = sel.to.map(|b| to_time(b, "--to")).transpose()?;
        let last = self.pieces.last().unwrap_or(first);
        let (t_begin, t_end) = (first.t0, last.t0 + last.data.len() as f64 * ts);
        if let (Some(a), Some(b)) = (from, to) {
            if b <= a {
                return Err(bad(format!(
                    "--to {} s is not after --from {} s",
                    fmt_sig(b, 6),
                    fmt_sig(a, 6)
                )));
            }
        }
        // the window, piece by piece (keeping each piece's number)
        let mut cut: Vec<(usize, Dataset)> = Vec::new();
        for (i, p) in self.pieces.iter().enumerate() {
            let n = p.data.len();
            // sample j is at p.t0 + j ts; keep from ≤ t < to (half a sample of slack)
            let lo = from.map_or(0, |a| {
                (((a - p.t0) / ts) - 0.5).ceil().clamp(0.0, n as f64) as usize
            });
            let hi = to.map_or(n, |b| {
                (((b - p.t0) / ts) - 0.5).ceil().clamp(0.0, n as f64) as usize
            });
            if hi > lo {
                // the window's samples alone are copied (not the piece, then its window)
                let d = Dataset {
                    name: p.name.clone(),
                    data: p.data.slice(lo..hi),
                    t0: p.t0 + lo as f64 * ts,
                    excitation: p.excitation,
                    meta: p.meta.clone(),
                };
                cut.push((i + 1, d));
            }
        }
        if cut.is_empty() {
            return Err(bad(format!(
                "the window {}..{} holds no sample (the record spans {} s to {} s)",
                from.map_or_else(|| "start".to_string(), |a| format!("{} s", fmt_sig(a, 6))),
                to.map_or_else(|| "end".to_string(), |b| format!("{} s", fmt_sig(b, 6))),
                fmt_sig(t_begin, 6),
                fmt_sig(t_end, 6)
            )));
        }
        let mut notes = self.notes.clone();
        let windowed = from.is_some() || to.is_some();
        let of = |(i, d): &(usize, Dataset)| -> String {
            format!(
                "segment {i} ({} s from {} s{})",
                fmt_sig(d.data.len() as f64 * ts, 6),
                fmt_sig(d.t0, 6),
                whole_periods(d).map_or_else(String::new, |p| format!(", {p} whole periods"))
            )
        };
        let gaps_phrase = || {
            format!(
                "{} has {} gap{} ({} samples missing)",
                name,
                self.pieces.len() - 1,
                if self.pieces.len() == 2 { "" } else { "s" },
                self.missing_samples()
            )
        };
        let chosen: Vec<(usize, Dataset)> = match sel.segment {
            None if self.pieces.len() == 1 => cut,
            Some(SegmentChoice::Index(k)) => {
                if k > self.pieces.len() {
                    return Err(bad(format!(
                        "--segment {k}: the file has {} segment{} ({})",
                        self.pieces.len(),
                        if self.pieces.len() == 1 { "" } else { "s" },
                        describe_segments(&self.segments())
                    )));
                }
                let Some(c) = cut.into_iter().find(|(i, _)| *i == k) else {
                    return Err(bad(format!(
                        "--segment {k} holds no sample inside the window"
                    )));
                };
                if self.pieces.len() > 1 {
                    notes.push(format!("{}; using {}", gaps_phrase(), of(&c)));
                }
                vec![c]
            }
            None | Some(SegmentChoice::Longest) => {
                let best = cut
                    .iter()
                    .enumerate()
                    .max_by_key(|(j, (_, d))| {
                        (whole_periods(d).unwrap_or(0), d.data.len(), usize::MAX - j)
                    })
                    .map(|(j, _)| j)
                    .unwrap_or(0);
                let c = cut.swap_remove(best);
                if self.pieces.len() > 1 {
                    notes.push(format!(
                        "{}; using the longest, {}{} (--segment all uses every segment, \
                         --segment N one of them; `jointid info` lists them)",
                        gaps_phrase(),
                        of(&c),
                        if windowed { " of the window" } else { "" }
                    ));
                }
                vec![c]
            }
            Some(SegmentChoice::All) => {
                let (used, unused): (Vec<_>, Vec<_>) = cut
                    .into_iter()
                    .partition(|(_, d)| whole_periods(d).is_none_or(|p| p > 0));
                if used.is_empty() {
                    return Err(bad(format!(
                        "--segment all: no segment holds a whole excitation period ({})",
                        unused.iter().map(of).collect::<Vec<_>>().join("; ")
                    )));
                }
                if !unused.is_empty() {
                    notes.push(format!(
                        "{} not used: no whole excitation period in {}",
                        unused.len(),
                        unused.iter().map(of).collect::<Vec<_>>().join("; ")
                    ));
                }
                if self.pieces.len() > 1 {
                    notes.push(format!(
                        "{}; using {}",
                        gaps_phrase(),
                        used.iter().map(of).collect::<Vec<_>>().join("; ")
                    ));
                }
                used
            }
        };
        let (segments, datasets): (Vec<usize>, Vec<Dataset>) = chosen.into_iter().unzip();
        let (outliers, outlier_count) = super::screen::outliers(&self.pieces, |o| {
            datasets.iter().any(|d| super::screen::within(o, d))
        });
        Ok(Selected {
            datasets,
            segments,
            notes,
            record_samples: self.pieces.iter().map(|p| p.data.len()).sum(),
            record_span: self.pieces.iter().map(|p| p.data.len()).sum::<usize>()
                + usize::try_from(self.missing_samples()).unwrap_or(usize::MAX),
            record_pieces: self.pieces.len(),
            outliers,
            outlier_count,
        })
    }
}

/// The longest of `segs` (the first of equal length): the record a fit over several
/// segments is named after, plots and starts from.
///
/// # Panics
/// When `segs` is empty (a [`Selected`] always holds one record or more).
pub fn longest_segment(segs: &[Dataset]) -> &Dataset {
    &segs[longest_index(segs)]
}

/// Where [`longest_segment`] is in `segs` (0 for none).
pub fn longest_index(segs: &[Dataset]) -> usize {
    (0..segs.len())
        .max_by_key(|&i| (segs[i].data.len(), usize::MAX - i))
        .unwrap_or(0)
}

/// Segment numbers as `1, 3`.
pub fn segment_list(numbers: &[usize]) -> String {
    numbers
        .iter()
        .map(usize::to_string)
        .collect::<Vec<_>>()
        .join(", ")
}

/// Least samples of a segment that a time-domain fit takes with `--segment all`; shorter
/// ones are left out with a note (each would add an initial state for little data).
pub const MIN_SEGMENT_SAMPLES: usize = 200;

/// The two notes of a command on several segments ([`usable_segments`]), in its words.
#[derive(Clone, Copy, Debug)]
pub struct SegmentNotes {
    /// from the segments left out, listed (`segment 2 (150 samples)`)
    pub leaving: fn(&str) -> String,
    /// from the numbers of the segments used, listed (`1, 3`)
    pub using: fn(&str) -> String,
}

/// The notes of a fit over several segments ([`usable_segments`]): the segments it leaves
/// out, the segments it fits.
pub const FITTING_NOTES: SegmentNotes = SegmentNotes {
    leaving: |left| {
        format!(
            "the time-domain fit leaves out {left}: shorter than {MIN_SEGMENT_SAMPLES} samples, \
             each would add an initial state for little data"
        )
    },
    using: |list| {
        format!(
            "fitting segments {list} as separate experiments (one parameter vector, each \
             segment its own initial state)"
        )
    },
};

/// The segments a time-domain computation takes ([`usable_segments`]).
#[derive(Clone, Debug, PartialEq)]
pub struct UsableSegments {
    /// the segments of [`MIN_SEGMENT_SAMPLES`] samples or more, in order
    pub datasets: Vec<Dataset>,
    /// their numbers (from 1, as [`Record::segments`] lists them)
    pub segments: Vec<usize>,
    /// `NAME: ...` for the user: the segments left out and why (when any), and how the
    /// others are used ([`SegmentNotes`])
    pub notes: Vec<String>,
}

/// The segments `segs` (numbered `numbers`) of the record `name` that a time-domain
/// computation takes: those of [`MIN_SEGMENT_SAMPLES`] samples or more, each of which
/// is an experiment with its own initial state; the notes say which are left out and how
/// the others are used, in the words of `notes`.
pub fn usable_segments(
    segs: Vec<Dataset>,
    numbers: &[usize],
    name: &str,
    notes: SegmentNotes,
) -> UsableSegments {
    let mut datasets = Vec::new();
    let mut segments = Vec::new();
    let mut left = Vec::new();
    for (d, &k) in segs.into_iter().zip(numbers) {
        if d.data.len() >= MIN_SEGMENT_SAMPLES {
            datasets.push(d);
            segments.push(k);
        } else {
            left.push(format!("segment {k} ({} samples)", d.data.len()));
        }
    }
    let mut said = Vec::new();
    if !left.is_empty() {
        said.push(format!("{name}: {}", (notes.leaving)(&left.join(", "))));
    }
    said.push(format!(
        "{name}: {}",
        (notes.using)(&segment_list(&segments))
    ));
    UsableSegments {
        datasets,
        segments,
        notes: said,
    }
}

/// Excitation sample index of `ds`'s first sample, unrounded (`t0 / ts`).
fn first_sample_f(ds: &Dataset) -> f64 {
    ds.t0 / ds.data.ts
}

/// Whole excitation periods after the ramp-in in `ds` (`None` without an excitation).
pub fn whole_periods(ds: &Dataset) -> Option<usize> {
    ds.excitation?;
    Some(ds.period_layout(0).map_or(0, |l| l.count))
}

/// `1: 0 s + 10.2 s (20 periods); 2: ...`
fn describe_segments(segs: &[SegmentInfo]) -> String {
    segs.iter()
        .map(|s| {
            format!(
                "{}: {} s from {} s{}",
                s.index,
                fmt_sig(s.length_s, 6),
                fmt_sig(s.start_s, 6),
                s.whole_periods
                    .map_or_else(String::new, |p| format!(", {p} whole periods"))
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::{excitation_comment_lines, parse_csv_record, ColumnMap, SignalKind};

    /// A capture CSV at 1 kHz, period 10, ramp 5, 20 periods (205 samples, the ramp-out
    /// left out), with the samples `missing` never arriving; `u` is the sample index.
    fn gapped(missing: std::ops::Range<usize>) -> Record {
        let cfg = ExcitationConfig {
            kind: SignalKind::SpecialOddMultisine,
            fs_hz: 1000,
            period_samples: 10,
            max_line: 3,
            cutoff_hz: 50.0,
            rms_rad: 0.01,
            seed: 1,
            ramp_samples: 5,
            periods: 20,
        };
        let mut text = excitation_comment_lines(&cfg);
        text.push_str("# sample_interval_s=0.001\nt,theta_ref,u,theta_m\n");
        for k in (0..205).filter(|k| !missing.contains(k)) {
            text.push_str(&format!("{},0,{k},0\n", k as f64 * 1e-3));
        }
        parse_csv_record(&text, "g.csv", &ColumnMap::capture()).unwrap()
    }

    fn sel(segment: Option<SegmentChoice>, from: Option<&str>, to: Option<&str>) -> Selection {
        Selection {
            segment,
            from: from.map(|s| s.parse().unwrap()),
            to: to.map(|s| s.parse().unwrap()),
        }
    }

    #[test]
    fn a_gap_splits_the_record_into_segments_with_their_whole_periods() {
        // samples 47..=79 missing: segment 1 is 0..47 (ramp 5, periods 0..4 whole: 5..45),
        // segment 2 is 80..205 (periods from 85: 85..195, 12 whole ones, the last
        // period 195..205 included as the run's 20th)
        let rec = gapped(47..80);
        assert_eq!(rec.pieces.len(), 2);
        assert_eq!(rec.missing_samples(), 33);
        let segs = rec.segments();
        assert_eq!(segs[0].samples, 47);
        assert_eq!(segs[0].whole_periods, Some(4));
        assert_eq!(segs[1].index, 2);
        assert_eq!(segs[1].samples, 125);
        assert!((segs[1].start_s - 0.080).abs() < 1e-12);
        assert_eq!(segs[1].whole_periods, Some(12));
        // the second piece's layout starts at the next period boundary, 85
        let lay = rec.pieces[1].period_layout(1).unwrap();
        assert_eq!((lay.start, lay.count), (5, 12));
        assert_eq!(rec.pieces[1].data.u[lay.start], 85.0);
        // one record only when asked for, naming the segments and the flag
        let e = rec.clone().into_single().unwrap_err();
        assert_eq!(
            e.to_string(),
            "g.csv: 1 gap, 33 samples missing; gap-free segments 1: 0.047 s from 0 s, 4 whole \
             periods; 2: 0.125 s from 0.08 s, 12 whole periods; choose with --segment \
             longest|N|all (and --from/--to)"
        );
    }

    #[test]
    fn the_default_on_a_gapped_record_is_the_longest_segment_with_a_note() {
        let rec = gapped(47..80);
        let s = rec.select(&Selection::default()).unwrap();
        assert_eq!(s.segments, vec![2]);
        assert_eq!(s.datasets[0].data.u[0], 80.0);
        assert_eq!(s.notes.len(), 1);
        assert!(
            s.notes[0].starts_with(
                "g.csv has 1 gap (33 samples missing); using the longest, segment 2 (0.125 s \
                 from 0.08 s, 12 whole periods)"
            ),
            "{}",
            s.notes[0]
        );
        assert!(s.notes[0].contains("--segment all"));
        // a record without gaps: the whole of it, no note
        let whole = gapped(0..0);
        let s = whole.select(&Selection::default()).unwrap();
        assert_eq!(s.datasets[0].data.len(), 205);
        assert!(s.notes.is_empty());
    }

    #[test]
    fn segment_n_all_and_the_window_pick_what_is_asked() {
        let rec = gapped(47..80);
        let s = rec
            .select(&sel(Some(SegmentChoice::Index(1)), None, None))
            .unwrap();
        assert_eq!(
            (s.segments.clone(), s.datasets[0].data.len()),
            (vec![1], 47)
        );
        let s = rec
            .select(&sel(Some(SegmentChoice::All), None, None))
            .unwrap();
        assert_eq!(s.segments, vec![1, 2]);
        assert_eq!(s.datasets.len(), 2);
        // --from 3p: from the start of the fourth period after the ramp, sample 35
        let s = rec
            .select(&sel(Some(SegmentChoice::All), Some("3p"), Some("0.1")))
            .unwrap();
        assert_eq!(s.datasets[0].data.u[0], 35.0);
        assert_eq!(s.datasets[0].data.len(), 12);
        assert_eq!(
            s.datasets[1].data.u,
            (80..100).map(f64::from).collect::<Vec<_>>()
        );
        assert!((s.datasets[1].t0 - 0.08).abs() < 1e-12);
        // a segment left without a whole period is not used by `all`, and said so
        let s = rec
            .select(&sel(Some(SegmentChoice::All), Some("4p"), None))
            .unwrap();
        assert_eq!(s.segments, vec![2]);
        assert!(s.notes[0].starts_with("1 not used: no whole excitation period in segment 1"));
        // errors name the file and what is wrong
        let e = rec
            .select(&sel(Some(SegmentChoice::Index(3)), None, None))
            .unwrap_err();
        assert!(
            e.to_string()
                .starts_with("g.csv: --segment 3: the file has 2 segments (1: "),
            "{e}"
        );
        let e = rec.select(&sel(None, Some("1"), None)).unwrap_err();
        assert_eq!(
            e.to_string(),
            "g.csv: the window 1 s..end holds no sample (the record spans 0 s to 0.205 s)"
        );
        let e = rec
            .select(&sel(None, Some("0.1"), Some("0.05")))
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "g.csv: --to 0.05 s is not after --from 0.1 s"
        );
    }

    #[test]
    fn bounds_and_choices_parse_and_refuse_what_they_cannot_mean() {
        assert_eq!("3p".parse(), Ok(TimeBound::Periods(3)));
        assert_eq!("2.5".parse(), Ok(TimeBound::Seconds(2.5)));
        assert_eq!("2.5s".parse(), Ok(TimeBound::Seconds(2.5)));
        assert!("-1".parse::<TimeBound>().is_err());
        assert!("1.5p".parse::<TimeBound>().is_err());
        assert_eq!("all".parse(), Ok(SegmentChoice::All));
        assert_eq!("2".parse(), Ok(SegmentChoice::Index(2)));
        assert_eq!(
            "0".parse::<SegmentChoice>(),
            Err(SelectionParseError::SegmentZero)
        );
        assert_eq!(
            "1.5p".parse::<TimeBound>().unwrap_err().to_string(),
            "`1.5p`: whole periods are written as an integer and `p` (`3p`)"
        );
    }

    #[test]
    fn usable_segments_leave_out_the_short_ones_with_a_note_and_longest_is_the_first_of_equals() {
        let piece = |n: usize| Dataset {
            name: "g.csv".into(),
            data: crate::data::IdData {
                ts: 1e-3,
                u: vec![0.0; n],
                y: vec![0.0; n],
                r: None,
            },
            t0: 0.0,
            excitation: None,
            meta: Default::default(),
        };
        let segs = vec![piece(300), piece(150), piece(300)];
        assert!(std::ptr::eq(longest_segment(&segs), &segs[0]));
        let u = usable_segments(segs, &[1, 2, 4], "g.csv", FITTING_NOTES);
        assert_eq!(u.segments, [1, 4]);
        assert_eq!(u.datasets.len(), 2);
        assert_eq!(
            u.notes,
            [
                "g.csv: the time-domain fit leaves out segment 2 (150 samples): shorter than \
                 200 samples, each would add an initial state for little data",
                "g.csv: fitting segments 1, 4 as separate experiments (one parameter vector, \
                 each segment its own initial state)"
            ]
        );
    }
}
