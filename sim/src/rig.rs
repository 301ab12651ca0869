//! A rig: the controller core driving the simulated link at the real control rate, with the
//! simulator-only `SIM` commands. `morph-sim`, the tests and the emulated image all use it.

use crate::link::{Plant, SimLink};
use morphlink::controller::{Config, Controller, Outputs, TICK_MS};
use morphlink::heater::CommandWatchdog;
use morphlink::protocol::SimCommand;

/// Controller plus simulated link plus a clock.
pub struct Rig {
    /// The controller under test.
    pub ctrl: Controller,
    /// The simulated link.
    pub link: SimLink,
    /// The heater output stage: PLA and TCA duties hold only while the controller refreshes
    /// them (the core's command watchdog, as a board's PWM stage would apply it).
    pwm: [CommandWatchdog; 2],
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
            pwm: [CommandWatchdog::default(); 2],
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
        self.apply(out);
        self.run_link();
        out
    }

    /// One control period in which the controller does not run (a stalled control loop): the
    /// output stage keeps the last duties only until the command watchdog expires them.
    pub fn stalled_tick(&mut self) {
        self.run_link();
    }

    /// Duties the heaters actually get now.
    pub fn applied(&self) -> Outputs {
        Outputs {
            pla_duty: self.pwm[0].duty(self.now_ms),
            tca_duty: self.pwm[1].duty(self.now_ms),
        }
    }

    fn apply(&mut self, out: Outputs) {
        self.pwm[0].refresh(self.now_ms, out.pla_duty);
        self.pwm[1].refresh(self.now_ms, out.tca_duty);
    }

    fn run_link(&mut self) {
        let applied = self.applied();
        self.link.advance(TICK_MS as f64 / 1000.0, applied);
        self.now_ms += TICK_MS;
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
        // A command may change the duties (ABORT): applied at once, as the firmware does.
        let now = self.ctrl.outputs();
        self.apply(now);
    }

    fn sim_command(&mut self, cmd: SimCommand, out: &mut impl FnMut(&str)) {
        self.link.command(cmd, out);
    }
}
