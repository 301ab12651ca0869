//! `paper`: the paper's fixed timing (Fig. 8). PLA 4 W from MORPH to 20 s, then the hold power
//! to 70 s; TCA at the table's power from 20 s to 120 s; no thermistor decides anything (the
//! supervisor still watches them).

use super::{Start, Strategy, Tick, RELEASE_S};
use crate::heater::HeaterConfig;
use crate::link::HOLD_POWER_W;
use crate::table;
use crate::vocab::{Measurements, Phase, Powers};

/// Power that softens the PLA, W (paper: 4 W; reaches 70 °C in about 5 s under water).
pub const SOFTEN_POWER_W: f32 = 4.0;
const _: () = assert!(SOFTEN_POWER_W <= HeaterConfig::PLA.max_power_w);
const _: () = assert!(HOLD_POWER_W <= HeaterConfig::PLA.max_power_w);

/// The paper's fixed timing (Fig. 8), s from MORPH: soften ends, PLA hold ends, TCA off.
pub const PAPER_SOFTEN_END_S: f32 = 20.0;
/// See [`PAPER_SOFTEN_END_S`].
pub const PAPER_HOLD_END_S: f32 = 70.0;
/// See [`PAPER_SOFTEN_END_S`].
pub const PAPER_TCA_END_S: f32 = 120.0;
const _: () = assert!(PAPER_SOFTEN_END_S < PAPER_HOLD_END_S && PAPER_HOLD_END_S < PAPER_TCA_END_S);
/// Slack of each fixed phase's timeout over its planned length, s: the phases end on the clock,
/// so only a stuck sequence reaches it.
pub const PAPER_TIMEOUT_SLACK_S: f32 = 5.0;

/// The powers of the table strategies (`paper`, `gated`): the paper's 4 W in soften, the hold
/// power with the TCA at the table's power in bend, the PLA off and the TCA at `lock_tca_w` in lock.
pub(super) fn table_powers(phase: Phase, tca_power_w: f32, lock_tca_w: f32) -> Powers {
    match phase {
        Phase::Soften => Powers {
            pla_w: SOFTEN_POWER_W,
            tca_w: 0.0,
        },
        Phase::Bend => Powers {
            pla_w: HOLD_POWER_W,
            tca_w: tca_power_w,
        },
        Phase::Lock => Powers {
            pla_w: 0.0,
            tca_w: lock_tca_w,
        },
        _ => Powers::default(),
    }
}

/// The `paper` strategy: only the table's TCA power.
#[derive(Clone, Copy, Debug)]
pub struct Paper {
    tca_power_w: f32,
}

impl Paper {
    /// For a morph starting as `s` says.
    pub fn new(s: &Start) -> Self {
        Paper {
            tca_power_w: s.tca_power_w,
        }
    }
}

impl Strategy for Paper {
    fn enter(&mut self, _phase: Phase, _now_ms: u64) {}

    fn timeout_s(&self, phase: Phase) -> Option<f32> {
        match phase {
            Phase::Soften => Some(PAPER_SOFTEN_END_S + PAPER_TIMEOUT_SLACK_S),
            Phase::Bend => Some(PAPER_HOLD_END_S - PAPER_SOFTEN_END_S + PAPER_TIMEOUT_SLACK_S),
            Phase::Lock => Some(PAPER_TCA_END_S - PAPER_HOLD_END_S + PAPER_TIMEOUT_SLACK_S),
            _ => None,
        }
    }

    fn phase_done(&mut self, t: &Tick) -> bool {
        let t_s = t.since_start_s;
        match t.phase {
            Phase::Soften => t_s >= PAPER_SOFTEN_END_S,
            Phase::Bend => t_s >= PAPER_HOLD_END_S,
            Phase::Lock => t_s >= PAPER_TCA_END_S,
            Phase::Release => t.in_phase_s >= RELEASE_S,
            Phase::Idle | Phase::Rest | Phase::Fault => false,
        }
    }

    fn radius_estimate_mm(&self, m: &Measurements) -> f32 {
        table::radius_for_tca_rise_mm(m.t_tca_c - m.t_amb_c)
    }

    fn powers(&mut self, phase: Phase, _t: &Tick) -> Powers {
        // The paper keeps the bend power through lock.
        table_powers(phase, self.tca_power_w, self.tca_power_w)
    }
}
