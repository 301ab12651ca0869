//! `closed`: temperature control of both heaters on the model corrected by the thermistors (the
//! observer); every phase is gated on the corrected estimate, and the lock temperature is
//! compensated for the release spring-back.

use super::model::observer::{HeatedNode, DISTURBANCE_TAU_S, LEARN_MAX_RATE_K_PER_S, SENSOR_TAU_S};
use super::model::own::{OwnTemp, OWN_STILL_K_PER_S};
use super::model::{target, ModelDrive, PlaView};
use super::{Start, Strategy, TargetTemps, Tick, RELEASE_S, RIGID_THRESHOLD_C, SOFT_THRESHOLD_C};
use crate::vocab::{Measurements, Phase, Powers};

/// `closed` ends lock when the observer's PLA estimate and the PLA thermistor corrected for its
/// lag (reading + assumed lag × its rate, what a first-order sensor trails by) are both below
/// [`RIGID_THRESHOLD_C`]. Under water this ends lock about 3 s before the bare thermistor would;
/// a thermistor that stops falling holds the lock, whatever the model says, until it has stalled
/// cool enough for the shape to hold ([`CLOSED_LOCK_STALL_MAX_C`]).
pub const CLOSED_RIGID_LEAD_S: f32 = SENSOR_TAU_S;
/// The lag correction of [`CLOSED_RIGID_LEAD_S`] is used only while the surroundings read at
/// least this far below [`RIGID_THRESHOLD_C`], K: then the rod keeps cooling after release and a
/// lock ended a kelvin early freezes the same shape. In surroundings nearer the threshold the
/// rod may stall just above it, so the bare thermistor decides, as in `gated`.
pub const CLOSED_LEAD_AMBIENT_MARGIN_K: f32 = 10.0;
/// Where `closed` counts the PLA as rigid in cool surroundings (see
/// [`CLOSED_LEAD_AMBIENT_MARGIN_K`]), °C: 12 K below Tg the PLA's modulus is 98 % of the way to
/// glassy on a log scale (about 1.5 GPa) and its flow time 27 s, growing e-fold with every 3 K it
/// keeps cooling after release, so the shape is frozen and waiting for [`RIGID_THRESHOLD_C`]
/// only costs time (docs/strategies.md, "The strategies"). In warm surroundings the rod may
/// stall near these temperatures, so there `closed` waits for [`RIGID_THRESHOLD_C`] on the bare
/// thermistor, as `gated` does.
pub const CLOSED_RIGID_COOL_C: f32 = 50.0;
const _: () =
    assert!(RIGID_THRESHOLD_C <= CLOSED_RIGID_COOL_C && CLOSED_RIGID_COOL_C < SOFT_THRESHOLD_C);

/// Bend need not wait for the PLA thermistor to slow while it reads within this of what the
/// observer expects ([`super::model::observer::Observer::innovation_k`]), K, unless the
/// observer has lowered its PLA estimate by more than this within the last
/// [`CLOSED_PLA_CORRECTED_S`]: otherwise the model follows the rod, so its estimate holds. 3 K
/// is what the reading's 0.5 s smoothing and a bead lag 1.5 s off the assumed 3 s make
/// together at the 1.5 K/s the bead rises at late in soften (the lumped ensemble's lags are
/// 2–6 s). A reading that agrees only because the observer has just caught up with it (a bead
/// that lags its rod by 10 s, as on the high-fidelity links) says the rod was that much colder
/// than the estimate: its heater is heating it on and it still flows (`cargo xtask
/// calibration`; docs/calibration.md, "Bend ends when the rod has stopped flowing").
pub const CLOSED_PLA_AGREE_K: f32 = 3.0;
/// How long a lowering of the observer's PLA estimate holds bend, s ([`CLOSED_PLA_AGREE_K`]):
/// three of the observer's time constants ([`DISTURBANCE_TAU_S`]), in which it completes 95 %
/// of a correction and the heater, following the estimate, brings the rod to its target. Since
/// bend began instead of over this window, a before-TUNE link (whose bead reads a share of its
/// rise, so the estimate is lowered through all of bend) held its rod 13 K over its target for
/// up to 20 s more and its median went 54.5 → 65.2 s with no gain in error; and the dead TCA in
/// a hifi lock was named in 14 s, past the 10 s aim (docs/safety.md).
pub const CLOSED_PLA_CORRECTED_S: f32 = 3.0 * DISTURBANCE_TAU_S;
const _: () = assert!(CLOSED_PLA_CORRECTED_S > 0.0 && CLOSED_PLA_CORRECTED_S <= 20.0);
const _: () = assert!(CLOSED_PLA_AGREE_K > 0.0 && CLOSED_PLA_AGREE_K < 5.0);

/// Bend waits for the PLA thermistor to change slower than this, K/s (unless it reads what the
/// observer expects, [`CLOSED_PLA_AGREE_K`]): a bead still rising says the rod is still
/// heating, and a rod a few kelvin under the PLA target flows several times slower. It is half
/// the observer's learning rate ([`LEARN_MAX_RATE_K_PER_S`]), at which the hifi rods were still
/// heating when bend ended (`cargo xtask calibration`; docs/calibration.md, "What changed, and
/// why").
pub const CLOSED_PLA_SETTLED_K_PER_S: f32 = 0.3;
const _: () = assert!(
    CLOSED_PLA_SETTLED_K_PER_S > 0.0 && CLOSED_PLA_SETTLED_K_PER_S <= LEARN_MAX_RATE_K_PER_S
);

/// A TCA past its target on the PLA's heat alone still waits in bend while the PLA thermistor,
/// not yet slowed under [`CLOSED_PLA_SETTLED_K_PER_S`], reads more than this below what the
/// observer expects, K: the rod is then colder than the estimate and has not flowed (the
/// high-fidelity links, whose bead reads far under the model late in soften). A reading that
/// trails the model by a bead lag alone (the lumped links', 2–6 s) is left out: there the rod
/// has flowed and waiting only bends it further (`cargo xtask calibration`;
/// docs/calibration.md, "What changed, and why").
pub const CLOSED_PLA_COLD_K: f32 = 6.0;
const _: () = assert!(CLOSED_PLA_COLD_K > CLOSED_PLA_AGREE_K);

/// `closed` also ends lock once the PLA thermistor has stalled: its rate came under this, either
/// way, K/s, and has stayed under [`CLOSED_LOCK_STALL_RESET_K_PER_S`] for [`CLOSED_LOCK_STALL_S`],
/// at a temperature under
/// [`CLOSED_LOCK_STALL_MAX_C`], in cool surroundings ([`CLOSED_LEAD_AMBIENT_MARGIN_K`], so the rod
/// keeps cooling after release; a bath too warm for the rod to turn rigid still ends in the lock
/// timeout). In still air the TCA's hold keeps the rod warm above [`CLOSED_RIGID_COOL_C`], and
/// waiting for a temperature the link will not reach would keep the TCA on until the lock
/// timeout (docs/strategies.md, "Where each strategy fails (lumped plant)"). 0.03 K/s is within a
/// few kelvin of the settled value at the still-air cooling time of minutes; under water the rod
/// passes these temperatures at several K/s, so the rule leaves water morphs alone (`cargo xtask
/// strategies`).
pub const CLOSED_LOCK_STALL_K_PER_S: f32 = 0.03;
/// How long the PLA thermistor must stay stalled before lock ends on it, s: from a rate under
/// [`CLOSED_LOCK_STALL_K_PER_S`], with no rate over [`CLOSED_LOCK_STALL_RESET_K_PER_S`] since. A
/// reading whose cooling a drift upward cancels passes through zero rate within seconds under
/// water.
pub const CLOSED_LOCK_STALL_S: f32 = 10.0;
/// A PLA rate over this, either way, K/s, ends a stall ([`CLOSED_LOCK_STALL_S`]): the observer's
/// rate carries up to 0.05 K/s of noise, which at the stall rate itself restarted the count
/// for a minute on the nominal still-air links.
pub const CLOSED_LOCK_STALL_RESET_K_PER_S: f32 = 0.06;
/// The warmest stalled PLA reading that ends lock, °C: 4 K under the 62 °C glass transition,
/// where a released shape holds as it does after the full wait and does not creep later
/// (`tests/morph.rs`; docs/strategies.md, "Where each strategy fails (lumped plant)"). A rod that
/// settles warmer is too warm to end ([`CLOSED_LOCK_SETTLE_TAU_S`], [`CLOSED_LOCK_EASE_MAX_K`]).
pub const CLOSED_LOCK_STALL_MAX_C: f32 = 58.0;
const _: () = assert!(
    CLOSED_LOCK_STALL_K_PER_S > 0.0
        && CLOSED_LOCK_STALL_K_PER_S < CLOSED_PLA_SETTLED_K_PER_S
        && CLOSED_LOCK_STALL_S > 0.0
        && CLOSED_LOCK_STALL_RESET_K_PER_S > CLOSED_LOCK_STALL_K_PER_S
        && CLOSED_RIGID_COOL_C < CLOSED_LOCK_STALL_MAX_C
        && CLOSED_LOCK_STALL_MAX_C < SOFT_THRESHOLD_C
);

/// A lock whose PLA cannot cool under [`CLOSED_LOCK_STALL_MAX_C`] is too warm to end: the TCA
/// holding this radius, or the surroundings, keep the rod soft, and waiting out the lock timeout
/// (`LOCK_TIMEOUT_S`, 600 s) with the TCA hot changes nothing. It cannot cool under it when even
/// its slowest settling stays over the line: the PLA reading and estimate less how fast the
/// reading fell over the last [`CLOSED_LOCK_STUCK_S`] times this, s, over two windows in a row:
/// a settling slower than any lock here shows (the links settle in their lock within 20–60 s
/// once the PLA heater is off; a still-air link at the least rated convection is the slowest),
/// so a rod that is still cooling towards a lockable temperature is not judged stuck. The fall is
/// the reading's over the window, not the observer's rate, whose 0.05 K/s of noise would hide
/// any stall. Such a lock first eases the TCA's hold ([`CLOSED_LOCK_EASE_MAX_K`]); once that is
/// spent it ends at once, as its timeout would, with the PLA's reading in its alarm.
pub const CLOSED_LOCK_SETTLE_TAU_S: f32 = 200.0;
/// The window over which the PLA's fall is read, s: long enough for its noise to matter little
/// (0.07 K between two readings, 0.5 K of settling once times [`CLOSED_LOCK_SETTLE_TAU_S`]).
pub const CLOSED_LOCK_STUCK_S: f32 = 30.0;
const _: () = assert!(CLOSED_LOCK_SETTLE_TAU_S > 0.0 && CLOSED_LOCK_STUCK_S > 0.0);

/// How far a lock too warm to end may lower its TCA's hold, K, in all: a rod that the TCA's
/// own heat keeps soft (still air at the tightest radii: the TCA holding the bend warms the
/// PLA beside it over [`CLOSED_LOCK_STALL_MAX_C`]) cools once the TCA is held a few kelvin
/// lower, and the rod, still soft, gives back that much of its bend (about 0.27 mm/K) before it
/// turns rigid. Each time the lock is judged too warm ([`CLOSED_LOCK_SETTLE_TAU_S`]) the hold
/// comes down by what the calibration's coupling says brings the PLA's settling
/// [`CLOSED_LOCK_EASE_AIM_K`] under the line, until this much is spent; the next too-warm
/// judgment then ends the lock as before. `done` reports the shape bend ended at: the
/// high-fidelity rods hold it while the hold comes down, a rod of one temperature gives some
/// back (docs/strategies.md, "A lock too warm to end"). 10 K is about 2.7 mm of a soft rod's
/// bend: a bath too warm for any hold still ends in the too-warm alarm.
pub const CLOSED_LOCK_EASE_MAX_K: f32 = 10.0;
/// Where an eased hold aims the PLA's settling, K under [`CLOSED_LOCK_STALL_MAX_C`], and how far
/// under it the lock's settling is still judged: far enough for the stall rule to end the lock
/// under it despite the reading's noise and the coupling being a kelvin off (aimed 1 K under, a
/// hifi still-air link settled 0.3 K under the line, where its noise kept resetting the stall).
pub const CLOSED_LOCK_EASE_AIM_K: f32 = 2.0;
/// A settling from here up is too warm for the lock to end, °C: half [`CLOSED_LOCK_EASE_AIM_K`]
/// under [`CLOSED_LOCK_STALL_MAX_C`], because the stall rule needs ten seconds on end under the
/// line, which a reading settling that near it seldom gives (a lumped still-air link settling at
/// 58.1 °C met the lock timeout).
const LOCK_TOO_WARM_C: f32 = CLOSED_LOCK_STALL_MAX_C - 0.5 * CLOSED_LOCK_EASE_AIM_K;
/// The least one easing lowers the hold, K: a strong coupling would otherwise ask for steps so
/// small that the lock timeout came before the cap was spent.
const LOCK_EASE_MIN_K: f32 = 1.0;
const _: () = assert!(
    CLOSED_LOCK_EASE_MAX_K > 0.0 && CLOSED_LOCK_EASE_MAX_K <= 20.0 && CLOSED_LOCK_EASE_AIM_K > 0.0
);

/// The `closed` strategy.
#[derive(Clone, Copy, Debug)]
pub struct Closed {
    /// The model it corrects and drives.
    pub drive: ModelDrive,
    /// This link's TCA map from MEASURED reports, `(a, b)` (see
    /// [`crate::calibration::Calibration::map`]).
    map: (f32, f32),
    /// Since when the PLA has read stalled in lock, ms ([`CLOSED_LOCK_STALL_K_PER_S`]).
    stalled_since_ms: Option<u64>,
    /// Where the current window of a too-warm lock began: ms and the PLA reading, °C
    /// ([`CLOSED_LOCK_STUCK_S`]).
    window: Option<(u64, f32)>,
    /// Windows in a row whose slowest settling was too warm ([`LOCK_TOO_WARM_C`]); at two the
    /// lock cannot finish and its timeout is now, unless the TCA's hold may still come down.
    stuck_windows: u8,
    /// How far the lock has lowered the TCA's hold, K ([`CLOSED_LOCK_EASE_MAX_K`]).
    eased_k: f32,
    /// The PLA bead's steady rise per kelvin of the TCA bead's, with the TCA alone heated (the
    /// calibration's rises per watt): how far an eased hold lowers the PLA.
    pla_per_tca: f32,
    /// The TCA's own temperature, where the morph started with one (a board that senses
    /// current, after `TUNE` fitted its coefficient): the TCA is then bent and held on it
    /// instead of on its thermistor.
    own: Option<OwnTemp>,
    /// What the own temperature reads low by at the hold, K: the strain factor
    /// ([`crate::calibration::Calibration::strain_k_m`]) times the bend from the rest
    /// reference's shape to the lock's (0 where either is unknown).
    strain_k: f32,
    /// The observer's highest PLA disturbance of bend no older than [`CLOSED_PLA_CORRECTED_S`]
    /// (taken afresh once older): when it was taken, ms, and its value, K
    /// ([`CLOSED_PLA_AGREE_K`]).
    bend_d_pla: (u64, f32),
}

impl Closed {
    /// For a morph starting as `s` says: the TCA aims at the lock temperature whose shape after
    /// release is the target, in the measured surroundings.
    pub fn new(s: &Start) -> Self {
        let map = s.cal.map();
        let need = target::lock_temp_for_final_radius_c(s.radius_mm, s.m.t_amb_c);
        let t = target::calibrated_aim_c(map, need, s.m.t_amb_c);
        let bend_per_m = crate::lumped::curvature_per_m(need) - s.rest_shape_per_m;
        let strain_k = s.cal.strain_k_m() * bend_per_m;
        Closed {
            drive: ModelDrive::new(s, t),
            map,
            stalled_since_ms: None,
            window: None,
            stuck_windows: 0,
            eased_k: 0.0,
            pla_per_tca: s.cal.tca_to_pla_k_per_w / s.cal.tca_rise_k_per_w,
            own: OwnTemp::new(s.now_ms, s.tca_self_c).filter(|_| s.cal.self_sensed()),
            strain_k: if strain_k.is_finite() { strain_k } else { 0.0 },
            bend_d_pla: (0, f32::NEG_INFINITY),
        }
    }

    /// Whether this morph bends on the TCA's own temperature.
    pub fn self_sensed(&self) -> bool {
        self.own.is_some()
    }

    /// The TCA temperature this morph bends and holds on, °C: its own where sensed, else the
    /// observer's estimate from its thermistor.
    fn tca_c(&self) -> f32 {
        match &self.own {
            Some(own) => own.temp_c() + self.strain_k,
            None => self.drive.observer().estimate_c(HeatedNode::Tca),
        }
    }

    /// Whether the PLA counts as rigid: see [`CLOSED_RIGID_LEAD_S`], or has stalled where the
    /// shape holds ([`CLOSED_LOCK_STALL_K_PER_S`]).
    fn rigid(&mut self, t: &Tick, pla_c: f32) -> bool {
        let m = t.m;
        let rigid_threshold_c = t.th.rigid_threshold_c;
        let rate = self.drive.observer().measured_rate_k_per_s(HeatedNode::Pla);
        let cool_surroundings = m.t_amb_c < rigid_threshold_c - CLOSED_LEAD_AMBIENT_MARGIN_K;
        let (lead_c, rigid_c) = if cool_surroundings {
            (
                m.t_pla_c + CLOSED_RIGID_LEAD_S * rate.min(0.0),
                CLOSED_RIGID_COOL_C,
            )
        } else {
            (m.t_pla_c, rigid_threshold_c)
        };
        // Only where the rod keeps cooling after release (a bath too warm to lock never ends).
        let may_stall = cool_surroundings
            && m.t_pla_c < CLOSED_LOCK_STALL_MAX_C
            && pla_c < CLOSED_LOCK_STALL_MAX_C;
        // Starts under the stall rate, ends over the reset rate (the rate's noise between).
        self.stalled_since_ms = match self.stalled_since_ms {
            Some(since) if may_stall && rate.abs() <= CLOSED_LOCK_STALL_RESET_K_PER_S => {
                Some(since)
            }
            _ if may_stall && rate.abs() <= CLOSED_LOCK_STALL_K_PER_S => Some(t.now_ms),
            _ => None,
        };
        // In whole milliseconds: the same test as in seconds, without a conversion.
        let stalled = self.stalled_since_ms.is_some_and(|since| {
            t.now_ms.saturating_sub(since) >= (CLOSED_LOCK_STALL_S * 1000.0) as u64
        });
        // Where the PLA settles at the slowest, judged over each window while it reads near or
        // over the line: still over it, and the lock can never end.
        let aim_c = CLOSED_LOCK_STALL_MAX_C - CLOSED_LOCK_EASE_AIM_K;
        let warmest = m.t_pla_c.min(pla_c);
        self.window = match self.window {
            Some((t0, c0)) if warmest >= aim_c => {
                let dt_s = t.now_ms.saturating_sub(t0) as f32 / 1000.0;
                if dt_s < CLOSED_LOCK_STUCK_S {
                    Some((t0, c0))
                } else {
                    let fall = ((c0 - m.t_pla_c) / dt_s).max(0.0);
                    let settle_c = warmest - fall * CLOSED_LOCK_SETTLE_TAU_S;
                    self.stuck_windows = if settle_c >= LOCK_TOO_WARM_C {
                        self.stuck_windows.saturating_add(1)
                    } else {
                        0
                    };
                    // Too warm to end: lower the TCA's hold while it may come down, where the
                    // stall rule can then end the lock (in warmer surroundings only the bare
                    // reading under the rigid threshold ends it, which no easing reaches).
                    let ease_k = ((settle_c - aim_c) / self.pla_per_tca)
                        .max(LOCK_EASE_MIN_K)
                        .min(CLOSED_LOCK_EASE_MAX_K - self.eased_k);
                    if self.stuck_windows >= 2 && ease_k > 0.0 && cool_surroundings {
                        self.eased_k += ease_k;
                        self.drive.ease_tca(ease_k);
                        self.stuck_windows = 0;
                    }
                    Some((t.now_ms, m.t_pla_c))
                }
            }
            _ => {
                self.stuck_windows = 0;
                (warmest >= aim_c).then_some((t.now_ms, m.t_pla_c))
            }
        };
        (pla_c < rigid_c && lead_c < rigid_c) || stalled
    }
}

impl Strategy for Closed {
    fn enter(&mut self, _phase: Phase, _now_ms: u64) {
        self.drive.enter();
        // Taken afresh on bend's first tick.
        self.bend_d_pla.1 = f32::NEG_INFINITY;
        self.stalled_since_ms = None;
        self.window = None;
        self.stuck_windows = 0;
    }

    fn timeout_s(&self, phase: Phase) -> Option<f32> {
        // A lock too warm to end: now (the sequencer's timeout ends the morph, its alarm names
        // the PLA's reading).
        (phase == Phase::Lock && self.stuck_windows >= 2).then_some(0.0)
    }

    fn phase_done(&mut self, t: &Tick) -> bool {
        self.drive.observe(t.now_ms, t.m);
        if let Some(own) = self.own.as_mut() {
            own.update(t.now_ms, t.tca_self_c);
        }
        let tca_c = self.tca_c();
        let o = self.drive.observer();
        let pla_c = o.estimate_c(HeatedNode::Pla);
        match t.phase {
            Phase::Soften => pla_c >= t.th.soft_threshold_c,
            Phase::Bend => {
                // Also waits for both thermistors to slow down, so the observer has learnt the
                // model's error before the PLA freezes the shape: a PLA estimate not yet
                // corrected by its thermistor can call a rod soft whose core is still glassy
                // (the high-fidelity links then lock before the rod has flowed). A PLA
                // thermistor that reads what the model expects need not wait.
                // On its own temperature: settled, and the rod no longer straining the coil.
                let tca_learnt = match &self.own {
                    Some(own) => own.rate_k_per_s().abs() <= OWN_STILL_K_PER_S,
                    None => {
                        o.measured_rate_k_per_s(HeatedNode::Tca).abs() <= LEARN_MAX_RATE_K_PER_S
                    }
                };
                let pla_settled =
                    o.measured_rate_k_per_s(HeatedNode::Pla).abs() <= CLOSED_PLA_SETTLED_K_PER_S;
                let pla_innovation_k = o.innovation_k(HeatedNode::Pla);
                // Not found colder than it estimated the rod in the last few seconds.
                let d_pla = o.disturbance_k(HeatedNode::Pla);
                let (since_ms, high) = self.bend_d_pla;
                let followed = if d_pla >= high
                    || t.now_ms.saturating_sub(since_ms) > (CLOSED_PLA_CORRECTED_S * 1000.0) as u64
                {
                    self.bend_d_pla = (t.now_ms, d_pla);
                    true
                } else {
                    d_pla - high >= -CLOSED_PLA_AGREE_K
                };
                let pla = PlaView {
                    learnt: pla_settled
                        || (pla_innovation_k.abs() <= CLOSED_PLA_AGREE_K && followed),
                    cold: !pla_settled && pla_innovation_k < -CLOSED_PLA_COLD_K,
                };
                self.drive.bend_done(t, pla_c, tca_c, tca_learnt, pla)
            }
            Phase::Lock => self.rigid(t, pla_c),
            Phase::Release => t.in_phase_s >= RELEASE_S,
            Phase::Idle | Phase::Rest | Phase::Fault => false,
        }
    }

    fn radius_estimate_mm(&self, m: &Measurements) -> f32 {
        target::calibrated_final_radius_mm(self.map, self.tca_c(), m.t_amb_c)
    }

    fn powers(&mut self, phase: Phase, t: &Tick) -> Powers {
        // The model is driven to `target − disturbance`, so the estimate meets the target.
        // Bending on its own temperature, the TCA's disturbance is what it reads over the model.
        let o = self.drive.observer();
        let d_pla = o.disturbance_k(HeatedNode::Pla);
        let d_tca = match &self.own {
            Some(_) => self.tca_c() - o.model_c(HeatedNode::Tca),
            None => o.disturbance_k(HeatedNode::Tca),
        };
        self.drive.powers(phase, t, d_pla, d_tca)
    }

    fn targets_c(&self, phase: Phase) -> TargetTemps {
        self.drive.targets_c(phase)
    }
}
