//! Firmware entry point: the thin shell that moves data between the board and the
//! hardware-free core. Builds only for the target (`thumbv7em-none-eabihf`); on the host it
//! prints how to build it.
//!
//! Two embassy tasks share one [`morphlink::controller::Controller`]:
//! - `control`, every [`TICK_MS`] (10 Hz): ADC burst (16 samples per input) → `Controller::step`
//!   → PWM duties; feeds the watchdog; records its timing for `STATS`.
//! - `serial`: bytes from the board's serial port → `LineAssembler` →
//!   `Controller::handle_line` → replies; also writes queued events and alarms. Input is never
//!   left waiting behind output: replies queue in a bounded output buffer and are dropped (and
//!   counted, then reported in one `error: busy` line) when it is full; lost input marks its
//!   line as an overrun; an ABORT line is acted on as soon as its bytes are read.
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

#[cfg(all(target_os = "none", emulated))]
mod emulated;

#[cfg(target_os = "none")]
mod firmware {
    use core::cell::RefCell;
    use core::sync::atomic::{AtomicBool, Ordering};
    use defmt_rtt as _;
    use embassy_executor::Spawner;
    use embassy_futures::select::{select, select3, Either, Either3};
    use embassy_futures::yield_now;
    use embassy_sync::blocking_mutex::raw::ThreadModeRawMutex;
    use embassy_sync::blocking_mutex::Mutex;
    use embassy_sync::signal::Signal;
    use embassy_time::{Duration, Instant, Ticker, Timer};
    use embedded_io_async::Write;
    use morphlink::controller::{Config, Controller, Inputs, MAX_REPLY_BYTES, OVERSAMPLE, TICK_MS};
    use morphlink::protocol::{
        format_error, parse_line, reply, Assembled, Command, LineAssembler, OutLine, Overrun,
        SimCommand, ERR_INVALID_LINE, ERR_LINE_TOO_LONG,
    };
    use morphlink::settings::codec::LoadError;
    use morphlink::settings::store::SettingsStore;
    use morphlink::stats::{write_boot_line, LoopTiming};
    use morphlink::vocab::ResetCause;
    use morphlink_boards::selected as board;
    use morphlink_boards::{
        AnalogInputs, HeaterOutputs, Input, LastFatal, Received, SerialReceive, Watchdog, INPUTS,
        SERIAL_RX_BYTES,
    };

    /// Largest reply the serial task collects under the controller lock, bytes: the core's bound.
    const REPLY_BYTES: usize = MAX_REPLY_BYTES;

    /// Spacing of the ADC samples in a tick's burst: 16 samples 1 ms apart span 16 ms, about
    /// one mains period, so 50/60 Hz pickup averages out (the G4 sums in hardware instead).
    const SAMPLE_SPACING: Duration = Duration::from_millis(1);

    /// Reads per input per tick: the core's oversampling over what the ADC sums in hardware.
    const READS_PER_TICK: u32 = OVERSAMPLE / board::HW_OVERSAMPLE;
    const _: () = assert!(READS_PER_TICK * board::HW_OVERSAMPLE == OVERSAMPLE);

    /// The controller, shared by the two tasks. Both run in the same thread-mode executor, so
    /// the lock never contends and never masks interrupts (the UART interrupt keeps running
    /// while the control task steps).
    static CONTROLLER: Mutex<ThreadModeRawMutex, RefCell<Option<Controller>>> =
        Mutex::new(RefCell::new(None));

    /// Control → serial: new event or alarm lines may be queued.
    static EVENTS: Signal<ThreadModeRawMutex, ()> = Signal::new();

    /// Serial → control: a command changed the duties (ABORT); apply them now, not next tick.
    static APPLY_NOW: Signal<ThreadModeRawMutex, ()> = Signal::new();

    /// Runs `f` on the controller, briefly holding the lock.
    fn with_controller<R>(f: impl FnOnce(&mut Controller) -> R) -> R {
        CONTROLLER.lock(|c| f(c.borrow_mut().as_mut().expect("set up in main")))
    }

    /// The settings flash: the chip's own; on the emulated board the firmware's RAM flash
    /// that survives a reset (QEMU's flash cannot be written).
    #[cfg(not(emulated))]
    type SettingsFlash = board::SettingsFlash;
    #[cfg(emulated)]
    type SettingsFlash = &'static mut crate::emulated::SettingsFlash;

    /// The settings store over the board's settings area (`None` if the area is unusable: the
    /// defaults then hold and SAVE is unsupported).
    #[cfg(not(emulated))]
    fn settings_store(flash: board::SettingsFlash) -> Option<SettingsStore<SettingsFlash>> {
        SettingsStore::new(flash, morphlink_boards::settings_area()).ok()
    }
    #[cfg(emulated)]
    fn settings_store(_: ()) -> Option<SettingsStore<SettingsFlash>> {
        let flash = crate::emulated::settings_flash();
        SettingsStore::new(flash, crate::emulated::SETTINGS_AREA).ok()
    }

    /// The settings store the serial task carries out SAVE with.
    type Store = Option<SettingsStore<SettingsFlash>>;

    /// The board's parts; the emulated board gets the firmware's simulated link.
    fn board_parts() -> board::Parts {
        #[cfg(emulated)]
        return board::init(crate::emulated::init());
        #[cfg(not(emulated))]
        board::init()
    }

    /// Where `SIM` commands go: the simulated link on the emulated board; on hardware the
    /// core's `error: unsupported` reply.
    fn sim_command(c: &mut Controller, now_ms: u64, sim: SimCommand, out: &mut impl FnMut(&str)) {
        #[cfg(emulated)]
        crate::emulated::sim_command(c, now_ms, sim, out);
        #[cfg(not(emulated))]
        c.handle(now_ms, morphlink::protocol::Command::Sim(sim), out);
    }

    #[embassy_executor::main]
    async fn main(spawner: Spawner) {
        let parts = board_parts();
        let cause = ResetCause::from_flags(parts.reset_flags);
        defmt::info!(
            "morphlink {} on {}: reset cause {}",
            morphlink::controller::VERSION,
            board::NAME,
            cause.as_str()
        );

        let mut ctrl = Controller::new(Config::DEFAULT);
        ctrl.enable_timing(LoopTiming::new(board::CPU_HZ, TICK_MS as u32 * 1000, cause));
        // The stored settings, range-checked, or the defaults and why; before the control task
        // starts, and heaters stay off whatever it finds.
        let mut store = settings_store(parts.settings_flash);
        let loaded = match &mut store {
            Some(s) => s.load().await,
            None => Err(LoadError::Flash),
        };
        ctrl.load_settings(loaded);
        if store.is_some() {
            ctrl.enable_storage();
        }
        CONTROLLER.lock(|c| *c.borrow_mut() = Some(ctrl));

        let mut boot = OutLine::new();
        write_boot_line(&mut boot, cause, board::NAME);
        if let Some(f) = parts.last_fatal.as_ref().map(LastFatal::reason) {
            defmt::warn!("the previous run ended: {=str}", f);
            reply::boot_panic(&mut boot, f);
        }

        spawner.spawn(control(parts.sensors, parts.heaters, parts.watchdog).expect("spawned once"));
        spawner.spawn(serial(parts.tx, parts.rx, boot, store).expect("spawned once"));
    }

    #[embassy_executor::task]
    async fn control(sensors: board::Sensors, heaters: board::Heaters, wdg: board::Iwdg) {
        control_loop(sensors, heaters, wdg).await
    }

    #[embassy_executor::task]
    async fn serial(tx: board::SerialTx, rx: board::SerialRx, boot: OutLine, store: Store) {
        serial_loop(tx, rx, boot, store).await
    }

    /// Sums [`READS_PER_TICK`] reads of every input, [`SAMPLE_SPACING`] apart.
    async fn read_burst(sensors: &mut impl AnalogInputs) -> [u32; INPUTS] {
        let mut sums = [0u32; INPUTS];
        for i in 0..READS_PER_TICK {
            if i > 0 {
                Timer::after(SAMPLE_SPACING).await;
            }
            for (s, v) in sums.iter_mut().zip(sensors.read()) {
                *s += u32::from(v);
            }
        }
        sums
    }

    /// The control loop at [`TICK_MS`]; the only feeder of the watchdog.
    async fn control_loop(
        mut sensors: impl AnalogInputs,
        mut heaters: impl HeaterOutputs,
        mut wdg: impl Watchdog,
    ) {
        wdg.start();
        let mut ticker = Ticker::every(Duration::from_millis(TICK_MS));
        loop {
            if let Either::Second(()) = select(ticker.next(), APPLY_NOW.wait()).await {
                let o = with_controller(|c| c.outputs());
                heaters.apply(o.pla_duty, o.tca_duty);
                continue;
            }
            let start = board::cycles();
            // The frame is stamped when its ADC burst starts, not when the step runs: a burst
            // that stalls (a hung ADC, a starved task) then arrives old, and the supervisor's
            // stale-sensor check (`STALE_AFTER_MS`) refuses it.
            let sample_ms = Instant::now().as_millis();
            let sums = read_burst(&mut sensors).await;
            let adc_done = board::cycles();
            let now_ms = Instant::now().as_millis();
            let inputs = Inputs {
                thermistor_counts: [
                    sums[Input::PlaThermistor as usize],
                    sums[Input::TcaThermistor as usize],
                    sums[Input::AmbThermistor as usize],
                ],
                supply_counts: sums[Input::Supply as usize],
                sample_ms,
            };
            let o = with_controller(|c| c.step(now_ms, &inputs));
            heaters.apply(o.pla_duty, o.tca_duty);
            let applied = board::cycles();
            wdg.feed();
            with_controller(|c| c.record_timing(start, adc_done, applied));
            EVENTS.signal(());
        }
    }

    /// Appends `line` and a newline to `reply`; a line that does not fit is dropped (logged).
    fn push_line(reply: &mut heapless::String<REPLY_BYTES>, line: &str) {
        if reply
            .push_str(line)
            .and_then(|()| reply.push('\n'))
            .is_err()
        {
            defmt::warn!("reply longer than {} bytes; line dropped", REPLY_BYTES);
        }
    }

    /// Output waiting for the serial port, bytes: two of the longest replies (HELP).
    const OUT_BYTES: usize = 2 * REPLY_BYTES;
    /// Room kept free of replies for event and alarm lines and the dropped-replies notice:
    /// two maximal lines with their endings.
    const OUT_RESERVE: usize = 2 * LINE_ROOM;
    /// Room for one line and its ending: [`OutLine`]'s capacity and a newline.
    const LINE_ROOM: usize = 192 + 1;
    /// Most bytes handed to the serial port in one go before the serial task yields (a board
    /// may take fewer: the emulated port takes four, each a slow QEMU round trip).
    const TX_CHUNK: usize = 64;

    /// Replies, events and alarms waiting for the serial port, and the replies dropped
    /// because there was no room (their commands were run).
    struct Output {
        q: heapless::Deque<u8, OUT_BYTES>,
        dropped: u32,
    }

    impl Output {
        fn room(&self) -> usize {
            OUT_BYTES - self.q.len()
        }

        /// Queues all of `s` if at least `keep` bytes stay free after it; else nothing.
        fn offer(&mut self, s: &str, keep: usize) -> bool {
            if s.len() + keep > self.room() {
                return false;
            }
            for b in s.bytes() {
                let _ = self.q.push_back(b);
            }
            true
        }

        /// The oldest queued bytes, at most [`TX_CHUNK`].
        fn chunk(&self) -> &[u8] {
            let (a, _) = self.q.as_slices();
            &a[..a.len().min(TX_CHUNK)]
        }

        fn sent(&mut self, n: usize) {
            for _ in 0..n {
                self.q.pop_front();
            }
        }

        /// Queues the dropped-replies notice and any event and alarm lines that fit.
        fn refill(&mut self) {
            let line_room = LINE_ROOM;
            // Once the congestion is over (all queued output sent): one notice per flood.
            if self.dropped > 0 && self.q.is_empty() {
                let mut l = OutLine::new();
                reply::replies_dropped(&mut l, self.dropped);
                let _ = l.push('\n');
                if self.offer(&l, 0) {
                    self.dropped = 0;
                }
            }
            while self.room() >= line_room {
                let Some(mut line) = with_controller(|c| c.pop_event_line()) else {
                    break;
                };
                let _ = line.push('\n');
                self.offer(&line, 0);
            }
        }
    }

    /// Answers one finished line into `reply`; says whether it was an ABORT.
    fn answer(
        c: &mut Controller,
        now_ms: u64,
        line: Result<Assembled<'_>, Overrun>,
        reply: &mut heapless::String<REPLY_BYTES>,
    ) -> bool {
        let mut out = |l: &str| push_line(reply, l);
        match line {
            Ok(Assembled::Line(l)) => {
                let abort = matches!(parse_line(l), Ok(Some(Command::Abort)));
                if let Some(sim) = c.handle_line(now_ms, l, &mut out) {
                    sim_command(c, now_ms, sim, &mut out);
                }
                return abort;
            }
            Ok(Assembled::TooLong) => out(&format_error(&ERR_LINE_TOO_LONG)),
            Ok(Assembled::Invalid) => out(&format_error(&ERR_INVALID_LINE)),
            Err(Overrun) => out(&format_error(&reply::ERR_OVERRUN)),
        }
        false
    }

    /// ABORT first: if `bytes` (just received) hold a whole line that is ABORT, the controller
    /// aborts now, before the lines ahead of it are answered; the line itself is answered in
    /// its turn (a second ABORT changes nothing). A line counts if it starts in `bytes` after
    /// a line end, or at their start when `at_line_start`, and ends in them.
    fn abort_first(bytes: &[u8], at_line_start: bool) {
        let mut start = if at_line_start { Some(0) } else { None };
        for (i, &b) in bytes.iter().enumerate() {
            if b != b'\r' && b != b'\n' {
                continue;
            }
            if let Some(s) = start {
                let seg = &bytes[s..i];
                if seg.len() <= 16 {
                    if let Ok(text) = core::str::from_utf8(seg) {
                        if let Ok(Some(Command::Abort)) = parse_line(text) {
                            let now_ms = Instant::now().as_millis();
                            with_controller(|c| c.handle(now_ms, Command::Abort, &mut |_| {}));
                            APPLY_NOW.signal(());
                            return;
                        }
                    }
                }
            }
            start = Some(i + 1);
        }
    }

    /// The serial line: commands in, replies, events and alarms out.
    ///
    /// Input is never left waiting behind output: each pass answers at most one line, writes
    /// at most [`TX_CHUNK`] bytes and yields, and waits on the port only for whichever of
    /// input, room to write or events comes first. A reply that finds [`Output`] full is
    /// dropped and counted (its command was run); the count goes out as one `error: busy`
    /// line once all queued output is out, and until then later replies are dropped too. Lost
    /// input makes its line an overrun error.
    async fn serial_loop(
        mut tx: impl Write,
        mut rx: impl SerialReceive,
        boot: OutLine,
        mut store: Store,
    ) {
        let mut reply: heapless::String<REPLY_BYTES> = heapless::String::new();
        let mut out = Output {
            q: heapless::Deque::new(),
            dropped: 0,
        };
        let mut boot_line = boot;
        let _ = boot_line.push('\n');
        out.offer(&boot_line, 0);
        let mut assembler = LineAssembler::new();
        let mut inbuf = [0u8; SERIAL_RX_BYTES];
        let (mut pos, mut len, mut lost) = (0usize, 0usize, false);
        loop {
            out.refill();
            if pos < len || lost {
                // One line's worth of the received bytes.
                while pos < len {
                    let byte = inbuf[pos];
                    pos += 1;
                    let Some(line) = assembler.push_checked(byte) else {
                        continue;
                    };
                    reply.clear();
                    let now_ms = Instant::now().as_millis();
                    let (abort, changed) = with_controller(|c| {
                        let before = c.outputs();
                        let abort = answer(c, now_ms, line, &mut reply);
                        (abort, c.outputs() != before)
                    });
                    if changed || abort {
                        APPLY_NOW.signal(());
                    }
                    // SAVE: only ever asked for while no morph runs (heaters off), so the CPU
                    // stalling on its flash during an erase or write holds no heater on.
                    if let Some(blob) = with_controller(|c| c.take_save_request()) {
                        if let Some(s) = &mut store {
                            let t0 = Instant::now();
                            let r = s.save(&blob).await;
                            defmt::info!("SAVE took {} ms", t0.elapsed().as_millis());
                            with_controller(|c| {
                                c.finish_save(r, &mut |l| push_line(&mut reply, l))
                            });
                        }
                    }
                    // Once one reply is dropped, the following ones are too until the notice
                    // is out, so the notice counts the replies right before it (an ABORT's
                    // reply still goes out, in the room kept free).
                    let queued = if abort {
                        out.offer(&reply, 0)
                    } else {
                        out.dropped == 0 && out.offer(&reply, OUT_RESERVE)
                    };
                    if !queued && !reply.is_empty() {
                        out.dropped += 1;
                    }
                    // A MORPH's first event follows its `ok`.
                    out.refill();
                    break;
                }
                if pos == len && lost {
                    assembler.overrun();
                    lost = false;
                }
                // Offer output without waiting for room, then let the control task run.
                if !out.q.is_empty() {
                    if let Either::First(r) = select(tx.write(out.chunk()), yield_now()).await {
                        sent(&mut out, r);
                    }
                }
                yield_now().await;
                continue;
            }
            // Everything received is answered: wait for input, room to write, or events.
            let got: Option<Received> = if out.q.is_empty() {
                match select(rx.receive(&mut inbuf), EVENTS.wait()).await {
                    Either::First(r) => Some(r),
                    Either::Second(()) => None,
                }
            } else {
                match select3(rx.receive(&mut inbuf), tx.write(out.chunk()), EVENTS.wait()).await {
                    Either3::First(r) => Some(r),
                    Either3::Second(r) => {
                        sent(&mut out, r);
                        yield_now().await;
                        None
                    }
                    Either3::Third(()) => None,
                }
            };
            if let Some(r) = got {
                pos = 0;
                len = r.len.min(inbuf.len());
                lost = r.lost_after;
                abort_first(&inbuf[..len], assembler.at_line_start());
            }
        }
    }

    /// Drops what a write took from `out` (a failed write drops the chunk, logged).
    fn sent<E>(out: &mut Output, r: Result<usize, E>) {
        match r {
            Ok(n) => out.sent(n),
            Err(_) => {
                defmt::warn!("serial send error");
                let n = out.chunk().len();
                out.sent(n);
            }
        }
    }

    /// Set by the first panic or HardFault, so a fault while logging it skips straight to the
    /// end instead of recursing.
    static FAULTED: AtomicBool = AtomicBool::new(false);

    /// Heaters off first (raw writes), then one log line over RTT, then the board's fatal end:
    /// the reason recorded in RAM that survives the reset, then a system reset, reported at the
    /// next boot as `reset=software panic="<reason>"`.
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
defmt::timestamp!("{=u64:ms}", embassy_time::Instant::now().as_millis());
