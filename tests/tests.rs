//! Workspace-level tests, one binary.

// identification on simulated joints with known truth and on measured data via the CLI
mod identify;
