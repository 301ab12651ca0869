//! NUCLEO-F401RE: STM32F401RE, Cortex-M4F, 512 KiB flash, 96 KiB RAM (`memory.x` here). The
//! default board.
//!
//! | signal | pin (Arduino) | peripheral |
//! | --- | --- | --- |
//! | PLA heater MOSFET gate | PA6 (D12) | TIM3_CH1, AF2 |
//! | TCA heater MOSFET gate | PA7 (D11) | TIM3_CH2, AF2 |
//! | PLA thermistor | PA0 (A0) | ADC1_IN0 |
//! | TCA thermistor | PA1 (A1) | ADC1_IN1 |
//! | ambient thermistor | PB0 (A3) | ADC1_IN8 |
//! | supply divider | PC1 (A4) | ADC1_IN11 |
//! | supply cut-off (its driver's gate) | PA9 (D8) | GPIO, push-pull; low = cut |
//! | PLA current: INA180A1 output | PA4 (A2) | ADC1_IN4 |
//! | TCA current: INA180A1 output | PC0 (A5) | ADC1_IN10 |
//! | ST-LINK virtual COM port | PA2 TX / PA3 RX | USART2, 115 200 8N1 |
//!
//! Current sense: a 50 mΩ low-side shunt per heater into an INA180A1 (gain 20, 1 V/A at the
//! ADC), on the thermistors' ADC1; the conversions are timed against TIM3's counter
//! (`stm32`, "Sampling the currents inside the pulse"), 15 ADC cycles of sampling (0.7 µs)
//! each. Written and built, never run on a board.
//!
//! The heater gates are on PA6/PA7 because those pins have no pull-up from reset until `init`
//! (input on the F4, analog on the G4 and L4), so the external gate pull-downs hold both heaters
//! off. Not PB4 (Arduino D5): it is JTAG NJTRST with an internal pull-up at reset, which against
//! a 100 kΩ pull-down would half-open a logic-level MOSFET.
//!
//! Clocks: HSI 16 MHz → PLL (/8 ×168 /4) → 84 MHz core, APB1 42 MHz, APB2 84 MHz; ADC clock
//! PCLK2/4 = 21 MHz. TIM2 is the embassy time driver.

use crate::stm32 as common;
use crate::stm32::Shunts;
pub use crate::stm32::{
    cycles, fatal, HardwareParts as Parts, Heaters, Iwdg, Sensors, SerialRx, SerialTx,
    SettingsFlash,
};
use crate::{ResetFlags, ShuntChain};
use embassy_stm32::adc::{Adc, AdcChannel, AnyAdcChannel, SampleTime};
use embassy_stm32::peripherals::{ADC1, USART2};
use embassy_stm32::usart::{self, BufferedUart};
use embassy_stm32::{bind_interrupts, pac};

/// Board name, as in the `board-nucleo-f401re` feature and the boot line.
pub const NAME: &str = "nucleo-f401re";
/// Core clock, Hz (converts cycle counts to µs for `STATS`).
pub const CPU_HZ: u32 = 84_000_000;
/// Conversions the ADC sums in hardware per read: none on the F4, so the control task sums
/// 16 reads spread over the burst.
pub const HW_OVERSAMPLE: u32 = 1;

/// ADC sample time: the longest, because the thermistor dividers are 5–10 kΩ sources and the
/// supply divider 8.2 kΩ; 480 cycles at 21 MHz is 23 µs per conversion.
const SAMPLE_TIME: SampleTime = SampleTime::CYCLES480;
/// Sample time of the current inputs: 15 cycles at 21 MHz, 0.7 µs (the INA180's output is a
/// low-impedance source), so two conversions take 2.6 µs.
const SHUNT_SAMPLE_TIME: SampleTime = SampleTime::CYCLES15;

/// The current-sense chain: 50 mΩ into an INA180A1.
pub const SHUNT: ShuntChain = ShuntChain::INA180A1;

/// The supply cut-off's pin, PA9 (Arduino D8): an input without pull from reset, so the
/// driver's 100 kΩ pull-down holds the cut-off open.
const CUTOFF: common::RawPin = (pac::GPIOA, 9);

/// Drives the cut-off and both heater gates low by raw register writes, whatever state the
/// firmware is in (the panic and HardFault handlers).
pub fn heater_pins_low() {
    common::heater_pins_low(CUTOFF);
}

bind_interrupts!(struct Irqs {
    USART2 => usart::BufferedInterruptHandler<USART2>;
});

/// Reads and clears the reset flags in RCC_CSR.
fn take_reset_flags() -> ResetFlags {
    let csr = pac::RCC.csr().read();
    pac::RCC.csr().modify(|w| w.set_rmvf(true));
    ResetFlags {
        watchdog: csr.wdgrstf(),
        window_watchdog: csr.wwdgrstf(),
        software: csr.sftrstf(),
        low_power: csr.lpwrrstf(),
        power_on: csr.porrstf() || csr.borrstf(),
        pin: csr.padrstf(),
    }
}

/// Sets up clocks and peripherals.
pub fn init() -> Parts {
    let reset_flags = take_reset_flags();
    let mut config = embassy_stm32::Config::default();
    {
        use embassy_stm32::rcc::*;
        // HSI, not the ST-LINK's 8 MHz MCO: no solder-bridge dependence, and its ±1 % is
        // plenty for 115 200 Bd and for thermal timing.
        config.rcc.hsi = true;
        config.rcc.pll_src = PllSource::HSI;
        config.rcc.pll = Some(Pll {
            prediv: PllPreDiv::DIV8,
            mul: PllMul::MUL168,
            divp: Some(PllPDiv::DIV4),
            divq: Some(PllQDiv::DIV7),
            divr: None,
        });
        config.rcc.sys = Sysclk::PLL1_P;
        config.rcc.ahb_pre = AHBPrescaler::DIV1;
        config.rcc.apb1_pre = APBPrescaler::DIV2;
        config.rcc.apb2_pre = APBPrescaler::DIV1;
    }
    let p = embassy_stm32::init(config);

    let heaters = Heaters::new(common::heater_pwm(p.TIM3, p.PA6, p.PA7), CUTOFF, p.PA9);

    let shunts: [AnyAdcChannel<'static, ADC1>; 2] = [p.PA4.degrade_adc(), p.PC0.degrade_adc()];
    // ADC1's driver sets it up and is kept for the program's life: dropped, it would switch the
    // ADC off (the conversions are register writes, `stm32::convert`).
    core::mem::forget(Adc::new(p.ADC1));
    let sensors = Sensors::new(
        [
            p.PA0.degrade_adc(),
            p.PA1.degrade_adc(),
            p.PB0.degrade_adc(),
            p.PC1.degrade_adc(),
        ],
        SAMPLE_TIME,
        Some(Shunts::new(
            pac::ADC1,
            shunts.map(|c| c.get_hw_channel()),
            SHUNT_SAMPLE_TIME,
        )),
    );

    let (tx_buf, rx_buf) = common::uart_buffers();
    let serial = BufferedUart::new(
        p.USART2,
        p.PA3,
        p.PA2,
        tx_buf,
        rx_buf,
        Irqs,
        common::uart_config(),
    )
    // Not `expect`: the error's Debug text would be carried in flash for a panic that cannot happen.
    .unwrap_or_else(|_| panic!("USART2 accepts 115200 8N1"));

    common::parts(sensors, heaters, serial, p.IWDG, p.FLASH, reset_flags)
}
