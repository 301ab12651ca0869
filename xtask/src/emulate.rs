//! `cargo xtask emulate`: build the emulated firmware image and boot it under QEMU's
//! b-l475e-iot01a machine, either serving USART1 on a loopback TCP port for any client, or
//! running one morph and printing what the firmware says.
use morphlink_host::emulator::{
    build_image_of, demo_morph, find_qemu, qemu_command, run_to_end_or_signal, Clock, Ended,
};
use morphlink_host::workspace::Workspace;
use std::path::Path;

/// Options of `cargo xtask emulate`.
#[derive(clap::Args)]
pub struct Args {
    /// Serve USART1 on `127.0.0.1:PORT`; QEMU waits for a client (nc, socat, a test) to connect.
    #[arg(long)]
    port: Option<u16>,
    /// Instead: boot, morph the simulated link to this radius (mm), print the phases and stop.
    #[arg(long, conflicts_with = "port")]
    morph: Option<f32>,
    /// How many links the image drives: 1, or 2 (the `links-2` image: addresses, GAIT and the
    /// supply budget, docs/multilink.md).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=2))]
    links: u8,
}

/// Runs the task.
pub fn run(args: &Args, ws: &Workspace) -> Result<(), String> {
    // A busy port is named before the image is built, not after QEMU fails on it.
    if let Some(port) = args.port {
        check_port_free(port)?;
    }
    let qemu = find_qemu()?;
    // Its own directory inside cargo's target directory, as the emulator tests use.
    let image = build_image_of(
        &ws.root,
        usize::from(args.links),
        &ws.target_dir.join("emulated"),
    )?;
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
    let mut done_t = String::from("?");
    let times = demo_morph(qemu, image, radius_mm, &mut |l| {
        println!("{l}");
        if let Some(t) = l
            .strip_prefix("event: done t=")
            .and_then(|r| r.split(' ').next())
        {
            done_t = t.to_string();
        }
    })?;
    eprintln!(
        "booted in {:.0} ms; the morph took {:.1} s of wall time ({done_t} s of firmware time at the emulated build's speed-up); {:.1} s in all",
        times.boot.as_secs_f64() * 1000.0,
        times.morph.as_secs_f64(),
        times.total.as_secs_f64()
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
