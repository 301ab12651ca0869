//! The morph sequence as a pure state machine: Idle → Soften → Bend → Lock → Release → Idle,
//! plus Fault. It turns measured temperatures into heater powers; it never touches hardware
//! and never decides about safety (the supervisor does, every tick, before it).

use crate::link::{HOLD_POWER_W, R_TP_K_PER_W, R_TT_K_PER_W};
use crate::protocol::Mode;
use crate::table;

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
        }
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

    /// Starts a morph to `radius_mm` with TCA power `tca_power_w` (from the table).
    pub fn start(
        &mut self,
        now_ms: u64,
        radius_mm: f32,
        tca_power_w: f32,
        mode: Mode,
        emit: &mut impl FnMut(SeqEvent),
    ) {
        self.mode = mode;
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
            Mode::Auto => self.step_gated(now_ms, m, emit),
            Mode::Paper => self.step_paper(now_ms, m, emit),
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
        s.start(0, 38.0, 0.6, Mode::Auto, &mut |e| ev.push(e));
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
            s.start(0, 38.0, 0.6, Mode::Auto, &mut |e| ev.push(e));
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
            s.start(0, 38.0, 0.6, Mode::Auto, &mut |e| ev.push(e));
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
}
