//! `morph-sim --flash-file PATH`: saved settings survive a restart, as on a board.

mod common;

use common::{run_with_input, text};
use std::path::Path;

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
        first.contains(&"ok saved bytes=90 erases=0".to_string()),
        "{first:?}"
    );
    assert_eq!(std::fs::metadata(&path).unwrap().len(), 4096);

    let second = run(&path, "CONFIG\n");
    assert_eq!(second[0], "event: config loaded settings=21", "{second:?}");
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
    assert_eq!(fourth[0], "event: config loaded settings=21", "{fourth:?}");
    let _ = std::fs::remove_dir_all(&dir);
}
