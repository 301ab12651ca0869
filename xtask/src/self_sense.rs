//! `cargo xtask self-sense`: the TCA as its own thermometer, judged against the true TCA mean
//! over the hifi ensemble. Per drawn link (on a board that senses current): `auto` morphs to
//! the targets with the compiled-in calibration ("before TUNE"), then TUNE from rest and the
//! same morphs with its calibration ("after TUNE"); at every tick of bend and lock the STATUS
//! value `t_tca_self_c` is compared with the plant's true TCA mean. Each link runs twice: as
//! drawn, and with its TCA's strain term (gauge factor) set to zero, which separates what the
//! coil's strain costs from what the temperature coefficient and the model cost. Prints the
//! Markdown tables of docs/safety.md, "The TCA as its own thermometer", and (after TUNE) how
//! far the TCA thermistor strays from a bead model driven by the own temperature within the
//! 20 s a drift must be caught in (docs/shape.md, "Not done, and why").

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

/// The window a drifting TCA thermistor must be caught in, s (issue 35: the faults' drift of
/// [`crate::faults::DRIFT_K_PER_S`] within 20 s).
pub const DRIFT_WINDOW_S: f64 = 20.0;
/// Phases of a morph the redundancy residual is judged in.
const JUDGED: [Phase; 4] = [Phase::Soften, Phase::Bend, Phase::Lock, Phase::Release];

/// The errors one morph gave: every judged tick's, and the one as bend ended, K; and per
/// morph, per judged phase, the largest change of the redundancy residual over
/// [`DRIFT_WINDOW_S`] ([`redundancy_changes`]).
#[derive(Default)]
struct Errors {
    ticks: Vec<f64>,
    bend_end: Vec<f64>,
    changes: [Vec<f64>; 4],
}

/// One tick of a morph: its time (s), phase, the TCA thermistor's reading and the own
/// temperature (°C), and the TCA's power (W).
type Sample = (f64, Phase, f64, f64, f64);

/// A healthy TCA thermistor as the own temperature would predict it: a first-order lag of
/// `tau_s` behind the own temperature less `drop_k_per_w` times the TCA's power (the fall from
/// the coil to the bead beside it while it heats).
fn predicted(trace: &[Sample], tau_s: f64, drop_k_per_w: f64) -> Vec<f64> {
    let mut b = trace.first().map_or(0.0, |s| s.2);
    let mut last_t = trace.first().map_or(0.0, |s| s.0);
    trace
        .iter()
        .map(|&(t, _, _, own, p)| {
            let (keep, to) = ((-(t - last_t) / tau_s).exp(), own - drop_k_per_w * p);
            last_t = t;
            b = to + (b - to) * keep;
            b
        })
        .collect()
}

/// The residual of the TCA thermistor against [`predicted`], with the lag and the drop fitted
/// on the morph itself (a grid; the best case a check with both learnt could hope for), and
/// per judged phase the largest change of that residual over [`DRIFT_WINDOW_S`], K: what a
/// drift of 0.2 K/s (4 K in the window) would have to stand out of.
fn redundancy_changes(trace: &[Sample]) -> [f64; 4] {
    let trace: Vec<Sample> = trace.iter().copied().filter(|s| s.3.is_finite()).collect();
    let mut best = (f64::INFINITY, Vec::new());
    for tau_s in [2.0, 3.0, 4.0, 6.0, 8.0, 10.0] {
        for drop in [0.0, 2.5, 5.0, 7.5, 10.0, 15.0, 20.0] {
            let r: Vec<f64> = predicted(&trace, tau_s, drop)
                .iter()
                .zip(&trace)
                .map(|(p, s)| s.2 - p)
                .collect();
            let mean = r.iter().sum::<f64>() / r.len().max(1) as f64;
            let ss = r.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>();
            if ss < best.0 {
                best = (ss, r);
            }
        }
    }
    let r = best.1;
    let mut out = [0.0f64; 4];
    let mut from = 0;
    for i in 0..trace.len() {
        while trace[i].0 - trace[from].0 > DRIFT_WINDOW_S {
            from += 1;
        }
        if let Some(k) = JUDGED.iter().position(|&p| p == trace[i].1) {
            for j in from..i {
                out[k] = out[k].max((r[i] - r[j]).abs());
            }
        }
    }
    out
}

/// Morphs `target_mm` on a fresh copy of `spec` with `cal`; the self-sensed TCA's errors, and
/// where `redundancy` the bead's against the own temperature ([`redundancy_changes`]).
fn morph(
    spec: &HifiSpec,
    noise: morphlink::bench::Noise,
    cal: &Calibration,
    target_mm: f32,
    e: &mut Errors,
    redundancy: bool,
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
    let mut trace: Vec<Sample> = Vec::new();
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
        let m = rig.ctrl.measurements();
        if redundancy {
            trace.push((
                rig.now_ms() as f64 / 1000.0,
                phase,
                m.t_tca_c as f64,
                rig.ctrl.tca_self_c().map_or(f64::NAN, f64::from),
                rig.ctrl.powers().tca_w as f64,
            ));
        }
    }
    if redundancy {
        for (v, c) in e.changes.iter_mut().zip(redundancy_changes(&trace)) {
            v.push(c);
        }
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

/// One table row: p50, p95 and the largest |error| of the ticks, and p95 at bend's end.
fn row(name: &str, e: &Errors) -> String {
    let mut abs: Vec<f64> = e.ticks.iter().map(|x| x.abs()).collect();
    let mut end: Vec<f64> = e.bend_end.iter().map(|x| x.abs()).collect();
    let bias = e.ticks.iter().sum::<f64>() / e.ticks.len().max(1) as f64;
    format!(
        "| {name} | {} | {:+.1} K | {:.1} K | {:.1} K | {:.1} K | {:.1} K |",
        abs.len(),
        bias,
        crate::ensemble::quantile(&mut abs, 0.5),
        crate::ensemble::quantile(&mut abs, 0.95),
        abs.last().copied().unwrap_or(f64::NAN),
        crate::ensemble::quantile(&mut end, 0.95),
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
                                    morph(
                                        &s,
                                        noise,
                                        &Calibration::DEFAULT,
                                        t,
                                        &mut out[2 * v],
                                        false,
                                    );
                                    morph(&s, noise, &cal, t, &mut out[2 * v + 1], true);
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
            for (a, c) in all[i].changes.iter_mut().zip(e.changes) {
                a.extend(c);
            }
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
            crate::ensemble::quantile(v, 0.5),
            crate::ensemble::quantile(v, 0.95),
            largest
        );
    }
    let _ = writeln!(t);
    let _ = writeln!(
        t,
        "| after TUNE | phase | morphs | largest 20 s change, p50 | p95 | largest | over 4 K |\n| --- | --- | --- | --- | --- | --- | --- |"
    );
    for (name, i) in [("as drawn", 1), ("no strain term", 3)] {
        for (phase, v) in JUDGED.iter().zip(all[i].changes.iter_mut()) {
            let drift_k = f64::from(crate::faults::DRIFT_K_PER_S) * DRIFT_WINDOW_S;
            let over = v.iter().filter(|&&c| c > drift_k).count();
            let largest = v.iter().cloned().fold(0.0f64, f64::max);
            let _ = writeln!(
                t,
                "| {name} | {} | {} | {:.1} K | {:.1} K | {:.1} K | {over} |",
                phase.as_str(),
                v.len(),
                crate::ensemble::quantile(v, 0.5),
                crate::ensemble::quantile(v, 0.95),
                largest,
            );
        }
    }
    print!("{t}");
    Ok(())
}
