//! A high-fidelity link, structurally different from the controller's model (feature `hifi`,
//! host only: `std` and `morphlink-model/reference`). See `docs/plant.md`.
//!
//! * **Thermal**: the project's 2-D polar finite-volume cross-section (`fv_thermal`: TCA tube,
//!   water core, PLA rod, silicone, convective rim with `h` from the medium), stepped by
//!   backward Euler at the plant's step. The nichrome's heat is released in the rod's boundary
//!   cells (the wire lies on the rod's surface), the TCA's through its tube. Not the
//!   controller's five-node network. [`Grid::Full`] steps all 3328 cells of a 32-ring grid;
//!   [`Grid::Reduced`] steps its 27-mode reduced-order model (`fv_thermal::Rom`, rational-Krylov
//!   projection: exact at steady state, within 1e-5 of the full grid in a morph, 50× cheaper).
//! * **Heaters**: duty → power through the true supply and resistances; the TCA's resistance
//!   follows its mean temperature (`R(T) = R₂₂ (1 + α (T − 22))`), the wrap's is constant.
//! * **Beads**: a heat capacity each, tied to the grid temperature at its position beside the
//!   heater (PLA bead in the silicone touching the wrap, TCA bead 0.5 mm from the TCA, ambient
//!   bead in the medium) by a dissipation constant, self-heated by the divider's bias; the
//!   sample reports the *apparent* °C, what the nominal conversion (10 kΩ, 3950 K) reads from
//!   the bead's true resistance (its own R25 and Beta). Their lag is this physics' own.
//! * **PLA**: modulus on a tanh glass transition (1046 → 1.2 MPa, Tg 62–65 °C) cell by cell over
//!   the rod's non-uniform field, about the link's axis; each cell's frozen curvature relaxes
//!   with WLF time above Tg and Arrhenius below (slow creep at room temperature).
//! * **TCA**: the helical spring rate of `tca_physics::PhysicsLaw` times the physics law's free
//!   stroke (untwist with thermal strain, a quadratic in temperature identified per link),
//!   through a play of ±1.5 K (hysteresis), less a slow creep of the coil.
//! * **Mechanics** (shared with the controller's model): quasi-static constant-curvature
//!   bending, the TCA's extension `δ = r L κ` and moment `r F`, bending about the link's axis.
//!   Not shared: the thermal model, the force law and its hysteresis and creep, the silicone's
//!   own stiffness and rest curvature (pre-bend), the PLA's field of moduli and its
//!   viscoelastic memory, the beads, `R(T)`, and a per-link calibration miss of the table.
//!
//! The balance each step: `κ = (r k S + B_sil κ_sil + Σ B_c κ0_c) / (B_sil + Σ B_c + r² L k)`
//! with `k` the coil's spring rate at the tube's temperature, `S` its creep-reduced free stroke
//! at the play's temperature, `B_c = E(T_c) A_c x_c²` of each rod cell.

pub mod bead;
pub mod pla;
pub mod spec;
pub mod tca;
#[cfg(test)]
mod tests;
pub mod thermal;

pub use spec::{BeadSpec, Grid, HifiSpec, PlaSpec, TcaSpec};

use crate::{Duties, Plant, Sample, SetError, Setting, Truth};
use bead::Bead;
use morphlink_model::reference::ReferenceError;
use pla::Rod;
use tca::Tca;
use thermal::Section;

/// A high-fidelity link's state.
#[derive(Clone, Debug)]
pub struct Hifi {
    spec: HifiSpec,
    section: Section,
    rod: Rod,
    tca: Tca,
    beads: [Bead; 3],
    kappa_per_m: f64,
    /// The curvature the TCA's resistance was measured at (the link as built), 1/m: its strain
    /// counts from there.
    kappa_ref_per_m: f64,
    powers_w: [f64; 2],
    time_s: f64,
}

impl Hifi {
    /// A link at rest at its ambient: every cell and bead at the medium's temperature (beads
    /// a little above it by their self-heating), the TCA's creep settled, the PLA frozen at
    /// the curvature the link relaxes to with the TCA cold (its pre-bend).
    pub fn new(spec: HifiSpec) -> Result<Self, ReferenceError> {
        let section = Section::new(&spec, spec.h_w_m2k())?;
        let amb = spec.ambient_c;
        let tca = Tca::at_rest(&spec.tca, amb);
        let mut hifi = Hifi {
            spec,
            rod: Rod::new(section.grid(), 0.0),
            section,
            tca,
            beads: [Bead { temp_c: amb }; 3],
            kappa_per_m: 0.0,
            kappa_ref_per_m: 0.0,
            powers_w: [0.0; 2],
            time_s: 0.0,
        };
        let rest = hifi.balance_per_m(false);
        hifi.rod = Rod::new(hifi.section.grid(), rest);
        hifi.kappa_per_m = rest;
        hifi.kappa_ref_per_m = rest;
        for (b, s) in hifi.beads.iter_mut().zip(&hifi.spec.beads) {
            let r = bead::resistance_ohm(s, amb);
            b.temp_c = amb + bead::self_heating_w(r) / s.dissipation_w_k;
        }
        Ok(hifi)
    }

    /// The link's parameters.
    pub fn spec(&self) -> &HifiSpec {
        &self.spec
    }

    /// The thermal section (field, grid).
    pub fn section(&self) -> &Section {
        &self.section
    }

    /// The PLA rod (cells, frozen curvatures).
    pub fn rod(&self) -> &Rod {
        &self.rod
    }

    /// The TCA's state.
    pub fn tca(&self) -> &Tca {
        &self.tca
    }

    /// True bead temperatures (PLA, TCA, ambient), °C.
    pub fn bead_true_c(&self) -> [f64; 3] {
        [
            self.beads[0].temp_c,
            self.beads[1].temp_c,
            self.beads[2].temp_c,
        ]
    }

    /// Curvature now, 1/m.
    pub fn curvature_per_m(&self) -> f64 {
        self.kappa_per_m
    }

    /// Modulus of each rod cell now, Pa (in the order of [`Rod::cells`]).
    pub fn pla_moduli_pa(&self) -> Vec<f64> {
        self.rod.moduli_pa(&self.spec.pla, self.section.field_c())
    }

    /// The PLA's bending stiffness about the axis now, N m².
    pub fn pla_stiffness_nm2(&self) -> f64 {
        self.rod.stiffness(&self.spec.pla, self.section.field_c()).0
    }

    /// TCA push at the present curvature, N.
    pub fn tca_push_n(&self) -> f64 {
        let g = &self.spec.params.geometry;
        let (t_tca, _) = self.section.means_c();
        self.tca.push_n(
            &self.spec.tca,
            t_tca,
            g.tca_offset_m * g.length_m * self.kappa_per_m,
        )
    }

    /// Equilibrium curvature for the present field, TCA and rod (`with_pla` false: the PLA
    /// carries no moment, as when fully relaxed), 1/m.
    fn balance_per_m(&self, with_pla: bool) -> f64 {
        let g = &self.spec.params.geometry;
        let (r, l) = (g.tca_offset_m, g.length_m);
        let (t_tca, _) = self.section.means_c();
        let k = self.spec.tca.law.spring_rate_n_per_m(t_tca);
        let s = self.tca.stroke_m(&self.spec.tca);
        let b_sil = self.spec.silicone_stiffness_nm2();
        let (b_pla, m_pla) = if with_pla {
            self.rod.stiffness(&self.spec.pla, self.section.field_c())
        } else {
            (0.0, 0.0)
        };
        (r * k * s + b_sil * self.spec.silicone_rest_per_m + m_pla)
            / (b_sil + b_pla + r * r * l * k)
    }

    /// The TCA coil's strain now (shortening negative): it sits `tca_offset_m` off the axis,
    /// on the side a tighter bend shortens.
    pub fn tca_strain(&self) -> f64 {
        -self.spec.params.geometry.tca_offset_m * (self.kappa_per_m - self.kappa_ref_per_m)
    }

    /// The heaters' true resistances now, Ω (PLA wrap at the rod's mean temperature; TCA at
    /// its mean temperature and strain).
    pub fn heater_ohm_now(&self) -> [f64; 2] {
        let (t_tca, t_pla) = self.section.means_c();
        let pla = self.spec.pla_heater_ohm
            * (1.0 + self.spec.pla_heater_tcr_per_k * (t_pla - spec::TCA_R_REF_C));
        [
            pla.max(1e-3),
            tca::resistance_ohm(&self.spec.tca, t_tca, self.tca_strain()),
        ]
    }

    fn supply_power_w(&self, ohm: f64, duty: f64) -> f64 {
        let d = if duty.is_finite() {
            duty.clamp(0.0, 1.0)
        } else {
            0.0
        };
        d * self.spec.supply_v * self.spec.supply_v / ohm
    }
}

impl Plant for Hifi {
    /// A step that is not positive and finite, or whose factorisation fails, changes nothing.
    fn step(&mut self, dt_s: f64, duty: Duties) {
        if !(dt_s > 0.0) || !dt_s.is_finite() {
            return;
        }
        let [r_pla, r_tca] = self.heater_ohm_now();
        let p_pla = self.supply_power_w(r_pla, duty.pla);
        let p_tca = self.supply_power_w(r_tca, duty.tca);
        let amb = self.spec.ambient_c;
        if self.section.step(dt_s, p_tca, p_pla, amb).is_err() {
            return;
        }
        self.powers_w = [p_pla, p_tca];
        let (t_tca, _) = self.section.means_c();
        self.tca.update(&self.spec.tca, t_tca, dt_s);
        self.kappa_per_m = self.balance_per_m(true);
        self.rod.relax(
            &self.spec.pla,
            self.section.field_c(),
            self.kappa_per_m,
            dt_s,
        );
        for (b, s) in self.beads.iter_mut().zip(&self.spec.beads) {
            let local = match s.position_m {
                Some(pos) => self.section.at_c(pos),
                None => amb,
            };
            b.step(s, local, dt_s);
        }
        self.time_s += dt_s;
    }

    fn sample(&self) -> Sample {
        let read = |i: usize| self.beads[i].apparent_c(&self.spec.beads[i]);
        Sample {
            t_pla_c: read(0),
            t_tca_c: read(1),
            t_amb_c: read(2),
            supply_v: self.spec.supply_v,
            radius_mm: 1e3 / self.kappa_per_m,
            heater_ohm: Some(self.heater_ohm_now()),
        }
    }

    fn truth(&self) -> Truth {
        let (tca_c, pla_c) = self.section.means_c();
        Truth {
            time_s: self.time_s,
            pla_c,
            tca_c,
            pla_w: self.powers_w[0],
            tca_w: self.powers_w[1],
        }
    }

    fn set(&mut self, setting: Setting) -> Result<(), SetError> {
        match setting {
            Setting::SupplyV(v) => self.spec.supply_v = v,
            Setting::AmbientC(c) => self.spec.ambient_c = c,
            Setting::Medium(m) => {
                let old = self.spec.medium;
                self.spec.medium = m;
                if self.section.set_h(self.spec.h_w_m2k()).is_err() {
                    self.spec.medium = old;
                    return Err(SetError::Unsupported);
                }
            }
        }
        Ok(())
    }
}
