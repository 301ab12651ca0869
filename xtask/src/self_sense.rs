//! `cargo xtask self-sense`: the TCA as its own thermometer, judged against the true TCA mean
//! over the hifi ensemble. Per drawn link (on a board that senses current): `auto` morphs to
//! the targets with the compiled-in calibration ("before TUNE"), then TUNE from rest and the
//! same morphs with its calibration ("after TUNE"); at every tick of bend and lock the STATUS
//! value `t_tca_self_c` is compared with the plant's true TCA mean. Each link runs twice: as
//! drawn, and with its TCA's strain term (gauge factor) set to zero, which separates what the
//! coil's strain costs from what the temperature coefficient and the model cost. Prints the
//! Markdown tables of docs/safety.md, "The TCA as its own thermometer".

use morphlink::calibration::{Calibration, TCA_TCR_NOMINAL_PPM_PER_K};
use morphlink::vocab::Phase;
use morphlink_plant::hifi::{Hifi, HifiSpec};
use morphlink_plant::Plant;
use morphlink_sim::Rig;
use std::fmt::Write as _;

/// High-fidelity links drawn by default (the calibration chart's count and seed, so the links
/// are the same ones).
pub const DEFAULT_DRAWS: u64 = 40;
/// Targets morphed per link, mm: the tightest, middle and loosest of the strategy chart's.
pub const TARGETS_MM: [f32; 3] = [32.92, 39.59, 46.26];
/// A tick is judged once the TCA's true mean is this far above ambient, K (below it the
/// reading is the rest reference itself).
pub const MIN_RISE_K: f64 = 5.0;

/// Options of the task.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// High-fidelity links to draw.
    #[arg(long, default_value_t = DEFAULT_DRAWS)]
    pub draws: u64,
    /// Seed of the draws.
    #[arg(long, default_value_t = crate::ensemble::DEFAULT_SEED)]
    pub seed: u64,
}

/// The errors one morph gave: every judged tick's, and the one as bend ended, K.
#[derive(Default)]
struct Errors {
    ticks: Vec<f64>,
    bend_end: Vec<f64>,
}

/// Morphs `target_mm` on a fresh copy of `spec` with `cal`; the self-sensed TCA's errors.
fn morph(
    spec: &HifiSpec,
    noise: morphlink::bench::Noise,
    cal: &Calibration,
    target_mm: f32,
    e: &mut Errors,
) {
    let mut rig = Rig::with_plant(Hifi::new(*spec).expect("a drawn link builds"), noise);
    rig.ctrl
        .set_calibration(*cal)
        .expect("a calibration in bounds");
    for _ in 0..50 {
        rig.tick();
    }
    rig.handle_line(&format!("MORPH {target_mm} auto"), &mut |_| {});
    let amb = spec.ambient_c;
    let mut last: Option<f64> = None;
    let stop = rig.now_ms() + 900_000;
    while !rig.ctrl.idle() && rig.now_ms() < stop {
        let was_bend = rig.ctrl.phase() == Phase::Bend;
        rig.tick();
        rig.drain_events(&mut |_| {});
        let phase = rig.ctrl.phase();
        let truth = rig.plant().truth().tca_c;
        let err = rig.ctrl.tca_self_c().map(|t| t as f64 - truth);
        if was_bend && phase != Phase::Bend {
            if let Some(x) = last {
                e.bend_end.push(x);
            }
        }
        if matches!(phase, Phase::Bend | Phase::Lock) && truth - amb >= MIN_RISE_K {
            if let Some(x) = err {
                e.ticks.push(x);
            }
        }
        last = err;
    }
}

/// TUNE from rest on a fresh copy of `spec`: the calibration it reached (the default if it
/// did not end `done`).
fn tune(spec: &HifiSpec, noise: morphlink::bench::Noise) -> Calibration {
    let mut rig = Rig::with_plant(Hifi::new(*spec).expect("a drawn link builds"), noise);
    rig.tick();
    rig.handle_line("TUNE", &mut |_| {});
    let stop = rig.now_ms() + 200_000;
    while rig.ctrl.tuning() && rig.now_ms() < stop {
        rig.tick();
        rig.drain_events(&mut |_| {});
    }
    rig.ctrl.calibration()
}

fn percentile(v: &mut [f64], p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    v[((v.len() - 1) as f64 * p).round() as usize]
}

/// One table row: p50, p95 and the largest |error| of the ticks, and p95 at bend's end.
fn row(name: &str, e: &Errors) -> String {
    let mut abs: Vec<f64> = e.ticks.iter().map(|x| x.abs()).collect();
    let mut end: Vec<f64> = e.bend_end.iter().map(|x| x.abs()).collect();
    let bias = e.ticks.iter().sum::<f64>() / e.ticks.len().max(1) as f64;
    format!(
        "| {name} | {} | {:+.1} K | {:.1} K | {:.1} K | {:.1} K | {:.1} K |",
        abs.len(),
        bias,
        percentile(&mut abs, 0.5),
        percentile(&mut abs, 0.95),
        abs.last().copied().unwrap_or(f64::NAN),
        percentile(&mut end, 0.95),
    )
}

/// Runs the task: prints the tables.
pub fn run(args: &Args) -> Result<(), String> {
    let draws: Vec<u64> = (0..args.draws).collect();
    // (variant, stage) → errors; the fitted coefficients against the drawn ones.
    let results: Vec<([Errors; 4], f64)> = std::thread::scope(|scope| {
        let handles: Vec<_> = draws
            .chunks(draws.len().div_ceil(2).max(1))
            .map(|chunk| {
                scope.spawn(move || {
                    chunk
                        .iter()
                        .map(|&d| {
                            let (spec, noise) = morphlink_sim::ensemble::hifi_draw(args.seed, d)
                                .expect("the ensemble's draws are valid");
                            let mut out: [Errors; 4] = Default::default();
                            let mut tcr_miss = f64::NAN;
                            for (v, gauge) in [spec.tca.gauge, 0.0].into_iter().enumerate() {
                                let mut s = spec;
                                s.tca.gauge = gauge;
                                let cal = tune(&s, noise);
                                if v == 0 {
                                    tcr_miss =
                                        cal.tca_tcr_ppm_per_k as f64 * 1e-6 / s.tca.tcr_per_k - 1.0;
                                }
                                for &t in &TARGETS_MM {
                                    morph(&s, noise, &Calibration::DEFAULT, t, &mut out[2 * v]);
                                    morph(&s, noise, &cal, t, &mut out[2 * v + 1]);
                                }
                            }
                            eprint!(".");
                            (out, tcr_miss)
                        })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap())
            .collect()
    });
    eprintln!();
    let mut all: [Errors; 4] = Default::default();
    let mut misses: Vec<f64> = Vec::new();
    let mut nominal_misses: Vec<f64> = Vec::new();
    for (d, (r, miss)) in draws.iter().zip(results) {
        for (i, e) in r.into_iter().enumerate() {
            all[i].ticks.extend(e.ticks);
            all[i].bend_end.extend(e.bend_end);
        }
        misses.push(miss.abs() * 100.0);
        let (spec, _) = morphlink_sim::ensemble::hifi_draw(args.seed, *d).expect("valid");
        nominal_misses.push(
            (TCA_TCR_NOMINAL_PPM_PER_K as f64 * 1e-6 / spec.tca.tcr_per_k - 1.0).abs() * 100.0,
        );
    }
    let mut t = String::new();
    let _ = writeln!(
        t,
        "| link, calibration | ticks | mean error | p50 \\|error\\| | p95 | largest | p95 at bend's end |"
    );
    let _ = writeln!(t, "| --- | --- | --- | --- | --- | --- | --- |");
    let names = [
        "as drawn, before TUNE",
        "as drawn, after TUNE",
        "no strain term, before TUNE",
        "no strain term, after TUNE",
    ];
    for (name, e) in names.iter().zip(&all) {
        let _ = writeln!(t, "{}", row(name, e));
    }
    let _ = writeln!(t);
    let _ = writeln!(
        t,
        "| temperature coefficient | p50 \\|miss\\| | p95 | largest |\n| --- | --- | --- | --- |"
    );
    for (name, v) in [
        ("nominal 1500 ppm/K", &mut nominal_misses),
        ("fitted by TUNE", &mut misses),
    ] {
        let largest = v.iter().cloned().fold(0.0f64, f64::max);
        let _ = writeln!(
            t,
            "| {name} | {:.1} % | {:.1} % | {:.1} % |",
            percentile(v, 0.5),
            percentile(v, 0.95),
            largest
        );
    }
    print!("{t}");
    Ok(())
}
