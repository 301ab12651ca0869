//! `cargo xtask stored-heat`: how far the heat stored in a healthy link lifts a heated
//! thermistor after both heaters are cut, and how close the supervisor's residual tests came
//! to an alarm (the fullest CUSUM sum as a share of `CUSUM_LIMIT_K_S`). A morph is
//! ABORTed at every [`ABORT_STEP_S`] from [`ABORT_FIRST_S`] to [`ABORT_LAST_S`] into it, in every
//! mode, on the nominal lumped link in water and still air with beads of each
//! [`LUMPED_BEAD_TAUS_S`], on the nominal hifi link in water and still air, and on the hifi
//! ensemble's draws. For [`WATCH_S`] after the cut the STATUS readings give each heated sensor's
//! rise above ambient over its lowest since the cut (measured from ambient when it was below
//! it). A second pass sends the same MORPH again
//! [`REMORPH_DELAYS_S`] after an ABORT at each of [`REMORPH_ABORTS_S`] and runs it to its end (a
//! warm link, a bead still warming). Prints the worst case per link family and the second
//! pass's alarms (the tables of docs/safety.md). Fails if a first-pass run alarms, or a
//! second-pass run raises an alarm of the residual tests (a phase timeout or an over-temperature trip is the
//! strategy's; `cargo xtask strategies` counts those) or does not end.

use crate::ensemble::{parallel, Common, Family, Link};
use morphlink::protocol::{classify, client::Status, LineKind, MODES};
use morphlink_plant::Plant;
use morphlink_sim::ensemble::TICKS_PER_S;
use morphlink_sim::Rig;

/// The morph ABORTed, mm (the README's example).
pub const TARGET_MM: f32 = 38.0;
/// The earliest ABORT, s into the morph (in soften).
pub const ABORT_FIRST_S: u64 = 1;
/// The latest ABORT, s into the morph (lock on both nominal links).
pub const ABORT_LAST_S: u64 = 30;
/// The step between ABORT times, s (soften lasts 3–5 s on the nominal links).
pub const ABORT_STEP_S: u64 = 1;
/// How long after the cut the readings are watched, s: past the slowest bead's peak.
pub const WATCH_S: u64 = 60;
/// The second pass: ABORT times, s into the first morph, after which the same MORPH is sent
/// again [`REMORPH_DELAYS_S`] later.
pub const REMORPH_ABORTS_S: [u64; 3] = [4, 10, 20];
/// The second pass: delays between the ABORT and the next MORPH, s.
pub const REMORPH_DELAYS_S: [u64; 4] = [0, 3, 10, 30];
/// Longest a second morph is run for, s: past the longest its rest and the phase timeouts
/// allow (900 s rest, 60 s soften, 120 s bend, 600 s lock, 10 s release).
pub const MORPH_MAX_S: u64 = 1_700;
/// The lumped link's bead time constants tried, s (the ensemble draws 2–6 s; nominal 3 s).
pub const LUMPED_BEAD_TAUS_S: [f64; 3] = [2.0, 3.0, 6.0];

/// Options of the task.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// High-fidelity ensemble links to draw (the strategy charts' draws).
    #[arg(long, default_value_t = crate::ensemble::DEFAULT_HIFI_DRAWS)]
    pub hifi_draws: u64,
    #[command(flatten)]
    pub common: Common,
}

/// What one ABORTed morph showed after the cut, K: each the largest over both heated sensors.
#[derive(Clone, Debug, Default)]
struct Rises {
    /// Rise above the lowest since the cut.
    raw_k: f32,
    /// The fullest any residual test came over the morph and the watch, share of its limit.
    share: f32,
    /// The first alarm line, if any came (before or after the ABORT).
    alarm: Option<String>,
}

/// A rig with its plant erased, so lumped and hifi links share one list.
trait RunOn {
    /// Runs one morph in `mode`, ABORTs it `abort_s` in, and watches the readings for
    /// [`WATCH_S`].
    fn run(&mut self, mode: &str, abort_s: u64) -> Rises;
    /// Runs one morph in `mode`, ABORTs it `abort_s` in, sends the same MORPH `delay_s` later
    /// and runs it to its end: the first alarm of the supervisor's plausibility and heater
    /// checks, if any (a phase timeout or an over-temperature trip is the strategy's, not a
    /// false alarm; the ensemble charts count those).
    fn rerun(&mut self, mode: &str, abort_s: u64, delay_s: u64) -> Rerun;
}

/// How a MORPH after an ABORT went.
#[derive(Clone, Debug, PartialEq)]
enum Rerun {
    /// It ended without an alarm of the plausibility and heater checks.
    Quiet,
    /// The first such alarm, before or during it.
    Alarm(String),
    /// It was refused (the reply): the first morph had latched a fault of its own.
    NotRun(String),
    /// Still busy after [`MORPH_MAX_S`].
    Unfinished,
}

impl<P: Plant> RunOn for Rig<P> {
    fn run(&mut self, mode: &str, abort_s: u64) -> Rises {
        let mut r = Rises::default();
        let mut first_alarm = |l: &str| {
            if classify(l) == LineKind::Alarm && r.alarm.is_none() {
                r.alarm = Some(l.to_string());
            }
        };
        let morph = format!("MORPH {TARGET_MM} {mode}");
        run_for(self, 20, &mut first_alarm);
        self.handle_line(&morph, &mut |_| {});
        run_for(self, abort_s * TICKS_PER_S, &mut first_alarm);
        self.handle_line("ABORT", &mut |_| {});
        let mut min_k: [Option<f32>; 2] = [None; 2];
        for _ in 0..WATCH_S * TICKS_PER_S {
            run_for(self, 1, &mut first_alarm);
            let mut temps = None;
            self.handle_line("STATUS", &mut |l: &str| {
                temps = Status::parse(l).map(|s| s.temps_c);
            });
            let Some([Some(pla), Some(tca), Some(amb)]) = temps else {
                continue;
            };
            for (i, own_c) in [pla, tca].into_iter().enumerate() {
                let rise_k = own_c - amb;
                let lowest = |m: &mut Option<f32>| {
                    let v = m.map_or(rise_k, |k| k.min(rise_k));
                    *m = Some(v);
                    rise_k - v.max(0.0)
                };
                r.raw_k = r.raw_k.max(lowest(&mut min_k[i]));
            }
        }
        let [level, change] = self.ctrl.supervisor().peak_shares();
        r.share = level.max(change);
        r
    }
    fn rerun(&mut self, mode: &str, abort_s: u64, delay_s: u64) -> Rerun {
        let mut alarm = None;
        let mut checks_alarm = |l: &str| {
            let code = l.strip_prefix("alarm: ").and_then(|r| r.split(' ').next());
            let false_alarm =
                code.is_some_and(|c| !["phase-timeout", "over-temperature"].contains(&c));
            if false_alarm && alarm.is_none() {
                alarm = Some(l.to_string());
            }
        };
        let morph = format!("MORPH {TARGET_MM} {mode}");
        run_for(self, 20, &mut checks_alarm);
        self.handle_line(&morph, &mut |_| {});
        run_for(self, abort_s * TICKS_PER_S, &mut checks_alarm);
        self.handle_line("ABORT", &mut |_| {});
        run_for(self, delay_s * TICKS_PER_S, &mut checks_alarm);
        let mut reply = String::new();
        self.handle_line(&morph, &mut |l| reply = l.to_string());
        if reply != "ok" {
            // The first morph latched a fault of its own (a strategy's over-temperature trip):
            // there is no second morph to judge.
            return Rerun::NotRun(reply);
        }
        for _ in 0..MORPH_MAX_S {
            run_for(self, TICKS_PER_S, &mut checks_alarm);
            if !self.ctrl.busy() {
                return alarm.map_or(Rerun::Quiet, Rerun::Alarm);
            }
        }
        Rerun::Unfinished
    }
}

/// Ticks `rig` `ticks` times, handing every event and alarm line to `seen`.
fn run_for<P: Plant>(rig: &mut Rig<P>, ticks: u64, seen: &mut impl FnMut(&str)) {
    for _ in 0..ticks {
        rig.tick();
        rig.drain_events(seen);
    }
}

/// The links: the lumped nominal ones with each bead, the hifi nominal ones, both in the
/// stillest rated air, the hifi draws.
fn links(a: &Args) -> Result<Vec<Link>, String> {
    let mut v = Vec::new();
    for air in [false, true] {
        v.extend(LUMPED_BEAD_TAUS_S.map(|tau| Link::lumped_nominal(air, tau)));
        v.push(Link::hifi_nominal(air)?);
    }
    for hifi in [false, true] {
        v.push(Link::nominal_stillest_air(hifi)?);
    }
    for d in 0..a.hifi_draws {
        v.push(Link::hifi_draw(a.common.seed, d)?);
    }
    Ok(v)
}

/// Runs the task: prints the worst stored-heat rise per link family and overall.
pub fn run(args: &Args) -> Result<(), String> {
    let links = links(args)?;
    let aborts: Vec<u64> = (ABORT_FIRST_S..=ABORT_LAST_S)
        .step_by(ABORT_STEP_S as usize)
        .collect();
    let jobs: Vec<(usize, &str, u64)> = (0..links.len())
        .flat_map(|l| {
            let aborts = &aborts;
            MODES
                .iter()
                .flat_map(move |m| aborts.iter().map(move |&a| (l, m.as_str(), a)))
        })
        .collect();
    let results = parallel(
        &jobs,
        args.common.threads,
        "ABORTed morphs",
        |&(l, mode, a)| links[l].rig().run(mode, a),
    )?;
    println!(
        "| links | runs | largest rise after the cut | fullest residual test (share of its limit) | alarms |"
    );
    println!("| --- | --- | --- | --- | --- |");
    for family in [
        Family::LumpedNominal,
        Family::HifiNominal,
        Family::HifiDraws,
    ] {
        let rows: Vec<_> = jobs
            .iter()
            .zip(&results)
            .filter(|((l, _, _), _)| links[*l].family == family)
            .collect();
        let worst = |f: fn(&Rises) -> f32, unit: &str| {
            rows.iter()
                .max_by(|x, y| f(x.1).total_cmp(&f(y.1)))
                .map(|((l, mode, a), r)| {
                    format!(
                        "{:.2}{unit} ({}, ABORT {a} s into {mode})",
                        f(r),
                        links[*l].name
                    )
                })
                .unwrap_or_default()
        };
        println!(
            "| {} | {} | {} | {} | {} |",
            family.as_str(),
            rows.len(),
            worst(|r| r.raw_k, " K"),
            worst(|r| r.share, ""),
            rows.iter().filter(|(_, r)| r.alarm.is_some()).count()
        );
    }
    let rejobs: Vec<(usize, &str, u64, u64)> = (0..links.len())
        .flat_map(|l| {
            MODES.iter().flat_map(move |m| {
                REMORPH_ABORTS_S.iter().flat_map(move |&a| {
                    REMORPH_DELAYS_S.iter().map(move |&d| (l, m.as_str(), a, d))
                })
            })
        })
        .collect();
    let realarms = parallel(
        &rejobs,
        args.common.threads,
        "MORPHs after an ABORT",
        |&(l, mode, a, d)| links[l].rig().rerun(mode, a, d),
    )?;
    println!("\nMORPH again 0, 3, 10 or 30 s after an ABORT 4, 10 or 20 s into a morph:\n");
    println!("| links | runs | alarms of the residual tests | not run (the first morph latched a fault) |");
    println!("| --- | --- | --- | --- |");
    for family in [
        Family::LumpedNominal,
        Family::HifiNominal,
        Family::HifiDraws,
    ] {
        let rows: Vec<_> = rejobs
            .iter()
            .zip(&realarms)
            .filter(|((l, ..), _)| links[*l].family == family)
            .collect();
        let count = |f: fn(&Rerun) -> bool| rows.iter().filter(|(_, r)| f(r)).count();
        println!(
            "| {} | {} | {} | {} |",
            family.as_str(),
            rows.len(),
            count(|r| matches!(r, Rerun::Alarm(_) | Rerun::Unfinished)),
            count(|r| matches!(r, Rerun::NotRun(_)))
        );
    }
    let mut failed: Vec<String> = rejobs
        .iter()
        .zip(&realarms)
        .filter_map(|((l, mode, a, d), r)| {
            let what = match r {
                Rerun::Alarm(al) => al.clone(),
                Rerun::Unfinished => format!("still running after {MORPH_MAX_S} s"),
                Rerun::Quiet | Rerun::NotRun(_) => return None,
            };
            Some(format!(
                "{} {mode} ABORT {a} s, MORPH {d} s later: {what}",
                links[*l].name
            ))
        })
        .collect();
    failed.extend(
        jobs.iter()
            .zip(&results)
            .filter(|(_, r)| r.alarm.is_some())
            .map(|((l, mode, a), r)| {
                format!(
                    "{} {mode} ABORT {a} s: rise {:.1} K, residual {:.2}; {}",
                    links[*l].name,
                    r.raw_k,
                    r.share,
                    r.alarm.as_deref().unwrap_or("no alarm")
                )
            }),
    );
    if failed.is_empty() {
        println!("\nNo run alarmed.");
        Ok(())
    } else {
        Err(format!(
            "{} runs alarmed:\n{}",
            failed.len(),
            failed.join("\n")
        ))
    }
}
