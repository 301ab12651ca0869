//! What the hardware boards share (each board includes this file): both heaters on TIM3
//! channels 1 and 2 (PA6 = Arduino D12, PA7 = D11, pins without a pull-up at reset), the four
//! analog inputs on ADC1, and the parts `init` hands to the firmware's tasks.

use embassy_stm32::adc::{Adc, AnyAdcChannel, SampleTime};
use embassy_stm32::peripherals::{ADC1, IWDG, TIM3};
use embassy_stm32::timer::simple_pwm::SimplePwm;
use embassy_stm32::timer::Channel;
use embassy_stm32::usart::BufferedUart;
use embassy_stm32::{pac, Peri};
use morphlink::stats::ResetFlags;

/// Timer driving both heaters.
pub type HeaterTimer = TIM3;
/// Timer channel of the PLA heater (PA6).
pub const PLA_CHANNEL: Channel = Channel::Ch1;
/// Timer channel of the TCA heater (PA7).
pub const TCA_CHANNEL: Channel = Channel::Ch2;

/// Drives both heater gates low by raw register writes (output mode, level low), whatever
/// state the timer and the rest of the firmware are in. For the panic and HardFault handlers.
pub fn heater_pins_low() {
    crate::force_low(pac::GPIOA, 6);
    crate::force_low(pac::GPIOA, 7);
}

/// The thermistor and supply inputs on ADC1.
pub struct Sensors {
    adc: Adc<'static, ADC1>,
    channels: [AnyAdcChannel<'static, ADC1>; 4],
    sample_time: SampleTime,
}

impl Sensors {
    /// The ADC with the PLA, TCA and ambient thermistor channels and the supply channel, in that
    /// order, each converted with `sample_time`.
    pub fn new(
        adc: Adc<'static, ADC1>,
        channels: [AnyAdcChannel<'static, ADC1>; 4],
        sample_time: SampleTime,
    ) -> Self {
        Sensors {
            adc,
            channels,
            sample_time,
        }
    }

    /// One read each of the PLA, TCA and ambient thermistors and the supply divider, counts
    /// (one conversion, or the sum of the board's hardware oversampling).
    pub fn read(&mut self) -> [u16; 4] {
        let (adc, t) = (&mut self.adc, self.sample_time);
        self.channels.each_mut().map(|ch| adc.blocking_read(ch, t))
    }
}

/// The board's peripherals, configured: heaters at 0 % duty, UART running.
pub struct Board {
    /// Thermistor and supply inputs.
    pub sensors: Sensors,
    /// Heater PWM timer (both channels at 0 % duty, outputs not yet enabled).
    pub pwm: SimplePwm<'static, HeaterTimer>,
    /// The ST-LINK virtual COM port.
    pub serial: BufferedUart<'static>,
    /// The independent watchdog, not started yet.
    pub iwdg: Peri<'static, IWDG>,
    /// Reset flags read (and cleared) at boot.
    pub reset_flags: ResetFlags,
}
