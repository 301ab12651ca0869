//! The TCA: resistance that follows its temperature, a force law (fibre untwist with thermal
//! expansion, coil as a helical spring: see [`TcaSpec`]) driven through a play of a
//! few kelvin (force–temperature hysteresis) and a slow creep of the loaded coil.

use super::spec::{TcaSpec, STROKE_REF_C, TCA_R_REF_C};

/// The TCA's state: the temperature its untwist follows (after the play) and its creep.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tca {
    /// Temperature the fibre's untwist follows, °C (the play's output).
    pub untwist_c: f64,
    /// Free stroke lost to creep, m.
    pub creep_m: f64,
}

/// Free stroke at `temp_c` (preload included), m.
pub fn free_stroke_m(spec: &TcaSpec, temp_c: f64) -> f64 {
    let u = temp_c - STROKE_REF_C;
    let [a, b, c] = spec.stroke_coeffs;
    a + b * u + c * u * u
}

/// Resistance at mean temperature `temp_c` and coil strain `strain` (shortening negative), Ω.
pub fn resistance_ohm(spec: &TcaSpec, temp_c: f64, strain: f64) -> f64 {
    (spec.r_ref_ohm * (1.0 + spec.tcr_per_k * (temp_c - TCA_R_REF_C) + spec.gauge * strain))
        .max(1e-3)
}

impl Tca {
    /// A TCA that has sat at `temp_c` long enough for its creep to settle.
    pub fn at_rest(spec: &TcaSpec, temp_c: f64) -> Self {
        Tca {
            untwist_c: temp_c,
            creep_m: spec.creep_fraction * free_stroke_m(spec, temp_c),
        }
    }

    /// Follows the tube's mean temperature `temp_c` over `dt_s`: the play moves the untwist
    /// temperature only when the tube leaves the band `±hysteresis_half_k` around it; creep
    /// relaxes toward its share of the free stroke.
    pub fn update(&mut self, spec: &TcaSpec, temp_c: f64, dt_s: f64) {
        let h = spec.hysteresis_half_k;
        if temp_c > self.untwist_c + h {
            self.untwist_c = temp_c - h;
        } else if temp_c < self.untwist_c - h {
            self.untwist_c = temp_c + h;
        }
        let target = spec.creep_fraction * free_stroke_m(spec, self.untwist_c);
        let keep = libm::exp(-dt_s / spec.creep_time_s);
        self.creep_m = target + (self.creep_m - target) * keep;
    }

    /// Stroke the coil would reach unloaded, m (creep taken off).
    pub fn stroke_m(&self, spec: &TcaSpec) -> f64 {
        free_stroke_m(spec, self.untwist_c) - self.creep_m
    }

    /// Push at extension `delta_m` with the tube at `temp_c`, N.
    pub fn push_n(&self, spec: &TcaSpec, temp_c: f64, delta_m: f64) -> f64 {
        spec.law.spring_rate_n_per_m(temp_c) * (self.stroke_m(spec) - delta_m)
    }
}
