//! Every parameter of a high-fidelity link, its nominal value and source, and the ensemble
//! draw of links that differ from one another the way hand-made links do.
//!
//! Each range is a named constant with the reason for it beside it, as in the lumped
//! ensemble (`morphlink-sim`'s `ensemble`). [`HifiSpec::draw`] is reproducible: draw `i` of
//! seed `s` is the same link whatever else was drawn.

use super::tca::Tca;
use super::thermal::cross_section;
use crate::Medium;
use morphlink_model::draw::{splitmix, uniform};
use morphlink_model::mechanics::radius_mm;
use morphlink_model::params::{H_AIR_W_M2K, H_WATER_W_M2K};
use morphlink_model::reference::tca_physics::PhysicsLaw;
use morphlink_model::reference::ReferenceError;
use morphlink_model::table::power_of_entry_w;
use morphlink_model::LinkParams;

/// Glassy PLA modulus, Pa: DMA of printed PLA (Polymers 16(11):1526, 2024), 1046 MPa.
pub const PLA_E_GLASSY_PA: f64 = 1046e6;
/// Rubbery PLA modulus above Tg, Pa: the same DMA, 1.2 MPa.
pub const PLA_E_RUBBERY_PA: f64 = 1.2e6;
/// Nominal glass transition, °C: middle of the paper's 62 °C and the DMA's 65 °C.
pub const PLA_TG_NOMINAL_C: f64 = 63.5;
/// Half-width of the tanh transition of log-modulus, K: the DMA's storage modulus falls over
/// about 10 K (±2 widths hold 96 % of the drop).
pub const PLA_TRANSITION_WIDTH_K: f64 = 2.5;
/// Relaxation time of the PLA at Tg, s: the conventional definition of Tg (τ ≈ 100 s).
pub const PLA_TAU_AT_TG_S: f64 = 100.0;
/// WLF constants above Tg (the "universal" C1 = 17.44, C2 = 51.6 K of Williams, Landel and
/// Ferry): τ falls a decade every few kelvin above Tg.
pub const PLA_WLF_C1: f64 = 17.44;
/// WLF C2, K (see [`PLA_WLF_C1`]).
pub const PLA_WLF_C2_K: f64 = 51.6;
/// Apparent activation energy of the glassy PLA's creep below Tg, J/mol: sub-Tg creep of
/// amorphous polyesters is quoted at 100–200 kJ/mol; 150 kJ/mol puts τ at room temperature at
/// about two days, so a locked shape creeps slowly but does creep.
pub const PLA_CREEP_ACTIVATION_J_MOL: f64 = 150e3;
/// Gas constant, J/(mol K).
pub const GAS_CONSTANT_J_MOLK: f64 = 8.314;
/// Nominal EcoFlex 00-10 Young's modulus, Pa: between 37.8 kPa (Sparks et al. 2015) and the
/// maker's 55 kPa 100 % modulus.
pub const SILICONE_E_NOMINAL_PA: f64 = 45e3;
/// Silicone modulus range, Pa: the two sources' values are the ends.
pub const SILICONE_E_RANGE_PA: (f64, f64) = (37.8e3, 55e3);
/// Rest curvature of the cast silicone body, 1/m (a 0.5 m radius): a body cast around an
/// offset rod and a pre-stretched coil is not straight; the paper names pre-bending as one of
/// its two error sources. Estimate.
pub const SILICONE_REST_CURVATURE_PER_M: f64 = 2.0;
/// Spread of the silicone's rest curvature, 1/m.
pub const SILICONE_REST_CURVATURE_RANGE_PER_M: (f64, f64) = (1.0, 3.0);
/// Nominal heater resistances, Ω: nichrome wrap and TCA (the rig's nominal link). The TCA's
/// is at [`TCA_R_REF_C`].
pub const HEATER_OHM_NOMINAL: [f64; 2] = [30.0, 6.5];
/// Temperature at which the TCA's resistance is [`HEATER_OHM_NOMINAL`], °C (measured once at
/// room temperature).
pub const TCA_R_REF_C: f64 = 22.0;
/// Temperature coefficient of the TCA's resistance, 1/K: silver's is 3.8e-3/K, but the
/// plated thread's resistance is partly contact resistance between filaments that does not
/// follow the metal; 1.5e-3/K is an estimate (20 % more resistance at 150 °C).
pub const TCA_TCR_PER_K: f64 = 1.5e-3;
/// Spread of the TCA's temperature coefficient over the ensemble, 1/K (estimate: half to one
/// and a half times the nominal).
pub const TCA_TCR_RANGE_PER_K: (f64, f64) = (0.75e-3, 2.25e-3);
/// The TCA's resistance against its strain (gauge factor, ΔR/R per unit strain of the coil):
/// bending the link towards the TCA shortens the coil (it sits `tca_offset_m` off the axis), and
/// the plated thread's contacts between turns change with it. No source gives the number for
/// this coil; 0.3 is an estimate, sign included (a coil drawn shorter closing its turns on each
/// other would lower it: positive). Bending from the cast rest (53 mm) to 33 mm strains the
/// 2 mm-offset coil by −2.3 %, so 0.3 is 0.7 % of resistance, some 5 K of the temperature
/// term's worth.
pub const TCA_GAUGE: f64 = 0.3;
/// Spread of the gauge factor over the ensemble, both signs (estimate).
pub const TCA_GAUGE_RANGE: (f64, f64) = (-0.3, 0.9);
/// Temperature coefficient of the nichrome wrap's resistance, 1/K (Ni80Cr20, about 1e-4/K).
pub const PLA_HEATER_TCR_PER_K: f64 = 1.0e-4;
/// Its spread over the ensemble, 1/K (alloys and datasheets give 0.5–1.7e-4/K).
pub const PLA_HEATER_TCR_RANGE_PER_K: (f64, f64) = (0.5e-4, 1.7e-4);
/// Heater resistance factor range: ±10 % (hand-wound wrap, the TCA's 5–8 Ω narrowed by
/// measuring it once), as the lumped ensemble.
pub const HEATER_SCALE_RANGE: (f64, f64) = (0.9, 1.1);
/// Half-width of the TCA's force–temperature hysteresis, K: the force follows the
/// temperature through a play of this half-width, so heating and cooling curves are 3 K apart
/// (TCAs show a few kelvin of thermal hysteresis in force and stroke).
pub const TCA_HYSTERESIS_HALF_K: f64 = 1.5;
/// Share of the TCA's free stroke lost to creep of the loaded nylon at equilibrium: a few
/// percent (estimate from creep of annealed nylon 6,6 under a steady load).
pub const TCA_CREEP_FRACTION: f64 = 0.03;
/// Time constant of the TCA's creep, s: slow beside a morph's 100 s hold.
pub const TCA_CREEP_TIME_S: f64 = 400.0;
/// Convection factor range: ±30 % (stirred to still water, the scatter of the paper's nine
/// measurements), as the lumped ensemble.
pub const H_SCALE_RANGE: (f64, f64) = (0.7, 1.3);
/// Share of links in still air instead of water, as the lumped ensemble.
pub const AIR_SHARE: f64 = 0.1;
/// Ambient range, °C: a cool lab to a warm one, as the lumped ensemble.
pub const AMBIENT_RANGE_C: (f64, f64) = (15.0, 30.0);
/// Supply range, V: 12 V ± 10 %, as the lumped ensemble.
pub const SUPPLY_RANGE_V: (f64, f64) = (10.8, 13.2);
/// Nominal supply, V.
pub const SUPPLY_NOMINAL_V: f64 = 12.0;
/// Glass-transition spread, °C: the paper's 62 °C to the DMA's 65 °C (filament batches).
pub const TG_RANGE_C: (f64, f64) = (62.0, 65.0);
/// Calibration miss, offset: the table's radius misses the link's true radius by this share at
/// mid power, uniform in ± 1.5 % (RMS 0.87 %): the fit to three measured radii leaves about
/// 0.5 % and the measurement of a radius by three markers another 1 %.
pub const CALIBRATION_OFFSET_RANGE: (f64, f64) = (-0.015, 0.015);
/// Calibration miss, slope across the table's power range (from −half to +half of it at the
/// ends), uniform: the fit's error grows away from its three points.
pub const CALIBRATION_SLOPE_RANGE: (f64, f64) = (-0.02, 0.02);
/// Thermistor bead heat capacity, J/K: a 1.5 mm glass-coated bead (1.8 mm³ × 2.5 MJ/(m³ K))
/// with its lead stubs.
pub const BEAD_CAPACITY_J_K: f64 = 4.5e-3;
/// Nominal dissipation constant of an embedded bead (bead to local silicone, contact included),
/// W/K: a sphere of 0.75 mm radius in silicone conducts `4π k a` = 1.9 mW/K; datasheets give
/// 0.5–2 mW/K in still air. With [`BEAD_CAPACITY_J_K`] it gives a 3 s time constant.
pub const BEAD_DISSIPATION_NOMINAL_W_K: f64 = 1.5e-3;
/// Dissipation constant of the ambient bead in the medium, W/K (still water conducts more than
/// silicone; the datasheet's upper end).
pub const BEAD_AMBIENT_DISSIPATION_W_K: f64 = 2.0e-3;
/// Dissipation range of an embedded bead, W/K: a bead pressed against its heater to one
/// loosely potted (time constants 2.2–6 s, the lumped ensemble's 2–6 s).
pub const BEAD_DISSIPATION_RANGE_W_K: (f64, f64) = (0.75e-3, 2.0e-3);
/// Gap from the nichrome-wrapped rod's surface to the PLA bead's centre, m: a 0.6 mm bead
/// touching the 0.1 mm wrap.
pub const PLA_BEAD_GAP_M: f64 = 0.4e-3;
/// Gap from the TCA's surface to the TCA bead's centre, m: the bead cannot sit on a 1.4 mm
/// coil that moves; it is potted beside it.
pub const TCA_BEAD_GAP_M: f64 = 0.5e-3;
/// Spread of the bead gaps, m: ± 0.15 mm of placement by hand.
pub const BEAD_GAP_SPREAD_M: f64 = 0.15e-3;
/// Angle of the beads around their heater from the direction perpendicular to the bending
/// plane, rad: nominal 0 (beside the heater, off the bending plane).
pub const BEAD_ANGLE_SPREAD_RAD: f64 = 0.5;
/// Thermistor R25 tolerance: ± 1 % parts.
pub const BEAD_R25_TOLERANCE: f64 = 0.01;
/// Thermistor Beta tolerance: B25/50 = 3950 K ± 1 %.
pub const BEAD_BETA_TOLERANCE: f64 = 0.01;
/// Nominal thermistor: 10 kΩ at 25 °C.
pub const BEAD_R25_OHM: f64 = 10_000.0;
/// Nominal thermistor Beta, K.
pub const BEAD_BETA_K: f64 = 3950.0;
/// Divider: pull-up to the ADC reference, Ω (the board's 10 kΩ).
pub const DIVIDER_PULLUP_OHM: f64 = 10_000.0;
/// Divider bias, V (the ADC reference the pull-up goes to).
pub const DIVIDER_BIAS_V: f64 = 3.3;
/// Rings of the full grid (100 sectors, 3328 cells): heater means and bead temperatures within
/// about 1 % of a 24-ring grid over a morph-like transient, so converged for these purposes.
pub const FULL_RINGS: usize = 32;
/// Shifts of the reduced-order model's rational-Krylov basis, 1/s: σ = 0 makes steady states
/// exact; the rest span the section's time constants from the whole link's (minutes) to the
/// TCA tube's (a tenth of a second), three per decade. Up to 27 modes.
pub const ROM_SHIFTS_PER_S: [f64; 9] = [0.0, 0.003, 0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0];
/// Step the thermal stepper is factorised for, s (the controller's tick).
pub const DEFAULT_STEP_S: f64 = 0.1;

/// Reference temperature of the TCA's stroke polynomial, °C (the physics law's 20 °C).
pub const STROKE_REF_C: f64 = 20.0;

/// Solves a 3×3 system by Cramer's rule; `None` if it is singular.
fn solve3(a: [[f64; 3]; 3], b: [f64; 3]) -> Option<[f64; 3]> {
    let det = |m: [[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(a);
    if !(d.abs() > 0.0) || !d.is_finite() {
        return None;
    }
    let mut x = [0.0; 3];
    for (k, xk) in x.iter_mut().enumerate() {
        let mut m = a;
        for i in 0..3 {
            m[i][k] = b[i];
        }
        *xk = det(m) / d;
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// The grid a plant solves its cross-section on, and how.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Grid {
    /// [`FULL_RINGS`] rings, every cell stepped.
    Full,
    /// The reduced-order model ([`ROM_SHIFTS_PER_S`]) of the full grid: for ensembles.
    Reduced,
    /// Any number of rings, every cell stepped (tests).
    Rings(usize),
    /// The reduced-order model of a grid of that many rings (tests).
    ReducedRings(usize),
}

impl Grid {
    /// Number of rings.
    pub fn rings(self) -> usize {
        match self {
            Grid::Full | Grid::Reduced => FULL_RINGS,
            Grid::Rings(n) | Grid::ReducedRings(n) => n,
        }
    }
}

/// PLA rod: modulus against temperature and its viscoelastic relaxation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaSpec {
    /// Glassy modulus, Pa.
    pub e_glassy_pa: f64,
    /// Rubbery modulus, Pa.
    pub e_rubbery_pa: f64,
    /// Glass transition, °C.
    pub tg_c: f64,
    /// Half-width of the tanh transition of log-modulus, K.
    pub width_k: f64,
    /// Relaxation time at Tg, s.
    pub tau_at_tg_s: f64,
    /// WLF C1 (above Tg).
    pub wlf_c1: f64,
    /// WLF C2, K.
    pub wlf_c2_k: f64,
    /// Activation energy below Tg, J/mol.
    pub creep_activation_j_mol: f64,
}

/// TCA: force law, resistance, hysteresis, creep.
///
/// The push is `k(T) (S(T*) − creep − δ)`: `k(T)` the helical spring rate of [`PhysicsLaw`]
/// (`G(T) d⁴/(8 D³ n)`) at the tube's temperature, `S` the free stroke at the play's
/// temperature `T*`. The physics law's stroke `x_pre + R l_f γ τ_b ε_th(T)` with
/// `ε_th = ∫ α dT` and `α` linear in T is a quadratic in `u = T − 20 °C`; its three
/// coefficients (preload, `γ α₀`, `γ α₁` in effect) are identified per link
/// ([`HifiSpec::identify`]), because the thread's expansion and untwist are what a calibration
/// measures.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TcaSpec {
    /// Spring rate source: the helical-spring law of the coil.
    pub law: PhysicsLaw,
    /// Free stroke `a + b u + c u²`, `u = T − STROKE_REF_C`: (m, m/K, m/K²).
    pub stroke_coeffs: [f64; 3],
    /// Resistance at [`TCA_R_REF_C`], Ω.
    pub r_ref_ohm: f64,
    /// Temperature coefficient of resistance, 1/K.
    pub tcr_per_k: f64,
    /// Gauge factor: ΔR/R per unit strain of the coil (shortening is negative strain).
    pub gauge: f64,
    /// Half-width of the force–temperature play, K.
    pub hysteresis_half_k: f64,
    /// Share of free stroke lost to creep at equilibrium.
    pub creep_fraction: f64,
    /// Creep time constant, s.
    pub creep_time_s: f64,
}

/// One thermistor bead.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BeadSpec {
    /// Where it sits: a point of the cross-section (m), or `None` in the medium.
    pub position_m: Option<(f64, f64)>,
    /// Heat capacity, J/K.
    pub capacity_j_k: f64,
    /// Dissipation constant to the local temperature (contact included), W/K.
    pub dissipation_w_k: f64,
    /// True R25, Ω.
    pub r25_ohm: f64,
    /// True Beta, K.
    pub beta_k: f64,
}

/// Everything that defines one high-fidelity link.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HifiSpec {
    /// The link as the controller's model knows it (geometry, materials, the calibrated table
    /// constants); its surroundings are the calibration's (water, 22 °C).
    pub params: LinkParams,
    /// Grid of the cross-section.
    pub grid: Grid,
    /// Medium now.
    pub medium: Medium,
    /// Convection relative to the medium's nominal coefficient.
    pub h_scale: f64,
    /// Temperature of the medium, °C.
    pub ambient_c: f64,
    /// Heater supply, V.
    pub supply_v: f64,
    /// Nichrome wrap resistance at [`TCA_R_REF_C`], Ω.
    pub pla_heater_ohm: f64,
    /// Temperature coefficient of the wrap's resistance, 1/K (it follows the rod's mean).
    pub pla_heater_tcr_per_k: f64,
    /// TCA.
    pub tca: TcaSpec,
    /// PLA.
    pub pla: PlaSpec,
    /// Silicone Young's modulus, Pa.
    pub silicone_e_pa: f64,
    /// Silicone body's rest curvature, 1/m.
    pub silicone_rest_per_m: f64,
    /// Beads: PLA, TCA, ambient.
    pub beads: [BeadSpec; 3],
    /// Calibration miss (offset, slope) the TCA law was identified against.
    pub calibration_miss: (f64, f64),
}

/// Bead beside a heater of centre (x, y) and radius `r`, `gap` from its surface, turned by
/// `angle` from the +y direction (perpendicular to the bending plane).
fn beside(x: f64, r: f64, gap: f64, angle: f64) -> (f64, f64) {
    let d = r + gap;
    (x + d * libm::sin(angle), d * libm::cos(angle))
}

impl HifiSpec {
    /// The nominal link of `params` (the controller's link), identified on `grid`.
    pub fn nominal(params: LinkParams, grid: Grid) -> Result<Self, ReferenceError> {
        let mut spec = Self::unidentified(params, grid);
        spec.identify()?;
        Ok(spec)
    }

    /// The nominal values, the TCA's stroke not yet identified.
    fn unidentified(params: LinkParams, grid: Grid) -> Self {
        let g = &params.geometry;
        let embedded = |pos| BeadSpec {
            position_m: Some(pos),
            capacity_j_k: BEAD_CAPACITY_J_K,
            dissipation_w_k: BEAD_DISSIPATION_NOMINAL_W_K,
            r25_ohm: BEAD_R25_OHM,
            beta_k: BEAD_BETA_K,
        };
        HifiSpec {
            params,
            grid,
            medium: Medium::Water,
            h_scale: params.surroundings.h_w_m2k / H_WATER_W_M2K,
            ambient_c: params.surroundings.ambient_c,
            supply_v: SUPPLY_NOMINAL_V,
            pla_heater_ohm: HEATER_OHM_NOMINAL[0],
            pla_heater_tcr_per_k: PLA_HEATER_TCR_PER_K,
            tca: TcaSpec {
                law: PhysicsLaw::identified(&params, 100.0),
                stroke_coeffs: [0.0; 3],
                r_ref_ohm: HEATER_OHM_NOMINAL[1],
                tcr_per_k: TCA_TCR_PER_K,
                gauge: TCA_GAUGE,
                hysteresis_half_k: TCA_HYSTERESIS_HALF_K,
                creep_fraction: TCA_CREEP_FRACTION,
                creep_time_s: TCA_CREEP_TIME_S,
            },
            pla: PlaSpec {
                e_glassy_pa: PLA_E_GLASSY_PA,
                e_rubbery_pa: PLA_E_RUBBERY_PA,
                tg_c: PLA_TG_NOMINAL_C,
                width_k: PLA_TRANSITION_WIDTH_K,
                tau_at_tg_s: PLA_TAU_AT_TG_S,
                wlf_c1: PLA_WLF_C1,
                wlf_c2_k: PLA_WLF_C2_K,
                creep_activation_j_mol: PLA_CREEP_ACTIVATION_J_MOL,
            },
            silicone_e_pa: SILICONE_E_NOMINAL_PA,
            silicone_rest_per_m: SILICONE_REST_CURVATURE_PER_M,
            beads: [
                embedded(beside(
                    -g.pla_offset_m,
                    g.pla_diameter_m / 2.0,
                    PLA_BEAD_GAP_M,
                    0.0,
                )),
                embedded(beside(
                    g.tca_offset_m,
                    g.tca_outer_diameter_m / 2.0,
                    TCA_BEAD_GAP_M,
                    0.0,
                )),
                BeadSpec {
                    position_m: None,
                    capacity_j_k: BEAD_CAPACITY_J_K,
                    dissipation_w_k: BEAD_AMBIENT_DISSIPATION_W_K,
                    r25_ohm: BEAD_R25_OHM,
                    beta_k: BEAD_BETA_K,
                },
            ],
            calibration_miss: (0.0, 0.0),
        }
    }

    /// Draw number `index` of the ensemble with seed `seed` around the link of `params`:
    /// every factor uniform in its range, the TCA law then identified so the controller's
    /// table misses this link's radius curve by the drawn calibration miss.
    pub fn draw(
        params: LinkParams,
        grid: Grid,
        seed: u64,
        index: u64,
    ) -> Result<Self, ReferenceError> {
        let mut s = seed ^ index.wrapping_mul(0xd1b5_4a32_d192_ed03);
        splitmix(&mut s);
        let mut spec = Self::unidentified(params, grid);
        let g = params.geometry;
        let air = uniform(&mut s, (0.0, 1.0)) < AIR_SHARE;
        spec.medium = if air { Medium::Air } else { Medium::Water };
        spec.h_scale = uniform(&mut s, H_SCALE_RANGE);
        spec.ambient_c = uniform(&mut s, AMBIENT_RANGE_C);
        spec.supply_v = uniform(&mut s, SUPPLY_RANGE_V);
        spec.pla_heater_ohm *= uniform(&mut s, HEATER_SCALE_RANGE);
        spec.tca.r_ref_ohm *= uniform(&mut s, HEATER_SCALE_RANGE);
        spec.pla.tg_c = uniform(&mut s, TG_RANGE_C);
        spec.silicone_e_pa = uniform(&mut s, SILICONE_E_RANGE_PA);
        spec.silicone_rest_per_m = uniform(&mut s, SILICONE_REST_CURVATURE_RANGE_PER_M);
        let spread = (-BEAD_GAP_SPREAD_M, BEAD_GAP_SPREAD_M);
        let angle = (-BEAD_ANGLE_SPREAD_RAD, BEAD_ANGLE_SPREAD_RAD);
        let pla_pos = beside(
            -g.pla_offset_m,
            g.pla_diameter_m / 2.0,
            PLA_BEAD_GAP_M + uniform(&mut s, spread),
            uniform(&mut s, angle),
        );
        let tca_pos = beside(
            g.tca_offset_m,
            g.tca_outer_diameter_m / 2.0,
            TCA_BEAD_GAP_M + uniform(&mut s, spread),
            uniform(&mut s, angle),
        );
        spec.beads[0].position_m = Some(pla_pos);
        spec.beads[1].position_m = Some(tca_pos);
        for b in spec.beads.iter_mut() {
            if b.position_m.is_some() {
                b.dissipation_w_k = uniform(&mut s, BEAD_DISSIPATION_RANGE_W_K);
            }
            b.r25_ohm *= 1.0 + uniform(&mut s, (-BEAD_R25_TOLERANCE, BEAD_R25_TOLERANCE));
            b.beta_k *= 1.0 + uniform(&mut s, (-BEAD_BETA_TOLERANCE, BEAD_BETA_TOLERANCE));
        }
        spec.calibration_miss = (
            uniform(&mut s, CALIBRATION_OFFSET_RANGE),
            uniform(&mut s, CALIBRATION_SLOPE_RANGE),
        );
        // The resistances' coefficients from a stream of their own, so adding them left every
        // earlier draw of the ensemble as it was.
        let mut e = s ^ 0x5eed_e1ec_0000_0001;
        splitmix(&mut e);
        spec.pla_heater_tcr_per_k = uniform(&mut e, PLA_HEATER_TCR_RANGE_PER_K);
        spec.tca.tcr_per_k = uniform(&mut e, TCA_TCR_RANGE_PER_K);
        spec.tca.gauge = uniform(&mut e, TCA_GAUGE_RANGE);
        spec.identify()?;
        Ok(spec)
    }

    /// Rim coefficient now, W/(m² K).
    pub fn h_w_m2k(&self) -> f64 {
        self.h_scale
            * match self.medium {
                Medium::Water => H_WATER_W_M2K,
                Medium::Air => H_AIR_W_M2K,
            }
    }

    /// Bending stiffness of the silicone body about the link's axis, N m²: `E π a⁴/4` less the
    /// two inclusions' share.
    pub fn silicone_stiffness_nm2(&self) -> f64 {
        let g = &self.params.geometry;
        let pi = core::f64::consts::PI;
        let a = g.body_diameter_m / 2.0;
        let hole = |d: f64, rho: f64| {
            let r = d / 2.0;
            pi * r * r * r * r / 4.0 + pi * r * r * rho * rho
        };
        let i = pi * a * a * a * a / 4.0
            - hole(g.pla_diameter_m, g.pla_offset_m)
            - hole(g.tca_outer_diameter_m, g.tca_offset_m);
        self.silicone_e_pa * i
    }

    /// Radius the link truly has at steady TCA power `p_tca_w` with the PLA held soft at the
    /// table's hold power, at the calibration conditions, by the table's curve and the
    /// calibration miss, mm. What [`Self::identify`] fits the TCA law to.
    pub fn calibrated_radius_mm(&self, p_tca_w: f64) -> f64 {
        let p = &self.params;
        let span = p.table_max_power_w;
        let (off, slope) = self.calibration_miss;
        radius_mm(p, p_tca_w) * (1.0 + off + slope * (p_tca_w / span - 0.5))
    }

    /// Fits the TCA's stroke polynomial so the link's steady curvature on
    /// this grid, with the PLA at the hold power, at the calibration conditions (the model's
    /// surroundings), through the TCA's heating branch and its creep at equilibrium, matches
    /// [`Self::calibrated_radius_mm`] at the table's powers (least squares). This is the
    /// link's own calibration, done once per link: the table is the controller's.
    pub fn identify(&mut self) -> Result<(), ReferenceError> {
        let p = self.params;
        let resistance = cross_section(self, p.surroundings.h_w_m2k)?.resistance_matrix()?;
        let g = &p.geometry;
        let (r, l) = (g.tca_offset_m, g.length_m);
        let b_sil = self.silicone_stiffness_nm2();
        // Normal equations of the least-squares fit of S(T) = a + b u + c u², u = T − 20 °C.
        let mut ata = [[0.0f64; 3]; 3];
        let mut atb = [0.0f64; 3];
        for i in 0..p.table_entries {
            let pw = power_of_entry_w(&p, i);
            let rise = resistance.rises_k(pw, p.pla_hold_power_w).0;
            let t = p.surroundings.ambient_c + rise;
            let u = t - self.tca.hysteresis_half_k - STROKE_REF_C;
            let k = self.tca.law.spring_rate_n_per_m(t);
            let kappa = 1e3 / self.calibrated_radius_mm(pw);
            let need =
                (kappa * (b_sil + r * r * l * k) - b_sil * self.silicone_rest_per_m) / (r * k);
            let row = [1.0, u, u * u];
            for a in 0..3 {
                for b in 0..3 {
                    ata[a][b] += row[a] * row[b];
                }
                atb[a] += row[a] * need;
            }
        }
        let c = solve3(ata, atb).ok_or(ReferenceError::NonFinite("TCA law identification"))?;
        let keep = 1.0 - self.tca.creep_fraction;
        self.tca.stroke_coeffs = [c[0] / keep, c[1] / keep, c[2] / keep];
        Ok(())
    }

    /// The link's own steady radii at TCA powers `powers_w` with the PLA held soft at the hold
    /// power, at the calibration conditions: the FV section's steady TCA temperature, the
    /// heating branch of the play, creep settled, the PLA fully relaxed, mm. Independent of
    /// [`Self::identify`]'s fit: the tests measure the table's miss with it.
    pub fn steady_radii_mm(&self, powers_w: &[f64]) -> Result<Vec<f64>, ReferenceError> {
        let p = &self.params;
        let res = cross_section(self, p.surroundings.h_w_m2k)?.resistance_matrix()?;
        let g = &p.geometry;
        let (r, l) = (g.tca_offset_m, g.length_m);
        let b_sil = self.silicone_stiffness_nm2();
        Ok(powers_w
            .iter()
            .map(|&pw| {
                let t = p.surroundings.ambient_c + res.rises_k(pw, p.pla_hold_power_w).0;
                let mut tca = Tca::at_rest(&self.tca, t - self.tca.hysteresis_half_k);
                tca.update(&self.tca, t, 1.0);
                let k = self.tca.law.spring_rate_n_per_m(t);
                let s = tca.stroke_m(&self.tca);
                let kappa =
                    (r * k * s + b_sil * self.silicone_rest_per_m) / (b_sil + r * r * l * k);
                1e3 / kappa
            })
            .collect())
    }
}
