//! Where a capture's bytes come from: a serial port, a CAN interface, a TCP socket or a
//! file (regular file, named pipe, pty).
//!
//! Each source is opened on the caller's thread, so a bad port, an unknown interface or a
//! refused connection is a setup error reported before anything is recorded. Reading then
//! runs on a thread of its own that sends [`SourceMsg`]s over a channel; the capture loop
//! waits on the channel with a timeout, so the file is flushed and Ctrl-C, `--duration`
//! and `--periods` are honoured even while the link is silent.
//!
//! Link loss: a serial port that disappears (USB unplugged), a CAN interface that goes
//! down or a TCP connection that is reset is reported as [`SourceMsg::LinkLost`]; the
//! thread then tries to reopen it every [`RetryPolicy::interval`] and reports
//! [`SourceMsg::LinkResumed`] when it succeeds. End of file (regular file, pipe whose
//! writer closed, pty whose other side hung up) and an orderly TCP close end the stream.
//!
//! CAN: frames (classic and FD) are reassembled into the serial byte stream with the
//! core's `transport::can` reassembler ([`super::can::CanStream`]); the recorded bytes are that
//! reassembled stream, so a CAN capture and a serial capture of the same run are the same
//! file.
//!
//! slcan and candump: the adapter's lines (a serial port, reopened like one) and the log's
//! lines (a file, read to its end) are parsed by [`super::canlog::LineReader`] into the
//! same reassembler; each line it cannot read arrives as [`SourceMsg::BadLine`] at its
//! place in the stream.

use std::fs::File;
use std::io::{self, Read};
use std::net::{TcpListener, TcpStream, ToSocketAddrs};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use super::canlog::{LineFormat, LineReader, Piece};

/// How long one blocking read may wait before the reader thread checks its stop flag.
const READ_TIMEOUT: Duration = Duration::from_millis(50);
/// Size of one read [bytes].
const CHUNK: usize = 64 * 1024;

/// Which link to capture from (validated command-line choice).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SourceSpec {
    /// serial port device path (`/dev/ttyACM0`, `COM3`) and baud rate [bit/s]
    Serial {
        /// device path
        port: String,
        /// baud rate [bit/s]
        baud: u32,
    },
    /// SocketCAN interface name (`can0`), classic and FD frames
    Can {
        /// interface name
        iface: String,
        /// identifier of the board's frames (`None`: every data frame)
        id: Option<embedded_can::Id>,
    },
    /// TCP endpoint `HOST:PORT` to connect to (the emulated board's UART as a server,
    /// QEMU `-serial tcp:HOST:PORT,server=on`)
    Tcp {
        /// `HOST:PORT`
        addr: String,
    },
    /// TCP address `HOST:PORT` to listen on for the board to connect (QEMU
    /// `-serial tcp:HOST:PORT`, the firmware README's `JOINTID_SERIAL` recipe); one
    /// connection at a time, a new one accepted after a connection is reset
    TcpListen {
        /// `HOST:PORT`
        addr: String,
    },
    /// slcan adapter (CANable, USBtin, Lawicel) on a serial port: opened with `C`, the
    /// bit-rate command and `O`, closed with `C` at the end; its frame lines reassembled
    /// like [`SourceSpec::Can`]'s frames (`super::canlog`)
    Slcan {
        /// device path
        port: String,
        /// baud rate of the serial link [bit/s] (USB adapters ignore it)
        baud: u32,
        /// CAN bit rate [bit/s] (`None`: the adapter's current setting)
        bitrate: Option<u32>,
        /// CAN FD data-phase bit rate [bit/s] (`None`: the adapter's current setting)
        data_bitrate: Option<u32>,
        /// identifier of the board's frames (`None`: every data frame)
        id: Option<embedded_can::Id>,
    },
    /// `candump -l` log file, replayed at the speed it can be read
    Candump {
        /// the log
        path: PathBuf,
        /// identifier of the board's frames (`None`: every data frame)
        id: Option<embedded_can::Id>,
    },
    /// raw byte stream from a file, named pipe or pty; a stream that starts with the
    /// `.jcap` magic (a capture file replayed) is read from the byte after it
    File {
        /// path of the file
        path: PathBuf,
    },
}

impl std::fmt::Display for SourceSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Serial { port, baud } => write!(f, "serial {port} at {baud} baud"),
            Self::Can { iface, id: None } => write!(f, "can {iface}"),
            Self::Can {
                iface,
                id: Some(embedded_can::Id::Standard(id)),
            } => write!(f, "can {iface} id {:#05x}", id.as_raw()),
            Self::Can {
                iface,
                id: Some(embedded_can::Id::Extended(id)),
            } => write!(f, "can {iface} id {:#010x}", id.as_raw()),
            Self::Tcp { addr } => write!(f, "tcp {addr}"),
            Self::TcpListen { addr } => write!(f, "tcp listening on {addr}"),
            Self::File { path } => write!(f, "file {}", path.display()),
            Self::Slcan {
                port, bitrate, id, ..
            } => {
                write!(f, "slcan {port}")?;
                if let Some(b) = bitrate {
                    write!(f, " at {b} bit/s")?;
                }
                write_id(f, *id)
            }
            Self::Candump { path, id } => {
                write!(f, "candump {}", path.display())?;
                write_id(f, *id)
            }
        }
    }
}

fn write_id(f: &mut std::fmt::Formatter<'_>, id: Option<embedded_can::Id>) -> std::fmt::Result {
    match id {
        None => Ok(()),
        Some(embedded_can::Id::Standard(id)) => write!(f, " id {:#05x}", id.as_raw()),
        Some(embedded_can::Id::Extended(id)) => write!(f, " id {:#010x}", id.as_raw()),
    }
}

/// How a lost link is retried.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RetryPolicy {
    /// pause between two attempts to reopen a lost link [s]
    pub interval: Duration,
}

impl Default for RetryPolicy {
    fn default() -> Self {
        Self {
            interval: Duration::from_millis(200),
        }
    }
}

/// Errors opening or reading a source.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SourceError {
    /// The serial port could not be opened.
    #[error("serial port {port}: {message}")]
    SerialOpen {
        /// device path
        port: String,
        /// what the driver said
        message: String,
    },
    /// The CAN interface could not be opened (unknown name, not up, not CAN).
    #[error("can interface {iface}: {}", super::io_msg(err))]
    CanOpen {
        /// interface name
        iface: String,
        /// what the kernel said
        err: io::Error,
    },
    /// CAN capture needs SocketCAN, which only Linux has.
    #[error("can interface {iface}: CAN capture needs Linux SocketCAN")]
    CanUnsupported {
        /// interface name
        iface: String,
    },
    /// `HOST:PORT` did not resolve or the connection failed.
    #[error("tcp {addr}: {}", super::io_msg(err))]
    Tcp {
        /// `HOST:PORT`
        addr: String,
        /// what the resolver or the network said
        err: io::Error,
    },
    /// The file could not be opened or is not a byte stream.
    #[error("{path}: {}", super::io_msg(err))]
    File {
        /// the file
        path: PathBuf,
        /// what the operating system said
        err: io::Error,
    },
    /// Reading failed in a way that retrying cannot fix.
    #[error(
        "{source_name}: read failed at stream byte {offset}: {}",
        super::io_msg(err)
    )]
    Read {
        /// the source, as displayed by [`SourceSpec`]
        source_name: String,
        /// stream offset at which the read failed
        offset: u64,
        /// what the operating system said
        err: io::Error,
    },
}

/// What the reader thread reports.
#[derive(Debug)]
pub enum SourceMsg {
    /// bytes, in arrival order
    Data(Vec<u8>),
    /// the link stopped delivering; the thread is retrying (detail = why)
    LinkLost(String),
    /// the link delivers again (detail = what was reopened)
    LinkResumed(String),
    /// a line of an slcan or candump source that could not be read (or an error the
    /// adapter or the bus reported), at this point of the stream
    BadLine(super::canlog::BadLine),
    /// the stream ended (detail = why); no message follows
    End(String),
    /// unrecoverable error; no message follows
    Failed(SourceError),
}

/// A running source: a reader thread and the channel it reports on.
#[derive(Debug)]
pub struct RunningSource {
    rx: Receiver<SourceMsg>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    name: String,
}

impl RunningSource {
    /// The source, as displayed by [`SourceSpec`].
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Next message, or `None` when none arrived within `timeout` (or the thread is gone).
    pub fn recv_timeout(&self, timeout: Duration) -> Option<SourceMsg> {
        match self.rx.recv_timeout(timeout) {
            Ok(m) => Some(m),
            Err(RecvTimeoutError::Timeout) => None,
            Err(RecvTimeoutError::Disconnected) => Some(SourceMsg::End("reader stopped".into())),
        }
    }

    /// Asks the reader thread to stop and waits for it, unless it is blocked in a read
    /// that has no timeout (a pipe or pty given as `--file`): that thread is left to end
    /// with the process. Returns the bytes and bad lines that had already been read but
    /// not yet received ([`SourceMsg::Data`], [`SourceMsg::BadLine`]), in order, so that a
    /// stop loses nothing that arrived.
    pub fn stop(mut self) -> Vec<SourceMsg> {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            if t.is_finished() || !self.name.starts_with("file ") {
                let _ = t.join();
            }
        }
        self.rx
            .try_iter()
            .filter(|m| matches!(m, SourceMsg::Data(_) | SourceMsg::BadLine(_)))
            .collect()
    }
}

/// A link that delivers bytes: one blocking read with a short timeout.
trait Link: Send {
    /// `Ok(0)` means end of stream; `Err(TimedOut | WouldBlock)` means nothing yet.
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize>;
}

impl Link for Box<dyn serialport::SerialPort> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        Read::read(self, buf)
    }
}

impl Link for TcpStream {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        Read::read(self, buf)
    }
}

impl Link for File {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        Read::read(self, buf)
    }
}

impl SourceSpec {
    /// Opens the source on this thread and starts its reader thread.
    ///
    /// # Errors
    /// The `*Open`/`Tcp`/`File` variants of [`SourceError`] naming the port, interface,
    /// address or path and what went wrong.
    pub fn open(&self, retry: RetryPolicy) -> Result<RunningSource, SourceError> {
        let name = self.to_string();
        let (tx, rx) = mpsc::channel();
        let stop = Arc::new(AtomicBool::new(false));
        let thread = match self {
            Self::Serial { port, baud } => {
                let link = open_serial(port, *baud)?;
                let (port, baud) = (port.clone(), *baud);
                spawn_link(link, tx, stop.clone(), name.clone(), retry, move || {
                    open_serial(&port, baud)
                })
            }
            Self::Tcp { addr } => {
                let link = open_tcp(addr)?;
                let addr = addr.clone();
                spawn_link(link, tx, stop.clone(), name.clone(), retry, move || {
                    open_tcp(&addr)
                })
            }
            Self::TcpListen { addr } => spawn_listen(addr, tx, stop.clone())?,
            Self::File { path } => spawn_file(path.clone(), tx, stop.clone(), name.clone())?,
            Self::Can { iface, id } => {
                can::spawn(iface, *id, tx, stop.clone(), name.clone(), retry)?
            }
            Self::Slcan {
                port,
                baud,
                bitrate,
                data_bitrate,
                id,
            } => {
                let rates = (*bitrate, *data_bitrate);
                spawn_slcan(port, *baud, rates, *id, tx, stop.clone(), retry)?
            }
            Self::Candump { path, id } => {
                spawn_candump(path.clone(), *id, tx, stop.clone(), name.clone())?
            }
        };
        Ok(RunningSource {
            rx,
            stop,
            thread: Some(thread),
            name,
        })
    }
}

fn open_serial(port: &str, baud: u32) -> Result<Box<dyn serialport::SerialPort>, SourceError> {
    serialport::new(port, baud)
        .timeout(READ_TIMEOUT)
        .open()
        .map_err(|e| SourceError::SerialOpen {
            port: port.to_string(),
            message: serial_message(&e),
        })
}

fn serial_message(e: &serialport::Error) -> String {
    let mut m = e.description.clone();
    if let Some(first) = m.get(..1) {
        let lower = first.to_lowercase();
        m.replace_range(..1, &lower);
    }
    m
}

fn open_tcp(addr: &str) -> Result<TcpStream, SourceError> {
    let err = |source| SourceError::Tcp {
        addr: addr.to_string(),
        err: source,
    };
    let mut last = io::Error::new(io::ErrorKind::NotFound, "address resolved to nothing");
    for sa in addr.to_socket_addrs().map_err(err)? {
        match TcpStream::connect_timeout(&sa, Duration::from_secs(5)) {
            Ok(s) => {
                s.set_read_timeout(Some(READ_TIMEOUT)).map_err(err)?;
                let _ = s.set_nodelay(true);
                return Ok(s);
            }
            Err(e) => last = e,
        }
    }
    Err(err(last))
}

/// Binds `addr` here (an address in use or that does not resolve is a setup error) and
/// starts the thread that accepts the board's connection and reads it. The peer closing
/// the connection ends the stream; a connection reset is a link loss, and the thread
/// then waits for the next connection.
fn spawn_listen(
    addr: &str,
    tx: Sender<SourceMsg>,
    stop: Arc<AtomicBool>,
) -> Result<JoinHandle<()>, SourceError> {
    let err = |source| SourceError::Tcp {
        addr: addr.to_string(),
        err: source,
    };
    let listener = TcpListener::bind(addr).map_err(err)?;
    // accept polls, so that a stop is honoured while no board has connected
    listener.set_nonblocking(true).map_err(err)?;
    Ok(std::thread::spawn(move || {
        let mut buf = vec![0u8; CHUNK];
        let mut connections = 0u64;
        'accept: while !stop.load(Ordering::SeqCst) {
            let (mut stream, peer) = match listener.accept() {
                Ok(c) => c,
                Err(e) if is_timeout(&e) => {
                    std::thread::sleep(READ_TIMEOUT);
                    continue;
                }
                Err(e) => {
                    let _ = tx.send(SourceMsg::LinkLost(format!("accept: {e}")));
                    std::thread::sleep(READ_TIMEOUT);
                    continue;
                }
            };
            let ready = stream
                .set_nonblocking(false)
                .and_then(|()| stream.set_read_timeout(Some(READ_TIMEOUT)));
            if let Err(e) = ready {
                let _ = tx.send(SourceMsg::LinkLost(format!("connection from {peer}: {e}")));
                continue;
            }
            let _ = stream.set_nodelay(true);
            connections += 1;
            if connections > 1
                && tx
                    .send(SourceMsg::LinkResumed(format!("connection from {peer}")))
                    .is_err()
            {
                return;
            }
            while !stop.load(Ordering::SeqCst) {
                match Read::read(&mut stream, &mut buf) {
                    Ok(0) => {
                        let _ = tx.send(SourceMsg::End("connection closed by peer".into()));
                        return;
                    }
                    Ok(n) => {
                        if tx.send(SourceMsg::Data(buf[..n].to_vec())).is_err() {
                            return;
                        }
                    }
                    Err(e) if is_timeout(&e) => {}
                    Err(e) => {
                        if tx.send(SourceMsg::LinkLost(e.to_string())).is_err() {
                            return;
                        }
                        continue 'accept;
                    }
                }
            }
        }
    }))
}

fn is_timeout(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
    )
}

/// Reader thread for a link that can be lost and reopened (serial, TCP).
fn spawn_link<L, F>(
    mut link: L,
    tx: Sender<SourceMsg>,
    stop: Arc<AtomicBool>,
    name: String,
    retry: RetryPolicy,
    mut reopen: F,
) -> JoinHandle<()>
where
    L: Link + 'static,
    F: FnMut() -> Result<L, SourceError> + Send + 'static,
{
    std::thread::spawn(move || {
        let mut buf = vec![0u8; CHUNK];
        while !stop.load(Ordering::SeqCst) {
            let lost = match link.read(&mut buf) {
                Ok(0) if name.starts_with("tcp ") => {
                    let _ = tx.send(SourceMsg::End("connection closed by peer".into()));
                    return;
                }
                // a tty that reports readable and then returns nothing has hung up
                Ok(0) => "device hung up".to_string(),
                Ok(n) => {
                    if tx.send(SourceMsg::Data(buf[..n].to_vec())).is_err() {
                        return;
                    }
                    continue;
                }
                Err(e) if is_timeout(&e) => continue,
                Err(e) => e.to_string(),
            };
            if tx.send(SourceMsg::LinkLost(lost)).is_err() {
                return;
            }
            // close the dead handle first so the device node is free, then retry until
            // reopened or stopped
            drop(link);
            link = loop {
                std::thread::sleep(retry.interval);
                if stop.load(Ordering::SeqCst) {
                    return;
                }
                if let Ok(l) = reopen() {
                    break l;
                }
            };
            if tx.send(SourceMsg::LinkResumed(name.clone())).is_err() {
                return;
            }
        }
    })
}

/// Adds `bytes` to the held `head` of a file; once it holds as many bytes as the `.jcap`
/// magic (or differs from it), returns the stream bytes: everything but a leading magic.
/// `None` while the head is still a proper prefix of the magic.
fn strip_magic(head: &mut Vec<u8>, bytes: &[u8]) -> Option<Vec<u8>> {
    let magic = &super::jcap::MAGIC;
    head.extend_from_slice(bytes);
    let n = head.len().min(magic.len());
    if head[..n] != magic[..n] {
        return Some(std::mem::take(head));
    }
    if head.len() < magic.len() {
        return None;
    }
    Some(head.split_off(magic.len()))
}

/// The metadata of `path`, which must exist and not be a directory (a setup error names
/// the file).
fn not_a_directory(path: &std::path::Path) -> Result<std::fs::Metadata, SourceError> {
    let err = |source| SourceError::File {
        path: path.to_path_buf(),
        err: source,
    };
    let meta = std::fs::metadata(path).map_err(err)?;
    if meta.is_dir() {
        return Err(err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "is a directory",
        )));
    }
    Ok(meta)
}

/// Reader thread for `--file`: regular files, named pipes and ptys.
///
/// A regular file or pty is opened here (a missing or unreadable file is a setup error);
/// a named pipe is opened by the thread, because opening it blocks until a writer
/// appears.
fn spawn_file(
    path: PathBuf,
    tx: Sender<SourceMsg>,
    stop: Arc<AtomicBool>,
    name: String,
) -> Result<JoinHandle<()>, SourceError> {
    let err = |source| SourceError::File {
        path: path.clone(),
        err: source,
    };
    let meta = not_a_directory(&path)?;
    #[cfg(unix)]
    let is_fifo = std::os::unix::fs::FileTypeExt::is_fifo(&meta.file_type());
    #[cfg(not(unix))]
    let is_fifo = false;
    let opened = if is_fifo {
        None
    } else {
        Some(File::open(&path).map_err(err)?)
    };
    Ok(std::thread::spawn(move || {
        let mut file = match opened {
            Some(f) => f,
            None => match File::open(&path) {
                Ok(f) => f,
                Err(source) => {
                    let _ = tx.send(SourceMsg::Failed(SourceError::File { path, err: source }));
                    return;
                }
            },
        };
        let mut buf = vec![0u8; CHUNK];
        let mut offset = 0u64;
        // the first bytes, held until they can be told from a `.jcap` magic
        let mut head = Some(Vec::with_capacity(super::jcap::MAGIC.len()));
        while !stop.load(Ordering::SeqCst) {
            match Read::read(&mut file, &mut buf) {
                Ok(0) => {
                    if let Some(h) = head.take().filter(|h| !h.is_empty()) {
                        let _ = tx.send(SourceMsg::Data(h));
                    }
                    let _ = tx.send(SourceMsg::End("end of file".into()));
                    return;
                }
                Ok(n) => {
                    offset += n as u64;
                    let data = match head.as_mut() {
                        Some(h) => match strip_magic(h, &buf[..n]) {
                            Some(rest) => {
                                head = None;
                                rest
                            }
                            None => continue,
                        },
                        None => buf[..n].to_vec(),
                    };
                    if !data.is_empty() && tx.send(SourceMsg::Data(data)).is_err() {
                        return;
                    }
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                // EIO on a pty: the other side hung up, which is its end of stream
                Err(e) if e.raw_os_error() == Some(5) => {
                    let _ = tx.send(SourceMsg::End("pty hung up".into()));
                    return;
                }
                Err(source) => {
                    let _ = tx.send(SourceMsg::Failed(SourceError::Read {
                        source_name: name,
                        offset,
                        err: source,
                    }));
                    return;
                }
            }
        }
    }))
}

/// Sends the pieces of a line reader in order; false when the receiver is gone.
fn send_pieces(tx: &Sender<SourceMsg>, pieces: Vec<Piece>) -> bool {
    pieces.into_iter().all(|p| {
        tx.send(match p {
            Piece::Data(d) => SourceMsg::Data(d),
            Piece::Bad(b) => SourceMsg::BadLine(b),
        })
        .is_ok()
    })
}

/// Reader thread for `--candump`: the log is opened here (a missing or unreadable file is
/// a setup error) and read line by line; a read error later ends the capture.
fn spawn_candump(
    path: PathBuf,
    id: Option<embedded_can::Id>,
    tx: Sender<SourceMsg>,
    stop: Arc<AtomicBool>,
    name: String,
) -> Result<JoinHandle<()>, SourceError> {
    let err = |source| SourceError::File {
        path: path.clone(),
        err: source,
    };
    not_a_directory(&path)?;
    let mut file = File::open(&path).map_err(err)?;
    Ok(std::thread::spawn(move || {
        let mut reader = LineReader::new(LineFormat::Candump, id);
        let mut buf = vec![0u8; CHUNK];
        let mut offset = 0u64;
        while !stop.load(Ordering::SeqCst) {
            match Read::read(&mut file, &mut buf) {
                Ok(0) => {
                    if send_pieces(&tx, reader.finish()) {
                        let _ = tx.send(SourceMsg::End("end of file".into()));
                    }
                    return;
                }
                Ok(n) => {
                    offset += n as u64;
                    if !send_pieces(&tx, reader.feed(&buf[..n])) {
                        return;
                    }
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(source) => {
                    let _ = tx.send(SourceMsg::Failed(SourceError::Read {
                        source_name: name,
                        offset,
                        err: source,
                    }));
                    return;
                }
            }
        }
    }))
}

/// Opens the slcan adapter's port and its CAN channel: `C` (close, in case it was left
/// open), the bit rates `(nominal, data)` when given, `O`. Their replies are read with
/// the frames ([`LineReader`]).
fn open_slcan(
    port: &str,
    baud: u32,
    (bitrate, data_bitrate): (Option<u32>, Option<u32>),
    reader: &mut LineReader,
) -> Result<Box<dyn serialport::SerialPort>, SourceError> {
    let refused = |message| SourceError::SerialOpen {
        port: port.to_string(),
        message,
    };
    let mut commands = vec!["C"];
    if let Some(b) = bitrate {
        commands.push(super::canlog::slcan_bitrate_command(b).map_err(|e| refused(e.to_string()))?);
    }
    if let Some(b) = data_bitrate {
        commands.push(
            super::canlog::slcan_data_bitrate_command(b).map_err(|e| refused(e.to_string()))?,
        );
    }
    let mut link = open_serial(port, baud)?;
    commands.push("O");
    for c in commands {
        io::Write::write_all(&mut link, format!("{c}\r").as_bytes()).map_err(|e| {
            SourceError::SerialOpen {
                port: port.to_string(),
                message: format!("writing `{c}` to the adapter: {e}"),
            }
        })?;
        reader.expect_reply(c);
    }
    Ok(link)
}

/// Reader thread for `--slcan`: the port is opened here; a lost port is reopened (and
/// the channel with it) like a serial port's; at the stop the channel is closed (`C`).
fn spawn_slcan(
    port: &str,
    baud: u32,
    rates: (Option<u32>, Option<u32>),
    id: Option<embedded_can::Id>,
    tx: Sender<SourceMsg>,
    stop: Arc<AtomicBool>,
    retry: RetryPolicy,
) -> Result<JoinHandle<()>, SourceError> {
    let mut reader = LineReader::new(LineFormat::Slcan, id);
    let mut link = open_slcan(port, baud, rates, &mut reader)?;
    let port = port.to_string();
    Ok(std::thread::spawn(move || {
        let mut buf = vec![0u8; CHUNK];
        while !stop.load(Ordering::SeqCst) {
            let lost = match Read::read(&mut link, &mut buf) {
                Ok(0) => "device hung up".to_string(),
                Ok(n) => {
                    if !send_pieces(&tx, reader.feed(&buf[..n])) {
                        return;
                    }
                    continue;
                }
                Err(e) if is_timeout(&e) => continue,
                Err(e) => e.to_string(),
            };
            if !send_pieces(&tx, reader.link_lost()) || tx.send(SourceMsg::LinkLost(lost)).is_err()
            {
                return;
            }
            drop(link);
            link = loop {
                std::thread::sleep(retry.interval);
                if stop.load(Ordering::SeqCst) {
                    return;
                }
                if let Ok(l) = open_slcan(&port, baud, rates, &mut reader) {
                    break l;
                }
                // replies of a failed attempt will not come
                let _ = reader.link_lost();
            };
            if tx
                .send(SourceMsg::LinkResumed(format!("slcan {port}")))
                .is_err()
            {
                return;
            }
        }
        // close the channel; the adapter stops sending
        let _ = io::Write::write_all(&mut link, b"C\r");
    }))
}

#[cfg(target_os = "linux")]
mod can {
    use super::*;
    use socketcan::{CanAnyFrame, CanFdSocket, Socket};

    fn open(iface: &str) -> Result<CanFdSocket, SourceError> {
        let err = |source| SourceError::CanOpen {
            iface: iface.to_string(),
            err: source,
        };
        let sock = CanFdSocket::open(iface).map_err(|e| {
            // if_nametoindex fails with ENODEV for an unknown name
            if e.raw_os_error() == Some(19) {
                err(io::Error::new(io::ErrorKind::NotFound, "no such interface"))
            } else {
                err(e)
            }
        })?;
        sock.set_read_timeout(READ_TIMEOUT).map_err(err)?;
        Ok(sock)
    }

    pub(super) fn spawn(
        iface: &str,
        id: Option<embedded_can::Id>,
        tx: Sender<SourceMsg>,
        stop: Arc<AtomicBool>,
        name: String,
        retry: RetryPolicy,
    ) -> Result<JoinHandle<()>, SourceError> {
        let mut sock = open(iface)?;
        let iface = iface.to_string();
        Ok(std::thread::spawn(move || {
            let mut stream = crate::capture::can::CanStream::new(id);
            let mut out = Vec::new();
            while !stop.load(Ordering::SeqCst) {
                let lost = match sock.read_frame() {
                    Ok(frame) => {
                        match frame {
                            CanAnyFrame::Normal(f) => stream.push(&f, &mut out),
                            CanAnyFrame::Fd(f) => stream.push(&f, &mut out),
                            // remote and error frames carry no stream bytes
                            CanAnyFrame::Remote(_) | CanAnyFrame::Error(_) => {}
                        }
                        if !out.is_empty()
                            && tx.send(SourceMsg::Data(std::mem::take(&mut out))).is_err()
                        {
                            return;
                        }
                        continue;
                    }
                    Err(e) if is_timeout(&e) => continue,
                    Err(e) => e.to_string(),
                };
                if tx.send(SourceMsg::LinkLost(lost)).is_err() {
                    return;
                }
                sock = loop {
                    std::thread::sleep(retry.interval);
                    if stop.load(Ordering::SeqCst) {
                        return;
                    }
                    if let Ok(s) = open(&iface) {
                        break s;
                    }
                };
                stream = crate::capture::can::CanStream::new(id);
                if tx.send(SourceMsg::LinkResumed(name.clone())).is_err() {
                    return;
                }
            }
        }))
    }
}

#[cfg(not(target_os = "linux"))]
mod can {
    use super::*;

    pub(super) fn spawn(
        iface: &str,
        _id: Option<embedded_can::Id>,
        _tx: Sender<SourceMsg>,
        _stop: Arc<AtomicBool>,
        _name: String,
        _retry: RetryPolicy,
    ) -> Result<JoinHandle<()>, SourceError> {
        Err(SourceError::CanUnsupported {
            iface: iface.to_string(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strip_magic_drops_a_leading_jcap_magic_fed_in_any_pieces() {
        let mut stream = super::super::jcap::MAGIC.to_vec();
        stream.extend_from_slice(&[0, 5, 1, 2, 0]);
        for cut in 0..stream.len() {
            let mut head = Vec::new();
            let mut out = Vec::new();
            let mut done = false;
            for piece in [&stream[..cut], &stream[cut..]] {
                if done {
                    out.extend_from_slice(piece);
                } else if let Some(rest) = strip_magic(&mut head, piece) {
                    out.extend(rest);
                    done = true;
                }
            }
            assert_eq!(out, [0, 5, 1, 2, 0], "cut at {cut}");
        }
        // a raw stream, even one that starts like the magic, is passed whole
        let mut head = Vec::new();
        assert_eq!(strip_magic(&mut head, b"JCA"), None);
        assert_eq!(strip_magic(&mut head, b"X\0"), Some(b"JCAX\0".to_vec()));
        let mut head = Vec::new();
        assert_eq!(strip_magic(&mut head, &[0, 1]), Some(vec![0, 1]));
    }
}
