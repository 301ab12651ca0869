//! `cargo xtask emulate`: build the emulated firmware image and boot it under QEMU's
//! b-l475e-iot01a machine, either serving USART1 on a loopback TCP port for any client, or
//! running one morph and printing what the firmware says.
use morphlink::protocol::{classify, LineKind};
use morphlink_host::emulator::{
    build_image, find_qemu, qemu_command, run_to_end_or_signal, Clock, Emulator, Ended,
};
use morphlink_host::workspace::Workspace;
use std::path::Path;
use std::time::{Duration, Instant};

/// Options of `cargo xtask emulate`.
#[derive(clap::Args)]
pub struct Args {
    /// Serve USART1 on 127.0.0.1:<PORT>; QEMU waits for a client (nc, socat, a test) to connect.
    #[arg(long)]
    port: Option<u16>,
    /// Instead: boot, morph the simulated link to this radius (mm), print the phases and stop.
    #[arg(long, conflicts_with = "port")]
    morph: Option<f32>,
}

/// Longest wall time allowed for the demo morph.
const DEMO_TIMEOUT: Duration = Duration::from_secs(120);

/// Runs the task.
pub fn run(args: &Args, ws: &Workspace) -> Result<(), String> {
    // A busy port is named before the image is built, not after QEMU fails on it.
    if let Some(port) = args.port {
        check_port_free(port)?;
    }
    let qemu = find_qemu()?;
    // Its own directory inside cargo's target directory, as the emulator tests use.
    let image = build_image(&ws.root, &ws.target_dir.join("emulated"))?;
    match (args.port, args.morph) {
        (Some(port), _) => serve(&qemu, &image, port),
        (None, Some(radius_mm)) => demo(&qemu, &image, radius_mm),
        (None, None) => Err(
            "give --port <PORT> to serve USART1, or --morph <radius_mm> for a demo morph".into(),
        ),
    }
}

/// Refuses a port another program already listens on, before QEMU is started: QEMU would fail to
/// bind it and exit, which read like a firmware crash. (Checked by binding and releasing it; a
/// program that takes it in between still makes QEMU fail, with QEMU's own message.)
pub fn check_port_free(port: u16) -> Result<(), String> {
    match std::net::TcpListener::bind(("127.0.0.1", port)) {
        Ok(_) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::AddrInUse => Err(format!(
            "127.0.0.1:{port} is busy: another program (another emulator?) listens on it; \
             pick another --port or stop that program"
        )),
        Err(e) => Err(format!("cannot listen on 127.0.0.1:{port}: {e}")),
    }
}

fn serve(qemu: &Path, image: &Path, port: u16) -> Result<(), String> {
    check_port_free(port)?;
    eprintln!("booting {} under QEMU; USART1 on 127.0.0.1:{port} (QEMU starts when a client connects, e.g. `nc 127.0.0.1 {port}`)", image.display());
    // The host's clock: a client such as `morphctl --tcp-speed 20` paces itself by wall time.
    // SIGTERM or Ctrl-C to xtask ends QEMU with it (QEMU was left running).
    let status = match run_to_end_or_signal(&mut qemu_command(qemu, image, port, Clock::Host))? {
        Ended::Exited(status) => status,
        Ended::Signalled(sig) => {
            return Err(format!("stopped by signal {sig}; QEMU was ended with it"))
        }
    };
    if status.success() {
        Ok(())
    } else {
        Err(format!(
            "QEMU ended with {status}: see its message above (QEMU's own error, or the \
             firmware's panic or fault report)"
        ))
    }
}

fn demo(qemu: &Path, image: &Path, radius_mm: f32) -> Result<(), String> {
    let started = Instant::now();
    let mut emu = Emulator::boot(qemu, image)?;
    println!("{}", emu.transcript[0]);
    eprintln!("booted in {:.0} ms", emu.boot_time.as_secs_f64() * 1000.0);
    emu.wait_ready(Duration::from_secs(5))?;
    let morph_start = Instant::now();
    for l in emu.command(&format!("MORPH {radius_mm}"), Duration::from_secs(5))? {
        println!("{l}");
        if classify(&l) == LineKind::Error {
            return Err(format!("the firmware refused MORPH {radius_mm}"));
        }
    }
    loop {
        let l = emu.next_line(DEMO_TIMEOUT)?;
        println!("{l}");
        match classify(&l) {
            LineKind::Alarm => return Err("the morph ended in a fault".into()),
            LineKind::Done => break,
            _ => {}
        }
    }
    let morph_wall = morph_start.elapsed();
    for l in emu.command("SIM STATE", Duration::from_secs(5))? {
        println!("{l}");
    }
    // The control loop's timing over the morph (docs/firmware.md, "Tick time under QEMU").
    for l in emu.command("STATS", Duration::from_secs(5))? {
        println!("{l}");
    }
    eprintln!(
        "morph took {:.1} s of wall time ({} s of firmware time at the emulated build's speed-up); {:.1} s in all",
        morph_wall.as_secs_f64(),
        emu.transcript.iter().rev().find_map(|l| l.strip_prefix("event: done t=").and_then(|r| r.split(' ').next())).unwrap_or("?"),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_busy_port_is_named_as_busy() {
        let held = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let port = held.local_addr().unwrap().port();
        let e = check_port_free(port).unwrap_err();
        assert!(
            e.contains(&format!("127.0.0.1:{port} is busy")) && !e.contains("panicked"),
            "{e}"
        );
        drop(held);
        check_port_free(port).unwrap();
    }
}
