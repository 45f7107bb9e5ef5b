//! The hardware layer, one module per board, chosen by cargo feature. A board
//! module owns clocks, pins, the 2 kHz tick interrupt (which calls
//! [`crate::app::tick`]) and the idle loop (which calls [`crate::app::pump`]);
//! it does no sample arithmetic.

#[cfg(all(feature = "nucleo-g474re", feature = "mps2-an386"))]
compile_error!("choose one board: --no-default-features --features nucleo-g474re OR mps2-an386");
#[cfg(not(any(feature = "nucleo-g474re", feature = "mps2-an386")))]
compile_error!("choose a board: `cargo fw` (nucleo-g474re) or `cargo fw-qemu` (mps2-an386)");

#[cfg(feature = "mps2-an386")]
mod cmsdk_uart;
#[cfg(feature = "mps2-an386")]
mod mps2_an386;
#[cfg(feature = "mps2-an386")]
mod sim_joint;
#[cfg(feature = "mps2-an386")]
pub use mps2_an386::*;

#[cfg(all(
    feature = "nucleo-g474re",
    not(feature = "mps2-an386"),
    feature = "can"
))]
mod nucleo_can;
#[cfg(all(feature = "nucleo-g474re", not(feature = "mps2-an386")))]
mod nucleo_g474;
#[cfg(all(feature = "nucleo-g474re", not(feature = "mps2-an386")))]
mod nucleo_io;
#[cfg(all(feature = "nucleo-g474re", not(feature = "mps2-an386")))]
pub use nucleo_g474::*;
