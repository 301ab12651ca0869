//! Host-side library of the morphlink tools: running the emulated firmware image.
#![deny(missing_docs)]

pub mod emulator;
