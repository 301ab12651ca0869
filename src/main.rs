//! Firmware entry point: the thin shell that moves data between the STM32 peripherals and the
//! hardware-free core. Builds only for the target (`thumbv7em-none-eabihf`); on the host it
//! prints how to build it.
//!
//! Two embassy tasks share one [`morphlink::controller::Controller`]:
//! - `control`, every [`TICK_MS`] (10 Hz): ADC burst (16 samples per input) → `Controller::step`
//!   → PWM duties; feeds the independent watchdog; records its timing for `STATS`.
//! - `serial`: bytes from the interrupt-driven buffered UART → `LineAssembler` →
//!   `Controller::handle_line` → replies; also writes queued events and alarms.
//!
//! The board (pins, clocks, memory) comes from `boards/<name>/`, picked by a `board-*` feature.
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

#[cfg(target_os = "none")]
#[cfg_attr(
    feature = "board-nucleo-f401re",
    path = "../boards/nucleo-f401re/mod.rs"
)]
#[cfg_attr(
    feature = "board-nucleo-g431rb",
    path = "../boards/nucleo-g431rb/mod.rs"
)]
#[cfg_attr(
    feature = "board-b-l475e-iot01a",
    path = "../boards/b-l475e-iot01a/mod.rs"
)]
#[cfg_attr(
    feature = "board-b-l475e-iot01a-emulated",
    path = "../boards/b-l475e-iot01a-emulated/mod.rs"
)]
mod board;

#[cfg(target_os = "none")]
pub use firmware::*;

#[cfg(target_os = "none")]
mod firmware {
    use crate::board;
    use core::cell::RefCell;
    use core::sync::atomic::{AtomicBool, Ordering};
    #[cfg(not(emulated))]
    use cortex_m::peripheral::DWT;
    use defmt_rtt as _;
    use embassy_executor::Spawner;
    use embassy_futures::select::{select, Either};
    use embassy_futures::yield_now;
    use embassy_stm32::pac;
    #[cfg(not(emulated))]
    use embassy_stm32::time::Hertz;
    #[cfg(not(emulated))]
    use embassy_stm32::timer::simple_pwm::{SimplePwm, SimplePwmChannel, SimplePwmChannels};
    #[cfg(not(emulated))]
    use embassy_stm32::timer::{Channel, GeneralInstance4Channel};
    #[cfg(not(emulated))]
    use embassy_stm32::usart;
    use embassy_sync::blocking_mutex::raw::ThreadModeRawMutex;
    use embassy_sync::blocking_mutex::Mutex;
    use embassy_sync::signal::Signal;
    use embassy_time::{Duration, Instant, Ticker, Timer};
    use embedded_io_async::{Read, Write};
    #[cfg(not(emulated))]
    use morphlink::controller::Outputs;
    use morphlink::controller::{Config, Controller, Inputs, MAX_REPLY_BYTES, OVERSAMPLE, TICK_MS};
    use morphlink::protocol::{
        format_error, Assembled, LineAssembler, OutLine, ERR_INVALID_LINE, ERR_LINE_TOO_LONG,
    };
    use morphlink::stats::{write_boot_line, LoopTiming, ResetCause};

    #[cfg(not(emulated))]
    /// Heater PWM frequency: 1 kHz. The heaters' thermal time constants are ≥ 1 s, so any
    /// frequency above ~10 Hz gives a ripple-free temperature; 1 kHz keeps switching losses of
    /// a GPIO-driven logic-level MOSFET negligible (edges of ~1 µs are 0.2 % of the period)
    /// and still gives a 16-bit timer tens of thousands of duty steps.
    pub const PWM_FREQUENCY: Hertz = Hertz(1_000);

    /// Independent-watchdog timeout, µs: 5 control ticks. The control task feeds it every
    /// 100 ms; the LSI that clocks it may run up to ~47 % fast, which still leaves > 3 ticks.
    /// A stalled control task resets the chip, and the reset leaves both heaters off.
    pub const WATCHDOG_TIMEOUT_US: u32 = 500_000;

    /// Serial line speed, baud: the ST-LINK virtual COM port's usual default.
    pub const BAUD: u32 = 115_200;

    /// UART receive buffer, bytes: four maximal lines; more is a flood, and the assembler
    /// reports an over-long line once rather than per byte.
    pub const UART_RX_BYTES: usize = 256;
    /// UART transmit buffer, bytes: holds a whole HELP reply, so replies rarely wait.
    pub const UART_TX_BYTES: usize = 1024;
    /// Largest reply the serial task collects under the controller lock, bytes: the core's bound.
    pub const REPLY_BYTES: usize = MAX_REPLY_BYTES;

    /// Spacing of the ADC samples in a tick's burst: 16 samples 1 ms apart span 16 ms, about
    /// one mains period, so 50/60 Hz pickup averages out (the G4 sums in hardware instead).
    pub const SAMPLE_SPACING: Duration = Duration::from_millis(1);

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

    /// Heater driver, serial halves and watchdog of a hardware board.
    #[cfg(not(emulated))]
    mod parts {
        /// Both heaters on the board's PWM timer.
        pub type HeaterDriver = super::Heaters<crate::board::HeaterTimer>;
        /// The buffered UART's transmit half.
        pub type SerialTx = embassy_stm32::usart::BufferedUartTx<'static>;
        /// The buffered UART's receive half.
        pub type SerialRx = embassy_stm32::usart::BufferedUartRx<'static>;
        /// The independent watchdog.
        pub type Watchdog =
            embassy_stm32::wdg::IndependentWatchdog<'static, embassy_stm32::peripherals::IWDG>;
    }

    /// The emulated board's replacements (see `boards/b-l475e-iot01a-emulated`).
    #[cfg(emulated)]
    mod parts {
        pub use crate::board::{HeaterDriver, Watchdog};
        /// Register-level USART1, transmit half.
        pub type SerialTx = crate::board::usart::Tx;
        /// Register-level USART1, receive half.
        pub type SerialRx = crate::board::usart::Rx;
    }
    use parts::{HeaterDriver, SerialRx, SerialTx, Watchdog};

    /// CPU cycle count for the loop timing of `STATS`: the DWT cycle counter on hardware.
    #[cfg(not(emulated))]
    fn cycles() -> u32 {
        DWT::cycle_count()
    }

    /// QEMU does not model the DWT cycle counter (it reads 0), so the emulated build counts
    /// [`board::CPU_HZ`] cycles per second of firmware time from the SysTick clock instead:
    /// `STATS` then reports firmware-time durations (20× compressed), in 5 µs steps.
    #[cfg(emulated)]
    fn cycles() -> u32 {
        (Instant::now().as_micros() * u64::from(board::CPU_HZ / 1_000_000)) as u32
    }

    /// Runs `f` on the controller, briefly holding the lock.
    fn with_controller<R>(f: impl FnOnce(&mut Controller) -> R) -> R {
        CONTROLLER.lock(|c| f(c.borrow_mut().as_mut().expect("set up in main")))
    }

    /// Drives one GPIO low as a plain output: sets the output latch low, then switches the
    /// pin from its timer function to output mode. Raw register writes only, so it works from
    /// a panic or HardFault whatever the drivers were doing (if the port's clock is still off,
    /// the pin is in its reset state and the gate pull-down holds it low anyway).
    pub fn force_low(port: pac::gpio::Gpio, pin: usize) {
        port.bsrr().write(|w| w.set_br(pin, true));
        port.moder()
            .modify(|w| w.set_moder(pin, pac::gpio::vals::Moder::OUTPUT));
    }

    #[cfg(not(emulated))]
    /// UART buffers, allocated once.
    pub fn uart_buffers() -> (&'static mut [u8], &'static mut [u8]) {
        let tx =
            cortex_m::singleton!(: [u8; UART_TX_BYTES] = [0; UART_TX_BYTES]).expect("called once");
        let rx =
            cortex_m::singleton!(: [u8; UART_RX_BYTES] = [0; UART_RX_BYTES]).expect("called once");
        (tx, rx)
    }

    #[cfg(not(emulated))]
    /// 115 200 8N1.
    pub fn uart_config() -> usart::Config {
        let mut c = usart::Config::default();
        c.baudrate = BAUD;
        c
    }

    #[cfg(not(emulated))]
    /// Both heater channels of one PWM timer.
    pub struct Heaters<T: GeneralInstance4Channel> {
        pla: SimplePwmChannel<'static, T>,
        tca: SimplePwmChannel<'static, T>,
    }

    #[cfg(not(emulated))]
    impl<T: GeneralInstance4Channel> Heaters<T> {
        /// Takes the board's timer and its two heater channels (which must differ); both
        /// outputs are enabled at 0 % duty, so the timer drives both gates low.
        pub fn new(pwm: SimplePwm<'static, T>, pla: Channel, tca: Channel) -> Self {
            let SimplePwmChannels { ch1, ch2, ch3, ch4 } = pwm.split();
            let mut slots = [Some(ch1), Some(ch2), Some(ch3), Some(ch4)];
            let mut take = |c: Channel| {
                let mut ch = slots[c.index()]
                    .take()
                    .expect("two different heater channels");
                ch.set_duty_cycle_fully_off();
                ch.enable();
                ch
            };
            let pla = take(pla);
            let tca = take(tca);
            Heaters { pla, tca }
        }

        /// Sets both duties (fractions in [0, 1]; anything else, NaN included, is off).
        pub fn apply(&mut self, o: Outputs) {
            set_duty(&mut self.pla, o.pla_duty);
            set_duty(&mut self.tca, o.tca_duty);
        }
    }

    #[cfg(not(emulated))]
    /// Sets one channel's duty from a fraction: 0 (or not a number) is fully off.
    fn set_duty<T: GeneralInstance4Channel>(ch: &mut SimplePwmChannel<'static, T>, duty: f32) {
        if duty > 0.0 {
            let max = ch.max_duty_cycle();
            ch.set_duty_cycle((duty.min(1.0) * max as f32) as u32);
        } else {
            ch.set_duty_cycle_fully_off();
        }
    }

    #[embassy_executor::main]
    async fn main(spawner: Spawner) {
        let b = board::init();
        let cause = ResetCause::from_flags(b.reset_flags);
        defmt::info!(
            "morphlink {} on {}: reset cause {}",
            morphlink::controller::VERSION,
            board::NAME,
            cause.as_str()
        );

        let mut cp = cortex_m::Peripherals::take().expect("taken once");
        cp.DCB.enable_trace();
        cp.DWT.enable_cycle_counter();

        let mut ctrl = Controller::new(Config::DEFAULT);
        ctrl.enable_timing(LoopTiming::new(board::CPU_HZ, TICK_MS as u32 * 1000, cause));
        CONTROLLER.lock(|c| *c.borrow_mut() = Some(ctrl));

        #[cfg(not(emulated))]
        let (heaters, (tx, rx), wdg) = (
            Heaters::new(b.pwm, board::PLA_CHANNEL, board::TCA_CHANNEL),
            b.serial.split(),
            Watchdog::new(b.iwdg, WATCHDOG_TIMEOUT_US),
        );
        #[cfg(emulated)]
        let (heaters, (tx, rx), wdg) = (b.heaters, (b.tx, b.rx), b.watchdog);
        let mut boot = OutLine::new();
        write_boot_line(&mut boot, cause, board::NAME);

        spawner.spawn(control(b.sensors, heaters, wdg).expect("spawned once"));
        spawner.spawn(serial(tx, rx, boot).expect("spawned once"));
    }

    /// Sums [`READS_PER_TICK`] reads of every input, [`SAMPLE_SPACING`] apart.
    async fn read_burst(sensors: &mut board::Sensors) -> [u32; 4] {
        let mut sums = [0u32; 4];
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
    #[embassy_executor::task]
    async fn control(mut sensors: board::Sensors, mut heaters: HeaterDriver, mut wdg: Watchdog) {
        wdg.unleash();
        let mut ticker = Ticker::every(Duration::from_millis(TICK_MS));
        loop {
            if let Either::Second(()) = select(ticker.next(), APPLY_NOW.wait()).await {
                heaters.apply(with_controller(|c| c.outputs()));
                continue;
            }
            let start = cycles();
            let sums = read_burst(&mut sensors).await;
            let adc_done = cycles();
            let now_ms = Instant::now().as_millis();
            let inputs = Inputs {
                thermistor_counts: [sums[0], sums[1], sums[2]],
                supply_counts: sums[3],
                sample_ms: now_ms,
            };
            let outputs = with_controller(|c| c.step(now_ms, &inputs));
            heaters.apply(outputs);
            let applied = cycles();
            wdg.pet();
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

    /// Answers one assembled line into `reply`. `SIM` commands get the core's
    /// `error: unsupported` reply: there is no simulated link on hardware.
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
                    #[cfg(not(emulated))]
                    c.handle(now_ms, morphlink::protocol::Command::Sim(sim), &mut out);
                    #[cfg(emulated)]
                    board::sim_command(sim, &mut out);
                }
            }
            Assembled::TooLong => out(&format_error(&ERR_LINE_TOO_LONG)),
            Assembled::Invalid => out(&format_error(&ERR_INVALID_LINE)),
        }
    }

    /// Writes every queued event and alarm line, oldest first, taking the lock once per line.
    async fn send_events(tx: &mut SerialTx) {
        while let Some(line) = with_controller(|c| c.pop_event_line()) {
            send(tx, &line).await;
            send(tx, "\n").await;
        }
    }

    /// The serial line: commands in, replies, events and alarms out.
    #[embassy_executor::task]
    async fn serial(mut tx: SerialTx, mut rx: SerialRx, boot: OutLine) {
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
                Either::First(Err(e)) => defmt::warn!("uart receive error: {}", e),
                Either::Second(()) => send_events(&mut tx).await,
            }
        }
    }

    /// Writes `s` to the UART (waiting for room in its transmit buffer); errors are logged.
    async fn send(tx: &mut SerialTx, s: &str) {
        if s.is_empty() {
            return;
        }
        if let Err(e) = tx.write_all(s.as_bytes()).await {
            defmt::warn!("uart send error: {}", e);
        }
    }

    /// Set by the first panic or HardFault, so a fault while logging it skips straight to the
    /// reset instead of recursing.
    static FAULTED: AtomicBool = AtomicBool::new(false);

    /// Heaters off first (raw writes), then one log line over RTT, then a system reset (reported
    /// at the next boot as `reset=software`).
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
        #[cfg(emulated)]
        board::fatal_panic(info);
        #[cfg(not(emulated))]
        cortex_m::peripheral::SCB::sys_reset()
    }

    /// As [`panic`], for faults the CPU raises (bus, memory, usage faults escalate here).
    #[cortex_m_rt::exception]
    unsafe fn HardFault(ef: &cortex_m_rt::ExceptionFrame) -> ! {
        board::heater_pins_low();
        if !FAULTED.swap(true, Ordering::Relaxed) {
            defmt::error!("HardFault at pc={=u32:#x}; heaters off, resetting", ef.pc());
        }
        #[cfg(emulated)]
        board::fatal("HardFault; heaters off");
        #[cfg(not(emulated))]
        cortex_m::peripheral::SCB::sys_reset()
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
