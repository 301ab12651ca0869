//! The ambient thermistor's own test: the surroundings change slowly or by steps, never by a
//! steady ramp. Every heated sensor's rise is measured from it, so the expectation cannot
//! judge it.

use super::{Fault, FaultCode, Subject};
use crate::vocab::Sensor;

/// Sensor-implausible, ambient: the fastest steady change of the surroundings, K/s (6 K/min).
/// A water bath or a room changes by a fraction of a kelvin a minute; a bath poured or the link
/// moved is a step, which the ambient bead follows within seconds (its time constant is 2–3 s)
/// and then holds. A reading that keeps moving faster than this, steadily, for
/// [`AMB_RAMP_SEGMENTS`] × [`AMB_RAMP_SEGMENT_S`] is a drifting sensor (a cracked bead, a
/// failing joint): every heated sensor's rise is measured from it, so the expectation
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
const _: () = assert!(AMB_RAMP_MAX_K_PER_S > 0.0 && AMB_RAMP_MAX_K_PER_S < 1.0);
const _: () = assert!(AMB_RAMP_SEGMENT_S >= 1.0);
const _: () = assert!(AMB_RAMP_SEGMENTS >= 2 && AMB_RAMP_SEGMENTS <= 8);
const _: () = assert!(AMB_RAMP_STEADY_SHARE > 0.0 && AMB_RAMP_STEADY_SHARE < 1.0);
const _: () = assert!(AMB_RAMP_SETTLING_SHARE > 0.0 && AMB_RAMP_SETTLING_SHARE < 1.0);
const _: () = assert!((AMB_RAMP_SEGMENTS as f32) * AMB_RAMP_SEGMENT_S + AMB_RAMP_SEGMENT_S <= 20.0);

/// The ambient sensor's steady-ramp watch: the mean reading of the segment in progress and of
/// the last [`AMB_RAMP_SEGMENTS`] + 1 whole segments.
#[derive(Clone, Copy, Debug, Default)]
pub struct RampWatch {
    /// When the segment in progress started (sample time, ms), its sum of readings (°C) and
    /// their count.
    segment: Option<(u64, f32, u16)>,
    /// The last whole segments' means, oldest first, °C; `count` of them are filled.
    means_c: [f32; AMB_RAMP_SEGMENTS + 1],
    count: usize,
    /// The rate of the steady ramp the last judgement found, K/s, or `None` when it found none
    /// (RESET waits until it finds none, and its refusal names this rate).
    pub ramping_k_per_s: Option<f32>,
}

impl RampWatch {
    /// A watch with no segment yet.
    pub const fn new() -> Self {
        RampWatch {
            segment: None,
            means_c: [0.0; AMB_RAMP_SEGMENTS + 1],
            count: 0,
            ramping_k_per_s: None,
        }
    }

    /// Adds one reading (`temp_c` at `sample_ms`) and judges the segments once one ends: a
    /// steady ramp faster than [`AMB_RAMP_MAX_K_PER_S`] trips `sensor-implausible amb` with
    /// its rate, K/s. A reading that is not a temperature (an open or shorted sample, which the
    /// range check judges) is skipped, so an intermittent contact cannot hide a drift; a gap
    /// longer than a segment starts the watch over (means across it are not comparable), its
    /// latch kept.
    pub fn update(&mut self, sample_ms: u64, temp_c: f32) -> Result<(), Fault> {
        if !temp_c.is_finite() {
            return Ok(());
        }
        let segment_ms = (AMB_RAMP_SEGMENT_S * 1000.0) as u64;
        if let Some((start_ms, _, _)) = self.segment {
            if sample_ms.saturating_sub(start_ms) >= 2 * segment_ms {
                // The latch stays: RESET waits for a whole watch without a ramp.
                (self.segment, self.count) = (None, 0);
            }
        }
        let (start_ms, sum_c, n) = self.segment.get_or_insert((sample_ms, 0.0, 0));
        if sample_ms.saturating_sub(*start_ms) < segment_ms {
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
        let span_s = AMB_RAMP_SEGMENTS as f32 * AMB_RAMP_SEGMENT_S;
        self.ramping_k_per_s = steady_ramp(&self.means_c)
            .then(|| (self.means_c[AMB_RAMP_SEGMENTS] - self.means_c[0]) / span_s);
        self.ramping_k_per_s
            .map_or(Ok(()), |rate| Err(ramp_fault(rate)))
    }
}

/// The ambient ramp's trip: `sensor-implausible amb` at `rate_k_per_s`.
pub fn ramp_fault(rate_k_per_s: f32) -> Fault {
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
