//! `morph-sim`: the controller core driving a simulated link, speaking protocol v1 on
//! stdin/stdout. At end of input it keeps simulating until the controller is idle or faulted.
//!
//! The link is an in-process plant (`--plant lumped`, the default) or another process over
//! the plant protocol (`--plant-cmd "<shell command>"`, see `morphlink_plant::wire`). A remote
//! plant that fails (exits, answers `error:` or garbage, is silent for `--plant-timeout-s`)
//! ends the run: a message naming the plant on stderr and exit code 1.
use clap::Parser;
use morphlink::controller::TICK_MS;
use morphlink::protocol::{
    format_error, reply, Assembled, LineAssembler, OutLine, ERR_INVALID_LINE, ERR_LINE_TOO_LONG,
};
use morphlink_host::flash_file;
use morphlink_host::plants::{self, PlantKind};
use morphlink_host::remote_plant::RemotePlant;
use morphlink_plant::Plant;
use morphlink_sim::{LinkSetup, Rig};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::mpsc::{self, TryRecvError};
use std::time::{Duration, Instant};

#[derive(Parser)]
#[command(
    name = "morph-sim",
    version,
    about = "Simulated morphing link on the serial protocol (stdin/stdout)"
)]
struct Cli {
    /// Simulation speed: a factor of real time (1 = real time) or `max` (as fast as possible).
    #[arg(long, default_value = "1", value_parser = parse_speed)]
    speed: Speed,
    /// Seed of the simulated sensor noise.
    #[arg(long, default_value_t = LinkSetup::NOMINAL.seed)]
    seed: u64,
    /// Stop after this much simulated time even if the controller is still busy, s.
    #[arg(long, default_value_t = 3600.0)]
    max_time_s: f64,
    /// The in-process plant (the simulated link).
    #[arg(long, value_enum, default_value_t = PlantKind::Lumped)]
    plant: PlantKind,
    /// Run the plant as this shell command (`sh -c`), spoken to over plant protocol 1 on its
    /// stdin/stdout, instead of an in-process plant.
    #[arg(long, value_name = "SHELL COMMAND", conflicts_with = "plant")]
    plant_cmd: Option<String>,
    /// How long to wait for each reply of a `--plant-cmd` plant, s.
    #[arg(long, default_value_t = morphlink_host::remote_plant::REPLY_TIMEOUT.as_secs_f64(),
          value_parser = parse_timeout)]
    plant_timeout_s: f64,
    /// Keep the simulated settings flash in this file (created at the first SAVE), so saved
    /// settings survive a restart as on a board. Without it SAVE is unsupported. A FIFO, a
    /// directory or a file that is read-only or cannot be opened for writing is refused
    /// (exit code 2) before anything runs.
    #[arg(long, value_name = "PATH")]
    flash_file: Option<PathBuf>,
    /// The board without its current-sense amplifiers: the paper's wiring plus the supply's
    /// cut-off, the heaters seen through their thermistors only (a `--plant-cmd` plant that
    /// reports no `r_pla_ohm=`/`r_tca_ohm=` makes the same board).
    #[arg(long)]
    thermistors_only: bool,
}

fn parse_timeout(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(t) if t > 0.0 && t <= 86_400.0 => Ok(t),
        _ => Err(format!("a timeout must be 0..86400 s, got `{s}`")),
    }
}

type SimRig = Rig<Box<dyn Plant>>;

#[derive(Clone, Copy)]
enum Speed {
    Factor(f64),
    Max,
}

fn parse_speed(s: &str) -> Result<Speed, String> {
    if s.eq_ignore_ascii_case("max") {
        return Ok(Speed::Max);
    }
    match s.parse::<f64>() {
        Ok(f) => morphlink_host::speed::check("--speed", f).map(Speed::Factor),
        _ => Err(format!(
            "speed must be a positive number or `max`, got `{s}`"
        )),
    }
}

/// Feeds received bytes through the protocol's bounded line assembler into the rig.
/// Stops at a failed plant (the caller ends the run). A SAVE's reply goes out only once the
/// flash file is written (`error: storage` if it could not be).
fn feed(
    rig: &mut SimRig,
    asm: &mut LineAssembler,
    bytes: &[u8],
    flash_file: Option<&Path>,
    emit: &mut impl FnMut(&str),
) {
    for &b in bytes {
        if rig.plant_failure().is_some() {
            return;
        }
        match asm.push(b) {
            Some(Assembled::Line(line)) => {
                // Events queued by the commands before this one (MORPH's first phase) go out
                // before this command's reply, as the board writes them: a line read later
                // never answers ahead of an event raised earlier.
                rig.drain_events(emit);
                let saves = rig.saves();
                let mut replies: Vec<String> = Vec::new();
                rig.handle_line(line, &mut |l: &str| replies.push(l.to_string()));
                if rig.saves() != saves {
                    if let (Some(path), Some(flash)) = (flash_file, rig.flash()) {
                        if let Err(e) = flash_file::write(path, flash) {
                            eprintln!("morph-sim: cannot write {}: {e}", path.display());
                            let mut l = OutLine::new();
                            reply::save_failed(&mut l, "file-error");
                            replies.pop();
                            replies.push(l.to_string());
                        }
                    }
                }
                for r in &replies {
                    emit(r);
                }
            }
            Some(Assembled::TooLong) => emit(&format_error(&ERR_LINE_TOO_LONG)),
            Some(Assembled::Invalid) => emit(&format_error(&ERR_INVALID_LINE)),
            None => {}
        }
    }
}

/// The plant the command line asks for.
fn plant(cli: &Cli, setup: &LinkSetup) -> Result<Box<dyn Plant>, Stop> {
    match &cli.plant_cmd {
        Some(cmd) => {
            let tick_s = TICK_MS as f64 / 1000.0;
            let timeout = Duration::from_secs_f64(cli.plant_timeout_s);
            let remote = RemotePlant::spawn(cmd, tick_s, timeout).map_err(Stop::PlantFailed)?;
            Ok(Box::new(remote))
        }
        None => plants::in_process(cli.plant, setup).map_err(Stop::Unavailable),
    }
}

fn main() {
    let cli = Cli::parse();
    // A flash file the run could not read or keep is refused before anything runs.
    if let Some(path) = &cli.flash_file {
        if let Err(why) = flash_file::check(path) {
            eprintln!("morph-sim: --flash-file {}: {why}", path.display());
            std::process::exit(2);
        }
    }
    match run(&cli) {
        Ok(()) => {}
        Err(Stop::Unavailable(why)) => {
            eprintln!("morph-sim: {why}");
            std::process::exit(2);
        }
        Err(Stop::PlantFailed(why)) => {
            eprintln!("morph-sim: {why}; run ended, heaters off");
            std::process::exit(1);
        }
    }
}

/// Why a run stopped early.
enum Stop {
    /// The in-process plant asked for is not in this build.
    Unavailable(String),
    /// The remote plant failed (its message names it).
    PlantFailed(String),
}

/// The run; `Err` names a plant that failed (the rig, and with it the plant, is dropped first).
fn run(cli: &Cli) -> Result<(), Stop> {
    let setup = LinkSetup {
        seed: cli.seed,
        ..LinkSetup::NOMINAL
    };
    let mut rig: SimRig = Rig::with_plant(plant(cli, &setup)?, setup.noise());
    rig.bench.set_current_sense(!cli.thermistors_only);
    if let Some(path) = &cli.flash_file {
        rig.boot_storage(flash_file::read(path));
    }

    let (tx, rx) = mpsc::channel::<Vec<u8>>();
    std::thread::spawn(move || {
        let mut stdin = std::io::stdin().lock();
        let mut buf = [0u8; 256];
        loop {
            match stdin.read(&mut buf) {
                Ok(0) | Err(_) => break,
                Ok(n) => {
                    if tx.send(buf[..n].to_vec()).is_err() {
                        break;
                    }
                }
            }
        }
    });
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    let mut emit = |l: &str| {
        let _ = writeln!(out, "{l}");
        let _ = out.flush();
    };
    // The boot's `event: config ...` comes before any reply, as on a board.
    rig.drain_events(&mut emit);
    let mut asm = LineAssembler::new();
    let start = Instant::now();
    let mut input_open = true;
    loop {
        // Take everything that has arrived; at end of input, run on until idle or faulted.
        while input_open {
            match rx.try_recv() {
                Ok(bytes) => feed(
                    &mut rig,
                    &mut asm,
                    &bytes,
                    cli.flash_file.as_deref(),
                    &mut emit,
                ),
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => input_open = false,
            }
        }
        if let Some(why) = rig.plant_failure() {
            return Err(Stop::PlantFailed(why.to_string()));
        }
        rig.tick();
        rig.drain_events(&mut emit);
        if let Some(why) = rig.plant_failure() {
            return Err(Stop::PlantFailed(why.to_string()));
        }
        let sim_s = rig.now_ms() as f64 / 1000.0;
        if !input_open && !rig.ctrl.busy() {
            break;
        }
        if sim_s >= cli.max_time_s {
            eprintln!(
                "morph-sim: stopped at the --max-time-s limit of {} s",
                cli.max_time_s
            );
            break;
        }
        match cli.speed {
            // Nothing running and input still open: wait for input instead of spinning.
            Speed::Max if input_open && !rig.ctrl.busy() => {
                if let Ok(bytes) = rx.recv_timeout(Duration::from_millis(50)) {
                    feed(
                        &mut rig,
                        &mut asm,
                        &bytes,
                        cli.flash_file.as_deref(),
                        &mut emit,
                    );
                }
            }
            Speed::Max => {}
            Speed::Factor(f) => {
                // Time run by SIM WAIT was asked to pass at once: pace only the rest.
                let paced_s = sim_s - rig.waited_ms() as f64 / 1000.0;
                let due = Duration::from_secs_f64(paced_s / f);
                if let Some(wait) = due.checked_sub(start.elapsed()) {
                    std::thread::sleep(wait);
                }
            }
        }
    }
    eprintln!(
        "morph-sim: {} after {:.1} s simulated; link radius {:.2} mm",
        rig.ctrl.phase().as_str(),
        rig.now_ms() as f64 / 1000.0,
        rig.radius_mm()
    );
    Ok(())
}
