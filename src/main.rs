//! Firmware entry point: the thin shell that moves data between the board and the
//! hardware-free core. Builds only for the target (`thumbv7em-none-eabihf`); on the host it
//! prints how to build it.
//!
//! A `start` task boots (the board, the core and its settings) and spawns the two that then
//! share the core: one [`morphlink::controller::Controller`], or with the `links-2` feature a
//! `morphlink::links::Links` of two (both behind `morphlink::session::Served`):
//! - `control`, every [`TICK_MS`] (10 Hz): ADC burst (16 samples per input), then the heaters'
//!   currents where the board senses them (16 readings inside the pulses and between them) →
//!   `Controller::step` → PWM duties and the supply's cut-off; feeds the watchdog; records its
//!   timing for `STATS`.
//! - `serial`: bytes from the board's serial port → `morphlink::session::Session` (line
//!   assembly, ABORT first, replies built or dropped and counted, events and alarms) → the
//!   port; it signals the control task to apply the duties at once after an ABORT and carries
//!   out a SAVE the session hands it. Every decision is the session's, host-tested.
//!
//! Both are written once against the board traits of `morphlink-boards`; the board (pins,
//! clocks, memory) is the one its `board-*` feature selects.
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

#[cfg(all(
    target_os = "none",
    not(any(
        feature = "board-nucleo-f401re",
        feature = "board-nucleo-g431rb",
        feature = "board-b-l475e-iot01a",
        feature = "board-b-l475e-iot01a-emulated"
    ))
))]
compile_error!("no board: build with exactly one `board-*` feature (see boards/README.md)");

#[cfg(all(target_os = "none", feature = "links-2", not(emulated)))]
compile_error!(
    "`links-2`: only the emulated board is wired for two links yet (docs/multilink.md, \"Boards\")"
);

/// How many links this image drives: two with the `links-2` feature (the emulated board),
/// one otherwise. A one-link image serves its `Controller` directly, exactly as before several
/// links existed; several links are served by `morphlink::links::Links`.
#[cfg(target_os = "none")]
pub const LINKS: usize = if cfg!(feature = "links-2") { 2 } else { 1 };

#[cfg(all(target_os = "none", emulated))]
mod emulated;

#[cfg(target_os = "none")]
mod firmware {
    use crate::LINKS;
    use core::cell::RefCell;
    use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};
    use defmt_rtt as _;
    use embassy_executor::{Executor, Spawner};
    use embassy_futures::select::{select, select3, Either, Either3};
    use embassy_futures::yield_now;
    use embassy_sync::blocking_mutex::raw::ThreadModeRawMutex;
    use embassy_sync::blocking_mutex::Mutex;
    use embassy_sync::signal::Signal;
    use embassy_time::{Duration, Instant, Ticker, Timer};
    use embedded_io_async::Write;
    use morphlink::controller::{Config, Inputs, Outputs, OVERSAMPLE, TICK_MS};
    use morphlink::electrical::{CurrentCounts, ShuntSense};
    use morphlink::protocol::{reply, OutLine, SimCommand};
    use morphlink::session::{Served, Session, OUT_BYTES};
    use morphlink::settings::codec::LoadError;
    use morphlink::settings::store::{Loaded, SettingsStore};
    use morphlink::stats::{write_boot_line, LoopTiming};
    use morphlink::vocab::ResetCause;
    use morphlink_boards::selected as board;
    use morphlink_boards::{
        AnalogInputs, CurrentSense, HeaterOutputs, Input, LastFatal, Received, SerialReceive,
        Watchdog, INPUTS, SERIAL_RX_BYTES,
    };

    /// Spacing of the ADC samples in a tick's burst: 16 samples 1 ms apart span 16 ms, about
    /// one mains period, so 50/60 Hz pickup averages out (the G4 sums in hardware instead).
    const SAMPLE_SPACING: Duration = Duration::from_millis(1);

    /// Reads per input per tick: the core's oversampling over what the ADC sums in hardware.
    const READS_PER_TICK: u32 = OVERSAMPLE / board::HW_OVERSAMPLE;
    const _: () = assert!(READS_PER_TICK * board::HW_OVERSAMPLE == OVERSAMPLE);

    // The board's PWM and probe pulse are the ones the core's electrical checks assume.
    const _: () = assert!(
        morphlink_boards::PWM_HZ as f32 == morphlink::electrical::PWM_HZ
            && morphlink_boards::PROBE_PULSE_US as f32 == morphlink::electrical::MIN_SENSED_ON_US
    );

    /// The controller's board settings: the defaults, with this board's current-sense chain.
    const CONFIG: Config = Config {
        shunt: ShuntSense {
            shunt_ohm: board::SHUNT.shunt_ohm,
            gain: board::SHUNT.gain,
            ..ShuntSense::DEFAULT
        },
        ..Config::DEFAULT
    };

    /// What the tasks serve: the one link's controller.
    #[cfg(not(feature = "links-2"))]
    type Core = morphlink::controller::Controller;
    /// What the tasks serve: the board's links.
    #[cfg(feature = "links-2")]
    type Core = morphlink::links::Links<LINKS>;

    /// The core at rest, no budget set.
    fn new_core() -> Core {
        #[cfg(not(feature = "links-2"))]
        let core = Core::new(CONFIG);
        #[cfg(feature = "links-2")]
        let core = Core::new(CONFIG, LINKS);
        core
    }

    /// The core, shared by the two tasks. Both run in the same thread-mode executor, so the
    /// lock never contends and never masks interrupts (the UART interrupt keeps running while
    /// the control task steps).
    static CONTROLLER: Mutex<ThreadModeRawMutex, RefCell<Slot>> =
        Mutex::new(RefCell::new(Slot::Empty));

    /// The controller's place: empty until `main` sets it up. An explicit zero tag (not
    /// `Option`, whose niche made the empty value non-zero) lets the 3.5 KiB static start
    /// zeroed in `.bss` instead of being an image in flash copied to `.data`.
    #[repr(u8)]
    enum Slot {
        Empty = 0,
        Ready(Core) = 1,
    }

    /// Control → serial: new event or alarm lines may be queued.
    static EVENTS: Signal<ThreadModeRawMutex, ()> = Signal::new();

    /// Serial → control: a command changed the duties (ABORT); apply them now, not next tick.
    static APPLY_NOW: Signal<ThreadModeRawMutex, ()> = Signal::new();

    /// Runs `f` on the core, briefly holding the lock.
    fn with_core<R>(f: impl FnOnce(&mut Core) -> R) -> R {
        CONTROLLER.lock(|c| match &mut *c.borrow_mut() {
            Slot::Ready(c) => f(c),
            Slot::Empty => panic!("set up in main"),
        })
    }

    /// The settings flash: the chip's own; on the emulated board the firmware's RAM flash
    /// that survives a reset (QEMU's flash cannot be written).
    #[cfg(not(emulated))]
    type SettingsFlash = board::SettingsFlash;
    #[cfg(emulated)]
    type SettingsFlash = &'static mut crate::emulated::SettingsFlash;

    /// Each link's settings store over its settings area (`None` if the area is unusable: the
    /// defaults then hold and SAVE is unsupported).
    #[cfg(not(emulated))]
    fn settings_stores(flash: board::SettingsFlash) -> Stores {
        [SettingsStore::new(flash, morphlink_boards::settings_area()).ok()]
    }
    #[cfg(emulated)]
    fn settings_stores(_: ()) -> Stores {
        let mut flashes = crate::emulated::settings_flash().iter_mut();
        core::array::from_fn(|_| {
            let f = flashes.next()?;
            SettingsStore::new(f, crate::emulated::SETTINGS_AREA).ok()
        })
    }

    /// The settings stores the serial task carries out SAVE with, one per link.
    type Stores = [Option<SettingsStore<SettingsFlash>>; LINKS];

    /// Puts link `k`'s settings loaded at boot in force, range-checked, or the defaults and why
    /// (`loaded`), and tells it whether SAVE has somewhere to write (`storage`).
    fn put_settings(k: usize, loaded: Result<Loaded, LoadError>, storage: bool) {
        with_core(|c| {
            let c = c.link_mut(k);
            c.load_settings(loaded);
            if storage {
                c.enable_storage();
            }
        });
    }

    /// Link `k`'s settings store, if it has one (a one-link image without an index: its
    /// bounds check cost flash the image does not have).
    #[inline(always)]
    fn store_of(stores: &mut Stores, k: usize) -> Option<&mut SettingsStore<SettingsFlash>> {
        #[cfg(not(feature = "links-2"))]
        let [store] = stores;
        #[cfg(not(feature = "links-2"))]
        let _ = k;
        #[cfg(feature = "links-2")]
        let store = stores.get_mut(k)?;
        store.as_mut()
    }

    /// The board's parts; the emulated board gets the firmware's simulated link.
    fn board_parts() -> board::Parts {
        #[cfg(emulated)]
        return board::init(crate::emulated::init());
        #[cfg(not(emulated))]
        board::init()
    }

    /// Where `SIM` commands go: the simulated link on the emulated board; on hardware the
    /// core's `error: unsupported` reply.
    fn sim_command(
        c: &mut Core,
        now_ms: u64,
        (k, sim): (usize, SimCommand),
        out: &mut dyn FnMut(&str),
    ) {
        #[cfg(emulated)]
        {
            let _ = c;
            crate::emulated::sim_command(k, now_ms, sim, out);
        }
        #[cfg(not(emulated))]
        c.link_mut(k)
            .handle(now_ms, morphlink::protocol::Command::Sim(sim), &mut |l| {
                out(l)
            });
    }

    /// The entry: the thread-mode executor, its one task [`start`] spawned. Written out rather
    /// than `#[embassy_executor::main]`, whose `unwrap()` of that spawn would carry
    /// `SpawnError`'s Debug text in flash for a panic that cannot happen.
    #[cortex_m_rt::entry]
    fn main() -> ! {
        let executor = cortex_m::singleton!(: Executor = Executor::new())
            .unwrap_or_else(|| panic!("entered once"));
        executor
            .run(|spawner| spawner.spawn(start(spawner).unwrap_or_else(|_| panic!("spawned once"))))
    }

    /// Boot: the board, the core and its settings, then the control and serial tasks.
    #[embassy_executor::task]
    async fn start(spawner: Spawner) {
        let parts = board_parts();
        let cause = ResetCause::from_flags(parts.reset_flags);
        defmt::info!(
            "morphlink {} on {}: reset cause {}",
            morphlink::controller::VERSION,
            board::NAME,
            cause.as_str()
        );

        // Built in its static, not in `start`'s future: held across the settings load below it
        // would take its 3.5 KiB again in the task's RAM.
        CONTROLLER.lock(|c| *c.borrow_mut() = Slot::Ready(new_core()));
        with_core(|c| {
            c.link_mut(0).enable_timing(LoopTiming::new(
                board::CPU_HZ,
                TICK_MS as u32 * 1000,
                cause,
            ))
        });
        // Each link's stored settings, range-checked, or the defaults and why; before the
        // control task starts, and heaters stay off whatever it finds.
        let mut stores = settings_stores(parts.settings_flash);
        // A one-link image loads its one store without a loop: an await inside a loop costs its
        // future some 90 B of flash, which the L475 image does not have.
        #[cfg(not(feature = "links-2"))]
        {
            let [store] = &mut stores;
            let loaded = match store {
                Some(s) => s.load().await,
                None => Err(LoadError::Flash),
            };
            put_settings(0, loaded, store.is_some());
        }
        #[cfg(feature = "links-2")]
        {
            for (k, store) in stores.iter_mut().enumerate() {
                let loaded = match store {
                    Some(s) => s.load().await,
                    None => Err(LoadError::Flash),
                };
                put_settings(k, loaded, store.is_some());
            }
            // The supply's settings, kept with link 1's, once every link's calibration is in.
            let board = match &mut stores[0] {
                Some(s) => s.load_board().await.map_err(|_| ()),
                None => Ok(None),
            };
            with_core(|c| c.load_board(board.as_ref().map(|b| b.as_deref()).map_err(|_| ())));
        }

        let mut boot = OutLine::new();
        write_boot_line(&mut boot, cause, board::NAME);
        if let Some(f) = parts.last_fatal.as_ref().map(LastFatal::reason) {
            defmt::warn!("the previous run ended: {=str}", f);
            reply::boot_panic(&mut boot, f);
        }

        // Not `expect`: SpawnError's Debug text would be carried in flash for a panic that
        // cannot happen (each task is spawned once).
        let control = control(parts.sensors, parts.heaters, parts.watchdog);
        spawner.spawn(control.unwrap_or_else(|_| panic!("spawned once")));
        let serial = serial(parts.tx, parts.rx, boot, stores);
        spawner.spawn(serial.unwrap_or_else(|_| panic!("spawned once")));
    }

    #[embassy_executor::task]
    async fn control(sensors: board::Sensors, heaters: board::Heaters, wdg: board::Iwdg) {
        control_loop(sensors, heaters, wdg).await
    }

    #[embassy_executor::task]
    async fn serial(tx: board::SerialTx, rx: board::SerialRx, boot: OutLine, stores: Stores) {
        serial_loop(tx, rx, boot, stores).await
    }

    /// Sums [`READS_PER_TICK`] reads of every link's inputs, [`SAMPLE_SPACING`] apart (every
    /// link in each read, so the burst spans 16 ms however many links there are).
    async fn read_burst(sensors: &mut impl AnalogInputs) -> [[u32; INPUTS]; LINKS] {
        let mut sums = [[0u32; INPUTS]; LINKS];
        for i in 0..READS_PER_TICK {
            if i > 0 {
                Timer::after(SAMPLE_SPACING).await;
            }
            for (k, link) in sums.iter_mut().enumerate() {
                for (s, v) in link.iter_mut().zip(sensors.read_link(k)) {
                    *s += u32::from(v);
                }
            }
        }
        sums
    }

    /// Drives link `k`'s heaters and cut-off as `o` says.
    fn drive(heaters: &mut impl HeaterOutputs, k: usize, o: Outputs) {
        heaters.apply_link(k, o.pla_duty, o.tca_duty, o.supply_on);
    }

    /// Milliseconds since boot. Not embassy's `Instant::as_millis`: its `u64` division is a
    /// software routine of about 1 KiB of flash on the Cortex-M4, which this one avoids
    /// ([`morphlink::fixed::div_rem_small`]).
    pub fn now_ms() -> u64 {
        ms_of(Instant::now().as_ticks())
    }

    /// `ticks` of embassy's time driver in whole milliseconds.
    fn ms_of(ticks: u64) -> u64 {
        const PER_MS: core::num::NonZeroU16 =
            core::num::NonZeroU16::new((embassy_time::TICK_HZ / 1000) as u16).unwrap();
        const _: () = assert!(
            embassy_time::TICK_HZ % 1000 == 0 && embassy_time::TICK_HZ / 1000 <= u16::MAX as u64
        );
        morphlink::fixed::div_rem_small(ticks, PER_MS).0
    }

    /// When the control loop's last tick started, ms (the low 32 bits of [`Instant`]): the
    /// serial task keeps out of the window before the next one ([`SERIAL_GUARD_MS`]).
    static TICK_STARTED_MS: AtomicU32 = AtomicU32::new(0);

    /// The serial task starts no pass this close before a control tick is due, ms: a pass
    /// (a line answered, a chunk written) then never holds a tick's start up. Each tick's ADC
    /// burst gives the serial task the CPU again. The floods of docs/emulation.md measure it.
    const SERIAL_GUARD_MS: u32 = 15;
    const _: () = assert!(SERIAL_GUARD_MS < TICK_MS as u32 / 4);

    /// The wait out of the window before the next control tick, if now is in it.
    #[inline(never)]
    fn tick_window_wait() -> Option<Timer> {
        let now = now_ms() as u32;
        let since = now.wrapping_sub(TICK_STARTED_MS.load(Ordering::Relaxed));
        let to_next = (TICK_MS as u32).saturating_sub(since % TICK_MS as u32);
        (to_next <= SERIAL_GUARD_MS).then(|| Timer::after_millis(u64::from(to_next) + 1))
    }

    /// The control loop at [`TICK_MS`]; the only feeder of the watchdog.
    async fn control_loop(
        mut sensors: impl AnalogInputs + CurrentSense,
        mut heaters: impl HeaterOutputs,
        mut wdg: impl Watchdog,
    ) {
        wdg.start();
        let mut ticker = Ticker::every(Duration::from_millis(TICK_MS));
        loop {
            if let Either::Second(()) = select(ticker.next(), APPLY_NOW.wait()).await {
                for k in 0..LINKS {
                    drive(&mut heaters, k, with_core(|c| c.link_outputs(k)));
                }
                continue;
            }
            let start = board::cycles();
            TICK_STARTED_MS.store(now_ms() as u32, Ordering::Relaxed);
            // The frame is stamped when its ADC burst starts, not when the step runs: a burst
            // that stalls (a hung ADC, a starved task) then arrives old, and the supervisor's
            // stale-sensor check (`STALE_AFTER_MS`) refuses it.
            let sample_ms = now_ms();
            let sums = read_burst(&mut sensors).await;
            let mut inputs = [Inputs {
                thermistor_counts: [0; 3],
                supply_counts: 0,
                sample_ms,
                current: None,
            }; LINKS];
            for (k, i) in inputs.iter_mut().enumerate() {
                i.thermistor_counts = [
                    sums[k][Input::PlaThermistor as usize],
                    sums[k][Input::TcaThermistor as usize],
                    sums[k][Input::AmbThermistor as usize],
                ];
                i.supply_counts = sums[k][Input::Supply as usize];
                i.current =
                    sensors
                        .read_link_currents(k, OVERSAMPLE)
                        .await
                        .map(|c| CurrentCounts {
                            on: c.on,
                            off: c.off,
                        });
            }
            let adc_done = board::cycles();
            let now_ms = now_ms();
            let mut outs = [Outputs::default(); LINKS];
            with_core(|c| c.tick(now_ms, &inputs, &mut outs));
            for (k, o) in outs.into_iter().enumerate() {
                drive(&mut heaters, k, o);
            }
            let applied = board::cycles();
            wdg.feed();
            with_core(|c| c.link_mut(0).record_timing(start, adc_done, applied));
            EVENTS.signal(());
        }
    }

    /// The serial line: commands in, replies, events and alarms out. The decisions are the
    /// core's [`Session`]; this loop only moves bytes between it and the port, and carries out
    /// a SAVE.
    ///
    /// Input is never left waiting behind output: each pass answers at most one line, writes
    /// at most one chunk and yields, and waits on the port only for whichever of input, room
    /// to write or events comes first.
    async fn serial_loop(
        mut tx: impl Write,
        mut rx: impl SerialReceive,
        boot: OutLine,
        mut stores: Stores,
    ) {
        let mut session: Session<SERIAL_RX_BYTES, OUT_BYTES> = Session::new(&boot);
        loop {
            if let Some(wait) = tick_window_wait() {
                wait.await;
            }
            with_core(|c| session.refill(c));
            if session.has_input() {
                let now_ms = now_ms();
                let answered = with_core(|c| session.answer_next(c, now_ms, sim_command));
                if let Some(a) = answered {
                    if a.apply_now {
                        APPLY_NOW.signal(());
                    }
                    // SAVE: only ever handed out while nothing heats, so the CPU stalling on
                    // its flash during an erase or write holds no heater on.
                    if let Some((k, blob)) = a.save {
                        if let Some(s) = store_of(&mut stores, k) {
                            let t0 = Instant::now();
                            #[cfg_attr(not(feature = "links-2"), allow(unused_mut))]
                            let mut r = s.save(&blob).await;
                            // Several links: the supply's settings go with link 1's (a
                            // one-link image has none, and its flash no room for the code).
                            #[cfg(feature = "links-2")]
                            if let (Ok(_), Some(b)) = (&r, with_core(|c| c.board_record(k))) {
                                if let Err(e) = s.save_board(&b).await {
                                    r = Err(e);
                                }
                            }
                            defmt::info!("SAVE took {} ms", ms_of(t0.elapsed().as_ticks()));
                            with_core(|c| session.finish_save(c, r));
                        }
                    }
                }
                // Offer output without waiting for room, then let the control task run.
                if session.has_output() {
                    if let Either::First(r) = select(tx.write(session.output()), yield_now()).await
                    {
                        sent(&mut session, r);
                    }
                }
                yield_now().await;
                continue;
            }
            // Everything received is answered: wait for input, room to write, or events.
            let got: Option<Received> = if !session.has_output() {
                match select(rx.receive(session.buffer()), EVENTS.wait()).await {
                    Either::First(r) => Some(r),
                    Either::Second(()) => None,
                }
            } else {
                let (buffer, output) = session.buffer_and_output();
                match select3(rx.receive(buffer), tx.write(output), EVENTS.wait()).await {
                    Either3::First(r) => Some(r),
                    Either3::Second(r) => {
                        sent(&mut session, r);
                        yield_now().await;
                        None
                    }
                    Either3::Third(()) => None,
                }
            };
            if let Some(r) = got {
                let now_ms = now_ms();
                if with_core(|c| session.received(c, now_ms, r.len, r.lost_after)) {
                    APPLY_NOW.signal(());
                }
            }
        }
    }

    /// Drops what a write took from the output (a failed write drops the rest of its line,
    /// logged).
    fn sent<E, const R: usize, const N: usize>(s: &mut Session<R, N>, r: Result<usize, E>) {
        match r {
            Ok(n) => s.sent(n),
            Err(_) => {
                defmt::warn!("serial send error");
                s.send_failed();
            }
        }
    }

    /// Set by the first panic or HardFault, so a fault while logging it skips straight to the
    /// end instead of recursing.
    static FAULTED: AtomicBool = AtomicBool::new(false);

    /// Supply cut and heaters off first (raw writes), then one log line over RTT, then the
    /// board's fatal end: the reason recorded in RAM that survives the reset, then a system
    /// reset, reported at the next boot as `reset=software panic="<reason>"`.
    #[panic_handler]
    fn panic(info: &core::panic::PanicInfo) -> ! {
        board::heater_pins_low();
        if !FAULTED.swap(true, Ordering::Relaxed) {
            match info.location() {
                Some(l) => defmt::error!(
                    "panic at {=str}:{=u32}; heaters off, resetting",
                    l.file(),
                    l.line()
                ),
                None => defmt::error!("panic; heaters off, resetting"),
            }
        }
        match info.location() {
            Some(l) => board::fatal(format_args!(
                "panic at {}:{}: {}; heaters off",
                l.file(),
                l.line(),
                info.message()
            )),
            None => board::fatal(format_args!("panic: {}; heaters off", info.message())),
        }
    }

    /// As [`panic`], for faults the CPU raises (bus, memory, usage faults escalate here).
    #[cortex_m_rt::exception]
    unsafe fn HardFault(ef: &cortex_m_rt::ExceptionFrame) -> ! {
        board::heater_pins_low();
        if !FAULTED.swap(true, Ordering::Relaxed) {
            defmt::error!("HardFault at pc={=u32:#x}; heaters off, resetting", ef.pc());
        }
        board::fatal(format_args!("HardFault at pc={:#x}; heaters off", ef.pc()))
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "morphlink is firmware: flash it with `cargo fw` (the alias for `cargo run --release \
         --target thumbv7em-none-eabihf --bin morphlink`); on the host run \
         `cargo run -p morphlink-host --bin morph-sim` instead"
    );
    std::process::exit(2);
}

// Every defmt log line carries the firmware's uptime from embassy-time, in milliseconds
// (`probe-rs run` prints it in front of the message).
#[cfg(target_os = "none")]
defmt::timestamp!("{=u64:ms}", firmware::now_ms());
