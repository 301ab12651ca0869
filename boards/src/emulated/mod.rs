//! B-L475E-IOT01A under QEMU (`qemu-system-arm -M b-l475e-iot01a`): the same firmware — core,
//! control and serial tasks, protocol — with only the pieces QEMU does not model replaced:
//!
//! | on hardware | here | why |
//! | --- | --- | --- |
//! | TIM2 embassy time driver | [`time_driver`]: SysTick, running [`SPEEDUP`]× real time | QEMU models no STM32 timers |
//! | `embassy_stm32::init` (HSI → PLL 80 MHz) | reset clock (MSI 4 MHz), no init | init waits forever for PWR/RCC ready bits QEMU never sets |
//! | ADC1 thermistors and supply | [`Sensors`]: the firmware's [`SimulatedLink`] | QEMU's ADC never becomes ready |
//! | shunt amplifiers sampled against TIM3 | [`Sensors`]: the link's currents, with the frame they came in | no ADC, no timers |
//! | TIM3 PWM heaters, the cut-off on PB2 | [`Heaters`]: duties and cut-off into the [`SimulatedLink`] | no timers |
//! | buffered USART1 (embassy) | [`usart`]: register-level USART1 with an RX interrupt | QEMU's USART needs 32-bit accesses and never sets IDLE |
//! | IWDG | [`Iwdg`]: the same 500 ms rule checked in the SysTick interrupt, then a system reset | no IWDG model |
//! | panic/HardFault → reset | heaters off, message on the semihosting console, then the same reset | a test must see it |
//! | `RCC_CSR` reset flags | the firmware's reset record (`.uninit` RAM) names a software or watchdog reset | QEMU's RCC sets no reset flags |
//!
//! The simulated link is the firmware's (a plant from `morphlink-plant` on the core's simulated
//! board, `morphlink::bench`): the very code `morph-sim` and the host tests run. This module
//! only calls it through [`SimulatedLink`], at firmware time, so a whole morph runs
//! [`SPEEDUP`] times faster than real time.

use crate::{
    AnalogInputs, CurrentSense, CurrentSums, FatalKind, HeaterOutputs, ResetFlags, ShuntChain,
    Watchdog, INPUTS,
};
use core::cell::Cell;
use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use critical_section::Mutex;
use embassy_stm32::pac;

mod time_driver;
pub mod usart;

/// Board name, as in the feature and the boot line.
pub const NAME: &str = "b-l475e-iot01a-emulated";
/// Core clock after reset (MSI), Hz: the SysTick reference in QEMU.
pub const CPU_HZ: u32 = 4_000_000;
/// The simulated ADC returns the 16× oversampled sums directly, as the G4's hardware does.
pub const HW_OVERSAMPLE: u32 = 16;
/// Firmware time runs this many times faster than QEMU's virtual time: a 100 ms control tick
/// takes 5 ms of it, so a whole morph finishes in seconds. Virtual time is wall-clock time, or,
/// under QEMU's `-icount` (as the tests run it), the emulated instructions' time while the CPU
/// runs and wall-clock time while it sleeps (docs/emulation.md, "Speed-up and the clock").
pub const SPEEDUP: u32 = 20;
/// Watchdog timeout, firmware ms: as the hardware IWDG's 500 ms.
pub const WATCHDOG_MS: u64 = 500;
/// The simulated board's current-sense chain: the one its ADC model uses
/// (`morphlink::bench`, the core's `ShuntSense::DEFAULT`).
pub const SHUNT: ShuntChain = ShuntChain::INA180A1;

/// What stands in for the ADC, the heater PWM and the cut-off: the simulated links the
/// firmware keeps (one, or one per link of an image built for several). Its methods take
/// `&self` (it keeps its own lock), the link (0-based) and firmware time in ms.
pub trait SimulatedLink: Sync {
    /// One read of link `link`'s inputs at `now_ms`, ADC counts as [`AnalogInputs::read`]
    /// gives them; the frame's currents are kept for [`SimulatedLink::currents`].
    fn read(&self, link: usize, now_ms: u64) -> [u16; INPUTS];
    /// The currents of the frame the last [`SimulatedLink::read`] of `link` took, sums of the
    /// core's oversampling count (`None`: the simulated board senses no current).
    fn currents(&self, link: usize) -> Option<CurrentSums>;
    /// Applies link `link`'s duties and cut-off (`supply_on`: closed) from `now_ms` on.
    fn apply(&self, link: usize, now_ms: u64, pla_duty: f32, tca_duty: f32, supply_on: bool);
    /// Every link's heaters off and supplies cut, from a panic or the watchdog: must not block
    /// or panic.
    fn heaters_off(&self);
}

static LINK: Mutex<Cell<Option<&'static dyn SimulatedLink>>> = Mutex::new(Cell::new(None));

fn link() -> Option<&'static dyn SimulatedLink> {
    critical_section::with(|cs| LINK.borrow(cs).get())
}

fn now_ms() -> u64 {
    embassy_time::Instant::now().as_millis()
}

/// Drives the cut-off's pin and both heater gates low by raw register writes (PB2, PA6 and
/// PA7, as on the hardware board) and switches the simulated heaters and supply off, whatever
/// state the rest of the firmware is in.
pub fn heater_pins_low() {
    for (port, pin) in [(pac::GPIOB, 2), (pac::GPIOA, 6), (pac::GPIOA, 7)] {
        port.bsrr().write(|w| w.set_br(pin, true));
        port.moder()
            .modify(|w| w.set_moder(pin, pac::gpio::vals::Moder::OUTPUT));
    }
    if let Some(l) = link() {
        l.heaters_off();
    }
}

/// The simulated thermistor and supply inputs and heater currents.
pub struct Sensors(&'static dyn SimulatedLink);

impl AnalogInputs for Sensors {
    fn read(&mut self) -> [u16; INPUTS] {
        self.0.read(0, now_ms())
    }

    fn read_link(&mut self, link: usize) -> [u16; INPUTS] {
        self.0.read(link, now_ms())
    }
}

impl CurrentSense for Sensors {
    /// The currents of the tick's frame, already summed by the simulated board over the core's
    /// oversampling count (which is what the firmware asks for: `reads` is not used), probe
    /// pulses included. The firmware reads them after the frame's [`AnalogInputs::read`].
    async fn read_currents(&mut self, _reads: u32) -> Option<CurrentSums> {
        self.0.currents(0)
    }

    async fn read_link_currents(&mut self, link: usize, _reads: u32) -> Option<CurrentSums> {
        self.0.currents(link)
    }
}

/// The simulated heaters and cut-off: duties and cut-off go into the link.
pub struct Heaters(&'static dyn SimulatedLink);

impl HeaterOutputs for Heaters {
    fn apply(&mut self, pla_duty: f32, tca_duty: f32, supply_on: bool) {
        self.0.apply(0, now_ms(), pla_duty, tca_duty, supply_on);
    }

    fn apply_link(&mut self, link: usize, pla_duty: f32, tca_duty: f32, supply_on: bool) {
        self.0.apply(link, now_ms(), pla_duty, tca_duty, supply_on);
    }
}

static WDG_ARMED: AtomicBool = AtomicBool::new(false);
static WDG_LAST_PET_MS: AtomicU32 = AtomicU32::new(0);

/// Watchdog with the hardware IWDG's rule: once started, a control task that stops feeding it
/// for [`WATCHDOG_MS`] resets the machine (heaters off; the next boot says `reset=watchdog`).
pub struct Iwdg(());

impl Watchdog for Iwdg {
    fn start(&mut self) {
        WDG_LAST_PET_MS.store(now_ms() as u32, Ordering::Relaxed);
        WDG_ARMED.store(true, Ordering::Relaxed);
    }

    fn feed(&mut self) {
        WDG_LAST_PET_MS.store(now_ms() as u32, Ordering::Relaxed);
    }
}

/// Called from the SysTick interrupt every firmware millisecond.
fn watchdog_check(now_ms: u64) {
    let since_pet = (now_ms as u32).wrapping_sub(WDG_LAST_PET_MS.load(Ordering::Relaxed));
    if WDG_ARMED.load(Ordering::Relaxed) && u64::from(since_pet) > WATCHDOG_MS {
        heater_pins_low();
        end(
            FatalKind::Watchdog,
            format_args!(
                "watchdog: the control task stopped feeding the watchdog for {} ms; heaters off",
                since_pet
            ),
        );
    }
}

/// QEMU does not model the DWT cycle counter (it reads 0), so the emulated build counts
/// [`CPU_HZ`] cycles per second of firmware time from the SysTick clock instead: `STATS` then
/// reports firmware-time durations (20× compressed), in 5 µs steps.
pub fn cycles() -> u32 {
    (embassy_time::Instant::now().as_micros() * u64::from(CPU_HZ / 1_000_000)) as u32
}

/// Ends a fatal error (heaters already off): prints `reason` on the semihosting console,
/// records it for the next boot and resets the machine, as the hardware boards do. QEMU keeps
/// RAM over the reset (it reloads only the image), so the record survives.
pub fn fatal(reason: core::fmt::Arguments) -> ! {
    end(FatalKind::Fault, reason)
}

fn end(kind: FatalKind, reason: core::fmt::Arguments) -> ! {
    cortex_m_semihosting::hprintln!("{}", reason);
    crate::reset_record::record(kind, reason);
    cortex_m::peripheral::SCB::sys_reset()
}

/// USART1 transmit half.
pub type SerialTx = usart::Tx;
/// USART1 receive half.
pub type SerialRx = usart::Rx;

/// The board's parts.
pub type Parts = crate::Parts<Sensors, Heaters, Iwdg, SerialTx, SerialRx>;

/// Sets up the time source and USART1 around the firmware's simulated `link`.
pub fn init(link: &'static dyn SimulatedLink) -> Parts {
    let csr = pac::RCC.csr().read();
    let last_fatal = crate::reset_record::take();
    let mut reset_flags = ResetFlags {
        watchdog: csr.iwdgrstf(),
        window_watchdog: csr.wwdgrstf(),
        software: csr.sftrstf(),
        low_power: csr.lpwrrstf(),
        power_on: csr.borrstf(),
        pin: csr.pinrstf(),
    };
    // QEMU sets no reset flags; the record says which reset the firmware asked for.
    match last_fatal.map(|f| f.kind) {
        Some(FatalKind::Watchdog) => reset_flags.watchdog = true,
        Some(FatalKind::Fault) => reset_flags.software = true,
        None => {}
    }
    critical_section::with(|cs| LINK.borrow(cs).set(Some(link)));
    heater_pins_low();
    time_driver::start(CPU_HZ, SPEEDUP, watchdog_check);
    let (tx, rx) = usart::init(CPU_HZ, crate::BAUD);
    crate::Parts {
        sensors: Sensors(link),
        heaters: Heaters(link),
        watchdog: Iwdg(()),
        tx,
        rx,
        reset_flags,
        last_fatal,
        settings_flash: (),
    }
}
