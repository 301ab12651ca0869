//! `morph-model`: the link's models on the command line — fit the constants, print the
//! parameters file and the firmware table; compare the lumped and reference thermal matrices,
//! run the accuracy/cost study and its charts, pick the cheapest model for a tolerance.
use clap::{Parser, Subcommand};
use morphlink_host::charts;
use morphlink_model::reference::levels::{self, Level, REFERENCE_RINGS};
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
    /// Print the lumped and the reference (finite-volume) thermal-resistance matrices, K/W, as JSON.
    Thermal,
    /// Run the accuracy/cost study of every model level; write the charts and study.csv.
    Charts {
        /// CSV with measured and paper_model rows.
        #[arg(long, default_value = "data/fig9_calibration.csv")]
        data: PathBuf,
        /// Directory for the SVG charts and study.csv.
        #[arg(long, default_value = "docs/charts")]
        out: PathBuf,
        /// Wall time spent timing each level, s (median of the repeats).
        #[arg(long, default_value_t = 1.0)]
        budget_s: f64,
    },
    /// Pick the cheapest model level whose radius is within a tolerance of the reference.
    Pick {
        /// Allowed radius error against the reference, mm.
        #[arg(long)]
        tolerance_mm: f64,
        /// CSV with measured rows.
        #[arg(long, default_value = "data/fig9_calibration.csv")]
        data: PathBuf,
        /// Wall time spent timing each level, s.
        #[arg(long, default_value_t = 0.2)]
        budget_s: f64,
    },
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
        Cmd::Thermal => {
            let j = thermal_json(&p, REFERENCE_RINGS)?;
            println!(
                "{}",
                serde_json::to_string_pretty(&j).map_err(|e| e.to_string())?
            );
        }
        Cmd::Charts {
            data,
            out,
            budget_s,
        } => {
            let fig9 = charts::load_fig9(&data)?;
            let summary = charts::run(&p, &fig9, &out, budget_s)?;
            println!("{summary}");
            println!("wrote charts and study.csv to {}", out.display());
        }
        Cmd::Pick {
            tolerance_mm,
            data,
            budget_s,
        } => {
            if tolerance_mm.is_nan() || tolerance_mm <= 0.0 {
                return Err(format!("tolerance must be positive, got {tolerance_mm}"));
            }
            let fig9 = charts::load_fig9(&data)?;
            let scored = charts::score_all(&p, &fig9, budget_s)?;
            let mut candidates: Vec<&levels::Scored> = scored
                .iter()
                .filter(|s| !s.level.pla_stiffness && s.level.law == levels::Law::Linear)
                .collect();
            candidates.sort_by(|a, b| a.seconds.total_cmp(&b.seconds));
            println!(
                "tolerance {tolerance_mm} mm against {} (same physics: linear TCA law, PLA soft)",
                Level::REFERENCE.name()
            );
            println!(
                "  {:<22} {:>12} {:>12}  verdict",
                "level", "time", "error_mm"
            );
            let picked = levels::pick(&scored, tolerance_mm);
            for s in &candidates {
                let verdict = if Some(s.level) == picked.map(|x| x.level) {
                    "PICKED: cheapest within tolerance"
                } else if s.error_vs_reference_mm <= tolerance_mm {
                    "within tolerance, costlier"
                } else {
                    "error above tolerance"
                };
                println!(
                    "  {:<22} {:>12} {:>12.4}  {verdict}",
                    s.level.name(),
                    charts::human_time(s.seconds),
                    s.error_vs_reference_mm
                );
            }
            let reference = scored
                .iter()
                .find(|s| s.level == Level::REFERENCE)
                .ok_or("reference level missing")?;
            let (fw_ref, fw_meas) =
                charts::firmware_table_errors(&p, &reference.radius_mm, &fig9.measured);
            println!(
                "firmware table ({} entries, f32): worst error vs reference {fw_ref:.3} mm ({}), vs measured {fw_meas:.3} mm",
                p.table_entries,
                if fw_ref <= tolerance_mm { "within tolerance" } else { "ABOVE tolerance" }
            );
            match picked {
                Some(s) => {
                    let cheaper: Vec<String> = candidates
                        .iter()
                        .take_while(|c| c.level != s.level)
                        .map(|c| format!("{} ({:.4} mm)", c.level.name(), c.error_vs_reference_mm))
                        .collect();
                    let why = if cheaper.is_empty() {
                        "it is the cheapest level of all".to_string()
                    } else {
                        format!("every cheaper level errs more: {}", cheaper.join(", "))
                    };
                    println!(
                        "pick: {} — error {:.4} mm <= {tolerance_mm} mm at {} per curve; {why}",
                        s.level.name(),
                        s.error_vs_reference_mm,
                        charts::human_time(s.seconds)
                    );
                }
                None => {
                    return Err(format!(
                        "no level is within {tolerance_mm} mm of the reference; use the reference itself"
                    ))
                }
            }
        }
    }
    Ok(())
}

/// `{"lumped": {r_tt, r_pp, r_tp}, "reference": {...}}` in K/W, the reference on `rings` rings.
fn thermal_json(p: &LinkParams, rings: usize) -> Result<serde_json::Value, String> {
    let m = |r: morphlink_model::thermal::ResistanceMatrix| serde_json::json!({"r_tt": r.r_tt, "r_pp": r.r_pp, "r_tp": r.r_tp});
    let lumped = levels::thermal_matrix(p, levels::Thermal::Lumped).map_err(|e| e.to_string())?;
    let reference = levels::thermal_matrix(p, levels::Thermal::FiniteVolume(rings))
        .map_err(|e| e.to_string())?;
    Ok(serde_json::json!({"lumped": m(lumped), "reference": m(reference)}))
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thermal_json_has_exactly_the_documented_shape() {
        let p = LinkParams::DEFAULT;
        let j = thermal_json(&p, 8).unwrap();
        let obj = j.as_object().unwrap();
        assert_eq!(obj.len(), 2);
        let lumped = morphlink_model::thermal::resistance_matrix(&p);
        for (key, want_tt) in [("lumped", Some(lumped.r_tt)), ("reference", None)] {
            let m = obj[key].as_object().unwrap();
            assert_eq!(m.len(), 3);
            for k in ["r_tt", "r_pp", "r_tp"] {
                let v = m[k].as_f64().unwrap();
                assert!(v.is_finite() && v > 0.0, "{key}.{k} = {v}");
            }
            if let Some(w) = want_tt {
                assert_eq!(m["r_tt"].as_f64().unwrap(), w);
            }
        }
    }

    #[test]
    fn pick_rejects_a_tolerance_that_is_not_positive() {
        let cli = Cli::parse_from(["morph-model", "pick", "--tolerance-mm", "0"]);
        assert!(run(cli).unwrap_err().contains("positive"));
    }
}
