//! Hardware-independent core of the joint-excitation firmware.
//!
//! The board application (`jointid-fw`) and the host (`jointid`) both depend on
//! this crate: the board to excite the joint, take samples and stream them;
//! the host for the wire types and to regenerate the excitation bit for bit.
//!
//! - [`excitation`]: special odd multisine and validation signals (seed 000, eq. (4)).
//! - [`wire`]: postcard messages, CRC-32, COBS framing, streaming decoder.
//! - [`sampler`]: the 2 kHz tick and the transmit pump.
//! - [`transport`]: serial (`embedded-io`) and CAN (`embedded-can`) links.
//! - [`joint`]: an on-target simulated joint (three-mass model, seed 000 eq. (6)).
//!
//! **Invariants**: no allocation outside `std`-gated helpers; decoders never
//! panic on any input; the sampler does bounded work per tick.
//!
//! The crate is `no_std` unless the `std` feature is on (test builds also link
//! std so the unit tests can use `Vec`).
#![cfg_attr(not(any(feature = "std", test)), no_std)]
#![deny(missing_docs)]
// Units are written in brackets (`/// motor angle [rad]`, project style), which
// rustdoc would otherwise take for intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

#[macro_use]
mod fmt;

pub mod excitation;
pub mod joint;
pub mod rng;
pub mod sampler;
pub mod transport;
pub mod wire;
