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
//! | supply cut-off (its driver's gate) | PA9 (D8) | GPIO, push-pull; low = cut |
//! | PLA current: shunt into OPAMP2 | PB14 (morpho CN10) | OPAMP2_VINP1, PGA ×16 → ADC2_IN16 (internal) |
//! | TCA current: shunt into OPAMP3 | PB13 (morpho CN10) | OPAMP3_VINP1, PGA ×16 → ADC2_IN18 (internal) |
//! | ST-LINK virtual COM port | PA2 TX / PA3 RX | LPUART1, 115 200 8N1 |
//!
//! Current sense: a 50 mΩ low-side shunt per heater straight into an op-amp of the G431 as a
//! programmable-gain amplifier (×16: 0.8 V/A at the ADC, 4.1 A full scale), each op-amp's
//! offset trimmed by its calibration at boot; their outputs reach ADC2 internally, so ADC2
//! converts only currents (no hardware oversampling: one conversion per sample) while ADC1
//! oversamples the thermistors. The op-amps' other inputs are taken (PA1, PA3, PA7, PB0), so
//! their inputs are the morpho pins PB14 and PB13, not Arduino pins. The conversions are
//! timed against TIM3's counter (`stm32`, "Sampling the currents inside the pulse"), 24.5 ADC
//! cycles of sampling (0.6 µs) each. Written and built, never run on a board.
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
use crate::stm32::Shunts;
pub use crate::stm32::{
    cycles, fatal, HardwareParts as Parts, Heaters, Iwdg, Sensors, SerialRx, SerialTx,
    SettingsFlash,
};
use crate::{ResetFlags, ShuntChain};
use embassy_stm32::adc::{AdcChannel, SampleTime};
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
/// Sample time of the op-amps' outputs: 24.5 cycles at 42.5 MHz, 0.6 µs (the op-amp drives the
/// ADC's sampling capacitor directly; the datasheet's minimum for it is not checked here, so
/// this leaves margin), so two conversions take 1.7 µs.
const SHUNT_SAMPLE_TIME: SampleTime = SampleTime::CYCLES24_5;
/// ADC2's channels of OPAMP2's and OPAMP3's internal outputs (RM0440, "ADC connectivity").
const OPAMP_CHANNELS: [u8; 2] = [16, 18];

/// The current-sense chain: 50 mΩ into the op-amp as PGA at gain 16.
pub const SHUNT: ShuntChain = ShuntChain {
    shunt_ohm: 0.05,
    gain: 16.0,
};

/// The supply cut-off's pin, PA9 (Arduino D8): analog from reset, so the driver's 100 kΩ
/// pull-down holds the cut-off open.
const CUTOFF: common::RawPin = (pac::GPIOA, 9);

/// Drives the cut-off and both heater gates low by raw register writes, whatever state the
/// firmware is in (the panic and HardFault handlers).
pub fn heater_pins_low() {
    common::heater_pins_low(CUTOFF);
}

bind_interrupts!(struct Irqs {
    LPUART1 => usart::BufferedInterruptHandler<LPUART1>;
});

/// Cycles of `us` µs at the core clock, for busy waits before the scheduler runs.
const fn cycles_of_us(us: u32) -> u32 {
    us * (CPU_HZ / 1_000_000)
}

/// Makes `amp` a programmable-gain amplifier of gain 16 on its non-inverting input 1 (PB`pin`,
/// analog) with its output to the ADC inside the chip, after trimming its offset: both input
/// pairs' trims found by the reference manual's binary search against its comparator
/// (RM0440, "Calibration"; 2 ms per step, 20 ms in all). The same steps as embassy-stm32's
/// `OpAmp::calibrate` and `pga_int`, by registers, so one copy serves both op-amps.
fn pga_x16(amp: pac::opamp::Opamp, pin: usize) {
    use embassy_stm32::pac::opamp::vals::{Calsel, PgaGain, VmSel, VpSel};
    // MODER's two bits of the pin to 0b11, analog (as at reset; made sure of here).
    pac::GPIOB.moder().modify(|w| w.0 |= 0b11 << (2 * pin));
    amp.csr().modify(|w| {
        w.set_opampen(true);
        w.set_calon(true);
        w.set_usertrim(true);
    });
    for (calsel, n_pair) in [(Calsel::PERCENT10, false), (Calsel::PERCENT90, true)] {
        amp.csr().modify(|w| w.set_calsel(calsel));
        let (mut low, mut high) = (0u8, 31u8);
        while low <= high {
            let mid = (low + high) / 2;
            amp.csr().modify(|w| {
                if n_pair {
                    w.set_trimoffsetn(mid)
                } else {
                    w.set_trimoffsetp(mid)
                }
            });
            // The comparator settles within 2 ms of a trim step (RM0440).
            cortex_m::asm::delay(cycles_of_us(2_000));
            if !amp.csr().read().calout() {
                if mid == 0 {
                    break;
                }
                high = mid - 1;
            } else {
                if mid == 31 {
                    break;
                }
                low = mid + 1;
            }
        }
    }
    amp.csr().modify(|w| {
        w.set_calon(false);
        w.set_vp_sel(VpSel::VINP1);
        w.set_vm_sel(VmSel::PGA);
        w.set_pga_gain(PgaGain::GAIN16);
        w.set_opaintoen(true);
    });
}

/// ADC1 (the thermistors', its hardware oversampler summing 16 conversions: ratio ×16, no
/// shift, all 16 after one start) and ADC2 (the currents', one conversion each), by registers:
/// the steps of embassy-stm32's `Adc::new` for single-ended channels. Their shared clock is
/// SYSCLK / 4, 42.5 MHz (at most 60 MHz).
fn adcs_on() {
    use embassy_stm32::pac::adc::vals::{Adcaldif, Rovsm, Trovs};
    use embassy_stm32::pac::adccommon::vals::Presc;
    embassy_stm32::rcc::enable_and_reset::<embassy_stm32::peripherals::ADC1>();
    pac::ADC12_COMMON.ccr().modify(|w| w.set_presc(Presc::DIV4));
    for a in [pac::ADC1, pac::ADC2] {
        a.cr().modify(|w| {
            w.set_deeppwd(false);
            w.set_advregen(true);
        });
        // The regulator's start-up time, 20 µs.
        cortex_m::asm::delay(cycles_of_us(20));
        a.cr().modify(|w| w.set_adcaldif(Adcaldif::SINGLE_ENDED));
        a.cr().modify(|w| w.set_adcal(true));
        while a.cr().read().adcal() {}
        cortex_m::asm::delay(cycles_of_us(20));
        common::enable(a);
    }
    pac::ADC1.cfgr2().modify(|w| {
        w.set_ovsr(OVERSAMPLING_RATIO_X16);
        w.set_ovss(0);
        w.set_rovsm(Rovsm::CONTINUED);
        w.set_trovs(Trovs::AUTOMATIC);
        w.set_rovse(true);
    });
}

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

    let heaters = Heaters::new(common::heater_pwm(p.TIM3, p.PA6, p.PA7), CUTOFF, p.PA9);

    // The ADCs, and the op-amps as PGAs with their outputs inside the chip, into ADC2.
    let _ = (p.ADC1, p.ADC2, p.OPAMP2, p.OPAMP3, p.PB14, p.PB13);
    adcs_on();
    pga_x16(pac::OPAMP2, 14);
    pga_x16(pac::OPAMP3, 13);
    let shunts = Shunts::new(pac::ADC2, OPAMP_CHANNELS, SHUNT_SAMPLE_TIME);
    let sensors = Sensors::new(
        [
            p.PA0.degrade_adc(),
            p.PA1.degrade_adc(),
            p.PB0.degrade_adc(),
            p.PC1.degrade_adc(),
        ],
        SAMPLE_TIME,
        Some(shunts),
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
    // Not `expect`: the error's Debug text would be carried in flash for a panic that cannot happen.
    .unwrap_or_else(|_| panic!("LPUART1 accepts 115200 8N1"));

    common::parts(sensors, heaters, serial, p.IWDG, p.FLASH, reset_flags)
}
