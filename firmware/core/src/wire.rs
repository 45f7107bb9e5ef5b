//! The wire protocol between the board and the host.
//!
//! Every message travels as `00 COBS(postcard(message) + CRC-32) 00`; a session
//! is a [`SessionHeader`] (repeated every [`HEADER_INTERVAL_S`]), then
//! [`SampleBatch`]es with a [`Status`] every few batches, then [`Message::End`].
//!
//! - `wire/icd.rs`: the messages and constants, and the bytes they make on the
//!   link, byte by byte: the file a host in another language is written from.
//! - `wire/batch.rs`: the delta/zigzag/LEB128 sample codec ([`BatchBuilder`],
//!   [`SampleBatch::samples`]).
//! - `wire/crc.rs`: [`Crc32`]; `wire/cobs.rs`: [`cobs_encode`], [`cobs_decode_in_place`].
//! - `wire/frame.rs`: [`encode_frame`] and the streaming [`Decoder`].
//!
//! The modules are private (rustdoc does not render `icd.rs`: read the file);
//! every item is used as `jointid_core::wire::X`.

mod batch;
mod cobs;
mod crc;
mod frame;
mod icd;
#[cfg(test)]
mod test_support;

pub use batch::{BatchBuilder, BatchError};
pub use cobs::{cobs_decode_in_place, cobs_encode, cobs_max_len};
pub use crc::{reference_crc, Crc32};
pub use frame::{
    decode_frame_body, encode_frame, encode_frame_ref, DecodeError, DecodeEvent, Decoder,
    DecoderStats, EncodeError,
};
pub use icd::{
    header_interval_samples, Message, MessageRef, RawSample, SampleBatch, Scale, SessionHeader,
    Status, BATCH_CAPACITY, BATCH_DATA_CAPACITY, HEADER_INTERVAL_S, MAX_FRAME_LEN, MAX_MESSAGE_LEN,
    PROTOCOL_VERSION,
};
