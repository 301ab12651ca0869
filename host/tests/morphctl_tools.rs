//! morphctl's lab tools end to end: plots refused before anything starts, scripts (`run`)
//! on one simulator, the live view's exit path, bring-up on the simulator.
#![cfg(unix)]

mod common;

use common::script;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const MORPHCTL: &str = env!("CARGO_BIN_EXE_morphctl");

/// A fresh directory for one test.
fn scratch(name: &str) -> PathBuf {
    common::scratch("morphctl-tools", name)
}

/// Runs morphctl to its end.
fn morphctl(args: &[&str]) -> Output {
    Command::new(MORPHCTL).args(args).output().unwrap()
}

#[test]
fn a_plot_morphctl_cannot_write_is_refused_before_the_device_is_started() {
    let dir = scratch("jpg");
    let started = dir.join("started");
    let device = script(
        &dir,
        "device.sh",
        &format!("touch '{}'; cat >/dev/null", started.display()),
    );
    let out = morphctl(&[
        "--sim",
        "--sim-program",
        device.to_str().unwrap(),
        "morph",
        "38",
        "--plot",
        dir.join("run.jpg").to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("run.jpg: the plot must end in .svg or .png"),
        "{err}"
    );
    assert!(!started.exists(), "the device was started");
    assert!(!dir.join("run.jpg").exists());
    // A directory that is not there: refused at once, not after the whole morph.
    let nowhere = dir.join("no-such-dir").join("x.png");
    let out = morphctl(&[
        "--sim",
        "--sim-program",
        device.to_str().unwrap(),
        "morph",
        "38",
        "--plot",
        nowhere.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("no-such-dir does not exist"), "{err}");
    assert!(!started.exists(), "the device was started");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_plot_that_fails_to_write_fails_the_run() {
    // The directory is there when the run starts and gone at its end.
    let dir = scratch("plot-fails");
    let out_dir = dir.join("plots");
    std::fs::create_dir_all(&out_dir).unwrap();
    let device = script(
        &dir,
        "device.sh",
        &format!("rm -rf '{}'; exec '{MORPH_SIM}' \"$@\"", out_dir.display()),
    );
    let out = morphctl(&[
        "--sim",
        "--sim-speed",
        "50",
        "--sim-program",
        device.to_str().unwrap(),
        "morph",
        "38",
        "--plot",
        out_dir.join("run.svg").to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    // The file and the cause, in plain words.
    let want = format!(
        "morphctl: plot: cannot write {}: the directory {} does not exist",
        out_dir.join("run.svg").display(),
        out_dir.display()
    );
    assert!(err.contains(&want), "{err}");
    assert!(!err.contains("backend error"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_sim_program_takes_arguments_the_plant_is_in_the_title_and_pipes_get_plain_lines() {
    let dir = scratch("sim-args");
    let plot = dir.join("run.svg");
    // `--speed` after the command is `--sim-speed`.
    let program = format!("'{MORPH_SIM}' --plant hifi");
    let out = morphctl(&[
        "--sim",
        "--sim-program",
        &program,
        "morph",
        "38",
        "--speed",
        "50",
        "--plot",
        plot.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stdout}{err}");
    // Not a terminal: one line per poll, no carriage returns for a `tee` log to swallow.
    assert!(!stdout.contains('\r'), "{stdout:?}");
    assert!(
        stdout.lines().filter(|l| l.contains(" s  ")).count() > 5,
        "{stdout}"
    );
    let svg = read(&plot);
    assert!(
        svg.contains("on morph-sim (plant hifi)"),
        "the plot's title names the plant"
    );
    let out = morphctl(&["--sim", "morph", "38", "--speed", "max"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("--sim-speed 100"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn morph_waits_for_the_first_sensor_reading_of_a_device_that_just_booted() {
    let dir = scratch("no-reading-yet");
    // STATUS shows no temperatures for its first three answers, and MORPH is refused until it
    // does, as the emulated image right after boot.
    let device = script(
        &dir,
        "device.sh",
        r#"n=0
while IFS= read -r line; do
  case "$line" in
    VERSION) echo "ok version=0.1.0 protocol=1" ;;
    STATUS) n=$((n+1))
      if [ $n -le 3 ]; then t=nan; else t=22.00; fi
      echo "ok phase=idle target_mm=38.00 t_pla_c=$t t_tca_c=$t t_amb_c=$t p_pla_w=0.000 p_tca_w=0.000 supply_v=12.00 fault=none" ;;
    MORPH*) if [ $n -le 3 ]; then echo "error: busy no sensor reading yet; try again in a moment"
      else echo ok; echo "event: done t=1.0 radius_mm=38.00"; fi ;;
    *) echo "error: unsupported" ;;
  esac
done"#,
    );
    // As a simulator's child, and over TCP as the emulated image serves its USART1.
    let (addr, server) = tcp_serve(device.clone(), Vec::new());
    for args in [
        vec![
            "--sim",
            "--sim-program",
            device.to_str().unwrap(),
            "morph",
            "38",
        ],
        vec!["--tcp", &addr, "morph", "38"],
    ] {
        let out = morphctl(&args);
        let stdout = String::from_utf8_lossy(&out.stdout);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(0), "{args:?}: {stdout}{err}");
        assert!(
            stdout.contains("waiting for the first sensor reading"),
            "{args:?}: {stdout}"
        );
        assert!(stdout.contains("event: done"), "{args:?}: {stdout}");
    }
    server.join().unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn calibrate_asks_again_after_an_answer_that_is_not_a_radius_and_says_it_is_not_stored() {
    let out = common::run_with_input(
        MORPHCTL,
        ["--sim", "--sim-speed", "50", "calibrate", "--radii", "38"],
        b"abc\n34,9\n38.1\n",
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stdout}{err}");
    assert!(stdout.contains("`abc` is not a radius in mm"), "{stdout}");
    assert!(stdout.contains("`34,9` is not a radius in mm"), "{stdout}");
    assert!(stdout.contains("1 measured morph(s) counted"), "{stdout}");
    // No flash file: SAVE is not tried (it would answer `error: unsupported`), and said so.
    assert!(!stdout.contains("error: unsupported"), "{stdout}");
    assert!(
        stdout.contains("not saved: this morph-sim has no flash file"),
        "{stdout}"
    );
}

/// Every number `calibrate` is given is checked before the first morph: a bad one found after
/// it would leave the calibration changed by the morphs before it.
#[test]
fn calibrate_refuses_a_bad_number_before_any_morph() {
    for args in [
        ["--radii", "34,NaN", "--measured", "34.1,40"],
        ["--radii", "34,38", "--measured", "34.1,-1"],
        ["--radii", "34", "--measured", "34.1,40"],
    ] {
        let mut all = vec!["--sim", "--sim-speed", "50", "calibrate"];
        all.extend(args);
        let out = morphctl(&all);
        let stdout = String::from_utf8_lossy(&out.stdout);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {stdout}{err}");
        assert!(!stdout.contains("calibrate: morph 1"), "{args:?}: {stdout}");
        assert!(err.starts_with("morphctl: "), "{args:?}: {err}");
    }
}

#[test]
fn tune_on_the_simulator_says_the_fit_ends_with_it_or_saves_it_to_the_flash_file() {
    let out = morphctl(&["--sim", "--sim-speed", "200", "tune"]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stdout}{err}");
    assert!(stdout.contains("event: tune done"), "{stdout}");
    assert!(
        stdout.contains("the fit is in use, not saved: this morph-sim has no flash file"),
        "{stdout}"
    );
    let dir = scratch("tune-flash");
    let flash = dir.join("link.flash");
    let out = morphctl(&[
        "--sim",
        "--sim-speed",
        "200",
        "--sim-flash-file",
        flash.to_str().unwrap(),
        "tune",
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(0), "{stdout}");
    assert!(
        stdout.contains("tune: saved to the simulator's flash file"),
        "{stdout}"
    );
    assert!(flash.is_file());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_sim_flash_file_that_is_a_fifo_is_refused_before_the_device_is_started() {
    // morph-sim refuses it too, but morphctl does not show the simulator's stderr.
    let dir = scratch("fifo");
    let started = dir.join("started");
    let device = script(
        &dir,
        "device.sh",
        &format!("touch '{}'; cat >/dev/null", started.display()),
    );
    let fifo = dir.join("link.flash");
    assert!(Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    let out = morphctl(&[
        "--sim",
        "--sim-program",
        device.to_str().unwrap(),
        "--sim-flash-file",
        fifo.to_str().unwrap(),
        "config",
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("link.flash: it is a FIFO"), "{err}");
    assert!(!started.exists(), "the device was started");
    let _ = std::fs::remove_dir_all(&dir);
}

const MORPH_SIM: &str = env!("CARGO_BIN_EXE_morph-sim");

/// morph-sim that counts its starts in `starts` and records every line to it in
/// `to_device.log` and from it in `from_device.log`.
fn counted_sim(dir: &Path) -> PathBuf {
    script(
        dir,
        "device.sh",
        &format!(
            "echo start >> '{}'; tee '{}' | '{MORPH_SIM}' \"$@\" | tee '{}'",
            dir.join("starts").display(),
            dir.join("to_device.log").display(),
            dir.join("from_device.log").display()
        ),
    )
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_default()
}

/// The device's last STATUS reply once it shows the heaters off (the recording `tee` may
/// write its file a moment after morphctl read the line), within 5 s.
fn last_status_heaters_off(dir: &Path) -> String {
    let t0 = std::time::Instant::now();
    loop {
        let from = read(&dir.join("from_device.log"));
        let last = from.lines().rfind(|l| l.starts_with("ok phase="));
        match last {
            Some(l) if heaters_off(l) => return l.to_string(),
            _ if t0.elapsed().as_secs() >= 5 => panic!("no heaters-off STATUS last:\n{from}"),
            _ => std::thread::sleep(std::time::Duration::from_millis(50)),
        }
    }
}

/// True if a STATUS line shows both heaters off in idle or fault.
fn heaters_off(status: &str) -> bool {
    status.contains(" p_pla_w=0.000 p_tca_w=0.000 ")
        && (status.starts_with("ok phase=idle ") || status.starts_with("ok phase=fault "))
}

#[test]
fn a_script_injects_a_fault_then_morphs_on_one_simulator_and_logs_every_line() {
    let dir = scratch("run");
    let device = counted_sim(&dir);
    let file = dir.join("fault-then-morph.txt");
    std::fs::write(
        &file,
        "# a dead TCA heater is caught, then a healthy morph on the same link\n\
         SIM FAULT heater-open tca\n\
         MORPH 38\n\
         wait alarm 120   # the supervisor's current check\n\
         SIM CLEAR\n\
         RESET\n\
         MORPH 40\n\
         wait done\n\
         sleep 1\n\
         SIM STATE\n",
    )
    .unwrap();
    let log = dir.join("session.log");
    let out = morphctl(&[
        "--sim",
        "--sim-speed",
        "50",
        "--sim-program",
        device.to_str().unwrap(),
        "run",
        file.to_str().unwrap(),
        "--log",
        log.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        read(&dir.join("starts")).lines().count(),
        1,
        "one simulator"
    );
    let text = read(&log);
    assert_eq!(text, stdout, "the log file is the session as printed");
    // In order: each line sent (>) and received (<), with its time.
    let mut at = 0;
    for want in [
        "> SIM FAULT heater-open tca",
        "< ok fault=heater-open target=tca",
        "> MORPH 38",
        "< alarm: heater-open tca",
        "> RESET",
        "< ok cleared=heater-open",
        "> MORPH 40",
        "< event: done ",
        "> SIM STATE",
        "< ok time_s=",
        "# script done",
    ] {
        let found = text[at..]
            .find(want)
            .unwrap_or_else(|| panic!("`{want}` missing after byte {at}:\n{text}"));
        at += found + want.len();
    }
    assert!(
        text.lines()
            .all(|l| l.starts_with("[wall ") && l[1..].contains(" s] ")),
        "{text}"
    );
    let last = text.lines().last().unwrap();
    assert!(heaters_off(&last[last.find("< ").unwrap() + 2..]), "{last}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_bad_script_is_refused_before_the_device_is_started() {
    let dir = scratch("bad-script");
    let device = counted_sim(&dir);
    let file = dir.join("typo.txt");
    std::fs::write(&file, "MORPH 38\nwait dome\n").unwrap();
    let out = morphctl(&[
        "--sim",
        "--sim-program",
        device.to_str().unwrap(),
        "run",
        file.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        err.contains("typo.txt: line 2: `wait` needs `done` or `alarm`"),
        "{err}"
    );
    assert!(!dir.join("starts").exists(), "the device was started");
    // A misspelt step is not sent as a protocol line: the core's parser refuses it first.
    std::fs::write(&file, "MORPH 38\nslep 3\nwait done\n").unwrap();
    let out = morphctl(&[
        "--sim",
        "--sim-program",
        device.to_str().unwrap(),
        "run",
        file.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        err.contains("typo.txt: line 2: `slep 3` is neither"),
        "{err}"
    );
    assert!(!dir.join("starts").exists(), "the device was started");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_script_that_fails_mid_morph_ends_in_abort_and_the_device_reports_the_heaters_off() {
    let dir = scratch("run-fails");
    let device = counted_sim(&dir);
    let file = dir.join("short-wait.txt");
    // The morph takes about 25 s of link time; the wait allows 2.
    std::fs::write(&file, "MORPH 38\nwait done 2\nSTATUS\n").unwrap();
    let out = morphctl(&[
        "--sim",
        "--sim-speed",
        "2",
        "--sim-program",
        device.to_str().unwrap(),
        "run",
        file.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(1), "{stdout}");
    assert!(
        stdout.contains("# line 2: no done within 2 s; stopping the heaters"),
        "{stdout}"
    );
    assert!(stdout.contains("heaters off: ok phase=idle"), "{stdout}");
    assert!(
        !stdout.contains("> STATUS\n"),
        "the script went on after the failure"
    );
    // Seen from the device's side: ABORT, then a STATUS with both heaters off.
    let to = read(&dir.join("to_device.log"));
    let after_abort = to
        .split("ABORT\n")
        .nth(1)
        .expect("no ABORT reached the device");
    assert!(after_abort.starts_with("STATUS"), "{to}");
    last_status_heaters_off(&dir);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn sigint_during_a_script_sleep_ends_in_abort_and_heaters_off() {
    let dir = scratch("run-sigint");
    let device = counted_sim(&dir);
    let file = dir.join("sleepy.txt");
    std::fs::write(&file, "MORPH 38\nsleep 600\n").unwrap();
    let child = Command::new(MORPHCTL)
        .args([
            "--sim",
            "--sim-speed",
            "1",
            "--sim-program",
            device.to_str().unwrap(),
            "run",
            file.to_str().unwrap(),
        ])
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until the morph is under way (the device has said `ok` to MORPH and a phase).
    let t0 = std::time::Instant::now();
    while !read(&dir.join("from_device.log")).contains("event: phase soften") {
        assert!(t0.elapsed().as_secs() < 20, "the morph never started");
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(128 + libc::SIGINT), "{stdout}");
    assert!(
        stdout.contains("interrupted by SIGINT (Ctrl-C); stopping the heaters"),
        "{stdout}"
    );
    last_status_heaters_off(&dir);
    assert!(read(&dir.join("to_device.log")).contains("ABORT"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// A TCP serial port in front of a fresh morph-sim per connection, as the emulated image
/// serves its USART1: the address and the thread serving it.
fn tcp_sim(speed: &str) -> (String, std::thread::JoinHandle<()>) {
    tcp_serve(MORPH_SIM.into(), vec!["--speed".into(), speed.into()])
}

/// A TCP serial port in front of `program` (a fresh one for the one connection it takes).
fn tcp_serve(program: PathBuf, args: Vec<String>) -> (String, std::thread::JoinHandle<()>) {
    use std::io::{Read, Write};
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    let handle = std::thread::spawn(move || {
        let (mut sock, _) = listener.accept().unwrap();
        let mut sim = Command::new(program)
            .args(args)
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let mut to_sim = sim.stdin.take().unwrap();
        let mut from_sim = sim.stdout.take().unwrap();
        let mut back = sock.try_clone().unwrap();
        let pump = std::thread::spawn(move || {
            let mut buf = [0u8; 512];
            while let Ok(n) = from_sim.read(&mut buf) {
                if n == 0 || back.write_all(&buf[..n]).is_err() {
                    break;
                }
            }
        });
        let mut buf = [0u8; 512];
        while let Ok(n) = sock.read(&mut buf) {
            if n == 0 || to_sim.write_all(&buf[..n]).is_err() {
                break;
            }
        }
        drop(to_sim);
        let _ = sim.kill();
        let _ = sim.wait();
        let _ = pump.join();
    });
    (addr, handle)
}

#[test]
fn tcp_reaches_a_serial_port_served_over_tcp_and_finds_its_sim_commands() {
    let dir = scratch("tcp");
    let (addr, server) = tcp_sim("20");
    let plot = dir.join("tcp.svg");
    let out = morphctl(&[
        "--tcp",
        &addr,
        "--tcp-speed",
        "20",
        "morph",
        "40",
        "--plot",
        plot.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("event: done"), "{stdout}");
    // SIM STATE answered over TCP: the plot has the simulated radius.
    let svg = read(&plot);
    assert!(svg.contains(&format!("on tcp:{addr}")) && svg.contains("radius (mm)"));
    server.join().unwrap();
    // Nothing listening: named as such.
    let out = morphctl(&["--tcp", &addr, "status"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1));
    assert!(err.contains(&format!("cannot connect to {addr}")), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_live_view_without_a_terminal_is_refused_before_the_device_is_started() {
    let dir = scratch("live");
    let device = counted_sim(&dir);
    for args in [
        &["morph", "38", "--live"][..],
        &["gait", "34", "42", "--live"][..],
        &["watch"][..],
    ] {
        let mut all = vec!["--sim", "--sim-program", device.to_str().unwrap()];
        all.extend_from_slice(args);
        let out = morphctl(&all);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{err}");
        assert!(err.contains("the live view needs a terminal"), "{err}");
    }
    assert!(!dir.join("starts").exists(), "the device was started");
    let _ = std::fs::remove_dir_all(&dir);
}

const MORPH_PLANT: &str = env!("CARGO_BIN_EXE_morph-plant");

/// Runs `morphctl bringup` on the simulator started by `device_body` (a `sh` script body that
/// gets morph-sim's arguments in `"$@"`); returns the exit code and stdout.
fn bringup(name: &str, device_body: &str) -> (Option<i32>, String) {
    let dir = scratch(name);
    let device = script(&dir, "device.sh", device_body);
    let out = morphctl(&[
        "--sim",
        "--sim-speed",
        "40",
        "--sim-program",
        device.to_str().unwrap(),
        "bringup",
    ]);
    let _ = std::fs::remove_dir_all(&dir);
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr),
    )
}

/// The last line: the heaters confirmed off.
fn ends_heaters_off(out: &str) {
    let last = out
        .lines()
        .rev()
        .find(|l| l.starts_with("sent ABORT"))
        .unwrap_or_else(|| panic!("no ABORT at the end:\n{out}"));
    assert!(
        heaters_off(&last[last.find("ok phase=").unwrap()..]),
        "{last}"
    );
}

#[test]
fn bringup_passes_a_healthy_link_lumped_and_hifi_and_ends_with_the_heaters_off() {
    for plant in ["lumped", "hifi"] {
        let (code, out) = bringup(
            &format!("bringup-{plant}"),
            &format!("exec '{MORPH_SIM}' \"$@\" --plant {plant}"),
        );
        assert_eq!(code, Some(0), "{plant}:\n{out}");
        for want in [
            "ok   thermistors at rest:",
            "ok   heater supply: 12.00 V",
            "ok   PLA heater warms its own thermistor",
            "ok   TCA heater warms its own thermistor",
            "ok   ambient thermistor stays put",
        ] {
            assert!(out.contains(want), "{plant}: `{want}` missing:\n{out}");
        }
        ends_heaters_off(&out);
    }
}

#[test]
fn bringup_names_swapped_thermistor_wires() {
    // The plant's pla and tca bead temperatures swapped on their way to the board's ADC: the
    // two thermistor wires on each other's inputs.
    let swap = r"sed -u -E 's/t_pla_c=([^ ]*) t_tca_c=([^ ]*)/t_pla_c=\2 t_tca_c=\1/'";
    let (code, out) = bringup(
        "bringup-swapped",
        &format!(
            "exec '{MORPH_SIM}' \"$@\" --plant-cmd \"'{MORPH_PLANT}' --plant lumped | {swap}\""
        ),
    );
    assert_eq!(code, Some(1), "{out}");
    assert!(
        out.contains("FAIL PLA and TCA swapped: the PLA heater warmed the tca thermistor"),
        "{out}"
    );
    assert!(out.contains("ok   thermistors at rest:"), "{out}");
    ends_heaters_off(&out);
}

#[test]
fn bringup_names_a_dead_heater_and_refuses_a_faulted_device() {
    // On the paper's wiring the pulses find it: no thermistor warms.
    let (code, out) = bringup(
        "bringup-dead",
        &format!("{{ echo 'SIM FAULT heater-open tca'; cat; }} | '{MORPH_SIM}' --thermistors-only \"$@\" | sed -u '/^ok fault=heater-open/d'"),
    );
    assert_eq!(code, Some(1), "{out}");
    assert!(out.contains("FAIL TCA heater warms no thermistor"), "{out}");
    assert!(
        out.contains("ok   PLA heater warms its own thermistor"),
        "{out}"
    );
    ends_heaters_off(&out);
    // A board that senses current names it at rest, before any pulse, by its alarm.
    let (code, out) = bringup(
        "bringup-dead-sensed",
        &format!("{{ echo 'SIM FAULT heater-open tca'; cat; }} | '{MORPH_SIM}' \"$@\" | sed -u '/^ok fault=heater-open/d'"),
    );
    assert_eq!(code, Some(1), "{out}");
    assert!(out.contains("heater-open"), "{out}");
    assert!(!out.contains("HEAT"), "a heater was pulsed:\n{out}");
    ends_heaters_off(&out);
    // A supply out of range trips the supervisor at rest: bring-up refuses the faulted device
    // and pulses no heater.
    let (code, out) = bringup(
        "bringup-supply",
        &format!(
            "{{ echo 'SIM SUPPLY 16'; cat; }} | '{MORPH_SIM}' \"$@\" | sed -u '/^ok supply_v=/d'"
        ),
    );
    assert_eq!(code, Some(1), "{out}");
    // The trip comes within a few ticks: before the first STATUS or during the rest readings.
    assert!(
        out.contains("bring-up stopped: the device is in phase fault, not idle: send RESET")
            || out.contains("bring-up stopped: the device left idle during the rest readings: phase fault, fault supply-out-of-range"),
        "{out}"
    );
    assert!(!out.contains("HEAT"), "a heater was pulsed:\n{out}");
    ends_heaters_off(&out);
}

#[test]
fn config_set_with_save_says_saved_once() {
    let dir = scratch("config-save");
    let flash = dir.join("link.flash");
    let out = morphctl(&[
        "--sim",
        "--sim-flash-file",
        flash.to_str().unwrap(),
        "config",
        "set",
        "lock_timeout_s",
        "500",
        "--save",
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(0), "{stdout}");
    assert!(!stdout.contains("saved=no"), "{stdout}");
    assert!(stdout.contains("ok lock_timeout_s=500.0\n"), "{stdout}");
    assert!(stdout.contains("ok saved bytes="), "{stdout}");
    assert!(
        stdout.contains("(saved: kept across a restart)"),
        "{stdout}"
    );
    // Without a flash file SAVE is refused: the set is said to last until a restart.
    let out = morphctl(&["--sim", "config", "set", "lock_timeout_s", "500", "--save"]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(1), "{stdout}");
    assert!(stdout.contains("(set, but not saved"), "{stdout}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn keys_typed_during_a_calibrate_morph_do_not_answer_its_prompt() {
    use std::io::{BufRead, BufReader, Write};
    use std::os::fd::{FromRawFd, OwnedFd};
    // stdin a terminal (a pseudo-terminal), as at a lab's keyboard: an Enter pressed during
    // the morph would skip its measurement if it reached the prompt.
    let (mut master, mut slave) = (0, 0);
    // SAFETY: openpty writes two new descriptors, owned below.
    let rc = unsafe {
        libc::openpty(
            &mut master,
            &mut slave,
            std::ptr::null_mut(),
            std::ptr::null(),
            std::ptr::null(),
        )
    };
    assert_eq!(rc, 0, "openpty: {}", std::io::Error::last_os_error());
    // SAFETY: both descriptors were just opened and nothing else owns them.
    let (master, slave) = unsafe { (OwnedFd::from_raw_fd(master), OwnedFd::from_raw_fd(slave)) };
    let mut keys = std::fs::File::from(master);
    let mut child = Command::new(MORPHCTL)
        .args(["--sim", "--sim-speed", "50", "calibrate", "--radii", "38"])
        .stdin(std::process::Stdio::from(slave))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut seen = String::new();
    let mut typed_ahead = false;
    for line in BufReader::new(child.stdout.take().unwrap()).lines() {
        let line = line.unwrap();
        seen.push_str(&line);
        seen.push('\n');
        if line.contains("event: phase bend") && !typed_ahead {
            keys.write_all(b"\n").unwrap();
            typed_ahead = true;
        }
        if line.starts_with("measured radius of this morph") {
            keys.write_all(b"38.1\n").unwrap();
        }
    }
    let status = child.wait().unwrap();
    assert!(typed_ahead, "{seen}");
    assert!(status.success(), "{seen}");
    assert!(!seen.contains("calibrate: skipped"), "{seen}");
    assert!(seen.contains("1 measured morph(s) counted"), "{seen}");
}

#[test]
fn a_morph_logs_and_plots_the_current_sense_and_older_logs_plot_as_before() {
    let dir = scratch("current-sense");
    let (csv, svg) = (dir.join("run.csv"), dir.join("run.svg"));
    let out = morphctl(&[
        "--sim",
        "morph",
        "38",
        "--speed",
        "100",
        "--log",
        csv.to_str().unwrap(),
        "--plot",
        svg.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    let log = read(&csv);
    let mut rows = log.lines();
    let header = rows.next().unwrap();
    assert!(
        header.ends_with(",mode,i_pla_a,i_tca_a,r_pla_ohm,r_tca_ohm,t_tca_self_c,cutoff"),
        "{header}"
    );
    let rows: Vec<&str> = rows.collect();
    // morph-sim senses current: the values are there once the heaters have been driven (the
    // morph's first tick may not have measured them yet), and a healthy morph keeps the supply on.
    for r in &rows {
        let cols: Vec<&str> = r.split(',').collect();
        assert_eq!(cols.len(), 19, "{r}");
        let finite = |v: &&str| v.parse::<f64>().is_ok_and(f64::is_finite);
        if ["bend", "lock"].contains(&cols[1]) {
            assert!(cols[13..18].iter().all(finite), "{r}");
        }
        assert_eq!(cols[18], "closed", "{r}");
    }
    let plot = read(&svg);
    for want in ["TCA (own resistance)", "heater current (A)"] {
        assert!(plot.contains(want), "`{want}` not in the plot");
    }

    // `morphctl plot` reads the logs of older morphctls (before the current sense: 13 columns;
    // before the targets: 9) and draws them as it did.
    for (name, header, columns) in [
        (
            "v2",
            "t_s,phase,t_pla_c,t_tca_c,t_amb_c,p_pla_w,p_tca_w,supply_v,radius_mm,target_mm,pla_target_c,tca_target_c,mode",
            13,
        ),
        (
            "v1",
            "t_s,phase,t_pla_c,t_tca_c,t_amb_c,p_pla_w,p_tca_w,supply_v,radius_mm",
            9,
        ),
    ] {
        let old = dir.join(format!("{name}.csv"));
        let body: Vec<String> = rows
            .iter()
            .map(|r| r.split(',').take(columns).collect::<Vec<_>>().join(","))
            .collect();
        std::fs::write(&old, format!("{header}\n{}\n", body.join("\n"))).unwrap();
        let out_svg = dir.join(format!("{name}.svg"));
        let out = morphctl(&["plot", old.to_str().unwrap(), out_svg.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(0), "{name}: {err}");
        let plot = read(&out_svg);
        assert!(plot.contains("power (W)") && plot.contains("radius (mm)"), "{name}");
        for gone in ["TCA (own resistance)", "heater current (A)"] {
            assert!(!plot.contains(gone), "{name}: `{gone}` drawn from an older log");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_running_line_and_the_log_say_when_an_alarm_opens_the_cutoff() {
    let dir = scratch("cutoff-open");
    // morph-sim whose TCA heater dies as the morph starts (at idle its probe pulses would
    // name it before MORPH); the fault's own `ok` is dropped, so morphctl sees no extra reply.
    let device = script(
        &dir,
        "device.sh",
        &format!(
            "while IFS= read -r l; do printf '%s\\n' \"$l\"; case \"$l\" in \
             'MORPH '*) echo 'SIM FAULT heater-open tca';; esac; done \
             | '{MORPH_SIM}' \"$@\" | grep --line-buffered -v '^ok fault=heater-open'"
        ),
    );
    let csv = dir.join("run.csv");
    let out = morphctl(&[
        "--sim",
        "--sim-program",
        device.to_str().unwrap(),
        "morph",
        "38",
        "--speed",
        "50",
        "--log",
        csv.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stdout}{err}");
    assert!(stdout.contains("alarm: heater-open tca"), "{stdout}");
    // The running line is printed once more after the alarm, from a STATUS that follows it.
    let mut running = stdout.lines().filter(|l| l.contains(" s  "));
    let last = running.next_back().unwrap();
    assert!(
        last.contains(" fault ") && last.ends_with(" W  cutoff=open"),
        "{stdout}"
    );
    let log = read(&csv);
    let last = log.lines().last().unwrap();
    assert!(last.ends_with(",open"), "{log}");
    // The dead heater carries no current.
    let i_tca_a: f64 = last.split(',').nth(14).unwrap().parse().unwrap();
    assert!(i_tca_a < 0.05, "{log}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `gait` on two simulated links under a budget of one soften: link 2 waits, both finish,
/// the log has a row per link per poll with the supply's total never over the budget, and
/// `plot` reads the log back; a device of one link is told it needs several.
#[test]
fn a_gait_logs_a_row_per_link_under_its_budget_and_plots_it() {
    let dir = scratch("gait");
    let csv = dir.join("gait.csv");
    let svg = dir.join("gait.svg");
    let out = morphctl(&[
        "--sim",
        "--sim-links",
        "2",
        "--sim-speed",
        "100",
        "gait",
        "34",
        "42",
        "--budget-w",
        "5",
        "--log",
        csv.to_str().unwrap(),
        "--plot",
        svg.to_str().unwrap(),
    ]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("@2 event: queued "), "{text}");
    assert!(
        text.contains("@1 event: done ") && text.contains("@2 event: done "),
        "{text}"
    );
    let log = std::fs::read_to_string(&csv).unwrap();
    let mut lines = log.lines();
    assert!(lines.next().unwrap().starts_with("link,t_s,phase,"));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert!(rows.len() >= 10, "{log}");
    assert_eq!(
        rows.iter().filter(|r| r[0] == "1").count(),
        rows.len() / 2,
        "{log}"
    );
    // Link 2 waits for the budget: its rows say so until it starts.
    assert!(
        rows.iter().any(|r| r[0] == "2" && r[2] == "queued"),
        "{log}"
    );
    assert!(
        rows.iter().any(|r| r[0] == "2" && r[2] == "soften"),
        "{log}"
    );
    let total = rows[0].len() - 2;
    for r in &rows {
        let (t, b): (f64, f64) = (r[total].parse().unwrap(), r[total + 1].parse().unwrap());
        assert!(t <= b + 1e-6 && b == 5.0, "{r:?}");
    }
    assert!(std::fs::read_to_string(&svg).unwrap().contains("budget"));
    let again = dir.join("again.svg");
    let out = morphctl(&["plot", csv.to_str().unwrap(), again.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    let one = morphctl(&["--sim", "--sim-speed", "100", "gait", "34"]);
    let err = String::from_utf8_lossy(&one.stderr);
    assert!(
        !one.status.success() && err.contains("a gait needs several"),
        "{err}"
    );
}

#[test]
fn a_simulator_that_exits_at_once_is_reported_with_what_it_said() {
    let program = format!("'{MORPH_SIM}' --no-such-option");
    let out = morphctl(&["--sim", "--sim-program", &program, "status"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(
            "morph-sim closed the link; it said: `error: unexpected argument '--no-such-option'"
        ),
        "{err}"
    );
    assert!(!err.contains("is this a morphlink board"), "{err}");
}

#[test]
fn a_simulator_that_hangs_is_reported_with_what_it_said_and_its_own_options_are_refused() {
    let dir = scratch("sim-hangs");
    let hang = script(&dir, "hang.sh", "echo 'stuck: no plant' >&2; exec sleep 60");
    let out = morphctl(&["--sim", "--sim-program", hang.to_str().unwrap(), "status"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("did not answer `VERSION` within 3 s; it said: `stuck: no plant`"),
        "{err}"
    );
    // What morphctl passes itself may not be in --sim-program too.
    let program = format!("'{MORPH_SIM}' --speed 5");
    let out = morphctl(&["--sim", "--sim-program", &program, "status"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("give --speed as morphctl's --sim-speed"),
        "{err}"
    );
    // A flash file morphctl does not know of would leave a TUNE's fit unsaved.
    let program = format!("'{MORPH_SIM}' --flash-file {}", dir.join("f.bin").display());
    let out = morphctl(&["--sim", "--sim-program", &program, "status"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("give --flash-file as morphctl's --sim-flash-file"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_plot_to_a_fifo_or_a_device_is_refused_before_the_device_is_started() {
    let dir = scratch("plot-fifo");
    let fifo = dir.join("p.svg");
    assert!(Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    let device = dir.join("full.svg");
    std::os::unix::fs::symlink("/dev/full", &device).unwrap();
    for out_path in [fifo.as_path(), device.as_path()] {
        let out = morphctl(&["--sim", "morph", "38", "--plot", out_path.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{err}");
        assert!(err.contains("that is not a regular file"), "{err}");
        // Refused before the simulator ran: no morph began.
        assert!(
            !String::from_utf8_lossy(&out.stdout).contains("phase"),
            "{err}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
