//! B-L475E-IOT01A (Discovery kit IoT node): STM32L475VG, Cortex-M4F, 1 MiB flash, 128 KiB RAM
//! (96 KiB SRAM1 used, see `memory.x` here). The board that also runs under QEMU:
//! [`init`] builds the peripheral drivers one by one ([`Sensors`], the heater timer, the
//! UART); the emulated build (`emulated`) swaps each for a simulated
//! link or a register-level driver without touching the tasks.
//!
//! | signal | pin (Arduino) | peripheral |
//! | --- | --- | --- |
//! | PLA heater MOSFET gate | PA6 (D12) | TIM3_CH1, AF2 |
//! | TCA heater MOSFET gate | PA7 (D11) | TIM3_CH2, AF2 |
//! | PLA thermistor | PC5 (A0) | ADC1_IN14 |
//! | TCA thermistor | PC4 (A1) | ADC1_IN13 |
//! | ambient thermistor | PC2 (A3) | ADC1_IN3 |
//! | supply divider | PC1 (A4) | ADC1_IN2 |
//! | ST-LINK virtual COM port | PB6 TX / PB7 RX | USART1, 115 200 8N1 |
//!
//! The heater gates are on PA6/PA7 because those pins have no pull-up from reset until `init`
//! (input on the F4, analog on the G4 and L4), so the external gate pull-downs hold both heaters
//! off. Not PB4 (Arduino D5): it is JTAG NJTRST with an internal pull-up at reset, which against
//! a 100 kΩ pull-down would half-open a logic-level MOSFET.
//!
//! Clocks: HSI 16 MHz → PLL (/1 ×10 /2) → 80 MHz core, APB1 = APB2 = 80 MHz; ADC kernel
//! clock SYSCLK. TIM2 is the embassy time driver.

use crate::stm32 as common;
pub use crate::stm32::{
    cycles, fatal, heater_pins_low, HardwareParts as Parts, Heaters, Iwdg, Sensors, SerialRx,
    SerialTx, SettingsFlash,
};
use crate::ResetFlags;
use embassy_stm32::adc::{Adc, AdcChannel, SampleTime};
use embassy_stm32::peripherals::USART1;
use embassy_stm32::usart::{self, BufferedUart};
use embassy_stm32::{bind_interrupts, pac};

/// Board name, as in the `board-b-l475e-iot01a` feature and the boot line.
pub const NAME: &str = "b-l475e-iot01a";
/// Core clock, Hz (converts cycle counts to µs for `STATS`).
pub const CPU_HZ: u32 = 80_000_000;
/// Conversions the ADC sums in hardware per read: none here (the L4 oversampler is left off so the
/// emulated ADC stays simple), so the control task sums
/// 16 reads spread over the burst.
pub const HW_OVERSAMPLE: u32 = 1;

/// ADC sample time: the longest, because the thermistor dividers are 5–10 kΩ sources and the
/// supply divider 8.2 kΩ; 640.5 cycles at 80 MHz is 8 µs per conversion.
const SAMPLE_TIME: SampleTime = SampleTime::CYCLES640_5;

bind_interrupts!(struct Irqs {
    USART1 => usart::BufferedInterruptHandler<USART1>;
});

/// Reads and clears the reset flags in RCC_CSR.
fn take_reset_flags() -> ResetFlags {
    let csr = pac::RCC.csr().read();
    pac::RCC.csr().modify(|w| w.set_rmvf(true));
    ResetFlags {
        watchdog: csr.iwdgrstf(),
        window_watchdog: csr.wwdgrstf(),
        software: csr.sftrstf() || csr.oblrstf() || csr.fwrstf(),
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
        // HSI, not the MSI: ±1 % over temperature without LSE trimming is plenty for
        // 115 200 Bd and for thermal timing.
        config.rcc.hsi = true;
        config.rcc.pll = Some(Pll {
            source: PllSource::HSI,
            prediv: PllPreDiv::DIV1,
            mul: PllMul::MUL10,
            divp: None,
            divq: None,
            divr: Some(PllRDiv::DIV2),
        });
        config.rcc.sys = Sysclk::PLL1_R;
        config.rcc.mux.adcsel = mux::Adcsel::SYS;
    }
    let p = embassy_stm32::init(config);

    let pwm = common::heater_pwm(p.TIM3, p.PA6, p.PA7);

    let sensors = Sensors::new(
        Adc::new(p.ADC1),
        [
            p.PC5.degrade_adc(),
            p.PC4.degrade_adc(),
            p.PC2.degrade_adc(),
            p.PC1.degrade_adc(),
        ],
        SAMPLE_TIME,
    );

    let (tx_buf, rx_buf) = common::uart_buffers();
    let serial = BufferedUart::new(
        p.USART1,
        p.PB7,
        p.PB6,
        tx_buf,
        rx_buf,
        Irqs,
        common::uart_config(),
    )
    .expect("USART1 accepts 115200 8N1");

    common::parts(sensors, pwm, serial, p.IWDG, p.FLASH, reset_flags)
}
