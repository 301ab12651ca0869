//! `morph-sim`: the controller core driving a simulated link, speaking protocol v1 on
//! stdin/stdout. At end of input it keeps simulating until the controller is idle or faulted.
//!
//! The link is an in-process plant (`--plant lumped`, the default) or another process over
//! the plant protocol (`--plant-cmd "<shell command>"`, see `morphlink_plant::wire`). A remote
//! plant that fails (exits, answers `error:` or garbage, is silent for `--plant-timeout-s`)
//! ends the run: a message naming the plant on stderr and exit code 1.
//!
//! `--links N` puts N links on the one simulated board (docs/multilink.md): each its own
//! plant (`--plant-cmd` given once per link drives links 1, 2, ... from outside; the rest are
//! in-process), all on one bench supply with an internal resistance and a current limit
//! (`--supply-limit-a`), lines addressed `@<n>`.
use clap::Parser;
use morphlink::controller::TICK_MS;
use morphlink::protocol::{
    format_error, reply, Assembled, LineAssembler, OutLine, ERR_INVALID_LINE, ERR_LINE_TOO_LONG,
};
use morphlink_host::flash_file;
use morphlink_host::plants::{self, PlantKind};
use morphlink_host::remote_plant::RemotePlant;
use morphlink_plant::Plant;
use morphlink_sim::{LinkSetup, MultiRig, Rig, SharedSupply};
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
    /// Simulation speed: a factor of real time (1 = real time) or `max` (as fast as possible;
    /// simulated time then stands still while the link is idle and waits for input).
    #[arg(long, default_value = "1", value_parser = parse_speed, allow_hyphen_values = true)]
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
    /// With `--links`, given once per link: links 1, 2, ... in order (the links it is not
    /// given for run the lumped plant in-process).
    #[arg(long, value_name = "SHELL COMMAND", conflicts_with = "plant")]
    plant_cmd: Vec<String>,
    /// Links on the one simulated board, each its own plant (1 to 4; docs/multilink.md).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=4))]
    links: u8,
    /// The shared bench supply's current limit, A (constant-current mode beyond it: the
    /// supply sags). With one link the plant's own supply is used, as before.
    #[arg(long, default_value_t = SharedSupply::STIFF.limit_a)]
    supply_limit_a: f64,
    /// The shared bench supply's internal resistance, ohm.
    #[arg(long, default_value_t = SharedSupply::STIFF.internal_ohm)]
    supply_ohm: f64,
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
        _ => Err(format!(
            "a timeout must be over 0 and at most 86400 s, got `{s}`"
        )),
    }
}

type SimRig = Rig<Box<dyn Plant>>;
type SimBoard = MultiRig<Box<dyn Plant>>;

/// What the run loop asks of a simulated board: one link's rig or several links' board.
trait Board {
    fn tick(&mut self);
    fn drain_events(&mut self, out: &mut dyn FnMut(&str));
    fn handle_line(&mut self, line: &str, out: &mut dyn FnMut(&str));
    fn failure(&self) -> Option<String>;
    fn now_ms(&self) -> u64;
    fn waited_ms(&self) -> u64;
    fn busy(&self) -> bool;
    fn saves(&self) -> u32;
    fn flash(&self) -> Option<&morphlink_sim::rig::SimFlash>;
    fn summary(&self) -> String;
}

impl Board for SimRig {
    fn tick(&mut self) {
        Rig::tick(self);
    }
    fn drain_events(&mut self, out: &mut dyn FnMut(&str)) {
        Rig::drain_events(self, &mut |l: &str| out(l));
    }
    fn handle_line(&mut self, line: &str, out: &mut dyn FnMut(&str)) {
        Rig::handle_line(self, line, &mut |l: &str| out(l));
    }
    fn failure(&self) -> Option<String> {
        self.plant_failure().map(str::to_string)
    }
    fn now_ms(&self) -> u64 {
        Rig::now_ms(self)
    }
    fn waited_ms(&self) -> u64 {
        Rig::waited_ms(self)
    }
    fn busy(&self) -> bool {
        self.ctrl.busy()
    }
    fn saves(&self) -> u32 {
        Rig::saves(self)
    }
    fn flash(&self) -> Option<&morphlink_sim::rig::SimFlash> {
        Rig::flash(self)
    }
    fn summary(&self) -> String {
        format!(
            "{} after {:.1} s simulated; link radius {:.2} mm",
            self.ctrl.phase().as_str(),
            Rig::now_ms(self) as f64 / 1000.0,
            self.radius_mm()
        )
    }
}

impl Board for SimBoard {
    fn tick(&mut self) {
        MultiRig::tick(self);
    }
    fn drain_events(&mut self, out: &mut dyn FnMut(&str)) {
        MultiRig::drain_events(self, &mut |l: &str| out(l));
    }
    fn handle_line(&mut self, line: &str, out: &mut dyn FnMut(&str)) {
        MultiRig::handle_line(self, line, &mut |l: &str| out(l));
    }
    fn failure(&self) -> Option<String> {
        self.plant_failure()
            .map(|(k, w)| format!("link {}: {w}", k + 1))
    }
    fn now_ms(&self) -> u64 {
        MultiRig::now_ms(self)
    }
    fn waited_ms(&self) -> u64 {
        MultiRig::waited_ms(self)
    }
    fn busy(&self) -> bool {
        !self.links.idle()
    }
    fn saves(&self) -> u32 {
        0
    }
    fn flash(&self) -> Option<&morphlink_sim::rig::SimFlash> {
        None
    }
    fn summary(&self) -> String {
        let radii: Vec<String> = (0..self.count())
            .map(|k| format!("{:.2}", self.radius_mm(k)))
            .collect();
        let phases: Vec<&str> = (0..self.count())
            .map(|k| self.links.link(k).phase().as_str())
            .collect();
        format!(
            "{} after {:.1} s simulated; link radii {} mm",
            phases.join(","),
            MultiRig::now_ms(self) as f64 / 1000.0,
            radii.join(", ")
        )
    }
}

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
    rig: &mut dyn Board,
    asm: &mut LineAssembler,
    bytes: &[u8],
    flash_file: Option<&Path>,
    emit: &mut impl FnMut(&str),
) {
    for &b in bytes {
        if rig.failure().is_some() {
            return;
        }
        let assembled = asm.push(b);
        if assembled.is_some() {
            // Events queued by the commands before this line (MORPH's first phase) go out
            // before its answer, as the board writes them: a line read later, a refused one
            // too, never answers ahead of an event raised earlier.
            rig.drain_events(emit);
        }
        match assembled {
            Some(Assembled::Line(line)) => {
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

/// The plant of link `k` (0-based) the command line asks for.
fn plant(cli: &Cli, setup: &LinkSetup, k: usize) -> Result<Box<dyn Plant>, Stop> {
    match cli.plant_cmd.get(k) {
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
    if cli.plant_cmd.len() > cli.links as usize {
        eprintln!(
            "morph-sim: {} --plant-cmd for {} link(s): give it at most once per link",
            cli.plant_cmd.len(),
            cli.links
        );
        std::process::exit(2);
    }
    if cli.links > 1 && cli.flash_file.is_some() {
        eprintln!("morph-sim: --flash-file keeps one link's settings; it needs --links 1");
        std::process::exit(2);
    }
    if !(cli.supply_limit_a > 0.0
        && cli.supply_limit_a.is_finite()
        && cli.supply_ohm >= 0.0
        && cli.supply_ohm < 10.0)
    {
        eprintln!(
            "morph-sim: --supply-limit-a must be a number above 0 A and --supply-ohm 0..10 ohm"
        );
        std::process::exit(2);
    }
    if !(cli.max_time_s > 0.0 && cli.max_time_s.is_finite()) {
        eprintln!("morph-sim: --max-time-s must be a number of seconds above 0");
        std::process::exit(2);
    }
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
    let mut board: Box<dyn Board> = if cli.links == 1 {
        let mut rig: SimRig = Rig::with_plant(plant(cli, &setup, 0)?, setup.noise());
        rig.bench.set_current_sense(!cli.thermistors_only);
        if let Some(path) = &cli.flash_file {
            rig.boot_storage(flash_file::read(path));
        }
        Box::new(rig)
    } else {
        let plants = (0..cli.links as usize)
            .map(|k| plant(cli, &setup, k))
            .collect::<Result<Vec<_>, _>>()?;
        let supply = SharedSupply {
            open_v: setup.supply_v,
            internal_ohm: cli.supply_ohm,
            limit_a: cli.supply_limit_a,
        };
        let mut rig: SimBoard = MultiRig::new(plants, setup.noise(), supply);
        for b in &mut rig.benches {
            b.set_current_sense(!cli.thermistors_only);
        }
        Box::new(rig)
    };
    let rig = board.as_mut();

    let (tx, rx) = mpsc::channel::<Vec<u8>>();
    std::thread::spawn(move || {
        let mut stdin = std::io::stdin().lock();
        // A pipe's whole capacity: a script written in one go (`printf ... | morph-sim --speed
        // max`) arrives as one piece, so no line of it waits while the simulation runs ahead
        // (with 256 bytes, an ABORT in the second piece was acted on 5 or 18 simulated seconds
        // late, as the threads fell).
        let mut buf = vec![0u8; 1 << 16];
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
                Ok(bytes) => feed(rig, &mut asm, &bytes, cli.flash_file.as_deref(), &mut emit),
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => input_open = false,
            }
        }
        // As fast as possible, simulated time runs only while something does: an idle link
        // waits for input without ticking, so a run depends on its input alone, never on when
        // the input arrived.
        if matches!(cli.speed, Speed::Max) && input_open && !rig.busy() {
            match rx.recv() {
                Ok(bytes) => feed(rig, &mut asm, &bytes, cli.flash_file.as_deref(), &mut emit),
                Err(_) => input_open = false,
            }
            continue;
        }
        if let Some(why) = rig.failure() {
            return Err(Stop::PlantFailed(why));
        }
        rig.tick();
        rig.drain_events(&mut emit);
        if let Some(why) = rig.failure() {
            return Err(Stop::PlantFailed(why));
        }
        let sim_s = rig.now_ms() as f64 / 1000.0;
        if !input_open && !rig.busy() {
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
    eprintln!("morph-sim: {}", rig.summary());
    Ok(())
}
