//! Register-level USART1 for QEMU's STM32L4 USART model: 32-bit accesses only (QEMU faults on
//! byte access to TDR/RDR), receive by interrupt into a ring buffer, transmit by polling TXE
//! (QEMU usually sends at once; when it cannot, the writer yields rather than spins). No IDLE detection, which QEMU never signals.
//!
//! Receive never loses a byte silently. QEMU has no baud rate: it hands over the next byte as
//! soon as RDR is read, so a host flood arrives as fast as the interrupt can take it. When the
//! ring is full the interrupt leaves the byte in RDR and masks itself; QEMU's serial backend
//! then waits (it offers no byte while RDR is full), the emulated stand-in for the wire pausing,
//! and [`Rx`] unmasks it once it has taken bytes. An overrun QEMU does flag (ORE) is reported
//! as lost input after the bytes already in the ring, and bytes are dropped until the reader
//! has seen that mark, so one gap is one marked line.

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
const ICR: usize = 0x20;
const ICR_ORECF: u32 = 1 << 3;
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
pub const RX_BYTES: usize = crate::SERIAL_RX_BYTES;

/// Received bytes, and where input was lost.
struct RxRing {
    q: Deque<u8, RX_BYTES>,
    /// Input was lost after this many of the queued bytes.
    gap: Option<usize>,
}

static RX: Mutex<RefCell<RxRing>> = Mutex::new(RefCell::new(RxRing {
    q: Deque::new(),
    gap: None,
}));

const CR1_ON: u32 = CR1_UE | CR1_RE | CR1_TE | CR1_RXNEIE;
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

/// Most bytes one [`Tx`] write sends. Every byte written to TDR is a round trip through QEMU's
/// TCP serial backend, measured at 50–70 µs of wall time (without QEMU's `-icount`, 1–1.4 ms of
/// firmware time at 20×; with it, as the tests run QEMU, none), so the serial task yields to the
/// control task after every byte.
pub const TX_PER_WRITE: usize = 1;

/// Most bytes one [`Rx`] read takes from the ring: all of it. (Smaller reads, tried at 1 and
/// 8 bytes, did not change the late ticks under a flood, and the firmware's ABORT-first scan
/// sees only what one read returns.)
pub const RX_PER_READ: usize = RX_BYTES;

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
    write(CR1, CR1_ON);
    // SAFETY: the handler below is ready before the interrupt is unmasked.
    unsafe { cortex_m::peripheral::NVIC::unmask(embassy_stm32::pac::Interrupt::USART1) };
    (Tx(()), Rx(()))
}

#[interrupt]
fn USART1() {
    loop {
        let isr = read(ISR);
        if isr & ISR_ORE != 0 {
            write(ICR, ICR_ORECF);
            critical_section::with(|cs| {
                let mut rx = RX.borrow(cs).borrow_mut();
                if rx.gap.is_none() {
                    rx.gap = Some(rx.q.len());
                }
            });
        }
        if isr & ISR_RXNE == 0 {
            break;
        }
        let taken = critical_section::with(|cs| {
            let mut rx = RX.borrow(cs).borrow_mut();
            if rx.q.is_full() {
                // Hold the byte in RDR (QEMU waits) until the reader makes room.
                write(CR1, CR1_ON & !CR1_RXNEIE);
                return false;
            }
            let byte = read(RDR) as u8;
            // Bytes after an unreported gap are part of it: one gap, one marked line.
            if rx.gap.is_none() {
                let _ = rx.q.push_back(byte);
            }
            true
        });
        if !taken {
            break;
        }
    }
    RX_WAKER.wake();
}

impl embedded_io_async::ErrorType for Tx {
    type Error = Error;
}

impl embedded_io_async::Write for Tx {
    /// Writes up to [`TX_PER_WRITE`] bytes QEMU takes now (TXE set), at least one: when it
    /// takes none (its serial backend is waiting for the host to read), the task yields
    /// instead of spinning, so the control task keeps running.
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Error> {
        let buf = &buf[..buf.len().min(TX_PER_WRITE)];
        if buf.is_empty() {
            return Ok(0);
        }
        poll_fn(|cx| {
            let mut n = 0;
            while n < buf.len() && read(ISR) & ISR_TXE != 0 {
                write(TDR, u32::from(buf[n]));
                n += 1;
            }
            if n == 0 {
                cx.waker().wake_by_ref();
                Poll::Pending
            } else {
                Poll::Ready(Ok(n))
            }
        })
        .await
    }

    async fn flush(&mut self) -> Result<(), Error> {
        poll_fn(|cx| {
            if read(ISR) & ISR_TXE != 0 {
                Poll::Ready(Ok(()))
            } else {
                cx.waker().wake_by_ref();
                Poll::Pending
            }
        })
        .await
    }
}

impl crate::SerialReceive for Rx {
    async fn receive(&mut self, buf: &mut [u8]) -> crate::Received {
        poll_fn(|cx| {
            RX_WAKER.register(cx.waker());
            let got = critical_section::with(|cs| {
                let mut rx = RX.borrow(cs).borrow_mut();
                let ahead = rx.gap.unwrap_or(rx.q.len()).min(RX_PER_READ);
                let mut len = 0;
                while len < buf.len().min(ahead) {
                    match rx.q.pop_front() {
                        Some(b) => {
                            buf[len] = b;
                            len += 1;
                        }
                        None => break,
                    }
                }
                let lost_after = match rx.gap {
                    Some(g) if g == len => {
                        rx.gap = None;
                        true
                    }
                    Some(g) => {
                        rx.gap = Some(g - len);
                        false
                    }
                    None => false,
                };
                (len, lost_after)
            });
            match got {
                (0, false) => Poll::Pending,
                (len, lost_after) => {
                    // Room again: let the interrupt take the byte it may be holding.
                    write(CR1, CR1_ON);
                    Poll::Ready(crate::Received { len, lost_after })
                }
            }
        })
        .await
    }
}
