//! Host-side library of the morphlink tools: running the emulated firmware image, locating the
//! workspace and its target directory at run time, the charts' shared plotting, the
//! reference-model study of `morph-model charts`, the plants of `morph-sim` and
//! `morph-plant` (in process, or another process over the plant protocol), `morph-sim`'s flash
//! file, and the check that a file written later can be made.
#![deny(missing_docs)]

pub mod charts;
pub mod emulator;
pub mod flash_file;
pub mod gait_chart;
pub mod out_path;
pub mod plants;
pub mod plot;
pub mod remote_plant;
pub mod speed;
pub mod workspace;
