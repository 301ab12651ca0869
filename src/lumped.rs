//! The link's lumped model as the controller runs it: in `f32`, the precision of the
//! Cortex-M4F's FPU (every `f64` operation there is a software routine: slower by some tens of
//! times and kilobytes of flash).
//!
//! The model itself is `morphlink-model`'s (`thermal`: the steady 2×2 resistance matrix and the
//! five-node network; `mechanics`: the constant-curvature balance), which the host's tools run
//! in `f64`. What of it is fixed for the built-in link (the network's capacities and shell
//! conductances, the bending stiffness, the PLA's second moment) the build script takes from
//! it once (`crate::link`); what the controller varies at run time (the convection a
//! calibration sets, the temperatures, the heater powers) is computed here with the same
//! formulas. The tests hold both to the `f64` model.

use crate::link::{
    BENDING_STIFFNESS_NM2, LINK, NETWORK_CAPACITY_J_K, NETWORK_SHELL_CONDUCTANCE_W_K,
    PLA_SECOND_MOMENT_ABOUT_AXIS_M4,
};
use crate::mathf::{exp, ln};
pub use morphlink_model::thermal::node;

// The link's fixed quantities, evaluated from the f64 parameters at compile time.
const PI: f64 = core::f64::consts::PI;
/// Radius of the silicone body, m.
const BODY_R_M: f32 = (LINK.geometry.body_diameter_m / 2.0) as f32;
/// Silicone conductivity, W/(m K).
const SILICONE_K_W_MK: f32 = LINK.materials.silicone.k_w_mk as f32;
/// `1 / (2 π k L)` of the silicone, K/W.
const UNIT_K_PER_W: f32 =
    (1.0 / (2.0 * PI * LINK.materials.silicone.k_w_mk * LINK.geometry.length_m)) as f32;
/// The TCA's internal resistance for uniform heating, `1 / (8 π k L)`, K/W.
const TCA_INTERNAL_K_PER_W: f32 =
    (1.0 / (8.0 * PI * LINK.materials.tca.k_w_mk * LINK.geometry.length_m)) as f32;
/// TCA and PLA radii, m.
const TCA_R_M: f32 = (LINK.geometry.tca_outer_diameter_m / 2.0) as f32;
const PLA_R_M: f32 = (LINK.geometry.pla_diameter_m / 2.0) as f32;
/// TCA and PLA offsets from the axis, m.
const TCA_OFFSET_M: f32 = LINK.geometry.tca_offset_m as f32;
const PLA_OFFSET_M: f32 = LINK.geometry.pla_offset_m as f32;
/// Link length, m.
const LENGTH_M: f32 = LINK.geometry.length_m as f32;
/// The TCA's force law (`morphlink_model::params::Mechanics`).
const PRELOAD_N: f32 = LINK.mechanics.preload_n as f32;
const FORCE_COEFF_N_PER_K: f32 = LINK.mechanics.force_coeff_n_per_k as f32;
const TCA_STIFFNESS_N_PER_M: f32 = LINK.mechanics.tca_stiffness_n_per_m as f32;
const NYLON_E0_PA: f32 = LINK.mechanics.nylon_e0_pa as f32;
const NYLON_E_SLOPE_PA_PER_C: f32 = LINK.mechanics.nylon_e_slope_pa_per_c as f32;
const T_REF_C: f32 = morphlink_model::params::T_REF_C as f32;
/// The PLA's stiffness across its glass transition (`morphlink_model::params::PlaStiffness`).
const PLA_E_GLASSY_PA: f32 = LINK.pla_stiffness.e_glassy_pa as f32;
const PLA_E_RUBBERY_PA: f32 = LINK.pla_stiffness.e_rubbery_pa as f32;
const PLA_TG_C: f32 = LINK.pla_stiffness.tg_c as f32;
const PLA_TRANSITION_WIDTH_K: f32 = LINK.pla_stiffness.transition_width_k as f32;

/// Steady thermal resistances of the cross-section, K/W (`morphlink_model::thermal::ResistanceMatrix`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ResistanceMatrix {
    /// TCA rise per TCA watt, K/W.
    pub r_tt: f32,
    /// PLA rise per PLA watt, K/W.
    pub r_pp: f32,
    /// Rise of either per watt in the other, K/W.
    pub r_tp: f32,
}

/// The link's steady resistance matrix at rim convection `h_w_m2k`, W/(m² K)
/// (`morphlink_model::thermal::resistance_matrix`: line sources in a disk, the convective rim
/// replaced by a fixed-temperature one at `a · exp(k / (h a))`, the method of images).
pub fn resistance_matrix(h_w_m2k: f32) -> ResistanceMatrix {
    let a = BODY_R_M;
    let b = a * exp(SILICONE_K_W_MK / (h_w_m2k * a));
    let self_r = |rho: f32, r_s: f32| UNIT_K_PER_W * ln((b * b - rho * rho) / (b * r_s));
    let (rt, rp) = (TCA_OFFSET_M, PLA_OFFSET_M);
    let mutual = UNIT_K_PER_W * ln(rp * (rt + b * b / rp) / (b * (rt + rp)));
    ResistanceMatrix {
        r_tt: self_r(rt, TCA_R_M) + TCA_INTERNAL_K_PER_W,
        r_pp: self_r(rp, PLA_R_M),
        r_tp: mutual,
    }
}

/// The five-node RC network (`morphlink_model::thermal::Network`): capacities (J/K),
/// conductances TCA→shell, shell→bulk, PLA→shell, shell→bulk, bulk→ambient (W/K) and node
/// temperatures (°C).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Network {
    /// Heat capacity of each node, J/K.
    pub capacity_j_k: [f32; node::COUNT],
    /// Conductances, W/K.
    pub conductance_w_k: [f32; 5],
    /// Node temperatures, °C.
    pub temp_c: [f32; node::COUNT],
}

impl Network {
    /// The link's network at rim convection `h_w_m2k` with every node at `ambient_c`.
    pub fn new(h_w_m2k: f32, ambient_c: f32) -> Self {
        let mut n = Network {
            capacity_j_k: NETWORK_CAPACITY_J_K,
            conductance_w_k: [0.0; 5],
            temp_c: [ambient_c; node::COUNT],
        };
        n.set_convection(h_w_m2k);
        n
    }

    /// Rebuilds the conductances for rim convection `h_w_m2k`, keeping the temperatures: the
    /// shells' are the link's own; the rest make the network's steady state the matrix's.
    pub fn set_convection(&mut self, h_w_m2k: f32) {
        let r = resistance_matrix(h_w_m2k);
        let [tca_shell, pla_shell] = NETWORK_SHELL_CONDUCTANCE_W_K;
        let r_bulk = r.r_tp;
        self.conductance_w_k = [
            tca_shell,
            1.0 / (r.r_tt - r_bulk - 1.0 / tca_shell),
            pla_shell,
            1.0 / (r.r_pp - r_bulk - 1.0 / pla_shell),
            1.0 / r_bulk,
        ];
    }

    /// Heat flows into each node, W.
    fn flows_w(&self, p_tca_w: f32, p_pla_w: f32, ambient_c: f32) -> [f32; node::COUNT] {
        use node::*;
        let (g, t) = (&self.conductance_w_k, &self.temp_c);
        let q0 = g[0] * (t[TCA] - t[TCA_SHELL]);
        let q1 = g[1] * (t[TCA_SHELL] - t[BULK]);
        let q2 = g[2] * (t[PLA] - t[PLA_SHELL]);
        let q3 = g[3] * (t[PLA_SHELL] - t[BULK]);
        let q4 = g[4] * (t[BULK] - ambient_c);
        [p_tca_w - q0, q0 - q1, p_pla_w - q2, q2 - q3, q1 + q3 - q4]
    }

    /// Longest stable explicit-Euler step, s: half the smallest node time constant `C / ΣG`.
    pub fn max_stable_step_s(&self) -> f32 {
        let g = &self.conductance_w_k;
        let sums = [g[0], g[0] + g[1], g[2], g[2] + g[3], g[1] + g[3] + g[4]];
        let mut tau = f32::INFINITY;
        for i in 0..node::COUNT {
            let t = self.capacity_j_k[i] / sums[i];
            if t < tau {
                tau = t;
            }
        }
        0.5 * tau
    }

    /// Advances the network by `dt_s` with constant heater powers (W) and ambient (°C), in as
    /// many explicit sub-steps as stability needs.
    pub fn advance(&mut self, dt_s: f32, p_tca_w: f32, p_pla_w: f32, ambient_c: f32) {
        if !(dt_s > 0.0) {
            return;
        }
        let q = dt_s / self.max_stable_step_s();
        // ⌈q⌉, at least 1 (`as` saturates; NaN gives 0).
        let mut n = q as u32;
        if (n as f32) < q {
            n += 1;
        }
        let n = n.max(1);
        let h = dt_s / n as f32;
        for _ in 0..n {
            let f = self.flows_w(p_tca_w, p_pla_w, ambient_c);
            for (i, flow) in f.iter().enumerate() {
                self.temp_c[i] += h * flow / self.capacity_j_k[i];
            }
        }
    }
}

/// The fraction of a step that remains after `dt_s` through a first-order lag of time constant
/// `tau_s` (`morphlink_model::thermal::lag_remaining`).
pub fn lag_remaining(dt_s: f32, tau_s: f32) -> f32 {
    if tau_s <= 0.0 {
        0.0
    } else {
        exp(-dt_s / tau_s)
    }
}

/// Nylon modulus relative to its value at the reference temperature.
fn modulus_ratio(temp_c: f32) -> f32 {
    let e = |t: f32| NYLON_E0_PA - NYLON_E_SLOPE_PA_PER_C * t;
    (e(temp_c) / e(T_REF_C)).max(0.0)
}

/// Equilibrium curvature, 1/m, for a TCA at `tca_temp_c` (°C) with an extra elastic term
/// `extra_stiffness_nm2 · (κ − extra_rest_per_m)` (`morphlink_model::mechanics::curvature_with_extra_per_m`).
pub fn curvature_with_extra_per_m(
    tca_temp_c: f32,
    extra_stiffness_nm2: f32,
    extra_rest_per_m: f32,
) -> f32 {
    let r = TCA_OFFSET_M;
    let e = modulus_ratio(tca_temp_c);
    let drive = r * e * (PRELOAD_N + FORCE_COEFF_N_PER_K * (tca_temp_c - T_REF_C));
    let stiffness =
        BENDING_STIFFNESS_NM2 + extra_stiffness_nm2 + r * r * LENGTH_M * TCA_STIFFNESS_N_PER_M * e;
    (drive + extra_stiffness_nm2 * extra_rest_per_m) / stiffness
}

/// Equilibrium curvature with the PLA soft, 1/m (`morphlink_model::mechanics::curvature_per_m`).
pub fn curvature_per_m(tca_temp_c: f32) -> f32 {
    curvature_with_extra_per_m(tca_temp_c, 0.0, 0.0)
}

/// The PLA rod's stiffness above its rubbery value at `temp_c`, N m²
/// (`morphlink_model::mechanics::pla_extra_stiffness_nm2`).
pub fn pla_extra_stiffness_nm2(temp_c: f32) -> f32 {
    let glassy_share = 1.0 / (1.0 + exp((temp_c - PLA_TG_C) / PLA_TRANSITION_WIDTH_K));
    let (lg, lr) = (ln(PLA_E_GLASSY_PA), ln(PLA_E_RUBBERY_PA));
    let modulus = exp(lr + (lg - lr) * glassy_share);
    (modulus - PLA_E_RUBBERY_PA).max(0.0) * PLA_SECOND_MOMENT_ABOUT_AXIS_M4
}

#[cfg(test)]
mod tests {
    use super::*;
    use morphlink_model::{mechanics, thermal};

    fn rel(a: f32, b: f64) -> f64 {
        ((a as f64 - b) / b).abs()
    }

    #[test]
    fn resistances_agree_with_the_f64_model_over_the_convection_range() {
        let (lo, hi) = crate::link::CONVECTION_RANGE_W_M2K;
        for i in 0..=40 {
            let h = lo + (hi - lo) * i as f32 / 40.0;
            let mut p = LINK;
            p.surroundings.h_w_m2k = h as f64;
            let want = thermal::resistance_matrix(&p);
            let got = resistance_matrix(h);
            assert!(rel(got.r_tt, want.r_tt) < 2e-6, "{h}: {got:?} {want:?}");
            assert!(rel(got.r_pp, want.r_pp) < 2e-6, "{h}: {got:?} {want:?}");
            assert!(rel(got.r_tp, want.r_tp) < 2e-5, "{h}: {got:?} {want:?}");
        }
    }

    #[test]
    fn network_follows_the_f64_model() {
        for h in [10.0f32, 20.0, LINK.surroundings.h_w_m2k as f32, 200.0] {
            let mut p = LINK;
            p.surroundings.h_w_m2k = h as f64;
            p.surroundings.ambient_c = 24.0;
            let mut want = thermal::Network::new(&p);
            let mut got = Network::new(h, 24.0);
            for k in 0..5 {
                assert!(rel(got.capacity_j_k[k], want.capacity_j_k[k]) < 1e-6);
                assert!(
                    rel(got.conductance_w_k[k], want.conductance_w_k[k]) < 2e-5,
                    "{h} {k}"
                );
            }
            // 300 s at 0.1 s: heating both, then cooling.
            for tick in 0..3000 {
                let (t, pl) = if tick < 1500 { (0.8, 1.5) } else { (0.0, 0.0) };
                want.advance(0.1, t as f64, pl as f64, 24.0);
                got.advance(0.1, t, pl, 24.0);
                for k in 0..5 {
                    let d = (got.temp_c[k] as f64 - want.temp_c[k]).abs();
                    assert!(d < 2e-3, "{h} W/m²K, tick {tick}, node {k}: {d} K");
                }
            }
        }
    }

    #[test]
    fn lags_and_mechanics_agree_with_the_f64_model() {
        for (dt, tau) in [(0.1f32, 3.0f32), (0.1, 0.5), (1.0, 2.0), (0.1, 0.0)] {
            let want = thermal::lag_remaining(dt as f64, tau as f64);
            assert!((lag_remaining(dt, tau) as f64 - want).abs() < 1e-6);
        }
        for i in 0..=130 {
            let t = i as f32;
            let want = mechanics::curvature_per_m(&LINK, t as f64);
            assert!(
                (curvature_per_m(t) as f64 - want).abs() < 1e-5 * want.abs().max(1.0),
                "{t}"
            );
            let want = mechanics::pla_extra_stiffness_nm2(&LINK, t as f64);
            let got = pla_extra_stiffness_nm2(t) as f64;
            // Against the soft link's own stiffness, the scale the curvature sees: above the
            // transition the excess is a small difference of two moduli.
            let scale = BENDING_STIFFNESS_NM2 as f64;
            assert!(
                (got - want).abs() <= 1e-5 * want + 1e-6 * scale,
                "{t}: {got} {want}"
            );
            let want = mechanics::curvature_with_extra_per_m(&LINK, t as f64, want, 20.0);
            let got = curvature_with_extra_per_m(t, got as f32, 20.0) as f64;
            assert!((got - want).abs() < 1e-5 * want.abs().max(1.0), "{t}");
        }
    }
}
