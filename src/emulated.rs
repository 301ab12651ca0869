//! The emulated board's simulated links (firmware only, declared by `main.rs` for the
//! `board-b-l475e-iot01a-emulated` feature): per link the nominal lumped plant on the core's
//! simulated board ([`morphlink::bench`]: the host rig's board, with its supply cut-off and
//! its heaters' current sense), kept here and lent to the board's ADC, PWM and cut-off
//! stand-ins through `morphlink_boards::emulated::SimulatedLink`. The plants run at firmware
//! time; an image of several links ([`crate::LINKS`]) gives each link its own bench and supply
//! (the shared bench supply that sags is the host's, `morphlink_sim::MultiRig`).

use crate::LINKS;
use core::cell::RefCell;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::blocking_mutex::Mutex;
use morphlink::bench::{Bench, Noise, NOMINAL_LINK};
use morphlink::controller::{Config, Outputs};
use morphlink::protocol::SimCommand;
use morphlink_boards::emulated::SimulatedLink;
use morphlink_boards::{CurrentSums, INPUTS};
use morphlink_plant::Lumped;

/// The bench, the time it was last advanced to, and the currents of the last frame read.
struct State {
    bench: Bench<Lumped>,
    last_ms: u64,
    /// When the tick's last thermistor read was taken, ms: its currents are sampled then.
    last_read_ms: u64,
}

impl State {
    /// Lets the link run from its last time to `now_ms` under the duties its output stage
    /// applied then (they expire if the control task stops refreshing them).
    fn advance_to(&mut self, now_ms: u64) {
        if now_ms > self.last_ms {
            let dt_s = (now_ms - self.last_ms) as f64 / 1000.0;
            self.bench.run(self.last_ms, dt_s);
            self.last_ms = now_ms;
        }
    }
}

static STATE: Mutex<CriticalSectionRawMutex, RefCell<Option<[State; LINKS]>>> =
    Mutex::new(RefCell::new(None));

/// Runs `f` on link `k`'s state (a link past the image's is link 0's: the board asks only for
/// the image's links).
fn with_state<R>(k: usize, f: impl FnOnce(&mut State) -> R) -> R {
    STATE.lock(|s| {
        let mut s = s.borrow_mut();
        let states = s.as_mut().expect("set up by init");
        f(&mut states[if k < LINKS { k } else { 0 }])
    })
}

/// The simulated links the board reads and drives.
pub struct Link;

/// The one instance, lent to the board.
pub static LINK: Link = Link;

impl SimulatedLink for Link {
    fn read(&self, link: usize, now_ms: u64) -> [u16; INPUTS] {
        with_state(link, |s| {
            s.advance_to(now_ms);
            // The currents once a tick (`currents`), not with each of the sixteen reads: the
            // bench's noise is software double precision on this CPU.
            let i = s.bench.thermistor_inputs(now_ms);
            s.last_read_ms = now_ms;
            let c = i.thermistor_counts;
            [c[0], c[1], c[2], i.supply_counts].map(|v| v.min(u16::MAX as u32) as u16)
        })
    }

    fn currents(&self, link: usize) -> Option<CurrentSums> {
        with_state(link, |s| {
            let at_ms = s.last_read_ms;
            s.bench.current_counts(at_ms).map(|c| CurrentSums {
                on: c.on,
                off: c.off,
            })
        })
    }

    fn apply(&self, link: usize, now_ms: u64, pla_duty: f32, tca_duty: f32, supply_on: bool) {
        with_state(link, |s| {
            s.advance_to(now_ms);
            let out = Outputs {
                pla_duty,
                tca_duty,
                supply_on,
            };
            s.bench.drive(now_ms, out);
        });
    }

    fn heaters_off(&self) {
        STATE.lock(|s| {
            if let Ok(mut s) = s.try_borrow_mut() {
                for s in s.iter_mut().flatten() {
                    s.bench.heaters_off();
                }
            }
        });
    }
}

/// Builds each nominal link at rest, read through the default board's ADC model; call before
/// the board starts.
pub fn init() -> &'static Link {
    STATE.lock(|s| {
        *s.borrow_mut() = Some(core::array::from_fn(|_| State {
            bench: Bench::new(Lumped::new(NOMINAL_LINK), Config::DEFAULT, Noise::NOMINAL),
            last_ms: 0,
            last_read_ms: 0,
        }))
    });
    &LINK
}

/// Carries out a `SIM` command on simulated link `link` (0-based) at firmware time `now_ms`;
/// `SIM PANIC` panics on purpose, to prove the panic path, and `SIM STALL` stops the tasks, to
/// prove the watchdog.
pub fn sim_command(link: usize, now_ms: u64, cmd: SimCommand, out: &mut dyn FnMut(&str)) {
    if cmd == SimCommand::Panic {
        panic!("SIM PANIC asked for a panic");
    }
    if cmd == SimCommand::Stall {
        // Thread mode stops here: neither task runs again, so the control task stops feeding
        // the watchdog, which fires from the SysTick interrupt (heaters off, reset).
        loop {
            cortex_m::asm::nop();
        }
    }
    with_state(link, |s| {
        s.advance_to(now_ms);
        s.bench.command(cmd, &mut |l| out(l));
    });
}

/// The emulated board's settings flash: QEMU's STM32L475 flash is read-only to the firmware (its
/// model ignores the flash controller's program and erase commands), so the settings live in
/// a RAM flash in cortex-m-rt's `.uninit` section, which the start-up code neither loads nor
/// zeroes: SAVE survives a reset (`SIM PANIC`, the watchdog), not a restart of QEMU.
pub type SettingsFlash = morphlink::settings::ram_flash::RamFlash<4096, 2048, 8>;

/// The emulated settings area: the whole [`SettingsFlash`], two 2 KiB pages as on the L475
/// (one such flash per link: each link keeps its own settings).
pub const SETTINGS_AREA: core::ops::Range<u32> = 0..4096;

/// Marks a [`SettingsFlash`] the firmware set up; anything else is power-on garbage.
const FLASH_MAGIC: u32 = 0x4D4C_5346; // "MLSF"

#[repr(C)]
struct KeptFlash {
    magic: u32,
    flash: [SettingsFlash; LINKS],
}

struct FlashSlot(core::cell::UnsafeCell<core::mem::MaybeUninit<KeptFlash>>);

// SAFETY: taken once, at boot, before the tasks start (see `settings_flash`).
unsafe impl Sync for FlashSlot {}

#[link_section = ".uninit.morphlink_settings"]
static FLASH_SLOT: FlashSlot =
    FlashSlot(core::cell::UnsafeCell::new(core::mem::MaybeUninit::uninit()));

/// Each link's settings flash, kept across resets: erased at the first boot after power-on
/// (no magic), as it was otherwise. Call once.
pub fn settings_flash() -> &'static mut [SettingsFlash; LINKS] {
    static TAKEN: core::sync::atomic::AtomicBool = core::sync::atomic::AtomicBool::new(false);
    assert!(
        !TAKEN.swap(true, core::sync::atomic::Ordering::Relaxed),
        "taken once"
    );
    let kept = FLASH_SLOT.0.get() as *mut KeptFlash;
    // SAFETY: taken once (above), so this is the only reference; every bit pattern is a valid
    // `KeptFlash` (integers and bytes only), so reading what a previous run left is sound.
    unsafe {
        let magic = core::ptr::addr_of!((*kept).magic).read_volatile();
        if magic != FLASH_MAGIC {
            let first = core::ptr::addr_of_mut!((*kept).flash) as *mut SettingsFlash;
            for k in 0..LINKS {
                first.add(k).write(SettingsFlash::new());
            }
            core::ptr::addr_of_mut!((*kept).magic).write_volatile(FLASH_MAGIC);
        }
        &mut (*kept).flash
    }
}
