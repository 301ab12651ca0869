//! Safety supervisor, run every control tick before the sequencer and independently of it.
//!
//! By concern: the limits every reading is held to whatever the model says ([`limits`](mod@limits): the
//! sensors' ranges, the parts' estimates, the supply, a frame's age, a reading that does not
//! move by its noise), the ambient thermistor's ramp ([`ramp`]), the one expectation of the
//! heated sensors ([`expect`]: a family of the link's lumped model fed the powers delivered)
//! and the residual tests on it ([`residual`]); the electrical checks of a board that senses
//! current are `crate::electrical`'s. A trip is returned as a [`Fault`]; the controller turns
//! both heaters off (and cuts the supply) in the same tick and latches it.

pub mod expect;
pub mod limits;
pub mod ramp;
pub mod residual;

pub use expect::{
    Expectation, BEAD_LAG_MAX_S, TUNED_SPREAD, UNTUNED_CROSS_LEAST, UNTUNED_GAIN_RANGE,
};
pub use limits::*;
pub use ramp::{
    AMB_RAMP_MAX_K_PER_S, AMB_RAMP_SEGMENTS, AMB_RAMP_SEGMENT_S, AMB_RAMP_SETTLING_SHARE,
    AMB_RAMP_STEADY_SHARE,
};
pub use residual::{
    drift_delay_s, CHANGE_LIMIT_K, CHANGE_SLACK_K_PER_S, CHANGE_SMOOTH_S, CUSUM_LIMIT_K_S,
    RESIDUAL_SLACK_K,
};

pub use crate::fault::{Fault, FaultCode, Subject, SAFETY_DOC, SAFETY_DOC_SECTION};

use crate::calibration::Calibration;
use crate::part_limit::{estimate_c, limit_shares, UNTUNED_BEAD_SHARES};
use crate::thermistor::{RangeCheck, Reading};
use crate::vocab::{Doing, Heater, Measurements, Powers, Sensor};
use ramp::{ramp_fault, RampWatch};
use residual::{Change, Envelope, Side};

/// The time the residual tests are designed to name a heater that does not heat within, once
/// its own heat should show, s: the aim of docs/safety.md ("Aims"); the strategies wait this
/// long before they take a stalled reading for a heater at its cap, and the soften timeout's
/// floor lies beyond it. Not a setting the tests read: the CUSUM's limit and slack give it.
pub const HEATER_VERDICT_S: f32 = 10.0;
const _: () = assert!(HEATER_VERDICT_S > 0.0 && HEATER_VERDICT_S < 20.0);

/// Every fault one frame can show at once: one per sensor, the supply, the two heater checks,
/// with room to spare.
pub type Faults = heapless::Vec<Fault, 8>;

/// The supervisor's state: the limits' counters, the last good temperatures, the expectation
/// and each channel's residual test.
#[derive(Clone, Copy, Debug)]
pub struct Supervisor {
    range: [RangeCheck; 3],
    limit_count: [u8; 3],
    last_c: [f32; 3],
    live_c: [f32; 3],
    still: Still,
    ramp: RampWatch,
    expect: Expectation,
    envelope: [Envelope; 2],
    change: [Change; 2],
    /// The board senses its heaters' current (the powers fed are the delivered ones).
    sensed: bool,
    /// The TCA's own temperature from its resistance, °C (NaN where not read).
    tca_self_c: f32,
    last_ms: Option<u64>,
    /// The share of its part's rise each heated bead is taken to read (PLA, TCA), 1
    /// ([`crate::part_limit::limit_shares`]).
    shares: [f32; 2],
    /// This tick's estimates of the PLA rod and the TCA, °C (NaN before a reading).
    parts_c: [f32; 2],
    /// Leaky counts of estimates over their part's limit (as `limit_count`).
    part_count: [u8; 2],
    /// The fullest the level and the change tests have been since the last RESET, each a
    /// share of its limit.
    peak_share: [f32; 2],
}

impl Default for Supervisor {
    fn default() -> Self {
        Self::new()
    }
}

impl Supervisor {
    /// A supervisor with no history (temperatures unknown until the first frame) and the
    /// compiled-in link's expectation.
    pub fn new() -> Self {
        Supervisor {
            range: [RangeCheck::new(RangeCheck::DEFAULT_CONSECUTIVE); 3],
            limit_count: [0; 3],
            last_c: [f32::NAN; 3],
            live_c: [f32::NAN; 3],
            still: Still::default(),
            ramp: RampWatch::new(),
            expect: Expectation::new(),
            envelope: [Envelope::default(); 2],
            change: [Change::default(); 2],
            sensed: false,
            tca_self_c: f32::NAN,
            last_ms: None,
            shares: UNTUNED_BEAD_SHARES,
            parts_c: [f32::NAN; 2],
            part_count: [0; 2],
            peak_share: [0.0; 2],
        }
    }

    /// Takes the calibration in force: the beads' shares the parts' limits are judged with
    /// ([`crate::part_limit::limit_shares`]) and the expectation's family (the fitted one
    /// once `TUNE` has run).
    pub fn set_calibration(&mut self, cal: &Calibration) {
        self.shares = limit_shares(cal);
        self.expect.set_calibration(cal);
    }

    /// What this tick's frame comes with on a board that senses current: `sensed` (the powers
    /// commanded are then delivered, at the measured resistance; a heater that is open or
    /// shorted is named by the electrical checks) and the TCA's own temperature, °C.
    pub fn set_sensing(&mut self, sensed: bool, tca_self_c: Option<f32>) {
        self.sensed = sensed;
        self.tca_self_c = tca_self_c.unwrap_or(f32::NAN);
    }

    /// This tick's estimates of the heated parts (PLA rod, TCA), °C: each bead's last good
    /// reading lifted by its share ([`crate::part_limit::estimate_c`]); NaN before a reading.
    pub fn parts_c(&self) -> [f32; 2] {
        self.parts_c
    }

    /// The fullest the level tests and the change tests have each been since the supervisor
    /// started or was re-armed, as a share of its limit (1 trips): how close a healthy run came
    /// to an alarm.
    pub fn peak_shares(&self) -> [f32; 2] {
        self.peak_share
    }

    /// The expectation's hull of each heated thermistor now, (floor, ceiling) K above the
    /// ambient reading (NaN before it starts).
    pub fn bounds_k(&self, heater: Heater) -> (f32, f32) {
        self.expect.bounds_k(heater.index())
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

    /// Checks one frame with the powers the previous tick delivered for `doing`. Returns the
    /// temperatures to control from, or the first fault found (see [`Supervisor::check_all`]).
    pub fn check(
        &mut self,
        now_ms: u64,
        frame: &Frame,
        delivered: Powers,
        doing: impl Into<Doing>,
    ) -> Result<Measurements, Fault> {
        let mut faults = Faults::new();
        let m = self.check_all(now_ms, frame, delivered, doing, &mut faults);
        match faults.first() {
            Some(f) => Err(*f),
            None => Ok(m),
        }
    }

    /// Runs every check on one frame, whatever runs (a latched fault included: the controller
    /// calls it every tick), and collects every fault present into `faults`, in check order.
    /// `delivered` are the powers the previous tick's duties delivered (W); `doing` what
    /// commanded them (the model judges every activity alike; a `TUNE` against the compiled-in
    /// link). Returns the last good temperatures. Every sensor is read even when an earlier one
    /// is faulty, so [`Supervisor::live`] stays live.
    pub fn check_all(
        &mut self,
        now_ms: u64,
        frame: &Frame,
        delivered: Powers,
        doing: impl Into<Doing>,
        faults: &mut Faults,
    ) -> Measurements {
        self.expect.tuning(doing.into() == Doing::Tune);
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
        if let Err(f) = self.still.update(self.live_c, frame.sample_ms) {
            found(f);
        }
        let amb_c = self.live_c[Sensor::Amb.index()];
        if let Err(f) = self.ramp.update(frame.sample_ms, amb_c) {
            found(f);
        }
        // A gap (a stale stretch) counts at most 1 s: the powers of it are unknown.
        let dt_s = self.last_ms.map_or(0.0, |ms| {
            (now_ms.saturating_sub(ms) as f32 / 1000.0).min(1.0)
        });
        self.last_ms = Some(now_ms);
        self.check_residuals(dt_s, &mut found, delivered);
        self.measurements()
    }

    /// Advances the expectation under `p` and judges every channel's live reading against its
    /// hull.
    fn check_residuals(&mut self, dt_s: f32, found: &mut impl FnMut(Fault), p: Powers) {
        let [pla_c, tca_c, amb_c] = self.last_c;
        self.expect.update(dt_s, p, [pla_c, tca_c], amb_c);
        if !self.expect.started() {
            return;
        }
        // The last good readings, where this frame has one (NaN where not): a reading past
        // its limit is the limits' to judge.
        let good = |s: usize| [f32::NAN, self.last_c[s]][self.live_c[s].is_finite() as usize];
        let amb_c = good(Sensor::Amb.index());
        let live = [good(0), good(1)];
        for (ch, temp_c) in live.into_iter().enumerate() {
            let y_k = temp_c - amb_c;
            let bounds = self.expect.bounds_k(ch);
            let level = self.envelope[ch].update(dt_s, y_k, bounds);
            let change = self.change[ch].update(dt_s, y_k, self.expect.change_k(ch));
            let shares = [self.envelope[ch].share(), self.change[ch].share()];
            self.peak_share = [0, 1].map(|i| self.peak_share[i].max(shares[i]));
            // The value: how far outside the hull, or how far beyond every member's change.
            let off_k = match (level, change) {
                (Some(Side::Below), _) => Some((Side::Below, bounds.0 - y_k)),
                (Some(Side::Above), _) => Some((Side::Above, y_k - bounds.1)),
                (None, Some(side)) => Some((side, self.change[ch].sum_k(side))),
                (None, None) => None,
            };
            if let Some((side, off_k)) = off_k {
                found(self.name(ch, side, off_k));
            }
        }
    }

    /// What a thermistor that left its hull (or outran every member's change) on `side` by
    /// `off_k` (K) means. Where current is sensed the powers are known, so a thermistor outside
    /// is its own fault, unless it is the TCA's, its heat should show, and the TCA's own
    /// temperature (from its resistance) stands below the same floor: then the TCA itself is
    /// cold (analytical redundancy: a drifting bead is told from a cold TCA, and a drifting PLA
    /// bead from a stuck PLA heater, which the electrical checks name).
    /// Without current sense, a bead below while its own heat should show is a heater that
    /// does not heat, and one above a heater on that nothing commands.
    fn name(&self, ch: usize, side: Side, off_k: f32) -> Fault {
        let heater = if ch == 0 { Heater::Pla } else { Heater::Tca };
        let own_cold = heater == Heater::Tca
            && self.tca_self_c - self.last_c[Sensor::Amb.index()]
                < self.expect.bounds_k(ch).0 - RESIDUAL_SLACK_K;
        let heat_shows = self.expect.own_heat_k(heater) > RESIDUAL_SLACK_K;
        let code = match (self.sensed, side) {
            (true, Side::Below) if own_cold && heat_shows => FaultCode::HeaterNotHeating,
            (true, _) => FaultCode::SensorImplausible,
            (false, Side::Above) => FaultCode::HeatingWhileOff,
            (false, Side::Below) if heat_shows => FaultCode::HeaterNotHeating,
            (false, Side::Below) => FaultCode::SensorImplausible,
        };
        let subject = match code {
            FaultCode::SensorImplausible => Subject::Sensor(heater.sensor()),
            _ => Subject::Heater(heater),
        };
        Fault {
            code,
            subject,
            value: off_k,
        }
    }

    /// This frame's temperatures as read, °C: NaN for a sensor that reads open or short (what
    /// STATUS shows; [`Supervisor::measurements`] keeps the last good ones for control).
    pub fn live(&self) -> Measurements {
        Measurements::from_array(self.live_c)
    }

    /// Whether a latched fault's condition has cleared on this frame (RESET is allowed), or
    /// the fault that is still present. Sensor checks need a good reading now, not four; a
    /// heater whose sensor still stands above every member of the expectation, or still stands
    /// past half the change test's limit beyond every member's change, still heats.
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
            let i = heater.index();
            let c = &self.change[i];
            if self.envelope[i].above_now || c.sum_k(Side::Above) > 0.5 * CHANGE_LIMIT_K {
                // How far above the hull it reads, or how far it rose beyond every member,
                // named as the alarm names it (where current is sensed, the bead's own fault).
                let y_k = self.last_c[heater.sensor().index()] - self.last_c[Sensor::Amb.index()];
                let off_k = (y_k - self.expect.bounds_k(i).1).max(c.sum_k(Side::Above));
                return Err(self.name(i, Side::Above, off_k));
            }
        }
        if let Some(rate_k_per_s) = self.ramp.ramping_k_per_s {
            return Err(ramp_fault(rate_k_per_s));
        }
        supply_ok(frame)
    }

    /// Forgets counters and residual sums (after RESET) and starts the expectation again from
    /// the next readings, keeping last temperatures, the still-reading watch (a reading still
    /// frozen trips again at once, not 5 s later) and the ambient ramp watch (RESET is only
    /// allowed once it no longer sees a ramp).
    pub fn rearm(&mut self) {
        self.range = [RangeCheck::new(RangeCheck::DEFAULT_CONSECUTIVE); 3];
        self.limit_count = [0; 3];
        self.part_count = [0; 2];
        self.envelope = [Envelope::default(); 2];
        self.change = [Change::default(); 2];
        self.expect.restart();
        self.last_ms = None;
        self.peak_share = [0.0; 2];
    }
}
#[cfg(test)]
mod tests {
    use super::*;
    use crate::vocab::Phase;

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
    fn a_heater_that_warms_passes_and_a_dead_one_trips_within_its_verdict_time() {
        let on = Powers {
            pla_w: 0.0,
            tca_w: 1.0,
        };
        let (mut good, mut dead) = (Supervisor::new(), Supervisor::new());
        // A healthy bead: the model's own TCA node in water, read at 0.8 of its rise.
        let mut link =
            crate::lumped::Network::new(crate::link::LINK.surroundings.h_w_m2k as f32, 22.0);
        for tick in 0..300u64 {
            let ms = tick * 100;
            let warming = 22.0 + 0.8 * (link.temp_c[crate::lumped::node::TCA] - 22.0);
            link.advance(0.1, on.tca_w, 0.0, 22.0);
            assert!(
                good.check(ms, &frame(ms, 22.0, warming), on, Phase::Bend)
                    .is_ok(),
                "good heater tripped at {ms} ms"
            );
            if let Err(f) = dead.check(ms, &frame(ms, 22.0, 22.5), on, Phase::Bend) {
                assert_eq!(
                    (f.code, f.subject),
                    (FaultCode::HeaterNotHeating, Subject::Heater(Heater::Tca))
                );
                assert!((ms as f32) / 1000.0 <= HEATER_VERDICT_S, "{ms} ms");
                return;
            }
        }
        panic!("dead heater never tripped");
    }

    #[test]
    fn a_heater_on_that_nothing_commands_trips_and_reset_waits_until_it_has_cooled() {
        let off = Powers::default();
        let mut s = Supervisor::new();
        let mut ms = 0;
        let mut pla = 22.0;
        let tripped = loop {
            assert!(ms < 60_000, "never tripped");
            pla += 0.1 * 1.5;
            if let Err(f) = s.check(ms, &frame(ms, pla, 22.0), off, Phase::Idle) {
                break f;
            }
            ms += 100;
        };
        assert_eq!(
            (tripped.code, tripped.subject),
            (FaultCode::HeatingWhileOff, Subject::Heater(Heater::Pla))
        );
        assert!(ms <= 10_000, "{ms} ms");
        assert!(s.condition_clear(ms, &frame(ms, pla, 22.0)).is_err());
        // Cooled back to the bath: RESET is allowed.
        for _ in 0..50 {
            ms += 100;
            let _ = s.check(ms, &frame(ms, 22.5, 22.0), off, Phase::Idle);
        }
        assert!(s.condition_clear(ms, &frame(ms, 22.5, 22.0)).is_ok());
    }

    #[test]
    fn where_current_is_sensed_a_bead_outside_is_the_sensor_and_the_own_temperature_names_the_heater(
    ) {
        let on = Powers {
            pla_w: 0.0,
            tca_w: 1.0,
        };
        let first = |own: f32| {
            let mut s = Supervisor::new();
            for tick in 0..300u64 {
                let ms = tick * 100;
                s.set_sensing(true, Some(own));
                if let Err(f) = s.check(ms, &frame(ms, 22.0, 22.5), on, Phase::Bend) {
                    return (f.code, f.subject);
                }
            }
            panic!("never tripped");
        };
        // The TCA warms (its own temperature follows its power) but its bead does not.
        let mut s = Supervisor::new();
        let mut link =
            crate::lumped::Network::new(crate::link::LINK.surroundings.h_w_m2k as f32, 22.0);
        let got = (0..300u64).find_map(|tick| {
            let ms = tick * 100;
            s.set_sensing(true, Some(link.temp_c[crate::lumped::node::TCA]));
            link.advance(0.1, on.tca_w, 0.0, 22.0);
            s.check(ms, &frame(ms, 22.0, 22.5), on, Phase::Bend)
                .err()
                .map(|f| (f.code, f.subject))
        });
        assert_eq!(
            got,
            Some((FaultCode::SensorImplausible, Subject::Sensor(Sensor::Tca)))
        );
        // Neither warms: the TCA does not heat.
        assert_eq!(
            first(22.5),
            (FaultCode::HeaterNotHeating, Subject::Heater(Heater::Tca))
        );
    }
}
