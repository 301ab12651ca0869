//! The cross-section of a high-fidelity link: the project's 2-D finite-volume solver
//! (`morphlink_model::reference::fv_thermal`) with the nichrome's heat released at the rod's
//! surface, stepped by backward Euler against the medium's temperature.

use super::spec::{HifiSpec, DEFAULT_STEP_S};
use morphlink_model::reference::fv_thermal::{sectors_for, CrossSection, Layout, PlaHeat, Stepper};
use morphlink_model::reference::ReferenceError;
use morphlink_model::thermal::ResistanceMatrix;

/// The section's grid, its temperature field and a stepper for the step in use.
pub struct Section {
    cs: CrossSection,
    stepper: Stepper,
    /// Cell temperatures, °C (ring-major).
    t_c: Vec<f64>,
}

impl Section {
    /// The section of `spec`'s link with rim coefficient `h_w_m2k`, every cell at the
    /// spec's ambient, stepper for [`DEFAULT_STEP_S`].
    pub fn new(spec: &HifiSpec, h_w_m2k: f64) -> Result<Self, ReferenceError> {
        let mut layout = Layout::of_link(&spec.params);
        layout.h_w_m2k = h_w_m2k;
        let rings = spec.grid.rings();
        let cs =
            CrossSection::new(&layout, rings, sectors_for(rings))?.with_pla_heat(PlaHeat::Surface);
        let stepper = cs.stepper(DEFAULT_STEP_S)?;
        let t_c = vec![spec.ambient_c; cs.cells()];
        Ok(Section { cs, stepper, t_c })
    }

    /// The grid.
    pub fn grid(&self) -> &CrossSection {
        &self.cs
    }

    /// Cell temperatures, °C.
    pub fn field_c(&self) -> &[f64] {
        &self.t_c
    }

    /// The steady 2×2 resistance matrix of this grid (surface-released PLA heat), K/W.
    pub fn resistance_matrix(&self) -> Result<ResistanceMatrix, ReferenceError> {
        self.cs.resistance_matrix()
    }

    /// One backward-Euler step of `dt_s` with whole-link powers and the medium at `ambient_c`
    /// (a new step length factorises again).
    pub fn step(
        &mut self,
        dt_s: f64,
        p_tca_w: f64,
        p_pla_w: f64,
        ambient_c: f64,
    ) -> Result<(), ReferenceError> {
        if (self.stepper.dt_s() - dt_s).abs() > 1e-12 * dt_s.abs().max(1.0) {
            self.stepper = self.cs.stepper(dt_s)?;
        }
        self.stepper
            .step(&mut self.t_c, p_tca_w, p_pla_w, ambient_c);
        Ok(())
    }

    /// A new rim coefficient, W/(m² K); the temperatures stay.
    pub fn set_h(&mut self, h_w_m2k: f64) -> Result<(), ReferenceError> {
        self.cs.set_h(h_w_m2k);
        self.stepper = self.cs.stepper(self.stepper.dt_s())?;
        Ok(())
    }

    /// Area means of the TCA tube and of the PLA rod, °C.
    pub fn means_c(&self) -> (f64, f64) {
        self.cs.heater_means_k(&self.t_c)
    }

    /// Temperature at a point, °C.
    pub fn at_c(&self, (x_m, y_m): (f64, f64)) -> f64 {
        self.cs.value_at(&self.t_c, x_m, y_m)
    }

    /// Heat the rim gives the medium at `ambient_c` now, W.
    pub fn rim_power_w(&self, ambient_c: f64) -> f64 {
        self.cs.rim_power_w(&self.t_c, ambient_c)
    }

    /// Heat stored above `reference_c`, J.
    pub fn stored_j(&self, reference_c: f64) -> f64 {
        self.cs.stored_j(&self.t_c, reference_c)
    }
}
