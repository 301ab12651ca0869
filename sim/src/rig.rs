//! A rig: the controller core driving the simulated link at the real control rate, with the
//! simulator-only `SIM` commands. `morph-sim`, the tests and the emulated image all use it.

use crate::link::{Plant, SimLink};
use morphlink::controller::{Config, Controller, Outputs, TICK_MS};
use morphlink::protocol::SimCommand;

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
        self.link.command(cmd, out);
    }
}
