//! The limits a reading is held to whatever the model says: each sensor's temperature range,
//! the supply's, a frame's age, and a reading that must move by its noise.

use super::{Fault, FaultCode, Subject};
use crate::thermistor::{RangeCheck, Reading};
use crate::vocab::Sensor;

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
// Each limit stays 10 K or more under what it protects (the rod melts near 150 °C, the TCA was
// annealed at 160 °C, the model assumes a bath below 60 °C), the supply's around the 12 V
// design supply, and a frame is stale within two seconds.
const _: () = assert!(PLA_LIMITS.max_c <= 140.0 && TCA_LIMITS.max_c <= 140.0);
const _: () = assert!(AMB_LIMITS.max_c <= 60.0 && PLA_LIMITS.min_c < AMB_LIMITS.max_c);
const _: () = assert!(SUPPLY_MIN_V >= 6.0 && SUPPLY_MIN_V < 12.0 && SUPPLY_MAX_V <= 24.0);
/// The supply limits are judged on the reading to this much either side, V: half the 0.1 V
/// step the alarm reports the reading in, so a supply the alarm would print as within its range
/// never trips (a 9.0 V supply reads 8.9999 V through the divider and the ADC's steps).
pub const SUPPLY_READ_TOLERANCE_V: f32 = 0.05;
const _: () = assert!(SUPPLY_READ_TOLERANCE_V >= 0.0 && SUPPLY_READ_TOLERANCE_V < 0.5);
/// A sensor frame older than this counts as stale, ms. Klipper allows 7 s for hot ends with
/// time constants of minutes; the TCA's fast thermal part is about 1 s, so 1 s (10 ticks).
pub const STALE_AFTER_MS: u64 = 1000;
const _: () = assert!(STALE_AFTER_MS >= 200 && STALE_AFTER_MS <= 2000);
/// Out-of-limit readings before a temperature trip (Klipper: 4 samples), counted by a leaky
/// counter: +1 for a reading out of limits, −1 for one within, so one noisy reading never trips
/// but an intermittent excursion (every other reading) does.
pub const LIMIT_CONSECUTIVE: u8 = 4;
// The same 4-sample rule for open/short (thermistor::RangeCheck) and for the limits.
const _: () = assert!(LIMIT_CONSECUTIVE == RangeCheck::DEFAULT_CONSECUTIVE);

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

/// Sensor-frozen, still reading: a sensor whose reading repeats to the last bit for this long
/// of sample time trips, whatever the heaters do, s (the must-move test). A live reading
/// carries the ADC's and the bead's noise: 16 summed 12-bit samples step about 0.003 K at
/// 60 °C and 0.016 K at 120 °C, and the quietest bead drawn (0.02 K rms) spans several steps,
/// so 50 identical readings never come from a live sensor; a hung ADC channel repeats at once.
pub const FROZEN_STILL_S: f32 = 5.0;
const _: () = assert!(FROZEN_STILL_S >= 1.0 && FROZEN_STILL_S <= 10.0);

/// The still-reading watch: each sensor's last reading and the sample time it was first read
/// at, °C and ms.
#[derive(Clone, Copy, Debug, Default)]
pub struct Still {
    last: [Option<(f32, u64)>; 3],
}

impl Still {
    /// Judges this frame's live readings `live_c` (°C, NaN where not a temperature) sampled at
    /// `sample_ms`. Only frames with a new sample time count, so a frame read twice is left to
    /// the stale-sensor check.
    pub fn update(&mut self, live_c: [f32; 3], sample_ms: u64) -> Result<(), Fault> {
        for sensor in Sensor::ALL {
            let temp_c = live_c[sensor.index()];
            let w = &mut self.last[sensor.index()];
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
}

/// A frame older than [`STALE_AFTER_MS`] is a fault.
pub fn fresh(now_ms: u64, frame: &Frame) -> Result<(), Fault> {
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
    // A NaN reading is in no range.
    (SUPPLY_MIN_V - SUPPLY_READ_TOLERANCE_V..SUPPLY_MAX_V + SUPPLY_READ_TOLERANCE_V)
        .contains(&supply_v)
}

/// A supply outside [`supply_in_range`] is a fault.
pub fn supply_ok(frame: &Frame) -> Result<(), Fault> {
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
pub fn reading_fault(sensor: Sensor, reading: Reading) -> Option<Fault> {
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
