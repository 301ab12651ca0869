//! Lumped physical model of the TCA-driven shape-morphing link.
//!
//! The core (`no_std`, f64 through `libm`) is shared by the build-time table generator, the
//! simulated link and host tools: [`thermal`] (steady resistance matrix and transient network),
//! [`mechanics`] (TCA force law and constant-curvature balance) and [`table`]. With the `std`
//! feature, [`file`](mod@file) reads and writes `link.toml`; with `fit`, [`calibrate`] fits the unknown
//! mechanical constants to measured radii; [`fourbar`] is the paper's application, a four-bar
//! linkage with the locked link as its coupler, and the foot path it draws. With `reference`, [`reference`](mod@reference) holds the paper's full
//! model (2-D finite-volume thermal, Cosserat rod, physics-based TCA law) and the study of what
//! each level of model costs and buys.
#![cfg_attr(not(any(feature = "std", test)), no_std)]
#![deny(missing_docs)]
// `!(x >= limit)` is deliberate: a NaN reading must fail a check, not pass it.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
#![allow(clippy::needless_range_loop)]

pub mod draw;
pub mod mechanics;
pub mod params;
pub mod table;
pub mod thermal;

#[cfg(feature = "fit")]
pub mod calibrate;
#[cfg(feature = "std")]
pub mod file;
#[cfg(feature = "std")]
pub mod fourbar;
#[cfg(feature = "reference")]
pub mod reference;
#[cfg(feature = "std")]
pub mod validate;

pub use params::LinkParams;
