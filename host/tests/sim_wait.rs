//! `SIM WAIT` in `morph-sim`: simulated time that passes at once, at any `--speed`; and the
//! order of what it answers.

mod common;

use common::{run_with_input, text};
use std::time::{Duration, Instant};

#[test]
fn sim_wait_skips_time_in_real_time_mode_too() {
    let start = Instant::now();
    let out = run_with_input(
        env!("CARGO_BIN_EXE_morph-sim"),
        ["--speed", "2"],
        b"MORPH 38\nSIM WAIT 20\nSIM STATE\nSIM WAIT -5\n",
    );
    let elapsed = start.elapsed();
    let text = text(&out.stdout);
    assert!(out.status.success(), "{text}");
    // The morph ends at about 23 s: 20 s pass at once, the last 3 s or so at half real time
    // (paced as if the wait took none: 12 s would mean the waited time was paced too).
    assert!(
        elapsed < Duration::from_secs(7),
        "took {elapsed:?}:\n{text}"
    );
    let lines: Vec<&str> = text.lines().collect();
    let state = lines
        .iter()
        .position(|l| l.starts_with("ok time_s="))
        .expect(&text);
    assert!(lines[state].starts_with("ok time_s=20."), "{text}");
    assert_eq!(lines[state - 1], "ok", "the wait's reply: {text}");
    assert!(
        lines[1..state - 1]
            .iter()
            .all(|l| l.starts_with("event: phase ")),
        "events come out during the wait, before its ok:\n{text}"
    );
    assert_eq!(
        lines[state + 1],
        "error: out-of-range wait must be 0..3600 s"
    );
    assert!(lines.last().unwrap().starts_with("event: done"), "{text}");
}

/// A speed outside `morphlink_host::speed::SPEED_RANGE` is refused with a clear error and exit
/// code 2 by morph-sim and morphctl alike; before, `--speed 1e-30` panicked in the pacing.
#[test]
fn a_speed_outside_its_range_is_refused_not_a_panic() {
    for speed in ["1e-30", "1e30", "0", "-1"] {
        let out = run_with_input(
            env!("CARGO_BIN_EXE_morph-sim"),
            ["--speed", speed],
            b"STATUS\n",
        );
        let err = text(&out.stderr);
        assert_eq!(
            out.status.code(),
            Some(2),
            "morph-sim --speed {speed}: {err}"
        );
        assert!(
            err.contains("--speed must be a factor of real time from 0.001"),
            "{err}"
        );
        assert!(!err.contains("panicked"), "{err}");
        let out = run_with_input(
            env!("CARGO_BIN_EXE_morphctl"),
            ["--sim", "--sim-speed", speed, "info"],
            b"",
        );
        let err = text(&out.stderr);
        assert!(!out.status.success(), "morphctl --sim-speed {speed}: {err}");
        assert!(
            err.contains("--sim-speed must be a factor of real time"),
            "{err}"
        );
        assert!(!err.contains("panicked"), "{err}");
    }
}

#[test]
fn an_event_never_comes_after_the_reply_to_a_later_command() {
    // All three lines arrive at once: MORPH's first phase event is queued before ABORT and
    // STATUS are read, so it must go out before their replies.
    let out = run_with_input(
        env!("CARGO_BIN_EXE_morph-sim"),
        ["--speed", "max"],
        b"MORPH 38\nABORT\nSTATUS\n",
    );
    let text = text(&out.stdout);
    assert!(out.status.success(), "{text}");
    let lines: Vec<&str> = text.lines().collect();
    let status = lines
        .iter()
        .position(|l| l.starts_with("ok phase="))
        .expect(&text);
    assert!(lines[status].starts_with("ok phase=idle"), "{text}");
    assert_eq!(
        lines.len(),
        status + 1,
        "nothing after the STATUS reply:\n{text}"
    );
    let soften = lines
        .iter()
        .position(|l| l.starts_with("event: phase soften"))
        .expect(&text);
    assert_eq!(lines[soften - 1], "ok", "after MORPH's reply: {text}");
    assert_eq!(lines[soften + 1], "ok", "before ABORT's reply: {text}");
}

#[test]
fn a_refused_line_answers_after_the_events_raised_before_it() {
    // A line not valid text and one too long, each right after a MORPH: the MORPH's first
    // event goes out before their errors, as it does before any later reply.
    for bad in [&b"\xff"[..], &[b'a'; 100][..]] {
        let mut input = b"MORPH 38\n".to_vec();
        input.extend_from_slice(bad);
        input.extend_from_slice(b"\nABORT\n");
        let out = run_with_input(env!("CARGO_BIN_EXE_morph-sim"), ["--speed", "max"], &input);
        let text = text(&out.stdout);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], "ok", "{text}");
        assert!(lines[1].starts_with("event: phase soften"), "{text}");
        assert!(lines[2].starts_with("error: "), "{text}");
    }
}
