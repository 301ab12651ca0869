//! Lookups in the power/radius table: radius → TCA power (for MORPH), power → radius, and
//! measured TCA rise → radius (the achieved-radius estimate).
//!
//! Interpolation is linear in curvature (1/radius), which the model makes nearly linear in
//! power, between rows that are monotone by construction (checked by a test).

use crate::heater::HeaterConfig;
use crate::link::{Row, TABLE};

/// The largest TCA power of the table, W.
pub const MAX_POWER_W: f32 = {
    let mut max = 0.0f32;
    let mut i = 0;
    while i < TABLE.len() {
        if TABLE[i].power_w > max {
            max = TABLE[i].power_w;
        }
        i += 1;
    }
    max
};
// Every power the table asks of the TCA is one its heater delivers (gated and paper drive the
// table's power through lock, plus the lock compensation, which the heater's cap then bounds).
const _: () = assert!(MAX_POWER_W <= HeaterConfig::TCA.max_power_w);

/// Reachable radii of the table, mm: `(min, max)`.
pub fn range_mm() -> (f32, f32) {
    (TABLE[TABLE.len() - 1].radius_mm, TABLE[0].radius_mm)
}

/// A radius outside the reachable range; carries the range for the error message.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OutOfRange {
    /// Smallest reachable radius, mm.
    pub min_mm: f32,
    /// Largest reachable radius, mm.
    pub max_mm: f32,
}

/// Interpolates `y` at `x` along rows whose key `key(row)` ascends.
fn interpolate(
    rows: &[Row],
    x: f32,
    key: impl Fn(&Row) -> f32,
    value: impl Fn(&Row) -> f32,
) -> f32 {
    for pair in rows.windows(2) {
        let (a, b) = (&pair[0], &pair[1]);
        if x <= key(b) {
            let f = (x - key(a)) / (key(b) - key(a));
            return value(a) + f * (value(b) - value(a));
        }
    }
    value(&rows[rows.len() - 1])
}

/// TCA power for a target radius, W, or the reachable range if the radius is outside it.
pub fn power_for_radius_w(radius_mm: f32) -> Result<f32, OutOfRange> {
    let (min_mm, max_mm) = range_mm();
    if !(radius_mm >= min_mm && radius_mm <= max_mm) {
        return Err(OutOfRange { min_mm, max_mm });
    }
    // Curvature ascends with power.
    Ok(interpolate(
        &TABLE,
        1.0 / radius_mm,
        |r| 1.0 / r.radius_mm,
        |r| r.power_w,
    ))
}

/// Radius for a measured steady TCA rise above ambient with the PLA at hold power, mm
/// (clamped to the table's ends).
pub fn radius_for_tca_rise_mm(rise_k: f32) -> f32 {
    let lo = TABLE[0].tca_rise_k;
    let hi = TABLE[TABLE.len() - 1].tca_rise_k;
    let x = if rise_k.is_finite() {
        rise_k.clamp(lo, hi)
    } else {
        lo
    };
    1.0 / interpolate(&TABLE, x, |r| r.tca_rise_k, |r| 1.0 / r.radius_mm)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Radius the table predicts for a TCA power, mm (clamped to the table's ends).
    pub fn radius_for_power_mm(power_w: f32) -> f32 {
        let p = power_w.clamp(TABLE[0].power_w, TABLE[TABLE.len() - 1].power_w);
        1.0 / interpolate(&TABLE, p, |r| r.power_w, |r| 1.0 / r.radius_mm)
    }

    #[test]
    fn table_is_monotone_and_small() {
        assert!(core::mem::size_of_val(&TABLE) <= 1024);
        for pair in TABLE.windows(2) {
            assert!(pair[1].power_w > pair[0].power_w);
            assert!(pair[1].radius_mm < pair[0].radius_mm);
            assert!(pair[1].tca_rise_k > pair[0].tca_rise_k);
        }
    }

    #[test]
    fn out_of_range_states_the_range() {
        let (min, max) = range_mm();
        let e = power_for_radius_w(max + 1.0).unwrap_err();
        assert_eq!((e.min_mm, e.max_mm), (min, max));
        assert!(power_for_radius_w(min - 0.01).is_err());
        assert!(power_for_radius_w(f32::NAN).is_err());
        assert_eq!(power_for_radius_w(max).unwrap(), 0.0);
    }

    proptest! {
        #[test]
        fn inverse_round_trips(f in 0.0f32..=1.0) {
            let (min, max) = range_mm();
            let r = min + f * (max - min);
            let p = power_for_radius_w(r).unwrap();
            prop_assert!((radius_for_power_mm(p) - r).abs() < 1e-3 * r);
        }

        #[test]
        fn inverse_is_monotone(a in 0.0f32..=1.0, b in 0.0f32..=1.0) {
            let (min, max) = range_mm();
            let (ra, rb) = (min + a * (max - min), min + b * (max - min));
            let (pa, pb) = (power_for_radius_w(ra).unwrap(), power_for_radius_w(rb).unwrap());
            if ra < rb { prop_assert!(pa >= pb); } else { prop_assert!(pa <= pb); }
        }
    }
}
