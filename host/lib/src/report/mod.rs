//! What a person reads: SVG plots of spectra and Bode diagrams ([`plot`]).
//! Reports only draw what the estimators computed.

pub mod plot;
