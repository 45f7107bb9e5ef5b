//! Workspace-level tests, one binary.

// The thumbv7em firmware on QEMU mps2-an386, streaming over its UART to this test.
mod emulated_board;
