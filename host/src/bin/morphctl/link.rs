//! The line link to a board (serial port), to `morph-sim` (a child process over pipes) or to a
//! TCP serial port (the emulated image's USART1, a serial-to-TCP bridge), and a protocol
//! session on it: the VERSION handshake, commands with their final reply, and the
//! unsolicited `event:`/`alarm:` lines.

use morphlink::protocol::client::{classify, data_text, LineKind};
use std::fmt;
use std::io::{Read, Write};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Protocol version this tool speaks (`VERSION` replies `ok version=<v> protocol=<PROTOCOL>`).
pub const PROTOCOL: u32 = morphlink::protocol::PROTOCOL_VERSION;
/// Time a device has to answer VERSION, s: a board answers within a tick (100 ms); 3 s leaves
/// room for a board that was just reset by the port opening (USB CDC on some boards).
pub const HANDSHAKE_TIMEOUT_S: f64 = 3.0;
/// Time any other command's final reply may take, s.
pub const REPLY_TIMEOUT_S: f64 = 2.0;
/// Read timeout of the serial port, ms: short, so the reader thread notices a closed tool.
const SERIAL_READ_TIMEOUT_MS: u64 = 100;
/// Longest line a device sends, bytes without the ending: the firmware writes every line into a
/// `protocol::OutLine` ([`morphlink::protocol::OUT_LINE_BYTES`]). Longer lines are dropped and
/// reported, never buffered.
pub const MAX_REPLY_LINE: usize = morphlink::protocol::OUT_LINE_BYTES;
/// Lines the reader thread may queue before it waits for the tool to take them (then the
/// device's side of the pipe or the serial driver's buffer fills instead of our memory).
const LINE_QUEUE: usize = 256;
/// Longest a wait for a line goes without looking at the signal flag, ms.
const SIGNAL_POLL_MS: u64 = 50;
/// The simulator's last stderr lines kept, to say why it closed the link (its own error, such
/// as an option it refused): its stderr is not shown as it runs, since it would tear the
/// live view.
const STDERR_TAIL_LINES: usize = 8;
/// How long a closed link waits for the simulator's stderr to end before it reports, ms.
const STDERR_WAIT_MS: u64 = 500;

/// Why a link operation failed.
#[derive(Clone, Debug, PartialEq)]
pub enum LinkError {
    /// A termination signal arrived (its number) while waiting.
    Interrupted(i32),
    /// The device did not answer in time.
    Timeout(String),
    /// The link closed, or a write failed.
    Closed(String),
    /// The device sent something that is not the protocol.
    Protocol(String),
}

impl fmt::Display for LinkError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LinkError::Interrupted(sig) => write!(f, "interrupted by {}", signal_name(*sig)),
            LinkError::Timeout(m) | LinkError::Closed(m) | LinkError::Protocol(m) => f.write_str(m),
        }
    }
}

impl From<LinkError> for String {
    fn from(e: LinkError) -> String {
        e.to_string()
    }
}

/// `SIGINT`, `SIGTERM`, ... for a signal number.
pub fn signal_name(sig: i32) -> String {
    match sig {
        libc::SIGINT => "SIGINT (Ctrl-C)".into(),
        libc::SIGTERM => "SIGTERM".into(),
        libc::SIGHUP => "SIGHUP".into(),
        n => format!("signal {n}"),
    }
}

/// The signal flag: 0, or the number of the last termination signal received. The handlers
/// only store into it (`signal_hook::flag`); the tool's loops look at it.
pub fn watch_signals() -> Result<Arc<AtomicUsize>, String> {
    let flag = Arc::new(AtomicUsize::new(0));
    for sig in [libc::SIGINT, libc::SIGTERM, libc::SIGHUP] {
        signal_hook::flag::register_usize(sig, Arc::clone(&flag), sig as usize)
            .map_err(|e| format!("cannot watch {}: {e}", signal_name(sig)))?;
    }
    Ok(flag)
}

/// Where the lines come from.
pub enum Target {
    /// A serial port at a path, with a baud rate.
    Serial {
        /// Device path (`/dev/ttyACM0`, `COM3`).
        path: String,
        /// Baud rate (the firmware's USB CDC ignores it; a UART bridge needs it).
        baud: u32,
    },
    /// `morph-sim` started as a child at a speed factor.
    Sim {
        /// The `morph-sim` executable.
        program: PathBuf,
        /// Arguments given with it (`--sim-program "morph-sim --plant hifi"`), before
        /// morphctl's own (`--flash-file`, `--plant`, `--speed`).
        args: Vec<String>,
        /// morph-sim's `--plant` (`--sim-plant`), if given.
        plant: Option<String>,
        /// Simulation speed, a factor of real time.
        speed: f64,
        /// morph-sim's `--flash-file`: where the simulated settings flash is kept.
        flash_file: Option<PathBuf>,
        /// morph-sim's `--links` (`--sim-links`), if given.
        links: Option<u8>,
        /// Whether `program` came from `--sim-program` (not the default beside morphctl).
        given: bool,
    },
    /// A serial port served over TCP at `HOST:PORT` (`cargo xtask emulate --port`, ser2net).
    Tcp {
        /// `HOST:PORT`.
        addr: String,
    },
}

/// Time morphctl waits for a boot line after connecting over TCP, s: the emulated image sends
/// it about 80 ms after QEMU starts (docs/emulation.md); a bridge to a running board sends
/// nothing, and costs this once.
pub const TCP_BOOT_WAIT_S: f64 = 2.0;
/// Time to connect to a TCP serial port, s: a loopback or LAN peer answers within
/// milliseconds; beyond this the address is wrong or nothing listens.
pub const TCP_CONNECT_TIMEOUT_S: f64 = 3.0;

/// A line received from the device.
#[derive(Clone, Debug, PartialEq)]
pub enum Incoming {
    /// A line of text (without its line ending).
    Line(String),
    /// A line longer than [`MAX_REPLY_LINE`] was dropped; its length in bytes.
    TooLong(usize),
    /// The device closed the link (the child exited, the port vanished).
    Closed(String),
}

/// An open link: lines out, lines in through a reader thread.
pub struct Link {
    writer: Box<dyn Write + Send>,
    lines: Receiver<Incoming>,
    child: Option<Child>,
    signals: Arc<AtomicUsize>,
    /// False while morphctl stops the heaters: a second Ctrl-C must not cut that short.
    interruptible: bool,
    /// Replies still owed to commands whose wait a signal cut short: the next final replies
    /// are theirs, not the next command's.
    owed: usize,
    /// Over-long lines dropped so far.
    pub dropped_lines: usize,
    /// True for `morph-sim` (it answers `SIM` commands).
    pub simulated: bool,
    /// What the link is, for messages.
    pub name: String,
    /// The simulator's plant, where known (`lumped`, `hifi`, `--plant-cmd`), for titles.
    pub plant: Option<String>,
    /// How many links the device drives, as far as morphctl knows (1 until a gait asks
    /// `LINKS`): stopping the heaters then checks every link's STATUS.
    pub links: usize,
    /// The simulator's stderr: its last lines, and the thread that reads them.
    stderr: Option<StderrTail>,
}

/// The last [`STDERR_TAIL_LINES`] lines of a child's stderr, read on a thread.
struct StderrTail {
    lines: Arc<std::sync::Mutex<std::collections::VecDeque<String>>>,
    reader: std::thread::JoinHandle<()>,
}

impl StderrTail {
    fn spawn(source: impl Read + Send + 'static) -> StderrTail {
        let lines = Arc::new(std::sync::Mutex::new(std::collections::VecDeque::new()));
        let kept = Arc::clone(&lines);
        let reader = std::thread::spawn(move || {
            use std::io::BufRead;
            for l in std::io::BufReader::new(source)
                .split(b'\n')
                .map_while(Result::ok)
            {
                let mut q = kept.lock().unwrap_or_else(|e| e.into_inner());
                if q.len() == STDERR_TAIL_LINES {
                    q.pop_front();
                }
                // Control bytes (a terminal's escapes, a CR) shown, not acted on.
                let l: String = String::from_utf8_lossy(&l)
                    .trim_end_matches('\r')
                    .chars()
                    .take(MAX_REPLY_LINE)
                    .map(|c| if c.is_control() { '?' } else { c })
                    .collect();
                q.push_back(l);
            }
        });
        StderrTail { lines, reader }
    }

    /// Its lines so far, once the stream has ended or [`STDERR_WAIT_MS`] have passed.
    fn said(&self) -> Vec<String> {
        let until = Instant::now() + Duration::from_millis(STDERR_WAIT_MS);
        while !self.reader.is_finished() && Instant::now() < until {
            std::thread::sleep(Duration::from_millis(10));
        }
        let q = self.lines.lock().unwrap_or_else(|e| e.into_inner());
        q.iter().filter(|l| !l.trim().is_empty()).cloned().collect()
    }
}

/// Error text for a serial port that could not be opened.
fn serial_error(path: &str, e: &serialport::Error) -> String {
    use serialport::ErrorKind as K;
    let known = || match serialport::available_ports() {
        Ok(p) if !p.is_empty() => {
            let names: Vec<String> = p.into_iter().map(|p| p.port_name).collect();
            format!("ports found: {}", names.join(", "))
        }
        _ => "no serial ports found; is the board plugged in?".to_string(),
    };
    match e.kind() {
        K::Io(std::io::ErrorKind::NotFound) => {
            format!("no serial port at {path} ({})", known())
        }
        K::NoDevice => format!(
            "{path} is busy: another program (a terminal, another morphctl) has it open; close it and retry"
        ),
        K::Io(std::io::ErrorKind::PermissionDenied) => format!(
            "permission denied opening {path}: add your user to the group that owns it (often `dialout`)"
        ),
        _ => format!("cannot open {path} as a serial port: {e}"),
    }
}

/// Reads lines on a thread into a bounded queue; each line is held in at most
/// [`MAX_REPLY_LINE`] bytes.
fn spawn_reader(mut source: impl Read + Send + 'static, what: String) -> Receiver<Incoming> {
    let (tx, rx) = mpsc::sync_channel(LINE_QUEUE);
    std::thread::spawn(move || {
        let mut pending = Vec::with_capacity(MAX_REPLY_LINE);
        // Bytes of the current line, counted past the ones kept.
        let mut line_bytes = 0usize;
        let mut buf = [0u8; 256];
        loop {
            match source.read(&mut buf) {
                Ok(0) => {
                    let _ = tx.send(Incoming::Closed(format!("{what} closed the link")));
                    return;
                }
                Ok(n) => {
                    for &b in &buf[..n] {
                        if b == b'\n' {
                            let item = if line_bytes > MAX_REPLY_LINE {
                                Incoming::TooLong(line_bytes)
                            } else {
                                Incoming::Line(
                                    String::from_utf8_lossy(&pending)
                                        .trim_end_matches('\r')
                                        .to_string(),
                                )
                            };
                            pending.clear();
                            line_bytes = 0;
                            if tx.send(item).is_err() {
                                return;
                            }
                        } else if b == b'\r' && line_bytes == MAX_REPLY_LINE {
                            // A full-length line's `\r\n` ending: the `\r` is not content.
                        } else {
                            line_bytes = line_bytes.saturating_add(1);
                            if pending.len() < MAX_REPLY_LINE {
                                pending.push(b);
                            }
                        }
                    }
                }
                // A serial port's read timeout is TimedOut, a socket's WouldBlock.
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::TimedOut
                            | std::io::ErrorKind::Interrupted
                            | std::io::ErrorKind::WouldBlock
                    ) => {}
                Err(e) => {
                    let _ = tx.send(Incoming::Closed(format!("{what}: {e}")));
                    return;
                }
            }
        }
    });
    rx
}

/// `morph-sim` next to this executable (the same build), else on the PATH.
pub fn default_sim_program() -> PathBuf {
    let name = format!("morph-sim{}", std::env::consts::EXE_SUFFIX);
    if let Ok(me) = std::env::current_exe() {
        if let Some(dir) = me.parent() {
            let p = dir.join(&name);
            if p.exists() {
                return p;
            }
        }
    }
    PathBuf::from(name)
}

impl Link {
    fn new(
        writer: Box<dyn Write + Send>,
        lines: Receiver<Incoming>,
        child: Option<Child>,
        simulated: bool,
        name: String,
    ) -> Link {
        Link {
            writer,
            lines,
            child,
            signals: Arc::new(AtomicUsize::new(0)),
            interruptible: true,
            owed: 0,
            dropped_lines: 0,
            simulated,
            name,
            plant: None,
            links: 1,
            stderr: None,
        }
    }

    /// Why the link closed: `why`, and what the simulator said on its stderr ([`Link::said`]).
    fn closed(&self, why: String) -> LinkError {
        LinkError::Closed(format!("{why}{}", self.said()))
    }

    /// `; it said: ...` with the simulator's last stderr lines, or nothing (none, or no
    /// simulator).
    fn said(&self) -> String {
        let said = self
            .stderr
            .as_ref()
            .map(StderrTail::said)
            .unwrap_or_default();
        if said.is_empty() {
            String::new()
        } else {
            let quoted: Vec<String> = said.iter().map(|l| format!("`{l}`")).collect();
            format!("; it said: {}", quoted.join(" / "))
        }
    }

    /// The device for titles: `morph-sim (plant hifi)`, or its name.
    pub fn device(&self) -> String {
        match &self.plant {
            Some(p) => format!("{} (plant {p})", self.name),
            None => self.name.clone(),
        }
    }

    /// Waits for lines abort with [`LinkError::Interrupted`] once `flag` (from
    /// [`watch_signals`]) is set.
    pub fn watch(&mut self, flag: Arc<AtomicUsize>) {
        self.signals = flag;
    }

    /// The termination signal received, if any.
    pub fn signal(&self) -> Option<i32> {
        match self.signals.load(Ordering::SeqCst) {
            0 => None,
            n => Some(n as i32),
        }
    }

    /// Whether a signal cuts waits short (true by default; false while stopping the heaters).
    pub fn set_interruptible(&mut self, on: bool) {
        self.interruptible = on;
    }

    /// Opens the link (no handshake yet).
    pub fn open(target: &Target) -> Result<Link, String> {
        match target {
            Target::Serial { path, baud } => {
                if !Path::new(path).exists() && !path.to_ascii_uppercase().starts_with("COM") {
                    let e = serialport::Error::new(
                        serialport::ErrorKind::Io(std::io::ErrorKind::NotFound),
                        "not found",
                    );
                    return Err(serial_error(path, &e));
                }
                let port = serialport::new(path, *baud)
                    .timeout(Duration::from_millis(SERIAL_READ_TIMEOUT_MS))
                    .open()
                    .map_err(|e| serial_error(path, &e))?;
                let reader = port
                    .try_clone()
                    .map_err(|e| format!("cannot read from {path}: {e}"))?;
                Ok(Link::new(
                    Box::new(port),
                    spawn_reader(reader, path.clone()),
                    None,
                    false,
                    path.clone(),
                ))
            }
            Target::Tcp { addr } => open_tcp(addr),
            Target::Sim {
                program,
                args,
                plant,
                speed,
                flash_file,
                links,
                given,
            } => {
                let mut command = Command::new(program);
                command.args(args);
                if let Some(n) = links {
                    command.arg("--links").arg(n.to_string());
                }
                if let Some(f) = flash_file {
                    command.arg("--flash-file").arg(f);
                }
                if let Some(p) = plant {
                    command.arg("--plant").arg(p);
                }
                let mut child = command
                    .arg("--speed")
                    .arg(format!("{speed}"))
                    .stdin(Stdio::piped())
                    .stdout(Stdio::piped())
                    .stderr(Stdio::piped())
                    // Its own process group: a terminal's Ctrl-C reaches morphctl only, which
                    // then still has a simulator to send ABORT to.
                    .process_group(0)
                    .spawn()
                    .map_err(|e| {
                        let hint = if *given {
                            "check --sim-program"
                        } else {
                            "build it with `cargo build -p morphlink-host --bin morph-sim`, or pass --sim-program"
                        };
                        format!("cannot start {}: {e} ({hint})", program.display())
                    })?;
                let stdin = child.stdin.take().expect("piped stdin");
                let stdout = child.stdout.take().expect("piped stdout");
                let stderr = StderrTail::spawn(child.stderr.take().expect("piped stderr"));
                let mut link = Link::new(
                    Box::new(stdin),
                    spawn_reader(stdout, "morph-sim".into()),
                    Some(child),
                    true,
                    "morph-sim".into(),
                );
                link.plant = Some(sim_plant(args, plant.as_deref()));
                link.stderr = Some(stderr);
                Ok(link)
            }
        }
    }

    /// Sends one line.
    pub fn send(&mut self, line: &str) -> Result<(), LinkError> {
        let sent = self
            .writer
            .write_all(format!("{line}\n").as_bytes())
            .and_then(|_| self.writer.flush());
        sent.map_err(|e| match e.kind() {
            // A simulator that exited: as when its output ends, with what it said.
            std::io::ErrorKind::BrokenPipe if self.stderr.is_some() => {
                self.closed(format!("{} closed the link", self.name))
            }
            _ => self.closed(format!("cannot write to {}: {e}", self.name)),
        })
    }

    /// Next received line within `timeout`; `Ok(None)` if none arrived. Over-long lines are
    /// reported on stderr and skipped; a signal (while interruptible) ends the wait.
    pub fn recv(&mut self, timeout: Duration) -> Result<Option<String>, LinkError> {
        let deadline = Instant::now() + timeout;
        loop {
            if self.interruptible {
                if let Some(sig) = self.signal() {
                    return Err(LinkError::Interrupted(sig));
                }
            }
            let left = deadline.saturating_duration_since(Instant::now());
            let slice = left.min(Duration::from_millis(SIGNAL_POLL_MS));
            match self.lines.recv_timeout(slice) {
                Ok(Incoming::Line(l)) => return Ok(Some(l)),
                Ok(Incoming::TooLong(n)) => {
                    self.dropped_lines += 1;
                    eprintln!(
                        "morphctl: skipped a {n}-byte line from {} (lines are at most {MAX_REPLY_LINE} bytes)",
                        self.name
                    );
                }
                Ok(Incoming::Closed(why)) => return Err(self.closed(why)),
                Err(RecvTimeoutError::Timeout) if left.is_zero() => return Ok(None),
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => {
                    return Err(self.closed(format!("{} closed the link", self.name)))
                }
            }
        }
    }

    /// Sends a command and waits for its final reply (`ok ...` or `error: ...`), returning
    /// the `data:` lines and the final line; unsolicited lines go to `on_event`.
    pub fn command(
        &mut self,
        line: &str,
        timeout_s: f64,
        on_event: &mut dyn FnMut(&str),
    ) -> Result<(Vec<String>, String), LinkError> {
        self.command_where(line, timeout_s, on_event, &|_| true)
    }

    /// [`Link::command`] whose reply must pass `expected`: other final lines (a late reply to
    /// an earlier command that timed out) are skipped with a note on stderr. Replies owed to
    /// an interrupted command are skipped first.
    pub fn command_where(
        &mut self,
        line: &str,
        timeout_s: f64,
        on_event: &mut dyn FnMut(&str),
        expected: &dyn Fn(&str) -> bool,
    ) -> Result<(Vec<String>, String), LinkError> {
        self.send(line)?;
        let deadline = Instant::now() + Duration::from_secs_f64(timeout_s);
        let mut data = Vec::new();
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let got = if left.is_zero() {
                None
            } else {
                match self.recv(left) {
                    Err(e @ LinkError::Interrupted(_)) => {
                        self.owed += 1;
                        return Err(e);
                    }
                    r => r?,
                }
            };
            let Some(l) = got else {
                return Err(LinkError::Timeout(format!(
                    "{} did not answer `{line}` within {timeout_s} s{}",
                    self.name,
                    self.said()
                )));
            };
            match classify(&l) {
                kind if kind.is_unsolicited() => on_event(&l),
                LineKind::Data => data.push(data_text(&l).unwrap_or_default().to_string()),
                kind if kind.is_final() && self.owed > 0 => {
                    self.owed -= 1;
                    data.clear();
                }
                kind if kind.is_final() && !expected(&l) => {
                    eprintln!("morphctl: ignored `{l}`, a late reply to an earlier command");
                    data.clear();
                }
                kind if kind.is_final() => return Ok((data, l)),
                LineKind::Blank => {}
                _ => {
                    let why = not_morphlink(&self.name, &l, self.stderr.is_some());
                    return Err(LinkError::Protocol(why));
                }
            }
        }
    }

    /// Asks whether the device answers `SIM STATE` (morph-sim, the emulated image) and marks
    /// the link simulated if it does; a board answers `error: unsupported`.
    pub fn probe_simulated(&mut self) -> Result<bool, LinkError> {
        let (_, reply) = self.command("SIM STATE", REPLY_TIMEOUT_S, &mut |_| {})?;
        self.simulated = classify(&reply) == LineKind::Ok && field(&reply, "time_s").is_some();
        Ok(self.simulated)
    }

    /// Checks the device speaks [`PROTOCOL`]: `VERSION` must reply `ok version=.. protocol=<PROTOCOL>`.
    /// Returns the firmware version.
    pub fn handshake(&mut self) -> Result<String, String> {
        let (_, reply) = self
            .command("VERSION", HANDSHAKE_TIMEOUT_S, &mut |_| {})
            .map_err(|e| match e {
                // A simulator that exited has said why (its stderr, in the error).
                LinkError::Closed(_) | LinkError::Timeout(_) if self.stderr.is_some() => {
                    e.to_string()
                }
                LinkError::Interrupted(_) => e.to_string(),
                _ => format!("{e}; is this a morphlink board? (it must answer VERSION with `ok version=.. protocol={PROTOCOL}`)")
            })?;
        let version = field(&reply, "version");
        let ok = classify(&reply) == LineKind::Ok;
        match (ok, version, field(&reply, "protocol")) {
            (true, Some(v), Some(p)) if p == PROTOCOL.to_string() => Ok(v),
            (true, Some(_), Some(p)) => Err(format!(
                "{} speaks morphlink protocol {p}; this morphctl speaks protocol {PROTOCOL}",
                self.name
            )),
            _ => Err(not_morphlink(&self.name, &reply, self.stderr.is_some())),
        }
    }
}

/// The plant a morph-sim started with `args` and `--sim-plant` runs: the last `--plant` given,
/// `--plant-cmd` for a plant over the plant protocol, else morph-sim's default, `lumped`.
pub fn sim_plant(args: &[String], sim_plant: Option<&str>) -> String {
    if let Some(p) = sim_plant {
        return p.to_string();
    }
    let mut plant = "lumped".to_string();
    let mut words = args.iter();
    while let Some(w) = words.next() {
        if let Some(v) = w.strip_prefix("--plant=") {
            plant = v.to_string();
        } else if w == "--plant" {
            if let Some(v) = words.next() {
                plant = v.clone();
            }
        } else if w == "--plant-cmd" || w.starts_with("--plant-cmd=") {
            plant = "--plant-cmd".into();
        }
    }
    plant
}

/// Connects to a TCP serial port (`HOST:PORT`), Nagle off so each line goes out at once.
fn open_tcp(addr: &str) -> Result<Link, String> {
    use std::net::{TcpStream, ToSocketAddrs};
    let addrs: Vec<_> = addr
        .to_socket_addrs()
        .map_err(|e| format!("--tcp {addr}: not a HOST:PORT address ({e})"))?
        .collect();
    let timeout = Duration::from_secs_f64(TCP_CONNECT_TIMEOUT_S);
    let mut last = None;
    for a in &addrs {
        match TcpStream::connect_timeout(a, timeout) {
            Ok(stream) => {
                let name = format!("tcp:{addr}");
                let io = |e: std::io::Error| format!("{name}: {e}");
                stream.set_nodelay(true).map_err(io)?;
                stream
                    .set_read_timeout(Some(Duration::from_millis(SERIAL_READ_TIMEOUT_MS)))
                    .map_err(io)?;
                let reader = stream.try_clone().map_err(io)?;
                return Ok(Link::new(
                    Box::new(stream),
                    spawn_reader(reader, name.clone()),
                    None,
                    false,
                    name,
                ));
            }
            Err(e) => last = Some(e),
        }
    }
    Err(match last {
        Some(e) => format!(
            "cannot connect to {addr}: {e} (is `cargo xtask emulate --port <PORT>` or the bridge running?)"
        ),
        None => format!("--tcp {addr}: the name resolves to no address"),
    })
}

fn not_morphlink(name: &str, line: &str, simulated: bool) -> String {
    let shown: String = line.chars().take(60).collect();
    let check = if simulated {
        "check --sim-program"
    } else {
        "check the port and baud rate"
    };
    format!("{name} does not speak the morphlink protocol (it sent `{shown}`); {check}")
}

impl Drop for Link {
    fn drop(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// Value of `key=` in a reply line.
pub fn field(line: &str, key: &str) -> Option<String> {
    line.split(' ')
        .find_map(|w| w.strip_prefix(key)?.strip_prefix('=').map(str::to_string))
}

/// A reader over a fixed text, for tests: lines as a device would send them.
#[cfg(test)]
pub fn link_from_text(text: &str) -> Link {
    Link::new(
        Box::new(std::io::sink()),
        spawn_reader(
            std::io::Cursor::new(text.as_bytes().to_vec()),
            "test".into(),
        ),
        None,
        false,
        "test device".into(),
    )
}

/// A device for tests that sends `text` and then stays connected and silent (a reader that
/// times out, as an idle serial port does).
#[cfg(test)]
pub fn link_held_open(text: &str) -> Link {
    struct Held(std::io::Cursor<Vec<u8>>);
    impl Read for Held {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            match self.0.read(buf)? {
                0 => {
                    std::thread::sleep(Duration::from_millis(10));
                    Err(std::io::ErrorKind::TimedOut.into())
                }
                n => Ok(n),
            }
        }
    }
    Link::new(
        Box::new(std::io::sink()),
        spawn_reader(
            Held(std::io::Cursor::new(text.as_bytes().to_vec())),
            "test".into(),
        ),
        None,
        false,
        "test device".into(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn handshake_accepts_protocol_one_and_names_other_speakers() {
        let mut l = link_from_text("ok version=0.1.0 protocol=1\n");
        assert_eq!(l.handshake().unwrap(), "0.1.0");
        let mut l = link_from_text("event: phase bend t=1.0\nok version=2.0 protocol=2\n");
        let e = l.handshake().unwrap_err();
        assert!(e.contains("protocol 2"), "{e}");
        let mut l = link_from_text("AT+OK\r\n");
        let e = l.handshake().unwrap_err();
        assert!(e.contains("does not speak the morphlink protocol"), "{e}");
        let mut l = link_from_text("");
        let e = l.handshake().unwrap_err();
        assert!(e.contains("closed"), "{e}");
    }

    #[test]
    fn command_collects_data_and_passes_events_on() {
        let mut l = link_from_text("data: 0.000 46.46\nevent: done t=3.0 radius_mm=38.00\nok\n");
        let mut ev = Vec::new();
        let (data, fin) = l
            .command("TABLE", 1.0, &mut |e| ev.push(e.to_string()))
            .unwrap();
        assert_eq!(data, ["0.000 46.46"]);
        assert_eq!(fin, "ok");
        assert_eq!(ev, ["event: done t=3.0 radius_mm=38.00"]);
    }

    #[test]
    fn a_missing_port_is_named_with_the_ports_there_are() {
        let e = Link::open(&Target::Serial {
            path: "/dev/morphlink-no-such-port".into(),
            baud: 115_200,
        })
        .err()
        .unwrap();
        assert!(
            e.starts_with("no serial port at /dev/morphlink-no-such-port"),
            "{e}"
        );
    }

    #[test]
    fn over_long_lines_are_dropped_and_counted_not_buffered() {
        let long = "x".repeat(100_000);
        let exact = "y".repeat(MAX_REPLY_LINE);
        let mut l = link_from_text(&format!("{long}\n{exact}\r\nok\n"));
        assert_eq!(l.recv(Duration::from_secs(2)).unwrap(), Some(exact));
        assert_eq!(l.dropped_lines, 1);
        assert_eq!(
            l.recv(Duration::from_secs(2)).unwrap().as_deref(),
            Some("ok")
        );
    }

    #[test]
    fn the_line_cap_is_the_firmware_line_capacity() {
        assert_eq!(
            MAX_REPLY_LINE,
            morphlink::protocol::OutLine::new().capacity()
        );
    }

    #[test]
    fn a_signal_ends_a_wait_unless_stopping_the_heaters() {
        let mut l = link_from_text("");
        let flag = Arc::new(AtomicUsize::new(libc::SIGTERM as usize));
        l.watch(flag);
        assert_eq!(
            l.command("STATUS", 1.0, &mut |_| {}).unwrap_err(),
            LinkError::Interrupted(libc::SIGTERM)
        );
        l.set_interruptible(false);
        assert!(matches!(
            l.command("STATUS", 1.0, &mut |_| {}).unwrap_err(),
            LinkError::Closed(_)
        ));
    }

    #[test]
    fn the_sim_plant_is_named_from_its_arguments() {
        let a = |s: &[&str]| s.iter().map(|w| w.to_string()).collect::<Vec<_>>();
        assert_eq!(sim_plant(&[], None), "lumped");
        assert_eq!(sim_plant(&a(&["--plant", "hifi"]), None), "hifi");
        assert_eq!(
            sim_plant(&a(&["--plant=hifi", "--seed", "3"]), None),
            "hifi"
        );
        assert_eq!(sim_plant(&a(&["--plant-cmd", "x"]), None), "--plant-cmd");
        assert_eq!(sim_plant(&[], Some("hifi")), "hifi");
    }

    #[test]
    fn fields_are_found_by_key() {
        let l = "ok phase=bend target_mm=38.00 t_pla_c=75.1";
        assert_eq!(field(l, "phase").as_deref(), Some("bend"));
        assert_eq!(field(l, "t_pla_c").as_deref(), Some("75.1"));
        assert_eq!(field(l, "t_pla"), None);
    }
}
