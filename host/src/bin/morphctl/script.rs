//! `morphctl run FILE`: a script of protocol lines and waits played on one link (one
//! simulator for the whole script with `--sim`), every line sent and received logged with its
//! time.
//!
//! A script has one step a line: a protocol line to send (`MORPH 38`, `SIM FAULT heater-open tca`),
//! `wait done [<s>]`, `wait alarm [<s>]`, `sleep <s>`; `#` starts a comment, blank lines are
//! skipped. The whole script is checked before anything is sent (every line a script word or a
//! line the core's protocol parser accepts), so a typo changes nothing.
//!
//! Two clocks: `sleep` and `wait` count link time (the simulator's, sped up by `--sim-speed`);
//! the log's bracketed times (`[wall 12.345 s]`) are wall-clock seconds since the script began.

use crate::link::{Link, LinkError, REPLY_TIMEOUT_S};
use morphlink::protocol::client::{classify, link_of, LineKind};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;
use std::time::{Duration, Instant};

/// How long `wait done`/`wait alarm` waits without a number, s of link time: above the sum of
/// the firmware's phase timeouts (60 + 120 + 600 + 10 s), like `morph --timeout-s`.
pub const DEFAULT_WAIT_S: f64 = 900.0;
/// Longest `sleep` or `wait` a script may ask for, s of link time (an hour: a typo like
/// `sleep 50000` is refused, not waited out).
pub const MAX_WAIT_S: f64 = 3600.0;

/// One step of a script.
#[derive(Clone, Debug, PartialEq)]
pub enum Step {
    /// Send this protocol line and wait for its final reply; an `error:` reply fails the script.
    Send(String),
    /// Wait for `event: done` or `event: tune done` (an alarm or `event: tune failed` first
    /// fails the script), at most this long, s.
    WaitDone(f64),
    /// Wait for an `alarm:` (a `done` first fails the script), at most this long, s.
    WaitAlarm(f64),
    /// Let this much link time pass, s, logging whatever arrives.
    Sleep(f64),
}

/// A script step with its line number (1-based) in the file.
#[derive(Clone, Debug, PartialEq)]
pub struct Line {
    /// Line number in the file.
    pub number: usize,
    /// The step.
    pub step: Step,
}

/// Parses a seconds argument in [0, [`MAX_WAIT_S`]].
fn seconds(word: &str, what: &str) -> Result<f64, String> {
    match word.parse::<f64>() {
        Ok(s) if (0.0..=MAX_WAIT_S).contains(&s) => Ok(s),
        _ => Err(format!(
            "`{what}` takes seconds in 0..{MAX_WAIT_S}, not `{word}`"
        )),
    }
}

/// Parses a whole script; the error names the file's line.
pub fn parse(text: &str) -> Result<Vec<Line>, String> {
    let mut out = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let number = i + 1;
        let line = raw.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let words: Vec<&str> = line.split_whitespace().collect();
        let err = |e: String| format!("line {number}: {e}");
        let step = match words[0].to_ascii_lowercase().as_str() {
            "wait" => {
                let limit = match words.get(2) {
                    Some(w) => seconds(w, "wait").map_err(err)?,
                    None => DEFAULT_WAIT_S,
                };
                if words.len() > 3 {
                    return Err(err("`wait done|alarm [<s>]` takes at most two words".into()));
                }
                match words.get(1).map(|w| w.to_ascii_lowercase()).as_deref() {
                    Some("done") => Step::WaitDone(limit),
                    Some("alarm") => Step::WaitAlarm(limit),
                    _ => return Err(err("`wait` needs `done` or `alarm`".into())),
                }
            }
            "sleep" => match words.as_slice() {
                [_, s] => Step::Sleep(seconds(s, "sleep").map_err(err)?),
                _ => return Err(err("`sleep` takes one number of seconds".into())),
            },
            _ => {
                let line = words.join(" ");
                // The core's own parser: a line the device would refuse as unknown or
                // malformed (`slep 3`, `MORPH`) is refused here, before anything is sent.
                if let Err(e) = morphlink::protocol::links::check_line(&line) {
                    // The sentence as the device would send it, after `error: <code> `.
                    let wire = morphlink::protocol::format_error(&e);
                    let sentence = wire.splitn(3, ' ').nth(2).unwrap_or(e.text);
                    return Err(err(format!(
                        "`{line}` is neither a script step (`wait done|alarm [<s>]`, `sleep <s>`) nor a protocol line the device accepts: {}",
                        sentence.trim_end_matches('.')
                    )));
                }
                Step::Send(line)
            }
        };
        out.push(Line { number, step });
    }
    if out.is_empty() {
        return Err("the script has no steps".into());
    }
    Ok(out)
}

/// Reads and parses a script file.
pub fn read(path: &Path) -> Result<Vec<Line>, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    parse(&text).map_err(|e| format!("{}: {e}", path.display()))
}

/// The session log: every line sent (`>`) and received (`<`) and each step's note (`#`),
/// with the seconds since the script began, to stdout and optionally a file.
pub struct Log {
    start: Instant,
    file: Option<BufWriter<File>>,
}

impl Log {
    /// A log to stdout, and to `path` if given.
    pub fn new(path: Option<&Path>) -> Result<Log, String> {
        let file = match path {
            Some(p) => Some(BufWriter::new(
                File::create(p).map_err(|e| format!("cannot write {}: {e}", p.display()))?,
            )),
            None => None,
        };
        Ok(Log {
            start: Instant::now(),
            file,
        })
    }

    /// Writes one entry: `[wall   12.345 s] <mark> <text>`, wall-clock seconds since the
    /// script began (not link time, which `sleep` and `wait` count).
    pub fn entry(&mut self, mark: char, text: &str) {
        let line = format!(
            "[wall {:>9.3} s] {mark} {text}",
            self.start.elapsed().as_secs_f64()
        );
        println!("{line}");
        if let Some(f) = &mut self.file {
            // A log that cannot be written does not stop the heaters' session.
            let _ = writeln!(f, "{line}").and_then(|_| f.flush());
        }
    }

    /// A line sent.
    pub fn sent(&mut self, l: &str) {
        self.entry('>', l);
    }

    /// A line received.
    pub fn got(&mut self, l: &str) {
        self.entry('<', l);
    }

    /// A note of morphctl's own.
    pub fn note(&mut self, l: &str) {
        self.entry('#', l);
    }
}

/// Why a script stopped before its end.
#[derive(Debug)]
pub enum Stop {
    /// The script's own failure (an `error:` reply, a wait that saw the other outcome or ran
    /// out): its line and why.
    Failed(String),
    /// The link failed (a signal, a lost reply, a closed link).
    Link(LinkError),
}

impl From<LinkError> for Stop {
    fn from(e: LinkError) -> Stop {
        Stop::Link(e)
    }
}

/// How a morph or a tune ended, as a script's `wait` sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
enum End {
    /// `event: done` or `event: tune done`.
    Done,
    /// An `alarm:` line.
    Alarm,
    /// `event: tune failed`.
    TuneFailed,
}

/// The end a line announces, if any.
fn end_of(l: &str) -> Option<End> {
    match classify(l) {
        LineKind::Done => Some(End::Done),
        LineKind::Alarm => Some(End::Alarm),
        // A board of several links addresses its events (`@1 event: tune done ...`).
        LineKind::Event if link_of(l).1.starts_with("event: tune done") => Some(End::Done),
        LineKind::Event if link_of(l).1.starts_with("event: tune failed") => Some(End::TuneFailed),
        _ => None,
    }
}

/// Plays `steps` on `link`; link seconds pass `speed` times faster than host seconds.
pub fn play(link: &mut Link, steps: &[Line], speed: f64, log: &mut Log) -> Result<(), Stop> {
    // Lines that arrived but not yet logged: events during a command.
    let mut pending: Vec<String> = Vec::new();
    // The last `done` or alarm seen outside a wait and not yet waited for (a morph may end
    // during a `sleep`); a new MORPH forgets it.
    let mut unclaimed: Option<String> = None;
    let outcome = |l: &str| end_of(l).is_some();
    for Line { number, step } in steps {
        let fail = |why: String| Stop::Failed(format!("line {number}: {why}"));
        match step {
            Step::Send(line) => {
                let verb = line.split(' ').next().unwrap_or("").to_ascii_uppercase();
                if verb == "MORPH" || verb == "TUNE" {
                    unclaimed = None;
                }
                log.sent(line);
                let (data, fin) =
                    link.command(line, REPLY_TIMEOUT_S, &mut |l| pending.push(l.to_string()))?;
                for e in pending.drain(..) {
                    log.got(&e);
                    if outcome(&e) {
                        unclaimed = Some(e);
                    }
                }
                for d in data {
                    log.got(&format!("{} {d}", morphlink::protocol::DATA_TAG));
                }
                log.got(&fin);
                if classify(&fin) == LineKind::Error {
                    return Err(fail(format!("`{line}` was refused: {fin}")));
                }
            }
            Step::Sleep(s) => {
                log.note(&format!("sleep {s} s of link time"));
                let until = Instant::now() + Duration::from_secs_f64(s / speed);
                while let Some(left) = until.checked_duration_since(Instant::now()) {
                    if let Some(l) = link.recv(left)? {
                        log.got(&l);
                        if outcome(&l) {
                            unclaimed = Some(l);
                        }
                    }
                }
            }
            Step::WaitDone(limit) | Step::WaitAlarm(limit) => {
                let want = if matches!(step, Step::WaitDone(_)) {
                    End::Done
                } else {
                    End::Alarm
                };
                let name = if want == End::Done { "done" } else { "alarm" };
                log.note(&format!("wait {name} (at most {limit} s of link time)"));
                let until = Instant::now() + Duration::from_secs_f64(limit / speed);
                let got = loop {
                    if let Some(l) = unclaimed.take() {
                        break (end_of(&l), l);
                    }
                    let Some(left) = until.checked_duration_since(Instant::now()) else {
                        return Err(fail(format!("no {name} within {limit} s")));
                    };
                    let Some(l) = link.recv(left)? else { continue };
                    log.got(&l);
                    if outcome(&l) {
                        break (end_of(&l), l);
                    }
                };
                if got.0 != Some(want) {
                    return Err(fail(format!("waited for {name}, got `{}`", got.1)));
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::link::{link_from_text, link_held_open};

    #[test]
    fn scripts_parse_steps_comments_and_waits_and_name_the_bad_line() {
        let s = parse(
            "# a fault, then a morph\n\nSIM FAULT heater-open tca   # inject\nMORPH 38\nwait alarm 60\n\
             RESET\nsleep 5\nwait DONE\n",
        )
        .unwrap();
        let steps: Vec<(usize, Step)> = s.into_iter().map(|l| (l.number, l.step)).collect();
        assert_eq!(
            steps,
            [
                (3, Step::Send("SIM FAULT heater-open tca".into())),
                (4, Step::Send("MORPH 38".into())),
                (5, Step::WaitAlarm(60.0)),
                (6, Step::Send("RESET".into())),
                (7, Step::Sleep(5.0)),
                (8, Step::WaitDone(DEFAULT_WAIT_S)),
            ]
        );
        for (bad, want) in [
            ("MORPH 38\nsleep\n", "line 2: `sleep` takes one number"),
            ("sleep -1", "line 1: `sleep` takes seconds in 0..3600"),
            ("sleep 1e9", "line 1: `sleep` takes seconds"),
            ("sleep nan", "line 1: `sleep` takes seconds"),
            ("wait\n", "line 1: `wait` needs `done` or `alarm`"),
            ("wait idle", "line 1: `wait` needs"),
            ("wait done 5 6", "at most two words"),
            ("# nothing\n", "no steps"),
            (
                "MORPH 38\nslep 3\n",
                "line 2: `slep 3` is neither a script step",
            ),
            ("MORPH\n", "line 1: `MORPH` is neither"),
            // A command of no arguments given some: the device's whole sentence.
            ("STATUS now\n", "accepts: STATUS takes no arguments"),
            (
                "SIM FAULT nonsense tca\n",
                "line 1: `SIM FAULT nonsense tca`",
            ),
        ] {
            let e = parse(bad).unwrap_err();
            assert!(e.contains(want), "{bad:?}: {e}");
        }
    }

    #[test]
    fn play_sends_waits_and_stops_at_a_refusal_or_the_other_outcome() {
        let steps = parse("MORPH 38\nwait done 10\nSTATUS").unwrap();
        let mut l = link_from_text(
            "ok\nevent: phase soften t=0.0\nevent: done t=20.0 radius_mm=38.00\nok phase=idle\n",
        );
        let mut log = Log::new(None).unwrap();
        play(&mut l, &steps, 1.0, &mut log).unwrap();
        // A morph that ends during a sleep is still waited for.
        let slept = parse("MORPH 38\nsleep 0.5\nwait done 0").unwrap();
        let mut l = link_held_open("ok\nevent: done t=20.0 radius_mm=38.00\n");
        play(&mut l, &slept, 1.0, &mut log).unwrap();
        // A wait that runs out fails the script.
        let mut l = link_held_open("ok\n");
        let short = parse("MORPH 38\nwait done 0.2").unwrap();
        match play(&mut l, &short, 1.0, &mut log) {
            Err(Stop::Failed(why)) => assert_eq!(why, "line 2: no done within 0.2 s"),
            other => panic!("{other:?}"),
        }

        let mut l = link_from_text("error: out-of-range reachable=37..47 mm\n");
        match play(&mut l, &steps, 1.0, &mut log) {
            Err(Stop::Failed(why)) => {
                assert!(why.starts_with("line 1: `MORPH 38` was refused"), "{why}")
            }
            other => panic!("{other:?}"),
        }
        let mut l = link_from_text("ok\nalarm: over-temperature pla ...\n");
        match play(&mut l, &steps, 1.0, &mut log) {
            Err(Stop::Failed(why)) => {
                assert!(why.contains("waited for done, got `alarm:"), "{why}")
            }
            other => panic!("{other:?}"),
        }
        // `wait done` also ends at a tune's end; a failed tune fails it.
        let tune = parse("TUNE\nwait done 300\nSAVE").unwrap();
        let mut l = link_from_text(
            "ok total_s=170\nevent: tune step\nevent: tune done tau_s=1\nok saved bytes=90\n",
        );
        play(&mut l, &tune, 1.0, &mut log).unwrap();
        let mut l = link_held_open("ok total_s=170\nevent: tune failed no-rise\n");
        match play(&mut l, &tune, 1.0, &mut log) {
            Err(Stop::Failed(why)) => {
                assert!(
                    why.contains("waited for done, got `event: tune failed"),
                    "{why}"
                )
            }
            other => panic!("{other:?}"),
        }
        // The link closes mid-wait: a link failure, not the script's.
        let mut l = link_from_text("ok\n");
        assert!(matches!(
            play(&mut l, &steps, 1.0, &mut log),
            Err(Stop::Link(LinkError::Closed(_)))
        ));
    }
}
