//! Experiments on the simulated joint with a known truth: the paper's Table 2
//! ([`paper`]: simulate, stream through the wire, decode, fit, compare).

pub mod paper;
