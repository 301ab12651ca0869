//! Thermistor beads: a small heat capacity tied to the local temperature by a dissipation
//! constant (contact included), heated by the divider's bias current, read as the nominal
//! conversion reads its true resistance.

use super::spec::{BeadSpec, BEAD_BETA_K, BEAD_R25_OHM, DIVIDER_BIAS_V, DIVIDER_PULLUP_OHM};

/// Kelvin at 25 °C.
const T25_K: f64 = 298.15;
/// Kelvin at 0 °C.
const ZERO_C_K: f64 = 273.15;

/// True resistance of `spec`'s bead at `temp_c`, Ω (Beta law with its own R25 and Beta).
pub fn resistance_ohm(spec: &BeadSpec, temp_c: f64) -> f64 {
    spec.r25_ohm * libm::exp(spec.beta_k * (1.0 / (temp_c + ZERO_C_K) - 1.0 / T25_K))
}

/// Power the divider's bias dissipates in a bead of resistance `r_ohm`, W.
pub fn self_heating_w(r_ohm: f64) -> f64 {
    let i = DIVIDER_BIAS_V / (DIVIDER_PULLUP_OHM + r_ohm);
    i * i * r_ohm
}

/// Temperature the nominal conversion (R25 = 10 kΩ, Beta = 3950 K) gives for `r_ohm`, °C.
pub fn nominal_reading_c(r_ohm: f64) -> f64 {
    1.0 / (1.0 / T25_K + libm::log(r_ohm / BEAD_R25_OHM) / BEAD_BETA_K) - ZERO_C_K
}

/// A bead's temperature.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bead {
    /// True bead temperature, °C.
    pub temp_c: f64,
}

impl Bead {
    /// Steps `dt_s` toward `local_c` plus its self-heating rise (exact for a constant local
    /// temperature and bias over the step).
    pub fn step(&mut self, spec: &BeadSpec, local_c: f64, dt_s: f64) {
        let p = self_heating_w(resistance_ohm(spec, self.temp_c));
        let target = local_c + p / spec.dissipation_w_k;
        let keep = libm::exp(-dt_s * spec.dissipation_w_k / spec.capacity_j_k);
        self.temp_c = target + (self.temp_c - target) * keep;
    }

    /// What the nominal conversion reads from this bead's true resistance: apparent °C.
    pub fn apparent_c(&self, spec: &BeadSpec) -> f64 {
        nominal_reading_c(resistance_ohm(spec, self.temp_c))
    }
}
