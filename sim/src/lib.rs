//! The rig: the controller core driving a plant (`morphlink-plant`) on the simulated board
//! (`morphlink::bench`) at the control rate, and the mismatch ensembles measured with it.
//!
//! `no_std` and allocation-free.
#![cfg_attr(not(test), no_std)]
#![deny(missing_docs)]
// `!(x >= limit)` is deliberate: a NaN reading must fail a check, not pass it.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
#![allow(clippy::needless_range_loop)]

pub mod ensemble;
pub mod multi;
pub mod oracle;
pub mod rig;

pub use multi::{MultiRig, SharedSupply};
pub use rig::{LinkSetup, Rig};
