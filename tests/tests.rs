//! Workspace-level tests, one binary.
