//! What a person reads: SVG plots of spectra, Bode diagrams and time records ([`plot`]),
//! and the diagnosis report as one self-contained HTML page ([`html`]).
//! Reports only draw what the estimators computed.

pub mod html;
pub mod plot;
pub mod views;
