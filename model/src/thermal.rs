//! Lumped thermal model of the link cross-section: the steady 2×2 thermal-resistance matrix
//! between the two heaters, and a five-node RC network for transients.
//!
//! Steady state: each heater is a line source in a disk of silicone. The convective rim
//! (`−k ∂T/∂n = h (T − T∞)`) is replaced by a fixed-temperature rim at the extended radius
//! `b = a · exp(k / (h a))`, which is exact for a centred source; the off-centre sources then
//! follow from the method of images (the Green's function of a disk). Self resistances are
//! the image-method temperature at the heater's surface; the TCA adds its small internal
//! resistance for uniform heating of a solid cylinder, `1 / (8 π k L)`.
//!
//! Transient: a star of nodes — TCA, a silicone shell around it, PLA, a silicone shell around
//! it, and the bulk silicone — whose steady state equals the 2×2 matrix exactly. A single
//! first-order lag is wrong for the TCA under water: the TCA and its shell respond within
//! about a second, the bulk over tens of seconds.

use crate::params::LinkParams;
use core::f64::consts::PI;
use libm::{exp, log};

/// Steady thermal resistances of the cross-section, K/W: temperature rise of each heater per
/// watt in itself (`r_tt`, `r_pp`) and per watt in the other (`r_tp`, symmetric).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ResistanceMatrix {
    /// TCA rise per TCA watt, K/W.
    pub r_tt: f64,
    /// PLA rise per PLA watt, K/W.
    pub r_pp: f64,
    /// Rise of either per watt in the other, K/W.
    pub r_tp: f64,
}

impl ResistanceMatrix {
    /// Steady temperature rises above ambient `(tca_k, pla_k)` for the given powers.
    pub fn rises_k(&self, p_tca_w: f64, p_pla_w: f64) -> (f64, f64) {
        (
            self.r_tt * p_tca_w + self.r_tp * p_pla_w,
            self.r_tp * p_tca_w + self.r_pp * p_pla_w,
        )
    }
}

/// Extended radius `a · exp(k/(h a))` at which a fixed-temperature rim gives the same
/// resistance as the convective rim for a centred source, m.
pub fn extended_radius_m(p: &LinkParams) -> f64 {
    let a = p.geometry.body_diameter_m / 2.0;
    a * exp(p.materials.silicone.k_w_mk / (p.surroundings.h_w_m2k * a))
}

/// The steady 2×2 thermal-resistance matrix of the link, K/W.
pub fn resistance_matrix(p: &LinkParams) -> ResistanceMatrix {
    let g = &p.geometry;
    let b = extended_radius_m(p);
    let unit = 1.0 / (2.0 * PI * p.materials.silicone.k_w_mk * g.length_m);
    let self_r = |rho: f64, r_s: f64| unit * log((b * b - rho * rho) / (b * r_s));
    let tca_r = g.tca_outer_diameter_m / 2.0;
    let pla_r = g.pla_diameter_m / 2.0;
    let tca_internal = 1.0 / (8.0 * PI * p.materials.tca.k_w_mk * g.length_m);
    // Sources on opposite sides of the axis: x_t = +ρt, x_p = −ρp; image of the PLA at −b²/ρp.
    let (rt, rp) = (g.tca_offset_m, g.pla_offset_m);
    let mutual = unit * log(rp * (rt + b * b / rp) / (b * (rt + rp)));
    ResistanceMatrix {
        r_tt: self_r(rt, tca_r) + tca_internal,
        r_pp: self_r(rp, pla_r),
        r_tp: mutual,
    }
}

/// Node indices of the transient network.
pub mod node {
    /// The TCA itself.
    pub const TCA: usize = 0;
    /// Silicone shell around the TCA.
    pub const TCA_SHELL: usize = 1;
    /// The PLA rod and its nichrome wrap.
    pub const PLA: usize = 2;
    /// Silicone shell around the PLA rod.
    pub const PLA_SHELL: usize = 3;
    /// The rest of the silicone body.
    pub const BULK: usize = 4;
    /// Number of nodes.
    pub const COUNT: usize = 5;
}

/// Outer radius of the silicone shells as a multiple of the heater's radius: large enough to
/// hold the fast local response, small enough to stay inside the body for the default link.
pub const SHELL_RADIUS_RATIO: f64 = 1.6;

/// Five-node RC network: capacities (J/K), conductances (W/K) and node temperatures (°C).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Network {
    /// Heat capacity of each node, J/K.
    pub capacity_j_k: [f64; node::COUNT],
    /// Conductance TCA→shell, shell→bulk, PLA→shell, shell→bulk, bulk→ambient, W/K.
    pub conductance_w_k: [f64; 5],
    /// Node temperatures, °C.
    pub temp_c: [f64; node::COUNT],
}

impl Network {
    /// Builds the network of `p` with every node at the ambient temperature.
    pub fn new(p: &LinkParams) -> Self {
        let mut n = Network {
            capacity_j_k: [0.0; node::COUNT],
            conductance_w_k: [0.0; 5],
            temp_c: [p.surroundings.ambient_c; node::COUNT],
        };
        n.set_params(p);
        n
    }

    /// Rebuilds capacities and conductances from `p` (e.g. a new `h`), keeping temperatures.
    pub fn set_params(&mut self, p: &LinkParams) {
        let g = &p.geometry;
        let m = &p.materials;
        let r = resistance_matrix(p);
        let unit = 1.0 / (2.0 * PI * m.silicone.k_w_mk * g.length_m);
        let tca_r = g.tca_outer_diameter_m / 2.0;
        let pla_r = g.pla_diameter_m / 2.0;
        let tca_internal = 1.0 / (8.0 * PI * m.tca.k_w_mk * g.length_m);
        let r_tca_shell = tca_internal + unit * log(SHELL_RADIUS_RATIO);
        let r_pla_shell = unit * log(SHELL_RADIUS_RATIO);
        let r_bulk = r.r_tp;
        let r_tca_rest = r.r_tt - r_bulk - r_tca_shell;
        let r_pla_rest = r.r_pp - r_bulk - r_pla_shell;
        self.conductance_w_k = [
            1.0 / r_tca_shell,
            1.0 / r_tca_rest,
            1.0 / r_pla_shell,
            1.0 / r_pla_rest,
            1.0 / r_bulk,
        ];
        let area = |d: f64| PI * d * d / 4.0;
        let l = g.length_m;
        let tca_area = area(g.tca_outer_diameter_m) - area(g.tca_inner_diameter_m);
        let tca_shell = PI * (tca_r * tca_r) * (SHELL_RADIUS_RATIO * SHELL_RADIUS_RATIO - 1.0);
        let pla_area = area(g.pla_diameter_m);
        let pla_shell = PI * (pla_r * pla_r) * (SHELL_RADIUS_RATIO * SHELL_RADIUS_RATIO - 1.0);
        let body = area(g.body_diameter_m) - area(g.tca_outer_diameter_m) - pla_area;
        let bulk = body - tca_shell - pla_shell;
        let sil = m.silicone.rho_cp();
        self.capacity_j_k = [
            m.tca.rho_cp() * tca_area * l,
            sil * tca_shell * l,
            m.pla.rho_cp() * pla_area * l,
            sil * pla_shell * l,
            sil * bulk * l,
        ];
    }

    /// Heat flows into each node, W, for heater powers and ambient temperature.
    fn flows_w(
        &self,
        t: &[f64; node::COUNT],
        p_tca_w: f64,
        p_pla_w: f64,
        ambient_c: f64,
    ) -> [f64; node::COUNT] {
        use node::*;
        let g = &self.conductance_w_k;
        let q0 = g[0] * (t[TCA] - t[TCA_SHELL]);
        let q1 = g[1] * (t[TCA_SHELL] - t[BULK]);
        let q2 = g[2] * (t[PLA] - t[PLA_SHELL]);
        let q3 = g[3] * (t[PLA_SHELL] - t[BULK]);
        let q4 = g[4] * (t[BULK] - ambient_c);
        [p_tca_w - q0, q0 - q1, p_pla_w - q2, q2 - q3, q1 + q3 - q4]
    }

    /// Longest explicit-Euler step that is stable for this network, s (half the smallest
    /// node time constant `C / ΣG`).
    pub fn max_stable_step_s(&self) -> f64 {
        let g = &self.conductance_w_k;
        let sums = [g[0], g[0] + g[1], g[2], g[2] + g[3], g[1] + g[3] + g[4]];
        let mut tau = f64::INFINITY;
        for i in 0..node::COUNT {
            let t = self.capacity_j_k[i] / sums[i];
            if t < tau {
                tau = t;
            }
        }
        0.5 * tau
    }

    /// Advances the network by `dt_s` with constant heater powers (W) and ambient (°C), using
    /// as many explicit sub-steps as stability needs.
    pub fn advance(&mut self, dt_s: f64, p_tca_w: f64, p_pla_w: f64, ambient_c: f64) {
        if !(dt_s > 0.0) {
            return;
        }
        let h_max = self.max_stable_step_s();
        let n = libm::ceil(dt_s / h_max).max(1.0) as usize;
        let h = dt_s / n as f64;
        for _ in 0..n {
            let f = self.flows_w(&self.temp_c, p_tca_w, p_pla_w, ambient_c);
            for (i, flow) in f.iter().enumerate() {
                self.temp_c[i] += h * flow / self.capacity_j_k[i];
            }
        }
    }

    /// Steady node temperatures for constant powers, °C (solved directly along the star).
    pub fn steady_c(&self, p_tca_w: f64, p_pla_w: f64, ambient_c: f64) -> [f64; node::COUNT] {
        let g = &self.conductance_w_k;
        let bulk = ambient_c + (p_tca_w + p_pla_w) / g[4];
        let tca_shell = bulk + p_tca_w / g[1];
        let pla_shell = bulk + p_pla_w / g[3];
        [
            tca_shell + p_tca_w / g[0],
            tca_shell,
            pla_shell + p_pla_w / g[2],
            pla_shell,
            bulk,
        ]
    }
}

/// Exponential decay helper shared by lags: the fraction of a step that remains after `dt_s`
/// with time constant `tau_s`.
pub fn lag_remaining(dt_s: f64, tau_s: f64) -> f64 {
    if tau_s <= 0.0 {
        0.0
    } else {
        exp(-dt_s / tau_s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matrix_of_default_link_is_plausible() {
        let r = resistance_matrix(&LinkParams::DEFAULT);
        // Self resistances of a few tens of K/W, mutual much smaller.
        assert!(r.r_tt > 25.0 && r.r_tt < 45.0, "{r:?}");
        assert!(r.r_pp > 20.0 && r.r_pp < 40.0, "{r:?}");
        assert!(r.r_tp > 3.0 && r.r_tp < 0.5 * r.r_pp, "{r:?}");
    }

    #[test]
    fn centred_source_matches_exact_concentric_solution() {
        // A heater of radius r0 at the centre of a disk with a convective rim has the exact
        // resistance ln(a/r0)/(2πkL) + 1/(2πahL); the image form must reproduce it.
        let mut p = LinkParams::DEFAULT;
        p.geometry.pla_offset_m = 1e-9;
        let r = resistance_matrix(&p);
        let g = &p.geometry;
        let a = g.body_diameter_m / 2.0;
        let r0 = g.pla_diameter_m / 2.0;
        let k = p.materials.silicone.k_w_mk;
        let exact = log(a / r0) / (2.0 * PI * k * g.length_m)
            + 1.0 / (2.0 * PI * a * p.surroundings.h_w_m2k * g.length_m);
        assert!(
            (r.r_pp - exact).abs() < 1e-6 * exact,
            "{} vs {}",
            r.r_pp,
            exact
        );
    }

    #[test]
    fn less_convection_raises_every_resistance() {
        let water = resistance_matrix(&LinkParams::DEFAULT);
        let mut p = LinkParams::DEFAULT;
        p.surroundings.h_w_m2k = crate::params::H_AIR_W_M2K;
        let air = resistance_matrix(&p);
        assert!(air.r_tt > water.r_tt && air.r_pp > water.r_pp && air.r_tp > water.r_tp);
    }

    #[test]
    fn network_steady_state_equals_matrix() {
        let p = LinkParams::DEFAULT;
        let n = Network::new(&p);
        let r = resistance_matrix(&p);
        let (pt, pp) = (0.8, 1.5);
        let s = n.steady_c(pt, pp, 22.0);
        let (rt, rp) = r.rises_k(pt, pp);
        assert!((s[node::TCA] - 22.0 - rt).abs() < 1e-9);
        assert!((s[node::PLA] - 22.0 - rp).abs() < 1e-9);
        for gc in n.conductance_w_k {
            assert!(gc > 0.0 && gc.is_finite());
        }
    }

    #[test]
    fn transient_converges_to_steady_and_has_fast_and_slow_parts() {
        let p = LinkParams::DEFAULT;
        let mut n = Network::new(&p);
        let steady = n.steady_c(1.0, 0.0, 22.0)[node::TCA];
        let rise = steady - 22.0;
        n.advance(2.0, 1.0, 0.0, 22.0);
        let fast = (n.temp_c[node::TCA] - 22.0) / rise;
        n.advance(38.0, 1.0, 0.0, 22.0);
        let slow = (n.temp_c[node::TCA] - 22.0) / rise;
        n.advance(600.0, 1.0, 0.0, 22.0);
        let end = (n.temp_c[node::TCA] - 22.0) / rise;
        // A fifth of the rise within 2 s, yet still 5 % short of steady at 40 s. A single
        // first-order lag through the 2 s point would be within 0.2 % of steady at 40 s.
        assert!(fast > 0.2, "fast {fast}");
        assert!(slow < 0.95, "slow {slow}");
        assert!((end - 1.0).abs() < 1e-3, "end {end}");
        let single_lag_tau = -2.0 / libm::log(1.0 - fast);
        let single_lag_40 = 1.0 - libm::exp(-40.0 / single_lag_tau);
        assert!(
            single_lag_40 - slow > 0.03,
            "single lag {single_lag_40}, network {slow}"
        );
    }
}
