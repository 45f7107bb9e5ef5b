//! Links that carry encoded frames from the board to the host.
//!
//! Both links carry the same byte stream that [`crate::wire::encode_frame`]
//! produces, so one host [`crate::wire::Decoder`] serves both:
//! - [`serial`]: the frames written through `embedded_io::Write` (a UART);
//! - [`can`]: the frames cut into `embedded_can::Frame`s (classic or FD) with a
//!   rolling fragment counter, and reassembled on the host.

pub mod can;
pub mod serial;

/// Why a frame did not leave the board.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TxError {
    /// the link reported an error; the frame may be partly sent
    Link,
    /// the link accepted no byte (a write returned 0)
    Stalled,
    /// a fragment could not be built for the link (for example a CAN frame type
    /// that refuses the identifier or length)
    Fragment,
}

impl core::fmt::Display for TxError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Link => write!(f, "link write error"),
            Self::Stalled => write!(f, "link accepted no byte"),
            Self::Fragment => write!(f, "link frame could not be built"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for TxError {}

/// Something that sends whole encoded frames (delimiter included).
pub trait FrameSink {
    /// Sends one frame; on error the frame counts as lost.
    ///
    /// # Errors
    /// [`TxError`]; the sink counts it in [`FrameSink::tx_errors`].
    fn send_frame(&mut self, frame: &[u8]) -> Result<(), TxError>;

    /// Errors counted so far.
    fn tx_errors(&self) -> u32;
}
