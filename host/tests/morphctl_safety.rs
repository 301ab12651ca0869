//! morphctl stops what it started: a signal or a lost device during a morph ends in ABORT and
//! a STATUS with both heaters off (seen from the device's side), the CSV keeps the rows of an
//! interrupted run, and an over-long line from the device is dropped without being buffered.
//!
//! The device is `morph-sim` behind a recording shim (`tee` on both pipes), or a `sh` script
//! that plays a broken device; morphctl starts either through `--sim --sim-program`.
#![cfg(unix)]

mod common;

use common::script;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

const MORPHCTL: &str = env!("CARGO_BIN_EXE_morphctl");
const MORPH_SIM: &str = env!("CARGO_BIN_EXE_morph-sim");

/// A fresh directory for one test.
fn scratch(name: &str) -> PathBuf {
    common::scratch("morphctl-safety", name)
}

/// morph-sim with every line to it in `to_device.log` and from it in `from_device.log`.
fn recording_sim(dir: &Path) -> PathBuf {
    let to = dir.join("to_device.log");
    let from = dir.join("from_device.log");
    script(
        dir,
        "device.sh",
        &format!(
            "tee '{}' | '{MORPH_SIM}' \"$@\" | tee '{}'",
            to.display(),
            from.display()
        ),
    )
}

/// Starts morphctl with its stdout lines sent to the returned channel.
fn start(args: &[&str]) -> (Child, mpsc::Receiver<String>) {
    let mut child = Command::new(MORPHCTL)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let out = child.stdout.take().unwrap();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for l in BufReader::new(out).split(b'\n').map_while(Result::ok) {
            for part in String::from_utf8_lossy(&l).split('\r') {
                let _ = tx.send(part.to_string());
            }
        }
    });
    (child, rx)
}

/// Waits for morphctl's exit (bounded); returns its status and stderr.
fn finish(mut child: Child, limit: Duration) -> (ExitStatus, String) {
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if t0.elapsed() > limit {
            let _ = child.kill();
            panic!("morphctl did not exit within {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let mut err = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
    (status, err)
}

/// The file's text once `pred` holds of it (the shim's `tee` may write a moment late).
fn eventually(path: &Path, pred: impl Fn(&str) -> bool) -> String {
    let t0 = Instant::now();
    loop {
        let text = std::fs::read_to_string(path).unwrap_or_default();
        if pred(&text) || t0.elapsed() > Duration::from_secs(5) {
            return text;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn heaters_off(status: &str) -> bool {
    status.starts_with("ok phase=")
        && status.contains(" p_pla_w=0.000 p_tca_w=0.000 ")
        && (status.contains("phase=idle ") || status.contains("phase=fault "))
}

/// What the recording device answered: `power_key` above 0 W in some STATUS while `what` ran,
/// both heaters off in the last one.
fn assert_heated_then_off(dir: &Path, power_key: &str, what: &str) {
    let from = eventually(&dir.join("from_device.log"), |t| {
        t.lines()
            .rfind(|l| l.starts_with("ok phase="))
            .is_some_and(heaters_off)
    });
    let statuses: Vec<&str> = from
        .lines()
        .filter(|l| l.starts_with("ok phase="))
        .collect();
    assert!(
        statuses
            .iter()
            .any(|s| !s.contains(&format!(" {power_key}=0.000 "))),
        "the {what} was heating before the signal:\n{from}"
    );
    assert!(heaters_off(statuses.last().unwrap()), "{from}");
}

/// Starts a morph on the recording simulator, waits until it is bending and logged a few
/// rows, then sends `sig`; returns the exit status, stderr and the scratch directory.
fn interrupt_a_morph(name: &str, sig: i32, extra: &[&str]) -> (ExitStatus, String, PathBuf) {
    let dir = scratch(name);
    let device = recording_sim(&dir);
    let csv = dir.join("run.csv");
    let mut args = vec![
        "--sim",
        "--sim-speed",
        "4",
        "--sim-program",
        device.to_str().unwrap(),
        "morph",
        "38",
        "--log",
        csv.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let (child, out) = start(&args);
    let t0 = Instant::now();
    loop {
        let l = out
            .recv_timeout(Duration::from_secs(20))
            .expect("morphctl printed the bend phase");
        if l.starts_with("event: phase bend") {
            break;
        }
        assert!(t0.elapsed() < Duration::from_secs(20), "no bend phase");
    }
    eventually(&csv, |t| t.lines().count() >= 4);
    // SAFETY: kill(2) on our own child's pid.
    assert_eq!(unsafe { libc::kill(child.id() as libc::pid_t, sig) }, 0);
    let (status, err) = finish(child, Duration::from_secs(20));
    (status, err, dir)
}

#[test]
fn sigint_during_a_morph_sends_abort_and_the_device_reports_the_heaters_off() {
    let (status, err, dir) = interrupt_a_morph("sigint", libc::SIGINT, &[]);
    assert_eq!(status.code(), Some(130), "{err}");
    assert!(err.contains("interrupted by SIGINT"), "{err}");
    assert!(err.contains("sent ABORT"), "{err}");

    // What the device received: ABORT, then STATUS.
    let to = eventually(&dir.join("to_device.log"), |t| t.contains("ABORT\nSTATUS"));
    let sent: Vec<&str> = to.lines().collect();
    let abort = sent.iter().position(|l| *l == "ABORT").expect("ABORT sent");
    assert!(sent[abort + 1..].contains(&"STATUS"), "{to}");
    // What the device answered: heaters on before, off in the last STATUS.
    assert_heated_then_off(&dir, "p_pla_w", "morph");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn an_interrupted_run_keeps_its_csv_rows_and_plots_them() {
    let dir0 = scratch("sigterm-plot");
    let svg = dir0.join("run.svg");
    let (status, err, dir) =
        interrupt_a_morph("sigterm", libc::SIGTERM, &["--plot", svg.to_str().unwrap()]);
    assert_eq!(status.code(), Some(128 + libc::SIGTERM), "{err}");
    assert!(err.contains("interrupted by SIGTERM"), "{err}");
    let csv = std::fs::read_to_string(dir.join("run.csv")).unwrap();
    let mut rows = csv.lines();
    assert!(rows.next().unwrap().starts_with("t_s,phase,"));
    let rows: Vec<&str> = rows.collect();
    assert!(rows.len() >= 3, "{csv}");
    assert!(
        rows.iter()
            .any(|r| r.contains(",soften,") && r.contains(",5.000,")),
        "{csv}"
    );
    // Every row has the header's columns (time ... radius, target radius, targets, mode,
    // then the current sense and the cut-off).
    assert!(rows.iter().all(|r| r.split(',').count() == 19), "{csv}");
    let auto = morphlink::strategy::AUTO_STRATEGY.as_str();
    assert!(
        rows.iter().all(|r| r.split(',').nth(12) == Some(auto)),
        "auto ran {auto}: {csv}"
    );
    // morph-sim senses current: every value is there, and the supply stays on until the end.
    assert!(
        rows.iter()
            .all(|r| r.ends_with(",closed") && !r.split(',').skip(13).any(|v| v == "NaN")),
        "{csv}"
    );
    assert!(std::fs::read_to_string(&svg).unwrap().contains("<svg"));
    std::fs::remove_dir_all(&dir).unwrap();
    std::fs::remove_dir_all(&dir0).unwrap();
}

#[test]
fn a_device_that_goes_silent_mid_morph_gets_bounded_aborts_and_is_reported_lost() {
    let dir = scratch("silent");
    let log = dir.join("received.log");
    // Answers VERSION and MORPH, then nothing: a board that hung or lost its USB.
    let device = script(
        &dir,
        "device.sh",
        &format!(
            r#"silent=
while IFS= read -r line; do
  echo "$line" >> '{}'
  if [ -n "$silent" ]; then continue; fi
  case "$line" in
    VERSION) echo "ok version=0.1.0 protocol=1" ;;
    MORPH*) echo ok; echo "event: phase soften t=0.0"; silent=1 ;;
    *) echo "error: unknown-command" ;;
  esac
done"#,
            log.display()
        ),
    );
    let t0 = Instant::now();
    let (child, _out) = start(&[
        "--sim",
        "--sim-program",
        device.to_str().unwrap(),
        "morph",
        "38",
    ]);
    let (status, err) = finish(child, Duration::from_secs(30));
    assert_eq!(status.code(), Some(1), "{err}");
    assert!(err.contains("did not answer"), "{err}");
    assert!(err.contains("could not confirm the heaters off"), "{err}");
    assert!(err.contains("is lost"), "{err}");
    let received = eventually(&log, |t| t.matches("ABORT").count() >= 3);
    assert_eq!(
        received.lines().filter(|l| *l == "ABORT").count(),
        3,
        "{received}"
    );
    // One lost reply plus three ABORTs of 2 s each, not a hang.
    assert!(t0.elapsed() < Duration::from_secs(15), "{:?}", t0.elapsed());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Runs `morphctl status` against a device whose STATUS reply follows a `long_bytes`-byte
/// line; returns the exit status, stdout, stderr and morphctl's peak resident memory, KiB.
fn status_after_a_long_line(dir: &Path, long_bytes: usize) -> (i32, String, String, i64) {
    let device = script(
        dir,
        &format!("device-{long_bytes}.sh"),
        &format!(
            r#"while IFS= read -r line; do
  case "$line" in
    VERSION) echo "ok version=0.1.0 protocol=1" ;;
    STATUS) head -c {long_bytes} /dev/zero | tr '\0' x; echo
            echo "ok phase=idle target_mm=- t_pla_c=22.00 t_tca_c=22.00 t_amb_c=22.00 p_pla_w=0.000 p_tca_w=0.000 supply_v=12.00 fault=none" ;;
    *) echo "error: unknown-command" ;;
  esac
done"#
        ),
    );
    // Reaped by wait4(2) below, which also reports its peak memory.
    #[allow(clippy::zombie_processes)]
    let child = Command::new(MORPHCTL)
        .args(["--sim", "--sim-program", device.to_str().unwrap(), "status"])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let pid = child.id() as libc::pid_t;
    let (mut out, mut err) = (child.stdout.unwrap(), child.stderr.unwrap());
    let out_t = std::thread::spawn(move || {
        let mut s = String::new();
        std::io::Read::read_to_string(&mut out, &mut s).unwrap();
        s
    });
    let mut err_s = String::new();
    std::io::Read::read_to_string(&mut err, &mut err_s).unwrap();
    let mut wstatus = 0;
    // SAFETY: wait4(2) on our own child, with valid out-pointers.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    assert_eq!(
        unsafe { libc::wait4(pid, &mut wstatus, 0, &mut usage) },
        pid
    );
    assert!(libc::WIFEXITED(wstatus));
    let code = libc::WEXITSTATUS(wstatus);
    (code, out_t.join().unwrap(), err_s, usage.ru_maxrss)
}

#[test]
fn an_over_long_line_from_the_device_is_skipped_reported_and_not_buffered() {
    let dir = scratch("long-line");
    // An empty line (ignored) in its place: the baseline.
    let (code, out, err, base_kib) = status_after_a_long_line(&dir, 0);
    assert_eq!(code, 0, "{err}");
    assert!(err.is_empty(), "{err}");
    let long = 8_000_000;
    let (code, out_long, err, long_kib) = status_after_a_long_line(&dir, long);
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains(&format!("skipped a {long}-byte line")),
        "{err}"
    );
    assert_eq!(
        out_long, out,
        "the STATUS after the long line is read as usual"
    );
    assert!(out.contains("p_pla_w=0.000"), "{out}");
    // Buffering the line would cost at least its 8 MB (more with the string copies).
    assert!(
        long_kib < base_kib + 3_000,
        "peak memory {long_kib} KiB with an 8 MB line, {base_kib} KiB without"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn sigint_during_a_tune_sends_abort_and_the_device_reports_the_heaters_off() {
    let dir = scratch("sigint-tune");
    let device = recording_sim(&dir);
    let args = [
        "--sim",
        "--sim-speed",
        "4",
        "--sim-program",
        device.to_str().unwrap(),
        "tune",
    ];
    let (child, out) = start(&args);
    let t0 = Instant::now();
    loop {
        let l = out
            .recv_timeout(Duration::from_secs(30))
            .expect("morphctl printed the tca step");
        if l.starts_with("event: tune step tca") {
            break;
        }
        assert!(t0.elapsed() < Duration::from_secs(30), "no tca step");
    }
    // Into the heated step.
    std::thread::sleep(Duration::from_millis(1500));
    // SAFETY: kill(2) on our own child's pid.
    assert_eq!(
        unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGINT) },
        0
    );
    let (status, err) = finish(child, Duration::from_secs(20));
    assert_eq!(status.code(), Some(130), "{err}");
    assert!(err.contains("sent ABORT"), "{err}");
    let to = eventually(&dir.join("to_device.log"), |t| t.contains("ABORT\nSTATUS"));
    assert!(to.contains("TUNE\n"), "{to}");
    assert_heated_then_off(&dir, "p_tca_w", "tune");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A gait interrupted while its links heat: one ABORT stops every link, and every link's
/// STATUS (`@* STATUS`) shows it before morphctl exits.
#[test]
fn sigint_during_a_gait_stops_every_link_and_checks_each() {
    let dir = scratch("gait-sigint");
    let device = recording_sim(&dir);
    let (child, out) = start(&[
        "--sim",
        "--sim-links",
        "2",
        "--sim-speed",
        "4",
        "--sim-program",
        device.to_str().unwrap(),
        "gait",
        "34",
        "42",
    ]);
    let t0 = Instant::now();
    let mut bending = [false; 2];
    while !bending.iter().all(|b| *b) {
        let l = out
            .recv_timeout(Duration::from_secs(30))
            .expect("morphctl printed both links' bend phase");
        for (k, b) in bending.iter_mut().enumerate() {
            *b |= l.starts_with(&format!("@{} event: phase bend", k + 1));
        }
        assert!(t0.elapsed() < Duration::from_secs(30), "no bend phases");
    }
    // SAFETY: kill(2) on our own child's pid.
    assert_eq!(
        unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGINT) },
        0
    );
    let (status, err) = finish(child, Duration::from_secs(20));
    assert_eq!(status.code(), Some(130), "{err}");
    assert!(err.contains("sent ABORT"), "{err}");
    let from = eventually(&dir.join("from_device.log"), |t| {
        t.contains("\nok links=2\n")
    });
    // The last `@* STATUS` answered after the ABORT: both links off.
    let last: Vec<&str> = from
        .lines()
        .rev()
        .skip_while(|l| *l != "ok links=2")
        .skip(1)
        .take(2)
        .collect();
    assert_eq!(last.len(), 2, "{from}");
    for l in last {
        let status = l
            .strip_prefix("data: @")
            .and_then(|r| r.split_once(' '))
            .map(|(_, s)| s)
            .unwrap_or("");
        assert!(heaters_off(status), "{l}\n{from}");
    }
    let to = std::fs::read_to_string(dir.join("to_device.log")).unwrap();
    let sent: Vec<&str> = to.lines().collect();
    let abort = sent
        .iter()
        .rposition(|l| *l == "ABORT")
        .expect("ABORT sent");
    assert!(sent[abort..].contains(&"@* STATUS"), "{to}");
}
