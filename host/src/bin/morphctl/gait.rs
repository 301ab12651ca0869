//! `morphctl gait`: several links morphed at once on one supply (`GAIT`, docs/multilink.md),
//! followed link by link until every link is done or has alarmed: a running line per poll with
//! each link's phase and power and the supply's total against its budget, the telemetry CSV
//! with a row per link per poll, and its plot (each link's power and the total against the
//! budget; each link's true radius on the simulator). Whatever stops it, the heaters end off
//! on every link (an unaddressed ABORT stops them all; `@* STATUS` confirms it).

use crate::link::{field, Link, LinkError, REPLY_TIMEOUT_S};
use crate::telemetry::{Sample, CSV_HEADER};
use crate::{sim_time_and_radius, wait_for_sensors, CsvLog, MorphEnd};
use morphlink::protocol::client::{classify, link_of, LineKind};
use morphlink_host::gait_chart::GaitChart;
use morphlink_host::plot;
use std::io::Write;
use std::path::Path;
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// Budget a device reports when none binds, W (`supply_budget_w`'s default): not drawn.
const UNBOUND_BUDGET_W: f64 = 100.0;

/// What `morphctl gait` was asked.
pub struct Opts {
    /// One radius per link, mm.
    pub radii_mm: Vec<f32>,
    /// Strategy for every link.
    pub mode: String,
    /// Host time between polls.
    pub poll: Duration,
    /// Abort if not every link is done after this many seconds of link time.
    pub timeout_s: f64,
    /// `supply_budget_w` to set before the gait, W (`None`: the device's own).
    pub budget_w: Option<f32>,
}

/// One link's sample of one poll, with the supply's state at that poll.
#[derive(Clone, Debug, PartialEq)]
pub struct GaitSample {
    /// The link, 0-based.
    pub link: usize,
    /// Its STATUS (and true radius on the simulator).
    pub sample: Sample,
    /// The summed heater power of every link at this poll, W (`LINKS`).
    pub total_w: f64,
    /// The supply budget at this poll, W.
    pub budget_w: f64,
}

/// The CSV header of a gait log: the link, a [`Sample`]'s columns, then the supply's.
pub fn csv_header() -> String {
    format!("link,{CSV_HEADER},total_w,budget_w")
}

impl GaitSample {
    /// The sample as a CSV row under [`csv_header`] (links from 1, as on the wire).
    pub fn csv_row(&self) -> String {
        format!(
            "{},{},{:.3},{:.2}",
            self.link + 1,
            self.sample.csv_row(),
            self.total_w,
            self.budget_w
        )
    }

    /// Parses a row written by [`GaitSample::csv_row`].
    pub fn parse_csv(row: &str) -> Result<GaitSample, String> {
        let (link, rest) = row.split_once(',').ok_or("no link column")?;
        let link: usize = link
            .parse()
            .ok()
            .filter(|&k| k >= 1)
            .ok_or(format!("link `{link}` is not a link number from 1"))?;
        let mut tail = rest.rsplitn(3, ',');
        let budget = tail.next().ok_or("no budget_w column")?;
        let total = tail.next().ok_or("no total_w column")?;
        let sample = Sample::parse_csv(tail.next().ok_or("no sample columns")?)?;
        let num = |v: &str, name: &str| {
            v.parse::<f64>()
                .map_err(|_| format!("{name} `{v}` is not a number"))
        };
        Ok(GaitSample {
            link: link - 1,
            sample,
            total_w: num(total, "total_w")?,
            budget_w: num(budget, "budget_w")?,
        })
    }
}

/// Reads a gait log written by `morphctl gait --log`.
pub fn read_csv(path: &Path) -> Result<Vec<GaitSample>, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    let mut lines = text.lines();
    if lines.next() != Some(csv_header().as_str()) {
        return Err(format!("{}: not a gait log (its header)", path.display()));
    }
    lines
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            GaitSample::parse_csv(l).map_err(|e| format!("{}:{}: {e}", path.display(), i + 2))
        })
        .collect()
}

/// True if `path` starts with a gait log's header (`morphctl plot` tells the logs apart).
pub fn is_gait_log(path: &Path) -> bool {
    std::fs::read_to_string(path)
        .ok()
        .and_then(|t| t.lines().next().map(|h| h == csv_header()))
        .unwrap_or(false)
}

/// The chart of a gait's samples: one point per poll.
pub fn chart(samples: &[GaitSample], title: &str) -> GaitChart {
    let links = samples.iter().map(|s| s.link + 1).max().unwrap_or(0);
    let mut c = GaitChart {
        title: title.to_string(),
        power_w: vec![Vec::new(); links],
        radius_mm: vec![Vec::new(); links],
        target_mm: vec![f64::NAN; links],
        ..GaitChart::default()
    };
    let mut budget = f64::NAN;
    // A poll is the run of rows with one time; each link's row, or NaN where it has none.
    let mut i = 0;
    while i < samples.len() {
        let t = samples[i].sample.t_s;
        let end = i + samples[i..]
            .iter()
            .take_while(|s| s.sample.t_s == t)
            .count();
        c.time_s.push(t);
        c.total_w.push(samples[i].total_w);
        budget = samples[i].budget_w;
        for k in 0..links {
            let s = samples[i..end].iter().find(|s| s.link == k);
            let p = s.map_or(f64::NAN, |s| s.sample.powers_w.iter().sum());
            c.power_w[k].push(p);
            c.radius_mm[k].push(s.map_or(f64::NAN, |s| s.sample.radius_mm));
            if let Some(target) = s.map(|s| s.sample.target_mm).filter(|t| t.is_finite()) {
                c.target_mm[k] = target;
            }
        }
        i = end;
    }
    c.budget_w = (budget.is_finite() && budget < UNBOUND_BUDGET_W).then_some(budget);
    c
}

/// Plots a gait's samples to `path` (.svg or .png).
pub fn plot(samples: &[GaitSample], title: &str, path: &Path) -> Result<(), String> {
    plot::write(path, (1000, 700), &chart(samples, title)).map_err(|e| e.to_string())
}

/// How each link's morph stands.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum End {
    /// Neither done nor alarmed yet.
    Running,
    /// `event: done`.
    Done,
    /// An alarm: the link's heaters are off.
    Alarm,
}

/// `GAIT` on the device and every link followed to its end. `Err` as [`MorphEnd`] says.
pub fn gait(
    link: &mut Link,
    o: &Opts,
    samples: &mut Vec<GaitSample>,
    csv: &mut Option<CsvLog>,
) -> Result<ExitCode, MorphEnd> {
    let mut events: Vec<String> = Vec::new();
    let n = start(link, o, &mut events)?;
    follow(link, n, o, samples, csv, events)
}

/// Starts the gait: the device's links (`LINKS`; a device of one link is refused), the budget
/// if asked, the first sensor reading, then `GAIT`. Returns how many links; lines that arrived
/// meanwhile are in `events`.
pub fn start(link: &mut Link, o: &Opts, events: &mut Vec<String>) -> Result<usize, MorphEnd> {
    let (_, links) = link
        .command("LINKS", REPLY_TIMEOUT_S, &mut |l| {
            events.push(l.to_string())
        })
        .map_err(|e| match e {
            LinkError::Closed(e) => MorphEnd::Failed(e),
            e => MorphEnd::Broken(e),
        })?;
    let n = field(&links, "links")
        .and_then(|v| v.parse::<usize>().ok())
        .ok_or_else(|| {
            MorphEnd::Failed(format!(
                "{} drives one link (LINKS: `{links}`); a gait needs several: morph-sim --links N \
                 (`--sim-links N`) or an image of several links (docs/multilink.md)",
                link.name
            ))
        })?;
    link.links = n;
    // Checked before the budget is set: a refused gait changes nothing.
    if o.radii_mm.len() != n {
        return Err(MorphEnd::Failed(format!(
            "{} radii for {} links: a gait takes one radius per link",
            o.radii_mm.len(),
            n
        )));
    }
    let line = morphlink::protocol::client::gait_line(&o.radii_mm, Some(&o.mode));
    if let Err(e) = morphlink::protocol::links::check_line(&line) {
        return Err(MorphEnd::Failed(format!(
            "GAIT refused before anything was sent: {}",
            morphlink::protocol::format_error(&e)
        )));
    }
    if let Some(b) = o.budget_w {
        let (_, set) = link.command(
            &format!("CONFIG SET supply_budget_w {b}"),
            REPLY_TIMEOUT_S,
            &mut |l| events.push(l.to_string()),
        )?;
        if classify(&set) != LineKind::Ok {
            return Err(MorphEnd::Failed(format!("--budget-w {b} refused: {set}")));
        }
        println!("{set}");
    }
    wait_for_sensors(link, &mut |l| events.push(l.to_string()))?;
    let (_, reply) = link
        .command(&line, REPLY_TIMEOUT_S, &mut |l| events.push(l.to_string()))
        .map_err(|e| match e {
            // Never written: nothing started.
            LinkError::Closed(e) => MorphEnd::Failed(e),
            // Sent, so it may have started.
            e => MorphEnd::Broken(e),
        })?;
    if reply != morphlink::protocol::OK {
        return Err(MorphEnd::Failed(format!("GAIT refused: {reply}")));
    }
    Ok(n)
}

fn follow(
    link: &mut Link,
    n: usize,
    o: &Opts,
    samples: &mut Vec<GaitSample>,
    csv: &mut Option<CsvLog>,
    mut events: Vec<String>,
) -> Result<ExitCode, MorphEnd> {
    let mut clock = Clock::new();
    let mut ends = vec![End::Running; n];
    let mut last_line: Option<Instant> = None;
    loop {
        for e in events.drain(..) {
            println!("{e}");
            let (k, _) = link_of(&e);
            let end = match classify(&e) {
                LineKind::Done => End::Done,
                LineKind::Alarm => End::Alarm,
                _ => continue,
            };
            match k {
                Some(k) if k < n => ends[k] = end,
                // An alarm with no address (a one-link line) stops the board's only link.
                _ => ends.iter_mut().for_each(|x| *x = end),
            }
        }
        if ends.iter().all(|e| *e != End::Running) {
            let ok = ends.iter().all(|e| *e == End::Done);
            return Ok(if ok {
                ExitCode::SUCCESS
            } else {
                ExitCode::FAILURE
            });
        }
        let poll = poll(link, &mut clock, &mut |l| events.push(l.to_string()))?;
        if last_line.is_none_or(|t| t.elapsed() >= Duration::from_millis(200)) {
            println!("{}", running_line(&poll));
            let _ = std::io::stdout().flush();
            last_line = Some(Instant::now());
        }
        let t_s = poll.first().map_or(0.0, |s| s.sample.t_s);
        let stopped = poll
            .iter()
            .all(|s| s.sample.phase == "idle" || s.sample.phase == "fault");
        for s in poll {
            if let Some(csv) = csv {
                csv.line(&s.csv_row());
            }
            samples.push(s);
        }
        if stopped && events.is_empty() {
            // The done or alarm may already have been read with these replies; give it a tick.
            if let Some(l) = link.recv(Duration::from_millis(300))? {
                events.push(l);
                continue;
            }
            return Err(MorphEnd::Failed(
                "every link stopped without a done or an alarm for each".into(),
            ));
        }
        if t_s > o.timeout_s {
            return Err(MorphEnd::Broken(LinkError::Timeout(format!(
                "not every link done after {} s",
                o.timeout_s
            ))));
        }
        if let Some(l) = link.recv(o.poll)? {
            events.push(l);
        }
    }
}

/// The time of a gait's polls: the simulator's clock where it has one, else the host's, from
/// the first poll.
pub struct Clock {
    start: Instant,
    sim_start: Option<f64>,
}

impl Clock {
    /// A clock starting at the first poll.
    pub fn new() -> Clock {
        Clock {
            start: Instant::now(),
            sim_start: None,
        }
    }
}

/// One poll: the time, each link's STATUS (`@* STATUS`) and true radius (`@k SIM STATE` on
/// the simulator), and the supply's total power and budget (`LINKS`).
pub fn poll(
    link: &mut Link,
    clock: &mut Clock,
    on_event: &mut dyn FnMut(&str),
) -> Result<Vec<GaitSample>, LinkError> {
    let sim = sim_time_and_radius(link, on_event)?;
    let t_s = match sim {
        Some((t, _)) => t - *clock.sim_start.get_or_insert(t),
        None => clock.start.elapsed().as_secs_f64(),
    };
    let (statuses, end) = link.command("@* STATUS", REPLY_TIMEOUT_S, on_event)?;
    let (rows, links) = link.command("LINKS", REPLY_TIMEOUT_S, on_event)?;
    // A link whose MORPH waits for the budget reads idle in its STATUS: LINKS says it is queued.
    let queued = |k: usize| {
        rows.iter()
            .any(|r| link_of(r).0 == Some(k) && field(r, "queued").as_deref() == Some("yes"))
    };
    // A poll that is not every link's (an error reply, lost lines) cannot say the links have
    // stopped: it breaks the gait, which then stops every heater.
    if classify(&end) != LineKind::Ok
        || classify(&links) != LineKind::Ok
        || statuses.len() != link.links
    {
        return Err(LinkError::Protocol(format!(
            "a poll of every link got `{end}` and `{links}` ({} of {} STATUS lines)",
            statuses.len(),
            link.links
        )));
    }
    let num = |key: &str| {
        field(&links, key)
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap_or(f64::NAN)
    };
    let (total_w, budget_w) = (num("power_w"), num("budget_w"));
    let mut out = Vec::with_capacity(statuses.len());
    for d in &statuses {
        let (Some(k), status) = link_of(d) else {
            continue;
        };
        let radius_mm = if link.simulated {
            let (_, st) =
                link.command(&format!("@{} SIM STATE", k + 1), REPLY_TIMEOUT_S, on_event)?;
            field(&st, "radius_mm")
                .and_then(|v| v.parse().ok())
                .unwrap_or(f64::NAN)
        } else {
            f64::NAN
        };
        let mut sample = Sample::from_status(t_s, status, radius_mm);
        if queued(k) {
            sample.phase = "queued".into();
        }
        out.push(GaitSample {
            link: k,
            sample,
            total_w,
            budget_w,
        });
    }
    Ok(out)
}

/// A poll as one line: the time, each link's phase and power, the total against the budget.
fn running_line(poll: &[GaitSample]) -> String {
    let Some(first) = poll.first() else {
        return String::new();
    };
    let mut line = format!("{:>6.1} s", first.sample.t_s);
    for s in poll {
        let p: f64 = s.sample.powers_w.iter().sum();
        line.push_str(&format!(
            "  @{} {:<7} {:>5.2} W",
            s.link + 1,
            s.sample.phase,
            p
        ));
    }
    line.push_str(&format!("  total {:.2} W", first.total_w));
    if first.budget_w < UNBOUND_BUDGET_W {
        line.push_str(&format!(" of {:.2} W", first.budget_w));
    }
    line
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(link: usize, t_s: f64, phase: &str, p: [f64; 2]) -> GaitSample {
        let status = format!(
            "ok phase={phase} target_mm={} t_pla_c=40.00 t_tca_c=30.00 t_amb_c=22.00 p_pla_w={:.3} p_tca_w={:.3} supply_v=12.00 fault=none",
            34 + 4 * link,
            p[0],
            p[1]
        );
        GaitSample {
            link,
            sample: Sample::from_status(t_s, &status, 40.0 + link as f64),
            total_w: 5.5,
            budget_w: 8.0,
        }
    }

    #[test]
    fn a_gait_row_reads_back_as_written() {
        let s = sample(1, 12.5, "bend", [1.25, 0.5]);
        let row = s.csv_row();
        assert!(row.starts_with("2,12.50,bend,"), "{row}");
        assert_eq!(csv_header().split(',').count(), row.split(',').count());
        let back = GaitSample::parse_csv(&row).unwrap();
        assert_eq!(back.link, 1);
        assert_eq!(back.total_w, 5.5);
        assert_eq!(back.budget_w, 8.0);
        assert_eq!(back.sample.phase, "bend");
        assert_eq!(back.sample.powers_w, [1.25, 0.5]);
        assert!(GaitSample::parse_csv("0,1").is_err());
    }

    #[test]
    fn the_chart_has_a_point_per_poll_and_a_row_per_link() {
        let s = [
            sample(0, 0.0, "soften", [4.0, 0.0]),
            sample(1, 0.0, "soften", [1.0, 0.5]),
            sample(0, 0.5, "bend", [2.0, 1.0]),
            sample(1, 0.5, "soften", [3.0, 0.0]),
        ];
        let c = chart(&s, "t");
        assert_eq!(c.time_s, [0.0, 0.5]);
        assert_eq!(c.power_w, [vec![4.0, 3.0], vec![1.5, 3.0]]);
        assert_eq!(c.target_mm, [34.0, 38.0]);
        assert_eq!(c.budget_w, Some(8.0));
        assert_eq!(c.radius_mm[1], [41.0, 41.0]);
    }

    #[test]
    fn the_running_line_names_each_link_and_the_budget() {
        let s = [
            sample(0, 3.0, "bend", [2.0, 1.0]),
            sample(1, 3.0, "soften", [2.5, 0.0]),
        ];
        let l = running_line(&s);
        assert!(l.contains("@1 bend     3.00 W"), "{l}");
        assert!(l.contains("@2 soften   2.50 W"), "{l}");
        assert!(l.ends_with("total 5.50 W of 8.00 W"), "{l}");
    }
}
