//! The reference-model study of `morph-model charts`: accuracy versus cost of every model level,
//! radius versus power, firmware table size, thermal grid convergence. Writes SVG charts and a
//! CSV of the numbers, and prints a summary.

use crate::plot::{self, prelude::*};
use indicatif::{ProgressBar, ProgressStyle};
use morphlink_model::reference::fv_thermal::{CrossSection, Inclusion, Layout};
use morphlink_model::reference::levels::{self, Level, Scored, POWERS_W, REFERENCE_RINGS};
use morphlink_model::LinkParams;
use std::fmt::Write as _;
use std::path::Path;

/// The study's charts: 20 px captions, 15 px margins, room for `1e-3` labels on log axes.
const STUDY: Frame = Frame::new(20, 15, 45, 70);
/// The same on linear axes, whose labels are shorter.
const STUDY_LINEAR: Frame = Frame::new(20, 15, 45, 60);

/// Measured and paper-predicted points of Fig. 9, `(power_w, radius_mm)`.
pub struct Fig9 {
    /// The paper's measurements.
    pub measured: Vec<(f64, f64)>,
    /// The paper's own model.
    pub paper_model: Vec<(f64, f64)>,
}

/// Reads both sources from the calibration CSV.
pub fn load_fig9(path: &Path) -> Result<Fig9, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    let rows = |src: &str| -> Result<Vec<(f64, f64)>, String> {
        Ok(morphlink_model::calibrate::parse_points(&text, src)?
            .iter()
            .map(|p| (p.p_tca_w, p.radius_mm))
            .collect())
    };
    Ok(Fig9 {
        measured: rows("measured")?,
        paper_model: rows("paper_model")?,
    })
}

fn err<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// Scores every level of the study with a progress bar.
pub fn score_all(p: &LinkParams, fig9: &Fig9, budget_s: f64) -> Result<Vec<Scored>, String> {
    let study = Level::study();
    let bar = ProgressBar::new(study.len() as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} levels, {elapsed} elapsed {msg}")
            .map_err(err)?,
    );
    // Drawn from the start (the first level takes half a minute), on stderr, and only on a
    // terminal (indicatif hides a bar whose stderr is not one).
    bar.enable_steady_tick(std::time::Duration::from_millis(250));
    let out = levels::score(p, &study, &fig9.measured, budget_s, |l| {
        bar.set_message(l.name());
        bar.inc(1);
    })
    .map_err(err)?;
    bar.finish_and_clear();
    Ok(out)
}

/// One grid-convergence row: rings, cells, value, error against the exact or finest value.
pub struct GridRow {
    /// Rings.
    pub rings: usize,
    /// Cells.
    pub cells: usize,
    /// Relative error of the concentric heater's resistance against Eq. 11's exact form.
    pub concentric_error: f64,
    /// The link's R_tt, K/W.
    pub r_tt: f64,
    /// Relative difference of R_tt from the finest grid.
    pub link_error: f64,
    /// Explicit-Euler stability limit of the link's grid, s.
    pub explicit_limit_s: f64,
}

/// Grid convergence of the concentric heater (exact) and the link (against the finest grid).
pub fn grid_study(p: &LinkParams) -> Result<Vec<GridRow>, String> {
    let finest = CrossSection::of_link(p, REFERENCE_RINGS)
        .and_then(|x| x.resistance_matrix())
        .map_err(err)?
        .r_tt;
    let (a, k, h, l, r0, k_rod) = (4e-3, 0.2, 101.3, 0.05, 1e-3, 4.6);
    let inc = |x: f64, r: f64, kk: f64| Inclusion {
        x_m: x,
        y_m: 0.0,
        radius_m: r,
        core_radius_m: 0.0,
        k_w_mk: kk,
        rho_cp_j_m3k: 1e6,
        core_k_w_mk: kk,
        core_rho_cp_j_m3k: 1e6,
    };
    let lay = Layout {
        radius_m: a,
        k_w_mk: k,
        rho_cp_j_m3k: 1.1e6,
        h_w_m2k: h,
        tca: inc(0.0, r0, k_rod),
        pla: inc(3e-3, 0.6e-3, k),
        length_m: l,
    };
    let pi = core::f64::consts::PI;
    let exact =
        ((a / r0).ln() / (2.0 * pi * k) + 1.0 / (2.0 * pi * a * h) + 1.0 / (8.0 * pi * k_rod)) / l;
    let mut rows = Vec::new();
    for n in [8usize, 12, 16, 24, 32, 48, 64] {
        let c = CrossSection::new(&lay, n, 8)
            .and_then(|x| x.resistance_matrix())
            .map_err(err)?
            .r_tt;
        let x = CrossSection::of_link(p, n).map_err(err)?;
        let r = x.resistance_matrix().map_err(err)?.r_tt;
        rows.push(GridRow {
            rings: n,
            cells: x.cells(),
            concentric_error: (c - exact).abs() / exact,
            r_tt: r,
            link_error: (r - finest).abs() / finest,
            explicit_limit_s: x.explicit_limit_s(),
        });
    }
    Ok(rows)
}

/// Observed order between successive rows: `log(e₁/e₂) / log(n₂/n₁)` in rings.
pub fn orders(rows: &[(usize, f64)]) -> Vec<f64> {
    rows.windows(2)
        .map(|w| (w[0].1 / w[1].1).ln() / (w[1].0 as f64 / w[0].0 as f64).ln())
        .collect()
}

/// Error-versus-time scatter with labels and the Pareto front, both axes logarithmic. A level
/// with zero error (the reference against itself) has no place on a log axis: it is drawn as a
/// labelled vertical line at its run time, not as a point at a made-up small error.
fn pareto_chart(
    path: &Path,
    title: &str,
    scored: &[Scored],
    error: impl Fn(&Scored) -> f64,
) -> Result<(), String> {
    let (drawn, exact): (Vec<&Scored>, Vec<&Scored>) = scored.iter().partition(|s| error(s) > 0.0);
    let pts: Vec<(f64, f64)> = drawn.iter().map(|s| (s.seconds, error(s))).collect();
    let front = levels::pareto_front(&pts);
    let (xmin, xmax) = scored.iter().fold((f64::MAX, 0.0f64), |(a, b), s| {
        (a.min(s.seconds), b.max(s.seconds))
    });
    let (ymin, ymax) = pts
        .iter()
        .fold((f64::MAX, 0.0f64), |(a, b), p| (a.min(p.1), b.max(p.1)));
    let (ymin, ymax) = if pts.is_empty() {
        (1e-3, 1.0)
    } else {
        (ymin, ymax)
    };
    let y_label = if exact.is_empty() {
        "max |radius error|, mm".to_string()
    } else {
        format!(
            "max |radius error|, mm (zero error: {}, vertical line)",
            exact
                .iter()
                .map(|s| s.level.name())
                .collect::<Vec<_>>()
                .join(", ")
        )
    };
    Ok(plot::write_svg(path, (1000, 700), |root| {
        let (y0, y1) = (ymin / 2.0, ymax * 3.0);
        let mut chart = STUDY
            .builder(root, Some(title))
            .build_cartesian_2d((xmin / 2.0..xmax * 3.0).log_scale(), (y0..y1).log_scale())?;
        mesh(
            &mut chart,
            "run time of one 15-power curve, s",
            &y_label,
            true,
        )
        .x_label_formatter(&sci)
        .y_label_formatter(&sci)
        .draw()?;
        let front_pts: Vec<(f64, f64)> = front.iter().map(|&i| pts[i]).collect();
        line(
            &mut chart,
            front_pts,
            RED.stroke_width(2),
            Some("Pareto front"),
        )?;
        for (i, (s, p)) in drawn.iter().zip(&pts).enumerate() {
            let c = if front.contains(&i) { RED } else { palette(i) };
            labelled_point(&mut chart, *p, 5, c, &s.level.name())?;
        }
        for s in &exact {
            line(
                &mut chart,
                [(s.seconds, y0), (s.seconds, y1)],
                BLACK.stroke_width(1),
                None,
            )?;
            labelled_point(
                &mut chart,
                (s.seconds, y1 / 1.5),
                0,
                BLACK,
                &format!("{}: zero error", s.level.name()),
            )?;
        }
        legend(&mut chart, SeriesLabelPosition::MiddleRight)
    })?)
}

fn radius_chart(path: &Path, scored: &[Scored], fig9: &Fig9, shown: &[&str]) -> Result<(), String> {
    Ok(plot::write_svg(path, (1000, 700), |root| {
        let mut chart = STUDY_LINEAR
            .builder(
                root,
                Some("Radius versus TCA power (PLA held at 1.5 W, under water)"),
            )
            .build_cartesian_2d(0.0..1.6, 30.0..50.0)?;
        mesh(&mut chart, "TCA power, W", "radius, mm", true).draw()?;
        for (i, s) in scored
            .iter()
            .filter(|s| shown.contains(&s.level.name().as_str()))
            .enumerate()
        {
            let data: Vec<(f64, f64)> = POWERS_W
                .iter()
                .copied()
                .zip(s.radius_mm.iter().copied())
                .collect();
            line(
                &mut chart,
                data,
                palette(i).stroke_width(2),
                Some(&s.level.name()),
            )?;
        }
        chart
            .draw_series(
                fig9.paper_model
                    .iter()
                    .map(|p| Cross::new(*p, 5, BLACK.stroke_width(1))),
            )?
            .label("paper's model (Fig. 9)")
            .legend(|(x, y)| Cross::new((x + 10, y), 5, BLACK.stroke_width(1)));
        chart
            .draw_series(
                fig9.measured
                    .iter()
                    .map(|p| Circle::new(*p, 6, BLACK.filled())),
            )?
            .label("measured (Fig. 9)")
            .legend(|(x, y)| Circle::new((x + 10, y), 5, BLACK.filled()));
        legend(&mut chart, SeriesLabelPosition::MiddleRight)
    })?)
}

fn table_chart(path: &Path, rows: &[(usize, f64, usize)]) -> Result<(), String> {
    let ymax = rows.iter().map(|r| r.1).fold(0.0, f64::max) * 2.0;
    let ymin = rows.iter().map(|r| r.1).fold(f64::MAX, f64::min) / 2.0;
    Ok(plot::write_svg(path, (1000, 600), |root| {
        let mut chart = STUDY
            .builder(
                root,
                Some("Firmware table: entries vs worst radius error (labels: flash bytes)"),
            )
            .build_cartesian_2d((2.0..80.0).log_scale(), (ymin..ymax).log_scale())?;
        mesh(
            &mut chart,
            "entries",
            "worst |radius error| of interpolation, mm",
            true,
        )
        .x_label_formatter(&whole)
        .y_label_formatter(&sci)
        .draw()?;
        let data: Vec<(f64, f64)> = rows.iter().map(|r| (r.0 as f64, r.1)).collect();
        line(&mut chart, data.clone(), BLUE.stroke_width(2), None)?;
        for (r, d) in rows.iter().zip(&data) {
            labelled_point(&mut chart, *d, 4, BLUE, &format!("{} B", r.2))?;
        }
        Ok(())
    })?)
}

fn grid_chart(path: &Path, rows: &[GridRow]) -> Result<(), String> {
    let all: Vec<f64> = rows
        .iter()
        .flat_map(|r| [r.concentric_error, r.link_error])
        .filter(|v| *v > 0.0)
        .collect();
    let ymin = all.iter().copied().fold(f64::MAX, f64::min) / 2.0;
    let ymax = all.iter().copied().fold(0.0, f64::max) * 2.0;
    Ok(plot::write_svg(path, (1000, 600), |root| {
        let mut chart = STUDY
            .builder(root, Some("Finite-volume grid convergence"))
            .build_cartesian_2d((6.0..80.0).log_scale(), (ymin..ymax).log_scale())?;
        mesh(
            &mut chart,
            "rings (sectors ≈ π × rings for the link, 8 for the concentric case)",
            "relative error of R",
            true,
        )
        .x_label_formatter(&whole)
        .y_label_formatter(&sci)
        .draw()?;
        let c: Vec<(f64, f64)> = rows
            .iter()
            .map(|r| (r.rings as f64, r.concentric_error))
            .collect();
        let l: Vec<(f64, f64)> = rows
            .iter()
            .map(|r| (r.rings as f64, r.link_error))
            .collect();
        line(
            &mut chart,
            c,
            BLUE.stroke_width(2),
            Some("concentric heater vs exact (Eq. 11 form)"),
        )?;
        line(
            &mut chart,
            l,
            RED.stroke_width(2),
            Some(&format!("link R_tt vs {REFERENCE_RINGS} rings")),
        )?;
        legend(&mut chart, SeriesLabelPosition::MiddleRight)
    })?)
}

/// One transient sample: `(t_s, fv_tca_k, fv_pla_k, net_tca_k, net_pla_k)`.
pub type TransientRow = (f64, f64, f64, f64, f64);

/// TCA and PLA rises over the paper's bend phase (TCA 1 W, PLA 1.5 W from ambient, 60 s):
/// the reference grid stepped implicitly (0.1 s) against the lumped five-node network.
/// Returns `(t_s, fv_tca, fv_pla, net_tca, net_pla)` rows.
pub fn transient_study(p: &LinkParams, rings: usize) -> Result<Vec<TransientRow>, String> {
    use morphlink_model::reference::fv_thermal::Stepping;
    use morphlink_model::thermal::{node, Network};
    let dt = 0.1;
    let steps = 600;
    let x = CrossSection::of_link(p, rings).map_err(err)?;
    let fv = x
        .transient(1.0, 1.5, dt, steps, Stepping::Implicit)
        .map_err(err)?;
    let mut net = Network::new(p);
    let amb = p.surroundings.ambient_c;
    let mut rows = Vec::with_capacity(steps);
    for k in 0..steps {
        net.advance(dt, 1.0, 1.5, amb);
        rows.push((
            (k + 1) as f64 * dt,
            fv.tca_rise_k[k],
            fv.pla_rise_k[k],
            net.temp_c[node::TCA] - amb,
            net.temp_c[node::PLA] - amb,
        ));
    }
    Ok(rows)
}

fn transient_chart(path: &Path, rows: &[TransientRow], rings: usize) -> Result<(), String> {
    let ymax = rows
        .iter()
        .map(|r| r.1.max(r.2).max(r.3).max(r.4))
        .fold(0.0, f64::max)
        * 1.1;
    Ok(plot::write_svg(path, (1000, 600), |root| {
        let mut chart = STUDY_LINEAR
            .builder(
                root,
                Some("Heater rises, TCA 1 W + PLA 1.5 W from ambient: reference grid vs lumped network"),
            )
            .build_cartesian_2d(0.0..60.0, 0.0..ymax)?;
        mesh(&mut chart, "time, s", "rise above ambient, K", true).draw()?;
        let pick = |r: &TransientRow, i: usize| [r.1, r.2, r.3, r.4][i];
        let series = [
            ("TCA, finite volumes", 0usize),
            ("PLA, finite volumes", 1),
            ("TCA, lumped network", 2),
            ("PLA, lumped network", 3),
        ];
        for (name, i) in series {
            let label = if name.contains("finite") {
                format!("{name} ({rings} rings)")
            } else {
                name.to_string()
            };
            line(
                &mut chart,
                rows.iter().map(|r| (r.0, pick(r, i))),
                palette(i).stroke_width(2),
                Some(&label),
            )?;
        }
        legend(&mut chart, SeriesLabelPosition::LowerRight)
    })?)
}

/// Worst error of the firmware's 16-entry table (f32, linear in curvature) against a curve at
/// [`POWERS_W`] and against points, mm.
pub fn firmware_table_errors(p: &LinkParams, curve: &[f64], points: &[(f64, f64)]) -> (f64, f64) {
    let rows: Vec<(f32, f32)> = (0..p.table_entries)
        .map(|i| {
            let e = morphlink_model::table::entry(p, i);
            (e.power_w as f32, e.radius_mm as f32)
        })
        .collect();
    let radius = |pw: f64| -> f64 {
        let x = pw as f32;
        for w in rows.windows(2) {
            if x <= w[1].0 {
                let f = (x - w[0].0) / (w[1].0 - w[0].0);
                let k = 1.0 / w[0].1 + f * (1.0 / w[1].1 - 1.0 / w[0].1);
                return (1.0 / k) as f64;
            }
        }
        rows[rows.len() - 1].1 as f64
    };
    let vs_curve = POWERS_W
        .iter()
        .zip(curve)
        .map(|(&pw, r)| (radius(pw) - r).abs())
        .fold(0.0, f64::max);
    let vs_points = points
        .iter()
        .map(|&(pw, r)| (radius(pw) - r).abs())
        .fold(0.0, f64::max);
    (vs_curve, vs_points)
}

/// Runs the whole study, writes the charts and `study.csv` into `out`, returns the summary text.
pub fn run(p: &LinkParams, fig9: &Fig9, out: &Path, budget_s: f64) -> Result<String, String> {
    std::fs::create_dir_all(out).map_err(|e| format!("cannot create {}: {e}", out.display()))?;
    let scored = score_all(p, fig9, budget_s)?;
    let grid = grid_study(p)?;
    let table: Vec<(usize, f64, usize)> = [2usize, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64]
        .iter()
        .map(|&n| {
            let (e, b) = levels::table_error_mm(p, n);
            (n, e, b)
        })
        .collect();
    pareto_chart(
        &out.join("accuracy-vs-cost-reference.svg"),
        "Error against the finest reference vs run time",
        &scored,
        |s| s.error_vs_reference_mm,
    )?;
    pareto_chart(
        &out.join("accuracy-vs-cost-measured.svg"),
        "Error against the measured radii (Fig. 9) vs run time",
        &scored,
        |s| s.error_vs_measured_mm,
    )?;
    radius_chart(
        &out.join("radius-vs-power.svg"),
        &scored,
        fig9,
        &[
            "lumped",
            "fv8+closed",
            "fv96+closed",
            "lumped+cosserat",
            "fv96+cosserat",
            "fv96+cosserat+pla",
            "fv96+cosserat+tcaphys",
        ],
    )?;
    table_chart(&out.join("table-size.svg"), &table)?;
    let transient_rings = 32;
    let transient = transient_study(p, transient_rings)?;
    transient_chart(&out.join("transient.svg"), &transient, transient_rings)?;
    grid_chart(&out.join("grid-convergence.svg"), &grid)?;

    let mut csv = String::from("level,seconds,error_vs_reference_mm,error_vs_measured_mm");
    for pw in POWERS_W {
        let _ = write!(csv, ",r_{pw:.1}w_mm");
    }
    csv.push('\n');
    for s in &scored {
        let _ = write!(
            csv,
            "{},{:.6e},{:.4},{:.4}",
            s.level.name(),
            s.seconds,
            s.error_vs_reference_mm,
            s.error_vs_measured_mm
        );
        for r in &s.radius_mm {
            let _ = write!(csv, ",{r:.3}");
        }
        csv.push('\n');
    }
    std::fs::write(out.join("study.csv"), csv).map_err(err)?;

    let mut t = String::new();
    let _ = writeln!(t, "| level | time per curve | error vs reference, mm | error vs measured, mm | not refitted: diff vs reference, mm | fitted EI, N m² | F0, N | c, mN/K |");
    let _ = writeln!(t, "| --- | --- | --- | --- | --- | --- | --- | --- |");
    let pts_ref: Vec<(f64, f64)> = scored
        .iter()
        .map(|s| (s.seconds, s.error_vs_reference_mm))
        .collect();
    let pts_meas: Vec<(f64, f64)> = scored
        .iter()
        .map(|s| (s.seconds, s.error_vs_measured_mm))
        .collect();
    let fr = levels::pareto_front(&pts_ref);
    let fm = levels::pareto_front(&pts_meas);
    for (i, s) in scored.iter().enumerate() {
        let _ = writeln!(
            t,
            "| {} | {} | {:.4}{} | {:.3}{} | {:.2} | {:.4e} | {:.4} | {:.3} |",
            s.level.name(),
            human_time(s.seconds),
            s.error_vs_reference_mm,
            if fr.contains(&i) { " ◆" } else { "" },
            s.error_vs_measured_mm,
            if fm.contains(&i) { " ◆" } else { "" },
            s.uncalibrated_difference_mm,
            s.constants.0,
            s.constants.1,
            s.constants.2 * 1e3,
        );
    }
    let _ = writeln!(t, "\n◆ = on the Pareto front of that error.\n");
    let _ = writeln!(t, "| rings | cells | concentric rel. error | link R_tt, K/W | link rel. diff vs {REFERENCE_RINGS} rings | explicit step limit |");
    let _ = writeln!(t, "| --- | --- | --- | --- | --- | --- |");
    for r in &grid {
        let _ = writeln!(
            t,
            "| {} | {} | {:.2e} | {:.3} | {:.2e} | {} |",
            r.rings,
            r.cells,
            r.concentric_error,
            r.r_tt,
            r.link_error,
            human_time(r.explicit_limit_s)
        );
    }
    let oc = orders(
        &grid
            .iter()
            .map(|r| (r.rings, r.concentric_error))
            .collect::<Vec<_>>(),
    );
    let ol = orders(
        &grid
            .iter()
            .map(|r| (r.rings, r.link_error))
            .collect::<Vec<_>>(),
    );
    let _ = writeln!(t, "\nobserved orders, concentric: {}", fmt_list(&oc));
    let _ = writeln!(t, "observed orders, link R_tt:  {}\n", fmt_list(&ol));
    let _ = writeln!(
        t,
        "| table entries | flash bytes | worst interpolation error, mm |"
    );
    let _ = writeln!(t, "| --- | --- | --- |");
    for (n, e, b) in &table {
        let _ = writeln!(t, "| {n} | {b} | {e:.4} |");
    }
    let _ = writeln!(
        t,
        "\n| t, s | TCA rise FV, K | TCA rise network, K | PLA rise FV, K | PLA rise network, K |"
    );
    let _ = writeln!(t, "| --- | --- | --- | --- | --- |");
    for r in transient.iter().filter(|r| {
        [1.0, 2.0, 5.0, 10.0, 20.0, 40.0, 60.0]
            .iter()
            .any(|t| (r.0 - t).abs() < 1e-9)
    }) {
        let _ = writeln!(
            t,
            "| {:.0} | {:.2} | {:.2} | {:.2} | {:.2} |",
            r.0, r.1, r.3, r.2, r.4
        );
    }
    let reference = scored
        .iter()
        .find(|s| s.level == Level::REFERENCE)
        .ok_or("reference level missing from the study")?;
    let (fw_ref, fw_meas) = firmware_table_errors(p, &reference.radius_mm, &fig9.measured);
    let _ = writeln!(
        t,
        "\nfirmware table ({} entries, f32): worst error vs reference {:.3} mm, vs measured {:.3} mm",
        p.table_entries, fw_ref, fw_meas
    );
    Ok(t)
}

fn fmt_list(v: &[f64]) -> String {
    v.iter()
        .map(|x| format!("{x:.2}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Seconds in a readable unit.
pub fn human_time(s: f64) -> String {
    if s < 1e-3 {
        format!("{:.1} µs", s * 1e6)
    } else if s < 1.0 {
        format!("{:.2} ms", s * 1e3)
    } else {
        format!("{s:.2} s")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scored(level: Level, shift_mm: f64, seconds: f64) -> Scored {
        Scored {
            level,
            radius_mm: POWERS_W.iter().map(|p| 45.0 - 8.0 * p + shift_mm).collect(),
            seconds,
            error_vs_reference_mm: shift_mm.abs(),
            error_vs_measured_mm: 0.1 + shift_mm.abs(),
            uncalibrated_difference_mm: 0.0,
            constants: (1.5e-5, 0.17, 2.8e-3),
        }
    }

    #[test]
    fn every_study_chart_renders_its_titles_and_series() {
        let dir = std::env::temp_dir().join(format!("morph-model-charts-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let s = [
            scored(Level::LUMPED, 0.3, 1e-5),
            scored(Level::REFERENCE, 0.0, 2.0),
        ];
        let fig9 = Fig9 {
            measured: vec![(0.1, 44.96), (0.8, 36.94), (1.5, 32.85)],
            paper_model: vec![(0.1, 45.1), (0.8, 37.0), (1.5, 32.7)],
        };
        let grid: Vec<GridRow> = [8usize, 16, 32]
            .iter()
            .map(|&n| GridRow {
                rings: n,
                cells: n * n,
                concentric_error: 1.0 / (n * n) as f64,
                r_tt: 34.2,
                link_error: 0.5 / (n * n) as f64,
                explicit_limit_s: 1e-3,
            })
            .collect();
        let transient: Vec<TransientRow> = (1..=600)
            .map(|k| {
                let t = k as f64 * 0.1;
                let r = 1.0 - (-t / 10.0).exp();
                (t, 30.0 * r, 20.0 * r, 29.0 * r, 21.0 * r)
            })
            .collect();
        let path = |n: &str| dir.join(n);
        pareto_chart(&path("p.svg"), "pareto title", &s, |x| {
            x.error_vs_reference_mm
        })
        .unwrap();
        radius_chart(&path("r.svg"), &s, &fig9, &["lumped", "fv96+cosserat"]).unwrap();
        table_chart(
            &path("t.svg"),
            &[(2, 1.0, 24), (16, 0.02, 192), (64, 1e-3, 768)],
        )
        .unwrap();
        grid_chart(&path("g.svg"), &grid).unwrap();
        transient_chart(&path("tr.svg"), &transient, 32).unwrap();
        let has = |n: &str, want: &[&str]| {
            let text = std::fs::read_to_string(path(n)).unwrap();
            for w in want {
                assert!(text.contains(w), "{n}: `{w}` missing");
            }
        };
        has(
            "p.svg",
            &[
                "pareto title",
                "Pareto front",
                "lumped",
                "run time of one 15-power curve, s",
                "fv96+cosserat: zero error",
            ],
        );
        // The zero-error reference is a vertical line, not a point at a made-up 1e-6: the
        // log axis reaches no lower than half the smallest real error (0.3 mm).
        let p = std::fs::read_to_string(path("p.svg")).unwrap();
        assert!(
            !p.contains("1e-6") && !p.contains("1.0e-6"),
            "fake zero point"
        );
        has(
            "r.svg",
            &[
                "Radius versus TCA power",
                "lumped",
                "paper&apos;s model (Fig. 9)",
                "measured (Fig. 9)",
            ],
        );
        has("t.svg", &["Firmware table: entries", "192 B", "entries"]);
        has(
            "g.svg",
            &[
                "grid convergence",
                "concentric heater vs exact",
                "link R_tt vs 96 rings",
            ],
        );
        has(
            "tr.svg",
            &[
                "Heater rises",
                "TCA, finite volumes (32 rings)",
                "PLA, lumped network",
            ],
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
