//! `morphctl`: drive a morphlink board over its serial port, or `morph-sim` as a child
//! process, with protocol v1: morph to a radius and follow the phases, STATUS, ABORT, log
//! telemetry to CSV and plot a run (SVG or PNG, with text).
mod bringup;
mod config;
mod gait;
mod gait_view;
mod link;
mod live;
mod script;
mod telemetry;
mod tune;

use clap::{Parser, Subcommand};
use link::{default_sim_program, field, Link, LinkError, Target, REPLY_TIMEOUT_S};
use morphlink::protocol::client::{classify, LineKind};
use morphlink_host::plot;
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
    #[arg(long, conflicts_with_all = ["sim", "tcp"])]
    port: Option<String>,
    /// A serial port served over TCP, HOST:PORT: the emulated image (`cargo xtask emulate
    /// --port PORT`) or a serial-to-TCP bridge.
    #[arg(long, conflicts_with = "sim")]
    tcp: Option<String>,
    /// How many times faster than real time the device on --tcp runs: 20 for the emulated
    /// image, 1 for a board behind a bridge.
    #[arg(long, default_value_t = 1.0)]
    tcp_speed: f64,
    /// Baud rate of the serial port.
    #[arg(long, default_value_t = DEFAULT_BAUD)]
    baud: u32,
    /// Talk to the simulated link: start morph-sim as a child over pipes.
    #[arg(long)]
    sim: bool,
    /// morph-sim speed, a factor of real time (also `--speed`, before or after the command).
    #[arg(long, global = true, visible_alias = "speed", value_name = "FACTOR",
          default_value_t = DEFAULT_SIM_SPEED, value_parser = parse_sim_speed,
          allow_hyphen_values = true)]
    sim_speed: f64,
    /// The morph-sim program, with arguments if any, split as a shell would
    /// (`--sim-program "morph-sim --seed 3"`; default: beside morphctl, else on the PATH).
    #[arg(long, value_name = "PROGRAM [ARGS]")]
    sim_program: Option<String>,
    /// morph-sim's plant: `lumped` (its default) or `hifi` (its `--plant`).
    #[arg(long, requires = "sim", value_name = "NAME")]
    sim_plant: Option<String>,
    /// Keep morph-sim's settings flash in this file (its `--flash-file`), so `config save`
    /// survives a restart. A path morph-sim would refuse (a FIFO, a directory, a read-only
    /// file) is refused before the simulator starts.
    #[arg(long, requires = "sim")]
    sim_flash_file: Option<PathBuf>,
    /// How many links morph-sim simulates on one supply (its `--links`, 1 to 4), for `gait`.
    #[arg(long, requires = "sim", value_name = "N",
          value_parser = clap::value_parser!(u8).range(1..=4))]
    sim_links: Option<u8>,
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
        /// Plot the run to this file (.svg or .png; checked before the morph starts).
        #[arg(long)]
        plot: Option<PathBuf>,
        /// STATUS poll interval, ms of link time.
        #[arg(long, default_value_t = DEFAULT_POLL_MS)]
        poll_ms: u64,
        /// Abort the morph if it is not done after this many seconds of link time.
        #[arg(long, default_value_t = DEFAULT_MORPH_TIMEOUT_S, value_parser = parse_timeout_s)]
        timeout_s: f64,
        /// Follow the morph in a live terminal view (key `a` aborts, `q` quits).
        #[arg(long)]
        live: bool,
    },
    /// Morph several links at once on one supply (GAIT, one radius per link) and follow each
    /// to its end: each link's phase and power and the supply's total against its budget.
    Gait {
        /// One target radius per link, mm.
        #[arg(required = true, num_args = 1..)]
        radii_mm: Vec<f32>,
        /// Strategy for every link: auto, paper, gated, boost or closed.
        #[arg(long, default_value = "auto")]
        mode: String,
        /// Write the telemetry to this CSV file (a row per link per poll).
        #[arg(long)]
        log: Option<PathBuf>,
        /// Plot the run to this file (.svg or .png; checked before the gait starts).
        #[arg(long)]
        plot: Option<PathBuf>,
        /// Poll interval, ms of link time.
        #[arg(long, default_value_t = DEFAULT_POLL_MS)]
        poll_ms: u64,
        /// Abort if not every link is done after this many seconds of link time.
        #[arg(long, default_value_t = 2.0 * DEFAULT_MORPH_TIMEOUT_S, value_parser = parse_timeout_s)]
        timeout_s: f64,
        /// Set the supply budget first (`CONFIG SET supply_budget_w`), W.
        #[arg(long)]
        budget_w: Option<f32>,
        /// Follow the gait in a live terminal view, a row per link (key `a` aborts, `q` quits).
        #[arg(long)]
        live: bool,
    },
    /// Watch the device in a live terminal view without starting anything (`a` sends ABORT).
    Watch {
        /// STATUS poll interval, ms of link time.
        #[arg(long, default_value_t = DEFAULT_POLL_MS)]
        poll_ms: u64,
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
    /// Check a new board before its first morph: thermistors agree at rest, the supply is in
    /// range, each heater's low-power pulse warms its own thermistor; heaters off at the end.
    Bringup,
    /// Play a script on one link: protocol lines, `wait done|alarm [<s>]`, `sleep <s>`, `#`
    /// comments; every line sent and received is logged with its time.
    Run {
        /// The script file.
        file: PathBuf,
        /// Also write the session log to this file.
        #[arg(long)]
        log: Option<PathBuf>,
    },
    /// Plot a telemetry CSV written by `morph --log` or `gait --log` (needs no device).
    Plot {
        /// The CSV file.
        csv: PathBuf,
        /// The plot (.svg or .png).
        out: PathBuf,
    },
    /// The device's settings: list, set one, reset all to defaults, save to flash.
    Config {
        #[command(subcommand)]
        cmd: Option<config::ConfigCmd>,
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

/// `--sim-speed`: a factor of real time. `max` is morph-sim's own (as fast as it can): morphctl
/// paces its polls by the factor, so it needs a number.
fn parse_sim_speed(s: &str) -> Result<f64, String> {
    if s.eq_ignore_ascii_case("max") {
        return Err("morphctl needs a factor of real time (it paces its STATUS polls by it), e.g. --sim-speed 100; `max` is morph-sim's own".into());
    }
    let f: f64 = s
        .parse()
        .map_err(|_| format!("a factor of real time, e.g. 10, not `{s}`"))?;
    morphlink_host::speed::check("--sim-speed", f)
}

/// `--timeout-s`: a number of seconds above 0 (NaN would turn the timeout off, a negative
/// one end every morph at once).
fn parse_timeout_s(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(t) if t > 0.0 && t.is_finite() => Ok(t),
        _ => Err(format!("a number of seconds above 0, not `{s}`")),
    }
}

/// Refuses a file morphctl could not write at the end of a run (`--plot`), before anything is
/// sent: its directory must exist and take a new file.
fn check_writable(path: &Path, what: &str) -> Result<(), String> {
    morphlink_host::out_path::check_new_file(path)
        .map_err(|e| format!("{what} {}: {e}", path.display()))
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
    // A plot that could not be written is refused before anything is sent.
    if let Cmd::Morph {
        plot: Some(path), ..
    }
    | Cmd::Gait {
        plot: Some(path), ..
    } = &cli.cmd
    {
        plot::Format::of(path)?;
        check_writable(path, "--plot")?;
    }
    // The live view needs a terminal to draw on, known before anything is sent.
    if matches!(
        cli.cmd,
        Cmd::Morph { live: true, .. } | Cmd::Gait { live: true, .. } | Cmd::Watch { .. }
    ) {
        use std::io::IsTerminal;
        if !std::io::stdout().is_terminal() || !std::io::stdin().is_terminal() {
            return Err("the live view needs a terminal (stdin and stdout); without --live, morph prints its progress as lines".into());
        }
    }
    if let Cmd::Plot { csv, out } = &cli.cmd {
        plot::Format::of(out)?;
        if gait::is_gait_log(csv) {
            let samples = gait::read_csv(csv)?;
            gait::plot(&samples, &csv.display().to_string(), out)?;
            println!("wrote {}", out.display());
            return Ok(ExitCode::SUCCESS);
        }
        let samples = telemetry::read_csv(csv)?;
        let name = csv.display().to_string();
        let title = match samples.iter().rev().find(|s| s.mode != "-") {
            Some(s) => format!("{name}: {} ran", s.mode),
            None => name,
        };
        telemetry::plot(&samples, &title, out)?;
        println!("wrote {}", out.display());
        return Ok(ExitCode::SUCCESS);
    }
    // A script is read whole before the link opens: a typo changes nothing.
    let script = match &cli.cmd {
        Cmd::Run { file, .. } => Some(script::read(file)?),
        _ => None,
    };
    morphlink_host::speed::check("--tcp-speed", cli.tcp_speed)?;
    // morph-sim refuses such a file too, but its stderr is not shown here: say why first.
    if let Some(f) = &cli.sim_flash_file {
        morphlink_host::flash_file::check(f)
            .map_err(|why| format!("--sim-flash-file {}: {why}", f.display()))?;
    }
    let target = if cli.sim {
        let (program, args) = match &cli.sim_program {
            Some(line) => {
                let words = shlex::split(line).filter(|w| !w.is_empty()).ok_or(format!(
                    "--sim-program `{line}`: unbalanced quotes or empty"
                ))?;
                // morphctl gives the simulator these itself: twice, morph-sim would refuse.
                // (its option, morphctl's, whether morphctl passes it now): the speed paces
                // morphctl's polls and the flash file decides whether morphctl saves a fit, so
                // morphctl must know both.
                let own = [
                    ("--speed", "--sim-speed", true),
                    ("--flash-file", "--sim-flash-file", true),
                    ("--plant", "--sim-plant", cli.sim_plant.is_some()),
                    ("--links", "--sim-links", cli.sim_links.is_some()),
                ];
                for (flag, ours, passed) in own {
                    let given = |w: &String| w == flag || w.starts_with(&format!("{flag}="));
                    if passed && words[1..].iter().any(given) {
                        return Err(format!(
                            "--sim-program `{line}`: give {flag} as morphctl's {ours}: morphctl \
                             passes it to the simulator and acts on it"
                        ));
                    }
                }
                (PathBuf::from(&words[0]), words[1..].to_vec())
            }
            None => (default_sim_program(), Vec::new()),
        };
        Target::Sim {
            program,
            args,
            plant: cli.sim_plant.clone(),
            speed: cli.sim_speed,
            flash_file: cli.sim_flash_file.clone(),
            links: cli.sim_links,
            given: cli.sim_program.is_some(),
        }
    } else if let Some(addr) = &cli.tcp {
        Target::Tcp { addr: addr.clone() }
    } else {
        Target::Serial {
            path: cli
                .port
                .clone()
                .ok_or("say where the link is: --port <serial port>, --tcp <HOST:PORT> or --sim")?,
            baud: cli.baud,
        }
    };
    let signals = link::watch_signals()?;
    let mut link = Link::open(&target)?;
    link.watch(signals);
    if let Target::Tcp { .. } = target {
        // The emulated image boots when the connection opens and drops what arrives before
        // its UART runs: wait for its boot line (a bridge to a running board sends none).
        let _ = link.recv(Duration::from_secs_f64(link::TCP_BOOT_WAIT_S))?;
    }
    let version = link.handshake()?;
    // Link seconds per host second.
    let speed = match target {
        Target::Sim { speed, .. } => speed,
        Target::Tcp { .. } => {
            // The emulated image answers SIM commands (its time, its true radius); a bridge
            // to a board does not.
            link.probe_simulated()?;
            cli.tcp_speed
        }
        Target::Serial { .. } => 1.0,
    };
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
            live,
        } => {
            let opts = MorphOpts {
                radius_mm,
                mode,
                poll: Duration::from_secs_f64(poll_ms as f64 / 1000.0 / speed),
                timeout_s,
            };
            let mut csv = match &log {
                Some(path) => Some(CsvLog::create(path, CSV_HEADER)?),
                None => None,
            };
            let mut samples = Vec::new();
            let mut code = if live {
                morph_live(&mut link, &opts, &mut samples, &mut csv)
            } else {
                let end = morph(&mut link, &opts, &mut samples, &mut csv);
                finish(&mut link, end)
            };
            if let (Some(path), Some(csv)) = (&log, &csv) {
                match csv.rows {
                    0 => println!("telemetry: none logged; {} left as it was", path.display()),
                    n => println!("telemetry: {} ({n} samples)", path.display()),
                }
                if let Some(e) = &csv.failed {
                    eprintln!("morphctl: the log stopped early: {e}");
                }
            }
            if let Some(path) = plot {
                let title = telemetry::title(opts.radius_mm, &opts.mode, &samples, &link.device());
                if samples.is_empty() {
                    println!("plot: skipped, no samples were logged");
                } else {
                    match telemetry::plot(&samples, &title, &path) {
                        Ok(()) => println!("plot: {}", path.display()),
                        Err(e) => {
                            eprintln!("morphctl: plot: {e}");
                            code = ExitCode::FAILURE;
                        }
                    }
                }
            }
            Ok(code)
        }
        Cmd::Gait {
            radii_mm,
            mode,
            log,
            plot,
            poll_ms,
            timeout_s,
            budget_w,
            live,
        } => {
            let opts = gait::Opts {
                radii_mm,
                mode,
                poll: Duration::from_secs_f64(poll_ms as f64 / 1000.0 / speed),
                timeout_s,
                budget_w,
            };
            let mut csv = match &log {
                Some(path) => Some(CsvLog::create(path, &gait::csv_header())?),
                None => None,
            };
            let mut samples = Vec::new();
            let mut code = if live {
                gait_live(&mut link, &opts, &mut samples, &mut csv)
            } else {
                let end = match gait::gait(&mut link, &opts, &mut samples, &mut csv) {
                    Ok(code) => MorphEnd::Finished(code),
                    Err(e) => e,
                };
                finish(&mut link, end)
            };
            if let (Some(path), Some(csv)) = (&log, &csv) {
                match csv.rows {
                    0 => println!("telemetry: none logged; {} left as it was", path.display()),
                    n => println!("telemetry: {} ({n} rows)", path.display()),
                }
                if let Some(e) = &csv.failed {
                    eprintln!("morphctl: the log stopped early: {e}");
                }
            }
            if let Some(path) = plot {
                let radii: Vec<String> = opts.radii_mm.iter().map(|r| format!("{r}")).collect();
                let title = format!(
                    "GAIT {} {} on {}",
                    radii.join(" "),
                    opts.mode,
                    link.device()
                );
                if samples.is_empty() {
                    println!("plot: skipped, no samples were logged");
                } else if let Err(e) = gait::plot(&samples, &title, &path) {
                    eprintln!("morphctl: plot: {e}");
                    code = ExitCode::FAILURE;
                } else {
                    println!("plot: {}", path.display());
                }
            }
            Ok(code)
        }
        Cmd::Config { cmd } => config::run(&mut link, cmd.unwrap_or(config::ConfigCmd::List)),
        Cmd::Watch { poll_ms } => {
            let poll = Duration::from_secs_f64(poll_ms as f64 / 1000.0 / speed);
            let mut st = live::LiveState::new(format!("watch {}", link.name), false, f64::INFINITY);
            let end = {
                let mut view = LiveTerminal::open()?;
                live::run(
                    &mut view.0,
                    &mut link,
                    &mut st,
                    poll,
                    Vec::new(),
                    &mut |_| {},
                )
            };
            Ok(end_live(&mut link, end))
        }
        Cmd::Bringup => {
            println!(
                "{}: firmware {version}; bring-up checks (docs/bringup.md)",
                link.name
            );
            let result = bringup::run(&mut link, speed, &mut |l| println!("  {l}"));
            let mut code = ExitCode::SUCCESS;
            match &result {
                Ok(checks) => {
                    for c in checks {
                        println!("{} {}", if c.ok { "ok  " } else { "FAIL" }, c.text);
                    }
                    if checks.iter().any(|c| !c.ok) {
                        code = ExitCode::FAILURE;
                    }
                }
                Err(bringup::Stop::Refused(why)) => {
                    eprintln!("morphctl: bring-up stopped: {why}");
                    code = ExitCode::FAILURE;
                }
                Err(bringup::Stop::Link(e)) => {
                    eprintln!("morphctl: bring-up stopped: {e}");
                    code = match e {
                        LinkError::Interrupted(sig) => ExitCode::from((128 + sig) as u8),
                        _ => ExitCode::FAILURE,
                    };
                }
            }
            // Heaters off at the end whatever happened.
            match stop_heaters(&mut link) {
                Ok(done) => println!("{done}"),
                Err(e) => {
                    eprintln!("morphctl: could not confirm the heaters off after {ABORT_TRIES} ABORTs ({e}); {} is lost: the heaters may still be on, cut the heater supply", link.name);
                    code = ExitCode::FAILURE;
                }
            }
            Ok(code)
        }
        Cmd::Run { log, .. } => {
            let steps = script.expect("read above");
            let mut log = script::Log::new(log.as_deref())?;
            log.note(&format!(
                "{}: firmware {version}; {} steps",
                link.name,
                steps.len()
            ));
            let end = script::play(&mut link, &steps, speed, &mut log);
            Ok(end_script(&mut link, end, &mut log))
        }
        Cmd::Plot { .. } => unreachable!("handled above"),
        Cmd::Tune => {
            let speed = if link.simulated { cli.sim_speed } else { 1.0 };
            let keep = tune::Keep::of(&target);
            Ok(tune::tune(&mut link, speed, &keep))
        }
        Cmd::Calibrate {
            radii,
            measured,
            mode,
        } => {
            let speed = if link.simulated { cli.sim_speed } else { 1.0 };
            let poll = Duration::from_secs_f64(DEFAULT_POLL_MS as f64 / 1000.0 / speed);
            let keep = tune::Keep::of(&target);
            tune::calibrate(&mut link, &radii, &measured, &mode, poll, &keep)
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

/// Link time (s) and true radius (mm) from `SIM STATE` on the simulator; None on a board.
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

/// The telemetry CSV, written as the samples arrive: a run that ends early keeps its rows. The
/// file is made at the first row, so a run that logs nothing (a MORPH refused) leaves whatever
/// was at the path as it was.
struct CsvLog {
    file: Option<BufWriter<File>>,
    path: PathBuf,
    header: String,
    /// Data rows written (the header is not one).
    rows: usize,
    /// The first write error; later rows are not attempted.
    failed: Option<String>,
}

impl CsvLog {
    /// A log at `path` under `header`, checked writable now and written from its first row.
    fn create(path: &Path, header: &str) -> Result<CsvLog, String> {
        check_writable(path, "--log")?;
        Ok(CsvLog {
            file: None,
            path: path.to_path_buf(),
            header: header.to_string(),
            rows: 0,
            failed: None,
        })
    }

    /// Appends one line and flushes it to the file (made, with its header, at the first).
    fn write_line(&mut self, text: &str) -> bool {
        if self.failed.is_some() {
            return false;
        }
        let written = (|| -> std::io::Result<()> {
            if self.file.is_none() {
                let mut f = BufWriter::new(File::create(&self.path)?);
                writeln!(f, "{}", self.header)?;
                self.file = Some(f);
            }
            let f = self.file.as_mut().expect("made above");
            writeln!(f, "{text}")?;
            f.flush()
        })();
        if let Err(e) = written {
            self.failed = Some(format!("cannot write {}: {e}", self.path.display()));
            return false;
        }
        true
    }

    /// Appends one data row.
    fn line(&mut self, row: &str) {
        if self.write_line(row) {
            self.rows += 1;
        }
    }

    fn row(&mut self, s: &Sample) {
        self.line(&s.csv_row());
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

/// Ends a script: whatever happened, the heaters end off. A script that ran to its end is
/// checked with STATUS (a morph it left running is aborted); one that stopped on an error or
/// a signal gets ABORT and a heaters-off STATUS.
fn end_script(link: &mut Link, end: Result<(), script::Stop>, log: &mut script::Log) -> ExitCode {
    let code = match &end {
        Ok(()) => {
            log.note("script done");
            log.sent("STATUS");
            let status = link.command_where("STATUS", REPLY_TIMEOUT_S, &mut |l| log.got(l), &|l| {
                field(l, "phase").is_some() || classify(l) == LineKind::Error
            });
            match status {
                Ok((_, st)) if heaters_off(&st) => {
                    log.got(&st);
                    return ExitCode::SUCCESS;
                }
                Ok((_, st)) => {
                    log.got(&st);
                    log.note("the script left a heater on; stopping the heaters");
                    ExitCode::SUCCESS
                }
                Err(e) => {
                    log.note(&format!("{e}; stopping the heaters"));
                    ExitCode::FAILURE
                }
            }
        }
        Err(script::Stop::Failed(why)) => {
            log.note(&format!("{why}; stopping the heaters"));
            ExitCode::FAILURE
        }
        Err(script::Stop::Link(e)) => {
            log.note(&format!("{e}; stopping the heaters"));
            match e {
                LinkError::Interrupted(sig) => ExitCode::from((128 + sig) as u8),
                _ => ExitCode::FAILURE,
            }
        }
    };
    match stop_heaters(link) {
        Ok(done) => log.note(&done),
        Err(e) => {
            log.note(&format!(
                "could not confirm the heaters off after {ABORT_TRIES} ABORTs ({e}); {} is lost: the heaters may still be on, cut the heater supply",
                link.name
            ));
            return ExitCode::FAILURE;
        }
    }
    code
}

/// The terminal in the live view's mode (raw, alternate screen) until dropped.
struct LiveTerminal(ratatui::DefaultTerminal);

impl LiveTerminal {
    fn open() -> Result<LiveTerminal, String> {
        ratatui::try_init()
            .map(LiveTerminal)
            .map_err(|e| format!("cannot start the live view: {e}"))
    }
}

impl Drop for LiveTerminal {
    fn drop(&mut self) {
        ratatui::restore();
    }
}

/// A morph followed in the live view: MORPH, the view until the user quits, then as `morph`
/// ends (a user's abort, a lost link or a timeout stop the heaters).
fn morph_live(
    link: &mut Link,
    o: &MorphOpts,
    samples: &mut Vec<Sample>,
    csv: &mut Option<CsvLog>,
) -> ExitCode {
    let mut events: Vec<String> = Vec::new();
    if let Err(e) = wait_for_sensors(link, &mut |l| events.push(l.to_string())) {
        return finish(link, e);
    }
    let line = format!("MORPH {} {}", o.radius_mm, o.mode);
    let reply = match link.command(&line, REPLY_TIMEOUT_S, &mut |l| events.push(l.to_string())) {
        Ok((_, reply)) => reply,
        Err(LinkError::Closed(e)) => return finish(link, MorphEnd::Failed(e)),
        Err(e) => return finish(link, MorphEnd::Broken(e)),
    };
    if reply != morphlink::protocol::OK {
        return finish(link, MorphEnd::Failed(format!("MORPH refused: {reply}")));
    }
    let title = format!("{line} on {}", link.device());
    let mut st = live::LiveState::new(title, true, o.timeout_s);
    let end = match LiveTerminal::open() {
        Ok(mut view) => live::run(&mut view.0, link, &mut st, o.poll, events, &mut |s| {
            if let Some(csv) = csv.as_mut() {
                csv.row(s);
            }
            samples.push(s.clone());
        }),
        Err(e) => live::LiveEnd::Broken(LinkError::Closed(e)),
    };
    end_live(link, end)
}

/// A gait followed in the live view, a row per link: as `gait` starts it, then the view until
/// the user quits, then as `morph --live` ends.
fn gait_live(
    link: &mut Link,
    o: &gait::Opts,
    samples: &mut Vec<gait::GaitSample>,
    csv: &mut Option<CsvLog>,
) -> ExitCode {
    let mut events: Vec<String> = Vec::new();
    let n = match gait::start(link, o, &mut events) {
        Ok(n) => n,
        Err(e) => return finish(link, e),
    };
    let radii: Vec<String> = o.radii_mm.iter().map(|r| r.to_string()).collect();
    let title = format!("GAIT {} {} on {}", radii.join(" "), o.mode, link.device());
    let mut record = |s: &gait::GaitSample| {
        if let Some(csv) = csv.as_mut() {
            csv.line(&s.csv_row());
        }
        samples.push(s.clone());
    };
    let mut view = gait_view::GaitView::new(title, n, o.timeout_s, &mut record);
    let end = match LiveTerminal::open() {
        Ok(mut term) => live::run_view(&mut term.0, link, &mut view, o.poll, events),
        Err(e) => live::LiveEnd::Broken(LinkError::Closed(e)),
    };
    end_live(link, end)
}

/// The exit of a live view, after the terminal is restored: the outcome seen, or ABORT and
/// a heaters-off STATUS.
fn end_live(link: &mut Link, end: live::LiveEnd) -> ExitCode {
    match end {
        live::LiveEnd::Quit(Some(live::Outcome::Done(r))) => {
            println!("done: the controller estimates {r:.2} mm");
            ExitCode::SUCCESS
        }
        live::LiveEnd::Quit(Some(live::Outcome::EveryLinkDone)) => {
            println!("done: every link");
            ExitCode::SUCCESS
        }
        live::LiveEnd::Quit(Some(live::Outcome::Alarm(a))) => {
            println!("{a}");
            ExitCode::FAILURE
        }
        live::LiveEnd::Quit(None) => ExitCode::SUCCESS,
        live::LiveEnd::Abort => {
            eprintln!("morphctl: abort asked from the live view; stopping the heaters");
            match stop_heaters(link) {
                Ok(done) => {
                    eprintln!("morphctl: {done}");
                    ExitCode::FAILURE
                }
                Err(e) => {
                    eprintln!("morphctl: could not confirm the heaters off after {ABORT_TRIES} ABORTs ({e}); {} is lost: the heaters may still be on, cut the heater supply", link.name);
                    ExitCode::FAILURE
                }
            }
        }
        live::LiveEnd::TimedOut => finish(
            link,
            MorphEnd::Broken(LinkError::Timeout("no done within --timeout-s".into())),
        ),
        live::LiveEnd::Broken(e) => finish(link, MorphEnd::Broken(e)),
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
    if link.links > 1 {
        // Every link's STATUS: the ABORT stopped them all; each must show it.
        let (statuses, end) =
            link.command_where("@* STATUS", REPLY_TIMEOUT_S, print_event, &|l| {
                field(l, "links").is_some() || classify(l) == LineKind::Error
            })?;
        let all = statuses.len() == link.links
            && statuses
                .iter()
                .all(|d| heaters_off(morphlink::protocol::client::link_of(d).1));
        return if all {
            Ok(format!("every link ({end})"))
        } else {
            Err(format!(
                "@* STATUS does not show every link's heaters off: {statuses:?}"
            ))
        };
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

/// Longest morphctl waits for a device's first sensor reading before MORPH or TUNE, s of wall
/// time: the emulated image reads its first frame within a tick of booting, a board within a
/// second of its port opening (a USB CDC reset).
const SENSOR_WAIT_S: f64 = 5.0;

/// Polls STATUS until it shows a PLA temperature (a device that just booted refuses MORPH with
/// `error: busy no sensor reading yet`), at most [`SENSOR_WAIT_S`]; a device whose STATUS is
/// refused or not parsed is left to answer MORPH itself.
fn wait_for_sensors(link: &mut Link, on_event: &mut dyn FnMut(&str)) -> Result<(), MorphEnd> {
    let start = Instant::now();
    let mut said = false;
    loop {
        let (_, status) = link.command_where("STATUS", REPLY_TIMEOUT_S, on_event, &|l| {
            field(l, "phase").is_some() || classify(l) == LineKind::Error
        })?;
        let read = field(&status, "t_pla_c").and_then(|v| v.parse::<f64>().ok());
        if classify(&status) != LineKind::Ok || field(&status, "t_pla_c").is_none() {
            return Ok(());
        }
        if read.is_some_and(f64::is_finite) {
            if said {
                println!(
                    "{}: sensors read after {:.1} s",
                    link.name,
                    start.elapsed().as_secs_f64()
                );
            }
            return Ok(());
        }
        if start.elapsed().as_secs_f64() >= SENSOR_WAIT_S {
            return Err(MorphEnd::Failed(format!(
                "{} has no sensor reading after {SENSOR_WAIT_S} s (STATUS: `{status}`); check the thermistors' wiring, or retry once it has booted",
                link.name
            )));
        }
        if !said {
            println!(
                "{}: waiting for the first sensor reading (at most {SENSOR_WAIT_S} s)",
                link.name
            );
            said = true;
        }
        if let Some(l) = link.recv(Duration::from_millis(100))? {
            on_event(&l);
        }
    }
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
    if let Err(e) = wait_for_sensors(link, &mut |l| events.push(l.to_string())) {
        return e;
    }
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
    // On a terminal the running line is redrawn in place (`\r`); into a pipe or a file (`tee`)
    // each poll is a line of its own.
    let tty = {
        use std::io::IsTerminal;
        std::io::stdout().is_terminal()
    };
    while outcome.is_none() {
        for e in events.drain(..) {
            if tty {
                println!("\r{e:<78}");
            } else {
                println!("{e}");
            }
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
            let running = running_line(&s);
            if tty {
                print!("\r{running}   ");
            } else {
                println!("{running}");
            }
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
            if tty {
                println!();
            }
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
    if tty {
        println!();
    }
    Ok(outcome.unwrap_or(ExitCode::FAILURE))
}

/// The running line of a morph: time, phase, the two heated temperatures and powers, and
/// `cutoff=open` once the heater supply's cut-off has opened (an alarm took the supply away).
fn running_line(s: &Sample) -> String {
    let mut line = format!(
        "{:>6.1} s  {:<8} PLA {:>6.1} °C  TCA {:>6.1} °C  power {:.2} / {:.2} W",
        s.t_s, s.phase, s.temps_c[0], s.temps_c[1], s.powers_w[0], s.powers_w[1]
    );
    if s.cutoff_closed == Some(false) {
        line.push_str("  cutoff=open");
    }
    line
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_running_line_says_when_the_cutoff_opens() {
        let st = |phase: &str, cutoff: &str| {
            let line = format!("ok phase={phase} target_mm=38.00 t_pla_c=74.17 t_tca_c=56.88 t_amb_c=21.94 p_pla_w=0.000 p_tca_w=0.000 supply_v=12.00 fault=none pla_target_c=- tca_target_c=- mode=closed {cutoff}");
            running_line(&Sample::from_status(12.34, &line, f64::NAN))
        };
        assert_eq!(
            st("bend", "cutoff=closed"),
            "  12.3 s  bend     PLA   74.2 °C  TCA   56.9 °C  power 0.00 / 0.00 W"
        );
        assert!(st("fault", "cutoff=open").ends_with(" W  cutoff=open"));
        // An older device says nothing of a cut-off.
        assert!(!st("bend", "").contains("cutoff"));
    }

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
