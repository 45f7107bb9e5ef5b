//! `jointid capture`: record the board's stream into a `.jcap`.
//!
//! Layers (as ripgrep's `lowargs`/`hiargs`): [`CaptureArgs`] is what clap parsed (one
//! source out of seven is enforced by an argument group, numbers are range-checked by
//! their value parsers); [`CaptureArgs::validate`] turns it into a
//! [`jointid::capture::SourceSpec`] and [`jointid::capture::CaptureOptions`]; [`run`]
//! installs the Ctrl-C handler, draws the progress line and prints the summary.
//!
//! Output: progress on stderr (hidden when stderr is not a terminal or with `--quiet`),
//! the summary on stdout, as text or, with `--json`, as one JSON object with the fields
//! of [`jointid::capture::CaptureReport`] plus `out`, `stop` and `elapsed_s`.
//! Exit status: 0 captured, 1 `--strict` and something is missing or damaged, 2 error.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::time::Duration;

use serde::Serialize;

use super::{print_json, CmdResult, Context, Outcome};
use jointid::capture::{
    record_capture, CaptureOptions, CaptureReport, Progress, SourceSpec, StopRule,
};
use jointid::data::input::path_text;

/// Default serial baud rate: 2 kHz of samples needs about 420 kbaud (field notes §0.7).
pub const DEFAULT_BAUD: u32 = 921_600;

/// Arguments of `jointid capture`.
#[derive(Clone, Debug, PartialEq, clap::Args)]
#[command(group(clap::ArgGroup::new("source").required(true).args(["serial", "can", "slcan", "candump", "tcp", "tcp_listen", "file"])))]
pub struct CaptureArgs {
    /// Serial port to read (`/dev/ttyACM0`, `COM3`); reopened after an unplug
    #[arg(long, value_name = "PORT")]
    pub serial: Option<String>,
    /// Baud rate of the serial port [bit/s] (default 921600; with --slcan 115200, which
    /// USB adapters ignore)
    #[arg(long, value_name = "N", conflicts_with_all = ["can", "candump", "tcp", "tcp_listen", "file"],
          value_parser = clap::value_parser!(u32).range(1..))]
    pub baud: Option<u32>,
    /// SocketCAN interface to read (`can0`), classic and FD frames (Linux)
    #[arg(long, value_name = "IFACE")]
    pub can: Option<String>,
    /// slcan CAN adapter to read (CANable, USBtin, Lawicel: `/dev/ttyACM0`); its channel
    /// is opened (`C`, the bit rate, `O`) and closed again at the end
    #[arg(long, value_name = "PORT")]
    pub slcan: Option<String>,
    /// CAN bit rate of the slcan adapter [bit/s]: 10000 to 1000000 (`S0`..`S8`; the
    /// firmware sends at 1000000); default: the adapter's own setting
    #[arg(long, value_name = "BIT/S", value_parser = parse_slcan_bitrate,
          conflicts_with_all = ["serial", "can", "candump", "tcp", "tcp_listen", "file"])]
    pub slcan_bitrate: Option<u32>,
    /// CAN FD data-phase bit rate of the slcan adapter [bit/s]: 500000, 1000000, 2000000,
    /// 4000000 or 5000000 (`Y0`..`Y5` of CANable 2.0-class adapters; the firmware sends
    /// at 5000000); default: the adapter's own setting
    #[arg(long, value_name = "BIT/S", value_parser = parse_slcan_data_bitrate,
          conflicts_with_all = ["serial", "can", "candump", "tcp", "tcp_listen", "file"])]
    pub slcan_data_bitrate: Option<u32>,
    /// `candump -l` log file to replay (`(1700000000.123456) can0 101#80...`)
    #[arg(long, value_name = "LOG")]
    pub candump: Option<PathBuf>,
    /// CAN identifier of the board's frames (--can, --slcan, --candump): `0x101` (the
    /// firmware's), any standard or extended id in hex or decimal, or `any`
    #[arg(long, value_name = "ID", conflicts_with_all = ["serial", "tcp", "tcp_listen", "file"], value_parser = parse_can_id)]
    pub can_id: Option<CanId>,
    /// TCP endpoint to connect to and read, `HOST:PORT` (the emulated board's UART as a
    /// server: QEMU `-serial tcp:HOST:PORT,server=on`)
    #[arg(long, value_name = "HOST:PORT")]
    pub tcp: Option<String>,
    /// TCP address to listen on, `HOST:PORT`, until the board connects and while it
    /// sends (QEMU `-serial tcp:HOST:PORT`, as `JOINTID_SERIAL=tcp:HOST:PORT cargo
    /// fw-qemu-run` does)
    #[arg(long, value_name = "HOST:PORT")]
    pub tcp_listen: Option<String>,
    /// Raw byte stream to read: a recorded stream, a named pipe or a pty
    #[arg(long, value_name = "PATH")]
    pub file: Option<PathBuf>,
    /// Capture file to write (append-only; see `jointid info`)
    #[arg(long, value_name = "RUN.jcap")]
    pub out: PathBuf,
    /// Replace an existing capture file
    #[arg(long)]
    pub force: bool,
    /// Stop after this many seconds of wall time
    #[arg(long, value_name = "SECONDS", value_parser = parse_seconds)]
    pub duration: Option<f64>,
    /// Stop after N whole excitation periods following the ramp-in
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub periods: Option<u32>,
    /// Keep reading after the board's end-of-session message
    #[arg(long)]
    pub ignore_end: bool,
    /// No progress line
    #[arg(long, short)]
    pub quiet: bool,
    /// Exit with status 1 when anything is missing or damaged
    #[arg(long)]
    pub strict: bool,
}

/// Default CAN identifier of the board's stream (the firmware's `CAN_ID`).
pub const DEFAULT_CAN_ID: u16 = 0x101;

/// A `--can-id` value.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CanId {
    /// every data frame
    Any,
    /// only this identifier
    Id(embedded_can::Id),
}

fn parse_can_id(s: &str) -> Result<CanId, String> {
    if s == "any" {
        return Ok(CanId::Any);
    }
    let v = match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(hex) => u32::from_str_radix(hex, 16),
        None => s.parse(),
    }
    .map_err(|_| format!("`{s}` is not a CAN identifier (hex 0x101, decimal, or any)"))?;
    if let Some(id) = u16::try_from(v)
        .ok()
        .and_then(embedded_can::StandardId::new)
    {
        return Ok(CanId::Id(id.into()));
    }
    embedded_can::ExtendedId::new(v)
        .map(|id| CanId::Id(id.into()))
        .ok_or_else(|| format!("`{s}` is above the largest extended CAN identifier 0x1fffffff"))
}

fn parse_slcan_bitrate(s: &str) -> Result<u32, String> {
    let v: u32 = s
        .parse()
        .map_err(|_| format!("`{s}` is not a bit rate in bit/s"))?;
    jointid::capture::canlog::slcan_bitrate_command(v).map_err(|e| e.to_string())?;
    Ok(v)
}

fn parse_slcan_data_bitrate(s: &str) -> Result<u32, String> {
    let v: u32 = s
        .parse()
        .map_err(|_| format!("`{s}` is not a bit rate in bit/s"))?;
    jointid::capture::canlog::slcan_data_bitrate_command(v).map_err(|e| e.to_string())?;
    Ok(v)
}

fn parse_seconds(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .parse()
        .map_err(|_| format!("`{s}` is not a number of seconds"))?;
    if !(v.is_finite() && v > 0.0 && v < 1.0e9) {
        return Err(format!("`{s}` must be a positive number of seconds"));
    }
    Ok(v)
}

/// Default baud rate of an slcan adapter's serial link [bit/s] (USB adapters ignore it).
pub const DEFAULT_SLCAN_BAUD: u32 = 115_200;

impl CaptureArgs {
    /// The identifier `--can-id` asks for (default the firmware's).
    fn board_can_id(&self) -> Option<embedded_can::Id> {
        match self.can_id {
            Some(CanId::Any) => None,
            Some(CanId::Id(id)) => Some(id),
            None => embedded_can::StandardId::new(DEFAULT_CAN_ID).map(Into::into),
        }
    }

    /// The validated source and options.
    pub fn validate(&self) -> (SourceSpec, CaptureOptions) {
        let spec = if let Some(port) = &self.serial {
            SourceSpec::Serial {
                port: port.clone(),
                baud: self.baud.unwrap_or(DEFAULT_BAUD),
            }
        } else if let Some(iface) = &self.can {
            SourceSpec::Can {
                iface: iface.clone(),
                id: self.board_can_id(),
            }
        } else if let Some(port) = &self.slcan {
            SourceSpec::Slcan {
                port: port.clone(),
                baud: self.baud.unwrap_or(DEFAULT_SLCAN_BAUD),
                bitrate: self.slcan_bitrate,
                data_bitrate: self.slcan_data_bitrate,
                id: self.board_can_id(),
            }
        } else if let Some(path) = &self.candump {
            SourceSpec::Candump {
                path: path.clone(),
                id: self.board_can_id(),
            }
        } else if let Some(addr) = &self.tcp {
            SourceSpec::Tcp { addr: addr.clone() }
        } else if let Some(addr) = &self.tcp_listen {
            SourceSpec::TcpListen { addr: addr.clone() }
        } else {
            // the argument group guarantees one source
            SourceSpec::File {
                path: self.file.clone().unwrap_or_default(),
            }
        };
        let mut opts = CaptureOptions::new(self.out.clone());
        opts.overwrite = self.force;
        opts.stop = StopRule {
            duration: self.duration.map(Duration::from_secs_f64),
            periods: self.periods,
            ignore_end: self.ignore_end,
        };
        (spec, opts)
    }
}

/// What `capture --json` prints.
#[derive(Debug, Serialize)]
pub struct CaptureSummary {
    /// the capture file written
    pub out: String,
    /// why the capture stopped
    pub stop: String,
    /// wall time of the capture [s]
    pub elapsed_s: f64,
    /// the report
    #[serde(flatten)]
    pub report: CaptureReport,
}

/// Runs `jointid capture`: [`Outcome::CheckFailed`] with `--strict` when anything is
/// missing or damaged.
///
/// # Errors
/// Setup and capture errors ([`jointid::capture::CaptureError`]; see
/// [`jointid::capture::live`] for what stays on disk), output errors.
pub fn run(args: &CaptureArgs, ctx: &mut Context<'_>) -> CmdResult {
    let (spec, opts) = args.validate();
    // a second Ctrl-C while the capture winds down ends the process at once; the file is
    // still readable (append-only)
    let interrupt = super::interrupt::graceful();
    let bar = if args.quiet || !std::io::stderr().is_terminal() {
        indicatif::ProgressBar::hidden()
    } else {
        let bar = indicatif::ProgressBar::new_spinner();
        if let Ok(style) =
            indicatif::ProgressStyle::with_template("{spinner} {elapsed_precise} {msg}")
        {
            bar.set_style(style);
        }
        bar.set_message(format!("waiting for {spec}"));
        bar.enable_steady_tick(Duration::from_millis(200));
        bar
    };
    let mut rate = RateMeter::default();
    let outcome = record_capture(&spec, &opts, interrupt, |p, elapsed| {
        bar.set_message(progress_line(p, rate.update(p.samples, elapsed)));
    });
    bar.finish_and_clear();
    let outcome = outcome?;
    let summary = CaptureSummary {
        out: path_text(&opts.out),
        stop: outcome.stop.to_string(),
        elapsed_s: outcome.elapsed.as_secs_f64(),
        report: outcome.report,
    };
    if ctx.json {
        print_json(ctx.out, "capture", &summary)?;
    } else {
        writeln!(
            ctx.out,
            "captured {} bytes from {spec} into {} in {:.1} s ({})",
            outcome.bytes, summary.out, summary.elapsed_s, summary.stop
        )?;
        writeln!(ctx.out, "{}", summary.report)?;
        // the capture and, when the host logged events, its sidecar
        let events = jointid::capture::jcap::events_path(&opts.out);
        let files: Vec<String> = std::iter::once(summary.out.clone())
            .chain(events.is_file().then(|| path_text(&events)))
            .collect();
        super::print_written(ctx.out, &files)?;
    }
    Ok(if args.strict && !summary.report.is_clean() {
        Outcome::CheckFailed
    } else {
        Outcome::Ok
    })
}

/// Sample rate over the last few seconds, for the progress line.
#[derive(Debug, Default)]
struct RateMeter {
    last: Option<(u64, Duration)>,
    rate: f64,
}

impl RateMeter {
    fn update(&mut self, samples: u64, now: Duration) -> f64 {
        match self.last {
            Some((n0, t0)) if now > t0 + Duration::from_millis(500) => {
                let inst = (samples - n0) as f64 / (now - t0).as_secs_f64();
                self.rate = if self.rate == 0.0 {
                    inst
                } else {
                    0.7 * self.rate + 0.3 * inst
                };
                self.last = Some((samples, now));
            }
            None => self.last = Some((samples, now)),
            _ => {}
        }
        self.rate
    }
}

/// The live progress text (after the spinner and elapsed time).
pub fn progress_line(p: &Progress, rate: f64) -> String {
    format!(
        "{} samples ({rate:.0}/s)  seq {}  gaps {} ({} missing)  crc errors {}  damaged {}  overruns {}  {} bytes",
        p.samples,
        p.last_seq.map_or_else(|| "-".to_string(), |s| s.to_string()),
        p.gaps,
        p.missing,
        p.crc_errors,
        p.damaged,
        p.overruns,
        p.bytes
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Cli {
        #[command(flatten)]
        args: CaptureArgs,
    }

    fn parse(argv: &[&str]) -> Result<CaptureArgs, clap::Error> {
        Cli::try_parse_from(std::iter::once("capture").chain(argv.iter().copied())).map(|c| c.args)
    }

    #[test]
    fn capture_args_accept_each_source_alone() {
        let a = parse(&[
            "--serial",
            "/dev/ttyACM0",
            "--baud",
            "115200",
            "--out",
            "r.jcap",
        ])
        .unwrap();
        assert_eq!(
            a.validate().0,
            SourceSpec::Serial {
                port: "/dev/ttyACM0".into(),
                baud: 115_200
            }
        );
        let a = parse(&["--can", "can0", "--out", "r.jcap", "--periods", "4"]).unwrap();
        let (spec, opts) = a.validate();
        let board = embedded_can::StandardId::new(0x101).map(Into::into);
        assert_eq!(
            spec,
            SourceSpec::Can {
                iface: "can0".into(),
                id: board
            }
        );
        let a = parse(&["--can", "can1", "--can-id", "0x18FF0001", "--out", "r.jcap"]).unwrap();
        let ext = embedded_can::ExtendedId::new(0x18FF_0001).map(Into::into);
        assert_eq!(
            a.validate().0,
            SourceSpec::Can {
                iface: "can1".into(),
                id: ext
            }
        );
        let a = parse(&["--can", "can1", "--can-id", "any", "--out", "r.jcap"]).unwrap();
        assert_eq!(
            a.validate().0,
            SourceSpec::Can {
                iface: "can1".into(),
                id: None
            }
        );
        assert_eq!(opts.stop.periods, Some(4));
        let a = parse(&[
            "--tcp",
            "127.0.0.1:4321",
            "--out",
            "r.jcap",
            "--duration",
            "2.5",
        ])
        .unwrap();
        assert_eq!(
            a.validate().1.stop.duration,
            Some(Duration::from_millis(2500))
        );
        let a = parse(&["--tcp-listen", "127.0.0.1:4000", "--out", "r.jcap"]).unwrap();
        assert_eq!(
            a.validate().0,
            SourceSpec::TcpListen {
                addr: "127.0.0.1:4000".into()
            }
        );
        let a = parse(&["--file", "s.bin", "--out", "r.jcap"]).unwrap();
        assert_eq!(
            a.validate().0,
            SourceSpec::File {
                path: "s.bin".into()
            }
        );
        let a = parse(&[
            "--slcan",
            "/dev/ttyACM1",
            "--slcan-bitrate",
            "500000",
            "--can-id",
            "0x321",
            "--out",
            "r.jcap",
        ])
        .unwrap();
        assert_eq!(
            a.validate().0,
            SourceSpec::Slcan {
                port: "/dev/ttyACM1".into(),
                baud: DEFAULT_SLCAN_BAUD,
                bitrate: Some(500_000),
                data_bitrate: None,
                id: embedded_can::StandardId::new(0x321).map(Into::into),
            }
        );
        let a = parse(&["--candump", "bus.log", "--out", "r.jcap"]).unwrap();
        assert_eq!(
            a.validate().0,
            SourceSpec::Candump {
                path: "bus.log".into(),
                id: board
            }
        );
        let a = parse(&["--serial", "/dev/ttyUSB0", "--out", "r.jcap"]).unwrap();
        assert_eq!(
            a.validate().0,
            SourceSpec::Serial {
                port: "/dev/ttyUSB0".into(),
                baud: DEFAULT_BAUD
            }
        );
    }

    #[test]
    fn capture_args_reject_no_source_two_sources_and_bad_numbers() {
        for bad in [
            &["--out", "r.jcap"][..],
            &["--serial", "a", "--tcp", "h:1", "--out", "r.jcap"],
            &["--serial", "a"],
            &["--file", "f", "--baud", "9600", "--out", "r.jcap"],
            &["--serial", "a", "--baud", "0", "--out", "r.jcap"],
            &["--file", "f", "--out", "r.jcap", "--duration", "-1"],
            &["--file", "f", "--out", "r.jcap", "--duration", "nan"],
            &["--file", "f", "--out", "r.jcap", "--periods", "0"],
            &["--can", "c", "--can-id", "0x20000000", "--out", "r.jcap"],
            &["--can", "c", "--can-id", "zz", "--out", "r.jcap"],
            &["--file", "f", "--can-id", "0x101", "--out", "r.jcap"],
            &["--slcan", "p", "--candump", "l", "--out", "r.jcap"],
            &[
                "--slcan",
                "p",
                "--slcan-bitrate",
                "2000000",
                "--out",
                "r.jcap",
            ],
            &[
                "--candump",
                "l",
                "--slcan-bitrate",
                "500000",
                "--out",
                "r.jcap",
            ],
            &["--candump", "l", "--baud", "9600", "--out", "r.jcap"],
            &[
                "--slcan",
                "p",
                "--slcan-data-bitrate",
                "3000000",
                "--out",
                "r.jcap",
            ],
            &[
                "--can",
                "c",
                "--slcan-data-bitrate",
                "5000000",
                "--out",
                "r.jcap",
            ],
        ] {
            assert!(parse(bad).is_err(), "{bad:?} should be rejected");
        }
    }

    #[test]
    fn progress_line_names_every_counter() {
        let p = Progress {
            bytes: 1000,
            samples: 4000,
            last_seq: Some(4011),
            gaps: 2,
            missing: 12,
            crc_errors: 1,
            damaged: 3,
            overruns: 5,
        };
        assert_eq!(
            progress_line(&p, 1999.6),
            "4000 samples (2000/s)  seq 4011  gaps 2 (12 missing)  crc errors 1  damaged 3  overruns 5  1000 bytes"
        );
    }
}
