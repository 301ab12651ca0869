//! A rig: the controller core driving a plant on the simulated board at the real control rate,
//! with the simulator-only `SIM` commands. `morph-sim`, the tests and the ensemble use it; the
//! emulated image runs the same [`Bench`] with the firmware's own tasks instead.

use morphlink::bench::{Bench, Noise, NOMINAL_LINK, SIM_WAIT_MAX_S};
use morphlink::controller::{Config, Controller, Inputs, Outputs, TICK_MS};
use morphlink::protocol::{reply, OutLine, SimCommand};
use morphlink::settings::ram_flash::RamFlash;
use morphlink::settings::store::{block_on_ready, SettingsStore};
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
            heater_tcr_per_k: morphlink_plant::lumped::HEATER_TCR_NOMINAL_PER_K,
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

/// The rig's settings flash: two 2 KiB pages written in 8-byte words, as the STM32G431's and
/// STM32L475's settings areas (`morph-sim --flash-file` keeps its image in a file).
pub type SimFlash = RamFlash<SIM_FLASH_BYTES, 2048, 8>;
/// Size of [`SimFlash`], bytes (the size of a `--flash-file`).
pub const SIM_FLASH_BYTES: usize = 4096;

/// Controller plus a plant on the simulated board plus a clock.
pub struct Rig<P = Lumped> {
    /// The controller under test.
    pub ctrl: Controller,
    /// The plant on its simulated board (its output stage holds the duties only while the
    /// controller refreshes them).
    pub bench: Bench<P>,
    now_ms: u64,
    waited_ms: u64,
    store: Option<SettingsStore<SimFlash>>,
    saves: u32,
}

/// How long [`Rig::boot`] runs a fresh rig, ms of link time: a few ticks of current sense give
/// the TCA's rest reference; a second is what a user takes to type the first line.
pub const BOOT_MS: u64 = 1000;

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
            waited_ms: 0,
            store: None,
            saves: 0,
        };
        rig.tick();
        rig
    }

    /// Boots the settings from `flash` as the firmware does: the stored settings or the
    /// defaults (with `event: config defaults reason=<why>`), and SAVE from now on writes
    /// `flash`.
    /// `None` is a flash that could not be read (a damaged image): the defaults, `reason=
    /// flash-error`, and SAVE starts over on an erased flash.
    pub fn boot_storage(&mut self, flash: Option<SimFlash>) {
        let readable = flash.is_some();
        let mut store = SettingsStore::new(flash.unwrap_or_default(), 0..SIM_FLASH_BYTES as u32)
            .expect("two whole pages");
        let loaded = if readable {
            block_on_ready(store.load())
        } else {
            Err(morphlink::settings::codec::LoadError::Flash)
        };
        self.ctrl.load_settings(loaded);
        self.ctrl.enable_storage();
        self.store = Some(store);
    }

    /// The settings flash, if [`Rig::boot_storage`] gave one.
    pub fn flash(&self) -> Option<&SimFlash> {
        self.store.as_ref().map(|s| s.flash())
    }

    /// SAVEs carried out (a shell keeping the flash in a file writes it when this grows).
    pub fn saves(&self) -> u32 {
        self.saves
    }

    /// Rig time, ms.
    pub fn now_ms(&self) -> u64 {
        self.now_ms
    }

    /// Rig time spent in `SIM WAIT`, ms: a shell pacing the rig against a wall clock leaves
    /// it out (that time was asked to pass at once).
    pub fn waited_ms(&self) -> u64 {
        self.waited_ms
    }

    /// Why the plant can no longer answer ([`Plant::failure`]); the shell ends the run.
    pub fn plant_failure(&self) -> Option<&str> {
        self.bench.plant().failure()
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

    /// Runs the board up to [`BOOT_MS`] of link time, as a board is up for a moment before its
    /// first MORPH: where it senses current, that moment gives the TCA its resistance at rest,
    /// which its own temperature (`tca_self_bend`) counts from.
    pub fn boot(&mut self) {
        while self.now_ms < BOOT_MS {
            self.tick();
        }
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
        if let Some(blob) = self.ctrl.take_save_request() {
            if let Some(store) = &mut self.store {
                let r = block_on_ready(store.save(&blob));
                self.saves += 1;
                self.ctrl.finish_save(r, out);
            }
        }
        // A command may change the duties (ABORT): applied at once, as the firmware does.
        let now = self.ctrl.outputs();
        self.apply(now);
    }

    fn sim_command(&mut self, cmd: SimCommand, out: &mut impl FnMut(&str)) {
        match cmd {
            SimCommand::Wait(seconds) => self.wait(seconds, out),
            _ => {
                // A plant that fails on a `SIM` setting gets no reply written for it (its
                // refusal would read as the plant's answer): the shell ends the run instead.
                let mut reply = OutLine::new();
                self.bench.command(cmd, &mut |l: &str| {
                    reply.clear();
                    let _ = reply.push_str(l);
                });
                if self.plant_failure().is_none() {
                    out(&reply);
                }
            }
        }
    }

    /// `SIM WAIT <s>`: runs the controller and the plant for `seconds` of rig time at the
    /// control rate, writing events as they come, then `ok`. Refuses a negative, NaN or longer
    /// than [`SIM_WAIT_MAX_S`] wait with `out-of-range`. If the plant fails on the way, it
    /// stops there without a reply: the shell sees [`Rig::plant_failure`] and ends the run.
    fn wait(&mut self, seconds: f32, out: &mut impl FnMut(&str)) {
        let mut l = OutLine::new();
        if !(0.0..=SIM_WAIT_MAX_S).contains(&seconds) {
            reply::sim_wait_out_of_range(&mut l, SIM_WAIT_MAX_S);
            out(&l);
            return;
        }
        // Non-negative, so adding a half and truncating rounds to the nearest tick.
        let ticks = (seconds as f64 * 1000.0 / TICK_MS as f64 + 0.5) as u64;
        for _ in 0..ticks {
            self.tick();
            self.waited_ms += TICK_MS;
            self.drain_events(out);
            if self.plant_failure().is_some() {
                return;
            }
        }
        reply::ok(&mut l);
        out(&l);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use morphlink_plant::{Duties, Sample, SetError, Setting, Truth};
    use std::string::{String, ToString};
    use std::vec::Vec;

    fn lines(rig: &mut Rig<impl Plant>, line: &str) -> Vec<String> {
        let mut got = Vec::new();
        rig.handle_line(line, &mut |l: &str| got.push(l.to_string()));
        got
    }

    #[test]
    fn sim_wait_runs_the_rig_at_the_control_rate_and_emits_events() {
        let mut rig = Rig::new(LinkSetup::NOMINAL);
        let t0 = rig.now_ms();
        assert_eq!(lines(&mut rig, "SIM WAIT 2.5"), ["ok"]);
        assert_eq!(rig.now_ms() - t0, 2500);
        assert_eq!(rig.waited_ms(), 2500);
        assert_eq!(lines(&mut rig, "MORPH 38"), ["ok"]);
        let got = lines(&mut rig, "SIM WAIT 120");
        assert_eq!(got.last().map(String::as_str), Some("ok"), "{got:?}");
        assert!(got[0].starts_with("event: phase soften"), "{got:?}");
        assert!(got.iter().any(|l| l.starts_with("event: done")), "{got:?}");
        assert!(!rig.ctrl.busy());
        assert!((rig.radius_mm() - 38.0).abs() < 0.5, "{}", rig.radius_mm());
    }

    #[test]
    fn sim_wait_is_bounded() {
        let mut rig = Rig::new(LinkSetup::NOMINAL);
        let t0 = rig.now_ms();
        for bad in ["SIM WAIT -1", "SIM WAIT 3600.5", "SIM WAIT 100000"] {
            assert_eq!(
                lines(&mut rig, bad),
                ["error: out-of-range wait must be 0..3600 s"],
                "{bad}"
            );
        }
        assert_eq!(lines(&mut rig, "SIM WAIT 0"), ["ok"]);
        assert_eq!(rig.now_ms(), t0);
    }

    /// A plant that changes nothing it is asked to.
    struct Stubborn(Lumped);
    impl Plant for Stubborn {
        fn step(&mut self, dt_s: f64, duty: Duties) {
            self.0.step(dt_s, duty)
        }
        fn sample(&self) -> Sample {
            self.0.sample()
        }
        fn truth(&self) -> Truth {
            self.0.truth()
        }
        fn set(&mut self, _: Setting) -> Result<(), SetError> {
            Err(SetError::Unsupported)
        }
    }

    #[test]
    fn sim_settings_a_plant_refuses_answer_unsupported() {
        let mut rig = Rig::with_plant(Stubborn(LinkSetup::NOMINAL.lumped()), Noise::NOMINAL);
        for (line, word) in [
            ("SIM SUPPLY 5", "SUPPLY"),
            ("SIM AMBIENT 30", "AMBIENT"),
            ("SIM MEDIUM air", "MEDIUM"),
        ] {
            let got = lines(&mut rig, line);
            assert_eq!(
                got,
                [std::format!(
                    "error: unsupported SIM {word}: the plant cannot change that"
                )]
            );
        }
        // Range checks come first, as before.
        assert_eq!(
            lines(&mut rig, "SIM SUPPLY 99"),
            ["error: out-of-range supply must be 0..30 V"]
        );
        let mut lumped = Rig::new(LinkSetup::NOMINAL);
        assert_eq!(lines(&mut lumped, "SIM SUPPLY 11"), ["ok supply_v=11.00"]);
    }

    #[test]
    fn a_rig_runs_a_boxed_plant() {
        let plant: std::boxed::Box<dyn Plant> = std::boxed::Box::new(LinkSetup::NOMINAL.lumped());
        let mut boxed = Rig::with_plant(plant, Noise::NOMINAL);
        let mut plain = Rig::new(LinkSetup::NOMINAL);
        for rig_lines in [lines(&mut boxed, "MORPH 38"), lines(&mut plain, "MORPH 38")] {
            assert_eq!(rig_lines, ["ok"]);
        }
        for _ in 0..300 {
            boxed.tick();
            plain.tick();
        }
        assert_eq!(boxed.radius_mm(), plain.radius_mm());
        assert!(boxed.plant_failure().is_none());
    }
}
