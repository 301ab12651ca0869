//! The invariant of the protocol module: it is the only code that writes wire text. Every
//! other source file of the core, the rig, the plant and the boards passes values to
//! `morphlink::protocol::reply` instead of writing `ok ...`, `error: ...`, `data: ...`,
//! `event: ...` or `alarm: ...` literals (and the protocol version is written only there).
//! Unit tests (after a file's `#[cfg(test)]`) may spell replies out to check them.
//!
//! One file outside `src/protocol/` is exempt: `plant/src/wire.rs`, the plant protocol's one
//! home (the rig-to-plant lines `hello`/`step`/`set` and the plant's `ok ...`/`error: ...`).
//! It is another protocol, not the controller's, and writes none of the controller's lines.

use std::fs;
use std::path::{Path, PathBuf};

/// String literals that would be wire text.
const FORBIDDEN: [&str; 7] = [
    "\"ok\"",
    "\"ok ",
    "\"error:",
    "\"data:",
    "\"event:",
    "\"alarm:",
    "protocol=",
];

/// Every `.rs` file under `dir`, recursively, except those under `skip`.
fn rust_files(dir: &Path, skip: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    for entry in entries {
        let path = entry.unwrap().path();
        if path.starts_with(skip) {
            continue;
        }
        if path.is_dir() {
            rust_files(&path, skip, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// Lines of `text` before its test module, without `//` comments.
fn code_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines()
        .enumerate()
        .take_while(|(_, l)| l.trim() != "#[cfg(test)]")
        .map(|(i, l)| (i + 1, l.trim_start()))
        .filter(|(_, l)| !l.starts_with("//"))
}

#[test]
fn only_the_protocol_module_writes_wire_text() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let protocol = root.join("src").join("protocol");
    let mut files = Vec::new();
    for dir in ["src", "sim/src", "plant/src", "boards"] {
        rust_files(&root.join(dir), &protocol, &mut files);
    }
    assert!(
        files.iter().any(|f| f.ends_with("controller.rs")),
        "scanned {files:?}"
    );
    // The plant protocol's one home (see the module doc): its own `ok`/`error:` lines.
    let plant_wire = root.join("plant").join("src").join("wire.rs");
    assert!(files.contains(&plant_wire), "scanned {files:?}");
    files.retain(|f| *f != plant_wire);
    let mut found = Vec::new();
    for file in &files {
        let text = fs::read_to_string(file).unwrap();
        for (n, line) in code_lines(&text) {
            if let Some(pat) = FORBIDDEN.iter().find(|p| line.contains(*p)) {
                found.push(format!("{}:{n}: {pat} in `{line}`", file.display()));
            }
        }
    }
    assert!(
        found.is_empty(),
        "wire text outside src/protocol/ (use morphlink::protocol::reply):\n{}",
        found.join("\n")
    );
}

#[test]
fn the_scanner_finds_wire_text() {
    let text =
        "fn f() {\n    out(\"ok\");\n    // \"error: in a comment\"\n}\n#[cfg(test)]\n\"ok \"\n";
    let hits: Vec<usize> = code_lines(text)
        .filter(|(_, l)| FORBIDDEN.iter().any(|p| l.contains(p)))
        .map(|(n, _)| n)
        .collect();
    assert_eq!(hits, [2]);
}
