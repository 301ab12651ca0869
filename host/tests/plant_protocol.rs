//! `morph-sim` driving a plant in another process over plant protocol 1: `morph-plant` end to
//! end (the same run as the in-process plant, bit for bit), and every way a plant can fail.

mod common;

use common::{run_with_input, text};
use std::process::Output;

const MORPH_SIM: &str = env!("CARGO_BIN_EXE_morph-sim");
const MORPH_PLANT: &str = env!("CARGO_BIN_EXE_morph-plant");

/// Runs `morph-sim --speed max <args>` with `input` on stdin.
/// (A plant that fails at once may end morph-sim before it reads its input: no error.)
fn morph_sim(args: &[&str], input: &str) -> Output {
    let args = ["--speed", "max"].iter().chain(args);
    run_with_input(MORPH_SIM, args, input.as_bytes())
}

/// The value of `key=` in a reply line.
fn field(line: &str, key: &str) -> f64 {
    line.split(' ')
        .find_map(|t| t.strip_prefix(key)?.strip_prefix('='))
        .unwrap_or_else(|| panic!("no {key}= in {line}"))
        .parse()
        .unwrap()
}

const SCRIPT: &str = "SIM STATE\nMORPH 38\nSIM WAIT 60\nSIM STATE\nSTATUS\nSIM SUPPLY 11\n";

#[test]
fn morph_plant_drives_the_controller_end_to_end() {
    let plant_cmd = format!("'{MORPH_PLANT}' --plant lumped");
    let remote = morph_sim(&["--plant-cmd", &plant_cmd], SCRIPT);
    let out = text(&remote.stdout);
    let err = text(&remote.stderr);
    assert!(remote.status.success(), "{out}\n{err}");
    let lines: Vec<&str> = out.lines().collect();
    let done = lines
        .iter()
        .find(|l| l.starts_with("event: done"))
        .unwrap_or_else(|| panic!("no done event:\n{out}"));
    assert!((field(done, "radius_mm") - 38.0).abs() < 0.1, "{done}");
    for phase in ["soften", "bend", "lock", "release"] {
        let event = format!("event: phase {phase} ");
        assert!(out.contains(&event), "no {phase}:\n{out}");
    }
    // SIM STATE: the plant's radius and bead temperatures, at the rig's time.
    let states: Vec<&&str> = lines.iter().filter(|l| l.contains("time_s=")).collect();
    assert_eq!(states.len(), 2, "{out}");
    // The rig ticks while it waits for its first input: a tick or two before SIM STATE.
    let t0 = field(states[0], "time_s");
    assert!((0.1..=1.0).contains(&t0), "{}", states[0]);
    assert!(
        field(states[0], "radius_mm") > 50.0,
        "at rest: {}",
        states[0]
    );
    let waited = field(states[1], "time_s") - t0;
    assert!((waited - 60.0).abs() < 0.01, "SIM WAIT 60 ran {waited} s");
    assert!(
        (field(states[1], "radius_mm") - 38.0).abs() < 0.3,
        "{}",
        states[1]
    );
    assert!(field(states[1], "t_pla_c") > 22.5, "{}", states[1]);
    assert!(
        lines
            .iter()
            .any(|l| l.starts_with("ok phase=idle target_mm=38.00")),
        "{out}"
    );
    assert_eq!(
        lines.last(),
        Some(&"ok supply_v=11.00"),
        "set forwarded: {out}"
    );
    assert!(err.contains("idle after"), "{err}");

    // The numbers cross the pipe exactly: everything but SIM STATE's temperatures (bead
    // temperatures remotely, the rod's mean in process) is the in-process run's, bit for bit,
    // given the same number of ticks before the first input (which the first SIM STATE's time
    // shows; the noise draws follow the ticks), so the in-process run is retried until it has.
    let first_state = |out: &str| out.lines().next().map(|l| field(l, "time_s"));
    let local_out = (0..20)
        .map(|_| {
            let local = morph_sim(&["--plant", "lumped"], SCRIPT);
            assert!(local.status.success());
            text(&local.stdout)
        })
        .find(|l| first_state(l) == Some(t0))
        .expect("an in-process run with as many ticks before its first input");
    let strip = |s: &str| -> Vec<String> {
        s.lines()
            .map(|l| match l.find(" t_pla_c=") {
                Some(i) if l.contains("time_s=") => l[..i].to_string(),
                _ => l.to_string(),
            })
            .collect()
    };
    assert_eq!(strip(&out), strip(&local_out));
}

#[test]
fn settings_a_plant_refuses_are_answered_unsupported() {
    // A shell plant: a fixed sample to everything, `error: unsupported` to every `set`.
    let plant = "while read verb rest; do case $verb in set) echo 'error: unsupported';; \
                 *) echo 'ok t_pla_c=22 t_tca_c=23 t_amb_c=21 supply_v=12 radius_mm=46';; \
                 esac; done";
    let run = morph_sim(
        &["--plant-cmd", plant],
        "SIM SUPPLY 5\nSIM AMBIENT 30\nSIM MEDIUM air\nSIM STATE\nSIM WAIT 1\n",
    );
    let out = text(&run.stdout);
    assert!(run.status.success(), "{out}\n{}", text(&run.stderr));
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(
        lines,
        [
            "error: unsupported SIM SUPPLY: the plant cannot change that",
            "error: unsupported SIM AMBIENT: the plant cannot change that",
            "error: unsupported SIM MEDIUM: the plant cannot change that",
            "SIM STATE",
            "ok",
        ]
        .map(|l| lines
            .get(3)
            .filter(|_| l == "SIM STATE")
            .copied()
            .unwrap_or(l))
    );
    assert!(lines[3].starts_with("ok time_s="), "{}", lines[3]);
    assert!(
        lines[3].ends_with(" radius_mm=46.00 t_pla_c=22.00 t_tca_c=23.00"),
        "the protocol's radius and bead temperatures: {}",
        lines[3]
    );
}

/// `morph-sim --plant-cmd <cmd>` fails: non-zero exit, a message naming the plant.
fn fails(cmd: &str, extra: &[&str], input: &str, what: &str) {
    let mut args = vec!["--plant-cmd", cmd];
    args.extend_from_slice(extra);
    let run = morph_sim(&args, input);
    let err = text(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{cmd}: {err}");
    let name = format!("morph-sim: plant `{cmd}` ");
    assert!(err.contains(&name), "{cmd}: {err}");
    assert!(err.contains(what), "{cmd}: want {what:?} in {err}");
    assert!(err.trim_end().ends_with("run ended, heaters off"), "{err}");
}

#[test]
fn a_plant_that_exits_at_once_ends_the_run() {
    fails(
        "exit 0",
        &[],
        "MORPH 38\n",
        "exited (exit status: 0) instead of answering `hello",
    );
    fails("exit 7", &[], "", "exited (exit status: 7)");
}

#[test]
fn a_plant_that_answers_garbage_ends_the_run() {
    fails(
        "while read l; do echo garbage; done",
        &[],
        "MORPH 38\n",
        "answered garbage to `hello protocol=1 tick_s=0.1` (unknown verb): `garbage`",
    );
}

#[test]
fn a_plant_that_answers_an_error_ends_the_run() {
    fails(
        "while read l; do echo 'error: boom'; done",
        &[],
        "MORPH 38\n",
        "answered `error: boom` to `hello protocol=1 tick_s=0.1`",
    );
    // Mid-run: hello is fine, the first step is refused.
    fails(
        "read l; echo 'ok t_pla_c=22 t_tca_c=22 t_amb_c=22 supply_v=12 radius_mm=46'; \
         while read l; do echo 'error: boom'; done",
        &[],
        "MORPH 38\n",
        "answered `error: boom` to `step dt_s=0.1 pla_duty=0 tca_duty=0`",
    );
}

#[test]
fn a_plant_that_dies_mid_morph_ends_the_run() {
    // Answers hello and 30 steps (3 s: the morph is softening, and its readings that never
    // move are not yet a dead heater), then exits.
    let cmd = "i=0; while [ $i -le 30 ] && read l; do \
               echo 'ok t_pla_c=22 t_tca_c=22 t_amb_c=22 supply_v=12 radius_mm=46'; \
               i=$((i+1)); done";
    let run = morph_sim(&["--plant-cmd", cmd], "MORPH 38\n");
    let out = text(&run.stdout);
    let err = text(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{err}");
    assert!(out.starts_with("ok\nevent: phase soften t=0.0"), "{out}");
    assert!(
        err.contains("exited (exit status: 0) instead of answering `step"),
        "{err}"
    );
    assert!(err.contains("run ended, heaters off"), "{err}");
}

#[test]
fn a_silent_plant_ends_the_run() {
    fails(
        "sleep 30",
        &["--plant-timeout-s", "0.5"],
        "MORPH 38\n",
        "was silent for 0.5 s after `hello protocol=1 tick_s=0.1`",
    );
}

#[test]
fn the_hifi_plant_runs_in_process_and_over_the_protocol_alike() {
    let script = "MORPH 38\nSIM WAIT 240\nSTATUS\n";
    let local = morph_sim(&["--plant", "hifi"], script);
    assert_eq!(local.status.code(), Some(0), "{}", text(&local.stderr));
    let cmd = format!("{MORPH_PLANT} --plant hifi");
    let remote = morph_sim(&["--plant-cmd", &cmd], script);
    assert_eq!(remote.status.code(), Some(0), "{}", text(&remote.stderr));
    let (local, remote) = (text(&local.stdout), text(&remote.stdout));
    // The morph ends (done or an alarm: the hifi link is not the controller's model), and the
    // plant over the pipe gives the very same run.
    assert!(
        local.contains("event: done") || local.contains("alarm:"),
        "{local}"
    );
    assert_eq!(local, remote);
    // --plant and --plant-cmd are one choice.
    let run = morph_sim(&["--plant", "lumped", "--plant-cmd", "true"], "");
    assert_eq!(run.status.code(), Some(2));
    assert!(
        text(&run.stderr).contains("cannot be used with"),
        "{}",
        text(&run.stderr)
    );
}

#[test]
fn morph_plant_speaks_the_protocol_on_stdin_and_stdout() {
    let out = run_with_input(
        MORPH_PLANT,
        [""; 0],
        b"hello protocol=1 tick_s=0.1\nstep dt_s=1 pla_duty=1 tca_duty=0\nset medium=air\nfly\n",
    );
    assert!(out.status.success());
    let out = text(&out.stdout);
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.len(), 4, "{out}");
    assert!(lines[0].starts_with("ok t_pla_c=22 t_tca_c=22 t_amb_c=22 supply_v=12 radius_mm="));
    assert!(field(lines[1], "t_pla_c") > 22.0, "{}", lines[1]);
    assert!(lines[2].starts_with("ok t_pla_c="), "{}", lines[2]);
    assert_eq!(lines[3], "error: unknown verb: `fly`");
}

#[test]
fn a_plant_that_fails_on_a_setting_ends_the_run_without_a_reply() {
    let cmd = "while read verb rest; do case $verb in set) echo garbage;; \
               *) echo 'ok t_pla_c=22 t_tca_c=22 t_amb_c=22 supply_v=12 radius_mm=46';; \
               esac; done";
    let run = morph_sim(
        &["--plant-cmd", cmd],
        "SIM STATE\nSIM SUPPLY 5\nSIM STATE\n",
    );
    let out = text(&run.stdout);
    let err = text(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{err}");
    // The first SIM STATE only: no reply to the failed setting, nothing after it.
    assert_eq!(out.lines().count(), 1, "{out}");
    assert!(out.starts_with("ok time_s="), "{out}");
    assert!(
        err.contains("answered garbage to `set supply_v=5`"),
        "{err}"
    );
    assert!(err.contains("run ended, heaters off"), "{err}");
}

/// An outside plant that reports its heaters' resistances (`r_pla_ohm=`, `r_tca_ohm=`) runs on a
/// board that senses current: a MOSFET failed short in bend is named `heater-short` within half a
/// second and the cut-off opens. The same plant with the resistances stripped from its replies
/// (an older plant) runs on the paper's wiring, and STATUS says nothing is sensed.
#[test]
fn an_outside_plant_that_reports_its_resistances_gets_current_sense() {
    let script = "MORPH 38\nSIM WAIT 12\nSIM FAULT heater-stuck tca\nSIM WAIT 0.5\nSTATUS\n";
    let cmd = format!("'{MORPH_PLANT}' --plant hifi");
    let run = morph_sim(&["--plant-cmd", &cmd], script);
    let out = text(&run.stdout);
    assert!(out.contains("alarm: heater-short tca "), "{out}");
    let status = out.lines().rfind(|l| l.starts_with("ok phase=")).unwrap();
    assert!(
        status.contains(" fault=heater-short ") && status.contains(" cutoff=open "),
        "{status}"
    );
    let old =
        format!("'{MORPH_PLANT}' --plant hifi | sed -u 's/ r_pla_ohm=[^ ]* r_tca_ohm=[^ ]*//'");
    let run = morph_sim(&["--plant-cmd", &old], "STATUS\n");
    let out = text(&run.stdout);
    assert!(
        out.contains(" i_pla_a=- i_tca_a=- r_pla_ohm=- r_tca_ohm=- t_tca_self_c=- cutoff=closed"),
        "{out}"
    );
}
