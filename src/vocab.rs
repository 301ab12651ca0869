//! The words every part of the core shares: morph phases, heater powers, measured
//! temperatures, and which sensor or heater a value belongs to. Leaf module: it depends on
//! nothing else in the crate, so the modules that use it need not depend on each other.

/// Firmware version reported by VERSION and the boot line.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// Phase of the morph sequence.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    /// Both heaters off, waiting for MORPH.
    Idle,
    /// Heating the PLA until it is soft.
    Soften,
    /// PLA held soft; TCA at the power that gives the target radius.
    Bend,
    /// PLA heater off; TCA holds the shape while the PLA stiffens.
    Lock,
    /// TCA off; the link keeps its new shape.
    Release,
    /// A safety trip latched; both heaters off until RESET.
    Fault,
}

impl Phase {
    /// Wire name of the phase.
    pub fn as_str(self) -> &'static str {
        match self {
            Phase::Idle => "idle",
            Phase::Soften => "soften",
            Phase::Bend => "bend",
            Phase::Lock => "lock",
            Phase::Release => "release",
            Phase::Fault => "fault",
        }
    }

    /// True for the phases of a running morph (soften, bend, lock, release).
    pub fn is_morphing(self) -> bool {
        matches!(
            self,
            Phase::Soften | Phase::Bend | Phase::Lock | Phase::Release
        )
    }
}

/// One of the three thermistors. Its [`Sensor::index`] is its place in every per-sensor array
/// of the core (ADC counts, readings, limits, counters): the one definition of that order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sensor {
    /// On the PLA rod.
    Pla,
    /// Beside the TCA.
    Tca,
    /// In the surrounding medium.
    Amb,
}

impl Sensor {
    /// Every sensor, in index order.
    pub const ALL: [Sensor; 3] = [Sensor::Pla, Sensor::Tca, Sensor::Amb];

    /// Index of this sensor in per-sensor arrays: PLA 0, TCA 1, ambient 2.
    pub const fn index(self) -> usize {
        match self {
            Sensor::Pla => 0,
            Sensor::Tca => 1,
            Sensor::Amb => 2,
        }
    }

    /// The lowercase wire word (`pla`, `tca`, `amb`).
    pub fn as_str(self) -> &'static str {
        match self {
            Sensor::Pla => "pla",
            Sensor::Tca => "tca",
            Sensor::Amb => "amb",
        }
    }
}

/// One of the two heaters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Heater {
    /// Nichrome wrap on the PLA rod.
    Pla,
    /// The twisted-and-coiled actuator itself (Joule heated).
    Tca,
}

impl Heater {
    /// Every heater, in index order.
    pub const ALL: [Heater; 2] = [Heater::Pla, Heater::Tca];

    /// Index of this heater in per-heater arrays: PLA 0, TCA 1.
    pub const fn index(self) -> usize {
        match self {
            Heater::Pla => 0,
            Heater::Tca => 1,
        }
    }

    /// The thermistor that watches this heater.
    pub const fn sensor(self) -> Sensor {
        match self {
            Heater::Pla => Sensor::Pla,
            Heater::Tca => Sensor::Tca,
        }
    }

    /// The lowercase wire word (`pla`, `tca`).
    pub fn as_str(self) -> &'static str {
        match self {
            Heater::Pla => "pla",
            Heater::Tca => "tca",
        }
    }
}

/// Temperatures the sequencer decides from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Measurements {
    /// PLA thermistor, °C.
    pub t_pla_c: f32,
    /// TCA thermistor, °C.
    pub t_tca_c: f32,
    /// Ambient thermistor, °C.
    pub t_amb_c: f32,
}

impl Measurements {
    /// Measurements from per-sensor values in [`Sensor::index`] order, °C.
    pub const fn from_array(c: [f32; 3]) -> Self {
        Measurements {
            t_pla_c: c[Sensor::Pla.index()],
            t_tca_c: c[Sensor::Tca.index()],
            t_amb_c: c[Sensor::Amb.index()],
        }
    }

    /// The temperature of one sensor, °C.
    pub fn of(&self, s: Sensor) -> f32 {
        match s {
            Sensor::Pla => self.t_pla_c,
            Sensor::Tca => self.t_tca_c,
            Sensor::Amb => self.t_amb_c,
        }
    }
}

/// Heater powers the sequencer asks for, W.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Powers {
    /// PLA heater, W.
    pub pla_w: f32,
    /// TCA, W.
    pub tca_w: f32,
}

impl Powers {
    /// The power of one heater, W.
    pub fn of(&self, h: Heater) -> f32 {
        match h {
            Heater::Pla => self.pla_w,
            Heater::Tca => self.tca_w,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn indices_follow_the_all_order() {
        for (i, s) in Sensor::ALL.into_iter().enumerate() {
            assert_eq!(s.index(), i);
        }
        for (i, h) in Heater::ALL.into_iter().enumerate() {
            assert_eq!(h.index(), i);
            assert_eq!(h.sensor().as_str(), h.as_str());
        }
        let m = Measurements::from_array([1.0, 2.0, 3.0]);
        assert_eq!(
            (m.of(Sensor::Pla), m.of(Sensor::Tca), m.of(Sensor::Amb)),
            (1.0, 2.0, 3.0)
        );
    }
}
