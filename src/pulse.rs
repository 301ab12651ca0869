//! `HEAT <pla|tca> <power_w> <s>`: one heater at a low fixed power for a few seconds, the
//! other off, under the supervisor like a morph; for bring-up (does each heater warm its own
//! thermistor?). Bounded in power and time, ended by ABORT, by any fault, and by its own
//! clock.

use crate::heater::HeaterConfig;
use crate::vocab::{Heater, Powers};

/// Highest power a pulse may ask for, a fraction of the heater's cap (PLA 5 W → 1 W, TCA
/// 2 W → 0.4 W): enough to lift its thermistor a few kelvin in seconds, far below anything
/// that could soften the PLA or pull the TCA. It is also where the supervisor's
/// heater-not-heating watch begins (`supervisor::HEATING_MIN_POWER_FRACTION`), so a pulse at
/// the cap is judged by it as a morph is.
pub const HEAT_MAX_FRACTION: f32 = 0.2;
/// Longest pulse, s: a thermistor bead beside its heater answers within a few seconds; a
/// minute at 1 W warms the PLA by well under its 62 °C glass transition.
pub const HEAT_MAX_S: f32 = 60.0;
const _: () = assert!(
    HEAT_MAX_FRACTION > 0.0 && HEAT_MAX_FRACTION <= crate::supervisor::HEATING_MIN_POWER_FRACTION
);

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
            until_ms: now_ms + (duration_s * 1000.0) as u32 as u64,
        })
    }

    /// The powers at `now_ms`: this heater's while the pulse lasts; None once it is over.
    pub fn powers(&self, now_ms: u64) -> Option<Powers> {
        if now_ms >= self.until_ms {
            return None;
        }
        Some(match self.heater {
            Heater::Pla => Powers {
                pla_w: self.power_w,
                tca_w: 0.0,
            },
            Heater::Tca => Powers {
                pla_w: 0.0,
                tca_w: self.power_w,
            },
        })
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
    }
}
