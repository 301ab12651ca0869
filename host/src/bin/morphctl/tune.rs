//! `morphctl tune` (TUNE, followed to its end) and `morphctl calibrate` (guided: morphs to a few
//! radii, asks for each measured radius, sends MEASURED). A signal, a lost reply or an error
//! while TUNE heats ends in ABORT and a heaters-off STATUS, as for MORPH ([`super::finish`]).

use super::{finish, morph, MorphEnd, MorphOpts};
use crate::link::{field, Link, LinkError, REPLY_TIMEOUT_S};
use morphlink::protocol::client::{classify, link_of, LineKind};
use std::io::BufRead;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// Where in the reachable range `calibrate` morphs by default (fractions from the tightest):
/// spread so MEASURED fits the map's slope, inside the ends (the calibration benchmark's).
pub const CALIBRATE_FRACTIONS: [f64; 3] = [0.15, 0.5, 0.85];
/// How much longer than the tune's announced length morphctl waits for its end before it
/// calls the link lost and sends ABORT: a factor.
pub const TUNE_WAIT_FACTOR: f64 = 1.5;
/// The line that stores the calibration with the settings (`SAVE`), sent after the last
/// MEASURED that counted; a device without settings storage answers `error: unsupported`.
pub const SAVE_LINE: Option<&str> = Some("SAVE");

/// Where a tune's or a calibration's result can be kept.
#[derive(Clone, Debug, PartialEq)]
pub enum Keep {
    /// A board or the emulated image: `SAVE` stores it in the device's flash.
    Device,
    /// morph-sim with `--sim-flash-file`: `SAVE` writes that file.
    SimFlash(PathBuf),
    /// morph-sim without a flash file: the result lives in the simulator and ends with it.
    DiesWithSim,
}

impl Keep {
    /// Where `target` keeps a result.
    pub fn of(target: &crate::link::Target) -> Keep {
        use crate::link::Target;
        match target {
            Target::Sim {
                flash_file: Some(f),
                ..
            } => Keep::SimFlash(f.clone()),
            Target::Sim { .. } => Keep::DiesWithSim,
            _ => Keep::Device,
        }
    }
}

/// What is said of a result that is not stored because the simulator has no flash file.
pub const DIES_WITH_SIM: &str = "not saved: this morph-sim has no flash file, so the result is     held by the simulator only and ends with it when morphctl exits (--sim-flash-file FILE keeps     it, as SAVE does on a board)";

/// Runs TUNE and follows its events to `event: tune done` (exit 0), `event: tune failed` or an
/// alarm (exit 1, heaters already off); anything else ends in ABORT. A finished tune is saved to
/// a simulator's flash file; otherwise morphctl says where the fit is (not) kept.
pub fn tune(link: &mut Link, speed: f64, keep: &Keep) -> ExitCode {
    if *keep == Keep::DiesWithSim {
        println!("tune: {DIES_WITH_SIM}");
    }
    let end = run_tune(link, speed);
    let done = matches!(&end, MorphEnd::Finished(c) if *c == ExitCode::SUCCESS);
    let code = finish(link, end);
    if !done {
        return code;
    }
    match keep {
        Keep::Device => {
            println!("tune: the fit is in use, not saved: `morphctl config save` stores it");
            code
        }
        Keep::DiesWithSim => {
            println!("tune: the fit is in use, {DIES_WITH_SIM}");
            code
        }
        Keep::SimFlash(f) => match save(link) {
            Ok(reply) => {
                println!(
                    "tune: saved to the simulator's flash file {} ({reply})",
                    f.display()
                );
                code
            }
            Err(e) => {
                eprintln!("morphctl: tune: the fit is in use but not saved: {e}");
                ExitCode::FAILURE
            }
        },
    }
}

/// Sends SAVE: Ok(the reply) if it was stored, Err(why) if not.
fn save(link: &mut Link) -> Result<String, String> {
    let (_, reply) = link
        .command("SAVE", super::config::SAVE_TIMEOUT_S, &mut |l| {
            println!("{l}")
        })
        .map_err(String::from)?;
    if classify(&reply) == LineKind::Ok {
        Ok(reply)
    } else {
        Err(format!("SAVE answered `{reply}`"))
    }
}

fn run_tune(link: &mut Link, speed: f64) -> MorphEnd {
    let mut events: Vec<String> = Vec::new();
    if let Err(e) = super::wait_for_sensors(link, &mut |l| events.push(l.to_string())) {
        return e;
    }
    let reply = match link.command("TUNE", REPLY_TIMEOUT_S, &mut |l| events.push(l.to_string())) {
        Ok((_, r)) => r,
        Err(LinkError::Closed(e)) => return MorphEnd::Failed(e),
        Err(e) => return MorphEnd::Broken(e),
    };
    if classify(&reply) != LineKind::Ok {
        return MorphEnd::Failed(format!("TUNE refused: {reply}"));
    }
    let total_s: f64 = field(&reply, "total_s")
        .and_then(|v| v.parse().ok())
        .unwrap_or(180.0);
    println!("TUNE: about {total_s} s of link time; Ctrl-C stops it with the heaters off");
    let limit = Duration::from_secs_f64(total_s * TUNE_WAIT_FACTOR / speed.max(1e-3) + 10.0);
    let start = Instant::now();
    loop {
        for e in events.drain(..) {
            println!("{e}");
            // A board of several links addresses its events (`@1 event: tune done ...`).
            let text = link_of(&e).1;
            if text.starts_with("event: tune done") {
                return MorphEnd::Finished(ExitCode::SUCCESS);
            }
            if text.starts_with("event: tune failed") || classify(&e) == LineKind::Alarm {
                return MorphEnd::Finished(ExitCode::FAILURE);
            }
        }
        if start.elapsed() > limit {
            return MorphEnd::Broken(LinkError::Timeout(format!(
                "no end of TUNE within {} s",
                limit.as_secs()
            )));
        }
        match link.recv(Duration::from_millis(500)) {
            Ok(Some(l)) => events.push(l),
            Ok(None) => {
                // Still there? A STATUS a second keeps a lost link from going unnoticed.
                if let Err(e) = link.command("STATUS", REPLY_TIMEOUT_S, &mut |l| {
                    events.push(l.to_string())
                }) {
                    return MorphEnd::Broken(e);
                }
            }
            Err(e) => return MorphEnd::Broken(e),
        }
    }
}

/// Throws away what was typed on the terminal before the prompt (keys pressed during a morph
/// would otherwise answer it); nothing when stdin is not a terminal (piped answers are meant).
fn discard_typed_ahead() {
    use std::io::IsTerminal;
    if std::io::stdin().is_terminal() {
        // SAFETY: tcflush on fd 0 only discards the terminal's pending input.
        unsafe {
            libc::tcflush(libc::STDIN_FILENO, libc::TCIFLUSH);
        }
    }
}

/// Reads one line from stdin in a thread, so a signal still ends the wait.
fn ask(link: &Link, prompt: &str) -> Result<Option<String>, String> {
    discard_typed_ahead();
    println!("{prompt}");
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let mut s = String::new();
        let r = std::io::stdin().lock().read_line(&mut s).map(|n| (n, s));
        let _ = tx.send(r);
    });
    loop {
        if let Some(sig) = link.signal() {
            return Err(format!("interrupted by {}", crate::link::signal_name(sig)));
        }
        match rx.recv_timeout(Duration::from_millis(100)) {
            Ok(Ok((0, _))) => return Ok(None),
            Ok(Ok((_, s))) => return Ok(Some(s.trim().to_string())),
            Ok(Err(e)) => return Err(format!("cannot read stdin: {e}")),
            Err(mpsc::RecvTimeoutError::Timeout) => {}
            Err(mpsc::RecvTimeoutError::Disconnected) => return Ok(None),
        }
    }
}

/// `calibrate`: for each radius (default [`CALIBRATE_FRACTIONS`] of RANGE), MORPH in `mode`,
/// then the measured radius (from `measured`, else asked on stdin; empty skips) as MEASURED.
pub fn calibrate(
    link: &mut Link,
    radii: &[f32],
    measured: &[f32],
    mode: &str,
    poll: Duration,
    keep: &Keep,
) -> Result<ExitCode, String> {
    let radii: Vec<f32> = if radii.is_empty() {
        let (_, range) = link
            .command("RANGE", REPLY_TIMEOUT_S, &mut |l| println!("{l}"))
            .map_err(String::from)?;
        let num = |k: &str| field(&range, k).and_then(|v| v.parse::<f64>().ok());
        let (min, max) = num("min_mm")
            .zip(num("max_mm"))
            .ok_or(format!("RANGE answered `{range}`"))?;
        CALIBRATE_FRACTIONS
            .iter()
            .map(|f| ((min + (max - min) * f) * 10.0).round() as f32 / 10.0)
            .collect()
    } else {
        radii.to_vec()
    };
    // Every given number is checked before the first morph: a bad one found later would leave
    // the calibration changed by the morphs before it.
    if let Some(r) = radii.iter().find(|r| !(r.is_finite() && **r > 0.0)) {
        return Err(format!("--radii {r}: a radius is a number of mm over 0"));
    }
    if let Some(m) = measured.iter().find(|m| !(m.is_finite() && **m > 0.0)) {
        return Err(format!(
            "--measured {m}: a measured radius is a number of mm over 0"
        ));
    }
    if measured.len() > radii.len() {
        return Err(format!(
            "{} --measured values for {} morphs: one per morph at most",
            measured.len(),
            radii.len()
        ));
    }
    let mut counted = 0;
    for (i, &r) in radii.iter().enumerate() {
        println!("calibrate: morph {} of {} to {r} mm", i + 1, radii.len());
        let opts = MorphOpts {
            radius_mm: r,
            mode: mode.to_string(),
            poll,
            timeout_s: super::DEFAULT_MORPH_TIMEOUT_S,
        };
        let end = morph(link, &opts, &mut Vec::new(), &mut None);
        let finished_ok = matches!(&end, MorphEnd::Finished(c) if *c == ExitCode::SUCCESS);
        let code = finish(link, end);
        if !finished_ok {
            return Ok(code);
        }
        // An answer typed in that is not a radius, or that the device refuses, is asked
        // again (empty skips); one given with --measured is sent once.
        let typed = measured.get(i).is_none();
        let mut prompt = format!("measured radius of this morph, mm (target {r}; empty to skip):");
        loop {
            let value = match measured.get(i) {
                Some(v) => Some(v.to_string()),
                None => ask(link, &prompt)?,
            };
            let Some(value) = value.filter(|v| !v.is_empty()) else {
                println!("calibrate: skipped");
                break;
            };
            if typed && !value.parse::<f32>().is_ok_and(|v| v.is_finite() && v > 0.0) {
                prompt = format!(
                    "`{value}` is not a radius in mm (a number with a point, e.g. {r:.1}); measured radius, mm (empty to skip):"
                );
                continue;
            }
            let (_, reply) = link
                .command(&format!("MEASURED {value}"), REPLY_TIMEOUT_S, &mut |l| {
                    println!("{l}")
                })
                .map_err(String::from)?;
            println!("{reply}");
            if classify(&reply) == LineKind::Ok {
                counted += 1;
                break;
            }
            if !typed {
                break;
            }
            prompt =
                format!("refused; measured radius of this morph, mm (target {r}; empty to skip):");
        }
    }
    println!("calibrate: {counted} measured morph(s) counted");
    if counted == 0 {
        return Ok(ExitCode::FAILURE);
    }
    match (SAVE_LINE, keep) {
        (None, _) => Ok(ExitCode::SUCCESS),
        (Some(_), Keep::DiesWithSim) => {
            println!("calibrate: in use, {DIES_WITH_SIM}");
            Ok(ExitCode::SUCCESS)
        }
        (Some(_), _) => match save(link) {
            Ok(reply) => {
                println!("{reply}");
                println!("calibrate: stored with the settings");
                Ok(ExitCode::SUCCESS)
            }
            Err(e) => {
                eprintln!("morphctl: calibrate: the calibration is in use but not stored: {e}");
                Ok(ExitCode::FAILURE)
            }
        },
    }
}
