//! The ideal-knowledge bound: a host-only morph policy that reads the plant's true temperatures
//! and radius (what no controller can) and drives the heaters directly, at the controller's own
//! heater caps and temperature limits. What it takes is what a perfect controller of the same
//! phase structure would take; the strategies are judged beside it.
//!
//! The policy, for a TCA hold temperature `T*`: both heaters on from the start, the PLA at its
//! cap until the rod's true mean reaches [`SOFT_THRESHOLD_C`] and then held at
//! [`PLA_SOFT_TARGET_C`], the TCA at its cap up to `T*` and then held there (bang-bang on the
//! true temperature); lock when the TCA is at `T*` and the true radius has stopped moving; the
//! PLA off and the TCA held until the rod's true mean is [`ORACLE_RIGID_C`]; then the TCA off,
//! and `done` [`RELEASE_S`] later. `T*` is found by bisection on clones of the plant so that the
//! radius [`SETTLE_AFTER_DONE_S`] after `done` is the target. It is the best of this family,
//! not a proof of optimality over every policy.

use crate::ensemble::SETTLE_AFTER_DONE_S;
use morphlink::heater::HeaterConfig;
use morphlink::strategy::model::PLA_SOFT_TARGET_C;
use morphlink::strategy::{RELEASE_S, SOFT_THRESHOLD_C};
use morphlink::supervisor::{PLA_LIMITS, TCA_LIMITS};
use morphlink_plant::{Duties, Plant};

/// Control period of the oracle, s: the controller's.
pub const ORACLE_TICK_S: f64 = 0.1;
/// The rod counts as rigid at this true mean temperature, °C: 12 K below Tg (the `closed`
/// strategy's cool-surroundings threshold, here on the true value).
pub const ORACLE_RIGID_C: f64 = 50.0;
/// The TCA counts as at its hold temperature within this band, K.
pub const ORACLE_AT_TARGET_K: f64 = 0.3;
/// The radius counts as settled in bend below this rate, mm/s, measured over
/// [`ORACLE_RATE_WINDOW`] ticks (a bang-bang hold chatters tick to tick).
pub const ORACLE_SETTLED_MM_PER_S: f64 = 0.01;
/// Ticks over which the radius and TCA rates are measured: 1 s.
pub const ORACLE_RATE_WINDOW: usize = 10;
/// A TCA at its cap that rises slower than this has gone as far as the cap allows, K/s (the
/// controller's own stall rule): it counts as at its hold temperature.
pub const ORACLE_STALL_K_PER_S: f64 = 0.05;
/// Highest TCA hold temperature tried, °C: 10 K under the supervisor's TCA limit, the margin the
/// controller's own targets keep.
pub const ORACLE_TCA_MAX_C: f64 = TCA_LIMITS.max_c as f64 - 10.0;
/// Bisection steps on `T*`: 2⁻¹⁴ of a 100 K range is under 0.01 K.
pub const ORACLE_BISECTIONS: usize = 14;
/// Longest policy run before it is called stuck, s.
pub const ORACLE_MAX_S: f64 = 900.0;

const _: () = assert!(PLA_SOFT_TARGET_C < PLA_LIMITS.max_c);

/// One run of the policy.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OracleRun {
    /// TCA hold temperature, °C.
    pub tca_hold_c: f64,
    /// Start to `done`, s (NaN if the policy got stuck).
    pub time_s: f64,
    /// Radius [`SETTLE_AFTER_DONE_S`] after `done`, mm.
    pub final_mm: f64,
    /// Hottest true PLA and TCA temperatures, °C.
    pub max_true_c: [f64; 2],
}

/// Duty that gives `power_w` from a heater that gave `last_w` at duty `last_duty` (its true
/// V²/R), at most 1.
fn duty_for(power_w: f64, last_w: f64, last_duty: f64, fallback_w_per_duty: f64) -> f64 {
    let w_per_duty = if last_duty > 1e-6 && last_w > 0.0 {
        last_w / last_duty
    } else {
        fallback_w_per_duty
    };
    (power_w / w_per_duty).clamp(0.0, 1.0)
}

/// Runs the policy with hold temperature `tca_hold_c` on `plant` (consumed).
pub fn run_policy<P: Plant>(mut plant: P, tca_hold_c: f64) -> OracleRun {
    let pla_cap = HeaterConfig::PLA.max_power_w as f64;
    let tca_cap = HeaterConfig::TCA.max_power_w as f64;
    // Nominal V²/R until a first step tells the truth.
    let v = plant.sample().supply_v;
    let nominal = [
        v * v / HeaterConfig::PLA.resistance_ohm as f64,
        v * v / HeaterConfig::TCA.resistance_ohm as f64,
    ];
    let mut duty = Duties::default();
    let mut t_s = 0.0;
    let mut soft = false;
    let mut locked = false;
    let mut released_at = None;
    // The last second of radius and TCA temperature, oldest first.
    let mut history = [(plant.sample().radius_mm, plant.truth().tca_c); ORACLE_RATE_WINDOW];
    let window_s = ORACLE_RATE_WINDOW as f64 * ORACLE_TICK_S;
    let mut max_c = [f64::NEG_INFINITY; 2];
    while t_s < ORACLE_MAX_S {
        let truth = plant.truth();
        let r = plant.sample().radius_mm;
        let (old_r, old_tca) = history[0];
        history.rotate_left(1);
        history[ORACLE_RATE_WINDOW - 1] = (r, truth.tca_c);
        let rate = (r - old_r).abs() / window_s;
        let stalled = t_s > window_s && (truth.tca_c - old_tca) / window_s < ORACLE_STALL_K_PER_S;
        max_c = [max_c[0].max(truth.pla_c), max_c[1].max(truth.tca_c)];
        if let Some(at) = released_at {
            if t_s - at >= RELEASE_S as f64 {
                break;
            }
        }
        soft |= truth.pla_c >= SOFT_THRESHOLD_C as f64;
        let at_hold = truth.tca_c >= tca_hold_c - ORACLE_AT_TARGET_K || stalled;
        if soft && !locked && at_hold && rate < ORACLE_SETTLED_MM_PER_S {
            locked = true;
        }
        if locked && released_at.is_none() && truth.pla_c <= ORACLE_RIGID_C {
            released_at = Some(t_s);
        }
        let pla_w = if locked || truth.pla_c >= PLA_SOFT_TARGET_C as f64 {
            0.0
        } else {
            pla_cap
        };
        let tca_w = if released_at.is_some() || truth.tca_c >= tca_hold_c {
            0.0
        } else {
            tca_cap
        };
        duty = Duties {
            pla: duty_for(pla_w, truth.pla_w, duty.pla, nominal[0]),
            tca: duty_for(tca_w, truth.tca_w, duty.tca, nominal[1]),
        };
        plant.step(ORACLE_TICK_S, duty);
        t_s += ORACLE_TICK_S;
    }
    let done = released_at.is_some() && t_s < ORACLE_MAX_S;
    let mut settle = 0.0;
    while settle < SETTLE_AFTER_DONE_S {
        plant.step(ORACLE_TICK_S, Duties::default());
        settle += ORACLE_TICK_S;
    }
    OracleRun {
        tca_hold_c,
        time_s: if done { t_s } else { f64::NAN },
        final_mm: plant.sample().radius_mm,
        max_true_c: max_c,
    }
}

/// The ideal-knowledge morph to `target_mm` on `plant`: the hold temperature found by bisection
/// (the final radius falls as `T*` rises). `None` if the target is out of the policy's reach
/// (tighter than the hottest hold gives, or looser than the link at rest).
pub fn best<P: Plant + Clone>(plant: &P, target_mm: f64) -> Option<OracleRun> {
    let ambient = plant.sample().t_amb_c;
    // At a hold of the ambient the TCA is never heated: the loosest the policy goes.
    let (mut lo, mut hi) = (ambient, ORACLE_TCA_MAX_C);
    let hot = run_policy(plant.clone(), hi);
    if hot.time_s.is_nan() || hot.final_mm > target_mm {
        return None;
    }
    // Above what the TCA reaches at its cap every hold is the same: start from there.
    hi = hi.min(hot.max_true_c[1] + ORACLE_AT_TARGET_K);
    let cold = run_policy(plant.clone(), lo);
    if cold.final_mm < target_mm {
        return None;
    }
    let mut best = hot;
    for _ in 0..ORACLE_BISECTIONS {
        let mid = 0.5 * (lo + hi);
        let run = run_policy(plant.clone(), mid);
        if run.final_mm > target_mm {
            lo = mid;
        } else {
            hi = mid;
            best = run;
        }
    }
    Some(best)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::LinkSetup;

    #[test]
    fn the_oracle_hits_the_target_within_limits_and_beats_the_fixed_timing() {
        let plant = LinkSetup::NOMINAL.lumped();
        let run = best(&plant, 38.0).expect("38 mm is reachable");
        assert!((run.final_mm - 38.0).abs() < 0.1, "{run:?}");
        assert!(run.max_true_c[1] <= ORACLE_TCA_MAX_C + 1.0, "{run:?}");
        // The paper's fixed timing takes 120 s; perfect knowledge at the same caps is faster.
        assert!(run.time_s > 5.0 && run.time_s < 120.0, "{run:?}");
    }

    #[test]
    fn a_target_out_of_reach_is_refused() {
        let plant = LinkSetup::NOMINAL.lumped();
        assert!(best(&plant, 5.0).is_none());
    }
}
