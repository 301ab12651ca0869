//! Two-dimensional finite-volume model of the link's cross-section (paper Eq. 1–3).
//!
//! The disk of radius `a` is cut into `nr` rings × `nt` sectors (polar cells, so the convective
//! rim `−k ∂T/∂n = h (T − T∞)` lies exactly on cell faces). Each cell takes its conductivity and
//! heat capacity from the area fractions of the materials in it — TCA tube, the TCA's hollow
//! core (water: the mandrel is pulled out and the link is under water), PLA rod, silicone —
//! sampled on a 6×6 sub-grid. Face conductances are harmonic means of the two half-cells; the rim
//! face puts the half-cell and the film `1/h` in series. The TCA's power is spread uniformly
//! over its tube (paper Eq. 2), the PLA heater's over the rod (`q̇ = P/V`); heater temperatures
//! are area means over the heated region, as in the paper.
//!
//! The steady system `A T = q` is symmetric positive definite with a band of `nt` in ring-major
//! order; it is solved by a banded Cholesky factorisation (a pivot that is not positive is an
//! error, never a NaN). Transients `C dT/dt = −A T + q` are stepped by backward Euler
//! (unconditionally stable, same factorisation with `C/Δt` added) or explicit Euler, whose
//! stability limit `Δt < 2/λmax(C⁻¹A)` is computed and enforced.
//!
//! For plants that step the section with powers that change every step, [`CrossSection::stepper`]
//! factorises once for a step `Δt` and [`Stepper::step`] advances an absolute temperature field
//! against an ambient that may change between steps. [`PlaHeat::Surface`] releases the nichrome's
//! heat in the rod's boundary cells (those the rod's surface cuts) instead of through the rod.

use super::ReferenceError;
use crate::params::LinkParams;
use crate::thermal::ResistanceMatrix;
use core::f64::consts::PI;

/// Water filling the TCA's core: conductivity, W/(m K).
pub const CORE_K_W_MK: f64 = 0.6;
/// Water filling the TCA's core: volumetric heat capacity, J/(m³ K).
pub const CORE_RHO_CP_J_M3K: f64 = 4.18e6;
/// Sub-samples per cell side for the material fractions.
const SUB: usize = 6;

/// Which heater a unit of power goes to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Heater {
    /// The TCA (Joule heating of its tube).
    Tca,
    /// The nichrome wrap on the PLA rod.
    Pla,
}

/// A polar finite-volume discretisation of one cross-section, ready to solve.
#[derive(Clone, Debug)]
pub struct CrossSection {
    /// Rings.
    pub nr: usize,
    /// Sectors.
    pub nt: usize,
    /// Conductance from cell to the next ring outward, per metre of link, W/(m K).
    g_out: Vec<f64>,
    /// Conductance from cell to the next sector (periodic), per metre, W/(m K).
    g_side: Vec<f64>,
    /// Conductance to the surroundings (outer ring only), per metre, W/(m K).
    g_rim: Vec<f64>,
    /// Heat capacity per metre of link, J/(m K).
    capacity: Vec<f64>,
    /// Heated area of the TCA in each cell, m².
    tca_area: Vec<f64>,
    /// Heated area of the PLA in each cell, m².
    pla_area: Vec<f64>,
    /// PLA area of the cells the rod's surface cuts (partly PLA), m²; zero elsewhere.
    pla_surface_area: Vec<f64>,
    /// Where the PLA heater's power goes.
    pla_heat: PlaHeat,
    /// Half-cell conduction resistance of each outer-ring cell to the rim, per metre, m K/W
    /// (`dr / (2 k)` over the rim arc), so the rim conductance can follow a new `h`.
    rim_half_r: Vec<f64>,
    /// Disk radius, m.
    radius_m: f64,
    /// Rim heat-transfer coefficient, W/(m² K).
    h_w_m2k: f64,
    /// Link length, m (to turn per-metre conductances into K/W).
    length_m: f64,
}

/// Where the PLA heater (the nichrome wrap) releases its power.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlaHeat {
    /// Uniformly through the rod (`q̇ = P/V`, the paper's Eq. 2 form).
    Volume,
    /// In the rod's boundary cells, in proportion to their PLA area: the wire lies on the
    /// rod's surface.
    Surface,
}

/// Material of one sub-sample point.
#[derive(Clone, Copy)]
struct Mat {
    k: f64,
    rho_cp: f64,
    tca: bool,
    pla: bool,
}

/// A circular inclusion: centre, radius, optional inner radius (hole), material.
#[derive(Clone, Copy, Debug)]
pub struct Inclusion {
    /// Centre x, m.
    pub x_m: f64,
    /// Centre y, m.
    pub y_m: f64,
    /// Outer radius, m.
    pub radius_m: f64,
    /// Radius of a core of another material (0 for a solid rod), m.
    pub core_radius_m: f64,
    /// Conductivity, W/(m K).
    pub k_w_mk: f64,
    /// Volumetric heat capacity, J/(m³ K).
    pub rho_cp_j_m3k: f64,
    /// Conductivity of the core, W/(m K).
    pub core_k_w_mk: f64,
    /// Volumetric heat capacity of the core, J/(m³ K).
    pub core_rho_cp_j_m3k: f64,
}

/// A cross-section to discretise: a disk with a convective rim holding two heated inclusions.
#[derive(Clone, Copy, Debug)]
pub struct Layout {
    /// Disk radius, m.
    pub radius_m: f64,
    /// Matrix conductivity, W/(m K).
    pub k_w_mk: f64,
    /// Matrix volumetric heat capacity, J/(m³ K).
    pub rho_cp_j_m3k: f64,
    /// Rim heat-transfer coefficient, W/(m² K).
    pub h_w_m2k: f64,
    /// The TCA (heated tube).
    pub tca: Inclusion,
    /// The PLA rod (heated).
    pub pla: Inclusion,
    /// Link length, m.
    pub length_m: f64,
}

impl Layout {
    /// The link of `p`: TCA at `+tca_offset` on the x axis, PLA at `−pla_offset`.
    pub fn of_link(p: &LinkParams) -> Self {
        let g = &p.geometry;
        let m = &p.materials;
        Layout {
            radius_m: g.body_diameter_m / 2.0,
            k_w_mk: m.silicone.k_w_mk,
            rho_cp_j_m3k: m.silicone.rho_cp(),
            h_w_m2k: p.surroundings.h_w_m2k,
            tca: Inclusion {
                x_m: g.tca_offset_m,
                y_m: 0.0,
                radius_m: g.tca_outer_diameter_m / 2.0,
                core_radius_m: g.tca_inner_diameter_m / 2.0,
                k_w_mk: m.tca.k_w_mk,
                rho_cp_j_m3k: m.tca.rho_cp(),
                core_k_w_mk: CORE_K_W_MK,
                core_rho_cp_j_m3k: CORE_RHO_CP_J_M3K,
            },
            pla: Inclusion {
                x_m: -g.pla_offset_m,
                y_m: 0.0,
                radius_m: g.pla_diameter_m / 2.0,
                core_radius_m: 0.0,
                k_w_mk: m.pla.k_w_mk,
                rho_cp_j_m3k: m.pla.rho_cp(),
                core_k_w_mk: m.pla.k_w_mk,
                core_rho_cp_j_m3k: m.pla.rho_cp(),
            },
            length_m: g.length_m,
        }
    }

    fn material_at(&self, x: f64, y: f64) -> Mat {
        for (inc, is_tca) in [(&self.pla, false), (&self.tca, true)] {
            let d = libm::hypot(x - inc.x_m, y - inc.y_m);
            if d < inc.core_radius_m {
                return Mat {
                    k: inc.core_k_w_mk,
                    rho_cp: inc.core_rho_cp_j_m3k,
                    tca: false,
                    pla: false,
                };
            }
            if d < inc.radius_m {
                return Mat {
                    k: inc.k_w_mk,
                    rho_cp: inc.rho_cp_j_m3k,
                    tca: is_tca,
                    pla: !is_tca,
                };
            }
        }
        Mat {
            k: self.k_w_mk,
            rho_cp: self.rho_cp_j_m3k,
            tca: false,
            pla: false,
        }
    }
}

/// Number of sectors that makes cells about square at half the radius for `nr` rings
/// (a multiple of 4 so the x axis lies on sector faces).
pub fn sectors_for(nr: usize) -> usize {
    let nt = (PI * nr as f64).round() as usize;
    nt.div_ceil(4).max(2) * 4
}

/// Steady temperature field and the heater means it gives.
#[derive(Clone, Debug)]
pub struct SteadyField {
    /// Rise above ambient in every cell (ring-major), K.
    pub rise_k: Vec<f64>,
    /// Area-mean rise of the TCA tube, K.
    pub tca_rise_k: f64,
    /// Area-mean rise of the PLA rod, K.
    pub pla_rise_k: f64,
}

/// Banded Cholesky factor (lower band, `bw` below the diagonal), stored twice: by rows of `L`
/// (`l[i (bw+1) + (i − j)] = L[i][j]`) for the forward pass and by columns
/// (`u[j (bw+1) + (i − j)] = L[i][j]`) for the backward pass, so both inner loops run over
/// contiguous memory.
#[derive(Clone, Debug)]
struct Banded {
    n: usize,
    bw: usize,
    l: Vec<f64>,
    u: Vec<f64>,
}

impl Banded {
    fn new(n: usize, bw: usize, l: Vec<f64>) -> Self {
        let w = bw + 1;
        let mut u = vec![0.0; n * w];
        for i in 0..n {
            for d in 0..=bw.min(i) {
                u[(i - d) * w + d] = l[i * w + d];
            }
        }
        Banded { n, bw, l, u }
    }

    fn solve(&self, b: &mut [f64]) {
        let (n, bw) = (self.n, self.bw);
        let w = bw + 1;
        for i in 0..n {
            let row = &self.l[i * w..(i + 1) * w];
            let m = bw.min(i);
            let mut s = b[i];
            for (d, lij) in row[1..=m].iter().enumerate() {
                s -= lij * b[i - 1 - d];
            }
            b[i] = s / row[0];
        }
        for i in (0..n).rev() {
            let col = &self.u[i * w..(i + 1) * w];
            let m = bw.min(n - 1 - i);
            let mut s = b[i];
            for (lji, bj) in col[1..=m].iter().zip(&b[i + 1..=i + m]) {
                s -= lji * bj;
            }
            b[i] = s / col[0];
        }
    }
}

impl CrossSection {
    /// Discretises `layout` with `nr` rings and `nt` sectors.
    pub fn new(layout: &Layout, nr: usize, nt: usize) -> Result<Self, ReferenceError> {
        if nr < 2 || nt < 4 {
            return Err(ReferenceError::BadGrid { nr, nt });
        }
        let a = layout.radius_m;
        let dr = a / nr as f64;
        let dth = 2.0 * PI / nt as f64;
        let n = nr * nt;
        let mut k = vec![0.0; n];
        let mut capacity = vec![0.0; n];
        let mut tca_area = vec![0.0; n];
        let mut pla_area = vec![0.0; n];
        for i in 0..nr {
            let (r0, r1) = (i as f64 * dr, (i + 1) as f64 * dr);
            let area = 0.5 * dth * (r1 * r1 - r0 * r0);
            for j in 0..nt {
                let (mut ks, mut cs, mut ts, mut ps, mut ws) = (0.0, 0.0, 0.0, 0.0, 0.0);
                for si in 0..SUB {
                    let r = r0 + (si as f64 + 0.5) * dr / SUB as f64;
                    for sj in 0..SUB {
                        let th = (j as f64 + (sj as f64 + 0.5) / SUB as f64) * dth;
                        let m = layout.material_at(r * libm::cos(th), r * libm::sin(th));
                        ks += r * m.k;
                        cs += r * m.rho_cp;
                        ts += if m.tca { r } else { 0.0 };
                        ps += if m.pla { r } else { 0.0 };
                        ws += r;
                    }
                }
                let c = i * nt + j;
                k[c] = ks / ws;
                capacity[c] = cs / ws * area;
                tca_area[c] = ts / ws * area;
                pla_area[c] = ps / ws * area;
            }
        }
        let pla_surface_area: Vec<f64> = (0..n)
            .map(|c| {
                let (i, _) = (c / nt, c % nt);
                let (r0, r1) = (i as f64 * dr, (i + 1) as f64 * dr);
                let area = 0.5 * dth * (r1 * r1 - r0 * r0);
                let frac = pla_area[c] / area;
                if frac > 0.0 && frac < 1.0 - 1e-9 {
                    pla_area[c]
                } else {
                    0.0
                }
            })
            .collect();
        let mut g_out = vec![0.0; n];
        let mut g_side = vec![0.0; n];
        let mut g_rim = vec![0.0; nt];
        let mut rim_half_r = vec![0.0; nt];
        for i in 0..nr {
            let rc = (i as f64 + 0.5) * dr;
            let rf = (i + 1) as f64 * dr;
            for j in 0..nt {
                let c = i * nt + j;
                let right = i * nt + (j + 1) % nt;
                g_side[c] = dr / (0.5 * rc * dth * (1.0 / k[c] + 1.0 / k[right]));
                if i + 1 < nr {
                    let up = c + nt;
                    g_out[c] = rf * dth / (0.5 * dr * (1.0 / k[c] + 1.0 / k[up]));
                } else {
                    rim_half_r[j] = 0.5 * dr / k[c];
                    g_rim[j] = a * dth / (0.5 * dr / k[c] + 1.0 / layout.h_w_m2k);
                }
            }
        }
        if tca_area.iter().sum::<f64>() <= 0.0 || pla_area.iter().sum::<f64>() <= 0.0 {
            return Err(ReferenceError::BadGrid { nr, nt });
        }
        Ok(CrossSection {
            nr,
            nt,
            g_out,
            g_side,
            g_rim,
            capacity,
            tca_area,
            pla_area,
            pla_surface_area,
            pla_heat: PlaHeat::Volume,
            rim_half_r,
            radius_m: a,
            h_w_m2k: layout.h_w_m2k,
            length_m: layout.length_m,
        })
    }

    /// The same section with the PLA heater's power released as `heat` says.
    pub fn with_pla_heat(mut self, heat: PlaHeat) -> Self {
        if heat == PlaHeat::Surface && self.pla_surface_area.iter().sum::<f64>() <= 0.0 {
            // A grid so coarse that every rod cell is whole cannot say where the surface is:
            // fall back to the volume (never reached for grids that resolve the rod).
            return self;
        }
        self.pla_heat = heat;
        self
    }

    /// Where the PLA heater's power goes.
    pub fn pla_heat(&self) -> PlaHeat {
        self.pla_heat
    }

    /// A new rim heat-transfer coefficient, W/(m² K) (e.g. another medium). A [`Stepper`] made
    /// before must be made again.
    pub fn set_h(&mut self, h_w_m2k: f64) {
        let (a, dth) = (self.radius_m, 2.0 * PI / self.nt as f64);
        for j in 0..self.nt {
            self.g_rim[j] = a * dth / (self.rim_half_r[j] + 1.0 / h_w_m2k);
        }
        self.h_w_m2k = h_w_m2k;
    }

    /// Rim heat-transfer coefficient, W/(m² K).
    pub fn h_w_m2k(&self) -> f64 {
        self.h_w_m2k
    }

    /// Link length, m.
    pub fn length_m(&self) -> f64 {
        self.length_m
    }

    /// Ring width and sector angle, (m, rad).
    fn spacing(&self) -> (f64, f64) {
        (self.radius_m / self.nr as f64, 2.0 * PI / self.nt as f64)
    }

    /// Centre of cell `c` (ring-major), (x, y) in m; the TCA lies on +x, the PLA on −x.
    pub fn cell_centre_m(&self, c: usize) -> (f64, f64) {
        let (dr, dth) = self.spacing();
        let (i, j) = (c / self.nt, c % self.nt);
        let r = (i as f64 + 0.5) * dr;
        let th = (j as f64 + 0.5) * dth;
        (r * libm::cos(th), r * libm::sin(th))
    }

    /// PLA area of cell `c`, m².
    pub fn pla_area_m2(&self, c: usize) -> f64 {
        self.pla_area[c]
    }

    /// TCA tube area of cell `c`, m².
    pub fn tca_area_m2(&self, c: usize) -> f64 {
        self.tca_area[c]
    }

    /// PLA area of cell `c` if the rod's surface cuts it, else 0, m².
    pub fn pla_surface_area_m2(&self, c: usize) -> f64 {
        self.pla_surface_area[c]
    }

    /// Heat capacity of cell `c` per metre of link, J/(m K).
    pub fn capacity_j_mk(&self, c: usize) -> f64 {
        self.capacity[c]
    }

    /// Temperature of field `t` at the point (x, y), m: bilinear in ring and sector between
    /// cell centres (periodic in angle, held flat inside the first and outside the last ring
    /// centre).
    pub fn value_at(&self, t: &[f64], x_m: f64, y_m: f64) -> f64 {
        self.stencil(x_m, y_m).iter().map(|(c, w)| w * t[*c]).sum()
    }

    /// The four cells and weights [`Self::value_at`] interpolates the point (x, y) from.
    pub fn stencil(&self, x_m: f64, y_m: f64) -> [(usize, f64); 4] {
        let (dr, dth) = self.spacing();
        let (nr, nt) = (self.nr, self.nt);
        let r = libm::hypot(x_m, y_m);
        let mut th = libm::atan2(y_m, x_m);
        if th < 0.0 {
            th += 2.0 * PI;
        }
        let u = (r / dr - 0.5).clamp(0.0, (nr - 1) as f64);
        let i0 = (u.floor() as usize).min(nr - 1);
        let i1 = (i0 + 1).min(nr - 1);
        let fu = u - i0 as f64;
        let v = th / dth - 0.5;
        let vf = v.floor();
        let fv = v - vf;
        let j0 = ((vf as i64).rem_euclid(nt as i64)) as usize;
        let j1 = (j0 + 1) % nt;
        [
            (i0 * nt + j0, (1.0 - fu) * (1.0 - fv)),
            (i0 * nt + j1, (1.0 - fu) * fv),
            (i1 * nt + j0, fu * (1.0 - fv)),
            (i1 * nt + j1, fu * fv),
        ]
    }

    /// Heat the rim gives the medium at `ambient_c` from the absolute field `t_c`, W (whole
    /// link).
    pub fn rim_power_w(&self, t_c: &[f64], ambient_c: f64) -> f64 {
        let base = (self.nr - 1) * self.nt;
        (0..self.nt)
            .map(|j| self.g_rim[j] * (t_c[base + j] - ambient_c))
            .sum::<f64>()
            * self.length_m
    }

    /// Heat stored in the absolute field `t_c` above `reference_c`, J (whole link).
    pub fn stored_j(&self, t_c: &[f64], reference_c: f64) -> f64 {
        t_c.iter()
            .zip(&self.capacity)
            .map(|(t, c)| c * (t - reference_c))
            .sum::<f64>()
            * self.length_m
    }

    /// Source vectors per metre: TCA per whole-link watt, PLA per watt (as released), and the
    /// rim's coupling to the ambient per kelvin.
    fn input_vectors(&self) -> [Vec<f64>; 3] {
        let n = self.cells();
        let l = self.length_m;
        let ta: f64 = self.tca_area.iter().sum();
        let pla_w = match self.pla_heat {
            PlaHeat::Volume => &self.pla_area,
            PlaHeat::Surface => &self.pla_surface_area,
        };
        let pa: f64 = pla_w.iter().sum();
        let mut amb = vec![0.0; n];
        let base = (self.nr - 1) * self.nt;
        amb[base..].copy_from_slice(&self.g_rim);
        [
            self.tca_area.iter().map(|a| a / ta / l).collect(),
            pla_w.iter().map(|a| a / pa / l).collect(),
            amb,
        ]
    }

    /// A reduced-order model of this section by rational-Krylov (moment-matching) projection:
    /// the basis spans `(A + σC)⁻¹ b` for each shift σ (1/s) and each input b (TCA power, PLA
    /// power, ambient), `C`-orthonormalised; the Galerkin projection keeps the reduced system
    /// symmetric positive definite (stable) and, with σ = 0 among the shifts, exact at steady
    /// state. Stepped by backward Euler with step `dt_s`.
    pub fn rom(&self, shifts_per_s: &[f64], dt_s: f64) -> Result<Rom, ReferenceError> {
        if !(dt_s > 0.0) || !dt_s.is_finite() {
            return Err(ReferenceError::BadStep { dt_s });
        }
        let n = self.cells();
        let inputs = self.input_vectors();
        let dot_c = |x: &[f64], y: &[f64]| -> f64 {
            x.iter()
                .zip(y)
                .zip(&self.capacity)
                .map(|((a, b), c)| a * b * c)
                .sum()
        };
        let mut basis: Vec<Vec<f64>> = Vec::new();
        for &sigma in shifts_per_s {
            let shift: Vec<f64> = self.capacity.iter().map(|c| c * sigma).collect();
            let f = self.factor(&shift)?;
            for b in &inputs {
                let mut x = b.clone();
                f.solve(&mut x);
                let before = libm::sqrt(dot_c(&x, &x));
                for _ in 0..2 {
                    for v in &basis {
                        let h = dot_c(v, &x);
                        for (xi, vi) in x.iter_mut().zip(v) {
                            *xi -= h * vi;
                        }
                    }
                }
                let after = libm::sqrt(dot_c(&x, &x));
                if after > 1e-9 * before && after.is_finite() {
                    x.iter_mut().for_each(|v| *v /= after);
                    basis.push(x);
                }
            }
        }
        let q = basis.len();
        let mut av = vec![0.0; n];
        let mut a_r = vec![0.0; q * q];
        for j in 0..q {
            self.apply(&basis[j], &mut av);
            for i in 0..q {
                a_r[i * q + j] = basis[i].iter().zip(&av).map(|(a, b)| a * b).sum();
            }
        }
        // Symmetrise against rounding.
        for i in 0..q {
            for j in 0..i {
                let m = 0.5 * (a_r[i * q + j] + a_r[j * q + i]);
                a_r[i * q + j] = m;
                a_r[j * q + i] = m;
            }
        }
        let b_r: Vec<[f64; 3]> = basis
            .iter()
            .map(|v| {
                let mut r = [0.0; 3];
                for (k, b) in inputs.iter().enumerate() {
                    r[k] = v.iter().zip(b).map(|(a, b)| a * b).sum();
                }
                r
            })
            .collect();
        let ta: f64 = self.tca_area.iter().sum();
        let pa: f64 = self.pla_area.iter().sum();
        let means: Vec<[f64; 2]> = basis
            .iter()
            .map(|v| {
                let t: f64 = v.iter().zip(&self.tca_area).map(|(a, w)| a * w).sum();
                let p: f64 = v.iter().zip(&self.pla_area).map(|(a, w)| a * w).sum();
                [t / ta, p / pa]
            })
            .collect();
        // Column-major basis: cell c of mode k at v[c * q + k] (a cell's row is contiguous).
        let mut v = vec![0.0; n * q];
        for (k, col) in basis.iter().enumerate() {
            for c in 0..n {
                v[c * q + k] = col[c];
            }
        }
        let mut rom = Rom {
            n,
            q,
            v,
            capacity: self.capacity.clone(),
            a_r,
            b_r,
            means,
            m: Vec::new(),
            dt_s,
            z: vec![0.0; q],
        };
        rom.set_dt(dt_s)?;
        Ok(rom)
    }

    /// A backward-Euler stepper for steps of `dt_s`: one factorisation of `A + C/Δt`.
    pub fn stepper(&self, dt_s: f64) -> Result<Stepper, ReferenceError> {
        if !(dt_s > 0.0) || !dt_s.is_finite() {
            return Err(ReferenceError::BadStep { dt_s });
        }
        let shift: Vec<f64> = self.capacity.iter().map(|c| c / dt_s).collect();
        let factor = self.factor(&shift)?;
        let l = self.length_m;
        let ta: f64 = self.tca_area.iter().sum();
        let pla_w = match self.pla_heat {
            PlaHeat::Volume => &self.pla_area,
            PlaHeat::Surface => &self.pla_surface_area,
        };
        let pa: f64 = pla_w.iter().sum();
        Ok(Stepper {
            dt_s,
            shift,
            factor,
            tca_per_w: self.tca_area.iter().map(|a| a / ta / l).collect(),
            pla_per_w: pla_w.iter().map(|a| a / pa / l).collect(),
            rim: self.g_rim.clone(),
            rim_base: (self.nr - 1) * self.nt,
        })
    }

    /// The default link's cross-section with `nr` rings and [`sectors_for`] sectors.
    pub fn of_link(p: &LinkParams, nr: usize) -> Result<Self, ReferenceError> {
        Self::new(&Layout::of_link(p), nr, sectors_for(nr))
    }

    /// Number of cells.
    pub fn cells(&self) -> usize {
        self.nr * self.nt
    }

    /// Diagonal and neighbour conductances of `A` (+ `shift` on the diagonal), per metre.
    fn diag(&self, c: usize) -> f64 {
        let nt = self.nt;
        let (i, j) = (c / nt, c % nt);
        let left = i * nt + (j + nt - 1) % nt;
        let mut d = self.g_side[c] + self.g_side[left] + self.g_out[c];
        if i > 0 {
            d += self.g_out[c - nt];
        }
        if i + 1 == self.nr {
            d += self.g_rim[j];
        }
        d
    }

    /// `y = A x` (per metre, W/m per K).
    fn apply(&self, x: &[f64], y: &mut [f64]) {
        let nt = self.nt;
        for c in 0..self.cells() {
            let (i, j) = (c / nt, c % nt);
            let right = i * nt + (j + 1) % nt;
            let left = i * nt + (j + nt - 1) % nt;
            let mut s = self.diag(c) * x[c];
            s -= self.g_side[c] * x[right] + self.g_side[left] * x[left];
            if i + 1 < self.nr {
                s -= self.g_out[c] * x[c + nt];
            }
            if i > 0 {
                s -= self.g_out[c - nt] * x[c - nt];
            }
            y[c] = s;
        }
    }

    /// Factorises `A + diag(shift_c)` (per metre) by banded Cholesky.
    fn factor(&self, shift: &[f64]) -> Result<Banded, ReferenceError> {
        let (n, nt) = (self.cells(), self.nt);
        let bw = nt;
        let mut l = vec![0.0; n * (bw + 1)];
        let mut scale = 0.0f64;
        // Fill the lower band of A.
        for c in 0..n {
            let (i, j) = (c / nt, c % nt);
            l[c * (bw + 1)] = self.diag(c) + shift[c];
            scale = scale.max(l[c * (bw + 1)]);
            // Sector neighbour on the left (j−1), or the wrap partner (j = nt−1 ↔ 0).
            if j > 0 {
                l[c * (bw + 1) + 1] = -self.g_side[c - 1];
            }
            if j == nt - 1 {
                l[c * (bw + 1) + (nt - 1)] -= self.g_side[c];
            }
            if i > 0 {
                l[c * (bw + 1) + nt] = -self.g_out[c - nt];
            }
        }
        for i in 0..n {
            let lo = i.saturating_sub(bw);
            for j in lo..=i {
                let mut s = l[i * (bw + 1) + (i - j)];
                let kk = lo.max(j.saturating_sub(bw));
                for k in kk..j {
                    s -= l[i * (bw + 1) + (i - k)] * l[j * (bw + 1) + (j - k)];
                }
                if i == j {
                    // A pivot lost to rounding (a singular system, e.g. no path to the
                    // surroundings) is as much a failure as a negative one.
                    if !(s > 1e-12 * scale) || !s.is_finite() {
                        return Err(ReferenceError::NotPositiveDefinite { row: i });
                    }
                    l[i * (bw + 1)] = libm::sqrt(s);
                } else {
                    l[i * (bw + 1) + (i - j)] = s / l[j * (bw + 1)];
                }
            }
        }
        Ok(Banded::new(n, bw, l))
    }

    /// Source vector for `p_tca_w` and `p_pla_w` (whole-link watts), W per metre per cell.
    fn sources(&self, p_tca_w: f64, p_pla_w: f64) -> Vec<f64> {
        let ta: f64 = self.tca_area.iter().sum();
        let pla_w = match self.pla_heat {
            PlaHeat::Volume => &self.pla_area,
            PlaHeat::Surface => &self.pla_surface_area,
        };
        let pa: f64 = pla_w.iter().sum();
        let l = self.length_m;
        (0..self.cells())
            .map(|c| p_tca_w / l * self.tca_area[c] / ta + p_pla_w / l * pla_w[c] / pa)
            .collect()
    }

    /// Area means of a field over the TCA and the PLA, K.
    pub fn heater_means_k(&self, t: &[f64]) -> (f64, f64) {
        let ta: f64 = self.tca_area.iter().sum();
        let pa: f64 = self.pla_area.iter().sum();
        let st: f64 = t.iter().zip(&self.tca_area).map(|(x, w)| x * w).sum();
        let sp: f64 = t.iter().zip(&self.pla_area).map(|(x, w)| x * w).sum();
        (st / ta, sp / pa)
    }

    /// Steady rise above ambient for constant heater powers, W.
    pub fn steady(&self, p_tca_w: f64, p_pla_w: f64) -> Result<SteadyField, ReferenceError> {
        let f = self.factor(&vec![0.0; self.cells()])?;
        let mut t = self.sources(p_tca_w, p_pla_w);
        f.solve(&mut t);
        self.field(t)
    }

    fn field(&self, t: Vec<f64>) -> Result<SteadyField, ReferenceError> {
        if t.iter().any(|x| !x.is_finite()) {
            return Err(ReferenceError::NonFinite("thermal field"));
        }
        let (tca_rise_k, pla_rise_k) = self.heater_means_k(&t);
        Ok(SteadyField {
            rise_k: t,
            tca_rise_k,
            pla_rise_k,
        })
    }

    /// The 2×2 thermal-resistance matrix, K/W (one factorisation, two solves; the mutual term
    /// is the mean of the two, which reciprocity makes equal — see the tests).
    pub fn resistance_matrix(&self) -> Result<ResistanceMatrix, ReferenceError> {
        let f = self.factor(&vec![0.0; self.cells()])?;
        let mut t1 = self.sources(1.0, 0.0);
        f.solve(&mut t1);
        let mut t2 = self.sources(0.0, 1.0);
        f.solve(&mut t2);
        let a = self.field(t1)?;
        let b = self.field(t2)?;
        Ok(ResistanceMatrix {
            r_tt: a.tca_rise_k,
            r_pp: b.pla_rise_k,
            r_tp: 0.5 * (a.pla_rise_k + b.tca_rise_k),
        })
    }

    /// Largest eigenvalue of `C⁻¹A`, 1/s, by power iteration on the symmetric `C^-½ A C^-½`
    /// (a lower bound that converges from below; 300 iterations are within 0.1 % for the grids
    /// used, checked against the Gershgorin upper bound in the tests).
    pub fn max_rate_per_s(&self) -> f64 {
        let n = self.cells();
        let s: Vec<f64> = self.capacity.iter().map(|c| 1.0 / libm::sqrt(*c)).collect();
        // Start on a checkerboard: the fastest mode alternates in sign cell to cell.
        let mut x: Vec<f64> = (0..n)
            .map(|c| {
                if (c / self.nt + c % self.nt).is_multiple_of(2) {
                    1.0
                } else {
                    -1.0
                }
            })
            .collect();
        let mut y = vec![0.0; n];
        let mut lam = 0.0;
        for _ in 0..300 {
            let norm = libm::sqrt(x.iter().map(|v| v * v).sum::<f64>());
            for v in x.iter_mut() {
                *v /= norm;
            }
            let xs: Vec<f64> = x.iter().zip(&s).map(|(a, b)| a * b).collect();
            self.apply(&xs, &mut y);
            for c in 0..n {
                y[c] *= s[c];
            }
            lam = x.iter().zip(&y).map(|(a, b)| a * b).sum();
            core::mem::swap(&mut x, &mut y);
        }
        lam
    }

    /// Gershgorin upper bound on the largest eigenvalue of `C⁻¹A`, 1/s.
    pub fn max_rate_bound_per_s(&self) -> f64 {
        (0..self.cells())
            .map(|c| 2.0 * self.diag(c) / self.capacity[c])
            .fold(0.0, f64::max)
    }

    /// Explicit-Euler stability limit `2/λmax`, s.
    pub fn explicit_limit_s(&self) -> f64 {
        2.0 / self.max_rate_per_s()
    }

    /// Heater-mean rises over time from a uniform ambient start with constant powers.
    /// `Stepping::Explicit` refuses a step above the stability limit
    /// ([`ReferenceError::UnstableStep`]); `Stepping::Auto` takes explicit steps when they are
    /// stable and falls back to implicit otherwise, or when explicit stepping diverges.
    pub fn transient(
        &self,
        p_tca_w: f64,
        p_pla_w: f64,
        dt_s: f64,
        steps: usize,
        stepping: Stepping,
    ) -> Result<Transient, ReferenceError> {
        if !(dt_s > 0.0) || !dt_s.is_finite() {
            return Err(ReferenceError::BadStep { dt_s });
        }
        match stepping {
            Stepping::Implicit => self.run_implicit(p_tca_w, p_pla_w, dt_s, steps),
            Stepping::Explicit => {
                let limit = self.explicit_limit_s();
                if dt_s > limit {
                    return Err(ReferenceError::UnstableStep {
                        dt_s,
                        limit_s: limit,
                    });
                }
                self.run_explicit(p_tca_w, p_pla_w, dt_s, steps)
            }
            Stepping::ExplicitUnchecked => self.run_explicit(p_tca_w, p_pla_w, dt_s, steps),
            Stepping::Auto => {
                let limit = self.explicit_limit_s();
                if dt_s <= limit {
                    match self.run_explicit(p_tca_w, p_pla_w, dt_s, steps) {
                        Ok(t) => return Ok(t),
                        Err(ReferenceError::Diverged { .. }) => {}
                        Err(e) => return Err(e),
                    }
                }
                let mut t = self.run_implicit(p_tca_w, p_pla_w, dt_s, steps)?;
                t.method = Stepping::Implicit;
                Ok(t)
            }
        }
    }

    fn run_implicit(
        &self,
        p_tca_w: f64,
        p_pla_w: f64,
        dt_s: f64,
        steps: usize,
    ) -> Result<Transient, ReferenceError> {
        let shift: Vec<f64> = self.capacity.iter().map(|c| c / dt_s).collect();
        let f = self.factor(&shift)?;
        let q = self.sources(p_tca_w, p_pla_w);
        let mut t = vec![0.0; self.cells()];
        let mut out = Transient::new(Stepping::Implicit, dt_s);
        for _ in 0..steps {
            for c in 0..t.len() {
                t[c] = q[c] + shift[c] * t[c];
            }
            f.solve(&mut t);
            out.push(self.heater_means_k(&t));
        }
        Ok(out)
    }

    fn run_explicit(
        &self,
        p_tca_w: f64,
        p_pla_w: f64,
        dt_s: f64,
        steps: usize,
    ) -> Result<Transient, ReferenceError> {
        let q = self.sources(p_tca_w, p_pla_w);
        // Energy monitor: a stable run from ambient has stored at most the heat put in,
        // Σ C|T| ≤ P t (twice that allows for the decaying oscillation of steps above 1/λmax);
        // an unstable mode grows geometrically and crosses it within a few dozen steps.
        let power_per_m = (p_tca_w.abs() + p_pla_w.abs()) / self.length_m;
        let mut t = vec![0.0; self.cells()];
        let mut at = vec![0.0; self.cells()];
        let mut out = Transient::new(Stepping::Explicit, dt_s);
        for step in 0..steps {
            self.apply(&t, &mut at);
            let mut stored = 0.0;
            for c in 0..t.len() {
                t[c] += dt_s * (q[c] - at[c]) / self.capacity[c];
                stored += self.capacity[c] * t[c].abs();
            }
            let allowed = 2.0 * power_per_m * (step + 1) as f64 * dt_s + 1e-12;
            if !(stored <= allowed) {
                return Err(ReferenceError::Diverged { step });
            }
            out.push(self.heater_means_k(&t));
        }
        Ok(out)
    }
}

/// A reduced-order model of a [`CrossSection`] ([`CrossSection::rom`]): `q` modes `z`, the
/// field `T = V z`.
#[derive(Clone, Debug)]
pub struct Rom {
    n: usize,
    q: usize,
    /// Basis, cell-major: `v[c q + k]`.
    v: Vec<f64>,
    capacity: Vec<f64>,
    a_r: Vec<f64>,
    b_r: Vec<[f64; 3]>,
    means: Vec<[f64; 2]>,
    /// `(I/Δt + A_r)⁻¹`.
    m: Vec<f64>,
    dt_s: f64,
    z: Vec<f64>,
}

impl Rom {
    /// Number of modes.
    pub fn order(&self) -> usize {
        self.q
    }

    /// The step it is set up for, s.
    pub fn dt_s(&self) -> f64 {
        self.dt_s
    }

    /// A new step length (inverts the small reduced matrix again).
    pub fn set_dt(&mut self, dt_s: f64) -> Result<(), ReferenceError> {
        if !(dt_s > 0.0) || !dt_s.is_finite() {
            return Err(ReferenceError::BadStep { dt_s });
        }
        let q = self.q;
        let mut a = self.a_r.clone();
        for i in 0..q {
            a[i * q + i] += 1.0 / dt_s;
        }
        self.m = invert(&a, q).ok_or(ReferenceError::NotPositiveDefinite { row: 0 })?;
        self.dt_s = dt_s;
        Ok(())
    }

    /// Sets the state to the projection of the field `t_c` (exact for a field in the basis,
    /// such as a uniform one when σ = 0 was a shift).
    pub fn set_field(&mut self, t_c: &[f64]) {
        let q = self.q;
        for k in 0..q {
            self.z[k] = (0..self.n)
                .map(|c| self.v[c * q + k] * self.capacity[c] * t_c[c])
                .sum();
        }
    }

    /// One backward-Euler step with whole-link powers and the medium at `ambient_c`.
    pub fn step(&mut self, p_tca_w: f64, p_pla_w: f64, ambient_c: f64) {
        let q = self.q;
        let rhs: Vec<f64> = (0..q)
            .map(|k| {
                let b = self.b_r[k];
                self.z[k] / self.dt_s + b[0] * p_tca_w + b[1] * p_pla_w + b[2] * ambient_c
            })
            .collect();
        for i in 0..q {
            self.z[i] = self.m[i * q..(i + 1) * q]
                .iter()
                .zip(&rhs)
                .map(|(a, b)| a * b)
                .sum();
        }
    }

    /// Temperature of cell `c`, °C.
    pub fn cell_c(&self, c: usize) -> f64 {
        let q = self.q;
        self.v[c * q..(c + 1) * q]
            .iter()
            .zip(&self.z)
            .map(|(a, b)| a * b)
            .sum()
    }

    /// The whole field, °C.
    pub fn field_c(&self) -> Vec<f64> {
        (0..self.n).map(|c| self.cell_c(c)).collect()
    }

    /// Area means of the TCA tube and the PLA rod, °C.
    pub fn heater_means_c(&self) -> (f64, f64) {
        let (mut t, mut p) = (0.0, 0.0);
        for (m, z) in self.means.iter().zip(&self.z) {
            t += m[0] * z;
            p += m[1] * z;
        }
        (t, p)
    }
}

/// Inverse of the `q × q` row-major matrix `a` by Gauss–Jordan with partial pivoting; `None`
/// if singular.
fn invert(a: &[f64], q: usize) -> Option<Vec<f64>> {
    let mut m = a.to_vec();
    let mut inv = vec![0.0; q * q];
    for i in 0..q {
        inv[i * q + i] = 1.0;
    }
    for col in 0..q {
        let piv = (col..q).max_by(|&x, &y| {
            m[x * q + col]
                .abs()
                .partial_cmp(&m[y * q + col].abs())
                .unwrap_or(core::cmp::Ordering::Equal)
        })?;
        let p = m[piv * q + col];
        if !(p.abs() > 1e-300) || !p.is_finite() {
            return None;
        }
        for k in 0..q {
            m.swap(col * q + k, piv * q + k);
            inv.swap(col * q + k, piv * q + k);
        }
        for k in 0..q {
            m[col * q + k] /= p;
            inv[col * q + k] /= p;
        }
        for r in 0..q {
            if r != col {
                let f = m[r * q + col];
                if f != 0.0 {
                    for k in 0..q {
                        m[r * q + k] -= f * m[col * q + k];
                        inv[r * q + k] -= f * inv[col * q + k];
                    }
                }
            }
        }
    }
    Some(inv)
}

/// Backward-Euler stepping of an absolute temperature field with powers and ambient that may
/// change every step: `(C/Δt + A) Tⁿ⁺¹ = C/Δt Tⁿ + q + g_rim T∞`.
#[derive(Clone, Debug)]
pub struct Stepper {
    dt_s: f64,
    shift: Vec<f64>,
    factor: Banded,
    tca_per_w: Vec<f64>,
    pla_per_w: Vec<f64>,
    rim: Vec<f64>,
    rim_base: usize,
}

impl Stepper {
    /// The step it was made for, s.
    pub fn dt_s(&self) -> f64 {
        self.dt_s
    }

    /// Advances `t_c` (°C, ring-major, one per cell) by one step with whole-link heater powers
    /// `p_tca_w`, `p_pla_w` and the medium at `ambient_c`.
    pub fn step(&self, t_c: &mut [f64], p_tca_w: f64, p_pla_w: f64, ambient_c: f64) {
        for c in 0..t_c.len() {
            t_c[c] =
                self.shift[c] * t_c[c] + p_tca_w * self.tca_per_w[c] + p_pla_w * self.pla_per_w[c];
        }
        for (j, g) in self.rim.iter().enumerate() {
            t_c[self.rim_base + j] += g * ambient_c;
        }
        self.factor.solve(t_c);
    }
}

/// Time stepping of the transient.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stepping {
    /// Backward Euler (unconditionally stable).
    Implicit,
    /// Forward Euler, refused above the stability limit.
    Explicit,
    /// Forward Euler without the limit check (only the divergence monitor): for the tests that
    /// map the limit.
    ExplicitUnchecked,
    /// Explicit where stable, implicit otherwise or on divergence.
    Auto,
}

/// Heater-mean rises after each step.
#[derive(Clone, Debug)]
pub struct Transient {
    /// The method that produced it.
    pub method: Stepping,
    /// Step, s.
    pub dt_s: f64,
    /// TCA mean rise after each step, K.
    pub tca_rise_k: Vec<f64>,
    /// PLA mean rise after each step, K.
    pub pla_rise_k: Vec<f64>,
}

impl Transient {
    fn new(method: Stepping, dt_s: f64) -> Self {
        Transient {
            method,
            dt_s,
            tca_rise_k: Vec::new(),
            pla_rise_k: Vec::new(),
        }
    }
    fn push(&mut self, (t, p): (f64, f64)) {
        self.tca_rise_k.push(t);
        self.pla_rise_k.push(p);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A disk of matrix with one centred heated rod of radius `r0` (and a far, tiny second
    /// inclusion of the same matrix material so the layout stays valid).
    fn concentric(k_rod: f64, r0: f64) -> Layout {
        let inc = |x: f64, r: f64, k: f64| Inclusion {
            x_m: x,
            y_m: 0.0,
            radius_m: r,
            core_radius_m: 0.0,
            k_w_mk: k,
            rho_cp_j_m3k: 1e6,
            core_k_w_mk: k,
            core_rho_cp_j_m3k: 1e6,
        };
        Layout {
            radius_m: 4e-3,
            k_w_mk: 0.2,
            rho_cp_j_m3k: 1.1e6,
            h_w_m2k: 101.3,
            tca: inc(0.0, r0, k_rod),
            // A rod of matrix material: heats nothing when its power is 0.
            pla: inc(3e-3, 0.6e-3, 0.2),
            length_m: 0.05,
        }
    }

    /// Exact mean rise of a uniformly heated centred rod, K/W (paper Eq. 11 form plus film and
    /// the rod's own `1/(8πk)`).
    fn concentric_exact(k_rod: f64, r0: f64) -> f64 {
        let (a, k, h, l) = (4e-3, 0.2, 101.3, 0.05);
        (libm::log(a / r0) / (2.0 * PI * k) + 1.0 / (2.0 * PI * a * h) + 1.0 / (8.0 * PI * k_rod))
            / l
    }

    #[test]
    fn concentric_heater_converges_at_second_order() {
        // Rod radius on a ring face for every grid (a/4), so the order is the scheme's own.
        let (k_rod, r0) = (4.6, 1e-3);
        let exact = concentric_exact(k_rod, r0);
        let mut errs = Vec::new();
        for nr in [8, 16, 32] {
            let x = CrossSection::new(&concentric(k_rod, r0), nr, 8).unwrap();
            let r = x.resistance_matrix().unwrap().r_tt;
            errs.push((r - exact).abs() / exact);
        }
        let p1 = libm::log2(errs[0] / errs[1]);
        let p2 = libm::log2(errs[1] / errs[2]);
        assert!(errs[2] < 2e-3, "{errs:?}");
        assert!(p1 > 1.7 && p2 > 1.7, "orders {p1} {p2} ({errs:?})");
    }

    #[test]
    fn uniform_rod_field_matches_the_exact_profile() {
        // The whole disk heated uniformly: T(r) = q (a² − r²)/(4k) + q a/(2h).
        let mut lay = concentric(0.2, 4e-3);
        lay.tca.radius_m = 4.1e-3; // covers the disk
        let (nr, nt) = (32, 8);
        let x = CrossSection::new(&lay, nr, nt).unwrap();
        // The small second rod is part of the heated disk: share the watt by area.
        let (ta, pa): (f64, f64) = (x.tca_area.iter().sum(), x.pla_area.iter().sum());
        let f = x.steady(ta / (ta + pa), pa / (ta + pa)).unwrap();
        let (a, k, h, l) = (4e-3, 0.2, 101.3, 0.05);
        let q = 1.0 / l / (PI * a * a);
        let dr = a / nr as f64;
        let mut worst: f64 = 0.0;
        for i in 0..nr {
            let r = (i as f64 + 0.5) * dr;
            let exact = q * (a * a - r * r) / (4.0 * k) + q * a / (2.0 * h);
            worst = worst.max((f.rise_k[i * nt] - exact).abs() / exact);
        }
        assert!(worst < 1e-3, "worst relative error {worst}");
    }

    /// Exact mean rise of a uniformly heated disk (radius `a`, conductivity `k`, diffusivity
    /// `alpha`, rim coefficient `h`, heat `q` W/m³) started at ambient: the steady profile minus
    /// the Bessel series `Σ A_n J0(λ_n r) exp(−α λ_n² t)`, `λ J1(λa) = (h/k) J0(λa)`.
    fn disk_mean_rise_exact(a: f64, k: f64, alpha: f64, h: f64, q: f64, t: f64) -> f64 {
        let steady = |r: f64| q * (a * a - r * r) / (4.0 * k) + q * a / (2.0 * h);
        let f = |l: f64| l * libm::j1(l * a) - h / k * libm::j0(l * a);
        // Roots by bisection on a fine scan in λa.
        let mut roots = Vec::new();
        let (mut x0, step) = (1e-6, 0.01);
        while roots.len() < 40 {
            let x1 = x0 + step;
            let (mut lo, mut hi) = (x0 / a, x1 / a);
            if f(lo) * f(hi) < 0.0 {
                for _ in 0..100 {
                    let mid = 0.5 * (lo + hi);
                    if f(lo) * f(mid) <= 0.0 {
                        hi = mid;
                    } else {
                        lo = mid;
                    }
                }
                roots.push(0.5 * (lo + hi));
            }
            x0 = x1;
        }
        // ∫ g(r) r dr on [0, a] by the midpoint rule on 4000 panels.
        let integral = |g: &dyn Fn(f64) -> f64| {
            let n = 4000;
            let h = a / n as f64;
            (0..n)
                .map(|i| (i as f64 + 0.5) * h)
                .map(|r| g(r) * r * h)
                .sum::<f64>()
        };
        let mean_steady = 2.0 / (a * a) * integral(&|r| steady(r));
        let mut u = 0.0;
        for l in roots {
            let num = integral(&|r| steady(r) * libm::j0(l * r));
            let den = integral(&|r| libm::j0(l * r) * libm::j0(l * r));
            let mean_mode = 2.0 / (a * a) * a * libm::j1(l * a) / l;
            u += num / den * mean_mode * libm::exp(-alpha * l * l * t);
        }
        mean_steady - u
    }

    #[test]
    fn uniform_disk_transient_matches_the_bessel_series() {
        let mut lay = concentric(0.2, 4e-3);
        lay.tca.radius_m = 4.1e-3;
        let x = CrossSection::new(&lay, 16, 8).unwrap();
        let (ta, pa): (f64, f64) = (x.tca_area.iter().sum(), x.pla_area.iter().sum());
        let (pt, pp) = (ta / (ta + pa), pa / (ta + pa));
        let dt = 0.05;
        let run = x.transient(pt, pp, dt, 1200, Stepping::Implicit).unwrap();
        let (a, k, h, l) = (4e-3, 0.2, 101.3, 0.05);
        let q = 1.0 / l / (PI * a * a);
        for t in [2.0, 10.0, 30.0, 60.0] {
            let i = (t / dt).round() as usize - 1;
            let fv = (ta * run.tca_rise_k[i] + pa * run.pla_rise_k[i]) / (ta + pa);
            let exact = disk_mean_rise_exact(a, k, k / 1e6, h, q, t);
            assert!(
                (fv - exact).abs() < 0.01 * exact,
                "t={t}: fv {fv} exact {exact}"
            );
        }
    }

    #[test]
    fn link_matrix_is_reciprocal_and_near_the_lumped_one() {
        let p = LinkParams::DEFAULT;
        let x = CrossSection::of_link(&p, 16).unwrap();
        let f = x.factor(&vec![0.0; x.cells()]).unwrap();
        let mut t1 = x.sources(1.0, 0.0);
        f.solve(&mut t1);
        let mut t2 = x.sources(0.0, 1.0);
        f.solve(&mut t2);
        let (_, tp) = x.heater_means_k(&t1);
        let (pt, _) = x.heater_means_k(&t2);
        assert!((tp - pt).abs() < 1e-9 * tp, "{tp} vs {pt}");
        let r = x.resistance_matrix().unwrap();
        let lumped = crate::thermal::resistance_matrix(&p);
        for (a, b) in [
            (r.r_tt, lumped.r_tt),
            (r.r_pp, lumped.r_pp),
            (r.r_tp, lumped.r_tp),
        ] {
            assert!(
                (a - b).abs() < 0.25 * b,
                "reference {r:?} lumped {lumped:?}"
            );
        }
    }

    #[test]
    fn implicit_transient_reaches_steady_and_is_first_order_in_time() {
        let p = LinkParams::DEFAULT;
        let x = CrossSection::of_link(&p, 8).unwrap();
        let steady = x.steady(1.0, 0.0).unwrap().tca_rise_k;
        let long = x
            .transient(1.0, 0.0, 20.0, 100, Stepping::Implicit)
            .unwrap();
        let end = *long.tca_rise_k.last().unwrap();
        assert!((end - steady).abs() < 1e-6 * steady);
        // Value at 4 s with dt = 1, 0.5, 0.25 s against dt = 1/64 s.
        let at4 = |dt: f64| {
            let n = (4.0 / dt).round() as usize;
            *x.transient(1.0, 0.0, dt, n, Stepping::Implicit)
                .unwrap()
                .tca_rise_k
                .last()
                .unwrap()
        };
        let fine = at4(1.0 / 64.0);
        let e: Vec<f64> = [1.0, 0.5, 0.25]
            .iter()
            .map(|&d| (at4(d) - fine).abs())
            .collect();
        let order = libm::log2(e[1] / e[2]);
        assert!(order > 0.8 && order < 1.3, "order {order} {e:?}");
    }

    #[test]
    fn explicit_stepping_is_stable_below_its_limit_diverges_above_and_auto_falls_back() {
        let p = LinkParams::DEFAULT;
        let x = CrossSection::of_link(&p, 6).unwrap();
        let limit = x.explicit_limit_s();
        let bound = 2.0 / x.max_rate_bound_per_s();
        assert!(bound <= limit * 1.0001 && limit > 0.0, "{bound} vs {limit}");
        let t_end = 2.0;
        let steps = |dt: f64| (t_end / dt).ceil() as usize;
        let below = 0.95 * limit;
        let ok = x
            .transient(1.0, 0.5, below, steps(below), Stepping::Explicit)
            .unwrap();
        let imp = x
            .transient(1.0, 0.5, below, steps(below), Stepping::Implicit)
            .unwrap();
        let (a, b) = (
            *ok.tca_rise_k.last().unwrap(),
            *imp.tca_rise_k.last().unwrap(),
        );
        assert!((a - b).abs() < 0.02 * b, "explicit {a} implicit {b}");
        // Just above the limit: refused by the checked method, detected by the monitor when
        // forced, and the automatic method answers by implicit stepping.
        let above = 1.05 * limit;
        let n = steps(above) * 40;
        assert!(matches!(
            x.transient(1.0, 0.5, above, n, Stepping::Explicit),
            Err(ReferenceError::UnstableStep { .. })
        ));
        assert!(matches!(
            x.transient(1.0, 0.5, above, n, Stepping::ExplicitUnchecked),
            Err(ReferenceError::Diverged { .. })
        ));
        let auto = x.transient(1.0, 0.5, above, n, Stepping::Auto).unwrap();
        assert_eq!(auto.method, Stepping::Implicit);
        assert!(auto.tca_rise_k.iter().all(|v| v.is_finite() && *v >= 0.0));
    }

    #[test]
    fn surface_heat_makes_the_rod_rim_hotter_than_its_core_and_steps_balance_energy() {
        let p = LinkParams::DEFAULT;
        let vol = CrossSection::of_link(&p, 12).unwrap();
        let surf = vol.clone().with_pla_heat(PlaHeat::Surface);
        assert_eq!(surf.pla_heat(), PlaHeat::Surface);
        let centre = (-p.geometry.pla_offset_m, 0.0);
        let rim_pt = (-p.geometry.pla_offset_m - 0.8e-3, 0.0);
        let dip = |x: &CrossSection| {
            let f = x.steady(0.0, 1.0).unwrap().rise_k;
            x.value_at(&f, rim_pt.0, rim_pt.1) - x.value_at(&f, centre.0, centre.1)
        };
        // Volume heat peaks at the rod's centre; surface heat leaves the centre cooler than
        // its rim's cells (or at most level with them).
        assert!(dip(&vol) < 0.0, "volume {}", dip(&vol));
        assert!(
            dip(&surf) > dip(&vol) + 0.05,
            "surface {} volume {}",
            dip(&surf),
            dip(&vol)
        );
        // The stepper reaches the steady field and its rim gives off what goes in.
        let st = surf.stepper(5.0).unwrap();
        let amb = 22.0;
        let mut t = vec![amb; surf.cells()];
        for _ in 0..400 {
            st.step(&mut t, 0.3, 1.0, amb);
        }
        let out = surf.rim_power_w(&t, amb);
        assert!((out - 1.3).abs() < 1e-6, "rim {out} W");
        let steady = surf.steady(0.3, 1.0).unwrap();
        let (mt, mp) = surf.heater_means_k(&t);
        assert!((mt - amb - steady.tca_rise_k).abs() < 1e-6 * steady.tca_rise_k);
        assert!((mp - amb - steady.pla_rise_k).abs() < 1e-6 * steady.pla_rise_k);
        // A new h changes the rim: air keeps the section hotter.
        let mut air = surf.clone();
        air.set_h(20.0);
        assert!(air.steady(0.3, 1.0).unwrap().tca_rise_k > 2.0 * steady.tca_rise_k);
    }

    #[test]
    fn reduced_order_model_follows_the_grid_through_heating_and_cooling() {
        let p = LinkParams::DEFAULT;
        let x = CrossSection::of_link(&p, 12)
            .unwrap()
            .with_pla_heat(PlaHeat::Surface);
        let shifts = [0.0, 0.003, 0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0];
        let dt = 0.1;
        let mut rom = x.rom(&shifts, dt).unwrap();
        assert!(
            rom.order() <= 27 && rom.order() >= 12,
            "order {}",
            rom.order()
        );
        let st = x.stepper(dt).unwrap();
        let amb = 22.0;
        let mut t = vec![amb; x.cells()];
        rom.set_field(&t);
        assert!((rom.cell_c(5) - amb).abs() < 1e-9);
        let mut worst: f64 = 0.0;
        for k in 0..600 {
            let (pt, pp, a) = if k < 300 {
                (1.0, 3.0, amb)
            } else {
                (0.0, 0.0, amb + 3.0)
            };
            st.step(&mut t, pt, pp, a);
            rom.step(pt, pp, a);
            let (ft, fp) = x.heater_means_k(&t);
            let (rt, rp) = rom.heater_means_c();
            worst = worst.max((ft - rt).abs() / (ft - amb).abs().max(5.0));
            worst = worst.max((fp - rp).abs() / (fp - amb).abs().max(5.0));
            let c = x.cells() / 2 + 3;
            worst = worst.max((t[c] - rom.cell_c(c)).abs() / (t[c] - amb).abs().max(5.0));
        }
        assert!(worst < 0.01, "worst {worst}");
        // Steady state is exact.
        let mut rom = x.rom(&shifts, 1e4).unwrap();
        rom.set_field(&vec![amb; x.cells()]);
        for _ in 0..50 {
            rom.step(0.5, 1.0, amb);
        }
        let s = x.steady(0.5, 1.0).unwrap();
        let (rt, rp) = rom.heater_means_c();
        assert!((rt - amb - s.tca_rise_k).abs() < 1e-6 * s.tca_rise_k);
        assert!((rp - amb - s.pla_rise_k).abs() < 1e-6 * s.pla_rise_k);
    }

    #[test]
    fn bad_inputs_are_errors() {
        let p = LinkParams::DEFAULT;
        assert!(matches!(
            CrossSection::of_link(&p, 1),
            Err(ReferenceError::BadGrid { .. })
        ));
        let x = CrossSection::of_link(&p, 6).unwrap();
        assert!(matches!(
            x.transient(1.0, 0.0, f64::NAN, 3, Stepping::Implicit),
            Err(ReferenceError::BadStep { .. })
        ));
        // No convection and no conductance: singular, reported, not NaN.
        let mut lay = Layout::of_link(&p);
        lay.h_w_m2k = 0.0;
        let x = CrossSection::new(&lay, 6, 8).unwrap();
        assert!(x.steady(1.0, 0.0).is_err());
    }
}
