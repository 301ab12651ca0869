//! The controller's own copy of the link's thermal model, run alongside the real link.
//!
//! Two uses: as a **feed-forward** predictor (the `boost` strategy drives the model, not the
//! thermistors, to the target temperatures), and as an **observer** (the `closed` strategy
//! corrects the model's temperatures with what the lagging thermistors read). The model is the
//! five-node network of `morphlink_model::thermal` built from the link's built-in parameters,
//! run in `f32` ([`crate::lumped`]); the surroundings are the measured ambient temperature.
//!
//! Observer: each heated node `i` has a modelled thermistor (first-order lag of
//! [`SENSOR_TAU_S`]) and an output disturbance `d_i` that follows
//! `measured − modelled thermistor` with time constant [`DISTURBANCE_TAU_S`]. The estimate of the
//! true temperature is `node_i + d_i`: the model supplies the fast dynamics the thermistor
//! cannot see, the measurement removes the model's steady error (unknown convection, heater
//! resistance, ambient).

use crate::link::LINK;
use crate::lumped::{lag_remaining, node, Network};

/// Thermistor time constant the observer assumes, s: the bead is embedded in silicone against
/// the heater (3 s; the same value the simulated link uses for its nominal sensors).
pub const SENSOR_TAU_S: f32 = 3.0;
const _: () = assert!(SENSOR_TAU_S == crate::tune::SENSOR_TAU_S);
/// Time constant of the disturbance estimate, s. Shorter follows model errors faster but passes
/// more thermistor noise into the heater power; 2 s is below the 3 s sensor lag, so a steady
/// model error is removed within a few seconds, and averages the 0.05 °C noise over 20 ticks.
pub const DISTURBANCE_TAU_S: f32 = 2.0;
/// The disturbance estimate only learns while the thermistor changes slower than this, K/s.
/// While it moves fast, `measured − modelled thermistor` is mostly the error of the assumed
/// lag (a 5 s bead read as a 3 s one is 2 s × the rate off), not a model error; frozen, the
/// estimate is the feed-forward's. 0.3 K/s times the 3 s spread of real lags is under 1 K.
pub const LEARN_MAX_RATE_K_PER_S: f32 = 0.6;
/// Time constants of the two smoothings whose difference gives the thermistor's rate, s: the
/// difference of a 0.5 s and a 1.5 s exponential average is the rate delayed by about 1 s,
/// with the 0.05–0.2 °C noise of single readings averaged down to under 0.05 K/s.
pub const RATE_FILTER_S: (f32, f32) = (0.5, 1.5);

/// Time over which the heater power brings a node to its target temperature, s. The TCA's own
/// time constant is about 1 s: 1 s asks for a fast approach without a power spike the PWM cannot
/// deliver anyway (the heater caps clip it).
pub const APPROACH_S: f32 = 1.0;

/// The two heated nodes: the PLA rod (heated by the nichrome wrap) and the TCA (Joule heated),
/// named by their heater; [`Heater::index`] indexes the observer's per-node arrays.
pub use crate::vocab::Heater as HeatedNode;
use crate::vocab::Heater;

/// A heated node's place in the network: (node, its shell, conductance index node→shell).
fn model_nodes(n: HeatedNode) -> (usize, usize, usize) {
    match n {
        Heater::Pla => (node::PLA, node::PLA_SHELL, 2),
        Heater::Tca => (node::TCA, node::TCA_SHELL, 0),
    }
}

/// The model plus the observer's state.
#[derive(Clone, Copy, Debug)]
pub struct Observer {
    net: Network,
    sensor_c: [f32; 2],
    disturbance_k: [f32; 2],
    ambient_c: f32,
    smooth_c: [[f32; 2]; 2],
    /// Share of its node's rise above the surroundings each thermistor reads (PLA, TCA): the
    /// link's calibration ([`crate::calibration::Calibration::sensor_gain`]), 1 by default.
    sensor_gain: [f32; 2],
    /// Share of the other heater's part of its node's rise each thermistor reads (PLA, TCA):
    /// [`crate::calibration::Calibration::cross_gain`]; a bead beside one heater sees the
    /// other's heat at another share than its own heater's.
    cross_gain: [f32; 2],
    /// The same network driven by each heater alone (PLA, TCA), from the surroundings: the
    /// other heater's part of each node's rise.
    alone: [Network; 2],
}

impl Observer {
    /// A placeholder model with no heat flow, held by an idle sequencer until a morph starts one
    /// with [`Observer::from_measured`].
    pub const IDLE: Observer = Observer {
        net: Network {
            capacity_j_k: [1.0; node::COUNT],
            conductance_w_k: [0.0; 5],
            temp_c: [0.0; node::COUNT],
        },
        sensor_c: [0.0; 2],
        disturbance_k: [0.0; 2],
        ambient_c: 0.0,
        smooth_c: [[f32::NAN; 2]; 2],
        sensor_gain: [1.0; 2],
        cross_gain: [1.0; 2],
        alone: [Network {
            capacity_j_k: [1.0; node::COUNT],
            conductance_w_k: [0.0; 5],
            temp_c: [0.0; node::COUNT],
        }; 2],
    };

    /// A model at rest at `ambient_c` (°C) with the built-in link parameters.
    pub fn new(ambient_c: f32) -> Self {
        Self::with_convection(ambient_c, LINK.surroundings.h_w_m2k as f32)
    }

    /// As [`Observer::new`], at rim convection `h_w_m2k`, W/(m² K) (the calibration's
    /// [`crate::calibration::Calibration::model_convection_w_m2k`]: in still air the model
    /// rises about five times as far per watt as under water, and over minutes rather than
    /// seconds).
    pub fn with_convection(ambient_c: f32, h_w_m2k: f32) -> Self {
        let net = Network::new(h_w_m2k, ambient_c);
        Observer {
            net,
            sensor_c: [ambient_c; 2],
            disturbance_k: [0.0; 2],
            ambient_c,
            smooth_c: [[f32::NAN; 2]; 2],
            sensor_gain: [1.0; 2],
            cross_gain: [1.0; 2],
            alone: [net; 2],
        }
    }

    /// A model that starts from measured temperatures (°C): every node of the PLA's side at
    /// `t_pla_c`, the TCA's side at `t_tca_c`, the bulk at their mean. Used at MORPH, when the
    /// link may still be warm from a previous morph.
    pub fn from_measured(t_pla_c: f32, t_tca_c: f32, t_amb_c: f32) -> Self {
        Self::from_measured_with_gains(
            t_pla_c,
            t_tca_c,
            t_amb_c,
            [1.0, 1.0],
            [1.0, 1.0],
            LINK.surroundings.h_w_m2k as f32,
        )
    }

    /// As [`Observer::from_measured`], for thermistors that read `gains` (PLA, TCA) of their
    /// own heater's part of their node's rise above the surroundings and `cross` of the other
    /// heater's, with the model at rim convection `h_w_m2k` ([`Observer::with_convection`]):
    /// the nodes start at the rise the readings imply.
    pub fn from_measured_with_gains(
        t_pla_c: f32,
        t_tca_c: f32,
        t_amb_c: f32,
        gains: [f32; 2],
        cross: [f32; 2],
        h_w_m2k: f32,
    ) -> Self {
        let mut o = Observer::with_convection(t_amb_c, h_w_m2k);
        let g = gains.map(|g| if g.is_finite() && g > 0.1 { g } else { 1.0 });
        o.sensor_gain = g;
        o.cross_gain = cross.map(|g| if g.is_finite() && g >= 0.0 { g } else { 1.0 });
        let amb = if t_amb_c.is_finite() {
            t_amb_c
        } else {
            o.ambient_c
        };
        let (sp, st) = (t_pla_c, t_tca_c);
        let (p, t) = (amb + (sp - amb) / g[0], amb + (st - amb) / g[1]);
        o.net.temp_c = [t, t, p, p, 0.5 * (p + t)];
        o.sensor_c = [sp, st];
        o
    }

    /// Advances the model by `dt_s` with the heater powers actually delivered (W) and the
    /// measured ambient (°C).
    pub fn predict(&mut self, dt_s: f32, pla_w: f32, tca_w: f32, ambient_c: f32) {
        if ambient_c.is_finite() {
            self.ambient_c = ambient_c;
        }
        let dt = dt_s;
        let (tca_w, pla_w) = (tca_w.max(0.0), pla_w.max(0.0));
        // One call site for the three networks: one copy of the step, not three inlined.
        let [pla_alone, tca_alone] = &mut self.alone;
        for (net, t_w, p_w) in [
            (&mut self.net, tca_w, pla_w),
            (pla_alone, 0.0, pla_w),
            (tca_alone, tca_w, 0.0),
        ] {
            net.advance(dt, t_w, p_w, self.ambient_c);
        }
        let keep = lag_remaining(dt, SENSOR_TAU_S);
        for n in [HeatedNode::Pla, HeatedNode::Tca] {
            let i = n.index();
            let at = model_nodes(n).0;
            let node = self.net.temp_c[at];
            let other = match n {
                Heater::Pla => Heater::Tca,
                Heater::Tca => Heater::Pla,
            };
            let cross_k = self.alone[other.index()].temp_c[at] - self.ambient_c;
            let t = self.ambient_c
                + self.sensor_gain[i] * (node - self.ambient_c)
                + (self.cross_gain[i] - self.sensor_gain[i]) * cross_k;
            self.sensor_c[i] = t + (self.sensor_c[i] - t) * keep;
        }
    }

    /// Corrects the disturbance estimates with the thermistor readings (°C) after `dt_s`.
    /// Non-finite readings are ignored (the supervisor deals with broken sensors).
    pub fn correct(&mut self, dt_s: f32, t_pla_c: f32, t_tca_c: f32) {
        let dt = dt_s;
        let gain = 1.0 - lag_remaining(dt, DISTURBANCE_TAU_S);
        for (i, m) in [t_pla_c, t_tca_c].into_iter().enumerate() {
            if m.is_finite() {
                let sm = &mut self.smooth_c[i];
                for (k, tau) in [RATE_FILTER_S.0, RATE_FILTER_S.1].into_iter().enumerate() {
                    if sm[k].is_nan() {
                        sm[k] = m;
                    }
                    sm[k] = m + (sm[k] - m) * lag_remaining(dt, tau);
                }
                if !(self.rate_k_per_s_of(i).abs() <= LEARN_MAX_RATE_K_PER_S) {
                    continue;
                }
                let err = m - self.sensor_c[i] - self.disturbance_k[i];
                self.disturbance_k[i] += gain * err;
            }
        }
    }

    fn rate_k_per_s_of(&self, i: usize) -> f32 {
        let sm = &self.smooth_c[i];
        (sm[0] - sm[1]) / (RATE_FILTER_S.1 - RATE_FILTER_S.0)
    }

    /// How far a heated node's thermistor (smoothed over [`RATE_FILTER_S`]`.0`) is from what
    /// the observer expects it to read, K (reading − modelled thermistor − disturbance): near 0
    /// while the model follows the link, large while it runs ahead or behind it.
    pub fn innovation_k(&self, n: HeatedNode) -> f32 {
        let i = n.index();
        let m = self.smooth_c[i][0];
        if m.is_nan() {
            return 0.0;
        }
        m - self.sensor_c[i] - self.disturbance_k[i]
    }

    /// How fast a heated node's thermistor is changing (smoothed), K/s.
    pub fn measured_rate_k_per_s(&self, n: HeatedNode) -> f32 {
        self.rate_k_per_s_of(n.index())
    }

    /// The model's temperature of a heated node, °C (feed-forward: no correction).
    pub fn model_c(&self, n: HeatedNode) -> f32 {
        self.net.temp_c[model_nodes(n).0]
    }

    /// The observer's estimate of a heated node's true temperature, °C.
    pub fn estimate_c(&self, n: HeatedNode) -> f32 {
        self.net.temp_c[model_nodes(n).0] + self.node_disturbance_k(n.index())
    }

    /// The disturbance learnt in the thermistor's space, taken to the node's (divided by the
    /// thermistor's gain), K.
    fn node_disturbance_k(&self, i: usize) -> f32 {
        self.disturbance_k[i] / self.sensor_gain[i]
    }

    /// Current disturbance estimate of a heated node, K (estimate − model).
    pub fn disturbance_k(&self, n: HeatedNode) -> f32 {
        self.node_disturbance_k(n.index())
    }

    /// Heater power, W, that brings the model's node `n` to `target_c` (°C) within about
    /// [`APPROACH_S`] and holds it there: the heat its shell takes at the target plus what
    /// raises the node's own capacity, clamped to `[0, max_w]`. Far below the target this is
    /// `max_w` (overdrive); at the target it is the steady power.
    pub fn power_to_reach_w(&self, n: HeatedNode, target_c: f32, max_w: f32) -> f32 {
        let (i, shell, g) = model_nodes(n);
        let t = self.net.temp_c[i];
        let tgt = target_c;
        let g = self.net.conductance_w_k[g];
        let c = self.net.capacity_j_k[i];
        let p = g * (tgt - self.net.temp_c[shell]) + c * (tgt - t) / APPROACH_S;
        if p.is_finite() {
            crate::mathf::clamp(p, 0.0, max_w.max(0.0))
        } else {
            0.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::link::R_TT_K_PER_W;

    #[test]
    fn holding_power_matches_the_steady_resistances() {
        let mut o = Observer::new(22.0);
        let target = 22.0 + 30.0;
        let mut p = 0.0;
        for _ in 0..3000 {
            p = o.power_to_reach_w(HeatedNode::Tca, target, 2.0);
            o.predict(0.1, 0.0, p, 22.0);
        }
        assert!((o.model_c(HeatedNode::Tca) - target).abs() < 0.05);
        // Steady: the whole network at the TCA's steady rise per watt.
        assert!((p - 30.0 / R_TT_K_PER_W).abs() < 0.01, "{p}");
    }

    #[test]
    fn overdrive_reaches_the_target_far_sooner_than_the_steady_power() {
        let target = 52.0;
        let steady_w = 30.0 / R_TT_K_PER_W;
        let time_to = |boost: bool| {
            let mut o = Observer::new(22.0);
            for k in 0..2000 {
                let p = if boost {
                    o.power_to_reach_w(HeatedNode::Tca, target, 2.0)
                } else {
                    steady_w
                };
                o.predict(0.1, 0.0, p, 22.0);
                if o.model_c(HeatedNode::Tca) > target - 0.3 {
                    return k as f32 * 0.1;
                }
            }
            f32::INFINITY
        };
        let (fast, slow) = (time_to(true), time_to(false));
        assert!(fast < 5.0 && slow > 4.0 * fast, "{fast} s vs {slow} s");
    }

    #[test]
    fn the_observer_removes_a_steady_model_error() {
        // The real TCA runs 5 K hotter than the model (e.g. weaker convection).
        let mut o = Observer::new(22.0);
        let mut sensed = 22.0f32;
        for _ in 0..600 {
            o.predict(0.1, 0.0, 0.8, 22.0);
            let truth = o.model_c(HeatedNode::Tca) + 5.0;
            sensed += (truth - sensed) * (1.0 - libm_exp(-0.1 / SENSOR_TAU_S));
            o.correct(0.1, 22.0, sensed);
        }
        let truth = o.model_c(HeatedNode::Tca) + 5.0;
        assert!((o.estimate_c(HeatedNode::Tca) - truth).abs() < 0.1);
        assert!((o.disturbance_k(HeatedNode::Tca) - 5.0).abs() < 0.1);
    }

    #[test]
    fn innovation_is_small_while_the_model_follows_the_link_and_large_when_it_runs_ahead() {
        // 8 s of soften at 5 W, then the PLA at 1.5 W: a thermistor that reads the model's
        // own, and one that sees 60 % of the rise (a rod heating slower than the model's).
        let run = |share: f32, ticks: usize| {
            let mut o = Observer::new(22.0);
            for k in 0..ticks {
                let w = if k < 80 { 5.0 } else { 1.5 };
                o.predict(0.1, w, 0.0, 22.0);
                let sensed = 22.0 + share * (o.sensor_c[0] - 22.0);
                o.correct(0.1, sensed, 22.0);
            }
            o.innovation_k(HeatedNode::Pla)
        };
        // Settled, a following thermistor agrees; while it rises fast (the end of the 5 W
        // step, about 6–7 K/s), the reading's 0.5 s smoothing trails by half a second of that
        // rate, 3.3 K: just outside the agreement `closed` allows, so a bend does not take a
        // rod still heating this fast as settled.
        let (settled, rising, ahead) = (run(1.0, 6000), run(1.0, 80), run(0.6, 80));
        assert!(settled.abs() < 0.05, "{settled}");
        assert!(rising < 0.0 && rising > -0.5 * 8.0, "{rising}");
        assert!(ahead < rising - 1.0, "{ahead} vs {rising}");
        assert_eq!(Observer::new(22.0).innovation_k(HeatedNode::Tca), 0.0);
    }

    fn libm_exp(x: f32) -> f32 {
        crate::mathf::exp(x)
    }

    #[test]
    fn power_is_never_negative_nor_above_the_cap() {
        let o = Observer::from_measured(90.0, 90.0, 22.0);
        assert_eq!(o.power_to_reach_w(HeatedNode::Pla, 70.0, 5.0), 0.0);
        let o = Observer::new(22.0);
        assert_eq!(o.power_to_reach_w(HeatedNode::Pla, 120.0, 5.0), 5.0);
        assert_eq!(o.power_to_reach_w(HeatedNode::Tca, f32::NAN, 2.0), 0.0);
    }
}
