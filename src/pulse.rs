//! `HEAT <pla|tca> <power_w> <s>`: one heater at a low fixed power for a few seconds, the
//! other off, under the supervisor like a morph; for bring-up (does each heater warm its own
//! thermistor?). Bounded in power and time, ended by ABORT, by any fault, and by its own
//! clock.

use crate::heater::HeaterConfig;
use crate::vocab::{Heater, Powers};

/// Highest power a pulse may ask for, a fraction of the heater's cap (PLA 5 W → 1 W, TCA
/// 2 W → 0.4 W): enough to lift its thermistor a few kelvin in seconds, far below anything
/// that could soften the PLA or pull the TCA. The supervisor judges a pulse as it judges a
/// morph: its expectation is fed the pulse's power.
pub const HEAT_MAX_FRACTION: f32 = 0.2;
/// Longest pulse, s: a thermistor bead beside its heater answers within a few seconds; a
/// minute at 1 W warms the PLA by well under its 62 °C glass transition.
pub const HEAT_MAX_S: f32 = 60.0;
const _: () = assert!(HEAT_MAX_FRACTION > 0.0 && HEAT_MAX_FRACTION <= 0.25);

/// The window HEAT's time is counted over, s: a heater's pulse time is a bucket of
/// [`HEAT_MAX_S`] given back at [`HEAT_MAX_S`] per this window ([`HeatBudget`]; a full bucket
/// is empty again after it), so chained pulses average at most a fifth of the pulse power: 0.2 W into the PLA, whose steady rise even in still air (about
/// 100 K/W) stays some 20 K, far below the glass transition (docs/protocol.md, `HEAT`).
pub const HEAT_WINDOW_S: f32 = 300.0;
const _: () = assert!(HEAT_WINDOW_S >= 2.0 * HEAT_MAX_S);

/// Each heater's HEAT time, as a bucket that drains at
/// `HEAT_MAX_S / HEAT_WINDOW_S` seconds per second: a pulse counts its whole length when it
/// starts (an ABORTed one too) and is refused if the bucket would pass [`HEAT_MAX_S`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HeatBudget {
    /// Seconds in each heater's bucket (PLA, TCA) as of `at_ms`.
    used_s: [f32; 2],
    at_ms: u64,
}

impl HeatBudget {
    /// Seconds of pulse `heater` may still have at `now_ms`.
    pub fn available_s(&self, heater: Heater, now_ms: u64) -> f32 {
        HEAT_MAX_S - self.used_at(heater, now_ms)
    }

    fn used_at(&self, heater: Heater, now_ms: u64) -> f32 {
        let drained_s =
            now_ms.saturating_sub(self.at_ms) as f32 / 1000.0 * HEAT_MAX_S / HEAT_WINDOW_S;
        (self.used_s[heater.index()] - drained_s).max(0.0)
    }

    /// Counts a pulse of `duration_s` of `heater` starting at `now_ms`; refused, counting
    /// nothing, if it would pass the budget (the seconds still available).
    pub fn take(&mut self, heater: Heater, duration_s: f32, now_ms: u64) -> Result<(), f32> {
        let left_s = self.available_s(heater, now_ms);
        if !(duration_s <= left_s + 1e-3) {
            return Err(left_s);
        }
        self.used_s = Heater::ALL.map(|h| self.used_at(h, now_ms));
        self.used_s[heater.index()] += duration_s;
        self.at_ms = now_ms;
        Ok(())
    }
}

/// The highest pulse power of `heater`, W.
pub fn max_power_w(heater: Heater) -> f32 {
    let cap = match heater {
        Heater::Pla => HeaterConfig::PLA.max_power_w,
        Heater::Tca => HeaterConfig::TCA.max_power_w,
    };
    HEAT_MAX_FRACTION * cap
}

/// Why a pulse was refused.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PulseError {
    /// The power is not in (0, the heater's pulse cap]; the cap, W.
    Power(f32),
    /// The duration is not in (0, [`HEAT_MAX_S`]].
    Duration,
}

/// A running pulse.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pulse {
    /// The heater driven.
    pub heater: Heater,
    /// Its power, W.
    pub power_w: f32,
    /// When it ends, ms.
    pub until_ms: u64,
}

impl Pulse {
    /// A pulse of `heater` at `power_w` for `duration_s` from `now_ms`, if within the bounds.
    pub fn new(
        now_ms: u64,
        heater: Heater,
        power_w: f32,
        duration_s: f32,
    ) -> Result<Pulse, PulseError> {
        let cap = max_power_w(heater);
        if !(power_w > 0.0 && power_w <= cap) {
            return Err(PulseError::Power(cap));
        }
        if !(duration_s > 0.0 && duration_s <= HEAT_MAX_S) {
            return Err(PulseError::Duration);
        }
        Ok(Pulse {
            heater,
            power_w,
            // At most 60 000 ms: a u32 holds it (and needs no 64-bit float conversion).
            // Saturating: a clock at its end makes a pulse that ends there, not a panic.
            until_ms: now_ms.saturating_add((duration_s * 1000.0) as u32 as u64),
        })
    }

    /// The powers at `now_ms`: this heater's while the pulse lasts; None once it is over.
    pub fn powers(&self, now_ms: u64) -> Option<Powers> {
        if now_ms >= self.until_ms {
            return None;
        }
        Some(Powers::only(self.heater, self.power_w))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pulses_are_bounded_in_power_and_time_and_end_on_their_clock() {
        assert_eq!(max_power_w(Heater::Pla), 1.0);
        assert!((max_power_w(Heater::Tca) - 0.4).abs() < 1e-6);
        let p = Pulse::new(1000, Heater::Tca, 0.3, 5.0).unwrap();
        assert_eq!(
            p.powers(1000),
            Some(Powers {
                pla_w: 0.0,
                tca_w: 0.3
            })
        );
        assert_eq!(p.powers(5999).map(|p| p.tca_w), Some(0.3));
        assert_eq!(p.powers(6000), None);
        for (w, s) in [(0.0, 5.0), (-1.0, 5.0), (f32::NAN, 5.0), (0.5, 5.0)] {
            assert_eq!(
                Pulse::new(0, Heater::Tca, w, s),
                Err(PulseError::Power(max_power_w(Heater::Tca)))
            );
        }
        for s in [0.0, -1.0, f32::NAN, HEAT_MAX_S + 0.1, f32::INFINITY] {
            assert_eq!(
                Pulse::new(0, Heater::Pla, 1.0, s),
                Err(PulseError::Duration)
            );
        }
        assert!(Pulse::new(0, Heater::Pla, 1.0, HEAT_MAX_S).is_ok());
        // A clock at its very end (the fuzzer's jump) ends the pulse there instead of panicking.
        let late = Pulse::new(u64::MAX - 10, Heater::Pla, 1.0, 5.0).unwrap();
        assert_eq!(late.until_ms, u64::MAX);
        assert_eq!(late.powers(u64::MAX), None);
    }

    #[test]
    fn a_heaters_pulses_add_up_over_the_window_and_the_other_heater_keeps_its_own() {
        let mut b = HeatBudget::default();
        assert_eq!(b.take(Heater::Pla, HEAT_MAX_S, 0), Ok(()));
        assert!(matches!(b.take(Heater::Pla, 1.0, 1_000), Err(l) if (l - 0.2).abs() < 1e-3));
        assert_eq!(b.take(Heater::Tca, HEAT_MAX_S, 1_000), Ok(()));
        // The bucket drains a fifth of a second per second: half of it after half the window.
        let half_ms = (HEAT_WINDOW_S * 500.0) as u64;
        assert!((b.available_s(Heater::Pla, half_ms) - HEAT_MAX_S / 2.0).abs() < 1e-3);
        assert_eq!(
            b.take(Heater::Pla, HEAT_MAX_S, half_ms),
            Err(b.available_s(Heater::Pla, half_ms))
        );
        assert_eq!(
            b.take(Heater::Pla, HEAT_MAX_S, (HEAT_WINDOW_S * 1000.0) as u64),
            Ok(())
        );
    }
}
