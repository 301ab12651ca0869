//! The lumped plant: the five-node thermal network, quasi-static mechanics with a PLA that is
//! soft above Tg and freezes the curvature it cools at, spring-back on release, thermistor
//! beads that lag their node by a first-order time constant, and duty → watts from the true
//! supply and heater resistances.
//!
//! It is built from the same equations as the controller's model (`morphlink-model`), with
//! other parameters: fast, and the right plant for tests of logic, but a controller measured
//! on it measures its own model. `no_std` and allocation-free.

use crate::{Duties, Medium, Plant, Sample, SetError, Setting, Truth};
use morphlink_model::mechanics::{
    curvature_with_extra_per_m, pla_extra_stiffness_nm2, pla_flow_time_s,
};
use morphlink_model::params::{H_AIR_W_M2K, H_WATER_W_M2K};
use morphlink_model::thermal::{lag_remaining, node, Network};
use morphlink_model::LinkParams;

/// A lumped link's true values, where they may differ from what the controller assumes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LumpedSpec {
    /// The link's true physical parameters (h, ambient, fitted constants...).
    pub params: LinkParams,
    /// True heater resistances at [`HEATER_REF_C`], Ω: PLA wrap, TCA.
    pub heater_ohm: [f64; 2],
    /// Temperature coefficients of the heaters' resistances, 1/K (PLA wrap, TCA): each heater's
    /// resistance follows its own node's temperature, and its power with it.
    pub heater_tcr_per_k: [f64; 2],
    /// True heater supply, V.
    pub supply_v: f64,
    /// Thermistor time constants (PLA, TCA, ambient), s. Datasheets give 6.5–12 s in still air
    /// for a bare bead; embedded in silicone against the heater it is faster: 3 s.
    pub sensor_tau_s: [f64; 3],
}

/// Temperature at which [`LumpedSpec::heater_ohm`] holds, °C.
pub const HEATER_REF_C: f64 = 22.0;

/// The heaters' nominal temperature coefficients, 1/K: the nichrome wrap's (Ni80Cr20, about
/// 1e-4/K) and the silver-coated TCA's (1.5e-3/K, an estimate: docs/plant.md). The lumped
/// TCA has no strain term: its resistance follows its temperature only.
pub const HEATER_TCR_NOMINAL_PER_K: [f64; 2] = [1.0e-4, 1.5e-3];

/// The lumped link's state.
#[derive(Clone, Debug)]
pub struct Lumped {
    spec: LumpedSpec,
    net: Network,
    kappa_per_m: f64,
    kappa_ref_per_m: f64,
    sensed_c: [f64; 3],
    powers_w: [f64; 2],
    time_s: f64,
}

impl Lumped {
    /// A link at rest at ambient temperature, holding the curvature it relaxes to with the TCA
    /// cold (its pre-bend).
    pub fn new(spec: LumpedSpec) -> Self {
        let p = &spec.params;
        let amb = p.surroundings.ambient_c;
        let rest = curvature_with_extra_per_m(p, amb, 0.0, 0.0);
        Lumped {
            spec,
            net: Network::new(p),
            kappa_per_m: rest,
            kappa_ref_per_m: rest,
            sensed_c: [amb; 3],
            powers_w: [0.0; 2],
            time_s: 0.0,
        }
    }

    /// The link's true values.
    pub fn spec(&self) -> &LumpedSpec {
        &self.spec
    }

    fn heater_power_w(&self, ohm: f64, duty: f64) -> f64 {
        let v = self.spec.supply_v;
        duty.clamp(0.0, 1.0) * v * v / ohm
    }

    /// Each heater's resistance at its node's temperature now, Ω (PLA wrap, TCA).
    pub fn heater_ohm_now(&self) -> [f64; 2] {
        let t = [self.net.temp_c[node::PLA], self.net.temp_c[node::TCA]];
        core::array::from_fn(|i| {
            let r = self.spec.heater_ohm[i];
            (r * (1.0 + self.spec.heater_tcr_per_k[i] * (t[i] - HEATER_REF_C))).max(1e-3 * r)
        })
    }
}

impl Plant for Lumped {
    fn step(&mut self, dt_s: f64, duty: Duties) {
        let [r_pla, r_tca] = self.heater_ohm_now();
        let p_pla = self.heater_power_w(r_pla, duty.pla);
        let p_tca = self.heater_power_w(r_tca, duty.tca);
        self.powers_w = [p_pla, p_tca];
        let amb = self.spec.params.surroundings.ambient_c;
        self.net.advance(dt_s, p_tca, p_pla, amb);
        let (t_pla, t_tca) = (self.net.temp_c[node::PLA], self.net.temp_c[node::TCA]);
        let params = &self.spec.params;
        let extra = pla_extra_stiffness_nm2(params, t_pla);
        self.kappa_per_m = curvature_with_extra_per_m(params, t_tca, extra, self.kappa_ref_per_m);
        let keep = lag_remaining(dt_s, pla_flow_time_s(&params.pla_stiffness, t_pla));
        self.kappa_ref_per_m = self.kappa_per_m + (self.kappa_ref_per_m - self.kappa_per_m) * keep;
        let nodes = [t_pla, t_tca, amb];
        for ((sensed, node), tau_s) in self
            .sensed_c
            .iter_mut()
            .zip(nodes)
            .zip(self.spec.sensor_tau_s)
        {
            *sensed = node + (*sensed - node) * lag_remaining(dt_s, tau_s);
        }
        self.time_s += dt_s;
    }

    fn sample(&self) -> Sample {
        let [t_pla_c, t_tca_c, t_amb_c] = self.sensed_c;
        Sample {
            t_pla_c,
            t_tca_c,
            t_amb_c,
            supply_v: self.spec.supply_v,
            radius_mm: 1e3 / self.kappa_per_m,
            heater_ohm: Some(self.heater_ohm_now()),
        }
    }

    fn truth(&self) -> Truth {
        Truth {
            time_s: self.time_s,
            pla_c: self.net.temp_c[node::PLA],
            tca_c: self.net.temp_c[node::TCA],
            pla_w: self.powers_w[0],
            tca_w: self.powers_w[1],
        }
    }

    fn set(&mut self, setting: Setting) -> Result<(), SetError> {
        match setting {
            Setting::SupplyV(v) => self.spec.supply_v = v,
            Setting::AmbientC(c) => self.spec.params.surroundings.ambient_c = c,
            Setting::Medium(m) => {
                self.spec.params.surroundings.h_w_m2k = match m {
                    Medium::Water => H_WATER_W_M2K,
                    Medium::Air => H_AIR_W_M2K,
                };
                self.net.set_params(&self.spec.params);
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec() -> LumpedSpec {
        LumpedSpec {
            params: morphlink_model::LinkParams::DEFAULT,
            heater_ohm: [30.0, 6.5],
            heater_tcr_per_k: [0.0; 2],
            supply_v: 12.0,
            sensor_tau_s: [3.0; 3],
        }
    }

    #[test]
    fn at_rest_the_beads_read_ambient_and_nothing_heats() {
        let mut l = Lumped::new(spec());
        l.step(10.0, Duties::default());
        let s = l.sample();
        let amb = spec().params.surroundings.ambient_c;
        assert!((s.t_pla_c - amb).abs() < 1e-9 && (s.t_tca_c - amb).abs() < 1e-9);
        assert_eq!(l.truth().pla_w, 0.0);
    }

    #[test]
    fn heating_the_tca_bends_the_link_tighter() {
        let mut l = Lumped::new(spec());
        let r0 = l.sample().radius_mm;
        for _ in 0..300 {
            l.step(
                0.1,
                Duties {
                    pla: 0.4,
                    tca: 0.05,
                },
            );
        }
        let s = l.sample();
        assert!(s.t_tca_c > spec().params.surroundings.ambient_c + 5.0);
        assert!(s.radius_mm < r0, "{} !< {r0}", s.radius_mm);
        // Power is duty × V² / R.
        let t = l.truth();
        assert!((t.pla_w - 0.4 * 144.0 / 30.0).abs() < 1e-9);
    }
}
