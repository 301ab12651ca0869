//! `cargo xtask faults`: the fault detection-time table. Every injectable fault (`SIM FAULT`
//! kinds per sensor and heater, `SIM SUPPLY` out of range) in every phase of a morph to
//! [`TARGET_MM`] on the nominal hifi link (the headline) and the nominal lumped link beside it:
//! the time from injection to the first alarm, the alarm, and the peak TRUE temperatures of
//! the PLA rod and the TCA (the plant's truth, not the beads) from injection to
//! [`AFTER_ALARM_S`] after the alarm (what the trip's cut-off leaves), against the 130 °C
//! limits; each on the paper's wiring (thermistors only, plus the cut-off) and on a board that
//! senses its heaters' current. Prints a Markdown table (docs/safety.md holds one run of it).
//!
//! A fault injected in idle or release where nothing heats (a dead heater) can only show once
//! heat is asked for: there the run sends the next `MORPH` [`IDLE_BEFORE_MORPH_S`] after
//! injection (or after the running morph ended), and the time still counts from injection.
//!
//! Each row also gives the time from when the fault became observable ([`Observable`]: the
//! first tick after injection at which it makes a difference the sensors could show), and the
//! aims are judged on that time.

use morphlink::bench::Noise;
use morphlink::protocol::{classify, LineKind, Mode};
use morphlink::supervisor::{PLA_LIMITS, TCA_LIMITS};
use morphlink::vocab::{Heater, Phase};
use morphlink_plant::hifi::{Grid, Hifi, HifiSpec};
use morphlink_plant::Plant;
use morphlink_sim::{LinkSetup, Rig};
use std::fmt::Write as _;

/// The morph every fault is injected into, mm (the README's example).
pub const TARGET_MM: f32 = 38.0;
/// Longest wait for an alarm after injection, s (a phase timeout comes within it).
pub const MAX_WAIT_S: f64 = 600.0;
/// Idle time before the next `MORPH` once the link is idle after injection, s.
pub const IDLE_BEFORE_MORPH_S: f64 = 30.0;
/// Drift rate of the drift faults, K/s (the 0.2 K/s, either way).
pub const DRIFT_K_PER_S: f32 = 0.2;
/// Aim for an open or stuck heater, s.
pub const AIM_HEATER_S: f64 = 10.0;
/// Aim for a plausible-but-wrong sensor (stuck, or drifting once `TUNE` has run), s.
pub const AIM_SENSOR_S: f64 = 20.0;
/// Aim for a drifting sensor before `TUNE` (issue 27: 40 s), s.
pub const AIM_DRIFT_UNTUNED_S: f64 = 40.0;
/// Aim for an open or shorted heater where current is sensed, s (issue 26: half a second).
pub const AIM_SENSED_S: f64 = 0.5;
/// How long the peaks are followed after the alarm, s: a trip cuts the supply, and a heater
/// that still heats (a stuck MOSFET behind a stuck cut-off) shows within it.
pub const AFTER_ALARM_S: f64 = 60.0;

/// Options of the task.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The MORPH mode of every run (auto, paper, gated, boost, closed).
    #[arg(long, default_value = "auto")]
    pub mode: String,
    /// Run `TUNE` on each link before the morph (the supervisor then judges against the
    /// fitted model).
    #[arg(long)]
    pub tuned: bool,
}

/// When an injected fault first makes a difference the sensors could show.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Observable {
    /// At once (an open, shorted or frozen thermistor, a drift, the supply). A frozen reading
    /// repeats to the last bit from its first frame on, where a live one carries noise.
    AtInjection,
    /// Once the controller commands this heater on (a heater that is open).
    HeaterOn(Heater),
    /// Once the controller commands this heater below the power it dissipates (a stuck one).
    BelowStuck(Heater),
}

/// One injectable fault: its `SIM` line and the aim it is held to.
pub(crate) struct FaultCase {
    /// The name in the table.
    pub(crate) name: String,
    /// The `SIM` line that injects it.
    pub(crate) line: String,
    /// Its detection-time aim, s (`None`: none stated).
    aim_s: Option<f64>,
    /// When it becomes observable.
    observable: Observable,
}

/// Every injectable fault.
pub(crate) fn cases(tuned: bool) -> Vec<FaultCase> {
    let mut v = Vec::new();
    for sensor in ["pla", "tca", "amb"] {
        for kind in ["thermistor-open", "thermistor-short", "thermistor-stuck"] {
            let stuck = kind == "thermistor-stuck";
            v.push(FaultCase {
                name: format!("{kind} {sensor}"),
                line: format!("SIM FAULT {kind} {sensor}"),
                aim_s: stuck.then_some(AIM_SENSOR_S),
                observable: Observable::AtInjection,
            });
        }
        for rate in [-DRIFT_K_PER_S, DRIFT_K_PER_S] {
            v.push(FaultCase {
                name: format!("thermistor-drift {sensor} {rate:+.1} K/s"),
                line: format!("SIM FAULT thermistor-drift {sensor} {rate}"),
                aim_s: Some(if tuned {
                    AIM_SENSOR_S
                } else {
                    AIM_DRIFT_UNTUNED_S
                }),
                observable: Observable::AtInjection,
            });
        }
    }
    for heater in Heater::ALL {
        for kind in ["heater-open", "heater-stuck"] {
            let observable = if kind == "heater-open" {
                Observable::HeaterOn(heater)
            } else {
                Observable::BelowStuck(heater)
            };
            v.push(FaultCase {
                name: format!("{kind} {}", heater.as_str()),
                line: format!("SIM FAULT {kind} {}", heater.as_str()),
                aim_s: Some(AIM_HEATER_S),
                observable,
            });
        }
    }
    v.push(FaultCase {
        name: "heater-stuck tca, cutoff-stuck".into(),
        line: "SIM FAULT cutoff-stuck".into(),
        aim_s: Some(AIM_HEATER_S),
        observable: Observable::BelowStuck(Heater::Tca),
    });
    for volts in ["5", "20"] {
        v.push(FaultCase {
            name: format!("supply {volts} V"),
            line: format!("SIM SUPPLY {volts}"),
            aim_s: None,
            observable: Observable::AtInjection,
        });
    }
    v
}

/// What one injection gave.
pub(crate) struct Outcome {
    /// Seconds from injection to the first alarm, and the alarm's code (`None`: none within
    /// [`MAX_WAIT_S`]).
    pub(crate) alarm: Option<(f64, String)>,
    /// A `done` came between injection and the alarm (the radius it reports is in doubt).
    done_first: bool,
    /// Peak true PLA and TCA temperatures from injection to the alarm, °C.
    peak_c: [f64; 2],
    /// A `MORPH` had to be sent after injection (the fault only shows with heat).
    next_morph: bool,
    /// Seconds from injection to when the fault became observable (`None`: it never did
    /// before the alarm or the end of the run).
    observable_s: Option<f64>,
}

/// Whether `o` holds on this tick of `rig`.
fn observable_now<P: Plant>(o: Observable, rig: &Rig<P>) -> bool {
    let t = rig.plant().truth();
    let cmd = rig.ctrl.powers();
    match o {
        Observable::AtInjection => true,
        Observable::HeaterOn(h) => cmd.of(h) > 0.0,
        Observable::BelowStuck(h) => {
            let dissipated_w = match h {
                Heater::Pla => t.pla_w,
                Heater::Tca => t.tca_w,
            };
            (cmd.of(h) as f64) < dissipated_w - STUCK_OBSERVABLE_MARGIN_W
        }
    }
}

/// A stuck heater is observable once the commanded power is this far below what it
/// dissipates, W (a tenth of the TCA's 0.4 W judging threshold: above the PWM's resolution).
pub const STUCK_OBSERVABLE_MARGIN_W: f64 = 0.04;

/// Runs `case` injected in `phase` of a morph in `mode` on `rig`.
pub(crate) fn run_case<P: Plant>(
    mut rig: Rig<P>,
    case: &FaultCase,
    phase: Phase,
    mode: &str,
    tuned: bool,
) -> Outcome {
    let mut lines: Vec<String> = Vec::new();
    let send = |rig: &mut Rig<P>, line: &str, lines: &mut Vec<String>| {
        rig.handle_line(line, &mut |l: &str| lines.push(l.to_string()));
    };
    for _ in 0..20 {
        rig.tick();
    }
    if tuned {
        send(&mut rig, "TUNE", &mut lines);
        let end = rig.now_ms() + 600_000;
        while rig.ctrl.busy() && rig.now_ms() < end {
            rig.tick();
            rig.drain_events(&mut |_| {});
        }
    }
    let morph = format!("MORPH {TARGET_MM} {mode}");
    if phase != Phase::Idle {
        send(&mut rig, &morph, &mut lines);
        let end = rig.now_ms() + 300_000;
        while rig.ctrl.phase() != phase && rig.now_ms() < end {
            rig.tick();
            rig.drain_events(&mut |_| {});
        }
        for _ in 0..5 {
            rig.tick();
        }
        rig.drain_events(&mut |_| {});
    }
    let reached = rig.ctrl.phase() == phase;
    send(&mut rig, &case.line, &mut lines);
    if case.line == "SIM FAULT cutoff-stuck" {
        send(&mut rig, "SIM FAULT heater-stuck tca", &mut lines);
    }
    let t0 = rig.now_ms();
    let mut out = Outcome {
        alarm: None,
        done_first: false,
        peak_c: [f64::NAN; 2],
        next_morph: false,
        observable_s: None,
    };
    if !reached {
        return out;
    }
    let mut idle_since: Option<u64> = None;
    let mut peak = [f64::MIN; 2];
    while rig.now_ms() - t0 < (MAX_WAIT_S * 1000.0) as u64 {
        if out.observable_s.is_none() && observable_now(case.observable, &rig) {
            out.observable_s = Some((rig.now_ms() - t0) as f64 / 1000.0);
        }
        rig.tick();
        let t = rig.plant().truth();
        peak = [peak[0].max(t.pla_c), peak[1].max(t.tca_c)];
        let mut events = Vec::new();
        rig.drain_events(&mut |l| events.push(l.to_string()));
        if events.iter().any(|l| classify(l) == LineKind::Done) {
            out.done_first = true;
        }
        if let Some(a) = events.iter().find(|l| classify(l) == LineKind::Alarm) {
            let code = a
                .strip_prefix("alarm: ")
                .and_then(|r| r.split(' ').next())
                .unwrap_or("?");
            // `phase-timeout phase <name>`: the subject is the third word.
            let nth = if code == "phase-timeout" { 2 } else { 1 };
            let subject = a
                .strip_prefix("alarm: ")
                .and_then(|r| r.split(' ').nth(nth))
                .unwrap_or("?");
            let s = (rig.now_ms() - t0) as f64 / 1000.0;
            out.alarm = Some((s, format!("{code} {subject}")));
            // What the trip leaves: the cut-off ends the heat, unless it cannot.
            let after = rig.now_ms() + (AFTER_ALARM_S * 1000.0) as u64;
            while rig.now_ms() < after {
                rig.tick();
                rig.drain_events(&mut |_| {});
                let t = rig.plant().truth();
                peak = [peak[0].max(t.pla_c), peak[1].max(t.tca_c)];
            }
            break;
        }
        if rig.ctrl.idle() && !out.next_morph {
            let since = *idle_since.get_or_insert(rig.now_ms());
            if (rig.now_ms() - since) as f64 / 1000.0 >= IDLE_BEFORE_MORPH_S {
                out.next_morph = true;
                send(&mut rig, &morph, &mut lines);
            }
        }
    }
    out.peak_c = peak;
    out
}

/// One table cell: the time and alarm (from injection, and from when the fault became
/// observable), and whether the aim (judged from observable; for an open or stuck heater on a
/// board that senses current, [`AIM_SENSED_S`] from injection) and the limits held.
fn cell(o: &Outcome, case: &FaultCase, sensing: bool) -> String {
    let sensed_aim = sensing && case.observable != Observable::AtInjection;
    let limit_c = PLA_LIMITS.max_c.min(TCA_LIMITS.max_c) as f64;
    let mut s = match (&o.alarm, o.observable_s) {
        (None, _) if o.peak_c[0].is_nan() => "phase not reached".to_string(),
        (None, None) => format!("no alarm in {MAX_WAIT_S:.0} s: never observable"),
        (None, Some(obs)) => {
            format!("**no alarm in {MAX_WAIT_S:.0} s** (observable from {obs:.1} s)")
        }
        (Some((t, code)), obs) => {
            let from_obs = obs.map(|o| t - o);
            let mut s = format!("{t:.1} s `{code}`");
            match (case.observable, from_obs) {
                _ if sensed_aim => {}
                (Observable::AtInjection, _) => {}
                (_, Some(d)) => s.push_str(&format!(" ({d:.1} s from observable)")),
                (_, None) => s.push_str(" (before observable)"),
            }
            if sensed_aim {
                if *t > AIM_SENSED_S {
                    s.push_str(&format!(" **(aim {AIM_SENSED_S} s missed)**"));
                }
            } else if let Some(aim) = case.aim_s {
                if from_obs.unwrap_or(0.0) > aim {
                    s.push_str(&format!(" **(aim {aim:.0} s missed)**"));
                }
            }
            s
        }
    };
    if o.next_morph {
        s.push_str(" (next MORPH)");
    }
    if o.done_first {
        s.push_str(" **after done**");
    }
    if !o.peak_c[0].is_nan() {
        let over = o.peak_c.iter().any(|&c| c > limit_c);
        s.push_str(&format!(
            "; peak {:.0}/{:.0} °C{}",
            o.peak_c[0],
            o.peak_c[1],
            if over { " **over limit**" } else { "" }
        ));
    }
    s
}

/// Runs the task: prints the Markdown table.
pub fn run(args: &Args) -> Result<(), String> {
    let mode = args.mode.as_str();
    if !morphlink::protocol::MODES
        .iter()
        .any(|m: &Mode| m.as_str() == mode)
    {
        return Err(format!(
            "--mode {mode}: not a MORPH mode (auto, paper, gated, boost, closed)"
        ));
    }
    let hifi = Hifi::new(
        HifiSpec::nominal(morphlink::link::LINK, Grid::Reduced)
            .map_err(|e| format!("hifi nominal: {e}"))?,
    )
    .map_err(|e| format!("hifi nominal: {e}"))?;
    let lumped = LinkSetup::NOMINAL;
    let phases = [
        Phase::Idle,
        Phase::Soften,
        Phase::Bend,
        Phase::Lock,
        Phase::Release,
    ];
    let (cases, tuned) = (cases(args.tuned), args.tuned);
    let jobs: Vec<(usize, Phase)> = (0..cases.len())
        .flat_map(|c| phases.iter().map(move |&p| (c, p)))
        .collect();
    let rows: Vec<Vec<String>> = std::thread::scope(|scope| {
        let chunks: Vec<_> = jobs
            .chunks(jobs.len().div_ceil(2))
            .map(|chunk| {
                let (hifi, cases) = (&hifi, &cases);
                scope.spawn(move || {
                    chunk
                        .iter()
                        .map(|&(c, p)| {
                            let case = &cases[c];
                            let mut cells = Vec::new();
                            for hifi_plant in [true, false] {
                                for sensing in [false, true] {
                                    let o = if hifi_plant {
                                        let mut rig = Rig::with_plant(hifi.clone(), Noise::NOMINAL);
                                        rig.bench.set_current_sense(sensing);
                                        run_case(rig, case, p, mode, tuned)
                                    } else {
                                        let mut rig = Rig::new(lumped);
                                        rig.bench.set_current_sense(sensing);
                                        run_case(rig, case, p, mode, tuned)
                                    };
                                    cells.push(cell(&o, case, sensing));
                                }
                            }
                            cells
                        })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        chunks.into_iter().flat_map(|h| h.join().unwrap()).collect()
    });
    let mut t = String::new();
    let _ = writeln!(
        t,
        "| fault | phase | hifi, thermistors only: time to alarm, alarm; peak true PLA/TCA | hifi, current sense | lumped, thermistors only | lumped, current sense |"
    );
    let _ = writeln!(t, "| --- | --- | --- | --- | --- | --- |");
    for (&(c, p), cells) in jobs.iter().zip(&rows) {
        let _ = writeln!(
            t,
            "| {} | {} | {} |",
            cases[c].name,
            p.as_str(),
            cells.join(" | ")
        );
    }
    print!("{t}");
    Ok(())
}
