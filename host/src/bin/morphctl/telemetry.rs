//! Telemetry of a run: samples from STATUS (and, on `morph-sim`, SIM STATE), their CSV file,
//! and the plot of a run (SVG or PNG, both with text): temperatures against their targets,
//! the radius, the powers as the steps they are, the phases named.

use morphlink::protocol::client::Status;
use morphlink_host::plot::{self, prelude::*};
use std::path::Path;

/// One telemetry sample.
#[derive(Clone, Debug, PartialEq)]
pub struct Sample {
    /// Time since MORPH, s (the simulator's clock on `morph-sim`, the host's on a board).
    pub t_s: f64,
    /// Phase name.
    pub phase: String,
    /// PLA, TCA and ambient thermistors, °C.
    pub temps_c: [f64; 3],
    /// Commanded PLA and TCA powers, W.
    pub powers_w: [f64; 2],
    /// Measured supply, V.
    pub supply_v: f64,
    /// True radius (simulator only), mm; NaN on a board.
    pub radius_mm: f64,
    /// Target radius of the morph, mm; NaN when none.
    pub target_mm: f64,
    /// The PLA and TCA heaters' target temperatures, °C; NaN where there is none.
    pub targets_c: [f64; 2],
    /// The strategy that ran, as STATUS names it (`-` if unknown).
    pub mode: String,
}

/// The CSV header of [`Sample`] rows.
pub const CSV_HEADER: &str =
    "t_s,phase,t_pla_c,t_tca_c,t_amb_c,p_pla_w,p_tca_w,supply_v,radius_mm,target_mm,pla_target_c,tca_target_c,mode";
/// The header of files written before the targets and the mode were logged; still read.
const CSV_HEADER_V1: &str = "t_s,phase,t_pla_c,t_tca_c,t_amb_c,p_pla_w,p_tca_w,supply_v,radius_mm";

/// A parsed field as f64, NaN if absent; through its shortest decimal text, so `0.7` stays
/// 0.7 and does not become 0.699999988 (the wire carries decimals, not binary f32).
fn f(v: Option<f32>) -> f64 {
    v.and_then(|v| v.to_string().parse().ok())
        .unwrap_or(f64::NAN)
}

impl Sample {
    /// A sample from a STATUS reply at `t_s`, with the simulator's radius if known (NaN
    /// otherwise); fields the reply lacks are NaN.
    pub fn from_status(t_s: f64, status: &str, radius_mm: f64) -> Sample {
        let s = Status::parse(status);
        Sample {
            t_s,
            phase: s.map_or("?", |s| s.phase).to_string(),
            temps_c: s.map_or([f64::NAN; 3], |s| s.temps_c.map(f)),
            powers_w: s.map_or([f64::NAN; 2], |s| s.powers_w.map(f)),
            supply_v: f(s.and_then(|s| s.supply_v)),
            radius_mm,
            target_mm: f(s.and_then(|s| s.target_mm)),
            targets_c: s.map_or([f64::NAN; 2], |s| s.targets_c.map(f)),
            mode: s.and_then(|s| s.mode).unwrap_or("-").to_string(),
        }
    }

    /// The sample as a CSV row.
    pub fn csv_row(&self) -> String {
        format!(
            "{:.2},{},{:.2},{:.2},{:.2},{:.3},{:.3},{:.2},{:.3},{:.2},{:.2},{:.2},{}",
            self.t_s,
            self.phase,
            self.temps_c[0],
            self.temps_c[1],
            self.temps_c[2],
            self.powers_w[0],
            self.powers_w[1],
            self.supply_v,
            self.radius_mm,
            self.target_mm,
            self.targets_c[0],
            self.targets_c[1],
            self.mode
        )
    }

    /// Parses a CSV row written by [`Sample::csv_row`] (13 columns), or by an older morphctl
    /// (9 columns: no targets, mode unknown).
    pub fn parse_csv(row: &str) -> Result<Sample, String> {
        let f: Vec<&str> = row.split(',').collect();
        if f.len() != 13 && f.len() != 9 {
            return Err(format!("expected 13 columns, got {}: `{row}`", f.len()));
        }
        let n = |i: usize| -> Result<f64, String> {
            f[i].trim()
                .parse()
                .map_err(|_| format!("column {} is not a number: `{}`", i + 1, f[i]))
        };
        let old = f.len() == 9;
        Ok(Sample {
            t_s: n(0)?,
            phase: f[1].to_string(),
            temps_c: [n(2)?, n(3)?, n(4)?],
            powers_w: [n(5)?, n(6)?],
            supply_v: n(7)?,
            radius_mm: n(8)?,
            target_mm: if old { f64::NAN } else { n(9)? },
            targets_c: if old { [f64::NAN; 2] } else { [n(10)?, n(11)?] },
            mode: if old {
                "-".into()
            } else {
                f[12].trim().to_string()
            },
        })
    }
}

/// Reads a telemetry CSV written by `morphctl morph --log`.
pub fn read_csv(path: &Path) -> Result<Vec<Sample>, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    let mut lines = text.lines();
    let header = lines.next().map(str::trim);
    if header != Some(CSV_HEADER) && header != Some(CSV_HEADER_V1) {
        return Err(format!(
            "{} is not a morphctl telemetry file (header must be `{CSV_HEADER}`)",
            path.display()
        ));
    }
    lines
        .filter(|l| !l.trim().is_empty())
        .enumerate()
        .map(|(i, l)| {
            Sample::parse_csv(l).map_err(|e| format!("{} line {}: {e}", path.display(), i + 2))
        })
        .collect()
}

/// The plot's title: the line sent, the strategy that ran (from STATUS) and the device.
pub fn title(radius_mm: f32, asked_mode: &str, samples: &[Sample], device: &str) -> String {
    let ran = samples
        .iter()
        .rev()
        .map(|s| s.mode.as_str())
        .find(|m| *m != "-");
    match ran {
        Some(m) if m != asked_mode => {
            format!("MORPH {radius_mm} {asked_mode}: {m} ran, on {device}")
        }
        Some(m) => format!("MORPH {radius_mm}: {m} ran, on {device}"),
        None => format!("MORPH {radius_mm} {asked_mode} on {device} (mode not reported)"),
    }
}

/// Plot size, px: three panels one above the other, readable when shared at full size.
const PLOT_SIZE_PX: (u32, u32) = (1100, 900);
/// Height of a phase name above the panel's foot, a fraction of the panel's span (the
/// text hangs down from it); each further row of names is as much higher.
const MARK_TEXT_RISE: f64 = 0.08;
/// Width of the plotting area, px, about: the plot's width less the y labels and margins.
const PLOT_AREA_PX: f64 = 1000.0;
/// Width of one character of a phase name, px (13 px DejaVu Sans, a little over its mean).
const MARK_CHAR_PX: f64 = 8.0;

/// The row of each phase name (0 at the foot): a name that would run into an earlier one in
/// its row goes up a row (`soften` then `bend` 0.4 s later on a 35 s plot read `softbend`).
pub fn label_rows(marks: &[(f64, String)], t0: f64, t_end: f64) -> Vec<usize> {
    let per_s = PLOT_AREA_PX / (t_end - t0).max(1e-9);
    // Where each row is free again, px.
    let mut free: Vec<f64> = Vec::new();
    marks
        .iter()
        .map(|(t, name)| {
            let x = (t - t0) * per_s;
            let end = x + (name.chars().count() + 1) as f64 * MARK_CHAR_PX;
            let row = free.iter().position(|&f| f <= x).unwrap_or(free.len());
            if row == free.len() {
                free.push(end);
            } else {
                free[row] = end;
            }
            row
        })
        .collect()
}
/// Room above the curves of the temperature and power panels, a fraction of their span: the
/// legend sits there instead of over the data.
const LEGEND_ROOM: f64 = 0.35;

/// Plots a run into `out` (`.svg` or `.png`, checked first): temperatures with their targets
/// (top), the radius (middle, when known), the powers as steps (bottom), the phases named.
pub fn plot(samples: &[Sample], title: &str, out: &Path) -> Result<(), String> {
    plot::Format::of(out)?;
    if samples.is_empty() {
        return Err("nothing to plot: no samples".into());
    }
    Ok(plot::write(out, PLOT_SIZE_PX, &RunPlot { samples, title })?)
}

/// The panels of a run.
struct RunPlot<'a> {
    samples: &'a [Sample],
    title: &'a str,
}

/// The points of a value held from one sample until the next: a step at each sample time.
pub fn steps(samples: &[Sample], value: impl Fn(&Sample) -> f64) -> Vec<(f64, f64)> {
    steps_of(&runs(samples, value).concat())
}

/// Runs of finite values as separate polylines (a target that comes and goes is not joined
/// across the phases without one).
fn runs(samples: &[Sample], value: impl Fn(&Sample) -> f64) -> Vec<Vec<(f64, f64)>> {
    let mut out: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut open = false;
    for s in samples {
        let v = value(s);
        if v.is_finite() {
            if !open {
                out.push(Vec::new());
                open = true;
            }
            out.last_mut().expect("pushed").push((s.t_s, v));
        } else if open {
            // Held until this sample, where it ended.
            let run = out.last_mut().expect("open");
            let last = run.last().expect("open runs are not empty").1;
            run.push((s.t_s, last));
            open = false;
        }
    }
    out
}

/// Phase changes: (time, name of the phase entered), the first sample's phase at its time.
pub fn phase_marks(samples: &[Sample]) -> Vec<(f64, String)> {
    let mut marks: Vec<(f64, String)> = samples
        .first()
        .map(|s| (s.t_s, s.phase.clone()))
        .into_iter()
        .collect();
    marks.extend(
        samples
            .windows(2)
            .filter(|w| w[0].phase != w[1].phase)
            .map(|w| (w[1].t_s, w[1].phase.clone())),
    );
    marks
}

/// The range of the finite values, padded by `pad` each side; `fallback` when there are none.
fn span(values: impl Iterator<Item = f64>, pad: f64, fallback: (f64, f64)) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if lo.is_finite() {
        (lo - pad, hi + pad)
    } else {
        fallback
    }
}

impl Figure for RunPlot<'_> {
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        _format: Format,
    ) -> PlotResult {
        let s = self.samples;
        let t0 = s.first().map_or(0.0, |x| x.t_s).min(0.0);
        // A little room after the last sample for the name of the phase it ended in.
        let t_end = s.last().map_or(1.0, |x| x.t_s).max(t0 + 1.0) * 1.04;
        let has_radius = s.iter().any(|x| x.radius_mm.is_finite());
        let title_px = 30;
        let (head, body) = root.split_vertically(title_px);
        head.titled(self.title, (FONT, 22))?;
        let areas = if has_radius {
            body.split_evenly((3, 1))
        } else {
            body.split_evenly((2, 1))
        };
        let frame = Frame::new(16, 10, 40, 60);
        let marks = phase_marks(s);
        let rows = label_rows(&marks, t0, t_end);
        // Foot room for the rows of phase names.
        let rise = MARK_TEXT_RISE * (rows.iter().max().map_or(0, |r| r + 1)).max(1) as f64;
        let time = "time since MORPH (s)";
        let colours = [TAB_RED, TAB_BLUE, RGBColor(90, 90, 90)];

        // Temperatures and their targets.
        let (lo, hi) = span(
            s.iter()
                .flat_map(|x| x.temps_c.into_iter().chain(x.targets_c)),
            5.0,
            (10.0, 100.0),
        );
        // Head room for the legend above the curves, foot room for the phase names.
        let (lo, hi) = (lo - (hi - lo) * rise, hi + (hi - lo) * LEGEND_ROOM);
        let mut chart = frame
            .builder(&areas[0], None)
            .build_cartesian_2d(t0..t_end, lo..hi)?;
        mesh(&mut chart, time, "temperature (°C)", true).draw()?;
        for (i, name) in ["PLA", "TCA", "ambient"].iter().enumerate() {
            let pts = runs(s, |x| x.temps_c[i]).concat();
            line(&mut chart, pts, colours[i].stroke_width(2), Some(name))?;
        }
        for (i, name) in ["PLA target", "TCA target"].iter().enumerate() {
            let style = colours[i].mix(0.45).stroke_width(2);
            for (k, run) in runs(s, |x| x.targets_c[i]).into_iter().enumerate() {
                let pts = steps_of(&run);
                line(&mut chart, pts, style, (k == 0).then_some(*name))?;
            }
        }
        named_marks(&mut chart, &marks, &rows, lo, hi)?;
        legend(&mut chart, SeriesLabelPosition::UpperRight)?;

        // The radius (simulator truth) and the target.
        if has_radius {
            let target = s.iter().map(|x| x.target_mm).find(|r| r.is_finite());
            let (lo, hi) = span(
                s.iter().map(|x| x.radius_mm).chain(target),
                1.0,
                (30.0, 50.0),
            );
            let lo = lo - (hi - lo) * rise;
            let mut chart = frame
                .builder(&areas[1], None)
                .build_cartesian_2d(t0..t_end, lo..hi)?;
            mesh(&mut chart, time, "radius (mm)", true).draw()?;
            let pts = runs(s, |x| x.radius_mm).concat();
            line(
                &mut chart,
                pts,
                TAB_GREEN.stroke_width(2),
                Some("radius (simulated truth)"),
            )?;
            if let Some(r) = target {
                line(
                    &mut chart,
                    [(t0, r), (t_end, r)],
                    BLACK.mix(0.6).stroke_width(1),
                    Some("target radius"),
                )?;
            }
            named_marks(&mut chart, &marks, &rows, lo, hi)?;
            legend(&mut chart, SeriesLabelPosition::UpperRight)?;
        }

        // Powers, held between polls.
        let (_, p_hi) = span(s.iter().flat_map(|x| x.powers_w), 0.0, (0.0, 1.0));
        let p_hi = p_hi.max(0.5) * (1.0 + LEGEND_ROOM);
        let mut chart = frame
            .builder(areas.last().expect("two or three panels"), None)
            .build_cartesian_2d(t0..t_end, 0.0..p_hi)?;
        mesh(&mut chart, time, "power (W)", true).draw()?;
        for (i, name) in ["PLA heater", "TCA heater"].iter().enumerate() {
            line(
                &mut chart,
                steps(s, |x| x.powers_w[i]),
                colours[i].stroke_width(2),
                Some(name),
            )?;
        }
        named_marks(&mut chart, &marks, &rows, 0.0, p_hi)?;
        legend(&mut chart, SeriesLabelPosition::UpperRight)?;
        Ok(())
    }
}

/// A polyline of held values drawn as steps.
fn steps_of(run: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut pts = Vec::with_capacity(run.len() * 2);
    for &(t, v) in run {
        if let Some(&(_, prev)) = pts.last() {
            pts.push((t, prev));
        }
        pts.push((t, v));
    }
    pts
}

/// Phase marks as thin vertical lines, each with its phase's name at the top.
fn named_marks<DB, CT>(
    chart: &mut ChartContext<'_, DB, CT>,
    marks: &[(f64, String)],
    rows: &[usize],
    lo: f64,
    hi: f64,
) -> PlotResult
where
    DB: DrawingBackend,
    CT: plotters::coord::CoordTranslate<From = (f64, f64)>,
{
    plot::marks(chart, marks.iter().map(|m| m.0), lo, hi)?;
    // At the foot of the panel, clear of the legend at the top right.
    for ((t, name), row) in marks.iter().zip(rows) {
        let y = lo + (hi - lo) * MARK_TEXT_RISE * (row + 1) as f64;
        chart.draw_series(std::iter::once(Text::new(
            format!(" {name}"),
            (*t, y),
            (FONT, 13).into_font().color(&BLACK.mix(0.7)),
        )))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn st(phase: &str, pla: f64, p_pla: f64, targets: &str) -> String {
        format!("ok phase={phase} target_mm=38.00 t_pla_c={pla} t_tca_c=40.00 t_amb_c=22.00 p_pla_w={p_pla} p_tca_w=0.700 supply_v=12.00 fault=none {targets}")
    }

    fn samples() -> Vec<Sample> {
        let t = "pla_target_c=75.00 tca_target_c=57.50 mode=closed";
        vec![
            Sample::from_status(0.0, &st("soften", 22.0, 5.0, t), 46.0),
            Sample::from_status(1.0, &st("soften", 50.0, 4.0, t), 45.0),
            Sample::from_status(2.0, &st("bend", 72.0, 2.0, t), 40.0),
            Sample::from_status(
                3.0,
                &st(
                    "lock",
                    70.0,
                    0.0,
                    "pla_target_c=- tca_target_c=57.50 mode=closed",
                ),
                38.0,
            ),
        ]
    }

    #[test]
    fn status_replies_become_samples_and_round_trip_through_csv() {
        let s = samples();
        assert_eq!(s[2].phase, "bend");
        assert_eq!(s[2].temps_c, [72.0, 40.0, 22.0]);
        assert_eq!(s[2].powers_w, [2.0, 0.7]);
        assert_eq!(s[2].target_mm, 38.0);
        assert_eq!(s[2].targets_c, [75.0, 57.5]);
        assert_eq!(s[2].mode, "closed");
        assert!(s[3].targets_c[0].is_nan());
        for x in &s[..3] {
            assert_eq!(&Sample::parse_csv(&x.csv_row()).unwrap(), x);
        }
        let back = Sample::parse_csv(&s[3].csv_row()).unwrap();
        assert!(back.targets_c[0].is_nan() && back.targets_c[1] == 57.5);
        // A row from before the targets: read, targets unknown.
        let old =
            Sample::parse_csv("1.00,bend,72.00,40.00,22.00,4.000,0.700,12.00,40.000").unwrap();
        assert!(old.targets_c.iter().all(|t| t.is_nan()) && old.mode == "-");
        assert!(Sample::parse_csv("1,2,3").is_err());
        // A STATUS of a device without the new fields: NaN targets, mode unknown.
        let s = Sample::from_status(0.0, &st("bend", 70.0, 1.0, ""), f64::NAN);
        assert!(s.targets_c.iter().all(|t| t.is_nan()) && s.mode == "-");
    }

    #[test]
    fn powers_are_held_between_polls_as_steps() {
        let p = steps(&samples(), |x| x.powers_w[0]);
        assert_eq!(
            p,
            [
                (0.0, 5.0),
                (1.0, 5.0),
                (1.0, 4.0),
                (2.0, 4.0),
                (2.0, 2.0),
                (3.0, 2.0),
                (3.0, 0.0)
            ]
        );
    }

    #[test]
    fn phases_are_named_where_they_begin() {
        let m = phase_marks(&samples());
        let names: Vec<(f64, &str)> = m.iter().map(|(t, n)| (*t, n.as_str())).collect();
        assert_eq!(names, [(0.0, "soften"), (2.0, "bend"), (3.0, "lock")]);
    }

    #[test]
    fn phase_names_close_together_go_up_a_row_instead_of_overlapping() {
        let marks: Vec<(f64, String)> = [
            (0.0, "soften"),
            (0.4, "bend"),
            (12.0, "lock"),
            (34.0, "idle"),
        ]
        .iter()
        .map(|(t, n)| (*t, n.to_string()))
        .collect();
        assert_eq!(label_rows(&marks, 0.0, 36.4), [0, 1, 0, 0]);
        // Far apart, one row.
        assert_eq!(label_rows(&marks[..1], 0.0, 36.4), [0]);
        let spread: Vec<(f64, String)> = marks
            .iter()
            .enumerate()
            .map(|(i, (_, n))| (i as f64 * 10.0, n.clone()))
            .collect();
        assert_eq!(label_rows(&spread, 0.0, 36.4), [0, 0, 0, 0]);
    }

    #[test]
    fn the_title_names_the_strategy_that_ran() {
        let s = samples();
        assert_eq!(
            title(38.0, "auto", &s, "morph-sim"),
            "MORPH 38 auto: closed ran, on morph-sim"
        );
        assert_eq!(
            title(38.0, "closed", &s, "morph-sim"),
            "MORPH 38: closed ran, on morph-sim"
        );
        let old = vec![Sample::from_status(
            0.0,
            &st("bend", 70.0, 1.0, ""),
            f64::NAN,
        )];
        assert!(title(38.0, "auto", &old, "b").contains("mode not reported"));
    }

    #[test]
    fn plots_carry_text_targets_radius_and_named_phases_and_bad_names_are_refused() {
        let dir = std::env::temp_dir().join(format!("morphctl-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let svg = dir.join("run.svg");
        let png = dir.join("run.png");
        plot(&samples(), "MORPH 38 auto: closed ran", &svg).unwrap();
        plot(&samples(), "test", &png).unwrap();
        let text = std::fs::read_to_string(&svg).unwrap();
        for want in [
            "MORPH 38 auto: closed ran",
            "TCA heater",
            "PLA target",
            "TCA target",
            "radius (mm)",
            "target radius",
            "temperature (°C)",
            "power (W)",
            "soften",
            "bend",
            "lock",
        ] {
            assert!(text.contains(want), "{want} missing from the SVG");
        }
        assert!(std::fs::read(&png).unwrap().starts_with(b"\x89PNG"));
        let e = plot(&samples(), "test", &dir.join("run.jpg")).unwrap_err();
        assert!(e.contains("must end in .svg or .png"), "{e}");
        assert!(!dir.join("run.jpg").exists());
        assert!(plot(&[], "test", &svg).is_err());
        // A board: no radius panel.
        let mut board = samples();
        board.iter_mut().for_each(|s| s.radius_mm = f64::NAN);
        plot(&board, "board", &svg).unwrap();
        assert!(!std::fs::read_to_string(&svg)
            .unwrap()
            .contains("radius (mm)"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
