//! The settings in flash: one [`codec`](super::codec) blob under one key of a
//! sequential-storage map, over any NOR flash (`embedded-storage-async`'s [`NorFlash`]): the
//! boards' internal flash, the host's file-backed [`RamFlash`](super::ram_flash::RamFlash),
//! the tests' RAM flash.
//!
//! The map appends each SAVE as a new item after the old one and erases a page only when the
//! area is full, so a SAVE costs no erase most of the time; an item is valid only once wholly
//! written (its header's CRC), so a SAVE cut by a power loss leaves the previous blob in force.
//! The blob's own CRC ([`codec`](super::codec)) checks it again after load.

use super::codec::{self, Blob, LoadError, BLOB_MAX};
use super::Settings;
use core::future::Future;
use core::ops::Range;
use core::pin::pin;
use core::task::{Context, Poll, Waker};
use embedded_storage_async::nor_flash::{ErrorType, NorFlash, ReadNorFlash};
use sequential_storage::cache::Cache;
use sequential_storage::map::{MapConfig, MapStorage};

/// The map key the settings blob is stored under.
pub const SETTINGS_KEY: u8 = 1;

/// Work buffer of the map, bytes: the key, the largest blob and word alignment (8 bytes on the
/// G4 and L4).
pub const BUFFER_BYTES: usize = BLOB_MAX + 16;

/// Why a SAVE failed (the settings in flash are then the previous ones, or none).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StoreError {
    /// The settings area is not two or more whole erase pages.
    BadArea,
    /// The flash reported an error (or the map found it damaged).
    Flash,
}

impl StoreError {
    /// The reply's word.
    pub fn as_str(&self) -> &'static str {
        match self {
            StoreError::BadArea => "bad-area",
            StoreError::Flash => "flash-error",
        }
    }
}

/// What a SAVE did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SaveReport {
    /// Blob size, bytes.
    pub bytes: u32,
    /// Pages erased by this SAVE.
    pub erases: u32,
}

/// A flash that counts its erases (what a SAVE costs in wear).
struct Counting<'a, S> {
    flash: &'a mut S,
    erases: u32,
}

impl<S: ErrorType> ErrorType for Counting<'_, S> {
    type Error = S::Error;
}

impl<S: ReadNorFlash> ReadNorFlash for Counting<'_, S> {
    const READ_SIZE: usize = S::READ_SIZE;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        self.flash.read(offset, bytes).await
    }

    fn capacity(&self) -> usize {
        self.flash.capacity()
    }
}

impl<S: NorFlash> NorFlash for Counting<'_, S> {
    const WRITE_SIZE: usize = S::WRITE_SIZE;
    const ERASE_SIZE: usize = S::ERASE_SIZE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        self.erases += (to.saturating_sub(from)) / S::ERASE_SIZE as u32;
        self.flash.erase(from, to).await
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        self.flash.write(offset, bytes).await
    }
}

/// The settings area of a flash: `area` (byte offsets in `flash`), at least two erase pages.
pub struct SettingsStore<S> {
    flash: S,
    area: Range<u32>,
}

/// A word-aligned work buffer (some flash drivers want aligned RAM).
#[repr(align(8))]
struct Buffer([u8; BUFFER_BYTES]);

impl<S: NorFlash> SettingsStore<S> {
    /// The store over `area` of `flash`; [`StoreError::BadArea`] unless it is two or more
    /// whole erase pages.
    pub fn new(flash: S, area: Range<u32>) -> Result<Self, StoreError> {
        MapConfig::<S>::try_new(area.clone()).map_err(|_| StoreError::BadArea)?;
        Ok(SettingsStore { flash, area })
    }

    /// The flash, e.g. to write a file-backed one back to its file.
    pub fn flash(&self) -> &S {
        &self.flash
    }

    /// The flash, mutable (tests cut its power).
    pub fn flash_mut(&mut self) -> &mut S {
        &mut self.flash
    }

    /// The stored settings, or why the defaults must be used instead.
    pub async fn load(&mut self) -> Result<Settings, LoadError> {
        let mut buf = Buffer([0; BUFFER_BYTES]);
        let config = MapConfig::try_new(self.area.clone()).map_err(|_| LoadError::Flash)?;
        let mut map = MapStorage::<u8, _, _>::new(&mut self.flash, config, Cache::new_uncached());
        let found: Option<&[u8]> = map
            .fetch_item(&mut buf.0, &SETTINGS_KEY)
            .await
            .map_err(|_| LoadError::Flash)?;
        codec::decode(found.ok_or(LoadError::Absent)?)
    }

    /// Writes `blob` as the settings in force from now on.
    pub async fn save(&mut self, blob: &Blob) -> Result<SaveReport, StoreError> {
        self.save_bytes(blob.as_bytes()).await
    }

    /// Writes any bytes as the stored blob (what [`SettingsStore::save`] does with an encoded
    /// one; the tests store damaged blobs with it).
    pub async fn save_bytes(&mut self, bytes: &[u8]) -> Result<SaveReport, StoreError> {
        let mut buf = Buffer([0; BUFFER_BYTES]);
        let config = MapConfig::try_new(self.area.clone()).map_err(|_| StoreError::BadArea)?;
        let mut counting = Counting {
            flash: &mut self.flash,
            erases: 0,
        };
        let mut map = MapStorage::<u8, _, _>::new(&mut counting, config, Cache::new_uncached());
        match map.store_item(&mut buf.0, &SETTINGS_KEY, &bytes).await {
            Ok(()) => {}
            // An area the map cannot make sense of (never formatted, written by something
            // else), or one a power cut left with a half-programmed word the map then tries to
            // program again (the flash refuses a second write): the settings it held were read
            // at boot and are what the user is replacing, so start the area afresh, once. A cut
            // between the erase and the write boots with `reason=absent`: defaults, never
            // garbage (`power_lost_at_any_byte_...` below).
            Err(_) => {
                map.erase_all().await.map_err(|_| StoreError::Flash)?;
                map.store_item(&mut buf.0, &SETTINGS_KEY, &bytes)
                    .await
                    .map_err(|_| StoreError::Flash)?;
            }
        }
        drop(map);
        Ok(SaveReport {
            bytes: bytes.len() as u32,
            erases: counting.erases,
        })
    }

    /// Erases the whole settings area (the next boot then has no settings).
    pub async fn erase_all(&mut self) -> Result<(), StoreError> {
        self.flash
            .erase(self.area.start, self.area.end)
            .await
            .map_err(|_| StoreError::Flash)
    }
}

/// Runs `f` to completion by polling it; for flash whose operations never wait (RAM, a file
/// already read into RAM), so the host and the tests need no executor. A future that waits on
/// something else would spin here forever: the firmware awaits the store on its executor.
pub fn block_on_ready<F: Future>(f: F) -> F::Output {
    let mut f = pin!(f);
    let mut cx = Context::from_waker(Waker::noop());
    loop {
        if let Poll::Ready(v) = f.as_mut().poll(&mut cx) {
            return v;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::ram_flash::RamFlash;
    use super::*;
    extern crate std;

    /// Two 2 KiB pages of 8-byte words: the G431's and L475's page and word.
    type Flash = RamFlash<4096, 2048, 8>;

    fn store() -> SettingsStore<Flash> {
        SettingsStore::new(Flash::new(), 0..4096).unwrap()
    }

    fn with(name: &str, value: &str) -> Settings {
        let mut s = Settings::DEFAULT;
        s.set_text(name, value).unwrap();
        s
    }

    #[test]
    fn an_empty_area_loads_as_absent_and_a_save_loads_back() {
        let mut st = store();
        assert_eq!(block_on_ready(st.load()), Err(LoadError::Absent));
        let s = with("lock_timeout_s", "300");
        let r = block_on_ready(st.save(&codec::encode(&s))).unwrap();
        assert_eq!(r.bytes, 90);
        assert_eq!(block_on_ready(st.load()), Ok(s));
        // A second SAVE replaces the first.
        let s2 = with("bend_timeout_s", "200");
        block_on_ready(st.save(&codec::encode(&s2))).unwrap();
        assert_eq!(block_on_ready(st.load()), Ok(s2));
    }

    #[test]
    fn an_area_of_one_page_or_misaligned_is_refused() {
        assert!(matches!(
            SettingsStore::new(Flash::new(), 0..2048),
            Err(StoreError::BadArea)
        ));
        assert!(matches!(
            SettingsStore::new(Flash::new(), 100..4096),
            Err(StoreError::BadArea)
        ));
    }

    #[test]
    fn wear_erases_per_save() {
        // 1000 SAVEs in two 2 KiB pages: how many page erases they cost (docs/settings.md).
        let mut st = store();
        let mut erases = 0;
        let saves = 1000;
        let t0 = std::time::Instant::now();
        for i in 0..saves {
            let s = with("lock_timeout_s", &std::format!("{}", 100 + i % 500));
            erases += block_on_ready(st.save(&codec::encode(&s))).unwrap().erases;
            assert_eq!(block_on_ready(st.load()), Ok(s));
        }
        assert_eq!(st.flash().erases, erases);
        let per_save = erases as f32 / saves as f32;
        let us = t0.elapsed().as_secs_f64() * 1e6 / saves as f64;
        std::println!(
            "wear: {erases} page erases in {saves} SAVEs ({per_save:.3} per SAVE); \
             {us:.1} us per SAVE and load on the RAM flash"
        );
        // Each 2 KiB page holds dozens of 86-byte items: well under one erase per SAVE.
        assert!(per_save < 0.1, "{per_save}");
    }

    #[test]
    fn power_lost_at_any_byte_of_a_save_leaves_old_or_new_never_garbage() {
        let old = with("soften_timeout_s", "30");
        let new = with("soften_timeout_s", "90");
        // Fill the area near full first so the cut SAVEs include page erases too.
        for fill in [0usize, 55, 58, 60] {
            let mut cuts = 0;
            for budget in 0u32.. {
                let mut st = store();
                for i in 0..fill {
                    let s = with("bend_timeout_s", &std::format!("{}", 40 + i));
                    block_on_ready(st.save(&codec::encode(&s))).unwrap();
                }
                block_on_ready(st.save(&codec::encode(&old))).unwrap();
                st.flash_mut().fail_after_bytes = budget;
                let done = block_on_ready(st.save(&codec::encode(&new))).is_ok();
                // Power back: the board boots and loads.
                let mut rebooted =
                    SettingsStore::new(Flash::from_image(st.flash().image()).unwrap(), 0..4096)
                        .unwrap();
                let got = block_on_ready(rebooted.load());
                assert!(
                    got == Ok(old) || got == Ok(new),
                    "fill {fill}, power lost after {budget} bytes: {got:?}"
                );
                if done {
                    assert_eq!(got, Ok(new), "fill {fill}: a finished SAVE must hold");
                    break;
                }
                cuts += 1;
                // The board saves again after the reboot, and that works.
                block_on_ready(rebooted.save(&codec::encode(&new))).unwrap();
                assert_eq!(block_on_ready(rebooted.load()), Ok(new));
            }
            assert!(cuts > 0);
        }
    }

    #[test]
    fn wear_on_the_f401s_two_128_kib_sectors() {
        // A 256 KiB flash image moved by value: more than a test thread's stack holds in a
        // debug build, so the test runs on a thread with room for it.
        std::thread::Builder::new()
            .stack_size(32 << 20)
            .spawn(wear_on_the_f401s_sectors)
            .unwrap()
            .join()
            .unwrap();
    }

    fn wear_on_the_f401s_sectors() {
        // The F401RE's settings area: two 128 KiB sectors; how many SAVEs fill one.
        type F4 = RamFlash<{ 256 * 1024 }, { 128 * 1024 }, 4>;
        let flash: std::boxed::Box<F4> = std::boxed::Box::default();
        let mut st = SettingsStore::new(*flash, 0..256 * 1024).unwrap();
        let mut first_erase = None;
        for i in 0..4000u32 {
            let s = with("lock_timeout_s", &std::format!("{}", 100 + i % 500));
            let r = block_on_ready(st.save(&codec::encode(&s))).unwrap();
            if r.erases > 0 && first_erase.is_none() {
                first_erase = Some(i + 1);
            }
        }
        assert_eq!(
            block_on_ready(st.load()).unwrap().morph.lock_timeout_s,
            100.0 + (3999 % 500) as f32
        );
        let n = first_erase.expect("4000 SAVEs fill a 128 KiB sector");
        std::println!("F401 geometry: the first sector erase comes at SAVE {n}");
        // 128 KiB over a ~100-byte item (the 86-byte blob and its header): over a thousand.
        assert!(n > 1000, "{n}");
    }
}
