//! A rig: the controller core driving a plant on the simulated board at the real control rate,
//! with the simulator-only `SIM` commands. `morph-sim`, the tests and the ensemble use it; the
//! emulated image runs the same [`Bench`] with the firmware's own tasks instead.

use morphlink::bench::{Bench, Noise, NOMINAL_LINK};
use morphlink::controller::{Config, Controller, Inputs, Outputs, TICK_MS};
use morphlink::protocol::SimCommand;
use morphlink_plant::{Lumped, LumpedSpec, Plant};

/// A lumped link as the rig builds it: the plant's true values and the board's thermistor noise.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinkSetup {
    /// The link's true physical parameters (h, ambient, fitted constants...).
    pub params: morphlink_model::LinkParams,
    /// True heater resistances, Ω: PLA wrap, TCA.
    pub heater_ohm: [f64; 2],
    /// True heater supply, V.
    pub supply_v: f64,
    /// Thermistor time constants (PLA, TCA, ambient), s (see [`LumpedSpec::sensor_tau_s`]).
    pub sensor_tau_s: [f64; 3],
    /// Standard deviation of thermistor noise, °C.
    pub sensor_noise_c: f64,
    /// Seed of the noise generator.
    pub seed: u64,
}

impl LinkSetup {
    /// The nominal link ([`NOMINAL_LINK`]) with the nominal noise ([`Noise::NOMINAL`]).
    pub const NOMINAL: LinkSetup = LinkSetup {
        params: NOMINAL_LINK.params,
        heater_ohm: NOMINAL_LINK.heater_ohm,
        supply_v: NOMINAL_LINK.supply_v,
        sensor_tau_s: NOMINAL_LINK.sensor_tau_s,
        sensor_noise_c: Noise::NOMINAL.sensor_noise_c,
        seed: Noise::NOMINAL.seed,
    };

    /// The lumped plant this setup describes.
    pub fn lumped(&self) -> Lumped {
        Lumped::new(LumpedSpec {
            params: self.params,
            heater_ohm: self.heater_ohm,
            supply_v: self.supply_v,
            sensor_tau_s: self.sensor_tau_s,
        })
    }

    /// The board's thermistor noise.
    pub fn noise(&self) -> Noise {
        Noise {
            sensor_noise_c: self.sensor_noise_c,
            seed: self.seed,
        }
    }
}

/// Controller plus a plant on the simulated board plus a clock.
pub struct Rig<P = Lumped> {
    /// The controller under test.
    pub ctrl: Controller,
    /// The plant on its simulated board (its output stage holds the duties only while the
    /// controller refreshes them).
    pub bench: Bench<P>,
    now_ms: u64,
}

impl Rig<Lumped> {
    /// A rig with the default board and the lumped link `setup`, after one control tick (so
    /// the controller has a sensor frame).
    pub fn new(setup: LinkSetup) -> Self {
        Rig::with_plant(setup.lumped(), setup.noise())
    }
}

impl<P: Plant> Rig<P> {
    /// A rig with the default board around `plant`, after one control tick.
    pub fn with_plant(plant: P, noise: Noise) -> Self {
        let board = Config::DEFAULT;
        let mut rig = Rig {
            ctrl: Controller::new(board),
            bench: Bench::new(plant, board, noise),
            now_ms: 0,
        };
        rig.tick();
        rig
    }

    /// Rig time, ms.
    pub fn now_ms(&self) -> u64 {
        self.now_ms
    }

    /// The plant.
    pub fn plant(&self) -> &P {
        self.bench.plant()
    }

    /// True bending radius, mm.
    pub fn radius_mm(&self) -> f64 {
        self.bench.radius_mm()
    }

    /// Heater powers actually dissipated in the last period, W (PLA, TCA).
    pub fn powers_w(&self) -> [f64; 2] {
        self.bench.powers_w()
    }

    /// The ADC frame the board would read now, stamped `sample_ms`.
    pub fn inputs(&mut self, sample_ms: u64) -> Inputs {
        self.bench.inputs(sample_ms)
    }

    /// One control period: sample, step the controller, then let the link run one period
    /// with the resulting duties.
    pub fn tick(&mut self) -> Outputs {
        let inputs = self.bench.inputs(self.now_ms);
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
        self.bench.applied(self.now_ms)
    }

    fn apply(&mut self, out: Outputs) {
        self.bench.drive(self.now_ms, out);
    }

    fn run_link(&mut self) {
        self.bench.run(self.now_ms, TICK_MS as f64 / 1000.0);
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
        self.bench.command(cmd, out);
    }
}
