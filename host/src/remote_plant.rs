//! [`RemotePlant`]: a plant in another process, spoken to over plant protocol 1
//! (`morphlink_plant::wire`): a Python FEM, a recorded experiment, a rig's sensors, or
//! `morph-plant`.
//!
//! The command runs under `sh -c` with its stdin and stdout piped to the rig and its stderr
//! passed through. The rig sends `hello` once, then one `step` per [`Plant::step`] and a `set`
//! per `SIM SUPPLY`/`AMBIENT`/`MEDIUM`, and waits for each reply at most the reply timeout
//! (10 s by default; a reader thread and a channel). A plant that exits, answers `error:` (to
//! a step) or garbage, or is silent that long has failed: [`Plant::step`] returns nothing, so
//! the failure is recorded, named by the plant's command, and given by [`Plant::failure`];
//! the shell checks it after each tick and ends the run. After a failure the plant is not
//! spoken to again and keeps its last sample. Dropped, it closes the plant's input (end of
//! input: the plant exits) and after half a second kills the plant's process group.
//!
//! What the protocol does not carry, [`Plant::truth`] cannot give: its temperatures are the
//! bead temperatures of the last reply (not the rod means an in-process plant reports) and its
//! powers are NaN (unknown); its time is the sum of the steps sent.

use morphlink_plant::wire::{self, Reply, Request};
use morphlink_plant::{Duties, Plant, Sample, SetError, Setting, Truth};
use std::io::{BufRead, BufReader, Write};
use std::os::unix::process::CommandExt;
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

/// How long the rig waits for a reply by default: 10 s, far beyond a step of any sensible
/// model (the lumped plant answers in microseconds), short enough that a hung plant is seen.
pub const REPLY_TIMEOUT: Duration = Duration::from_secs(10);

/// How long a plant that closed its output is given to exit before its status is read.
const EXIT_GRACE: Duration = Duration::from_millis(500);

/// A plant in a child process, over the plant protocol.
pub struct RemotePlant {
    cmd: String,
    child: Child,
    stdin: Option<ChildStdin>,
    replies: Receiver<String>,
    timeout: Duration,
    last: Sample,
    time_s: f64,
    failure: Option<String>,
}

/// What a sent line got back.
enum Answer {
    /// `ok ...`.
    Ok(Sample),
    /// `error: <text>` (the text).
    Error(String),
}

impl RemotePlant {
    /// Starts `sh -c <cmd>`, sends `hello protocol=1 tick_s=<tick_s>` and takes the reply's
    /// sample as the plant's first. Any failure (it cannot start, exits, is silent for
    /// `timeout`, answers garbage or `error:`) is the error, naming the command.
    pub fn spawn(cmd: &str, tick_s: f64, timeout: Duration) -> Result<Self, String> {
        let mut child = Command::new("sh")
            .arg("-c")
            .arg(cmd)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            // Its own process group, so that a hung plant is ended with whatever it started.
            .process_group(0)
            .spawn()
            .map_err(|e| format!("plant `{cmd}` could not be started with sh -c: {e}"))?;
        let stdout = child.stdout.take().expect("piped stdout");
        let stdin = child.stdin.take();
        let (tx, replies) = mpsc::channel();
        std::thread::spawn(move || {
            let mut r = BufReader::new(stdout);
            loop {
                let mut line = String::new();
                match r.read_line(&mut line) {
                    Ok(0) | Err(_) => break,
                    Ok(_) => {
                        if tx.send(line).is_err() {
                            break;
                        }
                    }
                }
            }
        });
        let mut plant = RemotePlant {
            cmd: cmd.to_string(),
            child,
            stdin,
            replies,
            timeout,
            last: Sample {
                t_pla_c: f64::NAN,
                t_tca_c: f64::NAN,
                t_amb_c: f64::NAN,
                supply_v: f64::NAN,
                radius_mm: f64::NAN,
                heater_ohm: None,
            },
            time_s: 0.0,
            failure: None,
        };
        let hello = Request::Hello {
            protocol: wire::PROTOCOL,
            tick_s,
        };
        match plant.exchange(&hello)? {
            Answer::Ok(s) => plant.last = s,
            Answer::Error(text) => return Err(plant.refused(&hello, &text)),
        }
        Ok(plant)
    }

    /// The plant's command.
    pub fn command(&self) -> &str {
        &self.cmd
    }

    /// `plant `<cmd>` answered `error: <text>` to `<request>``.
    fn refused(&self, req: &Request, text: &str) -> String {
        let mut error = String::new();
        let _ = wire::write_error(&mut error, text);
        format!(
            "plant `{}` answered `{error}` to `{}`",
            self.cmd,
            request_line(req)
        )
    }

    /// Sends `req` and waits for its reply. `Err` is a failure of the plant (gone, silent,
    /// garbage), already worded.
    fn exchange(&mut self, req: &Request) -> Result<Answer, String> {
        let line = request_line(req);
        let sent = match self.stdin.as_mut() {
            Some(stdin) => writeln!(stdin, "{line}").and_then(|()| stdin.flush()),
            None => Err(std::io::ErrorKind::BrokenPipe.into()),
        };
        if sent.is_err() {
            return Err(self.gone(&line));
        }
        match self.replies.recv_timeout(self.timeout) {
            Ok(reply) => match wire::parse_reply(&reply) {
                Ok(Reply::Ok(s)) => Ok(Answer::Ok(s)),
                Ok(Reply::Error(text)) => Ok(Answer::Error(text.to_string())),
                Err(e) => Err(format!(
                    "plant `{}` answered garbage to `{line}` ({e}): `{}`",
                    self.cmd,
                    reply.trim_end()
                )),
            },
            Err(RecvTimeoutError::Timeout) => Err(format!(
                "plant `{}` was silent for {} s after `{line}`",
                self.cmd,
                self.timeout.as_secs_f64()
            )),
            Err(RecvTimeoutError::Disconnected) => Err(self.gone(&line)),
        }
    }

    /// The plant closed its side: how it exited, if it has.
    fn gone(&mut self, line: &str) -> String {
        self.stdin = None;
        let deadline = Instant::now() + EXIT_GRACE;
        let status = loop {
            match self.child.try_wait() {
                Ok(Some(status)) => break Some(status),
                Ok(None) if Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(5))
                }
                _ => break None,
            }
        };
        match status {
            Some(status) => format!(
                "plant `{}` exited ({status}) instead of answering `{line}`",
                self.cmd
            ),
            None => format!(
                "plant `{}` closed its output instead of answering `{line}`",
                self.cmd
            ),
        }
    }

    fn fail(&mut self, why: String) {
        if self.failure.is_none() {
            self.failure = Some(why);
        }
    }
}

/// The text of a request line.
fn request_line(req: &Request) -> String {
    let mut line = String::new();
    let _ = wire::write_request(&mut line, req);
    line
}

impl Plant for RemotePlant {
    fn step(&mut self, dt_s: f64, duty: Duties) {
        if self.failure.is_some() {
            return;
        }
        let req = Request::Step { dt_s, duty };
        match self.exchange(&req) {
            Ok(Answer::Ok(s)) => {
                self.last = s;
                self.time_s += dt_s;
            }
            Ok(Answer::Error(text)) => {
                let why = self.refused(&req, &text);
                self.fail(why)
            }
            Err(why) => self.fail(why),
        }
    }

    fn sample(&self) -> Sample {
        self.last
    }

    /// Bead temperatures and the summed step time; powers unknown (NaN): see the module doc.
    fn truth(&self) -> Truth {
        Truth {
            time_s: self.time_s,
            pla_c: self.last.t_pla_c,
            tca_c: self.last.t_tca_c,
            pla_w: f64::NAN,
            tca_w: f64::NAN,
        }
    }

    /// `error: unsupported ...` is [`SetError::Unsupported`]; any other error, or a plant that
    /// has failed, fails the plant (and refuses the setting).
    fn set(&mut self, setting: Setting) -> Result<(), SetError> {
        if self.failure.is_some() {
            return Err(SetError::Unsupported);
        }
        let req = Request::Set(setting);
        match self.exchange(&req) {
            Ok(Answer::Ok(s)) => {
                self.last = s;
                Ok(())
            }
            Ok(Answer::Error(text)) => {
                if !Reply::Error(&text).is_unsupported() {
                    let why = self.refused(&req, &text);
                    self.fail(why);
                }
                Err(SetError::Unsupported)
            }
            Err(why) => {
                self.fail(why);
                Err(SetError::Unsupported)
            }
        }
    }

    fn failure(&self) -> Option<&str> {
        self.failure.as_deref()
    }
}

impl Drop for RemotePlant {
    /// Closes the plant's input (its end of input: it exits), gives it a moment, then kills it.
    fn drop(&mut self) {
        self.stdin = None;
        let deadline = Instant::now() + EXIT_GRACE;
        while Instant::now() < deadline {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        // The group's id is the shell's pid (`process_group(0)`): end the shell and its children.
        if let Ok(pid) = i32::try_from(self.child.id()) {
            // SAFETY: kill(2) takes no pointers; a stale group id at worst fails with ESRCH.
            unsafe {
                libc::kill(-pid, libc::SIGKILL);
            }
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const OK_LINE: &str = "ok t_pla_c=22 t_tca_c=23 t_amb_c=21 supply_v=12 radius_mm=46";

    fn echo_plant(reply_to_set: &str) -> String {
        format!(
            "while read verb rest; do case $verb in set) echo '{reply_to_set}';; \
             *) echo '{OK_LINE}';; esac; done"
        )
    }

    #[test]
    fn a_shell_plant_answers_steps_and_refuses_settings() {
        let mut p =
            RemotePlant::spawn(&echo_plant("error: unsupported"), 0.1, REPLY_TIMEOUT).unwrap();
        assert_eq!(p.sample().radius_mm, 46.0);
        p.step(0.1, Duties { pla: 0.5, tca: 0.0 });
        p.step(0.1, Duties::default());
        assert!(p.failure().is_none());
        assert!((p.truth().time_s - 0.2).abs() < 1e-12);
        assert_eq!(p.truth().pla_c, 22.0);
        assert!(p.truth().pla_w.is_nan());
        assert_eq!(p.set(Setting::SupplyV(5.0)), Err(SetError::Unsupported));
        assert!(p.failure().is_none(), "unsupported is no failure");
    }

    #[test]
    fn any_other_error_to_a_setting_fails_the_plant() {
        let mut p = RemotePlant::spawn(&echo_plant("error: boom"), 0.1, REPLY_TIMEOUT).unwrap();
        assert_eq!(p.set(Setting::AmbientC(30.0)), Err(SetError::Unsupported));
        let why = p.failure().unwrap();
        assert!(
            why.contains("answered `error: boom` to `set ambient_c=30`"),
            "{why}"
        );
    }

    #[test]
    fn failures_name_the_plant() {
        let cases = [
            ("exit 3", "exited (exit status: 3)"),
            (
                "read l; echo garbage",
                "answered garbage to `hello protocol=1 tick_s=0.1`",
            ),
            (
                "read l; echo 'error: boom'",
                "answered `error: boom` to `hello",
            ),
            ("sleep 5", "was silent for 0.3 s"),
        ];
        for (cmd, what) in cases {
            let e = RemotePlant::spawn(cmd, 0.1, Duration::from_millis(300))
                .err()
                .unwrap();
            assert!(e.starts_with(&format!("plant `{cmd}` ")), "{e}");
            assert!(e.contains(what), "{cmd}: {e}");
        }
    }

    #[test]
    fn a_plant_that_dies_mid_run_is_recorded_and_left_alone() {
        let cmd = format!("read l; echo '{OK_LINE}'; read l; echo '{OK_LINE}'; exit 0");
        let mut p = RemotePlant::spawn(&cmd, 0.1, REPLY_TIMEOUT).unwrap();
        p.step(0.1, Duties::default());
        assert!(p.failure().is_none());
        p.step(0.1, Duties::default());
        let why = p.failure().unwrap().to_string();
        assert!(
            why.contains("exited (exit status: 0) instead of answering `step"),
            "{why}"
        );
        p.step(0.1, Duties::default());
        assert_eq!(p.failure(), Some(why.as_str()), "the first failure is kept");
        assert_eq!(p.sample().radius_mm, 46.0);
    }
}
