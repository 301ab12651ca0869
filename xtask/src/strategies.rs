//! `cargo xtask strategies`: every morph strategy over ensembles of links that differ from the
//! controller's model, on two plants side by side — the lumped plant (the controller's own
//! equations, other parameters) and the high-fidelity plant (`morphlink_plant::hifi`, which
//! shares the least with the controller and gives the headline) — with the ideal-knowledge
//! bound (`morphlink_sim::oracle`) beside them. Writes `docs/strategies.csv` (one row per run),
//! `docs/strategies_oracle.csv`, the charts of morph time against radius error with the Pareto
//! front (`docs/strategies_pareto.svg` on the hifi plant, `strategies_pareto_lumped.svg`) and a
//! time plot of one nominal morph per strategy on each plant (`docs/strategies_timeline.svg`,
//! `strategies_timeline_lumped.svg`), and prints the summary tables of `docs/strategies.md`.

use crate::ensemble::{parallel, percentile, Body, Common, Link, DEFAULT_HIFI_DRAWS};
use morphlink::protocol::Mode;
use morphlink::strategy::AUTO_STRATEGY;
use morphlink::table;
use morphlink_host::plot::{self, prelude::*};
use morphlink_plant::hifi::{Grid, HifiSpec};
use morphlink_sim::ensemble::{run_morph_on, Mismatch, Outcome, RunResult, TracePoint};
use morphlink_sim::{oracle, Rig};
use std::fmt::Write as _;
use std::path::Path;

/// Strategies compared (`auto` is one of them, chosen from this comparison).
pub const STRATEGIES: [Mode; 4] = [Mode::Paper, Mode::Gated, Mode::Boost, Mode::Closed];
/// Lumped links drawn by default: 250 links × 5 radii × 4 strategies = 5000 morphs, under
/// half a minute on two cores (each morph is simulated in milliseconds); `--draws 2000` for
/// a tighter 95th percentile.
pub const DEFAULT_DRAWS: u64 = 250;
/// Links of each plant the oracle runs on (its bisection runs the policy 16 times a radius).
pub const DEFAULT_ORACLE_DRAWS: u64 = 10;
/// Target radii per link, spread over the reachable range 0.2 mm inside its ends.
pub const DEFAULT_TARGETS: usize = 5;
/// The morph time aimed at (four times faster than the paper), s.
pub const AIM_TIME_S: f64 = 30.0;
/// The 95th-percentile radius error aimed at, %.
pub const AIM_ERROR_PCT: f64 = 2.0;
/// Radius of the nominal time-plot morphs, mm (the README's example).
pub const TIMELINE_TARGET_MM: f32 = 38.0;

/// Which plants to run.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlantChoice {
    /// The lumped plant only (fast; the controller's own equations).
    Lumped,
    /// The high-fidelity plant only.
    Hifi,
    /// Both, side by side (the default).
    Both,
}

/// Options of the task.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Lumped links to draw.
    #[arg(long, default_value_t = DEFAULT_DRAWS)]
    pub draws: u64,
    /// High-fidelity links to draw.
    #[arg(long, default_value_t = DEFAULT_HIFI_DRAWS)]
    pub hifi_draws: u64,
    /// Links of each plant the oracle (ideal-knowledge bound) runs on.
    #[arg(long, default_value_t = DEFAULT_ORACLE_DRAWS)]
    pub oracle_draws: u64,
    /// Plants to run.
    #[arg(long, value_enum, default_value_t = PlantChoice::Both)]
    pub plant: PlantChoice,
    /// Target radii per link.
    #[arg(long, default_value_t = DEFAULT_TARGETS)]
    pub targets: usize,
    #[command(flatten)]
    pub common: Common,
    /// Output directory, relative to the workspace root.
    #[arg(long, default_value = "docs")]
    pub out: String,
    /// Run `closed` alone, bending on the TCA's own temperature (`tca_self_bend 1` on a board
    /// that senses current, nothing else calibrated): writes `strategies_self.csv`,
    /// `strategies_self_oracle.csv` and `strategies_self_pareto*.svg`, beside the
    /// thermistor-only run's.
    #[arg(long)]
    pub self_bend: bool,
}

/// The two plants, by the name the CSV and the tables give them.
const LUMPED: &str = "lumped";
/// See [`LUMPED`].
const HIFI: &str = "hifi";

/// What the CSV records of a drawn link.
#[derive(Clone, Copy, Debug)]
struct LinkInfo {
    plant: &'static str,
    draw: u64,
    air: bool,
    h_scale: f64,
    ambient_c: f64,
    supply_v: f64,
    heater_scale: [f64; 2],
    sensor_noise_c: f64,
    /// Lumped: thermistor time constant, s; stiffness and force scales. Hifi: NaN.
    sensor_tau_s: f64,
    stiffness_scale: f64,
    force_scale: f64,
    /// Hifi: PLA glass transition, °C; silicone modulus, kPa; calibration miss (offset, slope).
    /// Lumped: NaN.
    tg_c: f64,
    silicone_kpa: f64,
    miss: (f64, f64),
}

struct Row {
    strategy: Mode,
    target_mm: f32,
    link: LinkInfo,
    result: RunResult,
}

/// The oracle's result for one link and radius.
struct OracleRow {
    plant: &'static str,
    draw: u64,
    target_mm: f32,
    run: Option<oracle::OracleRun>,
}

/// Targets spread over the reachable range, ends 0.2 mm inside.
pub(crate) fn targets(n: usize) -> Vec<f32> {
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

/// What the CSV records of `link`.
fn info(link: &Link) -> Result<LinkInfo, String> {
    Ok(match (&link.body, link.mismatch) {
        (Body::Lumped(_), Some(m)) => LinkInfo {
            plant: LUMPED,
            draw: link.draw,
            air: m.air,
            h_scale: m.h_scale,
            ambient_c: m.ambient_c,
            supply_v: m.supply_v,
            heater_scale: m.heater_scale,
            sensor_noise_c: m.sensor_noise_c,
            sensor_tau_s: m.sensor_tau_s,
            stiffness_scale: m.stiffness_scale,
            force_scale: m.force_scale,
            tg_c: f64::NAN,
            silicone_kpa: f64::NAN,
            miss: (f64::NAN, f64::NAN),
        },
        (Body::Hifi(p), _) => {
            let spec = p.spec();
            let nominal = HifiSpec::nominal(morphlink::link::LINK, Grid::Reduced)
                .map_err(|e| format!("hifi nominal: {e}"))?;
            LinkInfo {
                plant: HIFI,
                draw: link.draw,
                air: link.air,
                h_scale: spec.h_scale,
                ambient_c: spec.ambient_c,
                supply_v: spec.supply_v,
                heater_scale: [
                    spec.pla_heater_ohm / nominal.pla_heater_ohm,
                    spec.tca.r_ref_ohm / nominal.tca.r_ref_ohm,
                ],
                sensor_noise_c: link.noise.sensor_noise_c,
                sensor_tau_s: f64::NAN,
                stiffness_scale: f64::NAN,
                force_scale: f64::NAN,
                tg_c: spec.pla.tg_c,
                silicone_kpa: spec.silicone_e_pa / 1e3,
                miss: spec.calibration_miss,
            }
        }
        (Body::Lumped(_), None) => {
            return Err(format!("{}: a lumped link without its mismatch", link.name))
        }
    })
}

/// One morph on a copy of `link`, bending on the TCA's own temperature where `self_bend`.
fn morph(
    link: &Link,
    target_mm: f32,
    mode: Mode,
    self_bend: bool,
    trace: &mut impl FnMut(&TracePoint),
) -> RunResult {
    fn on<P: morphlink_plant::Plant>(mut rig: Rig<P>, self_bend: bool) -> Rig<P> {
        if self_bend {
            let cal = morphlink::calibration::Calibration {
                tca_self_bend: 1.0,
                ..morphlink::calibration::Calibration::DEFAULT
            };
            rig.ctrl.set_calibration(cal).expect("the flag is in range");
        }
        rig
    }
    let noise = link.noise;
    match &link.body {
        Body::Lumped(p) => run_morph_on(
            on(Rig::with_plant(p.clone(), noise), self_bend),
            target_mm,
            mode,
            trace,
        ),
        Body::Hifi(p) => run_morph_on(
            on(Rig::with_plant((**p).clone(), noise), self_bend),
            target_mm,
            mode,
            trace,
        ),
    }
}

/// The ideal-knowledge morph on a copy of `link`.
fn oracle_on(link: &Link, target_mm: f32) -> Option<oracle::OracleRun> {
    match &link.body {
        Body::Lumped(p) => oracle::best(p, target_mm as f64),
        Body::Hifi(p) => oracle::best(&**p, target_mm as f64),
    }
}

/// Runs the task.
pub fn run(args: &Args, root: &Path) -> Result<(), String> {
    let out = root.join(&args.out);
    std::fs::create_dir_all(&out).map_err(|e| format!("cannot create {}: {e}", out.display()))?;
    let targets = targets(args.targets);
    let (lumped, hifi) = match args.plant {
        PlantChoice::Lumped => (true, false),
        PlantChoice::Hifi => (false, true),
        PlantChoice::Both => (true, true),
    };
    let seed = args.common.seed;
    let mut links: Vec<(Link, LinkInfo)> = Vec::new();
    if lumped {
        for d in 0..args.draws {
            let l = Link::lumped_draw(seed, d);
            let i = info(&l)?;
            links.push((l, i));
        }
    }
    if hifi {
        let draws: Vec<u64> = (0..args.hifi_draws).collect();
        for l in parallel(&draws, args.common.threads, "hifi links built", |&d| {
            Link::hifi_draw(seed, d)
        })? {
            let l = l?;
            let i = info(&l)?;
            links.push((l, i));
        }
    }
    let (stem, strategies): (&str, &[Mode]) = if args.self_bend {
        ("strategies_self", &[Mode::Closed])
    } else {
        ("strategies", &STRATEGIES)
    };
    let mut jobs = Vec::new();
    for (i, _) in links.iter().enumerate() {
        for &t in &targets {
            for &s in strategies {
                jobs.push((i, t, s));
            }
        }
    }
    let rows = parallel(
        &jobs,
        args.common.threads,
        "morphs",
        |&(i, target_mm, strategy)| {
            let (link, info) = &links[i];
            Row {
                strategy,
                target_mm,
                link: *info,
                result: morph(link, target_mm, strategy, args.self_bend, &mut |_| {}),
            }
        },
    )?;
    let mut oracle_jobs = Vec::new();
    for (i, (_, info)) in links.iter().enumerate() {
        if info.draw < args.oracle_draws {
            for &t in &targets {
                oracle_jobs.push((i, t));
            }
        }
    }
    let oracle_rows = parallel(
        &oracle_jobs,
        args.common.threads,
        "oracle morphs",
        |&(i, t)| {
            let (link, info) = &links[i];
            OracleRow {
                plant: info.plant,
                draw: info.draw,
                target_mm: t,
                run: oracle_on(link, t),
            }
        },
    )?;
    write_csv(&out.join(format!("{stem}.csv")), &rows)?;
    write_oracle_csv(&out.join(format!("{stem}_oracle.csv")), &oracle_rows)?;
    let plants: Vec<&'static str> = [(lumped, LUMPED), (hifi, HIFI)]
        .iter()
        .filter(|(on, _)| *on)
        .map(|(_, p)| *p)
        .collect();
    let mut best = None;
    for &plant in &plants {
        let sel: Vec<&Row> = rows.iter().filter(|r| r.link.plant == plant).collect();
        let orc: Vec<&OracleRow> = oracle_rows.iter().filter(|r| r.plant == plant).collect();
        let summary = summarize(&sel, &orc);
        println!("\n## Plant: {plant}\n");
        print!("{}", summary.table);
        let suffix = if plant == HIFI { "" } else { "_lumped" };
        pareto_chart(
            &out.join(format!("{stem}_pareto{suffix}.svg")),
            plant,
            if args.self_bend {
                "closed bending on the TCA's own temperature (uncalibrated), morph time"
            } else {
                "morph time"
            },
            &sel,
            &orc,
            &summary,
        )?;
        best = summary.best;
        if args.self_bend {
            continue;
        }
        let nominal = if plant == HIFI {
            Link::hifi_nominal(false)?
        } else {
            Link::lumped_nominal(false, Mismatch::NONE.sensor_tau_s)
        };
        timeline_chart(
            &out.join(format!("strategies_timeline{suffix}.svg")),
            plant,
            &nominal,
        )?;
        // The headline is the plant that shares the least with the controller (the last).
    }
    println!(
        "wrote {}, {stem}_oracle.csv, {stem}_pareto*.svg{}",
        out.join(format!("{stem}.csv")).display(),
        if args.self_bend {
            ""
        } else {
            ", strategies_timeline*.svg"
        }
    );
    if args.self_bend {
        return Ok(());
    }
    let headline = plants.last().copied().unwrap_or(LUMPED);
    match best {
        Some(b) if b == AUTO_STRATEGY => {
            println!("auto = {} (the chart's choice on the {headline} plant)", b.as_str())
        }
        Some(b) => println!(
            "note: the chart picks {} on the {headline} plant but AUTO_STRATEGY is {}; update src/strategy/mod.rs",
            b.as_str(),
            AUTO_STRATEGY.as_str()
        ),
        None => println!("note: no strategy finished a morph on the {headline} plant"),
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
        "plant,strategy,target_mm,time_s,error_pct,outcome,final_mm,max_pla_c,max_tca_c,medium,h_scale,ambient_c,supply_v,pla_ohm_scale,tca_ohm_scale,sensor_noise_c,sensor_tau_s,stiffness_scale,force_scale,tg_c,silicone_kpa,miss_offset,miss_slope,draw\n",
    );
    for r in rows {
        let m = &r.link;
        let x = &r.result;
        let _ = writeln!(
            s,
            "{},{},{:.2},{:.1},{:.3},{},{:.3},{:.1},{:.1},{},{:.3},{:.2},{:.2},{:.3},{:.3},{:.3},{:.2},{:.4},{:.4},{:.2},{:.1},{:.4},{:.4},{}",
            m.plant,
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
            m.sensor_noise_c,
            m.sensor_tau_s,
            m.stiffness_scale,
            m.force_scale,
            m.tg_c,
            m.silicone_kpa,
            m.miss.0,
            m.miss.1,
            m.draw
        );
    }
    std::fs::write(path, s).map_err(|e| format!("cannot write {}: {e}", path.display()))
}

fn write_oracle_csv(path: &Path, rows: &[OracleRow]) -> Result<(), String> {
    let mut s =
        String::from("plant,target_mm,time_s,final_mm,tca_hold_c,max_pla_c,max_tca_c,draw\n");
    for r in rows {
        let (t, f, h, p, c) = match r.run {
            Some(o) => (
                o.time_s,
                o.final_mm,
                o.tca_hold_c,
                o.max_true_c[0],
                o.max_true_c[1],
            ),
            None => (f64::NAN, f64::NAN, f64::NAN, f64::NAN, f64::NAN),
        };
        let _ = writeln!(
            s,
            "{},{:.2},{:.1},{:.3},{:.2},{:.1},{:.1},{}",
            r.plant, r.target_mm, t, f, h, p, c, r.draw
        );
    }
    std::fs::write(path, s).map_err(|e| format!("cannot write {}: {e}", path.display()))
}

/// Per-strategy statistics over a subset of runs.
#[derive(Clone, Copy, Debug)]
struct Stats {
    runs: usize,
    failed: usize,
    /// Runs that ended in a supervisor trip: every link is healthy, so each is a false alarm.
    false_alarms: usize,
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
    let is_alarm = |r: &&&Row| {
        matches!(r.result.outcome, Outcome::Fault(f)
            if f != morphlink::supervisor::FaultCode::PhaseTimeout)
    };
    Stats {
        runs: rows.len(),
        failed: rows.len() - done.len(),
        false_alarms: rows.iter().filter(is_alarm).count(),
        time_p50_s: percentile(&t, 50.0),
        time_p95_s: percentile(&t, 95.0),
        err_p50_pct: percentile(&e, 50.0),
        err_p95_pct: percentile(&e, 95.0),
        max_pla_c: max(0),
        max_tca_c: max(1),
    }
}

/// Median and 95th-percentile oracle time over some runs, s, and how many were out of reach.
fn oracle_times(rows: &[&OracleRow]) -> (f64, f64, usize) {
    let mut t: Vec<f64> = rows
        .iter()
        .filter_map(|r| r.run.map(|o| o.time_s))
        .filter(|t| t.is_finite())
        .collect();
    t.sort_by(f64::total_cmp);
    let out = rows.len() - t.len();
    (percentile(&t, 50.0), percentile(&t, 95.0), out)
}

struct Summary {
    table: String,
    /// (strategy, water-ensemble stats)
    water: Vec<(Mode, Stats)>,
    best: Option<Mode>,
}

fn summarize(rows: &[&Row], oracle_rows: &[&OracleRow]) -> Summary {
    let mut table = String::from(
        "| strategy | medium | runs | failed | false alarms | time p50 | time p95 | \\|error\\| p50 | \\|error\\| p95 | hottest PLA | hottest TCA |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n",
    );
    let mut water = Vec::new();
    for s in STRATEGIES {
        for (name, air) in [("water", false), ("air", true)] {
            let sel: Vec<&Row> = rows
                .iter()
                .copied()
                .filter(|r| r.strategy == s && r.link.air == air)
                .collect();
            if sel.is_empty() {
                continue;
            }
            let st = stats(&sel);
            let _ = writeln!(
                table,
                "| {} | {} | {} | {} | {} | {:.1} s | {:.1} s | {:.2} % | {:.2} % | {:.1} °C | {:.1} °C |",
                s.as_str(),
                name,
                st.runs,
                st.failed,
                st.false_alarms,
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
    // failures; it is on the Pareto front of the strategies by construction. If none does, the
    // one that fails least, then the one with the smallest p95 error.
    let best = water
        .iter()
        .filter(|(_, st)| st.failed == 0 && st.err_p95_pct < AIM_ERROR_PCT)
        .min_by(|a, b| a.1.time_p95_s.total_cmp(&b.1.time_p95_s))
        .or_else(|| {
            water.iter().min_by(|a, b| {
                a.1.failed
                    .cmp(&b.1.failed)
                    .then(a.1.err_p95_pct.total_cmp(&b.1.err_p95_pct))
            })
        })
        .map(|(s, _)| *s);
    // Per target radius: where the time goes, where the error is, and the bound.
    let _ = writeln!(
        table,
        "\n| strategy | target | time p50 | time p95 | oracle p50 | \\|error\\| p50 | \\|error\\| p95 | failed | false alarms |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- |"
    );
    let mut targets: Vec<f32> = rows.iter().map(|r| r.target_mm).collect();
    targets.sort_by(f32::total_cmp);
    targets.dedup();
    for s in STRATEGIES {
        for &t in &targets {
            let sel: Vec<&Row> = rows
                .iter()
                .copied()
                .filter(|r| r.strategy == s && !r.link.air && r.target_mm == t)
                .collect();
            let st = stats(&sel);
            let orc: Vec<&OracleRow> = oracle_rows
                .iter()
                .copied()
                .filter(|r| {
                    r.target_mm == t && !rows.iter().any(|x| x.link.draw == r.draw && x.link.air)
                })
                .collect();
            let (o50, _, _) = oracle_times(&orc);
            let _ = writeln!(
                table,
                "| {} | {:.2} mm | {:.1} s | {:.1} s | {:.1} s | {:.2} % | {:.2} % | {} | {} |",
                s.as_str(),
                t,
                st.time_p50_s,
                st.time_p95_s,
                o50,
                st.err_p50_pct,
                st.err_p95_pct,
                st.failed,
                st.false_alarms
            );
        }
    }
    // How close the healthy runs came to a residual test's alarm (a run that ended in one is
    // counted as a false alarm above).
    for (i, test) in ["level", "change"].into_iter().enumerate() {
        if let Some(r) = rows
            .iter()
            .max_by(|a, b| a.result.peak_shares[i].total_cmp(&b.result.peak_shares[i]))
        {
            let _ = writeln!(
                table,
                "\nFullest {test} test over these runs: {:.2} of its limit ({} {} mm, {}).",
                r.result.peak_shares[i],
                r.strategy.as_str(),
                r.target_mm,
                if r.link.air { "air" } else { "water" }
            );
        }
    }
    let (o50, o95, out) = oracle_times(oracle_rows);
    let _ = writeln!(
        table,
        "\nOracle (ideal knowledge, same caps and limits) over {} runs: time p50 {:.1} s, p95 {:.1} s; {} out of its reach.",
        oracle_rows.len(),
        o50,
        o95,
        out
    );
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

/// Errors above this are drawn at it (the title says how many), %.
const PARETO_ERROR_CLIP_PCT: f64 = 10.0;

/// `bent_on` names what the chart is of (`morph time`, or the one strategy it shows).
fn pareto_chart(
    path: &Path,
    plant: &str,
    bent_on: &str,
    rows: &[&Row],
    oracle_rows: &[&OracleRow],
    summary: &Summary,
) -> Result<(), String> {
    let done = |r: &&&Row| r.result.outcome == Outcome::Done;
    let e_max = rows
        .iter()
        .filter(done)
        .map(|r| r.result.error_pct.abs())
        .fold(AIM_ERROR_PCT * 1.5, f64::max)
        .min(PARETO_ERROR_CLIP_PCT);
    let clipped = rows
        .iter()
        .filter(done)
        .filter(|r| r.result.error_pct.abs() > e_max)
        .count();
    let title = format!(
        "{plant} plant: {bent_on} vs final radius error (water: dots, air: crosses; triangles: p95 of water runs; black crosses: oracle)"
    );
    let mut notes = vec![format!(
        "{clipped} runs with an error above {e_max:.0} % are drawn as arrows pointing up from the top edge"
    )];
    notes.extend(
        not_drawn_note(rows)
            .split(" (")
            .enumerate()
            .map(|(i, part)| {
                if i == 0 {
                    part.to_string()
                } else {
                    format!("    ({part}")
                }
            }),
    );
    Ok(plot::write_svg(path, (1000, 660), |root| {
        let (root, foot) = root.split_vertically(600);
        for (i, n) in notes.iter().enumerate() {
            foot.draw_text(
                n,
                &("sans-serif", 13).into_font().color(&BLACK),
                (60, 4 + 18 * i as i32),
            )?;
        }
        let mut chart = Frame::new(14, 12, 45, 60)
            .builder(&root, Some(&title))
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
                    .filter(move |r| r.strategy == s && r.link.air == air)
                    .filter(move |r| r.result.error_pct.abs() <= e_max)
                    .map(|r| (r.result.time_s, r.result.error_pct.abs()))
            };
            chart
                .draw_series(pts(false).map(|p| Circle::new(p, 2, c.mix(0.45).filled())))?
                .label(s.as_str())
                .legend(move |(x, y)| Circle::new((x + 8, y), 4, c.filled()));
            chart.draw_series(pts(true).map(|p| Cross::new(p, 3, c.mix(0.6))))?;
            // Runs off the top of the chart: an arrow pointing up from the top edge, not a dot
            // that reads as an error of exactly the clip.
            let above = rows
                .iter()
                .filter(done)
                .filter(|r| r.strategy == s && r.result.error_pct.abs() > e_max)
                .map(|r| (r.result.time_s, e_max));
            chart.draw_series(above.map(|p| {
                EmptyElement::at(p)
                    + PathElement::new(vec![(0, 10), (0, 1)], c.stroke_width(2))
                    + PathElement::new(vec![(-4, 5), (0, 1), (4, 5)], c.stroke_width(2))
            }))?;
        }
        for (s, st) in &summary.water {
            chart.draw_series(std::iter::once(TriangleMarker::new(
                (st.time_p95_s, st.err_p95_pct.min(e_max)),
                9,
                colour(*s).filled(),
            )))?;
        }
        let oracle_pts: Vec<(f64, f64)> = oracle_rows
            .iter()
            .filter_map(|r| {
                let o = r.run?;
                let err = ((o.final_mm - r.target_mm as f64) / r.target_mm as f64 * 100.0).abs();
                o.time_s.is_finite().then_some((o.time_s, err.min(e_max)))
            })
            .collect();
        chart
            .draw_series(
                oracle_pts
                    .iter()
                    .map(|&p| Cross::new(p, 5, BLACK.stroke_width(2))),
            )?
            .label("oracle (ideal knowledge)")
            .legend(|(x, y)| Cross::new((x + 8, y), 4, BLACK.stroke_width(2)));
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

/// The runs a chart of finished morphs leaves out, by strategy and outcome: `not drawn: N runs
/// that did not finish (boost: 2 tca-overheat, 1 stuck; ...)`, or that none are left out.
fn not_drawn_note(rows: &[&Row]) -> String {
    let mut parts = Vec::new();
    let mut total = 0;
    for s in STRATEGIES {
        let mut counts: Vec<(&str, usize)> = Vec::new();
        for r in rows.iter().filter(|r| r.strategy == s) {
            let what = match r.result.outcome {
                Outcome::Done => continue,
                Outcome::Fault(f) => f.as_str(),
                Outcome::Stuck => "stuck",
            };
            total += 1;
            match counts.iter_mut().find(|(w, _)| *w == what) {
                Some((_, n)) => *n += 1,
                None => counts.push((what, 1)),
            }
        }
        if !counts.is_empty() {
            let c: Vec<String> = counts.iter().map(|(w, n)| format!("{n} {w}")).collect();
            parts.push(format!("{}: {}", s.as_str(), c.join(", ")));
        }
    }
    if total == 0 {
        "every run finished: none left out".to_string()
    } else {
        format!(
            "not drawn: {total} runs that did not finish, listed in strategies.csv ({})",
            parts.join("; ")
        )
    }
}

fn timeline_chart(path: &Path, plant: &str, link: &Link) -> Result<(), String> {
    Ok(plot::write_svg(path, (1000, 1100), |root| {
        let panels = root.split_evenly((STRATEGIES.len(), 1));
        let frame = Frame::new(16, 8, 30, 50).right_y(50);
        for (s, area) in STRATEGIES.iter().zip(panels.iter()) {
            let mut trace: Vec<TracePoint> = Vec::new();
            // The nominal board's noise on both plants, so the two time plots differ only in
            // the plant.
            let link = Link {
                noise: Mismatch::NONE.plant().noise(),
                ..link.clone()
            };
            let r = morph(&link, TIMELINE_TARGET_MM, *s, false, &mut |p| {
                trace.push(*p)
            });
            let t_end = trace.last().map(|p| p.t_s).unwrap_or(1.0);
            let title = format!(
                "{plant} plant, {}: MORPH {} mm, {} at {:.1} s, final {:.2} mm ({:+.2} %)",
                s.as_str(),
                TIMELINE_TARGET_MM,
                outcome_str(r.outcome),
                if r.outcome == Outcome::Done {
                    r.time_s
                } else {
                    trace.last().map_or(f64::NAN, |p| p.t_s)
                },
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
    fn targets_span_the_range_inside_its_ends() {
        let (min, max) = table::range_mm();
        let t = targets(5);
        assert_eq!(t.len(), 5);
        assert!((t[0] - (min + 0.2)).abs() < 1e-4 && (t[4] - (max - 0.2)).abs() < 1e-4);
    }
}
