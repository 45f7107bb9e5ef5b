//! Command-line layer (placeholder: the `analysis` branch owns this file).
pub mod capture;
pub mod export;
pub mod info;
