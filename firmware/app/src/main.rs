//! Joint-excitation firmware (board layers are added by the firmware issue).
fn main() {}
