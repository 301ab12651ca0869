//! `cargo xtask strategies`: every morph strategy over an ensemble of links that differ from the
//! controller's model, measured the same way; writes `docs/strategies.csv` (one row per run), the
//! chart of morph time against radius error with the Pareto front (`docs/strategies_pareto.svg`)
//! and a time plot of one nominal morph per strategy (`docs/strategies_timeline.svg`), and
//! prints the summary table of `docs/strategies.md`.

use indicatif::{ProgressBar, ProgressStyle};
use morphlink::protocol::Mode;
use morphlink::strategy::AUTO_STRATEGY;
use morphlink::table;
use morphlink_host::plot::{self, prelude::*};
use morphlink_sim::ensemble::{
    run_morph, run_morph_traced, Mismatch, Outcome, RunResult, TracePoint,
};
use std::fmt::Write as _;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// Strategies compared (`auto` is one of them, chosen from this comparison).
pub const STRATEGIES: [Mode; 4] = [Mode::Paper, Mode::Gated, Mode::Boost, Mode::Closed];
/// Mismatched links drawn by default: 250 links × 5 radii × 4 strategies = 5000 morphs, under
/// half a minute on two cores (each morph is simulated in milliseconds); `--draws 2000` for
/// a tighter 95th percentile.
pub const DEFAULT_DRAWS: u64 = 250;
/// Target radii per link, spread over the reachable range 0.2 mm inside its ends.
pub const DEFAULT_TARGETS: usize = 5;
/// Seed of the ensemble (the CSV records every drawn mismatch, so any run can be replayed).
pub const DEFAULT_SEED: u64 = 20_261_122;
/// The morph time aimed at (four times faster than the paper), s.
pub const AIM_TIME_S: f64 = 30.0;
/// The 95th-percentile radius error aimed at, %.
pub const AIM_ERROR_PCT: f64 = 2.0;
/// Radius of the nominal time-plot morphs, mm (the README's example).
pub const TIMELINE_TARGET_MM: f32 = 38.0;

/// Options of the task.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Mismatched links to draw.
    #[arg(long, default_value_t = DEFAULT_DRAWS)]
    pub draws: u64,
    /// Target radii per link.
    #[arg(long, default_value_t = DEFAULT_TARGETS)]
    pub targets: usize,
    /// Seed of the mismatch draws.
    #[arg(long, default_value_t = DEFAULT_SEED)]
    pub seed: u64,
    /// Worker threads.
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// Output directory, relative to the workspace root.
    #[arg(long, default_value = "docs")]
    pub out: String,
}

struct Row {
    strategy: Mode,
    target_mm: f32,
    draw: u64,
    mismatch: Mismatch,
    result: RunResult,
}

/// Targets spread over the reachable range, ends 0.2 mm inside.
fn targets(n: usize) -> Vec<f32> {
    let (min, max) = table::range_mm();
    let n = n.max(1);
    (0..n)
        .map(|i| {
            let f = if n == 1 {
                0.5
            } else {
                i as f32 / (n - 1) as f32
            };
            (min + 0.2) + (max - min - 0.4) * f
        })
        .collect()
}

/// Runs the task.
pub fn run(args: &Args, root: &Path) -> Result<(), String> {
    let out = root.join(&args.out);
    std::fs::create_dir_all(&out).map_err(|e| format!("cannot create {}: {e}", out.display()))?;
    let targets = targets(args.targets);
    let mut jobs = Vec::new();
    for draw in 0..args.draws {
        let m = Mismatch::draw(args.seed, draw);
        for &t in &targets {
            for s in STRATEGIES {
                jobs.push((s, t, draw, m));
            }
        }
    }
    let bar = ProgressBar::new(jobs.len() as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} morphs, {elapsed} elapsed, ~{eta} left")
            .map_err(|e| e.to_string())?,
    );
    let next = AtomicUsize::new(0);
    let rows = Mutex::new(Vec::with_capacity(jobs.len()));
    std::thread::scope(|scope| {
        for _ in 0..args.threads.max(1) {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(&(strategy, target_mm, draw, mismatch)) = jobs.get(i) else {
                    break;
                };
                let result = run_morph(mismatch.plant(), target_mm, strategy);
                rows.lock().unwrap().push(Row {
                    strategy,
                    target_mm,
                    draw,
                    mismatch,
                    result,
                });
                bar.inc(1);
            });
        }
    });
    bar.finish();
    let mut rows = rows.into_inner().unwrap();
    rows.sort_by(|a, b| {
        (a.draw, a.target_mm.to_bits(), a.strategy.as_str()).cmp(&(
            b.draw,
            b.target_mm.to_bits(),
            b.strategy.as_str(),
        ))
    });
    write_csv(&out.join("strategies.csv"), &rows)?;
    let summary = summarize(&rows);
    print!("{}", summary.table);
    pareto_chart(&out.join("strategies_pareto.svg"), &rows, &summary)?;
    timeline_chart(&out.join("strategies_timeline.svg"))?;
    println!(
        "wrote {}, strategies_pareto.svg, strategies_timeline.svg",
        out.join("strategies.csv").display()
    );
    match summary.best {
        Some(b) if b == AUTO_STRATEGY => println!("auto = {} (the chart's choice)", b.as_str()),
        Some(b) => println!(
            "note: the chart picks {} but AUTO_STRATEGY is {}; update src/strategy/mod.rs",
            b.as_str(),
            AUTO_STRATEGY.as_str()
        ),
        None => println!("note: no strategy meets the error aim over this ensemble"),
    }
    Ok(())
}

fn outcome_str(o: Outcome) -> &'static str {
    match o {
        Outcome::Done => "done",
        Outcome::Fault(f) => f.as_str(),
        Outcome::Stuck => "stuck",
    }
}

fn write_csv(path: &Path, rows: &[Row]) -> Result<(), String> {
    let mut s = String::from(
        "strategy,target_mm,time_s,error_pct,outcome,final_mm,max_pla_c,max_tca_c,medium,h_scale,ambient_c,supply_v,pla_ohm_scale,tca_ohm_scale,sensor_tau_s,sensor_noise_c,stiffness_scale,force_scale,draw\n",
    );
    for r in rows {
        let m = &r.mismatch;
        let x = &r.result;
        let _ = writeln!(
            s,
            "{},{:.2},{:.1},{:.3},{},{:.3},{:.1},{:.1},{},{:.3},{:.2},{:.2},{:.3},{:.3},{:.2},{:.3},{:.4},{:.4},{}",
            r.strategy.as_str(),
            r.target_mm,
            x.time_s,
            x.error_pct,
            outcome_str(x.outcome),
            x.final_mm,
            x.max_true_c[0],
            x.max_true_c[1],
            if m.air { "air" } else { "water" },
            m.h_scale,
            m.ambient_c,
            m.supply_v,
            m.heater_scale[0],
            m.heater_scale[1],
            m.sensor_tau_s,
            m.sensor_noise_c,
            m.stiffness_scale,
            m.force_scale,
            r.draw
        );
    }
    std::fs::write(path, s).map_err(|e| format!("cannot write {}: {e}", path.display()))
}

/// Percentile `p` (0–100) of sorted values, nearest rank.
fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let rank = ((p / 100.0) * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

/// Per-strategy statistics over a subset of runs.
#[derive(Clone, Copy, Debug)]
struct Stats {
    runs: usize,
    failed: usize,
    time_p50_s: f64,
    time_p95_s: f64,
    err_p50_pct: f64,
    err_p95_pct: f64,
    max_pla_c: f64,
    max_tca_c: f64,
}

fn stats(rows: &[&Row]) -> Stats {
    let done: Vec<&&Row> = rows
        .iter()
        .filter(|r| r.result.outcome == Outcome::Done)
        .collect();
    let mut t: Vec<f64> = done.iter().map(|r| r.result.time_s).collect();
    let mut e: Vec<f64> = done.iter().map(|r| r.result.error_pct.abs()).collect();
    t.sort_by(f64::total_cmp);
    e.sort_by(f64::total_cmp);
    let max = |i: usize| {
        rows.iter()
            .map(|r| r.result.max_true_c[i])
            .fold(f64::NEG_INFINITY, f64::max)
    };
    Stats {
        runs: rows.len(),
        failed: rows.len() - done.len(),
        time_p50_s: percentile(&t, 50.0),
        time_p95_s: percentile(&t, 95.0),
        err_p50_pct: percentile(&e, 50.0),
        err_p95_pct: percentile(&e, 95.0),
        max_pla_c: max(0),
        max_tca_c: max(1),
    }
}

struct Summary {
    table: String,
    /// (strategy, water-ensemble stats)
    water: Vec<(Mode, Stats)>,
    best: Option<Mode>,
}

fn summarize(rows: &[Row]) -> Summary {
    let mut table = String::from(
        "| strategy | medium | runs | failed | time p50 | time p95 | \\|error\\| p50 | \\|error\\| p95 | hottest PLA | hottest TCA |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n",
    );
    let mut water = Vec::new();
    for s in STRATEGIES {
        for (name, air) in [("water", false), ("air", true)] {
            let sel: Vec<&Row> = rows
                .iter()
                .filter(|r| r.strategy == s && r.mismatch.air == air)
                .collect();
            if sel.is_empty() {
                continue;
            }
            let st = stats(&sel);
            let _ = writeln!(
                table,
                "| {} | {} | {} | {} | {:.1} s | {:.1} s | {:.2} % | {:.2} % | {:.1} °C | {:.1} °C |",
                s.as_str(),
                name,
                st.runs,
                st.failed,
                st.time_p50_s,
                st.time_p95_s,
                st.err_p50_pct,
                st.err_p95_pct,
                st.max_pla_c,
                st.max_tca_c
            );
            if !air {
                water.push((s, st));
            }
        }
    }
    // The default: the fastest (p95 time) of the strategies meeting the error aim without
    // failures; it is on the Pareto front of the strategies by construction.
    let best = water
        .iter()
        .filter(|(_, st)| st.failed == 0 && st.err_p95_pct < AIM_ERROR_PCT)
        .min_by(|a, b| a.1.time_p95_s.total_cmp(&b.1.time_p95_s))
        .map(|(s, _)| *s);
    // Per target radius: where the time goes and where the error is.
    let _ = writeln!(
        table,
        "\n| strategy | target | time p50 | time p95 | \\|error\\| p50 | \\|error\\| p95 | failed |\n| --- | --- | --- | --- | --- | --- | --- |"
    );
    let mut targets: Vec<f32> = rows.iter().map(|r| r.target_mm).collect();
    targets.sort_by(f32::total_cmp);
    targets.dedup();
    for s in STRATEGIES {
        for &t in &targets {
            let sel: Vec<&Row> = rows
                .iter()
                .filter(|r| r.strategy == s && !r.mismatch.air && r.target_mm == t)
                .collect();
            let st = stats(&sel);
            let _ = writeln!(
                table,
                "| {} | {:.2} mm | {:.1} s | {:.1} s | {:.2} % | {:.2} % | {} |",
                s.as_str(),
                t,
                st.time_p50_s,
                st.time_p95_s,
                st.err_p50_pct,
                st.err_p95_pct,
                st.failed
            );
        }
    }
    Summary { table, water, best }
}

fn colour(s: Mode) -> RGBColor {
    match s {
        Mode::Paper => RGBColor(120, 120, 120),
        Mode::Gated => TAB_BLUE,
        Mode::Boost => TAB_ORANGE,
        _ => TAB_GREEN,
    }
}

/// Non-dominated points (less time and less error are better), ascending time.
fn pareto_front(points: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut p: Vec<(f64, f64)> = points
        .iter()
        .copied()
        .filter(|(t, e)| t.is_finite() && e.is_finite())
        .collect();
    p.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let mut front: Vec<(f64, f64)> = Vec::new();
    for q in p {
        if front.last().is_none_or(|l| q.1 < l.1) {
            front.push(q);
        }
    }
    front
}

fn pareto_chart(path: &Path, rows: &[Row], summary: &Summary) -> Result<(), String> {
    let done = |r: &&Row| r.result.outcome == Outcome::Done;
    let e_max = rows
        .iter()
        .filter(done)
        .map(|r| r.result.error_pct.abs())
        .fold(AIM_ERROR_PCT * 1.5, f64::max)
        .min(10.0);
    Ok(plot::write_svg(path, (900, 600), |root| {
        let mut chart = Frame::new(18, 12, 45, 60)
            .builder(
                root,
                Some("Morph time vs final radius error (water: dots, air: crosses; large: p95 of water runs)"),
            )
            .build_cartesian_2d((5f64..1000f64).log_scale(), 0f64..e_max)?;
        mesh(
            &mut chart,
            "morph time, MORPH to done (s, log scale)",
            "|final radius error| (%)",
            true,
        )
        .draw()?;
        for s in STRATEGIES {
            let c = colour(s);
            let pts = |air: bool| {
                rows.iter()
                    .filter(done)
                    .filter(move |r| r.strategy == s && r.mismatch.air == air)
                    .map(|r| (r.result.time_s, r.result.error_pct.abs().min(e_max)))
            };
            chart
                .draw_series(pts(false).map(|p| Circle::new(p, 2, c.mix(0.45).filled())))?
                .label(s.as_str())
                .legend(move |(x, y)| Circle::new((x + 8, y), 4, c.filled()));
            chart.draw_series(pts(true).map(|p| Cross::new(p, 3, c.mix(0.6))))?;
        }
        for (s, st) in &summary.water {
            chart.draw_series(std::iter::once(TriangleMarker::new(
                (st.time_p95_s, st.err_p95_pct.min(e_max)),
                9,
                colour(*s).filled(),
            )))?;
        }
        let all: Vec<(f64, f64)> = rows
            .iter()
            .filter(done)
            .map(|r| (r.result.time_s, r.result.error_pct.abs()))
            .collect();
        line(
            &mut chart,
            pareto_front(&all),
            BLACK.stroke_width(2),
            Some("Pareto front (all runs)"),
        )?;
        line(
            &mut chart,
            [
                (5.0, AIM_ERROR_PCT),
                (AIM_TIME_S, AIM_ERROR_PCT),
                (AIM_TIME_S, 0.0),
            ],
            RED.stroke_width(1),
            Some("aim: < 30 s, p95 < 2 %"),
        )?;
        legend(&mut chart, SeriesLabelPosition::UpperRight)
    })?)
}

fn timeline_chart(path: &Path) -> Result<(), String> {
    Ok(plot::write_svg(path, (1000, 1100), |root| {
        let panels = root.split_evenly((STRATEGIES.len(), 1));
        let frame = Frame::new(16, 8, 30, 50).right_y(50);
        for (s, area) in STRATEGIES.iter().zip(panels.iter()) {
            let mut trace: Vec<TracePoint> = Vec::new();
            let plant = Mismatch::NONE.plant();
            let r = run_morph_traced(plant, TIMELINE_TARGET_MM, *s, &mut |p| trace.push(*p));
            let t_end = trace.last().map(|p| p.t_s).unwrap_or(1.0);
            let title = format!(
                "{}: MORPH {} mm, done at {:.1} s, final {:.2} mm ({:+.2} %)",
                s.as_str(),
                TIMELINE_TARGET_MM,
                r.time_s,
                r.final_mm,
                r.error_pct
            );
            let mut chart = frame
                .builder(area, Some(&title))
                .build_cartesian_2d(0f64..t_end, 15f64..130f64)?
                .set_secondary_coord(0f64..t_end, 0f64..6f64);
            mesh(&mut chart, "time since MORPH (s)", "temperature (°C)", true).draw()?;
            chart
                .configure_secondary_axes()
                .y_desc("power (W)")
                .draw()?;
            let series: [(&str, RGBColor, bool, usize); 4] = [
                ("PLA true", TAB_RED, true, 0),
                ("PLA thermistor", TAB_RED, false, 0),
                ("TCA true", TAB_BLUE, true, 1),
                ("TCA thermistor", TAB_BLUE, false, 1),
            ];
            for (name, c, truth, i) in series {
                let style = if truth {
                    c.stroke_width(2)
                } else {
                    c.mix(0.5).stroke_width(1)
                };
                line(
                    &mut chart,
                    trace
                        .iter()
                        .map(|p| (p.t_s, if truth { p.true_c[i] } else { p.sensed_c[i] })),
                    style,
                    Some(name),
                )?;
            }
            for (name, c, i) in [("PLA power", TAB_ORANGE, 0), ("TCA power", TAB_GREEN, 1)] {
                chart
                    .draw_secondary_series(LineSeries::new(
                        trace.iter().map(|p| (p.t_s, p.power_w[i])),
                        c.stroke_width(1),
                    ))?
                    .label(name)
                    .legend(line_key(c.stroke_width(1)));
            }
            // Phase changes as thin vertical lines.
            let mut last = "";
            let mut changes = Vec::new();
            for p in &trace {
                if p.phase != last {
                    changes.push(p.t_s);
                    last = p.phase;
                }
            }
            marks(&mut chart, changes, 15.0, 130.0)?;
            legend(&mut chart, SeriesLabelPosition::UpperRight)?;
        }
        Ok(())
    })?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pareto_front_keeps_only_non_dominated_points() {
        let f = pareto_front(&[
            (10.0, 1.0),
            (20.0, 0.5),
            (15.0, 2.0),
            (30.0, 0.6),
            (5.0, 3.0),
        ]);
        assert_eq!(f, [(5.0, 3.0), (10.0, 1.0), (20.0, 0.5)]);
    }

    #[test]
    fn percentile_is_nearest_rank() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(percentile(&v, 50.0), 50.0);
        assert_eq!(percentile(&v, 95.0), 95.0);
        assert_eq!(percentile(&[3.0], 95.0), 3.0);
        assert!(percentile(&[], 50.0).is_nan());
    }

    #[test]
    fn targets_span_the_range_inside_its_ends() {
        let (min, max) = table::range_mm();
        let t = targets(5);
        assert_eq!(t.len(), 5);
        assert!((t[0] - (min + 0.2)).abs() < 1e-4 && (t[4] - (max - 0.2)).abs() < 1e-4);
    }
}
