//! The simulated link: the transient thermal network, quasi-static mechanics with a PLA that is
//! soft above Tg and freezes the curvature it cools at, spring-back on release, thermistors
//! with lag and noise read through the ADC model, and PWM duty → watts from the true supply
//! and heater resistances. `no_std` and allocation-free.

use morphlink::controller::{Config, Inputs, Outputs};
use morphlink::protocol::{format_error, reply, Medium, OutLine, Sensor, SimCommand, SimFault};
use morphlink_model::mechanics::{
    curvature_with_extra_per_m, pla_extra_stiffness_nm2, pla_flow_time_s,
};
use morphlink_model::params::{H_AIR_W_M2K, H_WATER_W_M2K};
use morphlink_model::thermal::{lag_remaining, node, Network};
use morphlink_model::LinkParams;

/// Highest supply `SIM SUPPLY` accepts, V (the supervisor's limit is lower, so faults can be tried).
pub const SIM_SUPPLY_MAX_V: f32 = 30.0;
/// Range `SIM AMBIENT` accepts, °C.
pub const SIM_AMBIENT_RANGE_C: (f32, f32) = (-10.0, 60.0);

/// What differs between the real (simulated) link and what the controller assumes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plant {
    /// The link's true physical parameters (h, ambient, fitted constants...).
    pub params: LinkParams,
    /// True heater resistances, Ω: PLA wrap, TCA.
    pub heater_ohm: [f64; 2],
    /// True heater supply, V.
    pub supply_v: f64,
    /// Thermistor time constants (PLA, TCA, ambient), s. Datasheets give 6.5–12 s in still air
    /// for a bare bead; embedded in silicone against the heater it is faster: 3 s.
    pub sensor_tau_s: [f64; 3],
    /// Standard deviation of thermistor noise, °C.
    pub sensor_noise_c: f64,
    /// Seed of the noise generator.
    pub seed: u64,
}

impl Plant {
    /// The nominal link: the built-in parameters, nominal heaters and supply, 3 s sensor lag
    /// and 0.05 °C noise.
    pub const NOMINAL: Plant = Plant {
        params: morphlink::link::LINK,
        heater_ohm: [30.0, 6.5],
        supply_v: 12.0,
        sensor_tau_s: [3.0, 3.0, 3.0],
        sensor_noise_c: 0.05,
        seed: 0x5eed_1234,
    };
}

/// The simulated link's state.
#[derive(Clone, Debug)]
pub struct SimLink {
    plant: Plant,
    board: Config,
    net: Network,
    kappa_per_m: f64,
    kappa_ref_per_m: f64,
    sensed_c: [f64; 3],
    thermistor_fault: [Option<SimFault>; 3],
    heater_open: [bool; 2],
    heater_stuck: [bool; 2],
    powers_w: [f64; 2],
    rng: u64,
    time_s: f64,
}

impl SimLink {
    /// A link at rest at ambient temperature, holding the curvature it relaxes to with the TCA
    /// cold (its pre-bend), read through `board`'s ADC model.
    pub fn new(plant: Plant, board: Config) -> Self {
        let p = &plant.params;
        let amb = p.surroundings.ambient_c;
        let rest = curvature_with_extra_per_m(p, amb, 0.0, 0.0);
        SimLink {
            plant,
            board,
            net: Network::new(p),
            kappa_per_m: rest,
            kappa_ref_per_m: rest,
            sensed_c: [amb; 3],
            thermistor_fault: [None; 3],
            heater_open: [false; 2],
            heater_stuck: [false; 2],
            powers_w: [0.0; 2],
            rng: plant.seed | 1,
            time_s: 0.0,
        }
    }

    /// Simulated time, s.
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// True bending radius, mm.
    pub fn radius_mm(&self) -> f64 {
        1e3 / self.kappa_per_m
    }

    /// True PLA and TCA temperatures, °C.
    pub fn temps_c(&self) -> (f64, f64) {
        (self.net.temp_c[node::PLA], self.net.temp_c[node::TCA])
    }

    /// Temperatures the PLA, TCA and ambient thermistor beads are at (lagged, before noise), °C.
    pub fn sensed_c(&self) -> [f64; 3] {
        self.sensed_c
    }

    /// Heater powers actually dissipated in the last step, W (PLA, TCA).
    pub fn powers_w(&self) -> [f64; 2] {
        self.powers_w
    }

    /// Ambient temperature, °C.
    pub fn ambient_c(&self) -> f64 {
        self.plant.params.surroundings.ambient_c
    }

    /// The plant (true parameters).
    pub fn plant(&self) -> &Plant {
        &self.plant
    }

    fn heater_power_w(&self, i: usize, duty: f32) -> f64 {
        if self.heater_open[i] {
            return 0.0;
        }
        let d = if self.heater_stuck[i] {
            1.0
        } else {
            (duty as f64).clamp(0.0, 1.0)
        };
        let v = self.plant.supply_v;
        d * v * v / self.plant.heater_ohm[i]
    }

    /// Advances the link by `dt_s` with PWM duties `out` held constant.
    pub fn advance(&mut self, dt_s: f64, out: Outputs) {
        let p_pla = self.heater_power_w(0, out.pla_duty);
        let p_tca = self.heater_power_w(1, out.tca_duty);
        self.powers_w = [p_pla, p_tca];
        let amb = self.ambient_c();
        self.net.advance(dt_s, p_tca, p_pla, amb);
        let (t_pla, t_tca) = self.temps_c();
        let params = &self.plant.params;
        let extra = pla_extra_stiffness_nm2(params, t_pla);
        self.kappa_per_m = curvature_with_extra_per_m(params, t_tca, extra, self.kappa_ref_per_m);
        let keep = lag_remaining(dt_s, pla_flow_time_s(&params.pla_stiffness, t_pla));
        self.kappa_ref_per_m = self.kappa_per_m + (self.kappa_ref_per_m - self.kappa_per_m) * keep;
        let nodes = [t_pla, t_tca, amb];
        for ((sensed, node), tau_s) in self
            .sensed_c
            .iter_mut()
            .zip(nodes)
            .zip(self.plant.sensor_tau_s)
        {
            *sensed = node + (*sensed - node) * lag_remaining(dt_s, tau_s);
        }
        self.time_s += dt_s;
    }

    /// Approximately normal noise with the plant's standard deviation (sum of four uniforms).
    fn noise_c(&mut self) -> f64 {
        let mut s = 0.0;
        for _ in 0..4 {
            self.rng ^= self.rng << 13;
            self.rng ^= self.rng >> 7;
            self.rng ^= self.rng << 17;
            s += (self.rng >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
        }
        // Four uniforms on [-0.5, 0.5] have variance 1/3.
        s * libm::sqrt(3.0) * self.plant.sensor_noise_c
    }

    /// The ADC frame the controller would read now (summed counts).
    pub fn inputs(&mut self, sample_ms: u64) -> Inputs {
        let mut counts = [0u32; 3];
        for (i, c) in counts.iter_mut().enumerate() {
            let t = self.sensed_c[i] + self.noise_c();
            *c = match self.thermistor_fault[i] {
                Some(SimFault::ThermistorOpen) => self.board.thermistor.adc_full_scale,
                Some(SimFault::ThermistorShort) => 0,
                _ => self.board.thermistor.counts_for_temp(t as f32),
            };
        }
        Inputs {
            thermistor_counts: counts,
            supply_counts: self.board.supply.counts(self.plant.supply_v as f32),
            sample_ms,
        }
    }

    /// Injects a fault on a sensor (0 PLA, 1 TCA, 2 ambient) or a heater (0 PLA, 1 TCA).
    pub fn inject(&mut self, fault: SimFault, index: usize) {
        match fault {
            SimFault::ThermistorOpen | SimFault::ThermistorShort => {
                self.thermistor_fault[index.min(2)] = Some(fault)
            }
            SimFault::HeaterOpen => self.heater_open[index.min(1)] = true,
            SimFault::HeaterStuck => self.heater_stuck[index.min(1)] = true,
        }
    }

    /// Removes every injected fault.
    pub fn clear_faults(&mut self) {
        self.thermistor_fault = [None; 3];
        self.heater_open = [false; 2];
        self.heater_stuck = [false; 2];
    }

    /// Sets the true supply voltage, V.
    pub fn set_supply_v(&mut self, v: f64) {
        self.plant.supply_v = v;
    }

    /// Sets the medium's temperature, °C.
    pub fn set_ambient_c(&mut self, c: f64) {
        self.plant.params.surroundings.ambient_c = c;
    }

    /// Sets the medium (its convection coefficient).
    pub fn set_medium(&mut self, m: Medium) {
        self.plant.params.surroundings.h_w_m2k = match m {
            Medium::Water => H_WATER_W_M2K,
            Medium::Air => H_AIR_W_M2K,
        };
        self.net.set_params(&self.plant.params);
    }

    /// Carries out a `SIM` command and writes its one reply line through `out`.
    pub fn command(&mut self, cmd: SimCommand, out: &mut impl FnMut(&str)) {
        let mut l = OutLine::new();
        match cmd {
            SimCommand::State => {
                let (pla, tca) = self.temps_c();
                let (time_s, radius_mm) = (self.time_s() as f32, self.radius_mm() as f32);
                reply::sim_state(&mut l, time_s, radius_mm, pla as f32, tca as f32);
            }
            SimCommand::Fault(kind, target) => {
                let index = match target {
                    Sensor::Pla => 0,
                    Sensor::Tca => 1,
                    Sensor::Amb => 2,
                };
                self.inject(kind, index);
                reply::sim_fault(&mut l, kind, target);
            }
            SimCommand::Supply(v) => {
                if !(0.0..=SIM_SUPPLY_MAX_V).contains(&v) {
                    reply::sim_supply_out_of_range(&mut l, SIM_SUPPLY_MAX_V);
                } else {
                    self.set_supply_v(v as f64);
                    reply::sim_supply(&mut l, v);
                }
            }
            SimCommand::Ambient(c) => {
                let (lo, hi) = SIM_AMBIENT_RANGE_C;
                if !(lo..=hi).contains(&c) {
                    reply::sim_ambient_out_of_range(&mut l, lo, hi);
                } else {
                    self.set_ambient_c(c as f64);
                    reply::sim_ambient(&mut l, c);
                }
            }
            SimCommand::Medium(m) => {
                self.set_medium(m);
                reply::sim_medium(&mut l, m);
            }
            SimCommand::Panic => {
                l = format_error(&reply::ERR_SIM_PANIC_UNSUPPORTED);
            }
            SimCommand::Clear => {
                self.clear_faults();
                reply::ok(&mut l);
            }
        }
        out(&l);
    }
}
