//! NOR flash in RAM: the settings store's flash for the tests and, kept in a file, for
//! `morph-sim --flash-file`. It behaves as the STM32 parts' internal flash does where the store
//! could tell: erase sets a page to `0xFF`, a write may only clear bits and each word may be
//! written once per erase (as the G4's and L4's ECC-checked double words demand), accesses
//! must be aligned. It counts erases and written bytes, and can lose power part-way through a
//! write or an erase ([`RamFlash::fail_after_bytes`]).

use embedded_storage_async::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};

/// A RAM flash of `BYTES` bytes in pages of `PAGE` bytes, written in words of `WORD` bytes.
#[derive(Clone, Debug)]
pub struct RamFlash<const BYTES: usize, const PAGE: usize, const WORD: usize> {
    data: [u8; BYTES],
    /// Non-zero for a word written since its page was last erased (at the word's first byte).
    /// Plain bytes, not `bool`s, and the budget below a plain integer: any bit pattern is a
    /// valid `RamFlash`, so one kept in RAM across a reset can never be an invalid value.
    written: [u8; BYTES],
    /// Pages erased since creation.
    pub erases: u32,
    /// Bytes written since creation.
    pub bytes_written: u32,
    /// Power fails once this many more bytes have been written or erased: the operation under
    /// way stops there (a write keeps the words before that point, an erase leaves the rest of
    /// its page as it was) and every later operation fails, as a board that lost power would.
    /// `u32::MAX` never fails.
    pub fail_after_bytes: u32,
}

/// A [`RamFlash`] error.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RamFlashError {
    /// Misaligned offset or length.
    NotAligned,
    /// Outside the flash.
    OutOfBounds,
    /// A word written twice without an erase between.
    WrittenTwice,
    /// Power was lost ([`RamFlash::fail_after_bytes`]).
    PowerLost,
}

impl NorFlashError for RamFlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            RamFlashError::NotAligned => NorFlashErrorKind::NotAligned,
            RamFlashError::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            _ => NorFlashErrorKind::Other,
        }
    }
}

impl<const BYTES: usize, const PAGE: usize, const WORD: usize> Default
    for RamFlash<BYTES, PAGE, WORD>
{
    fn default() -> Self {
        Self::new()
    }
}

impl<const BYTES: usize, const PAGE: usize, const WORD: usize> RamFlash<BYTES, PAGE, WORD> {
    const _GEOMETRY: () = assert!(BYTES.is_multiple_of(PAGE) && PAGE.is_multiple_of(WORD));

    /// An erased flash.
    pub const fn new() -> Self {
        #[allow(clippy::let_unit_value)]
        let () = Self::_GEOMETRY;
        RamFlash {
            data: [0xFF; BYTES],
            written: [0; BYTES],
            erases: 0,
            bytes_written: 0,
            fail_after_bytes: u32::MAX,
        }
    }

    /// A flash holding `image` (e.g. read back from a file); words that are not all `0xFF`
    /// count as written. `None` if `image` is not exactly `BYTES` long.
    pub fn from_image(image: &[u8]) -> Option<Self> {
        if image.len() != BYTES {
            return None;
        }
        let mut f = Self::new();
        f.data.copy_from_slice(image);
        for (w, word) in f.data.chunks(WORD).enumerate() {
            f.written[w * WORD] = word.iter().any(|&b| b != 0xFF) as u8;
        }
        Some(f)
    }

    /// The whole content.
    pub fn image(&self) -> &[u8] {
        &self.data
    }

    /// Spends `n` bytes of the power budget; the bytes allowed before power fails.
    fn budget(&mut self, n: u32) -> u32 {
        if self.fail_after_bytes == u32::MAX {
            return n;
        }
        let ok = n.min(self.fail_after_bytes);
        self.fail_after_bytes -= ok;
        ok
    }

    fn powered(&self) -> Result<(), RamFlashError> {
        match self.fail_after_bytes {
            0 => Err(RamFlashError::PowerLost),
            _ => Ok(()),
        }
    }

    fn check(&self, offset: u32, len: usize, align: usize) -> Result<usize, RamFlashError> {
        let start = offset as usize;
        if !start.is_multiple_of(align) || !len.is_multiple_of(align) {
            return Err(RamFlashError::NotAligned);
        }
        if start + len > BYTES {
            return Err(RamFlashError::OutOfBounds);
        }
        Ok(start)
    }
}

impl<const BYTES: usize, const PAGE: usize, const WORD: usize> ErrorType
    for RamFlash<BYTES, PAGE, WORD>
{
    type Error = RamFlashError;
}

impl<const BYTES: usize, const PAGE: usize, const WORD: usize> ReadNorFlash
    for RamFlash<BYTES, PAGE, WORD>
{
    const READ_SIZE: usize = 1;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        self.powered()?;
        let start = self.check(offset, bytes.len(), 1)?;
        bytes.copy_from_slice(&self.data[start..start + bytes.len()]);
        Ok(())
    }

    fn capacity(&self) -> usize {
        BYTES
    }
}

impl<const BYTES: usize, const PAGE: usize, const WORD: usize> NorFlash
    for RamFlash<BYTES, PAGE, WORD>
{
    const WRITE_SIZE: usize = WORD;
    const ERASE_SIZE: usize = PAGE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        self.powered()?;
        let start = self.check(from, (to.saturating_sub(from)) as usize, PAGE)?;
        let end = to as usize;
        for page in (start..end).step_by(PAGE) {
            let n = self.budget(PAGE as u32) as usize;
            self.data[page..page + n].fill(0xFF);
            self.written[page..page + n].fill(0);
            if n < PAGE {
                return Err(RamFlashError::PowerLost);
            }
            self.erases += 1;
        }
        Ok(())
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        self.powered()?;
        let start = self.check(offset, bytes.len(), WORD)?;
        for w in (0..bytes.len()).step_by(WORD) {
            if self.written[start + w] != 0 {
                return Err(RamFlashError::WrittenTwice);
            }
        }
        for (w, word) in bytes.chunks(WORD).enumerate() {
            let at = start + w * WORD;
            let n = self.budget(WORD as u32) as usize;
            for (d, &b) in self.data[at..at + n].iter_mut().zip(word) {
                *d &= b;
            }
            self.written[at] = 1;
            self.bytes_written += n as u32;
            if n < WORD {
                return Err(RamFlashError::PowerLost);
            }
        }
        Ok(())
    }
}
