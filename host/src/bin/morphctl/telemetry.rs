//! Telemetry of a run: samples from STATUS (and, on `morph-sim`, SIM STATE), their CSV file,
//! and the plot of a run (SVG or PNG, both with text): temperatures against their targets
//! (and the TCA's own reading of itself where the board senses current), the radius, the
//! powers and the heater currents as the steps they are, the phases named.

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
    /// Each heater's current while driven (PLA, TCA), A; NaN where not sensed.
    pub currents_a: [f64; 2],
    /// Each heater's measured resistance (PLA, TCA), Ω; NaN where not sensed.
    pub resistances_ohm: [f64; 2],
    /// The TCA's mean temperature from its own resistance, °C; NaN where not sensed.
    pub t_tca_self_c: f64,
    /// The heater supply's cut-off: true closed, false open (after an alarm); None unknown
    /// (an older device or log).
    pub cutoff_closed: Option<bool>,
}

/// The CSV header of [`Sample`] rows: the older columns first, so a reader of an older log
/// finds its columns where they were.
pub const CSV_HEADER: &str =
    "t_s,phase,t_pla_c,t_tca_c,t_amb_c,p_pla_w,p_tca_w,supply_v,radius_mm,target_mm,pla_target_c,tca_target_c,mode,i_pla_a,i_tca_a,r_pla_ohm,r_tca_ohm,t_tca_self_c,cutoff";
/// The header of files written before the current sense and the cut-off were logged; still read.
const CSV_HEADER_V2: &str =
    "t_s,phase,t_pla_c,t_tca_c,t_amb_c,p_pla_w,p_tca_w,supply_v,radius_mm,target_mm,pla_target_c,tca_target_c,mode";
/// The header of files written before the targets and the mode were logged; still read.
const CSV_HEADER_V1: &str = "t_s,phase,t_pla_c,t_tca_c,t_amb_c,p_pla_w,p_tca_w,supply_v,radius_mm";
/// Columns of a row under [`CSV_HEADER`], [`CSV_HEADER_V2`] and [`CSV_HEADER_V1`].
const CSV_COLUMNS: [usize; 3] = [19, 13, 9];

/// The cut-off as the log writes it: `closed`, `open`, or `-` when unknown.
fn cutoff_word(closed: Option<bool>) -> &'static str {
    match closed {
        Some(true) => "closed",
        Some(false) => "open",
        None => "-",
    }
}

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
            currents_a: s.map_or([f64::NAN; 2], |s| s.currents_a.map(f)),
            resistances_ohm: s.map_or([f64::NAN; 2], |s| s.resistances_ohm.map(f)),
            t_tca_self_c: f(s.and_then(|s| s.t_tca_self_c)),
            cutoff_closed: s.and_then(|s| s.cutoff_closed),
        }
    }

    /// The sample as a CSV row.
    pub fn csv_row(&self) -> String {
        format!(
            "{:.2},{},{:.2},{:.2},{:.2},{:.3},{:.3},{:.2},{:.3},{:.2},{:.2},{:.2},{},{:.3},{:.3},{:.2},{:.2},{:.2},{}",
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
            self.mode,
            self.currents_a[0],
            self.currents_a[1],
            self.resistances_ohm[0],
            self.resistances_ohm[1],
            self.t_tca_self_c,
            cutoff_word(self.cutoff_closed)
        )
    }

    /// Parses a CSV row written by [`Sample::csv_row`] (19 columns), or by an older morphctl
    /// (13 columns: no current sense, cut-off unknown; 9: no targets either, mode unknown).
    pub fn parse_csv(row: &str) -> Result<Sample, String> {
        let f: Vec<&str> = row.split(',').collect();
        if !CSV_COLUMNS.contains(&f.len()) {
            return Err(format!(
                "expected {} columns (or {} or {} from an older morphctl), got {}: `{row}`",
                CSV_COLUMNS[0],
                CSV_COLUMNS[1],
                CSV_COLUMNS[2],
                f.len()
            ));
        }
        let n = |i: usize| -> Result<f64, String> {
            f[i].trim()
                .parse()
                .map_err(|_| format!("column {} is not a number: `{}`", i + 1, f[i]))
        };
        let old = f.len() == CSV_COLUMNS[2];
        let sensed = f.len() == CSV_COLUMNS[0];
        // A current-sense column of a row that has them; NaN in an older row.
        let sensed_n = |i: usize| if sensed { n(i) } else { Ok(f64::NAN) };
        let cutoff_closed = match f.get(18).map(|w| w.trim()) {
            Some("closed") => Some(true),
            Some("open") => Some(false),
            Some("-") | None => None,
            Some(w) => return Err(format!("column 19 is not `closed`, `open` or `-`: `{w}`")),
        };
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
            currents_a: [sensed_n(13)?, sensed_n(14)?],
            resistances_ohm: [sensed_n(15)?, sensed_n(16)?],
            t_tca_self_c: sensed_n(17)?,
            cutoff_closed,
        })
    }
}

/// Reads a telemetry CSV written by `morphctl morph --log`.
pub fn read_csv(path: &Path) -> Result<Vec<Sample>, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    let mut lines = text.lines();
    let header = lines.next().map(str::trim);
    if ![CSV_HEADER, CSV_HEADER_V2, CSV_HEADER_V1]
        .iter()
        .any(|h| header == Some(*h))
    {
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

/// Plot size, px: up to three panels one above the other, readable when shared at full size.
const PLOT_SIZE_PX: (u32, u32) = (1100, 900);
/// Extra height for a fourth panel (the heater currents), px: it keeps the panels as tall as
/// three are.
const FOURTH_PANEL_PX: u32 = 290;
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
/// and the TCA's own reading where sensed (top), the radius (when known), the powers as steps,
/// the heater currents as steps (bottom, where sensed), the phases named.
pub fn plot(samples: &[Sample], title: &str, out: &Path) -> Result<(), String> {
    plot::Format::of(out)?;
    if samples.is_empty() {
        return Err("nothing to plot: no samples".into());
    }
    let (w, mut h) = PLOT_SIZE_PX;
    if has_radius(samples) && has_currents(samples) {
        h += FOURTH_PANEL_PX;
    }
    Ok(plot::write(out, (w, h), &RunPlot { samples, title })?)
}

/// True if the run knows the true radius (a simulator).
fn has_radius(samples: &[Sample]) -> bool {
    samples.iter().any(|x| x.radius_mm.is_finite())
}

/// True if the run's device senses the heater currents.
fn has_currents(samples: &[Sample]) -> bool {
    samples
        .iter()
        .any(|x| x.currents_a.iter().any(|i| i.is_finite()))
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
        let has_radius = has_radius(s);
        let has_currents = has_currents(s);
        let title_px = 30;
        let (head, body) = root.split_vertically(title_px);
        head.titled(self.title, (FONT, 22))?;
        let panels = 2 + usize::from(has_radius) + usize::from(has_currents);
        let areas = body.split_evenly((panels, 1));
        let frame = Frame::new(16, 10, 40, 60);
        let marks = phase_marks(s);
        let rows = label_rows(&marks, t0, t_end);
        // Foot room for the rows of phase names.
        let rise = MARK_TEXT_RISE * (rows.iter().max().map_or(0, |r| r + 1)).max(1) as f64;
        let time = "time since MORPH (s)";
        let colours = [TAB_RED, TAB_BLUE, RGBColor(90, 90, 90)];

        // Temperatures and their targets.
        let (lo, hi) = span(
            s.iter().flat_map(|x| {
                x.temps_c
                    .into_iter()
                    .chain(x.targets_c)
                    .chain([x.t_tca_self_c])
            }),
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
            if i == 1 {
                // Beside the TCA's bead, the TCA's mean from its resistance: where the two
                // part, the bead reads only a share of the actuator's rise.
                let own = runs(s, |x| x.t_tca_self_c);
                for (k, run) in own.into_iter().enumerate() {
                    let label = (k == 0).then_some("TCA (own resistance)");
                    line(&mut chart, run, TAB_PURPLE.stroke_width(2), label)?;
                }
            }
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
        let power_area = &areas[1 + usize::from(has_radius)];
        let held = HeldPanel {
            axis: "power (W)",
            floor: 0.5,
            value: |x: &Sample, i: usize| x.powers_w[i],
        };
        held.draw(power_area, &frame, s, (t0, t_end), &marks, &rows)?;
        // The currents the board measured, held between polls as the powers are.
        if has_currents {
            let held = HeldPanel {
                axis: "heater current (A)",
                floor: 0.1,
                value: |x: &Sample, i: usize| x.currents_a[i],
            };
            held.draw(
                areas.last().expect("four panels"),
                &frame,
                s,
                (t0, t_end),
                &marks,
                &rows,
            )?;
        }
        Ok(())
    }
}

/// A panel of the two heaters' values held between polls (drawn as steps) against time.
struct HeldPanel<F> {
    /// The y axis's description, with its unit.
    axis: &'static str,
    /// The least top of the y axis, in its unit: a run at zero still has an axis.
    floor: f64,
    /// The PLA's (0) or the TCA's (1) value of a sample, in the axis's unit.
    value: F,
}

impl<F: Fn(&Sample, usize) -> f64> HeldPanel<F> {
    /// Draws the panel into `area` over `t_s` (from, to), the phases named.
    fn draw<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        frame: &Frame,
        s: &[Sample],
        t_s: (f64, f64),
        marks: &[(f64, String)],
        rows: &[usize],
    ) -> PlotResult {
        let colours = [TAB_RED, TAB_BLUE];
        let values = s
            .iter()
            .flat_map(|x| [(self.value)(x, 0), (self.value)(x, 1)]);
        let (_, hi) = span(values, 0.0, (0.0, 1.0));
        let hi = hi.max(self.floor) * (1.0 + LEGEND_ROOM);
        let mut chart = frame
            .builder(area, None)
            .build_cartesian_2d(t_s.0..t_s.1, 0.0..hi)?;
        mesh(&mut chart, "time since MORPH (s)", self.axis, true).draw()?;
        for (i, name) in ["PLA heater", "TCA heater"].iter().enumerate() {
            line(
                &mut chart,
                steps(s, |x| (self.value)(x, i)),
                colours[i].stroke_width(2),
                Some(name),
            )?;
        }
        named_marks(&mut chart, marks, rows, 0.0, hi)?;
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

    /// The current sense of a board that has it, and its cut-off closed.
    const SENSED: &str = "i_pla_a=0.409 i_tca_a=1.773 r_pla_ohm=29.51 r_tca_ohm=6.75 t_tca_self_c=41.32 cutoff=closed";

    /// A morph on a board without current sense (the fields of a device before it).
    fn unsensed() -> Vec<Sample> {
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

    /// The same morph on a board that senses current.
    fn samples() -> Vec<Sample> {
        unsensed()
            .iter()
            .map(|x| {
                let pla_target = if x.targets_c[0].is_finite() {
                    "75.00"
                } else {
                    "-"
                };
                let fields =
                    format!("pla_target_c={pla_target} tca_target_c=57.50 mode=closed {SENSED}");
                let line = st(&x.phase, x.temps_c[0], x.powers_w[0], &fields);
                Sample::from_status(x.t_s, &line, x.radius_mm)
            })
            .collect()
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
        // The current sense and the cut-off, as STATUS gave them, in the last six columns.
        assert_eq!(s[2].currents_a, [0.409, 1.773]);
        assert_eq!(s[2].resistances_ohm, [29.51, 6.75]);
        assert_eq!(s[2].t_tca_self_c, 41.32);
        assert_eq!(s[2].cutoff_closed, Some(true));
        assert!(s[2]
            .csv_row()
            .ends_with(",closed,0.409,1.773,29.51,6.75,41.32,closed"));
        assert!(back.cutoff_closed == Some(true) && back.currents_a == [0.409, 1.773]);
        assert_eq!(
            s[3].csv_row().split(',').count(),
            CSV_HEADER.split(',').count()
        );
        // A board without current sense: NaN where it has no value, the cut-off still read.
        let bare = "i_pla_a=- i_tca_a=- r_pla_ohm=- r_tca_ohm=- t_tca_self_c=- cutoff=open";
        let b = Sample::from_status(0.0, &st("fault", 22.0, 0.0, bare), f64::NAN);
        assert!(b
            .currents_a
            .iter()
            .chain(&b.resistances_ohm)
            .all(|v| v.is_nan()));
        assert!(b.t_tca_self_c.is_nan() && b.cutoff_closed == Some(false));
        let back = Sample::parse_csv(&b.csv_row()).unwrap();
        assert!(back.currents_a[0].is_nan() && back.cutoff_closed == Some(false));
        // A row from before the current sense: read, the new values unknown.
        let v2 = Sample::parse_csv(
            "1.00,bend,72.00,40.00,22.00,4.000,0.700,12.00,40.000,38.00,75.00,57.50,closed",
        )
        .unwrap();
        assert_eq!((v2.targets_c, v2.mode.as_str()), ([75.0, 57.5], "closed"));
        assert!(v2
            .currents_a
            .iter()
            .chain(&v2.resistances_ohm)
            .all(|v| v.is_nan()));
        assert!(v2.t_tca_self_c.is_nan() && v2.cutoff_closed.is_none());
        // A row from before the targets: read, targets unknown.
        let old =
            Sample::parse_csv("1.00,bend,72.00,40.00,22.00,4.000,0.700,12.00,40.000").unwrap();
        assert!(old.targets_c.iter().all(|t| t.is_nan()) && old.mode == "-");
        assert!(old.currents_a[0].is_nan() && old.cutoff_closed.is_none());
        assert!(Sample::parse_csv("1,2,3").is_err());
        let bad = s[2].csv_row().replace(",closed,0.409", ",closed,x");
        assert!(Sample::parse_csv(&bad).unwrap_err().contains("column 14"));
        let bad = s[2].csv_row().replace("41.32,closed", "41.32,ajar");
        assert!(Sample::parse_csv(&bad).unwrap_err().contains("column 19"));
        // A STATUS of a device without the new fields: NaN targets, mode and sense unknown.
        let s = Sample::from_status(0.0, &st("bend", 70.0, 1.0, ""), f64::NAN);
        assert!(s.targets_c.iter().all(|t| t.is_nan()) && s.mode == "-");
        assert!(s.currents_a[1].is_nan() && s.t_tca_self_c.is_nan() && s.cutoff_closed.is_none());
    }

    #[test]
    fn logs_of_every_older_morphctl_are_read() {
        let dir = std::env::temp_dir().join(format!("morphctl-csv-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let row = samples()[2].csv_row();
        let cols: Vec<&str> = row.split(',').collect();
        for (header, n) in [(CSV_HEADER, 19), (CSV_HEADER_V2, 13), (CSV_HEADER_V1, 9)] {
            let path = dir.join(format!("v{n}.csv"));
            let text = format!("{header}\n{}\n", cols[..n].join(","));
            std::fs::write(&path, text).unwrap();
            let read = read_csv(&path).unwrap();
            assert_eq!(read.len(), 1, "{header}");
            assert_eq!(read[0].temps_c, [72.0, 40.0, 22.0], "{header}");
            assert_eq!(read[0].currents_a[0].is_finite(), n == 19, "{header}");
        }
        let path = dir.join("other.csv");
        std::fs::write(&path, "a,b\n1,2\n").unwrap();
        assert!(read_csv(&path)
            .unwrap_err()
            .contains("not a morphctl telemetry file"));
        std::fs::remove_dir_all(&dir).unwrap();
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
            "TCA (own resistance)",
            "heater current (A)",
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
        let text = std::fs::read_to_string(&svg).unwrap();
        assert!(!text.contains("radius (mm)"));
        assert!(text.contains("heater current (A)") && text.contains("TCA (own resistance)"));
        // Without current sense (a board without it, an older log): the plot of before.
        plot(&unsensed(), "older", &svg).unwrap();
        let text = std::fs::read_to_string(&svg).unwrap();
        for gone in ["TCA (own resistance)", "heater current (A)"] {
            assert!(!text.contains(gone), "{gone} drawn without current sense");
        }
        assert!(text.contains("radius (mm)") && text.contains("power (W)"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
