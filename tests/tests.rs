//! Workspace-level tests, one binary.

/// emulated board (QEMU) streaming over TCP into the capture, read back bit-exact
mod capture_cli;
