//! The chart of several links morphing on one supply (`cargo xtask gait --plot`,
//! docs/multilink.md): above, each link's heater power and their total against the budget;
//! below, each link's true radius against its target.

use crate::plot::{self, Figure, Format, Frame, PlotResult};
use plotters::coord::Shift;
use plotters::prelude::*;

/// What the chart shows, one sample per control tick.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GaitChart {
    /// Title.
    pub title: String,
    /// Sample times, s.
    pub time_s: Vec<f64>,
    /// Each link's heater power (PLA + TCA) at each sample, W: `power_w[link][sample]`.
    pub power_w: Vec<Vec<f64>>,
    /// The summed power at each sample, W.
    pub total_w: Vec<f64>,
    /// The budget, W (`None`: no budget).
    pub budget_w: Option<f64>,
    /// Each link's true radius at each sample, mm: `radius_mm[link][sample]`.
    pub radius_mm: Vec<Vec<f64>>,
    /// Each link's target, mm.
    pub target_mm: Vec<f64>,
}

impl Figure for GaitChart {
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        format: Format,
    ) -> PlotResult {
        let (top, bottom) = root.split_vertically(root.dim_in_pixel().1 / 2);
        let frame = Frame::new(18, 10, 40, 60).text(format.has_text());
        let t_max = self.time_s.last().copied().unwrap_or(1.0).max(1.0);
        let p_max = self
            .total_w
            .iter()
            .copied()
            .chain(self.budget_w)
            .fold(1.0, f64::max)
            * 1.1;
        let mut c = frame
            .builder(&top, Some(&self.title))
            .build_cartesian_2d(0.0..t_max, 0.0..p_max)?;
        plot::mesh(
            &mut c,
            "time since the command, s",
            "heater power, W",
            frame.text,
        )
        .draw()?;
        for (k, p) in self.power_w.iter().enumerate() {
            let label = format!("link {}", k + 1);
            let pts = self.time_s.iter().copied().zip(p.iter().copied());
            plot::line(&mut c, pts, plot::palette(k).stroke_width(1), Some(&label))?;
        }
        let pts = self
            .time_s
            .iter()
            .copied()
            .zip(self.total_w.iter().copied());
        plot::line(&mut c, pts, BLACK.stroke_width(2), Some("total"))?;
        if let Some(b) = self.budget_w {
            plot::line(
                &mut c,
                [(0.0, b), (t_max, b)],
                RED.stroke_width(1),
                Some("budget"),
            )?;
        }
        if frame.text {
            plot::legend(&mut c, SeriesLabelPosition::UpperRight)?;
        }
        let all = self.radius_mm.iter().flatten().chain(&self.target_mm);
        let (lo, hi) = all.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &r| {
            (lo.min(r), hi.max(r))
        });
        let (lo, hi) = if lo.is_finite() {
            (lo - 2.0, hi + 2.0)
        } else {
            (0.0, 1.0)
        };
        let mut c = frame
            .builder(&bottom, None)
            .build_cartesian_2d(0.0..t_max, lo..hi)?;
        plot::mesh(
            &mut c,
            "time since the command, s",
            "true radius, mm",
            frame.text,
        )
        .draw()?;
        for (k, r) in self.radius_mm.iter().enumerate() {
            let pts = self.time_s.iter().copied().zip(r.iter().copied());
            plot::line(&mut c, pts, plot::palette(k).stroke_width(2), None)?;
            if let Some(&t) = self.target_mm.get(k) {
                plot::line(
                    &mut c,
                    [(0.0, t), (t_max, t)],
                    plot::palette(k).mix(0.5).stroke_width(1),
                    None,
                )?;
            }
        }
        Ok(())
    }
}
