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
        assert!(
            !s.contains("#[path"),
            "{} uses a #[path] attribute",
            p.display()
        );
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
        assert!(
            !code(&s).contains("morphlink::"),
            "{} names the controller",
            p.display()
        );
    }
}

#[test]
fn the_boards_know_no_controller() {
    let deps = dependencies("boards/Cargo.toml");
    assert!(!deps.iter().any(|d| d == "morphlink"), "{deps:?}");
    for (p, s) in sources("boards") {
        assert!(
            !code(&s).contains("morphlink::"),
            "{} names the controller",
            p.display()
        );
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

/// The core's top-level modules and the other top-level modules each one names
/// (`crate::<module>`) outside its tests.
fn core_imports() -> std::collections::BTreeMap<String, std::collections::BTreeSet<String>> {
    let mut graph = std::collections::BTreeMap::new();
    for (p, s) in sources("src") {
        let rel = p.strip_prefix(root().join("src")).unwrap();
        let top = rel
            .iter()
            .next()
            .unwrap()
            .to_string_lossy()
            .replace(".rs", "");
        if ["main", "emulated", "lib"].contains(&top.as_str()) {
            continue;
        }
        let body = code(s.split("#[cfg(test)]").next().unwrap());
        let deps: &mut std::collections::BTreeSet<String> = graph.entry(top.clone()).or_default();
        for (i, _) in body.match_indices("crate::") {
            let name: String = body[i + 7..]
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            if name != top && !name.is_empty() {
                deps.insert(name);
            }
        }
    }
    graph
}

#[test]
fn the_core_has_no_import_cycle() {
    let graph = core_imports();
    assert!(
        graph.contains_key("controller") && graph.contains_key("vocab"),
        "{graph:?}"
    );
    // Depth-first search for a back edge.
    fn visit(
        m: &str,
        graph: &std::collections::BTreeMap<String, std::collections::BTreeSet<String>>,
        path: &mut Vec<String>,
        done: &mut std::collections::BTreeSet<String>,
    ) {
        if done.contains(m) {
            return;
        }
        if let Some(at) = path.iter().position(|p| p == m) {
            panic!("import cycle: {} -> {m}", path[at..].join(" -> "));
        }
        path.push(m.to_string());
        for d in graph.get(m).into_iter().flatten() {
            visit(d, graph, path, done);
        }
        path.pop();
        done.insert(m.to_string());
    }
    let mut done = Default::default();
    for m in graph.keys() {
        visit(m, &graph, &mut Vec::new(), &mut done);
    }
}

#[test]
fn the_supervisor_imports_no_strategy_and_the_vocabulary_nothing() {
    let graph = core_imports();
    let sup = &graph["supervisor"];
    for m in ["strategy", "sequencer", "controller"] {
        assert!(!sup.contains(m), "the supervisor imports {m}: {sup:?}");
    }
    assert!(
        graph["vocab"].is_empty(),
        "vocab imports {:?}",
        graph["vocab"]
    );
}

/// The supervisor's budget (issue 27): at most 800 lines of code (comments, blank lines and
/// tests apart) and at most 25 named constants, each of which its module explains and
/// range-checks.
#[test]
fn the_supervisor_stays_within_its_code_and_constant_budget() {
    let (mut lines, mut consts) = (0, Vec::new());
    for (p, s) in sources("src/supervisor") {
        let body = s.split("#[cfg(test)]").next().unwrap();
        for l in code(body).lines().map(str::trim) {
            if l.is_empty() {
                continue;
            }
            lines += 1;
            let named = l.strip_prefix("pub ").unwrap_or(l).strip_prefix("const ");
            if let Some(name) = named.and_then(|r| r.split(':').next()) {
                if name != "_" && name.chars().all(|c| c.is_ascii_uppercase() || c == '_') {
                    consts.push(format!("{} {name}", p.display()));
                }
            }
        }
    }
    println!(
        "supervisor: {lines} lines of code, {} constants",
        consts.len()
    );
    assert!(lines <= 800, "{lines} lines of code");
    // The sizes of the expectation's arrays (`CHANNELS`, `MEMBERS`, `LAGS`) are counts, not
    // tuned.
    let tuned: Vec<_> = consts
        .iter()
        .filter(|c| {
            !["CHANNELS", "MEMBERS", "LAGS"]
                .iter()
                .any(|n| c.ends_with(&format!(" {n}")))
        })
        .collect();
    assert!(
        tuned.len() <= 25,
        "{} tuned constants: {tuned:?}",
        tuned.len()
    );
}

/// Every snake_case name with two underscores or more that ARCHITECTURE.md, a README or a
/// page of docs/ puts in backticks (a test, a constant's or a function's name, a setting, a
/// wire field) is a word of the workspace's Rust sources: a test renamed or a constant removed
/// leaves no doc naming what no longer exists.
#[test]
fn every_name_the_docs_give_is_in_the_sources() {
    let mut files = Vec::new();
    rust_files(&root(), &mut files);
    let mut words = std::collections::HashSet::new();
    for f in &files {
        let s = fs::read_to_string(f).unwrap();
        for w in s.split(|c: char| !(c.is_ascii_alphanumeric() || c == '_')) {
            if !w.is_empty() {
                words.insert(w.to_string());
            }
        }
    }
    let mut docs = vec![
        root().join("ARCHITECTURE.md"),
        root().join("README.md"),
        root().join("boards/README.md"),
    ];
    for e in fs::read_dir(root().join("docs")).unwrap().flatten() {
        if e.path().extension().is_some_and(|x| x == "md") {
            docs.push(e.path());
        }
    }
    let is_name = |n: &str| {
        n.matches('_').count() >= 2
            && n.starts_with(|c: char| c.is_ascii_lowercase())
            && n.chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
    };
    let mut missing = Vec::new();
    let mut checked = 0;
    for d in &docs {
        let text = fs::read_to_string(d).unwrap();
        let mut fenced = false;
        for (n, line) in text.lines().enumerate() {
            if line.starts_with("```") {
                fenced = !fenced;
                continue;
            }
            if fenced {
                continue;
            }
            for span in line.split('`').skip(1).step_by(2) {
                if is_name(span) {
                    checked += 1;
                    if !words.contains(span) {
                        let shown = d.strip_prefix(root()).unwrap().display().to_string();
                        missing.push(format!("{shown}:{}: `{span}`", n + 1));
                    }
                }
            }
        }
    }
    assert!(
        checked > 50,
        "only {checked} names found: is the scan right?"
    );
    assert!(
        missing.is_empty(),
        "named in the docs, not in the sources: {missing:?}"
    );
}
