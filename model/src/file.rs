//! The parameters file (`link.toml`): reading, writing and checking it.

use crate::params::LinkParams;
use std::{fs, path::Path};

/// Parses a parameters file's text, then checks it (see [`check`]).
pub fn from_toml(text: &str) -> Result<LinkParams, String> {
    let p: LinkParams = toml::from_str(text).map_err(|e| format!("link parameters: {e}"))?;
    check(&p)?;
    Ok(p)
}

/// Reads and checks the parameters file at `path`.
pub fn load(path: &Path) -> Result<LinkParams, String> {
    let text =
        fs::read_to_string(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    from_toml(&text).map_err(|e| format!("{}: {e}", path.display()))
}

/// The parameters as TOML text.
pub fn to_toml(p: &LinkParams) -> String {
    toml::to_string_pretty(p).expect("LinkParams always serialises")
}

/// Rejects parameters the model cannot use, with a sentence saying which and why.
pub fn check(p: &LinkParams) -> Result<(), String> {
    let g = &p.geometry;
    let a = g.body_diameter_m / 2.0;
    let positive = [
        ("geometry.body_diameter_m", g.body_diameter_m),
        ("geometry.length_m", g.length_m),
        ("geometry.tca_outer_diameter_m", g.tca_outer_diameter_m),
        ("geometry.pla_diameter_m", g.pla_diameter_m),
        ("geometry.tca_offset_m", g.tca_offset_m),
        ("geometry.pla_offset_m", g.pla_offset_m),
        ("surroundings.h_w_m2k", p.surroundings.h_w_m2k),
        (
            "mechanics.bending_stiffness_nm2",
            p.mechanics.bending_stiffness_nm2,
        ),
        ("table_max_power_w", p.table_max_power_w),
    ];
    for (name, v) in positive {
        if !(v > 0.0 && v.is_finite()) {
            return Err(format!("{name} must be a positive number, got {v}"));
        }
    }
    if g.tca_offset_m + g.tca_outer_diameter_m / 2.0 >= a
        || g.pla_offset_m + g.pla_diameter_m / 2.0 >= a
    {
        return Err("the TCA and the PLA rod must lie inside the body".into());
    }
    if g.tca_offset_m + g.pla_offset_m <= (g.tca_outer_diameter_m + g.pla_diameter_m) / 2.0 {
        return Err("the TCA and the PLA rod overlap".into());
    }
    if !(2..=64).contains(&p.table_entries) || crate::table::flash_bytes(p.table_entries) > 1024 {
        return Err(format!(
            "table_entries must be 2..=64 (at most 1 KiB of flash), got {}",
            p.table_entries
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_through_toml() {
        let p = LinkParams::DEFAULT;
        assert_eq!(from_toml(&to_toml(&p)).unwrap(), p);
    }

    #[test]
    fn rejects_a_heater_outside_the_body() {
        let mut p = LinkParams::DEFAULT;
        p.geometry.tca_offset_m = 3.9e-3;
        assert!(from_toml(&to_toml(&p))
            .unwrap_err()
            .contains("inside the body"));
    }
}
