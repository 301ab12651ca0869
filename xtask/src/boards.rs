//! `cargo xtask boards`: builds the firmware for every board in `boards/` (release, one after
//! the other in the shared `target/`; the emulated board's in `target/emulated/`, where the
//! emulator tests build it) and the images of several links ([`MULTI_LINK_IMAGES`]: the
//! emulated board's two links), prints a table of flash and RAM use, and fails if an image
//! breaks its budget.
//!
//! Budgets:
//! - every image fits its board: flash ≤ the `FLASH` length of the board's `memory.x`, and
//!   static RAM plus [`STACK_RESERVE_BYTES`] ≤ its `RAM` length;
//! - the default board's image also fits a small part: [`SMALL_PART_FLASH_BYTES`] of flash for
//!   code (the part's flash less its settings area) and [`SMALL_PART_RAM_BYTES`] of RAM;
//! - every hardware board's `memory.x` has a `SETTINGS` region right after `FLASH` (the code
//!   is linked into `FLASH`, so it can never overlap the settings; its own `ASSERT` says so
//!   again at link time), of two or more erase units;
//! - every hardware board's image is at most [`HW_FLASH_BUDGET_BYTES`] of flash and
//!   [`HW_RAM_BUDGET_BYTES`] of static RAM (the emulated image carries the simulated link and a
//!   RAM flash in their place, so it only has to fit its board);
//! - no hardware image holds software double-precision arithmetic ([`is_soft_double`]: the
//!   Cortex-M4F FPU is single precision, every f64 operation is a library call) or `core`'s
//!   float text machinery ([`is_float_text`]: the core formats and parses numbers with
//!   `morphlink::fixed`).
//!
//! For the default board it also prints where the flash goes: per crate and the largest
//! symbols (from the ELF's symbol table; code generic over a task's future is named after the
//! crate of the generic, e.g. `embassy_executor`, though the body inlined in it is ours).
use morphlink_host::workspace::Workspace;
use object::elf::{SHF_ALLOC, SHF_WRITE, SHT_NOBITS};
use object::{Object, ObjectSection, ObjectSymbol, SectionFlags};
use std::path::{Path, PathBuf};

/// The default board (the `default` feature), which must also fit the small part.
pub const DEFAULT_BOARD: &str = "nucleo-f401re";
/// Flash for code on the smallest part that holds this firmware and its settings, bytes: a
/// project choice, re-based when the settings came to flash. The settings store needs two
/// equal erase units at the end of flash. On a 128 KiB STM32G431xB (2 KiB pages) that is
/// 4 KiB, leaving 124 KiB for code; on the F4s it is two sectors of 128 KiB, so the smallest
/// F401 with two equal sectors at its end is the 384 KiB STM32F401RD (sectors 5 and 6), with
/// 128 KiB for code; a 64 KiB part (G431x6) would keep 60 KiB, less than the image already
/// is (64 720 B before the settings). 124 KiB leaves the image room to grow by about half.
pub const SMALL_PART_FLASH_BYTES: u64 = 124 * 1024;
/// The settings area of every hardware board, at least: two erase units of the largest page
/// any board here has (the G431's and L475's 2 KiB).
pub const MIN_SETTINGS_BYTES: u64 = 4 * 1024;
/// RAM of that small part, bytes: the STM32G431xB's SRAM1 and SRAM2 (22 KiB; its 10 KiB CCM
/// SRAM is not used), as on the NUCLEO-G431RB. The F401RD has 96 KiB.
pub const SMALL_PART_RAM_BYTES: u64 = 22 * 1024;
/// RAM kept for the main stack on top of the static data, bytes. The tasks live in statics, so
/// the stack only holds `main`, interrupt handlers and the deepest call of a task poll
/// (`Controller::step`, or a reply with a few 192-byte lines). An estimate with a wide margin,
/// not a measurement: stable Rust cannot report stack sizes.
pub const STACK_RESERVE_BYTES: u64 = 4 * 1024;

/// Flash every hardware board's image must fit, bytes: the goal, 96 KiB.
pub const HW_FLASH_TARGET_BYTES: u64 = 96 * 1024;
/// Static RAM every hardware board's image must fit, bytes: the goal, 16 KiB.
pub const HW_RAM_TARGET_BYTES: u64 = 16 * 1024;
/// The flash budget enforced on hardware boards today, bytes (equal to
/// [`HW_FLASH_TARGET_BYTES`] once the images reach it; until then the level reached, so an
/// image can only shrink).
pub const HW_FLASH_BUDGET_BYTES: u64 = HW_FLASH_TARGET_BYTES;
/// The static-RAM budget enforced on hardware boards today, bytes (as [`HW_FLASH_BUDGET_BYTES`]).
pub const HW_RAM_BUDGET_BYTES: u64 = HW_RAM_TARGET_BYTES;
/// Software double-precision routines a hardware image may hold: none (the goal, reached:
/// the core runs its model in `f32`, `morphlink::lumped`). A list, so a routine that cannot be
/// avoided yet can be named here with its reason instead of switching the check off.
pub const SOFT_DOUBLE_TOLERATED: &[&str] = &[];
/// How many of the largest symbols the default board's report lists.
pub const TOP_SYMBOLS: usize = 15;

/// One board's image.
struct Image {
    board: String,
    /// The firmware's further features (`links-2`), shown after the board's name.
    features: &'static [&'static str],
    flash_bytes: u64,
    ram_bytes: u64,
    flash_size: u64,
    ram_size: u64,
    soft_double: Vec<String>,
    float_text: Vec<String>,
}

/// A defined symbol of an image: its name (demangled), size, and whether it takes flash
/// (code, read-only data, initial values) and RAM (`.data`, `.bss`, `.uninit`).
#[derive(Clone, Debug)]
pub struct Symbol {
    /// Demangled name, without the hash.
    pub name: String,
    /// Size, bytes.
    pub size: u64,
    /// In flash (a section with contents).
    pub flash: bool,
    /// In RAM (a writable section).
    pub ram: bool,
}

/// The image's sized symbols in allocated sections.
pub fn symbols(elf: &[u8]) -> Result<Vec<Symbol>, String> {
    let file = object::File::parse(elf).map_err(|e| format!("not an ELF: {e}"))?;
    // Symbols without a size (the machine outliner's `OUTLINED_FUNCTION_n`) reach to the next
    // symbol of their section.
    let mut starts: Vec<(object::SectionIndex, u64)> = file
        .symbols()
        .filter(|s| !s.name().is_ok_and(|n| n.starts_with('$')))
        .filter_map(|s| Some((s.section_index()?, s.address())))
        .collect();
    starts.sort_by_key(|&(i, a)| (i.0, a));
    let mut out = Vec::new();
    for sym in file.symbols() {
        let (Some(index), Ok(name)) = (sym.section_index(), sym.name()) else {
            continue;
        };
        let size = if sym.size() == 0 && name.starts_with("OUTLINED_FUNCTION") {
            let next = starts
                .iter()
                .find(|&&(i, a)| i == index && a > sym.address())
                .map(|&(_, a)| a);
            let end = file
                .section_by_index(index)
                .map(|s| s.address() + s.size())
                .unwrap_or(sym.address());
            next.unwrap_or(end).min(end) - sym.address()
        } else {
            sym.size()
        };
        if size == 0 {
            continue;
        }
        let Ok(section) = file.section_by_index(index) else {
            continue;
        };
        let SectionFlags::Elf { sh_type, sh_flags } = section.flags() else {
            continue;
        };
        if (sh_flags.0 & SHF_ALLOC.0) == 0 {
            continue;
        }
        out.push(Symbol {
            name: demangle(name),
            size,
            flash: sh_type != SHT_NOBITS,
            ram: (sh_flags.0 & SHF_WRITE.0) != 0,
        });
    }
    Ok(out)
}

/// Demangles a Rust legacy symbol (`_ZN4core3fmt9Formatter3pad17h…E` → `core::fmt::Formatter::pad`),
/// dropping the hash; other names are returned as they are.
pub fn demangle(name: &str) -> String {
    if let Some(v0) = name.strip_prefix("_R") {
        return demangle_v0_path(v0).unwrap_or_else(|| name.to_string());
    }
    let Some(mut rest) = name.strip_prefix("_ZN") else {
        return name.to_string();
    };
    let mut parts = Vec::new();
    while let Some(end) = rest.find(|c: char| !c.is_ascii_digit()) {
        if end == 0 {
            break;
        }
        let Ok(len) = rest[..end].parse::<usize>() else {
            break;
        };
        let Some(part) = rest.get(end..end + len) else {
            break;
        };
        parts.push(part);
        rest = &rest[end + len..];
    }
    if parts.is_empty() {
        return name.to_string();
    }
    if parts.len() > 1
        && parts
            .last()
            .is_some_and(|h| h.starts_with('h') && h.len() == 17)
    {
        parts.pop();
    }
    let mut joined = parts.join("::");
    for (code, text) in [
        ("$LT$", "<"),
        ("$GT$", ">"),
        ("$RF$", "&"),
        ("$BP$", "*"),
        ("$SP$", "@"),
        ("$C$", ","),
        ("$LP$", "("),
        ("$RP$", ")"),
        ("$u20$", " "),
        ("$u27$", "'"),
        ("$u5b$", "["),
        ("$u5d$", "]"),
        ("$u7b$", "{"),
        ("$u7d$", "}"),
        ("$u7e$", "~"),
        ("..", "::"),
    ] {
        joined = joined.replace(code, text);
    }
    joined
        .strip_prefix('_')
        .filter(|j| j.starts_with('<'))
        .map(str::to_string)
        .unwrap_or(joined)
}

/// The path of a Rust v0 symbol (`_RNvNtCs…_4core3f325clamp` → `core::f32::clamp`; `core` is
/// built with them): its identifiers in order, without generic arguments' types, impl
/// qualifiers or disambiguators. Enough to name the crate and the function, not a full
/// demangling.
fn demangle_v0_path(s: &str) -> Option<String> {
    let b = s.as_bytes();
    let (mut i, mut parts) = (0, Vec::new());
    while i < b.len() {
        match b[i] {
            // Crate root or disambiguator (`Cs<base62>_`, `s<base62>_`) and back-references
            // (`B<base62>_`): skip to the `_` that ends them.
            b'C' | b's' | b'B' if b.get(i + 1).is_some_and(|c| c.is_ascii_alphanumeric()) => {
                if b[i] == b'C' && b.get(i + 1).is_some_and(u8::is_ascii_digit) {
                    i += 1;
                    continue;
                }
                i += b[i..].iter().position(|&c| c == b'_')? + 1;
            }
            c if c.is_ascii_digit() => {
                let end = i + b[i..].iter().position(|c| !c.is_ascii_digit())?;
                let len: usize = s[i..end].parse().ok()?;
                let start = end + usize::from(b.get(end) == Some(&b'_'));
                parts.push(s.get(start..start + len)?);
                i = start + len;
            }
            _ => i += 1,
        }
    }
    (!parts.is_empty()).then(|| parts.join("::"))
}

/// The crate a (demangled) symbol belongs to: the first path segment, inside a leading `<`
/// for trait impls (`<morphlink::fixed::Fixed as core::fmt::Display>::fmt` → `morphlink`);
/// unmangled names (`__aeabi_*`, `memcpy`, interrupt handlers) as `compiler_builtins / C`, the
/// outliner's shared code sequences on their own, anonymous
/// constants (`.Lanon.*`, string and table literals merged by the linker) as `(anonymous
/// data)`.
pub fn crate_of(name: &str) -> String {
    if name.starts_with(".L") || name.starts_with("anon.") {
        return "(anonymous data)".into();
    }
    if name.starts_with("OUTLINED_FUNCTION") {
        return "(outlined code, shared by callers)".into();
    }
    let n = name.trim_start_matches(['<', '&', '*', ' ']);
    let n = n.strip_prefix("mut ").unwrap_or(n);
    match n.find("::") {
        Some(i) if !n[..i].contains(['<', ' ']) => n[..i].to_string(),
        _ if name.starts_with("__") || !name.contains("::") => "compiler_builtins / C".into(),
        _ => "(other)".into(),
    }
}

/// True for a software double-precision routine: compiler-builtins' `__*df*` (`__adddf3`,
/// `__muldf3`, `__divdf3`, `__truncdfsf2`, `__extendsfdf2`, `__fixdfsi`, ...), the ARM EABI's
/// `__aeabi_d*` and `__aeabi_*2d`, and libm's f64 functions (`libm::…::exp`, not `expf`).
pub fn is_soft_double(name: &str) -> bool {
    let last = name.rsplit("::").next().unwrap_or(name);
    let eabi = last
        .strip_prefix("__aeabi_")
        .is_some_and(|r| r.starts_with('d') || r.ends_with("2d"));
    let builtin = last.starts_with("__") && last.contains("df");
    let libm = name.starts_with("libm::") && !last.ends_with('f') && !name.contains("::support");
    eabi || builtin || libm
}

/// True for `core`'s float text machinery: `Display`/`Debug`/`FromStr` of `f32`/`f64` and what
/// they call (`core::fmt::float`, `float_to_decimal_common_*`, `flt2dec`, `dec2flt`).
pub fn is_float_text(name: &str) -> bool {
    [
        "flt2dec",
        "dec2flt",
        "fmt::float",
        "float_to_decimal",
        "float_to_exponential",
        "<f32 as core::fmt",
        "<f64 as core::fmt",
        "<f32 as core::str",
        "<f64 as core::str",
    ]
    .iter()
    .any(|p| name.contains(p))
}

/// Flash and RAM per crate, largest flash first: `(crate, flash, ram)`; bytes no symbol
/// covers (string literals, alignment) as `(no symbol: string literals, padding)`.
pub fn crate_table(syms: &[Symbol], flash_total: u64, ram_total: u64) -> Vec<(String, u64, u64)> {
    let mut rows: Vec<(String, u64, u64)> = Vec::new();
    for s in syms {
        let c = crate_of(&s.name);
        let i = match rows.iter().position(|r| r.0 == c) {
            Some(i) => i,
            None => {
                rows.push((c, 0, 0));
                rows.len() - 1
            }
        };
        if s.flash {
            rows[i].1 += s.size;
        }
        if s.ram {
            rows[i].2 += s.size;
        }
    }
    rows.sort_by_key(|r| (std::cmp::Reverse(r.1), std::cmp::Reverse(r.2), r.0.clone()));
    let (f, r) = rows
        .iter()
        .fold((0, 0), |(f, r), row| (f + row.1, r + row.2));
    rows.push((
        "(no symbol: string literals, padding)".into(),
        flash_total.saturating_sub(f),
        ram_total.saturating_sub(r),
    ));
    rows
}

/// Prints the per-crate table and the largest symbols.
fn print_breakdown(board: &str, syms: &[Symbol], flash: u64, ram: u64) {
    println!();
    println!("{board}: flash and static RAM per crate");
    println!();
    println!("| crate | flash | static RAM |");
    println!("| --- | ---: | ---: |");
    for (c, f, r) in crate_table(syms, flash, ram) {
        println!("| {c} | {f} | {r} |");
    }
    println!("| total | {flash} | {ram} |");
    println!();
    println!("{board}: the {TOP_SYMBOLS} largest symbols");
    println!();
    println!("| bytes | in | symbol |");
    println!("| ---: | --- | --- |");
    let mut by_size: Vec<&Symbol> = syms.iter().collect();
    by_size.sort_by_key(|s| (std::cmp::Reverse(s.size), s.name.clone()));
    for s in by_size.into_iter().take(TOP_SYMBOLS) {
        let place = match (s.flash, s.ram) {
            (true, true) => "flash+RAM",
            (true, false) => "flash",
            _ => "RAM",
        };
        let name: String = s.name.replace('|', "\\|").chars().take(110).collect();
        println!("| {} | {place} | `{name}` |", s.size);
    }
}

/// Boards: every folder in `boards/` with a `memory.x`, the default first.
fn boards(root: &Path) -> Result<Vec<String>, String> {
    let dir = root.join("boards");
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .map_err(|e| format!("{}: {e}", dir.display()))?
        .filter_map(|e| e.ok())
        .filter(|e| e.path().join("memory.x").is_file())
        .filter_map(|e| e.file_name().into_string().ok())
        .collect();
    names.sort_by_key(|n| (n != DEFAULT_BOARD, n.clone()));
    if names.first().map(String::as_str) != Some(DEFAULT_BOARD) {
        return Err(format!(
            "the default board {DEFAULT_BOARD} is missing from boards/"
        ));
    }
    Ok(names)
}

/// The board's `memory.x`.
fn memory_x(root: &Path, board: &str) -> PathBuf {
    root.join("boards").join(board).join("memory.x")
}

/// `LENGTH` of region `name` in a linker `MEMORY` block, bytes (`512K`, `1M`, `0x8000`, `98304`).
pub fn region_length(memory_x: &str, name: &str) -> Option<u64> {
    region_field(memory_x, name, "LENGTH")
}

/// `ORIGIN` of region `name` in a linker `MEMORY` block.
pub fn region_origin(memory_x: &str, name: &str) -> Option<u64> {
    region_field(memory_x, name, "ORIGIN")
}

fn region_field(memory_x: &str, name: &str, field: &str) -> Option<u64> {
    let line = memory_x
        .lines()
        .find(|l| l.trim_start().starts_with(name) && l.contains(field))?;
    let value = line.split(field).nth(1)?.trim_start().strip_prefix('=')?;
    let value = value.split(',').next()?.trim();
    let (digits, scale) = match value.chars().last()? {
        'K' | 'k' => (&value[..value.len() - 1], 1024),
        'M' | 'm' => (&value[..value.len() - 1], 1024 * 1024),
        _ => (value, 1),
    };
    let n = match digits
        .strip_prefix("0x")
        .or_else(|| digits.strip_prefix("0X"))
    {
        Some(hex) => u64::from_str_radix(hex, 16).ok()?,
        None => digits.parse().ok()?,
    };
    Some(n * scale)
}

/// Checks a hardware board's `SETTINGS` region: right after `FLASH`, at least
/// [`MIN_SETTINGS_BYTES`]; returns its origin and length.
pub fn settings_region(memory_x: &str) -> Result<(u64, u64), String> {
    let flash_end = region_origin(memory_x, "FLASH")
        .zip(region_length(memory_x, "FLASH"))
        .map(|(o, l)| o + l)
        .ok_or("no FLASH region")?;
    let (origin, length) = region_origin(memory_x, "SETTINGS")
        .zip(region_length(memory_x, "SETTINGS"))
        .ok_or("no SETTINGS region: the settings need their own flash (docs/settings.md)")?;
    if origin != flash_end {
        return Err(format!(
            "SETTINGS starts at {origin:#x}, not right after FLASH at {flash_end:#x}"
        ));
    }
    if length < MIN_SETTINGS_BYTES {
        return Err(format!(
            "SETTINGS is {length} B, under {MIN_SETTINGS_BYTES}"
        ));
    }
    Ok((origin, length))
}

/// Flash and static RAM of an ELF image, bytes: flash holds every allocated section with
/// contents (code, read-only data, the initial values of `.data`); RAM holds the writable
/// allocated sections (`.data`, `.bss`, `.uninit`).
pub fn image_sizes(elf: &[u8]) -> Result<(u64, u64), String> {
    let file = object::File::parse(elf).map_err(|e| format!("not an ELF: {e}"))?;
    let (mut flash, mut ram) = (0, 0);
    for s in file.sections() {
        let SectionFlags::Elf { sh_type, sh_flags } = s.flags() else {
            continue;
        };
        if (sh_flags.0 & SHF_ALLOC.0) == 0 {
            continue;
        }
        let writable = (sh_flags.0 & SHF_WRITE.0) != 0;
        let no_bits = sh_type == SHT_NOBITS;
        if !no_bits {
            flash += s.size();
        }
        if writable {
            ram += s.size();
        }
    }
    Ok((flash, ram))
}

/// The initial stack pointer the image was linked with (cortex-m-rt's `_stack_start`): the
/// end of the RAM region of the `memory.x` it was linked against, or with flip-link the top of
/// the stack at the bottom of that region.
pub fn stack_start(elf: &[u8]) -> Option<u64> {
    let file = object::File::parse(elf).ok()?;
    let sym = file.symbols().find(|s| s.name() == Ok("_stack_start"))?;
    Some(sym.address())
}

/// True if the image's RAM layout is that of the RAM region `(origin, length)`: linked by
/// flip-link (`.cargo/config.toml`), the stack sits at the bottom of the region (`_stack_end`
/// at its origin, `_stack_start` above it) and the statics above the stack end at the region's
/// end (cortex-m-rt's `__sheap`, within its 8-byte alignment); linked plainly, `_stack_start` is
/// the region's end.
fn linked_against(elf: &[u8], ram: Option<(u64, u64)>) -> bool {
    let Some((origin, len)) = ram else {
        return false;
    };
    let end = origin + len;
    let sym = |name: &str| {
        let file = object::File::parse(elf).ok()?;
        let s = file.symbols().find(|s| s.name() == Ok(name))?;
        Some(s.address())
    };
    match (stack_start(elf), sym("_stack_end"), sym("__sheap")) {
        (Some(start), _, _) if start == end => true,
        (Some(start), Some(bottom), Some(heap)) => {
            bottom == origin && origin < start && start < heap && heap <= end && end - heap < 8
        }
        _ => false,
    }
}

/// The images of several links built besides each board's own: (board, features). Only the
/// emulated board is wired for two links (docs/multilink.md, "Boards").
const MULTI_LINK_IMAGES: [(&str, &[&str]); 1] = [("b-l475e-iot01a-emulated", &["links-2"])];

fn build(ws: &Workspace, board: &str, features: &[&str]) -> Result<PathBuf, String> {
    // The emulated images in the directory the emulator tests and `cargo xtask emulate` build
    // them in: after `cargo test` (CI runs it first) they are already there, not built again.
    let target_dir = if board == morphlink_host::emulator::BOARD {
        ws.target_dir.join("emulated")
    } else {
        ws.target_dir.clone()
    };
    let elf =
        morphlink_host::emulator::build_firmware_with(&ws.root, board, features, &target_dir)?;
    if !features.is_empty() {
        return Ok(elf);
    }
    // Each build overwrites the same ELF; keep a copy per board (e.g. to flash with probe-rs).
    let dir = ws.target_dir.join("boards");
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let copy = dir.join(format!("morphlink-{board}.elf"));
    std::fs::copy(&elf, &copy).map_err(|e| format!("{}: {e}", elf.display()))?;
    Ok(copy)
}

fn kib(bytes: u64) -> String {
    format!("{:.1} KiB", bytes as f64 / 1024.0)
}

/// Runs the task: build every board, print the table, check the budgets.
pub fn run(ws: &Workspace) -> Result<(), String> {
    let root = ws.root.as_path();
    let mut images = Vec::new();
    let mut failed = Vec::new();
    let one_link = boards(root)?.into_iter().map(|b| (b, &[][..]));
    let several = MULTI_LINK_IMAGES.iter().map(|&(b, f)| (b.to_string(), f));
    for (board, features) in one_link.chain(several) {
        // A board that does not build (or link: an image over its FLASH region) is reported
        // with the others' table, not instead of it.
        let elf_path = match build(ws, &board, features) {
            Ok(p) => p,
            Err(e) => {
                failed.push(format!("{board}: {e}"));
                continue;
            }
        };
        let elf = std::fs::read(&elf_path).map_err(|e| e.to_string())?;
        let (flash_bytes, ram_bytes) = image_sizes(&elf)?;
        let mem_path = memory_x(root, &board);
        let mem = std::fs::read_to_string(&mem_path).map_err(|e| e.to_string())?;
        let region = |name| {
            region_length(&mem, name)
                .ok_or_else(|| format!("{}: no {name} LENGTH", mem_path.display()))
        };
        // The linker takes `memory.x` from the package directory before the search path; make
        // sure this image really was linked against its board's layout.
        let ram = region_origin(&mem, "RAM").zip(region_length(&mem, "RAM"));
        if !linked_against(&elf, ram) {
            return Err(format!(
                "{board}: image not linked against {} (stack start {:x?})",
                mem_path.display(),
                stack_start(&elf)
            ));
        }
        if !board.ends_with("-emulated") {
            settings_region(&mem).map_err(|e| format!("{}: {e}", mem_path.display()))?;
        }
        let syms = symbols(&elf)?;
        if board == DEFAULT_BOARD && features.is_empty() {
            print_breakdown(&board, &syms, flash_bytes, ram_bytes);
        }
        let named = |f: fn(&str) -> bool| {
            let mut v: Vec<String> = syms
                .iter()
                .filter(|s| s.flash && f(&s.name))
                .map(|s| s.name.clone())
                .collect();
            v.sort();
            v.dedup();
            v
        };
        images.push(Image {
            soft_double: named(is_soft_double),
            float_text: named(is_float_text),
            board,
            features,
            flash_bytes,
            ram_bytes,
            flash_size: region("FLASH")?,
            ram_size: region("RAM")?,
        });
    }

    println!();
    println!("| board | flash used | of | static RAM used | of |");
    println!("| --- | --- | --- | --- | --- |");
    for i in &images {
        println!(
            "| {}{} | {} ({} B) | {} | {} ({} B) | {} |",
            i.board,
            i.features
                .iter()
                .map(|f| format!(" {f}"))
                .collect::<String>(),
            kib(i.flash_bytes),
            i.flash_bytes,
            kib(i.flash_size),
            kib(i.ram_bytes),
            i.ram_bytes,
            kib(i.ram_size)
        );
    }
    println!();

    let mut errors = failed;
    for i in &images {
        if i.flash_bytes > i.flash_size {
            errors.push(format!(
                "{}: flash {} > {}",
                i.board, i.flash_bytes, i.flash_size
            ));
        }
        if i.ram_bytes + STACK_RESERVE_BYTES > i.ram_size {
            errors.push(format!(
                "{}: RAM {} + {} stack > {}",
                i.board, i.ram_bytes, STACK_RESERVE_BYTES, i.ram_size
            ));
        }
        if !i.board.ends_with("-emulated") {
            if i.flash_bytes > HW_FLASH_BUDGET_BYTES {
                errors.push(format!(
                    "{}: flash {} > the hardware boards' budget of {}",
                    i.board, i.flash_bytes, HW_FLASH_BUDGET_BYTES
                ));
            }
            if i.ram_bytes > HW_RAM_BUDGET_BYTES {
                errors.push(format!(
                    "{}: static RAM {} > the hardware boards' budget of {}",
                    i.board, i.ram_bytes, HW_RAM_BUDGET_BYTES
                ));
            }
            let new: Vec<&str> = i
                .soft_double
                .iter()
                .map(String::as_str)
                .filter(|n| !SOFT_DOUBLE_TOLERATED.contains(n))
                .collect();
            if !new.is_empty() {
                errors.push(format!(
                    "{}: software double precision in the image (the FPU is f32 only): {}",
                    i.board,
                    new.join(", ")
                ));
            }
            if !i.float_text.is_empty() {
                errors.push(format!(
                    "{}: core's float formatting or parsing in the image (use morphlink::fixed): {}",
                    i.board,
                    i.float_text.join(", ")
                ));
            }
        }
        if i.board == DEFAULT_BOARD && i.features.is_empty() {
            if i.flash_bytes > SMALL_PART_FLASH_BYTES {
                errors.push(format!(
                    "{}: flash {} > the {} of the small-part budget",
                    i.board, i.flash_bytes, SMALL_PART_FLASH_BYTES
                ));
            }
            if i.ram_bytes + STACK_RESERVE_BYTES > SMALL_PART_RAM_BYTES {
                errors.push(format!(
                    "{}: RAM {} + {} stack > the {} of the small-part budget",
                    i.board, i.ram_bytes, STACK_RESERVE_BYTES, SMALL_PART_RAM_BYTES
                ));
            }
        }
    }
    for i in images.iter().filter(|i| !i.board.ends_with("-emulated")) {
        if !i.soft_double.is_empty() {
            println!(
                "{}: {} software double-precision routines left (the goal is none)",
                i.board,
                i.soft_double.len()
            );
        }
        if i.flash_bytes > HW_FLASH_TARGET_BYTES || i.ram_bytes > HW_RAM_TARGET_BYTES {
            println!(
                "{}: short of the goal of {} flash / {} static RAM by {} B / {} B",
                i.board,
                kib(HW_FLASH_TARGET_BYTES),
                kib(HW_RAM_TARGET_BYTES),
                i.flash_bytes.saturating_sub(HW_FLASH_TARGET_BYTES),
                i.ram_bytes.saturating_sub(HW_RAM_TARGET_BYTES)
            );
        }
    }
    if errors.is_empty() {
        println!(
            "hardware boards: at most {} flash and {} static RAM each, no software double \
             precision beyond the tolerated list, no core float text",
            kib(HW_FLASH_BUDGET_BYTES),
            kib(HW_RAM_BUDGET_BYTES)
        );
        println!(
            "budgets ok: every image fits its board with {} of stack to spare; {} also fits \
             {} flash / {} RAM",
            kib(STACK_RESERVE_BYTES),
            DEFAULT_BOARD,
            kib(SMALL_PART_FLASH_BYTES),
            kib(SMALL_PART_RAM_BYTES)
        );
        Ok(())
    } else {
        Err(format!("over budget:\n  {}", errors.join("\n  ")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_memory_x_lengths() {
        let m = "MEMORY\n{\n  FLASH : ORIGIN = 0x08000000, LENGTH = 512K\n  RAM   : ORIGIN = 0x20000000, LENGTH = 96K\n}\n";
        assert_eq!(region_length(m, "FLASH"), Some(512 * 1024));
        assert_eq!(region_length(m, "RAM"), Some(96 * 1024));
        assert_eq!(
            region_length("RAM : ORIGIN = 0, LENGTH = 1M", "RAM"),
            Some(1 << 20)
        );
        assert_eq!(
            region_length("RAM : ORIGIN = 0, LENGTH = 0x4000", "RAM"),
            Some(0x4000)
        );
        assert_eq!(region_length(m, "CCM"), None);
        assert_eq!(region_origin(m, "RAM"), Some(0x2000_0000));
    }

    #[test]
    fn every_board_memory_x_parses() {
        let root = Workspace::containing(Path::new(env!("CARGO_MANIFEST_DIR")))
            .unwrap()
            .root;
        for b in boards(&root).unwrap() {
            let m = std::fs::read_to_string(memory_x(&root, &b)).unwrap();
            assert!(region_length(&m, "FLASH").unwrap() >= 64 * 1024, "{b}");
            assert!(region_length(&m, "RAM").unwrap() >= 16 * 1024, "{b}");
        }
    }

    #[test]
    fn every_hardware_board_has_a_settings_area_right_after_its_code() {
        let root = Workspace::containing(Path::new(env!("CARGO_MANIFEST_DIR")))
            .unwrap()
            .root;
        for b in boards(&root).unwrap() {
            if b.ends_with("-emulated") {
                continue;
            }
            let m = std::fs::read_to_string(memory_x(&root, &b)).unwrap();
            settings_region(&m).unwrap_or_else(|e| panic!("{b}: {e}"));
        }
        let overlapping = "FLASH : ORIGIN = 0x08000000, LENGTH = 128K\nSETTINGS : ORIGIN = 0x0801F000, LENGTH = 4K\n";
        assert!(settings_region(overlapping).is_err());
        assert!(settings_region("FLASH : ORIGIN = 0x08000000, LENGTH = 128K\n").is_err());
    }

    #[test]
    fn demangles_and_names_crates() {
        assert_eq!(
            demangle("_ZN4core3fmt9Formatter3pad17h0123456789abcdefE"),
            "core::fmt::Formatter::pad"
        );
        let d = demangle(
            "_ZN62_$LT$morphlink..fixed..Fixed$u20$as$u20$core..fmt..Display$GT$3fmt17h7a88df134df60cceE",
        );
        assert_eq!(d, "<morphlink::fixed::Fixed as core::fmt::Display>::fmt");
        assert_eq!(crate_of(&d), "morphlink");
        assert_eq!(crate_of("__aeabi_dadd"), "compiler_builtins / C");
        assert_eq!(crate_of(".Lanon.29ad.100"), "(anonymous data)");
        assert_eq!(demangle("memcpy"), "memcpy");
        assert_eq!(
            demangle("_RNvMNtCs7ldSeZOOJos_4core3f32f5clamp"),
            "core::f32::clamp"
        );
        let d = demangle("_RNvXs2_NtNtCs7ldSeZOOJos_4core3fmt5floatfNtB7_5Debug3fmt");
        assert_eq!(d, "core::fmt::float::Debug::fmt");
        assert!(is_float_text(&d));
        assert!(is_float_text(&demangle(
            "_RINvNtNtCs7ldSeZOOJos_4core3fmt5float29float_to_decimal_common_exactfEB6_"
        )));
    }

    #[test]
    fn names_soft_double_and_float_text() {
        for n in [
            "__aeabi_dadd",
            "__aeabi_d2f",
            "__aeabi_f2d",
            "__aeabi_i2d",
            "compiler_builtins::float::add::__adddf3",
            "__truncdfsf2",
            "libm::math::exp::exp",
            "libm::math::log::log",
        ] {
            assert!(is_soft_double(n), "{n}");
        }
        for n in [
            "__aeabi_fadd",
            "__aeabi_f2lz",
            "__aeabi_uldivmod",
            "libm::math::expf::expf",
            "memcpy",
            "morphlink::mathf::exp",
        ] {
            assert!(!is_soft_double(n), "{n}");
        }
        assert!(is_float_text(
            "core::fmt::float::float_to_decimal_common_exact"
        ));
        assert!(is_float_text(
            "core::num::flt2dec::strategy::grisu::format_shortest"
        ));
        assert!(is_float_text("<f32 as core::fmt::Display>::fmt"));
        assert!(is_float_text("core::num::dec2flt::parse"));
        assert!(!is_float_text(
            "<morphlink::fixed::Fixed as core::fmt::Display>::fmt"
        ));
    }

    #[test]
    fn sizes_of_a_host_elf_are_plausible() {
        // The test binary itself is an ELF with code and writable data on Linux.
        let exe = std::env::current_exe().unwrap();
        let elf = std::fs::read(exe).unwrap();
        if elf.starts_with(b"\x7fELF") {
            let (flash, ram) = image_sizes(&elf).unwrap();
            assert!(flash > 10_000 && ram > 0, "{flash} {ram}");
        }
    }
}
