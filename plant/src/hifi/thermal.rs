//! The cross-section of a high-fidelity link: the project's 2-D finite-volume solver
//! (`morphlink_model::reference::fv_thermal`) with the nichrome's heat released at the rod's
//! surface, stepped by backward Euler against the medium's temperature, either on the grid
//! itself or through its reduced-order model ([`Grid::Reduced`]).

use super::spec::{Grid, HifiSpec, DEFAULT_STEP_S, ROM_SHIFTS_PER_S};
use morphlink_model::reference::fv_thermal::{
    sectors_for, CrossSection, Layout, PlaHeat, Rom, Stepper,
};
use morphlink_model::reference::ReferenceError;
use morphlink_model::thermal::ResistanceMatrix;

/// The grid of `spec`'s link with rim coefficient `h_w_m2k` and surface-released wrap heat.
pub fn cross_section(spec: &HifiSpec, h_w_m2k: f64) -> Result<CrossSection, ReferenceError> {
    let mut layout = Layout::of_link(&spec.params);
    layout.h_w_m2k = h_w_m2k;
    let rings = spec.grid.rings();
    Ok(CrossSection::new(&layout, rings, sectors_for(rings))?.with_pla_heat(PlaHeat::Surface))
}

#[derive(Clone, Debug)]
enum Solver {
    /// Banded backward Euler on every cell.
    Grid(Stepper),
    /// The reduced-order model; only the watched cells of the field are kept current.
    Rom { rom: Rom, watched: Vec<usize> },
}

/// The section's grid, its temperature field and its time stepping.
#[derive(Clone, Debug)]
pub struct Section {
    cs: CrossSection,
    solver: Solver,
    /// Cell temperatures, °C (ring-major). In the reduced form only the rod's cells and the
    /// beads' interpolation cells are current.
    t_c: Vec<f64>,
}

impl Section {
    /// The section of `spec`'s link with rim coefficient `h_w_m2k`, every cell at the
    /// spec's ambient, stepping at [`DEFAULT_STEP_S`].
    pub fn new(spec: &HifiSpec, h_w_m2k: f64) -> Result<Self, ReferenceError> {
        let cs = cross_section(spec, h_w_m2k)?;
        let t_c = vec![spec.ambient_c; cs.cells()];
        let solver = if spec.grid.is_reduced() {
            let mut rom = cs.rom(&ROM_SHIFTS_PER_S, DEFAULT_STEP_S)?;
            rom.set_field(&t_c);
            let mut watched: Vec<usize> = (0..cs.cells())
                .filter(|&c| cs.pla_area_m2(c) > 0.0)
                .collect();
            for b in &spec.beads {
                if let Some((x, y)) = b.position_m {
                    watched.extend(cs.stencil(x, y).iter().map(|(c, _)| *c));
                }
            }
            watched.sort_unstable();
            watched.dedup();
            Solver::Rom { rom, watched }
        } else {
            Solver::Grid(cs.stepper(DEFAULT_STEP_S)?)
        };
        Ok(Section { cs, solver, t_c })
    }

    /// The grid.
    pub fn grid(&self) -> &CrossSection {
        &self.cs
    }

    /// Modes of the reduced form, or `None` on the full grid.
    pub fn rom_order(&self) -> Option<usize> {
        match &self.solver {
            Solver::Grid(_) => None,
            Solver::Rom { rom, .. } => Some(rom.order()),
        }
    }

    /// Cell temperatures, °C (in the reduced form, current for the rod's and beads' cells).
    pub fn field_c(&self) -> &[f64] {
        &self.t_c
    }

    /// Every cell's temperature, °C (the reduced form reconstructs it).
    pub fn full_field_c(&self) -> Vec<f64> {
        match &self.solver {
            Solver::Grid(_) => self.t_c.clone(),
            Solver::Rom { rom, .. } => rom.field_c(),
        }
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
        let same = |a: f64| (a - dt_s).abs() <= 1e-12 * dt_s.abs().max(1.0);
        match &mut self.solver {
            Solver::Grid(stepper) => {
                if !same(stepper.dt_s()) {
                    *stepper = self.cs.stepper(dt_s)?;
                }
                stepper.step(&mut self.t_c, p_tca_w, p_pla_w, ambient_c);
            }
            Solver::Rom { rom, watched } => {
                if !same(rom.dt_s()) {
                    rom.set_dt(dt_s)?;
                }
                rom.step(p_tca_w, p_pla_w, ambient_c);
                for &c in watched.iter() {
                    self.t_c[c] = rom.cell_c(c);
                }
            }
        }
        Ok(())
    }

    /// A new rim coefficient, W/(m² K); the temperatures stay.
    pub fn set_h(&mut self, h_w_m2k: f64) -> Result<(), ReferenceError> {
        let field = self.full_field_c();
        self.cs.set_h(h_w_m2k);
        match &mut self.solver {
            Solver::Grid(stepper) => *stepper = self.cs.stepper(stepper.dt_s())?,
            Solver::Rom { rom, .. } => {
                let mut new = self.cs.rom(&ROM_SHIFTS_PER_S, rom.dt_s())?;
                new.set_field(&field);
                *rom = new;
            }
        }
        Ok(())
    }

    /// Area means of the TCA tube and of the PLA rod, °C.
    pub fn means_c(&self) -> (f64, f64) {
        match &self.solver {
            Solver::Grid(_) => self.cs.heater_means_k(&self.t_c),
            Solver::Rom { rom, .. } => rom.heater_means_c(),
        }
    }

    /// Temperature at a bead's point (or any point of a full grid), °C.
    pub fn at_c(&self, (x_m, y_m): (f64, f64)) -> f64 {
        self.cs.value_at(&self.t_c, x_m, y_m)
    }

    /// Heat the rim gives the medium at `ambient_c` now, W.
    pub fn rim_power_w(&self, ambient_c: f64) -> f64 {
        self.cs.rim_power_w(&self.full_field_c(), ambient_c)
    }

    /// Heat stored above `reference_c`, J.
    pub fn stored_j(&self, reference_c: f64) -> f64 {
        self.cs.stored_j(&self.full_field_c(), reference_c)
    }
}

impl Grid {
    /// True for the reduced-order forms.
    pub fn is_reduced(self) -> bool {
        matches!(self, Grid::Reduced | Grid::ReducedRings(_))
    }
}
