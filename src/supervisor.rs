//! Safety supervisor, run every control tick before the sequencer and independently of it.
//!
//! Checks, each with a named default scaled to this link (a few grams of silicone whose heaters
//! respond within seconds, not a 3D-printer hot end):
//! thermistor open/short (ADC range, a leaky count), per-sensor min/max temperature,
//! heater-not-heating (a gain window, a held fall, and the TCA held against the PLA sensor),
//! heating while off or turned down, a frozen or implausible sensor, stale sensor frames and
//! supply voltage. A trip is returned as a [`Fault`]; the controller turns both heaters off in
//! the same tick and latches it.

use crate::heater::HeaterConfig;
use crate::link::{R_PP_K_PER_W, R_TP_K_PER_W, R_TT_K_PER_W};
use crate::part_limit::{estimate_c, CEILING_BAND_K, CEILING_MARGIN_K, UNTUNED_BEAD_SHARES};
use crate::thermistor::{RangeCheck, Reading};
use crate::vocab::{Doing, Heater, Measurements, Phase, Powers, Sensor};

/// What tripped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FaultCode {
    /// Thermistor reads open circuit (ADC near full scale).
    ThermistorOpen,
    /// Thermistor reads short circuit (ADC near zero).
    ThermistorShort,
    /// A sensor read below its minimum temperature.
    UnderTemperature,
    /// A sensor read above its maximum temperature.
    OverTemperature,
    /// A heater was commanded but its temperature did not rise.
    HeaterNotHeating,
    /// A heater's sensor kept rising with its heater commanded off or low (a stuck MOSFET).
    HeatingWhileOff,
    /// No fresh sensor frame arrived in time.
    StaleSensor,
    /// The heater supply is outside its allowed range.
    SupplyOutOfRange,
    /// A morph phase overran its timeout.
    PhaseTimeout,
    /// A heated sensor did not move while its heater's power changed (a hung ADC channel, a
    /// bead frozen to something else).
    SensorFrozen,
    /// A heated sensor disagreed with the supervisor's thermal expectation for too long
    /// (drifting, swapped, off its heater, or a heater that died).
    SensorImplausible,
    /// A driven heater carried no current (current sense: [`crate::electrical`]).
    HeaterOpen,
    /// A heater carried current while not driven: its MOSFET conducts (current sense).
    HeaterShort,
    /// A heater's resistance is out of its range: a partial short, a broken strand, the wrong
    /// heater on a channel (current sense).
    HeaterResistance,
    /// Current persisted after the supply's cut-off opened (current sense).
    CutoffFailed,
}

impl FaultCode {
    /// Wire code (kebab-case).
    pub fn as_str(self) -> &'static str {
        match self {
            FaultCode::ThermistorOpen => "thermistor-open",
            FaultCode::ThermistorShort => "thermistor-short",
            FaultCode::UnderTemperature => "under-temperature",
            FaultCode::OverTemperature => "over-temperature",
            FaultCode::HeaterNotHeating => "heater-not-heating",
            FaultCode::HeatingWhileOff => "heating-while-off",
            FaultCode::StaleSensor => "stale-sensor",
            FaultCode::SupplyOutOfRange => "supply-out-of-range",
            FaultCode::PhaseTimeout => "phase-timeout",
            FaultCode::SensorFrozen => "sensor-frozen",
            FaultCode::SensorImplausible => "sensor-implausible",
            FaultCode::HeaterOpen => "heater-open",
            FaultCode::HeaterShort => "heater-short",
            FaultCode::HeaterResistance => "heater-resistance",
            FaultCode::CutoffFailed => "cutoff-failed",
        }
    }
}

/// What a fault is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Subject {
    /// A thermistor.
    Sensor(Sensor),
    /// A heater.
    Heater(Heater),
    /// A morph phase.
    Phase(Phase),
    /// The heater supply.
    Supply,
    /// All sensors (a whole frame).
    Frame,
}

/// A latched safety trip.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fault {
    /// What tripped.
    pub code: FaultCode,
    /// Where.
    pub subject: Subject,
    /// The offending value (°C, V, s or ADC fraction; NaN if none).
    pub value: f32,
}

/// The doc that explains every check and its setting; alarm lines point to it.
pub const SAFETY_DOC: &str = "docs/safety.md";
/// The section of [`SAFETY_DOC`] with the table of every check and its setting.
pub const SAFETY_DOC_SECTION: &str = "Safety defaults";

impl Fault {
    /// The named settings that govern this trip, as they are spelled in the source and in the
    /// [`SAFETY_DOC`]'s [`SAFETY_DOC_SECTION`] table (alarm lines name them).
    pub fn settings(&self) -> &'static str {
        match (self.code, self.subject) {
            (FaultCode::ThermistorOpen, _) => "DEFAULT_MAX_FRACTION",
            (FaultCode::ThermistorShort, _) => "DEFAULT_MIN_FRACTION",
            (FaultCode::UnderTemperature | FaultCode::OverTemperature, Subject::Sensor(sensor)) => {
                match sensor {
                    Sensor::Pla => "PLA_LIMITS, LIMIT_CONSECUTIVE",
                    Sensor::Tca => "TCA_LIMITS, LIMIT_CONSECUTIVE",
                    Sensor::Amb => "AMB_LIMITS, LIMIT_CONSECUTIVE",
                }
            }
            (FaultCode::OverTemperature, Subject::Heater(Heater::Pla)) => {
                "PLA_LIMITS, UNTUNED_BEAD_SHARES"
            }
            (FaultCode::OverTemperature, Subject::Heater(Heater::Tca)) => {
                "TCA_LIMITS, UNTUNED_BEAD_SHARES"
            }
            (FaultCode::UnderTemperature | FaultCode::OverTemperature, _) => {
                "PLA_LIMITS, TCA_LIMITS, AMB_LIMITS"
            }
            (FaultCode::HeaterNotHeating, _) => {
                "HEATING_MIN_GAIN_K, HOLD_MAX_FALL_K, HELD_MAX_FALL_K"
            }
            (FaultCode::HeatingWhileOff, _) => {
                "OFF_GRACE_S, OFF_MAX_RISE_K, OFF_STORED_MAX_RISE_K, LOW_GRACE_S"
            }
            (FaultCode::StaleSensor, _) => "STALE_AFTER_MS",
            (FaultCode::SupplyOutOfRange, _) => {
                "SUPPLY_MIN_V, SUPPLY_MAX_V, SUPPLY_READ_TOLERANCE_V"
            }
            (FaultCode::PhaseTimeout, Subject::Phase(phase)) => match phase {
                Phase::Soften => "SOFTEN_TIMEOUT_S",
                Phase::Bend => "BEND_TIMEOUT_S",
                Phase::Lock => "LOCK_TIMEOUT_S",
                Phase::Rest => "REST_TIMEOUT_S, REST_MAX_RISE_K",
                _ => "RELEASE_TIMEOUT_S",
            },
            (FaultCode::PhaseTimeout, _) => "SOFTEN_TIMEOUT_S",
            (FaultCode::SensorFrozen, _) => {
                "FROZEN_POWER_STEP_FRACTION, FROZEN_WINDOW_S, MUST_COOL_MARGIN_K, FROZEN_STILL_S"
            }
            (FaultCode::SensorImplausible, Subject::Sensor(Sensor::Amb)) => {
                "AMB_RAMP_MAX_K_PER_S, AMB_RAMP_SETTLING_SHARE"
            }
            // The line cap leaves room for one name: the doc's row names both.
            (FaultCode::SensorImplausible, Subject::Heater(_)) => "CROSS_MAX_LEAD_K",
            (FaultCode::SensorImplausible, _) => {
                "PLAUS_LOW_GAIN, PLAUS_HIGH_GAIN, PLAUS_MARGIN_K, PLAUS_TIME_S"
            }
            (FaultCode::HeaterOpen, _) => "OPEN_MAX_SHARE, ELECTRICAL_TICKS",
            (FaultCode::HeaterShort, _) => "SHORT_MIN_A, ELECTRICAL_TICKS",
            (FaultCode::HeaterResistance, Subject::Heater(Heater::Pla)) => {
                "PLA_OHM_RANGE, ELECTRICAL_TICKS"
            }
            (FaultCode::HeaterResistance, _) => "TCA_OHM_RANGE, ELECTRICAL_TICKS",
            (FaultCode::CutoffFailed, _) => "SHORT_MIN_A, CUTOFF_SETTLE_TICKS",
        }
    }
}

/// Allowed temperature range of one sensor, °C.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limits {
    /// Below this the reading is implausible (broken wire, frozen water), °C.
    pub min_c: f32,
    /// Above this the link is in danger, °C.
    pub max_c: f32,
}

/// PLA limits: the rod melts near 150 °C; 130 °C leaves 20 K margin. The paper's 4 W for 20 s
/// reaches about 115 °C under water, so the paper's protocol still runs.
pub const PLA_LIMITS: Limits = Limits {
    min_c: 2.0,
    max_c: 130.0,
};
/// TCA limits: annealed at 160 °C, it must stay below about 150 °C; 130 °C leaves 20 K margin.
pub const TCA_LIMITS: Limits = Limits {
    min_c: 2.0,
    max_c: 130.0,
};
/// Ambient limits: a water bath or a room; above 50 °C the model's assumptions no longer hold.
pub const AMB_LIMITS: Limits = Limits {
    min_c: 2.0,
    max_c: 50.0,
};
/// Lowest heater supply, V: −25 % of 12 V. Heater duty is computed from the measured voltage,
/// so moderate sag is harmless; below this the heaters cannot reach the soften power.
pub const SUPPLY_MIN_V: f32 = 9.0;
/// Highest heater supply, V: +25 % of 12 V; above it one PWM step is too coarse for the TCA.
pub const SUPPLY_MAX_V: f32 = 15.0;
/// The supply limits are judged on the reading to this much either side, V: half the 0.1 V
/// step the alarm reports the reading in, so a supply the alarm would print as within its range
/// never trips (a 9.0 V supply reads 8.9999 V through the divider and the ADC's steps).
pub const SUPPLY_READ_TOLERANCE_V: f32 = 0.05;
const _: () = assert!(SUPPLY_READ_TOLERANCE_V >= 0.0 && SUPPLY_READ_TOLERANCE_V < 0.5);
/// A sensor frame older than this counts as stale, ms. Klipper allows 7 s for hot ends with
/// time constants of minutes; the TCA's fast thermal part is about 1 s, so 1 s (10 ticks).
pub const STALE_AFTER_MS: u64 = 1000;
/// Out-of-limit readings before a temperature trip (Klipper: 4 samples), counted by a leaky
/// counter: +1 for a reading out of limits, −1 for one within, so one noisy reading never trips
/// but an intermittent excursion (every other reading) does.
pub const LIMIT_CONSECUTIVE: u8 = 4;
// The same 4-sample rule for open/short (thermistor::RangeCheck) and for the limits.
const _: () = assert!(LIMIT_CONSECUTIVE == RangeCheck::DEFAULT_CONSECUTIVE);
/// Heater-not-heating (Klipper's `verify_heater`, scaled to this link): a heater is judged
/// while it is commanded at least this share of its power cap (`HeaterConfig::max_power_w`),
/// so the PLA from 1.0 W and the TCA from 0.4 W. Below it, the other heater's heat reaching the
/// sensor (`R_TP_K_PER_W`: 7.7 K per W, 31 K for the 4 W soften) is as large as the heater's own
/// and a dead heater could not be told from a weak one.
pub const HEATING_MIN_POWER_FRACTION: f32 = 0.2;
/// Heater-not-heating: while judged and outside its band ([`HEATING_BAND_K`]) the
/// heater's sensor must gain this much within [`HEATING_WINDOW_S`], K; each time it does, the
/// window starts again from the new reading. Klipper asks 2 K in 20 s of a hot end; the
/// slowest healthy gain measured here (the hifi link's lagging beads, a warm link, still air)
/// is several times this, while a dead heater's sensor cools or drifts with the other heater's
/// heat by less (see `tests/safety.rs`).
pub const HEATING_MIN_GAIN_K: f32 = 2.0;
/// Heater-not-heating: the window for [`HEATING_MIN_GAIN_K`], s. A dead heater trips within
/// this time of being switched on (or of its phase starting). About the PLA bead's lag and 3
/// TCA bead time constants: the shortest window the healthy ensemble passes without an alarm
/// (`cargo xtask strategies`; docs/safety.md, "What the table says").
pub const HEATING_WINDOW_S: f32 = 9.0;
/// Heater-not-heating: the band's floor, K above ambient plus the model's steady rise the other
/// heater alone would give this sensor (`R_TP_K_PER_W` times its power). Below it the heater has
/// shown nothing of its own and its sensor must gain; in it the heater has (a dead heater's
/// sensor never gets above what the other heater gives it: the hifi link couples the heaters
/// less than the model), and its sensor must not fall far. 3 K is 60 times the sensor noise; a
/// closed-loop hold in a 46 °C bath sits about 5 K above ambient.
pub const HEATING_BAND_K: f32 = 3.0;
/// Heater-not-heating, in band: a judged heater whose sensor falls more than this below its
/// highest reading since it entered the band (or since it was last above the model's
/// equilibrium) trips, K (Klipper's `max_error` once at target). A heater that dies hot cools
/// at once (1–2 K/s); the largest healthy fall measured is about 12 K (the hifi PLA bead
/// relaxing from the 4 W soften to the hold power's equilibrium, which on that link lies below
/// the model's), so 15 K.
pub const HEATING_MAX_FALL_K: f32 = 15.0;
/// Heater-not-heating: longest time a judged heater's sensor may stay below its band, s
/// (restarted by a power step up of more than [`HEATING_POWER_STEP_FRACTION`]; judged while the
/// heater's own model rise is at least [`HEATING_BAND_MIN_OWN_SHARE`] times the other heater's
/// share). The slowest healthy climb into the band measured (the hifi TCA bead at a low bend
/// power, 0.7 W) takes about 20 s; a dead heater whose sensor the other heater keeps warming
/// never gets there.
pub const HEATING_BAND_TIMEOUT_S: f32 = 30.0;
/// [`HEATING_BAND_TIMEOUT_S`] is judged only while the heater's own model rise is at least this
/// many times the other heater's share: the hifi link couples the heaters less than the model
/// does, so where the other heater's heat is comparable (boost's soften, the PLA at 4–5 W) a
/// healthy sensor need not reach the floor; the slope checks still judge it there.
pub const HEATING_BAND_MIN_OWN_SHARE: f32 = 2.0;
/// A commanded power rise by more than this share restarts [`HEATING_BAND_TIMEOUT_S`].
pub const HEATING_POWER_STEP_FRACTION: f32 = 0.1;
// A dead heater must trip within a soften phase, before it can time out: the soften timeout's
// floor is this window plus 10 s (`settings::SOFTEN_TIMEOUT_RANGE_S`, asserted there).
const _: () = assert!(HEATING_WINDOW_S > 0.0 && HEATING_WINDOW_S < 20.0);
/// Heating-while-off: how long both heaters must have been commanded off before a heater's
/// sensor is watched, s. The heat already in the link keeps a lagging bead rising for a few
/// seconds after turn-off (the hifi PLA bead, 10 s behind its rod, for about 3 s after the 4 W
/// soften); 15 s covers it with margin.
pub const OFF_GRACE_S: f32 = 15.0;
/// Heating-while-off: a sensor that rises this far above its lowest reading (relative to the
/// ambient sensor, so a warming bath does not count) while both heaters are off trips, K. A
/// cooling link only falls; 3 K is 60 times the sensor noise, and a stuck PLA heater at 10 V
/// (3.3 W) gains it within a few seconds, long before the 130 °C limit.
pub const OFF_MAX_RISE_K: f32 = 3.0;
/// Heating-while-off: a sensor that rises this far above its lowest reading (above ambient)
/// since both heaters were cut trips at once, within [`OFF_GRACE_S`] too, K. The heat stored in
/// the link lifts a lagging bead a few kelvin after a cut: set above the largest such rise
/// where judged (above the other heated sensor, [`OFF_NEIGHBOUR_MARGIN_K`]) measured by `cargo
/// xtask stored-heat` (docs/safety.md, "ABORT on a healthy link"), and low enough that a PLA
/// heater stuck on in release trips within the grace, before the rod passes 130 °C.
pub const OFF_STORED_MAX_RISE_K: f32 = 12.0;
/// Heating-while-off: a heater's sensor that rises while it reads less than this above the other
/// heated sensor is not judged, K: with both heaters off it may be warmed by the hotter part of
/// the link, and heat flows only from hot to cold (in still air the PLA rod cut after a long
/// soften warms the TCA's bead for a minute). The same holds for a heater turned down while the
/// other is on (a TCA holding a tight radius in still air warms the cooling PLA). A stuck
/// heater soon lifts its own sensor above the other's; the margin covers the PLA bead reading
/// below its rod. Measured by `cargo xtask stored-heat` and `cargo xtask faults`
/// (docs/safety.md, "ABORT on a healthy link").
pub const OFF_NEIGHBOUR_MARGIN_K: f32 = 3.0;
/// Heating-while-off: the most a sensor may rise since both heaters were cut and still count as
/// warmed by the other ([`OFF_NEIGHBOUR_MARGIN_K`]), K: set above the largest such rise a
/// healthy ABORT leaves (`cargo xtask stored-heat`; docs/safety.md, "ABORT on a healthy link");
/// past it a stuck heater is named whatever the other sensor reads.
pub const OFF_NEIGHBOUR_MAX_RISE_K: f32 = 20.0;
/// Sensor-implausible, crossed: the PLA heater is judged by the crossed-wires check while it is
/// commanded at least this share of its cap (from 2.5 W: soften's power) and the TCA below
/// [`HEATING_MIN_POWER_FRACTION`] of its own: then the PLA's own bead must lead.
pub const CROSS_MIN_POWER_FRACTION: f32 = 0.5;
/// Sensor-implausible, crossed: while judged ([`CROSS_MIN_POWER_FRACTION`]) the TCA's sensor
/// may gain at most this much more than the PLA's own since that began, K. A heater warms its
/// own bead first and most; the other bead sees its heat through the silicone, later and less,
/// so a TCA reading that leads is a swapped pair of thermistors, which would let `closed` hold
/// the PLA at 5 W on the TCA's cooling bead (docs/safety.md, "Wiring faults: swapped
/// thermistors, a bead off its heater").
pub const CROSS_MAX_LEAD_K: f32 = 3.0;

/// Heating-while-off, one heater low: how long a heater must have been commanded below
/// [`HEATING_MIN_POWER_FRACTION`] of its cap, with the other heater on, before its sensor is
/// watched, s (with both off, [`OFF_GRACE_S`] applies). After a power drop the hifi PLA bead,
/// 10 s behind its rod, keeps rising for about 3 s while it catches up; 8 s covers it and still
/// finds a stuck heater within the 11 s `tests/safety.rs` holds it to (docs/safety.md, "What
/// the table says").
pub const LOW_GRACE_S: f32 = 8.0;
/// Heating-while-off, one heater low: a heater's sensor is watched only while it reads more
/// than this above the widest rise the commanded powers can explain ([`PLAUS_HIGH_GAIN`] times
/// the model's steady rise for them: its own low power and the other heater's share, reached
/// in still air), K. There its own heater being low means it must cool; a sensor that instead rises
/// [`OFF_MAX_RISE_K`] above its lowest reading trips `heating-while-off` (a stuck MOSFET that
/// the controller is trying to turn down). The same margin arms `sensor-frozen` for the PLA with
/// its heater low while it reads above the TCA (warmed by the TCA alone, the rod must cool).
/// 3 K is 60 times the sensor noise.
pub const MUST_COOL_MARGIN_K: f32 = 3.0;
const _: () =
    assert!(LOW_GRACE_S > 0.0 && LOW_GRACE_S < HEATING_WINDOW_S && LOW_GRACE_S < OFF_GRACE_S);
const _: () = assert!(MUST_COOL_MARGIN_K > 0.0 && MUST_COOL_MARGIN_K <= OFF_MAX_RISE_K);
const _: () = assert!(OFF_STORED_MAX_RISE_K > OFF_MAX_RISE_K);
const _: () =
    assert!(OFF_NEIGHBOUR_MARGIN_K >= 0.0 && OFF_NEIGHBOUR_MARGIN_K < OFF_STORED_MAX_RISE_K);
const _: () = assert!(CROSS_MAX_LEAD_K > 0.0 && CROSS_MAX_LEAD_K <= HEATING_BAND_K);
const _: () = assert!(OFF_NEIGHBOUR_MAX_RISE_K > OFF_STORED_MAX_RISE_K);
const _: () = assert!(
    CROSS_MIN_POWER_FRACTION > HEATING_MIN_POWER_FRACTION && CROSS_MIN_POWER_FRACTION <= 1.0
);

/// One sensor frame as the supervisor sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// Classified readings of the thermistors, in [`Sensor::index`] order.
    pub readings: [Reading; 3],
    /// Measured heater supply, V.
    pub supply_v: f32,
    /// When the frame was sampled, ms.
    pub sample_ms: u64,
}

/// The limits of a sensor.
pub const fn limits(s: Sensor) -> Limits {
    match s {
        Sensor::Pla => PLA_LIMITS,
        Sensor::Tca => TCA_LIMITS,
        Sensor::Amb => AMB_LIMITS,
    }
}

/// One heater's heater-not-heating watch (Klipper's `verify_heater` state).
#[derive(Clone, Copy, Debug, Default)]
struct HeatWatch {
    /// The window: when it started and its reference reading (`None`: not judged now).
    window: Option<(u64, f32)>,
    /// Since when the sensor has been below its band while judged, ms.
    below_since_ms: Option<u64>,
    /// The power of the last judged tick, W.
    last_w: f32,
    /// The activity the watch was armed in (a new phase or activity re-arms it).
    doing: Option<Doing>,
}

/// Every fault one frame can show at once: one per sensor, the supply, the two heater checks,
/// with room to spare.
pub type Faults = heapless::Vec<Fault, 8>;

/// One heater's must-not-rise watch (heating while off, or while turned down): since when its
/// condition has held, and its sensor's lowest rise above ambient since its grace ended.
/// `check_off` and `check_low` each keep one per heater.
#[derive(Clone, Copy, Debug, Default)]
struct RiseWatch {
    since_ms: Option<u64>,
    /// The lowest rise since the grace ended (and, in `check_low`, since the sensor must cool), K.
    min_k: Option<f32>,
}

impl RiseWatch {
    /// Feeds one tick in which the condition holds, with the sensor's rise `rise_k` (K) and
    /// whether it is judged now: returns the lowest rise since the grace `grace_s` ended, or
    /// `None` within the grace or while not judged (the lowest is then forgotten).
    fn update(&mut self, now_ms: u64, grace_s: f32, rise_k: f32, judged: bool) -> Option<f32> {
        let since = *self.since_ms.get_or_insert(now_ms);
        if (now_ms.saturating_sub(since) as f32) / 1000.0 < grace_s || !judged {
            self.min_k = None;
            return None;
        }
        let min_k = self.min_k.map_or(rise_k, |k| k.min(rise_k));
        self.min_k = Some(min_k);
        Some(min_k)
    }
}

/// One heater's heating-while-off watch (both heaters off).
#[derive(Clone, Copy, Debug, Default)]
struct OffWatch {
    rise: RiseWatch,
    /// The lowest rise since both heaters were cut, grace included, K (the in-grace rule,
    /// [`OFF_STORED_MAX_RISE_K`]).
    min_since_cut_k: Option<f32>,
    /// The condition holds now (RESET is refused while it does).
    heating: bool,
}

/// One heater's heating-while-off watch while only it is low.
#[derive(Clone, Copy, Debug, Default)]
struct LowWatch {
    rise: RiseWatch,
    /// A trip's lowest rise while its sensor still stands more than [`OFF_MAX_RISE_K`] above
    /// it: the condition RESET waits for (the watch itself restarts when the heaters go off).
    tripped_min_k: Option<f32>,
}

/// The TCA's held watch against the PLA sensor (see `Supervisor::check_held`): the recent peak
/// of its coupling-corrected rise with the response-lagged own model rise at that peak, K, the
/// response-lagged own model rise now, K, and the PLA rise it is corrected by.
#[derive(Clone, Copy, Debug, Default)]
struct HeldWatch {
    peak_k: Option<(f32, f32)>,
    response_k: Option<f32>,
    /// The PLA sensor's rise as credited to the TCA's bead, K.
    pla_k: Option<f32>,
}

/// The supervisor's state: consecutive-sample counters, last good temperatures and the
/// heater watches.
#[derive(Clone, Copy, Debug)]
pub struct Supervisor {
    range: [RangeCheck; 3],
    limit_count: [u8; 3],
    last_c: [f32; 3],
    live_c: [f32; 3],
    watch: [HeatWatch; 2],
    off: [OffWatch; 2],
    frozen: [FrozenWatch; 2],
    plaus: [Expectation; 2],
    hold: [HoldWatch; 2],
    low: [LowWatch; 2],
    held: HeldWatch,
    /// The crossed-wires watch ([`CROSS_MAX_LEAD_K`]): the PLA's lowest reading since the PLA
    /// heater was found on alone and the TCA's reading then, °C.
    cross: Option<(f32, f32)>,
    /// Each sensor's last reading and the sample time it was first read at, °C and ms (the
    /// still-reading watch, [`FROZEN_STILL_S`]).
    still: [Option<(f32, u64)>; 3],
    /// The ambient sensor's steady-ramp watch ([`AMB_RAMP_MAX_K_PER_S`]).
    ramp: RampWatch,
    amb_slow_c: Option<f32>,
    last_ms: Option<u64>,
    /// The share of its part's rise each heated bead is taken to read (PLA, TCA), 1
    /// ([`crate::part_limit::limit_shares`]).
    shares: [f32; 2],
    /// This tick's estimates of the PLA rod and the TCA, °C (NaN before a reading).
    parts_c: [f32; 2],
    /// Leaky counts of estimates over their part's limit (as `limit_count`).
    part_count: [u8; 2],
}

impl Default for Supervisor {
    fn default() -> Self {
        Self::new()
    }
}

impl Supervisor {
    /// A supervisor with no history (temperatures unknown until the first frame).
    pub fn new() -> Self {
        Supervisor {
            range: [RangeCheck::new(RangeCheck::DEFAULT_CONSECUTIVE); 3],
            limit_count: [0; 3],
            last_c: [f32::NAN; 3],
            live_c: [f32::NAN; 3],
            watch: [HeatWatch::default(); 2],
            off: [OffWatch::default(); 2],
            frozen: [FrozenWatch::default(); 2],
            plaus: [Expectation::default(); 2],
            hold: [HoldWatch::default(); 2],
            low: [LowWatch::default(); 2],
            held: HeldWatch::default(),
            cross: None,
            still: [None; 3],
            ramp: RampWatch::new(),
            amb_slow_c: None,
            last_ms: None,
            shares: UNTUNED_BEAD_SHARES,
            parts_c: [f32::NAN; 2],
            part_count: [0; 2],
        }
    }

    /// Sets the share of its part's rise each heated bead is taken to read (PLA, TCA), 1: the
    /// controller's [`crate::part_limit::limit_shares`] of its calibration.
    pub fn set_shares(&mut self, shares: [f32; 2]) {
        self.shares = shares;
    }

    /// This tick's estimates of the heated parts (PLA rod, TCA), °C: each bead's last good
    /// reading lifted by its share ([`crate::part_limit::estimate_c`]); NaN before a reading.
    pub fn parts_c(&self) -> [f32; 2] {
        self.parts_c
    }

    /// Over-temperature of a part: its estimate above its sensor's limit, counted as the
    /// readings are ([`LIMIT_CONSECUTIVE`]). The bead's own limit stays judged as well.
    fn check_parts(&mut self, found: &mut impl FnMut(Fault)) {
        let amb_c = self.last_c[Sensor::Amb.index()];
        for h in Heater::ALL {
            let i = h.index();
            let est = estimate_c(self.last_c[h.sensor().index()], amb_c, self.shares[i]);
            self.parts_c[i] = est;
            if est > limits(h.sensor()).max_c {
                self.part_count[i] = (self.part_count[i] + 1).min(LIMIT_CONSECUTIVE);
                if self.part_count[i] >= LIMIT_CONSECUTIVE {
                    found(Fault {
                        code: FaultCode::OverTemperature,
                        subject: Subject::Heater(h),
                        value: est,
                    });
                }
            } else {
                self.part_count[i] = self.part_count[i].saturating_sub(1);
            }
        }
    }

    /// Last good temperatures, °C (NaN before the first good reading).
    pub fn measurements(&self) -> Measurements {
        Measurements::from_array(self.last_c)
    }

    /// Checks one frame with the powers commanded in the previous tick by `doing` (the activity
    /// that commanded them, a morph's phase included: a new one re-arms the heater watches; a
    /// bare [`Phase`] stands for a morph in it). Returns the
    /// temperatures to control from, or the first fault found (see [`Supervisor::check_all`]).
    pub fn check(
        &mut self,
        now_ms: u64,
        frame: &Frame,
        commanded: Powers,
        doing: impl Into<Doing>,
    ) -> Result<Measurements, Fault> {
        let mut faults = Faults::new();
        let m = self.check_all(now_ms, frame, commanded, doing, &mut faults);
        match faults.first() {
            Some(f) => Err(*f),
            None => Ok(m),
        }
    }

    /// Runs every check on one frame, whatever runs (a latched fault included: the
    /// controller calls it every tick), and collects every fault present into `faults`, in
    /// check order. Returns the last good temperatures. Every sensor is read even when an
    /// earlier one is faulty, so [`Supervisor::live`] stays live.
    pub fn check_all(
        &mut self,
        now_ms: u64,
        frame: &Frame,
        commanded: Powers,
        doing: impl Into<Doing>,
        faults: &mut Faults,
    ) -> Measurements {
        let doing = doing.into();
        let mut found = |f: Fault| {
            let _ = faults.push(f);
        };
        if let Err(f) = fresh(now_ms, frame) {
            // An old frame says nothing about now: nothing else is judged from it.
            found(f);
            return self.measurements();
        }
        for sensor in Sensor::ALL {
            let i = sensor.index();
            let reading = frame.readings[i];
            self.live_c[i] = match reading {
                Reading::Ok(t) => t,
                _ => f32::NAN,
            };
            // Open/short: latched once the ADC range check has seen it often enough in a row.
            if let Some(r) = self.range[i].update(reading) {
                found(reading_fault(sensor, r).unwrap_or(Fault {
                    code: FaultCode::ThermistorOpen,
                    subject: Subject::Sensor(sensor),
                    value: f32::NAN,
                }));
                continue;
            }
            if let Reading::Ok(t) = reading {
                // A leaky count: +1 out of limits, −1 within (intermittent faults add up).
                match reading_fault(sensor, reading) {
                    Some(f) => {
                        self.limit_count[i] = (self.limit_count[i] + 1).min(LIMIT_CONSECUTIVE);
                        if self.limit_count[i] >= LIMIT_CONSECUTIVE {
                            found(f);
                        }
                    }
                    None => {
                        self.limit_count[i] = self.limit_count[i].saturating_sub(1);
                        self.last_c[i] = t;
                    }
                }
            }
        }
        self.check_parts(&mut found);
        if let Err(f) = supply_ok(frame) {
            found(f);
        }
        if let Err(f) = self.check_still(frame.sample_ms) {
            found(f);
        }
        let amb_c = self.live_c[Sensor::Amb.index()];
        if let Err(f) = self.ramp.update(frame.sample_ms, amb_c) {
            found(f);
        }
        let dt_s = self
            .last_ms
            .map_or(0.0, |ms| now_ms.saturating_sub(ms) as f32 / 1000.0);
        self.last_ms = Some(now_ms);
        // Once a tick, before every check that reads it.
        self.update_amb_slow(dt_s);
        if let Err(f) = self.check_heating(now_ms, commanded, doing) {
            found(f);
        }
        if let Err(f) = self.check_off(now_ms, commanded) {
            found(f);
        }
        if let Err(f) = self.check_frozen(now_ms, commanded, doing) {
            found(f);
        }
        if let Err(f) = self.check_plausible(dt_s, commanded) {
            found(f);
        }
        if let Err(f) = self.check_hold(dt_s, commanded) {
            found(f);
        }
        if let Err(f) = self.check_held(dt_s, commanded, doing) {
            found(f);
        }
        if let Err(f) = self.check_low(now_ms, commanded) {
            found(f);
        }
        if let Err(f) = self.check_cross(commanded) {
            found(f);
        }
        self.measurements()
    }

    /// This frame's temperatures as read, °C: NaN for a sensor that reads open or short (what
    /// STATUS shows; [`Supervisor::measurements`] keeps the last good ones for control).
    pub fn live(&self) -> Measurements {
        Measurements::from_array(self.live_c)
    }

    /// Sensor-frozen, still reading: a sensor whose reading repeats to the last bit for
    /// [`FROZEN_STILL_S`] of sample time trips, whatever the heaters do. A live reading carries
    /// the ADC's and the bead's noise (the oversampled sum's last counts change from one reading
    /// to the next); one that does not is a hung ADC channel or a frozen value. Only frames with a
    /// new sample time count, so a frame read twice is left to the stale-sensor check.
    fn check_still(&mut self, sample_ms: u64) -> Result<(), Fault> {
        for sensor in Sensor::ALL {
            let i = sensor.index();
            let temp_c = self.live_c[i];
            let w = &mut self.still[i];
            match *w {
                _ if !temp_c.is_finite() => *w = None,
                Some((c, since_ms)) if c.to_bits() == temp_c.to_bits() => {
                    if sample_ms.saturating_sub(since_ms) as f32 / 1000.0 >= FROZEN_STILL_S {
                        return Err(Fault {
                            code: FaultCode::SensorFrozen,
                            subject: Subject::Sensor(sensor),
                            // Moved by nothing (the alarm says "moved 0.0 K").
                            value: 0.0,
                        });
                    }
                }
                _ => *w = Some((temp_c, sample_ms)),
            }
        }
        Ok(())
    }

    /// Heater-not-heating, Klipper's `verify_heater` on this link's model. Each heater commanded
    /// at least [`HEATING_MIN_POWER_FRACTION`] of its cap is judged against the slope of the
    /// moment, in one window at a time:
    /// - below its band (less than [`HEATING_BAND_K`] above ambient plus the other heater's
    ///   share), its sensor must gain [`HEATING_MIN_GAIN_K`] within every [`HEATING_WINDOW_S`]
    ///   (each gain restarts the window), and must not stay below the band longer than
    ///   [`HEATING_BAND_TIMEOUT_S`] where its own share of the model's rise dominates;
    /// - in its band, its sensor must not fall [`HEATING_MAX_FALL_K`] below its highest reading;
    /// - above the model's equilibrium it may fall freely (the window follows it down).
    ///
    /// The watch starts again with every switch-on and every phase in which the heater's power
    /// drops; in a phase at no less power its window runs on.
    fn check_heating(&mut self, now_ms: u64, cmd: Powers, doing: Doing) -> Result<(), Fault> {
        let m = self.measurements();
        for heater in Heater::ALL {
            let own_w = cmd.of(heater);
            let other_w = cmd.of(heater.other());
            let temp_c = m.of(heater.sensor());
            let (r_self, cap_w) = (own_r_k_per_w(heater), heater_cap_w(heater));
            let w = &mut self.watch[heater.index()];
            // A new phase re-arms the watch, unless the heater stays on at no less power: its
            // window then runs on (closed's phases can each be shorter than one window).
            if w.doing != Some(doing) {
                let carries_on =
                    own_w >= w.last_w * (1.0 - HEATING_POWER_STEP_FRACTION) && w.last_w > 0.0;
                *w = if carries_on {
                    HeatWatch {
                        doing: Some(doing),
                        ..*w
                    }
                } else {
                    HeatWatch {
                        doing: Some(doing),
                        ..HeatWatch::default()
                    }
                };
            }
            if !(own_w >= HEATING_MIN_POWER_FRACTION * cap_w) || !temp_c.is_finite() {
                w.window = None;
                w.below_since_ms = None;
                w.last_w = 0.0;
                continue;
            }
            // The model's steady rise of this sensor: its own heater's and the other's share.
            let own_rise_k = r_self * own_w;
            // The other heater's share counts only as far as its own sensor shows its heat (a
            // dead other heater gives this sensor nothing).
            let other_rise_k = m.of(heater.other().sensor()) - m.t_amb_c;
            let r_other = own_r_k_per_w(heater.other());
            let shown_w = (other_rise_k / r_other).max(0.0);
            let cross_rise_k = R_TP_K_PER_W * other_w.min(shown_w);
            let in_band = temp_c - m.t_amb_c - cross_rise_k >= HEATING_BAND_K;
            let heater_fault = |value: f32| Fault {
                code: FaultCode::HeaterNotHeating,
                subject: Subject::Heater(heater),
                value,
            };
            // One window at a time: below the band the sensor must gain, in it it must not
            // fall far (a heater that dies hot cools at once; one that holds its plateau, or
            // relaxes to the hifi link's lower equilibrium after a power step, falls less).
            let (since_ms, start_c) = *w.window.get_or_insert((now_ms, temp_c));
            let elapsed_s = now_ms.saturating_sub(since_ms) as f32 / 1000.0;
            let gain_k = temp_c - start_c;
            let above_steady = temp_c - m.t_amb_c >= own_rise_k + cross_rise_k;
            // Below the band for too long: the other heater's heat can keep a dead heater's
            // sensor gaining, but never lift it into the band (its floor includes that heat).
            // A power step up moves the floor: the race to it starts again.
            // Judged only while the heater's own share of the model's rise clearly dominates:
            // where the other heater's is comparable, a healthy sensor on a link that couples less than
            // the model cannot reach the floor either.
            if in_band || above_steady || own_rise_k < HEATING_BAND_MIN_OWN_SHARE * cross_rise_k {
                w.below_since_ms = None;
            } else if w.below_since_ms.is_none()
                || own_w > w.last_w * (1.0 + HEATING_POWER_STEP_FRACTION)
            {
                w.below_since_ms = Some(now_ms);
            }
            w.last_w = own_w;
            if let Some(since) = w.below_since_ms {
                if now_ms.saturating_sub(since) as f32 / 1000.0 >= HEATING_BAND_TIMEOUT_S {
                    return Err(heater_fault(temp_c - m.t_amb_c - cross_rise_k));
                }
            }
            if above_steady {
                // Above the model's equilibrium the sensor falls to it (after the 4 W soften, or
                // a power drop): judge from here.
                w.window = Some((now_ms, temp_c));
            } else if in_band {
                // In band the window holds the highest reading: the sensor must not fall far
                // below it while the heater is on.
                if gain_k < -HEATING_MAX_FALL_K {
                    return Err(heater_fault(gain_k));
                }
                if gain_k > 0.0 {
                    w.window = Some((now_ms, temp_c));
                }
            } else if gain_k >= HEATING_MIN_GAIN_K {
                w.window = Some((now_ms, temp_c));
            } else if elapsed_s >= HEATING_WINDOW_S {
                return Err(heater_fault(gain_k));
            }
        }
        Ok(())
    }

    /// Heating-while-off: once both heaters have been commanded off for [`OFF_GRACE_S`], a
    /// heater's sensor that rises [`OFF_MAX_RISE_K`] above its lowest reading (above ambient)
    /// trips, and from the cut on one that rises [`OFF_STORED_MAX_RISE_K`] above it: the heater
    /// is on although nothing commands it (a stuck MOSFET). Not while it reads less than
    /// [`OFF_NEIGHBOUR_MARGIN_K`] above the other heated sensor, whose heat may be warming it.
    fn check_off(&mut self, now_ms: u64, cmd: Powers) -> Result<(), Fault> {
        let m = self.measurements();
        let both_off = !(cmd.pla_w > 0.0) && !(cmd.tca_w > 0.0);
        // A bath that cools moves the ambient bead at once and the heated ones over a minute:
        // the rise is measured from the warmer of the ambient reading and its lagged value
        // (`PLAUS_AMB_TAU_S`), so a colder bath is not heating.
        let amb_c = self
            .amb_slow_c
            .map_or(m.t_amb_c, |slow| m.t_amb_c.max(slow));
        for heater in Heater::ALL {
            let w = &mut self.off[heater.index()];
            let rise_k = m.of(heater.sensor()) - amb_c;
            if !both_off || !rise_k.is_finite() {
                *w = OffWatch::default();
                continue;
            }
            let after_grace_k = w.rise.update(now_ms, OFF_GRACE_S, rise_k, true);
            let min_since_cut_k = w.min_since_cut_k.map_or(rise_k, |k| k.min(rise_k));
            w.min_since_cut_k = Some(min_since_cut_k);
            // Measured from the lowest reading, or from ambient if it was below it (a link
            // warming up to a warmer bath is not heating).
            let above = |min_k: f32| rise_k - min_k.max(0.0);
            let since_off_k = above(min_since_cut_k);
            let after_k = after_grace_k.map_or(0.0, above);
            let warmed = warmed_by_other(&self.range, &m, heater, since_off_k);
            let w = &mut self.off[heater.index()];
            w.heating =
                !warmed && (after_k > OFF_MAX_RISE_K || since_off_k > OFF_STORED_MAX_RISE_K);
            if w.heating {
                return Err(Fault {
                    code: FaultCode::HeatingWhileOff,
                    subject: Subject::Heater(heater),
                    value: after_k.max(since_off_k),
                });
            }
        }
        Ok(())
    }

    /// Whether a latched fault's condition has cleared on this frame (RESET is allowed), or
    /// the fault that is still present. Sensor checks need a good reading now, not four.
    pub fn condition_clear(&self, now_ms: u64, frame: &Frame) -> Result<(), Fault> {
        fresh(now_ms, frame)?;
        for sensor in Sensor::ALL {
            if let Some(f) = reading_fault(sensor, frame.readings[sensor.index()]) {
                return Err(f);
            }
        }
        for heater in Heater::ALL {
            let est = self.parts_c[heater.index()];
            if est > limits(heater.sensor()).max_c {
                return Err(Fault {
                    code: FaultCode::OverTemperature,
                    subject: Subject::Heater(heater),
                    value: est,
                });
            }
            if self.off[heater.index()].heating || self.low[heater.index()].tripped_min_k.is_some()
            {
                return Err(Fault {
                    code: FaultCode::HeatingWhileOff,
                    subject: Subject::Heater(heater),
                    value: f32::NAN,
                });
            }
        }
        if self.ramp.ramping {
            return Err(ramp_fault(f32::NAN));
        }
        supply_ok(frame)
    }

    /// Forgets counters and heater watches (after RESET), keeping last temperatures (the
    /// heating-while-off watch and the ambient ramp watch too: RESET is only allowed once they
    /// no longer see a rise or a ramp).
    pub fn rearm(&mut self) {
        self.range = [RangeCheck::new(RangeCheck::DEFAULT_CONSECUTIVE); 3];
        self.limit_count = [0; 3];
        self.part_count = [0; 2];
        self.watch = [HeatWatch::default(); 2];
        self.off = [OffWatch::default(); 2];
        self.frozen = [FrozenWatch::default(); 2];
        self.plaus = [Expectation::default(); 2];
        self.hold = [HoldWatch::default(); 2];
        self.low = [LowWatch::default(); 2];
        self.held = HeldWatch::default();
        self.cross = None;
        self.still = [None; 3];
        self.amb_slow_c = None;
        self.last_ms = None;
    }

    /// Heater-not-heating while held: a judged heater (at least [`HEATING_MIN_POWER_FRACTION`]
    /// of its cap) whose sensor falls more than [`HOLD_MAX_FALL_K`] below its recent peak,
    /// beyond what the recent power drops explain (the model's steady rise of each drop, the
    /// other heater's through `R_TP_K_PER_W`), trips. Peak and powers are recent maxima that
    /// relax toward the present ([`HOLD_PEAK_TAU_S`], [`HOLD_POWER_TAU_S`]). A heater that dies
    /// while held (bend, lock) loses its sensor's rise within seconds, long before a phase ends
    /// and `done` reports a radius from it.
    fn check_hold(&mut self, dt_s: f32, cmd: Powers) -> Result<(), Fault> {
        let k_peak = lag_share(dt_s, HOLD_PEAK_TAU_S);
        let k_power = lag_share(dt_s, HOLD_POWER_TAU_S);
        let k_cross = lag_share(dt_s, HOLD_CROSS_TAU_S);
        for heater in Heater::ALL {
            let temp_c = self.live_c[heater.sensor().index()];
            let own_w = cmd.of(heater);
            let (r_own, other_w) = (own_r_k_per_w(heater), cmd.of(heater.other()));
            let w = &mut self.hold[heater.index()];
            let relax = |x: &mut f32, now: f32, k: f32| *x = now.max(toward(*x, now, k));
            // The recent powers are followed whether judged or not: a heater switched on in a
            // link still hot from earlier power sees its sensor fall at first.
            let (own_ref_w, other_ref_w) = w.recent_w.get_or_insert((own_w, other_w));
            relax(own_ref_w, own_w, k_power);
            relax(other_ref_w, other_w, k_power);
            // The other heater's heat reaches this sensor through the link's slow path: its
            // drop is felt as its lagged power falls, not at once.
            let other_lag_w = w.other_lag_w.get_or_insert(other_w);
            *other_lag_w = toward(*other_lag_w, other_w, k_cross);
            let explained_k = r_own * (*own_ref_w - own_w)
                + R_TP_K_PER_W * (*other_ref_w - other_lag_w.min(*other_ref_w));
            if !(own_w >= HEATING_MIN_POWER_FRACTION * heater_cap_w(heater)) || !temp_c.is_finite()
            {
                w.peak_c = None;
                continue;
            }
            let peak_c = w.peak_c.get_or_insert(temp_c);
            relax(peak_c, temp_c, k_peak);
            let fall_k = *peak_c - temp_c - explained_k;
            if fall_k > HOLD_MAX_FALL_K {
                return Err(Fault {
                    code: FaultCode::HeaterNotHeating,
                    subject: Subject::Heater(heater),
                    value: -fall_k,
                });
            }
        }
        Ok(())
    }

    /// Heater-not-heating while held, against the other sensor (the TCA; see
    /// [`HELD_MAX_FALL_K`]): while the TCA is judged (in bend or lock, at least
    /// [`HEATING_MIN_POWER_FRACTION`] of its cap) and its sensor reads below the model's steady rise for its own power (lagged
    /// by [`HELD_RESPONSE_TAU_S`]), so a live heater must keep it up, its rise less the PLA's
    /// model share ([`held_share`]) must not fall more than [`HELD_MAX_FALL_K`] below its recent
    /// peak (relaxing with [`HOLD_PEAK_TAU_S`]) beyond the fall of the lagged own model rise
    /// since that peak. A dead TCA's bead sinks toward what the cooling PLA rod gives it; a live
    /// one at the power the controller holds stays up, whatever the PLA does.
    fn check_held(&mut self, dt_s: f32, cmd: Powers, doing: Doing) -> Result<(), Fault> {
        let heater = Heater::Tca;
        let own_w = cmd.of(heater);
        // A bath that warms moves the ambient bead before the heated ones (`check_plausible`).
        let amb_spread_k = self.amb_spread_k();
        let w = &mut self.held;
        let model_k = R_TT_K_PER_W * own_w;
        let response_k = w.response_k.get_or_insert(model_k);
        *response_k = lag(*response_k, model_k, dt_s, HELD_RESPONSE_TAU_S);
        let response_k = *response_k;
        let [pla_c, tca_c, amb_c] = self.live_c;
        // The PLA's heat reaches the TCA's bead through the silicone, late: its rise and its
        // fall are credited as they arrive (`HOLD_CROSS_TAU_S`).
        let pla_rise_k = pla_c - amb_c;
        let pla_k = match w.pla_k {
            Some(k) if pla_rise_k.is_finite() => lag(k, pla_rise_k, dt_s, HOLD_CROSS_TAU_S),
            _ => pla_rise_k,
        };
        w.pla_k = pla_k.is_finite().then_some(pla_k);
        let q_k = (tca_c - amb_c) - held_share() * pla_k;
        // Judged in the phases whose hold `done` reports from; a HEAT pulse or TUNE step (in
        // idle) is left to the other checks, so bring-up can still name swapped wires.
        let held = matches!(doing, Doing::Morph(Phase::Bend | Phase::Lock));
        let judged = held && own_w >= HEATING_MIN_POWER_FRACTION * heater_cap_w(heater);
        if !judged || !q_k.is_finite() || q_k >= response_k {
            w.peak_k = None;
            return Ok(());
        }
        let k = lag_share(dt_s, HOLD_PEAK_TAU_S);
        let (peak_k, at_peak_k) = w.peak_k.get_or_insert((q_k, response_k));
        let relaxed_k = toward(*peak_k, q_k, k);
        if q_k >= relaxed_k {
            (*peak_k, *at_peak_k) = (q_k, response_k);
        } else {
            *peak_k = relaxed_k;
            *at_peak_k = toward(*at_peak_k, response_k, k);
        }
        let fall_k = *peak_k - q_k - (*at_peak_k - response_k).max(0.0) - amb_spread_k;
        if fall_k > HELD_MAX_FALL_K {
            return Err(Fault {
                code: FaultCode::HeaterNotHeating,
                subject: Subject::Heater(heater),
                value: -fall_k,
            });
        }
        Ok(())
    }

    /// Sensor-implausible, crossed: while the PLA heater is commanded at least
    /// [`CROSS_MIN_POWER_FRACTION`] of its cap and the TCA below [`HEATING_MIN_POWER_FRACTION`]
    /// of its own, the TCA's sensor must not gain more than [`CROSS_MAX_LEAD_K`] over the PLA's
    /// since that began (the PLA's gain counted from its lowest reading since: a lagging bead may
    /// still fall for a moment when heating resumes): heat reaches the PLA's own bead first. A
    /// TCA held alone is left out: in still air a lock that stalls holds it for minutes, and the
    /// cooled rod's bead, warmed by it, may overtake its held one (docs/safety.md, "Wiring faults:
    /// swapped thermistors, a bead off its heater").
    fn check_cross(&mut self, cmd: Powers) -> Result<(), Fault> {
        // A PLA held at its ceiling (`part_limit::under_ceiling_w`) is kept from rising: its
        // own bead cannot lead then, whatever the wiring.
        let held = self.parts_c[Heater::Pla.index()]
            >= PLA_LIMITS.max_c - CEILING_MARGIN_K - CEILING_BAND_K;
        let judged = cmd.pla_w >= CROSS_MIN_POWER_FRACTION * heater_cap_w(Heater::Pla)
            && !(cmd.tca_w >= HEATING_MIN_POWER_FRACTION * heater_cap_w(Heater::Tca))
            && !held;
        let [pla_c, tca_c, _] = self.live_c;
        if !judged || !pla_c.is_finite() || !tca_c.is_finite() {
            self.cross = None;
            return Ok(());
        }
        let (pla_min_c, tca_start_c) = self.cross.get_or_insert((pla_c, tca_c));
        *pla_min_c = pla_min_c.min(pla_c);
        let lead_k = (tca_c - *tca_start_c) - (pla_c - *pla_min_c);
        if lead_k > CROSS_MAX_LEAD_K {
            return Err(Fault {
                code: FaultCode::SensorImplausible,
                subject: Subject::Heater(Heater::Pla),
                value: lead_k,
            });
        }
        Ok(())
    }

    /// Heating-while-off with one heater low: once a heater has been commanded below
    /// [`HEATING_MIN_POWER_FRACTION`] of its cap for [`LOW_GRACE_S`] while the other heater is
    /// on (with both off [`Supervisor::check_off`] watches), while its sensor must cool ([`must_cool`]), a rise of [`OFF_MAX_RISE_K`] above its
    /// lowest reading since (relative to ambient) trips: the heater is on although the
    /// controller turns it down (a stuck MOSFET during a morph).
    fn check_low(&mut self, now_ms: u64, cmd: Powers) -> Result<(), Fault> {
        let amb_c = self.live_c[Sensor::Amb.index()];
        let m = self.measurements();
        for heater in Heater::ALL {
            let rise_k = self.live_c[heater.sensor().index()] - amb_c;
            let w = &mut self.low[heater.index()];
            let other_on = cmd.of(heater.other()) > 0.0;
            let low = !(cmd.of(heater) >= HEATING_MIN_POWER_FRACTION * heater_cap_w(heater));
            // A trip holds RESET off while the sensor stays risen above the trip's lowest
            // reading, whatever the heaters are commanded now (a stuck MOSFET heats on).
            w.tripped_min_k = w
                .tripped_min_k
                .filter(|&m| rise_k.is_finite() && rise_k - m > OFF_MAX_RISE_K);
            // With both off, `check_off` watches it (with its longer grace). With the other
            // heater off too (its keep-alive aside) the link is cooling from stored heat, which
            // warms a low heater's sensor in still air: judged only while the other is on
            // (docs/safety.md, "Safety defaults", heating while turned down).
            if !low || !other_on || !rise_k.is_finite() {
                *w = LowWatch {
                    tripped_min_k: w.tripped_min_k,
                    ..LowWatch::default()
                };
                continue;
            }
            let Some(min_k) =
                w.rise
                    .update(now_ms, LOW_GRACE_S, rise_k, must_cool(heater, cmd, rise_k))
            else {
                continue;
            };
            // The other heater, on, may be what warms it (a hot TCA holding a tight radius
            // warms the cooling PLA in still air), as with both off.
            if rise_k - min_k > OFF_MAX_RISE_K
                && !warmed_by_other(&self.range, &m, heater, rise_k - min_k)
            {
                let w = &mut self.low[heater.index()];
                w.tripped_min_k = Some(min_k);
                return Err(Fault {
                    code: FaultCode::HeatingWhileOff,
                    subject: Subject::Heater(heater),
                    value: rise_k - min_k,
                });
            }
        }
        Ok(())
    }

    /// Sensor-frozen: once a heater's commanded power has moved [`FROZEN_POWER_STEP_FRACTION`]
    /// of its cap away from where its sensor last moved, or (the PLA) while its heater is low
    /// and its sensor reads more than [`MUST_COOL_MARGIN_K`] above the TCA's (plus the
    /// still-air reach of its own low power; the rod must then cool, as it does in lock), the
    /// sensor must move [`FROZEN_MIN_MOVE_K`] (either way) within [`FROZEN_WINDOW_S`].
    fn check_frozen(&mut self, now_ms: u64, cmd: Powers, doing: Doing) -> Result<(), Fault> {
        let [_, tca_c, amb_c] = self.live_c;
        for heater in Heater::ALL {
            let temp_c = self.live_c[heater.sensor().index()];
            let w = &mut self.frozen[heater.index()];
            if !temp_c.is_finite() {
                *w = FrozenWatch::default();
                continue;
            }
            let own_w = cmd.of(heater);
            let (ref_w, ref_c) = *w.reference.get_or_insert((own_w, temp_c));
            if (temp_c - ref_c).abs() >= FROZEN_MIN_MOVE_K {
                *w = FrozenWatch {
                    reference: Some((own_w, temp_c)),
                    since_ms: None,
                };
                continue;
            }
            let step_w = FROZEN_POWER_STEP_FRACTION * heater_cap_w(heater);
            // The PLA in lock: with its heater low the rod is warmed only by the TCA beside it,
            // so it cannot stay above the TCA's reading (plus its own power's still-air reach).
            let low = !(own_w >= HEATING_MIN_POWER_FRACTION * heater_cap_w(heater));
            let held_up_k = (tca_c - amb_c).max(0.0) + PLAUS_HIGH_GAIN * R_PP_K_PER_W * own_w;
            // Judged in lock only (the phase that waits for the PLA to fall): at rest a rod
            // near ambient in still air may cool slower than the window can see.
            let cooling = heater == Heater::Pla
                && doing == Doing::Morph(Phase::Lock)
                && low
                && tca_c.is_finite()
                && temp_c - amb_c > held_up_k + MUST_COOL_MARGIN_K;
            if w.since_ms.is_none() && ((own_w - ref_w).abs() >= step_w || cooling) {
                w.since_ms = Some(now_ms);
            }
            if let Some(since) = w.since_ms {
                if now_ms.saturating_sub(since) as f32 / 1000.0 >= FROZEN_WINDOW_S {
                    return Err(Fault {
                        code: FaultCode::SensorFrozen,
                        subject: Subject::Sensor(heater.sensor()),
                        value: temp_c - ref_c,
                    });
                }
            }
        }
        Ok(())
    }

    /// Moves the ambient reading's lagged value ([`PLAUS_AMB_TAU_S`]) on by `dt_s`: the heated
    /// beads follow a change of the bath that much later, so the checks that measure a rise
    /// from the ambient reading take the lag into account (forgotten while the reading is bad).
    fn update_amb_slow(&mut self, dt_s: f32) {
        let amb_c = self.live_c[Sensor::Amb.index()];
        let slow_c = match self.amb_slow_c {
            Some(slow) if amb_c.is_finite() => lag(slow, amb_c, dt_s, PLAUS_AMB_TAU_S),
            _ => amb_c,
        };
        self.amb_slow_c = slow_c.is_finite().then_some(slow_c);
    }

    /// How far the ambient reading stands from its lagged value, K (0 before the first good
    /// reading): where a bath has just changed, how much either may be the one to measure from.
    fn amb_spread_k(&self) -> f32 {
        let amb_c = self.live_c[Sensor::Amb.index()];
        self.amb_slow_c.map_or(0.0, |slow| (amb_c - slow).abs())
    }

    /// Sensor-implausible: each heated sensor's rise above the ambient sensor must stay within
    /// the supervisor's envelope of the model's steady rise for the commanded powers (see
    /// [`Expectation`]) widened by [`PLAUS_MARGIN_K`]; outside it for [`PLAUS_TIME_S`] (a leaky
    /// count of seconds) trips.
    fn check_plausible(&mut self, dt_s: f32, cmd: Powers) -> Result<(), Fault> {
        let amb_c = self.live_c[Sensor::Amb.index()];
        // A bath that warms or cools moves the ambient bead at once and the heated ones only
        // as their own lag allows: between the ambient reading and its lagged value either
        // may be the one to measure from, so the envelope is widened by their difference.
        let amb_spread_k = self.amb_spread_k();
        for heater in Heater::ALL {
            let temp_c = self.live_c[heater.sensor().index()];
            let e = &mut self.plaus[heater.index()];
            let rise_k = temp_c - amb_c;
            if !rise_k.is_finite() {
                *e = Expectation::default();
                continue;
            }
            let (r_own, other_w) = (own_r_k_per_w(heater), cmd.of(heater.other()));
            let own_k = r_own * cmd.of(heater);
            let steady_k = own_k + R_TP_K_PER_W * other_w;
            // Heat flows from hot to cold: the hotter part of the link may warm this sensor up
            // to what the other heated sensor reads, whatever the heaters do (a rod still hot
            // after a trip or a morph, its heater off).
            let neighbour_k = (self.live_c[heater.other().sensor().index()] - amb_c).max(0.0);
            let Some(mut off_k) = e.update(dt_s, own_k, steady_k, neighbour_k, rise_k) else {
                continue;
            };
            off_k = if off_k > 0.0 {
                (off_k - amb_spread_k).max(0.0)
            } else {
                (off_k + amb_spread_k).min(0.0)
            };
            if off_k != 0.0 {
                e.outside_s = (e.outside_s + dt_s).min(PLAUS_TIME_S);
            } else {
                e.outside_s = (e.outside_s - dt_s).max(0.0);
            }
            if e.outside_s >= PLAUS_TIME_S {
                return Err(Fault {
                    code: FaultCode::SensorImplausible,
                    subject: Subject::Sensor(heater.sensor()),
                    value: off_k,
                });
            }
        }
        Ok(())
    }
}

/// Whether `heater`'s sensor, risen `since_k` (K) since its watch began, may be warmed by the
/// other heater's part of the link: heat flows from hot to cold, so a sensor reading less than
/// [`OFF_NEIGHBOUR_MARGIN_K`] above the other heated sensor is not judged, up to
/// [`OFF_NEIGHBOUR_MAX_RISE_K`]. Judged on the last good readings `m`, so one glitch changes
/// nothing; a sensor whose range check stands tripped has failed and explains nothing.
fn warmed_by_other(
    range: &[RangeCheck; 3],
    m: &Measurements,
    heater: Heater,
    since_k: f32,
) -> bool {
    let other = heater.other().sensor();
    let other_c = if range[other.index()].tripped() {
        f32::NAN
    } else {
        m.of(other)
    };
    m.of(heater.sensor()) < other_c + OFF_NEIGHBOUR_MARGIN_K && since_k <= OFF_NEIGHBOUR_MAX_RISE_K
}

/// Whether `heater`'s sensor, reading `rise_k` above ambient, must cool with its own heater low:
/// it reads more than [`MUST_COOL_MARGIN_K`] above [`PLAUS_HIGH_GAIN`] times the model's steady
/// rise for the commanded powers (its own low power's and the other heater's share,
/// `R_TP_K_PER_W` times that power): the still-air reach of that heat, so it cannot be rising
/// in any medium.
fn must_cool(heater: Heater, cmd: Powers, rise_k: f32) -> bool {
    let (r_own, other_w) = (own_r_k_per_w(heater), cmd.of(heater.other()));
    let steady_k = r_own * cmd.of(heater).max(0.0) + R_TP_K_PER_W * other_w.max(0.0);
    rise_k > PLAUS_HIGH_GAIN * steady_k + MUST_COOL_MARGIN_K
}

/// The share of the PLA sensor's rise the model's TCA node sees from the PLA heater
/// (`R_TP_K_PER_W / R_PP_K_PER_W`, about 0.26): what a dead TCA's bead keeps of the PLA rod's
/// heat in [`Supervisor::check_held`].
fn held_share() -> f32 {
    R_TP_K_PER_W / R_PP_K_PER_W
}

/// The model's steady rise of `heater`'s own sensor per watt of its own heater, K/W
/// (`R_PP_K_PER_W`, `R_TT_K_PER_W`).
fn own_r_k_per_w(heater: Heater) -> f32 {
    match heater {
        Heater::Pla => R_PP_K_PER_W,
        Heater::Tca => R_TT_K_PER_W,
    }
}

/// The power cap of `heater`, W.
fn heater_cap_w(heater: Heater) -> f32 {
    match heater {
        Heater::Pla => HeaterConfig::PLA.max_power_w,
        Heater::Tca => HeaterConfig::TCA.max_power_w,
    }
}

/// Sensor-frozen: the share of a heater's power cap its commanded power must move (either way)
/// away from where its sensor last moved before the sensor is watched: the PLA from 1.0 W, the
/// TCA from 0.4 W. Such a step moves a healthy sensor by several kelvin within seconds (the
/// model's steady rise is 30 K and 14 K); smaller steps in a closed loop's hold may not.
pub const FROZEN_POWER_STEP_FRACTION: f32 = 0.2;
/// Sensor-frozen: how far a watched sensor must move, K (either way). A frozen reading moves by
/// nothing; a live one by its noise alone (0.05 K rms, so 0.1 K within a window is all but
/// certain) plus what the power step does to it, which in still air (time constants five
/// times water's) can be little within the window.
pub const FROZEN_MIN_MOVE_K: f32 = 0.1;
/// Sensor-frozen: the time a watched sensor has to move [`FROZEN_MIN_MOVE_K`], s. The slowest
/// healthy sensor (the hifi PLA bead, 10 s behind its rod) moves that far within about 3 s of a
/// 1 W step; 8 s leaves margin and keeps a frozen sensor under the 10 s aim.
pub const FROZEN_WINDOW_S: f32 = 8.0;
/// Sensor-frozen, still reading: how long a reading may repeat to the last bit, s of sample
/// time (any sensor, any phase). The quietest bead's noise spans several counts of the summed
/// reading, so 50 identical readings never come from a live sensor (docs/safety.md, "What the
/// table says"). A hung channel repeats at once; 5 s (50 readings) finds it within the 10 s aim
/// wherever it comes, a TCA frozen in a closed-loop hold (whose power and reading barely move)
/// included.
pub const FROZEN_STILL_S: f32 = 5.0;
const _: () = assert!(FROZEN_STILL_S >= 1.0 && FROZEN_STILL_S < FROZEN_WINDOW_S);

/// Sensor-implausible, the envelope's floor: this share of the model's steady rise (own heater
/// plus the other's share, `R_PP_K_PER_W`/`R_TT_K_PER_W` and `R_TP_K_PER_W` times the commanded
/// powers), reached no faster than [`PLAUS_TAU_SLOW_S`] and then [`PLAUS_LAG_S`] behind. A
/// bead beside its heater reads a fraction of the heater's mean rise: set under what the healthy
/// ensembles read in water and air (docs/safety.md, "No false alarm on a healthy link"), while a
/// dead heater's sensor stays near ambient.
pub const PLAUS_LOW_GAIN: f32 = 0.3;
/// Sensor-implausible, the envelope's ceiling: this many times the model's steady rise, reached
/// with [`PLAUS_TAU_FAST_S`] and left no faster than [`PLAUS_CEILING_FALL_S`] (a hot link
/// cools slowly). The model's resistances are water's; in still air a healthy link rises
/// several times as far (docs/safety.md, "No false alarm on a healthy link"), so 4.
pub const PLAUS_HIGH_GAIN: f32 = 4.0;
/// Sensor-implausible: the envelope's fast time constant, s (the TCA's fast thermal part is
/// about 1 s; the ceiling rises this fast, the floor falls this fast).
pub const PLAUS_TAU_FAST_S: f32 = 1.0;
/// Sensor-implausible: the envelope's slow time constant, s: the floor rises and the ceiling
/// falls no faster than this (slower than any healthy heating or cooling of this link).
pub const PLAUS_TAU_SLOW_S: f32 = 30.0;
/// Sensor-implausible: how slowly the ceiling falls after a power drop, s: in still air the
/// link cools five times slower than in water (h = 20 against 101 W/(m² K)), and a bead that
/// cools slower than the ceiling falls would read implausibly hot.
pub const PLAUS_CEILING_FALL_S: f32 = 200.0;
/// Sensor-implausible: the floor's extra lag, s (the hifi PLA bead lags its rod by about 10 s).
pub const PLAUS_LAG_S: f32 = 5.0;
/// Sensor-implausible: the lag of the heated beads behind a change of the bath, s: the
/// envelope is widened by the ambient reading's distance from its value lagged by this much
/// (a bath warmed from 22 to 46 °C moves the ambient bead within seconds, the PLA rod's bead
/// over a minute).
pub const PLAUS_AMB_TAU_S: f32 = 60.0;
/// Sensor-implausible: the envelope is widened by this much either side, K. A link at rest
/// reads within a kelvin or two of its bath; a sensor reading 3 K colder than the bath it is
/// in, or 3 K hotter than any heat it is given can explain, is wrong.
pub const PLAUS_MARGIN_K: f32 = 3.0;
/// Sensor-implausible: seconds outside the envelope before a trip, counted leaky (+dt outside,
/// −dt inside), so one noisy excursion never trips. 2.5 s (25 readings) brings a PLA heater
/// open in soften on the nominal hifi link under the 10 s aim with no alarm on either healthy
/// ensemble (docs/safety.md, "What the table says").
pub const PLAUS_TIME_S: f32 = 2.5;
const _: () = assert!(PLAUS_LOW_GAIN > 0.0 && PLAUS_LOW_GAIN < 1.0 && PLAUS_HIGH_GAIN > 1.0);
const _: () = assert!(PLAUS_TAU_FAST_S > 0.0 && PLAUS_TAU_SLOW_S > PLAUS_TAU_FAST_S);
const _: () = assert!(PLAUS_AMB_TAU_S > 0.0 && PLAUS_CEILING_FALL_S >= PLAUS_TAU_SLOW_S);
const _: () = assert!(PLAUS_MARGIN_K > 0.0 && PLAUS_TIME_S > 0.0 && PLAUS_LAG_S >= 0.0);
const _: () = assert!(FROZEN_MIN_MOVE_K > 0.0 && FROZEN_WINDOW_S < 10.0);
const _: () = assert!(FROZEN_POWER_STEP_FRACTION > 0.0 && FROZEN_POWER_STEP_FRACTION < 1.0);

/// Sensor-implausible, ambient: the fastest steady change of the surroundings, K/s (6 K/min).
/// A water bath or a room changes by a fraction of a kelvin a minute; a bath poured or the link
/// moved is a step, which the ambient bead follows within seconds (its time constant is 2–3 s)
/// and then holds. A reading that keeps moving faster than this, steadily, for
/// [`AMB_RAMP_SEGMENTS`] × [`AMB_RAMP_SEGMENT_S`] is a drifting sensor (a cracked bead, a
/// failing joint): every heated sensor's rise is measured from it, so the plausibility envelope
/// cannot see it.
pub const AMB_RAMP_MAX_K_PER_S: f32 = 0.1;
/// Sensor-implausible, ambient: the length of one segment of the ramp watch, s of sample time;
/// the watch compares the ambient reading's mean over consecutive segments (a mean of about
/// 30 readings, so the ADC's noise is far below a segment's change at the threshold, 0.3 K).
pub const AMB_RAMP_SEGMENT_S: f32 = 3.0;
/// Sensor-implausible, ambient: how many consecutive segment-to-segment changes must all exceed
/// [`AMB_RAMP_MAX_K_PER_S`], with one sign: 4 (12 s) finds a 0.2 K/s drift inside the 20 s aim
/// (`cargo xtask faults`; docs/safety.md, "What the table says").
pub const AMB_RAMP_SEGMENTS: usize = 4;
/// Sensor-implausible, ambient: the evenness a ramp needs: its smallest segment change at least
/// this share of its largest (the first change after a step, or after a drift starts, covers
/// part of a segment and is small).
pub const AMB_RAMP_STEADY_SHARE: f32 = 0.5;
/// Sensor-implausible, ambient: a ramp must not be settling: its last segment change at least
/// this share of its largest. A bath changed at once reaches the bead as a settling exponential,
/// whose changes shrink by e^(−3 s / tau) a segment, so its last change is its smallest: at
/// most 0.74 of its largest for beads up to 10 s and 0.89 up to 25 s (the 2.25 s bead in water:
/// 0.26), wherever the step falls in a segment; a drift's changes stay alike.
pub const AMB_RAMP_SETTLING_SHARE: f32 = 0.9;
const _: () = assert!(AMB_RAMP_MAX_K_PER_S > 0.0 && AMB_RAMP_SEGMENT_S >= 1.0);
const _: () = assert!(AMB_RAMP_SEGMENTS >= 2 && AMB_RAMP_SEGMENTS <= 8);
const _: () = assert!(AMB_RAMP_STEADY_SHARE > 0.0 && AMB_RAMP_STEADY_SHARE < 1.0);
const _: () = assert!(AMB_RAMP_SETTLING_SHARE > 0.0 && AMB_RAMP_SETTLING_SHARE < 1.0);
const _: () = assert!((AMB_RAMP_SEGMENTS as f32) * AMB_RAMP_SEGMENT_S + AMB_RAMP_SEGMENT_S <= 20.0);

/// The ambient sensor's steady-ramp watch: the mean reading of the segment in progress and of
/// the last [`AMB_RAMP_SEGMENTS`] + 1 whole segments.
#[derive(Clone, Copy, Debug)]
struct RampWatch {
    /// When the segment in progress started (sample time, ms), its sum of readings (°C) and
    /// their count.
    segment: Option<(u64, f32, u16)>,
    /// The last whole segments' means, oldest first, °C; `count` of them are filled.
    means_c: [f32; AMB_RAMP_SEGMENTS + 1],
    count: usize,
    /// The last judgement found a steady ramp (RESET waits until one does not).
    ramping: bool,
}

impl RampWatch {
    const fn new() -> Self {
        RampWatch {
            segment: None,
            means_c: [0.0; AMB_RAMP_SEGMENTS + 1],
            count: 0,
            ramping: false,
        }
    }

    /// Adds one reading (`temp_c` at `sample_ms`) and judges the segments once one ends: a
    /// steady ramp faster than [`AMB_RAMP_MAX_K_PER_S`] trips `sensor-implausible amb` with
    /// its rate, K/s. A reading that is not a temperature (an open or shorted sample, which the
    /// range check judges) is skipped, so an intermittent contact cannot hide a drift; a gap
    /// longer than a segment starts the watch over (means across it are not comparable).
    fn update(&mut self, sample_ms: u64, temp_c: f32) -> Result<(), Fault> {
        if !temp_c.is_finite() {
            return Ok(());
        }
        const SEGMENT_MS: u64 = (AMB_RAMP_SEGMENT_S * 1000.0) as u64;
        if let Some((start_ms, _, _)) = self.segment {
            if sample_ms.saturating_sub(start_ms) >= 2 * SEGMENT_MS {
                *self = RampWatch::new();
            }
        }
        let (start_ms, sum_c, n) = self.segment.get_or_insert((sample_ms, 0.0, 0));
        if sample_ms.saturating_sub(*start_ms) < SEGMENT_MS {
            *sum_c += temp_c;
            *n = n.saturating_add(1);
            return Ok(());
        }
        let mean_c = *sum_c / f32::from((*n).max(1));
        self.segment = Some((sample_ms, temp_c, 1));
        if self.count == self.means_c.len() {
            // The oldest out: a copy, not `copy_within`, whose `memmove` is 1.5 KiB of flash.
            let m = self.means_c;
            self.means_c = core::array::from_fn(|i| m[(i + 1).min(m.len() - 1)]);
            self.count -= 1;
        }
        self.means_c[self.count] = mean_c;
        self.count += 1;
        if self.count < self.means_c.len() {
            return Ok(());
        }
        self.ramping = steady_ramp(&self.means_c);
        if self.ramping {
            let span_s = AMB_RAMP_SEGMENTS as f32 * AMB_RAMP_SEGMENT_S;
            return Err(ramp_fault(
                (self.means_c[AMB_RAMP_SEGMENTS] - self.means_c[0]) / span_s,
            ));
        }
        Ok(())
    }
}

/// The ambient ramp's trip: `sensor-implausible amb` at `rate_k_per_s`.
fn ramp_fault(rate_k_per_s: f32) -> Fault {
    Fault {
        code: FaultCode::SensorImplausible,
        subject: Subject::Sensor(Sensor::Amb),
        value: rate_k_per_s,
    }
}

/// Whether consecutive segment means (°C, oldest first) ramp steadily: every change of one sign
/// and at least [`AMB_RAMP_MAX_K_PER_S`] × [`AMB_RAMP_SEGMENT_S`], the smallest at least
/// [`AMB_RAMP_STEADY_SHARE`] of the largest and the last at least [`AMB_RAMP_SETTLING_SHARE`]
/// of the largest (a settling step's last change is its smallest).
fn steady_ramp(means_c: &[f32]) -> bool {
    let mut lo_k = f32::INFINITY;
    let mut hi_k = 0.0f32;
    let mut sign = 0.0f32;
    for pair in means_c.windows(2) {
        let d_k = pair[1] - pair[0];
        if sign == 0.0 {
            sign = d_k.signum();
        }
        if d_k.signum() != sign {
            return false;
        }
        lo_k = lo_k.min(d_k.abs());
        hi_k = hi_k.max(d_k.abs());
    }
    let last_k = match means_c {
        [.., a, b] => (b - a).abs(),
        _ => return false,
    };
    lo_k >= AMB_RAMP_MAX_K_PER_S * AMB_RAMP_SEGMENT_S
        && lo_k >= AMB_RAMP_STEADY_SHARE * hi_k
        && last_k >= AMB_RAMP_SETTLING_SHARE * hi_k
}

/// Heater-not-heating while held: the largest unexplained fall of a judged heater's sensor
/// below its recent peak, K (see `Supervisor::check_hold`). A dead TCA's bead loses several
/// kelvin within seconds; the largest healthy unexplained fall measured on the hifi ensemble
/// (a bead relaxing to that link's lower equilibrium) sets it.
pub const HOLD_MAX_FALL_K: f32 = 4.0;
/// Heater-not-heating while held: how fast the recent peak relaxes toward the present reading,
/// s. A healthy sensor falling at r K/s stays about r × this below its recent peak: this
/// forgives the slow healthy relaxations (well under 0.5 K/s) but not a dead TCA's bead,
/// which loses its rise at several K/s.
pub const HOLD_PEAK_TAU_S: f32 = 30.0;
/// Heater-not-heating while held: the lag of the other heater's heat at this sensor, s (the
/// PLA rod's cooling, about 20 s, carries a PLA power drop to the TCA's bead).
pub const HOLD_CROSS_TAU_S: f32 = 20.0;
/// Heater-not-heating while held: how fast the recent powers relax toward the present, s. A
/// power drop explains a fall for about this long: the hifi TCA bead keeps losing the PLA's
/// heat for tens of seconds after the PLA heater goes off in lock.
pub const HOLD_POWER_TAU_S: f32 = 60.0;
const _: () = assert!(HOLD_MAX_FALL_K > 0.0 && HOLD_MAX_FALL_K < HEATING_MAX_FALL_K);
const _: () = assert!(HOLD_PEAK_TAU_S > 0.0 && HOLD_POWER_TAU_S >= HOLD_PEAK_TAU_S);
const _: () = assert!(HOLD_CROSS_TAU_S > 0.0);

/// Heater-not-heating while held, TCA against the PLA sensor (`Supervisor::check_held`): the
/// largest fall of the TCA's rise less the PLA's model share of its rise, below its recent
/// peak, while the TCA's reading is below the model's steady rise for its power, K. A TCA that
/// dies in bend or lock under a closed-loop hold (which turns it up as the reading falls) loses
/// several kelvin of it within the lock; 3 K is set a third above the largest healthy fall
/// measured (`cargo xtask calibration`, `cargo xtask strategies`; docs/safety.md, "What the
/// table says"). `HOLD_MAX_FALL_K` misses a dead TCA in lock because the PLA's power drop at
/// lock explains any TCA fall for tens of seconds.
pub const HELD_MAX_FALL_K: f32 = 3.0;
/// Heater-not-heating while held, TCA: the lag of the own model rise that explains a fall
/// after a power drop, s (the TCA bead's response to its heater; a shorter lag only explains
/// more, sooner).
pub const HELD_RESPONSE_TAU_S: f32 = 2.0;
const _: () = assert!(HELD_MAX_FALL_K > 0.0 && HELD_MAX_FALL_K < HOLD_MAX_FALL_K);
const _: () = assert!(HELD_RESPONSE_TAU_S > 0.0 && HELD_RESPONSE_TAU_S < HOLD_PEAK_TAU_S);

/// One heater's held watch: its sensor's recent peak while judged, °C, and its own and the
/// other heater's recent commanded power, W.
#[derive(Clone, Copy, Debug, Default)]
struct HoldWatch {
    peak_c: Option<f32>,
    recent_w: Option<(f32, f32)>,
    other_lag_w: Option<f32>,
}

/// One heated sensor's sensor-frozen watch.
#[derive(Clone, Copy, Debug, Default)]
struct FrozenWatch {
    /// The power and reading when the sensor last moved (W, °C).
    reference: Option<(f32, f32)>,
    /// Since when the power has been a step away with the sensor unmoved, ms.
    since_ms: Option<u64>,
}

/// One heated sensor's expected rise above ambient: the supervisor's own first-order envelope
/// of the model's steady rise for the commanded powers (no strategy's observer: the supervisor
/// judges the controller, it does not share its model). From the first reading it starts at
/// the reading itself (a warm link is not implausible).
#[derive(Clone, Copy, Debug, Default)]
pub struct Expectation {
    /// The ceiling, the floor before its lag and the floor, K above ambient (`None`: no
    /// reading yet).
    envelope_k: Option<(f32, f32, f32)>,
    /// Seconds outside the envelope (leaky).
    outside_s: f32,
}

impl Expectation {
    /// The envelope now, without its margin: (ceiling, floor), K above ambient.
    pub fn bounds_k(&self) -> Option<(f32, f32)> {
        self.envelope_k.map(|(hi, _, lo)| (hi, lo))
    }

    /// Moves the envelope `dt_s` toward the model's steady rise: the ceiling toward `steady_k`
    /// (both heaters' shares, K) but never under `neighbour_k` (the other heated sensor's rise,
    /// K: the heat it can pass on), the floor toward `own_k` (the own heater's alone: the hifi
    /// link couples the heaters less than the model, so the other's share is no floor), and
    /// returns how far `rise_k` (the reading's rise above ambient, K) lies outside it widened by
    /// [`PLAUS_MARGIN_K`] (negative below, 0 inside), or `None` on the first reading.
    pub fn update(
        &mut self,
        dt_s: f32,
        own_k: f32,
        steady_k: f32,
        neighbour_k: f32,
        rise_k: f32,
    ) -> Option<f32> {
        let Some((hi, lo1, lo)) = self.envelope_k.as_mut() else {
            self.envelope_k = Some((rise_k.max(0.0), rise_k, rise_k));
            return None;
        };
        let approach = |x: &mut f32, to: f32, tau_s: f32| *x = lag(*x, to, dt_s, tau_s);
        let to_hi = (PLAUS_HIGH_GAIN * steady_k).max(neighbour_k);
        let tau_hi = if to_hi > *hi {
            PLAUS_TAU_FAST_S
        } else {
            PLAUS_CEILING_FALL_S
        };
        approach(hi, to_hi, tau_hi);
        let to_lo = PLAUS_LOW_GAIN * own_k;
        let tau_lo = if to_lo > *lo1 {
            PLAUS_TAU_SLOW_S
        } else {
            PLAUS_TAU_FAST_S
        };
        approach(lo1, to_lo, tau_lo);
        if *lo1 > *lo {
            approach(lo, *lo1, PLAUS_LAG_S.max(dt_s));
        } else {
            *lo = *lo1;
        }
        let (hi, lo) = (*hi + PLAUS_MARGIN_K, *lo - PLAUS_MARGIN_K);
        Some(if rise_k > hi {
            rise_k - hi
        } else if rise_k < lo {
            rise_k - lo
        } else {
            0.0
        })
    }
}

/// The share of the way to its input a first-order lag of time constant `tau_s` moves in
/// `dt_s` (all of it for a step longer than the time constant): the one lag every watch uses.
fn lag_share(dt_s: f32, tau_s: f32) -> f32 {
    (dt_s / tau_s).min(1.0)
}

/// `x` moved `share` of the way toward `to`.
fn toward(x: f32, to: f32, share: f32) -> f32 {
    x + (to - x) * share
}

/// `x` after `dt_s` of a first-order lag of time constant `tau_s` toward `to`.
fn lag(x: f32, to: f32, dt_s: f32, tau_s: f32) -> f32 {
    toward(x, to, lag_share(dt_s, tau_s))
}

/// A frame older than [`STALE_AFTER_MS`] is a fault.
fn fresh(now_ms: u64, frame: &Frame) -> Result<(), Fault> {
    let age_ms = now_ms.saturating_sub(frame.sample_ms);
    if age_ms > STALE_AFTER_MS {
        return Err(Fault {
            code: FaultCode::StaleSensor,
            subject: Subject::Frame,
            value: age_ms as f32 / 1000.0,
        });
    }
    Ok(())
}

/// Whether a supply reading, V, lies within [`SUPPLY_MIN_V`]..[`SUPPLY_MAX_V`] to
/// [`SUPPLY_READ_TOLERANCE_V`] (the supervisor's check; bring-up tools use the same).
pub fn supply_in_range(supply_v: f32) -> bool {
    supply_v >= SUPPLY_MIN_V - SUPPLY_READ_TOLERANCE_V
        && supply_v < SUPPLY_MAX_V + SUPPLY_READ_TOLERANCE_V
}

/// A supply outside [`supply_in_range`] is a fault.
fn supply_ok(frame: &Frame) -> Result<(), Fault> {
    if !supply_in_range(frame.supply_v) {
        return Err(Fault {
            code: FaultCode::SupplyOutOfRange,
            subject: Subject::Supply,
            value: frame.supply_v,
        });
    }
    Ok(())
}

/// What one reading of `sensor` says is wrong, if anything: open, short, or outside limits.
fn reading_fault(sensor: Sensor, reading: Reading) -> Option<Fault> {
    let subject = Subject::Sensor(sensor);
    let lim = limits(sensor);
    let (code, value) = match reading {
        Reading::Open => (FaultCode::ThermistorOpen, f32::NAN),
        Reading::Short => (FaultCode::ThermistorShort, f32::NAN),
        Reading::Ok(t) if t > lim.max_c => (FaultCode::OverTemperature, t),
        Reading::Ok(t) if t < lim.min_c => (FaultCode::UnderTemperature, t),
        Reading::Ok(_) => return None,
    };
    Some(Fault {
        code,
        subject,
        value,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame sampled at `ms` reading `pla` and `tca` (and a 22 °C bath), each with a few
    /// hundredths of a kelvin of deterministic noise, as a live ADC reading has.
    fn frame(ms: u64, pla: f32, tca: f32) -> Frame {
        let noise = |k: u64| 0.01 * ((ms / 100 + k) % 3) as f32 - 0.01;
        Frame {
            readings: [pla + noise(0), tca + noise(1), 22.0 + noise(2)].map(Reading::Ok),
            supply_v: 12.0,
            sample_ms: ms,
        }
    }

    #[test]
    fn a_supply_at_its_limits_passes_through_the_adc_and_one_a_step_outside_trips() {
        let sense = crate::controller::SupplySense::DEFAULT;
        let read = |v: f32| Frame {
            supply_v: sense.volts(sense.counts(v)),
            ..frame(0, 22.0, 22.0)
        };
        for v in [SUPPLY_MIN_V, 12.0, SUPPLY_MAX_V] {
            assert!(
                supply_ok(&read(v)).is_ok(),
                "{v} V (reads {})",
                read(v).supply_v
            );
        }
        for v in [SUPPLY_MIN_V - 0.1, SUPPLY_MAX_V + 0.1, 5.0, 20.0] {
            assert!(supply_ok(&read(v)).is_err(), "{v} V");
        }
    }

    #[test]
    fn a_reading_that_repeats_to_the_last_bit_trips_and_a_noisy_or_reread_one_never_does() {
        let off = Powers::default();
        let mut noisy = Supervisor::new();
        let mut reread = Supervisor::new();
        let mut still = Supervisor::new();
        let mut tripped_s = None;
        for tick in 0..200u64 {
            let ms = tick * 100;
            assert!(noisy
                .check(ms, &frame(ms, 22.5, 22.3), off, Phase::Lock)
                .is_ok());
            // The same frame read again and again (a late ADC): the stale check's business.
            let old = frame(ms.min(900), 22.5, 22.3);
            let r = reread.check(ms, &old, off, Phase::Lock);
            assert!(r.is_ok() || r.unwrap_err().code == FaultCode::StaleSensor);
            let mut f = frame(ms, 22.5, 22.3);
            f.readings[Sensor::Tca.index()] = Reading::Ok(22.3);
            if tripped_s.is_none() {
                if let Err(fault) = still.check(ms, &f, off, Phase::Lock) {
                    assert_eq!(
                        (fault.code, fault.subject),
                        (FaultCode::SensorFrozen, Subject::Sensor(Sensor::Tca))
                    );
                    tripped_s = Some(ms as f32 / 1000.0);
                }
            }
        }
        let s = tripped_s.expect("a still reading never tripped");
        assert!((FROZEN_STILL_S..FROZEN_STILL_S + 0.15).contains(&s), "{s}");
    }

    /// The ambient ramp watch fed `amb(t_s)` every 100 ms for 120 s (NaN skipped as a sample
    /// the range check rejects): when it first tripped, s.
    fn ramp_trip_s(amb: impl Fn(f32) -> f32) -> Option<f32> {
        let mut w = RampWatch::new();
        (0..1200u64).find_map(|tick| {
            let (ms, t_s) = (tick * 100, tick as f32 / 10.0);
            let noise = 0.03 * ((tick % 5) as f32 - 2.0);
            w.update(ms, amb(t_s) + noise).err().map(|f| {
                assert_eq!(
                    (f.code, f.subject),
                    (FaultCode::SensorImplausible, Subject::Sensor(Sensor::Amb))
                );
                assert!(f.value.abs() > AMB_RAMP_MAX_K_PER_S, "{f:?}");
                t_s
            })
        })
    }

    #[test]
    fn an_ambient_drift_trips_within_20_s_and_a_bath_step_or_slow_change_never_does() {
        let span_s = AMB_RAMP_SEGMENTS as f32 * AMB_RAMP_SEGMENT_S;
        // Wherever in a segment it starts.
        for k in 0..12 {
            let t0_s = 5.0 + k as f32 * AMB_RAMP_SEGMENT_S / 12.0;
            for rate in [-0.2f32, 0.12, 0.2, 0.5] {
                let t = ramp_trip_s(|t| 22.0 + rate * (t - t0_s).max(0.0))
                    .unwrap_or_else(|| panic!("{rate} K/s from {t0_s} s missed"));
                assert!(
                    (t0_s + span_s..t0_s + 20.0).contains(&t),
                    "{rate} K/s from {t0_s} s tripped at {t} s"
                );
            }
            // A bath changed at once (22 to 46 °C, or to 5 °C), as beads of 2.25–25 s follow it.
            for (to_c, tau_s) in [
                (46.0f32, 2.25f32),
                (46.0, 3.0),
                (46.0, 10.0),
                (46.0, 25.0),
                (5.0, 25.0),
            ] {
                let step = |t: f32| {
                    let since = (t - t0_s).max(0.0);
                    22.0 + (to_c - 22.0) * (1.0 - libm::expf(-since / tau_s))
                };
                assert_eq!(
                    ramp_trip_s(step),
                    None,
                    "step to {to_c} °C at {t0_s} s, tau {tau_s} s"
                );
            }
        }
        // A bath warming at 3 K/min, and a still one.
        assert_eq!(ramp_trip_s(|t| 22.0 + 0.05 * t), None);
        assert_eq!(ramp_trip_s(|_| 22.0), None);
        // A sample lost now and then (an intermittent contact) does not hide a drift.
        let gappy = |t: f32| {
            if (t * 10.0) as u32 % 100 == 99 {
                f32::NAN
            } else {
                22.0 + 0.2 * t
            }
        };
        assert!(ramp_trip_s(gappy).is_some_and(|t| t < 20.0));
        // A gap longer than a segment starts the watch over.
        let gap = |t: f32| {
            if (10.0..17.0).contains(&t) {
                f32::NAN
            } else {
                22.0 + 0.2 * t
            }
        };
        assert!(ramp_trip_s(gap).is_some_and(|t| t >= 17.0 + span_s));
    }

    #[test]
    fn reset_waits_while_the_ambient_reading_still_ramps() {
        let mut s = Supervisor::new();
        let off = Powers::default();
        let amb_frame = |ms: u64, amb: f32| Frame {
            readings: [amb + 0.3, amb + 0.2, amb].map(Reading::Ok),
            supply_v: 12.0,
            sample_ms: ms,
        };
        let mut tripped = false;
        let mut ms = 0;
        while ms < 40_000 && !tripped {
            let amb = 22.0 + 0.2 * ms as f32 / 1000.0 + 0.01 * ((ms / 100) % 3) as f32;
            tripped = s.check(ms, &amb_frame(ms, amb), off, Phase::Idle).is_err();
            ms += 100;
        }
        assert!(tripped);
        let f = amb_frame(ms, 30.0);
        assert_eq!(
            s.condition_clear(ms, &f).map_err(|f| (f.code, f.subject)),
            Err((FaultCode::SensorImplausible, Subject::Sensor(Sensor::Amb)))
        );
        // RESET keeps the watch; once a segment's judgement finds the reading still, it clears.
        s.rearm();
        for _ in 0..100 {
            ms += 100;
            let _ = s.check(
                ms,
                &amb_frame(ms, 30.0 + 0.01 * ((ms / 100) % 3) as f32),
                off,
                Phase::Idle,
            );
        }
        assert!(s.condition_clear(ms, &amb_frame(ms, 30.0)).is_ok());
    }

    #[test]
    fn a_heater_that_warms_passes_and_a_dead_one_trips_after_the_check_time() {
        let on = Powers {
            pla_w: 0.0,
            tca_w: 1.0,
        };
        let (mut good, mut dead) = (Supervisor::new(), Supervisor::new());
        for tick in 0..200u64 {
            let ms = tick * 100;
            let warming = 22.0 + 30.0 * (1.0 - libm::expf(-(ms as f32) / 5000.0));
            assert!(
                good.check(ms, &frame(ms, 22.0, warming), on, Phase::Bend)
                    .is_ok(),
                "good heater tripped at {ms} ms"
            );
            let r = dead.check(ms, &frame(ms, 22.0, 22.5), on, Phase::Bend);
            if (ms as f32) / 1000.0 < HEATING_WINDOW_S {
                assert!(r.is_ok());
            } else {
                let f = r.unwrap_err();
                assert_eq!(
                    (f.code, f.subject),
                    (FaultCode::HeaterNotHeating, Subject::Heater(Heater::Tca))
                );
                return;
            }
        }
        panic!("dead heater never tripped");
    }

    #[test]
    fn an_intermittent_excursion_adds_up_and_a_rare_one_never_does() {
        let off = Powers::default();
        // Out of limits two readings in three: the leaky count reaches 4.
        let mut s = Supervisor::new();
        let tripped = (0..30u64).any(|i| {
            let t = if i % 3 == 2 { 30.0 } else { 140.0 };
            s.check(i * 100, &frame(i * 100, t, 30.0), off, Phase::Idle)
                .is_err()
        });
        assert!(tripped);
        // Every other reading: the count never climbs past 1.
        let mut s = Supervisor::new();
        for i in 0..100u64 {
            let t = if i % 2 == 0 { 140.0 } else { 30.0 };
            assert!(s
                .check(i * 100, &frame(i * 100, t, 30.0), off, Phase::Idle)
                .is_ok());
        }
    }

    #[test]
    fn limits_need_consecutive_readings_and_nan_never_passes() {
        let mut s = Supervisor::new();
        let off = Powers::default();
        for i in 0..(LIMIT_CONSECUTIVE as u64 - 1) {
            assert!(s
                .check(i * 100, &frame(i * 100, 140.0, 30.0), off, Phase::Idle)
                .is_ok());
        }
        let f = s
            .check(400, &frame(400, 140.0, 30.0), off, Phase::Idle)
            .unwrap_err();
        assert_eq!(f.code, FaultCode::OverTemperature);
        let mut nan = frame(0, 30.0, 30.0);
        nan.supply_v = f32::NAN;
        assert_eq!(
            Supervisor::new()
                .check(0, &nan, off, Phase::Idle)
                .unwrap_err()
                .code,
            FaultCode::SupplyOutOfRange
        );
        assert!(Supervisor::new().condition_clear(0, &nan).is_err());
    }

    #[test]
    fn a_frozen_sensor_trips_after_a_power_step_and_a_moving_one_never_does() {
        let on = Powers {
            pla_w: 0.0,
            tca_w: 1.0,
        };
        let (mut frozen, mut moving) = (Supervisor::new(), Supervisor::new());
        let mut tripped_s = None;
        for tick in 0..200u64 {
            let ms = tick * 100;
            let cmd = if ms < 2000 { Powers::default() } else { on };
            let warming = 22.0 + 20.0 * (1.0 - libm::expf(-(ms as f32 - 2000.0).max(0.0) / 4000.0));
            assert!(moving
                .check(ms, &frame(ms, 22.0, warming), cmd, Phase::Bend)
                .is_ok());
            if tripped_s.is_none() {
                if let Err(f) = frozen.check(ms, &frame(ms, 22.0, 22.0), cmd, Phase::Bend) {
                    assert_eq!(f.code, FaultCode::SensorFrozen);
                    assert_eq!(f.subject, Subject::Sensor(Sensor::Tca));
                    tripped_s = Some((ms - 2000) as f32 / 1000.0);
                }
            }
        }
        // Judged from the first tick the step is seen (the commanded power lags one tick).
        let s = tripped_s.expect("frozen sensor never tripped");
        assert!((FROZEN_WINDOW_S..FROZEN_WINDOW_S + 0.3).contains(&s), "{s}");
    }

    /// Heaters off after a trip with the rod still hot: the TCA's bead warmed by it (rising
    /// from 5 K towards the rod's 20 K over a minute) is plausible; one that climbs past the
    /// rod's reading is not. (A MORPH that rests on a warm link, heaters off, tripped
    /// `sensor-implausible tca` 0.8 K over an envelope that knew only the heaters.)
    #[test]
    fn a_sensor_warmed_by_its_hotter_neighbour_is_plausible_and_one_past_it_is_not() {
        let run = |to_k: f32| {
            let mut e = Expectation::default();
            let dt_s = 0.1;
            let mut worst = 0.0f32;
            for k in 0..900 {
                let t_s = k as f32 * dt_s;
                let rise_k = to_k + (5.0 - to_k) * crate::mathf::exp(-t_s / 20.0);
                let off = e.update(dt_s, 0.0, 0.0, 20.0, rise_k).unwrap_or(0.0);
                worst = worst.max(off);
            }
            worst
        };
        assert_eq!(run(19.0), 0.0);
        assert!(run(20.0 + 3.0 * PLAUS_MARGIN_K) > 0.0);
    }

    #[test]
    fn the_expectation_holds_a_healthy_first_order_sensor_and_rejects_a_drift() {
        let dt_s = 0.1;
        let (mut healthy, mut drifting) = (Expectation::default(), Expectation::default());
        let mut rise_k = 0.0f32;
        let mut tripped_s = None;
        for tick in 0..3000u32 {
            let t_s = tick as f32 * dt_s;
            // 1 W into the TCA for 100 s, then off: the sensor follows with 3 s, at 60 % of
            // the model's rise (a bead reading less than its heater's mean).
            let own_k = if t_s < 100.0 { R_TT_K_PER_W } else { 0.0 };
            rise_k += (0.6 * own_k - rise_k) * dt_s / 3.0;
            assert_eq!(
                healthy
                    .update(dt_s, own_k, own_k, 0.0, rise_k)
                    .unwrap_or(0.0),
                0.0,
                "{t_s}"
            );
            let off = drifting
                .update(dt_s, own_k, own_k, 0.0, rise_k - 0.2 * t_s)
                .unwrap_or(0.0);
            if off < 0.0 && tripped_s.is_none() {
                tripped_s = Some(t_s);
            }
        }
        assert!(tripped_s.is_some());
    }

    /// Runs `sup` on readings `temps(t_s) = (pla_c, tca_c)` at `cmd(t_s)` for `secs`; returns
    /// the first fault and when, s.
    fn first_fault(
        sup: &mut Supervisor,
        cmd: impl Fn(f32) -> Powers,
        phase: Phase,
        secs: u64,
        temps: impl Fn(f32) -> (f32, f32),
    ) -> Option<(Fault, f32)> {
        (0..secs * 10).find_map(|tick| {
            let ms = tick * 100;
            let t_s = ms as f32 / 1000.0;
            let (pla_c, tca_c) = temps(t_s);
            sup.check(ms, &frame(ms, pla_c, tca_c), cmd(t_s), phase)
                .err()
                .map(|f| (f, ms as f32 / 1000.0))
        })
    }

    #[test]
    fn a_held_tca_that_keeps_its_rise_passes_and_one_that_sinks_with_the_pla_trips() {
        // Lock: PLA off and cooling from 70 °C, TCA held at 1.4 W (model rise 48 K) reading
        // 55 °C: alive it stays (or creeps up), dead it sinks at 0.5 K/s.
        let cmd = Powers {
            pla_w: 0.0,
            tca_w: 1.4,
        };
        let pla = |t: f32| 22.0 + 48.0 * libm::expf(-t / 15.0);
        let mut alive = Supervisor::new();
        assert!(first_fault(
            &mut alive,
            |_| cmd,
            Phase::Lock,
            30,
            |t| (pla(t), 55.0 + 0.1 * t)
        )
        .is_none());
        let mut dead = Supervisor::new();
        let (f, at_s) = first_fault(
            &mut dead,
            |_| cmd,
            Phase::Lock,
            30,
            |t| (pla(t), 55.0 - 0.5 * t),
        )
        .expect("a sinking TCA never tripped");
        assert_eq!(
            (f.code, f.subject),
            (FaultCode::HeaterNotHeating, Subject::Heater(Heater::Tca))
        );
        assert!(at_s < 10.0, "{at_s}");
    }

    #[test]
    fn a_pla_rising_while_turned_down_trips_after_the_grace_and_a_cooling_one_never_does() {
        // Bend: 20 s at 4 W, then the PLA turned down to 0.05 W with the TCA at 1 W, the PLA
        // reading 48 K above ambient, above what 4x the commanded powers explain (37 K).
        let cmd = |t: f32| Powers {
            pla_w: if t < 20.0 { 4.0 } else { 0.05 },
            tca_w: 1.0,
        };
        let heated = |t: f32| 22.0 + 48.0 * (t / 20.0).min(1.0);
        // The TCA warms as a live heater at 1 W does (to 0.8 of its model rise), plus a share
        // of the PLA's heat.
        let tca = |t: f32| {
            22.0 + 0.8 * R_TT_K_PER_W * (1.0 - libm::expf(-t / 5.0)) + 0.3 * (heated(t) - 22.0)
        };
        let mut cooling = Supervisor::new();
        assert_eq!(
            first_fault(&mut cooling, cmd, Phase::Bend, 60, |t| {
                (heated(t) - 0.3 * (t - 20.0).max(0.0), tca(t))
            })
            .map(|(f, at_s)| (f.code, at_s)),
            None
        );
        let mut stuck = Supervisor::new();
        let (f, at_s) = first_fault(&mut stuck, cmd, Phase::Bend, 60, |t| {
            (heated(t) + 0.5 * (t - 20.0).max(0.0), tca(t))
        })
        .expect("a stuck PLA heater never tripped");
        assert_eq!(
            (f.code, f.subject),
            (FaultCode::HeatingWhileOff, Subject::Heater(Heater::Pla))
        );
        // Turned down at 20 s (seen a tick later): the grace, then 3 K at 0.5 K/s.
        let after_s = at_s - 20.0;
        assert!(
            (LOW_GRACE_S..LOW_GRACE_S + 7.0).contains(&after_s),
            "{after_s}"
        );
    }

    #[test]
    fn a_sensor_rising_far_after_both_heaters_are_cut_trips_within_the_grace_and_stored_heat_never_does(
    ) {
        // Release: both heaters cut at 10 s after 10 s of heating, the PLA reading 30 K above
        // ambient. Stored heat lifts it less than `OFF_STORED_MAX_RISE_K` before it cools
        // (docs/safety.md, "ABORT on a healthy link"); a stuck heater keeps it rising 2.5 K/s.
        let cmd = |t: f32| Powers {
            pla_w: if t < 10.0 { 1.0 } else { 0.0 },
            tca_w: if t < 10.0 { 0.5 } else { 0.0 },
        };
        let warm = |t: f32| 22.0 + 3.0 * t.min(10.0);
        let after = |t: f32| (t - 10.0).max(0.0);
        let stored =
            |t: f32| warm(t) + 11.2 * after(t).min(4.0) / 4.0 - 0.5 * (after(t) - 4.0).max(0.0);
        // The TCA warms as a live heater at 0.5 W does, then cools.
        let tca = |t: f32| {
            22.0 + 14.0 * (1.0 - libm::expf(-t.min(10.0) / 3.0)) * libm::expf(-after(t) / 10.0)
        };
        let mut sup = Supervisor::new();
        assert_eq!(
            first_fault(&mut sup, cmd, Phase::Release, 40, |t| (stored(t), tca(t)))
                .map(|(f, at_s)| (f.code, at_s)),
            None
        );
        let mut sup = Supervisor::new();
        let (f, at_s) = first_fault(&mut sup, cmd, Phase::Release, 40, |t| {
            (warm(t) + 2.5 * after(t), tca(t))
        })
        .expect("a stuck PLA heater never tripped");
        assert_eq!(
            (f.code, f.subject),
            (FaultCode::HeatingWhileOff, Subject::Heater(Heater::Pla))
        );
        // 12 K at 2.5 K/s: 4.8 s after the cut (seen a tick later), well inside the 15 s grace.
        let after_s = at_s - 10.0;
        assert!((4.8..5.2).contains(&after_s), "{after_s}");
        assert!(after_s < OFF_GRACE_S);
        // RESET waits while it still heats.
        assert!(sup.off[Heater::Pla.index()].heating);
    }

    #[test]
    fn a_tca_warmed_by_the_hotter_pla_after_a_cut_passes_and_one_that_passes_the_pla_trips() {
        // Still air: a long soften at 4 W, then both heaters cut at 20 s. The rod's heat warms
        // the TCA's bead 15 K over a minute, past both heating-while-off rules, while it reads
        // below the cooling PLA; a stuck TCA heater climbs past the PLA and trips.
        let cmd = |t: f32| Powers {
            pla_w: if t < 20.0 { 4.0 } else { 0.0 },
            tca_w: 0.0,
        };
        let after = |t: f32| (t - 20.0).max(0.0);
        let pla = |t: f32| {
            if t < 20.0 {
                22.0 + 3.0 * t
            } else {
                37.0 + 45.0 * libm::expf(-after(t) / 20.0)
            }
        };
        let warmed = |t: f32| 22.0 + 15.0 * (1.0 - libm::expf(-after(t) / 30.0));
        let mut sup = Supervisor::new();
        assert_eq!(
            first_fault(&mut sup, cmd, Phase::Idle, 100, |t| (pla(t), warmed(t)))
                .map(|(f, at_s)| (f.code, at_s)),
            None
        );
        let stuck = |t: f32| 22.0 + 3.0 * after(t);
        let mut sup = Supervisor::new();
        let (f, at_s) = first_fault(&mut sup, cmd, Phase::Idle, 100, |t| (pla(t), stuck(t)))
            .expect("a stuck TCA heater never tripped");
        assert_eq!(
            (f.code, f.subject),
            (FaultCode::HeatingWhileOff, Subject::Heater(Heater::Tca))
        );
        // Under the hot PLA its rise is explained until the ceiling (`OFF_NEIGHBOUR_MAX_RISE_K`):
        // 20 K at 3 K/s, 6.7 s after the cut (it would pass the PLA only at 13.6 s).
        let ceiling_s = 20.0 + OFF_NEIGHBOUR_MAX_RISE_K / 3.0;
        assert!((at_s - ceiling_s).abs() <= 0.2, "{at_s} {ceiling_s}");
        // A slower stuck TCA under a PLA holding 45 °C: explained until it passes the PLA plus
        // the margin (48 °C from 30 °C at 1 K/s: 18 s, a rise of 18 K, under the ceiling).
        let off = |_t: f32| Powers {
            pla_w: 0.0,
            tca_w: 0.0,
        };
        let f = all_faults(off, Phase::Idle, 40, |t| (45.0, 30.0 + t));
        let (_, at_s) = f
            .iter()
            .find(|(f, _)| f.code == FaultCode::HeatingWhileOff)
            .expect("a stuck TCA passing the PLA never tripped");
        let crossed_s = 45.0 + OFF_NEIGHBOUR_MARGIN_K - 30.0;
        assert!((at_s - crossed_s).abs() <= 0.2, "{at_s} {crossed_s}");
    }

    /// Every fault of every tick over `secs` s, at 10 ticks a second.
    fn all_faults(
        cmd: impl Fn(f32) -> Powers,
        phase: Phase,
        secs: u64,
        temps: impl Fn(f32) -> (f32, f32),
    ) -> std::vec::Vec<(Fault, f32)> {
        extern crate std;
        let mut sup = Supervisor::new();
        let mut all = std::vec::Vec::new();
        for tick in 0..secs * 10 {
            let ms = tick * 100;
            let t_s = ms as f32 / 1000.0;
            let (pla_c, tca_c) = temps(t_s);
            let mut faults = Faults::new();
            sup.check_all(ms, &frame(ms, pla_c, tca_c), cmd(t_s), phase, &mut faults);
            all.extend(faults.iter().map(|f| (*f, t_s)));
        }
        all
    }

    #[test]
    fn a_pla_heater_warming_the_tca_thermistor_more_than_its_own_trips_and_a_lagging_bead_never_does(
    ) {
        let crossed = |f: &Fault| {
            f.code == FaultCode::SensorImplausible && f.subject == Subject::Heater(Heater::Pla)
        };
        // Soften at 5 W with the TCA off: the PLA's own bead rises, late (a 10 s lag) but more
        // than the TCA's, which sees the heat through the silicone.
        let alone = |_t: f32| Powers {
            pla_w: 5.0,
            tca_w: 0.0,
        };
        let own = |t: f32| 22.0 + 60.0 * (1.0 - libm::expf(-t / 10.0));
        let through = |t: f32| 22.0 + 0.25 * (own(t) - 22.0) * (1.0 - libm::expf(-t / 5.0));
        let f = all_faults(alone, Phase::Soften, 30, |t| (own(t), through(t)));
        assert!(!f.iter().any(|(f, _)| crossed(f)), "{f:?}");
        // A MORPH soon after a still-air ABORT: the PLA bead still falls for 3 s before it
        // turns, the TCA bead still warms 0.2 K/s from the heat stored before.
        let dipping = |t: f32| {
            70.0 - 2.0 * t.min(3.0) + 20.0 * (1.0 - libm::expf(-(t - 3.0).max(0.0) / 10.0))
        };
        let f = all_faults(alone, Phase::Soften, 30, |t| (dipping(t), 40.0 + 0.2 * t));
        assert!(!f.iter().any(|(f, _)| crossed(f)), "{f:?}");
        // The wires swapped: the TCA input reads the PLA's bead; it trips within a second.
        let f = all_faults(alone, Phase::Soften, 5, |t| (through(t), own(t)));
        let (first, at_s) = f.iter().find(|(f, _)| crossed(f)).expect("never tripped");
        assert!(
            first.value > CROSS_MAX_LEAD_K && *at_s < 1.0,
            "{first:?} at {at_s} s"
        );
        // With the TCA on (closed's soften) the check stands aside.
        let both = |_t: f32| Powers {
            pla_w: 5.0,
            tca_w: 2.0,
        };
        let f = all_faults(both, Phase::Soften, 5, |t| (through(t), own(t)));
        assert!(!f.iter().any(|(f, _)| crossed(f)), "{f:?}");
    }

    #[test]
    fn a_sensor_below_a_hotter_one_is_warmed_by_it_up_to_a_ceiling_and_a_bad_one_explains_nothing()
    {
        // Both heaters cut at 0 s, the TCA hot and cooling; the PLA's reading climbs 1.5 K/s
        // below it (a stuck PLA heater).
        let off = |_t: f32| Powers {
            pla_w: 0.0,
            tca_w: 0.0,
        };
        let tca = |t: f32| 90.0 - 0.2 * t;
        let pla = |t: f32| 40.0 + 1.5 * t;
        let heating = |f: &Fault| {
            f.code == FaultCode::HeatingWhileOff && f.subject == Subject::Heater(Heater::Pla)
        };
        // Under the TCA its rise is explained until it passes the 20 K ceiling (13.3 s).
        let f = all_faults(off, Phase::Idle, 40, |t| (pla(t), tca(t)));
        let (_, at_s) = f
            .iter()
            .find(|(f, _)| heating(f))
            .expect("a stuck heater under a hotter sensor never tripped");
        let at_s = *at_s;
        let ceiling_s = OFF_NEIGHBOUR_MAX_RISE_K / 1.5;
        assert!(
            (at_s - ceiling_s).abs() < 0.3,
            "{at_s} s, ceiling at {ceiling_s} s"
        );
        // With the TCA thermistor open its last hot value explains nothing: 12 K, at 8 s.
        let mut sup = Supervisor::new();
        let mut found = None;
        for tick in 0..400u64 {
            let ms = tick * 100;
            let t_s = ms as f32 / 1000.0;
            let mut fr = frame(ms, pla(t_s), tca(t_s));
            if t_s >= 1.0 {
                fr.readings[Sensor::Tca.index()] = Reading::Open;
            }
            let mut faults = Faults::new();
            sup.check_all(ms, &fr, off(t_s), Phase::Idle, &mut faults);
            if faults.iter().any(heating) {
                found = Some(t_s);
                break;
            }
        }
        let at_s = found.expect("never tripped with the TCA open");
        assert!((at_s - OFF_STORED_MAX_RISE_K / 1.5).abs() < 0.3, "{at_s} s");
    }

    #[test]
    fn a_pla_reading_frozen_above_the_tca_with_its_heater_off_trips_sensor_frozen() {
        let cmd = Powers {
            pla_w: 0.0,
            tca_w: 1.4,
        };
        // Live: the rod cools (and its reading with it); frozen: it stays at 70 °C.
        let mut live = Supervisor::new();
        assert!(first_fault(
            &mut live,
            |_| cmd,
            Phase::Lock,
            20,
            |t| (70.0 - 0.5 * t, 55.0)
        )
        .is_none());
        let mut frozen = Supervisor::new();
        let (f, at_s) = first_fault(&mut frozen, |_| cmd, Phase::Lock, 20, |_| (70.0, 55.0))
            .expect("a frozen PLA reading never tripped");
        assert_eq!(
            (f.code, f.subject),
            (FaultCode::SensorFrozen, Subject::Sensor(Sensor::Pla))
        );
        assert!(
            (FROZEN_WINDOW_S..FROZEN_WINDOW_S + 0.3).contains(&at_s),
            "{at_s}"
        );
    }
}
