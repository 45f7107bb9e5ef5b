//! CAN frames to the serial byte stream (placeholder until core's `transport::can` lands).

/// Reassembles CAN frames into the byte stream.
#[derive(Debug, Default)]
pub struct CanStream {}

impl CanStream {
    /// A fresh reassembler.
    pub fn new() -> Self {
        Self {}
    }

    /// Feeds one frame; appends completed bytes to `out`.
    pub fn push(&mut self, _frame: &impl embedded_can::Frame, _out: &mut Vec<u8>) {}
}
