//! Docs that cannot drift: every output block in the README and `docs/*.md` that is marked with
//! the commands that print it is compared with what those commands print now.
//!
//! A marker is an HTML comment right before a fenced block:
//!
//! ```text
//! <!-- check
//! morph-sim --speed max < "MORPH 38\n"
//! tol 0.05
//! -->
//! ```
//!
//! Each line is one command (a binary of this crate and its arguments, split on spaces; `< "..."`
//! gives its standard input, `\n` for a newline), run from the workspace root; the expected text
//! is their standard output then standard error, in order. `tol X` lets every number differ by up
//! to X (for timings); without it numbers must match exactly. Lines of the block that start with
//! `$ ` (a shown command) are not output. A block line `...` stands for any lines (none
//! included), and a line ending in ` ...` for any line that begins as it does. `wall` leaves out
//! the seconds of morphctl's `[wall N s]` stamps (the wall clock is not reproducible).
//! `file NAME` writes the here-document `cat > NAME <<'END' ... END` of the `sh` block before
//! the marker into a scratch folder, and runs the block's commands there, so a script shown is
//! the script run. `emulate --morph MM` is `cargo xtask emulate --morph MM` in-process (the
//! real image under QEMU; skipped, loudly, with `MORPHLINK_SKIP_EMULATOR` and no QEMU).
//! `MORPHLINK_BLESS=1 cargo test -p morphlink-host --test docs` rewrites each marked block with
//! the output of today's commands.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

/// One command of a marker.
#[derive(Debug, PartialEq)]
struct Cmd {
    bin: String,
    args: Vec<String>,
    stdin: String,
}

/// One marked block.
#[derive(Debug)]
struct Block {
    /// 1-based line of the marker.
    line: usize,
    cmds: Vec<Cmd>,
    tol: f64,
    /// Leave out the seconds of `[wall N s]` stamps.
    wall: bool,
    /// Files to write before the commands run (name, text), from `file NAME`.
    files: Vec<(String, String)>,
    /// 0-based line range of the block's content (between the fences).
    body: std::ops::Range<usize>,
}

fn parse_cmd(line: &str) -> Result<Cmd, String> {
    let (cmd, stdin) = match line.split_once(" < ") {
        Some((c, s)) => {
            let s = s.trim();
            let s = s
                .strip_prefix('"')
                .and_then(|s| s.strip_suffix('"'))
                .ok_or_else(|| format!("stdin must be quoted: {line}"))?;
            (c, s.replace("\\n", "\n"))
        }
        None => (line, String::new()),
    };
    let mut words = cmd.split_whitespace().map(str::to_string);
    let bin = words.next().ok_or("empty command")?;
    Ok(Cmd {
        bin,
        args: words.collect(),
        stdin,
    })
}

fn blocks_in(file: &Path) -> Result<Vec<Block>, String> {
    let text = std::fs::read_to_string(file).map_err(|e| e.to_string())?;
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        if lines[i].trim() != "<!-- check" {
            i += 1;
            continue;
        }
        let line = i + 1;
        let (mut cmds, mut tol, mut wall, mut files) = (Vec::new(), 0.0, false, Vec::new());
        i += 1;
        while i < lines.len() && lines[i].trim() != "-->" {
            let l = lines[i].trim();
            if let Some(t) = l.strip_prefix("tol ") {
                tol = t.parse().map_err(|e| format!("line {}: tol: {e}", i + 1))?;
            } else if l == "wall" {
                wall = true;
            } else if let Some(name) = l.strip_prefix("file ") {
                let text = heredoc(&lines[..line], name.trim()).ok_or_else(|| {
                    format!(
                        "{}:{}: no `cat > {name} <<'END'` here-document before the marker",
                        file.display(),
                        i + 1
                    )
                })?;
                files.push((name.trim().to_string(), text));
            } else if !l.is_empty() {
                cmds.push(parse_cmd(l).map_err(|e| format!("line {}: {e}", i + 1))?);
            }
            i += 1;
        }
        i += 1;
        if i >= lines.len() || !lines[i].starts_with("```") {
            return Err(format!(
                "{}:{line}: a check marker must be followed by a fenced block",
                file.display()
            ));
        }
        let start = i + 1;
        let mut end = start;
        while end < lines.len() && !lines[end].starts_with("```") {
            end += 1;
        }
        out.push(Block {
            line,
            cmds,
            tol,
            wall,
            files,
            body: start..end,
        });
        i = end + 1;
    }
    Ok(out)
}

/// The text of the last here-document `cat > NAME <<'END'` ... `END` in `lines`.
fn heredoc(lines: &[&str], name: &str) -> Option<String> {
    let open = format!("cat > {name} <<'END'");
    let start = lines.iter().rposition(|l| l.trim() == open)? + 1;
    let len = lines[start..].iter().position(|l| l.trim() == "END")?;
    Some(
        lines[start..start + len]
            .iter()
            .map(|l| format!("{l}\n"))
            .collect(),
    )
}

fn binary(name: &str) -> Option<&'static str> {
    match name {
        "morph-sim" => Some(env!("CARGO_BIN_EXE_morph-sim")),
        "morph-model" => Some(env!("CARGO_BIN_EXE_morph-model")),
        "morphctl" => Some(env!("CARGO_BIN_EXE_morphctl")),
        _ => None,
    }
}

/// `emulate --morph MM`: the emulated image's demo morph, as `cargo xtask emulate` prints it;
/// `None` when QEMU is missing and skipping the emulator was asked for.
fn emulate(args: &[String]) -> Result<Option<Vec<String>>, String> {
    use morphlink_host::emulator::{build_image, demo_morph, find_qemu};
    let radius_mm: f32 = match args {
        [flag, mm] if flag == "--morph" => mm.parse().map_err(|e| format!("--morph {mm}: {e}"))?,
        _ => return Err(format!("emulate takes `--morph MM`, not {args:?}")),
    };
    let qemu = match find_qemu() {
        Ok(q) => q,
        Err(e) if std::env::var_os("MORPHLINK_SKIP_EMULATOR").is_some() => {
            eprintln!("\n!!!!! EMULATED DOC BLOCK SKIPPED (MORPHLINK_SKIP_EMULATOR): {e} !!!!!\n");
            return Ok(None);
        }
        Err(e) => return Err(format!("{e}\n(set MORPHLINK_SKIP_EMULATOR=1 to skip it)")),
    };
    let ws = morphlink_host::workspace::Workspace::containing(&root())?;
    let image = build_image(&ws.root, &ws.target_dir.join("emulated"))?;
    let mut out = Vec::new();
    demo_morph(&qemu, &image, radius_mm, &mut |l| out.push(l.to_string()))?;
    Ok(Some(out))
}

/// What the block's commands print now, stdout then stderr per command; `None` for a block
/// that cannot run here (the emulator skipped).
fn run(b: &Block) -> Result<Option<Vec<String>>, String> {
    let mut out = Vec::new();
    let dir = if b.files.is_empty() {
        root()
    } else {
        let d =
            std::env::temp_dir().join(format!("morphlink-docs-{}-{}", std::process::id(), b.line));
        std::fs::create_dir_all(&d).map_err(|e| e.to_string())?;
        for (name, text) in &b.files {
            std::fs::write(d.join(name), text).map_err(|e| e.to_string())?;
        }
        d
    };
    for c in &b.cmds {
        if c.bin == "emulate" {
            match emulate(&c.args)? {
                Some(lines) => out.extend(lines),
                None => return Ok(None),
            }
            continue;
        }
        let bin = binary(&c.bin).ok_or_else(|| format!("no binary `{}` to check with", c.bin))?;
        let mut child = Command::new(bin)
            .args(&c.args)
            .current_dir(&dir)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| format!("{}: {e}", c.bin))?;
        use std::io::Write;
        child
            .stdin
            .take()
            .unwrap()
            .write_all(c.stdin.as_bytes())
            .map_err(|e| e.to_string())?;
        let o = child.wait_with_output().map_err(|e| e.to_string())?;
        for stream in [&o.stdout, &o.stderr] {
            out.extend(String::from_utf8_lossy(stream).lines().map(str::to_string));
        }
    }
    if !b.files.is_empty() {
        let _ = std::fs::remove_dir_all(&dir);
    }
    Ok(Some(out))
}

/// A line cut into text and numbers: the text must match, the numbers within a tolerance.
#[derive(Debug, PartialEq)]
enum Piece {
    Text(String),
    Num(f64),
}

fn pieces(line: &str) -> Vec<Piece> {
    let b: Vec<char> = line.chars().collect();
    let mut out = Vec::new();
    let mut text = String::new();
    let mut i = 0;
    while i < b.len() {
        // A number starts a token: digits inside a word (`fv96`, `r_tt2`) are text.
        let free = i == 0 || !(b[i - 1].is_alphanumeric() || b[i - 1] == '_');
        let starts_number =
            b[i].is_ascii_digit() || (b[i] == '-' && i + 1 < b.len() && b[i + 1].is_ascii_digit());
        if starts_number && free {
            let mut j = i + 1;
            while j < b.len()
                && (b[j].is_ascii_digit()
                    || (b[j] == '.' && j + 1 < b.len() && b[j + 1].is_ascii_digit()))
            {
                j += 1;
            }
            let s: String = b[i..j].iter().collect();
            if let Ok(v) = s.parse::<f64>() {
                if !text.is_empty() {
                    out.push(Piece::Text(std::mem::take(&mut text)));
                }
                out.push(Piece::Num(v));
                i = j;
                continue;
            }
        }
        text.push(b[i]);
        i += 1;
    }
    if !text.is_empty() {
        out.push(Piece::Text(text));
    }
    out
}

fn lines_match(want: &str, got: &str, tol: f64) -> bool {
    let num = |x: f64, y: f64| (x - y).abs() <= tol + 1e-9 * x.abs();
    if let Some(prefix) = want.strip_suffix(" ...") {
        // Every piece of the prefix as it is, the last text piece only as a beginning.
        let (w, g) = (pieces(prefix), pieces(got));
        return g.len() >= w.len()
            && w.iter()
                .zip(&g)
                .enumerate()
                .all(|(k, (a, b))| match (a, b) {
                    (Piece::Text(x), Piece::Text(y)) if k + 1 == w.len() => {
                        y.starts_with(x.as_str())
                    }
                    (Piece::Text(x), Piece::Text(y)) => x == y,
                    (Piece::Num(x), Piece::Num(y)) => num(*x, *y),
                    _ => false,
                });
    }
    let (w, g) = (pieces(want), pieces(got));
    w.len() == g.len()
        && w.iter().zip(&g).all(|(a, b)| match (a, b) {
            (Piece::Text(x), Piece::Text(y)) => x == y,
            (Piece::Num(x), Piece::Num(y)) => num(*x, *y),
            _ => false,
        })
}

/// `[wall 12.345 s]` as `[wall s]`: the wall clock's seconds are not compared.
fn without_wall(line: &str) -> String {
    match (line.find("[wall "), line.find(" s]")) {
        (Some(a), Some(b)) if a < b => format!("{}[wall s]{}", &line[..a], &line[b + 3..]),
        _ => line.to_string(),
    }
}

/// The documented lines against the printed ones: `...` takes any lines (none included).
fn block_matches(want: &[String], got: &[String], tol: f64) -> bool {
    match want.split_first() {
        None => got.is_empty(),
        Some((w, rest)) if w.trim() == "..." => {
            (0..=got.len()).any(|k| block_matches(rest, &got[k..], tol))
        }
        Some((w, rest)) => {
            !got.is_empty() && lines_match(w, &got[0], tol) && block_matches(rest, &got[1..], tol)
        }
    }
}

fn doc_files() -> Vec<PathBuf> {
    let mut files = vec![root().join("README.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root().join("docs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "md"))
        .collect();
    docs.sort();
    files.extend(docs);
    files
}

#[test]
fn numbers_and_words_are_compared_apart() {
    assert!(lines_match(
        "event: done t=23.4 radius_mm=38.00",
        "event: done t=23.45 radius_mm=38.00",
        0.1
    ));
    assert!(!lines_match(
        "event: done t=23.4 radius_mm=38.00",
        "event: done t=23.0 radius_mm=38.00",
        0.1
    ));
    assert!(!lines_match(
        "event: done t=23.4",
        "event: dune t=23.4",
        1.0
    ));
    assert!(lines_match(
        "at -33.76 mm, x -2.49..24.17",
        "at -33.76 mm, x -2.49..24.17",
        0.0
    ));
    // Digits inside a word are text: `fv96` is a name.
    assert_eq!(
        pieces("fv96+cosserat -1.5"),
        vec![Piece::Text("fv96+cosserat ".into()), Piece::Num(-1.5)]
    );
    // A line ending in ` ...` is a beginning; `...` alone any lines, none included.
    assert!(lines_match(
        "alarm: heater-not-heating tca ...",
        "alarm: heater-not-heating tca rose 1.2 K",
        0.0
    ));
    assert!(!lines_match(
        "alarm: heater-not-heating pla ...",
        "alarm: heater-not-heating tca rose 1.2 K",
        0.0
    ));
    let v = |s: &[&str]| s.iter().map(|l| l.to_string()).collect::<Vec<_>>();
    assert!(block_matches(
        &v(&["a", "...", "d"]),
        &v(&["a", "b", "c", "d"]),
        0.0
    ));
    assert!(block_matches(&v(&["a", "...", "d"]), &v(&["a", "d"]), 0.0));
    assert!(!block_matches(
        &v(&["a", "...", "d"]),
        &v(&["a", "b", "c"]),
        0.0
    ));
    assert!(!block_matches(&v(&["a", "b"]), &v(&["a", "b", "c"]), 0.0));
    assert_eq!(
        without_wall("[wall     0.930 s] > SIM CLEAR"),
        "[wall s] > SIM CLEAR"
    );
    assert_eq!(
        heredoc(
            &[
                "x",
                "cat > s.txt <<'END'",
                "MORPH 38",
                "wait done",
                "END",
                "y"
            ],
            "s.txt"
        )
        .as_deref(),
        Some("MORPH 38\nwait done\n")
    );
    assert_eq!(
        parse_cmd(r#"morph-sim --speed max < "MORPH 38\n""#).unwrap(),
        Cmd {
            bin: "morph-sim".into(),
            args: vec!["--speed".into(), "max".into()],
            stdin: "MORPH 38\n".into()
        }
    );
}

#[test]
fn documented_outputs_match_the_commands() {
    let bless = std::env::var_os("MORPHLINK_BLESS").is_some();
    let mut failures = Vec::new();
    let mut checked = 0;
    for file in doc_files() {
        let blocks = blocks_in(&file).unwrap();
        if blocks.is_empty() {
            continue;
        }
        let text = std::fs::read_to_string(&file).unwrap();
        let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
        // From the last block up, so a rewrite keeps the earlier blocks' line numbers.
        for b in blocks.iter().rev() {
            checked += 1;
            let Some(got) = run(b).unwrap_or_else(|e| panic!("{}:{}: {e}", file.display(), b.line))
            else {
                continue;
            };
            let shown: Vec<String> = lines[b.body.clone()]
                .iter()
                .filter(|l| l.starts_with("$ "))
                .cloned()
                .collect();
            let want: Vec<&String> = lines[b.body.clone()]
                .iter()
                .filter(|l| !l.starts_with("$ "))
                .collect();
            let fix = |l: &String| if b.wall { without_wall(l) } else { l.clone() };
            let want_cmp: Vec<String> = want.iter().map(|l| fix(l)).collect();
            let got_cmp: Vec<String> = got.iter().map(fix).collect();
            let ok = block_matches(&want_cmp, &got_cmp, b.tol);
            if !ok {
                failures.push(format!(
                    "{}:{}: `{}` prints\n{}\nbut the doc shows\n{}",
                    file.display(),
                    b.line,
                    b.cmds
                        .iter()
                        .map(|c| format!("{} {}", c.bin, c.args.join(" ")))
                        .collect::<Vec<_>>()
                        .join("; "),
                    got.join("\n"),
                    want.iter()
                        .map(|s| s.as_str())
                        .collect::<Vec<_>>()
                        .join("\n")
                ));
                if bless {
                    let mut new = shown;
                    new.extend(got);
                    lines.splice(b.body.clone(), new);
                }
            }
        }
        if bless {
            let mut t = lines.join("\n");
            t.push('\n');
            std::fs::write(&file, t).unwrap();
        }
    }
    assert!(
        failures.is_empty() || bless,
        "{} documented outputs no longer match (rerun with MORPHLINK_BLESS=1 to rewrite them, then \
         check the prose around them):\n\n{}",
        failures.len(),
        failures.join("\n\n")
    );
    assert!(checked >= 4, "only {checked} marked blocks found");
}

/// The README's `## <heading>` section, up to the next `## ` heading.
fn readme_section(heading: &str) -> String {
    let text = std::fs::read_to_string(root().join("README.md")).unwrap();
    let start = text
        .find(&format!("\n## {heading}\n"))
        .unwrap_or_else(|| panic!("README.md has no \"## {heading}\" heading"));
    let body = &text[start + 1..];
    let end = body[3..].find("\n## ").map_or(body.len(), |e| e + 3);
    body[..end].to_string()
}

/// The Layout table's rows: the backticked paths of the first column, and the row's text.
fn layout_rows() -> Vec<(Vec<String>, String)> {
    readme_section("Layout")
        .lines()
        .filter(|l| l.starts_with("| `"))
        .map(|l| {
            let first = l.split(" | ").next().unwrap();
            let paths = first
                .split('`')
                .skip(1)
                .step_by(2)
                .map(str::to_string)
                .collect();
            (paths, l.to_string())
        })
        .collect()
}

/// The README is a front door: a page or two, the rest in `docs/`.
#[test]
fn the_readme_stays_short() {
    let lines = std::fs::read_to_string(root().join("README.md"))
        .unwrap()
        .lines()
        .count();
    assert!(
        lines <= 220,
        "README.md has {lines} lines; keep it under about 200 and move detail to docs/"
    );
}

/// Every top-level directory of the checkout (and every workspace member) has a row in the
/// README's Layout table, and every path the table lists exists.
#[test]
fn the_readme_layout_matches_the_tree() {
    let rows = layout_rows();
    let listed: Vec<&String> = rows.iter().flat_map(|(p, _)| p).collect();
    assert!(!listed.is_empty(), "README.md: no Layout rows found");
    for p in &listed {
        assert!(
            root().join(p).exists(),
            "README.md Layout lists `{p}`, which does not exist"
        );
    }
    let mut dirs: Vec<String> = std::fs::read_dir(root())
        .unwrap()
        .map(|e| e.unwrap())
        .filter(|e| e.file_type().unwrap().is_dir())
        .map(|e| e.file_name().into_string().unwrap())
        // Hidden folders (git, cargo's and CI's configuration) and the build output.
        .filter(|n| !n.starts_with('.') && n != "target")
        .collect();
    let manifest = std::fs::read_to_string(root().join("Cargo.toml")).unwrap();
    let members = manifest
        .lines()
        .find_map(|l| l.trim().strip_prefix("members = "))
        .expect("Cargo.toml: no workspace members line");
    dirs.extend(members.split('"').skip(1).step_by(2).map(str::to_string));
    dirs.sort();
    dirs.dedup();
    for d in dirs {
        assert!(
            listed.iter().any(|p| p.trim_end_matches('/') == d),
            "README.md Layout has no row for `{d}/`"
        );
    }
}

/// Every `cargo xtask` subcommand (xtask's `enum Task`) is named in the Layout's `xtask/` row.
#[test]
fn the_readme_layout_names_every_xtask() {
    let main = std::fs::read_to_string(root().join("xtask/src/main.rs")).unwrap();
    let body = main
        .split_once("enum Task {")
        .expect("xtask/src/main.rs: no `enum Task`")
        .1;
    let body = &body[..body.find("\n}").unwrap()];
    let tasks: Vec<String> = body
        .lines()
        .map(str::trim)
        .filter(|l| l.starts_with(|c: char| c.is_ascii_uppercase()))
        .map(|l| {
            let name: String = l.chars().take_while(|c| c.is_alphanumeric()).collect();
            // clap's default: CamelCase to kebab-case.
            let mut kebab = String::new();
            for (i, c) in name.chars().enumerate() {
                if c.is_ascii_uppercase() && i > 0 {
                    kebab.push('-');
                }
                kebab.push(c.to_ascii_lowercase());
            }
            kebab
        })
        .collect();
    assert!(tasks.len() >= 5, "only {tasks:?} found in enum Task");
    let rows = layout_rows();
    let (_, row) = rows
        .iter()
        .find(|(p, _)| p.iter().any(|p| p == "xtask/"))
        .expect("README.md Layout has no `xtask/` row");
    for t in tasks {
        assert!(
            row.contains(&format!("`{t}`")) || row.contains(&format!("`cargo xtask {t}`")),
            "README.md Layout's xtask row does not name `{t}`"
        );
    }
}

/// `.ci/run` runs the README's test command (the first command of its "Test" section).
#[test]
fn ci_runs_the_readme_test_command() {
    let section = readme_section("Test");
    let cmd = section
        .split("```sh\n")
        .nth(1)
        .and_then(|b| b.lines().next())
        .expect("README.md \"Test\": no ```sh block")
        .trim();
    assert!(
        cmd.starts_with("cargo test"),
        "README.md \"Test\" runs `{cmd}`"
    );
    let ci = std::fs::read_to_string(root().join(".ci/run")).unwrap();
    assert!(
        ci.lines()
            .map(str::trim)
            // A timed stage runs its command after its name (`stage test cargo test ...`).
            .map(|l| l.strip_prefix("stage test ").unwrap_or(l))
            .any(|l| l == cmd || l.strip_prefix(cmd) == Some(" --locked")),
        ".ci/run does not run the README's test command `{cmd}`"
    );
}

/// GitHub's anchor of a heading: lower case, spaces to `-`, punctuation dropped.
fn slug(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter_map(|c| match c {
            ' ' => Some('-'),
            c if c.is_alphanumeric() || c == '-' || c == '_' => Some(c),
            _ => None,
        })
        .collect()
}

/// The anchors of a Markdown file's headings (outside fenced blocks).
fn anchors(text: &str) -> Vec<String> {
    let mut fenced = false;
    let mut out = Vec::new();
    for l in text.lines() {
        if l.starts_with("```") {
            fenced = !fenced;
        } else if !fenced && l.starts_with('#') {
            out.push(slug(l.trim_start_matches('#')));
        }
    }
    out
}

/// The targets of a Markdown file's inline links and images `[..](target)`, outside fenced
/// blocks and code spans, with their line numbers.
fn link_targets(text: &str) -> Vec<(usize, String)> {
    let mut fenced = false;
    let mut out = Vec::new();
    for (n, l) in text.lines().enumerate() {
        if l.starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if fenced {
            continue;
        }
        // Outside code spans: every other piece between backticks.
        for piece in l.split('`').step_by(2) {
            let mut rest = piece;
            while let Some(i) = rest.find("](") {
                let after = &rest[i + 2..];
                let Some(end) = after.find(')') else { break };
                out.push((n + 1, after[..end].to_string()));
                rest = &after[end..];
            }
        }
    }
    out
}

/// Every relative link in the README and `docs/*.md` (and the other Markdown files they link
/// to: ARCHITECTURE.md, boards/README.md) points to a file that exists, and an anchor into a
/// Markdown file to one of its headings.
#[test]
fn relative_links_point_to_files_that_exist() {
    let mut files = doc_files();
    files.extend([
        root().join("ARCHITECTURE.md"),
        root().join("boards/README.md"),
    ]);
    let mut broken = Vec::new();
    let mut checked = 0;
    for file in &files {
        let text = std::fs::read_to_string(file).unwrap();
        let shown = file.strip_prefix(root()).unwrap().display().to_string();
        for (line, target) in link_targets(&text) {
            if target.contains("://") || target.starts_with("mailto:") {
                continue;
            }
            checked += 1;
            let (path, anchor) = match target.split_once('#') {
                Some((p, a)) => (p, Some(a)),
                None => (target.as_str(), None),
            };
            let resolved = if path.is_empty() {
                file.clone()
            } else {
                file.parent().unwrap().join(path)
            };
            if !resolved.exists() {
                broken.push(format!("{shown}:{line}: `{target}`: no such file"));
                continue;
            }
            if let Some(a) = anchor {
                if resolved.extension().is_some_and(|x| x == "md") {
                    let t = std::fs::read_to_string(&resolved).unwrap();
                    if !anchors(&t).iter().any(|h| h == a) {
                        broken.push(format!("{shown}:{line}: `{target}`: no such heading"));
                    }
                }
            }
        }
    }
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
    assert!(checked >= 20, "only {checked} relative links found");
}

#[test]
fn link_parsing_and_anchors() {
    assert_eq!(
        link_targets("see [a](docs/a.md#x) and `[b](no.md)` and ![c](c.svg)\n```\n[d](d.md)\n```"),
        vec![(1, "docs/a.md#x".to_string()), (1, "c.svg".to_string())]
    );
    assert_eq!(slug(" Safety defaults"), "safety-defaults".to_string());
    assert_eq!(
        slug(" Scripts: one session, many commands (`morphctl run`)"),
        "scripts-one-session-many-commands-morphctl-run"
    );
}
