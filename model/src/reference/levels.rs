//! Model levels from the lumped closed form to the finest reference, their radius-versus-power
//! curves, their errors and cost, and the rule that picks the cheapest level for a tolerance.
//!
//! A level is a thermal model (lumped image-method matrix, or the finite-volume cross-section at
//! some number of rings) feeding a mechanics model (the lumped closed form `κ = rF/(EI + r²Lk)`,
//! the constant-strain Cosserat rod, or the piecewise rod with N segments), with or without the
//! PLA's temperature-dependent stiffness and with the linear or the physics-based TCA law.
//! The reference is the finest grid with the constant-strain rod (for the link's loads — the TCA
//! alone, no tip load — the piecewise rod gives the same strain in every segment).

use super::cosserat::{self, link_stiffness, Rod, Strain, REFERENCE_STRAIN};
use super::fv_thermal::CrossSection;
use super::tca_physics::{PhysicsLaw, TcaLaw};
use super::ReferenceError;
use crate::params::LinkParams;
use crate::thermal::{resistance_matrix, ResistanceMatrix};
use std::time::Instant;

/// Rings of the finest finite-volume grid (the reference).
pub const REFERENCE_RINGS: usize = 96;
/// TCA powers at which curves are compared, W (the paper's 0.1–1.5 W in 0.1 W steps).
pub const POWERS_W: [f64; 15] = [
    0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.1, 1.2, 1.3, 1.4, 1.5,
];
/// Highest TCA temperature over which the physics law's coefficient is identified, °C.
const PHYSICS_FIT_MAX_C: f64 = 100.0;

/// Thermal part of a level.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Thermal {
    /// Image-method matrix of the lumped model.
    Lumped,
    /// Finite volumes with this many rings.
    FiniteVolume(usize),
}

/// Mechanics part of a level.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mechanics {
    /// `κ = r F / (K_yy + r² L k)` (planar, inextensible).
    ClosedForm,
    /// Piecewise-constant-strain Cosserat rod with this many segments (1 = constant strain).
    Cosserat(usize),
}

/// TCA law of a level.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Law {
    /// The calibrated linear law.
    Linear,
    /// The physics-based law (identified from the linear one).
    Physics,
}

/// One model level.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Level {
    /// Thermal model.
    pub thermal: Thermal,
    /// Mechanics model.
    pub mechanics: Mechanics,
    /// Include the PLA's temperature-dependent stiffness.
    pub pla_stiffness: bool,
    /// TCA law.
    pub law: Law,
}

impl Level {
    /// The lumped model of the firmware table.
    pub const LUMPED: Level = Level {
        thermal: Thermal::Lumped,
        mechanics: Mechanics::ClosedForm,
        pla_stiffness: false,
        law: Law::Linear,
    };

    /// The reference: finest grid, constant-strain Cosserat rod, linear law, PLA soft.
    pub const REFERENCE: Level = Level {
        thermal: Thermal::FiniteVolume(REFERENCE_RINGS),
        mechanics: Mechanics::Cosserat(1),
        pla_stiffness: false,
        law: Law::Linear,
    };

    /// A short name, e.g. `lumped`, `fv32+closed`, `lumped+cosserat`, `fv96+pcs8+pla`.
    pub fn name(&self) -> String {
        let t = match self.thermal {
            Thermal::Lumped => "lumped".to_string(),
            Thermal::FiniteVolume(n) => format!("fv{n}"),
        };
        let m = match self.mechanics {
            Mechanics::ClosedForm => "closed".to_string(),
            Mechanics::Cosserat(1) => "cosserat".to_string(),
            Mechanics::Cosserat(n) => format!("pcs{n}"),
        };
        let mut s = if *self == Level::LUMPED {
            "lumped".to_string()
        } else {
            format!("{t}+{m}")
        };
        if self.pla_stiffness {
            s.push_str("+pla");
        }
        if self.law == Law::Physics {
            s.push_str("+tcaphys");
        }
        s
    }

    /// The levels of the accuracy/cost study, cheapest first within each family.
    pub fn study() -> Vec<Level> {
        let mut v = vec![Level::LUMPED];
        let base = Level {
            thermal: Thermal::Lumped,
            mechanics: Mechanics::ClosedForm,
            pla_stiffness: false,
            law: Law::Linear,
        };
        for n in [8, 12, 16, 24, 32, 48, 64, REFERENCE_RINGS] {
            v.push(Level {
                thermal: Thermal::FiniteVolume(n),
                ..base
            });
        }
        v.push(Level {
            mechanics: Mechanics::Cosserat(1),
            ..base
        });
        for n in [16, 32] {
            v.push(Level {
                thermal: Thermal::FiniteVolume(n),
                mechanics: Mechanics::Cosserat(1),
                ..base
            });
        }
        for n in [1, 2, 4, 8, 16, 32] {
            v.push(Level {
                thermal: Thermal::FiniteVolume(REFERENCE_RINGS),
                mechanics: Mechanics::Cosserat(n),
                ..base
            });
        }
        v.push(Level {
            pla_stiffness: true,
            ..Level::LUMPED
        });
        v.push(Level {
            pla_stiffness: true,
            ..Level::REFERENCE
        });
        v.push(Level {
            law: Law::Physics,
            ..Level::LUMPED
        });
        v.push(Level {
            law: Law::Physics,
            ..Level::REFERENCE
        });
        v
    }
}

/// The thermal-resistance matrix of a thermal level, K/W.
pub fn thermal_matrix(p: &LinkParams, t: Thermal) -> Result<ResistanceMatrix, ReferenceError> {
    match t {
        Thermal::Lumped => Ok(resistance_matrix(p)),
        Thermal::FiniteVolume(n) => CrossSection::of_link(p, n)?.resistance_matrix(),
    }
}

/// Radius, mm, at each TCA power of `powers_w` (PLA at its hold power) for a level. Powers are
/// solved in the order given, each from the previous solution (continuation in power).
pub fn radius_curve_mm(
    p: &LinkParams,
    level: &Level,
    powers_w: &[f64],
) -> Result<Vec<f64>, ReferenceError> {
    let r = thermal_matrix(p, level.thermal)?;
    radius_curve_with_matrix_mm(p, level, &r, powers_w)
}

/// As [`radius_curve_mm`] with the thermal matrix already computed.
pub fn radius_curve_with_matrix_mm(
    p: &LinkParams,
    level: &Level,
    r: &ResistanceMatrix,
    powers_w: &[f64],
) -> Result<Vec<f64>, ReferenceError> {
    let law = match level.law {
        Law::Linear => TcaLaw::Linear(p.mechanics),
        Law::Physics => TcaLaw::Physics(PhysicsLaw::identified(p, PHYSICS_FIT_MAX_C)),
    };
    let amb = p.surroundings.ambient_c;
    let mut guess: Strain = REFERENCE_STRAIN;
    let mut out = Vec::with_capacity(powers_w.len());
    for &pw in powers_w {
        let (rt, rp) = r.rises_k(pw, p.pla_hold_power_w);
        let (t_tca, t_pla) = (amb + rt, amb + rp);
        let f = law.at(t_tca);
        let pla = level.pla_stiffness.then_some(t_pla);
        let radius_m = match level.mechanics {
            Mechanics::ClosedForm => {
                let kyy = link_stiffness(p, pla)[1][1];
                let off = p.geometry.tca_offset_m;
                let kappa =
                    off * f.push_n / (kyy + off * off * p.geometry.length_m * f.stiffness_n_per_m);
                if !(kappa > 0.0) || !kappa.is_finite() {
                    return Err(ReferenceError::Straight);
                }
                1.0 / kappa
            }
            Mechanics::Cosserat(n) => {
                let rod = Rod::of_link(p, f, pla);
                let s = cosserat::solve_robust(&rod, n, &guess)?;
                guess = s.strains[0];
                cosserat::radius_m(&s.strains, rod.length_m)?
            }
        };
        out.push(radius_m * 1e3);
    }
    Ok(out)
}

/// Fits `EI`, `F0` and `c` of `p` to measured `(power_w, radius_mm)` points with `level`'s own
/// model (thermal matrix `r` given), exactly as the lumped calibration does for the lumped
/// model: Levenberg–Marquardt on `(ln EI, F0, c)` with the same weak prior on `EI`
/// ([`crate::calibrate::PRIOR_WEIGHT_MM`] per e-fold), started from `p`'s constants. Each level
/// is compared with the data after its own fit, as a user of that level would use it.
pub fn calibrate_level(
    p: &LinkParams,
    level: &Level,
    r: &ResistanceMatrix,
    points: &[(f64, f64)],
) -> Result<LinkParams, ReferenceError> {
    use crate::calibrate::{levenberg_marquardt3, with_theta, PRIOR_WEIGHT_MM};
    let ln_prior = crate::calibrate::prior_stiffness_nm2(p).ln();
    let powers: Vec<f64> = points.iter().map(|x| x.0).collect();
    let residuals = |th: &nalgebra::Vector3<f64>| -> Result<Vec<f64>, ReferenceError> {
        let c = radius_curve_with_matrix_mm(&with_theta(p, th), level, r, &powers)?;
        let mut v: Vec<f64> = c.iter().zip(points).map(|(m, x)| m - x.1).collect();
        v.push(PRIOR_WEIGHT_MM * (th[0] - ln_prior));
        Ok(v)
    };
    let m = &p.mechanics;
    let start = nalgebra::Vector3::new(
        m.bending_stiffness_nm2.ln(),
        m.preload_n,
        m.force_coeff_n_per_k,
    );
    let (th, _) = levenberg_marquardt3(start, residuals)?;
    let q = with_theta(p, &th);
    if !(q.mechanics.bending_stiffness_nm2.is_finite() && q.mechanics.bending_stiffness_nm2 > 0.0) {
        return Err(ReferenceError::NonFinite("calibrated bending stiffness"));
    }
    Ok(q)
}

/// A level's result in the study.
#[derive(Clone, Debug)]
pub struct Scored {
    /// The level.
    pub level: Level,
    /// Radius at each of [`POWERS_W`], mm.
    pub radius_mm: Vec<f64>,
    /// Wall time of one whole curve (thermal model + 15 powers), s (median of repeats).
    pub seconds: f64,
    /// Largest difference from the reference curve, mm.
    pub error_vs_reference_mm: f64,
    /// Largest difference from the measured points, mm.
    pub error_vs_measured_mm: f64,
    /// Largest difference from the reference with the lumped model's constants, not refitted
    /// (what swapping the level in without recalibrating would change), mm.
    pub uncalibrated_difference_mm: f64,
    /// The level's own fitted constants `(EI N m², F0 N, c N/K)`.
    pub constants: (f64, f64, f64),
}

/// Median wall time of `f`, repeated until about `budget_s` has passed (at least 3 runs), s.
pub fn time_it<T>(budget_s: f64, mut f: impl FnMut() -> T) -> (T, f64) {
    let mut times = Vec::new();
    let start = Instant::now();
    let mut last;
    loop {
        let t0 = Instant::now();
        last = f();
        times.push(t0.elapsed().as_secs_f64());
        if times.len() >= 3 && start.elapsed().as_secs_f64() > budget_s {
            break;
        }
        if times.len() >= 1000 {
            break;
        }
    }
    times.sort_by(|a, b| a.total_cmp(b));
    (last, times[times.len() / 2])
}

/// Largest absolute difference between the curve (at [`POWERS_W`]) and measured points
/// `(power_w, radius_mm)`, interpolating the curve linearly in power, mm.
pub fn error_vs_points_mm(curve_mm: &[f64], points: &[(f64, f64)]) -> f64 {
    points
        .iter()
        .map(|&(pw, r)| (interpolate(&POWERS_W, curve_mm, pw) - r).abs())
        .fold(0.0, f64::max)
}

fn interpolate(xs: &[f64], ys: &[f64], x: f64) -> f64 {
    for i in 0..xs.len() - 1 {
        if x <= xs[i + 1] || i + 2 == xs.len() {
            let f = (x - xs[i]) / (xs[i + 1] - xs[i]);
            return ys[i] + f * (ys[i + 1] - ys[i]);
        }
    }
    ys[0]
}

/// Scores every level against the reference and the measured points, each level (the
/// reference too) calibrated to `measured` with its own model first; `progress` is called after
/// each level. Timing (of one curve with the fitted constants, thermal solve included) spends
/// about `budget_s` per level.
pub fn score(
    p: &LinkParams,
    levels: &[Level],
    measured: &[(f64, f64)],
    budget_s: f64,
    mut progress: impl FnMut(&Level),
) -> Result<Vec<Scored>, ReferenceError> {
    let r_ref = thermal_matrix(p, Level::REFERENCE.thermal)?;
    let p_ref = calibrate_level(p, &Level::REFERENCE, &r_ref, measured)?;
    let reference = radius_curve_with_matrix_mm(&p_ref, &Level::REFERENCE, &r_ref, &POWERS_W)?;
    let uncalibrated_ref = radius_curve_with_matrix_mm(p, &Level::REFERENCE, &r_ref, &POWERS_W)?;
    let mut out = Vec::new();
    for level in levels {
        let r = if level.thermal == Level::REFERENCE.thermal {
            r_ref
        } else {
            thermal_matrix(p, level.thermal)?
        };
        let uncal = radius_curve_with_matrix_mm(p, level, &r, &POWERS_W)?;
        let uncalibrated_difference_mm = uncal
            .iter()
            .zip(&uncalibrated_ref)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        let q = calibrate_level(p, level, &r, measured)?;
        let (curve, seconds) = time_it(budget_s, || radius_curve_mm(&q, level, &POWERS_W));
        let curve = curve?;
        let m = &q.mechanics;
        let error_vs_reference_mm = curve
            .iter()
            .zip(&reference)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        out.push(Scored {
            level: *level,
            error_vs_measured_mm: error_vs_points_mm(&curve, measured),
            radius_mm: curve,
            seconds,
            error_vs_reference_mm,
            uncalibrated_difference_mm,
            constants: (m.bending_stiffness_nm2, m.preload_n, m.force_coeff_n_per_k),
        });
        progress(level);
    }
    Ok(out)
}

/// Indices of the levels on the Pareto front of (seconds, error): no other level is both
/// cheaper and at least as accurate (errors closer than 1e-6 mm count as equal).
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..points.len()).collect();
    idx.sort_by(|&a, &b| points[a].0.total_cmp(&points[b].0));
    let mut best = f64::INFINITY;
    let mut front = Vec::new();
    for i in idx {
        if points[i].1 < best - 1e-6 {
            best = points[i].1;
            front.push(i);
        }
    }
    front
}

/// The rule: the cheapest level whose error against the reference is within `tolerance_mm`
/// (only levels of the reference's physics: linear law, PLA soft). `None` if none is.
pub fn pick(scored: &[Scored], tolerance_mm: f64) -> Option<&Scored> {
    scored
        .iter()
        .filter(|s| !s.level.pla_stiffness && s.level.law == Law::Linear)
        .filter(|s| s.error_vs_reference_mm <= tolerance_mm)
        .min_by(|a, b| a.seconds.total_cmp(&b.seconds))
}

/// Worst radius error, mm, of a firmware table of `entries` rows of `p`'s lumped model,
/// interpolated as the firmware does (f32, linear in curvature), when asked for any radius in
/// its range: the table gives a power, and the model's radius at that power is compared with the
/// target. Also returns the table's flash size, bytes.
pub fn table_error_mm(p: &LinkParams, entries: usize) -> (f64, usize) {
    let mut q = *p;
    q.table_entries = entries.max(2);
    let rows: Vec<(f32, f32)> = (0..q.table_entries)
        .map(|i| {
            let e = crate::table::entry(&q, i);
            (e.power_w as f32, e.radius_mm as f32)
        })
        .collect();
    let (rmin, rmax) = (rows[rows.len() - 1].1, rows[0].1);
    let mut worst: f64 = 0.0;
    let samples = 2000;
    for k in 0..=samples {
        let target = rmin + (rmax - rmin) * k as f32 / samples as f32;
        let x = 1.0 / target;
        let mut power = rows[rows.len() - 1].0;
        for w in rows.windows(2) {
            let (ka, kb) = (1.0 / w[0].1, 1.0 / w[1].1);
            if x <= kb {
                let f = (x - ka) / (kb - ka);
                power = w[0].0 + f * (w[1].0 - w[0].0);
                break;
            }
        }
        let got = crate::mechanics::radius_mm(p, power as f64);
        worst = worst.max((got - target as f64).abs());
    }
    (worst, crate::table::flash_bytes(q.table_entries))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lumped_level_reproduces_the_lumped_model_exactly() {
        let p = LinkParams::DEFAULT;
        let c = radius_curve_mm(&p, &Level::LUMPED, &POWERS_W).unwrap();
        for (r, pw) in c.iter().zip(POWERS_W) {
            let l = crate::mechanics::radius_mm(&p, pw);
            assert!((r - l).abs() < 1e-9, "{pw} W: {r} vs {l}");
        }
    }

    #[test]
    fn piecewise_rod_equals_constant_strain_for_the_actuator_alone() {
        let p = LinkParams::DEFAULT;
        let mk = |n| Level {
            thermal: Thermal::Lumped,
            mechanics: Mechanics::Cosserat(n),
            pla_stiffness: false,
            law: Law::Linear,
        };
        let a = radius_curve_mm(&p, &mk(1), &[0.3, 1.2]).unwrap();
        let b = radius_curve_mm(&p, &mk(4), &[0.3, 1.2]).unwrap();
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() < 1e-6, "{x} vs {y}");
        }
    }

    #[test]
    fn pick_takes_the_cheapest_level_within_tolerance_of_the_reference_physics() {
        let mk = |level: Level, seconds: f64, err: f64| Scored {
            level,
            radius_mm: vec![],
            seconds,
            error_vs_reference_mm: err,
            error_vs_measured_mm: 0.0,
            uncalibrated_difference_mm: 0.0,
            constants: (0.0, 0.0, 0.0),
        };
        let pla = Level {
            pla_stiffness: true,
            ..Level::LUMPED
        };
        let cos = Level {
            mechanics: Mechanics::Cosserat(1),
            ..Level::LUMPED
        };
        let s = vec![
            mk(pla, 1e-7, 0.0),
            mk(Level::LUMPED, 1e-6, 0.03),
            mk(cos, 1e-5, 0.002),
            mk(Level::REFERENCE, 1.0, 0.0),
        ];
        assert_eq!(pick(&s, 0.5).unwrap().level, Level::LUMPED);
        assert_eq!(pick(&s, 0.01).unwrap().level, cos);
        assert_eq!(pick(&s, 1e-4).unwrap().level, Level::REFERENCE);
        assert!(pick(&s[..3], 1e-4).is_none());
    }

    #[test]
    fn pareto_front_keeps_only_undominated_points() {
        let pts = [(1.0, 5.0), (2.0, 6.0), (3.0, 1.0), (0.5, 9.0), (4.0, 1.0)];
        assert_eq!(pareto_front(&pts), vec![3, 0, 2]);
    }

    #[test]
    fn table_error_falls_with_entries_and_the_default_table_meets_half_a_millimetre() {
        let p = LinkParams::DEFAULT;
        let (e4, _) = table_error_mm(&p, 4);
        let (e16, bytes) = table_error_mm(&p, 16);
        assert!(e16 < e4, "{e16} vs {e4}");
        assert_eq!(bytes, 192);
        assert!(e16 < 0.5, "{e16}");
    }
}
