//! The firmware's power/radius table, computed from the lumped model.
//!
//! Entries are evenly spaced in TCA power from 0 W to `table_max_power_w`, each with the steady
//! radius (PLA held soft at its hold power) and the steady TCA temperature rise above ambient,
//! so the firmware can map a target radius to a power, and a measured TCA rise back to a radius.

use crate::mechanics::{radius_mm, steady_tca_temp_c};
use crate::params::LinkParams;

/// One row of the table.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Entry {
    /// TCA power, W.
    pub power_w: f64,
    /// Steady bending radius at that power, mm.
    pub radius_mm: f64,
    /// Steady TCA temperature rise above ambient at that power (PLA at hold power), K.
    pub tca_rise_k: f64,
}

/// TCA power of entry `i` of the table, W.
pub fn power_of_entry_w(p: &LinkParams, i: usize) -> f64 {
    let n = p.table_entries.max(2);
    p.table_max_power_w * i as f64 / (n - 1) as f64
}

/// Entry `i` of the table of `p`.
pub fn entry(p: &LinkParams, i: usize) -> Entry {
    let power_w = power_of_entry_w(p, i);
    Entry {
        power_w,
        radius_mm: radius_mm(p, power_w),
        tca_rise_k: steady_tca_temp_c(p, power_w) - p.surroundings.ambient_c,
    }
}

/// Flash size of a table of `entries` rows of three `f32`, bytes.
pub fn flash_bytes(entries: usize) -> usize {
    entries * 3 * core::mem::size_of::<f32>()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_table_fits_one_kib_and_is_monotone() {
        let p = LinkParams::DEFAULT;
        assert!(flash_bytes(p.table_entries) <= 1024);
        let mut last = f64::INFINITY;
        for i in 0..p.table_entries {
            let e = entry(&p, i);
            assert!(e.radius_mm < last);
            last = e.radius_mm;
        }
    }
}
