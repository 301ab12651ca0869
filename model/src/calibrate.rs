//! Fit of the unknown mechanical constants to measured radii.
//!
//! Unknowns: bending stiffness `EI`, TCA preload `F0` and thermal force coefficient `c`.
//! Three measured points (`fig9_calibration.csv`) are fitted by Levenberg–Marquardt in radius
//! (mm). The balance `EI κ = r F` only fixes force-to-stiffness ratios well; the ratio of `EI`
//! to the TCA's own coil stiffness changes the curve's bow only weakly, so a weak prior keeps
//! `EI` near the silicone body's `E I` (E = 37.8 kPa) and the data decide the rest. The fit
//! reports how far the data moved it.

use crate::mechanics::radius_mm;
use crate::params::{Geometry, LinkParams};
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

/// Prefix of the comment line that records the geometry a data file's radii were measured on:
/// `# geometry: body_diameter_m = 0.008, length_m = 0.05, ...`, all eight `[geometry]` keys.
pub const GEOMETRY_LINE: &str = "# geometry:";

/// A measured-radii file: its points of one source and the geometry it records.
#[derive(Clone, Debug, PartialEq)]
pub struct Data {
    /// The rows of the chosen source, in file order.
    pub points: Vec<Point>,
    /// The geometry the radii were measured on (its `# geometry:` line), if the file says.
    pub geometry: Option<Geometry>,
}

/// Points of `source` (`measured` or `paper_model`) from a `p_tca_w,radius_mm,source` CSV.
pub fn load_points(path: &Path, source: &str) -> Result<Vec<Point>, String> {
    Ok(load_data(path, source)?.points)
}

/// The whole data file at `path`: points of `source` and its recorded geometry; errors name
/// the file.
pub fn load_data(path: &Path, source: &str) -> Result<Data, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    parse_data(&text, source).map_err(|e| format!("{}: {e}", path.display()))
}

/// Parses the CSV text; `#` lines are comments, the header must name `p_tca_w`, `radius_mm`
/// and `source`.
pub fn parse_points(text: &str, source: &str) -> Result<Vec<Point>, String> {
    Ok(parse_data(text, source)?.points)
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Row {
    p_tca_w: f64,
    radius_mm: f64,
    source: String,
}

/// Parses a data file's text: its rows of `source` (each power and radius finite and
/// positive) and its `# geometry:` line.
pub fn parse_data(text: &str, source: &str) -> Result<Data, String> {
    let mut geometry = None;
    for (n, line) in text.lines().enumerate() {
        if let Some(rest) = line.trim().strip_prefix(GEOMETRY_LINE) {
            if geometry.is_some() {
                return Err(format!("line {}: a second {GEOMETRY_LINE} line", n + 1));
            }
            geometry = Some(parse_geometry(rest).map_err(|e| format!("line {}: {e}", n + 1))?);
        }
    }
    let mut reader = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .trim(csv::Trim::All)
        .from_reader(text.as_bytes());
    let mut points = Vec::new();
    for row in reader.deserialize::<Row>() {
        let row = row.map_err(|e| match e.position() {
            Some(at) => format!("line {}: {e}", at.line()),
            None => e.to_string(),
        })?;
        if row.source != source {
            continue;
        }
        for (name, v) in [("p_tca_w", row.p_tca_w), ("radius_mm", row.radius_mm)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{name} must be a positive number, got {v}"));
            }
        }
        points.push(Point {
            p_tca_w: row.p_tca_w,
            radius_mm: row.radius_mm,
        });
    }
    Ok(Data { points, geometry })
}

/// The eight `[geometry]` keys of a `# geometry:` line, `key = value` separated by commas.
fn parse_geometry(text: &str) -> Result<Geometry, String> {
    let mut vals: [Option<f64>; 8] = [None; 8];
    const KEYS: [&str; 8] = [
        "body_diameter_m",
        "length_m",
        "tca_outer_diameter_m",
        "tca_inner_diameter_m",
        "tca_fibre_diameter_m",
        "tca_offset_m",
        "pla_diameter_m",
        "pla_offset_m",
    ];
    for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let (k, v) = item
            .split_once('=')
            .ok_or_else(|| format!("{GEOMETRY_LINE} expects key = value, got `{item}`"))?;
        let (k, v) = (k.trim(), v.trim());
        let i = KEYS
            .iter()
            .position(|x| *x == k)
            .ok_or_else(|| format!("{GEOMETRY_LINE} has unknown key `{k}`; expected {KEYS:?}"))?;
        let v: f64 = v
            .parse()
            .map_err(|e| format!("{GEOMETRY_LINE} {k} = `{v}`: {e}"))?;
        vals[i] = Some(v);
    }
    let get = |i: usize| vals[i].ok_or_else(|| format!("{GEOMETRY_LINE} lacks {}", KEYS[i]));
    Ok(Geometry {
        body_diameter_m: get(0)?,
        length_m: get(1)?,
        tca_outer_diameter_m: get(2)?,
        tca_inner_diameter_m: get(3)?,
        tca_fibre_diameter_m: get(4)?,
        tca_offset_m: get(5)?,
        pla_diameter_m: get(6)?,
        pla_offset_m: get(7)?,
    })
}

/// The `# geometry:` line for `g`, to head a data file measured on it.
pub fn geometry_line(g: &Geometry) -> String {
    format!(
        "{GEOMETRY_LINE} body_diameter_m = {}, length_m = {}, tca_outer_diameter_m = {}, \
         tca_inner_diameter_m = {}, tca_fibre_diameter_m = {}, tca_offset_m = {}, \
         pla_diameter_m = {}, pla_offset_m = {}",
        g.body_diameter_m,
        g.length_m,
        g.tca_outer_diameter_m,
        g.tca_inner_diameter_m,
        g.tca_fibre_diameter_m,
        g.tca_offset_m,
        g.pla_diameter_m,
        g.pla_offset_m
    )
}

/// Refuses to fit `p` to radii measured on `measured_on` when that is another geometry: the fit
/// would describe the link the radii came from, not this one. The sentence lists what differs.
pub fn check_same_geometry(p: &LinkParams, measured_on: &Geometry) -> Result<(), String> {
    if &p.geometry == measured_on {
        return Ok(());
    }
    let diffs: Vec<String> = crate::file::geometry_differences(&p.geometry, measured_on)
        .iter()
        .map(|d| d.replace("(fitted on", "(data measured on"))
        .collect();
    Err(format!(
        "the radii were measured on another geometry: {}. A fit to them would describe that \
         link, not this one: measure the steady radius at three or more TCA powers on this link \
         and fit those (docs/model.md, \"A new geometry\")",
        diffs.join(", ")
    ))
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
    fn the_shipped_data_records_the_paper_geometry() {
        let d = parse_data(CSV, "measured").unwrap();
        assert_eq!(d.geometry, Some(crate::params::PAPER_GEOMETRY));
        assert_eq!(parse_data(CSV, "paper_model").unwrap().points.len(), 15);
        let line = geometry_line(&crate::params::PAPER_GEOMETRY);
        assert_eq!(
            parse_data(&format!("{line}\np_tca_w,radius_mm,source\n"), "measured")
                .unwrap()
                .geometry,
            Some(crate::params::PAPER_GEOMETRY)
        );
    }

    #[test]
    fn data_from_another_geometry_is_refused() {
        let mut wide = LinkParams::DEFAULT;
        wide.geometry.body_diameter_m = 10e-3;
        let d = parse_data(CSV, "measured").unwrap();
        let e = check_same_geometry(&wide, &d.geometry.unwrap()).unwrap_err();
        assert!(
            e.contains("geometry.body_diameter_m = 0.01 (data measured on 0.008)"),
            "{e}"
        );
        assert!(check_same_geometry(&LinkParams::DEFAULT, &d.geometry.unwrap()).is_ok());
    }

    #[test]
    fn bad_rows_name_their_line() {
        let bad = "p_tca_w,radius_mm,source\n0.1,45,measured\n0.8,abc,measured\n";
        assert!(parse_data(bad, "measured").unwrap_err().contains("line 3"));
        let neg = "p_tca_w,radius_mm,source\n-0.1,45,measured\n";
        assert!(parse_data(neg, "measured").unwrap_err().contains("p_tca_w"));
        let short = "p_tca_w,radius_mm\n0.1,45\n";
        assert!(parse_data(short, "measured").is_err());
        let geo = "# geometry: body_diameter_m = 0.008\np_tca_w,radius_mm,source\n";
        assert!(parse_data(geo, "measured")
            .unwrap_err()
            .contains("lacks length_m"));
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
