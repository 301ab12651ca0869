//! embassy-time driver on the Cortex-M SysTick, for QEMU where the STM32 timers are not
//! modelled. One SysTick interrupt per firmware millisecond; the reload is shortened by the
//! speed-up factor, so firmware time runs that many times faster than wall time. `now()` is in
//! embassy ticks (1 MHz), interpolated within the millisecond from the SysTick counter.

use core::cell::{Cell, RefCell};
use core::task::Waker;
use cortex_m::peripheral::SYST;
use critical_section::Mutex;
use embassy_time_driver::Driver;
use embassy_time_queue_utils::Queue;

const SYST_CSR_ENABLE: u32 = 1 << 0;
const SYST_CSR_TICKINT: u32 = 1 << 1;
const SYST_CSR_CLKSOURCE_CORE: u32 = 1 << 2;

/// embassy ticks per firmware millisecond (embassy-time's default 1 MHz tick).
const TICKS_PER_MS: u64 = embassy_time_driver::TICK_HZ / 1000;

/// Called every firmware millisecond with the time in ms.
type MsHook = fn(u64);

struct SysTickDriver {
    ms: Mutex<Cell<u64>>,
    reload: Mutex<Cell<u32>>,
    queue: Mutex<RefCell<Queue>>,
    on_ms: Mutex<Cell<Option<MsHook>>>,
}

impl Driver for SysTickDriver {
    fn now(&self) -> u64 {
        critical_section::with(|cs| {
            let ms = self.ms.borrow(cs).get();
            let reload = self.reload.borrow(cs).get().max(1);
            // SysTick counts down from `reload`; a pending wrap means the millisecond is over.
            let current = SYST::get_current();
            let pending = cortex_m::peripheral::SCB::is_pendst_pending();
            let (ms, elapsed) = if pending {
                (ms + 1, 0)
            } else {
                (ms, reload - current.min(reload))
            };
            ms * TICKS_PER_MS + u64::from(elapsed) * TICKS_PER_MS / u64::from(reload)
        })
    }

    fn schedule_wake(&self, at: u64, waker: &Waker) {
        critical_section::with(|cs| {
            self.queue.borrow(cs).borrow_mut().schedule_wake(at, waker);
        });
    }
}

embassy_time_driver::time_driver_impl!(static DRIVER: SysTickDriver = SysTickDriver {
    ms: Mutex::new(Cell::new(0)),
    reload: Mutex::new(Cell::new(1)),
    queue: Mutex::new(RefCell::new(Queue::new())),
    on_ms: Mutex::new(Cell::new(None)),
});

/// Starts SysTick: one interrupt per firmware millisecond at `speedup`× real time for a core
/// clock of `cpu_hz`; `on_ms` runs in every interrupt with the firmware time in ms.
pub fn start(cpu_hz: u32, speedup: u32, on_ms: fn(u64)) {
    let reload = cpu_hz / 1000 / speedup.max(1);
    critical_section::with(|cs| {
        DRIVER.reload.borrow(cs).set(reload);
        DRIVER.on_ms.borrow(cs).set(Some(on_ms));
    });
    // SAFETY: the firmware owns SysTick and nothing else configures it; raw register writes
    // leave `cortex_m::Peripherals::take` to the firmware's main.
    unsafe {
        let syst = &*SYST::PTR;
        syst.rvr.write(reload - 1);
        syst.cvr.write(0);
        syst.csr
            .write(SYST_CSR_CLKSOURCE_CORE | SYST_CSR_TICKINT | SYST_CSR_ENABLE);
    }
}

#[cortex_m_rt::exception]
fn SysTick() {
    let (now_ms, hook) = critical_section::with(|cs| {
        let ms = DRIVER.ms.borrow(cs).get() + 1;
        DRIVER.ms.borrow(cs).set(ms);
        let mut q = DRIVER.queue.borrow(cs).borrow_mut();
        q.next_expiration(ms * TICKS_PER_MS);
        (ms, DRIVER.on_ms.borrow(cs).get())
    });
    if let Some(f) = hook {
        f(now_ms);
    }
}
