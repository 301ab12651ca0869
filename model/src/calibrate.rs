//! Fit of the unknown mechanical constants to measured radii.
//!
//! Unknowns: bending stiffness `EI`, TCA preload `F0` and thermal force coefficient `c`.
//! Three measured points (`fig9_calibration.csv`) are fitted by Levenberg–Marquardt in radius
//! (mm). The balance `EI κ = r F` only fixes force-to-stiffness ratios well; the ratio of `EI`
//! to the TCA's own coil stiffness changes the curve's bow only weakly, so a weak prior keeps
//! `EI` near the silicone body's `E I` (E = 37.8 kPa) and the data decide the rest. The fit
//! reports how far the data moved it.

use crate::mechanics::radius_mm;
use crate::params::LinkParams;
use nalgebra::{Matrix3, Vector3};
use std::path::Path;

pub use crate::mechanics::SILICONE_E_PA;
/// Weight of the stiffness prior, mm of radius residual per e-fold of `EI` away from it: small,
/// so it only settles the direction the data cannot see.
pub const PRIOR_WEIGHT_MM: f64 = 0.2;

/// One measured point: TCA power and steady radius.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Point {
    /// TCA power, W.
    pub p_tca_w: f64,
    /// Radius, mm.
    pub radius_mm: f64,
}

/// Points of `source` (`measured` or `paper_model`) from a `p_tca_w,radius_mm,source` CSV.
pub fn load_points(path: &Path, source: &str) -> Result<Vec<Point>, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    parse_points(&text, source)
}

/// Parses the CSV text; `#` lines and the header are skipped.
pub fn parse_points(text: &str, source: &str) -> Result<Vec<Point>, String> {
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') || line.starts_with("p_tca_w") {
            continue;
        }
        let f: Vec<&str> = line.split(',').collect();
        if f.len() != 3 {
            return Err(format!("line {}: expected p_tca_w,radius_mm,source", n + 1));
        }
        if f[2].trim() != source {
            continue;
        }
        let num = |s: &str| {
            s.trim()
                .parse::<f64>()
                .map_err(|e| format!("line {}: {e}", n + 1))
        };
        out.push(Point {
            p_tca_w: num(f[0])?,
            radius_mm: num(f[1])?,
        });
    }
    Ok(out)
}

/// Result of a calibration.
#[derive(Clone, Debug)]
pub struct Fit {
    /// The parameters with the fitted constants filled in.
    pub params: LinkParams,
    /// Model minus measured radius at each point, mm.
    pub residuals_mm: Vec<f64>,
    /// The stiffness prior, N m².
    pub prior_stiffness_nm2: f64,
    /// Levenberg–Marquardt iterations used.
    pub iterations: usize,
}

/// Stiffness prior: silicone body plus the rubbery PLA rod, N m².
pub fn prior_stiffness_nm2(p: &LinkParams) -> f64 {
    crate::mechanics::cross_section_stiffness_nm2(&p.geometry, &p.pla_stiffness)
}

/// `p` with the fit's parameters `(ln EI, F0, c)` filled in.
pub fn with_theta(p: &LinkParams, th: &Vector3<f64>) -> LinkParams {
    let mut q = *p;
    // The fitted constants belong to the geometry they are fitted on.
    q.fitted_on = p.geometry;
    q.mechanics.bending_stiffness_nm2 = th[0].exp();
    q.mechanics.preload_n = th[1];
    q.mechanics.force_coeff_n_per_k = th[2];
    q
}

fn residuals(p: &LinkParams, pts: &[Point], th: &Vector3<f64>, ln_prior: f64) -> Vec<f64> {
    let q = with_theta(p, th);
    let mut r: Vec<f64> = pts
        .iter()
        .map(|pt| radius_mm(&q, pt.p_tca_w) - pt.radius_mm)
        .collect();
    r.push(PRIOR_WEIGHT_MM * (th[0] - ln_prior));
    r
}

/// Fits `EI`, `F0` and `c` of `p` to `pts` (at least three points).
pub fn calibrate(p: &LinkParams, pts: &[Point]) -> Result<Fit, String> {
    if pts.len() < 3 {
        return Err(format!(
            "calibration needs at least three measured points, got {}",
            pts.len()
        ));
    }
    let prior = prior_stiffness_nm2(p);
    let ln_prior = prior.ln();
    // Start from the prior stiffness with the force scaled to the mean measured curvature.
    let mean_k = pts.iter().map(|pt| 1e3 / pt.radius_mm).sum::<f64>() / pts.len() as f64;
    let f0 = mean_k * prior / p.geometry.tca_offset_m;
    let start = Vector3::new(ln_prior, f0, 0.01 * f0);
    let Ok((th, iterations)) = levenberg_marquardt3(start, |th| {
        Ok::<_, core::convert::Infallible>(residuals(p, pts, th, ln_prior))
    });
    let params = with_theta(p, &th);
    let residuals_mm = pts
        .iter()
        .map(|pt| radius_mm(&params, pt.p_tca_w) - pt.radius_mm)
        .collect();
    if !params.mechanics.bending_stiffness_nm2.is_finite() {
        return Err("calibration diverged".into());
    }
    Ok(Fit {
        params,
        residuals_mm,
        prior_stiffness_nm2: prior,
        iterations,
    })
}

/// Levenberg–Marquardt on three parameters, from `start`, minimising the sum of squares of
/// `residuals` (forward-difference Jacobian). A trial step whose residuals cannot be computed is
/// a step too far, not a failure; an error at an accepted point is returned. Returns the
/// parameters and the iterations used (at most 200; stops when a step gains less than 1e-12
/// of the cost).
pub fn levenberg_marquardt3<E>(
    start: Vector3<f64>,
    residuals: impl Fn(&Vector3<f64>) -> Result<Vec<f64>, E>,
) -> Result<(Vector3<f64>, usize), E> {
    let cost = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>();
    let mut th = start;
    let mut lambda = 1e-3;
    let mut iterations = 0;
    for it in 0..200 {
        iterations = it + 1;
        let r0 = residuals(&th)?;
        let c0 = cost(&r0);
        let mut jtj = Matrix3::zeros();
        let mut jtr = Vector3::zeros();
        let mut cols = [Vec::new(), Vec::new(), Vec::new()];
        for (k, col) in cols.iter_mut().enumerate() {
            let h = 1e-6 * th[k].abs().max(1e-6);
            let mut t2 = th;
            t2[k] += h;
            *col = residuals(&t2)?
                .iter()
                .zip(&r0)
                .map(|(a, b)| (a - b) / h)
                .collect();
        }
        for i in 0..r0.len() {
            let j = Vector3::new(cols[0][i], cols[1][i], cols[2][i]);
            jtj += j * j.transpose();
            jtr += j * r0[i];
        }
        let mut improved = None;
        for _ in 0..20 {
            let mut a = jtj;
            for k in 0..3 {
                a[(k, k)] *= 1.0 + lambda;
                a[(k, k)] += 1e-30;
            }
            let Some(step) = a.lu().solve(&(-jtr)) else {
                break;
            };
            let cand = th + step;
            if let Ok(rc) = residuals(&cand) {
                let c = cost(&rc);
                if c < c0 {
                    th = cand;
                    lambda = (lambda * 0.3).max(1e-12);
                    improved = Some(c);
                    break;
                }
            }
            lambda *= 10.0;
        }
        match improved {
            Some(c) if c0 - c >= 1e-12 * c0.max(1e-30) => {}
            _ => break,
        }
    }
    Ok((th, iterations))
}

#[cfg(test)]
mod tests {
    use super::*;

    const CSV: &str = include_str!("../../data/fig9_calibration.csv");

    #[test]
    fn fit_reproduces_the_measured_points_within_half_a_millimetre() {
        let pts = parse_points(CSV, "measured").unwrap();
        assert_eq!(pts.len(), 3);
        let fit = calibrate(&LinkParams::DEFAULT, &pts).unwrap();
        for r in &fit.residuals_mm {
            assert!(r.abs() < 0.5, "residuals {:?}", fit.residuals_mm);
        }
    }

    #[test]
    fn shipped_constants_are_the_fitted_ones() {
        let pts = parse_points(CSV, "measured").unwrap();
        let fit = calibrate(&LinkParams::DEFAULT, &pts).unwrap();
        let (a, b) = (fit.params.mechanics, LinkParams::DEFAULT.mechanics);
        let close = |x: f64, y: f64| ((x - y) / y).abs() < 1e-3;
        assert!(
            close(a.bending_stiffness_nm2, b.bending_stiffness_nm2)
                && close(a.preload_n, b.preload_n)
                && close(a.force_coeff_n_per_k, b.force_coeff_n_per_k),
            "run `morph-model calibrate` and update params.rs: fitted {a:?}"
        );
    }

    #[test]
    fn too_few_points_is_an_error() {
        let pts = [Point {
            p_tca_w: 0.1,
            radius_mm: 45.0,
        }];
        assert!(calibrate(&LinkParams::DEFAULT, &pts).is_err());
    }
}
