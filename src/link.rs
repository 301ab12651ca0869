//! The built-in link: constants and the power/radius table generated at build time from
//! `link.toml` by the lumped model (see `model/`). Regenerate by editing `link.toml` (or setting
//! `MORPHLINK_LINK` to another file) and rebuilding.

/// One table row: a TCA power and what the model predicts for it with the PLA held soft.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Row {
    /// TCA power, W.
    pub power_w: f32,
    /// Steady bending radius, mm.
    pub radius_mm: f32,
    /// Steady TCA temperature rise above ambient, K.
    pub tca_rise_k: f32,
}

include!(concat!(env!("OUT_DIR"), "/link.rs"));
