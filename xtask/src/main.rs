//! `cargo xtask <task>`: project automation in Rust (the xtask convention), one module per task.
use clap::{Parser, Subcommand};

mod boards;
mod emulate;
mod strategies;
use std::process::ExitCode;

#[derive(Parser)]
#[command(name = "cargo xtask", about = "morphlink project tasks")]
struct Cli {
    #[command(subcommand)]
    task: Task,
}

#[derive(Subcommand)]
enum Task {
    /// Print the workspace root (a check that the task runner works).
    Root,
    /// Build the firmware for every board in release, print flash/RAM use, check budgets.
    Boards,
    /// Compare the morph strategies over a mismatch ensemble: docs/strategies.csv and charts.
    Strategies(strategies::Args),
    /// Build the emulated firmware and boot it under QEMU (b-l475e-iot01a).
    Emulate(emulate::Args),
}

fn main() -> ExitCode {
    let result: Result<(), String> = match Cli::parse().task {
        Task::Root => {
            println!("{}", workspace_root().display());
            Ok(())
        }
        Task::Boards => boards::run(&workspace_root()),
        Task::Strategies(a) => strategies::run(&a, &workspace_root()),
        Task::Emulate(a) => emulate::run(&a, &workspace_root()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: {e}");
            ExitCode::FAILURE
        }
    }
}

/// The workspace root (the parent of this crate's directory).
pub fn workspace_root() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("xtask lives in the workspace")
        .to_path_buf()
}
