//! The house's invariants that a reading of the source can hold (see ARCHITECTURE.md).

use std::fs;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Every `.rs` file below `dir`, `target/` and hidden folders skipped.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        let name = e.file_name().to_string_lossy().into_owned();
        if p.is_dir() {
            if name != "target" && !name.starts_with('.') {
                rust_files(&p, out);
            }
        } else if name.ends_with(".rs") {
            out.push(p);
        }
    }
}

/// The lines of `s` that are code, not comments.
fn code(s: &str) -> String {
    s.lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n")
}

fn sources(dir: &str) -> Vec<(PathBuf, String)> {
    let mut files = Vec::new();
    rust_files(&root().join(dir), &mut files);
    assert!(!files.is_empty(), "no sources in {dir}");
    files
        .into_iter()
        .map(|p| {
            let s = fs::read_to_string(&p).unwrap();
            (p, s)
        })
        .collect()
}

#[test]
fn no_module_is_included_by_path() {
    for (p, s) in sources(".") {
        // This file names the attribute it forbids.
        if p.ends_with("tests/layout.rs") {
            continue;
        }
        assert!(!s.contains("#[path"), "{} uses a #[path] attribute", p.display());
    }
}

/// The dependency names of a crate's manifest (all tables).
fn dependencies(manifest: &str) -> Vec<String> {
    let text = fs::read_to_string(root().join(manifest)).unwrap();
    let mut deps = Vec::new();
    let mut in_deps = false;
    for line in text.lines() {
        let l = line.trim();
        if l.starts_with('[') {
            in_deps = l.contains("dependencies");
        } else if in_deps {
            if let Some((name, _)) = l.split_once('=') {
                deps.push(name.trim().to_string());
            }
        }
    }
    deps
}

#[test]
fn the_plant_knows_no_controller() {
    let deps = dependencies("plant/Cargo.toml");
    assert!(!deps.iter().any(|d| d == "morphlink"), "{deps:?}");
    for (p, s) in sources("plant") {
        assert!(!code(&s).contains("morphlink::"), "{} names the controller", p.display());
    }
}

#[test]
fn the_boards_know_no_controller() {
    let deps = dependencies("boards/Cargo.toml");
    assert!(!deps.iter().any(|d| d == "morphlink"), "{deps:?}");
    for (p, s) in sources("boards") {
        assert!(!code(&s).contains("morphlink::"), "{} names the controller", p.display());
    }
}

#[test]
fn the_core_touches_no_hardware() {
    for (p, s) in sources("src") {
        if p.ends_with("main.rs") || p.ends_with("emulated.rs") {
            continue; // the firmware shell, built for the target only
        }
        for word in ["embassy_", "cortex_m", "morphlink_boards::selected"] {
            assert!(!code(&s).contains(word), "{} uses {word}", p.display());
        }
    }
}
