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
//! The share is [`UNTUNED_BEAD_SHARES`]' unless `TUNE` measured a lower one
//! ([`limit_shares`]). Why the fit may lower it but never raise it, and the measurements behind
//! the number: docs/safety.md, "The parts' limits" (`cargo xtask limits`).

use crate::calibration::Calibration;
use crate::vocab::Heater;

/// The least share of its heater's rise above the surroundings each bead (PLA, TCA) is taken
/// to read, 1: the estimate of a part divides its bead's rise by it. Set under the shares the
/// high-fidelity beads read once their part is steady (`cargo xtask limits --trace`;
/// docs/safety.md, "The parts' limits").
pub const UNTUNED_BEAD_SHARES: [f32; 2] = [0.7, 0.75];
/// The least share [`limit_shares`] takes from a fit, 1: the fitted rises are held to at
/// least this share of the model's (`calibration::RISE_MIN_SHARE`).
pub const FIT_MIN_SHARE: f32 = crate::calibration::RISE_MIN_SHARE;
const _: () = assert!(FIT_MIN_SHARE > 0.0 && FIT_MIN_SHARE < UNTUNED_BEAD_SHARES[0]);
const _: () = assert!(UNTUNED_BEAD_SHARES[0] <= 1.0 && UNTUNED_BEAD_SHARES[1] <= 1.0);
const _: () = assert!(FIT_MIN_SHARE < UNTUNED_BEAD_SHARES[1]);
/// How far below its part's limit the ceiling sits, K: while a part's estimate is above
/// `limit − CEILING_MARGIN_K` its heater gets only the keep-alive power, whatever the activity
/// asks. The margin covers what a part gains after the cut: the heat in the wrap and the bead's
/// lag (the hifi PLA bead, 10 s behind its rod, keeps rising a few kelvin).
pub const CEILING_MARGIN_K: f32 = 15.0;
const _: () = assert!(CEILING_MARGIN_K >= 5.0 && CEILING_MARGIN_K <= 30.0);
/// The band below its ceiling over which a heater's power is scaled down, K: at `ceiling −
/// CEILING_BAND_K` an activity gets all it asks, at the ceiling only the keep-alive power,
/// linearly between, so a part held at its ceiling settles there on a steady power: cut and
/// restored at one temperature, the heater would dither about it and the supervisor's checks
/// would take the swings for faults (docs/safety.md, "The parts' limits").
pub const CEILING_BAND_K: f32 = 5.0;
const _: () = assert!(CEILING_BAND_K > 0.0 && CEILING_BAND_K < CEILING_MARGIN_K);
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
        crate::mathf::clamp(share, FIT_MIN_SHARE, 1.0)
    } else {
        FIT_MIN_SHARE
    };
    if bead_c > amb {
        amb + (bead_c - amb) / share
    } else {
        bead_c
    }
}

/// The shares the estimates use (PLA, TCA): [`UNTUNED_BEAD_SHARES`], or the fitted share of
/// `cal` where it is lower. A fitted share is the bead's rise over the model's, so it mixes
/// the bead's share with the model's error: on a link that cools less than the model it reads
/// high, and it may only make the estimate stricter.
pub fn limit_shares(cal: &Calibration) -> [f32; 2] {
    Heater::ALL.map(|h| {
        crate::mathf::clamp(
            cal.sensor_gain(h),
            FIT_MIN_SHARE,
            UNTUNED_BEAD_SHARES[h.index()],
        )
    })
}

/// The highest temperature a strategy's thermal model may aim `h`'s part at, °C, so that its
/// heater still gets all it asks: the model's estimate (its bead's rise over the calibrated
/// share [`Calibration::sensor_gain`]) at which this module's estimate is [`CEILING_BAND_K`]
/// under the ceiling of a part limited to `limit_c`, in surroundings at `amb_c` (°C). A target
/// above it could not be held: the ceiling would scale the heater down first.
pub fn reachable_c(cal: &Calibration, h: Heater, amb_c: f32, limit_c: f32) -> f32 {
    let amb = if amb_c.is_finite() {
        amb_c
    } else {
        AMB_FALLBACK_C
    };
    let share = limit_shares(cal)[h.index()];
    let gain = cal.sensor_gain(h).max(share);
    amb + share / gain * (limit_c - CEILING_MARGIN_K - CEILING_BAND_K - amb)
}

/// The power, W, a heater may have of the `asked_w` an activity asks while its part's estimate
/// is `est_c` under a ceiling of `ceiling_c` (°C): all of it up to [`CEILING_BAND_K`] below the
/// ceiling, then linearly less, down to `keep_alive_w` (never more than asked) at the ceiling.
pub fn under_ceiling_w(asked_w: f32, est_c: f32, ceiling_c: f32, keep_alive_w: f32) -> f32 {
    let room = (ceiling_c - est_c) / CEILING_BAND_K;
    if room >= 1.0 || !est_c.is_finite() {
        return asked_w;
    }
    let floor_w = asked_w.min(keep_alive_w);
    (asked_w * room.max(0.0)).max(floor_w)
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
    fn the_ceiling_scales_the_power_down_to_keep_alive() {
        assert_eq!(under_ceiling_w(2.0, 100.0, 115.0, 0.05), 2.0);
        assert!((under_ceiling_w(2.0, 112.5, 115.0, 0.05) - 1.0).abs() < 1e-5);
        assert_eq!(under_ceiling_w(2.0, 116.0, 115.0, 0.05), 0.05);
        assert_eq!(under_ceiling_w(0.0, 116.0, 115.0, 0.05), 0.0);
        assert_eq!(under_ceiling_w(1.0, f32::NAN, 115.0, 0.05), 1.0);
    }

    #[test]
    fn an_untuned_link_reaches_its_beads_share_of_the_ceiling() {
        let cal = Calibration::DEFAULT;
        let t = reachable_c(&cal, Heater::Pla, 22.0, 130.0);
        assert!(
            (t - (22.0
                + UNTUNED_BEAD_SHARES[0] * (130.0 - CEILING_MARGIN_K - CEILING_BAND_K - 22.0)))
                .abs()
                < 1e-3
        );
        // A bead held there has an estimate the band below the ceiling: full power.
        let est = estimate_c(t, 22.0, limit_shares(&cal)[0]);
        assert_eq!(
            under_ceiling_w(1.0, est - 1e-3, 130.0 - CEILING_MARGIN_K, 0.05),
            1.0
        );
    }

    #[test]
    fn a_fit_only_lowers_the_share() {
        let mut cal = Calibration::DEFAULT;
        assert_eq!(limit_shares(&cal), UNTUNED_BEAD_SHARES);
        cal.pla_rise_k_per_w *= 0.5;
        cal.tca_rise_k_per_w *= 1.4;
        let s = limit_shares(&cal);
        assert!((s[0] - 0.5).abs() < 1e-3, "{s:?}");
        assert_eq!(s[1], UNTUNED_BEAD_SHARES[1]);
    }
}
