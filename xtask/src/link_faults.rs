//! `cargo xtask link-faults`: a fault on one link of several. Four links of the hifi ensemble
//! (`gait`'s, in water) run `GAIT 34 38 42 46` on one bench supply under a budget; each of
//! the faults that belong to one link (`cargo xtask faults`' cases on the PLA and TCA
//! thermistors and heaters, and a stuck cut-off) is injected on link 2 as it enters each phase
//! of its morph. The ambient thermistor and the supply are shared: `tests/links.rs` holds that
//! they stop every link. Prints, per fault and phase, link 2's time from injection to its alarm
//! among the others beside the same link's time alone (the same plant, noise, target and
//! phase; today's detection times), and whether the other three links finished their morphs
//! with no alarm. Fails if another link alarms or does not finish, or if a fault caught alone
//! is not caught among the others. How much later it is caught is printed, not judged: a drift
//! is judged against the heat its link gets, and the budget's queue changes when that is
//! (docs/multilink.md, "A fault on one link").

use crate::ensemble::{parallel, Common};
use crate::faults::{cases, run_case, FaultCase, TARGET_MM};
use crate::gait::{links, Medium};
use morphlink::protocol::{classify, LineKind};
use morphlink::vocab::Phase;
use morphlink_plant::hifi::Hifi;
use morphlink_plant::{Plant, Setting};
use morphlink_sim::{MultiRig, Rig, SharedSupply};
use std::fmt::Write as _;

/// The gait's targets, mm: link 2's is `faults`' [`TARGET_MM`], so its morph alone is the one
/// the detection-time table runs.
pub const TARGETS_MM: [f32; 4] = [34.0, TARGET_MM, 42.0, 46.0];
/// The link the faults are injected on (index: link 2).
pub const FAULTED: usize = 1;
/// Longest wait for link 2's alarm after injection, s (as `faults`).
pub const MAX_WAIT_S: u64 = 600;
/// Longest wait for the other links to finish after injection, s.
pub const FINISH_MAX_S: u64 = 2_000;

/// Options of the task.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The shared budget, W (0: none).
    #[arg(long, default_value_t = 8.0)]
    pub budget_w: f32,
    /// The bench supply's current limit, A.
    #[arg(long, default_value_t = 3.0)]
    pub limit_a: f32,
    #[command(flatten)]
    pub common: Common,
}

/// What one run among the others gave.
struct Shared {
    /// Seconds from injection to link 2's first alarm, and the alarm's first words.
    alarm: Option<(f64, String)>,
    /// Alarms of the other links.
    others_alarmed: Vec<String>,
    /// Other links that did not end `done`.
    others_unfinished: Vec<usize>,
}

/// The alarm's code and subject, as `faults` names them.
fn code_of(line: &str) -> String {
    let rest = line.split_once("alarm: ").map_or(line, |(_, r)| r);
    let words: Vec<&str> = rest.split(' ').collect();
    let nth = if words.first() == Some(&"phase-timeout") {
        2
    } else {
        1
    };
    format!(
        "{} {}",
        words.first().unwrap_or(&"?"),
        words.get(nth).unwrap_or(&"?")
    )
}

fn among_others(
    plants: &[Hifi],
    noise: morphlink::bench::Noise,
    case: &FaultCase,
    phase: Phase,
    a: &Args,
) -> Shared {
    let supply = SharedSupply {
        limit_a: a.limit_a as f64,
        ..SharedSupply::STIFF
    };
    let mut rig = MultiRig::new(plants.iter().cloned(), noise, supply);
    rig.boot(1000);
    let say = |rig: &mut MultiRig<Hifi>, l: &str| {
        let mut reply = String::new();
        rig.handle_line(l, &mut |r: &str| reply = r.to_string());
        reply
    };
    say(
        &mut rig,
        &format!("CONFIG SET supply_limit_a {}", a.limit_a),
    );
    say(
        &mut rig,
        &format!("CONFIG SET supply_budget_w {}", a.budget_w),
    );
    let gait = TARGETS_MM.map(|t| t.to_string()).join(" ");
    say(&mut rig, &format!("GAIT {gait}"));
    let mut out = Shared {
        alarm: None,
        others_alarmed: Vec::new(),
        others_unfinished: Vec::new(),
    };
    let mut done = [false; 4];
    let mut seen = |rig: &mut MultiRig<Hifi>, t0: Option<u64>, out: &mut Shared| {
        let now = rig.now_ms();
        rig.drain_events(&mut |l: &str| {
            let k = l
                .strip_prefix('@')
                .and_then(|r| r.split(' ').next())
                .and_then(|n| n.parse::<usize>().ok())
                .map_or(0, |n| n - 1);
            if classify(l.split_once(' ').map_or(l, |(_, r)| r)) == LineKind::Done {
                done[k] = true;
            }
            if l.contains("alarm:") {
                if k == FAULTED {
                    if let (None, Some(t0)) = (&out.alarm, t0) {
                        out.alarm = Some(((now - t0) as f64 / 1000.0, code_of(l)));
                    }
                } else {
                    out.others_alarmed.push(l.to_string());
                }
            }
        });
    };
    let end = rig.now_ms() + 300_000;
    while rig.links.link(FAULTED).phase() != phase && rig.now_ms() < end {
        rig.tick();
        seen(&mut rig, None, &mut out);
    }
    for _ in 0..5 {
        rig.tick();
    }
    seen(&mut rig, None, &mut out);
    say(&mut rig, &format!("@{} {}", FAULTED + 1, case.line));
    if case.line == "SIM FAULT cutoff-stuck" {
        say(
            &mut rig,
            &format!("@{} SIM FAULT heater-stuck tca", FAULTED + 1),
        );
    }
    let t0 = rig.now_ms();
    while rig.now_ms() - t0 < FINISH_MAX_S * 1000 {
        rig.tick();
        seen(&mut rig, Some(t0), &mut out);
        let others_idle = (0..4).all(|k| k == FAULTED || !rig.links.link(k).busy());
        let waited = rig.now_ms() - t0 >= MAX_WAIT_S * 1000;
        if others_idle && (out.alarm.is_some() || waited) {
            break;
        }
    }
    out.others_unfinished = (0..4)
        .filter(|&k| k != FAULTED && !done[k])
        .map(|k| k + 1)
        .collect();
    out
}

/// Runs the task: prints the table of docs/multilink.md, "A fault on one link".
pub fn run(a: &Args) -> Result<(), String> {
    let (plants, noise) = links(4, Medium::Water)?;
    let cases: Vec<FaultCase> = cases(false)
        .into_iter()
        .filter(|c| !c.line.contains(" amb") && !c.line.starts_with("SIM SUPPLY"))
        .collect();
    let phases = [Phase::Soften, Phase::Bend, Phase::Lock, Phase::Release];
    let jobs: Vec<(usize, Phase)> = (0..cases.len())
        .flat_map(|c| phases.iter().map(move |&p| (c, p)))
        .collect();
    let alone_noise = morphlink::bench::Noise {
        seed: noise.seed.wrapping_add(0x9e37_79b9 * FAULTED as u64),
        ..noise
    };
    let rows = parallel(&jobs, a.common.threads, "faulted gaits", |&(c, p)| {
        let mut plant = plants[FAULTED].clone();
        let _ = plant.set(Setting::SupplyV(SharedSupply::STIFF.open_v));
        let alone = run_case(
            Rig::with_plant(plant, alone_noise),
            &cases[c],
            p,
            "auto",
            false,
        );
        (alone.alarm, among_others(&plants, noise, &cases[c], p, a))
    })?;
    let mut t = String::new();
    let _ = writeln!(t, "| fault on link 2 | its phase | alone: time to alarm, alarm | among three others ({} W, {} A) | later by | the others |", a.budget_w, a.limit_a);
    let _ = writeln!(t, "| --- | --- | --- | --- | --- | --- |");
    let mut failures = Vec::new();
    let fmt = |o: &Option<(f64, String)>| match o {
        Some((s, code)) => format!("{s:.1} s, {code}"),
        None => format!("none in {MAX_WAIT_S} s"),
    };
    for (&(c, p), (alone, shared)) in jobs.iter().zip(&rows) {
        let what = format!("{} in {}", cases[c].name, p.as_str());
        // A stuck cut-off whose current the budget cannot hold beside the others stops them
        // all, each saying what flows (docs/multilink.md); nothing else may stop them.
        let stopped_by_the_stray = cases[c].line == "SIM FAULT cutoff-stuck"
            && !shared.others_alarmed.is_empty()
            && shared
                .others_alarmed
                .iter()
                .all(|l| l.contains("alarm: cutoff-failed "));
        let others = if shared.others_alarmed.is_empty() && shared.others_unfinished.is_empty() {
            "all done, no alarm".to_string()
        } else if stopped_by_the_stray {
            format!(
                "links {:?} stopped: cutoff-failed (the stray over the budget)",
                shared.others_unfinished
            )
        } else {
            failures.push(format!(
                "{what}: other links alarmed {:?}, did not finish {:?}",
                shared.others_alarmed, shared.others_unfinished
            ));
            format!(
                "{} alarms, links {:?} not done",
                shared.others_alarmed.len(),
                shared.others_unfinished
            )
        };
        if let (Some(_), None) = (alone, &shared.alarm) {
            failures.push(format!("{what}: caught alone, not among the others"));
        }
        let later = match (alone, &shared.alarm) {
            (Some((s_alone, _)), Some((s_shared, _))) => format!("{:+.1} s", s_shared - s_alone),
            _ => "-".into(),
        };
        let _ = writeln!(
            t,
            "| {} | {} | {} | {} | {later} | {others} |",
            cases[c].name,
            p.as_str(),
            fmt(alone),
            fmt(&shared.alarm)
        );
    }
    print!("{t}");
    if failures.is_empty() {
        Ok(())
    } else {
        Err(failures.join("\n"))
    }
}
