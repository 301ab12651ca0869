//! `cargo xtask calibration`: what TUNE and MEASURED buy on a mismatch ensemble of each plant.
//!
//! Per drawn link: `auto` morphs to the targets with the compiled-in calibration ("before");
//! then TUNE from rest, and after it three measured morphs, each at one of
//! [`CALIBRATION_FRACTIONS`] of the range, the "user" measuring the plant's true radius
//! [`SETTLE_AFTER_DONE_S`] after `done` with a uniform error of ± [`MEASURE_ERROR_MM`] and
//! sending `MEASURED`. After TUNE and after each measured morph the targets are morphed again
//! (each on a fresh copy of the link at rest, with the calibration reached so far). Then the
//! read chain (docs/shape.md): from TUNE, one link rests as built, makes one measured morph and
//! four more to [`READ_FRACTIONS`], each read at rest by the link itself; the targets are
//! morphed again after its measured morph and after the four read ones; a second chain, whose
//! user measures two morphs first, gives its readings' table only. Writes
//! `docs/calibration.csv` (one row per evaluated morph, with the times bend, lock and release
//! began), `docs/calibration_shape.csv` (one row per rest-shape outcome of the read chain), the
//! chart of the error reached against the number of measured morphs (`docs/calibration.svg`,
//! `.png`) and prints the tables of `docs/calibration.md` and `docs/shape.md`.

use morphlink::calibration::Calibration;
use morphlink::controller::{Event, TICK_MS};
use morphlink::protocol::{Command, Mode};
use morphlink::sequencer::SeqEvent;
use morphlink::table;
use morphlink::vocab::Phase;
use morphlink_host::plot::{self, prelude::*};
use morphlink_model::draw::{splitmix, uniform};
use morphlink_plant::Plant;
use morphlink_sim::ensemble::{MAX_MORPH_S, SETTLE_AFTER_DONE_S};
use morphlink_sim::Rig;
use std::fmt::Write as _;
use std::path::Path;

use crate::ensemble::{parallel, percentile, Common, Link, DEFAULT_HIFI_DRAWS};
use crate::strategies::targets;

/// Lumped links drawn by default (each: TUNE, 3 measured morphs, 25 evaluated morphs).
pub const DEFAULT_DRAWS: u64 = 100;
/// Target radii evaluated per link, spread over the range 0.2 mm inside its ends (as the
/// strategy chart's).
pub const DEFAULT_TARGETS: usize = 5;
/// Where in the reachable range the three measured morphs aim (fractions from the tightest):
/// spread, so the map's slope is fitted, and inside the ends.
pub const CALIBRATION_FRACTIONS: [f32; 3] = [0.15, 0.5, 0.85];
/// Where the self-corrected morphs aim, after the first measured one (at
/// `CALIBRATION_FRACTIONS[0]`): four other places in the range, each read at rest and folded
/// in by the link itself (docs/shape.md).
pub const READ_FRACTIONS: [f32; 4] = [0.5, 0.85, 0.3, 0.7];
/// Where the read chain's second caliper measurement aims, when it has two (its readings'
/// table only): far from the first, so the gauge rests on two measured shapes.
pub const SECOND_CALIPER_FRACTION: f32 = 0.95;
/// The stage of the evaluations after the read chain's one measured morph (its baseline: the
/// same link, morph and MEASURED the readings then build on).
pub const CHAIN_STAGE: usize = 4;
/// The stage of the evaluations after the read chain's measured morph and its four read ones.
pub const READ_STAGE: usize = 5;
/// Ticks over which [`Eval::flow_mm_s`] is read: one second.
const FLOW_TICKS: usize = (1000 / TICK_MS) as usize;
/// The user's measuring error, mm (uniform ±): a ruler or calliper on a curved link.
pub const MEASURE_ERROR_MM: f64 = 0.3;
/// The aims of the issue: p95 |error| after calibration, %, and median time, s.
pub const AIM_ERROR_PCT: f64 = 2.0;
/// See [`AIM_ERROR_PCT`].
pub const AIM_TIME_S: f64 = 25.0;

/// Options of the task.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Lumped links to draw.
    #[arg(long, default_value_t = DEFAULT_DRAWS)]
    pub draws: u64,
    /// High-fidelity links to draw.
    #[arg(long, default_value_t = DEFAULT_HIFI_DRAWS)]
    pub hifi_draws: u64,
    /// Target radii evaluated per link.
    #[arg(long, default_value_t = DEFAULT_TARGETS)]
    pub targets: usize,
    // The seed also draws the measuring error.
    #[command(flatten)]
    pub common: Common,
    /// Output directory, relative to the workspace root.
    #[arg(long, default_value = "docs")]
    pub out: String,
    /// Skip TUNE: the measured morphs start from the compiled-in calibration (what MEASURED
    /// alone does).
    #[arg(long)]
    pub no_tune: bool,
    /// Bend on the TCA's own temperature (`tca_self_bend 1`, a board that senses current):
    /// writes `calibration_self.csv`, `.svg` and `.png` instead.
    #[arg(long)]
    pub self_bend: bool,
    /// The medium's temperature drifts at this rate through each read chain, K/h, from the
    /// link's own (a lab or bath that warms or cools): how the rest-shape readings bear it
    /// (docs/shape.md). The other stages keep still surroundings.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub ambient_drift_k_per_h: f64,
    /// The read chain's four read morphs are measured instead, each with the plant's true
    /// radius (a `MEASURED` with no error): what rest readings as good as a caliper, and
    /// better, could buy (docs/shape.md). The "+ 4 read" rows then give that.
    #[arg(long)]
    pub true_reads: bool,
}

impl Args {
    /// The name the outputs start with.
    fn stem(&self) -> &'static str {
        if self.self_bend {
            "calibration_self"
        } else {
            "calibration"
        }
    }

    /// The calibration a link starts with: the compiled-in one, with the own-temperature bend
    /// where asked.
    fn start(&self) -> Calibration {
        Calibration {
            tca_self_bend: if self.self_bend { 1.0 } else { 0.0 },
            ..Calibration::DEFAULT
        }
    }
}

/// A fresh rig on a copy of `link` with calibration `cal`, booted.
fn rig(link: &Link, cal: &Calibration) -> Rig<Box<dyn Plant>> {
    let mut rig = link.rig();
    rig.ctrl
        .set_calibration(*cal)
        .expect("a calibration the controller made is within its bounds");
    rig.boot();
    rig
}

/// One evaluated morph.
#[derive(Clone, Copy, Debug)]
struct Eval {
    /// Measured morphs folded in before it; `None` = before TUNE (compiled-in calibration).
    measured: Option<usize>,
    target_mm: f32,
    /// MORPH to done, s (NaN unless done).
    time_s: f64,
    /// (final − target) / target, % (NaN unless done).
    error_pct: f64,
    /// Seconds since MORPH at which bend, lock and release began (NaN if never).
    phase_s: [f64; 3],
    /// How it ended: `done`, the fault's code or `unfinished`.
    end: &'static str,
    /// How fast the true radius moved over the last second of bend, mm/s (NaN if bend never
    /// ended): a rod still flowing when lock froze it.
    flow_mm_s: f64,
}

/// One rest-shape outcome of the read chain.
#[derive(Clone, Debug)]
struct ShapeRow {
    /// 0: as built, 1: the measured morph, 2..: the read morphs.
    step: usize,
    /// The event line (`event: shape ...`), or `(none)` if no line came.
    line: String,
    /// The plant's true radius when the line came, mm.
    true_mm: f64,
    /// Seconds from `done` (from boot, as built) to the line.
    after_s: f64,
    /// The gauge the link had learnt then (ΔR/R per 1/m; NaN: none).
    gauge: f64,
}

impl ShapeRow {
    /// The reading's radius and sigma, mm, and whether it was learnt.
    fn reading(&self) -> Option<(f64, f64, bool)> {
        let field = |k: &str| {
            self.line
                .split_whitespace()
                .find_map(|w| w.strip_prefix(k))
                .and_then(|v| v.parse::<f64>().ok())
        };
        Some((
            field("radius_mm=")?,
            field("sigma_mm=")?,
            field("learnt=")? == 1.0,
        ))
    }

    /// The reason of a `none` line.
    fn none_reason(&self) -> Option<&str> {
        self.line
            .split_whitespace()
            .find_map(|w| w.strip_prefix("reason="))
    }
}

/// What one link gave.
struct LinkResult {
    plant: &'static str,
    draw: u64,
    air: bool,
    /// The end line of TUNE (`event: tune done ...` or `... failed ...`).
    tune_line: String,
    evals: Vec<Eval>,
    /// The read chain's rest-shape outcomes.
    shapes: Vec<ShapeRow>,
    /// The same with two caliper measurements before the read morphs.
    shapes2: Vec<ShapeRow>,
}

/// What one morph gave: MORPH to done, s, the true radius `SETTLE_AFTER_DONE_S` later, mm
/// (both NaN unless done), and when bend, lock and release began, s since MORPH.
struct MorphRun {
    time_s: f64,
    final_mm: f64,
    phase_s: [f64; 3],
    /// `done`, the fault's code (a phase timeout or an alarm) or `unfinished`.
    end: &'static str,
    /// See [`Eval::flow_mm_s`].
    flow_mm_s: f64,
}

/// An end that is a safety alarm (not `done`, a phase timeout, or a morph still running).
fn is_alarm(end: &str) -> bool {
    !matches!(end, "done" | "phase-timeout" | "unfinished")
}

/// Which of [`MorphRun::phase_s`] a phase event fills.
fn phase_slot(phase: Phase) -> Option<usize> {
    match phase {
        Phase::Bend => Some(0),
        Phase::Lock => Some(1),
        Phase::Release => Some(2),
        _ => None,
    }
}

/// Runs one MORPH on `rig` to its end and `SETTLE_AFTER_DONE_S` past it.
fn morph(rig: &mut Rig<Box<dyn Plant>>, target_mm: f32) -> MorphRun {
    let t0 = rig.now_ms();
    rig.ctrl.handle(
        t0,
        Command::Morph {
            radius_mm: target_mm,
            mode: Mode::Auto,
        },
        &mut |_| {},
    );
    let end = t0 + (MAX_MORPH_S * 1000.0) as u64;
    let mut phase_s = [f64::NAN; 3];
    // The true radius over the last second, one a tick: how fast it moved when lock began.
    let mut last_s = std::collections::VecDeque::with_capacity(FLOW_TICKS + 1);
    let mut flow_mm_s = f64::NAN;
    while rig.ctrl.busy() && rig.now_ms() < end {
        if last_s.len() > FLOW_TICKS {
            last_s.pop_front();
        }
        last_s.push_back(rig.radius_mm());
        rig.tick();
        while let Some(e) = rig.ctrl.pop_event() {
            if let Event::Seq(SeqEvent::Phase { phase, t_s, .. }) = e {
                if phase == Phase::Lock {
                    let first = last_s.front().copied().unwrap_or(f64::NAN);
                    let span_s = (last_s.len() - 1).max(1) as f64 * TICK_MS as f64 / 1000.0;
                    flow_mm_s = (rig.radius_mm() - first).abs() / span_s;
                }
                if let Some(i) = phase_slot(phase) {
                    phase_s[i] = t_s as f64;
                }
            }
        }
    }
    let time_s = (rig.now_ms() - t0) as f64 / 1000.0;
    if !rig.ctrl.busy() && rig.ctrl.fault().is_none() {
        wait_settled(rig, None);
    }
    // Unfinished, faulted, or an alarm in the minute after `done` (still this morph's).
    let end = match rig.ctrl.fault() {
        Some(f) => f.code.as_str(),
        None if rig.ctrl.busy() => "unfinished",
        None => "done",
    };
    let done = end == "done";
    MorphRun {
        time_s: if done { time_s } else { f64::NAN },
        final_mm: if done { rig.radius_mm() } else { f64::NAN },
        phase_s,
        end,
        flow_mm_s,
    }
}

/// Ticks `rig` until an `event: shape` line (or [`morphlink::shape::SHAPE_REST_MAX_S`] and a
/// minute), sending `measured` (mm) as MEASURED [`SETTLE_AFTER_DONE_S`] in, as a user would.
fn wait_shape(
    rig: &mut Rig<Box<dyn Plant>>,
    measured: Option<f64>,
    drift: Option<Drift>,
) -> (String, f64, f64) {
    let t0 = rig.now_ms();
    let stop = t0 + ((morphlink::shape::SHAPE_REST_MAX_S as f64 + 60.0) * 1000.0) as u64;
    let at = t0 + (SETTLE_AFTER_DONE_S * 1000.0) as u64;
    let mut pending = measured;
    let mut line = None;
    while line.is_none() && rig.now_ms() < stop {
        if rig.now_ms() >= at {
            if let Some(r) = pending.take() {
                rig.handle_line(&format!("MEASURED {r:.2}"), &mut |_| {});
            }
        }
        tick(rig, drift);
        rig.drain_events(&mut |l| {
            if l.starts_with("event: shape") {
                line = Some(l.to_string());
            }
        });
    }
    let after_s = (rig.now_ms() - t0) as f64 / 1000.0;
    (
        line.unwrap_or_else(|| "(none)".into()),
        rig.radius_mm(),
        after_s,
    )
}

/// The read chain: from `cal` on one link at rest as built, its rest read; one morph the user
/// measures; then one morph to each of [`READ_FRACTIONS`], each corrected by its own rest
/// reading. The calibrations after the measured morph and at the end, and the rest-shape
/// outcomes.
fn read_chain(
    link: &Link,
    cal: &Calibration,
    s: &mut u64,
    calipers: usize,
    drift_k_per_h: f64,
    true_reads: bool,
) -> (Calibration, Calibration, Vec<ShapeRow>) {
    let (min, max) = table::range_mm();
    let mut rig = rig(link, cal);
    let mut rows = Vec::new();
    let drift = (drift_k_per_h != 0.0).then(|| Drift {
        from_c: link.ambient_c(),
        k_per_s: drift_k_per_h / 3600.0,
        since_ms: rig.now_ms(),
    });
    // As built the rest says nothing (nobody asked): it is the anchor once read.
    let t0 = rig.now_ms();
    while rig.ctrl.rest_shape().anchor().is_none() && rig.now_ms() - t0 < 300_000 {
        tick(&mut rig, drift);
        rig.drain_events(&mut |_| {});
    }
    let line = match rig.ctrl.rest_shape().anchor() {
        Some(_) => "(as built: anchor read)".to_string(),
        None => "(as built: no anchor in 300 s)".to_string(),
    };
    let (true_mm, after_s) = (rig.radius_mm(), (rig.now_ms() - t0) as f64 / 1000.0);
    rows.push(ShapeRow {
        step: 0,
        line,
        true_mm,
        after_s,
        gauge: gauge_of(&rig),
    });
    let measured_at = [CALIBRATION_FRACTIONS[0], SECOND_CALIPER_FRACTION];
    let fractions = measured_at[..calipers]
        .iter()
        .copied()
        .chain(READ_FRACTIONS);
    let mut measured_cal = *cal;
    for (step, f) in fractions.enumerate() {
        let target = min + (max - min) * f;
        let t0 = rig.now_ms();
        rig.handle_line(&format!("MORPH {target:.2}"), &mut |_| {});
        let end = t0 + (MAX_MORPH_S * 1000.0) as u64;
        while rig.ctrl.busy() && rig.now_ms() < end {
            tick(&mut rig, drift);
            rig.drain_events(&mut |_| {});
        }
        if rig.ctrl.busy() || rig.ctrl.fault().is_some() {
            rig.handle_line("ABORT", &mut |_| {});
            break;
        }
        // The first `calipers` are measured 60 s after done, by the user; with `true_reads`
        // the rest too, without error.
        let measured = (step < calipers || true_reads).then(|| {
            let settled = wait_settled(&mut rig, drift);
            match step < calipers {
                true => settled + uniform(s, (-MEASURE_ERROR_MM, MEASURE_ERROR_MM)),
                false => settled,
            }
        });
        let (line, true_mm, after_s) = wait_shape(&mut rig, measured, drift);
        if step + 1 == calipers {
            measured_cal = rig.ctrl.calibration();
        }
        rows.push(ShapeRow {
            step: step + 1,
            line,
            true_mm,
            after_s: after_s
                + if step < calipers {
                    SETTLE_AFTER_DONE_S
                } else {
                    0.0
                },
            gauge: gauge_of(&rig),
        });
    }
    (measured_cal, rig.ctrl.calibration(), rows)
}

/// The gauge `rig`'s link has learnt, ΔR/R per 1/m (NaN: none).
fn gauge_of(rig: &Rig<Box<dyn Plant>>) -> f64 {
    rig.ctrl
        .calibration()
        .gauge()
        .map_or(f64::NAN, |(g, _)| g as f64)
}

/// Ticks [`SETTLE_AFTER_DONE_S`] past `done`: the plant's true radius then (what a user
/// measures).
fn wait_settled(rig: &mut Rig<Box<dyn Plant>>, drift: Option<Drift>) -> f64 {
    let settle = (SETTLE_AFTER_DONE_S * 1000.0) as u64 / TICK_MS;
    for _ in 0..settle {
        tick(rig, drift);
        rig.drain_events(&mut |_| {});
    }
    rig.radius_mm()
}

/// The medium's temperature drifting at a steady rate through a read chain
/// (`--ambient-drift-k-per-h`).
#[derive(Clone, Copy, Debug)]
struct Drift {
    /// The medium's temperature when the drift began, °C.
    from_c: f64,
    /// Its rate, K/s.
    k_per_s: f64,
    /// When it began, ms of rig time.
    since_ms: u64,
}

/// One tick of `rig`, the medium first set where `drift` puts it now.
fn tick(rig: &mut Rig<Box<dyn Plant>>, drift: Option<Drift>) {
    if let Some(d) = drift {
        let c = d.from_c + d.k_per_s * rig.now_ms().saturating_sub(d.since_ms) as f64 / 1000.0;
        rig.bench
            .set_ambient_c(c)
            .expect("the plants take any medium temperature a drift reaches");
    }
    rig.tick();
}

fn evaluate(link: &Link, cal: &Calibration, measured: Option<usize>, targets: &[f32]) -> Vec<Eval> {
    targets
        .iter()
        .map(|&t| {
            let m = morph(&mut rig(link, cal), t);
            Eval {
                measured,
                target_mm: t,
                time_s: m.time_s,
                error_pct: (m.final_mm - t as f64) / t as f64 * 100.0,
                phase_s: m.phase_s,
                end: m.end,
                flow_mm_s: m.flow_mm_s,
            }
        })
        .collect()
}

/// TUNE on a copy of the link at rest from `start`: the calibration it ends with and its end
/// line.
fn tune(link: &Link, start: &Calibration) -> (Calibration, String) {
    let mut rig = rig(link, start);
    rig.tick();
    rig.handle_line("TUNE", &mut |_| {});
    let mut end = String::from("(no end line)");
    let stop = rig.now_ms() + 200_000;
    while rig.ctrl.tuning() && rig.now_ms() < stop {
        rig.tick();
        rig.drain_events(&mut |l| {
            if l.starts_with("event: tune done")
                || l.starts_with("event: tune failed")
                || l.starts_with("alarm:")
            {
                end = l.to_string();
            }
        });
    }
    (rig.ctrl.calibration(), end)
}

fn run_link(link: &Link, targets: &[f32], args: &Args) -> LinkResult {
    let plant = if link.is_hifi() { "hifi" } else { "lumped" };
    let (draw, air) = (link.draw, link.air);
    let start = args.start();
    let seed = args.common.seed;
    let mut evals = evaluate(link, &start, None, targets);
    let (mut cal, tune_line) = if args.no_tune {
        (start, "(TUNE skipped)".to_string())
    } else {
        tune(link, &start)
    };
    evals.extend(evaluate(link, &cal, Some(0), targets));
    let tuned = cal;
    let (min, max) = table::range_mm();
    let mut s = seed ^ draw.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ (plant.len() as u64);
    splitmix(&mut s);
    for (k, f) in CALIBRATION_FRACTIONS.iter().enumerate() {
        let target = min + (max - min) * f;
        let mut rig = rig(link, &cal);
        let final_mm = morph(&mut rig, target).final_mm;
        if final_mm.is_finite() {
            let reported = final_mm + uniform(&mut s, (-MEASURE_ERROR_MM, MEASURE_ERROR_MM));
            let now = rig.now_ms();
            rig.ctrl.handle(
                now,
                Command::Measured {
                    radius_mm: reported as f32,
                },
                &mut |_| {},
            );
            cal = rig.ctrl.calibration();
        }
        evals.extend(evaluate(link, &cal, Some(k + 1), targets));
    }
    let drift = args.ambient_drift_k_per_h;
    let truth = args.true_reads;
    let (chain_cal, read_cal, shapes) = read_chain(link, &tuned, &mut s, 1, drift, truth);
    let (_, _, shapes2) = read_chain(link, &tuned, &mut s, 2, drift, truth);
    evals.extend(evaluate(link, &chain_cal, Some(CHAIN_STAGE), targets));
    evals.extend(evaluate(link, &read_cal, Some(READ_STAGE), targets));
    LinkResult {
        plant,
        draw,
        air,
        tune_line,
        evals,
        shapes,
        shapes2,
    }
}

/// (runs, failed, of which alarms, |error| p50, p95, time p50) over evaluations.
fn stats<'a>(evals: impl Iterator<Item = &'a Eval>) -> (usize, usize, usize, f64, f64, f64) {
    let all: Vec<&Eval> = evals.collect();
    let done: Vec<&&Eval> = all.iter().filter(|e| e.error_pct.is_finite()).collect();
    let mut e: Vec<f64> = done.iter().map(|e| e.error_pct.abs()).collect();
    let mut t: Vec<f64> = done.iter().map(|e| e.time_s).collect();
    e.sort_by(f64::total_cmp);
    t.sort_by(f64::total_cmp);
    (
        all.len(),
        all.len() - done.len(),
        all.iter().filter(|e| is_alarm(e.end)).count(),
        percentile(&e, 50.0),
        percentile(&e, 95.0),
        percentile(&t, 50.0),
    )
}

fn stage_name(m: Option<usize>) -> String {
    match m {
        None => "before TUNE".into(),
        Some(0) => "after TUNE".into(),
        Some(CHAIN_STAGE) => "chain: TUNE + 1 measured".into(),
        Some(READ_STAGE) => "chain: + 4 read".into(),
        Some(k) => format!("TUNE + {k} measured"),
    }
}

const STAGES: [Option<usize>; 7] = [
    None,
    Some(0),
    Some(1),
    Some(2),
    Some(3),
    Some(CHAIN_STAGE),
    Some(READ_STAGE),
];

/// One plant's line on the chart: (stage index, p50, p95) per stage.
type StageSeries = Vec<(f64, f64, f64)>;

/// The chart: p50 and p95 |error| against the measured morphs, per plant (water links).
struct Chart {
    /// (plant, its stages)
    series: Vec<(&'static str, StageSeries)>,
}

impl Figure for Chart {
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        format: Format,
    ) -> PlotResult {
        let top = self
            .series
            .iter()
            .flat_map(|(_, v)| v.iter().map(|p| p.2))
            .filter(|v| v.is_finite())
            .fold(AIM_ERROR_PCT, f64::max)
            * 1.1;
        let caption = format.has_text().then_some(
            "auto's |radius error| on water links: before TUNE (x = -1), after TUNE (0), after n measured morphs, the read chain after its measured morph (4) and its 4 read ones (5)",
        );
        let mut chart = Frame::new(16, 8, 40, 60)
            .builder(root, caption)
            .build_cartesian_2d(-1.2f64..5.2f64, 0f64..top)?;
        mesh(
            &mut chart,
            "measured morphs (-1: before TUNE)",
            "|error| (%)",
            format.has_text(),
        )
        .draw()?;
        line(
            &mut chart,
            [(-1.2, AIM_ERROR_PCT), (5.2, AIM_ERROR_PCT)],
            BLACK.mix(0.5).stroke_width(1),
            format.has_text().then_some("aim: p95 2 %"),
        )?;
        for (i, (plant, pts)) in self.series.iter().enumerate() {
            let c = palette(i);
            let l95 = format!("{plant} p95");
            let l50 = format!("{plant} p50");
            line(
                &mut chart,
                pts.iter().map(|p| (p.0, p.2)),
                c.stroke_width(3),
                format.has_text().then_some(l95.as_str()),
            )?;
            line(
                &mut chart,
                pts.iter().map(|p| (p.0, p.1)),
                c.mix(0.6).stroke_width(1),
                format.has_text().then_some(l50.as_str()),
            )?;
        }
        if format.has_text() {
            legend(&mut chart, SeriesLabelPosition::UpperRight)?;
        }
        Ok(())
    }
}

/// The read chain's tables: the rest-shape readings' own error against the plant's true
/// radius, what gave none and why, and the time from `done` to the reading.
fn shape_tables(sel: &[&LinkResult], calipers: usize) {
    println!("\nRest-shape readings of the read chain, {calipers} caliper measurement(s) first (docs/shape.md):\n");
    println!(
        "| medium | steps | read | learnt | none (reasons) | reading \\|error\\| p50 | p95 | sigma p50 | \\|error\\|/sigma p95 | after done p50 | p95 |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    for air in [false, true] {
        let rows: Vec<&ShapeRow> = sel
            .iter()
            .filter(|r| r.air == air)
            .flat_map(|r| if calipers == 1 { &r.shapes } else { &r.shapes2 })
            .filter(|r| r.step > calipers)
            .collect();
        if rows.is_empty() {
            continue;
        }
        let mut reasons: std::collections::BTreeMap<&str, usize> = Default::default();
        let (mut err, mut sig, mut z, mut after) = (vec![], vec![], vec![], vec![]);
        let mut learnt = 0;
        for r in &rows {
            match r.reading() {
                Some((mm, sigma, l)) => {
                    err.push(((mm - r.true_mm) / r.true_mm * 100.0).abs());
                    sig.push(sigma / mm * 100.0);
                    z.push((mm - r.true_mm).abs() / sigma.max(1e-6));
                    after.push(r.after_s);
                    learnt += l as usize;
                }
                None => {
                    *reasons
                        .entry(r.none_reason().unwrap_or("no line"))
                        .or_default() += 1
                }
            }
        }
        for v in [&mut err, &mut sig, &mut z, &mut after] {
            v.sort_by(f64::total_cmp);
        }
        let none: Vec<String> = reasons.iter().map(|(k, v)| format!("{v} {k}")).collect();
        println!(
            "| {} | {} | {} | {learnt} | {} | {:.2} % | {:.2} % | {:.2} % | {:.1} | {:.0} s | {:.0} s |",
            if air { "air" } else { "water" },
            rows.len(),
            err.len(),
            if none.is_empty() { "0".into() } else { none.join(", ") },
            percentile(&err, 50.0),
            percentile(&err, 95.0),
            percentile(&sig, 50.0),
            percentile(&z, 95.0),
            percentile(&after, 50.0),
            percentile(&after, 95.0),
        );
    }
}

/// The reading's error against the gauge's magnitude (hifi, both media): how the sensor
/// depends on the coil's strain term.
fn shape_by_gauge(sel: &[&LinkResult]) {
    println!("\nReading |error| by the learnt gauge's magnitude (ΔR/R per 1/m):\n");
    println!("| \\|gauge\\| | read | none | \\|error\\| p50 | p95 |");
    println!("| --- | --- | --- | --- | --- |");
    for (lo, hi) in [(0.0, 2e-4), (2e-4, 5e-4), (5e-4, 1e-3), (1e-3, 1.0)] {
        let rows: Vec<&ShapeRow> = sel
            .iter()
            .flat_map(|r| r.shapes.iter())
            .filter(|r| r.step >= 2 && r.gauge.abs() >= lo && r.gauge.abs() < hi)
            .collect();
        let mut err: Vec<f64> = rows
            .iter()
            .filter_map(|r| {
                let (mm, _, _) = r.reading()?;
                Some(((mm - r.true_mm) / r.true_mm * 100.0).abs())
            })
            .collect();
        err.sort_by(f64::total_cmp);
        println!(
            "| {lo:.0e}–{hi:.0e} | {} | {} | {:.2} % | {:.2} % |",
            err.len(),
            rows.len() - err.len(),
            percentile(&err, 50.0),
            percentile(&err, 95.0)
        );
    }
}

/// Writes the read chains' rows: one per rest-shape outcome, of the chain with one caliper
/// measurement and of the one with two.
fn shape_csv(results: &[LinkResult], path: &Path) -> Result<(), String> {
    let mut csv = String::from("plant,draw,air,calipers,step,true_mm,after_s,gauge,line\n");
    for r in results {
        for (calipers, rows) in [(1, &r.shapes), (2, &r.shapes2)] {
            for s in rows {
                let _ = writeln!(
                    csv,
                    "{},{},{},{calipers},{},{:.3},{:.1},{:.3e},\"{}\"",
                    r.plant, r.draw, r.air, s.step, s.true_mm, s.after_s, s.gauge, s.line
                );
            }
        }
    }
    std::fs::write(path, csv).map_err(|e| format!("{}: {e}", path.display()))
}

/// Runs the task.
pub fn run(args: &Args, root: &Path) -> Result<(), String> {
    let out = root.join(&args.out);
    std::fs::create_dir_all(&out).map_err(|e| format!("cannot create {}: {e}", out.display()))?;
    let targets = targets(args.targets);
    let mut jobs: Vec<(bool, u64)> = Vec::new();
    jobs.extend((0..args.hifi_draws).map(|d| (true, d)));
    jobs.extend((0..args.draws).map(|d| (false, d)));
    let results: Vec<LinkResult> = parallel(&jobs, args.common.threads, "links", |&(hifi, d)| {
        let link = if hifi {
            Link::hifi_draw(args.common.seed, d)?
        } else {
            Link::lumped_draw(args.common.seed, d)
        };
        Ok::<_, String>(run_link(&link, &targets, args))
    })?
    .into_iter()
    .collect::<Result<_, _>>()?;
    // CSV: one row per evaluated morph.
    let mut csv = String::from(
        "plant,draw,air,stage,measured,target_mm,time_s,error_pct,bend_s,lock_s,release_s,bend_end_flow_mm_s,end,tune\n",
    );
    for r in &results {
        for (k, e) in r.evals.iter().enumerate() {
            // The link's TUNE line once, on its first row.
            let tune_line = if k == 0 { r.tune_line.as_str() } else { "" };
            let _ = writeln!(
                csv,
                "{},{},{},{},{},{:.2},{:.1},{:.3},{:.1},{:.1},{:.1},{:.3},{},\"{}\"",
                r.plant,
                r.draw,
                r.air,
                stage_name(e.measured),
                e.measured.map_or(-1, |k| k as i64),
                e.target_mm,
                e.time_s,
                e.error_pct,
                e.phase_s[0],
                e.phase_s[1],
                e.phase_s[2],
                e.flow_mm_s,
                e.end,
                tune_line.replace('"', "'")
            );
        }
    }
    let csv_path = out.join(format!("{}.csv", args.stem()));
    std::fs::write(&csv_path, csv).map_err(|e| format!("{}: {e}", csv_path.display()))?;
    shape_csv(&results, &out.join(format!("{}_shape.csv", args.stem())))?;
    let mut series = Vec::new();
    for plant in ["hifi", "lumped"] {
        let sel: Vec<&LinkResult> = results.iter().filter(|r| r.plant == plant).collect();
        if sel.is_empty() {
            continue;
        }
        let tuned = sel
            .iter()
            .filter(|r| r.tune_line.starts_with("event: tune done"))
            .count();
        println!(
            "\n## Plant: {plant} ({} links, TUNE done on {tuned})\n",
            sel.len()
        );
        println!(
            "| stage | medium | runs | failed | of which alarms | time p50 | \\|error\\| p50 | \\|error\\| p95 | flow at bend's end p95 | max |"
        );
        println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |");
        let mut pts = Vec::new();
        for (si, stage) in STAGES.iter().enumerate() {
            for air in [false, true] {
                let (n, failed, alarms, p50, p95, t50) = stats(
                    sel.iter()
                        .filter(|r| r.air == air)
                        .flat_map(|r| r.evals.iter())
                        .filter(|e| e.measured == *stage),
                );
                if n == 0 {
                    continue;
                }
                let mut flow: Vec<f64> = sel
                    .iter()
                    .filter(|r| r.air == air)
                    .flat_map(|r| r.evals.iter())
                    .filter(|e| e.measured == *stage && e.flow_mm_s.is_finite())
                    .map(|e| e.flow_mm_s)
                    .collect();
                flow.sort_by(f64::total_cmp);
                println!(
                    "| {} | {} | {n} | {failed} | {alarms} | {t50:.1} s | {p50:.2} % | {p95:.2} % | {:.3} mm/s | {:.3} mm/s |",
                    stage_name(*stage),
                    if air { "air" } else { "water" },
                    percentile(&flow, 95.0),
                    flow.last().copied().unwrap_or(f64::NAN),
                );
                if !air {
                    pts.push((si as f64 - 1.0, p50, p95));
                }
            }
        }
        println!("\n(aims: |error| p95 <= {AIM_ERROR_PCT} %, time p50 <= {AIM_TIME_S} s)");
        println!("\nPer target, water links, after TUNE + 3 measured:\n");
        println!(
            "| target | time p50 | soften p50 | bend p50 | lock p50 | \\|error\\| p50 | \\|error\\| p95 | failed |"
        );
        println!("| --- | --- | --- | --- | --- | --- | --- | --- |");
        for &t in &targets {
            let at = || {
                sel.iter()
                    .filter(|r| !r.air)
                    .flat_map(|r| r.evals.iter())
                    .filter(move |e| e.measured == Some(3) && e.target_mm == t)
            };
            let (_, failed, _, p50, p95, t50) = stats(at());
            // Phase lengths of the finished morphs: soften to bend, bend to lock, lock to
            // release.
            let span = |from: Option<usize>, to: usize| {
                let mut v: Vec<f64> = at()
                    .filter(|e| e.error_pct.is_finite())
                    .map(|e| e.phase_s[to] - from.map_or(0.0, |f| e.phase_s[f]))
                    .collect();
                v.sort_by(f64::total_cmp);
                percentile(&v, 50.0)
            };
            println!(
                "| {t:.2} mm | {t50:.1} s | {:.1} s | {:.1} s | {:.1} s | {p50:.2} % | {p95:.2} % | {failed} |",
                span(None, 0),
                span(Some(0), 1),
                span(Some(1), 2)
            );
        }
        // Per link: the worst p95 after calibration (the aim is on every link).
        let mut worst: Vec<(u64, f64)> = sel
            .iter()
            .filter(|r| !r.air)
            .map(|r| {
                let m = r
                    .evals
                    .iter()
                    .filter(|e| e.measured == Some(3))
                    .map(|e| {
                        if e.error_pct.is_finite() {
                            e.error_pct.abs()
                        } else {
                            f64::INFINITY
                        }
                    })
                    .fold(0.0, f64::max);
                (r.draw, m)
            })
            .collect();
        worst.sort_by(|a, b| b.1.total_cmp(&a.1));
        let over = worst.iter().filter(|w| w.1 > AIM_ERROR_PCT).count();
        println!(
            "\nWater links whose worst |error| after TUNE + 3 measured exceeds {AIM_ERROR_PCT} %: {over} of {}; worst: {}",
            worst.len(),
            worst
                .iter()
                .take(5)
                .map(|(d, e)| format!("draw {d} {e:.2} %"))
                .collect::<Vec<_>>()
                .join(", ")
        );
        shape_tables(&sel, 1);
        shape_tables(&sel, 2);
        if plant == "hifi" {
            shape_by_gauge(&sel);
        }
        series.push((if plant == "hifi" { "hifi" } else { "lumped" }, pts));
    }
    let chart = Chart { series };
    for ext in ["svg", "png"] {
        let name = format!("{}.{ext}", args.stem());
        plot::write(&out.join(name), (900, 600), &chart).map_err(String::from)?;
    }
    println!(
        "\nwrote {}, {stem}_shape.csv, {stem}.svg, {stem}.png",
        csv_path.display(),
        stem = args.stem()
    );
    Ok(())
}
