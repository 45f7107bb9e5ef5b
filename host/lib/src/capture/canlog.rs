//! CAN as people record it: the serial-line CAN protocol of USB adapters (slcan:
//! CANable, USBtin, Lawicel CANUSB) and the log files of `candump -l`, read line by line
//! into the capture stream through the core's CAN reassembler ([`super::can::CanStream`]).
//!
//! slcan (what the adapter sends, each line ended by `\r`; a lone BEL `0x07` is its error
//! reply):
//!
//! ```text
//! t1018 80 00 41 ...        classic, 11-bit id 0x101, 8 bytes (hex, no spaces), [tttt]
//! T18FF00018 ...            classic, 29-bit id (8 hex digits)
//! d101F <64 bytes>          CAN FD (DLC code 0..F: 0-8, 12, 16, 20, 24, 32, 48, 64 bytes);
//! D / b / B                 FD with a 29-bit id / FD with bit-rate switch (CANable 2)
//! r1010 / R18FF00010        remote frames: carry no stream bytes, ignored
//! (empty) / z / Z / V... / N... / F...   replies to commands, ignored
//! ```
//!
//! An optional timestamp of 4 hex digits (Lawicel `Z1`, milliseconds) or 8 (microseconds)
//! may follow the data. candump log (`candump -l`, one frame a line):
//!
//! ```text
//! (1700000000.123456) can0 101#80004100       classic, 3 hex digits: 11-bit id
//! (1700000000.123457) can0 18FF0001#...       8 hex digits: 29-bit id
//! (1700000000.123458) can0 101##1<data>       CAN FD: one flags digit, then the data
//! (1700000000.123459) can0 101#R              remote frame, ignored
//! ```
//!
//! An id with the error flag (`0x20000000`) is a bus error frame: it carries no stream
//! bytes and is reported like a malformed line, with its line number. Every line that
//! cannot be read is reported with its number ([`BadLine`]); it never ends the capture.

use std::collections::VecDeque;

use embedded_can::{ExtendedId, Id, StandardId};
use jointid_core::transport::can::{fd_len, MemFrame};

use super::can::{CanStats, CanStream};

/// Longest line kept for parsing [characters]; `D` with 64 data bytes and an 8-digit
/// timestamp is 147, a candump FD line about 170.
const MAX_LINE: usize = 256;
/// Characters of a bad line quoted in its report.
const QUOTE: usize = 48;
/// The error flag of a SocketCAN identifier (`CAN_ERR_FLAG`).
const CAN_ERR_FLAG: u32 = 0x2000_0000;

/// What one line holds.
#[derive(Clone, Debug, PartialEq)]
pub enum CanLine {
    /// a data frame (classic or FD)
    Data(MemFrame),
    /// a remote frame (no data; ignored)
    Remote,
    /// slcan: the adapter's reply to a command (an empty line is "OK")
    Reply,
    /// candump: a bus error frame (reported, no data)
    ErrorFrame(u32),
}

/// A line that could not be read, or an error the adapter or the bus reported.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BadLine {
    /// 1-based line number in the source (slcan: each `\r`-ended line and each BEL counts)
    pub line: u64,
    /// the line (quoted, clipped) and what is wrong with it
    pub detail: String,
}

/// Why a run of hex digits could not be read.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum HexError {
    /// bytes need two digits each
    #[error("odd number of hex digits ({0})")]
    OddCount(usize),
    /// a character that is not `0-9`, `a-f` or `A-F`
    #[error("`{}` is not a hex digit", .0.escape_ascii())]
    NotDigit(u8),
}

/// The part of a line a [`HexError`] is in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LinePart {
    /// the CAN identifier
    Identifier,
    /// slcan: the length (DLC) digit
    Length,
    /// slcan: the timestamp after the data
    Timestamp,
    /// the data bytes
    Data,
    /// candump: the flags digit of a CAN FD frame
    FdFlags,
}

impl std::fmt::Display for LinePart {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            LinePart::Identifier => "identifier",
            LinePart::Length => "length",
            LinePart::Timestamp => "timestamp",
            LinePart::Data => "data",
            LinePart::FdFlags => "FD flags",
        })
    }
}

/// Why one slcan or candump line could not be read; the text names what was expected.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum LineError {
    /// a part of the line is not hex where hex digits belong
    #[error("{part}: {source}")]
    Hex {
        /// where in the line
        part: LinePart,
        /// what is wrong with its digits
        #[source]
        source: HexError,
    },
    /// an 11-bit identifier above 0x7ff
    #[error("identifier {0:#x} is above the 11-bit maximum 0x7ff")]
    StandardId(u32),
    /// a 29-bit identifier above 0x1fffffff
    #[error("identifier {0:#x} is above the 29-bit maximum 0x1fffffff")]
    ExtendedId(u32),
    /// slcan: the first character is no frame type and no reply
    #[error("unknown line type `{}` (expected t, T, d, D, b, B, r, R or a reply)", .0.escape_ascii())]
    UnknownType(u8),
    /// slcan: the line ends before its identifier and length digit
    #[error("too short: {0} identifier digits and a length digit expected")]
    TooShort(usize),
    /// slcan: a classic frame's length digit above 8
    #[error("length {0} of a classic frame is above 8")]
    ClassicLength(u8),
    /// slcan: fewer data digits than the length digit says
    #[error("{expected} data digits for {bytes} bytes, {present} present")]
    DataDigits {
        /// digits the length needs
        expected: usize,
        /// bytes the length says
        bytes: usize,
        /// digits there
        present: usize,
    },
    /// slcan: what follows the data is no 4- or 8-digit timestamp
    #[error("{0} characters after the data (expected none or a 4- or 8-digit timestamp)")]
    Trailing(usize),
    /// an overlong line (its length in characters; only its start was kept)
    #[error("line of {0} characters (at most {MAX_LINE})")]
    Overlong(usize),
    /// candump: bytes that are not UTF-8
    #[error("not UTF-8 text")]
    NotUtf8,
    /// candump: no `(SECONDS.MICROS)` timestamp first
    #[error("expected `(SECONDS.MICROS) IFACE ID#DATA`")]
    Timestamp,
    /// candump: the interface or the frame missing
    #[error("expected an interface name and a frame after the timestamp")]
    NoFrame,
    /// candump: more after the frame than the direction `R` or `T`
    #[error("unexpected text after the frame")]
    TextAfterFrame,
    /// candump: the frame (quoted) has no `#`
    #[error("`{0}` has no `#` between identifier and data")]
    NoHash(String),
    /// candump: an identifier of neither 3 nor 8 digits
    #[error("identifier `{id}` has {digits} digits (3 for 11-bit, 8 for 29-bit)")]
    IdDigits {
        /// the identifier's text
        id: String,
        /// its digits
        digits: usize,
    },
    /// candump: a CAN XL frame (`###`)
    #[error("CAN XL frames are not supported")]
    CanXl,
    /// candump: `##` with nothing after it
    #[error("CAN FD frame without its flags digit")]
    NoFdFlags,
    /// candump: a CAN FD frame of a length no DLC gives
    #[error("{0} data bytes is not a CAN FD length (0-8, 12, 16, 20, 24, 32, 48, 64)")]
    FdLength(usize),
    /// candump: a remote frame with something else than a length after `R`
    #[error("remote frame `R{0}`: expected `R` or `R` and a length")]
    Remote(String),
    /// candump: more than 8 bytes in a classic frame
    #[error("{0} data bytes in a classic frame (at most 8; FD frames are written `##`)")]
    ClassicTooLong(usize),
    /// candump: a raw DLC `_X` that is not 9-F after 8 bytes
    #[error("`_{0}`: a raw DLC 9-F follows 8 data bytes only")]
    RawDlc(String),
}

/// `part` of a line is not hex: the [`LineError`] naming it.
fn in_part(part: LinePart) -> impl Fn(HexError) -> LineError {
    move |source| LineError::Hex { part, source }
}

/// The bytes of a hex string; an error for a character that is not a hex digit or an odd count.
fn hex_bytes(s: &[u8]) -> Result<Vec<u8>, HexError> {
    if !s.len().is_multiple_of(2) {
        return Err(HexError::OddCount(s.len()));
    }
    s.chunks(2)
        .map(|p| {
            let hi = hex_digit(p[0])?;
            let lo = hex_digit(p[1])?;
            Ok(hi << 4 | lo)
        })
        .collect()
}

fn hex_digit(c: u8) -> Result<u8, HexError> {
    (c as char)
        .to_digit(16)
        .map(|d| d as u8)
        .ok_or(HexError::NotDigit(c))
}

fn hex_u32(s: &[u8]) -> Result<u32, HexError> {
    s.iter()
        .try_fold(0u32, |v, &c| Ok(v << 4 | u32::from(hex_digit(c)?)))
}

fn standard(raw: u32) -> Result<Id, LineError> {
    u16::try_from(raw)
        .ok()
        .and_then(StandardId::new)
        .map(Id::Standard)
        .ok_or(LineError::StandardId(raw))
}

fn extended(raw: u32) -> Result<Id, LineError> {
    ExtendedId::new(raw)
        .map(Id::Extended)
        .ok_or(LineError::ExtendedId(raw))
}

/// Data length of a CAN FD DLC code (ISO 11898-1: 0–8, then 12, 16, 20, 24, 32, 48, 64).
fn fd_dlc_len(code: u8) -> usize {
    match code {
        0..=8 => usize::from(code),
        9 => 12,
        10 => 16,
        11 => 20,
        12 => 24,
        13 => 32,
        14 => 48,
        _ => 64,
    }
}

/// Parses one slcan line (without its `\r`).
///
/// # Errors
/// What is wrong, naming what was expected.
pub fn parse_slcan(line: &[u8]) -> Result<CanLine, LineError> {
    let Some((&kind, rest)) = line.split_first() else {
        return Ok(CanLine::Reply);
    };
    let (id_len, fd, remote) = match kind {
        b't' => (3, false, false),
        b'T' => (8, false, false),
        b'r' => (3, false, true),
        b'R' => (8, false, true),
        b'd' | b'b' => (3, true, false),
        b'D' | b'B' => (8, true, false),
        b'z' | b'Z' | b'V' | b'v' | b'N' | b'F' => return Ok(CanLine::Reply),
        _ => return Err(LineError::UnknownType(kind)),
    };
    if rest.len() < id_len + 1 {
        return Err(LineError::TooShort(id_len));
    }
    let raw = hex_u32(&rest[..id_len]).map_err(in_part(LinePart::Identifier))?;
    let id = if id_len == 3 {
        standard(raw)?
    } else {
        extended(raw)?
    };
    let code = hex_digit(rest[id_len]).map_err(in_part(LinePart::Length))?;
    let len = if fd {
        fd_dlc_len(code)
    } else if code <= 8 {
        usize::from(code)
    } else {
        return Err(LineError::ClassicLength(code));
    };
    let body = &rest[id_len + 1..];
    let data_digits = if remote { 0 } else { 2 * len };
    if body.len() < data_digits {
        return Err(LineError::DataDigits {
            expected: data_digits,
            bytes: len,
            present: body.len(),
        });
    }
    let stamp = &body[data_digits..];
    if !matches!(stamp.len(), 0 | 4 | 8) {
        return Err(LineError::Trailing(stamp.len()));
    }
    hex_u32(stamp).map_err(in_part(LinePart::Timestamp))?;
    if remote {
        return Ok(CanLine::Remote);
    }
    let data = hex_bytes(&body[..data_digits]).map_err(in_part(LinePart::Data))?;
    Ok(CanLine::Data(MemFrame { id, data }))
}

/// Parses one line of a `candump -l` log (without its `\n`).
///
/// # Errors
/// What is wrong, naming what was expected.
pub fn parse_candump(line: &[u8]) -> Result<CanLine, LineError> {
    let text = std::str::from_utf8(line).map_err(|_| LineError::NotUtf8)?;
    let mut words = text.split_ascii_whitespace();
    let stamp = words.next().unwrap_or("");
    let ok_stamp = stamp
        .strip_prefix('(')
        .and_then(|s| s.strip_suffix(')'))
        .and_then(|s| s.split_once('.'))
        .is_some_and(|(a, b)| {
            !a.is_empty()
                && !b.is_empty()
                && a.bytes().all(|c| c.is_ascii_digit())
                && b.bytes().all(|c| c.is_ascii_digit())
        });
    if !ok_stamp {
        return Err(LineError::Timestamp);
    }
    let (Some(_iface), Some(frame)) = (words.next(), words.next()) else {
        return Err(LineError::NoFrame);
    };
    // newer can-utils may end a line with the direction, `R` or `T`
    match words.next() {
        None | Some("R" | "T") if words.next().is_none() => {}
        _ => return Err(LineError::TextAfterFrame),
    }
    let (id_text, rest) = frame
        .split_once('#')
        .ok_or_else(|| LineError::NoHash(frame.to_string()))?;
    let raw = hex_u32(id_text.as_bytes()).map_err(in_part(LinePart::Identifier))?;
    let id = match id_text.len() {
        3 => standard(raw)?,
        8 if raw & CAN_ERR_FLAG != 0 => return Ok(CanLine::ErrorFrame(raw & !CAN_ERR_FLAG)),
        8 => extended(raw)?,
        n => {
            return Err(LineError::IdDigits {
                id: id_text.to_string(),
                digits: n,
            })
        }
    };
    let digits = |s: &str| -> Vec<u8> { s.bytes().filter(|&c| c != b'.').collect() };
    if let Some(fd) = rest.strip_prefix('#') {
        if fd.starts_with('#') {
            return Err(LineError::CanXl);
        }
        let mut chars = fd.bytes();
        let flags = chars.next().ok_or(LineError::NoFdFlags)?;
        hex_digit(flags).map_err(in_part(LinePart::FdFlags))?;
        let data = hex_bytes(&digits(&fd[1..])).map_err(in_part(LinePart::Data))?;
        if data.len() > 64 || fd_len(data.len()) != data.len() {
            return Err(LineError::FdLength(data.len()));
        }
        return Ok(CanLine::Data(MemFrame { id, data }));
    }
    if let Some(r) = rest.strip_prefix('R') {
        let ok = r.is_empty()
            || (r.len() == 1 && r.as_bytes()[0].is_ascii_digit() && r.as_bytes()[0] <= b'8')
            || (r.len() == 3 && r.as_bytes()[1] == b'_');
        return if ok {
            Ok(CanLine::Remote)
        } else {
            Err(LineError::Remote(r.to_string()))
        };
    }
    // a classic frame of 8 bytes may carry its raw DLC 9..F as `_X`
    let (hex, dlc) = match rest.split_once('_') {
        Some((h, d)) => (h, Some(d)),
        None => (rest, None),
    };
    let data = hex_bytes(&digits(hex)).map_err(in_part(LinePart::Data))?;
    if data.len() > 8 {
        return Err(LineError::ClassicTooLong(data.len()));
    }
    if let Some(d) = dlc {
        let ok = data.len() == 8 && d.len() == 1 && hex_digit(d.as_bytes()[0]).is_ok_and(|v| v > 8);
        if !ok {
            return Err(LineError::RawDlc(d.to_string()));
        }
    }
    Ok(CanLine::Data(MemFrame { id, data }))
}

/// The line format of a source.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LineFormat {
    /// slcan from an adapter: lines end with `\r`, a BEL is one error reply
    Slcan,
    /// `candump -l` log: lines end with `\n`
    Candump,
}

/// What [`LineReader::feed`] hands on, in source order.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Piece {
    /// capture stream bytes (the reassembled wire frames)
    Data(Vec<u8>),
    /// a line that could not be read, or an error reply or frame
    Bad(BadLine),
}

/// Counts of a line-based CAN source.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LineStats {
    /// lines read (slcan: BEL replies included)
    pub lines: u64,
    /// data frames passed to the reassembler
    pub frames: u64,
    /// remote frames (ignored)
    pub remote: u64,
    /// lines reported bad (unreadable, error replies, error frames)
    pub bad: u64,
}

/// Lines of slcan or candump text into the capture stream, with every unreadable line
/// reported by number.
#[derive(Debug)]
pub struct LineReader {
    format: LineFormat,
    id: Option<Id>,
    stream: CanStream,
    line: Vec<u8>,
    /// characters of the current line beyond [`MAX_LINE`]
    overlong: usize,
    stats: LineStats,
    /// slcan commands sent whose reply has not arrived, oldest first
    awaiting: VecDeque<String>,
}

impl LineReader {
    /// A reader of `format` taking the frames with identifier `id` (`None`: all).
    pub fn new(format: LineFormat, id: Option<Id>) -> Self {
        Self {
            format,
            id,
            stream: CanStream::new(id),
            line: Vec::new(),
            overlong: 0,
            stats: LineStats::default(),
            awaiting: VecDeque::new(),
        }
    }

    /// slcan: `command` (`C`, `S8`, `O`) was sent; its reply (an empty line, or a BEL
    /// when refused) is expected before any frame. A BEL to `C` only says the channel
    /// was closed already and is not reported.
    pub fn expect_reply(&mut self, command: &str) {
        self.awaiting.push_back(command.to_string());
    }

    /// Line counts.
    pub fn stats(&self) -> LineStats {
        self.stats
    }

    /// CAN-level counts of the reassembler.
    pub fn can_stats(&self) -> CanStats {
        self.stream.stats()
    }

    /// The link was lost: the line in progress is reported as cut, the reassembler
    /// starts afresh (the stream's decoder does too, at the same offset).
    pub fn link_lost(&mut self) -> Vec<Piece> {
        let mut out = Vec::new();
        if !self.line.is_empty() || self.overlong > 0 {
            self.stats.lines += 1;
            let detail = format!("{}: cut by the link loss", self.quote());
            self.bad(detail, &mut out);
        }
        self.line.clear();
        self.overlong = 0;
        self.stream = CanStream::new(self.id);
        self.awaiting.clear();
        out
    }

    /// Reads `bytes`; returns stream bytes and bad lines in source order.
    pub fn feed(&mut self, bytes: &[u8]) -> Vec<Piece> {
        let mut out = Vec::new();
        let mut data = Vec::new();
        for &b in bytes {
            match (self.format, b) {
                (LineFormat::Slcan, b'\r') | (LineFormat::Candump, b'\n') => {
                    self.end_line(&mut data, &mut out)
                }
                (LineFormat::Slcan, 0x07) => {
                    self.stats.lines += 1;
                    let refused = self.awaiting.pop_front();
                    let detail = match refused.as_deref() {
                        Some("C") => None,
                        Some(cmd) => Some(format!("adapter refused `{cmd}` (BEL)")),
                        None => Some("adapter reported an error (BEL)".to_string()),
                    };
                    if let Some(d) = detail {
                        flush(&mut data, &mut out);
                        self.bad(d, &mut out);
                    }
                }
                // slcan adapters that end lines with `\r\n`; a candump log written on Windows
                (LineFormat::Slcan, b'\n') => {}
                (LineFormat::Candump, b'\r') if self.line.len() < MAX_LINE => {}
                _ if self.line.len() < MAX_LINE => self.line.push(b),
                _ => self.overlong += 1,
            }
        }
        flush(&mut data, &mut out);
        out
    }

    /// End of the source: a last line without its terminator is read.
    pub fn finish(&mut self) -> Vec<Piece> {
        let mut out = Vec::new();
        let mut data = Vec::new();
        if !self.line.is_empty() || self.overlong > 0 {
            self.end_line(&mut data, &mut out);
        }
        flush(&mut data, &mut out);
        out
    }

    fn quote(&self) -> String {
        let shown = &self.line[..self.line.len().min(QUOTE)];
        let more = self.line.len() > QUOTE || self.overlong > 0;
        format!(
            "`{}{}`",
            shown.escape_ascii(),
            if more { "..." } else { "" }
        )
    }

    fn bad(&mut self, detail: String, out: &mut Vec<Piece>) {
        self.stats.bad += 1;
        out.push(Piece::Bad(BadLine {
            line: self.stats.lines,
            detail,
        }));
    }

    fn end_line(&mut self, data: &mut Vec<u8>, out: &mut Vec<Piece>) {
        self.stats.lines += 1;
        let parsed = if self.overlong > 0 {
            Err(LineError::Overlong(self.line.len() + self.overlong))
        } else if self.format == LineFormat::Candump && self.line.is_empty() {
            // blank lines of a log carry nothing
            Ok(CanLine::Reply)
        } else {
            match self.format {
                LineFormat::Slcan => parse_slcan(&self.line),
                LineFormat::Candump => parse_candump(&self.line),
            }
        };
        match parsed {
            Ok(CanLine::Data(frame)) => {
                // replies come before frames: any still awaited are not coming
                self.awaiting.clear();
                self.stats.frames += 1;
                self.stream.push(&frame, data);
            }
            Ok(CanLine::Remote) => self.stats.remote += 1,
            Ok(CanLine::Reply) => {
                if self.format == LineFormat::Slcan && self.line.is_empty() {
                    self.awaiting.pop_front();
                }
            }
            Ok(CanLine::ErrorFrame(class)) => {
                flush(data, out);
                let detail = format!("{}: CAN error frame (class {class:#x})", self.quote());
                self.bad(detail, out);
            }
            Err(why) => {
                flush(data, out);
                let detail = format!("{}: {why}", self.quote());
                self.bad(detail, out);
            }
        }
        self.line.clear();
        self.overlong = 0;
    }
}

fn flush(data: &mut Vec<u8>, out: &mut Vec<Piece>) {
    if !data.is_empty() {
        out.push(Piece::Data(std::mem::take(data)));
    }
}

/// The slcan bit-rate commands: `S0` (10 kbit/s) to `S8` (1 Mbit/s).
const NOMINAL_RATES: [(u32, &str); 9] = [
    (10_000, "S0"),
    (20_000, "S1"),
    (50_000, "S2"),
    (100_000, "S3"),
    (125_000, "S4"),
    (250_000, "S5"),
    (500_000, "S6"),
    (800_000, "S7"),
    (1_000_000, "S8"),
];

/// The slcan data-phase bit-rate commands of CAN FD adapters.
const DATA_RATES: [(u32, &str); 5] = [
    (500_000, "Y0"),
    (1_000_000, "Y1"),
    (2_000_000, "Y2"),
    (4_000_000, "Y4"),
    (5_000_000, "Y5"),
];

/// A bit rate the slcan adapter has no command for [bit/s]; the message lists those it has.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum BitrateError {
    /// the nominal (arbitration) bit rate
    #[error("{0} bit/s is not an slcan bit rate ({rates})", rates = rate_list(&NOMINAL_RATES))]
    Nominal(u32),
    /// the CAN FD data-phase bit rate
    #[error("{0} bit/s is not an slcan data bit rate ({rates})", rates = rate_list(&DATA_RATES))]
    Data(u32),
}

/// The bit rates of `rates`, comma separated.
fn rate_list(rates: &[(u32, &str)]) -> String {
    let list: Vec<String> = rates.iter().map(|(r, _)| r.to_string()).collect();
    list.join(", ")
}

/// The command of `bitrate` in `rates`.
fn rate_command(rates: &[(u32, &'static str)], bitrate: u32) -> Option<&'static str> {
    rates.iter().find(|(r, _)| *r == bitrate).map(|(_, c)| *c)
}

/// The slcan bit-rate command for `bitrate` [bit/s]: `S0` (10 kbit/s) to `S8` (1 Mbit/s).
///
/// # Errors
/// [`BitrateError::Nominal`], listing the bit rates there are, when `bitrate` is not one
/// of them.
pub fn slcan_bitrate_command(bitrate: u32) -> Result<&'static str, BitrateError> {
    rate_command(&NOMINAL_RATES, bitrate).ok_or(BitrateError::Nominal(bitrate))
}

/// The slcan data-phase bit-rate command of CAN FD adapters (CANable 2.0, WeAct
/// USB2CANFD) for `bitrate` [bit/s]: `Y0` (500 kbit/s), `Y1`, `Y2`, `Y4`, `Y5` (5 Mbit/s,
/// the firmware's).
///
/// # Errors
/// [`BitrateError::Data`], listing the bit rates there are, when `bitrate` is not one of
/// them.
pub fn slcan_data_bitrate_command(bitrate: u32) -> Result<&'static str, BitrateError> {
    rate_command(&DATA_RATES, bitrate).ok_or(BitrateError::Data(bitrate))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn std_id(raw: u16) -> Id {
        Id::Standard(StandardId::new(raw).unwrap())
    }

    fn data(line: &str, parse: fn(&[u8]) -> Result<CanLine, LineError>) -> MemFrame {
        match parse(line.as_bytes()) {
            Ok(CanLine::Data(f)) => f,
            other => panic!("{line}: {other:?}"),
        }
    }

    fn err(line: &str, parse: fn(&[u8]) -> Result<CanLine, LineError>) -> String {
        parse(line.as_bytes()).expect_err(line).to_string()
    }

    #[test]
    fn slcan_lines_of_every_frame_kind_parse() {
        let f = data("t1013DEAD01", parse_slcan);
        assert_eq!(f.id, std_id(0x101));
        assert_eq!(f.data, [0xDE, 0xAD, 0x01]);
        // with a Lawicel millisecond timestamp, and an 8-digit one
        assert_eq!(data("t1012BEEF1A2B", parse_slcan).data, [0xBE, 0xEF]);
        assert_eq!(data("t1010000012AB", parse_slcan).data, Vec::<u8>::new());
        let f = data("T18FF00012CAFE", parse_slcan);
        assert_eq!(f.id, Id::Extended(ExtendedId::new(0x18FF_0001).unwrap()));
        assert_eq!(f.data, [0xCA, 0xFE]);
        // FD: DLC code 9 is 12 bytes, F is 64
        let f = data(&format!("d7FF9{}", "11".repeat(12)), parse_slcan);
        assert_eq!((f.id, f.data.len()), (std_id(0x7FF), 12));
        let f = data(&format!("B00000101F{}", "a5".repeat(64)), parse_slcan);
        assert_eq!(f.data, vec![0xA5; 64]);
        assert_eq!(parse_slcan(b"r1010"), Ok(CanLine::Remote));
        assert_eq!(parse_slcan(b"R18FF00018"), Ok(CanLine::Remote));
        for reply in ["", "z", "Z", "V1013", "N0042", "F00"] {
            assert_eq!(parse_slcan(reply.as_bytes()), Ok(CanLine::Reply), "{reply}");
        }
    }

    #[test]
    fn slcan_malformed_lines_say_what_was_expected() {
        let cases = [
            ("x123", "unknown line type `x`"),
            ("t10", "too short"),
            ("t8001AA", "above the 11-bit maximum"),
            ("T200000001AA", "above the 29-bit maximum"),
            ("t1G11AA", "identifier: `G` is not a hex digit"),
            ("t1019AABBCCDDEEFF001122", "classic frame is above 8"),
            ("t1013AABB", "6 data digits for 3 bytes, 4 present"),
            ("t1011AAB", "1 characters after the data"),
            ("t1011AAzzzz", "timestamp: `z` is not a hex digit"),
            ("t1011ZZ", "data: `Z` is not a hex digit"),
            ("d1019AABB", "24 data digits for 12 bytes"),
        ];
        for (line, want) in cases {
            let e = err(line, parse_slcan);
            assert!(e.contains(want), "{line}: {e}");
        }
        // the error says which part of the line holds what, as values
        assert_eq!(
            parse_slcan(b"t1G11AA"),
            Err(LineError::Hex {
                part: LinePart::Identifier,
                source: HexError::NotDigit(b'G'),
            })
        );
        assert_eq!(
            parse_slcan(b"t1013AABB"),
            Err(LineError::DataDigits {
                expected: 6,
                bytes: 3,
                present: 4,
            })
        );
    }

    #[test]
    fn candump_lines_of_every_frame_kind_parse() {
        let p = parse_candump;
        let f = data("(1700000000.123456) can0 101#DEADBEEF", p);
        assert_eq!(
            (f.id, f.data),
            (std_id(0x101), vec![0xDE, 0xAD, 0xBE, 0xEF])
        );
        assert_eq!(data("(1.000001) vcan1 101#", p).data, Vec::<u8>::new());
        assert_eq!(data("(1.000001) can0 101#DE.AD", p).data, [0xDE, 0xAD]);
        let f = data("(1.5) can0 18FF0001#0102 T", p);
        assert_eq!(f.id, Id::Extended(ExtendedId::new(0x18FF_0001).unwrap()));
        let f = data(&format!("(1.5) can0 101##1{}", "00".repeat(64)), p);
        assert_eq!(f.data.len(), 64);
        assert_eq!(data("(1.5) can0 101##4", p).data, Vec::<u8>::new());
        assert_eq!(data("(1.5) can0 123#1122334455667788_C", p).data.len(), 8);
        assert_eq!(parse_candump(b"(1.5) can0 101#R"), Ok(CanLine::Remote));
        assert_eq!(parse_candump(b"(1.5) can0 101#R4"), Ok(CanLine::Remote));
        assert_eq!(
            parse_candump(b"(1.5) can0 20000004#0004000000000000"),
            Ok(CanLine::ErrorFrame(4))
        );
    }

    #[test]
    fn candump_malformed_lines_say_what_was_expected() {
        let p = parse_candump;
        let cases = [
            ("can0 101#00", "expected `(SECONDS.MICROS) IFACE ID#DATA`"),
            ("(1700000000) can0 101#00", "expected `(SECONDS.MICROS)"),
            ("(1.5) can0", "an interface name and a frame"),
            ("(1.5) can0 10100", "has no `#`"),
            ("(1.5) can0 1010#00", "has 4 digits"),
            ("(1.5) can0 801#00", "above the 11-bit maximum"),
            ("(1.5) can0 101#0", "odd number of hex digits"),
            ("(1.5) can0 101#GG", "`G` is not a hex digit"),
            (
                "(1.5) can0 101#112233445566778899",
                "9 data bytes in a classic frame",
            ),
            (
                "(1.5) can0 101##1112233445566778899",
                "9 data bytes is not a CAN FD length",
            ),
            ("(1.5) can0 101##", "without its flags digit"),
            ("(1.5) can0 101###00", "CAN XL"),
            ("(1.5) can0 101#R9", "remote frame"),
            (
                "(1.5) can0 101#00_9",
                "raw DLC 9-F follows 8 data bytes only",
            ),
            (
                "(1.5) can0 101#00 T extra",
                "unexpected text after the frame",
            ),
        ];
        for (line, want) in cases {
            let e = err(line, p);
            assert!(e.contains(want), "{line}: {e}");
        }
        assert!(err("(1.5) can0 \u{ff}", |l| parse_candump(&l[..l.len() - 1])).contains("UTF-8"));
    }

    #[test]
    fn line_reader_reports_each_bad_line_by_number_and_keeps_going() {
        // a header fragment (first flag, counter 0) carrying a whole wire frame `00 01 02 00`
        let log = "(1.000000) can0 101#8000010200\n\
                   garbage\n\
                   \n\
                   (1.000001) can0 101#R\n\
                   (1.000002) can0 20000004#0004000000000000\n\
                   (1.000003) can0 101#810003040";
        let mut r = LineReader::new(LineFormat::Candump, Some(std_id(0x101)));
        let mut pieces = r.feed(log.as_bytes());
        pieces.extend(r.finish());
        let bad: Vec<(u64, bool)> = pieces
            .iter()
            .filter_map(|p| match p {
                Piece::Bad(b) => Some((b.line, b.detail.contains("error frame"))),
                Piece::Data(_) => None,
            })
            .collect();
        assert_eq!(bad, [(2, false), (5, true), (6, false)]);
        assert_eq!(pieces[0], Piece::Data(vec![0, 1, 2, 0]));
        let s = r.stats();
        assert_eq!((s.lines, s.frames, s.remote, s.bad), (6, 1, 1, 3));
    }

    #[test]
    fn slcan_reader_takes_replies_bel_and_frames_split_anywhere() {
        let mut stream = b"\x07\r\rt10158000010200\r".to_vec();
        stream.extend_from_slice(b"\x07t1012AB\rt10158100030400");
        let mut r = LineReader::new(LineFormat::Slcan, Some(std_id(0x101)));
        for c in ["C", "S8", "O"] {
            r.expect_reply(c);
        }
        let mut pieces = Vec::new();
        for b in stream.chunks(3) {
            pieces.extend(r.feed(b));
        }
        pieces.extend(r.link_lost());
        let want = vec![
            Piece::Data(vec![0, 1, 2, 0]),
            Piece::Bad(BadLine {
                line: 5,
                detail: "adapter reported an error (BEL)".into(),
            }),
            Piece::Bad(BadLine {
                line: 6,
                detail: "`t1012AB`: 4 data digits for 2 bytes, 2 present".into(),
            }),
            Piece::Bad(BadLine {
                line: 7,
                detail: "`t10158100030400`: cut by the link loss".into(),
            }),
        ];
        assert_eq!(pieces, want);
        // a refused bit rate is reported
        let mut r = LineReader::new(LineFormat::Slcan, None);
        r.expect_reply("S8");
        let p = r.feed(b"\x07");
        assert_eq!(
            p,
            [Piece::Bad(BadLine {
                line: 1,
                detail: "adapter refused `S8` (BEL)".into()
            })]
        );
    }

    #[test]
    fn overlong_lines_are_reported_not_stored() {
        let mut r = LineReader::new(LineFormat::Slcan, None);
        let mut long = vec![b't'; 1000];
        long.push(b'\r');
        let p = r.feed(&long);
        match &p[..] {
            [Piece::Bad(b)] => {
                assert_eq!(b.line, 1);
                assert!(b.detail.contains("line of 1000 characters"), "{}", b.detail);
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn slcan_bitrates_map_to_their_commands() {
        assert_eq!(slcan_bitrate_command(1_000_000), Ok("S8"));
        assert_eq!(slcan_bitrate_command(125_000), Ok("S4"));
        assert_eq!(slcan_data_bitrate_command(5_000_000), Ok("Y5"));
        assert!(slcan_data_bitrate_command(3_000_000).is_err());
        assert_eq!(
            slcan_bitrate_command(2_000_000).unwrap_err().to_string(),
            "2000000 bit/s is not an slcan bit rate (10000, 20000, 50000, 100000, 125000, \
             250000, 500000, 800000, 1000000)"
        );
    }
}
