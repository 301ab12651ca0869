//! The real firmware image, booted under QEMU's b-l475e-iot01a machine and driven over USART1
//! with protocol v1: morphs, STATUS, ABORT mid-phase, injected faults, bad lines, and the panic
//! path. Needs `qemu-system-arm` 9 or newer; without it these tests fail and say how to install
//! it, unless `MORPHLINK_SKIP_EMULATOR=1` is set, which skips them with a loud warning.
use morphlink_host::emulator::{build_image_of, find_qemu, Emulator};
use morphlink_host::workspace::Workspace;
use std::path::{Path, PathBuf};
use std::sync::{Condvar, Mutex, OnceLock};
use std::time::Duration;

/// Longest wall time for one emulated morph (about 80 s of firmware time at 20×: 4 s).
const MORPH_WALL: Duration = Duration::from_secs(60);
const REPLY: Duration = Duration::from_secs(5);
/// Firmware time a morphed link is left to cool before its radius is read, s (the TCA cools and
/// springs back within about 20 s under water).
const COOL_S: f64 = 40.0;

/// QEMU and the one-link image, built once for all tests; `None` when skipping was asked for.
fn setup() -> Option<(PathBuf, PathBuf)> {
    static SETUP: OnceLock<Option<(PathBuf, PathBuf)>> = OnceLock::new();
    SETUP.get_or_init(|| setup_image(1)).clone()
}

/// QEMU and the two-link image (`links-2`), built once for the tests that use it.
fn setup_two_links() -> Option<(PathBuf, PathBuf)> {
    static SETUP: OnceLock<Option<(PathBuf, PathBuf)>> = OnceLock::new();
    SETUP.get_or_init(|| setup_image(2)).clone()
}

/// QEMU and the image of `links` links; `None` when skipping was asked for.
fn setup_image(links: usize) -> Option<(PathBuf, PathBuf)> {
    let qemu = match find_qemu() {
        Ok(q) => q,
        Err(e) if std::env::var_os("MORPHLINK_SKIP_EMULATOR").is_some() => {
            eprintln!("\n!!!!! EMULATOR TESTS SKIPPED (MORPHLINK_SKIP_EMULATOR): {e} !!!!!\n");
            return None;
        }
        Err(e) => panic!("{e}\n(set MORPHLINK_SKIP_EMULATOR=1 to skip the emulator tests)"),
    };
    // The workspace and cargo's target directory (CARGO_TARGET_DIR if set), from cargo.
    let ws = Workspace::containing(Path::new(env!("CARGO_MANIFEST_DIR")))
        .unwrap_or_else(|e| panic!("{e}"));
    let image = build_image_of(&ws.root, links, &ws.target_dir.join("emulated"))
        .unwrap_or_else(|e| panic!("{e}"));
    Some((qemu, image))
}

/// As many emulators at once as the machine has cores (at most [`MOST_AT_ONCE`]): each QEMU
/// gets a whole core, and under `-icount` the firmware's clock follows its own instructions, so
/// one QEMU beside another runs the same firmware timing, only its wall time shared.
const MOST_AT_ONCE: usize = 2;

/// The emulator slots in use, and the wait for one to free.
static SLOTS: (Mutex<usize>, Condvar) = (Mutex::new(0), Condvar::new());

/// Held emulator slots (how many), given back when dropped.
struct Slot(usize);

impl Slot {
    /// Waits for `want` slots (all of them for a test that times the firmware against the
    /// host's serial line, the floods, which then run alone as they always did).
    fn take(want: usize) -> Slot {
        let most = std::thread::available_parallelism().map_or(1, |n| n.get().min(MOST_AT_ONCE));
        let want = want.min(most);
        let (count, freed) = &SLOTS;
        let mut n = count.lock().unwrap_or_else(|p| p.into_inner());
        while *n + want > most {
            n = freed.wait(n).unwrap_or_else(|p| p.into_inner());
        }
        *n += want;
        Slot(want)
    }
}

impl Drop for Slot {
    fn drop(&mut self) {
        let (count, freed) = &SLOTS;
        *count.lock().unwrap_or_else(|p| p.into_inner()) -= self.0;
        freed.notify_all();
    }
}

/// Boots the image and waits for the first control tick; the slot keeps further tests waiting.
fn boot() -> Option<(Slot, Emulator)> {
    boot_taking(1)
}

/// [`boot`] holding `slots` emulator slots.
fn boot_taking(slots: usize) -> Option<(Slot, Emulator)> {
    let (qemu, image) = setup()?;
    let slot = Slot::take(slots);
    let mut emu = Emulator::boot(&qemu, &image).unwrap_or_else(|e| panic!("{e}"));
    emu.wait_ready(REPLY).unwrap_or_else(|e| panic!("{e}"));
    Some((slot, emu))
}

fn field(line: &str, key: &str) -> Option<String> {
    line.split(' ')
        .find_map(|w| w.strip_prefix(&format!("{key}=")).map(str::to_string))
}

/// Asserts with QEMU's log and the serial transcript attached.
macro_rules! check {
    ($emu:expr, $cond:expr, $($msg:tt)+) => {
        let holds: bool = $cond;
        if !holds {
            let report = $emu.report();
            panic!("{}\n{}", format!($($msg)+), report);
        }
    };
}

#[test]
fn boots_and_answers_version_status_and_range() {
    let Some((_slot, mut emu)) = boot() else {
        return;
    };
    let boot_line = emu.transcript[0].clone();
    check!(
        emu,
        boot_line.starts_with("event: boot "),
        "boot line: {boot_line}"
    );
    println!("boot to first line: {:?}", emu.boot_time);
    let v = emu.command("VERSION", REPLY).unwrap();
    check!(emu, v.last().unwrap().contains("protocol=1"), "{v:?}");
    let s = emu.command("STATUS", REPLY).unwrap();
    check!(
        emu,
        field(s.last().unwrap(), "phase").as_deref() == Some("idle"),
        "{s:?}"
    );
    let r = emu.command("RANGE", REPLY).unwrap();
    check!(emu, field(r.last().unwrap(), "min_mm").is_some(), "{r:?}");
    // Firmware time cannot be skipped: SIM WAIT is morph-sim's alone.
    let w = emu.command("SIM WAIT 5", REPLY).unwrap();
    check!(
        emu,
        w.last().unwrap().starts_with("error: unsupported SIM WAIT"),
        "{w:?}"
    );
}

#[test]
fn full_morphs_reach_their_targets_with_phases_in_order() {
    let Some((_slot, mut emu)) = boot() else {
        return;
    };
    for target in [34.0, 38.0, 44.0] {
        let started = std::time::Instant::now();
        let r = emu.command(&format!("MORPH {target}"), REPLY).unwrap();
        check!(emu, r.last().map(String::as_str) == Some("ok"), "{r:?}");
        let lines = emu.wait_for("event: done", MORPH_WALL).unwrap();
        let phases: Vec<&str> = lines
            .iter()
            .filter_map(|l| l.strip_prefix("event: phase "))
            .map(|l| l.split(' ').next().unwrap())
            .collect();
        // A link still warm from the previous morph rests first.
        let heated = phases.strip_prefix(&["rest"][..]).unwrap_or(&phases);
        check!(
            emu,
            heated == ["soften", "bend", "lock", "release"],
            "phases {phases:?}"
        );
        // Let the TCA cool for 40 s of firmware time (2 s of wall time at 20×, longer on a
        // loaded machine), then read the simulated truth.
        let sim_time = |emu: &mut Emulator| -> (f64, String) {
            let state = emu.command("SIM STATE", REPLY).unwrap();
            let line = state.last().unwrap().clone();
            (field(&line, "time_s").unwrap().parse().unwrap(), line)
        };
        let (done_s, _) = sim_time(&mut emu);
        let cooled = std::time::Instant::now();
        let state = loop {
            let (t, line) = sim_time(&mut emu);
            if t >= done_s + COOL_S || cooled.elapsed() > MORPH_WALL {
                break vec![line];
            }
            std::thread::sleep(Duration::from_millis(200));
        };
        let radius: f64 = field(state.last().unwrap(), "radius_mm")
            .unwrap()
            .parse()
            .unwrap();
        let err = (radius - target) / target * 100.0;
        println!(
            "emulated morph to {target} mm: {radius:.2} mm ({err:+.2} %) in {:.1} s wall",
            started.elapsed().as_secs_f64()
        );
        check!(
            emu,
            err.abs() < 2.0,
            "target {target}: simulated radius {radius} ({err:+.2} %)"
        );
    }
}

#[test]
fn abort_mid_phase_turns_heaters_off() {
    let Some((_slot, mut emu)) = boot() else {
        return;
    };
    for phase in ["soften", "bend", "lock"] {
        emu.command("MORPH 36", REPLY).unwrap();
        emu.wait_for(&format!("event: phase {phase}"), MORPH_WALL)
            .unwrap();
        let a = emu.command("ABORT", REPLY).unwrap();
        check!(emu, a.last().map(String::as_str) == Some("ok"), "{a:?}");
        let s = emu.command("STATUS", REPLY).unwrap();
        let s = s.last().unwrap().clone();
        check!(emu, field(&s, "phase").as_deref() == Some("idle"), "{s}");
        check!(
            emu,
            field(&s, "p_pla_w").as_deref() == Some("0.000")
                && field(&s, "p_tca_w").as_deref() == Some("0.000"),
            "{s}"
        );
    }
}

#[test]
fn injected_faults_raise_their_alarm_with_heaters_off() {
    let Some((_slot, mut emu)) = boot() else {
        return;
    };
    for (inject, alarm, clear) in [
        (
            "SIM FAULT thermistor-open tca",
            "alarm: thermistor-open tca",
            "SIM CLEAR",
        ),
        (
            "SIM FAULT thermistor-short pla",
            "alarm: thermistor-short pla",
            "SIM CLEAR",
        ),
        (
            "SIM SUPPLY 5",
            "alarm: supply-out-of-range",
            "SIM SUPPLY 12",
        ),
        // The emulated board senses its heaters' current (as the host rig's does): an open
        // heater carries none while driven, named within two ticks, before any thermal check.
        (
            "SIM FAULT heater-open pla",
            "alarm: heater-open pla",
            "SIM CLEAR",
        ),
    ] {
        emu.command("MORPH 38", REPLY).unwrap();
        emu.wait_for("event: phase soften", MORPH_WALL).unwrap();
        emu.command(inject, REPLY).unwrap();
        let got = emu.wait_for("alarm: ", MORPH_WALL).unwrap();
        let line = got.last().unwrap();
        check!(
            emu,
            alarm.split('|').any(|a| line.starts_with(a)),
            "{inject}: expected {alarm}, got {line}"
        );
        let s = emu.command("STATUS", REPLY).unwrap();
        let s = s.last().unwrap().clone();
        check!(
            emu,
            field(&s, "phase").as_deref() == Some("fault"),
            "{inject}: {s}"
        );
        check!(
            emu,
            field(&s, "p_pla_w").as_deref() == Some("0.000")
                && field(&s, "p_tca_w").as_deref() == Some("0.000"),
            "{s}"
        );
        let m = emu.command("MORPH 38", REPLY).unwrap();
        check!(
            emu,
            m.last().unwrap().starts_with("error: fault-latched"),
            "{m:?}"
        );
        emu.command(clear, REPLY).unwrap();
        std::thread::sleep(Duration::from_millis(300));
        let r = emu.command("RESET", REPLY).unwrap();
        check!(
            emu,
            r.last().unwrap().starts_with("ok"),
            "{inject}: RESET {r:?}"
        );
    }
}

/// The cut-off and current-sense path of the real image: a TCA MOSFET stuck on during a morph
/// carries current in its off-time, named `heater-short` within 0.5 s of firmware time (five
/// control ticks, counted by `STATS`), and the supply's cut-off ends the heating a stuck MOSFET
/// would go on with: the TCA cools although its MOSFET still conducts.
#[test]
fn a_stuck_heater_is_named_by_its_current_and_the_cut_off_ends_its_heating() {
    let Some((_slot, mut emu)) = boot() else {
        return;
    };
    emu.command("MORPH 38", REPLY).unwrap();
    emu.wait_for("event: phase soften", MORPH_WALL).unwrap();
    // Injected and counted in one write: the two lines are answered in consecutive passes of
    // the serial task, within a tick.
    emu.write_raw(b"SIM FAULT heater-stuck tca\nSTATS\n")
        .unwrap();
    let first = emu.wait_for("ok ticks=", REPLY).unwrap();
    let ticks_at_fault = parse_stats(first.last().unwrap()).0;
    // Polled until the alarm arrives: the trip came before the first STATS answered after it.
    let (alarm, ticks_at_alarm) = loop {
        let r = emu.command("STATS", REPLY).unwrap();
        let ticks = parse_stats(r.last().unwrap()).0;
        if let Some(a) = r.iter().find(|l| l.starts_with("alarm: ")) {
            break (a.clone(), ticks);
        }
        check!(
            emu,
            ticks < ticks_at_fault + 50,
            "no alarm 5 s of firmware time after the fault"
        );
    };
    let ticks = ticks_at_alarm - ticks_at_fault;
    println!("heater-stuck tca to its alarm: {ticks} ticks or fewer: {alarm}");
    check!(
        emu,
        alarm.starts_with("alarm: heater-short tca"),
        "expected heater-short tca: {alarm}"
    );
    check!(emu, ticks <= 5, "heater-short took {ticks} ticks (> 0.5 s)");
    let s = emu.command("STATUS", REPLY).unwrap();
    let s = s.last().unwrap().clone();
    check!(
        emu,
        field(&s, "phase").as_deref() == Some("fault")
            && field(&s, "fault").as_deref() == Some("heater-short")
            && field(&s, "p_tca_w").as_deref() == Some("0.000"),
        "{s}"
    );
    // The MOSFET is still stuck (the fault stays injected): only the open cut-off keeps the
    // 22 W the stuck TCA would take off it. Over 5 s of firmware time it cools.
    let tca_c = |emu: &mut Emulator| -> (f64, f64) {
        let st = emu.command("SIM STATE", REPLY).unwrap();
        let st = st.last().unwrap().clone();
        let n = |k: &str| field(&st, k).unwrap().parse::<f64>().unwrap();
        (n("time_s"), n("t_tca_c"))
    };
    let (t0, c0) = tca_c(&mut emu);
    let started = std::time::Instant::now();
    let (t1, c1) = loop {
        std::thread::sleep(Duration::from_millis(100));
        let (t, c) = tca_c(&mut emu);
        if t >= t0 + 5.0 || started.elapsed() > MORPH_WALL {
            break (t, c);
        }
    };
    println!("stuck TCA after the trip: {c0:.2} C at {t0:.1} s, {c1:.2} C at {t1:.1} s");
    check!(
        emu,
        t1 >= t0 + 5.0 && c1 < c0,
        "the stuck TCA did not cool with the cut-off open: {c0} C -> {c1} C over {:.1} s",
        t1 - t0
    );
    emu.command("SIM CLEAR", REPLY).unwrap();
}

#[test]
fn overlong_and_garbage_lines_get_errors() {
    let Some((_slot, mut emu)) = boot() else {
        return;
    };
    let mut long = vec![b'X'; 300];
    long.push(b'\n');
    emu.write_raw(&long).unwrap();
    let l = emu.next_line(REPLY).unwrap();
    check!(emu, l.starts_with("error: line-too-long"), "{l}");
    emu.write_raw(&[0xff, 0x00, 0x80, b'\n']).unwrap();
    let l = emu.next_line(REPLY).unwrap();
    check!(emu, l.starts_with("error: "), "{l}");
    let r = emu.command("FLY 38", REPLY).unwrap();
    check!(
        emu,
        r.last().unwrap().starts_with("error: unknown-command"),
        "{r:?}"
    );
    let r = emu.command("status", REPLY).unwrap();
    check!(emu, r.last().unwrap().starts_with("ok phase=idle"), "{r:?}");
}

/// Reads `STATUS` and asserts the controller is idle with both heaters at 0 W.
fn assert_idle_and_off(emu: &mut Emulator, when: &str) {
    let s = emu.command("STATUS", REPLY).unwrap();
    let s = s.last().unwrap().clone();
    check!(
        emu,
        field(&s, "phase").as_deref() == Some("idle")
            && field(&s, "p_pla_w").as_deref() == Some("0.000")
            && field(&s, "p_tca_w").as_deref() == Some("0.000"),
        "{when}: {s}"
    );
}

/// Waits for the boot line of the next run (after a reset), returns it.
fn next_boot_line(emu: &mut Emulator) -> String {
    let lines = emu
        .wait_for("event: boot ", Duration::from_secs(10))
        .unwrap_or_else(|e| panic!("no reboot: {e}"));
    lines.last().unwrap().clone()
}

#[test]
fn a_panic_turns_heaters_off_resets_and_the_next_boot_names_it() {
    let Some((_slot, mut emu)) = boot() else {
        return;
    };
    emu.command("MORPH 38", REPLY).unwrap();
    emu.wait_for("event: phase bend", MORPH_WALL).unwrap();
    emu.write_raw(b"SIM PANIC\n").unwrap();
    let boot_line = next_boot_line(&mut emu);
    check!(
        emu,
        boot_line.contains(" reset=software ")
            && boot_line.contains(" panic=\"panic at src/emulated.rs:")
            && boot_line.contains("SIM PANIC asked for a panic; heaters off\"")
            && boot_line.len() <= morphlink::protocol::reply::BOOT_LINE_MAX,
        "boot line after the panic: {boot_line}"
    );
    check!(
        emu,
        emu.exited().is_none(),
        "QEMU must keep running: the machine resets"
    );
    emu.wait_ready(REPLY).unwrap();
    assert_idle_and_off(&mut emu, "after the panic reset");
    // The reason is reported once: a RESET-free second look at STATS shows the software reset.
    let stats = emu.command("STATS", REPLY).unwrap();
    check!(
        emu,
        field(stats.last().unwrap(), "reset").as_deref() == Some("software"),
        "{stats:?}"
    );
    let report = emu.report();
    assert!(report.contains("panic at src/emulated.rs"), "{report}");
}

#[test]
fn a_stalled_control_task_is_reset_by_the_watchdog_with_heaters_off() {
    let Some((_slot, mut emu)) = boot() else {
        return;
    };
    emu.command("MORPH 38", REPLY).unwrap();
    emu.wait_for("event: phase bend", MORPH_WALL).unwrap();
    let stalled = std::time::Instant::now();
    emu.write_raw(b"SIM STALL\n").unwrap();
    let boot_line = next_boot_line(&mut emu);
    let wall = stalled.elapsed();
    check!(
        emu,
        boot_line.contains(" reset=watchdog ") && boot_line.contains("panic=\"watchdog: "),
        "boot line after the stall: {boot_line}"
    );
    // 500 ms of firmware time is 25 ms of wall time at 20x; allow a loaded machine 100x that.
    println!("SIM STALL to the watchdog's reboot line: {wall:?} wall");
    check!(
        emu,
        wall < Duration::from_millis(2500),
        "watchdog took {wall:?}"
    );
    emu.wait_ready(REPLY).unwrap();
    assert_idle_and_off(&mut emu, "after the watchdog reset");
    let report = emu.report();
    assert!(
        report.contains("watchdog: the control task stopped"),
        "{report}"
    );
}

/// Nothing heats after a boot: the controller starts idle, and the simulated link stays at
/// ambient for a minute of firmware time (checked after power-on and after a reset).
#[test]
fn a_boot_never_heats() {
    let Some((_slot, mut emu)) = boot() else {
        return;
    };
    let watch = |emu: &mut Emulator, when: &str| {
        let t0 = emu.command("SIM STATE", REPLY).unwrap();
        let t0: f64 = field(t0.last().unwrap(), "time_s")
            .unwrap()
            .parse()
            .unwrap();
        let started = std::time::Instant::now();
        loop {
            assert_idle_and_off(emu, when);
            let st = emu.command("SIM STATE", REPLY).unwrap();
            let st = st.last().unwrap().clone();
            let t: f64 = field(&st, "time_s").unwrap().parse().unwrap();
            for key in ["t_pla_c", "t_tca_c"] {
                let c: f64 = field(&st, key).unwrap().parse().unwrap();
                check!(emu, c < 23.0, "{when}: {key} rose to {c} C: {st}");
            }
            if t > t0 + 60.0 || started.elapsed() > MORPH_WALL {
                break;
            }
            std::thread::sleep(Duration::from_millis(200));
        }
    };
    watch(&mut emu, "after power-on");
    emu.command("MORPH 38", REPLY).unwrap();
    emu.wait_for("event: phase bend", MORPH_WALL).unwrap();
    emu.write_raw(b"SIM PANIC\n").unwrap();
    next_boot_line(&mut emu);
    emu.wait_ready(REPLY).unwrap();
    watch(&mut emu, "after a reset mid-bend");
}

#[test]
fn cr_only_and_crlf_line_endings_run_abort_and_status() {
    let Some((_slot, mut emu)) = boot() else {
        return;
    };
    for ending in ["\r", "\r\n"] {
        emu.write_raw(format!("MORPH 36{ending}").as_bytes())
            .unwrap();
        emu.wait_for("event: phase soften", MORPH_WALL).unwrap();
        emu.write_raw(format!("ABORT{ending}").as_bytes()).unwrap();
        let a = emu.wait_for("ok", REPLY).unwrap();
        check!(
            emu,
            a.last().map(String::as_str) == Some("ok"),
            "{ending:?}: {a:?}"
        );
        emu.write_raw(format!("STATUS{ending}").as_bytes()).unwrap();
        let s = emu.next_line(REPLY).unwrap();
        check!(
            emu,
            s.starts_with("ok phase=idle ") && field(&s, "p_tca_w").as_deref() == Some("0.000"),
            "{ending:?}: {s}"
        );
    }
    // CRLF makes no empty line: exactly one reply per line, nothing after it.
    emu.write_raw(b"VERSION\r\nVERSION\r\n").unwrap();
    for _ in 0..2 {
        let l = emu.next_line(REPLY).unwrap();
        check!(emu, l.starts_with("ok version="), "{l}");
    }
    let r = emu.command("STATUS", REPLY).unwrap();
    check!(emu, r.len() == 1 && r[0].starts_with("ok phase="), "{r:?}");
}

/// Waits until the firmware has worked through everything written so far: sends RANGE until
/// one is answered (while the output is congested, replies are dropped and counted, or come
/// late), then until the line has been quiet for a second; returns how many RANGE lines it sent.
fn drain(emu: &mut Emulator, limit: Duration) -> usize {
    let end = std::time::Instant::now() + limit;
    let mut sent = 0;
    loop {
        emu.write_raw(b"RANGE\n").unwrap();
        sent += 1;
        if emu.wait_for("ok min_mm=", Duration::from_secs(2)).is_ok() {
            break;
        }
        check!(
            emu,
            std::time::Instant::now() < end,
            "the firmware did not drain the flood in {limit:?}"
        );
    }
    while emu.next_line(Duration::from_secs(1)).is_ok() {}
    sent
}

/// `STATS` as (ticks, late, period_max_us).
fn stats(emu: &mut Emulator) -> (u64, u64, u64) {
    let s = emu.command("STATS", REPLY).unwrap();
    parse_stats(s.last().unwrap())
}

fn parse_stats(line: &str) -> (u64, u64, u64) {
    let n = |k: &str| {
        field(line, k)
            .and_then(|v| v.parse().ok())
            .unwrap_or(u64::MAX)
    };
    (n("ticks"), n("late"), n("period_max_us"))
}

/// Longest tick period a flood may cause, µs: three ticks, well inside the 500 ms watchdog.
/// (The STATUS flood also asserts `late` = 0, no tick over 110 ms: under QEMU's `-icount` the
/// firmware's clock follows its own instructions, see docs/emulation.md. The HELP flood only
/// reports `late`: its 1.4 KiB replies, formatted on an emulated CPU some 25 times slower than
/// the chip, may hold a tick up by a few ms.)
const FLOOD_PERIOD_MAX_US: u64 = 300_000;

/// Lines of the STATUS flood (`MORPHLINK_FLOOD_LINES` overrides, e.g. 100000).
fn flood_lines() -> usize {
    std::env::var("MORPHLINK_FLOOD_LINES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(20_000)
}

/// A flood of STATUS lines written as fast as TCP takes them, with a paper-mode morph and, while
/// it is in bend, an ABORT in the middle: the ABORT is acted on (heaters off), every reply is
/// one of the expected forms (no command formed from two lines), every line is accounted for
/// (answered, or counted in an `error: busy ... replies dropped` notice), and the control task
/// keeps its timing: no tick late (`STATS late=0`).
#[test]
fn a_status_flood_loses_no_abort_and_merges_no_lines() {
    let Some((_slot, mut emu)) = boot_taking(MOST_AT_ONCE) else {
        return;
    };
    let n = flood_lines();
    let (_, late_before, _) = stats(&mut emu);
    // The first half of the flood, then the morph; once it is in bend (20..70 s of firmware
    // time after MORPH in paper mode), a few hundred more STATUS lines, the ABORT and the second
    // half: the ABORT lands a few firmware seconds into bend.
    let k = 200;
    let pre = n / 2 - k;
    let post = n - pre - k;
    let from = emu.transcript.len();
    let started = std::time::Instant::now();
    let mut blob = "STATUS\n".repeat(pre);
    blob.push_str("MORPH 38 paper\n");
    emu.write_raw(blob.as_bytes()).unwrap();
    emu.wait_for(
        "event: phase bend",
        Duration::from_secs(60) + Duration::from_millis(20) * n as u32,
    )
    .unwrap();
    let mut blob = "STATUS\n".repeat(k);
    blob.push_str("ABORT\n");
    blob.push_str(&"STATUS\n".repeat(post));
    emu.write_raw(blob.as_bytes()).unwrap();
    let ranges = drain(
        &mut emu,
        Duration::from_secs(60) + Duration::from_millis(20) * n as u32,
    );
    let wall = started.elapsed();
    let lines = emu.transcript[from..].to_vec();
    println!("flood: {pre} STATUS, MORPH 38 paper, (bend) {k} STATUS, ABORT, {post} STATUS");

    let (mut statuses, mut bare_ok, mut dropped, mut overruns) =
        (0usize, Vec::new(), 0usize, 0usize);
    let mut range_replies = 0;
    for (i, l) in lines.iter().enumerate() {
        if l.starts_with("ok phase=") {
            statuses += 1;
        } else if l.starts_with("ok min_mm=") {
            range_replies += 1;
        } else if l == "ok" {
            bare_ok.push(i);
        } else if l.starts_with("event: phase ") || l.starts_with("event: done ") {
        } else if let Some(rest) = l.strip_prefix("error: busy ") {
            let count = rest.split(' ').next().and_then(|c| c.parse::<usize>().ok());
            check!(
                emu,
                rest.contains(" replies dropped") && count.is_some(),
                "reply {i}: {l}"
            );
            dropped += count.unwrap();
        } else if l.starts_with("error: overrun ") {
            overruns += 1;
        } else {
            check!(
                emu,
                false,
                "reply {i} is no expected form (two lines merged?): {l}"
            );
        }
    }
    let (ticks, late, period_max_us) = stats(&mut emu);
    println!(
        "flood of {n} STATUS lines: {wall:.1?} wall; {statuses} STATUS replies, {dropped} replies \
         dropped (counted), {overruns} overrun errors; STATS ticks={ticks} late={late} \
         (before the flood {late_before}) period_max_us={period_max_us}"
    );
    // The ABORT's reply (never dropped: it may use the room kept for events) is the last bare ok.
    let abort_at = *bare_ok.last().expect("the ABORT's ok");
    let before = &lines[..abort_at];
    check!(
        emu,
        before.iter().any(|l| l.starts_with("event: phase bend"))
            && !before.iter().any(|l| l.starts_with("event: phase lock")
                || l.starts_with("event: phase release")
                || l.starts_with("event: done")),
        "the ABORT must land in bend: events before it {:?}",
        before
            .iter()
            .filter(|l| l.starts_with("event:"))
            .collect::<Vec<_>>()
    );
    for l in &lines[abort_at + 1..] {
        check!(
            emu,
            !l.starts_with("event: phase"),
            "a phase after ABORT: {l}"
        );
        if l.starts_with("ok phase=") {
            check!(
                emu,
                l.starts_with("ok phase=idle ")
                    && field(l, "p_pla_w").as_deref() == Some("0.000")
                    && field(l, "p_tca_w").as_deref() == Some("0.000"),
                "after ABORT: {l}"
            );
        }
    }
    if overruns == 0 {
        // Nothing lost: every STATUS, the MORPH and the ABORT answered or counted as dropped.
        check!(
            emu,
            statuses + bare_ok.len() + range_replies + dropped == n + 2 + ranges,
            "{statuses} STATUS + {} ok + {range_replies} RANGE + {dropped} dropped != {} lines",
            bare_ok.len(),
            n + 2 + ranges
        );
    }
    check!(emu, emu.exited().is_none(), "QEMU ended during the flood");
    check!(
        emu,
        !emu.transcript[1..]
            .iter()
            .any(|l| l.starts_with("event: boot")),
        "the firmware reset during the flood"
    );
    check!(
        emu,
        period_max_us < FLOOD_PERIOD_MAX_US,
        "period_max_us={period_max_us}"
    );
    check!(
        emu,
        late == 0,
        "{late} control ticks started over 10 ms late during the flood (period_max_us={period_max_us})"
    );
    assert_idle_and_off(&mut emu, "after the flood");
}

/// 300 HELP lines in a row (each 17 data lines and an ok, about 1.4 KiB) do not starve the
/// control task: no watchdog reset, no tick late (`STATS late=0`: a reply the Outbox will drop
/// is not built), and the replies that did not fit are counted in `error: busy` notices.
#[test]
fn a_help_flood_does_not_starve_the_control_task() {
    let Some((_slot, mut emu)) = boot_taking(MOST_AT_ONCE) else {
        return;
    };
    let n = 300;
    let started = std::time::Instant::now();
    let from = emu.transcript.len();
    emu.write_raw("HELP\n".repeat(n).as_bytes()).unwrap();
    let ranges = drain(&mut emu, MORPH_WALL);
    let wall = started.elapsed();
    let lines = emu.transcript[from..].to_vec();
    let (mut oks, mut dropped, mut range_replies) = (0usize, 0usize, 0usize);
    for l in &lines {
        if l.starts_with("ok min_mm=") {
            range_replies += 1;
        } else if l == "ok" {
            oks += 1;
        } else if let Some(rest) = l.strip_prefix("error: busy ") {
            dropped += rest
                .split(' ')
                .next()
                .and_then(|c| c.parse::<usize>().ok())
                .unwrap_or(0);
        } else {
            check!(emu, l.starts_with("data: "), "{l}");
        }
    }
    let (ticks, late, period_max_us) = stats(&mut emu);
    println!(
        "HELP flood of {n}: {wall:.1?} wall; {oks} answered, {dropped} dropped (counted); \
         STATS ticks={ticks} late={late} period_max_us={period_max_us}"
    );
    check!(
        emu,
        oks + range_replies + dropped == n + ranges,
        "{oks} HELP + {range_replies} RANGE answered + {dropped} dropped != {}",
        n + ranges
    );
    check!(
        emu,
        emu.exited().is_none(),
        "QEMU ended during the HELP flood"
    );
    check!(
        emu,
        !emu.transcript[1..]
            .iter()
            .any(|l| l.starts_with("event: boot")),
        "the watchdog reset the firmware during the HELP flood"
    );
    check!(
        emu,
        period_max_us < FLOOD_PERIOD_MAX_US,
        "period_max_us={period_max_us}"
    );
    check!(
        emu,
        late == 0,
        "{late} control ticks started over 10 ms late during the HELP flood (period_max_us={period_max_us})"
    );
}

#[test]
fn a_saved_setting_survives_a_reset_and_an_unsaved_one_does_not() {
    let Some((qemu, image)) = setup() else {
        return;
    };
    let _slot = Slot::take(1);
    let mut emu = Emulator::boot(&qemu, &image).unwrap_or_else(|e| panic!("{e}"));
    // QEMU starts with zeroed RAM: no settings kept yet.
    let first = emu.wait_for("event: config ", REPLY).unwrap();
    check!(
        emu,
        first.last().unwrap() == "event: config defaults reason=absent",
        "{first:?}"
    );
    emu.wait_ready(REPLY).unwrap();
    let set = emu.command("CONFIG SET lock_timeout_s 321", REPLY).unwrap();
    check!(
        emu,
        set.last().unwrap() == "ok lock_timeout_s=321.0 saved=no",
        "{set:?}"
    );
    let t0 = std::time::Instant::now();
    let saved = emu.command("SAVE", REPLY).unwrap();
    let save_wall = t0.elapsed();
    check!(
        emu,
        saved.last().unwrap().starts_with("ok saved bytes=106 "),
        "{saved:?}"
    );
    println!("emulated SAVE round trip: {save_wall:?} wall time");
    emu.command("CONFIG SET bend_timeout_s 222", REPLY).unwrap();

    emu.write_raw(b"SIM PANIC\n").unwrap();
    next_boot_line(&mut emu);
    let again = emu.wait_for("event: config ", REPLY).unwrap();
    check!(
        emu,
        again.last().unwrap() == "event: config loaded settings=25",
        "{again:?}"
    );
    emu.wait_ready(REPLY).unwrap();
    assert_idle_and_off(&mut emu, "after the reset with saved settings");
    let config = emu.command("CONFIG", REPLY).unwrap();
    check!(
        emu,
        config
            .iter()
            .any(|l| l.starts_with("data: lock_timeout_s=321.0 s"))
            && config
                .iter()
                .any(|l| l.starts_with("data: bend_timeout_s=120.0 s")),
        "{config:?}"
    );
}

/// The two-link image: each link its own addressed morph under one supply budget (the second
/// waits for room, then starts by itself), bad addresses and gaits refused, a fault on one link
/// stopping that link alone while the other finishes, each link's SAVE kept apart, and the
/// supply's budget kept with link 1's.
#[test]
fn two_links_share_one_budget_and_a_fault_on_one_stops_only_it() {
    let Some((qemu, image)) = setup_two_links() else {
        return;
    };
    let _slot = Slot::take(1);
    let mut emu = Emulator::boot(&qemu, &image).unwrap_or_else(|e| panic!("{e}"));
    emu.wait_ready(REPLY).unwrap();
    let links = emu.command("LINKS", REPLY).unwrap();
    check!(
        emu,
        links.last().unwrap().starts_with("ok links=2 ")
            && links.iter().any(|l| l.starts_with("data: @2 phase=idle")),
        "{links:?}"
    );
    // Bad input: refused with its reason, nothing changes.
    let past = emu.command("@3 STATUS", REPLY).unwrap();
    check!(
        emu,
        past.last()
            .unwrap()
            .starts_with("error: out-of-range no link 3"),
        "{past:?}"
    );
    let short = emu.command("GAIT 34", REPLY).unwrap();
    check!(
        emu,
        short
            .last()
            .unwrap()
            .starts_with("error: bad-argument GAIT took 1"),
        "{short:?}"
    );
    let zero = emu.command("CONFIG SET supply_budget_w 0", REPLY).unwrap();
    check!(emu, zero.last().unwrap().starts_with("error: "), "{zero:?}");

    // One soften's worth of budget: link 2 waits, then morphs once link 1 leaves room.
    let set = emu.command("CONFIG SET supply_budget_w 5", REPLY).unwrap();
    check!(
        emu,
        set.last().unwrap().starts_with("ok supply_budget_w=5.00"),
        "{set:?}"
    );
    emu.command("GAIT 34 42", REPLY).unwrap();
    let mut done = [None, None];
    let mut queued = false;
    while done.iter().any(Option::is_none) {
        let line = emu.next_line(MORPH_WALL).unwrap_or_else(|e| panic!("{e}"));
        check!(emu, !line.contains("alarm: "), "{line}");
        queued |= line.starts_with("@2 event: queued ");
        for (k, d) in done.iter_mut().enumerate() {
            if line.starts_with(&format!("@{} event: done ", k + 1)) {
                *d = field(&line, "radius_mm").and_then(|r| r.parse::<f64>().ok());
            }
        }
    }
    check!(emu, queued, "link 2 did not wait for the budget");
    for (k, target) in [34.0, 42.0].into_iter().enumerate() {
        let st = emu
            .command(&format!("@{} SIM STATE", k + 1), REPLY)
            .unwrap();
        let radius = field(st.last().unwrap(), "radius_mm").and_then(|r| r.parse::<f64>().ok());
        check!(
            emu,
            radius.is_some_and(|r| (r - target).abs() < 1.0) && done[k].is_some(),
            "link {}: {st:?} {done:?}",
            k + 1
        );
    }

    // A fault on link 2 stops link 2; link 1's morph goes on to done.
    emu.command("CONFIG SET supply_budget_w 100", REPLY)
        .unwrap();
    emu.command("GAIT 38 38", REPLY).unwrap();
    emu.wait_for("@2 event: phase soften", MORPH_WALL).unwrap();
    emu.command("@2 SIM FAULT thermistor-open pla", REPLY)
        .unwrap();
    emu.wait_for("@2 alarm: thermistor-open pla", MORPH_WALL)
        .unwrap();
    let seen = emu.wait_for("@1 event: done ", MORPH_WALL).unwrap();
    check!(
        emu,
        !seen.iter().any(|l| l.starts_with("@1 alarm:")),
        "{seen:?}"
    );
    let st = emu.command("@2 STATUS", REPLY).unwrap();
    let st = st.last().unwrap().clone();
    check!(
        emu,
        field(&st, "phase").as_deref() == Some("fault")
            && field(&st, "p_pla_w").as_deref() == Some("0.000")
            && field(&st, "p_tca_w").as_deref() == Some("0.000"),
        "{st}"
    );
    assert_idle_and_off(&mut emu, "link 1 after its morph");

    // Each link keeps its own settings: link 2's SAVE survives a reset, link 1 has none.
    emu.command("@2 SIM CLEAR", REPLY).unwrap();
    // RESET is refused until the cleared bead has read healthy for a few ticks.
    let reset_ok = (0..50).any(|_| {
        std::thread::sleep(Duration::from_millis(100));
        emu.command("@2 RESET", REPLY)
            .is_ok_and(|r| r.last().is_some_and(|l| l.starts_with("ok")))
    });
    check!(
        emu,
        reset_ok,
        "link 2's RESET was refused for 5 s after SIM CLEAR"
    );
    let set = emu
        .command("@2 CONFIG SET lock_timeout_s 321", REPLY)
        .unwrap();
    check!(
        emu,
        set.last().unwrap() == "ok lock_timeout_s=321.0 saved=no",
        "{set:?}"
    );
    let saved = emu.command("@2 SAVE", REPLY).unwrap();
    check!(
        emu,
        saved.last().unwrap().starts_with("ok saved "),
        "{saved:?}"
    );
    // The supply's settings are the board's: saved with link 1's (an unaddressed SAVE).
    let set = emu.command("CONFIG SET supply_budget_w 6", REPLY).unwrap();
    check!(
        emu,
        set.last().unwrap().starts_with("ok supply_budget_w=6.00"),
        "{set:?}"
    );
    let saved = emu.command("SAVE", REPLY).unwrap();
    check!(
        emu,
        saved.last().unwrap().starts_with("ok saved "),
        "{saved:?}"
    );
    emu.write_raw(b"SIM PANIC\n").unwrap();
    next_boot_line(&mut emu);
    // Every line from the boot to link 2's config event (the board's own come first).
    let seen = emu.wait_for("@2 event: config ", REPLY).unwrap();
    let has = |l: &str| seen.iter().any(|s| s == l);
    check!(
        emu,
        has("@1 event: config loaded settings=25")
            && has("@2 event: config loaded settings=25")
            && has("event: config supply loaded supply_budget_w=6.00 supply_limit_a=20.00"),
        "{seen:?}"
    );
    emu.wait_ready(REPLY).unwrap();
    let links = emu.command("LINKS", REPLY).unwrap();
    check!(
        emu,
        links.last().unwrap().contains(" budget_w=6.00 "),
        "{links:?}"
    );
    let kept = |emu: &mut Emulator, k: usize| {
        let config = emu.command(&format!("@{k} CONFIG"), REPLY).unwrap();
        config
            .iter()
            .any(|l| l.starts_with("data: lock_timeout_s=321.0 s"))
    };
    check!(
        emu,
        kept(&mut emu, 2) && !kept(&mut emu, 1),
        "each link keeps its own settings"
    );
}
