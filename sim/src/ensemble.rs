//! Mismatch ensembles: links that differ from the controller's model the way a real link does,
//! and whole morphs on them measured the same way for every strategy. `no_std` and
//! allocation-free; `cargo xtask strategies` and the tests drive it.
//!
//! Every range is a named default with the reason for it.

use crate::rig::{LinkSetup, Rig};
use morphlink::controller::{Outputs, TICK_MS};
use morphlink::protocol::{Command, Mode};
use morphlink::supervisor::FaultCode;
use morphlink_model::draw::{splitmix, uniform};
use morphlink_model::params::{H_AIR_W_M2K, H_WATER_W_M2K};
use morphlink_plant::Plant;

/// Convection coefficient relative to the model's, a factor range: ±30 % covers stirred to
/// still water and the scatter of the paper's nine convection measurements.
pub const H_SCALE_RANGE: (f64, f64) = (0.7, 1.3);
/// Share of links in still air instead of water (`h` = [`H_AIR_W_M2K`] × the drawn factor):
/// the model assumes water, so these test what a five-fold convection error does.
pub const AIR_SHARE: f64 = 0.1;
/// Ambient (water or air) temperature, °C: a cool lab to a warm one.
pub const AMBIENT_RANGE_C: (f64, f64) = (15.0, 30.0);
/// Heater supply, V: 12 V ± 10 % (a bench supply set by hand, a sagging adapter).
pub const SUPPLY_RANGE_V: (f64, f64) = (10.8, 13.2);
/// Each heater's true resistance relative to the nominal one, a factor range: ± 10 %
/// (nichrome wrap length by hand, the TCA's 5–8 Ω spread narrowed by measuring it once).
pub const HEATER_SCALE_RANGE: (f64, f64) = (0.9, 1.1);
/// Thermistor time constant, s, for the PLA and TCA sensors (drawn once per link, shared): 2 s
/// for a bead pressed against the heater to 6 s for one loosely embedded (a bare bead in still
/// air is 6.5–12 s).
pub const SENSOR_TAU_RANGE_S: (f64, f64) = (2.0, 6.0);
/// Thermistor noise, °C (standard deviation): the nominal 0.05 °C up to four times that for
/// long unshielded leads.
pub const SENSOR_NOISE_RANGE_C: (f64, f64) = (0.02, 0.2);
/// Calibration error of the table, a factor range applied separately to the bending stiffness
/// and to the TCA force (preload and coefficient together): ± 1 %. The fit's residuals at the
/// three measured radii are at most 0.19 mm (0.5 %); ± 1 % on each gives radius errors up to
/// about twice that.
pub const CALIBRATION_SCALE_RANGE: (f64, f64) = (0.99, 1.01);
/// Time the link is left after `done` before its radius is measured, s: the TCA and the
/// surroundings-warmed silicone cool fully, so the spring-back and any slow creep are in.
pub const SETTLE_AFTER_DONE_S: f64 = 60.0;
/// Longest simulated morph before a run is called stuck, s (above every phase timeout's sum).
pub const MAX_MORPH_S: f64 = 900.0;

/// How the simulated link differs from the controller's model in one run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mismatch {
    /// True if the medium is still air instead of water.
    pub air: bool,
    /// Convection coefficient relative to the medium's nominal one.
    pub h_scale: f64,
    /// Ambient temperature, °C.
    pub ambient_c: f64,
    /// Heater supply, V.
    pub supply_v: f64,
    /// True heater resistances relative to nominal (PLA, TCA).
    pub heater_scale: [f64; 2],
    /// Thermistor time constant, s (PLA and TCA).
    pub sensor_tau_s: f64,
    /// Thermistor noise, °C.
    pub sensor_noise_c: f64,
    /// True bending stiffness relative to the calibrated one.
    pub stiffness_scale: f64,
    /// True TCA force (preload and coefficient) relative to the calibrated one.
    pub force_scale: f64,
    /// Seed of the sensor noise.
    pub seed: u64,
}

/// High-fidelity link `draw` of the ensemble with seed `seed`, on the reduced-order grid (the
/// strategy and calibration charts' links), and its board's thermistor noise: the lumped draw's
/// of the same number. One definition for the charts and the tests, so a test of "draw 15"
/// runs the link the charts call draw 15.
#[cfg(feature = "hifi")]
pub fn hifi_draw(
    seed: u64,
    draw: u64,
) -> Result<
    (morphlink_plant::hifi::HifiSpec, morphlink::bench::Noise),
    morphlink_model::reference::ReferenceError,
> {
    let spec = morphlink_plant::hifi::HifiSpec::draw(
        morphlink::link::LINK,
        morphlink_plant::hifi::Grid::Reduced,
        seed,
        draw,
    )?;
    Ok((spec, Mismatch::draw(seed, draw).plant().noise()))
}

impl Mismatch {
    /// The nominal link: no mismatch, the nominal sensors.
    pub const NONE: Mismatch = Mismatch {
        air: false,
        h_scale: 1.0,
        ambient_c: 22.0,
        supply_v: 12.0,
        heater_scale: [1.0, 1.0],
        sensor_tau_s: 3.0,
        sensor_noise_c: 0.05,
        stiffness_scale: 1.0,
        force_scale: 1.0,
        seed: 0x5eed_1234,
    };

    /// Draw number `index` of the ensemble with seed `seed`: every factor uniform in its range.
    pub fn draw(seed: u64, index: u64) -> Mismatch {
        let mut s = seed ^ index.wrapping_mul(0xd1b5_4a32_d192_ed03);
        splitmix(&mut s);
        Mismatch {
            air: uniform(&mut s, (0.0, 1.0)) < AIR_SHARE,
            h_scale: uniform(&mut s, H_SCALE_RANGE),
            ambient_c: uniform(&mut s, AMBIENT_RANGE_C),
            supply_v: uniform(&mut s, SUPPLY_RANGE_V),
            heater_scale: [
                uniform(&mut s, HEATER_SCALE_RANGE),
                uniform(&mut s, HEATER_SCALE_RANGE),
            ],
            sensor_tau_s: uniform(&mut s, SENSOR_TAU_RANGE_S),
            sensor_noise_c: uniform(&mut s, SENSOR_NOISE_RANGE_C),
            stiffness_scale: uniform(&mut s, CALIBRATION_SCALE_RANGE),
            force_scale: uniform(&mut s, CALIBRATION_SCALE_RANGE),
            seed: splitmix(&mut s),
        }
    }

    /// The simulated link this mismatch describes.
    pub fn plant(&self) -> LinkSetup {
        let mut p = LinkSetup::NOMINAL;
        let s = &mut p.params.surroundings;
        s.h_w_m2k = self.h_scale * if self.air { H_AIR_W_M2K } else { H_WATER_W_M2K };
        s.ambient_c = self.ambient_c;
        let m = &mut p.params.mechanics;
        m.bending_stiffness_nm2 *= self.stiffness_scale;
        m.preload_n *= self.force_scale;
        m.force_coeff_n_per_k *= self.force_scale;
        p.supply_v = self.supply_v;
        p.heater_ohm = [
            p.heater_ohm[0] * self.heater_scale[0],
            p.heater_ohm[1] * self.heater_scale[1],
        ];
        p.sensor_tau_s = [self.sensor_tau_s, self.sensor_tau_s, p.sensor_tau_s[2]];
        p.sensor_noise_c = self.sensor_noise_c;
        p.seed = self.seed;
        p
    }
}

/// One tick of a traced morph.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TracePoint {
    /// Time since MORPH, s.
    pub t_s: f64,
    /// True PLA and TCA temperatures, °C.
    pub true_c: [f64; 2],
    /// What the PLA and TCA thermistors read (lagged, before noise), °C.
    pub sensed_c: [f64; 2],
    /// Heater powers delivered, W (PLA, TCA).
    pub power_w: [f64; 2],
    /// True radius, mm.
    pub radius_mm: f64,
    /// Phase name.
    pub phase: &'static str,
}

/// How a run ended.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Outcome {
    /// `done` was reported.
    Done,
    /// The supervisor or a phase timeout tripped.
    Fault(FaultCode),
    /// Still busy after [`MAX_MORPH_S`].
    Stuck,
}

/// The measured result of one morph.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RunResult {
    /// How it ended.
    pub outcome: Outcome,
    /// MORPH to `done`, s (NaN unless done).
    pub time_s: f64,
    /// Radius [`SETTLE_AFTER_DONE_S`] after done, mm (NaN unless done).
    pub final_mm: f64,
    /// `(final − target) / target`, % (NaN unless done).
    pub error_pct: f64,
    /// Hottest true PLA and TCA temperatures during the run, °C.
    pub max_true_c: [f64; 2],
    /// The fullest the supervisor's level and change tests came over the run, each a share of
    /// its limit (1 trips): how close a healthy morph came to an alarm.
    pub peak_shares: [f32; 2],
}

/// Runs one morph to `target_mm` in `mode` on the lumped link `plant`, calling `trace` every
/// tick from MORPH to the radius measurement, and measures it.
pub fn run_morph_traced(
    plant: LinkSetup,
    target_mm: f32,
    mode: Mode,
    trace: &mut impl FnMut(&TracePoint),
) -> RunResult {
    run_morph_on(Rig::new(plant), target_mm, mode, trace)
}

/// Runs one morph to `target_mm` in `mode` on the rig `rig` (any plant: the lumped link, or
/// the high-fidelity one with `morphlink-plant`'s `hifi` feature), calling `trace` every tick,
/// and measures it as [`run_morph_traced`] does.
pub fn run_morph_on<P: Plant>(
    mut rig: Rig<P>,
    target_mm: f32,
    mode: Mode,
    trace: &mut impl FnMut(&TracePoint),
) -> RunResult {
    rig.boot();
    let t0 = rig.now_ms();
    rig.ctrl.handle(
        t0,
        Command::Morph {
            radius_mm: target_mm,
            mode,
        },
        &mut |_| {},
    );
    let mut max_c = [f64::NEG_INFINITY; 2];
    let mut outcome = Outcome::Stuck;
    let mut done_ms = None;
    let end_ms = t0 + (MAX_MORPH_S * 1000.0) as u64;
    loop {
        let now = rig.now_ms();
        if let Some(d) = done_ms {
            if now >= d + (SETTLE_AFTER_DONE_S * 1000.0) as u64 {
                break;
            }
        } else if now >= end_ms {
            break;
        }
        let _: Outputs = rig.tick();
        let truth = rig.plant().truth();
        let (pla, tca) = (truth.pla_c, truth.tca_c);
        max_c = [max_c[0].max(pla), max_c[1].max(tca)];
        let sensed = rig.plant().sample();
        trace(&TracePoint {
            t_s: (rig.now_ms() - t0) as f64 / 1000.0,
            true_c: [pla, tca],
            sensed_c: [sensed.t_pla_c, sensed.t_tca_c],
            power_w: rig.powers_w(),
            radius_mm: rig.radius_mm(),
            phase: rig.ctrl.phase().as_str(),
        });
        if done_ms.is_none() {
            if let Some(f) = rig.ctrl.fault() {
                outcome = Outcome::Fault(f.code);
                break;
            }
            if !rig.ctrl.busy() {
                outcome = Outcome::Done;
                done_ms = Some(rig.now_ms());
            }
        }
        while rig.ctrl.pop_event().is_some() {}
    }
    let (time_s, final_mm) = match (outcome, done_ms) {
        (Outcome::Done, Some(d)) => ((d - t0) as f64 / 1000.0, rig.radius_mm()),
        _ => (f64::NAN, f64::NAN),
    };
    RunResult {
        outcome,
        time_s,
        final_mm,
        error_pct: (final_mm - target_mm as f64) / target_mm as f64 * 100.0,
        max_true_c: max_c,
        peak_shares: rig.ctrl.supervisor().peak_shares(),
    }
}

/// Runs one morph and measures it (see [`run_morph_traced`]).
pub fn run_morph(plant: LinkSetup, target_mm: f32, mode: Mode) -> RunResult {
    run_morph_traced(plant, target_mm, mode, &mut |_| {})
}

/// Ticks per second of simulated time.
pub const TICKS_PER_S: u64 = 1000 / TICK_MS;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_are_reproducible_and_within_their_ranges() {
        let mut air = 0;
        for i in 0..500 {
            let m = Mismatch::draw(7, i);
            assert_eq!(m, Mismatch::draw(7, i));
            assert!((0.7..=1.3).contains(&m.h_scale));
            assert!((15.0..=30.0).contains(&m.ambient_c));
            assert!((10.8..=13.2).contains(&m.supply_v));
            assert!(m.heater_scale.iter().all(|s| (0.9..=1.1).contains(s)));
            assert!((2.0..=6.0).contains(&m.sensor_tau_s));
            air += m.air as u32;
        }
        assert!((25..=80).contains(&air), "{air} of 500 in air");
        assert_ne!(Mismatch::draw(7, 1), Mismatch::draw(7, 2));
        assert_ne!(Mismatch::draw(7, 1), Mismatch::draw(8, 1));
    }

    #[test]
    fn the_nominal_mismatch_is_the_nominal_plant() {
        assert_eq!(Mismatch::NONE.plant(), LinkSetup::NOMINAL);
    }

    #[test]
    fn a_measured_run_reports_time_error_and_peak_temperatures() {
        let r = run_morph(LinkSetup::NOMINAL, 38.0, Mode::Gated);
        assert_eq!(r.outcome, Outcome::Done);
        assert!(r.time_s > 30.0 && r.time_s < 200.0, "{r:?}");
        assert!(r.error_pct.abs() < 2.0, "{r:?}");
        assert!(r.max_true_c[0] > 70.0 && r.max_true_c[0] < 130.0, "{r:?}");
    }
}
