//! `morph-sim`: the controller core driving the simulated link, speaking protocol v1 on
//! stdin/stdout. At end of input it keeps simulating until the controller is idle or faulted.
use clap::Parser;
use morphlink::protocol::{
    format_error, Assembled, LineAssembler, ERR_INVALID_LINE, ERR_LINE_TOO_LONG,
};
use morphlink_sim::{LinkSetup, Rig};
use std::io::{Read, Write};
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
        Ok(f) if f > 0.0 && f.is_finite() => Ok(Speed::Factor(f)),
        _ => Err(format!(
            "speed must be a positive number or `max`, got `{s}`"
        )),
    }
}

/// Feeds received bytes through the protocol's bounded line assembler into the rig.
fn feed(rig: &mut Rig, asm: &mut LineAssembler, bytes: &[u8], emit: &mut impl FnMut(&str)) {
    for &b in bytes {
        match asm.push(b) {
            Some(Assembled::Line(line)) => rig.handle_line(line, emit),
            Some(Assembled::TooLong) => emit(&format_error(&ERR_LINE_TOO_LONG)),
            Some(Assembled::Invalid) => emit(&format_error(&ERR_INVALID_LINE)),
            None => {}
        }
    }
}

fn main() {
    let cli = Cli::parse();
    let plant = LinkSetup {
        seed: cli.seed,
        ..LinkSetup::NOMINAL
    };
    let mut rig = Rig::new(plant);
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
    let mut asm = LineAssembler::new();
    let start = Instant::now();
    let mut input_open = true;
    loop {
        // Take everything that has arrived; at end of input, run on until idle or faulted.
        while input_open {
            match rx.try_recv() {
                Ok(bytes) => feed(&mut rig, &mut asm, &bytes, &mut emit),
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => input_open = false,
            }
        }
        rig.tick();
        rig.drain_events(&mut emit);
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
                    feed(&mut rig, &mut asm, &bytes, &mut emit);
                }
            }
            Speed::Max => {}
            Speed::Factor(f) => {
                let due = Duration::from_secs_f64(sim_s / f);
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
}
