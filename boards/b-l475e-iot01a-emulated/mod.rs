//! B-L475E-IOT01A under QEMU (`qemu-system-arm -M b-l475e-iot01a`): the same firmware — core,
//! control and serial tasks, protocol — with only the pieces QEMU does not model replaced:
//!
//! | on hardware | here | why |
//! | --- | --- | --- |
//! | TIM2 embassy time driver | [`time_driver`]: SysTick, running [`SPEEDUP`]× real time | QEMU models no STM32 timers |
//! | `embassy_stm32::init` (HSI → PLL 80 MHz) | reset clock (MSI 4 MHz), no init | init waits forever for PWR/RCC ready bits QEMU never sets |
//! | ADC1 thermistors and supply | [`Sensors`]: the simulated link's ADC model | QEMU's ADC never becomes ready |
//! | TIM3 PWM heaters | [`HeaterDriver`]: duties into the simulated link | no timers |
//! | buffered USART1 (embassy) | [`usart`]: register-level USART1 with an RX interrupt | QEMU's USART needs 32-bit accesses and never sets IDLE |
//! | IWDG | [`Watchdog`]: the same 500 ms rule checked in the SysTick interrupt | no IWDG model |
//! | panic/HardFault → reset | heaters off, message on the semihosting console, QEMU exits 1 | a test must see it |
//!
//! The simulated link is `sim/src/link.rs`, compiled into this image unchanged: the very code
//! `morph-sim` and the host tests run. Its time is the firmware's time, so a whole morph runs
//! [`SPEEDUP`] times faster than real time.

use core::cell::RefCell;
use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use embassy_stm32::pac;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::blocking_mutex::Mutex;
use morphlink::controller::{Config, Outputs};
use morphlink::protocol::SimCommand;
use morphlink::stats::ResetFlags;

#[path = "../../sim/src/link.rs"]
#[allow(dead_code)]
mod sim_link;
mod time_driver;
pub mod usart;

use sim_link::{Plant, SimLink};

/// Board name, as in the feature and the boot line.
pub const NAME: &str = "b-l475e-iot01a-emulated";
/// Core clock after reset (MSI), Hz: the SysTick reference in QEMU.
pub const CPU_HZ: u32 = 4_000_000;
/// The simulated ADC returns the 16× oversampled sums directly, as the G4's hardware does.
pub const HW_OVERSAMPLE: u32 = 16;
/// Firmware time runs this many times faster than wall-clock time: a 100 ms control tick takes
/// 5 ms of wall time, so a whole morph finishes in seconds. QEMU keeps up easily: one tick is a
/// few thousand emulated instructions.
pub const SPEEDUP: u32 = 20;
/// Watchdog timeout, firmware ms: as the hardware IWDG's 500 ms.
pub const WATCHDOG_MS: u64 = 500;

/// The simulated link with the duties last applied and the time it was last advanced to.
struct SimState {
    link: SimLink,
    duties: Outputs,
    last_ms: u64,
}

impl SimState {
    /// Lets the link run from its last time to `now_ms` under the current duties.
    fn advance_to(&mut self, now_ms: u64) {
        if now_ms > self.last_ms {
            self.link
                .advance((now_ms - self.last_ms) as f64 / 1000.0, self.duties);
            self.last_ms = now_ms;
        }
    }
}

static SIM: Mutex<CriticalSectionRawMutex, RefCell<Option<SimState>>> =
    Mutex::new(RefCell::new(None));

fn with_sim<R>(f: impl FnOnce(&mut SimState) -> R) -> R {
    SIM.lock(|s| f(s.borrow_mut().as_mut().expect("set up in init")))
}

fn now_ms() -> u64 {
    embassy_time::Instant::now().as_millis()
}

/// Drives both heater gates low by raw register writes (PA6 and PA7, as on the hardware board)
/// and zeroes the simulated duties, whatever state the rest of the firmware is in.
pub fn heater_pins_low() {
    crate::force_low(pac::GPIOA, 6);
    crate::force_low(pac::GPIOA, 7);
    SIM.lock(|s| {
        if let Ok(mut s) = s.try_borrow_mut() {
            if let Some(s) = s.as_mut() {
                s.duties = Outputs::default();
            }
        }
    });
}

/// The simulated thermistor and supply inputs.
pub struct Sensors(());

impl Sensors {
    /// The PLA, TCA and ambient thermistors and the supply divider, as 16× oversampled sums.
    pub fn read(&mut self) -> [u16; 4] {
        with_sim(|s| {
            let now = now_ms();
            s.advance_to(now);
            let i = s.link.inputs(now);
            let c = i.thermistor_counts;
            [c[0], c[1], c[2], i.supply_counts].map(|v| v.min(u16::MAX as u32) as u16)
        })
    }
}

/// The simulated heaters: duties go into the link.
pub struct HeaterDriver(());

impl HeaterDriver {
    /// Applies both duties from now on.
    pub fn apply(&mut self, o: Outputs) {
        with_sim(|s| {
            s.advance_to(now_ms());
            s.duties = o;
        });
    }
}

static WDG_ARMED: AtomicBool = AtomicBool::new(false);
static WDG_LAST_PET_MS: AtomicU32 = AtomicU32::new(0);

/// Watchdog with the hardware IWDG's rule: once unleashed, a control task that stops petting it
/// for [`WATCHDOG_MS`] ends the run (heaters off, QEMU exits with failure).
pub struct Watchdog(());

impl Watchdog {
    /// Starts watching.
    pub fn unleash(&mut self) {
        WDG_LAST_PET_MS.store(now_ms() as u32, Ordering::Relaxed);
        WDG_ARMED.store(true, Ordering::Relaxed);
    }

    /// Proves the control task is alive.
    pub fn pet(&mut self) {
        WDG_LAST_PET_MS.store(now_ms() as u32, Ordering::Relaxed);
    }
}

/// Called from the SysTick interrupt every firmware millisecond.
fn watchdog_check(now_ms: u64) {
    let since_pet = (now_ms as u32).wrapping_sub(WDG_LAST_PET_MS.load(Ordering::Relaxed));
    if WDG_ARMED.load(Ordering::Relaxed) && u64::from(since_pet) > WATCHDOG_MS {
        heater_pins_low();
        fatal("watchdog: the control task stopped feeding the watchdog; heaters off");
    }
}

/// Prints `msg` on the semihosting console and ends QEMU with exit code 1.
pub fn fatal(msg: &str) -> ! {
    cortex_m_semihosting::hprintln!("{}", msg);
    cortex_m_semihosting::debug::exit(cortex_m_semihosting::debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}

/// Panic report on the semihosting console, then QEMU exits 1 (heaters are already off).
pub fn fatal_panic(info: &core::panic::PanicInfo) -> ! {
    cortex_m_semihosting::hprintln!("panic: {}; heaters off", info);
    fatal("firmware panicked")
}

/// Carries out a `SIM` command on the simulated link (at the current firmware time).
pub fn sim_command(cmd: SimCommand, out: &mut impl FnMut(&str)) {
    if cmd == SimCommand::Panic {
        panic!("SIM PANIC asked for a panic");
    }
    with_sim(|s| {
        s.advance_to(now_ms());
        s.link.command(cmd, out);
    });
}

/// The board's parts, ready for the tasks.
pub struct Board {
    /// Simulated inputs.
    pub sensors: Sensors,
    /// Simulated heaters (duties 0).
    pub heaters: HeaterDriver,
    /// USART1 transmit half.
    pub tx: usart::Tx,
    /// USART1 receive half.
    pub rx: usart::Rx,
    /// Watchdog, not started yet.
    pub watchdog: Watchdog,
    /// Reset flags as QEMU's RCC reports them.
    pub reset_flags: ResetFlags,
}

/// Sets up the time source, USART1 and the simulated link.
pub fn init() -> Board {
    let csr = pac::RCC.csr().read();
    let reset_flags = ResetFlags {
        watchdog: csr.iwdgrstf(),
        window_watchdog: csr.wwdgrstf(),
        software: csr.sftrstf(),
        low_power: csr.lpwrrstf(),
        power_on: csr.borrstf(),
        pin: csr.pinrstf(),
    };
    heater_pins_low();
    time_driver::start(CPU_HZ, SPEEDUP, watchdog_check);
    let board = Config::DEFAULT;
    SIM.lock(|s| {
        *s.borrow_mut() = Some(SimState {
            link: SimLink::new(Plant::NOMINAL, board),
            duties: Outputs::default(),
            last_ms: 0,
        })
    });
    let (tx, rx) = usart::init(CPU_HZ, crate::BAUD);
    Board {
        sensors: Sensors(()),
        heaters: HeaterDriver(()),
        tx,
        rx,
        watchdog: Watchdog(()),
        reset_flags,
    }
}
