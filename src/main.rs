//! Firmware entry point: the thin shell that moves data between the board and the
//! hardware-free core. Builds only for the target (`thumbv7em-none-eabihf`); on the host it
//! prints how to build it.
//!
//! Two embassy tasks share one [`morphlink::controller::Controller`]:
//! - `control`, every [`TICK_MS`] (10 Hz): ADC burst (16 samples per input) → `Controller::step`
//!   → PWM duties; feeds the watchdog; records its timing for `STATS`.
//! - `serial`: bytes from the board's serial port → `LineAssembler` →
//!   `Controller::handle_line` → replies; also writes queued events and alarms.
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
    use embassy_futures::select::{select, Either};
    use embassy_futures::yield_now;
    use embassy_sync::blocking_mutex::raw::ThreadModeRawMutex;
    use embassy_sync::blocking_mutex::Mutex;
    use embassy_sync::signal::Signal;
    use embassy_time::{Duration, Instant, Ticker, Timer};
    use embedded_io_async::{Read, Write};
    use morphlink::controller::{Config, Controller, Inputs, MAX_REPLY_BYTES, OVERSAMPLE, TICK_MS};
    use morphlink::protocol::{
        format_error, Assembled, LineAssembler, OutLine, SimCommand, ERR_INVALID_LINE,
        ERR_LINE_TOO_LONG,
    };
    use morphlink::stats::{write_boot_line, LoopTiming};
    use morphlink::vocab::ResetCause;
    use morphlink_boards::selected as board;
    use morphlink_boards::{AnalogInputs, HeaterOutputs, Input, Watchdog, INPUTS};

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
        CONTROLLER.lock(|c| *c.borrow_mut() = Some(ctrl));

        let mut boot = OutLine::new();
        write_boot_line(&mut boot, cause, board::NAME);

        spawner.spawn(control(parts.sensors, parts.heaters, parts.watchdog).expect("spawned once"));
        spawner.spawn(serial(parts.tx, parts.rx, boot).expect("spawned once"));
    }

    #[embassy_executor::task]
    async fn control(sensors: board::Sensors, heaters: board::Heaters, wdg: board::Iwdg) {
        control_loop(sensors, heaters, wdg).await
    }

    #[embassy_executor::task]
    async fn serial(tx: board::SerialTx, rx: board::SerialRx, boot: OutLine) {
        serial_loop(tx, rx, boot).await
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

    /// Answers one assembled line into `reply`.
    fn answer(
        c: &mut Controller,
        now_ms: u64,
        line: Assembled<'_>,
        reply: &mut heapless::String<REPLY_BYTES>,
    ) {
        let mut out = |l: &str| push_line(reply, l);
        match line {
            Assembled::Line(l) => {
                if let Some(sim) = c.handle_line(now_ms, l, &mut out) {
                    sim_command(c, now_ms, sim, &mut out);
                }
            }
            Assembled::TooLong => out(&format_error(&ERR_LINE_TOO_LONG)),
            Assembled::Invalid => out(&format_error(&ERR_INVALID_LINE)),
        }
    }

    /// Writes every queued event and alarm line, oldest first, taking the lock once per line.
    async fn send_events(tx: &mut impl Write) {
        while let Some(line) = with_controller(|c| c.pop_event_line()) {
            send(tx, &line).await;
            send(tx, "\n").await;
        }
    }

    /// The serial line: commands in, replies, events and alarms out.
    async fn serial_loop(mut tx: impl Write, mut rx: impl Read, boot: OutLine) {
        let mut reply: heapless::String<REPLY_BYTES> = heapless::String::new();
        push_line(&mut reply, &boot);
        send(&mut tx, &reply).await;
        let mut assembler = LineAssembler::new();
        let mut buf = [0u8; 32];
        loop {
            match select(rx.read(&mut buf), EVENTS.wait()).await {
                Either::First(Ok(n)) => {
                    for &byte in &buf[..n] {
                        let Some(line) = assembler.push(byte) else {
                            continue;
                        };
                        reply.clear();
                        let now_ms = Instant::now().as_millis();
                        with_controller(|c| answer(c, now_ms, line, &mut reply));
                        APPLY_NOW.signal(());
                        send(&mut tx, &reply).await;
                        // A MORPH's first event follows its `ok`.
                        send_events(&mut tx).await;
                    }
                    // A flood arrives faster than lines end: let the control task run.
                    yield_now().await;
                }
                Either::First(Err(_)) => defmt::warn!("serial receive error"),
                Either::Second(()) => send_events(&mut tx).await,
            }
        }
    }

    /// Writes `s` to the serial port (waiting for room in its transmit buffer); errors are logged.
    async fn send(tx: &mut impl Write, s: &str) {
        if s.is_empty() {
            return;
        }
        if tx.write_all(s.as_bytes()).await.is_err() {
            defmt::warn!("serial send error");
        }
    }

    /// Set by the first panic or HardFault, so a fault while logging it skips straight to the
    /// end instead of recursing.
    static FAULTED: AtomicBool = AtomicBool::new(false);

    /// Heaters off first (raw writes), then one log line over RTT, then the board's fatal end
    /// (a system reset on hardware, reported at the next boot as `reset=software`).
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
        board::fatal(format_args!("panic: {}; heaters off", info))
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
