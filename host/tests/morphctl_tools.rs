//! morphctl's lab tools end to end: plots refused before anything starts, scripts (`run`)
//! on one simulator, the live view's exit path, bring-up on the simulator.
#![cfg(unix)]

use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const MORPHCTL: &str = env!("CARGO_BIN_EXE_morphctl");

/// A fresh directory for one test.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("morphctl-tools-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Writes an executable `sh` script.
fn script(dir: &Path, name: &str, body: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, format!("#!/bin/sh\n{body}\n")).unwrap();
    std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o755)).unwrap();
    p
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
    let _ = std::fs::remove_dir_all(&dir);
}
