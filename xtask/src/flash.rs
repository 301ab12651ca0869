//! `cargo xtask flash <board>` and `cargo xtask run <board>`: one command per board that picks
//! the cargo feature (`board-<board>`) and the probe-rs chip together, from one table, so the two
//! cannot disagree (by hand, `PROBE_RS_CHIP` and `--features` had to be kept in agreement).
use morphlink_host::emulator::build_firmware;
use morphlink_host::workspace::Workspace;
use std::process::Command;

/// Every board folder in `boards/` and how it is flashed: its probe-rs chip, or `None` for a
/// board with no probe (the QEMU build, which `cargo xtask emulate` runs). A test checks that
/// each folder with a `memory.x` has exactly one row and each row a folder and a feature.
pub const CHIPS: &[(&str, Option<&str>)] = &[
    ("nucleo-f401re", Some("STM32F401RETx")),
    ("nucleo-g431rb", Some("STM32G431RBTx")),
    ("b-l475e-iot01a", Some("STM32L475VGTx")),
    ("b-l475e-iot01a-emulated", None),
];

/// What to do with the board's image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Action {
    /// Write the image to flash (`probe-rs download`), then reset the board (`probe-rs reset`).
    Flash,
    /// Flash and run it, printing the defmt log over RTT until Ctrl-C (`probe-rs run`).
    Run,
}

/// Options of `cargo xtask flash` and `cargo xtask run`.
#[derive(clap::Args)]
pub struct Args {
    /// The board: a folder of `boards/` (nucleo-f401re, nucleo-g431rb, b-l475e-iot01a).
    board: String,
}

/// The probe-rs chip of `board`, or why it has none.
pub fn chip(board: &str) -> Result<&'static str, String> {
    match CHIPS.iter().find(|(b, _)| *b == board) {
        Some((_, Some(chip))) => Ok(chip),
        Some((_, None)) => Err(format!(
            "{board} has no probe: it runs under QEMU with `cargo xtask emulate`"
        )),
        None => Err(format!(
            "unknown board `{board}`; boards: {}",
            CHIPS
                .iter()
                .filter(|(_, c)| c.is_some())
                .map(|(b, _)| *b)
                .collect::<Vec<_>>()
                .join(", ")
        )),
    }
}

/// The probe-rs command lines for `action` on `chip` with the image `elf`: `download` then
/// `reset` to flash (the new image starts at once), or `run` (flash, run, defmt log over RTT).
pub fn probe_rs_commands(action: Action, chip: &str, elf: &str) -> Vec<Vec<String>> {
    let with_chip = |verb: &str| vec![verb.to_string(), "--chip".into(), chip.to_string()];
    match action {
        Action::Flash => {
            let mut download = with_chip("download");
            download.push(elf.into());
            vec![download, with_chip("reset")]
        }
        Action::Run => {
            let mut run = with_chip("run");
            run.push(elf.into());
            vec![run]
        }
    }
}

/// Builds the board's image in release (its feature) and hands it to probe-rs (its chip).
pub fn run(action: Action, args: &Args, ws: &Workspace) -> Result<(), String> {
    let chip = chip(&args.board)?;
    let elf = build_firmware(&ws.root, &args.board, &ws.target_dir)?;
    for a in probe_rs_commands(action, chip, &elf.display().to_string()) {
        eprintln!("probe-rs {}", a.join(" "));
        let status = Command::new("probe-rs").args(&a).status().map_err(|e| {
            format!(
                "cannot run probe-rs ({e}); install it (https://probe.rs) and put it on the PATH"
            )
        })?;
        if !status.success() {
            return Err(format!("probe-rs {} ended with {status}", a[0]));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn root() -> &'static Path {
        Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
    }

    #[test]
    fn every_board_folder_has_one_row_and_every_row_a_folder_and_a_feature() {
        let mut folders: Vec<String> = std::fs::read_dir(root().join("boards"))
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| e.path().join("memory.x").is_file())
            .filter_map(|e| e.file_name().into_string().ok())
            .collect();
        folders.sort();
        let mut rows: Vec<String> = CHIPS.iter().map(|(b, _)| b.to_string()).collect();
        rows.sort();
        assert_eq!(
            folders, rows,
            "CHIPS must list exactly the folders of boards/"
        );
        let manifest = std::fs::read_to_string(root().join("Cargo.toml")).unwrap();
        for (b, _) in CHIPS {
            assert!(
                manifest.contains(&format!("\nboard-{b} = ")),
                "no feature board-{b} in Cargo.toml"
            );
        }
    }

    #[test]
    fn the_default_chip_in_cargo_config_is_the_default_boards() {
        let config = std::fs::read_to_string(root().join(".cargo/config.toml")).unwrap();
        let chip = chip(crate::boards::DEFAULT_BOARD).unwrap();
        assert!(
            config.contains(&format!("PROBE_RS_CHIP = \"{chip}\"")),
            "`cargo fw`'s PROBE_RS_CHIP must be {chip}"
        );
    }

    #[test]
    fn the_chip_goes_with_its_board() {
        assert_eq!(chip("nucleo-g431rb").unwrap(), "STM32G431RBTx");
        assert!(chip("b-l475e-iot01a-emulated")
            .unwrap_err()
            .contains("xtask emulate"));
        assert!(chip("nucleo-h743zi").unwrap_err().contains("nucleo-f401re"));
        assert_eq!(
            probe_rs_commands(Action::Flash, "STM32G431RBTx", "fw.elf"),
            [
                vec!["download", "--chip", "STM32G431RBTx", "fw.elf"],
                vec!["reset", "--chip", "STM32G431RBTx"]
            ]
        );
        assert_eq!(
            probe_rs_commands(Action::Run, "STM32F401RETx", "fw.elf"),
            [vec!["run", "--chip", "STM32F401RETx", "fw.elf"]]
        );
    }
}
