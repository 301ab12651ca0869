//! The real firmware image, booted under QEMU's b-l475e-iot01a machine and driven over USART1
//! with protocol v1: morphs, STATUS, ABORT mid-phase, injected faults, bad lines, and the panic
//! path. Needs `qemu-system-arm` 9 or newer; without it these tests fail and say how to install
//! it, unless `MORPHLINK_SKIP_EMULATOR=1` is set, which skips them with a loud warning.
use morphlink_host::emulator::{build_image, find_qemu, Emulator};
use morphlink_host::workspace::Workspace;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard, OnceLock};
use std::time::Duration;

/// Longest wall time for one emulated morph (about 80 s of firmware time at 20×: 4 s).
const MORPH_WALL: Duration = Duration::from_secs(60);
const REPLY: Duration = Duration::from_secs(5);
/// Firmware time a morphed link is left to cool before its radius is read, s (the TCA cools and
/// springs back within about 20 s under water).
const COOL_S: f64 = 40.0;

/// QEMU and the image, built once for all tests; `None` when skipping was asked for.
fn setup() -> Option<(PathBuf, PathBuf)> {
    static SETUP: OnceLock<Option<(PathBuf, PathBuf)>> = OnceLock::new();
    SETUP
        .get_or_init(|| {
            let qemu = match find_qemu() {
                Ok(q) => q,
                Err(e) if std::env::var_os("MORPHLINK_SKIP_EMULATOR").is_some() => {
                    eprintln!(
                        "\n!!!!! EMULATOR TESTS SKIPPED (MORPHLINK_SKIP_EMULATOR): {e} !!!!!\n"
                    );
                    return None;
                }
                Err(e) => panic!("{e}\n(set MORPHLINK_SKIP_EMULATOR=1 to skip the emulator tests)"),
            };
            // The workspace and cargo's target directory (CARGO_TARGET_DIR if set), from cargo.
            let ws = Workspace::containing(Path::new(env!("CARGO_MANIFEST_DIR")))
                .unwrap_or_else(|e| panic!("{e}"));
            let image = build_image(&ws.root, &ws.target_dir.join("emulated"))
                .unwrap_or_else(|e| panic!("{e}"));
            Some((qemu, image))
        })
        .clone()
}

/// One emulator at a time: the tests share two cores with everything else, and each QEMU
/// should get a whole one.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// Boots the image and waits for the first control tick; the guard keeps other tests waiting.
fn boot() -> Option<(MutexGuard<'static, ()>, Emulator)> {
    let (qemu, image) = setup()?;
    let guard = ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
    let mut emu = Emulator::boot(&qemu, &image).unwrap_or_else(|e| panic!("{e}"));
    emu.wait_ready(REPLY).unwrap_or_else(|e| panic!("{e}"));
    Some((guard, emu))
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
    let Some((_one, mut emu)) = boot() else {
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
    let Some((_one, mut emu)) = boot() else {
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
        check!(
            emu,
            phases == ["soften", "bend", "lock", "release"],
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
    let Some((_one, mut emu)) = boot() else {
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
    let Some((_one, mut emu)) = boot() else {
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
        (
            "SIM FAULT heater-open pla",
            "alarm: heater-not-heating pla",
            "SIM CLEAR",
        ),
    ] {
        emu.command("MORPH 38", REPLY).unwrap();
        emu.wait_for("event: phase soften", MORPH_WALL).unwrap();
        emu.command(inject, REPLY).unwrap();
        emu.wait_for(alarm, MORPH_WALL).unwrap();
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

#[test]
fn overlong_and_garbage_lines_get_errors() {
    let Some((_one, mut emu)) = boot() else {
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

#[test]
fn a_panic_turns_heaters_off_and_ends_qemu_with_failure() {
    let Some((_one, mut emu)) = boot() else {
        return;
    };
    emu.command("MORPH 38", REPLY).unwrap();
    emu.wait_for("event: phase bend", MORPH_WALL).unwrap();
    emu.write_raw(b"SIM PANIC\n").unwrap();
    let mut status = None;
    for _ in 0..100 {
        if let Some(s) = emu.exited() {
            status = Some(s);
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let status = status.expect("QEMU must exit after a panic");
    check!(emu, status.code() == Some(1), "exit status {status}");
    let report = emu.report();
    assert!(
        report.contains("panic:") && report.contains("heaters off"),
        "{report}"
    );
}
