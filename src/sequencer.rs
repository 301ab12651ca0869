//! The morph sequence as a pure state machine: Idle → (Rest →) Soften → Bend → Lock →
//! Release → Idle, plus Fault. It owns the phases, their timeouts and the events; the strategy the morph runs
//! ([`crate::strategy`]) turns measured temperatures into heater powers and says when a phase
//! is over. It never touches hardware and never decides about safety (the supervisor does,
//! every tick, before it).

use crate::protocol::Mode;
use crate::strategy::{AnyStrategy, Start, Strategy, TargetTemps, Thresholds, Tick, RELEASE_S};
use crate::vocab::{Measurements, Phase, Powers};

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
/// A MORPH starts heating only once the PLA's and the TCA's thermistors read within this of
/// ambient, K; before that it rests ([`Phase::Rest`], heaters off). The heat a previous morph
/// left in the silicone keeps the TCA above a looser morph's target while the PLA is held
/// soft, and the rod then locks tighter than asked; from a link this close to ambient a morph
/// lands as from rest (`cargo xtask warm`, docs/strategies.md "Morphs in a row"). The same
/// 3 K as TUNE's start (`tune::TUNE_START_MAX_RISE_K`).
pub const REST_MAX_RISE_K: f32 = 3.0;
/// Longest rest, s: a still-air link cools from a morph's 80 °C to within
/// [`REST_MAX_RISE_K`] of ambient in several minutes (its lock alone may take 10).
pub const REST_TIMEOUT_S: f32 = 900.0;
// Release is fixed-length: it must end well before its timeout.
const _: () = assert!(RELEASE_S < RELEASE_TIMEOUT_S);
// The heater-not-heating check judges a heater during soften, before soften can time out.
const _: () = assert!(crate::supervisor::HEATER_VERDICT_S < SOFTEN_TIMEOUT_S);

/// The phase timeouts a morph runs with, s: the user-settable values of `crate::settings`
/// (defaults [`SOFTEN_TIMEOUT_S`], [`BEND_TIMEOUT_S`], [`LOCK_TIMEOUT_S`]). Release keeps
/// [`RELEASE_TIMEOUT_S`]: its length is fixed by the strategy ([`RELEASE_S`]). A strategy's
/// own timeout (`paper`'s fixed schedule) still takes precedence.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhaseTimeouts {
    /// Soften timeout, s.
    pub soften_s: f32,
    /// Bend timeout, s.
    pub bend_s: f32,
    /// Lock timeout, s.
    pub lock_s: f32,
}

impl PhaseTimeouts {
    /// The compiled-in values.
    pub const DEFAULT: PhaseTimeouts = PhaseTimeouts {
        soften_s: SOFTEN_TIMEOUT_S,
        bend_s: BEND_TIMEOUT_S,
        lock_s: LOCK_TIMEOUT_S,
    };
}

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
        /// The target it was asked for, mm (`done` says how far the estimate missed it when
        /// that is more than [`DONE_MISS_SHARE`] of it).
        target_mm: f32,
    },
}

/// A `done` whose own radius estimate is further than this share of its target from the
/// target says by how much (`missed_mm=`): the morph ended, but not where it was asked to (a
/// TCA the link's heat keeps past a looser target, a heater cap short of a tighter one). 1 %
/// is half the accuracy the calibrated morphs are held to.
pub const DONE_MISS_SHARE: f32 = 0.01;

/// A phase overran its timeout (the morph has ended; the controller latches the fault).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PhaseTimeout(pub Phase);

impl PhaseTimeout {
    /// The fault it latches: `phase-timeout <phase>`, carrying `value` (a lock's PLA reading,
    /// °C: a lock ends only on a PLA cool enough, so its timeout says how warm the rod stayed;
    /// else NaN).
    pub fn fault(self, value: f32) -> crate::fault::Fault {
        crate::fault::Fault {
            code: crate::fault::FaultCode::PhaseTimeout,
            subject: crate::fault::Subject::Phase(self.0),
            value,
        }
    }
}

/// Where the running or last morph is: its phase and its clocks.
#[derive(Clone, Copy, Debug)]
struct Progress {
    phase: Phase,
    target_mm: f32,
    tca_power_w: f32,
    start_ms: u64,
    /// When heating began (soften entered), ms: the strategies' clock.
    heat_ms: u64,
    phase_ms: u64,
    estimate_mm: f32,
}

impl Progress {
    fn enter(
        &mut self,
        strategy: Option<&mut dyn Strategy>,
        phase: Phase,
        now_ms: u64,
        emit: &mut dyn FnMut(SeqEvent),
    ) {
        self.phase = phase;
        self.phase_ms = now_ms;
        if let Some(s) = strategy {
            s.enter(phase, now_ms);
        }
        let t_s = since_s(now_ms, self.start_ms);
        let power_w = (phase == Phase::Bend).then_some(self.tca_power_w);
        emit(SeqEvent::Phase {
            phase,
            t_s,
            power_w,
        });
    }

    fn finish(&mut self, now_ms: u64, emit: &mut dyn FnMut(SeqEvent)) {
        self.phase = Phase::Idle;
        let t_s = since_s(now_ms, self.start_ms);
        emit(SeqEvent::Done {
            t_s,
            radius_mm: self.estimate_mm,
            target_mm: self.target_mm,
        });
    }
}

/// What a resting morph starts its strategy with.
#[derive(Clone, Copy, Debug)]
struct Pending {
    radius_mm: f32,
    tca_power_w: f32,
    mode: Mode,
    cal: crate::calibration::Calibration,
}

/// Whether `m` reads a link close enough to ambient for a morph to start heating.
fn rested(m: &Measurements) -> bool {
    let warm = |c: f32| !(c - m.t_amb_c <= REST_MAX_RISE_K);
    !(warm(m.t_pla_c) || warm(m.t_tca_c))
}

/// The sequence state.
#[derive(Clone, Copy, Debug)]
pub struct Sequencer {
    at: Progress,
    /// A morph resting before it heats: what its strategy starts with once the link has
    /// cooled.
    pending: Option<Pending>,
    strategy: Option<AnyStrategy>,
    supply_v: f32,
    allow_w: Powers,
    tca_self_c: f32,
    rest_shape_per_m: f32,
    thresholds: Thresholds,
    timeouts: PhaseTimeouts,
}

impl Default for Sequencer {
    fn default() -> Self {
        Self::new()
    }
}

fn since_s(now_ms: u64, from_ms: u64) -> f32 {
    now_ms.saturating_sub(from_ms) as f32 / 1000.0
}

impl Sequencer {
    /// An idle sequencer.
    pub const fn new() -> Self {
        Sequencer {
            at: Progress {
                phase: Phase::Idle,
                target_mm: f32::NAN,
                tca_power_w: 0.0,
                start_ms: 0,
                heat_ms: 0,
                phase_ms: 0,
                estimate_mm: f32::NAN,
            },
            pending: None,
            strategy: None,
            supply_v: f32::NAN,
            allow_w: Powers::UNLIMITED,
            tca_self_c: f32::NAN,
            rest_shape_per_m: f32::NAN,
            thresholds: Thresholds::DEFAULT,
            timeouts: PhaseTimeouts::DEFAULT,
        }
    }

    /// Sets the thresholds and timeouts the next morphs run with (the controller passes the
    /// live settings before each MORPH; a running morph keeps what it started with only in
    /// that settings cannot change while one runs).
    pub fn set_limits(&mut self, thresholds: Thresholds, timeouts: PhaseTimeouts) {
        self.thresholds = thresholds;
        self.timeouts = timeouts;
    }

    /// Tells the sequencer the measured heater supply, V, so the model strategies know what
    /// power the heaters can actually deliver. Call before [`Sequencer::step`].
    pub fn set_supply_v(&mut self, supply_v: f32) {
        self.supply_v = supply_v;
    }

    /// Tells the sequencer the most power each heater may take this tick, W (the supply
    /// budget's share, [`crate::budget`]; unlimited on a board with one link). Call before
    /// [`Sequencer::step`].
    pub fn set_allowance(&mut self, allow_w: Powers) {
        self.allow_w = allow_w;
    }

    /// Tells the sequencer the TCA's own temperature, °C (NaN where not sensed), and the link's
    /// curvature when its rest reference was read, 1/m (NaN: unknown), so `closed` can bend on
    /// it. Call every tick, before a morph starts and before [`Sequencer::step`].
    pub fn set_tca_self(&mut self, tca_self_c: f32, rest_shape_per_m: f32) {
        self.tca_self_c = tca_self_c;
        self.rest_shape_per_m = rest_shape_per_m;
    }

    /// The running morph's phase ([`Phase::Idle`] when none runs; the controller, which
    /// latches faults, reports [`Phase::Fault`]).
    pub fn phase(&self) -> Phase {
        self.at.phase
    }

    /// Target radius of the running or last morph, mm (NaN if none).
    pub fn target_mm(&self) -> f32 {
        self.at.target_mm
    }

    /// True while a morph is under way.
    pub fn busy(&self) -> bool {
        self.at.phase.is_morphing()
    }

    /// Starts a morph to `radius_mm` with TCA power `tca_power_w` (from the table) in `mode`
    /// (`auto` runs [`crate::strategy::AUTO_STRATEGY`]) from the measured temperatures `m`
    /// (they start the model strategies' observer and set the spring-back compensation's
    /// ambient).
    // The morph's whole start in one call, so no half-started morph is ever observable.
    #[allow(clippy::too_many_arguments)]
    pub fn start_from(
        &mut self,
        now_ms: u64,
        radius_mm: f32,
        tca_power_w: f32,
        mode: Mode,
        m: &Measurements,
        cal: &crate::calibration::Calibration,
        emit: &mut dyn FnMut(SeqEvent),
    ) {
        self.at.target_mm = radius_mm;
        self.at.tca_power_w = tca_power_w;
        self.at.start_ms = now_ms;
        self.at.estimate_mm = f32::NAN;
        let pending = Pending {
            radius_mm,
            tca_power_w,
            mode,
            cal: *cal,
        };
        if rested(m) {
            self.heat(now_ms, pending, m, emit);
        } else {
            self.pending = Some(pending);
            self.at.enter(None, Phase::Rest, now_ms, emit);
        }
    }

    /// Starts the strategy from the measurements `m` and enters soften. Called from MORPH and
    /// from the end of a rest: kept out of line so the strategy's construction is in the image
    /// once.
    #[inline(never)]
    fn heat(&mut self, now_ms: u64, p: Pending, m: &Measurements, emit: &mut dyn FnMut(SeqEvent)) {
        let start = Start {
            now_ms,
            radius_mm: p.radius_mm,
            tca_power_w: p.tca_power_w,
            m,
            cal: &p.cal,
            pla_target_c: self.thresholds.pla_soft_target_c,
            tca_self_c: self.tca_self_c,
            rest_shape_per_m: self.rest_shape_per_m,
        };
        self.pending = None;
        let strategy = self.strategy.insert(AnyStrategy::new(p.mode, &start));
        self.at.heat_ms = now_ms;
        self.at
            .enter(Some(strategy.get_mut()), Phase::Soften, now_ms, emit);
    }

    /// Stops at once (ABORT, a trip): Idle, heaters off from the next step.
    pub fn abort(&mut self) {
        self.at.phase = Phase::Idle;
    }

    /// The temperatures the running morph's strategy aims at in the current phase, °C (NaN
    /// for a heater driven by power, and for both when no morph runs).
    pub fn targets_c(&self) -> TargetTemps {
        match (&self.strategy, self.busy()) {
            (Some(s), true) => s.get().targets_c(self.at.phase),
            _ => TargetTemps::NONE,
        }
    }

    /// The strategy the running or last morph ran (`auto` resolved; a resting morph's, the
    /// one it will run), None before the first.
    pub fn mode_ran(&self) -> Option<Mode> {
        match self.pending {
            Some(p) => Some(AnyStrategy::resolve(p.mode)),
            None => self.strategy.as_ref().map(AnyStrategy::mode),
        }
    }

    fn timeout_s(&self) -> f32 {
        let phase = self.at.phase;
        let own = self
            .strategy
            .as_ref()
            .and_then(|s| s.get().timeout_s(phase));
        own.unwrap_or(match phase {
            Phase::Soften => self.timeouts.soften_s,
            Phase::Bend => self.timeouts.bend_s,
            Phase::Lock => self.timeouts.lock_s,
            Phase::Rest => REST_TIMEOUT_S,
            _ => RELEASE_TIMEOUT_S,
        })
    }

    fn check_timeout(&mut self, now_ms: u64) -> Result<(), PhaseTimeout> {
        let timeout_s = self.timeout_s();
        if self.busy() && since_s(now_ms, self.at.phase_ms) > timeout_s {
            let p = self.at.phase;
            self.abort();
            return Err(PhaseTimeout(p));
        }
        Ok(())
    }

    /// One control tick: advances the phase from the measurements and returns the powers.
    pub fn step(
        &mut self,
        now_ms: u64,
        m: &Measurements,
        emit: &mut dyn FnMut(SeqEvent),
    ) -> Result<Powers, PhaseTimeout> {
        self.check_timeout(now_ms)?;
        if !self.busy() {
            return Ok(Powers::default());
        }
        if self.at.phase == Phase::Rest {
            if let Some(p) = self.pending.filter(|_| rested(m)) {
                self.heat(now_ms, p, m, emit);
            } else {
                return Ok(Powers::default());
            }
        }
        let at = &mut self.at;
        let Some(strategy) = self.strategy.as_mut() else {
            return Ok(Powers::default());
        };
        let s = strategy.get_mut();
        let tick = Tick {
            now_ms,
            phase: at.phase,
            m,
            in_phase_s: since_s(now_ms, at.phase_ms),
            since_start_s: since_s(now_ms, at.heat_ms),
            supply_v: self.supply_v,
            tca_self_c: self.tca_self_c,
            th: &self.thresholds,
            allow_w: self.allow_w,
        };
        if s.phase_done(&tick) {
            match at.phase {
                Phase::Soften => at.enter(Some(&mut *s), Phase::Bend, now_ms, emit),
                Phase::Bend => {
                    at.estimate_mm = s.radius_estimate_mm(m);
                    at.enter(Some(&mut *s), Phase::Lock, now_ms, emit);
                }
                Phase::Lock => at.enter(Some(&mut *s), Phase::Release, now_ms, emit),
                Phase::Release => at.finish(now_ms, emit),
                Phase::Idle | Phase::Rest | Phase::Fault => {}
            }
        }
        Ok(s.powers(at.phase, &tick))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::link::HOLD_POWER_W;
    use crate::strategy::model::observer::{HeatedNode, Observer};
    use crate::strategy::model::{
        MODEL_GUARD_K, MODEL_KEEP_ALIVE_W, PLA_BOOST_MAX_W, PLA_SOFT_TARGET_C, TCA_BOOST_MAX_W,
    };
    use crate::strategy::paper::SOFTEN_POWER_W;
    use crate::strategy::AUTO_STRATEGY;
    extern crate std;
    use std::vec::Vec;

    /// What only these tests ask of a sequencer.
    impl Sequencer {
        /// [`Sequencer::start_from`] with the link at the built-in ambient temperature.
        fn start(
            &mut self,
            now_ms: u64,
            radius_mm: f32,
            tca_power_w: f32,
            mode: Mode,
            emit: &mut dyn FnMut(SeqEvent),
        ) {
            let amb = crate::link::LINK.surroundings.ambient_c as f32;
            let m = Measurements {
                t_pla_c: amb,
                t_tca_c: amb,
                t_amb_c: amb,
            };
            self.start_from(
                now_ms,
                radius_mm,
                tca_power_w,
                mode,
                &m,
                &crate::calibration::Calibration::DEFAULT,
                emit,
            );
        }

        /// The strategy a morph in `mode` runs (`auto` resolved to [`AUTO_STRATEGY`]).
        fn strategy_of(mode: Mode) -> Mode {
            AnyStrategy::resolve(mode)
        }

        /// Strategy of the running or last morph (never `Auto`).
        fn strategy(&self) -> Mode {
            match self.strategy {
                None => Mode::Auto,
                Some(AnyStrategy::Paper(_)) => Mode::Paper,
                Some(AnyStrategy::Gated(_)) => Mode::Gated,
                Some(AnyStrategy::Boost(_)) => Mode::Boost,
                Some(AnyStrategy::Closed(_)) => Mode::Closed,
            }
        }

        /// TCA temperature the `boost` or `closed` morph aims at, °C (NaN for the others).
        fn tca_target_c(&self) -> f32 {
            self.strategy
                .as_ref()
                .and_then(|s| s.model())
                .map_or(f32::NAN, |d| d.tca_target_c())
        }

        /// The thermal model of a `boost` or `closed` morph.
        fn observer(&self) -> &Observer {
            self.strategy
                .as_ref()
                .and_then(|s| s.model())
                .unwrap()
                .observer()
        }
    }

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
    fn a_warm_link_rests_heaters_off_until_it_has_cooled_and_a_rest_is_bounded() {
        let cal = crate::calibration::Calibration::DEFAULT;
        let warm = meas(22.0 + REST_MAX_RISE_K + 20.0, 60.0);
        let mut s = Sequencer::new();
        let mut ev = Vec::new();
        s.start_from(0, 38.0, 0.6, Mode::Gated, &warm, &cal, &mut |e| ev.push(e));
        assert_eq!(s.phase(), Phase::Rest);
        assert!(s.busy());
        assert_eq!(s.mode_ran(), Some(Mode::Gated));
        assert_eq!(run(&mut s, 1000, warm, &mut ev), Powers::default());
        assert_eq!(s.phase(), Phase::Rest);
        // Cooled to within the rest: soften starts, and heats, on that tick.
        let cool = meas(22.0 + REST_MAX_RISE_K - 0.1, 22.0 + REST_MAX_RISE_K - 0.1);
        let p = run(&mut s, 60_000, cool, &mut ev);
        assert_eq!(s.phase(), Phase::Soften);
        assert!(p.pla_w > 0.0, "{p:?}");
        let entered: Vec<Phase> = ev
            .iter()
            .filter_map(|e| match e {
                SeqEvent::Phase { phase, .. } => Some(*phase),
                _ => None,
            })
            .collect();
        assert_eq!(entered, [Phase::Rest, Phase::Soften]);
        // A link that never cools: the rest times out, heaters off throughout.
        let mut s = Sequencer::new();
        s.start_from(0, 38.0, 0.6, Mode::Closed, &warm, &cal, &mut |_| {});
        let mut t = 0;
        let end = loop {
            t += 1000;
            match s.step(t, &warm, &mut |_| {}) {
                Ok(p) => assert_eq!(p, Powers::default()),
                Err(e) => break e,
            }
        };
        assert_eq!(end, PhaseTimeout(Phase::Rest));
        assert!(t as f32 / 1000.0 > REST_TIMEOUT_S && !s.busy());
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
            // The morph has ended (the controller latches the fault): nothing runs, no heat.
            assert_eq!(s.phase(), Phase::Idle);
            assert!(!s.busy());
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

    #[test]
    fn set_limits_changes_the_timeouts_and_thresholds_a_morph_runs_with() {
        let th = Thresholds {
            soft_threshold_c: 64.0,
            rigid_threshold_c: 40.0,
            ..Thresholds::DEFAULT
        };
        let to = PhaseTimeouts {
            soften_s: 25.0,
            ..PhaseTimeouts::DEFAULT
        };
        // A PLA stuck at 63 °C: soften times out at the set 25 s, not the default 60 s.
        let mut s = Sequencer::new();
        s.set_limits(th, to);
        let mut ev = Vec::new();
        s.start(0, 38.0, 0.6, Mode::Gated, &mut |e| ev.push(e));
        let mut t = 0;
        let result = loop {
            t += 100;
            let r = s.step(t, &meas(63.0, 22.0), &mut |e| ev.push(e));
            if r.is_err() || t > 70_000 {
                break r;
            }
        };
        assert_eq!(result, Err(PhaseTimeout(Phase::Soften)));
        assert!((25_000..=25_200).contains(&t), "timed out at {t} ms");
        // 66 °C ends soften with the set 64 °C threshold, not with the default 70 °C.
        for (limits, ends) in [(Some((th, to)), true), (None, false)] {
            let mut s = Sequencer::new();
            if let Some((th, to)) = limits {
                s.set_limits(th, to);
            }
            s.start(0, 38.0, 0.6, Mode::Gated, &mut |e| ev.push(e));
            run(&mut s, 100, meas(66.0, 22.0), &mut ev);
            assert_eq!(s.phase() == Phase::Bend, ends, "{limits:?}");
        }
    }
}
