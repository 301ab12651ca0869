//! Plants: simulated morphing links that know nothing of the controller.
//!
//! A plant takes the two heater duties and time and gives what a board's sensors would see
//! (the temperature each thermistor bead is at and the heater supply) and the true radius,
//! which no sensor gives. Everything between that and the controller, the thermistor and ADC
//! model, the heater output stage, injected faults and the control clock, lives in the rig
//! (`morphlink::bench` and `morphlink-sim`). This crate imports no controller type; a test in
//! the workspace holds that (`tests/layout.rs`).
//!
//! The same seam is the plant protocol's: any model that answers [`Plant`]'s questions can
//! drive the real controller tick by tick: [`wire`] is that protocol (plant protocol 1), with
//! [`wire::serve`] (feature `std`) answering any [`Plant`] over it. `no_std` and
//! allocation-free without `std`, so the emulated firmware image runs the very same plant as
//! the host tools.
//!
//! With the `hifi` feature (host only, `std`), [`hifi`] is a high-fidelity plant structurally
//! different from the controller's model: the 2-D finite-volume cross-section, beads beside the
//! heaters, a viscoelastic PLA over its temperature field, a hysteretic, creeping TCA.
#![cfg_attr(not(any(test, feature = "std", feature = "hifi")), no_std)]
#![deny(missing_docs)]
#![allow(clippy::neg_cmp_op_on_partial_ord)]

#[cfg(feature = "hifi")]
pub mod hifi;
pub mod lumped;
pub mod wire;

pub use lumped::{Lumped, LumpedSpec};

/// Heater duties held over one step, fractions in [0, 1] (anything else counts as 0 or 1).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Duties {
    /// PLA heater (the nichrome wrap).
    pub pla: f64,
    /// TCA heater (the actuator's own resistance).
    pub tca: f64,
}

/// What the link shows at the end of a step: the board's inputs before any electronics, and
/// the true radius (for the rig and the charts, never for the controller).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Temperature of the PLA thermistor bead, °C.
    pub t_pla_c: f64,
    /// Temperature of the TCA thermistor bead, °C.
    pub t_tca_c: f64,
    /// Temperature of the ambient thermistor bead, °C.
    pub t_amb_c: f64,
    /// Heater supply, V.
    pub supply_v: f64,
    /// True bending radius of the link, mm.
    pub radius_mm: f64,
    /// The heaters' true resistances at this step (PLA wrap, TCA), Ω: what a board that senses
    /// its heaters' current measures. `None`: the plant does not say, and the board it runs on
    /// senses no current (the paper's wiring).
    pub heater_ohm: Option<[f64; 2]>,
}

/// Inside values a sensor cannot give: for `SIM STATE`, charts and the ensemble's peak checks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Truth {
    /// Plant time since it was made, s.
    pub time_s: f64,
    /// Mean temperature of the PLA rod, °C.
    pub pla_c: f64,
    /// Mean temperature of the TCA, °C.
    pub tca_c: f64,
    /// Power dissipated in the PLA heater over the last step, W.
    pub pla_w: f64,
    /// Power dissipated in the TCA over the last step, W.
    pub tca_w: f64,
}

/// The medium around the link.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Medium {
    /// Still water (the paper's bath).
    Water,
    /// Still air.
    Air,
}

/// A change of the link's surroundings or supply, asked for by a test or a user (`SIM ...`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Setting {
    /// Heater supply, V.
    SupplyV(f64),
    /// Temperature of the medium, °C.
    AmbientC(f64),
    /// The medium.
    Medium(Medium),
}

/// Why a plant refused a [`Setting`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SetError {
    /// This plant cannot change that.
    Unsupported,
}

/// A simulated link.
pub trait Plant {
    /// Holds `duty` for `dt_s` seconds.
    fn step(&mut self, dt_s: f64, duty: Duties);
    /// What the link shows now.
    fn sample(&self) -> Sample;
    /// Inside values for checks and charts.
    fn truth(&self) -> Truth;
    /// Changes the surroundings or the supply from now on.
    fn set(&mut self, setting: Setting) -> Result<(), SetError>;
    /// Why the plant can no longer answer (a remote plant that exited, timed out or refused a
    /// step), naming it; `None` while it works. The rig's shell checks it after each tick and
    /// ends the run. In-process plants never fail.
    fn failure(&self) -> Option<&str> {
        None
    }
}

/// A boxed plant is a plant: shells pick one at run time (`Rig<Box<dyn Plant>>`).
#[cfg(any(test, feature = "std"))]
impl<P: Plant + ?Sized> Plant for std::boxed::Box<P> {
    fn step(&mut self, dt_s: f64, duty: Duties) {
        (**self).step(dt_s, duty)
    }
    fn sample(&self) -> Sample {
        (**self).sample()
    }
    fn truth(&self) -> Truth {
        (**self).truth()
    }
    fn set(&mut self, setting: Setting) -> Result<(), SetError> {
        (**self).set(setting)
    }
    fn failure(&self) -> Option<&str> {
        (**self).failure()
    }
}
