//! Booting the emulated firmware image under QEMU's `b-l475e-iot01a` machine and talking
//! protocol v1 to it over USART1 on a loopback TCP socket.
//!
//! Used by `cargo xtask emulate` and by the emulator tests. QEMU 10 is needed (Debian
//! bookworm-backports: `apt-get install -t bookworm-backports qemu-system-arm`).

use morphlink::protocol::is_final_reply;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::thread;
use std::time::{Duration, Instant};

/// QEMU machine that models the STM32L475 of the B-L475E-IOT01A board.
pub const MACHINE: &str = "b-l475e-iot01a";
/// Board folder (and `board-*` feature) of the emulated build.
pub const BOARD: &str = "b-l475e-iot01a-emulated";
/// Firmware target triple.
pub const TARGET: &str = "thumbv7em-none-eabihf";
/// Oldest QEMU major version with a working `b-l475e-iot01a` machine (Debian bookworm has 7.2).
pub const MIN_QEMU_MAJOR: u32 = 9;
/// Longest wait for the first byte after boot.
pub const BOOT_TIMEOUT: Duration = Duration::from_secs(10);

/// The `qemu-system-arm` binary, or a sentence saying how to install it.
pub fn find_qemu() -> Result<PathBuf, String> {
    let name = std::env::var("QEMU_SYSTEM_ARM").unwrap_or_else(|_| "qemu-system-arm".into());
    let out = Command::new(&name).arg("--version").output().map_err(|e| {
        format!(
            "cannot run `{name}` ({e}): install QEMU 10 from Debian bookworm-backports \
             (`apt-get install -t bookworm-backports qemu-system-arm`)"
        )
    })?;
    let version = String::from_utf8_lossy(&out.stdout);
    let major = version
        .split("version ")
        .nth(1)
        .and_then(|v| v.split('.').next())
        .and_then(|m| m.trim().parse::<u32>().ok());
    match major {
        Some(m) if m >= MIN_QEMU_MAJOR => {}
        _ => return Err(format!("`{name}` is too old or unknown for machine {MACHINE} (QEMU {MIN_QEMU_MAJOR}+ needed): {}", version.trim())),
    }
    Ok(PathBuf::from(name))
}

/// Builds the firmware for `board` (the `board-<board>` feature) in release into `target_dir`;
/// returns the ELF path, as cargo reports it (its JSON messages name the executable it wrote).
/// Used for the emulated image here and for every board by `cargo xtask boards`; callers take
/// `target_dir` from [`crate::workspace::Workspace`], so it honours `CARGO_TARGET_DIR`.
pub fn build_firmware(workspace: &Path, board: &str, target_dir: &Path) -> Result<PathBuf, String> {
    build_firmware_with(workspace, board, &[], target_dir)
}

/// As [`build_firmware`], with the firmware's further `features` (`links-2`). The ELF is
/// copied to `<target_dir>/images/morphlink-<board>[-<feature>...].elf` and that copy returned,
/// so images of other features built into the same `target_dir` later do not replace it.
pub fn build_firmware_with(
    workspace: &Path,
    board: &str,
    features: &[&str],
    target_dir: &Path,
) -> Result<PathBuf, String> {
    // One build at a time in this process: cargo's lock serialises builds, not the copy after.
    static BUILDING: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _one = BUILDING.lock().unwrap_or_else(|p| p.into_inner());
    let elf = build_elf(workspace, board, features, target_dir)?;
    let mut name = format!("morphlink-{board}");
    for f in features {
        name.push('-');
        name.push_str(f);
    }
    let dir = target_dir.join("images");
    std::fs::create_dir_all(&dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    let copy = dir.join(format!("{name}.elf"));
    std::fs::copy(&elf, &copy).map_err(|e| format!("cannot copy {}: {e}", elf.display()))?;
    Ok(copy)
}

fn build_elf(
    workspace: &Path,
    board: &str,
    features: &[&str],
    target_dir: &Path,
) -> Result<PathBuf, String> {
    let mut all = format!("board-{board}");
    for f in features {
        all.push(',');
        all.push_str(f);
    }
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut child = Command::new(cargo)
        .current_dir(workspace)
        .args([
            "build",
            "--release",
            "--target",
            TARGET,
            "--bin",
            "morphlink",
            "--no-default-features",
            // Artifacts as JSON on stdout; diagnostics still rendered for people on stderr.
            "--message-format=json-render-diagnostics",
        ])
        .args(["--features", &all])
        .args(remap_registry())
        .env("CARGO_TARGET_DIR", target_dir)
        .stdout(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot run cargo: {e}"))?;
    let mut elf = None;
    if let Some(out) = child.stdout.take() {
        for m in cargo_metadata::Message::parse_stream(BufReader::new(out)).map_while(Result::ok) {
            if let cargo_metadata::Message::CompilerArtifact(a) = m {
                if a.target.name == "morphlink" {
                    if let Some(exe) = a.executable {
                        elf = Some(exe.into_std_path_buf());
                    }
                }
            }
        }
    }
    let status = child.wait().map_err(|e| format!("cannot run cargo: {e}"))?;
    if !status.success() {
        return Err(format!(
            "building the firmware for {board} failed ({status})"
        ));
    }
    elf.ok_or_else(|| format!("cargo built the firmware for {board} but named no executable"))
}

/// `--config` arguments that strip the crates' download directory from the paths the image
/// carries (its dependencies' panic locations): a panic then reports `embassy-stm32-0.6.0/src/…`
/// (the reason kept across the reset is short), the image says nothing of the machine it was
/// built on, and builds on machines whose cargo homes differ are the same size (about 0.8 KiB
/// smaller). Empty if the cargo home is unknown.
fn remap_registry() -> Vec<String> {
    let home = std::env::var_os("CARGO_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cargo")));
    let Some(home) = home else {
        return Vec::new();
    };
    let src = home.join("registry").join("src");
    let Ok(dirs) = std::fs::read_dir(&src) else {
        return Vec::new();
    };
    let flags: Vec<String> = dirs
        .filter_map(Result::ok)
        .map(|d| format!("\"--remap-path-prefix={}/=\"", d.path().display()))
        .collect();
    if flags.is_empty() {
        return Vec::new();
    }
    vec![
        "--config".into(),
        format!("target.{TARGET}.rustflags=[{}]", flags.join(",")),
    ]
}

/// Builds the emulated image in release into `target_dir`; returns the ELF path.
pub fn build_image(workspace: &Path, target_dir: &Path) -> Result<PathBuf, String> {
    build_firmware_with(workspace, BOARD, &[], target_dir)
}

/// Builds the emulated image of `links` links (1 or 2: the `links-2` feature) in release into
/// `target_dir`; returns the ELF path.
pub fn build_image_of(
    workspace: &Path,
    links: usize,
    target_dir: &Path,
) -> Result<PathBuf, String> {
    match links {
        1 => build_image(workspace, target_dir),
        2 => build_firmware_with(workspace, BOARD, &["links-2"], target_dir),
        n => Err(format!("the emulated image drives 1 or 2 links, not {n}")),
    }
}

/// A free loopback TCP port (bound and released; a race with another process is possible but
/// harmless: QEMU then fails to start and says so).
pub fn free_port() -> Result<u16, String> {
    let l = TcpListener::bind("127.0.0.1:0").map_err(|e| format!("no free port: {e}"))?;
    l.local_addr().map(|a| a.port()).map_err(|e| e.to_string())
}

/// How QEMU's virtual clock, and with it the firmware's (SysTick), runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Clock {
    /// Follows the host's clock: the firmware runs 20x real time when QEMU has a core to
    /// itself, and QEMU's host-side stalls count as firmware time. For clients that pace
    /// themselves by the wall clock (`cargo xtask emulate --port`, `morphctl --tcp-speed 20`).
    Host,
    /// Follows the emulated instructions while the CPU runs, real time while it sleeps
    /// (`-icount`, [`ICOUNT_SHIFT`]): the firmware's timing is its own, whatever the host does.
    /// For the tests and the demo morph.
    Instructions,
}

/// The QEMU command line that boots `image` with USART1 as a TCP server on `port`, its clock
/// run as `clock` says.
pub fn qemu_command(qemu: &Path, image: &Path, port: u16, clock: Clock) -> Command {
    let mut c = Command::new(qemu);
    c.args(["-M", MACHINE, "-nographic", "-monitor", "none"])
        .args(["-semihosting-config", "enable=on,target=native"])
        .arg("-serial")
        .arg(format!("tcp:127.0.0.1:{port},server=on,wait=on,nodelay=on"))
        .arg("-kernel")
        .arg(image);
    ends_with_its_parent(&mut c);
    if clock == Clock::Instructions {
        match std::env::var("MORPHLINK_QEMU_ICOUNT") {
            Ok(v) if v == "off" => {}
            Ok(v) => {
                c.args(["-icount", &v]);
            }
            Err(_) => {
                c.arg("-icount")
                    .arg(format!("shift={ICOUNT_SHIFT},sleep=on"));
            }
        }
    }
    c
}

/// Makes the kernel kill the child started by `command` (SIGKILL) when the thread that started
/// it ends, however this process ends: a SIGTERM or SIGKILL to `cargo xtask emulate --morph`, a
/// panicking test. QEMU runs on alone otherwise, at a whole core, with nobody reading its port.
/// Linux only (`PR_SET_PDEATHSIG`); elsewhere [`Emulator`]'s drop and
/// [`run_to_end_or_signal`] are all there is.
pub fn ends_with_its_parent(command: &mut Command) {
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::process::CommandExt;
        // SAFETY: the closure runs in the forked child before exec and only calls prctl,
        // which is async-signal-safe.
        unsafe {
            command.pre_exec(|| {
                if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                Ok(())
            });
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = command;
}

/// How a child run by [`run_to_end_or_signal`] ended.
#[derive(Debug)]
pub enum Ended {
    /// It exited on its own.
    Exited(ExitStatus),
    /// This signal reached this process first; the child was killed and reaped.
    Signalled(i32),
}

/// Runs `command` (QEMU serving a port) to its end. A SIGINT, SIGTERM or SIGHUP to this
/// process no longer ends it alone: the child is killed and reaped first, so no QEMU outlives
/// the `cargo xtask emulate` that started it. The handlers are removed again on return.
pub fn run_to_end_or_signal(command: &mut Command) -> Result<Ended, String> {
    use std::sync::atomic::AtomicUsize;
    use std::sync::Arc;
    let flag = Arc::new(AtomicUsize::new(0));
    let mut ids = Vec::new();
    for sig in [libc::SIGINT, libc::SIGTERM, libc::SIGHUP] {
        let id = signal_hook::flag::register_usize(sig, Arc::clone(&flag), sig as usize)
            .map_err(|e| format!("cannot watch signal {sig}: {e}"))?;
        ids.push(id);
    }
    let program = command.get_program().to_string_lossy().into_owned();
    let ended = match command.spawn() {
        Ok(mut child) => {
            wait_or_kill(&mut child, &flag).map_err(|e| format!("waiting for {program}: {e}"))
        }
        Err(e) => Err(format!("cannot start {program}: {e}")),
    };
    for id in ids {
        signal_hook::low_level::unregister(id);
    }
    ended
}

/// Waits for `child` to exit, or kills and reaps it once `signal` holds a signal's number.
pub fn wait_or_kill(
    child: &mut Child,
    signal: &std::sync::atomic::AtomicUsize,
) -> std::io::Result<Ended> {
    use std::sync::atomic::Ordering;
    loop {
        if let Some(status) = child.try_wait()? {
            return Ok(Ended::Exited(status));
        }
        let sig = signal.load(Ordering::SeqCst);
        if sig != 0 {
            let _ = child.kill();
            child.wait()?;
            return Ok(Ended::Signalled(sig as i32));
        }
        thread::sleep(Duration::from_millis(50));
    }
}

/// QEMU's `-icount` shift under [`Clock::Instructions`]: every emulated instruction advances
/// the virtual clock by 2^`ICOUNT_SHIFT` ns, so the firmware's time follows the instructions it
/// runs and not QEMU's host-side work, such as the per-byte TCP round trips of the serial port,
/// which otherwise stall the CPU while its clock runs on (docs/emulation.md, "Floods"). With
/// `sleep=on` an idle CPU's clock follows real time, so the image keeps its 20x speed-up while
/// idle. 4 gives 3 125 instructions per firmware millisecond (one SysTick period is 50 µs of
/// virtual time), some 25 times fewer than the real 80 MHz chip: the firmware's timing is
/// judged on a slower CPU than it will run on. Measured with a 3 000-line STATUS flood: 2 took
/// 39 s of wall time (4: 11 s); 5 and 6 are too slow a CPU (3 and 105 late ticks).
/// `MORPHLINK_QEMU_ICOUNT` replaces the whole option (`off`: no `-icount`).
pub const ICOUNT_SHIFT: u32 = 4;
const _: () = assert!(ICOUNT_SHIFT >= 2 && ICOUNT_SHIFT <= 4);

/// A running emulated board: QEMU plus the protocol connection to its USART1.
pub struct Emulator {
    child: Child,
    stream: TcpStream,
    lines: Receiver<String>,
    log: Receiver<String>,
    log_kept: Vec<String>,
    /// Every line received from the firmware, in order.
    pub transcript: Vec<String>,
    /// Wall time from QEMU start to the first line received.
    pub boot_time: Duration,
}

impl Emulator {
    /// Starts QEMU on `image`, connects to USART1 and waits for the boot banner.
    pub fn boot(qemu: &Path, image: &Path) -> Result<Emulator, String> {
        let port = free_port()?;
        let started = Instant::now();
        let mut child = qemu_command(qemu, image, port, Clock::Instructions)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| format!("cannot start {}: {e}", qemu.display()))?;
        // QEMU's semihosting console and errors, kept for the report on failure.
        let (log_tx, log) = mpsc::channel();
        for pipe in [
            child
                .stdout
                .take()
                .map(|p| Box::new(p) as Box<dyn Read + Send>),
            child
                .stderr
                .take()
                .map(|p| Box::new(p) as Box<dyn Read + Send>),
        ]
        .into_iter()
        .flatten()
        {
            let tx = log_tx.clone();
            thread::spawn(move || {
                for l in BufReader::new(pipe).lines().map_while(Result::ok) {
                    let _ = tx.send(l);
                }
            });
        }
        let stream = loop {
            match TcpStream::connect(("127.0.0.1", port)) {
                Ok(s) => break s,
                Err(e) => {
                    if let Ok(Some(status)) = child.try_wait() {
                        return Err(format!(
                            "QEMU exited before accepting a connection ({status})"
                        ));
                    }
                    if started.elapsed() > BOOT_TIMEOUT {
                        let _ = child.kill();
                        return Err(format!(
                            "cannot connect to QEMU's USART1 on port {port}: {e}"
                        ));
                    }
                    thread::sleep(Duration::from_millis(20));
                }
            }
        };
        stream.set_nodelay(true).map_err(|e| e.to_string())?;
        let reader = stream.try_clone().map_err(|e| e.to_string())?;
        let (tx, lines) = mpsc::channel();
        thread::spawn(move || {
            for l in BufReader::new(reader).lines().map_while(Result::ok) {
                if tx.send(l.trim_end_matches('\r').to_string()).is_err() {
                    break;
                }
            }
        });
        let mut emu = Emulator {
            child,
            stream,
            lines,
            log,
            log_kept: Vec::new(),
            transcript: Vec::new(),
            boot_time: Duration::ZERO,
        };
        let first = emu.next_line(BOOT_TIMEOUT)?;
        emu.boot_time = started.elapsed();
        let _ = first;
        Ok(emu)
    }

    /// Waits until the controller has its first sensor frame (STATUS reports temperatures), so
    /// a MORPH right after boot is not refused as too early.
    pub fn wait_ready(&mut self, timeout: Duration) -> Result<(), String> {
        let end = Instant::now() + timeout;
        loop {
            let r = self.command("STATUS", timeout)?;
            let ready = r
                .last()
                .and_then(|l| l.split(' ').find_map(|w| w.strip_prefix("t_pla_c=")))
                .is_some_and(|t| t.parse::<f64>().is_ok_and(f64::is_finite));
            if ready {
                return Ok(());
            }
            if Instant::now() > end {
                return Err(format!(
                    "the controller reported no temperatures within {timeout:?}\n{}",
                    self.report()
                ));
            }
            thread::sleep(Duration::from_millis(20));
        }
    }

    /// Next line from the firmware, or an error after `timeout` (with QEMU's log attached).
    pub fn next_line(&mut self, timeout: Duration) -> Result<String, String> {
        match self.lines.recv_timeout(timeout) {
            Ok(l) => {
                self.transcript.push(l.clone());
                Ok(l)
            }
            Err(RecvTimeoutError::Timeout) => Err(format!(
                "no line from the firmware within {timeout:?}\n{}",
                self.report()
            )),
            Err(RecvTimeoutError::Disconnected) => Err(format!(
                "the firmware's serial port closed\n{}",
                self.report()
            )),
        }
    }

    /// Sends raw bytes to USART1.
    pub fn write_raw(&mut self, bytes: &[u8]) -> Result<(), String> {
        self.stream
            .write_all(bytes)
            .map_err(|e| format!("write to USART1: {e}"))
    }

    /// Sends a command line and collects lines up to and including its final reply (`ok...` or
    /// `error: ...`); unsolicited `event:`/`alarm:` lines that arrive meanwhile are included.
    pub fn command(&mut self, line: &str, timeout: Duration) -> Result<Vec<String>, String> {
        self.write_raw(format!("{line}\n").as_bytes())?;
        let end = Instant::now() + timeout;
        let mut got = Vec::new();
        loop {
            let left = end.saturating_duration_since(Instant::now());
            let l = self.next_line(left).map_err(|e| format!("`{line}`: {e}"))?;
            let last = is_final_reply(&l);
            got.push(l);
            if last {
                return Ok(got);
            }
        }
    }

    /// Waits for a line starting with `prefix`; returns it and every line before it.
    pub fn wait_for(&mut self, prefix: &str, timeout: Duration) -> Result<Vec<String>, String> {
        let end = Instant::now() + timeout;
        let mut got = Vec::new();
        loop {
            let left = end.saturating_duration_since(Instant::now());
            let l = self
                .next_line(left)
                .map_err(|e| format!("waiting for `{prefix}`: {e}"))?;
            let hit = l.starts_with(prefix);
            got.push(l);
            if hit {
                return Ok(got);
            }
        }
    }

    /// QEMU's exit status, if it has exited.
    pub fn exited(&mut self) -> Option<ExitStatus> {
        self.child.try_wait().ok().flatten()
    }

    /// What QEMU and the firmware's semihosting console printed, plus the serial transcript's tail.
    pub fn report(&mut self) -> String {
        while let Ok(l) = self.log.try_recv() {
            self.log_kept.push(l);
        }
        let status = match self.child.try_wait() {
            Ok(Some(s)) => format!("QEMU exited: {s}"),
            _ => "QEMU still running".to_string(),
        };
        let tail: Vec<&String> = self
            .transcript
            .iter()
            .rev()
            .take(20)
            .collect::<Vec<_>>()
            .into_iter()
            .rev()
            .collect();
        format!(
            "{status}\n--- QEMU / semihosting log ---\n{}\n--- last serial lines ---\n{}",
            self.log_kept.join("\n"),
            tail.iter()
                .map(|s| s.as_str())
                .collect::<Vec<_>>()
                .join("\n")
        )
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Longest wall time the demo morph may take.
pub const DEMO_TIMEOUT: Duration = Duration::from_secs(120);

/// Wall times of a [`demo_morph`], for the reader (they vary run to run, so they are not part
/// of its printed output).
pub struct DemoTimes {
    /// Boot to the first line.
    pub boot: Duration,
    /// MORPH sent to `event: done`.
    pub morph: Duration,
    /// The whole demo.
    pub total: Duration,
}

/// The demo of `cargo xtask emulate --morph`: boots the image, morphs to `radius_mm`, asks
/// `SIM STATE` and `STATS`, and hands every line the firmware sends to `out` (the docs test
/// checks docs/emulation.md's block against exactly these lines).
pub fn demo_morph(
    qemu: &Path,
    image: &Path,
    radius_mm: f32,
    out: &mut dyn FnMut(&str),
) -> Result<DemoTimes, String> {
    use morphlink::protocol::{classify, LineKind};
    let started = Instant::now();
    let mut emu = Emulator::boot(qemu, image)?;
    out(&emu.transcript[0]);
    emu.wait_ready(Duration::from_secs(5))?;
    let morph_start = Instant::now();
    for l in emu.command(&format!("MORPH {radius_mm}"), Duration::from_secs(5))? {
        out(&l);
        if classify(&l) == LineKind::Error {
            return Err(format!("the firmware refused MORPH {radius_mm}"));
        }
    }
    loop {
        let l = emu.next_line(DEMO_TIMEOUT)?;
        out(&l);
        match classify(&l) {
            LineKind::Alarm => return Err("the morph ended in a fault".into()),
            LineKind::Done => break,
            _ => {}
        }
    }
    let morph = morph_start.elapsed();
    // The control loop's timing over the morph (docs/firmware.md, "Tick time under QEMU").
    for cmd in ["SIM STATE", "STATS"] {
        for l in emu.command(cmd, Duration::from_secs(5))? {
            out(&l);
        }
    }
    Ok(DemoTimes {
        boot: emu.boot_time,
        morph,
        total: started.elapsed(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    #[cfg(target_os = "linux")]
    #[test]
    fn a_child_dies_with_the_thread_that_started_it() {
        // The parent here is a thread that ends at once without waiting, as xtask does when a
        // signal or a kill ends it: its child must not run on.
        let child = thread::spawn(|| {
            let mut c = Command::new("sleep");
            c.arg("30");
            ends_with_its_parent(&mut c);
            c.spawn().unwrap()
        })
        .join()
        .unwrap();
        let mut child = child;
        let t0 = Instant::now();
        let status = child.wait().unwrap();
        use std::os::unix::process::ExitStatusExt;
        assert_eq!(status.signal(), Some(libc::SIGKILL), "{status:?}");
        assert!(t0.elapsed() < Duration::from_secs(5));
    }

    #[test]
    fn a_signal_kills_and_reaps_the_child_instead_of_leaving_it_running() {
        let mut child = Command::new("sleep").arg("30").spawn().unwrap();
        let pid = child.id() as i32;
        let flag = AtomicUsize::new(0);
        let t0 = Instant::now();
        thread::scope(|s| {
            s.spawn(|| {
                thread::sleep(Duration::from_millis(200));
                flag.store(libc::SIGTERM as usize, Ordering::SeqCst);
            });
            match wait_or_kill(&mut child, &flag).unwrap() {
                Ended::Signalled(sig) => assert_eq!(sig, libc::SIGTERM),
                other => panic!("{other:?}"),
            }
        });
        assert!(t0.elapsed() < Duration::from_secs(5));
        // Reaped: no such process any more.
        assert_eq!(unsafe { libc::kill(pid, 0) }, -1);
        // A child that ends on its own is waited for.
        let mut quick = Command::new("true").spawn().unwrap();
        assert!(matches!(
            wait_or_kill(&mut quick, &AtomicUsize::new(0)).unwrap(),
            Ended::Exited(s) if s.success()
        ));
    }
}
