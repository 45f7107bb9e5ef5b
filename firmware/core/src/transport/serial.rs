//! Serial link: encoded frames written through `embedded_io::Write` (a UART).
//!
//! A write may take only part of a buffer; the sink loops until the frame is
//! out. A write error or a write that accepts nothing (`Ok(0)`, which
//! `embedded_io::Write::write_all` would turn into a panic) abandons the frame
//! and counts a transmit error. The next frame starts with its own 0x00
//! delimiter (every wire frame does), so the host's decoder closes the cut
//! frame (reporting it as damaged) and reads the next one intact instead of
//! losing it too. (A frame cut just before its closing delimiter is closed by
//! the next one's leading delimiter and arrives whole, although the sink
//! reported it lost.)

use embedded_io::Write;

use super::{FrameSink, TxError};

/// [`FrameSink`] over an `embedded_io::Write`.
#[derive(Debug)]
pub struct SerialSink<W> {
    writer: W,
    tx_errors: u32,
    bytes_sent: u64,
}

impl<W: Write> SerialSink<W> {
    /// Sink writing to `writer`.
    pub fn new(writer: W) -> Self {
        Self {
            writer,
            tx_errors: 0,
            bytes_sent: 0,
        }
    }

    /// Bytes accepted by the writer so far.
    pub fn bytes_sent(&self) -> u64 {
        self.bytes_sent
    }

    /// The writer.
    pub fn get_mut(&mut self) -> &mut W {
        &mut self.writer
    }

    /// Gives the writer back.
    pub fn into_inner(self) -> W {
        self.writer
    }

    /// Flushes the writer.
    ///
    /// # Errors
    /// [`TxError::Link`] (counted).
    pub fn flush(&mut self) -> Result<(), TxError> {
        self.writer.flush().map_err(|_| {
            self.tx_errors = self.tx_errors.saturating_add(1);
            TxError::Link
        })
    }

    fn write_all(&mut self, mut buf: &[u8]) -> Result<(), TxError> {
        while !buf.is_empty() {
            match self.writer.write(buf) {
                Ok(0) => return Err(TxError::Stalled),
                Ok(n) => {
                    let n = n.min(buf.len());
                    self.bytes_sent += n as u64;
                    buf = &buf[n..];
                }
                Err(_) => return Err(TxError::Link),
            }
        }
        Ok(())
    }
}

impl<W: Write> FrameSink for SerialSink<W> {
    fn send_frame(&mut self, frame: &[u8]) -> Result<(), TxError> {
        self.write_all(frame).inspect_err(|_| {
            self.tx_errors = self.tx_errors.saturating_add(1);
        })
    }

    fn tx_errors(&self) -> u32 {
        self.tx_errors
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::{encode_frame, DecodeEvent, Decoder, Message, Status, MAX_FRAME_LEN};

    /// Writer that takes at most 3 bytes per call and fails (or stalls) on
    /// chosen calls.
    struct Choppy {
        out: Vec<u8>,
        calls: u32,
        fail_on: Vec<u32>,
        stall_on: Vec<u32>,
    }

    impl embedded_io::ErrorType for Choppy {
        type Error = embedded_io::ErrorKind;
    }
    impl Write for Choppy {
        fn write(&mut self, buf: &[u8]) -> Result<usize, embedded_io::ErrorKind> {
            self.calls += 1;
            if self.fail_on.contains(&self.calls) {
                return Err(embedded_io::ErrorKind::Other);
            }
            if self.stall_on.contains(&self.calls) {
                return Ok(0);
            }
            let n = buf.len().min(3);
            self.out.extend_from_slice(&buf[..n]);
            Ok(n)
        }
        fn flush(&mut self) -> Result<(), embedded_io::ErrorKind> {
            Ok(())
        }
    }

    #[test]
    fn partial_writes_deliver_whole_frames_and_errors_resync() {
        let mut sink = SerialSink::new(Choppy {
            out: Vec::new(),
            calls: 0,
            fail_on: vec![11, 40],
            stall_on: vec![26],
        });
        let mut buf = [0u8; MAX_FRAME_LEN];
        let mut sent = Vec::new();
        let mut ok = 0;
        // failed frames of which more than the leading delimiter went out
        let mut cut = 0;
        for seq in 0..20u32 {
            let msg = Message::Status(Status {
                seq,
                overruns: seq * 1000,
                ..Status::default()
            });
            let n = encode_frame(&msg, &mut buf).unwrap();
            let before = sink.bytes_sent();
            if sink.send_frame(&buf[..n]).is_ok() {
                ok += 1;
                sent.push(msg);
            } else if sink.bytes_sent() + 1 >= before + n as u64 {
                // all but the closing delimiter went out: the next frame's
                // leading delimiter closes it, and it arrives intact
                sent.push(msg);
            } else if sink.bytes_sent() > before + 1 {
                cut += 1;
            }
        }
        assert_eq!(sink.tx_errors(), 3);
        assert_eq!(ok, 17);
        let mut good = Vec::new();
        let mut damaged = 0;
        let mut dec = Decoder::new();
        dec.feed(&sink.get_mut().out, |e| match e {
            DecodeEvent::Frame { message, .. } => good.push(message),
            DecodeEvent::Damaged { .. } => damaged += 1,
        });
        // every frame reported sent arrives; each cut frame is one damaged frame
        assert_eq!(good, sent);
        assert_eq!(cut, 2, "the choppy writer cuts two frames midway");
        assert_eq!(damaged, cut);
        assert_eq!(sink.bytes_sent(), sink.get_mut().out.len() as u64);
    }
}
