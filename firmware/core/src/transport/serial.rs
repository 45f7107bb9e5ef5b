//! Serial link (filled in below).
