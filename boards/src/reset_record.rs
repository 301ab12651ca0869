//! The fatal-error record: a few words of RAM in cortex-m-rt's `.uninit` section, which the
//! start-up code neither loads nor zeroes, so what a panic, HardFault or watchdog handler writes
//! there survives the reset that follows and the next boot can report it. A magic word marks
//! a valid record; boot reads it once and clears it.

use crate::{FatalKind, LastFatal, FATAL_REASON_BYTES};
use core::cell::UnsafeCell;
use core::fmt::{self, Write};
use core::mem::MaybeUninit;

/// Marks a record written by [`record`]; anything else is power-on garbage.
const MAGIC: u32 = 0x4D4C_4641; // "MLFA"
const KIND_FAULT: u32 = 1;
const KIND_WATCHDOG: u32 = 2;

#[repr(C)]
struct Record {
    magic: u32,
    kind: u32,
    len: u32,
    reason: [u8; FATAL_REASON_BYTES],
}

struct Slot(UnsafeCell<MaybeUninit<Record>>);

// SAFETY: written only by the fatal handlers (interrupts are of no concern: the record is
// written on the way to a reset, and a second writer only overwrites it), read once at boot
// before the tasks start.
unsafe impl Sync for Slot {}

#[link_section = ".uninit.morphlink_last_fatal"]
static SLOT: Slot = Slot(UnsafeCell::new(MaybeUninit::uninit()));

/// Writes the record for the coming reset: `kind` and the formatted `reason`, cut to fit.
pub fn record(kind: FatalKind, reason: fmt::Arguments) {
    struct Cut<'a>(&'a mut [u8; FATAL_REASON_BYTES], usize);
    impl Write for Cut<'_> {
        fn write_str(&mut self, s: &str) -> fmt::Result {
            for &b in s.as_bytes() {
                if self.1 < FATAL_REASON_BYTES {
                    self.0[self.1] = b;
                    self.1 += 1;
                }
            }
            Ok(())
        }
    }
    let mut reason_buf = [0u8; FATAL_REASON_BYTES];
    let mut cut = Cut(&mut reason_buf, 0);
    let _ = cut.write_fmt(reason);
    let len = cut.1;
    let rec = Record {
        magic: MAGIC,
        kind: match kind {
            FatalKind::Fault => KIND_FAULT,
            FatalKind::Watchdog => KIND_WATCHDOG,
        },
        len: len as u32,
        reason: reason_buf,
    };
    // SAFETY: see `Slot`; a plain volatile write of a whole record.
    unsafe { (SLOT.0.get() as *mut Record).write_volatile(rec) };
}

/// The record the previous run left, if any; clears it, so it is reported once.
pub fn take() -> Option<LastFatal> {
    // SAFETY: any bit pattern is a valid `Record` (integers and bytes); read once at boot.
    let rec = unsafe { (SLOT.0.get() as *const Record).read_volatile() };
    // SAFETY: as above; clearing the magic word invalidates the record.
    unsafe { core::ptr::addr_of_mut!((*(SLOT.0.get() as *mut Record)).magic).write_volatile(0) };
    if rec.magic != MAGIC {
        return None;
    }
    let kind = match rec.kind {
        KIND_WATCHDOG => FatalKind::Watchdog,
        _ => FatalKind::Fault,
    };
    let len = (rec.len as usize).min(FATAL_REASON_BYTES);
    Some(LastFatal::new(kind, &rec.reason[..len]))
}
