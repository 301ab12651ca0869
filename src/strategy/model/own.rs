//! The TCA's own temperature as `closed` bends on it, where the board senses current: the
//! resistance's temperature ([`crate::electrical::Electrical::tca_self_c`]) smoothed against the
//! shunt's noise, and its rate. It reads the TCA itself, not a bead beside it: no lag to wait
//! for, and no share of the rise that differs from link to link (docs/strategies.md, "Bending
//! on the TCA's own temperature").

use crate::lumped::lag_remaining;

/// The smoothing lags of the own temperature, s: the first is the temperature `closed` bends
/// on (the shunt's noise, up to 1 K a tick after the resistance's own filter, averaged over
/// fifteen ticks: some 0.15 K left; at 0.5 s the noise that passed into the TCA's power tripped
/// `sensor-frozen` on a healthy hifi link); the difference of the other two, over theirs, is
/// its rate (a 5 s difference, so the noise leaves some 0.02 K/s of it). Still half the
/// thermistor's 3 s lag, with no bead between.
pub const OWN_SMOOTH_S: [f32; 3] = [1.5, 3.0, 8.0];
const _: () = assert!(
    OWN_SMOOTH_S[0] > 0.0 && OWN_SMOOTH_S[1] > OWN_SMOOTH_S[0] && OWN_SMOOTH_S[2] > OWN_SMOOTH_S[1]
);

/// Bend ends only once the own temperature changes slower than this, K/s: the TCA has settled
/// at its target and the rod has stopped moving (a bend that still flows strains the coil,
/// which moves its resistance). Half the thermistor view's learning rate
/// ([`super::observer::LEARN_MAX_RATE_K_PER_S`]): 0.1 K/s added 5 s to the hifi links' bend
/// for no accuracy (`cargo xtask calibration --self-bend`).
pub const OWN_STILL_K_PER_S: f32 = 0.3;
const _: () = assert!(
    OWN_STILL_K_PER_S > 0.0 && OWN_STILL_K_PER_S <= super::observer::LEARN_MAX_RATE_K_PER_S
);

/// The TCA's own temperature, smoothed, °C, and when it was last fed.
#[derive(Clone, Copy, Debug)]
pub struct OwnTemp {
    smooth_c: [f32; 3],
    last_ms: u64,
}

impl OwnTemp {
    /// From the own temperature `temp_c` at `now_ms` (°C), or None where it is not known.
    pub fn new(now_ms: u64, temp_c: f32) -> Option<Self> {
        temp_c.is_finite().then_some(OwnTemp {
            smooth_c: [temp_c; 3],
            last_ms: now_ms,
        })
    }

    /// Feeds this tick's own temperature (°C; a tick without one changes nothing).
    pub fn update(&mut self, now_ms: u64, temp_c: f32) {
        if !temp_c.is_finite() {
            return;
        }
        let dt_s = now_ms.saturating_sub(self.last_ms) as f32 / 1000.0;
        self.last_ms = now_ms;
        for (c, tau_s) in self.smooth_c.iter_mut().zip(OWN_SMOOTH_S) {
            *c = temp_c + (*c - temp_c) * lag_remaining(dt_s, tau_s);
        }
    }

    /// The smoothed own temperature, °C.
    pub fn temp_c(&self) -> f32 {
        self.smooth_c[0]
    }

    /// Its rate, K/s (what the two lags' difference says).
    pub fn rate_k_per_s(&self) -> f32 {
        (self.smooth_c[1] - self.smooth_c[2]) / (OWN_SMOOTH_S[2] - OWN_SMOOTH_S[1])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn it_follows_a_step_within_seconds_and_its_rate_falls_to_zero_once_still() {
        assert!(OwnTemp::new(0, f32::NAN).is_none());
        let mut o = OwnTemp::new(0, 22.0).unwrap();
        for k in 1..=100 {
            o.update(k * 100, 60.0);
            o.update(k * 100, f32::NAN);
        }
        assert!((o.temp_c() - 60.0).abs() < 0.1, "{}", o.temp_c());
        assert!(o.rate_k_per_s() > 0.0);
        for k in 31..=600 {
            o.update(k * 100, 60.0);
        }
        assert!(o.rate_k_per_s().abs() < 0.01, "{}", o.rate_k_per_s());
        // A ramp reads as its rate once the lags have caught up.
        for k in 601..=1200 {
            o.update(k * 100, 60.0 + 0.5 * (k - 600) as f32 / 10.0);
        }
        assert!(
            (o.rate_k_per_s() - 0.5).abs() < 0.05,
            "{}",
            o.rate_k_per_s()
        );
    }
}
