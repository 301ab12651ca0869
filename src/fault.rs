//! What a safety trip is: its code, what it is about, the offending value, and the named
//! settings that govern it (every alarm line names them and docs/safety.md explains them).
//! The supervisor, the electrical checks and the sequencer's phase timeouts all raise these.

use crate::vocab::{Heater, Phase, Sensor};

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
    /// A heater was driven but its sensor read below every member of the expectation.
    HeaterNotHeating,
    /// A heater's sensor read above every member of the expectation for the powers commanded
    /// (a stuck MOSFET on a board that cannot sense current).
    HeatingWhileOff,
    /// No fresh sensor frame arrived in time.
    StaleSensor,
    /// The heater supply is outside its allowed range.
    SupplyOutOfRange,
    /// A morph phase overran its timeout.
    PhaseTimeout,
    /// A sensor's reading repeated to the last bit for `FROZEN_STILL_S` (a hung ADC channel):
    /// a live reading moves by its noise.
    SensorFrozen,
    /// A heated sensor left the expectation where the heater's power is known (drifting,
    /// swapped, off its heater), or the ambient one drifts steadily.
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
                "RESIDUAL_SLACK_K, CUSUM_LIMIT_K_S, CHANGE_LIMIT_K, UNTUNED_GAIN_RANGE"
            }
            (FaultCode::HeatingWhileOff, _) => {
                "RESIDUAL_SLACK_K, CUSUM_LIMIT_K_S, CHANGE_LIMIT_K, BEAD_LAG_MAX_S"
            }
            (FaultCode::StaleSensor, _) => "STALE_AFTER_MS",
            (FaultCode::SupplyOutOfRange, _) => {
                "SUPPLY_MIN_V, SUPPLY_MAX_V, SUPPLY_READ_TOLERANCE_V"
            }
            // A lock carries the PLA's reading: it stayed too warm, by `closed`'s judgment or
            // until the clock.
            (FaultCode::PhaseTimeout, Subject::Phase(Phase::Lock)) if self.value.is_finite() => {
                "LOCK_TIMEOUT_S, CLOSED_LOCK_SETTLE_TAU_S"
            }
            (FaultCode::PhaseTimeout, Subject::Phase(phase)) => match phase {
                Phase::Soften => "SOFTEN_TIMEOUT_S",
                Phase::Bend => "BEND_TIMEOUT_S",
                Phase::Lock => "LOCK_TIMEOUT_S",
                Phase::Rest => "REST_TIMEOUT_S, REST_MAX_RISE_K",
                _ => "RELEASE_TIMEOUT_S",
            },
            (FaultCode::PhaseTimeout, _) => "SOFTEN_TIMEOUT_S",
            (FaultCode::SensorFrozen, _) => "FROZEN_STILL_S",
            (FaultCode::SensorImplausible, Subject::Sensor(Sensor::Amb)) => {
                "AMB_RAMP_MAX_K_PER_S, AMB_RAMP_SETTLING_SHARE"
            }
            (FaultCode::SensorImplausible, _) => {
                "RESIDUAL_SLACK_K, CUSUM_LIMIT_K_S, CHANGE_LIMIT_K, TUNED_SPREAD"
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
