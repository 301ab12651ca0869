//! The morph strategies: what the heaters get in each phase and when a phase is over.
//!
//! The [`crate::sequencer::Sequencer`] owns the phases, their timeouts and the events; each
//! tick it hands the running strategy a [`Tick`] and asks it two things through the
//! [`Strategy`] trait: is the current phase over ([`Strategy::phase_done`]), and which powers
//! the (possibly new) phase gets ([`Strategy::powers`]). One type and one file per strategy:
//!
//! - [`paper`]: the paper's fixed timing, table power;
//! - [`gated`]: thermistor thresholds and settling, table power;
//! - [`boost`]: the controller's thermal model driven open loop to target temperatures;
//! - [`closed`]: the same model corrected by the thermistors (observer), spring-back compensated.
//!
//! [`model`] holds what `boost` and `closed` share: the thermal model ([`model::observer`]), the
//! target temperatures from the mechanics ([`model::target`]) and the drive towards them.
//! [`AnyStrategy`] holds whichever one a morph runs and is the one place that dispatches.

pub mod boost;
pub mod closed;
pub mod gated;
pub mod model;
pub mod paper;

use crate::protocol::Mode;
use crate::vocab::{Measurements, Phase, Powers};

/// The strategy `auto` runs: the one the strategy chart (`cargo xtask strategies`,
/// `docs/strategies.md`) puts on the Pareto front with a 95th-percentile radius error under 2 %
/// and the shortest 95th-percentile morph time.
pub const AUTO_STRATEGY: Mode = Mode::Closed;
const _: () = assert!(
    !matches!(AUTO_STRATEGY, Mode::Auto),
    "auto must name a strategy"
);

/// PLA temperature at which it counts as soft, °C (8 K above its 62 °C glass transition, so
/// the lagging thermistor does not call it soft too early).
pub const SOFT_THRESHOLD_C: f32 = 70.0;
/// PLA temperature at which it counts as rigid again, °C (17 K below Tg: modulus back to
/// glassy, the shape frozen).
pub const RIGID_THRESHOLD_C: f32 = 45.0;
const _: () = assert!(RIGID_THRESHOLD_C < SOFT_THRESHOLD_C);
/// Time the TCA is kept off after lock before the morph is done, s: the TCA's force decays
/// within about a second, so the spring-back has happened when `done` is reported.
pub const RELEASE_S: f32 = 2.0;

/// The temperatures a morph's phases end on and aim at, °C: the user-settable values of
/// `crate::settings` (defaults [`SOFT_THRESHOLD_C`], [`RIGID_THRESHOLD_C`] and
/// [`model::PLA_SOFT_TARGET_C`]); the settings' ranges keep every combination inside the
/// constants' own margins.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Thresholds {
    /// PLA temperature at which it counts as soft, °C.
    pub soft_threshold_c: f32,
    /// PLA temperature at which it counts as rigid again, °C.
    pub rigid_threshold_c: f32,
    /// PLA temperature the model strategies (`boost`, `closed`) drive the rod to, °C.
    pub pla_soft_target_c: f32,
}

impl Thresholds {
    /// The compiled-in values.
    pub const DEFAULT: Thresholds = Thresholds {
        soft_threshold_c: SOFT_THRESHOLD_C,
        rigid_threshold_c: RIGID_THRESHOLD_C,
        pla_soft_target_c: model::PLA_SOFT_TARGET_C,
    };
}

/// What the sequencer tells the running strategy each tick.
#[derive(Clone, Copy, Debug)]
pub struct Tick<'a> {
    /// Now, ms.
    pub now_ms: u64,
    /// The current phase (one of soften, bend, lock, release).
    pub phase: Phase,
    /// This tick's temperatures.
    pub m: &'a Measurements,
    /// Seconds since the current phase began.
    pub in_phase_s: f32,
    /// Seconds since MORPH.
    pub since_start_s: f32,
    /// Measured heater supply, V (NaN if unknown).
    pub supply_v: f32,
    /// The TCA's mean temperature from its own resistance, °C (NaN on a board that does not
    /// sense current, or before its rest reference: [`crate::electrical`]).
    pub tca_self_c: f32,
    /// The thresholds and targets this morph runs with.
    pub th: &'a Thresholds,
    /// Most power each heater may take this tick, W: the heater caps, or less where several
    /// links share one supply budget ([`crate::budget`]); the model strategies' observers are
    /// fed what the heaters can deliver under it.
    pub allow_w: Powers,
}

/// What one strategy decides. The sequencer calls, each tick of a morph: [`Strategy::phase_done`]
/// (the strategy may update its own state from the measurements first), then on a phase change
/// [`Strategy::enter`] (after bend, [`Strategy::radius_estimate_mm`] first), then
/// [`Strategy::powers`] for the phase now current.
pub trait Strategy {
    /// A new phase began at `now_ms`: reset whatever the strategy judges per phase.
    fn enter(&mut self, phase: Phase, now_ms: u64);
    /// This strategy's own timeout of `phase`, s, or `None` for the sequencer's default.
    fn timeout_s(&self, _phase: Phase) -> Option<f32> {
        None
    }
    /// Whether the current phase is over this tick.
    fn phase_done(&mut self, t: &Tick) -> bool;
    /// The radius this morph will end at, mm, judged as bend ends.
    fn radius_estimate_mm(&self, m: &Measurements) -> f32;
    /// Heater powers for `phase` (the phase after this tick's change, if any), W.
    fn powers(&mut self, phase: Phase, t: &Tick) -> Powers;
    /// The temperatures this strategy drives the heaters towards in `phase`, °C; NaN for a
    /// heater it drives by power, not to a temperature (STATUS reports them, `-` for NaN).
    fn targets_c(&self, _phase: Phase) -> TargetTemps {
        TargetTemps::NONE
    }
}

/// The temperatures a strategy aims the heaters at, °C (NaN: no temperature target).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TargetTemps {
    /// PLA heater's target, °C.
    pub pla_c: f32,
    /// TCA heater's target, °C.
    pub tca_c: f32,
}

impl TargetTemps {
    /// No temperature target for either heater.
    pub const NONE: TargetTemps = TargetTemps {
        pla_c: f32::NAN,
        tca_c: f32::NAN,
    };
}

/// How a morph starts: the target and what the table and the sensors say.
#[derive(Clone, Copy, Debug)]
pub struct Start<'a> {
    /// MORPH time, ms.
    pub now_ms: u64,
    /// Target radius, mm.
    pub radius_mm: f32,
    /// The table's TCA power for the radius, W.
    pub tca_power_w: f32,
    /// Temperatures at MORPH.
    pub m: &'a Measurements,
    /// This link's calibration (TUNE's thermistor gains, MEASURED's TCA map).
    pub cal: &'a crate::calibration::Calibration,
    /// The PLA temperature the model strategies hold in soften and bend, °C (the live
    /// `pla_soft_target_c`).
    pub pla_target_c: f32,
    /// The TCA's own temperature at the start, °C (NaN where not sensed): `closed` bends on it
    /// where it is known and `TUNE` has fitted its coefficient.
    pub tca_self_c: f32,
    /// The link's curvature when the TCA's rest reference was read, 1/m (NaN: unknown): what
    /// the own temperature's strain term counts from.
    pub rest_shape_per_m: f32,
}

/// The strategy a morph runs, one of the four: the single place that dispatches on it.
#[derive(Clone, Copy, Debug)]
pub enum AnyStrategy {
    /// [`paper::Paper`].
    Paper(paper::Paper),
    /// [`gated::Gated`].
    Gated(gated::Gated),
    /// [`boost::Boost`].
    Boost(boost::Boost),
    /// [`closed::Closed`].
    Closed(closed::Closed),
}

impl AnyStrategy {
    /// The strategy a morph in `mode` runs (`auto` resolved to [`AUTO_STRATEGY`]).
    pub fn resolve(mode: Mode) -> Mode {
        match mode {
            Mode::Auto => AUTO_STRATEGY,
            m => m,
        }
    }

    /// The strategy for `mode`, set up for a morph that starts as `s` says.
    pub fn new(mode: Mode, s: &Start) -> Self {
        match Self::resolve(mode) {
            Mode::Paper => AnyStrategy::Paper(paper::Paper::new(s)),
            Mode::Boost => AnyStrategy::Boost(boost::Boost::new(s)),
            Mode::Closed => AnyStrategy::Closed(closed::Closed::new(s)),
            Mode::Gated | Mode::Auto => AnyStrategy::Gated(gated::Gated::new(s)),
        }
    }

    /// The strategy this is, as its mode (never `Auto`).
    pub fn mode(&self) -> Mode {
        match self {
            AnyStrategy::Paper(_) => Mode::Paper,
            AnyStrategy::Gated(_) => Mode::Gated,
            AnyStrategy::Boost(_) => Mode::Boost,
            AnyStrategy::Closed(_) => Mode::Closed,
        }
    }

    /// The one dispatch point.
    pub fn get(&self) -> &dyn Strategy {
        match self {
            AnyStrategy::Paper(s) => s,
            AnyStrategy::Gated(s) => s,
            AnyStrategy::Boost(s) => s,
            AnyStrategy::Closed(s) => s,
        }
    }

    /// The one dispatch point, mutable.
    pub fn get_mut(&mut self) -> &mut dyn Strategy {
        match self {
            AnyStrategy::Paper(s) => s,
            AnyStrategy::Gated(s) => s,
            AnyStrategy::Boost(s) => s,
            AnyStrategy::Closed(s) => s,
        }
    }

    /// The thermal model of a `boost` or `closed` morph.
    #[cfg(test)]
    pub(crate) fn model(&self) -> Option<&model::ModelDrive> {
        match self {
            AnyStrategy::Boost(s) => Some(&s.drive),
            AnyStrategy::Closed(s) => Some(&s.drive),
            _ => None,
        }
    }
}
