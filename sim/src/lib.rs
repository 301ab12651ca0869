//! The simulated morphing link and a rig that drives it with the controller core.
//!
//! `no_std` and allocation-free, so the emulated firmware image runs the very same code as
//! `morph-sim` and the host tests.
#![cfg_attr(not(test), no_std)]
#![deny(missing_docs)]
// `!(x >= limit)` is deliberate: a NaN reading must fail a check, not pass it.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
#![allow(clippy::needless_range_loop)]

pub mod ensemble;
pub mod link;
pub mod rig;

pub use link::{Plant, SimLink};
pub use rig::Rig;
