//! TCA force law and constant-curvature kinetostatics of the link in its bending plane.
//!
//! The paper's Cosserat rod (Sec. II-B) with constant strain, reduced to the plane and to
//! bending only: the TCA runs parallel to the axis at offset `r` on the convex side, so for a
//! curvature `κ` its length grows by `δ = r L κ` (Eq. 8) and its push `F` makes the moment
//! `r F` (Eq. 6). The wrench balance `K (ξ − ξ*) = W_act` (Eq. 9) becomes
//! `EI κ = r F(r L κ, T)`, linear in `κ`:
//! `κ = r e(T) (F0 + c (T − T_ref)) / (EI + r² L k e(T))`.

use crate::params::{Geometry, LinkParams, Mechanics, PlaStiffness, T_REF_C};
use crate::thermal::resistance_matrix;
use libm::{exp, log};

/// Nylon modulus relative to its value at the reference temperature (dimensionless).
pub fn modulus_ratio(m: &Mechanics, temp_c: f64) -> f64 {
    let e = |t: f64| m.nylon_e0_pa - m.nylon_e_slope_pa_per_c * t;
    (e(temp_c) / e(T_REF_C)).max(0.0)
}

/// TCA push, N, at extension `delta_m` (m, positive = longer) and temperature `temp_c`.
pub fn tca_force_n(m: &Mechanics, delta_m: f64, temp_c: f64) -> f64 {
    modulus_ratio(m, temp_c)
        * (m.preload_n + m.force_coeff_n_per_k * (temp_c - T_REF_C)
            - m.tca_stiffness_n_per_m * delta_m)
}

/// Equilibrium curvature, 1/m, for a TCA at `tca_temp_c` with an extra elastic term
/// `extra_stiffness_nm2 · (κ − extra_rest_per_m)` (the PLA's stiffness above its rubbery
/// value; zero when the PLA is soft).
pub fn curvature_with_extra_per_m(
    p: &LinkParams,
    tca_temp_c: f64,
    extra_stiffness_nm2: f64,
    extra_rest_per_m: f64,
) -> f64 {
    let m = &p.mechanics;
    let r = p.geometry.tca_offset_m;
    let l = p.geometry.length_m;
    let e = modulus_ratio(m, tca_temp_c);
    let drive = r * e * (m.preload_n + m.force_coeff_n_per_k * (tca_temp_c - T_REF_C));
    let stiffness =
        bending_stiffness_nm2(p) + extra_stiffness_nm2 + r * r * l * m.tca_stiffness_n_per_m * e;
    (drive + extra_stiffness_nm2 * extra_rest_per_m) / stiffness
}

/// Young's modulus of EcoFlex 00-10, Pa (Pawlowski et al. 2019): the body's share of the
/// cross-section's stiffness estimate.
pub const SILICONE_E_PA: f64 = 37.8e3;

/// Stiffness estimate of a cross-section with the PLA soft, N m²: the silicone body's `E I`
/// plus the rubbery PLA rod's own `E I`. The calibration's prior, and the yardstick that carries
/// fitted stiffness from one geometry to another.
pub fn cross_section_stiffness_nm2(g: &Geometry, s: &PlaStiffness) -> f64 {
    let d = g.body_diameter_m;
    let i_body = core::f64::consts::PI * d * d * d * d / 64.0;
    let dp = g.pla_diameter_m;
    let i_pla = core::f64::consts::PI * dp * dp * dp * dp / 64.0;
    SILICONE_E_PA * i_body + s.e_rubbery_pa * i_pla
}

/// Soft-link bending stiffness of `p`'s geometry, N m²: the fitted
/// `mechanics.bending_stiffness_nm2` (which belongs to `p.fitted_on`) times the ratio of the
/// cross-section estimates of the two geometries. Equal to the fitted value when the geometry
/// is the fitted one; for another geometry it keeps a stiffer body from being predicted to bend
/// more, but it is an estimate until radii measured on that geometry are fitted.
pub fn bending_stiffness_nm2(p: &LinkParams) -> f64 {
    if p.geometry_is_fitted() {
        return p.mechanics.bending_stiffness_nm2;
    }
    let s = &p.pla_stiffness;
    p.mechanics.bending_stiffness_nm2 * cross_section_stiffness_nm2(&p.geometry, s)
        / cross_section_stiffness_nm2(&p.fitted_on, s)
}

/// Equilibrium curvature with the PLA soft, 1/m, for a TCA at `tca_temp_c`.
pub fn curvature_per_m(p: &LinkParams, tca_temp_c: f64) -> f64 {
    curvature_with_extra_per_m(p, tca_temp_c, 0.0, 0.0)
}

/// Steady TCA temperature, °C, at TCA power `p_tca_w` with the PLA at its hold power.
pub fn steady_tca_temp_c(p: &LinkParams, p_tca_w: f64) -> f64 {
    let r = resistance_matrix(p);
    p.surroundings.ambient_c + r.rises_k(p_tca_w, p.pla_hold_power_w).0
}

/// Steady bending radius, mm, at TCA power `p_tca_w` with the PLA held soft.
pub fn radius_mm(p: &LinkParams, p_tca_w: f64) -> f64 {
    1e3 / curvature_per_m(p, steady_tca_temp_c(p, p_tca_w))
}

/// Second moment of area of the PLA rod, m⁴.
pub fn pla_second_moment_m4(p: &LinkParams) -> f64 {
    let d = p.geometry.pla_diameter_m;
    core::f64::consts::PI * d * d * d * d / 64.0
}

/// PLA Young's modulus at `temp_c`, Pa: log-modulus follows a logistic step at Tg.
pub fn pla_modulus_pa(s: &PlaStiffness, temp_c: f64) -> f64 {
    let glassy_share = 1.0 / (1.0 + exp((temp_c - s.tg_c) / s.transition_width_k));
    let (lg, lr) = (log(s.e_glassy_pa), log(s.e_rubbery_pa));
    exp(lr + (lg - lr) * glassy_share)
}

/// Second moment of area of the PLA rod about the link's axis, m⁴: its own `π d⁴/64` plus the
/// parallel-axis term `A ρ²` of its offset ρ from the axis (about 30× the own term here), which
/// is what the rod resists bending with once it is glassy.
pub fn pla_second_moment_about_axis_m4(p: &LinkParams) -> f64 {
    let d = p.geometry.pla_diameter_m;
    let area = core::f64::consts::PI * d * d / 4.0;
    let rho = p.geometry.pla_offset_m;
    pla_second_moment_m4(p) + area * rho * rho
}

/// PLA bending stiffness above its rubbery value at `temp_c`, N m² (what the fitted soft-link
/// stiffness does not already contain), about the link's axis.
pub fn pla_extra_stiffness_nm2(p: &LinkParams, temp_c: f64) -> f64 {
    let s = &p.pla_stiffness;
    (pla_modulus_pa(s, temp_c) - s.e_rubbery_pa).max(0.0) * pla_second_moment_about_axis_m4(p)
}

/// Relaxation time of the PLA's stress-free curvature at `temp_c`, s (bounded so the
/// simulation stays finite: 10 ms to about three years).
pub fn pla_flow_time_s(s: &PlaStiffness, temp_c: f64) -> f64 {
    let x = ((s.tg_c - temp_c) / s.transition_width_k).clamp(-60.0, 60.0);
    (s.flow_time_at_tg_s * exp(x)).clamp(0.01, 1e8)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn more_power_bends_more() {
        let p = LinkParams::DEFAULT;
        let mut last = f64::INFINITY;
        for i in 0..=15 {
            let r = radius_mm(&p, i as f64 * 0.1);
            assert!(r < last, "radius must fall with power: {r} at step {i}");
            last = r;
        }
    }

    #[test]
    fn balance_holds_at_the_solution() {
        let p = LinkParams::DEFAULT;
        let t = 70.0;
        let k = curvature_per_m(&p, t);
        let r = p.geometry.tca_offset_m;
        let moment = r * tca_force_n(&p.mechanics, r * p.geometry.length_m * k, t);
        assert!((p.mechanics.bending_stiffness_nm2 * k - moment).abs() < 1e-12);
    }

    /// A 10 mm body is about 2.4 times as stiff as the paper's 8 mm one; with the fitted
    /// stiffness left at the 8 mm value it was predicted to bend more (a smaller radius) at the
    /// same power. Scaled with the cross-section it bends less.
    #[test]
    fn a_stiffer_body_bends_less() {
        let paper = LinkParams::DEFAULT;
        let mut wide = paper;
        wide.geometry.body_diameter_m = 10e-3;
        let ratio = bending_stiffness_nm2(&wide) / bending_stiffness_nm2(&paper);
        assert!((2.2..2.5).contains(&ratio), "stiffness ratio {ratio}");
        for p_w in [0.1, 0.8, 1.5] {
            assert!(
                radius_mm(&wide, p_w) > radius_mm(&paper, p_w),
                "at {p_w} W: 10 mm {} mm vs 8 mm {} mm",
                radius_mm(&wide, p_w),
                radius_mm(&paper, p_w)
            );
        }
        // The unscaled constants (the fitted geometry set to the new one) bend more.
        let mut unscaled = wide;
        unscaled.fitted_on = wide.geometry;
        assert!(radius_mm(&unscaled, 0.8) < radius_mm(&paper, 0.8));
    }

    #[test]
    fn stiff_pla_holds_its_rest_curvature() {
        let p = LinkParams::DEFAULT;
        let cold = pla_extra_stiffness_nm2(&p, 25.0);
        let soft = pla_extra_stiffness_nm2(&p, 80.0);
        assert!(
            cold > 50.0 * p.mechanics.bending_stiffness_nm2,
            "cold PLA {cold}"
        );
        assert!(
            soft < 0.05 * p.mechanics.bending_stiffness_nm2,
            "soft PLA {soft}"
        );
        let held = curvature_with_extra_per_m(&p, 90.0, cold, 20.0);
        assert!(
            (held - 20.0).abs() < 0.5,
            "rigid PLA moves only a little: {held}"
        );
    }

    #[test]
    fn the_offset_rod_resists_bending_mostly_through_its_distance_from_the_axis() {
        let p = LinkParams::DEFAULT;
        let ratio = pla_second_moment_about_axis_m4(&p) / pla_second_moment_m4(&p);
        // 1 + 16 ρ²/d² for a solid rod: ρ = 2.5 mm, d = 1.75 mm.
        let expected = 1.0 + 16.0 * (2.5f64 / 1.75).powi(2);
        assert!((ratio - expected).abs() < 1e-9, "{ratio} vs {expected}");
    }

    #[test]
    fn flow_is_fast_when_soft_and_frozen_when_cold() {
        let s = LinkParams::DEFAULT.pla_stiffness;
        assert!(pla_flow_time_s(&s, 75.0) < 0.1);
        assert!(pla_flow_time_s(&s, 40.0) > 500.0);
    }
}
