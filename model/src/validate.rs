//! Range and unit checks of every `link.toml` value: one table of allowed ranges, one check.
//!
//! Used by `morph-model` (through [`crate::file`]) and by the firmware's build script alike, so a
//! value the model cannot use fails both with the same sentence: the key, the value, the allowed
//! range with its unit and the reason. NaN and infinities are never in range. A length above its
//! range that would be in range divided by 1000 is named as millimetres typed for metres.

use crate::params::{Geometry, LinkParams, Material};

/// One checked key: its name in `link.toml`, the allowed closed range and why.
#[derive(Clone, Debug, PartialEq)]
pub struct Allowed {
    /// The key as written in `link.toml`, with its section (`geometry.length_m`).
    pub key: String,
    /// Smallest allowed value, in `unit`.
    pub min: f64,
    /// Largest allowed value, in `unit`.
    pub max: f64,
    /// The unit of the value (`m`, `W`, `°C`, ...).
    pub unit: &'static str,
    /// Why the range is what it is.
    pub why: &'static str,
}

/// Highest TCA power a table may ask for, W: the TCA heater's cap (`HeaterConfig::TCA` in the
/// core, 2 W); the firmware also asserts it at compile time.
pub const TCA_HEATER_CAP_W: f64 = 2.0;
/// Highest PLA hold power, W: the PLA heater's cap (`HeaterConfig::PLA`, 5 W).
pub const PLA_HEATER_CAP_W: f64 = 5.0;
/// Hottest TCA temperature the force law must stay physical at, °C: the nylon modulus must be
/// positive up to here (well above the supervisor's TCA limit).
pub const NYLON_MAX_TEMP_C: f64 = 200.0;

const LEN_WHY: &str = "a length in metres";

fn allowed(key: &str, min: f64, max: f64, unit: &'static str, why: &'static str) -> Allowed {
    Allowed {
        key: key.to_string(),
        min,
        max,
        unit,
        why,
    }
}

/// Each key of `p` with its allowed range, in the file's order.
pub fn table(p: &LinkParams) -> Vec<(Allowed, f64)> {
    let mut out = vec![
        (
            allowed(
                "pla_hold_power_w",
                0.0,
                PLA_HEATER_CAP_W,
                "W",
                "at most the PLA heater's cap",
            ),
            p.pla_hold_power_w,
        ),
        (
            allowed(
                "table_max_power_w",
                0.05,
                TCA_HEATER_CAP_W,
                "W",
                "at most the TCA heater's cap",
            ),
            p.table_max_power_w,
        ),
    ];
    geometry_rows("geometry", &p.geometry, &mut out);
    for (name, m) in [
        ("tca", &p.materials.tca),
        ("pla", &p.materials.pla),
        ("silicone", &p.materials.silicone),
    ] {
        material_rows(name, m, &mut out);
    }
    let s = &p.surroundings;
    out.push((
        allowed(
            "surroundings.h_w_m2k",
            1.0,
            10_000.0,
            "W/(m² K)",
            "still air is about 20, still water 101.3, forced water a few thousand",
        ),
        s.h_w_m2k,
    ));
    out.push((
        allowed(
            "surroundings.ambient_c",
            -20.0,
            45.0,
            "°C",
            "a lab or water bath; the PLA softens at about 62 °C",
        ),
        s.ambient_c,
    ));
    let m = &p.mechanics;
    for (key, v, min, max, unit, why) in [
        (
            "mechanics.bending_stiffness_nm2",
            m.bending_stiffness_nm2,
            1e-9,
            1e-2,
            "N m²",
            "a soft silicone link: the paper's is 1.5e-5",
        ),
        (
            "mechanics.preload_n",
            m.preload_n,
            0.0,
            10.0,
            "N",
            "the TCA's push at 20 °C: the paper's is 0.17",
        ),
        (
            "mechanics.force_coeff_n_per_k",
            m.force_coeff_n_per_k,
            0.0,
            1.0,
            "N/K",
            "the TCA's push per kelvin: the paper's is 0.0028",
        ),
        (
            "mechanics.tca_stiffness_n_per_m",
            m.tca_stiffness_n_per_m,
            0.01,
            10_000.0,
            "N/m",
            "the TCA coil's axial stiffness: the paper's is 19.4",
        ),
        (
            "mechanics.nylon_e0_pa",
            m.nylon_e0_pa,
            1e7,
            1e10,
            "Pa",
            "nylon's modulus intercept: 560.2e6",
        ),
        (
            "mechanics.nylon_e_slope_pa_per_c",
            m.nylon_e_slope_pa_per_c,
            0.0,
            1e8,
            "Pa/°C",
            "nylon's modulus slope: 1.777e6",
        ),
    ] {
        out.push((allowed(key, min, max, unit, why), v));
    }
    let s = &p.pla_stiffness;
    for (key, v, min, max, unit, why) in [
        (
            "pla_stiffness.e_glassy_pa",
            s.e_glassy_pa,
            1e8,
            1e11,
            "Pa",
            "glassy PLA: 1.7e9",
        ),
        (
            "pla_stiffness.e_rubbery_pa",
            s.e_rubbery_pa,
            1e4,
            1e9,
            "Pa",
            "rubbery PLA: 1.2e6",
        ),
        (
            "pla_stiffness.tg_c",
            s.tg_c,
            30.0,
            150.0,
            "°C",
            "PLA's glass transition: about 62",
        ),
        (
            "pla_stiffness.transition_width_k",
            s.transition_width_k,
            0.1,
            50.0,
            "K",
            "width of the glass transition: 3",
        ),
        (
            "pla_stiffness.flow_time_at_tg_s",
            s.flow_time_at_tg_s,
            1e-3,
            1e4,
            "s",
            "relaxation time at Tg: 0.5",
        ),
    ] {
        out.push((allowed(key, min, max, unit, why), v));
    }
    geometry_rows("fitted_on", &p.fitted_on, &mut out);
    out
}

fn geometry_rows(section: &str, g: &Geometry, out: &mut Vec<(Allowed, f64)>) {
    for (name, v, min, max) in [
        ("body_diameter_m", g.body_diameter_m, 2e-3, 0.1),
        ("length_m", g.length_m, 5e-3, 1.0),
        ("tca_outer_diameter_m", g.tca_outer_diameter_m, 1e-4, 0.02),
        ("tca_inner_diameter_m", g.tca_inner_diameter_m, 0.0, 0.02),
        ("tca_fibre_diameter_m", g.tca_fibre_diameter_m, 1e-5, 0.01),
        ("tca_offset_m", g.tca_offset_m, 1e-4, 0.05),
        ("pla_diameter_m", g.pla_diameter_m, 1e-4, 0.02),
        ("pla_offset_m", g.pla_offset_m, 1e-4, 0.05),
    ] {
        out.push((
            allowed(&format!("{section}.{name}"), min, max, "m", LEN_WHY),
            v,
        ));
    }
}

fn material_rows(name: &str, m: &Material, out: &mut Vec<(Allowed, f64)>) {
    for (field, v, min, max, unit, why) in [
        (
            "k_w_mk",
            m.k_w_mk,
            0.01,
            500.0,
            "W/(m K)",
            "thermal conductivity: polymers 0.1-0.5, silver-coated nylon 4.6, copper 400",
        ),
        (
            "rho_kg_m3",
            m.rho_kg_m3,
            100.0,
            25_000.0,
            "kg/m³",
            "density: polymers about 1000-1400",
        ),
        (
            "cp_j_kgk",
            m.cp_j_kgk,
            100.0,
            5_000.0,
            "J/(kg K)",
            "specific heat: polymers about 1000-2000",
        ),
    ] {
        out.push((
            allowed(&format!("materials.{name}.{field}"), min, max, unit, why),
            v,
        ));
    }
}

/// The sentence for a value outside its range, or `None` when it is in range.
pub fn out_of_range(a: &Allowed, v: f64) -> Option<String> {
    let range = format!("{}..={} {}", a.min, a.max, a.unit);
    if !v.is_finite() {
        return Some(format!(
            "{} = {v} is not a finite number; allowed {range} ({})",
            a.key, a.why
        ));
    }
    if v >= a.min && v <= a.max {
        return None;
    }
    let mut s = format!("{} = {v} is outside {range} ({})", a.key, a.why);
    if a.unit == "m" && v > a.max && v / 1000.0 >= a.min && v / 1000.0 <= a.max {
        s.push_str(&format!(
            "; it looks like millimetres: {v} mm is {} m",
            v / 1000.0
        ));
    }
    Some(s)
}

/// Checks every value of `p` against [`table`] and the relations between values: the TCA's
/// bore and fibre inside its coil, rubbery PLA softer than glassy, the nylon modulus positive up
/// to [`NYLON_MAX_TEMP_C`], the table's size. The first failure, as a sentence.
pub fn check_values(p: &LinkParams) -> Result<(), String> {
    for (a, v) in table(p) {
        if let Some(e) = out_of_range(&a, v) {
            return Err(e);
        }
    }
    for (section, g) in [("geometry", &p.geometry), ("fitted_on", &p.fitted_on)] {
        if !(g.tca_inner_diameter_m < g.tca_outer_diameter_m) {
            return Err(format!(
                "{section}.tca_inner_diameter_m = {} must be less than {section}.tca_outer_diameter_m = {} (the bore is inside the coil)",
                g.tca_inner_diameter_m, g.tca_outer_diameter_m
            ));
        }
        if !(g.tca_fibre_diameter_m <= g.tca_outer_diameter_m) {
            return Err(format!(
                "{section}.tca_fibre_diameter_m = {} must be at most {section}.tca_outer_diameter_m = {} (the fibre is coiled into it)",
                g.tca_fibre_diameter_m, g.tca_outer_diameter_m
            ));
        }
    }
    let s = &p.pla_stiffness;
    if !(s.e_rubbery_pa < s.e_glassy_pa) {
        return Err(format!(
            "pla_stiffness.e_rubbery_pa = {} must be less than pla_stiffness.e_glassy_pa = {} (PLA softens above Tg)",
            s.e_rubbery_pa, s.e_glassy_pa
        ));
    }
    let m = &p.mechanics;
    if !(m.nylon_e0_pa - m.nylon_e_slope_pa_per_c * NYLON_MAX_TEMP_C > 0.0) {
        return Err(format!(
            "mechanics.nylon_e0_pa = {} and mechanics.nylon_e_slope_pa_per_c = {} give no positive nylon modulus at {NYLON_MAX_TEMP_C} °C",
            m.nylon_e0_pa, m.nylon_e_slope_pa_per_c
        ));
    }
    if !(2..=64).contains(&p.table_entries) || crate::table::flash_bytes(p.table_entries) > 1024 {
        return Err(format!(
            "table_entries = {} is outside 2..=64 (at most 1 KiB of flash)",
            p.table_entries
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_paper_link_is_in_range() {
        check_values(&LinkParams::DEFAULT).unwrap();
    }

    #[test]
    fn every_key_is_checked_once() {
        let rows = table(&LinkParams::DEFAULT);
        let mut keys: Vec<&str> = rows.iter().map(|(a, _)| a.key.as_str()).collect();
        let n = keys.len();
        keys.sort();
        keys.dedup();
        assert_eq!(keys.len(), n, "a key is listed twice");
        // 2 powers, 8 + 8 lengths, 9 material values, 2 surroundings, 6 mechanics, 5 PLA.
        assert_eq!(n, 2 + 16 + 9 + 2 + 6 + 5);
    }

    #[test]
    fn millimetres_for_metres_are_named() {
        let mut p = LinkParams::DEFAULT;
        p.geometry.length_m = 50.0;
        let e = check_values(&p).unwrap_err();
        assert!(
            e.contains("geometry.length_m = 50")
                && e.contains("0.005..=1 m")
                && e.contains("millimetres"),
            "{e}"
        );
    }

    #[test]
    fn relations_between_values_are_checked() {
        let mut p = LinkParams::DEFAULT;
        p.geometry.tca_inner_diameter_m = 2e-3;
        assert!(check_values(&p).unwrap_err().contains("bore"));
        let mut p = LinkParams::DEFAULT;
        p.pla_stiffness.e_rubbery_pa = 2e9;
        assert!(check_values(&p).unwrap_err().contains("e_rubbery_pa"));
        let mut p = LinkParams::DEFAULT;
        p.mechanics.nylon_e_slope_pa_per_c = 5e6;
        assert!(check_values(&p).unwrap_err().contains("nylon modulus"));
    }
}
