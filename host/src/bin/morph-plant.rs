//! `morph-plant`: an in-process plant served over plant protocol 1 on stdin/stdout
//! (`morphlink_plant::wire::serve`), for `morph-sim --plant-cmd morph-plant` or any rig that
//! speaks the protocol. Exits 0 at end of input.
use clap::Parser;
use morphlink_host::plants::{self, PlantKind};
use morphlink_sim::LinkSetup;

#[derive(Parser)]
#[command(
    name = "morph-plant",
    version,
    about = "A simulated morphing link on the plant protocol (stdin/stdout): \
             hello/step/set lines in, ok/error lines out"
)]
struct Cli {
    /// The plant to serve.
    #[arg(long, value_enum, default_value_t = PlantKind::Lumped)]
    plant: PlantKind,
}

fn main() {
    let cli = Cli::parse();
    let mut plant = match plants::in_process(cli.plant, &LinkSetup::NOMINAL) {
        Ok(p) => p,
        Err(why) => {
            eprintln!("morph-plant: {why}");
            std::process::exit(2);
        }
    };
    let stdin = std::io::stdin().lock();
    let stdout = std::io::stdout().lock();
    if let Err(e) = morphlink_plant::wire::serve(&mut *plant, stdin, stdout) {
        // The rig closing its end is its way of ending the run.
        if e.kind() != std::io::ErrorKind::BrokenPipe {
            eprintln!("morph-plant: {e}");
            std::process::exit(1);
        }
    }
}
