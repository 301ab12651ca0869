//! TCA force laws: the linear law of the lumped model and the physics-based law the paper cites
//! (Abbas & Zhao, ICRA 2017): heating makes the twisted nylon fibre expand and untwist; the coil
//! is a helical spring whose free length follows the fibre's twist.
//!
//! Physics law. A close-coiled spring of mean radius `R` made of `n` turns of fibre (length
//! `l_f = 2π R n`) lengthens by `R · Δφ` when its fibre turns by `Δφ` in total. The fibre's bias
//! twist `τ_b` (576 turns/m inserted) relaxes with thermal strain `ε_th(T) = ∫ α(T) dT` as
//! `Δτ = γ τ_b ε_th`, so the free length grows by `ΔL(T) = R l_f γ τ_b ε_th(T)`. With the spring
//! rate `k(T) = G(T) d⁴/(8 D³ n)`, `G = E(T)/(2(1+ν))`, the push at extension `δ` is
//! `F = k(T) (x_pre + ΔL(T) − δ)`. `α(T) = 4.158e-5 + 9.82e-7 T` /°C, `E(T)` and `ν = 0.45` are
//! the nylon data of the project's parameters; the untwist coefficient `γ` is the one unknown and
//! is identified from the calibrated linear law over the working range ([`PhysicsLaw::identified`]).
//! Both laws are affine in `δ` at a fixed temperature, which is all the rod solvers need.

use crate::params::{LinkParams, Mechanics, T_REF_C};
use core::f64::consts::PI;

/// The push of a TCA at one temperature: `F(δ) = push_n − stiffness_n_per_m · δ`, N.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForceAtTemp {
    /// Push at zero extension, N.
    pub push_n: f64,
    /// Loss of push per metre of extension, N/m.
    pub stiffness_n_per_m: f64,
}

impl ForceAtTemp {
    /// Push at extension `delta_m`, N.
    pub fn force_n(&self, delta_m: f64) -> f64 {
        self.push_n - self.stiffness_n_per_m * delta_m
    }
}

/// Which TCA law a model uses.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TcaLaw {
    /// `F = e(T) (F0 + c (T − 20) − k δ)` (lumped model, fitted).
    Linear(Mechanics),
    /// Fibre untwisting with thermal expansion, coil as a helical spring.
    Physics(PhysicsLaw),
}

impl TcaLaw {
    /// The law's push at `temp_c`.
    pub fn at(&self, temp_c: f64) -> ForceAtTemp {
        match self {
            TcaLaw::Linear(m) => {
                let e = crate::mechanics::modulus_ratio(m, temp_c);
                ForceAtTemp {
                    push_n: e * (m.preload_n + m.force_coeff_n_per_k * (temp_c - T_REF_C)),
                    stiffness_n_per_m: e * m.tca_stiffness_n_per_m,
                }
            }
            TcaLaw::Physics(p) => p.at(temp_c),
        }
    }
}

/// Nylon thermal expansion coefficient intercept, 1/°C (project parameters).
pub const NYLON_ALPHA0_PER_C: f64 = 4.158e-5;
/// Nylon thermal expansion coefficient slope, 1/°C² (project parameters).
pub const NYLON_ALPHA1_PER_C2: f64 = 9.82e-7;
/// Nylon Poisson ratio (project parameters).
pub const NYLON_POISSON: f64 = 0.45;
/// Twist inserted in the fibre before coiling, turns/m (paper Sec. III-A).
pub const BIAS_TWIST_TURNS_PER_M: f64 = 576.0;

/// The physics-based TCA law of one actuator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhysicsLaw {
    /// Mean coil radius `(D_outer − d_fibre)/2`, m.
    pub coil_radius_m: f64,
    /// Fibre diameter, m.
    pub fibre_diameter_m: f64,
    /// Number of turns (close-coiled over the link length).
    pub turns: f64,
    /// Untwist per unit thermal strain `γ` (dimensionless, identified).
    pub untwist_per_strain: f64,
    /// Preload extension `x_pre`, m: the push at 20 °C and zero extension is `k x_pre`.
    pub preload_m: f64,
    /// Nylon Young's modulus intercept, Pa.
    pub nylon_e0_pa: f64,
    /// Nylon Young's modulus slope, Pa/°C.
    pub nylon_e_slope_pa_per_c: f64,
}

impl PhysicsLaw {
    /// Thermal strain of the fibre from 20 °C to `temp_c`, `∫ α dT` (dimensionless).
    pub fn thermal_strain(temp_c: f64) -> f64 {
        let t0 = T_REF_C;
        NYLON_ALPHA0_PER_C * (temp_c - t0) + 0.5 * NYLON_ALPHA1_PER_C2 * (temp_c * temp_c - t0 * t0)
    }

    /// Spring rate of the coil at `temp_c`, N/m.
    pub fn spring_rate_n_per_m(&self, temp_c: f64) -> f64 {
        let e = (self.nylon_e0_pa - self.nylon_e_slope_pa_per_c * temp_c).max(0.0);
        let g = e / (2.0 * (1.0 + NYLON_POISSON));
        let d = self.fibre_diameter_m;
        let dm = 2.0 * self.coil_radius_m;
        g * d * d * d * d / (8.0 * dm * dm * dm * self.turns)
    }

    /// Free-length growth per unit of `γ` at `temp_c`, m: `R l_f τ_b ε_th(T)`.
    fn stroke_per_gamma_m(&self, temp_c: f64) -> f64 {
        let fibre_length = 2.0 * PI * self.coil_radius_m * self.turns;
        let bias = 2.0 * PI * BIAS_TWIST_TURNS_PER_M;
        self.coil_radius_m * fibre_length * bias * Self::thermal_strain(temp_c)
    }

    /// The push at `temp_c`.
    pub fn at(&self, temp_c: f64) -> ForceAtTemp {
        let k = self.spring_rate_n_per_m(temp_c);
        ForceAtTemp {
            push_n: k
                * (self.preload_m + self.untwist_per_strain * self.stroke_per_gamma_m(temp_c)),
            stiffness_n_per_m: k,
        }
    }

    /// The law for the link of `p`, with `γ` identified by least squares against the calibrated
    /// linear law's free stroke `(c/k)(T − 20)` at temperatures from 20 °C to `max_temp_c`, and
    /// the preload equal to the linear law's.
    pub fn identified(p: &LinkParams, max_temp_c: f64) -> Self {
        let g = &p.geometry;
        let m = &p.mechanics;
        let mut law = PhysicsLaw {
            coil_radius_m: (g.tca_outer_diameter_m - g.tca_fibre_diameter_m) / 2.0,
            fibre_diameter_m: g.tca_fibre_diameter_m,
            turns: g.length_m / g.tca_fibre_diameter_m,
            untwist_per_strain: 0.0,
            preload_m: 0.0,
            nylon_e0_pa: m.nylon_e0_pa,
            nylon_e_slope_pa_per_c: m.nylon_e_slope_pa_per_c,
        };
        let k20 = law.spring_rate_n_per_m(T_REF_C);
        law.preload_m = m.preload_n / k20;
        let (mut sab, mut saa) = (0.0, 0.0);
        for i in 1..=50 {
            let t = T_REF_C + (max_temp_c - T_REF_C) * i as f64 / 50.0;
            let a = law.stroke_per_gamma_m(t);
            let b = m.force_coeff_n_per_k / m.tca_stiffness_n_per_m * (t - T_REF_C);
            sab += a * b;
            saa += a * a;
        }
        law.untwist_per_strain = sab / saa;
        law
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spring_rate_matches_the_helical_spring_estimate_of_the_lumped_model() {
        let p = LinkParams::DEFAULT;
        let law = PhysicsLaw::identified(&p, 100.0);
        let k = law.spring_rate_n_per_m(T_REF_C);
        assert!(
            (k - p.mechanics.tca_stiffness_n_per_m).abs() < 0.2,
            "k = {k}"
        );
    }

    #[test]
    fn identified_law_is_close_to_the_linear_law_and_bends_upward() {
        let p = LinkParams::DEFAULT;
        let phys = TcaLaw::Physics(PhysicsLaw::identified(&p, 100.0));
        let lin = TcaLaw::Linear(p.mechanics);
        let g = PhysicsLaw::identified(&p, 100.0).untwist_per_strain;
        assert!(g > 0.1 && g < 100.0, "γ = {g}");
        for t in [30.0, 60.0, 90.0] {
            let (a, b) = (phys.at(t).force_n(1e-3), lin.at(t).force_n(1e-3));
            assert!((a - b).abs() < 0.1 * b, "{t} °C: physics {a} linear {b}");
        }
        // α grows with T, so the physics law's stroke is convex in T: relative to the straight
        // line it is low in the middle of the range and high at its ends.
        let law = PhysicsLaw::identified(&p, 100.0);
        let s = |t: f64| law.stroke_per_gamma_m(t);
        assert!(s(60.0) < 0.5 * (s(20.0) + s(100.0)));
    }
}
