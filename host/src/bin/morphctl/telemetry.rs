//! Telemetry of a run: samples from STATUS (and, on `morph-sim`, SIM STATE), their CSV file,
//! and the plot of temperatures and powers against time (SVG with labels, PNG as curves only).

use crate::link::field;
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
}

/// The CSV header of [`Sample`] rows.
pub const CSV_HEADER: &str = "t_s,phase,t_pla_c,t_tca_c,t_amb_c,p_pla_w,p_tca_w,supply_v,radius_mm";

fn num(line: &str, key: &str) -> f64 {
    field(line, key)
        .and_then(|v| v.parse().ok())
        .unwrap_or(f64::NAN)
}

impl Sample {
    /// A sample from a STATUS reply at `t_s`, with the simulator's radius if known.
    pub fn from_status(t_s: f64, status: &str, radius_mm: f64) -> Sample {
        Sample {
            t_s,
            phase: field(status, "phase").unwrap_or_else(|| "?".into()),
            temps_c: [
                num(status, "t_pla_c"),
                num(status, "t_tca_c"),
                num(status, "t_amb_c"),
            ],
            powers_w: [num(status, "p_pla_w"), num(status, "p_tca_w")],
            supply_v: num(status, "supply_v"),
            radius_mm,
        }
    }

    /// The sample as a CSV row.
    pub fn csv_row(&self) -> String {
        format!(
            "{:.2},{},{:.2},{:.2},{:.2},{:.3},{:.3},{:.2},{:.3}",
            self.t_s,
            self.phase,
            self.temps_c[0],
            self.temps_c[1],
            self.temps_c[2],
            self.powers_w[0],
            self.powers_w[1],
            self.supply_v,
            self.radius_mm
        )
    }

    /// Parses a CSV row written by [`Sample::csv_row`].
    pub fn parse_csv(row: &str) -> Result<Sample, String> {
        let f: Vec<&str> = row.split(',').collect();
        if f.len() != 9 {
            return Err(format!("expected 9 columns, got {}: `{row}`", f.len()));
        }
        let n = |i: usize| -> Result<f64, String> {
            f[i].trim()
                .parse()
                .map_err(|_| format!("column {} is not a number: `{}`", i + 1, f[i]))
        };
        Ok(Sample {
            t_s: n(0)?,
            phase: f[1].to_string(),
            temps_c: [n(2)?, n(3)?, n(4)?],
            powers_w: [n(5)?, n(6)?],
            supply_v: n(7)?,
            radius_mm: n(8)?,
        })
    }
}

/// Reads a telemetry CSV written by `morphctl morph --log`.
pub fn read_csv(path: &Path) -> Result<Vec<Sample>, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    let mut lines = text.lines();
    if lines.next().map(str::trim) != Some(CSV_HEADER) {
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

/// Plots temperatures (top) and powers (bottom) against time into `out` (`.svg` or `.png`).
pub fn plot(samples: &[Sample], title: &str, out: &Path) -> Result<(), String> {
    if samples.is_empty() {
        return Err("nothing to plot: no samples".into());
    }
    // No font ships with the tool, so the PNG carries the curves and the phase marks only.
    Ok(plot::write(out, (1000, 700), &RunPlot { samples, title })?)
}

/// The two panels of a run.
struct RunPlot<'a> {
    samples: &'a [Sample],
    title: &'a str,
}

impl Figure for RunPlot<'_> {
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        format: Format,
    ) -> PlotResult {
        let s = self.samples;
        let text = format.has_text();
        let t_end = s.last().map(|x| x.t_s).unwrap_or(1.0).max(1.0);
        let (top, bottom) = root.split_vertically(420);
        let t_max = s
            .iter()
            .flat_map(|x| x.temps_c)
            .filter(|v| v.is_finite())
            .fold(40.0f64, f64::max)
            + 5.0;
        let p_max = s
            .iter()
            .flat_map(|x| x.powers_w)
            .filter(|v| v.is_finite())
            .fold(1.0f64, f64::max)
            * 1.1;
        let panels: [(&DrawingArea<DB, Shift>, f64, f64, &str); 2] = [
            (&top, 10.0, t_max, "temperature (°C)"),
            (&bottom, 0.0, p_max, "power (W)"),
        ];
        let colours = [TAB_RED, TAB_BLUE, RGBColor(90, 90, 90)];
        let frame = Frame::new(18, 10, 35, 55).text(text);
        for (k, (area, lo, hi, y_desc)) in panels.into_iter().enumerate() {
            let mut chart = frame
                .builder(area, (k == 0).then_some(self.title))
                .build_cartesian_2d(0f64..t_end, lo..hi)?;
            mesh(&mut chart, "time since MORPH (s)", y_desc, text).draw()?;
            let names: &[&str] = if k == 0 {
                &["PLA", "TCA", "ambient"]
            } else {
                &["PLA heater", "TCA heater"]
            };
            for (i, name) in names.iter().enumerate() {
                let pts: Vec<(f64, f64)> = s
                    .iter()
                    .map(|x| (x.t_s, if k == 0 { x.temps_c[i] } else { x.powers_w[i] }))
                    .filter(|p| p.1.is_finite())
                    .collect();
                line(
                    &mut chart,
                    pts,
                    colours[i].stroke_width(2),
                    text.then_some(*name),
                )?;
            }
            // Phase changes as thin vertical lines.
            let changes = s
                .windows(2)
                .filter(|w| w[0].phase != w[1].phase)
                .map(|w| w[1].t_s);
            marks(&mut chart, changes, lo, hi)?;
            if text {
                legend(&mut chart, SeriesLabelPosition::UpperRight)?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn samples() -> Vec<Sample> {
        let st = |phase: &str, pla: f64| {
            format!("ok phase={phase} target_mm=38.00 t_pla_c={pla} t_tca_c=40.00 t_amb_c=22.00 p_pla_w=4.000 p_tca_w=0.700 supply_v=12.00 fault=none")
        };
        vec![
            Sample::from_status(0.0, &st("soften", 22.0), 46.0),
            Sample::from_status(1.0, &st("soften", 50.0), 45.0),
            Sample::from_status(2.0, &st("bend", 72.0), 40.0),
        ]
    }

    #[test]
    fn status_replies_become_samples_and_round_trip_through_csv() {
        let s = samples();
        assert_eq!(s[2].phase, "bend");
        assert_eq!(s[2].temps_c, [72.0, 40.0, 22.0]);
        assert_eq!(s[2].powers_w, [4.0, 0.7]);
        for x in &s {
            assert_eq!(&Sample::parse_csv(&x.csv_row()).unwrap(), x);
        }
        assert!(Sample::parse_csv("1,2,3").is_err());
    }

    #[test]
    fn plots_are_written_as_svg_and_png() {
        let dir = std::env::temp_dir().join(format!("morphctl-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let svg = dir.join("run.svg");
        let png = dir.join("run.png");
        plot(&samples(), "test", &svg).unwrap();
        plot(&samples(), "test", &png).unwrap();
        let text = std::fs::read_to_string(&svg).unwrap();
        assert!(text.contains("<svg") && text.contains("TCA heater"));
        assert!(std::fs::read(&png).unwrap().starts_with(b"\x89PNG"));
        assert!(plot(&samples(), "test", &dir.join("run.txt")).is_err());
        assert!(plot(&[], "test", &svg).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
