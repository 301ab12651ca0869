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
//! `$ ` (a shown command) are not output. `MORPHLINK_BLESS=1 cargo test -p morphlink-host --test
//! docs` rewrites each marked block with the output of today's commands.

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
        let (mut cmds, mut tol) = (Vec::new(), 0.0);
        i += 1;
        while i < lines.len() && lines[i].trim() != "-->" {
            let l = lines[i].trim();
            if let Some(t) = l.strip_prefix("tol ") {
                tol = t.parse().map_err(|e| format!("line {}: tol: {e}", i + 1))?;
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
            body: start..end,
        });
        i = end + 1;
    }
    Ok(out)
}

fn binary(name: &str) -> Option<&'static str> {
    match name {
        "morph-sim" => Some(env!("CARGO_BIN_EXE_morph-sim")),
        "morph-model" => Some(env!("CARGO_BIN_EXE_morph-model")),
        _ => None,
    }
}

/// What the block's commands print now, stdout then stderr per command.
fn run(b: &Block) -> Result<Vec<String>, String> {
    let mut out = Vec::new();
    for c in &b.cmds {
        let bin = binary(&c.bin).ok_or_else(|| format!("no binary `{}` to check with", c.bin))?;
        let mut child = Command::new(bin)
            .args(&c.args)
            .current_dir(root())
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
    Ok(out)
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
    let (w, g) = (pieces(want), pieces(got));
    w.len() == g.len()
        && w.iter().zip(&g).all(|(a, b)| match (a, b) {
            (Piece::Text(x), Piece::Text(y)) => x == y,
            (Piece::Num(x), Piece::Num(y)) => (x - y).abs() <= tol + 1e-9 * x.abs(),
            _ => false,
        })
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
            let got = run(b).unwrap_or_else(|e| panic!("{}:{}: {e}", file.display(), b.line));
            let shown: Vec<String> = lines[b.body.clone()]
                .iter()
                .filter(|l| l.starts_with("$ "))
                .cloned()
                .collect();
            let want: Vec<&String> = lines[b.body.clone()]
                .iter()
                .filter(|l| !l.starts_with("$ "))
                .collect();
            let ok = want.len() == got.len()
                && want.iter().zip(&got).all(|(w, g)| lines_match(w, g, b.tol));
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
