//! Host-side library of the morphlink tools: running the emulated firmware image, locating the
//! workspace and its target directory at run time, the charts' shared plotting and the
//! reference-model study of `morph-model charts`.
#![deny(missing_docs)]

pub mod charts;
pub mod emulator;
pub mod plot;
pub mod workspace;
