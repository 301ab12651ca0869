//! Board support for the morphlink firmware.
//!
//! The firmware's tasks (`src/main.rs`) are written once against the traits here; each board
//! module implements them for its peripherals and is picked by one cargo feature:
//!
//! | feature | module | board |
//! | --- | --- | --- |
//! | `nucleo-f401re` | `nucleo_f401re` | NUCLEO-F401RE (the default) |
//! | `nucleo-g431rb` | `nucleo_g431rb` | NUCLEO-G431RB (hardware ADC oversampling) |
//! | `b-l475e-iot01a` | `b_l475e_iot01a` | B-L475E-IOT01A |
//! | `b-l475e-iot01a-emulated` | `emulated` | the same board under QEMU |
//!
//! The selected module is re-exported as `selected`. Every board module provides the same
//! items: `NAME`, `CPU_HZ`, `HW_OVERSAMPLE`, `SHUNT`, `init() -> Parts`, `heater_pins_low()`,
//! `cycles()` and `fatal()`. Nothing here knows the controller: the board moves ADC counts,
//! PWM duties and the supply's cut-off, and bytes through its serial port
//! (`embedded_io_async::{Read, Write}`). On the host only the traits and [`ResetFlags`]
//! compile.
#![no_std]
#![deny(missing_docs)]

/// Which analog input: the order of [`AnalogInputs::read`]'s counts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(usize)]
pub enum Input {
    /// PLA thermistor divider.
    PlaThermistor = 0,
    /// TCA thermistor divider.
    TcaThermistor = 1,
    /// Ambient thermistor divider.
    AmbThermistor = 2,
    /// Heater supply divider.
    Supply = 3,
}

/// Serial line speed on every board, baud: the ST-LINK virtual COM port's usual default (8N1,
/// no flow control).
pub const BAUD: u32 = 115_200;

/// Number of analog inputs.
pub const INPUTS: usize = 4;

/// The thermistor and supply inputs.
pub trait AnalogInputs {
    /// One read of every input, ADC counts, indexed by [`Input`] (a read is one conversion,
    /// or the sum of `HW_OVERSAMPLE` conversions where the ADC oversamples in hardware).
    fn read(&mut self) -> [u16; INPUTS];

    /// One read of link `link`'s inputs (0-based), as [`AnalogInputs::read`]: its own
    /// thermistors, the shared ambient bead and supply. A board wired for one link has only
    /// link 0, which is [`AnalogInputs::read`].
    fn read_link(&mut self, link: usize) -> [u16; INPUTS] {
        let _ = link;
        self.read()
    }
}

/// Both heaters' PWM outputs and the cut-off of their supply.
///
/// The cut-off is a switch in the heater supply ahead of both heaters (a high-side P-MOSFET,
/// or a relay), driven by one GPIO whose pull-down holds it open: from reset until `init`,
/// after a crash and in the panic path (each board's `heater_pins_low()`)
/// the heaters have no supply, whatever their MOSFETs do.
pub trait HeaterOutputs {
    /// Sets both duties, fractions in [0, 1] (anything else, NaN included, is off), then the
    /// cut-off: closed (the heaters supplied) if `supply_on`, open otherwise.
    fn apply(&mut self, pla_duty: f32, tca_duty: f32, supply_on: bool);

    /// As [`HeaterOutputs::apply`], for link `link`'s heaters and cut-off (0-based; one cut-off
    /// per link, docs/bringup.md). A board wired for one link has only link 0.
    fn apply_link(&mut self, link: usize, pla_duty: f32, tca_duty: f32, supply_on: bool) {
        let _ = link;
        self.apply(pla_duty, tca_duty, supply_on);
    }
}

/// Heater PWM frequency on every board, Hz: the core's `electrical::PWM_HZ` (the firmware
/// asserts they agree). Why 1 kHz: `stm32::PWM_FREQUENCY`.
pub const PWM_HZ: u32 = 1000;

/// Length of the probe pulse, µs: the core's `electrical::MIN_SENSED_ON_US` (the firmware
/// asserts they agree). A heater driven below the duty of this pulse (off included) gets one
/// such pulse per tick, and its on-current is sampled inside it ([`CurrentSense`]).
pub const PROBE_PULSE_US: u32 = 10;

/// One tick's load-current readings of both heaters (PLA first, then TCA), each the sum of
/// the number of 12-bit conversions [`CurrentSense::read_currents`] was asked for, ADC counts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CurrentSums {
    /// Sampled inside each heater's PWM on-time, or inside its probe pulse.
    pub on: [u32; 2],
    /// Sampled inside its off-time.
    pub off: [u32; 2],
}

/// The heaters' load currents, through a low-side shunt and an amplifier per heater into the
/// ADC, sampled inside the PWM on-time and inside the off-time (each board module says how it
/// times the conversions against the PWM). A board without current sense returns `None`: the
/// controller then runs on its thermistors alone, the paper's wiring plus the cut-off.
#[allow(async_fn_in_trait)]
pub trait CurrentSense {
    /// Takes `reads` readings of each heater inside its on-time and `reads` inside its
    /// off-time and returns their sums; a heater driven below the probe pulse's duty gets one
    /// probe pulse ([`PROBE_PULSE_US`]), and its one reading inside it counts `reads` times.
    /// `None` where the board senses no current.
    async fn read_currents(&mut self, reads: u32) -> Option<CurrentSums>;

    /// As [`CurrentSense::read_currents`], for link `link`'s heaters (0-based). A board wired
    /// for one link has only link 0.
    async fn read_link_currents(&mut self, link: usize, reads: u32) -> Option<CurrentSums> {
        let _ = link;
        self.read_currents(reads).await
    }
}

/// A board's current-sense chain, for the controller's conversion of counts to amperes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShuntChain {
    /// Shunt resistance, Ω.
    pub shunt_ohm: f32,
    /// Amplifier gain, V/V.
    pub gain: f32,
}

impl ShuntChain {
    /// 50 mΩ into an INA180A1 (gain 20): 1 V/A at the ADC, the core's `ShuntSense::DEFAULT`.
    pub const INA180A1: ShuntChain = ShuntChain {
        shunt_ohm: 0.05,
        gain: 20.0,
    };
}

/// A watchdog that resets (or, emulated, ends) the firmware when it is not fed in time.
pub trait Watchdog {
    /// Starts it; from now on [`Watchdog::feed`] must come within the board's timeout.
    fn start(&mut self);
    /// Proves the control task is alive.
    fn feed(&mut self);
}

/// The reset flags a chip reports (STM32 `RCC_CSR`); each is true if set.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ResetFlags {
    /// Independent watchdog (`IWDGRSTF`).
    pub watchdog: bool,
    /// Window watchdog (`WWDGRSTF`).
    pub window_watchdog: bool,
    /// Software (`SFTRSTF`; the panic and HardFault handlers end in one).
    pub software: bool,
    /// Low-power management (`LPWRRSTF`).
    pub low_power: bool,
    /// Power-on or brown-out (`PORRSTF`, `BORRSTF`).
    pub power_on: bool,
    /// Reset pin (`PINRSTF`/`PADRSTF`).
    pub pin: bool,
}

/// Received-byte buffer of every board's serial port, bytes: four maximal lines. The firmware
/// reads with a buffer at least this long, so a read that returns this many bytes drained a
/// full buffer.
pub const SERIAL_RX_BYTES: usize = 256;

/// What one [`SerialReceive::receive`] gave.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Received {
    /// Bytes copied into the caller's buffer, oldest first.
    pub len: usize,
    /// Input may have been lost right after these bytes (the receive buffer was full, or the
    /// UART overran): the line in progress there must not be run.
    pub lost_after: bool,
}

/// A serial receiver that never loses input silently.
#[allow(async_fn_in_trait)]
pub trait SerialReceive {
    /// Waits for received bytes and copies them into `buf` (at least [`SERIAL_RX_BYTES`]
    /// long), saying whether input was lost after them. Cancel-safe: dropped before it
    /// completes, it has taken nothing.
    async fn receive(&mut self, buf: &mut [u8]) -> Received;
}

/// Why the previous run ended, as the firmware recorded it in RAM that survives a reset.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FatalKind {
    /// A panic or HardFault (or another fatal error the firmware named).
    Fault,
    /// The (emulated) watchdog: the control task stopped feeding it.
    Watchdog,
}

/// Longest recorded fatal-error reason, bytes (longer reasons are cut).
pub const FATAL_REASON_BYTES: usize = 120;

/// The fatal error that ended the previous run: its kind and its reason, ASCII.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LastFatal {
    /// What ended it.
    pub kind: FatalKind,
    reason: [u8; FATAL_REASON_BYTES],
    len: usize,
}

impl LastFatal {
    /// A record of `kind` with `reason` (cut at [`FATAL_REASON_BYTES`]; non-ASCII bytes
    /// become `?`).
    pub fn new(kind: FatalKind, reason: &[u8]) -> Self {
        let mut r = LastFatal {
            kind,
            reason: [0; FATAL_REASON_BYTES],
            len: 0,
        };
        for &b in reason.iter().take(FATAL_REASON_BYTES) {
            r.reason[r.len] = if b.is_ascii() { b } else { b'?' };
            r.len += 1;
        }
        r
    }

    /// The reason text.
    pub fn reason(&self) -> &str {
        core::str::from_utf8(&self.reason[..self.len.min(FATAL_REASON_BYTES)]).unwrap_or("?")
    }
}

/// A board's peripherals, configured and ready for the tasks: heaters at 0 % duty, the
/// supply's cut-off open.
pub struct Parts<S, H, W, Tx, Rx, F = ()> {
    /// Thermistor and supply inputs, and the heaters' currents ([`CurrentSense`]).
    pub sensors: S,
    /// Both heaters, off, and the cut-off, open.
    pub heaters: H,
    /// The watchdog, not started yet.
    pub watchdog: W,
    /// Serial transmit half.
    pub tx: Tx,
    /// Serial receive half.
    pub rx: Rx,
    /// Reset flags read (and cleared) at boot.
    pub reset_flags: ResetFlags,
    /// The fatal error that ended the previous run, if the firmware recorded one (read once:
    /// the record is cleared at boot).
    pub last_fatal: Option<LastFatal>,
    /// The flash the settings area is in (`()` where the firmware brings its own: the
    /// emulated board), with the area from `settings_area()`.
    pub settings_flash: F,
}

/// The settings area, byte offsets from the start of the chip's flash: the `SETTINGS` region
/// of the board's `memory.x`, right after `FLASH` (which the code is linked into, so it can
/// never overlap the settings; `cargo xtask boards` checks the two regions).
#[cfg(all(target_os = "none", feature = "_stm32"))]
pub fn settings_area() -> core::ops::Range<u32> {
    extern "C" {
        static __morphlink_settings_start: u8;
        static __morphlink_settings_end: u8;
    }
    // Only the addresses of the linker's symbols are taken, never their contents.
    let (start, end) = (
        core::ptr::addr_of!(__morphlink_settings_start) as u32,
        core::ptr::addr_of!(__morphlink_settings_end) as u32,
    );
    (start - FLASH_BASE)..(end - FLASH_BASE)
}

/// Where the STM32s map their flash.
#[cfg(all(target_os = "none", feature = "_stm32"))]
const FLASH_BASE: u32 = 0x0800_0000;

#[cfg(target_os = "none")]
pub mod reset_record;

#[cfg(all(target_os = "none", feature = "_stm32"))]
pub mod stm32;

#[cfg(all(target_os = "none", feature = "nucleo-f401re"))]
pub mod nucleo_f401re;
#[cfg(all(target_os = "none", feature = "nucleo-f401re"))]
pub use nucleo_f401re as selected;

#[cfg(all(target_os = "none", feature = "nucleo-g431rb"))]
pub mod nucleo_g431rb;
#[cfg(all(target_os = "none", feature = "nucleo-g431rb"))]
pub use nucleo_g431rb as selected;

#[cfg(all(target_os = "none", feature = "b-l475e-iot01a"))]
pub mod b_l475e_iot01a;
#[cfg(all(target_os = "none", feature = "b-l475e-iot01a"))]
pub use b_l475e_iot01a as selected;

#[cfg(all(target_os = "none", feature = "b-l475e-iot01a-emulated"))]
pub mod emulated;
#[cfg(all(target_os = "none", feature = "b-l475e-iot01a-emulated"))]
pub use emulated as selected;
