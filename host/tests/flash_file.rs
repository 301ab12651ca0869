//! `morph-sim --flash-file PATH`: saved settings survive a restart, as on a board; a path that
//! cannot be the flash file is refused before anything runs.

mod common;

use common::{run_with_input, scratch, text};
use std::io::Write;
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// Runs morph-sim on `input` with `--flash-file path`; its stdout lines.
fn run(path: &Path, input: &str) -> Vec<String> {
    let args = [
        Path::new("--speed"),
        Path::new("max"),
        Path::new("--flash-file"),
        path,
    ];
    let out = run_with_input(env!("CARGO_BIN_EXE_morph-sim"), args, input.as_bytes());
    assert!(out.status.success(), "{}", text(&out.stderr));
    text(&out.stdout).lines().map(str::to_string).collect()
}

#[test]
fn a_saved_setting_survives_a_restart_and_an_unsaved_one_does_not() {
    let dir = std::env::temp_dir().join(format!("morphlink-flash-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("settings.bin");
    let _ = std::fs::remove_file(&path);

    let first = run(
        &path,
        "CONFIG SET lock_timeout_s 321\nSAVE\nCONFIG SET bend_timeout_s 222\n",
    );
    assert_eq!(
        first[0], "event: config defaults reason=absent",
        "{first:?}"
    );
    assert!(
        first.contains(&"ok saved bytes=106 erases=0".to_string()),
        "{first:?}"
    );
    assert_eq!(std::fs::metadata(&path).unwrap().len(), 4096);

    let second = run(&path, "CONFIG\n");
    assert_eq!(second[0], "event: config loaded settings=25", "{second:?}");
    assert!(
        second
            .iter()
            .any(|l| l.starts_with("data: lock_timeout_s=321.0 s")),
        "{second:?}"
    );
    assert!(
        second
            .iter()
            .any(|l| l.starts_with("data: bend_timeout_s=120.0 s")),
        "the unsaved change must not survive: {second:?}"
    );

    // A damaged file boots as the defaults, says why, and SAVE writes a good one.
    let mut image = std::fs::read(&path).unwrap();
    for b in image.iter_mut().take(200) {
        *b ^= 0xA5;
    }
    std::fs::write(&path, &image).unwrap();
    let third = run(&path, "SAVE\n");
    assert!(
        third[0].starts_with("event: config defaults reason="),
        "{third:?}"
    );
    assert!(third.iter().any(|l| l.starts_with("ok saved")), "{third:?}");
    let fourth = run(&path, "STATUS\n");
    assert_eq!(fourth[0], "event: config loaded settings=25", "{fourth:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Longest a refused run may take, s: it ends before the boot, so well under a second.
const REFUSAL_LIMIT_S: u64 = 20;

/// Runs morph-sim with `--flash-file path` on one `SAVE`, killing it if it is still running
/// after [`REFUSAL_LIMIT_S`] (a hang fails the test instead of stalling the suite).
fn run_bounded(path: &Path) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_morph-sim"))
        .arg("--speed")
        .arg("max")
        .arg("--flash-file")
        .arg(path)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let _ = child.stdin.take().unwrap().write_all(b"SAVE\n");
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > Duration::from_secs(REFUSAL_LIMIT_S) {
            child.kill().unwrap();
            let out = child.wait_with_output().unwrap();
            panic!(
                "morph-sim still running after {REFUSAL_LIMIT_S} s with --flash-file {}: {}",
                path.display(),
                text(&out.stdout)
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

/// The run was refused up front: exit code 2, nothing on stdout (no boot), and a message on
/// stderr naming the path and containing `why`.
fn assert_refused(out: &Output, path: &Path, why: &str) {
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert_eq!(text(&out.stdout), "", "the run must not start");
    assert!(err.contains(&path.display().to_string()), "{err}");
    assert!(err.contains(why), "{err}");
}

#[test]
fn a_fifo_is_refused_before_the_boot_instead_of_hanging_it() {
    let dir = scratch("morphlink-flash", "fifo");
    let path = dir.join("settings.bin");
    let made = Command::new("mkfifo").arg(&path).status().unwrap();
    assert!(made.success());
    assert_refused(&run_bounded(&path), &path, "a FIFO");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_directory_is_refused_and_leaves_no_temporary_file() {
    let dir = scratch("morphlink-flash", "dir");
    let path = dir.join("settings.bin");
    std::fs::create_dir(&path).unwrap();
    assert_refused(&run_bounded(&path), &path, "a directory");
    let entries: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
    assert_eq!(entries.len(), 1, "only the directory itself: {entries:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_read_only_file_is_refused_and_kept_even_for_root() {
    // Mode 0444 says read-only whoever runs the simulator: root could write it, but its owner
    // does not want it replaced, so it is refused on its mode.
    use std::os::unix::fs::PermissionsExt;
    let dir = scratch("morphlink-flash", "read-only");
    let path = dir.join("settings.bin");
    let image = vec![0xFFu8; 4096];
    std::fs::write(&path, &image).unwrap();
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o444)).unwrap();
    assert_refused(&run_bounded(&path), &path, "read-only");
    assert_eq!(
        std::fs::read(&path).unwrap(),
        image,
        "the file must be kept"
    );
    let mode = std::fs::metadata(&path).unwrap().permissions().mode();
    assert_eq!(mode & 0o777, 0o444, "and not replaced");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_missing_file_in_an_existing_directory_is_fine() {
    let dir = scratch("morphlink-flash", "missing");
    let path = dir.join("settings.bin");
    let out = run_bounded(&path);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let lines: Vec<String> = text(&out.stdout).lines().map(str::to_string).collect();
    assert_eq!(
        lines[0], "event: config defaults reason=absent",
        "{lines:?}"
    );
    assert!(lines[1].starts_with("ok saved"), "{lines:?}");
    assert_eq!(
        std::fs::metadata(&path).unwrap().len(),
        4096,
        "created by the SAVE"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
