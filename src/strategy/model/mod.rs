//! What `boost` and `closed` share: both heaters driven through the controller's thermal model
//! ([`observer`]) to target temperatures (PLA [`PLA_SOFT_TARGET_C`], TCA the radius's
//! temperature from [`target`]), the TCA from the start of soften on.

pub mod observer;
pub mod own;
pub mod target;

use super::{Start, TargetTemps, Tick, SOFT_THRESHOLD_C};
use crate::heater::HeaterConfig;
use crate::link::R_TT_K_PER_W;
use crate::supervisor::{HEATER_VERDICT_S, PLA_LIMITS, TCA_LIMITS};
use crate::vocab::{Measurements, Phase, Powers};
use observer::{HeatedNode, Observer};

/// PLA temperature the `boost` and `closed` strategies hold while bending, °C: 5 K above the
/// [`SOFT_THRESHOLD_C`] (so thermistor noise and the observer's error do not drop it below the
/// threshold) and no hotter, because every kelvin above Tg must be cooled off again in lock.
pub const PLA_SOFT_TARGET_C: f32 = 75.0;
const _: () = assert!(PLA_SOFT_TARGET_C >= SOFT_THRESHOLD_C + 5.0);
/// Largest PLA heater power of the model strategies, W: the heater's cap (5 W, above the
/// paper's 4 W) is the overdrive.
pub const PLA_BOOST_MAX_W: f32 = HeaterConfig::PLA.max_power_w;
/// Largest TCA power of the model strategies, W: the TCA heater's cap (2 W, about 110 °C steady
/// under water); the target temperature, not this cap, bounds the TCA.
pub const TCA_BOOST_MAX_W: f32 = HeaterConfig::TCA.max_power_w;
/// The model strategies count the TCA as at its target once within this band, K: 0.27 mm of
/// radius per kelvin, so 0.3 K is under 0.1 mm.
pub const MODEL_SETTLE_BAND_C: f32 = 0.3;
/// ...for this long, s: a few ticks more than the observer's correction needs to move after a
/// step, so a passing crossing of the band does not count.
pub const MODEL_SETTLE_S: f32 = 1.5;

/// A TCA past its target on the PLA's heat alone (its heater at keep-alive) waits in bend for
/// the PLA's view to be learnt, so the rod has flowed, until it is this far over its target,
/// K: then waiting would only bend the rod past the target (0.27 mm of radius per kelvin), so
/// bend ends as it is (`cargo xtask calibration`; docs/calibration.md, "What changed, and
/// why").
pub const MODEL_PASSIVE_OVERSHOOT_K: f32 = 2.0;

/// Longest bend waits on the PLA's view alone once everything else is ready, s: long enough for
/// a hifi PLA bead, 10 s behind its rod, to slow after soften (`cargo xtask calibration`;
/// docs/calibration.md, "What changed, and why"), short enough that a PLA thermistor that never
/// slows (drifting low while the PLA is held on it) does not keep the rod heated until the bend
/// timeout.
pub const MODEL_PLA_WAIT_MAX_S: f32 = 20.0;

/// Thermistor guard of the model strategies, K: a heater is switched off for the tick while its
/// thermistor reads more than this above the heater's target temperature. The model assumes
/// water; in still air the same power heats about five times as much, and the feed-forward
/// alone would run into the supervisor's 130 °C limit. 10 K is far outside the observer's
/// normal error (under 2 K) and keeps every target (at most 110 °C) 10 K under the limit.
pub const MODEL_GUARD_K: f32 = 10.0;
// The guard trips before the supervisor does, with the margin the comment above claims.
const _: () = assert!(target::TARGET_MAX_C + MODEL_GUARD_K + 10.0 <= TCA_LIMITS.max_c);
const _: () = assert!(PLA_SOFT_TARGET_C + MODEL_GUARD_K + 10.0 <= PLA_LIMITS.max_c);
// TUNE's soft-rod check takes the same ceiling and threshold.
const _: () = assert!(
    PLA_SOFT_TARGET_C + MODEL_GUARD_K == crate::tune::TUNE_SOFTEN_READING_MAX_C
        && SOFT_THRESHOLD_C == crate::tune::TUNE_SOFT_THRESHOLD_C
);

/// Least power the model strategies ask of a heater in a phase that has it on, W. The
/// supervisor's heater watch starts afresh whenever a heater's command drops to 0 W; restarted
/// on a hot heater that the controller is letting cool towards its target, it would read the
/// fall as a dead heater. 0.05 W keeps the watch running and heats the TCA by under 2 K.
pub const MODEL_KEEP_ALIVE_W: f32 = 0.05;
const _: () = assert!(MODEL_KEEP_ALIVE_W > 0.0 && MODEL_KEEP_ALIVE_W * R_TT_K_PER_W < 2.0);

/// A TCA at full power has reached as close to its target as the 2 W cap allows (strong
/// convection in cold water, a low supply) once its thermistor's rate times this, s, no longer
/// covers what it lacks of the target band: a first-order approach at the bulk's 17 s time
/// constant ends `rate × 17 s` above where it is, so the TCA will not get there within a bend,
/// and the model strategies lock there instead of waiting for the bend timeout. The TCA's slower
/// modes (the silicone's, minutes) rise further, too slowly to matter before the rod locks, and
/// lock keeps heating the TCA towards its target. 1.15 K short of the target this asks under
/// 0.05 K/s, as the fixed rate it replaces did; a TCA far short and still rising slowly (a bead
/// lagging its TCA by 20 K on a high-fidelity link at 10.95 V) stalls too, where the fixed rate
/// waited out the bend timeout (`cargo xtask strategies`; docs/strategies.md, "Morphs in a
/// row").
pub const MODEL_STALL_TAU_S: f32 = 17.0;
/// A stall counts only this long after MORPH, s: after the supervisor's heater-not-heating check
/// has judged the TCA (on from MORPH, judged within `HEATER_VERDICT_S`), so a dead TCA, which does not rise at
/// all, trips instead of passing for a stalled one.
pub const STALL_AFTER_S: f32 = HEATER_VERDICT_S + MODEL_SETTLE_S;
const _: () = assert!(STALL_AFTER_S > HEATER_VERDICT_S);

/// Power a heater delivers when asked for `w` (W) at the measured supply: capped by the
/// heater and by full duty (`V²/R`); unknown supply assumes the request is met.
fn deliverable_w(heater: &HeaterConfig, w: f32, supply_v: f32) -> f32 {
    let w = crate::mathf::clamp(w, 0.0, heater.max_power_w);
    if supply_v.is_finite() && supply_v > 0.0 {
        w.min(supply_v * supply_v / heater.resistance_ohm)
    } else {
        w
    }
}

/// The most the model may ask of the TCA this tick, W: its boost cap, or less under a shared
/// supply's allowance.
fn tca_most_w(t: &Tick) -> f32 {
    TCA_BOOST_MAX_W.min(t.allow_w.tca_w)
}

/// Which heaters the model drives in `phase`: (PLA, TCA). The PLA is heated through soften and
/// bend; the TCA from soften on until lock ends, so it holds the shape while the PLA cools.
fn driven(phase: Phase) -> (bool, bool) {
    (
        matches!(phase, Phase::Soften | Phase::Bend),
        matches!(phase, Phase::Soften | Phase::Bend | Phase::Lock),
    )
}

/// What a strategy knows of its PLA view when bend may end (see [`ModelDrive::bend_done`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct PlaView {
    /// The PLA's view is learnt: its thermistor has slowed or reads what the model expects.
    pub learnt: bool,
    /// The PLA thermistor reads far colder than the model expects: the rod is colder than the
    /// estimate says and may not have flowed.
    pub cold: bool,
}

/// The model, the TCA target and the drive state `boost` and `closed` share.
#[derive(Clone, Copy, Debug)]
pub struct ModelDrive {
    observer: Observer,
    tca_target_c: f32,
    /// The PLA target of soften and bend, °C ([`Start::pla_target_c`]).
    pla_target_c: f32,
    last_ms: u64,
    applied: Powers,
    /// Whether the TCA was given the most it may have when its power was last set: its cap,
    /// or a shared supply's allowance, judged against that tick's own (an allowance moves by
    /// milliwatts from tick to tick).
    tca_at_most: bool,
    settled_since_ms: Option<u64>,
    /// Since when bend has waited on the PLA's view alone, ms.
    pla_wait_since_ms: Option<u64>,
}

impl ModelDrive {
    /// The model started from the temperatures at MORPH, aiming the TCA at `tca_target_c` and
    /// the PLA at the morph's target, each at most what its part's ceiling lets it reach
    /// ([`crate::part_limit::reachable_c`]).
    pub fn new(s: &Start, tca_target_c: f32) -> Self {
        let m = s.m;
        // Targets the parts' ceilings would not let the heaters reach are not targets.
        let reachable = |h: HeatedNode, limit_c: f32| {
            crate::part_limit::reachable_c(s.cal, h, m.t_amb_c, limit_c)
        };
        let tca_target_c = tca_target_c.min(reachable(HeatedNode::Tca, TCA_LIMITS.max_c));
        let pla_target_c = s
            .pla_target_c
            .min(reachable(HeatedNode::Pla, PLA_LIMITS.max_c));
        ModelDrive {
            observer: Observer::from_measured_with_gains(
                m.t_pla_c,
                m.t_tca_c,
                m.t_amb_c,
                [
                    s.cal.sensor_gain(HeatedNode::Pla),
                    s.cal.sensor_gain(HeatedNode::Tca),
                ],
                [
                    s.cal.cross_gain(HeatedNode::Pla),
                    s.cal.cross_gain(HeatedNode::Tca),
                ],
                s.cal.model_convection_w_m2k(),
            ),
            tca_target_c,
            pla_target_c,
            last_ms: s.now_ms,
            applied: Powers::default(),
            tca_at_most: false,
            settled_since_ms: None,
            pla_wait_since_ms: None,
        }
    }

    /// The controller's thermal model of the link.
    pub fn observer(&self) -> &Observer {
        &self.observer
    }

    /// TCA temperature the morph aims at, °C.
    #[cfg(test)]
    pub(crate) fn tca_target_c(&self) -> f32 {
        self.tca_target_c
    }

    /// The temperatures [`ModelDrive::powers`] drives to in `phase`: the PLA at the morph's
    /// PLA target in soften and bend, the TCA at its target in soften, bend and lock.
    pub(crate) fn targets_c(&self, phase: Phase) -> TargetTemps {
        let (pla_on, tca_on) = driven(phase);
        TargetTemps {
            pla_c: if pla_on { self.pla_target_c } else { f32::NAN },
            tca_c: if tca_on { self.tca_target_c } else { f32::NAN },
        }
    }

    /// Lowers the TCA's target by `k`, K: a lock too warm to end eases its hold
    /// (`closed`'s [`super::closed::CLOSED_LOCK_EASE_MAX_K`]).
    pub(crate) fn ease_tca(&mut self, k: f32) {
        self.tca_target_c -= k;
    }

    /// A new phase: the settle hold starts afresh.
    pub(crate) fn enter(&mut self) {
        self.settled_since_ms = None;
        self.pla_wait_since_ms = None;
    }

    /// Runs the model over the time since the last tick with the powers the heaters delivered,
    /// then corrects it with this tick's thermistors.
    pub(crate) fn observe(&mut self, now_ms: u64, m: &Measurements) {
        let dt_s = now_ms.saturating_sub(self.last_ms) as f32 / 1000.0;
        self.last_ms = now_ms;
        if dt_s > 0.0 {
            let a = self.applied;
            self.observer.predict(dt_s, a.pla_w, a.tca_w, m.t_amb_c);
            self.observer.correct(dt_s, m.t_pla_c, m.t_tca_c);
        }
    }

    /// True once `ok` has held for [`MODEL_SETTLE_S`].
    fn held(&mut self, now_ms: u64, ok: bool) -> bool {
        if !ok {
            self.settled_since_ms = None;
            return false;
        }
        let since = *self.settled_since_ms.get_or_insert(now_ms);
        now_ms.saturating_sub(since) as f32 / 1000.0 >= MODEL_SETTLE_S
    }

    /// Whether bend is over: the TCA (`tca_c`, the strategy's view of it) at its target or as
    /// close as the link allows, the PLA (`pla_c`) soft, the TCA's view `learnt` and the PLA's
    /// `pla.learnt`, all for [`MODEL_SETTLE_S`]; the wait on `pla.learnt` alone lasts at most
    /// [`MODEL_PLA_WAIT_MAX_S`]. A TCA that is past its target on the PLA's heat alone (heater
    /// at keep-alive) does not wait for `pla.learnt` (it only warms further while it waits)
    /// unless `pla.cold` says the PLA reads far colder than the model expects (the rod has not
    /// flowed yet), and then only until it is [`MODEL_PASSIVE_OVERSHOOT_K`] over its target.
    pub(crate) fn bend_done(
        &mut self,
        t: &Tick,
        pla_c: f32,
        tca_c: f32,
        learnt: bool,
        pla: PlaView,
    ) -> bool {
        // Above the target with the TCA off is as close as the link can get (warm
        // surroundings and the PLA's heat keep it there).
        let passive = tca_c > self.tca_target_c && self.applied.tca_w <= MODEL_KEEP_ALIVE_W;
        let reached = (tca_c - self.tca_target_c).abs() <= MODEL_SETTLE_BAND_C
            || passive
            || (tca_c < self.tca_target_c
                && self.tca_at_most
                && self.observer.measured_rate_k_per_s(HeatedNode::Tca) * MODEL_STALL_TAU_S
                    < self.tca_target_c - MODEL_SETTLE_BAND_C - tca_c
                && t.since_start_s > STALL_AFTER_S);
        let overshooting = tca_c > self.tca_target_c + MODEL_PASSIVE_OVERSHOOT_K;
        let pla_ready = pla.learnt || (passive && (!pla.cold || overshooting));
        let ready_but_pla = reached && pla_c >= t.th.soft_threshold_c && learnt;
        // The wait on the PLA's view alone is bounded: a PLA thermistor that never slows (one
        // drifting while the PLA is held on it) must not keep the rod heated until the timeout.
        let waited_out = if ready_but_pla && !pla_ready {
            let since = *self.pla_wait_since_ms.get_or_insert(t.now_ms);
            t.now_ms.saturating_sub(since) >= (MODEL_PLA_WAIT_MAX_S * 1000.0) as u64
        } else {
            self.pla_wait_since_ms = None;
            false
        };
        let at_target = ready_but_pla && (pla_ready || waited_out);
        self.held(t.now_ms, at_target) && t.in_phase_s >= MODEL_SETTLE_S
    }

    /// Powers for `phase`: the model driven to `target − offset` for each heater (the offsets
    /// are `closed`'s disturbance estimates, 0 for `boost`), then the thermistor guard.
    pub(crate) fn powers(&mut self, phase: Phase, t: &Tick, d_pla: f32, d_tca: f32) -> Powers {
        let o = &self.observer;
        let m = t.m;
        let (pla_on, tca_on) = driven(phase);
        let pla_most_w = PLA_BOOST_MAX_W.min(t.allow_w.pla_w);
        let pla_w = if pla_on {
            o.power_to_reach_w(HeatedNode::Pla, self.pla_target_c - d_pla, pla_most_w)
        } else {
            0.0
        };
        let tca_w = if tca_on {
            o.power_to_reach_w(HeatedNode::Tca, self.tca_target_c - d_tca, tca_most_w(t))
        } else {
            0.0
        };
        // The guard: whatever the model says, a thermistor well above target turns its heater
        // down to the keep-alive power.
        let keep = |on: bool, w: f32, too_hot: bool| {
            if !on {
                0.0
            } else if too_hot {
                MODEL_KEEP_ALIVE_W
            } else {
                w.max(MODEL_KEEP_ALIVE_W)
            }
        };
        let pla_w = keep(pla_on, pla_w, m.t_pla_c > self.pla_target_c + MODEL_GUARD_K);
        let tca_w = keep(tca_on, tca_w, m.t_tca_c > self.tca_target_c + MODEL_GUARD_K);
        let p = Powers { pla_w, tca_w };
        // What the heaters deliver under the allowance (the controller caps them to it).
        self.applied = Powers {
            pla_w: deliverable_w(&HeaterConfig::PLA, p.pla_w, t.supply_v),
            tca_w: deliverable_w(&HeaterConfig::TCA, p.tca_w, t.supply_v),
        }
        .min(t.allow_w);
        self.tca_at_most = self.applied.tca_w
            >= deliverable_w(&HeaterConfig::TCA, tca_most_w(t), t.supply_v) - 1e-3;
        p
    }
}
