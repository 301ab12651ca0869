//! What the temperature limits protect: the PLA rod and the TCA, not the thermistor beads
//! beside them.
//!
//! A bead embedded in the silicone beside its heater reads only a share of the heater's rise
//! above the surroundings (the rest drops across the silicone between them), so a bead held at
//! 110 °C can sit beside a rod at 138 °C. Each heated part's temperature is estimated from its
//! bead as `ambient + (bead − ambient) / share` ([`estimate_c`]); the supervisor trips
//! over-temperature when an estimate passes its part's limit, and the controller holds every
//! activity's heater at its keep-alive power while the estimate is above the part's ceiling
//! (the limit less [`CEILING_MARGIN_K`]), so a healthy link is stopped short of the trip.
//!
//! The share is [`UNTUNED_BEAD_SHARE`] unless `TUNE` measured a lower one
//! ([`limit_shares`]). Why the fit may lower it but never raise it, and the measurements behind
//! the number: docs/safety.md, "The parts' limits" (`cargo xtask limits`).

use crate::calibration::Calibration;
use crate::vocab::Heater;

/// The least share of its heater's rise above the surroundings a bead is taken to read, 1:
/// the estimate of a part divides its bead's rise by it. Beads of the high-fidelity ensemble
/// read 0.72–0.93 of their heater's mean rise once it is steady (the PLA's least, water), and
/// less while the heater rises fast; the lumped link's read all of it. 0.7 keeps the estimate
/// at or above the steady part on every link measured (`cargo xtask limits`).
pub const UNTUNED_BEAD_SHARE: f32 = 0.7;
/// The least share [`limit_shares`] takes from a fit, 1: the fitted rises are held to at
/// least this share of the model's (`calibration::RISE_MIN_SHARE`).
pub const FIT_MIN_SHARE: f32 = crate::calibration::RISE_MIN_SHARE;
const _: () = assert!(FIT_MIN_SHARE > 0.0 && FIT_MIN_SHARE < UNTUNED_BEAD_SHARE);
const _: () = assert!(UNTUNED_BEAD_SHARE > 0.0 && UNTUNED_BEAD_SHARE <= 1.0);
/// How far below its part's limit the ceiling sits, K: while a part's estimate is above
/// `limit − CEILING_MARGIN_K` its heater gets only the keep-alive power, whatever the activity
/// asks. The margin covers what a part gains after the cut: the heat in the wrap and the bead's
/// lag (the hifi PLA bead, 10 s behind its rod, keeps rising a few kelvin).
pub const CEILING_MARGIN_K: f32 = 15.0;
const _: () = assert!(CEILING_MARGIN_K >= 5.0 && CEILING_MARGIN_K <= 30.0);
/// The ambient the estimate assumes while the ambient thermistor has no good reading, °C: the
/// coldest bath the supervisor allows (`AMB_LIMITS`), the largest rise any reading can mean.
pub const AMB_FALLBACK_C: f32 = 2.0;

/// The estimate of a heated part's temperature from its bead's reading `bead_c` and the
/// ambient `amb_c` (°C) for a bead that reads `share` of the part's rise, °C. A bead at or
/// below ambient is its part's temperature; a non-finite reading stays non-finite.
pub fn estimate_c(bead_c: f32, amb_c: f32, share: f32) -> f32 {
    let amb = if amb_c.is_finite() {
        amb_c
    } else {
        AMB_FALLBACK_C
    };
    let share = if share.is_finite() {
        share.clamp(FIT_MIN_SHARE, 1.0)
    } else {
        UNTUNED_BEAD_SHARE
    };
    if bead_c > amb {
        amb + (bead_c - amb) / share
    } else {
        bead_c
    }
}

/// The shares the estimates use (PLA, TCA): [`UNTUNED_BEAD_SHARE`], or the fitted share of
/// `cal` where it is lower. A fitted share is the bead's rise over the model's, so it mixes
/// the bead's share with the model's error: on a link that cools less than the model it reads
/// high, and it may only make the estimate stricter.
pub fn limit_shares(cal: &Calibration) -> [f32; 2] {
    Heater::ALL.map(|h| cal.sensor_gain(h).clamp(FIT_MIN_SHARE, UNTUNED_BEAD_SHARE))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bead_below_its_part_is_lifted_by_its_share() {
        assert!((estimate_c(92.0, 22.0, 0.7) - 122.0).abs() < 1e-4);
        assert_eq!(estimate_c(20.0, 22.0, 0.7), 20.0);
        assert!(estimate_c(f32::NAN, 22.0, 0.7).is_nan());
        // No ambient: the coldest allowed bath, the largest rise.
        assert!(estimate_c(72.0, f32::NAN, 0.7) > estimate_c(72.0, 22.0, 0.7));
        // A share outside 0.3..1 is clamped: never a part colder than its bead.
        assert_eq!(estimate_c(80.0, 22.0, 2.0), 80.0);
    }

    #[test]
    fn a_fit_only_lowers_the_share() {
        let mut cal = Calibration::DEFAULT;
        assert_eq!(limit_shares(&cal), [UNTUNED_BEAD_SHARE; 2]);
        cal.pla_rise_k_per_w *= 0.5;
        cal.tca_rise_k_per_w *= 1.4;
        let s = limit_shares(&cal);
        assert!((s[0] - 0.5).abs() < 1e-3, "{s:?}");
        assert_eq!(s[1], UNTUNED_BEAD_SHARE);
    }
}
