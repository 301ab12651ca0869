//! Safety supervisor, run every control tick before the sequencer and independently of it.
//!
//! Checks, each with a named default scaled to this link (a few grams of silicone whose heaters
//! respond within seconds, not a 3D-printer hot end):
//! thermistor open/short (ADC range, consecutive samples), per-sensor min/max temperature,
//! heater-not-heating, stale sensor frames and supply voltage. A trip is returned as a
//! [`Fault`]; the controller turns both heaters off in the same tick and latches it.

use crate::heater::HeaterConfig;
use crate::link::{R_PP_K_PER_W, R_TP_K_PER_W, R_TT_K_PER_W};
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
    /// A heater's sensor kept rising with both heaters commanded off (a stuck MOSFET).
    HeatingWhileOff,
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
            FaultCode::HeatingWhileOff => "heating-while-off",
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
            (FaultCode::HeaterNotHeating, _) => "HEATING_MIN_GAIN_K, HEATING_MAX_FALL_K",
            (FaultCode::HeatingWhileOff, _) => "OFF_GRACE_S, OFF_MAX_RISE_K",
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
/// this time of being switched on (or of its phase starting); 12 s is 1.2 times the PLA bead's
/// 10 s lag and 3–4 TCA bead time constants.
pub const HEATING_WINDOW_S: f32 = 10.0;
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
/// share). The slowest
/// healthy climb into the band measured (the hifi TCA bead at a low bend power, 0.7 W) takes
/// about 20 s; a dead heater whose sensor the other heater keeps warming never gets there.
pub const HEATING_BAND_TIMEOUT_S: f32 = 30.0;
/// [`HEATING_BAND_TIMEOUT_S`] is judged only while the heater's own model rise is at least this
/// many times the other heater's share: the hifi link couples the heaters less than the model
/// does, so where the other heater's heat is comparable (boost's soften, the PLA at 4–5 W) a
/// healthy sensor need not reach the floor; the slope checks still judge it there.
pub const HEATING_BAND_MIN_OWN_SHARE: f32 = 2.0;
/// A commanded power rise by more than this share restarts [`HEATING_BAND_TIMEOUT_S`].
pub const HEATING_POWER_STEP_FRACTION: f32 = 0.1;
// A dead heater must trip within a soften phase, before it can time out.
const _: () = assert!(HEATING_WINDOW_S < 20.0);
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
    /// The phase the watch was armed in (a new phase re-arms it).
    phase: Option<Phase>,
}

/// Every fault one frame can show at once: one per sensor, the supply, the two heater checks,
/// with room to spare.
pub type Faults = heapless::Vec<Fault, 8>;

/// One heater's heating-while-off watch: since when both heaters are off, and the sensor's
/// lowest rise above ambient since the grace ended.
#[derive(Clone, Copy, Debug, Default)]
struct OffWatch {
    off_since_ms: Option<u64>,
    min_rise_k: Option<f32>,
    /// The condition holds now (RESET is refused while it does).
    heating: bool,
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
        }
    }

    /// Last good temperatures, °C (NaN before the first good reading).
    pub fn measurements(&self) -> Measurements {
        Measurements::from_array(self.last_c)
    }

    /// Checks one frame with the powers commanded in the previous tick, in `phase` (the phase
    /// they were commanded in: a new phase re-arms the heater watches). Returns the
    /// temperatures to control from, or the first fault found (see [`Supervisor::check_all`]).
    pub fn check(
        &mut self,
        now_ms: u64,
        frame: &Frame,
        commanded: Powers,
        phase: Phase,
    ) -> Result<Measurements, Fault> {
        let mut faults = Faults::new();
        let m = self.check_all(now_ms, frame, commanded, phase, &mut faults);
        match faults.first() {
            Some(f) => Err(*f),
            None => Ok(m),
        }
    }

    /// Runs every check on one frame, whatever the phase (a latched fault included: the
    /// controller calls it every tick), and collects every fault present into `faults`, in
    /// check order. Returns the last good temperatures. Every sensor is read even when an
    /// earlier one is faulty, so [`Supervisor::live`] stays live.
    pub fn check_all(
        &mut self,
        now_ms: u64,
        frame: &Frame,
        commanded: Powers,
        phase: Phase,
        faults: &mut Faults,
    ) -> Measurements {
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
        if let Err(f) = supply_ok(frame) {
            found(f);
        }
        if let Err(f) = self.check_heating(now_ms, commanded, phase) {
            found(f);
        }
        if let Err(f) = self.check_off(now_ms, commanded) {
            found(f);
        }
        self.measurements()
    }

    /// This frame's temperatures as read, °C: NaN for a sensor that reads open or short (what
    /// STATUS shows; [`Supervisor::measurements`] keeps the last good ones for control).
    pub fn live(&self) -> Measurements {
        Measurements::from_array(self.live_c)
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
    fn check_heating(&mut self, now_ms: u64, cmd: Powers, phase: Phase) -> Result<(), Fault> {
        let m = self.measurements();
        for heater in Heater::ALL {
            let own_w = cmd.of(heater);
            let other_w = match heater {
                Heater::Pla => cmd.tca_w,
                Heater::Tca => cmd.pla_w,
            };
            let temp_c = m.of(heater.sensor());
            let (r_self, cap_w) = match heater {
                Heater::Pla => (R_PP_K_PER_W, HeaterConfig::PLA.max_power_w),
                Heater::Tca => (R_TT_K_PER_W, HeaterConfig::TCA.max_power_w),
            };
            let w = &mut self.watch[heater.index()];
            // A new phase re-arms the watch, unless the heater stays on at no less power: its
            // window then runs on (closed's phases can each be shorter than one window).
            if w.phase != Some(phase) {
                let carries_on =
                    own_w >= w.last_w * (1.0 - HEATING_POWER_STEP_FRACTION) && w.last_w > 0.0;
                *w = if carries_on {
                    HeatWatch {
                        phase: Some(phase),
                        ..*w
                    }
                } else {
                    HeatWatch {
                        phase: Some(phase),
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
            let (other_rise_k, r_other) = match heater {
                Heater::Pla => (m.t_tca_c - m.t_amb_c, R_TT_K_PER_W),
                Heater::Tca => (m.t_pla_c - m.t_amb_c, R_PP_K_PER_W),
            };
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
    /// trips: the heater is on although nothing commands it (a stuck MOSFET).
    fn check_off(&mut self, now_ms: u64, cmd: Powers) -> Result<(), Fault> {
        let m = self.measurements();
        let both_off = !(cmd.pla_w > 0.0) && !(cmd.tca_w > 0.0);
        for heater in Heater::ALL {
            let w = &mut self.off[heater.index()];
            let rise_k = m.of(heater.sensor()) - m.t_amb_c;
            if !both_off || !rise_k.is_finite() {
                *w = OffWatch::default();
                continue;
            }
            let since = *w.off_since_ms.get_or_insert(now_ms);
            if (now_ms.saturating_sub(since) as f32) / 1000.0 < OFF_GRACE_S {
                continue;
            }
            let min_k = w.min_rise_k.map_or(rise_k, |k| k.min(rise_k));
            w.min_rise_k = Some(min_k);
            // Measured from the lowest reading, or from ambient if it was below it (a link
            // warming up to a warmer bath is not heating).
            w.heating = rise_k - min_k.max(0.0) > OFF_MAX_RISE_K;
            if w.heating {
                return Err(Fault {
                    code: FaultCode::HeatingWhileOff,
                    subject: Subject::Heater(heater),
                    value: rise_k - min_k.max(0.0),
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
            if self.off[heater.index()].heating {
                return Err(Fault {
                    code: FaultCode::HeatingWhileOff,
                    subject: Subject::Heater(heater),
                    value: f32::NAN,
                });
            }
        }
        supply_ok(frame)
    }

    /// Forgets counters and heater watches (after RESET), keeping last temperatures (the
    /// heating-while-off watch too: RESET is only allowed once it no longer sees a rise).
    pub fn rearm(&mut self) {
        self.range = [RangeCheck::new(RangeCheck::DEFAULT_CONSECUTIVE); 3];
        self.limit_count = [0; 3];
        self.watch = [HeatWatch::default(); 2];
        self.off = [OffWatch::default(); 2];
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
}
