//! The PLA rod: modulus on a glass-transition curve, applied cell by cell over the rod's
//! temperature field, and a viscoelastic (Maxwell) relaxation of each cell's stress-free
//! curvature with a time that follows WLF above Tg and Arrhenius below it.
//!
//! Bending is about the link's axis (the controller's model makes the same choice: the rod is
//! held at its offset by the silicone and the base), so each rod cell adds `E(T_c) A_c x_c²`
//! (`x_c` its centre's distance from the axis in the bending plane) to the stiffness and
//! `E(T_c) A_c x_c² κ0_c` to the moment it holds, `κ0_c` its frozen curvature.

use super::spec::{PlaSpec, GAS_CONSTANT_J_MOLK};
use morphlink_model::reference::fv_thermal::CrossSection;

/// Kelvin at 0 °C.
const ZERO_C_K: f64 = 273.15;
/// Bounds on the relaxation time, s (finite arithmetic; far beyond any run).
const TAU_BOUNDS_S: (f64, f64) = (1e-6, 1e13);

/// PLA Young's modulus at `temp_c`, Pa: log-modulus on a tanh step at Tg.
pub fn modulus_pa(s: &PlaSpec, temp_c: f64) -> f64 {
    let glassy = 0.5 * (1.0 - libm::tanh((temp_c - s.tg_c) / s.width_k));
    let (lg, lr) = (libm::log(s.e_glassy_pa), libm::log(s.e_rubbery_pa));
    libm::exp(lr + (lg - lr) * glassy)
}

/// Relaxation time of the PLA at `temp_c`, s: `τ_g · a_T` with WLF `log10 a_T = −C1 ΔT/(C2 +
/// ΔT)` above Tg and Arrhenius `ln a_T = Ea/R (1/T − 1/Tg)` below (continuous at Tg).
pub fn relaxation_time_s(s: &PlaSpec, temp_c: f64) -> f64 {
    let dt = temp_c - s.tg_c;
    let ln_a = if dt >= 0.0 {
        -s.wlf_c1 * dt / (s.wlf_c2_k + dt) * core::f64::consts::LN_10
    } else {
        s.creep_activation_j_mol / GAS_CONSTANT_J_MOLK
            * (1.0 / (temp_c + ZERO_C_K) - 1.0 / (s.tg_c + ZERO_C_K))
    };
    (s.tau_at_tg_s * libm::exp(ln_a.min(700.0))).clamp(TAU_BOUNDS_S.0, TAU_BOUNDS_S.1)
}

/// One cell of the rod.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RodCell {
    /// Cell index in the grid.
    pub cell: usize,
    /// PLA area in it, m².
    pub area_m2: f64,
    /// Centre (x, y), m; x is the bending-plane distance from the axis.
    pub centre_m: (f64, f64),
}

/// The rod's cells and their frozen curvatures.
#[derive(Clone, Debug)]
pub struct Rod {
    cells: Vec<RodCell>,
    frozen_per_m: Vec<f64>,
}

impl Rod {
    /// The rod of `grid`, every cell frozen at `kappa_per_m`.
    pub fn new(grid: &CrossSection, kappa_per_m: f64) -> Self {
        let cells: Vec<RodCell> = (0..grid.cells())
            .filter(|&c| grid.pla_area_m2(c) > 0.0)
            .map(|c| RodCell {
                cell: c,
                area_m2: grid.pla_area_m2(c),
                centre_m: grid.cell_centre_m(c),
            })
            .collect();
        let frozen_per_m = vec![kappa_per_m; cells.len()];
        Rod {
            cells,
            frozen_per_m,
        }
    }

    /// The rod's cells.
    pub fn cells(&self) -> &[RodCell] {
        &self.cells
    }

    /// Frozen curvature of each cell, 1/m.
    pub fn frozen_per_m(&self) -> &[f64] {
        &self.frozen_per_m
    }

    /// Modulus of each rod cell in the field `t_c`, Pa.
    pub fn moduli_pa(&self, s: &PlaSpec, t_c: &[f64]) -> Vec<f64> {
        self.cells
            .iter()
            .map(|c| modulus_pa(s, t_c[c.cell]))
            .collect()
    }

    /// Bending stiffness about the axis and the moment term `Σ E A x² κ0`, (N m², N m).
    pub fn stiffness(&self, s: &PlaSpec, t_c: &[f64]) -> (f64, f64) {
        let (mut b, mut m) = (0.0, 0.0);
        for (c, k0) in self.cells.iter().zip(&self.frozen_per_m) {
            let x = c.centre_m.0;
            let bc = modulus_pa(s, t_c[c.cell]) * c.area_m2 * x * x;
            b += bc;
            m += bc * k0;
        }
        (b, m)
    }

    /// Each cell's frozen curvature relaxes toward `kappa_per_m` over `dt_s` with its own time.
    pub fn relax(&mut self, s: &PlaSpec, t_c: &[f64], kappa_per_m: f64, dt_s: f64) {
        for (c, k0) in self.cells.iter().zip(self.frozen_per_m.iter_mut()) {
            let keep = libm::exp(-dt_s / relaxation_time_s(s, t_c[c.cell]));
            *k0 = kappa_per_m + (*k0 - kappa_per_m) * keep;
        }
    }
}
