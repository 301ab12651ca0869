//! The emulated board's simulated link (firmware only, declared by `main.rs` for the
//! `board-b-l475e-iot01a-emulated` feature): the nominal lumped plant on the core's simulated
//! board ([`morphlink::bench`]), kept here and lent to the board's ADC and PWM stand-ins
//! through `morphlink_boards::emulated::SimulatedLink`. The plant runs at firmware time.

use core::cell::RefCell;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::blocking_mutex::Mutex;
use morphlink::bench::{Bench, Noise, NOMINAL_LINK};
use morphlink::controller::{Config, Controller, Outputs};
use morphlink::protocol::SimCommand;
use morphlink_boards::emulated::SimulatedLink;
use morphlink_boards::INPUTS;
use morphlink_plant::Lumped;

/// The bench and the time it was last advanced to.
struct State {
    bench: Bench<Lumped>,
    last_ms: u64,
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

static STATE: Mutex<CriticalSectionRawMutex, RefCell<Option<State>>> =
    Mutex::new(RefCell::new(None));

fn with_state<R>(f: impl FnOnce(&mut State) -> R) -> R {
    STATE.lock(|s| f(s.borrow_mut().as_mut().expect("set up by init")))
}

/// The simulated link the board reads and drives.
pub struct Link;

/// The one instance, lent to the board.
pub static LINK: Link = Link;

impl SimulatedLink for Link {
    fn read(&self, now_ms: u64) -> [u16; INPUTS] {
        with_state(|s| {
            s.advance_to(now_ms);
            let i = s.bench.inputs(now_ms);
            let c = i.thermistor_counts;
            [c[0], c[1], c[2], i.supply_counts].map(|v| v.min(u16::MAX as u32) as u16)
        })
    }

    fn apply(&self, now_ms: u64, pla_duty: f32, tca_duty: f32) {
        with_state(|s| {
            s.advance_to(now_ms);
            s.bench.drive(now_ms, Outputs { pla_duty, tca_duty });
        });
    }

    fn heaters_off(&self) {
        STATE.lock(|s| {
            if let Ok(mut s) = s.try_borrow_mut() {
                if let Some(s) = s.as_mut() {
                    s.bench.heaters_off();
                }
            }
        });
    }
}

/// Builds the nominal link at rest, read through the default board's ADC model; call before
/// the board starts.
pub fn init() -> &'static Link {
    STATE.lock(|s| {
        *s.borrow_mut() = Some(State {
            bench: Bench::new(Lumped::new(NOMINAL_LINK), Config::DEFAULT, Noise::NOMINAL),
            last_ms: 0,
        })
    });
    &LINK
}

/// Carries out a `SIM` command on the simulated link at firmware time `now_ms`; `SIM PANIC`
/// panics on purpose, to prove the panic path, and `SIM STALL` stops the tasks, to prove the
/// watchdog.
pub fn sim_command(_: &mut Controller, now_ms: u64, cmd: SimCommand, out: &mut impl FnMut(&str)) {
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
    with_state(|s| {
        s.advance_to(now_ms);
        s.bench.command(cmd, out);
    });
}
