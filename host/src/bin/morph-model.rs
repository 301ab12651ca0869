//! `morph-model`: the link's lumped model on the command line — fit the constants, print the
//! parameters file and the firmware table.
use clap::{Parser, Subcommand};
use morphlink_model::{calibrate, file, table, LinkParams};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "morph-model",
    version,
    about = "Lumped model of the morphing link"
)]
struct Cli {
    /// Parameters file; the paper's link under water when omitted.
    #[arg(long, global = true)]
    link: Option<PathBuf>,
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Fit bending stiffness, TCA preload and force coefficient to measured radii.
    Calibrate {
        /// CSV with p_tca_w,radius_mm,source rows; rows with source "measured" are fitted.
        #[arg(long, default_value = "data/fig9_calibration.csv")]
        data: PathBuf,
        /// Write the parameters with the fitted constants to this file.
        #[arg(long)]
        write: Option<PathBuf>,
    },
    /// Print the parameters file (TOML).
    Params,
    /// Print the firmware table: power, radius and TCA rise per entry.
    Table,
}

fn run(cli: Cli) -> Result<(), String> {
    let p = match &cli.link {
        Some(path) => file::load(path)?,
        None => LinkParams::DEFAULT,
    };
    match cli.cmd {
        Cmd::Calibrate { data, write } => {
            let pts = calibrate::load_points(&data, "measured")?;
            let fit = calibrate::calibrate(&p, &pts)?;
            let m = fit.params.mechanics;
            println!(
                "fitted to {} measured points in {} iterations",
                pts.len(),
                fit.iterations
            );
            println!(
                "  bending_stiffness_nm2 = {:.5e}  (prior {:.5e})",
                m.bending_stiffness_nm2, fit.prior_stiffness_nm2
            );
            println!("  preload_n             = {:.6}", m.preload_n);
            println!("  force_coeff_n_per_k   = {:.7}", m.force_coeff_n_per_k);
            println!("  p_tca_w  measured_mm  model_mm  error_mm");
            for (pt, r) in pts.iter().zip(&fit.residuals_mm) {
                println!(
                    "  {:7.2}  {:11.2}  {:8.2}  {:+8.3}",
                    pt.p_tca_w,
                    pt.radius_mm,
                    pt.radius_mm + r,
                    r
                );
            }
            if let Some(path) = write {
                std::fs::write(&path, file::to_toml(&fit.params))
                    .map_err(|e| format!("cannot write {}: {e}", path.display()))?;
                println!("wrote {}", path.display());
            }
        }
        Cmd::Params => print!("{}", file::to_toml(&p)),
        Cmd::Table => {
            println!("power_w,radius_mm,tca_rise_k");
            for i in 0..p.table_entries {
                let e = table::entry(&p, i);
                println!("{:.4},{:.3},{:.3}", e.power_w, e.radius_mm, e.tca_rise_k);
            }
        }
    }
    Ok(())
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("morph-model: {e}");
            ExitCode::FAILURE
        }
    }
}
