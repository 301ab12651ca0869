//! `morph-model`: the link's models on the command line — fit the constants, print the
//! parameters file and the firmware table; compare the lumped and reference thermal matrices,
//! run the accuracy/cost study and its charts, pick the cheapest model for a tolerance; the
//! four-bar of the paper's application: its foot path for a radius, its chart, and the radius
//! for a wanted foot path.
use clap::{ArgGroup, Parser, Subcommand};
use morphlink_host::charts;
use morphlink_host::plot::prelude::*;
use morphlink_host::workspace::Workspace;
use morphlink_model::fourbar::{self, FourBar, FourBarGeometry, Inverse, Property};
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
    /// Parameters file; the repository's `link.toml` (at the workspace root, found with
    /// `cargo metadata` from any directory of the checkout) when omitted.
    #[arg(long, global = true)]
    link: Option<PathBuf>,
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Fit bending stiffness, TCA preload and force coefficient to radii measured on this
    /// link's geometry (docs/model.md, "A new geometry").
    Calibrate {
        /// CSV with p_tca_w,radius_mm,source rows (rows with source "measured" are fitted) and a
        /// `# geometry:` line naming the geometry they were measured on; the workspace's
        /// `data/fig9_calibration.csv` (the paper's link) when omitted.
        #[arg(long)]
        data: Option<PathBuf>,
        /// A parameters file whose `[geometry]` the radii were measured on, for a data file
        /// without a `# geometry:` line (or to check it against).
        #[arg(long)]
        measured_on: Option<PathBuf>,
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
        /// CSV with measured and paper_model rows; the workspace's `data/fig9_calibration.csv`
        /// when omitted.
        #[arg(long)]
        data: Option<PathBuf>,
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
        /// CSV with measured rows; the workspace's `data/fig9_calibration.csv` when omitted.
        #[arg(long)]
        data: Option<PathBuf>,
        /// Wall time spent timing each level, s.
        #[arg(long, default_value_t = 0.2)]
        budget_s: f64,
    },
    /// The four-bar with the locked link as its coupler (docs/fourbar.md): the foot path for a
    /// radius, a chart of the paths over the reachable radii, or the radius for a wanted path.
    #[command(group(ArgGroup::new("what").required(true).args(["radius_mm", "straight", "chart", "want", "gait"])))]
    Fourbar {
        /// The locked link's radius, mm (within the reachable range, `RANGE`).
        #[arg(long)]
        radius_mm: Option<f64>,
        /// The unmorphed, straight link.
        #[arg(long)]
        straight: bool,
        /// Print the path as one JSON object (with --radius-mm or --straight).
        #[arg(long)]
        json: bool,
        /// Draw the linkage and the foot paths over the reachable radii into this SVG (or PNG).
        #[arg(long)]
        chart: Option<PathBuf>,
        /// Find the radius that gives a foot path property: lowest_mm=, stride_mm= or height_mm=.
        #[arg(long, value_name = "PROPERTY=VALUE")]
        want: Option<String>,
        /// A gait of several legs, one morphing link each: the radius per leg for a property
        /// wanted per leg, and the `GAIT` line that morphs them all (docs/multilink.md).
        #[arg(long, value_name = "PROPERTY=V1,V2,...")]
        gait: Option<String>,
    },
}

/// What morph-model needs when it is run outside the checkout, and how to run it.
const NEEDS: &str = "morph-model reads the link's parameters from link.toml (and, for charts \
    and pick, the paper's radii from data/fig9_calibration.csv) at the root of the morphlink \
    checkout: run it from inside the checkout (`cargo run -p morphlink-host --bin morph-model \
    -- ...`), or pass --link FILE (and --data FILE)";

/// The root of the morphlink checkout the tool is run in (where `link.toml` is).
fn workspace_root() -> Result<PathBuf, String> {
    let here = std::env::current_dir().map_err(|e| format!("no current directory: {e}"))?;
    // Asked of cargo only inside a cargo project: elsewhere its error says nothing useful.
    if !here.ancestors().any(|d| d.join("Cargo.toml").is_file()) {
        return Err(format!(
            "{} is not inside the morphlink checkout; {NEEDS}",
            here.display()
        ));
    }
    match Workspace::current() {
        Ok(w) if w.root.join("link.toml").is_file() => Ok(w.root),
        Ok(w) => Err(format!(
            "{} is a cargo workspace without link.toml, not the morphlink checkout; {NEEDS}",
            w.root.display()
        )),
        Err(e) => Err(format!("{e}; {NEEDS}")),
    }
}

/// `--data`, or the paper's measured radii in the workspace's `data/`.
fn data_or_default(data: Option<PathBuf>) -> Result<PathBuf, String> {
    match data {
        Some(d) => Ok(d),
        None => Ok(workspace_root()?.join(DEFAULT_DATA)),
    }
}

/// The paper's measured radii, relative to the workspace root.
const DEFAULT_DATA: &str = "data/fig9_calibration.csv";

fn run(cli: Cli) -> Result<(), String> {
    let link = match cli.link {
        Some(path) => path,
        None => workspace_root()?.join("link.toml"),
    };
    let p = file::load(&link)?;
    // A geometry with no measured radii behind it: say so before anything is predicted for it
    // (calibrate says more: it refuses data from another geometry).
    if let Some(note) = file::unfitted_geometry_note(&p) {
        eprintln!("morph-model: {}: {note}", link.display());
    }
    match cli.cmd {
        Cmd::Fourbar {
            radius_mm,
            straight,
            json,
            chart,
            want,
            gait,
        } => {
            let g = file::load_with_fourbar(&link)?.1;
            if json && (chart.is_some() || want.is_some() || gait.is_some()) {
                return Err("--json goes with --radius-mm or --straight".into());
            }
            if let Some(path) = chart {
                fourbar_chart(&p, &g, &path)?;
                println!("wrote {}", path.display());
            } else if let Some(w) = want {
                print!("{}", fourbar_inverse(&p, &g, &w)?);
            } else if let Some(w) = gait {
                print!("{}", fourbar_gait(&p, &g, &w)?);
            } else {
                let radius = if straight { None } else { radius_mm };
                let (lo, hi) = fourbar::reachable_radii_mm(&p);
                if let Some(r) = radius {
                    if !(r >= lo && r <= hi) {
                        return Err(format!(
                            "--radius-mm {r} is outside the reachable range {} mm \
                             (--straight gives the unmorphed link)",
                            inward((lo, hi), 2)
                        ));
                    }
                }
                let fb = FourBar::new(g, p.geometry.length_m, radius).map_err(|e| e.to_string())?;
                if json {
                    let j = fourbar_json(&fb, radius)?;
                    println!("{}", serde_json::to_string(&j).map_err(|e| e.to_string())?);
                } else {
                    print!("{}", fourbar_summary(&fb, radius)?);
                }
            }
        }
        Cmd::Calibrate {
            data,
            measured_on,
            write,
        } => {
            let data = data_or_default(data)?;
            let d = calibrate::load_data(&data, "measured")?;
            let from_link = measured_on.map(|f| file::load(&f).map(|q| (f, q.geometry)));
            let measured = match (d.geometry, from_link.transpose()?) {
                (Some(g), Some((f, h))) if g != h => {
                    return Err(format!(
                        "{} records another geometry than --measured-on {}: {}",
                        data.display(),
                        f.display(),
                        file::geometry_differences(&h, &g).join(", ")
                    ))
                }
                (Some(g), _) | (None, Some((_, g))) => g,
                (None, None) => {
                    return Err(format!(
                        "{} does not say which geometry its radii were measured on: add a line \
                         `{}` or pass --measured-on LINK.toml",
                        data.display(),
                        calibrate::geometry_line(&p.geometry)
                    ))
                }
            };
            calibrate::check_same_geometry(&p, &measured)
                .map_err(|e| format!("{}: {e}", data.display()))?;
            let pts = d.points;
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
            let fig9 = charts::load_fig9(&data_or_default(data)?)?;
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
            let fig9 = charts::load_fig9(&data_or_default(data)?)?;
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

/// The foot path as one JSON object: `radius_mm` (null when straight), `straight`, `chord_mm`,
/// `end_angle_deg`, `length_mm`, the rigid links in mm, and `points` of
/// `{crank_deg, foot_x_mm, foot_y_mm}`, one per degree of crank.
fn fourbar_json(fb: &FourBar, radius_mm: Option<f64>) -> Result<serde_json::Value, String> {
    let g = &fb.geometry;
    let points: Vec<serde_json::Value> = fb
        .foot_path(fourbar::DEFAULT_STEPS)
        .map_err(|e| e.to_string())?
        .iter()
        .map(|p| serde_json::json!({"crank_deg": p.crank_deg, "foot_x_mm": p.foot_x_mm, "foot_y_mm": p.foot_y_mm}))
        .collect();
    Ok(serde_json::json!({
        "radius_mm": radius_mm,
        "straight": radius_mm.is_none(),
        "length_mm": fb.length_m * 1e3,
        "chord_mm": fb.chord_m() * 1e3,
        "end_angle_deg": fourbar::end_angle_rad(fb.length_m, fb.kappa_per_m).to_degrees(),
        "ground_mm": g.ground_m * 1e3,
        "crank_mm": g.crank_m * 1e3,
        "rocker_mm": g.rocker_m * 1e3,
        "points": points,
    }))
}

fn radius_words(radius_mm: Option<f64>) -> String {
    radius_mm.map_or("straight".to_string(), |r| {
        format!("locked at R = {r:.2} mm")
    })
}

/// The human summary: the linkage, the chord, the foot path's lowest point and extents.
fn fourbar_summary(fb: &FourBar, radius_mm: Option<f64>) -> Result<String, String> {
    let g = &fb.geometry;
    let c = fb.chord_m();
    let s = fb.stats().map_err(|e| e.to_string())?;
    let low = fb.pose(s.lowest_crank_deg).map_err(|e| e.to_string())?;
    let kind = if fourbar::is_crank_rocker(g, c) {
        "crank-rocker"
    } else {
        "full-turn crank, not a crank-rocker"
    };
    let margin = fourbar::grashof_margin_m([g.ground_m, g.crank_m, g.rocker_m, c]);
    Ok(format!(
        "four-bar: ground {:.1} mm, crank {:.1} mm, rocker {:.1} mm, morphing link {:.1} mm {}\n\
         {kind}, Grashof margin {:.2} mm; transmission angle at least {:.1} deg from a toggle\n\
         chord {:.2} mm, end angles {:.2} deg\n\
         foot path ({} points, foot at {:.2} of the link, offset {:.1} mm):\n  \
         lowest point ({:.2}, {:.2}) mm at crank {:.1} deg\n  \
         stride {:.2} mm, height {:.2} mm\n  \
         bounding box x {:.2}..{:.2} mm, y {:.2}..{:.2} mm\n",
        g.ground_m * 1e3,
        g.crank_m * 1e3,
        g.rocker_m * 1e3,
        fb.length_m * 1e3,
        radius_words(radius_mm),
        margin * 1e3,
        s.min_sin_transmission.asin().to_degrees(),
        c * 1e3,
        fourbar::end_angle_rad(fb.length_m, fb.kappa_per_m).to_degrees(),
        fourbar::DEFAULT_STEPS,
        g.foot_at,
        g.foot_offset_m * 1e3,
        low.foot[0] * 1e3,
        low.foot[1] * 1e3,
        s.lowest_crank_deg,
        s.get(Property::Stride),
        s.get(Property::Height),
        s.min_x_mm,
        s.max_x_mm,
        s.min_y_mm,
        s.max_y_mm,
    ))
}

/// A wanted value as given, or in exponent notation where it has more digits than a length
/// of a linkage could (`1e308`, `1e-320`).
fn number(v: f64) -> String {
    if v != 0.0 && !(1e-3..1e6).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// How far off, mm: to 0.0001 mm with its sign (a value just past an end of the span is off
/// by less than the span's 0.001 mm), or in exponent notation when far off.
fn off_text(v: f64) -> String {
    if v.abs() >= 1e6 {
        format!("{v:+e}")
    } else {
        format!("{v:+.4}")
    }
}

/// `lo..hi` to `decimals`, rounded inward so that each printed end is itself reached: the
/// reachable radii to 0.01 mm as `RANGE` prints them (each end a radius `MORPH` takes), a
/// property's span to 0.001 mm.
fn inward((lo, hi): (f64, f64), decimals: usize) -> String {
    let k = 10f64.powi(decimals as i32);
    let (lo, hi) = ((lo * k).ceil() / k, (hi * k).floor() / k);
    format!("{lo:.decimals$}..{hi:.decimals$}")
}

/// The `MORPH` line for a radius, rounded to 0.01 mm inside the reachable range.
fn morph_line(radius_mm: f64, (lo, hi): (f64, f64)) -> String {
    let r = (radius_mm * 100.0)
        .round()
        .clamp((lo * 100.0).ceil(), (hi * 100.0).floor())
        / 100.0;
    format!("MORPH {r:.2}")
}

/// `--gait property=v1,v2,...`: for each leg the radius that gives its value (the one nearest
/// the middle of the reachable range where several do), then the `GAIT` line of them all.
fn fourbar_gait(p: &LinkParams, g: &FourBarGeometry, spec: &str) -> Result<String, String> {
    let (name, values) = spec.split_once('=').ok_or(
        "--gait takes PROPERTY=V1,V2,..., one value per leg, e.g. stride_mm=26,25.5,26.5,25",
    )?;
    let prop = Property::parse(name.trim()).ok_or(format!("--gait: unknown property {name:?}"))?;
    let range = fourbar::reachable_radii_mm(p);
    let mid = 0.5 * (range.0 + range.1);
    let mut out = String::new();
    let mut radii = Vec::new();
    for (leg, v) in values.split(',').enumerate() {
        let want_mm: f64 = v
            .trim()
            .parse()
            .ok()
            .filter(|v: &f64| v.is_finite())
            .ok_or(format!(
                "--gait: leg {}: {v:?} is not a number of mm",
                leg + 1
            ))?;
        let sols = match fourbar::inverse(*g, p.geometry.length_m, range, prop, want_mm)
            .map_err(|e| e.to_string())?
        {
            Inverse::Found(sols) => sols,
            Inverse::Unreachable { span_mm, .. } => {
                return Err(format!(
                    "--gait: leg {}: no reachable radius gives {} = {} mm (it spans {} mm)",
                    leg + 1,
                    prop.name(),
                    number(want_mm),
                    inward(span_mm, 3)
                ))
            }
        };
        let (r, got) = sols
            .iter()
            .copied()
            .min_by(|a, b| (a.0 - mid).abs().total_cmp(&(b.0 - mid).abs()))
            .expect("found at least one");
        out += &format!(
            "leg {}: {} = {want_mm} mm at radius {r:.3} mm ({} = {got:.4} mm)\n",
            leg + 1,
            prop.name(),
            prop.name()
        );
        radii.push(
            morph_line(r, range)
                .trim_start_matches("MORPH ")
                .to_string(),
        );
    }
    if radii.len() > morphlink::budget::MAX_LINKS {
        return Err(format!(
            "--gait: {} legs; a board drives at most {}",
            radii.len(),
            morphlink::budget::MAX_LINKS
        ));
    }
    out += &format!("send: GAIT {}\n", radii.join(" "));
    Ok(out)
}

/// `--want property=value`: the radii that give it, each with its `MORPH` line, or how close
/// the reachable range gets (an error).
fn fourbar_inverse(p: &LinkParams, g: &FourBarGeometry, want: &str) -> Result<String, String> {
    let names: Vec<&str> = Property::ALL.iter().map(|p| p.name()).collect();
    let (name, value) = want.split_once('=').ok_or(format!(
        "--want takes PROPERTY=VALUE, e.g. stride_mm=30 (properties: {})",
        names.join(", ")
    ))?;
    let prop = Property::parse(name.trim()).ok_or(format!(
        "--want: unknown property {name:?}; properties: {}",
        names.join(", ")
    ))?;
    let want_mm: f64 = value
        .trim()
        .parse()
        .ok()
        .filter(|v: &f64| v.is_finite())
        .ok_or(format!("--want: {value:?} is not a number of mm"))?;
    let range = fourbar::reachable_radii_mm(p);
    match fourbar::inverse(*g, p.geometry.length_m, range, prop, want_mm)
        .map_err(|e| e.to_string())?
    {
        Inverse::Found(sols) => {
            let mut out = format!(
                "{} = {want_mm} mm: {} solution{} within the reachable radii {} mm\n",
                prop.name(),
                sols.len(),
                if sols.len() == 1 { "" } else { "s" },
                inward(range, 2)
            );
            for (r, v) in &sols {
                out += &format!(
                    "  radius {r:.3} mm gives {} = {v:.4} mm; send: {}\n",
                    prop.name(),
                    morph_line(*r, range)
                );
            }
            Ok(out)
        }
        Inverse::Unreachable { span_mm, nearest } => Err(format!(
            "no reachable radius gives {} = {} mm: over {} mm it spans {} mm; \
             nearest: radius {:.3} mm gives {:.4} mm ({} mm off), {}",
            prop.name(),
            number(want_mm),
            inward(range, 2),
            inward(span_mm, 3),
            nearest.0,
            nearest.1,
            off_text(nearest.1 - want_mm),
            morph_line(nearest.0, range)
        )),
    }
}

/// Fig. 10 of the paper, for the model: the linkage at a few crank angles (the tightest
/// reachable radius) and the foot paths of the straight link and radii across the range.
struct FourBarChart {
    /// `(legend, foot path in mm)`, straight first.
    paths: Vec<(String, Vec<(f64, f64)>)>,
    /// The linkage drawn: `(ground pivots, crank, morphing link, rocker)` per crank angle, mm.
    poses: Vec<Vec<(f64, f64)>>,
    /// Which radius the drawn linkage has.
    drawn: String,
    /// Plot bounds, mm.
    x: (f64, f64),
    y: (f64, f64),
}

/// Pixels per mm of the four-bar chart (equal scales on both axes).
const FOURBAR_PX_PER_MM: f64 = 9.0;

impl Figure for FourBarChart {
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        format: Format,
    ) -> PlotResult {
        let text = format.has_text();
        let frame = Frame::new(20, 12, 40, 55).text(text);
        let title = format!("Foot paths; linkage at {}", self.drawn);
        let mut chart = frame
            .builder(root, Some(&title))
            .build_cartesian_2d(self.x.0..self.x.1, self.y.0..self.y.1)?;
        mesh(&mut chart, "x (mm)", "y (mm)", text).draw()?;
        for (i, pose) in self.poses.iter().enumerate() {
            let style = if i == 0 {
                BLACK.stroke_width(2)
            } else {
                BLACK.mix(0.35).stroke_width(1)
            };
            line(&mut chart, pose.iter().copied(), style, None)?;
            // The joints: O4, O2, A and B (the link's last point before the rocker).
            let joints = [pose[0], pose[1], pose[2], pose[pose.len() - 2]];
            chart.draw_series(
                joints
                    .into_iter()
                    .map(|p| Circle::new(p, 3, style.filled())),
            )?;
        }
        for (i, (label, pts)) in self.paths.iter().enumerate() {
            let colour = if i == 0 {
                RGBColor(90, 90, 90)
            } else {
                palette(i - 1)
            };
            let mut closed = pts.clone();
            closed.push(pts[0]);
            line(
                &mut chart,
                closed,
                colour.stroke_width(2),
                text.then_some(label.as_str()),
            )?;
        }
        if text {
            legend(&mut chart, SeriesLabelPosition::UpperRight)?;
        }
        Ok(())
    }
}

fn fourbar_chart(
    p: &LinkParams,
    g: &FourBarGeometry,
    path: &std::path::Path,
) -> Result<(), String> {
    let l = p.geometry.length_m;
    let (lo, hi) = fourbar::reachable_radii_mm(p);
    let mut radii: Vec<Option<f64>> = vec![None];
    radii.extend((0..4).map(|i| Some(hi - (hi - lo) * i as f64 / 3.0)));
    let mut paths = Vec::new();
    for r in &radii {
        let fb = FourBar::new(*g, l, *r).map_err(|e| e.to_string())?;
        let pts: Vec<(f64, f64)> = fb
            .foot_path(fourbar::DEFAULT_STEPS)
            .map_err(|e| e.to_string())?
            .iter()
            .map(|q| (q.foot_x_mm, q.foot_y_mm))
            .collect();
        let label = match r {
            None => "straight link (unmorphed)".to_string(),
            Some(r) => format!("R = {r:.2} mm (chord {:.2} mm)", fb.chord_m() * 1e3),
        };
        paths.push((label, pts));
    }
    let fb = FourBar::new(*g, l, Some(lo)).map_err(|e| e.to_string())?;
    let mm = |v: [f64; 2]| (v[0] * 1e3, v[1] * 1e3);
    let mut poses = Vec::new();
    for deg in [60.0, 150.0, 240.0, 330.0] {
        let pose = fb.pose(deg).map_err(|e| e.to_string())?;
        let mut pts = vec![mm([g.ground_m, 0.0]), (0.0, 0.0), mm(pose.a)];
        pts.extend(fb.link_points(&pose, 24).into_iter().map(mm));
        pts.push(mm([g.ground_m, 0.0]));
        poses.push(pts);
    }
    let all = paths
        .iter()
        .flat_map(|(_, v)| v.iter())
        .chain(poses.iter().flatten());
    let (mut x, mut y) = (
        (f64::INFINITY, f64::NEG_INFINITY),
        (f64::INFINITY, f64::NEG_INFINITY),
    );
    for &(px, py) in all {
        x = (x.0.min(px), x.1.max(px));
        y = (y.0.min(py), y.1.max(py));
    }
    // Room for the legend above the linkage, a margin elsewhere.
    let (x, y) = ((x.0 - 5.0, x.1 + 5.0), (y.0 - 5.0, y.1 + 12.0));
    let size = (
        ((x.1 - x.0) * FOURBAR_PX_PER_MM) as u32 + 67,
        ((y.1 - y.0) * FOURBAR_PX_PER_MM) as u32 + 84,
    );
    let chart = FourBarChart {
        paths,
        poses,
        drawn: format!("R = {lo:.2} mm, crank 60..330 deg"),
        x,
        y,
    };
    write(path, size, &chart).map_err(String::from)
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

    #[test]
    fn fourbar_json_has_the_documented_shape_and_the_closed_form_chord() {
        let p = LinkParams::DEFAULT;
        let l = p.geometry.length_m;
        for r in [Some(38.0), None] {
            let fb = FourBar::new(FourBarGeometry::DEFAULT, l, r).unwrap();
            let j = fourbar_json(&fb, r).unwrap();
            let want_chord = r.map_or(50.0, |r| 2.0 * r * (50.0 / (2.0 * r)).sin());
            assert!((j["chord_mm"].as_f64().unwrap() - want_chord).abs() < 1e-12);
            assert_eq!(j["radius_mm"].as_f64(), r);
            assert_eq!(j["straight"].as_bool(), Some(r.is_none()));
            let pts = j["points"].as_array().unwrap();
            assert_eq!(pts.len(), 360);
            for (i, q) in pts.iter().enumerate() {
                let q = q.as_object().unwrap();
                assert_eq!(q.len(), 3);
                assert_eq!(q["crank_deg"].as_f64(), Some(i as f64));
                assert!(q["foot_x_mm"].as_f64().unwrap().is_finite());
                assert!(
                    q["foot_y_mm"].as_f64().unwrap() < 0.0,
                    "the foot hangs below the pivots"
                );
            }
        }
    }

    #[test]
    fn fourbar_inverse_prints_the_morph_line_and_round_trips() {
        let p = LinkParams::DEFAULT;
        let g = FourBarGeometry::DEFAULT;
        let out = fourbar_inverse(&p, &g, "stride_mm=26.5").unwrap();
        assert!(
            out.contains("1 solution") && out.contains("send: MORPH 35.94"),
            "{out}"
        );
        let r: f64 = out
            .split("send: MORPH ")
            .nth(1)
            .unwrap()
            .trim()
            .parse()
            .unwrap();
        let s = FourBar::new(g, p.geometry.length_m, Some(r))
            .unwrap()
            .stats()
            .unwrap();
        assert!((s.get(Property::Stride) - 26.5).abs() < 1e-3);
        let e = fourbar_inverse(&p, &g, "stride_mm=30").unwrap_err();
        assert!(
            e.contains("no reachable radius") && e.contains("nearest") && e.contains("MORPH 46.45"),
            "{e}"
        );
        assert!(fourbar_inverse(&p, &g, "width_mm=3")
            .unwrap_err()
            .contains("lowest_mm, stride_mm, height_mm"));
        assert!(fourbar_inverse(&p, &g, "stride_mm")
            .unwrap_err()
            .contains("PROPERTY=VALUE"));
        assert!(fourbar_inverse(&p, &g, "stride_mm=abc")
            .unwrap_err()
            .contains("not a number"));
    }

    #[test]
    fn fourbar_morph_lines_stay_inside_the_reachable_range() {
        let range = (32.7166, 46.4571);
        assert_eq!(morph_line(38.123, range), "MORPH 38.12");
        assert_eq!(morph_line(32.7166, range), "MORPH 32.72");
        assert_eq!(morph_line(46.4571, range), "MORPH 46.45");
    }

    #[test]
    fn fourbar_cli_refuses_what_it_cannot_do() {
        let run_args = |a: &[&str]| {
            let mut v = vec!["morph-model", "fourbar"];
            v.extend_from_slice(a);
            Cli::try_parse_from(v)
                .map_err(|e| e.to_string())
                .and_then(run)
        };
        assert!(run_args(&["--radius-mm", "20"])
            .unwrap_err()
            .contains("outside the reachable range"));
        assert!(run_args(&["--want", "stride_mm=26.5", "--json"])
            .unwrap_err()
            .contains("--json goes with"));
        assert!(
            run_args(&[]).is_err(),
            "one of --radius-mm, --straight, --chart, --want is needed"
        );
        assert!(run_args(&["--radius-mm", "38", "--straight"]).is_err());
    }

    #[test]
    fn fourbar_reads_its_section_from_the_link_file() {
        let dir =
            std::env::temp_dir().join(format!("morphlink-fourbar-link-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let base =
            std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../link.toml")).unwrap();
        let run_with = |section: &str| {
            let path = dir.join("link.toml");
            std::fs::write(&path, format!("{base}\n[fourbar]\n{section}\n")).unwrap();
            let link = path.to_str().unwrap().to_string();
            run(Cli::parse_from([
                "morph-model",
                "--link",
                &link,
                "fourbar",
                "--straight",
            ]))
        };
        run_with("crank_m = 0.012").unwrap();
        let e = run_with("rocker_m = 0.018").unwrap_err();
        assert!(
            e.contains("link.toml: [fourbar] with radius 32.72 mm")
                && e.contains("cannot assemble"),
            "{e}"
        );
        // The other commands do not judge the four-bar.
        let path = dir.join("link.toml");
        run(Cli::parse_from([
            "morph-model",
            "--link",
            path.to_str().unwrap(),
            "table",
        ]))
        .unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn fourbar_chart_names_every_radius() {
        let dir = std::env::temp_dir().join(format!("morphlink-fourbar-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("fourbar.svg");
        fourbar_chart(&LinkParams::DEFAULT, &FourBarGeometry::DEFAULT, &path).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        for s in [
            "straight link",
            "R = 46.46 mm",
            "R = 32.72 mm",
            "x (mm)",
            "y (mm)",
        ] {
            assert!(svg.contains(s), "{s} missing");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
