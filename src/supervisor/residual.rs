//! The residual tests on the one expectation (`expect`): how far a reading lies outside the
//! family's hull, accumulated by a one-sided CUSUM (Page's test) per side.
//!
//! Each side sums `residual − RESIDUAL_SLACK_K` over time, never below zero, and trips when the
//! sum passes [`CUSUM_LIMIT_K_S`]. The slack is what a healthy link may stray outside the hull
//! (noise, the model's transients) without ever adding up; past it, the detection delay is a
//! design number: a reading that stands `d` K beyond the slack trips after
//! `CUSUM_LIMIT_K_S / d` s, and one drifting away from the hull's edge at `r` K/s after
//! `RESIDUAL_SLACK_K / r + sqrt(2 CUSUM_LIMIT_K_S / r)` s ([`drift_delay_s`]).
//!
//! The floor is the must-rise test while the heater's own heat is in it and the ceiling the
//! must-not-rise test (a heater off or turned down, the heat an ABORT left); together they
//! keep every reading in the envelope whatever runs.

/// What a healthy reading may stray outside the hull without adding up, K: 20 times the beads'
/// noise, and the largest healthy excursion measured over the high-fidelity ensemble with
/// margin (docs/safety.md, "The expectation").
pub const RESIDUAL_SLACK_K: f32 = 2.0;
const _: () = assert!(RESIDUAL_SLACK_K > 0.5 && RESIDUAL_SLACK_K < 10.0);
/// The sum of a side's residual beyond the slack at which it trips, K·s: 4 K beyond the slack
/// for 2 s, 8 K beyond it for 1 s.
pub const CUSUM_LIMIT_K_S: f32 = 8.0;
const _: () = assert!(CUSUM_LIMIT_K_S > 0.0 && CUSUM_LIMIT_K_S <= 100.0);

/// The change test's slack: how much faster than the fastest member a healthy reading may
/// fall or rise without adding up, K/s (the model's transients against the high-fidelity
/// beads', measured over its ensemble: docs/safety.md, "The expectation").
pub const CHANGE_SLACK_K_PER_S: f32 = 0.1;
const _: () = assert!(CHANGE_SLACK_K_PER_S > 0.0 && CHANGE_SLACK_K_PER_S < 5.0);
/// How far a reading may fall (or rise) beyond the fastest member's change, less the slack,
/// before the change test trips, K: the sum of changes telescopes, so the readings' noise
/// enters it once, smoothed ([`CHANGE_SMOOTH_S`]) to a few hundredths of a kelvin.
pub const CHANGE_LIMIT_K: f32 = 1.5;
const _: () = assert!(CHANGE_LIMIT_K > 0.5 && CHANGE_LIMIT_K < 20.0);
/// The change test averages each step's excess change over this time constant, s: the beads'
/// noise (up to 0.2 K rms a reading) averaged over 20 readings, at a second's delay.
pub const CHANGE_SMOOTH_S: f32 = 1.0;
const _: () = assert!(CHANGE_SMOOTH_S > 0.0 && CHANGE_SMOOTH_S <= 3.0);

/// The detection delay of a reading drifting away from the hull's edge at `rate_k_per_s`, s:
/// the design number of the drift aim (`rate² t² / 2` beyond the slack's time adds up to the
/// limit).
pub fn drift_delay_s(rate_k_per_s: f32) -> f32 {
    use crate::mathf::{exp, ln};
    let root = |x: f32| exp(0.5 * ln(x));
    RESIDUAL_SLACK_K / rate_k_per_s + root(2.0 * CUSUM_LIMIT_K_S / rate_k_per_s)
}

/// One side of one channel: the running sum, K·s.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Cusum {
    sum_k_s: f32,
}

impl Cusum {
    /// Adds `dt_s` of `residual_k` (K beyond the hull; negative inside): whether the sum has
    /// passed the limit. A residual that is not a number adds nothing.
    pub fn update(&mut self, dt_s: f32, residual_k: f32) -> bool {
        if residual_k.is_finite() {
            self.sum_k_s = (self.sum_k_s + dt_s * (residual_k - RESIDUAL_SLACK_K)).max(0.0);
        }
        self.sum_k_s > CUSUM_LIMIT_K_S
    }

    /// The sum's share of the limit, 1 (how close a healthy run came).
    pub fn share(&self) -> f32 {
        self.sum_k_s / CUSUM_LIMIT_K_S
    }
}

/// Which side of the hull a channel left.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// Below the floor: colder than every member (a heater that does not heat, a bead drifting
    /// down or off its heater).
    Below,
    /// Above the ceiling: warmer than every member (a heater on that nothing commands, a bead
    /// drifting up).
    Above,
}

/// The change test of one channel: a CUSUM per side of how much further the reading moved
/// than the member that moved furthest that way, anchored at the reading (so the hull's width
/// does not hide it): a heater that dies under a held power loses its bead's rise at several
/// K/s while every member holds; one stuck on lifts it while every member falls.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Change {
    last_k: Option<f32>,
    /// This step's excess fall and rise, averaged ([`CHANGE_SMOOTH_S`]), K per step.
    excess_k: [f32; 2],
    fall_k: f32,
    rise_k: f32,
}

impl Change {
    /// Judges the reading `y_k` (K above ambient) over `dt_s` against the members' least and
    /// greatest change `(fall, rise)` (K) over the same step.
    pub fn update(&mut self, dt_s: f32, y_k: f32, (fall, rise): (f32, f32)) -> Option<Side> {
        if !y_k.is_finite() {
            self.last_k = None;
            return None;
        }
        let last = self.last_k.replace(y_k)?;
        let d_k = y_k - last;
        // The excess is averaged, not the reading alone: a change every member and the reading
        // share (the ambient reading's) then cancels whatever its pace.
        let share = crate::mathf::clamp(dt_s / CHANGE_SMOOTH_S, 0.0, 1.0);
        for (e, now) in self.excess_k.iter_mut().zip([fall - d_k, d_k - rise]) {
            *e += (now - *e) * share;
        }
        let slack_k = CHANGE_SLACK_K_PER_S * dt_s;
        self.fall_k = (self.fall_k + self.excess_k[0] - slack_k).max(0.0);
        self.rise_k = (self.rise_k + self.excess_k[1] - slack_k).max(0.0);
        if self.fall_k > CHANGE_LIMIT_K {
            Some(Side::Below)
        } else if self.rise_k > CHANGE_LIMIT_K {
            Some(Side::Above)
        } else {
            None
        }
    }

    /// The fuller side's share of the limit, 1.
    pub fn share(&self) -> f32 {
        self.fall_k.max(self.rise_k) / CHANGE_LIMIT_K
    }

    /// How far the reading has moved beyond every member on `side`, less the slack, K.
    pub fn sum_k(&self, side: Side) -> f32 {
        match side {
            Side::Below => self.fall_k,
            Side::Above => self.rise_k,
        }
    }
}

/// Both sides of one channel.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Envelope {
    below: Cusum,
    above: Cusum,
    /// The reading stands beyond the ceiling's slack now (RESET waits until it does not).
    pub above_now: bool,
}

impl Envelope {
    /// Judges one reading `y_k` against the hull `(floor, ceiling)` (K above the ambient
    /// reading) over `dt_s`: the side that has added up to the limit, if any.
    pub fn update(
        &mut self,
        dt_s: f32,
        y_k: f32,
        (floor_k, ceiling_k): (f32, f32),
    ) -> Option<Side> {
        self.above_now = y_k - ceiling_k > RESIDUAL_SLACK_K;
        if self.below.update(dt_s, floor_k - y_k) {
            return Some(Side::Below);
        }
        if self.above.update(dt_s, y_k - ceiling_k) {
            return Some(Side::Above);
        }
        None
    }

    /// The fuller side's share of the limit, 1.
    pub fn share(&self) -> f32 {
        self.below.share().max(self.above.share())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Seconds until a residual `r(t)` (K beyond the hull) trips, at 0.1 s ticks.
    fn trip_s(r: impl Fn(f32) -> f32) -> Option<f32> {
        let mut c = Cusum::default();
        (0..6000)
            .map(|i| i as f32 / 10.0)
            .find(|&t| c.update(0.1, r(t)))
    }

    #[test]
    fn a_step_beyond_the_slack_trips_after_its_design_delay_and_one_within_never_does() {
        let d = 4.0;
        let t = trip_s(|_| RESIDUAL_SLACK_K + d).unwrap();
        assert!((t - CUSUM_LIMIT_K_S / d).abs() <= 0.2, "{t}");
        assert_eq!(trip_s(|_| RESIDUAL_SLACK_K - 0.01), None);
        // Noise of 20 × the slack's reach, alternating, never adds up.
        assert_eq!(
            trip_s(|t| if ((t * 10.0) as u32).is_multiple_of(2) {
                8.0
            } else {
                -8.0
            }),
            None
        );
    }

    #[test]
    fn a_drift_from_the_edge_trips_at_its_design_delay() {
        let t = trip_s(|t| 0.2 * t).unwrap();
        assert!(
            (t - drift_delay_s(0.2)).abs() <= 0.5,
            "{t} vs {}",
            drift_delay_s(0.2)
        );
    }

    #[test]
    fn a_reading_inside_the_hull_empties_the_sum() {
        let mut e = Envelope::default();
        for _ in 0..20 {
            assert_eq!(e.update(0.1, 10.0, (0.0, 5.0)), None);
        }
        assert!(e.above_now && e.share() > 0.0);
        for _ in 0..100 {
            e.update(0.1, 3.0, (0.0, 5.0));
        }
        assert_eq!(e.share(), 0.0);
        assert!(!e.above_now);
    }
}
