//! `cargo xtask limits`: do the settings' ranges keep the rod and the TCA under their limits?
//! Every strategy morphs every link of the hifi ensemble, in its drawn medium and again in
//! still air, and the nominal lumped link in water and still air, under each corner of the
//! settings that steer a heater ([`corners`]: the PLA target, the model's convection, the
//! thermistors' shares, the soft threshold and the phase timeouts at their ends, each alone
//! and the worst together). For each run it records the plant's true peak temperatures (the
//! PLA rod's and the TCA's means) against the 130 °C limits, the thermistors' peaks, and how
//! the run ended. Prints the worst per corner (the table of docs/safety.md, "True limits") and
//! fails if any run's true peak passes a limit by more than [`OVERSHOOT_ALLOWED_K`] (the heat
//! already in the parts when the supervisor cuts them) or any healthy run at the default
//! settings alarms. `--trace FILE` writes every run's readings and truths, one row each 0.5 s.

use crate::ensemble::{parallel, Common, Link};
use morphlink::protocol::{classify, client::Status, LineKind};
use morphlink::settings::Settings;
use morphlink::supervisor::{PLA_LIMITS, TCA_LIMITS};
use morphlink::table;
use morphlink_plant::Plant;
use morphlink_sim::ensemble::{Mismatch, TICKS_PER_S};
use morphlink_sim::Rig;
use std::fmt::Write as _;

/// Strategies run.
pub const MODES: [&str; 4] = ["paper", "gated", "boost", "closed"];
/// Longest a morph runs, s: past the longest phase timeouts the ranges allow.
pub const MORPH_MAX_S: u64 = 2_000;
/// How far a true peak may pass its limit, K: the supervisor stops a heater once its estimate
/// of the part reaches the limit; the heat already in the part and in its wrap carries the mean
/// on for a moment after the cut.
pub const OVERSHOOT_ALLOWED_K: f64 = 0.0;
/// Rows of the trace: one every this many ticks (0.5 s).
pub const TRACE_EVERY_TICKS: u64 = 5;

/// Options of the task.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// High-fidelity ensemble links to draw (the strategy charts' draws).
    #[arg(long, default_value_t = 12)]
    pub hifi_draws: u64,
    #[command(flatten)]
    pub common: Common,
    /// Only the default settings (no corners).
    #[arg(long)]
    pub defaults_only: bool,
    /// Write every run's readings and true temperatures to this CSV.
    #[arg(long)]
    pub trace: Option<std::path::PathBuf>,
}

/// A named corner of the settings: the CONFIG SET lines that make it.
#[derive(Clone, Debug)]
pub struct Corner {
    /// Its name in the table.
    pub name: String,
    /// The `CONFIG SET` lines.
    pub lines: Vec<String>,
}

/// The range `CONFIG` prints for `name` at the defaults (a calibration field's narrowed to
/// what the other fields allow, [`Settings::live`]).
fn spec_range(name: &str) -> (f32, f32) {
    Settings::DEFAULT
        .find(name)
        .map(|(_, s)| (s.min, s.max))
        .unwrap_or_else(|| panic!("no setting {name}"))
}

/// The corners: each heater-steering setting at each end of its range, and the hottest
/// combination (PLA target at its top, the weakest shares and the longest timeouts).
pub fn corners(defaults_only: bool) -> Vec<Corner> {
    let set = |name: &str, v: f32| format!("CONFIG SET {name} {v}");
    let mut v = vec![Corner {
        name: "defaults".into(),
        lines: vec![],
    }];
    if defaults_only {
        return v;
    }
    let ends = |name: &str| {
        let (lo, hi) = spec_range(name);
        [
            (format!("{name} {lo}"), set(name, lo)),
            (format!("{name} {hi}"), set(name, hi)),
        ]
    };
    for name in [
        "pla_soft_target_c",
        "convection_w_m2k",
        "soft_threshold_c",
        "lock_timeout_s",
    ] {
        for (n, l) in ends(name) {
            v.push(Corner {
                name: n,
                lines: vec![l],
            });
        }
    }
    let top = spec_range("pla_soft_target_c").1;
    for h in [
        spec_range("convection_w_m2k").0,
        spec_range("convection_w_m2k").1,
    ] {
        v.push(Corner {
            name: format!("pla_soft_target_c {top}, convection_w_m2k {h}"),
            lines: vec![set("pla_soft_target_c", top), set("convection_w_m2k", h)],
        });
    }
    v
}

/// The links: the nominal lumped and hifi ones in water and still air, and the first hifi
/// draws in their drawn medium and again in still air.
fn links(a: &Args) -> Result<Vec<Link>, String> {
    let mut v: Vec<Link> = Vec::new();
    for air in [false, true] {
        v.push(Link::lumped_nominal(air, Mismatch::NONE.sensor_tau_s));
    }
    for air in [false, true] {
        v.push(Link::hifi_nominal(air)?);
    }
    for d in 0..a.hifi_draws {
        v.push(Link::hifi_draw(a.common.seed, d)?);
        v.extend(Link::hifi_draw_in_air(a.common.seed, d)?);
    }
    Ok(v)
}

/// What one run showed.
#[derive(Clone, Debug, Default)]
struct Peaks {
    /// True peaks (PLA rod mean, TCA mean), °C.
    true_c: [f64; 2],
    /// Thermistor peaks (PLA, TCA), °C.
    bead_c: [f32; 2],
    /// How it ended: `done`, an alarm's code, `refused` or `unfinished`.
    end: String,
    /// Trace rows, if asked for.
    trace: String,
}

fn run_one(
    mut rig: Rig<Box<dyn Plant>>,
    corner: &Corner,
    mode: &str,
    r_mm: f32,
    id: usize,
    trace: bool,
) -> Peaks {
    let mut p = Peaks {
        true_c: [f64::NEG_INFINITY; 2],
        bead_c: [f32::NEG_INFINITY; 2],
        ..Peaks::default()
    };
    for _ in 0..20 {
        rig.tick();
        rig.drain_events(&mut |_| {});
    }
    for l in &corner.lines {
        let mut reply = String::new();
        rig.handle_line(l, &mut |r| reply = r.to_string());
        if !reply.starts_with("ok") {
            p.end = format!("refused {l}: {reply}");
            return p;
        }
    }
    let mut reply = String::new();
    rig.handle_line(&format!("MORPH {r_mm} {mode}"), &mut |r| {
        reply = r.to_string()
    });
    if reply != "ok" {
        p.end = format!("refused: {reply}");
        return p;
    }
    let mut end: Option<String> = None;
    for tick in 0..MORPH_MAX_S * TICKS_PER_S {
        rig.tick();
        rig.drain_events(&mut |l: &str| {
            if end.is_none() && classify(l) == LineKind::Alarm {
                end = l
                    .strip_prefix("alarm: ")
                    .and_then(|r| r.split(' ').take(2).reduce(|_, b| b).map(|_| r))
                    .map(|r| r.split(' ').take(2).collect::<Vec<_>>().join(" "));
            }
        });
        let t = rig.plant().truth();
        p.true_c = [p.true_c[0].max(t.pla_c), p.true_c[1].max(t.tca_c)];
        let m = rig.ctrl.measurements();
        p.bead_c = [p.bead_c[0].max(m.t_pla_c), p.bead_c[1].max(m.t_tca_c)];
        if trace && tick % TRACE_EVERY_TICKS == 0 {
            let _ = writeln!(
                p.trace,
                "{id},{:.1},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{}",
                tick as f64 / TICKS_PER_S as f64,
                m.t_pla_c,
                m.t_tca_c,
                m.t_amb_c,
                t.pla_c,
                t.tca_c,
                rig.ctrl.powers().pla_w,
                rig.ctrl.powers().tca_w,
                rig.ctrl.phase().as_str(),
            );
        }
        if !rig.ctrl.busy() {
            break;
        }
    }
    p.end = match end {
        Some(a) => a,
        None if rig.ctrl.busy() => "unfinished".into(),
        None => "done".into(),
    };
    // Status parse keeps the client classifier in use (one home of the wire text).
    let _ = Status::parse("ok phase=idle");
    p
}

/// Runs the task.
pub fn run(args: &Args) -> Result<(), String> {
    let links = links(args)?;
    let corners = corners(args.defaults_only);
    let (min, max) = table::range_mm();
    let radii = [min + 0.2, 0.5 * (min + max)];
    let mut jobs = Vec::new();
    for c in 0..corners.len() {
        for l in 0..links.len() {
            for m in MODES {
                for r in radii {
                    jobs.push((c, l, m, r));
                }
            }
        }
    }
    let trace = args.trace.is_some();
    let results = parallel(&jobs, args.common.threads, "morphs", |&(c, l, m, r)| {
        let id = jobs
            .iter()
            .position(|j| j.0 == c && j.1 == l && j.2 == m && j.3 == r)
            .unwrap_or(0);
        run_one(links[l].rig(), &corners[c], m, r, id, trace)
    })?;
    if let Some(path) = &args.trace {
        let mut s =
            String::from("run,t_s,pla_c,tca_c,amb_c,true_pla_c,true_tca_c,p_pla_w,p_tca_w,phase\n");
        for r in &results {
            s.push_str(&r.trace);
        }
        let mut idx = String::from(
            "run,corner,link,mode,radius_mm,end,true_pla_c,true_tca_c,bead_pla_c,bead_tca_c\n",
        );
        for (i, ((c, l, m, r), p)) in jobs.iter().zip(&results).enumerate() {
            let _ = writeln!(
                idx,
                "{i},{},{},{m},{r:.2},{},{:.1},{:.1},{:.1},{:.1}",
                corners[*c].name,
                links[*l].name,
                p.end,
                p.true_c[0],
                p.true_c[1],
                p.bead_c[0],
                p.bead_c[1]
            );
        }
        std::fs::write(path, s).map_err(|e| format!("{}: {e}", path.display()))?;
        let runs = path.with_extension("runs.csv");
        std::fs::write(&runs, idx).map_err(|e| format!("{}: {e}", runs.display()))?;
    }
    println!("| settings | runs | true PLA peak, °C | true TCA peak, °C | over a limit | alarms | other ends |");
    println!("| --- | --- | --- | --- | --- | --- | --- |");
    let mut failures = Vec::new();
    for (c, corner) in corners.iter().enumerate() {
        let rows: Vec<_> = jobs
            .iter()
            .zip(&results)
            .filter(|(j, _)| j.0 == c)
            .collect();
        let worst = |k: usize| {
            rows.iter()
                .max_by(|a, b| a.1.true_c[k].total_cmp(&b.1.true_c[k]))
                .map(|(j, p)| {
                    (
                        p.true_c[k],
                        format!("{} {} {:.2}", links[j.1].name, j.2, j.3),
                    )
                })
                .unwrap_or((f64::NAN, String::new()))
        };
        let (wp, wp_at) = worst(0);
        let (wt, wt_at) = worst(1);
        // A corner every run refused has no peak.
        let peak = |c: f64, at: &str| {
            if c.is_finite() {
                format!("{c:.1} ({at})")
            } else {
                "none".to_string()
            }
        };
        let over: Vec<_> = rows
            .iter()
            .filter(|(_, p)| {
                p.true_c[0] > PLA_LIMITS.max_c as f64 + OVERSHOOT_ALLOWED_K
                    || p.true_c[1] > TCA_LIMITS.max_c as f64 + OVERSHOOT_ALLOWED_K
            })
            .collect();
        let alarms = rows
            .iter()
            .filter(|(_, p)| {
                p.end != "done" && !p.end.starts_with("refused") && p.end != "unfinished"
            })
            .count();
        let mut codes: std::collections::BTreeMap<&str, usize> = Default::default();
        for (_, p) in &rows {
            if p.end != "done" {
                *codes.entry(p.end.as_str()).or_default() += 1;
            }
        }
        let codes: Vec<String> = codes.iter().map(|(k, v)| format!("{k} ×{v}")).collect();
        println!(
            "| {} | {} | {} | {} | {} | {alarms} | {} |",
            corner.name,
            rows.len(),
            peak(wp, &wp_at),
            peak(wt, &wt_at),
            over.len(),
            codes.join(", ")
        );
        for (j, p) in &over {
            failures.push(format!(
                "{}: {} {} {:.2}: true peaks {:.1} / {:.1} °C ({})",
                corner.name, links[j.1].name, j.2, j.3, p.true_c[0], p.true_c[1], p.end
            ));
        }
    }
    if failures.is_empty() {
        Ok(())
    } else {
        Err(format!(
            "{} runs past a limit:\n{}",
            failures.len(),
            failures.join("\n")
        ))
    }
}
