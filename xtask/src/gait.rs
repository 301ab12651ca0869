//! `cargo xtask gait`: several links on one supply budget (docs/multilink.md). Four links of
//! the hifi ensemble (their drawn links, in the medium asked for) morph at once with `GAIT`
//! on one bench supply, for each budget (the first one soften's worth: the least under which
//! each of the gait's morphs starts); each link also morphs alone with no budget. Prints,
//! per budget, the makespan (every link `done`) against its lower bound (the slowest link's
//! own morph, and the total energy of the links' own morphs over the budget) and against the
//! best schedule of the links' bends as they run alone ([`bends_as_alone_s`]), the highest
//! summed heater power of any tick (as the controllers reckon it and as the plants took it)
//! against the budget, the highest instantaneous current of any PWM period against the
//! supply's limit, the alarms, and each link's final error against its error alone. Fails if
//! a tick's reckoned power passes the budget, a period's current passes the limit, or a link
//! that finishes alone alarms or does not finish.

use crate::ensemble::{parallel, Body, Link, DEFAULT_SEED};
use morphlink::budget::MAX_LINKS;
use morphlink_plant::hifi::Hifi;
use morphlink_sim::ensemble::{Mismatch, TICKS_PER_S};
use morphlink_sim::{MultiRig, SharedSupply};
use std::fmt::Write as _;

/// Rest after the last `done` before the radii are read, s (spring-back included).
pub const SETTLE_S: u64 = 60;
/// Longest a gait may run, s.
pub const GAIT_MAX_S: u64 = 3_000;
/// Longest the links' TUNE may run (`--tune`), s, and then longest they may take to cool.
pub const TUNE_MAX_S: u64 = 600;
/// After TUNE the gait waits until every thermistor reads within this of ambient, K.
pub const COOL_K: f32 = 1.0;

/// Options of the task.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Budgets to run, W (0: no budget).
    #[arg(long, value_delimiter = ',', default_value = "5,8,12,0")]
    pub budgets_w: Vec<f32>,
    /// Leave out the row at one soften's worth: the least budget under which the gait's most
    /// demanding soften starts on an idle board (what `CONFIG SET supply_budget_w` refuses
    /// under), found on the links themselves after their TUNE with `--tune`.
    #[arg(long)]
    pub no_least: bool,
    /// The bench supply's current limit, A (also set as `supply_limit_a`).
    #[arg(long, default_value_t = 3.0)]
    pub limit_a: f32,
    /// The links' medium.
    #[arg(long, value_enum, default_value_t = Medium::Water)]
    pub medium: Medium,
    /// Targets, one per link, mm.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "34,38,42,46",
        conflicts_with = "stride_mm"
    )]
    pub targets_mm: Vec<f32>,
    /// The foot's stride wanted of each leg's four-bar, mm (docs/fourbar.md): the targets are
    /// the radii that give them (`morph-model fourbar --gait stride_mm=...`).
    #[arg(long, value_delimiter = ',')]
    pub stride_mm: Vec<f64>,
    /// Draw the tightest budget's run (each link's power, the total against the budget, each
    /// link's true radius against its target) into this SVG or PNG.
    #[arg(long)]
    pub plot: Option<std::path::PathBuf>,
    /// TUNE every link first (alone and together alike), as a user does before morphing.
    #[arg(long)]
    pub tune: bool,
    /// Also morph each link alone on this many other noise seeds: how far its |error| moves
    /// from run to run alone, beside which its error under a budget is judged.
    #[arg(long, default_value_t = 0)]
    pub seeds: u64,
    /// Worker threads.
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// Write the per-tick record of the tightest budget here (CSV: time, each link's phase
    /// and power, the total, the budget), for a plot.
    #[arg(long)]
    pub trace: Option<std::path::PathBuf>,
}

/// The links' medium.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Medium {
    /// Still water (the paper's bath).
    Water,
    /// Still air.
    Air,
}

/// The first `n` hifi draws of the strategy charts' ensemble in `medium`, with the noise of
/// the first one (each link of a rig gets its own seed from it).
pub fn links(n: usize, medium: Medium) -> Result<(Vec<Hifi>, morphlink::bench::Noise), String> {
    let mut plants = Vec::new();
    let mut noise = None;
    let mut d = 0;
    while plants.len() < n {
        let air = Mismatch::draw(DEFAULT_SEED, d).air;
        if air == (medium == Medium::Air) {
            let link = Link::hifi_draw(DEFAULT_SEED, d)?;
            noise.get_or_insert(link.noise);
            if let Body::Hifi(p) = link.body {
                plants.push(*p);
            }
        }
        d += 1;
    }
    Ok((plants, noise.expect("n > 0")))
}

/// What one run gave.
#[derive(Clone, Debug, Default)]
pub struct Run {
    /// The budget it ran under, W (0: none).
    pub budget_w: f32,
    /// Whether that budget was one soften's worth ([`Budget::OneSoften`]).
    pub least: bool,
    /// Seconds from the command to each link's `done` (NaN: not done).
    pub done_s: Vec<f64>,
    /// Each link's true radius after the settle, mm.
    pub radius_mm: Vec<f64>,
    /// Energy the heaters took from the command to the last `done`, J.
    pub energy_j: f64,
    /// Highest summed power of a tick as the controllers reckon it, W.
    pub max_reckoned_w: f64,
    /// Highest summed power of a tick as the plants took it, W.
    pub max_true_w: f64,
    /// Highest instantaneous current the heaters on at once drew (or, past the supply's
    /// limit, would have drawn) in a period, A.
    pub peak_a: f64,
    /// Lowest terminal voltage of a period, V.
    pub min_v: f64,
    /// Alarm and fault lines.
    pub alarms: Vec<String>,
    /// Morphs that waited for the budget.
    pub queued: usize,
    /// (time, each link's power, total, each link's true radius) per tick, for the trace.
    pub trace: Vec<(f64, Vec<f64>, f64, Vec<f64>)>,
    /// Each link's phases, as [`bends_as_alone_s`] takes them.
    pub phases: Vec<Phases>,
}

/// How long one link spent in its morph's phases, s, and the least power its heaters drew in
/// bend, W: what [`bends_as_alone_s`] takes of a link's morph alone.
#[derive(Clone, Debug, Default)]
pub struct Phases {
    /// From the command to the end of soften (a rest included), s.
    pub soften_s: f64,
    /// Bend, s.
    pub bend_s: f64,
    /// From the end of bend to `done` (lock and release), s.
    pub after_s: f64,
    /// The lowest mean power of both heaters over any [`LEAST_WINDOW_S`] of bend, W (its
    /// whole bend if shorter): the PLA's hold of a soft rod and the TCA's heat.
    pub least_w: f64,
    /// Both heaters' powers in bend so far, one per tick, W.
    bend_w: Vec<f64>,
}

/// The window a bend's power is averaged over, s: long enough to smooth the controllers'
/// ripple, short enough that the lowest window is what bend never went under.
pub const LEAST_WINDOW_S: f64 = 5.0;

impl Phases {
    /// Adds one tick of `dt_s` in `phase` with both heaters at `power_w`.
    fn note(&mut self, phase: morphlink::vocab::Phase, power_w: f64, dt_s: f64) {
        use morphlink::vocab::Phase::*;
        match phase {
            Rest | Soften => self.soften_s += dt_s,
            Bend => {
                self.bend_s += dt_s;
                self.bend_w.push(power_w);
            }
            Lock | Release => self.after_s += dt_s,
            _ => {}
        }
    }

    /// Fixes [`Phases::least_w`] from bend's powers, `dt_s` apart.
    fn finish(&mut self, dt_s: f64) {
        let p = std::mem::take(&mut self.bend_w);
        let w = ((LEAST_WINDOW_S / dt_s).round() as usize).clamp(1, p.len().max(1));
        self.least_w = p
            .windows(w)
            .map(|s| s.iter().sum::<f64>() / w as f64)
            .fold(f64::INFINITY, f64::min);
        if !self.least_w.is_finite() {
            self.least_w = 0.0;
        }
    }
}

/// The shortest makespan of the links' own morphs under `budget_w`, s, if each bend runs as
/// it runs alone: as long, and drawing throughout at least the least it drew alone
/// ([`Phases::least_w`]); each soften at least as long as alone before it, each lock and
/// release as long as alone after it, and soften and lock taken as drawing nothing. So it
/// bounds from below any schedule that bends each link as alone; a scheduler that throttles a
/// bend's TCA trades a longer bend, and more of its PLA's hold, for room beside it, which this
/// does not bound. Exact for the rigid bends: the serial schedule (each bend at the earliest
/// moment it fits beside the bends already placed) over every order gives every active
/// schedule, among which is a shortest.
pub fn bends_as_alone_s(links: &[Phases], budget_w: f64) -> f64 {
    fn orders(n: usize) -> Vec<Vec<usize>> {
        if n == 0 {
            return vec![vec![]];
        }
        let mut out = Vec::new();
        for o in orders(n - 1) {
            for at in 0..=o.len() {
                let mut v = o.clone();
                v.insert(at, n - 1);
                out.push(v);
            }
        }
        out
    }
    let mut best = f64::INFINITY;
    for order in orders(links.len()) {
        // (start, end, power) of the bends placed.
        let mut placed: Vec<(f64, f64, f64)> = Vec::new();
        let mut makespan = 0.0f64;
        for &k in &order {
            let l = &links[k];
            // A link that bent under this budget drew no more than it.
            let least_w = l.least_w.min(budget_w);
            let fits = |t: f64| {
                let load_at = |x: f64| {
                    placed
                        .iter()
                        .filter(|(s, e, _)| *s <= x && x < *e)
                        .map(|p| p.2)
                        .sum::<f64>()
                };
                std::iter::once(t)
                    .chain(
                        placed
                            .iter()
                            .map(|p| p.0)
                            .filter(|&s| t < s && s < t + l.bend_s),
                    )
                    .all(|x| load_at(x) + least_w <= budget_w + 1e-9)
            };
            let mut starts: Vec<f64> = std::iter::once(l.soften_s)
                .chain(placed.iter().map(|p| p.1).filter(|&e| e > l.soften_s))
                .collect();
            starts.sort_by(f64::total_cmp);
            let t = starts
                .into_iter()
                .find(|&t| fits(t))
                .expect("the last end fits");
            placed.push((t, t + l.bend_s, least_w));
            makespan = makespan.max(t + l.bend_s + l.after_s);
        }
        best = best.min(makespan);
    }
    best
}

/// The budget a [`run`] is under.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Budget {
    /// None (`supply_budget_w` left at its default).
    None,
    /// This many watts.
    Watts(f32),
    /// One soften's worth for the run's targets ([`least_budget_w`]).
    OneSoften,
}

/// Runs `plants` on one supply under `budget` (with [`Budget::OneSoften`], for `targets_mm`):
/// with `tune`, TUNE on every link and a wait until each
/// has cooled to [`COOL_K`] of ambient; then the command `cmd`, then until every link is done
/// (or [`GAIT_MAX_S`]), then [`SETTLE_S`].
#[allow(clippy::too_many_arguments)]
pub fn run(
    plants: Vec<Hifi>,
    noise: morphlink::bench::Noise,
    budget: Budget,
    limit_a: f32,
    cmd: &str,
    targets_mm: &[f32],
    trace: bool,
    tune: bool,
) -> Run {
    let n = plants.len();
    let supply = SharedSupply {
        limit_a: limit_a as f64,
        ..SharedSupply::STIFF
    };
    let mut rig = MultiRig::new(plants, noise, supply);
    rig.boot(1000);
    let mut lines = Vec::new();
    let mut say = |rig: &mut MultiRig<Hifi>, l: &str| {
        rig.handle_line(l, &mut |r: &str| lines.push(r.to_string()));
    };
    say(&mut rig, &format!("CONFIG SET supply_limit_a {limit_a}"));
    let mut tune_alarms = Vec::new();
    if tune {
        say(&mut rig, if n == 1 { "TUNE" } else { "@* TUNE" });
        for _ in 0..TUNE_MAX_S * TICKS_PER_S {
            rig.tick();
            if rig.links.idle() {
                break;
            }
        }
        // Then the link cools, as a user lets it, so no MORPH begins with a rest.
        let cool = |r: &MultiRig<Hifi>| {
            (0..n).all(|k| {
                let m = r.links.link(k).measurements();
                m.t_pla_c - m.t_amb_c <= COOL_K && m.t_tca_c - m.t_amb_c <= COOL_K
            })
        };
        for _ in 0..TUNE_MAX_S * TICKS_PER_S {
            if cool(&rig) {
                break;
            }
            rig.tick();
        }
        let mut events = Vec::new();
        rig.drain_events(&mut |l: &str| events.push(l.to_string()));
        for e in events
            .iter()
            .filter(|e| e.contains("alarm:") || e.contains("tune failed"))
        {
            tune_alarms.push(format!("TUNE: {e}"));
        }
    }
    let least = budget == Budget::OneSoften;
    let budget_w = match budget {
        Budget::None => 0.0,
        Budget::Watts(w) => w,
        Budget::OneSoften => least_budget_w(&rig, targets_mm),
    };
    if budget_w > 0.0 {
        say(&mut rig, &format!("CONFIG SET supply_budget_w {budget_w}"));
    }
    let start_ms = rig.now_ms();
    say(&mut rig, cmd);
    let mut r = Run {
        budget_w,
        least,
        done_s: vec![f64::NAN; n],
        min_v: f64::INFINITY,
        phases: vec![Phases::default(); n],
        ..Run::default()
    };
    for l in &lines {
        if l.starts_with("error") {
            r.alarms.push(l.clone());
        }
    }
    r.alarms.extend(tune_alarms);
    let dt_s = 1.0 / TICKS_PER_S as f64;
    let mut last_done_ms = None;
    loop {
        rig.tick();
        let t = rig.last;
        let elapsed_s = (rig.now_ms() - start_ms) as f64 / 1000.0;
        let mut events = Vec::new();
        rig.drain_events(&mut |l: &str| events.push(l.to_string()));
        for e in events {
            let k = link_of(&e, n);
            if e.contains("event: done") && r.done_s[k].is_nan() {
                r.done_s[k] = elapsed_s;
            }
            if e.contains("alarm:") || e.contains("dropped") {
                r.alarms.push(e.clone());
            }
            if e.contains("event: queued") {
                r.queued += 1;
            }
        }
        if trace {
            let each = (0..n)
                .map(|k| {
                    let p = rig.links.link(k).powers();
                    (p.pla_w + p.tca_w) as f64
                })
                .collect();
            let radii = (0..n).map(|k| rig.radius_mm(k)).collect();
            r.trace.push((elapsed_s, each, t.reckoned_w, radii));
        }
        for (k, ph) in r.phases.iter_mut().enumerate() {
            if r.done_s[k].is_nan() {
                let c = rig.links.link(k);
                ph.note(
                    c.phase(),
                    (c.powers().pla_w + c.powers().tca_w) as f64,
                    dt_s,
                );
            }
        }
        if last_done_ms.is_none() {
            r.energy_j += t.power_w * dt_s;
            r.max_reckoned_w = r.max_reckoned_w.max(t.reckoned_w);
            r.max_true_w = r.max_true_w.max(t.power_w);
            r.peak_a = r.peak_a.max(t.demand_a);
            r.min_v = r.min_v.min(t.min_v);
        }
        let busy = !rig.links.idle();
        if last_done_ms.is_none() && !busy {
            last_done_ms = Some(rig.now_ms());
        }
        if let Some(at) = last_done_ms {
            if rig.now_ms() >= at + SETTLE_S * 1000 {
                break;
            }
        }
        if elapsed_s > GAIT_MAX_S as f64 {
            r.alarms.push(format!("not done after {GAIT_MAX_S} s"));
            break;
        }
    }
    r.radius_mm = (0..n).map(|k| rig.radius_mm(k)).collect();
    for ph in &mut r.phases {
        ph.finish(dt_s);
    }
    r
}

/// One soften's worth for morphs to `targets_mm` on `rig`'s links, W: the least budget under
/// which each of them starts on an idle board (the largest soften reserve, with every link's
/// probe pulses, `morphlink::budget::least_budget_w`), rounded up to the 0.01 W that
/// `CONFIG SET` is given.
pub fn least_budget_w(rig: &MultiRig<Hifi>, targets_mm: &[f32]) -> f32 {
    let n = targets_mm.len();
    let most = (0..n)
        .filter_map(|k| rig.links.soften_reserve_w(k, targets_mm[k]))
        .map(|r| morphlink::budget::least_budget_w(r, n))
        .fold(0.0f32, f32::max);
    (most * 100.0).ceil() / 100.0
}

/// The link an event line names (`@<n> ...`; link 1 without an address).
fn link_of(line: &str, n: usize) -> usize {
    line.strip_prefix('@')
        .and_then(|s| s.split(' ').next())
        .and_then(|w| w.parse::<usize>().ok())
        .map_or(0, |k| (k.max(1) - 1).min(n - 1))
}

/// The radius that gives each leg's stride, mm (the one nearest the middle of the reachable
/// range where several do), from the checkout's `link.toml`.
fn targets_for_strides(root: &std::path::Path, strides_mm: &[f64]) -> Result<Vec<f32>, String> {
    use morphlink_model::fourbar::{self, Inverse, Property};
    let (p, g) = morphlink_model::file::load_with_fourbar(&root.join("link.toml"))?;
    let range = fourbar::reachable_radii_mm(&p);
    let mid = 0.5 * (range.0 + range.1);
    strides_mm
        .iter()
        .enumerate()
        .map(|(leg, &want)| {
            match fourbar::inverse(g, p.geometry.length_m, range, Property::Stride, want)
                .map_err(|e| e.to_string())?
            {
                Inverse::Found(sols) => Ok(sols
                    .iter()
                    .map(|s| s.0)
                    .min_by(|a, b| (a - mid).abs().total_cmp(&(b - mid).abs()))
                    .expect("a solution") as f32),
                Inverse::Unreachable { span_mm, .. } => Err(format!(
                    "leg {}: no reachable radius gives a {want} mm stride ({:.3}..{:.3} mm)",
                    leg + 1,
                    span_mm.0,
                    span_mm.1
                )),
            }
        })
        .collect()
}

/// The task.
pub fn run_task(a: &Args, root: &std::path::Path) -> Result<(), String> {
    let targets = if a.stride_mm.is_empty() {
        a.targets_mm.clone()
    } else {
        let t = targets_for_strides(root, &a.stride_mm)?;
        println!(
            "strides {:?} mm: radii {} mm",
            a.stride_mm,
            t.iter()
                .map(|r| format!("{r:.2}"))
                .collect::<Vec<_>>()
                .join(", ")
        );
        t
    };
    let a = &Args {
        targets_mm: targets
            .iter()
            .map(|r| (r * 100.0).round() / 100.0)
            .collect(),
        budgets_w: a.budgets_w.clone(),
        stride_mm: a.stride_mm.clone(),
        trace: a.trace.clone(),
        plot: a.plot.clone(),
        ..*a
    };
    let n = a.targets_mm.len();
    if !(1..=MAX_LINKS).contains(&n) {
        return Err(format!("1 to {MAX_LINKS} targets, one per link"));
    }
    let (plants, noise) = links(n, a.medium)?;
    let gait = morphlink::protocol::client::gait_line(&a.targets_mm, None).to_string();
    // Each link alone, no budget: its own fastest morph, its energy and its error.
    let alone_jobs: Vec<usize> = (0..n).collect();
    let alone: Vec<Run> = parallel(&alone_jobs, a.threads, "links alone", |&k| {
        alone_run(a, &plants[k], noise_of(noise, k), k)
    })?;
    let alone_s: Vec<f64> = alone.iter().map(|r| r.done_s[0]).collect();
    let spread = alone_spread(a, &plants, noise, &alone)?;
    let alone_err: Vec<f64> = (0..n)
        .map(|k| error_pct(alone[k].radius_mm[0], a.targets_mm[k]))
        .collect();
    let energy_j: f64 = alone.iter().map(|r| r.energy_j).sum();
    let slowest_s = alone_s.iter().cloned().fold(0.0, f64::max);
    let tightest = a
        .budgets_w
        .iter()
        .cloned()
        .filter(|b| *b > 0.0)
        .fold(f32::INFINITY, f32::min);
    let budgets: Vec<Budget> = (!a.no_least)
        .then_some(Budget::OneSoften)
        .into_iter()
        .chain(a.budgets_w.iter().map(|&w| match w > 0.0 {
            true => Budget::Watts(w),
            false => Budget::None,
        }))
        .collect();
    let runs: Vec<Run> = parallel(&budgets, a.threads, "budgets", |&b| {
        let trace = (a.trace.is_some() || a.plot.is_some()) && b == Budget::Watts(tightest);
        let t = &a.targets_mm;
        run(plants.clone(), noise, b, a.limit_a, &gait, t, trace, a.tune)
    })?;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{n} hifi links in {:?}, targets {:?} mm, bench supply 12 V, {} A limit, 0.1 ohm",
        a.medium, a.targets_mm, a.limit_a
    );
    let _ = writeln!(
        out,
        "alone (no budget): done in {} s; |error| {} %; energy {:.0} J",
        fmt_list(&alone_s, 1),
        fmt_list(&alone_err.iter().map(|e| e.abs()).collect::<Vec<_>>(), 2),
        energy_j
    );
    let _ = writeln!(
        out,
        "alone, soften / bend / lock and release s, least power in bend W: {}",
        alone
            .iter()
            .map(|r| {
                let p = &r.phases[0];
                format!(
                    "{:.1} / {:.1} / {:.1}, {:.2}",
                    p.soften_s, p.bend_s, p.after_s, p.least_w
                )
            })
            .collect::<Vec<_>>()
            .join("; ")
    );
    let alone_phases: Vec<Phases> = alone.iter().map(|r| r.phases[0].clone()).collect();
    if let Some(pp) = &spread {
        let _ = writeln!(
            out,
            "alone on {} noise seeds: |error| spread {} pp",
            a.seeds + 1,
            fmt_list(pp, 2)
        );
    }
    let _ = writeln!(
        out,
        "| budget W | makespan s | lower bound s | ratio | bends as alone s | ratio | max power W (reckoned / true) | peak A | min V | queued | worst |error| vs alone pp | alarms |"
    );
    let _ = writeln!(
        out,
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
    );
    let mut failures = Vec::new();
    for r in &runs {
        let b = &r.budget_w;
        let makespan = r.done_s.iter().cloned().fold(0.0, f64::max);
        let all_done = r.done_s.iter().all(|d| d.is_finite());
        let bound = if *b > 0.0 {
            slowest_s.max(energy_j / *b as f64)
        } else {
            slowest_s
        };
        let rigid = if *b > 0.0 {
            // Never under the lower bound: soften's and lock's power are not in it.
            bends_as_alone_s(&alone_phases, *b as f64).max(bound)
        } else {
            bound
        };
        let worse_pp = (0..n)
            .map(|k| error_pct(r.radius_mm[k], a.targets_mm[k]).abs() - alone_err[k].abs())
            .fold(f64::NEG_INFINITY, f64::max);
        let name = match (*b > 0.0, r.least) {
            (true, true) => format!("{b} (one soften)"),
            (true, false) => format!("{b}"),
            _ => "none".into(),
        };
        let _ = writeln!(
            out,
            "| {name} | {} | {:.1} | {} | {:.1} | {} | {:.2} / {:.2} | {:.2} | {:.2} | {} | {:+.2} | {} |",
            if all_done {
                format!("{makespan:.1}")
            } else {
                "not done".into()
            },
            bound,
            if all_done {
                format!("{:.2}", makespan / bound)
            } else {
                "-".into()
            },
            rigid,
            if all_done {
                format!("{:.2}", makespan / rigid)
            } else {
                "-".into()
            },
            r.max_reckoned_w,
            r.max_true_w,
            r.peak_a,
            r.min_v,
            r.queued,
            worse_pp,
            r.alarms.len()
        );
        if *b > 0.0 && r.max_reckoned_w > *b as f64 + 1e-3 {
            failures.push(format!(
                "budget {b} W: a tick reckoned {:.3} W",
                r.max_reckoned_w
            ));
        }
        if r.peak_a > a.limit_a as f64 + 1e-3 {
            failures.push(format!("budget {name}: a period drew {:.3} A", r.peak_a));
        }
        // A link that does not finish alone either (a healthy still-air morph timing out,
        // docs/strategies.md) is reported, not charged to the budget.
        let charged: Vec<&String> = r
            .alarms
            .iter()
            .filter(|l| alone_s[link_of(l, n)].is_finite())
            .collect();
        let unfinished = (0..n).any(|k| alone_s[k].is_finite() && !r.done_s[k].is_finite());
        if unfinished || !charged.is_empty() {
            failures.push(format!("budget {name}: {charged:?}"));
        }
    }
    print!("{out}");
    let traced = runs.iter().find(|r| !r.least && r.budget_w == tightest);
    if let (Some(path), Some(r)) = (&a.plot, traced) {
        let chart = morphlink_host::gait_chart::GaitChart {
            title: format!("{gait} on {n} hifi links, {tightest} W, {} A", a.limit_a),
            time_s: r.trace.iter().map(|t| t.0).collect(),
            power_w: (0..n)
                .map(|k| r.trace.iter().map(|t| t.1[k]).collect())
                .collect(),
            total_w: r.trace.iter().map(|t| t.2).collect(),
            budget_w: Some(tightest as f64),
            radius_mm: (0..n)
                .map(|k| r.trace.iter().map(|t| t.3[k]).collect())
                .collect(),
            target_mm: a.targets_mm.iter().map(|&t| t as f64).collect(),
        };
        morphlink_host::plot::write(path, (900, 700), &chart).map_err(|e| e.0)?;
        println!("wrote {}", path.display());
    }
    if let (Some(path), Some(r)) = (&a.trace, traced) {
        let mut csv = String::from("time_s");
        for k in 0..n {
            let _ = write!(csv, ",link{}_w", k + 1);
        }
        let _ = writeln!(csv, ",total_w,budget_w");
        for (t, each, total, _) in &r.trace {
            let _ = write!(csv, "{t:.1}");
            for p in each {
                let _ = write!(csv, ",{p:.3}");
            }
            let _ = writeln!(csv, ",{total:.3},{tightest}");
        }
        std::fs::write(path, csv).map_err(|e| format!("{}: {e}", path.display()))?;
    }
    if failures.is_empty() {
        Ok(())
    } else {
        Err(failures.join("; "))
    }
}

/// With `--seeds`, each link's |error| spread (largest less smallest, pp) over its morph alone
/// on `a.seeds` other noise seeds and on the first (`alone`).
fn alone_spread(
    a: &Args,
    plants: &[Hifi],
    noise: morphlink::bench::Noise,
    alone: &[Run],
) -> Result<Option<Vec<f64>>, String> {
    if a.seeds == 0 {
        return Ok(None);
    }
    let n = plants.len();
    let jobs: Vec<(usize, u64)> = (0..n)
        .flat_map(|k| (1..=a.seeds).map(move |s| (k, s)))
        .collect();
    let runs = parallel(&jobs, a.threads, "links alone, other seeds", |&(k, s)| {
        let mut nz = noise_of(noise, k);
        nz.seed = nz.seed.wrapping_add(0x2545_f491 * s);
        alone_run(a, &plants[k], nz, k)
    })?;
    let pp = (0..n)
        .map(|k| {
            let errs = jobs
                .iter()
                .zip(&runs)
                .filter(|(j, _)| j.0 == k)
                .map(|(_, r)| &r.radius_mm[0])
                .chain([&alone[k].radius_mm[0]])
                .map(|&r| error_pct(r, a.targets_mm[k]).abs());
            let (lo, hi) = errs.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), e| {
                (lo.min(e), hi.max(e))
            });
            hi - lo
        })
        .collect();
    Ok(Some(pp))
}

/// Link `k`'s morph to its target alone on `plant`, with `noise`, no budget (TUNEd first with
/// `--tune`).
fn alone_run(a: &Args, plant: &Hifi, noise: morphlink::bench::Noise, k: usize) -> Run {
    let cmd = format!("MORPH {}", a.targets_mm[k]);
    run(
        vec![plant.clone()],
        noise,
        Budget::None,
        a.limit_a,
        &cmd,
        &a.targets_mm[k..=k],
        false,
        a.tune,
    )
}

/// The noise a rig gives its link `k` (so a link alone reads as it does among the others).
fn noise_of(noise: morphlink::bench::Noise, k: usize) -> morphlink::bench::Noise {
    morphlink::bench::Noise {
        seed: noise.seed.wrapping_add(0x9e37_79b9 * k as u64),
        ..noise
    }
}

fn error_pct(radius_mm: f64, target_mm: f32) -> f64 {
    100.0 * (radius_mm - target_mm as f64) / target_mm as f64
}

fn fmt_list(v: &[f64], decimals: usize) -> String {
    v.iter()
        .map(|x| format!("{x:.decimals$}"))
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn link(soften_s: f64, bend_s: f64, after_s: f64, least_w: f64) -> Phases {
        Phases {
            soften_s,
            bend_s,
            after_s,
            least_w,
            ..Phases::default()
        }
    }

    #[test]
    fn bends_that_do_not_fit_together_run_one_after_another() {
        let l = [link(4.0, 50.0, 10.0, 3.0), link(5.0, 40.0, 15.0, 3.0)];
        // 6 W takes both at once: the slower alone bounds it.
        assert_eq!(bends_as_alone_s(&l, 6.0), 64.0);
        // 5 W takes one: the best order bends the second first (5 + 40), then the first
        // (45 + 50 + 10): 105 s; the other order gives 4 + 50 + 40 + 15 = 109 s.
        assert_eq!(bends_as_alone_s(&l, 5.0), 105.0);
    }

    #[test]
    fn a_bend_fits_beside_another_only_where_their_sum_fits_the_budget() {
        // Two bends of 2 W fit 5 W beside each other, a third of 2 W waits for one of them.
        let l = [
            link(0.0, 10.0, 0.0, 2.0),
            link(0.0, 20.0, 0.0, 2.0),
            link(0.0, 10.0, 0.0, 2.0),
        ];
        assert_eq!(bends_as_alone_s(&l, 5.0), 20.0);
        assert_eq!(bends_as_alone_s(&l, 3.0), 40.0);
    }

    #[test]
    fn a_bends_least_power_is_its_least_window() {
        let mut p = Phases::default();
        for k in 0..100 {
            let w = if (40..60).contains(&k) { 1.0 } else { 3.0 };
            p.note(morphlink::vocab::Phase::Bend, w, 0.1);
        }
        p.finish(0.1);
        assert!((p.bend_s - 10.0).abs() < 1e-9);
        // The 5 s windows over the 2 s dip: the lowest has 2 s at 1 W and 3 s at 3 W.
        assert!((p.least_w - 2.2).abs() < 1e-9, "{}", p.least_w);
    }
}
