//! morphlink core: the hardware-free controller of a TCA-driven shape-morphing link.
//!
//! `no_std`, allocation-free and free of hardware access so the same code runs in the firmware,
//! in the simulated link on the host and in the emulated image.
#![cfg_attr(not(test), no_std)]
#![deny(missing_docs)]

pub mod fixed;
pub mod heater;
pub mod mathf;
pub mod protocol;
pub mod thermistor;
