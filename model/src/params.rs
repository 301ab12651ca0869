//! Parameters of one link: geometry, materials, surroundings, hold power and fitted constants.
//!
//! SI units throughout (m, W, K, N, Pa) except where a name says otherwise. The defaults describe
//! the seed paper's link in the paper's experiment: under water, PLA held at 1.5 W.

/// Thermal properties of one material.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "std", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "std", serde(deny_unknown_fields))]
pub struct Material {
    /// Thermal conductivity, W/(m K).
    pub k_w_mk: f64,
    /// Density, kg/m³.
    pub rho_kg_m3: f64,
    /// Specific heat, J/(kg K).
    pub cp_j_kgk: f64,
}

impl Material {
    /// Volumetric heat capacity, J/(m³ K).
    pub fn rho_cp(&self) -> f64 {
        self.rho_kg_m3 * self.cp_j_kgk
    }
}

/// Cross-section and length of the link. The TCA and the PLA rod sit on opposite sides of the
/// axis in the bending plane; the TCA is on the convex side (it is an extension actuator).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "std", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "std", serde(deny_unknown_fields))]
pub struct Geometry {
    /// Silicone body diameter, m (paper: 8 mm).
    pub body_diameter_m: f64,
    /// Link length, m (paper: 50 mm).
    pub length_m: f64,
    /// TCA outer diameter, m (paper: 1.4 mm).
    pub tca_outer_diameter_m: f64,
    /// TCA inner diameter, m (the mandrel hole, paper: 0.4 mm).
    pub tca_inner_diameter_m: f64,
    /// Diameter of the twisted fibre the TCA is coiled from, m (paper: 0.5 mm).
    pub tca_fibre_diameter_m: f64,
    /// Distance of the TCA centre from the link axis, m (paper Fig. 2: about 2.0 mm).
    pub tca_offset_m: f64,
    /// PLA rod diameter, m (paper: 1.75 mm filament).
    pub pla_diameter_m: f64,
    /// Distance of the PLA centre from the axis on the side opposite the TCA, m (about 2.5 mm).
    pub pla_offset_m: f64,
}

/// The three materials of the cross-section (paper, Table I).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "std", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "std", serde(deny_unknown_fields))]
pub struct Materials {
    /// Silver-coated nylon TCA.
    pub tca: Material,
    /// PLA rod.
    pub pla: Material,
    /// EcoFlex 00-10 body.
    pub silicone: Material,
}

/// The link's surroundings.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "std", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "std", serde(deny_unknown_fields))]
pub struct Surroundings {
    /// Convective heat-transfer coefficient at the rim, W/(m² K). Water: 101.3 (paper Eq. 10);
    /// still air: 20 ([`H_AIR_W_M2K`]).
    pub h_w_m2k: f64,
    /// Temperature of the medium, °C. The paper does not state its water temperature; 22 °C is
    /// an assumption (room-temperature tap water).
    pub ambient_c: f64,
}

/// Convection coefficient under still water, W/(m² K): mean of nine measurements (paper Eq. 10).
pub const H_WATER_W_M2K: f64 = 101.3;
/// Convection coefficient in still air, W/(m² K) (Pawlowski et al., CDC 2018).
pub const H_AIR_W_M2K: f64 = 20.0;

/// Mechanical constants: the TCA force law and the rod's bending stiffness.
///
/// Force law (axial push of the extension TCA, N):
/// `F(δ, T) = e(T) · (preload_n + force_coeff_n_per_k · (T − T_REF) − tca_stiffness_n_per_m · δ)`
/// with `e(T)` the nylon modulus ratio `E(T)/E(T_REF)`, `E(T) = nylon_e0_pa − nylon_e_slope_pa_per_c · T`.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "std", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "std", serde(deny_unknown_fields))]
pub struct Mechanics {
    /// Bending stiffness of the link with the PLA soft, N m² (fitted).
    pub bending_stiffness_nm2: f64,
    /// TCA push at the reference temperature and zero extension, N (fitted). It is what keeps
    /// the link pre-bent with the TCA off.
    pub preload_n: f64,
    /// Growth of the TCA push per kelvin, N/K (fitted).
    pub force_coeff_n_per_k: f64,
    /// Axial stiffness of the TCA coil, N/m (estimate from the helical-spring formula
    /// `G d⁴ / (8 D³ n)` with nylon G = 181 MPa, d = 0.5 mm, D = 0.9 mm, 100 turns: 19.4 N/m).
    pub tca_stiffness_n_per_m: f64,
    /// Nylon Young's modulus intercept, Pa (560.2 MPa; Pawlowski et al. 2019).
    pub nylon_e0_pa: f64,
    /// Nylon Young's modulus slope, Pa/°C (1.777 MPa/°C; same source).
    pub nylon_e_slope_pa_per_c: f64,
}

/// Reference temperature of the TCA force law, °C.
pub const T_REF_C: f64 = 20.0;

/// PLA stiffness versus temperature, used by the simulated link (freezing and spring-back).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "std", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "std", serde(deny_unknown_fields))]
pub struct PlaStiffness {
    /// Glassy modulus, Pa (paper: 1.7 GPa).
    pub e_glassy_pa: f64,
    /// Rubbery modulus above Tg, Pa (1.2 MPa, DMA of printed PLA).
    pub e_rubbery_pa: f64,
    /// Glass transition, °C (paper: about 62 °C).
    pub tg_c: f64,
    /// Width of the transition, K: log-modulus follows a logistic curve of this width.
    pub transition_width_k: f64,
    /// Relaxation time of the PLA's stress-free curvature at Tg, s. Above Tg the PLA flows to
    /// whatever curvature it is held at; below it the time grows by e every `transition_width_k`.
    pub flow_time_at_tg_s: f64,
}

/// Everything that defines one link and its morph conditions.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "std", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "std", serde(deny_unknown_fields))]
pub struct LinkParams {
    /// Geometry.
    pub geometry: Geometry,
    /// Materials.
    pub materials: Materials,
    /// Surroundings.
    pub surroundings: Surroundings,
    /// Mechanics (fitted constants included).
    pub mechanics: Mechanics,
    /// PLA stiffness law (simulation only).
    pub pla_stiffness: PlaStiffness,
    /// PLA heater power that keeps the rod soft while bending, W (paper: 1.5 W).
    pub pla_hold_power_w: f64,
    /// Highest TCA power in the firmware table, W (paper's tested range: up to 1.5 W).
    pub table_max_power_w: f64,
    /// Number of table entries from 0 W to `table_max_power_w`.
    pub table_entries: usize,
    /// The geometry the fitted mechanical constants (`mechanics.bending_stiffness_nm2`,
    /// `preload_n`, `force_coeff_n_per_k`) were measured and fitted on (`[fitted_on]` in
    /// `link.toml`; the paper's link when absent). A `geometry` that differs from it has no
    /// measured radii behind it: the model scales the fitted stiffness to the new cross-section
    /// ([`crate::mechanics::bending_stiffness_nm2`]) and the tools say to measure and refit
    /// (docs/model.md, "A new geometry").
    #[cfg_attr(feature = "std", serde(default = "paper_geometry"))]
    pub fitted_on: Geometry,
}

/// The seed paper's link geometry: the one the shipped fitted constants came from.
pub const PAPER_GEOMETRY: Geometry = Geometry {
    body_diameter_m: 8.0e-3,
    length_m: 50.0e-3,
    tca_outer_diameter_m: 1.4e-3,
    tca_inner_diameter_m: 0.4e-3,
    tca_fibre_diameter_m: 0.5e-3,
    tca_offset_m: 2.0e-3,
    pla_diameter_m: 1.75e-3,
    pla_offset_m: 2.5e-3,
};

#[cfg(feature = "std")]
fn paper_geometry() -> Geometry {
    PAPER_GEOMETRY
}

impl LinkParams {
    /// The seed paper's link under water with the PLA held at 1.5 W, with fitted constants.
    pub const DEFAULT: LinkParams = LinkParams {
        geometry: PAPER_GEOMETRY,
        materials: Materials {
            tca: Material {
                k_w_mk: 4.6,
                rho_kg_m3: 1300.0,
                cp_j_kgk: 1267.0,
            },
            pla: Material {
                k_w_mk: 0.13,
                rho_kg_m3: 1250.0,
                cp_j_kgk: 1200.0,
            },
            silicone: Material {
                k_w_mk: 0.2,
                rho_kg_m3: 1040.0,
                cp_j_kgk: 1050.0,
            },
        },
        surroundings: Surroundings {
            h_w_m2k: H_WATER_W_M2K,
            ambient_c: 22.0,
        },
        mechanics: Mechanics {
            bending_stiffness_nm2: FITTED_BENDING_STIFFNESS_NM2,
            preload_n: FITTED_PRELOAD_N,
            force_coeff_n_per_k: FITTED_FORCE_COEFF_N_PER_K,
            tca_stiffness_n_per_m: 19.4,
            nylon_e0_pa: 560.2e6,
            nylon_e_slope_pa_per_c: 1.777e6,
        },
        pla_stiffness: PlaStiffness {
            e_glassy_pa: 1.7e9,
            e_rubbery_pa: 1.2e6,
            tg_c: 62.0,
            transition_width_k: 3.0,
            flow_time_at_tg_s: 0.5,
        },
        pla_hold_power_w: 1.5,
        table_max_power_w: 1.5,
        table_entries: 16,
        fitted_on: PAPER_GEOMETRY,
    };
}

/// Fitted bending stiffness, N m² (`morph-model calibrate`).
pub const FITTED_BENDING_STIFFNESS_NM2: f64 = 1.5007e-5;
/// Fitted TCA preload, N (`morph-model calibrate`).
pub const FITTED_PRELOAD_N: f64 = 0.173382;
/// Fitted TCA force coefficient, N/K (`morph-model calibrate`).
pub const FITTED_FORCE_COEFF_N_PER_K: f64 = 0.0027711;

impl LinkParams {
    /// Whether `geometry` is the one the fitted constants came from (`fitted_on`).
    pub fn geometry_is_fitted(&self) -> bool {
        self.geometry == self.fitted_on
    }
}

impl Default for LinkParams {
    fn default() -> Self {
        Self::DEFAULT
    }
}
