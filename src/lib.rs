//! morphlink core: the hardware-free controller of a TCA-driven shape-morphing link.
//!
//! `no_std`, allocation-free and free of hardware access so the same code runs in the firmware,
//! in the simulated link on the host and in the emulated image. The firmware, `morph-sim` and
//! the emulated build only move ADC counts into [`controller::Controller::step`] and PWM duties
//! out of it, and protocol lines through [`controller::Controller::handle_line`].
#![cfg_attr(not(test), no_std)]
#![deny(missing_docs)]
// `!(x >= limit)` is deliberate: a NaN reading must fail a check, not pass it.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
#![allow(clippy::needless_range_loop)]

pub mod activity;
#[cfg(feature = "sim")]
pub mod bench;
pub mod budget;
pub mod calibration;
pub mod controller;
pub mod electrical;
pub mod fault;
pub mod fixed;
pub mod heater;
pub mod link;
pub mod links;
pub mod lumped;
pub mod mathf;
pub mod part_limit;
pub mod protocol;
pub mod pulse;
pub mod sequencer;
pub mod session;
pub mod settings;
pub mod shape;
pub mod stats;
pub mod strategy;
pub mod supervisor;
pub mod table;
pub mod thermistor;
pub mod tune;
pub mod vocab;
