//! Firmware entry point. Builds only for the target (`thumbv7em-none-eabihf`); on the host it
//! prints how to build it.
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

#[cfg(target_os = "none")]
mod firmware {
    use core::panic::PanicInfo;

    #[cortex_m_rt::entry]
    fn main() -> ! {
        loop {
            cortex_m::asm::wfi();
        }
    }

    #[panic_handler]
    fn panic(_info: &PanicInfo) -> ! {
        loop {
            cortex_m::asm::nop();
        }
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "morphlink is firmware: build it with `cargo build --release --target thumbv7em-none-eabihf`; \
         on the host run `cargo run -p morphlink-host --bin morph-sim` instead"
    );
    std::process::exit(2);
}
