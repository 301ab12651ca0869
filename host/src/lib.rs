//! Host-side library of the morphlink tools: running the emulated firmware image, locating the
//! workspace and its target directory at run time, and the charts' shared plotting.
#![deny(missing_docs)]

pub mod emulator;
pub mod plot;
pub mod workspace;
