//! The words every part of the core shares: morph phases, heater powers, measured
//! temperatures, which sensor or heater a value belongs to, and why the chip last reset. Leaf
//! module: it depends on nothing else in the crate, so the modules that use it need not depend
//! on each other (`tests/layout.rs` holds that).

/// Firmware version reported by VERSION and the boot line.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// Phase of the morph sequence.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    /// Both heaters off, waiting for MORPH.
    Idle,
    /// A MORPH on a warm link: both heaters off until it has cooled to the rest the morph's
    /// model starts from ([`crate::sequencer::REST_MAX_RISE_K`]).
    Rest,
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
            Phase::Rest => "rest",
            Phase::Soften => "soften",
            Phase::Bend => "bend",
            Phase::Lock => "lock",
            Phase::Release => "release",
            Phase::Fault => "fault",
        }
    }

    /// True for the phases of a running morph (rest, soften, bend, lock, release).
    pub fn is_morphing(self) -> bool {
        matches!(
            self,
            Phase::Rest | Phase::Soften | Phase::Bend | Phase::Lock | Phase::Release
        )
    }
}

/// What the controller is doing, as the supervisor is told it: its checks judge a heater's
/// power by the activity that commands it (a morph's phase, a TUNE step, a bring-up pulse).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Doing {
    /// Nothing runs (at rest, or a fault latched): both heaters off.
    Idle,
    /// A morph, in this phase (one of [`Phase::is_morphing`]'s).
    Morph(Phase),
    /// A `TUNE`.
    Tune,
    /// A `HEAT` pulse of this heater.
    Heat(Heater),
}

impl From<Phase> for Doing {
    /// A morph in `phase`; idle for [`Phase::Idle`] and [`Phase::Fault`].
    fn from(phase: Phase) -> Doing {
        if phase.is_morphing() {
            Doing::Morph(phase)
        } else {
            Doing::Idle
        }
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

    /// The other heater of the link.
    pub const fn other(self) -> Heater {
        match self {
            Heater::Pla => Heater::Tca,
            Heater::Tca => Heater::Pla,
        }
    }

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
    /// No allowance below the heaters' own caps (a board with one link, no budget).
    pub const UNLIMITED: Powers = Powers {
        pla_w: f32::INFINITY,
        tca_w: f32::INFINITY,
    };

    /// Each heater's power, at most `other`'s, W.
    pub fn min(self, other: Powers) -> Powers {
        Powers {
            pla_w: self.pla_w.min(other.pla_w),
            tca_w: self.tca_w.min(other.tca_w),
        }
    }

    /// `w` W on heater `h`, the other off.
    pub fn only(h: Heater, w: f32) -> Powers {
        match h {
            Heater::Pla => Powers {
                pla_w: w,
                tca_w: 0.0,
            },
            Heater::Tca => Powers {
                pla_w: 0.0,
                tca_w: w,
            },
        }
    }

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

/// The reset flags a chip reports (STM32 `RCC_CSR`): the board boundary's type.
pub use morphlink_boards::ResetFlags;

/// Why the chip last reset, decoded from its reset flags by [`ResetCause::from_flags`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ResetCause {
    /// The independent watchdog expired: the control task stopped feeding it.
    Watchdog,
    /// The window watchdog expired (not used by this firmware; reported if it ever fires).
    WindowWatchdog,
    /// Software reset: a panic or HardFault handler (heaters were forced off first), or a
    /// debugger's reset.
    Software,
    /// Illegal entry into a low-power mode.
    LowPower,
    /// Power came up, or the supply dipped below the brown-out threshold.
    PowerOn,
    /// The reset pin: the board's reset button or the ST-LINK.
    Pin,
    /// No flag was set.
    Unknown,
}

impl ResetCause {
    /// The cause behind a set of flags. Every internal reset also pulses the reset pin and a
    /// power-on also sets brown-out, so the most specific flag wins: watchdogs, then software,
    /// then low power, then power-on, and the pin only when nothing else is set.
    pub fn from_flags(f: ResetFlags) -> ResetCause {
        if f.watchdog {
            ResetCause::Watchdog
        } else if f.window_watchdog {
            ResetCause::WindowWatchdog
        } else if f.software {
            ResetCause::Software
        } else if f.low_power {
            ResetCause::LowPower
        } else if f.power_on {
            ResetCause::PowerOn
        } else if f.pin {
            ResetCause::Pin
        } else {
            ResetCause::Unknown
        }
    }

    /// The lowercase wire word.
    pub fn as_str(self) -> &'static str {
        match self {
            ResetCause::Watchdog => "watchdog",
            ResetCause::WindowWatchdog => "window-watchdog",
            ResetCause::Software => "software",
            ResetCause::LowPower => "low-power",
            ResetCause::PowerOn => "power-on",
            ResetCause::Pin => "pin",
            ResetCause::Unknown => "unknown",
        }
    }
}
