//! The parameters file (`link.toml`): reading, writing and checking it.

use crate::fourbar::{self, FourBarGeometry};
use crate::params::{
    Geometry, LinkParams, Materials, Mechanics, PlaStiffness, Surroundings, PAPER_GEOMETRY,
};
use std::{fs, path::Path};

/// The whole file as written: the link's keys and the optional `[fourbar]` section. Unknown
/// keys anywhere are refused (a misspelt key must not silently fall back to a default).
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct FileText {
    geometry: Geometry,
    materials: Materials,
    surroundings: Surroundings,
    mechanics: Mechanics,
    pla_stiffness: PlaStiffness,
    pla_hold_power_w: f64,
    table_max_power_w: f64,
    table_entries: usize,
    #[serde(default)]
    fitted_on: Option<Geometry>,
    #[serde(default)]
    fourbar: FourBarGeometry,
}

/// The link's parameters and the four-bar of a file's text, the link checked (see [`check`]).
fn parse(text: &str) -> Result<(LinkParams, FourBarGeometry), String> {
    let f: FileText = toml::from_str(text).map_err(|e| format!("link parameters: {e}"))?;
    let p = LinkParams {
        geometry: f.geometry,
        materials: f.materials,
        surroundings: f.surroundings,
        mechanics: f.mechanics,
        pla_stiffness: f.pla_stiffness,
        pla_hold_power_w: f.pla_hold_power_w,
        table_max_power_w: f.table_max_power_w,
        table_entries: f.table_entries,
        fitted_on: f.fitted_on.unwrap_or(PAPER_GEOMETRY),
    };
    check(&p)?;
    Ok((p, f.fourbar))
}

/// Parses a parameters file's text, then checks it (see [`check`]).
pub fn from_toml(text: &str) -> Result<LinkParams, String> {
    Ok(parse(text)?.0)
}

/// Reads and checks the parameters file at `path`; errors start with the path.
pub fn load(path: &Path) -> Result<LinkParams, String> {
    load_for_build(path).map(|(_, p)| p)
}

/// What the firmware's build script builds in: the text of the parameters file at `path` and
/// its checked parameters, or the sentence that fails the build (the file, the key, the allowed
/// range). The same checks as [`load`].
pub fn load_for_build(path: &Path) -> Result<(String, LinkParams), String> {
    let text =
        fs::read_to_string(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    let p = from_toml(&text).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok((text, p))
}

/// The optional `[fourbar]` section of a parameters file's text: the four-bar's lengths (m), its
/// foot and branch, each key defaulting to [`FourBarGeometry::DEFAULT`]; checked (see
/// [`check_fourbar`]) for the link of the same file. No section: the default.
pub fn fourbar_from_toml(text: &str) -> Result<FourBarGeometry, String> {
    let (p, g) = parse(text)?;
    check_fourbar(&g, &p)?;
    Ok(g)
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

/// Rejects parameters the model cannot use, with a sentence saying which and why: every value
/// in its range ([`crate::validate`]), then the heaters inside the body and apart.
pub fn check(p: &LinkParams) -> Result<(), String> {
    crate::validate::check_values(p)?;
    for (section, g) in [("geometry", &p.geometry), ("fitted_on", &p.fitted_on)] {
        let a = g.body_diameter_m / 2.0;
        if g.tca_offset_m + g.tca_outer_diameter_m / 2.0 >= a
            || g.pla_offset_m + g.pla_diameter_m / 2.0 >= a
        {
            return Err(format!(
                "[{section}]: the TCA and the PLA rod must lie inside the body"
            ));
        }
        if g.tca_offset_m + g.pla_offset_m <= (g.tca_outer_diameter_m + g.pla_diameter_m) / 2.0 {
            return Err(format!("[{section}]: the TCA and the PLA rod overlap"));
        }
    }
    Ok(())
}

/// The keys of `g` that differ from `fitted`, as `geometry.key = value (fitted on value)`.
pub fn geometry_differences(g: &Geometry, fitted: &Geometry) -> Vec<String> {
    [
        ("body_diameter_m", g.body_diameter_m, fitted.body_diameter_m),
        ("length_m", g.length_m, fitted.length_m),
        (
            "tca_outer_diameter_m",
            g.tca_outer_diameter_m,
            fitted.tca_outer_diameter_m,
        ),
        (
            "tca_inner_diameter_m",
            g.tca_inner_diameter_m,
            fitted.tca_inner_diameter_m,
        ),
        (
            "tca_fibre_diameter_m",
            g.tca_fibre_diameter_m,
            fitted.tca_fibre_diameter_m,
        ),
        ("tca_offset_m", g.tca_offset_m, fitted.tca_offset_m),
        ("pla_diameter_m", g.pla_diameter_m, fitted.pla_diameter_m),
        ("pla_offset_m", g.pla_offset_m, fitted.pla_offset_m),
    ]
    .iter()
    .filter(|(_, a, b)| a != b)
    .map(|(k, a, b)| format!("geometry.{k} = {a} (fitted on {b})"))
    .collect()
}

/// The sentence that says a geometry has no measured radii behind it, or `None` when `p`'s
/// geometry is the one its fitted constants came from: every key that differs, and what to do.
pub fn unfitted_geometry_note(p: &LinkParams) -> Option<String> {
    if p.geometry_is_fitted() {
        return None;
    }
    Some(format!(
        "new geometry, no measured radii: {}. The fitted mechanics constants came from another \
         link; the bending stiffness is scaled to the new cross-section, but every radius is an \
         estimate until radii measured on this link are fitted: measure the steady radius at \
         three or more TCA powers and run `morph-model calibrate --data FILE` (docs/model.md, \
         \"A new geometry\")",
        geometry_differences(&p.geometry, &p.fitted_on).join(", ")
    ))
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

    /// The repository's `link.toml` with `from` replaced by `to` (the first occurrence).
    fn edited(from: &str, to: &str) -> String {
        let base =
            std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../link.toml")).unwrap();
        assert!(base.contains(from), "link.toml has no `{from}`");
        base.replacen(from, to, 1)
    }

    /// Each bad value fails `load_for_build` (what the firmware's build script calls) with the
    /// file, the key and the allowed range in the sentence.
    #[test]
    fn every_bad_value_names_the_file_the_key_and_the_range() {
        let dir = std::env::temp_dir().join(format!("morphlink-validate-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let cases = [
            (
                "k_w_mk = 0.13",
                "k_w_mk = nan",
                "materials.pla.k_w_mk = NaN",
                "0.01..=500 W/(m K)",
            ),
            (
                "k_w_mk = 4.6",
                "k_w_mk = inf",
                "materials.tca.k_w_mk = inf",
                "0.01..=500 W/(m K)",
            ),
            (
                "ambient_c = 22.0",
                "ambient_c = 400.0",
                "surroundings.ambient_c = 400",
                "-20..=45 °C",
            ),
            (
                "table_max_power_w = 1.5",
                "table_max_power_w = 50.0",
                "table_max_power_w = 50",
                "0.05..=2 W",
            ),
            (
                "length_m = 0.05",
                "length_m = 50.0",
                "geometry.length_m = 50",
                "millimetres",
            ),
            (
                "pla_hold_power_w = 1.5",
                "pla_hold_power_w = -1.0",
                "pla_hold_power_w = -1",
                "0..=5 W",
            ),
            (
                "rho_kg_m3 = 1040.0",
                "rho_kg_m3 = 0.0",
                "materials.silicone.rho_kg_m3 = 0",
                "100..=25000 kg/m³",
            ),
            (
                "h_w_m2k = 101.3",
                "h_w_m2k = 101.3\nwater = true",
                "unknown field `water`",
                "expected `h_w_m2k` or `ambient_c`",
            ),
            (
                "[mechanics]",
                "[mechanic]",
                "unknown field `mechanic`",
                "expected one of",
            ),
        ];
        for (n, (from, to, key, range)) in cases.iter().enumerate() {
            let path = dir.join(format!("bad{n}.toml"));
            std::fs::write(&path, edited(from, &to.replace("\\n", "\n"))).unwrap();
            let e = load_for_build(&path).unwrap_err();
            assert!(
                e.starts_with(&path.display().to_string()) && e.contains(key) && e.contains(range),
                "{to}: {e}"
            );
            assert!(!e.contains("cannot find value"), "{e}");
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_file_without_fitted_on_was_fitted_on_the_paper_link() {
        let p = from_toml(&edited("ambient_c = 22.0", "ambient_c = 22.0")).unwrap();
        assert_eq!(p.fitted_on, PAPER_GEOMETRY);
        assert!(unfitted_geometry_note(&p).is_none());
        let p = from_toml(&edited(
            "body_diameter_m = 0.008",
            "body_diameter_m = 0.010",
        ))
        .unwrap();
        let note = unfitted_geometry_note(&p).unwrap();
        assert!(
            note.contains("geometry.body_diameter_m = 0.01 (fitted on 0.008)")
                && note.contains("calibrate --data"),
            "{note}"
        );
        // Written back out, the file keeps the geometry its constants came from.
        assert_eq!(from_toml(&to_toml(&p)).unwrap(), p);
    }
}
