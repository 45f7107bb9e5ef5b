//! CAN link (filled in below).
