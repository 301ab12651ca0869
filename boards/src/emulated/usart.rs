//! Register-level USART1 for QEMU's STM32L4 USART model: 32-bit accesses only (QEMU faults on
//! byte access to TDR/RDR), receive by interrupt into a ring buffer, transmit by polling TXE
//! (QEMU sends at once). No IDLE detection, which QEMU never signals.

use core::cell::RefCell;
use core::future::poll_fn;
use core::task::Poll;
use critical_section::Mutex;
use embassy_stm32::interrupt;
use embassy_sync::waitqueue::AtomicWaker;
use heapless::Deque;

const BASE: usize = 0x4001_3800;
const CR1: usize = 0x00;
const BRR: usize = 0x0C;
const ISR: usize = 0x1C;
const RDR: usize = 0x24;
const TDR: usize = 0x28;
const CR1_UE: u32 = 1 << 0;
const CR1_RE: u32 = 1 << 2;
const CR1_TE: u32 = 1 << 3;
const CR1_RXNEIE: u32 = 1 << 5;
const ISR_ORE: u32 = 1 << 3;
const ISR_RXNE: u32 = 1 << 5;
const ISR_TXE: u32 = 1 << 7;
/// RCC_APB2ENR and its USART1EN bit.
const RCC_APB2ENR: usize = 0x4002_1060;
const USART1EN: u32 = 1 << 14;

/// Received bytes not yet read, bytes: four maximal lines, as the hardware build's buffer.
pub const RX_BYTES: usize = 256;

static RX: Mutex<RefCell<Deque<u8, RX_BYTES>>> = Mutex::new(RefCell::new(Deque::new()));
static RX_WAKER: AtomicWaker = AtomicWaker::new();

fn read(off: usize) -> u32 {
    // SAFETY: a valid, aligned USART1 register; 32-bit access as QEMU requires.
    unsafe { ((BASE + off) as *const u32).read_volatile() }
}

fn write(off: usize, v: u32) {
    // SAFETY: as `read`.
    unsafe { ((BASE + off) as *mut u32).write_volatile(v) }
}

/// Serial errors (none can happen on the emulated port; the type exists for the traits).
#[derive(Debug, defmt::Format)]
pub enum Error {}

impl core::fmt::Display for Error {
    fn fmt(&self, _: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {}
    }
}

impl core::error::Error for Error {}

impl embedded_io_async::Error for Error {
    fn kind(&self) -> embedded_io_async::ErrorKind {
        match *self {}
    }
}

/// Transmit half.
pub struct Tx(());
/// Receive half.
pub struct Rx(());

/// Enables USART1 at `baud` from a `cpu_hz` kernel clock, with the receive interrupt on.
pub fn init(cpu_hz: u32, baud: u32) -> (Tx, Rx) {
    // SAFETY: read-modify-write of the clock-enable register during start-up.
    unsafe {
        let en = RCC_APB2ENR as *mut u32;
        en.write_volatile(en.read_volatile() | USART1EN);
    }
    write(BRR, cpu_hz / baud);
    write(CR1, CR1_UE | CR1_RE | CR1_TE | CR1_RXNEIE);
    // SAFETY: the handler below is ready before the interrupt is unmasked.
    unsafe { cortex_m::peripheral::NVIC::unmask(embassy_stm32::pac::Interrupt::USART1) };
    (Tx(()), Rx(()))
}

#[interrupt]
fn USART1() {
    loop {
        let isr = read(ISR);
        if isr & (ISR_RXNE | ISR_ORE) == 0 {
            break;
        }
        let byte = read(RDR) as u8;
        // A flood beyond the buffer is dropped; the line assembler then reports a bad line.
        critical_section::with(|cs| {
            let _ = RX.borrow(cs).borrow_mut().push_back(byte);
        });
    }
    RX_WAKER.wake();
}

impl embedded_io_async::ErrorType for Tx {
    type Error = Error;
}

impl embedded_io_async::ErrorType for Rx {
    type Error = Error;
}

impl embedded_io_async::Write for Tx {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Error> {
        for &b in buf {
            while read(ISR) & ISR_TXE == 0 {}
            write(TDR, u32::from(b));
        }
        Ok(buf.len())
    }

    async fn flush(&mut self) -> Result<(), Error> {
        while read(ISR) & ISR_TXE == 0 {}
        Ok(())
    }
}

impl embedded_io_async::Read for Rx {
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, Error> {
        poll_fn(|cx| {
            RX_WAKER.register(cx.waker());
            let n = critical_section::with(|cs| {
                let mut q = RX.borrow(cs).borrow_mut();
                let mut n = 0;
                while n < buf.len() {
                    match q.pop_front() {
                        Some(b) => {
                            buf[n] = b;
                            n += 1;
                        }
                        None => break,
                    }
                }
                n
            });
            if n == 0 || buf.is_empty() {
                if buf.is_empty() {
                    return Poll::Ready(Ok(0));
                }
                Poll::Pending
            } else {
                Poll::Ready(Ok(n))
            }
        })
        .await
    }
}
