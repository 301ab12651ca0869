//! The morph sequence as a pure state machine: Idle → Soften → Bend → Lock → Release → Idle,
//! plus Fault. It turns measured temperatures into heater powers; it never touches hardware
//! and never decides about safety (the supervisor does, every tick, before it).

use crate::heater::HeaterConfig;
use crate::link::{HOLD_POWER_W, R_TP_K_PER_W, R_TT_K_PER_W};
use crate::observer::{HeatedNode, Observer};
use crate::protocol::Mode;
use crate::table;
use crate::target;

/// Phase of the morph sequence.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    /// Both heaters off, waiting for MORPH.
    Idle,
    /// Heating the PLA until it is soft.
    Soften,
    /// PLA held soft; TCA at the power that gives the target radius.
    Bend,
    /// PLA heater off; TCA holds the shape while the PLA stiffens.
    Lock,
    /// TCA off; the link keeps its new shape.
    Release,
    /// A safety trip latched; both heaters off until RESET.
    Fault,
}

impl Phase {
    /// Wire name of the phase.
    pub fn as_str(self) -> &'static str {
        match self {
            Phase::Idle => "idle",
            Phase::Soften => "soften",
            Phase::Bend => "bend",
            Phase::Lock => "lock",
            Phase::Release => "release",
            Phase::Fault => "fault",
        }
    }
}

/// Temperatures and supply the sequencer decides from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Measurements {
    /// PLA thermistor, °C.
    pub t_pla_c: f32,
    /// TCA thermistor, °C.
    pub t_tca_c: f32,
    /// Ambient thermistor, °C.
    pub t_amb_c: f32,
}

/// Heater powers the sequencer asks for, W.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Powers {
    /// PLA heater, W.
    pub pla_w: f32,
    /// TCA, W.
    pub tca_w: f32,
}

/// Power that softens the PLA, W (paper: 4 W; reaches 70 °C in about 5 s under water).
pub const SOFTEN_POWER_W: f32 = 4.0;
/// PLA temperature at which it counts as soft, °C (8 K above its 62 °C glass transition, so
/// the lagging thermistor does not call it soft too early).
pub const SOFT_THRESHOLD_C: f32 = 70.0;
/// PLA temperature at which it counts as rigid again, °C (17 K below Tg: modulus back to
/// glassy, the shape frozen).
pub const RIGID_THRESHOLD_C: f32 = 45.0;
/// Shortest bend, s: lets the TCA's fast thermal part (about 1 s) finish before settling is judged.
pub const MIN_BEND_S: f32 = 6.0;
/// Window over which the TCA temperature must stay within [`SETTLE_BAND_C`], s.
pub const SETTLE_WINDOW_S: f32 = 4.0;
/// Largest TCA temperature change over the settle window that counts as settled, K. The
/// radius moves about 0.27 mm per kelvin of TCA temperature; the slow thermal part still to
/// come is about (rate × 17 s), so 0.2 K per 4 s leaves under 1 K ≈ 0.3 mm.
pub const SETTLE_BAND_C: f32 = 0.2;
/// Time the TCA is kept off after lock before the morph is done, s: the TCA's force decays
/// within about a second, so the spring-back has happened when `done` is reported.
pub const RELEASE_S: f32 = 2.0;
/// Phase timeouts of the gated sequence, s. Soften reaches its threshold in about 5 s under
/// water; bend settles in 20–40 s; lock takes about 15 s under water and several minutes in
/// still air; release is fixed. Exceeding one ends in Fault (`phase-timeout`).
pub const SOFTEN_TIMEOUT_S: f32 = 60.0;
/// See [`SOFTEN_TIMEOUT_S`].
pub const BEND_TIMEOUT_S: f32 = 120.0;
/// See [`SOFTEN_TIMEOUT_S`].
pub const LOCK_TIMEOUT_S: f32 = 600.0;
/// See [`SOFTEN_TIMEOUT_S`].
pub const RELEASE_TIMEOUT_S: f32 = 10.0;

/// The paper's fixed timing (Fig. 8), s from MORPH: soften ends, PLA hold ends, TCA off.
pub const PAPER_SOFTEN_END_S: f32 = 20.0;
/// See [`PAPER_SOFTEN_END_S`].
pub const PAPER_HOLD_END_S: f32 = 70.0;
/// See [`PAPER_SOFTEN_END_S`].
pub const PAPER_TCA_END_S: f32 = 120.0;

/// The strategy `auto` runs: the one the strategy chart (`cargo xtask strategies`,
/// `docs/strategies.md`) puts on the Pareto front with a 95th-percentile radius error under 2 %
/// and the shortest 95th-percentile morph time.
pub const AUTO_STRATEGY: Mode = Mode::Closed;

/// PLA temperature the `boost` and `closed` strategies hold while bending, °C: 5 K above the
/// [`SOFT_THRESHOLD_C`] (so thermistor noise and the observer's error do not drop it below the
/// threshold) and no hotter, because every kelvin above Tg must be cooled off again in lock.
pub const PLA_SOFT_TARGET_C: f32 = 75.0;
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
/// `closed` ends lock when the observer's PLA estimate and the PLA thermistor corrected for its
/// lag (reading + assumed lag × its rate, what a first-order sensor trails by) are both below
/// [`RIGID_THRESHOLD_C`]. Under water this ends lock about 3 s before the bare thermistor would;
/// a thermistor that stops falling (warm surroundings) holds the lock, whatever the model says.
pub const CLOSED_RIGID_LEAD_S: f32 = crate::observer::SENSOR_TAU_S;
/// The lag correction of [`CLOSED_RIGID_LEAD_S`] is used only while the surroundings read at
/// least this far below [`RIGID_THRESHOLD_C`], K: then the rod keeps cooling after release and a
/// lock ended a kelvin early freezes the same shape. In surroundings nearer the threshold the
/// rod may stall just above it, so the bare thermistor decides, as in `gated`.
pub const CLOSED_LEAD_AMBIENT_MARGIN_K: f32 = 10.0;
/// Where `closed` counts the PLA as rigid in cool surroundings (see
/// [`CLOSED_LEAD_AMBIENT_MARGIN_K`]), °C: 12 K below Tg the PLA's modulus is 98 % of the way to
/// glassy on a log scale (about 1.5 GPa) and its flow time 27 s, growing e-fold with every 3 K it
/// keeps cooling after release, so the shape is frozen. Waiting for [`RIGID_THRESHOLD_C`] costs
/// 3–8 s under water with no measurable change of the final radius over the ensemble. In warm
/// surroundings the rod may stall near these temperatures, so there `closed` waits for
/// [`RIGID_THRESHOLD_C`] on the bare thermistor, as `gated` does.
pub const CLOSED_RIGID_COOL_C: f32 = 50.0;

/// Thermistor guard of the model strategies, K: a heater is switched off for the tick while its
/// thermistor reads more than this above the heater's target temperature. The model assumes
/// water; in still air the same power heats about five times as much, and the feed-forward
/// alone would run into the supervisor's 130 °C limit. 10 K is far outside the observer's
/// normal error (under 2 K) and keeps every target (at most 110 °C) 10 K under the limit.
pub const MODEL_GUARD_K: f32 = 10.0;

/// Least power the model strategies ask of a heater in a phase that has it on, W. The
/// supervisor's heater watch starts afresh whenever a heater's command drops to 0 W; restarted
/// on a hot heater that the controller is letting cool towards its target, it would read the
/// fall as a dead heater. 0.05 W keeps the watch running and heats the TCA by under 2 K.
pub const MODEL_KEEP_ALIVE_W: f32 = 0.05;

/// A TCA at full power whose thermistor rises slower than this has reached as close to its
/// target as the 2 W cap allows, K/s (strong convection in cold water, a low supply): the model
/// strategies lock there instead of waiting for the bend timeout. The bulk's 17 s time constant
/// makes 0.05 K/s about 1 K short of where it would end.
pub const MODEL_STALL_RATE_K_PER_S: f32 = 0.05;
/// A stall counts only this long after MORPH, s: after the supervisor's heater-not-heating check
/// has judged the TCA (on from MORPH, judged after 10 s), so a dead TCA, which does not rise at
/// all, trips instead of passing for a stalled one.
pub const STALL_AFTER_S: f32 = crate::supervisor::HEATING_CHECK_S + MODEL_SETTLE_S;

/// Something the sequencer reports to the user.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SeqEvent {
    /// A new phase began `t_s` after MORPH; `power_w` is the TCA power for bend.
    Phase {
        /// The phase entered.
        phase: Phase,
        /// Seconds since MORPH.
        t_s: f32,
        /// TCA power of the bend phase, W.
        power_w: Option<f32>,
    },
    /// The morph finished `t_s` after MORPH with this radius estimate, mm.
    Done {
        /// Seconds since MORPH.
        t_s: f32,
        /// Estimated achieved radius, mm.
        radius_mm: f32,
    },
}

/// A phase overran its timeout.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PhaseTimeout(pub Phase);

/// The sequence state.
#[derive(Clone, Copy, Debug)]
pub struct Sequencer {
    phase: Phase,
    mode: Mode,
    target_mm: f32,
    tca_power_w: f32,
    start_ms: u64,
    phase_ms: u64,
    window_ms: u64,
    window_temp_c: f32,
    estimate_mm: f32,
    observer: Observer,
    tca_target_c: f32,
    last_ms: u64,
    applied: Powers,
    supply_v: f32,
    settled_since_ms: Option<u64>,
}

impl Default for Sequencer {
    fn default() -> Self {
        Self::new()
    }
}

impl Sequencer {
    /// An idle sequencer.
    pub const fn new() -> Self {
        Sequencer {
            phase: Phase::Idle,
            mode: Mode::Auto,
            target_mm: f32::NAN,
            tca_power_w: 0.0,
            start_ms: 0,
            phase_ms: 0,
            window_ms: 0,
            window_temp_c: f32::NAN,
            estimate_mm: f32::NAN,
            observer: Observer::IDLE,
            tca_target_c: f32::NAN,
            last_ms: 0,
            applied: Powers {
                pla_w: 0.0,
                tca_w: 0.0,
            },
            supply_v: f32::NAN,
            settled_since_ms: None,
        }
    }

    /// The strategy a morph in `mode` runs (`auto` resolved to [`AUTO_STRATEGY`]).
    pub fn strategy_of(mode: Mode) -> Mode {
        match mode {
            Mode::Auto => AUTO_STRATEGY,
            m => m,
        }
    }

    /// Strategy of the running or last morph (never `Auto`).
    pub fn strategy(&self) -> Mode {
        self.mode
    }

    /// TCA temperature the `boost` or `closed` morph aims at, °C (NaN for the others).
    pub fn tca_target_c(&self) -> f32 {
        self.tca_target_c
    }

    /// The controller's thermal model of the link (meaningful during `boost`/`closed` morphs).
    pub fn observer(&self) -> &Observer {
        &self.observer
    }

    /// Tells the sequencer the measured heater supply, V, so the model strategies know what
    /// power the heaters can actually deliver. Call before [`Sequencer::step`].
    pub fn set_supply_v(&mut self, supply_v: f32) {
        self.supply_v = supply_v;
    }

    /// Current phase.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// Target radius of the running or last morph, mm (NaN if none).
    pub fn target_mm(&self) -> f32 {
        self.target_mm
    }

    /// True while a morph is under way.
    pub fn busy(&self) -> bool {
        matches!(
            self.phase,
            Phase::Soften | Phase::Bend | Phase::Lock | Phase::Release
        )
    }

    /// Starts a morph to `radius_mm` with TCA power `tca_power_w` (from the table) in `mode`
    /// (`auto` runs [`AUTO_STRATEGY`]). Equivalent to [`Sequencer::start_from`] with the link at
    /// the built-in ambient temperature.
    pub fn start(
        &mut self,
        now_ms: u64,
        radius_mm: f32,
        tca_power_w: f32,
        mode: Mode,
        emit: &mut impl FnMut(SeqEvent),
    ) {
        let amb = crate::link::LINK.surroundings.ambient_c as f32;
        let m = Measurements {
            t_pla_c: amb,
            t_tca_c: amb,
            t_amb_c: amb,
        };
        self.start_from(now_ms, radius_mm, tca_power_w, mode, &m, emit);
    }

    /// Starts a morph to `radius_mm` with TCA power `tca_power_w` (from the table) in `mode`
    /// (`auto` runs [`AUTO_STRATEGY`]) from the measured temperatures `m` (they start the
    /// model strategies' observer and set the spring-back compensation's ambient).
    pub fn start_from(
        &mut self,
        now_ms: u64,
        radius_mm: f32,
        tca_power_w: f32,
        mode: Mode,
        m: &Measurements,
        emit: &mut impl FnMut(SeqEvent),
    ) {
        let mode = Self::strategy_of(mode);
        self.mode = mode;
        self.observer = Observer::from_measured(m.t_pla_c, m.t_tca_c, m.t_amb_c);
        self.tca_target_c = match mode {
            Mode::Boost => target::tca_temp_for_radius_c(radius_mm),
            Mode::Closed => target::lock_temp_for_final_radius_c(radius_mm, m.t_amb_c),
            _ => f32::NAN,
        };
        self.last_ms = now_ms;
        self.applied = Powers::default();
        self.settled_since_ms = None;
        self.target_mm = radius_mm;
        self.tca_power_w = tca_power_w;
        self.start_ms = now_ms;
        self.estimate_mm = f32::NAN;
        self.enter(Phase::Soften, now_ms, emit);
    }

    /// Stops at once: Idle, heaters off from the next step.
    pub fn abort(&mut self) {
        self.phase = Phase::Idle;
    }

    /// Enters Fault (the supervisor tripped); heaters off.
    pub fn fault(&mut self) {
        self.phase = Phase::Fault;
    }

    /// Leaves Fault after a successful RESET.
    pub fn clear_fault(&mut self) {
        if self.phase == Phase::Fault {
            self.phase = Phase::Idle;
        }
    }

    fn since_s(&self, now_ms: u64, from_ms: u64) -> f32 {
        now_ms.saturating_sub(from_ms) as f32 / 1000.0
    }

    fn enter(&mut self, phase: Phase, now_ms: u64, emit: &mut impl FnMut(SeqEvent)) {
        self.phase = phase;
        self.settled_since_ms = None;
        self.phase_ms = now_ms;
        self.window_ms = now_ms;
        self.window_temp_c = f32::NAN;
        let t_s = self.since_s(now_ms, self.start_ms);
        let power_w = (phase == Phase::Bend).then_some(self.tca_power_w);
        emit(SeqEvent::Phase {
            phase,
            t_s,
            power_w,
        });
    }

    /// TCA power during lock, W: the bend power plus what replaces the heat the PLA heater
    /// stops giving the TCA (`R_tp / R_tt · hold power`), so the TCA stays at its bend
    /// temperature while the PLA freezes the shape.
    pub fn lock_tca_power_w(&self) -> f32 {
        self.tca_power_w + R_TP_K_PER_W / R_TT_K_PER_W * HOLD_POWER_W
    }

    /// One control tick: advances the phase from the measurements and returns the powers.
    pub fn step(
        &mut self,
        now_ms: u64,
        m: &Measurements,
        emit: &mut impl FnMut(SeqEvent),
    ) -> Result<Powers, PhaseTimeout> {
        match self.mode {
            Mode::Paper => self.step_paper(now_ms, m, emit),
            Mode::Boost | Mode::Closed => self.step_model(now_ms, m, emit),
            Mode::Auto | Mode::Gated => self.step_gated(now_ms, m, emit),
        }
    }

    fn timeout_s(&self) -> f32 {
        match (self.mode, self.phase) {
            (Mode::Paper, Phase::Soften) => PAPER_SOFTEN_END_S + 5.0,
            (Mode::Paper, Phase::Bend) => PAPER_HOLD_END_S - PAPER_SOFTEN_END_S + 5.0,
            (Mode::Paper, Phase::Lock) => PAPER_TCA_END_S - PAPER_HOLD_END_S + 5.0,
            (_, Phase::Soften) => SOFTEN_TIMEOUT_S,
            (_, Phase::Bend) => BEND_TIMEOUT_S,
            (_, Phase::Lock) => LOCK_TIMEOUT_S,
            _ => RELEASE_TIMEOUT_S,
        }
    }

    fn check_timeout(&mut self, now_ms: u64) -> Result<(), PhaseTimeout> {
        if self.busy() && self.since_s(now_ms, self.phase_ms) > self.timeout_s() {
            let p = self.phase;
            self.phase = Phase::Fault;
            return Err(PhaseTimeout(p));
        }
        Ok(())
    }

    /// True once the TCA temperature has stayed within the settle band for a whole window.
    fn tca_settled(&mut self, now_ms: u64, t_tca_c: f32) -> bool {
        if self.window_temp_c.is_nan() {
            self.window_temp_c = t_tca_c;
            self.window_ms = now_ms;
            return false;
        }
        if self.since_s(now_ms, self.window_ms) < SETTLE_WINDOW_S {
            return false;
        }
        let settled = (t_tca_c - self.window_temp_c).abs() <= SETTLE_BAND_C;
        self.window_temp_c = t_tca_c;
        self.window_ms = now_ms;
        settled
    }

    fn finish(&mut self, now_ms: u64, emit: &mut impl FnMut(SeqEvent)) {
        self.phase = Phase::Idle;
        let t_s = self.since_s(now_ms, self.start_ms);
        emit(SeqEvent::Done {
            t_s,
            radius_mm: self.estimate_mm,
        });
    }

    fn step_gated(
        &mut self,
        now_ms: u64,
        m: &Measurements,
        emit: &mut impl FnMut(SeqEvent),
    ) -> Result<Powers, PhaseTimeout> {
        self.check_timeout(now_ms)?;
        let in_phase_s = self.since_s(now_ms, self.phase_ms);
        match self.phase {
            Phase::Idle | Phase::Fault => return Ok(Powers::default()),
            Phase::Soften => {
                if m.t_pla_c >= SOFT_THRESHOLD_C {
                    self.enter(Phase::Bend, now_ms, emit);
                }
            }
            Phase::Bend => {
                if self.tca_settled(now_ms, m.t_tca_c) && in_phase_s >= MIN_BEND_S {
                    self.estimate_mm = table::radius_for_tca_rise_mm(m.t_tca_c - m.t_amb_c);
                    self.enter(Phase::Lock, now_ms, emit);
                }
            }
            Phase::Lock => {
                if m.t_pla_c < RIGID_THRESHOLD_C {
                    self.enter(Phase::Release, now_ms, emit);
                }
            }
            Phase::Release => {
                if in_phase_s >= RELEASE_S {
                    self.finish(now_ms, emit);
                }
            }
        }
        Ok(self.powers())
    }

    fn step_paper(
        &mut self,
        now_ms: u64,
        m: &Measurements,
        emit: &mut impl FnMut(SeqEvent),
    ) -> Result<Powers, PhaseTimeout> {
        self.check_timeout(now_ms)?;
        let t_s = self.since_s(now_ms, self.start_ms);
        let next = match self.phase {
            Phase::Soften if t_s >= PAPER_SOFTEN_END_S => Some(Phase::Bend),
            Phase::Bend if t_s >= PAPER_HOLD_END_S => {
                self.estimate_mm = table::radius_for_tca_rise_mm(m.t_tca_c - m.t_amb_c);
                Some(Phase::Lock)
            }
            Phase::Lock if t_s >= PAPER_TCA_END_S => Some(Phase::Release),
            Phase::Release if self.since_s(now_ms, self.phase_ms) >= RELEASE_S => {
                self.finish(now_ms, emit);
                None
            }
            _ => None,
        };
        if let Some(p) = next {
            self.enter(p, now_ms, emit);
        }
        Ok(self.powers())
    }

    /// Power a heater delivers when asked for `w` (W) at the measured supply: capped by the
    /// heater and by full duty (`V²/R`); unknown supply assumes the request is met.
    fn deliverable_w(heater: &HeaterConfig, w: f32, supply_v: f32) -> f32 {
        let w = w.clamp(0.0, heater.max_power_w);
        if supply_v.is_finite() && supply_v > 0.0 {
            w.min(supply_v * supply_v / heater.resistance_ohm)
        } else {
            w
        }
    }

    /// True once `ok` has held for [`MODEL_SETTLE_S`].
    fn held(&mut self, now_ms: u64, ok: bool) -> bool {
        if !ok {
            self.settled_since_ms = None;
            return false;
        }
        let since = *self.settled_since_ms.get_or_insert(now_ms);
        self.since_s(now_ms, since) >= MODEL_SETTLE_S
    }

    /// `boost` and `closed`: both heaters driven through the thermal model to target
    /// temperatures (PLA [`PLA_SOFT_TARGET_C`], TCA the radius's temperature), the TCA from the
    /// start of soften on. `boost` drives the bare model (feed-forward) and gates soften and
    /// lock on the thermistors; `closed` drives the observer's corrected estimate and gates
    /// every phase on it.
    fn step_model(
        &mut self,
        now_ms: u64,
        m: &Measurements,
        emit: &mut impl FnMut(SeqEvent),
    ) -> Result<Powers, PhaseTimeout> {
        self.check_timeout(now_ms)?;
        if !self.busy() {
            return Ok(Powers::default());
        }
        let closed = self.mode == Mode::Closed;
        let dt_s = self.since_s(now_ms, self.last_ms);
        self.last_ms = now_ms;
        if dt_s > 0.0 {
            let a = self.applied;
            self.observer.predict(dt_s, a.pla_w, a.tca_w, m.t_amb_c);
            self.observer.correct(dt_s, m.t_pla_c, m.t_tca_c);
        }
        let o = &self.observer;
        let (pla_c, tca_c) = if closed {
            (o.estimate_c(HeatedNode::Pla), o.estimate_c(HeatedNode::Tca))
        } else {
            (o.model_c(HeatedNode::Pla), o.model_c(HeatedNode::Tca))
        };
        let in_phase_s = self.since_s(now_ms, self.phase_ms);
        match self.phase {
            Phase::Soften => {
                let soft = if closed { pla_c } else { m.t_pla_c };
                if soft >= SOFT_THRESHOLD_C {
                    self.enter(Phase::Bend, now_ms, emit);
                }
            }
            Phase::Bend => {
                // `closed` also waits for the TCA thermistor to slow down, so the observer has
                // learnt the model's error before the PLA freezes the shape.
                let learnt = !closed
                    || self.observer.measured_rate_k_per_s(HeatedNode::Tca).abs()
                        <= crate::observer::LEARN_MAX_RATE_K_PER_S;
                // Above the target with the TCA off is as close as the link can get (warm
                // surroundings and the PLA's heat keep it there): lock as it is.
                let reached = (tca_c - self.tca_target_c).abs() <= MODEL_SETTLE_BAND_C
                    || (tca_c > self.tca_target_c && self.applied.tca_w <= MODEL_KEEP_ALIVE_W)
                    || (tca_c < self.tca_target_c
                        && self.applied.tca_w
                            >= Self::deliverable_w(
                                &HeaterConfig::TCA,
                                TCA_BOOST_MAX_W,
                                self.supply_v,
                            ) - 1e-3
                        && self.observer.measured_rate_k_per_s(HeatedNode::Tca)
                            < MODEL_STALL_RATE_K_PER_S
                        && self.since_s(now_ms, self.start_ms) > STALL_AFTER_S);
                let at_target = reached && pla_c >= SOFT_THRESHOLD_C && learnt;
                if self.held(now_ms, at_target) && in_phase_s >= MODEL_SETTLE_S {
                    self.estimate_mm = target::final_radius_mm(tca_c, m.t_amb_c);
                    self.enter(Phase::Lock, now_ms, emit);
                }
            }
            Phase::Lock => {
                let rigid = if closed {
                    let rate = self.observer.measured_rate_k_per_s(HeatedNode::Pla);
                    let cool_surroundings =
                        m.t_amb_c < RIGID_THRESHOLD_C - CLOSED_LEAD_AMBIENT_MARGIN_K;
                    let (lead_c, rigid_c) = if cool_surroundings {
                        (
                            m.t_pla_c + CLOSED_RIGID_LEAD_S * rate.min(0.0),
                            CLOSED_RIGID_COOL_C,
                        )
                    } else {
                        (m.t_pla_c, RIGID_THRESHOLD_C)
                    };
                    pla_c < rigid_c && lead_c < rigid_c
                } else {
                    m.t_pla_c < RIGID_THRESHOLD_C
                };
                if rigid {
                    self.enter(Phase::Release, now_ms, emit);
                }
            }
            Phase::Release => {
                if in_phase_s >= RELEASE_S {
                    self.finish(now_ms, emit);
                }
            }
            Phase::Idle | Phase::Fault => {}
        }
        let o = &self.observer;
        // The model is driven to `target − disturbance`, so the estimate meets the target.
        let (d_pla, d_tca) = if closed {
            (
                o.disturbance_k(HeatedNode::Pla),
                o.disturbance_k(HeatedNode::Tca),
            )
        } else {
            (0.0, 0.0)
        };
        let pla_on = matches!(self.phase, Phase::Soften | Phase::Bend);
        let tca_on = matches!(self.phase, Phase::Soften | Phase::Bend | Phase::Lock);
        let pla_w = if pla_on {
            o.power_to_reach_w(HeatedNode::Pla, PLA_SOFT_TARGET_C - d_pla, PLA_BOOST_MAX_W)
        } else {
            0.0
        };
        let tca_w = if tca_on {
            o.power_to_reach_w(HeatedNode::Tca, self.tca_target_c - d_tca, TCA_BOOST_MAX_W)
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
        let pla_w = keep(pla_on, pla_w, m.t_pla_c > PLA_SOFT_TARGET_C + MODEL_GUARD_K);
        let tca_w = keep(tca_on, tca_w, m.t_tca_c > self.tca_target_c + MODEL_GUARD_K);
        let p = Powers { pla_w, tca_w };
        self.applied = Powers {
            pla_w: Self::deliverable_w(&HeaterConfig::PLA, p.pla_w, self.supply_v),
            tca_w: Self::deliverable_w(&HeaterConfig::TCA, p.tca_w, self.supply_v),
        };
        Ok(p)
    }

    /// Powers of the current phase, W.
    fn powers(&self) -> Powers {
        let paper = self.mode == Mode::Paper;
        match self.phase {
            Phase::Soften => Powers {
                pla_w: SOFTEN_POWER_W,
                tca_w: 0.0,
            },
            Phase::Bend => Powers {
                pla_w: HOLD_POWER_W,
                tca_w: self.tca_power_w,
            },
            Phase::Lock if paper => Powers {
                pla_w: 0.0,
                tca_w: self.tca_power_w,
            },
            Phase::Lock => Powers {
                pla_w: 0.0,
                tca_w: self.lock_tca_power_w(),
            },
            _ => Powers::default(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    extern crate std;
    use std::vec::Vec;

    fn meas(pla: f32, tca: f32) -> Measurements {
        Measurements {
            t_pla_c: pla,
            t_tca_c: tca,
            t_amb_c: 22.0,
        }
    }

    fn run(seq: &mut Sequencer, now: u64, m: Measurements, ev: &mut Vec<SeqEvent>) -> Powers {
        seq.step(now, &m, &mut |e| ev.push(e)).unwrap()
    }

    #[test]
    fn gated_sequence_walks_every_phase_in_order() {
        let mut s = Sequencer::new();
        let mut ev = Vec::new();
        s.start(0, 38.0, 0.6, Mode::Gated, &mut |e| ev.push(e));
        assert_eq!(
            run(&mut s, 100, meas(30.0, 22.0), &mut ev),
            Powers {
                pla_w: SOFTEN_POWER_W,
                tca_w: 0.0
            }
        );
        run(&mut s, 5000, meas(71.0, 30.0), &mut ev);
        assert_eq!(s.phase(), Phase::Bend);
        // Rising TCA: not settled.
        let mut t = 5000;
        for i in 0..20 {
            t += 1000;
            let p = run(&mut s, t, meas(70.0, 30.0 + i as f32), &mut ev);
            assert_eq!(
                p,
                Powers {
                    pla_w: HOLD_POWER_W,
                    tca_w: 0.6
                }
            );
        }
        assert_eq!(s.phase(), Phase::Bend);
        for _ in 0..10 {
            t += 1000;
            run(&mut s, t, meas(70.0, 52.0), &mut ev);
        }
        assert_eq!(s.phase(), Phase::Lock);
        let p = run(&mut s, t + 100, meas(60.0, 52.0), &mut ev);
        assert_eq!(p.pla_w, 0.0);
        assert!(p.tca_w > 0.6, "lock compensates the lost PLA heat: {p:?}");
        run(&mut s, t + 200, meas(44.0, 52.0), &mut ev);
        assert_eq!(s.phase(), Phase::Release);
        assert_eq!(
            run(&mut s, t + 300, meas(44.0, 52.0), &mut ev),
            Powers::default()
        );
        run(&mut s, t + 2300, meas(40.0, 40.0), &mut ev);
        assert_eq!(s.phase(), Phase::Idle);
        let phases: Vec<Phase> = ev
            .iter()
            .filter_map(|e| {
                if let SeqEvent::Phase { phase, .. } = e {
                    Some(*phase)
                } else {
                    None
                }
            })
            .collect();
        assert_eq!(
            phases,
            [Phase::Soften, Phase::Bend, Phase::Lock, Phase::Release]
        );
        assert!(
            matches!(ev.last(), Some(SeqEvent::Done { radius_mm, .. }) if radius_mm.is_finite())
        );
    }

    #[test]
    fn every_gated_phase_times_out_into_fault() {
        for (phase_at, timeout) in [
            (0u64, SOFTEN_TIMEOUT_S),
            (1, BEND_TIMEOUT_S),
            (2, LOCK_TIMEOUT_S),
        ] {
            let mut s = Sequencer::new();
            let mut ev = Vec::new();
            s.start(0, 38.0, 0.6, Mode::Gated, &mut |e| ev.push(e));
            let mut now = 0;
            if phase_at >= 1 {
                now += 100;
                run(&mut s, now, meas(75.0, 30.0), &mut ev);
            }
            if phase_at >= 2 {
                for _ in 0..12 {
                    now += 1000;
                    run(&mut s, now, meas(75.0, 50.0), &mut ev);
                }
            }
            let entered = now;
            let p = s.phase();
            // Conditions that never let the phase end: PLA cold, TCA rising, PLA hot.
            let stuck = match p {
                Phase::Soften => meas(30.0, 22.0),
                Phase::Bend => meas(75.0, 0.0),
                _ => meas(80.0, 50.0),
            };
            let mut t = entered;
            let mut result = Ok(Powers::default());
            let mut i = 0.0;
            while t <= entered + (timeout as u64 + 2) * 1000 {
                t += 500;
                i += 1.0;
                let m = if p == Phase::Bend {
                    meas(75.0, i)
                } else {
                    stuck
                };
                result = s.step(t, &m, &mut |e| ev.push(e));
                if result.is_err() {
                    break;
                }
            }
            assert_eq!(result, Err(PhaseTimeout(p)), "phase {p:?}");
            assert_eq!(s.phase(), Phase::Fault);
            assert_eq!(
                s.step(t + 100, &stuck, &mut |e| ev.push(e)),
                Ok(Powers::default())
            );
        }
    }

    #[test]
    fn paper_mode_follows_the_fixed_timing() {
        let mut s = Sequencer::new();
        let mut ev = Vec::new();
        s.start(0, 38.0, 0.6, Mode::Paper, &mut |e| ev.push(e));
        let m = meas(80.0, 40.0);
        let at = |s: &mut Sequencer, ev: &mut Vec<SeqEvent>, t_s: f32| {
            run(s, (t_s * 1000.0) as u64, m, ev)
        };
        assert_eq!(
            at(&mut s, &mut ev, 10.0),
            Powers {
                pla_w: 4.0,
                tca_w: 0.0
            }
        );
        assert_eq!(
            at(&mut s, &mut ev, 20.0),
            Powers {
                pla_w: HOLD_POWER_W,
                tca_w: 0.6
            }
        );
        assert_eq!(
            at(&mut s, &mut ev, 69.9),
            Powers {
                pla_w: HOLD_POWER_W,
                tca_w: 0.6
            }
        );
        assert_eq!(
            at(&mut s, &mut ev, 70.0),
            Powers {
                pla_w: 0.0,
                tca_w: 0.6
            }
        );
        assert_eq!(
            at(&mut s, &mut ev, 119.9),
            Powers {
                pla_w: 0.0,
                tca_w: 0.6
            }
        );
        assert_eq!(at(&mut s, &mut ev, 120.0), Powers::default());
        at(&mut s, &mut ev, 122.0);
        assert_eq!(s.phase(), Phase::Idle);
        assert!(
            matches!(ev.last(), Some(SeqEvent::Done { t_s, .. }) if (*t_s - 122.0).abs() < 0.01)
        );
    }

    #[test]
    fn abort_from_any_phase_gives_zero_power() {
        for steps in 0..4 {
            let mut s = Sequencer::new();
            let mut ev = Vec::new();
            s.start(0, 38.0, 0.6, Mode::Gated, &mut |e| ev.push(e));
            let ms = [meas(75.0, 30.0), meas(75.0, 50.0), meas(40.0, 50.0)];
            let mut t = 0;
            for m in ms.iter().take(steps) {
                for _ in 0..12 {
                    t += 1000;
                    run(&mut s, t, *m, &mut ev);
                }
            }
            s.abort();
            assert_eq!(s.phase(), Phase::Idle);
            assert_eq!(
                run(&mut s, t + 100, meas(75.0, 50.0), &mut ev),
                Powers::default()
            );
        }
    }

    #[test]
    fn auto_runs_the_charted_strategy() {
        let mut s = Sequencer::new();
        s.start(0, 38.0, 0.6, Mode::Auto, &mut |_| {});
        assert_eq!(s.strategy(), AUTO_STRATEGY);
        assert_ne!(AUTO_STRATEGY, Mode::Auto);
        for m in [Mode::Paper, Mode::Gated, Mode::Boost, Mode::Closed] {
            assert_eq!(Sequencer::strategy_of(m), m);
        }
    }

    #[test]
    fn model_strategies_overdrive_both_heaters_from_the_start() {
        for mode in [Mode::Boost, Mode::Closed] {
            let mut s = Sequencer::new();
            s.set_supply_v(12.0);
            s.start(0, 35.0, 1.0, mode, &mut |_| {});
            let p = s.step(100, &meas(22.0, 22.0), &mut |_| {}).unwrap();
            assert_eq!(p.pla_w, PLA_BOOST_MAX_W, "{mode:?}");
            assert_eq!(p.tca_w, TCA_BOOST_MAX_W, "{mode:?}");
            assert!(s.tca_target_c() > 60.0 && s.tca_target_c() < 90.0);
        }
    }

    #[test]
    fn the_guard_turns_a_hot_heater_down_but_never_to_zero_while_its_phase_has_it_on() {
        for mode in [Mode::Boost, Mode::Closed] {
            let mut s = Sequencer::new();
            s.set_supply_v(12.0);
            s.start(0, 35.0, 1.0, mode, &mut |_| {});
            let hot = meas(PLA_SOFT_TARGET_C + MODEL_GUARD_K + 1.0, 22.0);
            let p = s.step(100, &hot, &mut |_| {}).unwrap();
            assert_eq!(p.pla_w, MODEL_KEEP_ALIVE_W, "{mode:?}");
            let t = s.tca_target_c();
            let p = s
                .step(200, &meas(30.0, t + MODEL_GUARD_K + 1.0), &mut |_| {})
                .unwrap();
            assert_eq!(p.tca_w, MODEL_KEEP_ALIVE_W, "{mode:?}");
            // Far above target on the model too: still the keep-alive, not zero.
            let mut now = 200;
            for _ in 0..50 {
                now += 100;
                let p = s.step(now, &meas(30.0, t + 5.0), &mut |_| {}).unwrap();
                assert!(p.tca_w >= MODEL_KEEP_ALIVE_W, "{mode:?} {p:?}");
            }
        }
    }

    #[test]
    fn model_strategies_end_in_idle_with_both_heaters_off() {
        for mode in [Mode::Boost, Mode::Closed] {
            let mut s = Sequencer::new();
            let mut ev = Vec::new();
            s.set_supply_v(12.0);
            s.start(0, 38.0, 0.7, mode, &mut |e| ev.push(e));
            // A plant that follows the request exactly: read the observer's own estimates.
            let mut now = 0;
            let mut p = Powers::default();
            while s.busy() && now < 300_000 {
                now += 100;
                let o = s.observer();
                let m = Measurements {
                    t_pla_c: o.estimate_c(HeatedNode::Pla),
                    t_tca_c: o.estimate_c(HeatedNode::Tca),
                    t_amb_c: 22.0,
                };
                p = s.step(now, &m, &mut |e| ev.push(e)).unwrap();
            }
            assert_eq!(s.phase(), Phase::Idle, "{mode:?}");
            assert_eq!(p, Powers::default());
            assert!(now < 60_000, "{mode:?} took {now} ms");
            assert!(
                matches!(ev.last(), Some(SeqEvent::Done { radius_mm, .. }) if (radius_mm - 38.0).abs() < 0.5),
                "{mode:?}: {:?}",
                ev.last()
            );
        }
    }
}
