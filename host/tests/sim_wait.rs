//! `SIM WAIT` in `morph-sim`: simulated time that passes at once, at any `--speed`.

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
