//! Helpers shared by the workspace-level tests (finding the firmware, running QEMU).
