//! `cargo xtask <task>`: project automation in Rust (the xtask convention), one module per task.
//!
//! The workspace and its target directory come from `cargo metadata` at run time (the checkout
//! `cargo xtask` is run in, and `CARGO_TARGET_DIR` or `build.target-dir` if set), never from
//! paths baked in when xtask was compiled: with a shared target directory the same xtask binary
//! serves several checkouts.
use clap::{Parser, Subcommand};

mod boards;
mod calibration;
mod emulate;
mod ensemble;
mod faults;
mod flash;
mod gait;
mod limits;
mod link_faults;
mod self_sense;
mod stored_heat;
mod strategies;
mod warm;
use morphlink_host::workspace::Workspace;
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
    /// Inject every fault in every phase on the hifi and lumped links: the detection-time table.
    Faults(faults::Args),
    /// ABORT morphs on healthy links: the heat stored in them must raise no alarm.
    StoredHeat(stored_heat::Args),
    /// TUNE and MEASURED over a mismatch ensemble: docs/calibration.csv, .svg, .png.
    Calibration(calibration::Args),
    /// Every strategy on every link at each corner of the settings: true peaks against limits.
    Limits(limits::Args),
    /// Morphs back to back on the hifi ensemble: a warm start against the same morph from rest.
    Warm(warm::Args),
    /// The TCA's self-sensed temperature against its true mean over the hifi ensemble.
    SelfSense(self_sense::Args),
    /// Several links on one supply budget: the makespan, the budget and the current limit held.
    Gait(gait::Args),
    /// A fault on one link of a gait: it stops that link as fast as alone; the others finish.
    LinkFaults(link_faults::Args),
    /// Build a board's firmware (its feature) and flash it with probe-rs (its chip).
    Flash(flash::Args),
    /// Build a board's firmware, flash and run it, printing the defmt log (probe-rs run).
    Run(flash::Args),
}

fn main() -> ExitCode {
    let task = Cli::parse().task;
    let result: Result<(), String> = Workspace::current().and_then(|ws| match task {
        Task::Root => {
            println!("{}", ws.root.display());
            Ok(())
        }
        Task::Boards => boards::run(&ws),
        Task::Strategies(a) => strategies::run(&a, &ws.root),
        Task::Emulate(a) => emulate::run(&a, &ws),
        Task::Faults(a) => faults::run(&a),
        Task::StoredHeat(a) => stored_heat::run(&a),
        Task::Calibration(a) => calibration::run(&a, &ws.root),
        Task::Limits(a) => limits::run(&a),
        Task::Warm(a) => warm::run(&a),
        Task::SelfSense(a) => self_sense::run(&a),
        Task::Gait(a) => gait::run_task(&a, &ws.root),
        Task::LinkFaults(a) => link_faults::run(&a),
        Task::Flash(a) => flash::run(flash::Action::Flash, &a, &ws),
        Task::Run(a) => flash::run(flash::Action::Run, &a, &ws),
    });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: {e}");
            ExitCode::FAILURE
        }
    }
}
