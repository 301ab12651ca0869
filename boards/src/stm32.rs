//! What the hardware boards share: both heaters on TIM3 channels 1 and 2 (PA6 = Arduino D12,
//! PA7 = D11, pins without a pull-up at reset) and the supply's cut-off on a GPIO, the four
//! analog inputs on ADC1, the heaters' currents sampled against TIM3's counter
//! ([`Shunts`]), the independent watchdog, the buffered UART, the DWT cycle counter and the
//! reset that ends a fatal error.
//!
//! # Sampling the currents inside the pulse
//!
//! Both heaters' PWM is edge-aligned on one timer, so every pulse, whatever its duty, starts
//! at the counter's wrap: the first [`PROBE_PULSE_US`] of a period are inside every pulse of
//! at least the probe's duty, and the last [`PROBE_PULSE_US`] are inside every off-time of a
//! duty up to the core's `MAX_SENSED_DUTY` (99 %). One reading takes the off-sample of both
//! heaters [`OFF_SAMPLE_BEFORE_END_US`] before a period ends and their on-sample
//! [`ON_SAMPLE_US`] after the next one starts: two fixed points of the counter, for any duty.
//! The firmware sleeps until just before the first point, then, with interrupts masked for at
//! most [`SAMPLE_LEAD_US`] plus 15 µs, watches TIM3's counter and starts each conversion
//! itself when it gets there (single conversions of a few register writes each, [`convert`];
//! the thermistors' conversions are the same routine, at their own sample time).
//!
//! Why not a conversion triggered by the timer (an injected sequence started by a compare
//! channel, or the ADC started by TIM3's TRGO): embassy-stm32 0.6 offers timer-triggered
//! injected conversions on the F4's and the G4's ADC only, not on the L4's, with no way to
//! wait for their end but polling, and on the F4 only by giving up its driver's regular
//! conversions (`setup_injected_conversions` consumes the ADC). By registers it would take each
//! family's trigger selection and injected-sequence layout, which differ on all three chips and
//! cannot be tried here (QEMU models neither the timers nor the ADC). Timing the conversions
//! against the counter is one piece of shared code whose only chip-specific part is a single
//! conversion, within a few ADC clocks of the point it aims at. Its costs: the masked
//! interrupts (about half a UART byte time), the control task's 16 readings taking 16 PWM
//! periods after the thermistors' burst, and a reading taken only when the control task gets
//! to run in time (a late wake-up waits for the next period).

use crate::{
    AnalogInputs, CurrentSense, CurrentSums, FatalKind, HeaterOutputs, Parts, Received, ResetFlags,
    SerialReceive, Watchdog, INPUTS, PROBE_PULSE_US,
};
use core::mem::ManuallyDrop;
use embassy_stm32::adc::{AnyAdcChannel, SampleTime};
use embassy_stm32::gpio::OutputType;
use embassy_stm32::peripherals::{ADC1, IWDG, PA6, PA7, TIM3};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::low_level::{CountingMode, OutputCompareMode, Timer};
use embassy_stm32::timer::simple_pwm::PwmPin;
use embassy_stm32::timer::{Ch1, Ch2, Channel};
use embassy_stm32::usart::{self, BufferedUart, BufferedUartRx, BufferedUartTx};
use embassy_stm32::{flash, pac, Peri};

/// Heater PWM frequency: 1 kHz. The heaters' thermal time constants are ≥ 1 s, so any
/// frequency above ~10 Hz gives a ripple-free temperature; 1 kHz keeps switching losses of
/// a GPIO-driven logic-level MOSFET negligible (edges of ~1 µs are 0.2 % of the period)
/// and still gives a 16-bit timer tens of thousands of duty steps.
pub const PWM_FREQUENCY: Hertz = Hertz(crate::PWM_HZ);

/// Independent-watchdog timeout, µs: 5 control ticks. The control task feeds it every
/// 100 ms; the LSI that clocks it may run up to ~47 % fast, which still leaves > 3 ticks.
/// A stalled control task resets the chip, and the reset leaves both heaters off.
pub const WATCHDOG_TIMEOUT_US: u32 = 500_000;

/// UART receive buffer, bytes: four maximal lines. The serial task drains it at once and
/// never waits on its output while input is waiting, so at 115 200 baud (87 µs a byte) it
/// fills only if the task is held off for 22 ms; a read that finds it full reports input
/// lost after its bytes ([`SerialRx`]).
pub const UART_RX_BYTES: usize = crate::SERIAL_RX_BYTES;
/// UART transmit buffer, bytes: holds a whole HELP reply, so replies rarely wait.
pub const UART_TX_BYTES: usize = 1024;

/// Timer driving both heaters.
pub type HeaterTimer = TIM3;
/// Timer channel of the PLA heater (PA6).
pub const PLA_CHANNEL: Channel = Channel::Ch1;
/// Timer channel of the TCA heater (PA7).
pub const TCA_CHANNEL: Channel = Channel::Ch2;

/// The buffered UART's transmit half.
pub type SerialTx = BufferedUartTx<'static>;
/// The buffered UART's receive half, reporting lost input.
///
/// embassy-stm32 0.6's buffered UART drops a byte that finds its ring full, and for an overrun
/// in the UART itself (ORE) it clears the flag in its interrupt and only logs it; its `read`
/// returns no error for either. The full ring is detected here: a read that drains a full ring
/// (as many bytes as the ring holds: the firmware reads with a buffer that large) may have lost
/// input after them, so the line in progress there is marked; a full ring that lost nothing
/// costs one needless error, never a wrong command. Any read error (`usart::Error::Overrun`, and
/// framing, noise and parity errors, should an embassy version return them) marks it too. An
/// ORE (a byte lost because the interrupt was held off for more than one byte time, 87 µs) is
/// NOT detected with embassy 0.6; the firmware masks interrupts for at most 45 µs (a current
/// reading, [`SAMPLE_LEAD_US`]).
pub struct SerialRx(ManuallyDrop<BufferedUartRx<'static>>);

impl SerialReceive for SerialRx {
    async fn receive(&mut self, buf: &mut [u8]) -> Received {
        match embedded_io_async::Read::read(&mut *self.0, buf).await {
            Ok(len) => Received {
                len,
                lost_after: len >= UART_RX_BYTES,
            },
            Err(e) => {
                if e == usart::Error::Overrun {
                    defmt::warn!("UART overrun: the line in progress is dropped");
                } else {
                    defmt::warn!("UART receive error {}: the line in progress is dropped", e);
                }
                Received {
                    len: 0,
                    lost_after: true,
                }
            }
        }
    }
}

/// A hardware board's parts.
pub type HardwareParts = Parts<Sensors, Heaters, Iwdg, SerialTx, SerialRx, SettingsFlash>;
/// The chip's flash, for the settings area ([`crate::settings_area`]): embassy-stm32's blocking
/// driver behind the async NOR-flash trait the settings store takes (offsets from the flash
/// start; erase unit the largest sector: the F401's 128 KiB, the G4's and L4's 2 KiB pages).
/// Blocking is no loss: the CPU stalls on its own flash while it erases or writes whichever
/// driver runs it. An erase stalls the CPU (code runs from the same bank) for up to
/// 2 s on the F401, longer than [`WATCHDOG_TIMEOUT_US`]: the watchdog's period is stretched
/// to [`ERASE_WATCHDOG_S`] for the erase and put back after it. The firmware erases only with
/// the heaters off (SAVE is refused while a morph runs).
pub struct SettingsFlash(flash::Flash<'static, flash::Blocking>);

/// The watchdog's period during a flash erase, s (prescaler 256, reload 4095 at the 32 kHz
/// LSI): above the F401's 2 s worst-case 128 KiB sector erase.
pub const ERASE_WATCHDOG_S: u32 = 32;

/// Waits until the IWDG has taken its last prescaler and reload writes.
fn iwdg_settled() {
    while pac::IWDG.sr().read().0 != 0 {}
}

/// Writes the IWDG's prescaler and reload (unlocking them first) and reloads the counter.
fn iwdg_period(pr: u8, rl: u16) {
    use embassy_stm32::pac::iwdg::vals::{Key, Pr};
    let w = pac::IWDG;
    w.kr().write(|k| k.set_key(Key::RESET));
    w.kr().write(|k| k.set_key(Key::ENABLE));
    iwdg_settled();
    w.pr().write(|p| p.set_pr(Pr::from_bits(pr)));
    w.rlr().write(|r| r.set_rl(rl));
    iwdg_settled();
    w.kr().write(|k| k.set_key(Key::RESET));
}

impl embedded_storage_async::nor_flash::ErrorType for SettingsFlash {
    type Error = embassy_stm32::flash::Error;
}

impl embedded_storage_async::nor_flash::ReadNorFlash for SettingsFlash {
    const READ_SIZE: usize = flash::READ_SIZE;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        self.0.blocking_read(offset, bytes)
    }

    fn capacity(&self) -> usize {
        flash::FLASH_SIZE
    }
}

impl embedded_storage_async::nor_flash::NorFlash for SettingsFlash {
    const WRITE_SIZE: usize = flash::WRITE_SIZE;
    const ERASE_SIZE: usize = flash::MAX_ERASE_SIZE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        let w = pac::IWDG;
        iwdg_settled();
        let (pr, rl) = (w.pr().read().pr().to_bits(), w.rlr().read().rl());
        iwdg_period(6, 0xFFF);
        let r = self.0.blocking_erase(from, to);
        iwdg_period(pr, rl);
        r
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        self.0.blocking_write(offset, bytes)
    }
}

/// Drives one GPIO low as a plain output: sets the output latch low, then switches the
/// pin from its timer function to output mode. Raw register writes only, so it works from
/// a panic or HardFault whatever the drivers were doing (if the port's clock is still off,
/// the pin is in its reset state and the gate pull-down holds it low anyway).
pub fn force_low(port: pac::gpio::Gpio, pin: usize) {
    set_pin(port, pin, false);
    // MODER's two bits of the pin to 0b01, output (bit arithmetic: the pin is in range by
    // construction, and the field accessors would check it again).
    port.moder()
        .modify(|w| w.0 = (w.0 & !(0b11 << (2 * pin))) | (0b01 << (2 * pin)));
}

/// Sets one GPIO's output level by its port's set/reset register.
fn set_pin(port: pac::gpio::Gpio, pin: usize, high: bool) {
    let bit = if high { pin } else { pin + 16 };
    port.bsrr().write(|w| w.0 = 1 << bit);
}

/// A GPIO by port and pin number, for the raw writes of the panic path.
pub type RawPin = (pac::gpio::Gpio, usize);

/// Drives the supply's cut-off pin (`cutoff`, the board's) and both heater gates low by raw
/// register writes (output mode, level low), whatever state the timer and the rest of the
/// firmware are in: the supply cut first, then the gates. For the panic and HardFault handlers.
pub fn heater_pins_low(cutoff: RawPin) {
    force_low(cutoff.0, cutoff.1);
    // PA6 and PA7 together: both reset bits, then both pins' MODER fields to output.
    pac::GPIOA
        .bsrr()
        .write(|w| w.0 = (1 << (16 + 6)) | (1 << (16 + 7)));
    pac::GPIOA
        .moder()
        .modify(|w| w.0 = (w.0 & !(0b1111 << 12)) | (0b0101 << 12));
}

/// CPU cycle count for the loop timing of `STATS`: the DWT cycle counter.
pub fn cycles() -> u32 {
    cortex_m::peripheral::DWT::cycle_count()
}

/// Ends a fatal error (heaters already off): records `reason` where the next boot finds it,
/// then a system reset, reported at the next boot as `reset=software panic="<reason>"`.
pub fn fatal(reason: core::fmt::Arguments) -> ! {
    crate::reset_record::record(FatalKind::Fault, reason);
    cortex_m::peripheral::SCB::sys_reset()
}

/// UART buffers, allocated once.
pub fn uart_buffers() -> (&'static mut [u8], &'static mut [u8]) {
    let b = cortex_m::singleton!(: ([u8; UART_TX_BYTES], [u8; UART_RX_BYTES]) =
        ([0; UART_TX_BYTES], [0; UART_RX_BYTES]))
    .expect("called once");
    (&mut b.0, &mut b.1)
}

/// 115 200 8N1.
pub fn uart_config() -> usart::Config {
    let mut c = usart::Config::default();
    c.baudrate = crate::BAUD;
    c
}

/// The heater timer and its two gate pins, set up: what [`Heaters::new`] keeps for the
/// program's life.
pub struct HeaterPwm {
    _timer: Timer<'static, HeaterTimer>,
    _pins: (
        PwmPin<'static, HeaterTimer, Ch1>,
        PwmPin<'static, HeaterTimer, Ch2>,
    ),
}

/// The heater timer with the PLA gate (PA6) on channel 1 and the TCA gate (PA7) on channel 2,
/// push-pull, at [`PWM_FREQUENCY`] edge-aligned, PWM mode 1 with preloaded compares; both at
/// 0 % duty. What embassy's `SimplePwm::new` sets up, but with the period's prescaler and
/// reload found in 32-bit arithmetic: its `u64` division is a software routine of about 1 KiB
/// of flash on the Cortex-M4, which nothing else in the image needs.
pub fn heater_pwm(
    tim: Peri<'static, HeaterTimer>,
    pla: Peri<'static, PA6>,
    tca: Peri<'static, PA7>,
) -> HeaterPwm {
    let pins = (
        PwmPin::new(pla, OutputType::PushPull),
        PwmPin::new(tca, OutputType::PushPull),
    );
    let timer = Timer::new(tim);
    timer.set_counting_mode(CountingMode::EdgeAlignedUp);
    let (psc, arr) = prescaler_reload(timer.get_clock_frequency().0, PWM_FREQUENCY.0);
    let regs = timer.regs_gp16();
    regs.psc().write_value(psc);
    regs.arr().write(|w| w.set_arr(arr));
    timer.enable_outputs();
    for ch in [PLA_CHANNEL, TCA_CHANNEL] {
        timer.set_output_compare_mode(ch, OutputCompareMode::PwmMode1);
        timer.set_output_compare_preload(ch, true);
    }
    timer.set_autoreload_preload(true);
    // The preloaded prescaler and reload reach the counter now, not at the first wrap.
    timer.generate_update_event();
    timer.start();
    HeaterPwm {
        _timer: timer,
        _pins: pins,
    }
}

/// The prescaler and reload (both as written to the timer: one less than the divisor and the
/// period) that give `hz` periods a second from a `clock_hz` timer clock, the prescaler as
/// small as lets the reload fit 16 bits (as embassy's `SimplePwm::set_frequency` finds it) and
/// the period rounded down, at most one prescaled clock short (embassy rounds it up).
pub const fn prescaler_reload(clock_hz: u32, hz: u32) -> (u16, u16) {
    let clocks = clock_hz / hz;
    let psc = (clocks - 1) >> 16;
    (psc as u16, (clocks / (psc + 1) - 1) as u16)
}
// The boards' timer clocks: 84 MHz (F401), 80 MHz (L475), 170 MHz (G431) at 1 kHz.
const _: () = {
    assert!(matches!(prescaler_reload(84_000_000, 1000), (1, 41_999)));
    assert!(matches!(prescaler_reload(80_000_000, 1000), (1, 39_999)));
    assert!(matches!(prescaler_reload(170_000_000, 1000), (2, 56_665)));
    assert!(matches!(prescaler_reload(16_000_000, 1000), (0, 15_999)));
};

/// Heater `h`'s compare register (0: the PLA's, [`PLA_CHANNEL`]; else the TCA's,
/// [`TCA_CHANNEL`]).
fn compare(h: usize) -> pac::common::Reg<pac::timer::regs::Ccr1ch, pac::common::RW> {
    if h == 0 {
        pac::TIM3.ccr(PLA_CHANNEL.index())
    } else {
        pac::TIM3.ccr(TCA_CHANNEL.index())
    }
}

/// Writes both heaters' compare registers (PLA's first).
fn set_compares(ccr: [u16; 2]) {
    compare(0).write(|w| w.set_ccr(ccr[0]));
    compare(1).write(|w| w.set_ccr(ccr[1]));
}

/// Both heaters on [`HeaterTimer`]'s channels 1 and 2, and the supply's cut-off. The duties go
/// straight into the timer's compare registers (embassy's channel API checks each value it is
/// given; these are in range by construction).
pub struct Heaters {
    /// High closes the cut-off (through its driver transistor); its pull-down holds it open
    /// while the pin is not driven.
    cutoff: RawPin,
}

impl Heaters {
    /// Takes the heater timer and the cut-off's pin (`cutoff`, reserved by taking its
    /// `pin`): both channels enabled at 0 % duty, so the timer drives both gates low, and the
    /// cut-off driven low, open. The pin's level is set before it leaves its reset state, so
    /// it never drives high on the way.
    pub fn new(
        pwm: HeaterPwm,
        cutoff: RawPin,
        pin: Peri<'static, impl embassy_stm32::gpio::Pin>,
    ) -> Self {
        let _reserved = pin;
        force_low(cutoff.0, cutoff.1);
        compare(0).write(|w| w.set_ccr(0));
        compare(1).write(|w| w.set_ccr(0));
        pac::TIM3.ccer().modify(|w| {
            w.set_cce(PLA_CHANNEL.index(), true);
            w.set_cce(TCA_CHANNEL.index(), true);
        });
        // The timer and its gate pins stay as `heater_pwm` set them for the program's life:
        // dropped, its driver would stop the timer.
        core::mem::forget(pwm);
        Heaters { cutoff }
    }
}

impl HeaterOutputs for Heaters {
    fn apply(&mut self, pla_duty: f32, tca_duty: f32, supply_on: bool) {
        let tim = pac::TIM3;
        let period = f32::from(tim.arr().read().arr()) + 1.0;
        for (h, duty) in [pla_duty, tca_duty].into_iter().enumerate() {
            // 0 or less, and not a number, is fully off; 1 or more fully on.
            let share = if duty > 0.0 { duty } else { 0.0 };
            let ticks = if share < 1.0 { share * period } else { period };
            compare(h).write(|w| w.set_ccr(ticks as u16));
        }
        set_pin(self.cutoff.0, self.cutoff.1, supply_on);
    }
}

/// The thermistor and supply inputs on ADC1, and the heaters' shunt amplifiers where the board
/// has them. Every conversion is [`convert`]'s: the channels' sample times are set once, here.
/// The board sets ADC1 up and keeps it so (its embassy driver, where it has one, is never
/// dropped: that would switch the ADC off).
pub struct Sensors {
    /// The inputs' channels, in [`crate::Input`] order.
    channels: [u8; INPUTS],
    shunts: Option<Shunts>,
}

impl Sensors {
    /// ADC1's PLA, TCA and ambient thermistor channels and the supply channel, in
    /// [`crate::Input`] order, each converted with `sample_time`; and the shunt amplifiers'
    /// inputs (`None`: a board without current sense). Enables the ADC.
    pub fn new(
        channels: [AnyAdcChannel<'static, ADC1>; INPUTS],
        sample_time: SampleTime,
        shunts: Option<Shunts>,
    ) -> Self {
        enable(pac::ADC1);
        let channels = channels.map(|c| {
            let ch = c.get_hw_channel();
            set_sample_time(pac::ADC1, ch, sample_time);
            ch
        });
        Sensors { channels, shunts }
    }
}

impl AnalogInputs for Sensors {
    fn read(&mut self) -> [u16; INPUTS] {
        self.channels.map(|ch| {
            // The L4's erratum on a conversion after a pause (2.7.3): the first is discarded,
            // as embassy-stm32's driver does on the L4.
            #[cfg(feature = "b-l475e-iot01a")]
            convert(pac::ADC1, ch);
            convert(pac::ADC1, ch)
        })
    }
}

impl CurrentSense for Sensors {
    /// `reads` readings, one per PWM period, in the periods that follow (see the module doc);
    /// a heater below the probe's duty gets its probe pulse in the first.
    async fn read_currents(&mut self, reads: u32) -> Option<CurrentSums> {
        let shunts = self.shunts.as_ref()?;
        let mut r = Reading::new(reads);
        while r.left > 0 {
            let sleep_us = cortex_m::interrupt::free(|_| r.take(shunts));
            if sleep_us > 0 {
                embassy_time::Timer::after_micros(u64::from(sleep_us)).await;
            }
        }
        Some(r.sums)
    }
}

/// Where a reading's on-samples start, µs after the period starts (every pulse's rising
/// edge): the MOSFET has switched and the amplifier settled (an INA180A1 within 2 µs, the G4's
/// op-amp as PGA faster), and both conversions end by 7 µs, inside the shortest pulse sampled
/// ([`PROBE_PULSE_US`]).
pub const ON_SAMPLE_US: u32 = 4;
/// Where a reading's off-samples start, µs before the period ends: 4 µs after the last falling
/// edge of a duty of 99 %, both conversions done before the next pulse.
pub const OFF_SAMPLE_BEFORE_END_US: u32 = 6;
/// How long before the off-samples the control task masks interrupts and watches the counter,
/// µs at most: it sleeps until half of this before the point, so a wake-up up to that late still
/// samples this period. Masked for at most this plus 15 µs (to the end of the on-samples),
/// about half a byte time at 115 200 Bd (87 µs), so the UART's receive interrupt loses nothing.
pub const SAMPLE_LEAD_US: u32 = 30;

/// The heaters' shunt amplifiers on two inputs of one ADC (its register block and channel
/// numbers: the conversions are started by register writes, [`convert`]), sampled against
/// [`HeaterTimer`]'s counter (see the module doc). The ADC must be enabled and kept so: the
/// board's embassy driver of it is never dropped.
pub struct Shunts {
    adc: pac::adc::Adc,
    /// PLA's, then TCA's channel.
    channels: [u8; 2],
}

impl Shunts {
    /// The amplifiers of the PLA heater and the TCA on `channels` of `adc`, each sampled for
    /// `sample_time` (set here once: the thermistors' conversions set only their own
    /// channels').
    pub fn new(adc: pac::adc::Adc, channels: [u8; 2], sample_time: SampleTime) -> Self {
        for ch in channels {
            set_sample_time(adc, ch, sample_time);
        }
        Shunts { adc, channels }
    }
}

/// One [`CurrentSense::read_currents`] of [`Shunts`]: its points on the PWM counter (ticks
/// from the wrap), the compare values the heaters were given, and the sums so far.
struct Reading {
    period: u32,
    on: u32,
    off: u32,
    lead: u32,
    probe: u16,
    ccr: [u16; 2],
    reads: u32,
    left: u32,
    sums: CurrentSums,
}

impl Reading {
    /// Before the first of `reads` readings, at the heater timer's period and compare values.
    fn new(reads: u32) -> Self {
        let tim = pac::TIM3;
        let period = u32::from(tim.arr().read().arr()) + 1;
        // Counter ticks of `us` µs at the PWM frequency.
        let ticks = |us: u32| us * period / (1_000_000 / crate::PWM_HZ);
        Reading {
            period,
            on: ticks(ON_SAMPLE_US),
            off: period - ticks(OFF_SAMPLE_BEFORE_END_US),
            lead: ticks(SAMPLE_LEAD_US),
            probe: ticks(PROBE_PULSE_US) as u16,
            ccr: [0, 1].map(|h| compare(h).read().ccr()),
            reads,
            left: reads,
            sums: CurrentSums::default(),
        }
    }

    /// Interrupts masked: if the counter is within `lead` of the off point, one reading
    /// (off-samples there, on-samples at the next period's on point, with the probe pulse in
    /// the first reading), added to the sums, and 0; otherwise the µs to sleep until half of
    /// `lead` before the off point. Out of line: inlined into the control task's poll it makes
    /// the image larger.
    #[inline(never)]
    fn take(&mut self, shunts: &Shunts) -> u32 {
        let tim = pac::TIM3;
        let cnt = || u32::from(tim.cnt().read().cnt());
        let now = cnt();
        let to_off = if now < self.off {
            self.off - now
        } else {
            self.off + self.period - now
        };
        if to_off > self.lead {
            return (to_off - self.lead / 2) * (1_000_000 / crate::PWM_HZ) / self.period;
        }
        let first = self.left == self.reads;
        // The probe pulse, in the first reading: each compare register at least the probe's
        // (a heater at or above it keeps its own). They are preloaded: a value written now holds
        // from the wrap to the next one, so the pulse is one period's.
        let probe = self.ccr.map(|c| c.max(self.probe));
        let (adc, [pla, tca]) = (shunts.adc, shunts.channels);
        // The L4's and G4's ADCs may get a conversion wrong that comes more than 1 ms after
        // the previous one (errata 2.7.3 of either): one to discard, before the off point.
        convert(adc, pla);
        while cnt() < self.off {}
        if first {
            set_compares(probe);
        }
        let off = [convert(adc, pla), convert(adc, tca)];
        // Past the wrap, to the on point.
        while cnt() >= self.off {}
        while cnt() < self.on {}
        let on = [convert(adc, pla), convert(adc, tca)];
        if first {
            set_compares(self.ccr);
        }
        for h in 0..2 {
            self.sums.off[h] += u32::from(off[h]);
            // A probed heater's one reading inside its probe pulse stands for all of them.
            self.sums.on[h] += if self.ccr[h] >= self.probe {
                u32::from(on[h])
            } else if first {
                u32::from(on[h]) * self.reads
            } else {
                0
            };
        }
        self.left -= 1;
        0
    }
}

/// One single conversion of channel `ch` on `adc`, started by software at once, ADC counts: a
/// few register writes, so that two fit inside a 10 µs pulse (embassy's `blocking_read`
/// first stops and re-enables the ADC, 3 µs on the F4). The ADC must be enabled, idle, and its
/// sequence one conversion long, as embassy's `blocking_read` leaves it.
pub fn convert(adc: pac::adc::Adc, ch: u8) -> u16 {
    #[cfg(feature = "nucleo-f401re")]
    {
        adc.sqr3().write(|w| w.set_sq(0, ch));
        adc.sr().modify(|w| w.set_eoc(false));
        adc.cr2().modify(|w| w.set_swstart(true));
        while !adc.sr().read().eoc() {}
        adc.dr().read().data()
    }
    #[cfg(not(feature = "nucleo-f401re"))]
    {
        adc.sqr1().write(|w| w.set_sq(0, ch));
        adc.isr().write(|w| w.set_eoc(true));
        adc.cr().modify(|w| w.set_adstart(true));
        while !adc.isr().read().eoc() {}
        #[cfg(feature = "nucleo-g431rb")]
        return adc.dr().read().rdata();
        #[cfg(not(feature = "nucleo-g431rb"))]
        adc.dr().read().regular_data()
    }
}

/// Enables `adc` if it is not (embassy-stm32's F4 driver does it in its constructor, its L4
/// driver only at its first conversion).
pub fn enable(adc: pac::adc::Adc) {
    #[cfg(not(feature = "nucleo-f401re"))]
    if !adc.cr().read().aden() {
        adc.isr().write(|w| w.set_adrdy(true));
        adc.cr().modify(|w| w.set_aden(true));
        while !adc.isr().read().adrdy() {}
    }
    #[cfg(feature = "nucleo-f401re")]
    let _ = adc;
}

/// Sets the sample time of channel `ch` (0..=18) of `adc`.
fn set_sample_time(adc: pac::adc::Adc, ch: u8, t: SampleTime) {
    let (low, shift) = (ch < 10, u32::from(ch % 10) * 3);
    let set = |bits: &mut u32| *bits = (*bits & !(7 << shift)) | (u32::from(t.to_bits()) << shift);
    // Channels 0..=9 in one register, 10..=18 in the next (named SMPR2/SMPR1 on the F4).
    #[cfg(feature = "nucleo-f401re")]
    if low {
        adc.smpr2().modify(|w| set(&mut w.0));
    } else {
        adc.smpr1().modify(|w| set(&mut w.0));
    }
    #[cfg(feature = "nucleo-g431rb")]
    if low {
        adc.smpr().modify(|w| set(&mut w.0));
    } else {
        adc.smpr2().modify(|w| set(&mut w.0));
    }
    #[cfg(feature = "b-l475e-iot01a")]
    adc.smpr(usize::from(!low)).modify(|w| set(&mut w.0));
}

/// The independent watchdog at [`WATCHDOG_TIMEOUT_US`], by its registers: the prescaler and
/// reload embassy-stm32's driver would choose (the smallest prescaler that reaches the
/// timeout), without its search and range checks.
pub struct Iwdg(());

/// The LSI that clocks the IWDG, Hz (nominal, the same on every board here).
const LSI_HZ: u32 = 32_000;
/// The IWDG's prescaler for [`WATCHDOG_TIMEOUT_US`] (÷4, its smallest: 4096 counts of 125 µs
/// reach 512 ms) as its register value, and the reload that gives the timeout (3999).
const IWDG_PR: u8 = 0;
const IWDG_RL: u16 = (WATCHDOG_TIMEOUT_US / 4 * LSI_HZ / 1_000_000) as u16 - 1;
const _: () = assert!(4096 * 4 * (1_000_000 / 1000) / (LSI_HZ / 1000) >= WATCHDOG_TIMEOUT_US);

impl Iwdg {
    /// Sets the period (the IWDG runs only once started).
    fn new(_iwdg: Peri<'static, IWDG>) -> Self {
        use embassy_stm32::pac::iwdg::vals::{Key, Pr};
        let w = pac::IWDG;
        w.kr().write(|k| k.set_key(Key::ENABLE));
        w.pr().write(|p| p.set_pr(Pr::from_bits(IWDG_PR)));
        w.rlr().write(|r| r.set_rl(IWDG_RL));
        Iwdg(())
    }
}

impl Watchdog for Iwdg {
    fn start(&mut self) {
        pac::IWDG
            .kr()
            .write(|k| k.set_key(embassy_stm32::pac::iwdg::vals::Key::START));
    }

    fn feed(&mut self) {
        pac::IWDG
            .kr()
            .write(|k| k.set_key(embassy_stm32::pac::iwdg::vals::Key::RESET));
    }
}

/// The parts of a hardware board from its configured peripherals; starts the DWT cycle
/// counter for [`cycles`].
pub fn parts(
    sensors: Sensors,
    heaters: Heaters,
    serial: BufferedUart<'static>,
    iwdg: Peri<'static, IWDG>,
    flash: Peri<'static, embassy_stm32::peripherals::FLASH>,
    reset_flags: ResetFlags,
) -> HardwareParts {
    // SAFETY: only these two registers of the core's peripherals are touched, once, here;
    // nothing else in the firmware takes the core peripherals.
    let mut cp = unsafe { cortex_m::Peripherals::steal() };
    cp.DCB.enable_trace();
    cp.DWT.enable_cycle_counter();
    let (tx, rx) = serial.split();
    Parts {
        sensors,
        heaters,
        watchdog: Iwdg::new(iwdg),
        tx,
        rx: SerialRx(ManuallyDrop::new(rx)),
        reset_flags,
        last_fatal: crate::reset_record::take(),
        settings_flash: SettingsFlash(flash::Flash::new_blocking(flash)),
    }
}
