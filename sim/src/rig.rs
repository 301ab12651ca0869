//! A rig: the controller core driving the simulated link at the real control rate, with the
//! simulator-only `SIM` commands. `morph-sim`, the tests and the emulated image all use it.

use crate::link::{Plant, SimLink};
use core::fmt::Write;
use morphlink::controller::{Config, Controller, Outputs, TICK_MS};
use morphlink::fixed::Fixed;
use morphlink::protocol::{OutLine, Sensor, SimCommand};

/// Highest supply `SIM SUPPLY` accepts, V (the supervisor's limit is lower, so faults can be tried).
pub const SIM_SUPPLY_MAX_V: f32 = 30.0;
/// Range `SIM AMBIENT` accepts, °C.
pub const SIM_AMBIENT_RANGE_C: (f32, f32) = (-10.0, 60.0);

/// Controller plus simulated link plus a clock.
pub struct Rig {
    /// The controller under test.
    pub ctrl: Controller,
    /// The simulated link.
    pub link: SimLink,
    now_ms: u64,
}

impl Rig {
    /// A rig with the default board and the given plant, after one control tick (so the
    /// controller has a sensor frame).
    pub fn new(plant: Plant) -> Self {
        let board = Config::DEFAULT;
        let mut rig = Rig {
            ctrl: Controller::new(board),
            link: SimLink::new(plant, board),
            now_ms: 0,
        };
        rig.tick();
        rig
    }

    /// Rig time, ms.
    pub fn now_ms(&self) -> u64 {
        self.now_ms
    }

    /// One control period: sample, step the controller, then let the link run one period
    /// with the resulting duties.
    pub fn tick(&mut self) -> Outputs {
        let inputs = self.link.inputs(self.now_ms);
        let out = self.ctrl.step(self.now_ms, &inputs);
        self.link.advance(TICK_MS as f64 / 1000.0, out);
        self.now_ms += TICK_MS;
        out
    }

    /// Writes every queued event or alarm line through `out`.
    pub fn drain_events(&mut self, out: &mut impl FnMut(&str)) {
        while let Some(l) = self.ctrl.pop_event_line() {
            out(&l);
        }
    }

    /// Handles one protocol line, `SIM` commands included; replies through `out`.
    pub fn handle_line(&mut self, line: &str, out: &mut impl FnMut(&str)) {
        if let Some(sim) = self.ctrl.handle_line(self.now_ms, line, out) {
            self.sim_command(sim, out);
        }
    }

    fn sim_command(&mut self, cmd: SimCommand, out: &mut impl FnMut(&str)) {
        let mut l = OutLine::new();
        match cmd {
            SimCommand::State => {
                let (pla, tca) = self.link.temps_c();
                let _ = write!(
                    l,
                    "ok time_s={} radius_mm={} t_pla_c={} t_tca_c={}",
                    Fixed(self.link.time_s() as f32, 1),
                    Fixed(self.link.radius_mm() as f32, 2),
                    Fixed(pla as f32, 2),
                    Fixed(tca as f32, 2)
                );
            }
            SimCommand::Fault(kind, target) => {
                let index = match target {
                    Sensor::Pla => 0,
                    Sensor::Tca => 1,
                    Sensor::Amb => 2,
                };
                self.link.inject(kind, index);
                let _ = write!(l, "ok fault={} target={}", kind.as_str(), target.as_str());
            }
            SimCommand::Supply(v) => {
                if !(0.0..=SIM_SUPPLY_MAX_V).contains(&v) {
                    let _ = write!(
                        l,
                        "error: out-of-range supply must be 0..{} V",
                        Fixed(SIM_SUPPLY_MAX_V, 0)
                    );
                } else {
                    self.link.set_supply_v(v as f64);
                    let _ = write!(l, "ok supply_v={}", Fixed(v, 2));
                }
            }
            SimCommand::Ambient(c) => {
                let (lo, hi) = SIM_AMBIENT_RANGE_C;
                if !(lo..=hi).contains(&c) {
                    let _ = write!(
                        l,
                        "error: out-of-range ambient must be {}..{} C",
                        Fixed(lo, 0),
                        Fixed(hi, 0)
                    );
                } else {
                    self.link.set_ambient_c(c as f64);
                    let _ = write!(l, "ok t_amb_c={}", Fixed(c, 2));
                }
            }
            SimCommand::Medium(m) => {
                self.link.set_medium(m);
                let _ = write!(l, "ok medium={}", m.as_str());
            }
            SimCommand::Clear => {
                self.link.clear_faults();
                let _ = write!(l, "ok");
            }
        }
        out(&l);
    }
}
