//! `gated`: the phases end on thermistor thresholds and settling; the TCA gets the table's
//! power. Soften until the PLA reads soft, bend until the TCA thermistor settles, lock until the
//! PLA reads rigid.

use super::paper::table_powers;
use super::{Start, Strategy, Tick, RELEASE_S};
use crate::link::{HOLD_POWER_W, R_TP_K_PER_W, R_TT_K_PER_W};
use crate::table;
use crate::vocab::{Measurements, Phase, Powers};

/// Shortest bend, s: lets the TCA's fast thermal part (about 1 s) finish before settling is judged.
pub const MIN_BEND_S: f32 = 6.0;
/// Window over which the TCA temperature must stay within [`SETTLE_BAND_C`], s.
pub const SETTLE_WINDOW_S: f32 = 4.0;
/// Largest TCA temperature change over the settle window that counts as settled, K. The
/// radius moves about 0.27 mm per kelvin of TCA temperature; the slow thermal part still to
/// come is about (rate × 17 s), so 0.2 K per 4 s leaves under 1 K ≈ 0.3 mm.
pub const SETTLE_BAND_C: f32 = 0.2;

/// The `gated` strategy: the table's TCA power and the TCA's settle window.
#[derive(Clone, Copy, Debug)]
pub struct Gated {
    tca_power_w: f32,
    window_ms: u64,
    window_temp_c: f32,
}

impl Gated {
    /// For a morph starting as `s` says.
    pub fn new(s: &Start) -> Self {
        Gated {
            tca_power_w: s.tca_power_w,
            window_ms: s.now_ms,
            window_temp_c: f32::NAN,
        }
    }

    /// TCA power during lock, W: the bend power plus what replaces the heat the PLA heater
    /// stops giving the TCA (`R_tp / R_tt · hold power`), so the TCA stays at its bend
    /// temperature while the PLA freezes the shape.
    fn lock_tca_power_w(&self) -> f32 {
        self.tca_power_w + R_TP_K_PER_W / R_TT_K_PER_W * HOLD_POWER_W
    }

    /// True once the TCA temperature has stayed within the settle band for a whole window.
    fn tca_settled(&mut self, now_ms: u64, t_tca_c: f32) -> bool {
        if self.window_temp_c.is_nan() {
            self.window_temp_c = t_tca_c;
            self.window_ms = now_ms;
            return false;
        }
        if now_ms.saturating_sub(self.window_ms) as f32 / 1000.0 < SETTLE_WINDOW_S {
            return false;
        }
        let settled = (t_tca_c - self.window_temp_c).abs() <= SETTLE_BAND_C;
        self.window_temp_c = t_tca_c;
        self.window_ms = now_ms;
        settled
    }
}

impl Strategy for Gated {
    fn enter(&mut self, _phase: Phase, now_ms: u64) {
        self.window_ms = now_ms;
        self.window_temp_c = f32::NAN;
    }

    fn phase_done(&mut self, t: &Tick) -> bool {
        let m = t.m;
        match t.phase {
            Phase::Soften => m.t_pla_c >= t.th.soft_threshold_c,
            Phase::Bend => self.tca_settled(t.now_ms, m.t_tca_c) && t.in_phase_s >= MIN_BEND_S,
            Phase::Lock => m.t_pla_c < t.th.rigid_threshold_c,
            Phase::Release => t.in_phase_s >= RELEASE_S,
            Phase::Idle | Phase::Rest | Phase::Fault => false,
        }
    }

    fn radius_estimate_mm(&self, m: &Measurements) -> f32 {
        table::radius_for_tca_rise_mm(m.t_tca_c - m.t_amb_c)
    }

    fn powers(&mut self, phase: Phase, _t: &Tick) -> Powers {
        table_powers(phase, self.tca_power_w, self.lock_tca_power_w())
    }
}
