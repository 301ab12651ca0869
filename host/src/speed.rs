//! The simulated link's speed, a factor of real time (`morph-sim --speed`, `morphctl
//! --sim-speed` and `--tcp-speed`): one range and one check for every tool that paces by it.

use std::ops::RangeInclusive;

/// Speed factors a tool accepts: from a thousandth of real time (a 25 s morph in about 7
/// hours, slow enough to watch any tick) to a million times faster (`max` runs unpaced). Outside
/// it the pacing's durations stop meaning anything (1e-30 overflowed a `Duration`).
pub const SPEED_RANGE: RangeInclusive<f64> = 1e-3..=1e6;

/// `speed` if it is a number in [`SPEED_RANGE`], else an error that names the range and what
/// `flag` was given.
pub fn check(flag: &str, speed: f64) -> Result<f64, String> {
    if SPEED_RANGE.contains(&speed) {
        Ok(speed)
    } else {
        Err(format!(
            "{flag} must be a factor of real time from {} to {} (or `max` for morph-sim), not {speed}",
            SPEED_RANGE.start(),
            SPEED_RANGE.end()
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_range_ends_pass_and_nonsense_is_refused() {
        assert_eq!(check("--speed", 1e-3), Ok(1e-3));
        assert_eq!(check("--speed", 1e6), Ok(1e6));
        for bad in [0.0, -1.0, 1e-30, 1e30, f64::NAN, f64::INFINITY] {
            let e = check("--speed", bad).unwrap_err();
            assert!(e.starts_with("--speed must be a factor"), "{e}");
        }
    }
}
