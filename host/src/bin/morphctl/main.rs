//! `morphctl`: drive a morphlink board over its serial port, or `morph-sim` as a child
//! process, with protocol v1: morph to a radius and follow the phases, STATUS, ABORT, log
//! telemetry to CSV and plot a run (SVG, or PNG without text).
mod link;
mod telemetry;

use clap::{Parser, Subcommand};
use link::{default_sim_program, field, Link, Target, REPLY_TIMEOUT_S};
use morphlink::protocol::client::{classify, LineKind};
use std::io::Write;
use std::path::PathBuf;
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
    let mut link = Link::open(&target)?;
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
            let (code, samples) = morph(&mut link, &opts)?;
            if let Some(path) = log {
                let mut text = format!("{CSV_HEADER}\n");
                for s in &samples {
                    text.push_str(&s.csv_row());
                    text.push('\n');
                }
                std::fs::write(&path, text)
                    .map_err(|e| format!("cannot write {}: {e}", path.display()))?;
                println!("telemetry: {} ({} samples)", path.display(), samples.len());
            }
            if let Some(path) = plot {
                let title = format!("MORPH {} {} on {}", opts.radius_mm, opts.mode, link.name);
                telemetry::plot(&samples, &title, &path)?;
                println!("plot: {}", path.display());
            }
            Ok(code)
        }
        Cmd::Plot { .. } => unreachable!("handled above"),
    }
}

/// Sends one line and prints the reply; an `error:` reply is a failure exit.
fn simple(link: &mut Link, line: &str) -> Result<ExitCode, String> {
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
fn sim_time_and_radius(link: &mut Link, on_event: &mut dyn FnMut(&str)) -> Option<(f64, f64)> {
    if !link.simulated {
        return None;
    }
    let (_, st) = link.command("SIM STATE", REPLY_TIMEOUT_S, on_event).ok()?;
    let t = field(&st, "time_s")?.parse().ok()?;
    let r = field(&st, "radius_mm")?.parse().ok()?;
    Some((t, r))
}

/// Runs one morph: MORPH, then STATUS polls until `done` or an alarm; prints the phases.
fn morph(link: &mut Link, o: &MorphOpts) -> Result<(ExitCode, Vec<Sample>), String> {
    let mut events: Vec<String> = Vec::new();
    let (_, reply) = link.command(
        &format!("MORPH {} {}", o.radius_mm, o.mode),
        REPLY_TIMEOUT_S,
        &mut |l| events.push(l.to_string()),
    )?;
    if reply != morphlink::protocol::OK {
        return Err(format!("MORPH refused: {reply}"));
    }
    let start = Instant::now();
    let sim_start = sim_time_and_radius(link, &mut |l| events.push(l.to_string())).map(|x| x.0);
    let mut samples = Vec::new();
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
        let sim = sim_time_and_radius(link, &mut on_event);
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
        samples.push(s);
        if outcome.is_none() && (phase == "idle" || phase == "fault") && events.is_empty() {
            // The done/alarm event may already have been read with this reply; give it a tick.
            if let Some(l) = link.recv(Duration::from_millis(300))? {
                events.push(l);
                continue;
            }
            println!();
            return Err(format!(
                "the morph stopped in phase {phase} without a done event"
            ));
        }
        if t_s > o.timeout_s {
            let _ = link.command("ABORT", REPLY_TIMEOUT_S, &mut |_| {});
            println!();
            return Err(format!("no done after {} s: sent ABORT", o.timeout_s));
        }
        if outcome.is_none() {
            if let Some(l) = link.recv(o.poll)? {
                events.push(l);
            }
        }
    }
    println!();
    Ok((outcome.unwrap_or(ExitCode::FAILURE), samples))
}
