//! Target TCA temperatures from the built-in mechanics, for the strategies that control
//! temperature rather than power.
//!
//! The radius follows the TCA's absolute temperature (its force grows with `T − 20 °C`), not
//! its rise above the surroundings, so a temperature target is right whatever the ambient, the
//! convection or the heater power needed to reach it. On release the glassy PLA holds the
//! curvature it froze at, but the silicone and the cold TCA still pull back a little
//! (spring-back); [`lock_temp_for_final_radius_c`] aims the lock so that the shape after
//! release is the target.

use crate::lumped::{curvature_per_m, curvature_with_extra_per_m, pla_extra_stiffness_nm2};

/// Highest TCA temperature a target may ask for, °C: 20 K under the supervisor's 130 °C limit,
/// and above every temperature the table's 1.5 W reaches (about 86 °C in 30 °C water).
pub const TARGET_MAX_C: f32 = 110.0;
/// Bisection steps of the inversion: the bracket is under 110 K wide, so 30 steps narrow it to
/// 1e-7 K, below the resolution of an `f32` temperature (some 8e-6 K at 100 °C), where it
/// stops.
const BISECT_STEPS: usize = 30;
// 20 K under the supervisor's limit, as claimed above.
const _: () = assert!(TARGET_MAX_C + 20.0 <= crate::supervisor::TCA_LIMITS.max_c);
// Above the steady TCA temperature of the table's largest power with the PLA at hold power in
// 30 °C water (the lumped resistances), so no table radius is out of the targets' reach.
const _: () = assert!(
    30.0 + crate::link::R_TT_K_PER_W * crate::table::MAX_POWER_W
        + crate::link::R_TP_K_PER_W * crate::link::HOLD_POWER_W
        < TARGET_MAX_C
);

/// Curvature after release, 1/m, of a link that froze at curvature `lock_per_m` and whose TCA
/// and PLA have cooled to `ambient_c` (°C).
pub fn released_curvature_per_m(lock_per_m: f32, ambient_c: f32) -> f32 {
    let extra = pla_extra_stiffness_nm2(ambient_c);
    curvature_with_extra_per_m(ambient_c, extra, lock_per_m)
}

/// TCA temperature, °C, at which the soft link bends to `radius_mm` (no spring-back).
pub fn tca_temp_for_radius_c(radius_mm: f32) -> f32 {
    temp_for_curvature_c(1e3 / radius_mm)
}

/// TCA temperature, °C, to hold while the PLA freezes so that the link ends at `radius_mm`
/// after release into surroundings at `ambient_c` (°C): the spring-back compensated target.
pub fn lock_temp_for_final_radius_c(radius_mm: f32, ambient_c: f32) -> f32 {
    let want = 1e3 / radius_mm;
    let amb = ambient_c;
    // The released curvature is linear in the frozen one: solve a + b·κ_lock = want.
    let a = released_curvature_per_m(0.0, amb);
    let b = released_curvature_per_m(1.0, amb) - a;
    if !(b.abs() > 1e-12) {
        return temp_for_curvature_c(want);
    }
    temp_for_curvature_c((want - a) / b)
}

/// Radius after release, mm, for a lock at TCA temperature `lock_tca_c` into surroundings at
/// `ambient_c` (°C): the estimate reported with `done`.
pub fn final_radius_mm(lock_tca_c: f32, ambient_c: f32) -> f32 {
    let lock = curvature_per_m(lock_tca_c);
    1e3 / released_curvature_per_m(lock, ambient_c)
}

/// The estimate's TCA temperature, °C, to aim at so that the link is at `need_c` (°C), through
/// this link's measured map `(a, b)` ([`crate::calibration::Calibration::map`]: the needed rise
/// above `ambient_c` is `a + b ×` the estimate's), at most [`TARGET_MAX_C`].
pub fn calibrated_aim_c(map: (f32, f32), need_c: f32, ambient_c: f32) -> f32 {
    let (a, b) = map;
    let aim = ambient_c + (need_c - ambient_c - a) / b;
    if aim.is_finite() {
        aim.min(TARGET_MAX_C)
    } else {
        need_c
    }
}

/// Radius after release, mm, for a lock at the estimate's TCA temperature `estimate_c` (°C),
/// through this link's map `(a, b)` (see [`calibrated_aim_c`]).
pub fn calibrated_final_radius_mm(map: (f32, f32), estimate_c: f32, ambient_c: f32) -> f32 {
    let (a, b) = map;
    final_radius_mm(ambient_c + a + b * (estimate_c - ambient_c), ambient_c)
}

/// TCA temperature, °C, at which the soft link has curvature `kappa_per_m`, clamped to
/// [0 °C, [`TARGET_MAX_C`]] (curvature grows with temperature over that range).
fn temp_for_curvature_c(kappa_per_m: f32) -> f32 {
    let (mut lo, mut hi) = (0.0f32, TARGET_MAX_C);
    if !kappa_per_m.is_finite() || curvature_per_m(lo) >= kappa_per_m {
        return lo;
    }
    if curvature_per_m(hi) <= kappa_per_m {
        return hi;
    }
    for _ in 0..BISECT_STEPS {
        let mid = 0.5 * (lo + hi);
        if curvature_per_m(mid) < kappa_per_m {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::link::{LINK, TABLE};

    #[test]
    fn soft_target_agrees_with_the_table() {
        // The table's radius at a TCA rise is the soft link's radius at ambient + rise.
        let amb = LINK.surroundings.ambient_c as f32;
        for row in TABLE.iter() {
            let t = tca_temp_for_radius_c(row.radius_mm);
            assert!((t - (amb + row.tca_rise_k)).abs() < 0.02, "{row:?}: {t}");
        }
    }

    #[test]
    fn spring_back_compensation_round_trips() {
        for amb in [15.0f32, 22.0, 30.0] {
            for r in [33.0f32, 38.0, 45.0] {
                let lock = lock_temp_for_final_radius_c(r, amb);
                let back = final_radius_mm(lock, amb);
                assert!((back - r).abs() < 1e-3 * r, "{r} at {amb}: {back}");
                // Spring-back opens the link, so the lock aims a little tighter (hotter).
                assert!(lock > tca_temp_for_radius_c(r), "{r} at {amb}");
                assert!(lock - tca_temp_for_radius_c(r) < 3.0, "{r} at {amb}");
            }
        }
    }

    #[test]
    fn targets_stay_in_bounds() {
        assert_eq!(tca_temp_for_radius_c(1.0), TARGET_MAX_C);
        assert_eq!(tca_temp_for_radius_c(1e6), 0.0);
        assert_eq!(tca_temp_for_radius_c(f32::NAN), 0.0);
    }
}
