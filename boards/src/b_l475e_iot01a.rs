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
//! | supply cut-off (its driver's gate) | PB2 (D8) | GPIO, push-pull; low = cut |
//! | PLA current: INA180A1 output | PC3 (A2) | ADC1_IN4 |
//! | TCA current: INA180A1 output | PC0 (A5) | ADC1_IN1 |
//! | ST-LINK virtual COM port | PB6 TX / PB7 RX | USART1, 115 200 8N1 |
//!
//! Current sense: a 50 mΩ low-side shunt per heater into an INA180A1 (gain 20, 1 V/A at the
//! ADC), on the thermistors' ADC1; the conversions are timed against TIM3's counter
//! (`stm32`, "Sampling the currents inside the pulse"), 24.5 ADC cycles of sampling (0.3 µs)
//! each, after one discarded conversion (the L4's erratum on a first conversion after a
//! pause). Written and built, never run on a board.
//!
//! The heater gates are on PA6/PA7 because those pins have no pull-up from reset until `init`
//! (input on the F4, analog on the G4 and L4), so the external gate pull-downs hold both heaters
//! off. Not PB4 (Arduino D5): it is JTAG NJTRST with an internal pull-up at reset, which against
//! a 100 kΩ pull-down would half-open a logic-level MOSFET.
//!
//! Clocks: HSI 16 MHz → PLL (/1 ×10 /2) → 80 MHz core, APB1 = APB2 = 80 MHz; ADC kernel
//! clock SYSCLK. TIM2 is the embassy time driver.

use crate::stm32 as common;
use crate::stm32::Shunts;
pub use crate::stm32::{
    cycles, fatal, HardwareParts as Parts, Heaters, Iwdg, Sensors, SerialRx, SerialTx,
    SettingsFlash,
};
use crate::{ResetFlags, ShuntChain};
use embassy_stm32::adc::{AdcChannel, AnyAdcChannel, SampleTime};
use embassy_stm32::peripherals::{ADC1, USART1};
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
/// Sample time of the current inputs: 24.5 cycles at 80 MHz, 0.3 µs (the INA180's output is a
/// low-impedance source), so two conversions take under 1 µs.
const SHUNT_SAMPLE_TIME: SampleTime = SampleTime::CYCLES24_5;

/// The current-sense chain: 50 mΩ into an INA180A1.
pub const SHUNT: ShuntChain = ShuntChain::INA180A1;

/// The supply cut-off's pin, PB2 (Arduino D8): analog from reset, so the driver's 100 kΩ
/// pull-down holds the cut-off open.
const CUTOFF: common::RawPin = (pac::GPIOB, 2);

/// Drives the cut-off and both heater gates low by raw register writes, whatever state the
/// firmware is in (the panic and HardFault handlers).
pub fn heater_pins_low() {
    common::heater_pins_low(CUTOFF);
}

bind_interrupts!(struct Irqs {
    USART1 => usart::BufferedInterruptHandler<USART1>;
});

/// Powers and calibrates ADC1 by registers, the steps of embassy-stm32's `Adc::new` on the L4
/// (its clock: SYSCLK, 80 MHz, the kernel clock `init` selects); `Sensors::new` enables it.
fn adc1_on() {
    embassy_stm32::rcc::enable_and_reset_without_stop::<ADC1>();
    let a = pac::ADC1;
    a.cr().modify(|w| {
        w.set_deeppwd(false);
        w.set_advregen(true);
    });
    // The regulator's start-up time, 20 µs; then the calibration, and 1 µs before enabling.
    cortex_m::asm::delay(20 * (CPU_HZ / 1_000_000));
    a.cr().modify(|w| w.set_adcal(true));
    while a.cr().read().adcal() {}
    cortex_m::asm::delay(CPU_HZ / 1_000_000);
}

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
        // The reset clock: left as reset set it, not reconfigured (the PLL runs from the HSI).
        config.rcc.msi = None;
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

    let heaters = Heaters::new(common::heater_pwm(p.TIM3, p.PA6, p.PA7), CUTOFF, p.PB2);

    let shunts: [AnyAdcChannel<'static, ADC1>; 2] = [p.PC3.degrade_adc(), p.PC0.degrade_adc()];
    let _ = p.ADC1;
    adc1_on();
    let sensors = Sensors::new(
        [
            p.PC5.degrade_adc(),
            p.PC4.degrade_adc(),
            p.PC2.degrade_adc(),
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
        p.USART1,
        p.PB7,
        p.PB6,
        tx_buf,
        rx_buf,
        Irqs,
        common::uart_config(),
    )
    // Not `expect`: the error's Debug text would be carried in flash for a panic that cannot happen.
    .unwrap_or_else(|_| panic!("USART1 accepts 115200 8N1"));

    common::parts(sensors, heaters, serial, p.IWDG, p.FLASH, reset_flags)
}
