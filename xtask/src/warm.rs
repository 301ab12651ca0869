//! `cargo xtask warm`: does a morph from a warm link land as well as one from rest? On each
//! link of the hifi ensemble (its drawn medium) and the nominal lumped link, every ordered pair
//! of the strategy charts' targets is morphed back to back (the second MORPH sent the moment
//! the first reports `done`), and the second morph's final radius (after 60 s of rest, spring
//! back included) is compared with the same morph from a rested link. Prints, per plant, how
//! much worse a warm start lands (|error| warm − |error| from rest, percentage points) and fails
//! if any pair is worse by more than [`WARM_AIM_PP`]. `auto` runs (`closed`).

use crate::ensemble::{parallel, quantile, Common, Link};
use morphlink::protocol::{classify, LineKind};
use morphlink::table;
use morphlink_plant::Plant;
use morphlink_sim::ensemble::{Mismatch, TICKS_PER_S};
use morphlink_sim::Rig;

/// The aim, percentage points: a warm start lands no worse than this against the same morph
/// from rest.
pub const WARM_AIM_PP: f64 = 0.5;
/// Rest after a morph before its radius is read, s: the TCA cools and the link springs back.
pub const SETTLE_S: u64 = 60;
/// Longest a morph runs, s (its rest and every phase to its timeout).
pub const MORPH_MAX_S: u64 = 1_700;

/// Options of the task.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// High-fidelity ensemble links to draw (the strategy charts' first draws).
    #[arg(long, default_value_t = 12)]
    pub hifi_draws: u64,
    #[command(flatten)]
    pub common: Common,
}

/// The links: the nominal lumped one and the first hifi draws, each in its drawn medium.
fn links(a: &Args) -> Result<Vec<Link>, String> {
    let mut v = vec![Link::lumped_nominal(false, Mismatch::NONE.sensor_tau_s)];
    for d in 0..a.hifi_draws {
        v.push(Link::hifi_draw(a.common.seed, d)?);
    }
    Ok(v)
}

/// Morphs `rig` to `r_mm` in auto: seconds from `MORPH` to its end (a rest included);
/// `None` unless it ends `done` with no alarm.
fn morph(rig: &mut Rig<Box<dyn Plant>>, r_mm: f32) -> Option<f64> {
    let t0 = rig.now_ms();
    let mut reply = String::new();
    rig.handle_line(&format!("MORPH {r_mm}"), &mut |l| reply = l.to_string());
    if reply != "ok" {
        return None;
    }
    let mut ok = true;
    for _ in 0..MORPH_MAX_S * TICKS_PER_S {
        rig.tick();
        rig.drain_events(&mut |l: &str| {
            if classify(l) == LineKind::Alarm {
                ok = false;
            }
        });
        if !rig.ctrl.busy() {
            break;
        }
    }
    (ok && !rig.ctrl.busy()).then_some((rig.now_ms() - t0) as f64 / 1000.0)
}

/// The final radius error of a morph to `to_mm` (after [`SETTLE_S`]), %, and its time (from
/// `MORPH` to its end, a rest included), s: from rest, or right after a morph to `from_mm`.
/// `None` if a morph did not end `done`.
fn error_pct(link: &Link, from_mm: Option<f32>, to_mm: f32) -> Option<(f64, f64)> {
    let mut rig = link.rig();
    for _ in 0..2 * TICKS_PER_S {
        rig.tick();
        rig.drain_events(&mut |_| {});
    }
    if let Some(f) = from_mm {
        morph(&mut rig, f)?;
    }
    let time_s = morph(&mut rig, to_mm)?;
    for _ in 0..SETTLE_S * TICKS_PER_S {
        rig.tick();
        rig.drain_events(&mut |_| {});
    }
    Some((
        (rig.radius_mm() - to_mm as f64) / to_mm as f64 * 100.0,
        time_s,
    ))
}

/// Runs the task.
pub fn run(args: &Args) -> Result<(), String> {
    let links = links(args)?;
    let (min, max) = table::range_mm();
    let targets: Vec<f32> = (0..5)
        .map(|i| (min + 0.2) + (max - min - 0.4) * i as f32 / 4.0)
        .collect();
    let mut jobs: Vec<(usize, Option<f32>, f32)> = Vec::new();
    for l in 0..links.len() {
        for &b in &targets {
            jobs.push((l, None, b));
            for &a in &targets {
                if a != b {
                    jobs.push((l, Some(a), b));
                }
            }
        }
    }
    let results = parallel(&jobs, args.common.threads, "morphs", |&(l, a, b)| {
        error_pct(&links[l], a, b)
    })?;
    let rest = |l: usize, b: f32| {
        jobs.iter()
            .zip(&results)
            .find(|(j, _)| j.0 == l && j.1.is_none() && j.2 == b)
            .and_then(|(_, e)| *e)
    };
    println!("| plant | pairs | failed | worse than from rest, p50 | p95 | worst | over {WARM_AIM_PP} pp | time warm, p50 / p95 | from rest |");
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    let mut over = Vec::new();
    for hifi in [true, false] {
        let mut worse: Vec<(f64, String)> = Vec::new();
        let (mut warm_s, mut rest_s) = (Vec::new(), Vec::new());
        let mut failed = 0;
        for (j, e) in jobs.iter().zip(&results) {
            let (l, Some(a), b) = *j else { continue };
            if links[l].is_hifi() != hifi {
                continue;
            }
            match (e, rest(l, b)) {
                (Some((w, ws)), Some((r, rs))) => {
                    warm_s.push(*ws);
                    rest_s.push(rs);
                    let pp = w.abs() - r.abs();
                    let what = format!(
                        "{} {a:.2} -> {b:.2} mm: {w:+.2} % warm, {r:+.2} % from rest",
                        links[l].name
                    );
                    if pp > WARM_AIM_PP {
                        over.push(what.clone());
                    }
                    worse.push((pp, what));
                }
                (w, r) => {
                    failed += 1;
                    eprintln!(
                        "not compared: {} {a:.2} -> {b:.2} mm (warm {}, from rest {})",
                        links[l].name,
                        if w.is_some() { "done" } else { "failed" },
                        if r.is_some() { "done" } else { "failed" },
                    );
                }
            }
        }
        worse.sort_by(|x, y| x.0.total_cmp(&y.0));
        let q = |p: f64| {
            worse
                .get(((worse.len() as f64 - 1.0) * p).round() as usize)
                .map_or(f64::NAN, |w| w.0)
        };
        let n_over = worse.iter().filter(|w| w.0 > WARM_AIM_PP).count();
        println!(
            "| {} | {} | {failed} | {:+.2} pp | {:+.2} pp | {:+.2} pp ({}) | {n_over} | {:.0} / {:.0} s | {:.0} / {:.0} s |",
            if hifi { "hifi" } else { "lumped" },
            worse.len(),
            q(0.5),
            q(0.95),
            q(1.0),
            worse.last().map_or("", |w| w.1.as_str()),
            quantile(&mut warm_s, 0.5),
            quantile(&mut warm_s, 0.95),
            quantile(&mut rest_s, 0.5),
            quantile(&mut rest_s, 0.95),
        );
    }
    if over.is_empty() {
        Ok(())
    } else {
        Err(format!(
            "{} warm morphs land more than {WARM_AIM_PP} pp worse than from rest:\n{}",
            over.len(),
            over.join("\n")
        ))
    }
}
