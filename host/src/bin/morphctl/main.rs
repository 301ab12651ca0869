//! `morphctl`: drive a morphlink board over its serial port, or `morph-sim` as a child
//! process, with protocol v1: morph to a radius and follow the phases, STATUS, ABORT, log
//! telemetry to CSV and plot a run (SVG, or PNG without text).
mod link;
mod telemetry;
mod tune;

use clap::{Parser, Subcommand};
use link::{default_sim_program, field, Link, LinkError, Target, REPLY_TIMEOUT_S};
use morphlink::protocol::client::{classify, LineKind};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};
use telemetry::{Sample, CSV_HEADER};

/// Serial baud rate by default: the firmware's UART bridge setting (USB CDC ignores it).
const DEFAULT_BAUD: u32 = 115_200;
/// Simulation speed of `--sim` by default: a 25 s morph passes in 2.5 s and every STATUS poll
/// still sees the phases.
const DEFAULT_SIM_SPEED: f64 = 10.0;
/// STATUS poll interval, ms: 2 Hz on a board (temperatures move on a second scale); on
/// `morph-sim` the interval is divided by the speed, so samples stay 0.5 s of link time apart.
const DEFAULT_POLL_MS: u64 = 500;
/// Longest a morph may run before morphctl sends ABORT, s: above the sum of the firmware's
/// phase timeouts (60 + 120 + 600 + 10 s).
const DEFAULT_MORPH_TIMEOUT_S: f64 = 900.0;
/// ABORTs sent before morphctl gives up confirming the heaters off: one lost line or a slow
/// reply is retried, a dead device costs at most this many reply timeouts.
const ABORT_TRIES: u32 = 3;

#[derive(Parser)]
#[command(
    name = "morphctl",
    version,
    about = "Control a morphlink board over a serial port, or morph-sim (--sim)"
)]
struct Cli {
    /// Serial port of the board (e.g. /dev/ttyACM0, COM3).
    #[arg(long, conflicts_with = "sim")]
    port: Option<String>,
    /// Baud rate of the serial port.
    #[arg(long, default_value_t = DEFAULT_BAUD)]
    baud: u32,
    /// Talk to the simulated link: start morph-sim as a child over pipes.
    #[arg(long)]
    sim: bool,
    /// morph-sim speed, a factor of real time.
    #[arg(long, default_value_t = DEFAULT_SIM_SPEED)]
    sim_speed: f64,
    /// The morph-sim executable (default: beside morphctl, else on the PATH).
    #[arg(long)]
    sim_program: Option<PathBuf>,
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Morph to a radius and follow it through the phases until done.
    Morph {
        /// Target radius, mm (RANGE shows the reachable ones).
        radius_mm: f32,
        /// Strategy: auto, paper, gated, boost or closed.
        #[arg(long, default_value = "auto")]
        mode: String,
        /// Write the telemetry to this CSV file.
        #[arg(long)]
        log: Option<PathBuf>,
        /// Plot the run to this file (.svg, or .png without text).
        #[arg(long)]
        plot: Option<PathBuf>,
        /// STATUS poll interval, ms of link time.
        #[arg(long, default_value_t = DEFAULT_POLL_MS)]
        poll_ms: u64,
        /// Abort the morph if it is not done after this many seconds of link time.
        #[arg(long, default_value_t = DEFAULT_MORPH_TIMEOUT_S)]
        timeout_s: f64,
    },
    /// Print STATUS.
    Status,
    /// Both heaters off at once (ABORT).
    Abort,
    /// Clear a latched fault whose cause is gone (RESET).
    Reset,
    /// Print the firmware version and the reachable radii.
    Info,
    /// Send one protocol line and print every reply line.
    Send {
        /// The line, e.g. `TABLE` or `SIM SUPPLY 11`.
        line: Vec<String>,
    },
    /// Plot a telemetry CSV written by `morph --log` (needs no device).
    Plot {
        /// The CSV file.
        csv: PathBuf,
        /// The plot (.svg, or .png without text).
        out: PathBuf,
    },
    /// Fit the thermal model to this link (TUNE, under 3 minutes of heating); Ctrl-C aborts.
    Tune,
    /// Guided calibration: morph to a few radii, send each measured radius (MEASURED).
    Calibrate {
        /// Radii to morph to, mm (default: three across RANGE).
        #[arg(long, value_delimiter = ',')]
        radii: Vec<f32>,
        /// The measured radii, mm, in order (default: asked after each morph).
        #[arg(long, value_delimiter = ',')]
        measured: Vec<f32>,
        /// Strategy: auto, paper, gated, boost or closed.
        #[arg(long, default_value = "auto")]
        mode: String,
    },
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("morphctl: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> Result<ExitCode, String> {
    if let Cmd::Plot { csv, out } = &cli.cmd {
        let samples = telemetry::read_csv(csv)?;
        telemetry::plot(&samples, &csv.display().to_string(), out)?;
        println!("wrote {}", out.display());
        return Ok(ExitCode::SUCCESS);
    }
    let target = if cli.sim {
        Target::Sim {
            program: cli.sim_program.clone().unwrap_or_else(default_sim_program),
            speed: cli.sim_speed,
        }
    } else {
        Target::Serial {
            path: cli
                .port
                .clone()
                .ok_or("say where the link is: --port <serial port> or --sim")?,
            baud: cli.baud,
        }
    };
    let signals = link::watch_signals()?;
    let mut link = Link::open(&target)?;
    link.watch(signals);
    let version = link.handshake()?;
    let print_event = &mut |l: &str| println!("{l}");
    match cli.cmd {
        Cmd::Status => simple(&mut link, "STATUS"),
        Cmd::Abort => simple(&mut link, "ABORT"),
        Cmd::Reset => simple(&mut link, "RESET"),
        Cmd::Info => {
            let (_, range) = link.command("RANGE", REPLY_TIMEOUT_S, print_event)?;
            println!(
                "{}: firmware {version}, protocol {}; reachable {}..{} mm",
                link.name,
                link::PROTOCOL,
                field(&range, "min_mm").unwrap_or_default(),
                field(&range, "max_mm").unwrap_or_default()
            );
            Ok(ExitCode::SUCCESS)
        }
        Cmd::Send { line } => simple(&mut link, &line.join(" ")),
        Cmd::Morph {
            radius_mm,
            mode,
            log,
            plot,
            poll_ms,
            timeout_s,
        } => {
            let speed = if link.simulated { cli.sim_speed } else { 1.0 };
            let opts = MorphOpts {
                radius_mm,
                mode,
                poll: Duration::from_secs_f64(poll_ms as f64 / 1000.0 / speed),
                timeout_s,
            };
            let mut csv = match &log {
                Some(path) => Some(CsvLog::create(path)?),
                None => None,
            };
            let mut samples = Vec::new();
            let end = morph(&mut link, &opts, &mut samples, &mut csv);
            let code = finish(&mut link, end);
            if let (Some(path), Some(csv)) = (&log, &csv) {
                println!("telemetry: {} ({} samples)", path.display(), csv.rows);
                if let Some(e) = &csv.failed {
                    eprintln!("morphctl: the log stopped early: {e}");
                }
            }
            if let Some(path) = plot {
                let title = format!("MORPH {} {} on {}", opts.radius_mm, opts.mode, link.name);
                if samples.is_empty() {
                    println!("plot: skipped, no samples were logged");
                } else {
                    match telemetry::plot(&samples, &title, &path) {
                        Ok(()) => println!("plot: {}", path.display()),
                        Err(e) => eprintln!("morphctl: plot: {e}"),
                    }
                }
            }
            Ok(code)
        }
        Cmd::Plot { .. } => unreachable!("handled above"),
        Cmd::Tune => {
            let speed = if link.simulated { cli.sim_speed } else { 1.0 };
            Ok(tune::tune(&mut link, speed))
        }
        Cmd::Calibrate {
            radii,
            measured,
            mode,
        } => {
            let speed = if link.simulated { cli.sim_speed } else { 1.0 };
            let poll = Duration::from_secs_f64(DEFAULT_POLL_MS as f64 / 1000.0 / speed);
            tune::calibrate(&mut link, &radii, &measured, &mode, poll)
        }
    }
}

/// Sends one line and prints the reply; an `error:` reply is a failure exit.
fn simple(link: &mut Link, line: &str) -> Result<ExitCode, String> {
    if let Some(sig) = link.signal() {
        return Err(LinkError::Interrupted(sig).into());
    }
    let (data, fin) = link.command(line, REPLY_TIMEOUT_S, &mut |l| println!("{l}"))?;
    for d in data {
        println!("data: {d}");
    }
    println!("{fin}");
    Ok(if classify(&fin) == LineKind::Error {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    })
}

struct MorphOpts {
    radius_mm: f32,
    mode: String,
    poll: Duration,
    timeout_s: f64,
}

/// Link time from `SIM STATE` on the simulator, s; None on a board.
/// A link that fails is an error; a reply without the numbers is None.
fn sim_time_and_radius(
    link: &mut Link,
    on_event: &mut dyn FnMut(&str),
) -> Result<Option<(f64, f64)>, LinkError> {
    if !link.simulated {
        return Ok(None);
    }
    let (_, st) = link.command("SIM STATE", REPLY_TIMEOUT_S, on_event)?;
    let num = |key: &str| field(&st, key)?.parse::<f64>().ok();
    Ok(num("time_s").zip(num("radius_mm")))
}

/// The telemetry CSV, written as the samples arrive: a run that ends early keeps its rows.
struct CsvLog {
    file: BufWriter<File>,
    path: PathBuf,
    rows: usize,
    /// The first write error; later rows are not attempted.
    failed: Option<String>,
}

impl CsvLog {
    fn create(path: &Path) -> Result<CsvLog, String> {
        let mut log = CsvLog {
            file: BufWriter::new(
                File::create(path).map_err(|e| format!("cannot write {}: {e}", path.display()))?,
            ),
            path: path.to_path_buf(),
            rows: 0,
            failed: None,
        };
        log.line(CSV_HEADER);
        match log.failed.take() {
            Some(e) => Err(e),
            None => Ok(log),
        }
    }

    /// Appends one line and flushes it to the file.
    fn line(&mut self, text: &str) {
        if self.failed.is_some() {
            return;
        }
        if let Err(e) = writeln!(self.file, "{text}").and_then(|_| self.file.flush()) {
            self.failed = Some(format!("cannot write {}: {e}", self.path.display()));
        }
    }

    fn row(&mut self, s: &Sample) {
        self.line(&s.csv_row());
        if self.failed.is_none() {
            self.rows += 1;
        }
    }
}

/// How a morph ended.
enum MorphEnd {
    /// `event: done` (exit 0) or an alarm (the controller has turned the heaters off; exit 1).
    Finished(ExitCode),
    /// Failed with no heater left on: MORPH refused or never written, or the morph went idle
    /// on its own without `done`.
    Failed(String),
    /// Anything else once MORPH was sent: a signal, a lost reply, a closed link, garbage, an
    /// overrun. The heaters may be on.
    Broken(LinkError),
}

impl From<LinkError> for MorphEnd {
    fn from(e: LinkError) -> MorphEnd {
        MorphEnd::Broken(e)
    }
}

/// Turns a morph's end into the exit code; after a broken morph stops the heaters first.
fn finish(link: &mut Link, end: MorphEnd) -> ExitCode {
    let why = match end {
        MorphEnd::Finished(code) => return code,
        MorphEnd::Failed(why) => {
            eprintln!("morphctl: {why}");
            return ExitCode::FAILURE;
        }
        MorphEnd::Broken(why) => why,
    };
    println!();
    eprintln!("morphctl: {why}; stopping the heaters");
    match stop_heaters(link) {
        Ok(done) => eprintln!("morphctl: {done}"),
        Err(e) => eprintln!(
            "morphctl: could not confirm the heaters off after {ABORT_TRIES} ABORTs ({e}); {} is lost: the heaters may still be on, cut the heater supply",
            link.name
        ),
    }
    match why {
        // The shell's convention for a run ended by a signal.
        LinkError::Interrupted(sig) => ExitCode::from((128 + sig) as u8),
        _ => ExitCode::FAILURE,
    }
}

/// Sends ABORT until STATUS shows both heaters off (at most [`ABORT_TRIES`] times); signals
/// do not cut this short.
fn stop_heaters(link: &mut Link) -> Result<String, String> {
    link.set_interruptible(false);
    let mut last = String::new();
    for attempt in 1..=ABORT_TRIES {
        match abort_and_check(link) {
            Ok(status) => {
                return Ok(format!(
                    "sent ABORT ({attempt} of at most {ABORT_TRIES}); heaters off: {status}"
                ))
            }
            Err(e) => {
                eprintln!("morphctl: ABORT {attempt} of {ABORT_TRIES}: {e}");
                last = e;
            }
        }
    }
    Err(last)
}

/// One ABORT, then STATUS: Ok(the STATUS line) if it shows the heaters off.
fn abort_and_check(link: &mut Link) -> Result<String, String> {
    let print_event = &mut |l: &str| println!("{l}");
    // ABORT answers a plain `ok`; STATUS `ok phase=...`: anything else is a late reply.
    let (_, reply) = link.command_where("ABORT", REPLY_TIMEOUT_S, print_event, &|l| {
        l == morphlink::protocol::OK || classify(l) == LineKind::Error
    })?;
    if classify(&reply) != LineKind::Ok {
        return Err(format!("ABORT answered `{reply}`"));
    }
    let (_, status) = link.command_where("STATUS", REPLY_TIMEOUT_S, print_event, &|l| {
        field(l, "phase").is_some() || classify(l) == LineKind::Error
    })?;
    if heaters_off(&status) {
        Ok(status)
    } else {
        Err(format!("STATUS does not show the heaters off: `{status}`"))
    }
}

/// True if a STATUS reply shows both powers zero in phase idle or fault.
fn heaters_off(status: &str) -> bool {
    let is =
        |key: &str, want: &[&str]| field(status, key).is_some_and(|v| want.contains(&v.as_str()));
    classify(status) == LineKind::Ok
        && is("p_pla_w", &["0.000"])
        && is("p_tca_w", &["0.000"])
        && is("phase", &["idle", "fault"])
}

/// Runs one morph: MORPH, then STATUS polls until `done` or an alarm; prints the phases and
/// appends each sample to `samples` and the log.
fn morph(
    link: &mut Link,
    o: &MorphOpts,
    samples: &mut Vec<Sample>,
    csv: &mut Option<CsvLog>,
) -> MorphEnd {
    let mut events: Vec<String> = Vec::new();
    let line = format!("MORPH {} {}", o.radius_mm, o.mode);
    let reply = match link.command(&line, REPLY_TIMEOUT_S, &mut |l| events.push(l.to_string())) {
        Ok((_, reply)) => reply,
        // Never written: nothing started.
        Err(LinkError::Closed(e)) => return MorphEnd::Failed(e),
        // Sent, so it may have started.
        Err(e) => return MorphEnd::Broken(e),
    };
    if reply != morphlink::protocol::OK {
        return MorphEnd::Failed(format!("MORPH refused: {reply}"));
    }
    match follow(link, o, samples, csv, events) {
        Ok(code) => MorphEnd::Finished(code),
        Err(e) => e,
    }
}

/// Follows a started morph to its end.
fn follow(
    link: &mut Link,
    o: &MorphOpts,
    samples: &mut Vec<Sample>,
    csv: &mut Option<CsvLog>,
    mut events: Vec<String>,
) -> Result<ExitCode, MorphEnd> {
    let start = Instant::now();
    let sim_start = sim_time_and_radius(link, &mut |l| events.push(l.to_string()))?.map(|x| x.0);
    let mut outcome = None;
    let mut last_line = Instant::now();
    while outcome.is_none() {
        for e in events.drain(..) {
            println!("\r{e:<78}");
            match classify(&e) {
                LineKind::Done => outcome = Some(ExitCode::SUCCESS),
                LineKind::Alarm => outcome = Some(ExitCode::FAILURE),
                _ => {}
            }
        }
        let mut on_event = |l: &str| events.push(l.to_string());
        let sim = sim_time_and_radius(link, &mut on_event)?;
        let (_, status) = link.command("STATUS", REPLY_TIMEOUT_S, &mut on_event)?;
        let t_s = match (sim, sim_start) {
            (Some((t, _)), Some(t0)) => t - t0,
            _ => start.elapsed().as_secs_f64(),
        };
        let s = Sample::from_status(t_s, &status, sim.map(|x| x.1).unwrap_or(f64::NAN));
        if last_line.elapsed() >= Duration::from_millis(200) || outcome.is_some() {
            print!(
                "\r{:>6.1} s  {:<8} PLA {:>6.1} °C  TCA {:>6.1} °C  power {:.2} / {:.2} W   ",
                s.t_s, s.phase, s.temps_c[0], s.temps_c[1], s.powers_w[0], s.powers_w[1]
            );
            let _ = std::io::stdout().flush();
            last_line = Instant::now();
        }
        let phase = s.phase.clone();
        if let Some(csv) = csv {
            csv.row(&s);
        }
        samples.push(s);
        if outcome.is_none() && (phase == "idle" || phase == "fault") && events.is_empty() {
            // The done/alarm event may already have been read with this reply; give it a tick.
            if let Some(l) = link.recv(Duration::from_millis(300))? {
                events.push(l);
                continue;
            }
            println!();
            return Err(MorphEnd::Failed(format!(
                "the morph stopped in phase {phase} without a done event"
            )));
        }
        if t_s > o.timeout_s {
            return Err(MorphEnd::Broken(LinkError::Timeout(format!(
                "no done after {} s",
                o.timeout_s
            ))));
        }
        if outcome.is_none() {
            if let Some(l) = link.recv(o.poll)? {
                events.push(l);
            }
        }
    }
    println!();
    Ok(outcome.unwrap_or(ExitCode::FAILURE))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heaters_off_needs_both_powers_zero_in_idle_or_fault() {
        let st = |phase: &str, pla: &str, tca: &str| {
            format!("ok phase={phase} target_mm=38.00 t_pla_c=74.17 t_tca_c=56.88 t_amb_c=21.94 p_pla_w={pla} p_tca_w={tca} supply_v=12.00 fault=none")
        };
        assert!(heaters_off(&st("idle", "0.000", "0.000")));
        assert!(heaters_off(&st("fault", "0.000", "0.000")));
        assert!(!heaters_off(&st("bend", "0.000", "0.000")));
        assert!(!heaters_off(&st("idle", "0.000", "0.001")));
        assert!(!heaters_off(&st("idle", "1.500", "0.000")));
        assert!(!heaters_off("ok"));
        assert!(!heaters_off(
            "error: busy p_pla_w=0.000 p_tca_w=0.000 phase=idle"
        ));
    }
}
