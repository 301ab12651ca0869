//! The simulated morphing link and a rig that drives it with the controller core.
//!
//! `no_std` and allocation-free, so the emulated firmware image runs the very same code as
//! `morph-sim` and the host tests.
#![cfg_attr(not(test), no_std)]
#![deny(missing_docs)]

pub mod link;
pub mod rig;

pub use link::{Plant, SimLink};
pub use rig::Rig;
