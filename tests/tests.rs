//! Workspace-level tests, one binary.

// The emulated board streaming over TCP into `jointid capture`, read back bit-exact.
mod board_capture_over_tcp;
// The thumbv7em firmware on QEMU mps2-an386, streaming over its UART to this test.
mod emulated_board;
// identification on simulated joints with known truth (measured data via the CLI: host tests)
mod identify;
// Software in the loop: generator -> simulator -> wire -> .jcap -> decoder -> CSV, exact.
mod sil;
