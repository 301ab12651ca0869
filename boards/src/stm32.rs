//! What the hardware boards share: both heaters on TIM3 channels 1 and 2 (PA6 = Arduino D12,
//! PA7 = D11, pins without a pull-up at reset), the four analog inputs on ADC1, the independent
//! watchdog, the buffered UART, the DWT cycle counter and the reset that ends a fatal error.

use crate::{
    AnalogInputs, FatalKind, HeaterOutputs, Parts, Received, ResetFlags, SerialReceive, Watchdog,
    INPUTS,
};
use embassy_stm32::adc::{Adc, AnyAdcChannel, SampleTime};
use embassy_stm32::gpio::OutputType;
use embassy_stm32::peripherals::{ADC1, IWDG, PA6, PA7, TIM3};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::simple_pwm::{PwmPin, SimplePwm, SimplePwmChannel, SimplePwmChannels};
use embassy_stm32::timer::{Channel, GeneralInstance4Channel};
use embassy_stm32::usart::{self, BufferedUart, BufferedUartRx, BufferedUartTx};
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{pac, Peri};

/// Heater PWM frequency: 1 kHz. The heaters' thermal time constants are ≥ 1 s, so any
/// frequency above ~10 Hz gives a ripple-free temperature; 1 kHz keeps switching losses of
/// a GPIO-driven logic-level MOSFET negligible (edges of ~1 µs are 0.2 % of the period)
/// and still gives a 16-bit timer tens of thousands of duty steps.
pub const PWM_FREQUENCY: Hertz = Hertz(1_000);

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
/// NOT detected with embassy 0.6; the firmware masks no interrupts for that long.
pub struct SerialRx(BufferedUartRx<'static>);

impl SerialReceive for SerialRx {
    async fn receive(&mut self, buf: &mut [u8]) -> Received {
        match embedded_io_async::Read::read(&mut self.0, buf).await {
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
/// The chip's flash driver behind the async NOR-flash trait the settings store takes.
type FlashDriver = embassy_embedded_hal::adapter::BlockingAsync<
    embassy_stm32::flash::Flash<'static, embassy_stm32::flash::Blocking>,
>;

/// The chip's flash, for the settings area ([`crate::settings_area`]): embassy-stm32's driver
/// (offsets from the flash start; erase unit the largest sector: the F401's 128 KiB, the G4's
/// and L4's 2 KiB pages). An erase stalls the CPU (code runs from the same bank) for up to
/// 2 s on the F401, longer than [`WATCHDOG_TIMEOUT_US`]: the watchdog's period is stretched
/// to [`ERASE_WATCHDOG_S`] for the erase and put back after it. The firmware erases only with
/// the heaters off (SAVE is refused while a morph runs).
pub struct SettingsFlash(FlashDriver);

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
    const READ_SIZE: usize =
        <FlashDriver as embedded_storage_async::nor_flash::ReadNorFlash>::READ_SIZE;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        self.0.read(offset, bytes).await
    }

    fn capacity(&self) -> usize {
        self.0.capacity()
    }
}

impl embedded_storage_async::nor_flash::NorFlash for SettingsFlash {
    const WRITE_SIZE: usize =
        <FlashDriver as embedded_storage_async::nor_flash::NorFlash>::WRITE_SIZE;
    const ERASE_SIZE: usize =
        <FlashDriver as embedded_storage_async::nor_flash::NorFlash>::ERASE_SIZE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        let w = pac::IWDG;
        iwdg_settled();
        let (pr, rl) = (w.pr().read().pr().to_bits(), w.rlr().read().rl());
        iwdg_period(6, 0xFFF);
        let r = self.0.erase(from, to).await;
        iwdg_period(pr, rl);
        r
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        self.0.write(offset, bytes).await
    }
}
/// Both heaters on [`HeaterTimer`].
pub type Heaters = PwmHeaters<HeaterTimer>;

/// Drives one GPIO low as a plain output: sets the output latch low, then switches the
/// pin from its timer function to output mode. Raw register writes only, so it works from
/// a panic or HardFault whatever the drivers were doing (if the port's clock is still off,
/// the pin is in its reset state and the gate pull-down holds it low anyway).
pub fn force_low(port: pac::gpio::Gpio, pin: usize) {
    port.bsrr().write(|w| w.set_br(pin, true));
    port.moder()
        .modify(|w| w.set_moder(pin, pac::gpio::vals::Moder::OUTPUT));
}

/// Drives both heater gates low by raw register writes (output mode, level low), whatever
/// state the timer and the rest of the firmware are in. For the panic and HardFault handlers.
pub fn heater_pins_low() {
    force_low(pac::GPIOA, 6);
    force_low(pac::GPIOA, 7);
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
    let tx = cortex_m::singleton!(: [u8; UART_TX_BYTES] = [0; UART_TX_BYTES]).expect("called once");
    let rx = cortex_m::singleton!(: [u8; UART_RX_BYTES] = [0; UART_RX_BYTES]).expect("called once");
    (tx, rx)
}

/// 115 200 8N1.
pub fn uart_config() -> usart::Config {
    let mut c = usart::Config::default();
    c.baudrate = crate::BAUD;
    c
}

/// The heater timer with the PLA gate (PA6) on channel 1 and the TCA gate (PA7) on channel 2,
/// push-pull, at [`PWM_FREQUENCY`]; both at 0 % duty.
pub fn heater_pwm(
    tim: Peri<'static, HeaterTimer>,
    pla: Peri<'static, PA6>,
    tca: Peri<'static, PA7>,
) -> SimplePwm<'static, HeaterTimer> {
    SimplePwm::new(
        tim,
        Some(PwmPin::new(pla, OutputType::PushPull)),
        Some(PwmPin::new(tca, OutputType::PushPull)),
        None,
        None,
        PWM_FREQUENCY,
        CountingMode::EdgeAlignedUp,
    )
}

/// Both heater channels of one PWM timer.
pub struct PwmHeaters<T: GeneralInstance4Channel> {
    pla: SimplePwmChannel<'static, T>,
    tca: SimplePwmChannel<'static, T>,
}

impl<T: GeneralInstance4Channel> PwmHeaters<T> {
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
        PwmHeaters { pla, tca }
    }
}

impl<T: GeneralInstance4Channel> HeaterOutputs for PwmHeaters<T> {
    fn apply(&mut self, pla_duty: f32, tca_duty: f32) {
        set_duty(&mut self.pla, pla_duty);
        set_duty(&mut self.tca, tca_duty);
    }
}

/// Sets one channel's duty from a fraction: 0 (or not a number) is fully off.
fn set_duty<T: GeneralInstance4Channel>(ch: &mut SimplePwmChannel<'static, T>, duty: f32) {
    if duty > 0.0 {
        let max = ch.max_duty_cycle();
        ch.set_duty_cycle((duty.min(1.0) * max as f32) as u32);
    } else {
        ch.set_duty_cycle_fully_off();
    }
}

/// The thermistor and supply inputs on ADC1.
pub struct Sensors {
    adc: Adc<'static, ADC1>,
    channels: [AnyAdcChannel<'static, ADC1>; INPUTS],
    sample_time: SampleTime,
}

impl Sensors {
    /// The ADC with the PLA, TCA and ambient thermistor channels and the supply channel, in
    /// [`crate::Input`] order, each converted with `sample_time`.
    pub fn new(
        adc: Adc<'static, ADC1>,
        channels: [AnyAdcChannel<'static, ADC1>; INPUTS],
        sample_time: SampleTime,
    ) -> Self {
        Sensors {
            adc,
            channels,
            sample_time,
        }
    }
}

impl AnalogInputs for Sensors {
    fn read(&mut self) -> [u16; INPUTS] {
        let (adc, t) = (&mut self.adc, self.sample_time);
        self.channels.each_mut().map(|ch| adc.blocking_read(ch, t))
    }
}

/// The independent watchdog at [`WATCHDOG_TIMEOUT_US`].
pub struct Iwdg(IndependentWatchdog<'static, IWDG>);

impl Watchdog for Iwdg {
    fn start(&mut self) {
        self.0.unleash();
    }

    fn feed(&mut self) {
        self.0.pet();
    }
}

/// The parts of a hardware board from its configured peripherals; starts the DWT cycle
/// counter for [`cycles`].
pub fn parts(
    sensors: Sensors,
    pwm: SimplePwm<'static, HeaterTimer>,
    serial: BufferedUart<'static>,
    iwdg: Peri<'static, IWDG>,
    flash: Peri<'static, embassy_stm32::peripherals::FLASH>,
    reset_flags: ResetFlags,
) -> HardwareParts {
    let mut cp = cortex_m::Peripherals::take().expect("taken once");
    cp.DCB.enable_trace();
    cp.DWT.enable_cycle_counter();
    let (tx, rx) = serial.split();
    Parts {
        sensors,
        heaters: PwmHeaters::new(pwm, PLA_CHANNEL, TCA_CHANNEL),
        watchdog: Iwdg(IndependentWatchdog::new(iwdg, WATCHDOG_TIMEOUT_US)),
        tx,
        rx: SerialRx(rx),
        reset_flags,
        last_fatal: crate::reset_record::take(),
        settings_flash: SettingsFlash(embassy_embedded_hal::adapter::BlockingAsync::new(
            embassy_stm32::flash::Flash::new_blocking(flash),
        )),
    }
}
