//! NUCLEO-G431RB: STM32G431RB, Cortex-M4F, 128 KiB flash, 32 KiB RAM (22 KiB used, see
//! `memory.x` here). Uses the G4's hardware ADC oversampler: one read returns the sum of 16
//! conversions.
//!
//! | signal | pin (Arduino) | peripheral |
//! | --- | --- | --- |
//! | PLA heater MOSFET gate | PA6 (D12) | TIM3_CH1, AF2 |
//! | TCA heater MOSFET gate | PA7 (D11) | TIM3_CH2, AF2 |
//! | PLA thermistor | PA0 (A0) | ADC1_IN1 |
//! | TCA thermistor | PA1 (A1) | ADC1_IN2 |
//! | ambient thermistor | PB0 (A3) | ADC1_IN15 |
//! | supply divider | PC1 (A4) | ADC1_IN7 |
//! | ST-LINK virtual COM port | PA2 TX / PA3 RX | LPUART1, 115 200 8N1 |
//!
//! The heater gates are on PA6/PA7 because those pins have no pull-up from reset until `init`
//! (input on the F4, analog on the G4 and L4), so the external gate pull-downs hold both heaters
//! off. Not PB4 (Arduino D5): it is JTAG NJTRST with an internal pull-up at reset, which against
//! a 100 kΩ pull-down would half-open a logic-level MOSFET.
//!
//! Clocks: HSI 16 MHz → PLL (/4 ×85 /2) → 170 MHz core (boost mode), APB1 = APB2 = 170 MHz;
//! ADC12 kernel clock SYSCLK/4 = 42.5 MHz. TIM2 is the embassy time driver. (A2 is PA4, which
//! only ADC2 reads, so the ambient thermistor sits on A3 on every board.)

use crate::stm32 as common;
pub use crate::stm32::{
    cycles, fatal, heater_pins_low, HardwareParts as Parts, Heaters, Iwdg, Sensors, SerialRx,
    SerialTx, SettingsFlash,
};
use crate::ResetFlags;
use embassy_stm32::adc::vals::{Rovsm, Trovs};
use embassy_stm32::adc::{Adc, AdcChannel, AdcConfig, SampleTime};
use embassy_stm32::peripherals::LPUART1;
use embassy_stm32::usart::{self, BufferedUart};
use embassy_stm32::{bind_interrupts, pac};

/// Board name, as in the `board-nucleo-g431rb` feature and the boot line.
pub const NAME: &str = "nucleo-g431rb";
/// Core clock, Hz (converts cycle counts to µs for `STATS`).
pub const CPU_HZ: u32 = 170_000_000;
/// Conversions the ADC sums in hardware per read: the G4 oversampler sums 16 (ratio ×16, no
/// shift: 16 × 4095 = 65 520 fits the 16-bit data register), so the control task reads once.
pub const HW_OVERSAMPLE: u32 = 16;
/// Oversampling ratio register value for ×16 (OVSR = 3).
const OVERSAMPLING_RATIO_X16: u8 = 3;

/// ADC sample time: the longest, because the thermistor dividers are 5–10 kΩ sources and the
/// supply divider 8.2 kΩ; 640.5 cycles at 42.5 MHz is 15 µs, 0.25 ms per 16-fold read.
const SAMPLE_TIME: SampleTime = SampleTime::CYCLES640_5;

bind_interrupts!(struct Irqs {
    LPUART1 => usart::BufferedInterruptHandler<LPUART1>;
});

/// Reads and clears the reset flags in RCC_CSR.
fn take_reset_flags() -> ResetFlags {
    let csr = pac::RCC.csr().read();
    pac::RCC.csr().modify(|w| w.set_rmvf(true));
    ResetFlags {
        watchdog: csr.iwdgrstf(),
        window_watchdog: csr.wwdgrstf(),
        software: csr.sftrstf() || csr.oblrstf(),
        low_power: csr.lpwrrstf(),
        power_on: csr.borrstf(),
        pin: csr.pinrstf(),
    }
}

/// Sets up clocks and peripherals.
pub fn init() -> Parts {
    let reset_flags = take_reset_flags();
    let mut config = embassy_stm32::Config::default();
    {
        use embassy_stm32::rcc::*;
        // HSI, not the ST-LINK's MCO: no solder-bridge dependence, and its ±1 % is plenty for
        // 115 200 Bd and for thermal timing.
        config.rcc.hsi = true;
        config.rcc.pll = Some(Pll {
            source: PllSource::HSI,
            prediv: PllPreDiv::DIV4,
            mul: PllMul::MUL85,
            divp: None,
            divq: None,
            divr: Some(PllRDiv::DIV2),
        });
        config.rcc.sys = Sysclk::PLL1_R;
        config.rcc.boost = true;
        config.rcc.mux.adc12sel = mux::Adcsel::SYS;
    }
    let p = embassy_stm32::init(config);

    let pwm = common::heater_pwm(p.TIM3, p.PA6, p.PA7);

    let sensors = Sensors::new(
        Adc::new(
            p.ADC1,
            AdcConfig {
                oversampling_ratio: Some(OVERSAMPLING_RATIO_X16),
                oversampling_shift: Some(0),
                oversampling_mode: Some((Rovsm::CONTINUED, Trovs::AUTOMATIC, true)),
                ..AdcConfig::default()
            },
        ),
        [
            p.PA0.degrade_adc(),
            p.PA1.degrade_adc(),
            p.PB0.degrade_adc(),
            p.PC1.degrade_adc(),
        ],
        SAMPLE_TIME,
    );

    let (tx_buf, rx_buf) = common::uart_buffers();
    let serial = BufferedUart::new(
        p.LPUART1,
        p.PA3,
        p.PA2,
        tx_buf,
        rx_buf,
        Irqs,
        common::uart_config(),
    )
    .expect("LPUART1 accepts 115200 8N1");

    common::parts(sensors, pwm, serial, p.IWDG, p.FLASH, reset_flags)
}
