//! Heater power ↔ PWM duty conversion with a power cap, and a command watchdog.
//!
//! Both heaters are resistive loads switched by a low-side MOSFET from the supply, so the mean
//! power at duty `d` is `d · V² / R`. The controller thinks in watts; the conversion here is the
//! single place that clamps to each heater's safe maximum.

/// Lowest supply voltage in volts for which a duty is computed; below it (brown-out, supply
/// unplugged, a bad reading) the heater is switched off rather than driven at full duty.
pub const MIN_SUPPLY_V: f32 = 1.0;

/// Electrical limits of one heater.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeaterConfig {
    /// Heater resistance in ohms.
    pub resistance_ohm: f32,
    /// Largest mean power ever commanded, in watts.
    pub max_power_w: f32,
}

impl HeaterConfig {
    /// The TCA, Joule heated through its silver-coated nylon: 6.5 Ω, the middle of the 5–8 Ω
    /// estimated for the seed actuator. 2.0 W at most keeps it under about 130 °C when
    /// submerged, below where the nylon's twist relaxes for good.
    pub const TCA: HeaterConfig = HeaterConfig {
        resistance_ohm: 6.5,
        max_power_w: 2.0,
    };

    /// The PLA rod's nichrome wrap: about 0.22 m of 0.1 mm Ni80 wire at 138 Ω/m ≈ 30 Ω.
    /// 5.0 W at most, a margin over the paper's 4 W softening phase.
    pub const PLA: HeaterConfig = HeaterConfig {
        resistance_ohm: 30.0,
        max_power_w: 5.0,
    };

    /// PWM duty in [0, 1] that delivers `power_w` from `supply_v` volts: `P·R/V²` with the
    /// power first clamped to [0, `max_power_w`] and the duty to 1 (a low supply gives less
    /// than asked, never more). Returns 0 for non-finite inputs, negative power, a supply
    /// ≤ [`MIN_SUPPLY_V`] or an invalid configuration, so every doubtful case means "off".
    pub fn duty(&self, power_w: f32, supply_v: f32) -> f32 {
        let valid = power_w.is_finite()
            && supply_v.is_finite()
            && supply_v > MIN_SUPPLY_V
            && power_w >= 0.0
            && self.resistance_ohm.is_finite()
            && self.resistance_ohm > 0.0
            && self.max_power_w.is_finite()
            && self.max_power_w > 0.0;
        if !valid {
            return 0.0;
        }
        let power_w = power_w.min(self.max_power_w);
        let duty = power_w * self.resistance_ohm / (supply_v * supply_v);
        if duty.is_finite() {
            duty.clamp(0.0, 1.0)
        } else {
            0.0
        }
    }

    /// Mean power in watts delivered at `duty` (clamped to [0, 1]) from `supply_v` volts:
    /// `d·V²/R`, what the supervisor's expectation is fed (a duty clamped at 1 delivers less
    /// than was asked). Returns 0 for non-finite inputs, a non-positive supply or an invalid
    /// resistance. Not capped: it reports what the hardware would do (e.g. a stuck MOSFET).
    pub fn power_w(&self, duty: f32, supply_v: f32) -> f32 {
        let valid = duty.is_finite()
            && supply_v.is_finite()
            && supply_v > 0.0
            && self.resistance_ohm.is_finite()
            && self.resistance_ohm > 0.0;
        if !valid {
            return 0.0;
        }
        duty.clamp(0.0, 1.0) * supply_v * supply_v / self.resistance_ohm
    }
}

// The paper's 4 W PLA softening phase must fit under the PLA cap, and the TCA estimate must stay
// within the 5–8 Ω estimated for the seed actuator; checked at compile time.
const _: () = assert!(HeaterConfig::PLA.max_power_w >= 4.0);
const _: () =
    assert!(HeaterConfig::TCA.resistance_ohm >= 5.0 && HeaterConfig::TCA.resistance_ohm <= 8.0);

/// Holds the last commanded duty and drops it to 0 when the controller stops refreshing it,
/// so a stalled or crashed control loop cannot leave a heater on.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CommandWatchdog {
    max_age_ms: u64,
    last: Option<(u64, f32)>,
}

impl Default for CommandWatchdog {
    fn default() -> Self {
        Self::new(Self::DEFAULT_MAX_AGE_MS)
    }
}

impl CommandWatchdog {
    /// Longest a duty command stays valid, in ms. Klipper forces a heater off when its command
    /// is not refreshed within 3 s; our heaters have ~1–3 s time constants, so we allow 1 s,
    /// i.e. 10 missed control ticks at 10 Hz.
    pub const DEFAULT_MAX_AGE_MS: u64 = 1000;

    /// A watchdog with no command yet (duty 0) whose commands expire after `max_age_ms`.
    pub const fn new(max_age_ms: u64) -> Self {
        CommandWatchdog {
            max_age_ms,
            last: None,
        }
    }

    /// Records `duty` (clamped to [0, 1]; non-finite means 0) as commanded at `now_ms`.
    pub fn refresh(&mut self, now_ms: u64, duty: f32) {
        let duty = if duty.is_finite() {
            duty.clamp(0.0, 1.0)
        } else {
            0.0
        };
        self.last = Some((now_ms, duty));
    }

    /// The duty to apply at `now_ms`: the last command if it is at most `max_age_ms` old,
    /// otherwise 0. Also 0 if nothing was ever commanded, or if `now_ms` is before the command
    /// (a clock that ran backwards is not to be trusted).
    pub fn duty(&self, now_ms: u64) -> f32 {
        match self.last {
            Some((at_ms, duty)) if now_ms >= at_ms && now_ms - at_ms <= self.max_age_ms => duty,
            _ => 0.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use proptest::prelude::*;

    #[test]
    fn defaults_match_their_derivation() {
        // 0.22 m of 0.1 mm Ni80 at 138 Ω/m.
        assert!((0.22 * 138.0 - HeaterConfig::PLA.resistance_ohm).abs() < 1.0);
    }

    #[test]
    fn duty_formula() {
        let tca = HeaterConfig::TCA;
        // 1 W into 6.5 Ω from 12 V: 6.5 / 144.
        assert!((tca.duty(1.0, 12.0) - 6.5 / 144.0).abs() < 1e-7);
        // Capped at 2 W.
        assert!((tca.duty(10.0, 12.0) - 13.0 / 144.0).abs() < 1e-7);
        // A 5 V supply gives at most 5²/30 = 0.83 W into 30 Ω, so asking 2 W saturates at 1.
        assert_eq!(HeaterConfig::PLA.duty(2.0, 5.0), 1.0);
        assert_eq!(tca.duty(0.0, 12.0), 0.0);
        let back = tca.power_w(tca.duty(1.5, 9.0), 9.0);
        assert!((back - 1.5).abs() < 1e-5);
    }

    #[test]
    fn doubtful_inputs_mean_off() {
        let tca = HeaterConfig::TCA;
        for (p, v) in [
            (f32::NAN, 12.0),
            (1.0, f32::NAN),
            (f32::INFINITY, 12.0),
            (1.0, f32::INFINITY),
            (-1.0, 12.0),
            (1.0, 1.0),
            (1.0, 0.5),
            (1.0, -12.0),
        ] {
            assert_eq!(tca.duty(p, v), 0.0, "{p} W {v} V");
        }
        let broken = HeaterConfig {
            resistance_ohm: 0.0,
            max_power_w: 2.0,
        };
        assert_eq!(broken.duty(1.0, 12.0), 0.0);
        assert_eq!(broken.power_w(1.0, 12.0), 0.0);
        let uncapped = HeaterConfig {
            resistance_ohm: 6.5,
            max_power_w: f32::NAN,
        };
        assert_eq!(uncapped.duty(1.0, 12.0), 0.0);
        assert_eq!(tca.power_w(f32::NAN, 12.0), 0.0);
        assert_eq!(tca.power_w(2.0, 5.0), 25.0 / 6.5); // duty clamped to 1
    }

    #[test]
    fn watchdog_expires_stale_commands() {
        let mut wd = CommandWatchdog::default();
        assert_eq!(wd.duty(0), 0.0);
        wd.refresh(5_000, 0.4);
        assert_eq!(wd.duty(5_000), 0.4);
        assert_eq!(wd.duty(6_000), 0.4);
        assert_eq!(wd.duty(6_001), 0.0);
        assert_eq!(wd.duty(4_999), 0.0); // clock went backwards
        wd.refresh(6_500, 2.0);
        assert_eq!(wd.duty(6_600), 1.0);
        wd.refresh(6_600, f32::NAN);
        assert_eq!(wd.duty(6_600), 0.0);
        let mut wd = CommandWatchdog::new(100);
        wd.refresh(u64::MAX - 10, 0.5);
        assert_eq!(wd.duty(u64::MAX), 0.5);
    }

    fn any_f32() -> impl Strategy<Value = f32> {
        prop_oneof![
            4 => -20f32..50.0,
            1 => proptest::num::f32::ANY,
        ]
    }

    proptest! {
        #[test]
        fn duty_in_range_and_within_cap(
            power_w in any_f32(),
            supply_v in any_f32(),
            resistance_ohm in 0.1f32..100.0,
            max_power_w in 0.1f32..20.0,
        ) {
            let cfg = HeaterConfig { resistance_ohm, max_power_w };
            let duty = cfg.duty(power_w, supply_v);
            prop_assert!((0.0..=1.0).contains(&duty), "duty {}", duty);
            let delivered = cfg.power_w(duty, supply_v);
            prop_assert!(delivered <= max_power_w * (1.0 + 1e-5), "{} W", delivered);
            if power_w >= 0.0 && power_w.is_finite() && supply_v > 1.0 && supply_v < 1e6 {
                // Never less than asked unless capped or supply-limited (absolute slack for
                // subnormal requests).
                let want = power_w.min(max_power_w);
                let possible = cfg.power_w(1.0, supply_v);
                prop_assert!(delivered >= want.min(possible) * (1.0 - 1e-5) - 1e-30);
            }
        }

        #[test]
        fn default_heaters_never_exceed_cap(power_w in any_f32(), supply_v in any_f32()) {
            for cfg in [HeaterConfig::TCA, HeaterConfig::PLA] {
                let duty = cfg.duty(power_w, supply_v);
                prop_assert!((0.0..=1.0).contains(&duty));
                prop_assert!(cfg.power_w(duty, supply_v) <= cfg.max_power_w * (1.0 + 1e-5));
            }
        }

        #[test]
        fn watchdog_duty_is_last_fresh_command(
            steps in prop::collection::vec((0u64..1500, any::<bool>(), any_f32()), 0..50),
        ) {
            let mut wd = CommandWatchdog::default();
            let mut now = 0u64;
            let mut last: Option<(u64, f32)> = None;
            for (dt, refresh, duty) in steps {
                now += dt;
                if refresh {
                    wd.refresh(now, duty);
                    let clamped = if duty.is_finite() { duty.clamp(0.0, 1.0) } else { 0.0 };
                    last = Some((now, clamped));
                }
                let want = match last {
                    Some((at, d)) if now - at <= CommandWatchdog::DEFAULT_MAX_AGE_MS => d,
                    _ => 0.0,
                };
                let got = wd.duty(now);
                prop_assert!((0.0..=1.0).contains(&got));
                prop_assert_eq!(got, want);
            }
        }
    }
}
