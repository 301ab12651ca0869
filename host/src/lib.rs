//! Host-side library of the morphlink tools: running the emulated firmware image, locating the
//! workspace and its target directory at run time, the charts' shared plotting, the
//! reference-model study of `morph-model charts`, and the plants of `morph-sim` and
//! `morph-plant` (in process, or another process over the plant protocol).
#![deny(missing_docs)]

pub mod charts;
pub mod emulator;
pub mod plants;
pub mod plot;
pub mod remote_plant;
pub mod speed;
pub mod workspace;
