//! Safety supervisor, run every control tick before the sequencer and independently of it.
//!
//! Checks, each with a named default scaled to this link (a few grams of silicone whose heaters
//! respond within seconds, not a 3D-printer hot end):
//! thermistor open/short (ADC range, consecutive samples), per-sensor min/max temperature,
//! heater-not-heating, stale sensor frames and supply voltage. A trip is returned as a
//! [`Fault`]; the controller turns both heaters off in the same tick and latches it.

use crate::link::{R_PP_K_PER_W, R_TT_K_PER_W};
use crate::thermistor::{RangeCheck, Reading};
use crate::vocab::{Heater, Measurements, Phase, Powers, Sensor};

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
    /// No fresh sensor frame arrived in time.
    StaleSensor,
    /// The heater supply is outside its allowed range.
    SupplyOutOfRange,
    /// A morph phase overran its timeout.
    PhaseTimeout,
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
            FaultCode::StaleSensor => "stale-sensor",
            FaultCode::SupplyOutOfRange => "supply-out-of-range",
            FaultCode::PhaseTimeout => "phase-timeout",
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

/// The README section that explains every check and its setting; alarm lines point to it.
pub const SAFETY_README_SECTION: &str = "Safety defaults";

impl Fault {
    /// The named settings that govern this trip, as they are spelled in the source and in the
    /// README's [`SAFETY_README_SECTION`] table (alarm lines name them).
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
            (FaultCode::UnderTemperature | FaultCode::OverTemperature, _) => {
                "PLA_LIMITS, TCA_LIMITS, AMB_LIMITS"
            }
            (FaultCode::HeaterNotHeating, _) => "HEATING_CHECK_S, HEATING_MIN_FRACTION",
            (FaultCode::StaleSensor, _) => "STALE_AFTER_MS",
            (FaultCode::SupplyOutOfRange, _) => "SUPPLY_MIN_V, SUPPLY_MAX_V",
            (FaultCode::PhaseTimeout, Subject::Phase(phase)) => match phase {
                Phase::Soften => "SOFTEN_TIMEOUT_S",
                Phase::Bend => "BEND_TIMEOUT_S",
                Phase::Lock => "LOCK_TIMEOUT_S",
                _ => "RELEASE_TIMEOUT_S",
            },
            (FaultCode::PhaseTimeout, _) => "SOFTEN_TIMEOUT_S",
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
/// A sensor frame older than this counts as stale, ms. Klipper allows 7 s for hot ends with
/// time constants of minutes; the TCA's fast thermal part is about 1 s, so 1 s (10 ticks).
pub const STALE_AFTER_MS: u64 = 1000;
/// Consecutive out-of-limit readings before a temperature trip (Klipper: 4 samples).
pub const LIMIT_CONSECUTIVE: u8 = 4;
// The same 4-sample rule for open/short (thermistor::RangeCheck) and for the limits.
const _: () = assert!(LIMIT_CONSECUTIVE == RangeCheck::DEFAULT_CONSECUTIVE);
/// Heater-not-heating: the heater must have been on this long before it is judged, s.
/// Klipper's check_gain_time is 20 s for hot ends; the TCA's thermal time constants are a few
/// seconds (its steady rise is half reached in about 6–10 s under water), so 10 s.
pub const HEATING_CHECK_S: f32 = 10.0;
/// Heater-not-heating: smallest share of the model's steady self-rise that must be seen
/// after [`HEATING_CHECK_S`]. After 10 s under water the lumped network has the TCA at 72 % of
/// its steady rise but the 2-D reference model (docs/reference-model.md) only at about 40–48 %,
/// less with thermistor lag: 30 % is a thin margin on real hardware. It errs on the safe side —
/// a false trip only turns the heaters off — while a lower share would let a heater that dies in
/// bend, or a thermistor that has come loose, go unnoticed for the rest of the phase.
pub const HEATING_MIN_FRACTION: f32 = 0.3;
/// Heater-not-heating: a heater whose expected rise is below this is not judged, K: the other
/// heater can warm its sensor by a few kelvin within one check window, which would hide a dead
/// heater; below this the check could not tell. The TCA is judged from about 0.4 W.
pub const HEATING_MIN_RISE_C: f32 = 4.0;

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

#[derive(Clone, Copy, Debug, Default)]
struct HeatWatch {
    on_since_ms: Option<u64>,
    min_power_w: f32,
    start_c: f32,
}

/// The supervisor's state: consecutive-sample counters, last good temperatures and the
/// heater watches.
#[derive(Clone, Copy, Debug)]
pub struct Supervisor {
    range: [RangeCheck; 3],
    limit_count: [u8; 3],
    last_c: [f32; 3],
    watch: [HeatWatch; 2],
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
            watch: [HeatWatch::default(); 2],
        }
    }

    /// Last good temperatures, °C (NaN before the first good reading).
    pub fn measurements(&self) -> Measurements {
        Measurements::from_array(self.last_c)
    }

    /// Checks one frame with the powers commanded in the previous tick. Returns the
    /// temperatures to control from, or the fault to latch.
    pub fn check(
        &mut self,
        now_ms: u64,
        frame: &Frame,
        commanded: Powers,
    ) -> Result<Measurements, Fault> {
        fresh(now_ms, frame)?;
        for sensor in Sensor::ALL {
            let i = sensor.index();
            let reading = frame.readings[i];
            // Open/short: latched once the ADC range check has seen it often enough in a row.
            if let Some(r) = self.range[i].update(reading) {
                return Err(reading_fault(sensor, r).unwrap_or(Fault {
                    code: FaultCode::ThermistorOpen,
                    subject: Subject::Sensor(sensor),
                    value: f32::NAN,
                }));
            }
            if let Reading::Ok(t) = reading {
                match reading_fault(sensor, reading) {
                    Some(f) => {
                        self.limit_count[i] = self.limit_count[i].saturating_add(1);
                        if self.limit_count[i] >= LIMIT_CONSECUTIVE {
                            return Err(f);
                        }
                    }
                    None => {
                        self.limit_count[i] = 0;
                        self.last_c[i] = t;
                    }
                }
            }
        }
        supply_ok(frame)?;
        self.check_heating(now_ms, commanded)?;
        Ok(self.measurements())
    }

    fn check_heating(&mut self, now_ms: u64, cmd: Powers) -> Result<(), Fault> {
        let m = self.measurements();
        for heater in Heater::ALL {
            // Own power, own sensor, own thermal resistance.
            let own_w = cmd.of(heater);
            let temp_c = m.of(heater.sensor());
            let r_self = match heater {
                Heater::Pla => R_PP_K_PER_W,
                Heater::Tca => R_TT_K_PER_W,
            };
            let w = &mut self.watch[heater.index()];
            // One watch per on-period: it starts when the heater is switched on and judges the
            // rise since then against the lowest power of the period.
            if !(own_w > 0.0) {
                *w = HeatWatch::default();
                continue;
            }
            if w.on_since_ms.is_none() {
                *w = HeatWatch {
                    on_since_ms: Some(now_ms),
                    min_power_w: own_w,
                    start_c: temp_c,
                };
            }
            w.min_power_w = w.min_power_w.min(own_w);
            let since = w.on_since_ms.unwrap_or(now_ms);
            let judged = w.min_power_w * r_self * HEATING_MIN_FRACTION >= HEATING_MIN_RISE_C;
            if !judged || (now_ms.saturating_sub(since) as f32) / 1000.0 < HEATING_CHECK_S {
                continue;
            }
            // Two rises must each reach the expected share of the model's steady rise: since the
            // heater came on (catches a heater dead from the start even while the other heater
            // warms its sensor) and above ambient (catches one that dies later: it cools away).
            let expected = HEATING_MIN_FRACTION * r_self * w.min_power_w;
            let rise = (temp_c - w.start_c).min(temp_c - m.t_amb_c);
            if !(rise >= expected) {
                return Err(Fault {
                    code: FaultCode::HeaterNotHeating,
                    subject: Subject::Heater(heater),
                    value: rise,
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
        supply_ok(frame)
    }

    /// Forgets counters and heater watches (after RESET), keeping last temperatures.
    pub fn rearm(&mut self) {
        self.range = [RangeCheck::new(RangeCheck::DEFAULT_CONSECUTIVE); 3];
        self.limit_count = [0; 3];
        self.watch = [HeatWatch::default(); 2];
    }
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

/// A supply outside [`SUPPLY_MIN_V`]..=[`SUPPLY_MAX_V`] is a fault.
fn supply_ok(frame: &Frame) -> Result<(), Fault> {
    if !(frame.supply_v >= SUPPLY_MIN_V && frame.supply_v <= SUPPLY_MAX_V) {
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

    fn frame(ms: u64, pla: f32, tca: f32) -> Frame {
        Frame {
            readings: [Reading::Ok(pla), Reading::Ok(tca), Reading::Ok(22.0)],
            supply_v: 12.0,
            sample_ms: ms,
        }
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
                good.check(ms, &frame(ms, 22.0, warming), on).is_ok(),
                "good heater tripped at {ms} ms"
            );
            let r = dead.check(ms, &frame(ms, 22.0, 22.5), on);
            if (ms as f32) / 1000.0 < HEATING_CHECK_S {
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
    fn limits_need_consecutive_readings_and_nan_never_passes() {
        let mut s = Supervisor::new();
        let off = Powers::default();
        for i in 0..(LIMIT_CONSECUTIVE as u64 - 1) {
            assert!(s.check(i * 100, &frame(i * 100, 140.0, 30.0), off).is_ok());
        }
        let f = s.check(400, &frame(400, 140.0, 30.0), off).unwrap_err();
        assert_eq!(f.code, FaultCode::OverTemperature);
        let mut nan = frame(0, 30.0, 30.0);
        nan.supply_v = f32::NAN;
        assert_eq!(
            Supervisor::new().check(0, &nan, off).unwrap_err().code,
            FaultCode::SupplyOutOfRange
        );
        assert!(Supervisor::new().condition_clear(0, &nan).is_err());
    }
}
