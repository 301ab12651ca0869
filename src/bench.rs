//! The simulated board around a plant: what stands between a simulated link and the
//! controller on a real board. The heater output stage (duties that hold only while the
//! controller refreshes them, a stuck MOSFET, an open heater, the supply's cut-off), the
//! thermistor dividers and ADC (with noise, an open or shorted thermistor), the heaters'
//! shunt amplifiers (where the plant reports its heaters' resistances: gain error, offset,
//! noise, the ADC's steps, samples inside the pulse and inside the off-time) and the `SIM`
//! commands. The plant (`morphlink-plant`) gives bead temperatures, supply and radius; this
//! module turns them into the ADC frame the controller reads and turns the controller's duties
//! into what reaches the heaters.
//!
//! Used by the host rig (`morphlink-sim`) and by the emulated firmware image alike, so both
//! run the same board model. Built with the `sim` feature; `no_std` and allocation-free.

use crate::controller::{Config, Inputs, Outputs};
use crate::electrical::{CurrentCounts, MIN_SENSED_ON_US, PROBE_DUTY};
use crate::heater::CommandWatchdog;
use crate::protocol::reply::SimSetting;
use crate::protocol::{format_error, reply, Medium, OutLine, SimCommand, SimFault};
use morphlink_plant::{Duties, LumpedSpec, Plant, SetError, Setting};

/// Highest supply `SIM SUPPLY` accepts, V (the supervisor's limit is lower, so faults can be tried).
pub const SIM_SUPPLY_MAX_V: f32 = 30.0;
/// Range `SIM AMBIENT` accepts, °C.
pub const SIM_AMBIENT_RANGE_C: (f32, f32) = (-10.0, 60.0);
/// Longest `SIM WAIT`, s: an hour of simulated time (the longest phase timeouts sum to under
/// 800 s, and `morph-sim` stops at `--max-time-s`, 3600 s by default), a bound on one line's
/// work.
pub const SIM_WAIT_MAX_S: f32 = 3600.0;

/// Largest drift rate `SIM FAULT thermistor-drift` accepts, K/s, either sign: 10 K/s is far
/// beyond any plausible-but-wrong reading (it crosses a limit within seconds) and keeps the
/// offset finite over an hour of simulated time.
pub const SIM_DRIFT_MAX_K_PER_S: f32 = 10.0;

/// The nominal lumped link: the built-in parameters, nominal heaters (30 Ω wrap, 6.5 Ω TCA)
/// and a 12 V supply, 3 s thermistor lag. The plant of `morph-sim` and the emulated image.
pub const NOMINAL_LINK: LumpedSpec = LumpedSpec {
    params: crate::link::LINK,
    heater_ohm: [30.0, 6.5],
    heater_tcr_per_k: morphlink_plant::lumped::HEATER_TCR_NOMINAL_PER_K,
    supply_v: 12.0,
    sensor_tau_s: [3.0, 3.0, 3.0],
};

/// The simulated board's current-sense chain, per heater (PLA, TCA): gain errors (a 1 %
/// shunt and the amplifier's 1 % gain error, one sign each), offset at the ADC, A, and
/// noise of one tick's reading, A (the amplifier's and the ADC's, a few counts).
pub const SENSE_GAIN_ERROR: [f32; 2] = [0.012, -0.015];
/// Offset of the current-sense chain at the ADC, A (an INA180's 150 µV at gain 20 is 3 mA).
pub const SENSE_OFFSET_A: f32 = 0.003;
/// Noise of one tick's current reading, A (standard deviation).
pub const SENSE_NOISE_A: f32 = 0.003;

/// Share of a control tick the probe pulse is on (one pulse of [`MIN_SENSED_ON_US`] per tick):
/// the heat it delivers, as a mean duty.
const PROBE_TICK_DUTY: f32 = MIN_SENSED_ON_US * 1e-6 * crate::controller::CONTROL_HZ as f32;

/// The rig's side of the thermistors: noise on their readings and its seed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Noise {
    /// Standard deviation of thermistor noise, °C.
    pub sensor_noise_c: f64,
    /// Seed of the noise generator.
    pub seed: u64,
}

impl Noise {
    /// 0.05 °C: a 12-bit ADC oversampled 16× on a 10 kΩ divider, plus pickup.
    pub const NOMINAL: Noise = Noise {
        sensor_noise_c: 0.05,
        seed: 0x5eed_1234,
    };
}

/// A plant on a simulated board.
#[derive(Clone, Debug)]
pub struct Bench<P> {
    plant: P,
    board: Config,
    noise: Noise,
    thermistor_fault: [Option<SimFault>; 3],
    /// The counts a stuck thermistor reads (taken at its first frame after the fault).
    stuck_counts: [Option<u32>; 3],
    /// A drifting thermistor's rate, K/s, and when its drift started (its first frame after
    /// the fault, ms).
    drift: [Option<(f32, Option<u64>)>; 3],
    heater_open: [bool; 2],
    heater_stuck: [bool; 2],
    /// The cut-off never opens (`SIM FAULT cutoff-stuck`).
    cutoff_stuck: bool,
    /// The board has its current-sense amplifiers ([`Bench::set_current_sense`]).
    current_sense: bool,
    /// PLA, TCA and the cut-off (1 closed, 0 open): each holds only while refreshed.
    output: [CommandWatchdog; 3],
    rng: u64,
    /// The current sense's own noise, apart from the thermistors' (so a board with current
    /// sense reads its thermistors exactly as one without).
    current_rng: u64,
    /// The supply at the board's terminals, V, where a shared supply sags under the load of
    /// several links ([`Bench::set_terminal_v`]); `None`: the plant's own supply.
    terminal_v: Option<f64>,
    /// The supply inside each heater's own pulse where its on-current is sampled, V, on a
    /// supply shared by several links ([`Bench::set_pulse_v`]); `None`: the terminal voltage.
    pulse_v: Option<[f64; 2]>,
}

/// Approximately standard normal noise from `rng` (xorshift; the sum of four uniforms).
fn gaussian(rng: &mut u64) -> f64 {
    let mut s = 0.0;
    for _ in 0..4 {
        *rng ^= *rng << 13;
        *rng ^= *rng >> 7;
        *rng ^= *rng << 17;
        s += (*rng >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
    }
    // Four uniforms on [-0.5, 0.5] have variance 1/3.
    s * libm::sqrt(3.0)
}

impl<P: Plant> Bench<P> {
    /// `plant` read through `board`'s thermistor and ADC model, with `noise`.
    pub fn new(plant: P, board: Config, noise: Noise) -> Self {
        Bench {
            plant,
            board,
            noise,
            thermistor_fault: [None; 3],
            stuck_counts: [None; 3],
            drift: [None; 3],
            heater_open: [false; 2],
            heater_stuck: [false; 2],
            cutoff_stuck: false,
            current_sense: true,
            output: [CommandWatchdog::default(); 3],
            rng: noise.seed | 1,
            current_rng: (noise.seed ^ 0xc0ff_ee00_1234_5678) | 1,
            terminal_v: None,
            pulse_v: None,
        }
    }

    /// The plant.
    pub fn plant(&self) -> &P {
        &self.plant
    }

    /// The plant, to change it directly (tests).
    pub fn plant_mut(&mut self) -> &mut P {
        &mut self.plant
    }

    /// True bending radius, mm.
    pub fn radius_mm(&self) -> f64 {
        self.plant.sample().radius_mm
    }

    /// Heater powers actually dissipated in the last step, W (PLA, TCA).
    pub fn powers_w(&self) -> [f64; 2] {
        let t = self.plant.truth();
        [t.pla_w, t.tca_w]
    }

    /// Whether the board senses its heaters' current: it has the amplifiers and the plant
    /// reports the heaters' resistances.
    pub fn senses_current(&self) -> bool {
        self.current_sense && self.plant.sample().heater_ohm.is_some()
    }

    /// Fits (`true`, the default) or leaves out the current-sense amplifiers: without them the
    /// board is the paper's wiring plus the cut-off, thermistors only.
    pub fn set_current_sense(&mut self, on: bool) {
        self.current_sense = on;
    }

    /// Whether the heaters have a supply at `now_ms`: the cut-off closed, or stuck closed.
    fn supplied(&self, now_ms: u64) -> bool {
        self.cutoff_stuck || self.applied(now_ms).supply_on
    }

    /// The duty that reaches heater `i` (0 PLA, 1 TCA) when `duty` is commanded and the supply
    /// is `supplied`; below the probe duty a board that senses current adds its probe pulse.
    fn delivered(&self, i: usize, duty: f32, supplied: bool, sensing: bool) -> f64 {
        if !supplied || self.heater_open[i] {
            0.0
        } else if self.heater_stuck[i] {
            1.0
        } else if sensing && duty < PROBE_DUTY {
            (duty + PROBE_TICK_DUTY) as f64
        } else {
            duty as f64
        }
    }

    /// The controller's outputs at `now_ms`: the output stage holds them only while they are
    /// refreshed (the core's command watchdog, as a board's PWM stage would apply it), the
    /// cut-off's too (a stalled controller leaves the supply cut).
    pub fn drive(&mut self, now_ms: u64, out: Outputs) {
        self.output[0].refresh(now_ms, out.pla_duty);
        self.output[1].refresh(now_ms, out.tca_duty);
        self.output[2].refresh(now_ms, if out.supply_on { 1.0 } else { 0.0 });
    }

    /// The outputs the output stage applies at `now_ms`.
    pub fn applied(&self, now_ms: u64) -> Outputs {
        Outputs {
            pla_duty: self.output[0].duty(now_ms),
            tca_duty: self.output[1].duty(now_ms),
            supply_on: self.output[2].duty(now_ms) > 0.5,
        }
    }

    /// Both outputs off and the supply cut at once, whatever was commanded (the firmware's
    /// panic path: the gate and cut-off pins driven low).
    pub fn heaters_off(&mut self) {
        self.output = [CommandWatchdog::default(); 3];
    }

    /// Lets the plant run `dt_s` from `now_ms` with the duties the output stage applies then.
    pub fn run(&mut self, now_ms: u64, dt_s: f64) {
        let duty = self.reaching(now_ms);
        self.plant.step(dt_s, duty);
    }

    /// The duties that reach the heaters at `now_ms`: the output stage's, with the cut-off,
    /// an open or stuck heater and the probe pulse of current sense.
    pub fn reaching(&self, now_ms: u64) -> Duties {
        let out = self.applied(now_ms);
        let (supplied, sensing) = (self.supplied(now_ms), self.senses_current());
        Duties {
            pla: self.delivered(0, out.pla_duty, supplied, sensing),
            tca: self.delivered(1, out.tca_duty, supplied, sensing),
        }
    }

    /// Lets the plant run `dt_s` with `duty` (a shared supply's rig works out what reaches
    /// each heater over the period itself: [`Bench::reaching`] at the sagging voltage).
    pub fn run_duties(&mut self, dt_s: f64, duty: Duties) {
        self.plant.step(dt_s, duty);
    }

    /// The supply the board reads at its terminals from now on, V (`None`: the plant's own):
    /// a shared supply sagging under several links' load.
    pub fn set_terminal_v(&mut self, v: Option<f64>) {
        self.terminal_v = v;
    }

    /// The supply inside each heater's pulse where the board samples its on-current (PLA,
    /// TCA), V: on a shared supply other heaters' pulses, or its constant-current mode, may
    /// pull it under the period's mean. `None`: the terminal voltage.
    pub fn set_pulse_v(&mut self, v: Option<[f64; 2]>) {
        self.pulse_v = v;
    }

    /// The supply at the board's terminals, V.
    fn supply_at_terminals(&self, s: &morphlink_plant::Sample) -> f64 {
        self.terminal_v.unwrap_or(s.supply_v)
    }

    /// One heater's current reading through its shunt amplifier, summed counts: `amps` with
    /// the chain's gain error, offset and noise, in the ADC's 12-bit steps.
    fn sensed_counts(&mut self, i: usize, amps: f64) -> u32 {
        let noise = gaussian(&mut self.current_rng) as f32 * SENSE_NOISE_A;
        let a = amps as f32 * (1.0 + SENSE_GAIN_ERROR[i]) + SENSE_OFFSET_A + noise;
        let one = crate::electrical::ShuntSense {
            full_scale_counts: 4095,
            ..self.board.shunt
        };
        one.counts(a) * crate::controller::OVERSAMPLE
    }

    /// The currents the board samples at `sample_ms`, if it senses them: inside the pulse (or
    /// the probe pulse) and inside the off-time, of the heaters' true resistances now.
    fn currents(&mut self, sample_ms: u64, s: &morphlink_plant::Sample) -> Option<CurrentCounts> {
        let ohm = s.heater_ohm.filter(|_| self.current_sense)?;
        let v = if self.supplied(sample_ms) {
            self.supply_at_terminals(s)
        } else {
            0.0
        };
        let mut c = CurrentCounts::default();
        for i in 0..2 {
            let on_v = if v > 0.0 {
                self.pulse_v.map_or(v, |p| p[i])
            } else {
                0.0
            };
            let amps = if self.heater_open[i] {
                0.0
            } else {
                on_v / ohm[i]
            };
            c.on[i] = self.sensed_counts(i, amps);
            let stuck = if self.heater_stuck[i] && !self.heater_open[i] {
                v / ohm[i]
            } else {
                0.0
            };
            c.off[i] = self.sensed_counts(i, stuck);
        }
        Some(c)
    }

    /// Approximately normal noise with the bench's standard deviation.
    fn noise_c(&mut self) -> f64 {
        gaussian(&mut self.rng) * self.noise.sensor_noise_c
    }

    /// The ADC frame the controller would read now (summed counts), stamped `sample_ms`.
    pub fn inputs(&mut self, sample_ms: u64) -> Inputs {
        let s = self.plant.sample();
        let mut i = self.thermistor_inputs_of(sample_ms, &s);
        i.current = self.currents(sample_ms, &s);
        i
    }

    /// [`Bench::inputs`] without the currents: a reading of the thermistors and the supply only
    /// (the emulated board reads these sixteen times a tick and its currents once).
    pub fn thermistor_inputs(&mut self, sample_ms: u64) -> Inputs {
        let s = self.plant.sample();
        self.thermistor_inputs_of(sample_ms, &s)
    }

    /// The thermistors and the supply of the plant's sample `s`.
    fn thermistor_inputs_of(&mut self, sample_ms: u64, s: &morphlink_plant::Sample) -> Inputs {
        let beads = [s.t_pla_c, s.t_tca_c, s.t_amb_c];
        let mut counts = [0u32; 3];
        for (i, c) in counts.iter_mut().enumerate() {
            let mut t = beads[i] + self.noise_c();
            if let Some((rate_k_per_s, since)) = &mut self.drift[i] {
                let since_ms = *since.get_or_insert(sample_ms);
                t += *rate_k_per_s as f64 * sample_ms.saturating_sub(since_ms) as f64 / 1000.0;
            }
            let live = self.board.thermistor.counts_for_temp(t as f32);
            *c = match self.thermistor_fault[i] {
                Some(SimFault::ThermistorOpen) => self.board.thermistor.adc_full_scale,
                Some(SimFault::ThermistorShort) => 0,
                Some(SimFault::ThermistorStuck) => *self.stuck_counts[i].get_or_insert(live),
                _ => live,
            };
        }
        Inputs {
            thermistor_counts: counts,
            supply_counts: self.board.supply.counts(self.supply_at_terminals(s) as f32),
            sample_ms,
            current: None,
        }
    }

    /// The currents the board samples at `sample_ms`, if it senses them ([`Bench::inputs`]).
    pub fn current_counts(&mut self, sample_ms: u64) -> Option<CurrentCounts> {
        let s = self.plant.sample();
        self.currents(sample_ms, &s)
    }

    /// Injects a fault on the sensor with [`crate::vocab::Sensor::index`] `index`, or on the heater of that
    /// index (an ambient target counts as the TCA heater).
    pub fn inject(&mut self, fault: SimFault, index: usize) {
        match fault {
            SimFault::ThermistorOpen | SimFault::ThermistorShort | SimFault::ThermistorStuck => {
                self.thermistor_fault[index.min(2)] = Some(fault);
                self.stuck_counts[index.min(2)] = None;
            }
            SimFault::HeaterOpen => self.heater_open[index.min(1)] = true,
            SimFault::HeaterStuck => self.heater_stuck[index.min(1)] = true,
            SimFault::CutoffStuck => self.cutoff_stuck = true,
            // A drift without a rate is no drift: see [`Bench::inject_drift`].
            SimFault::ThermistorDrift => {}
        }
    }

    /// Makes the sensor of [`crate::vocab::Sensor::index`] `index` drift from the truth by
    /// `rate_k_per_s` (negative: reads low) from its next frame on.
    pub fn inject_drift(&mut self, index: usize, rate_k_per_s: f32) {
        self.drift[index.min(2)] = Some((rate_k_per_s, None));
    }

    /// Removes the faults and the drift injected on the sensor of
    /// [`crate::vocab::Sensor::index`] `index` alone.
    pub fn clear_sensor(&mut self, index: usize) {
        let i = index.min(2);
        self.thermistor_fault[i] = None;
        self.stuck_counts[i] = None;
        self.drift[i] = None;
    }

    /// Removes every injected fault.
    pub fn clear_faults(&mut self) {
        self.thermistor_fault = [None; 3];
        self.stuck_counts = [None; 3];
        self.drift = [None; 3];
        self.heater_open = [false; 2];
        self.heater_stuck = [false; 2];
        self.cutoff_stuck = false;
    }

    /// Sets the true supply voltage, V; the plant may refuse.
    pub fn set_supply_v(&mut self, v: f64) -> Result<(), SetError> {
        self.plant.set(Setting::SupplyV(v))
    }

    /// Sets the medium's temperature, °C; the plant may refuse.
    pub fn set_ambient_c(&mut self, c: f64) -> Result<(), SetError> {
        self.plant.set(Setting::AmbientC(c))
    }

    /// Sets the medium (its convection coefficient); the plant may refuse.
    pub fn set_medium(&mut self, m: Medium) -> Result<(), SetError> {
        self.plant.set(Setting::Medium(match m {
            Medium::Water => morphlink_plant::Medium::Water,
            Medium::Air => morphlink_plant::Medium::Air,
        }))
    }

    /// Carries out a `SIM` command and writes its one reply line through `out`.
    ///
    /// `SIM STATE` reports the plant's [`Plant::truth`] time and temperatures and its radius;
    /// a remote plant's truth is what the plant protocol gives (bead temperatures). A setting
    /// the plant refuses answers `error: unsupported SIM <WORD> ...`. `SIM WAIT` needs a rig
    /// that owns the clock (`morphlink-sim`'s `Rig` answers it before it gets here); here,
    /// as in the emulated image, it is `error: unsupported`.
    pub fn command(&mut self, cmd: SimCommand, out: &mut impl FnMut(&str)) {
        let mut l = OutLine::new();
        match cmd {
            SimCommand::State => {
                let t = self.plant.truth();
                let radius_mm = self.radius_mm() as f32;
                reply::sim_state(
                    &mut l,
                    t.time_s as f32,
                    radius_mm,
                    t.pla_c as f32,
                    t.tca_c as f32,
                );
            }
            SimCommand::Fault(kind, target) => {
                self.inject(kind, target.index());
                reply::sim_fault(&mut l, kind, target);
            }
            SimCommand::Drift(target, rate_k_per_s) => {
                if !(-SIM_DRIFT_MAX_K_PER_S..=SIM_DRIFT_MAX_K_PER_S).contains(&rate_k_per_s) {
                    reply::sim_drift_out_of_range(&mut l, SIM_DRIFT_MAX_K_PER_S);
                } else {
                    self.inject_drift(target.index(), rate_k_per_s);
                    reply::sim_fault_drift(&mut l, target, rate_k_per_s);
                }
            }
            SimCommand::Supply(v) => {
                if !(0.0..=SIM_SUPPLY_MAX_V).contains(&v) {
                    reply::sim_supply_out_of_range(&mut l, SIM_SUPPLY_MAX_V);
                } else {
                    match self.set_supply_v(v as f64) {
                        Ok(()) => reply::sim_supply(&mut l, v),
                        Err(SetError::Unsupported) => {
                            reply::sim_setting_unsupported(&mut l, SimSetting::Supply)
                        }
                    }
                }
            }
            SimCommand::Ambient(c) => {
                let (lo, hi) = SIM_AMBIENT_RANGE_C;
                if !(lo..=hi).contains(&c) {
                    reply::sim_ambient_out_of_range(&mut l, lo, hi);
                } else {
                    match self.set_ambient_c(c as f64) {
                        Ok(()) => reply::sim_ambient(&mut l, c),
                        Err(SetError::Unsupported) => {
                            reply::sim_setting_unsupported(&mut l, SimSetting::Ambient)
                        }
                    }
                }
            }
            SimCommand::Medium(m) => match self.set_medium(m) {
                Ok(()) => reply::sim_medium(&mut l, m),
                Err(SetError::Unsupported) => {
                    reply::sim_setting_unsupported(&mut l, SimSetting::Medium)
                }
            },
            SimCommand::Panic => {
                l = format_error(&reply::ERR_SIM_PANIC_UNSUPPORTED);
            }
            SimCommand::Stall => {
                l = format_error(&reply::ERR_SIM_STALL_UNSUPPORTED);
            }
            SimCommand::Wait(_) => {
                l = format_error(&reply::ERR_SIM_WAIT_UNSUPPORTED);
            }
            SimCommand::Clear => {
                self.clear_faults();
                reply::ok(&mut l);
            }
        }
        out(&l);
    }
}
