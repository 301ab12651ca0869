//! The parameters file (`link.toml`): reading, writing and checking it.

use crate::fourbar::{self, FourBarGeometry};
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

/// The optional `[fourbar]` section of a parameters file's text: the four-bar's lengths (m), its
/// foot and branch, each key defaulting to [`FourBarGeometry::DEFAULT`]; checked (see
/// [`check_fourbar`]) for the link of the same file. No section: the default.
pub fn fourbar_from_toml(text: &str) -> Result<FourBarGeometry, String> {
    #[derive(serde::Deserialize)]
    struct Section {
        #[serde(default)]
        fourbar: FourBarGeometry,
    }
    let s: Section = toml::from_str(text).map_err(|e| format!("link parameters: {e}"))?;
    let p = from_toml(text)?;
    check_fourbar(&s.fourbar, &p)?;
    Ok(s.fourbar)
}

/// Reads the parameters file at `path` and its `[fourbar]` section.
pub fn load_with_fourbar(path: &Path) -> Result<(LinkParams, FourBarGeometry), String> {
    let text =
        fs::read_to_string(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    let at = |e: String| format!("{}: {e}", path.display());
    Ok((
        from_toml(&text).map_err(at)?,
        fourbar_from_toml(&text).map_err(at)?,
    ))
}

/// Longest rigid link of the four-bar, m: 20 link lengths (1 m for the paper's link).
pub const FOURBAR_MAX_LENGTH_M: f64 = 1.0;

/// Rejects a four-bar the model cannot run with `p`'s link: each length must be positive and
/// at most [`FOURBAR_MAX_LENGTH_M`], the foot on the link (`foot_at` in 0..=1) and at most
/// [`FOURBAR_MAX_LENGTH_M`] from it, and the linkage must turn a full revolution, away from
/// any toggle, for every reachable radius and the straight link.
pub fn check_fourbar(g: &FourBarGeometry, p: &LinkParams) -> Result<(), String> {
    for (name, v) in [
        ("fourbar.ground_m", g.ground_m),
        ("fourbar.crank_m", g.crank_m),
        ("fourbar.rocker_m", g.rocker_m),
    ] {
        if !(v > 0.0 && v <= FOURBAR_MAX_LENGTH_M) {
            return Err(format!(
                "{name} must be a length in metres in (0, {FOURBAR_MAX_LENGTH_M}], got {v}"
            ));
        }
    }
    if !(0.0..=1.0).contains(&g.foot_at) {
        return Err(format!(
            "fourbar.foot_at must be a fraction of the link's length in 0..=1, got {}",
            g.foot_at
        ));
    }
    if !(g.foot_offset_m.abs() <= FOURBAR_MAX_LENGTH_M) {
        return Err(format!(
            "fourbar.foot_offset_m must be a length in metres within ±{FOURBAR_MAX_LENGTH_M}, got {}",
            g.foot_offset_m
        ));
    }
    let (lo, hi) = fourbar::reachable_radii_mm(p);
    // The chord grows with the radius, so the worst cases are the range's ends and the
    // straight link; the closed-form check covers every crank angle of each.
    for r in [Some(lo), Some(hi), None] {
        fourbar::FourBar::new(*g, p.geometry.length_m, r).map_err(|e| {
            let which = r.map_or("the straight link".to_string(), |r| {
                format!("radius {r:.2} mm")
            });
            format!("[fourbar] with {which}: {e}")
        })?;
    }
    Ok(())
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
    fn fourbar_section_is_optional_and_range_checked() {
        let base =
            std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../link.toml")).unwrap();
        assert_eq!(fourbar_from_toml(&base).unwrap(), FourBarGeometry::DEFAULT);
        let with = |section: &str| fourbar_from_toml(&format!("{base}\n[fourbar]\n{section}\n"));
        let g = with("crank_m = 0.012\nbranch = \"left\"").unwrap();
        assert_eq!(g.crank_m, 0.012);
        assert_eq!(g.branch, fourbar::Branch::Left);
        assert_eq!(g.rocker_m, FourBarGeometry::DEFAULT.rocker_m);
        // The base file still reads as link parameters with the section in it.
        assert!(from_toml(&format!("{base}\n[fourbar]\ncrank_m = 0.012\n")).is_ok());
        for (section, key) in [
            ("crank_m = 0.0", "fourbar.crank_m"),
            ("ground_m = 50.0", "fourbar.ground_m"),
            ("rocker_m = -0.04", "fourbar.rocker_m"),
            ("foot_at = 1.5", "fourbar.foot_at"),
            ("foot_offset_m = 2.0", "fourbar.foot_offset_m"),
        ] {
            let e = with(section).unwrap_err();
            assert!(e.contains(key), "{section}: {e}");
        }
        let e = with("rocker_m = 0.016").unwrap_err();
        assert!(
            e.contains("[fourbar] with radius") && e.contains("cannot assemble"),
            "{e}"
        );
        assert!(with("rocker_mm = 40").unwrap_err().contains("rocker_mm"));
        assert!(with("branch = \"up\"").is_err());
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
