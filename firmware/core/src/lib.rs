//! Hardware-independent core of the joint-excitation firmware.
#![cfg_attr(not(feature = "std"), no_std)]
