//! `morph-sim --flash-file PATH`: the simulated settings flash kept in a file, so saved settings
//! survive a restart as on a board (docs/settings.md, "Where the settings live").
//!
//! [`check`] runs before anything else: a path that could hang the boot (a FIFO), could never
//! hold the image (a directory, a device) or must not be replaced (a file that is read-only or
//! that this process cannot open for writing) is refused up front, so the run never starts on a
//! flash its SAVE cannot keep. A missing file is fine: an erased flash, created at the first
//! SAVE.

use morphlink_sim::rig::{SimFlash, SIM_FLASH_BYTES};
use std::fs::{FileType, OpenOptions};
use std::io::ErrorKind;
use std::path::Path;

/// What kind of non-file `file_type` is, in words; `None` for a regular file.
fn not_a_file(file_type: FileType) -> Option<&'static str> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if file_type.is_fifo() {
            return Some("a FIFO (reading it would wait for a writer)");
        }
        if file_type.is_socket() {
            return Some("a socket");
        }
        if file_type.is_char_device() || file_type.is_block_device() {
            return Some("a device");
        }
    }
    if file_type.is_dir() {
        Some("a directory")
    } else if !file_type.is_file() {
        Some("not a regular file")
    } else {
        None
    }
}

/// Whether `path` can be the flash file: `Ok` for a missing file or a regular file this
/// process may replace, otherwise a sentence saying why not.
///
/// A read-only file is refused on its mode (no write bit for anyone), not only on whether an
/// open for writing fails: root may write any file, and a file its owner made read-only is one
/// the owner does not want replaced, whoever runs the simulator. The open for appending (which
/// truncates nothing) catches what the mode cannot say (another user's file, a read-only
/// mount).
pub fn check(path: &Path) -> Result<(), String> {
    let meta = match std::fs::metadata(path) {
        Ok(m) => m,
        // Absent: an erased flash, so long as SAVE could make the file there.
        Err(e) if e.kind() == ErrorKind::NotFound => {
            return crate::out_path::check_new_file(path)
                .map_err(|e| format!("{e}, so SAVE could not keep it"))
        }
        Err(e) => return Err(format!("cannot look at it: {e}")),
    };
    if let Some(what) = not_a_file(meta.file_type()) {
        return Err(format!("it is {what}; give the path of a flash image file"));
    }
    if meta.permissions().readonly() {
        return Err(
            "it is read-only (its mode has no write bit), so SAVE could not keep it".to_string(),
        );
    }
    OpenOptions::new()
        .append(true)
        .open(path)
        .map(drop)
        .map_err(|e| format!("cannot open it for writing ({e}), so SAVE could not keep it"))
}

/// The settings flash kept in `path`: its image, or `None` (with a note on stderr) if the file
/// is there but is no flash image; an absent file is an erased flash. [`check`] it first.
pub fn read(path: &Path) -> Option<SimFlash> {
    match std::fs::read(path) {
        Ok(image) => {
            let flash = SimFlash::from_image(&image);
            if flash.is_none() {
                eprintln!(
                    "morph-sim: {} is not a {SIM_FLASH_BYTES}-byte flash image ({} bytes); \
                     defaults, and SAVE writes a new one",
                    path.display(),
                    image.len()
                );
            }
            flash
        }
        Err(_) => Some(SimFlash::new()),
    }
}

/// Writes the flash image to `path` (through a temporary file, so a crash mid-write leaves
/// the old file).
pub fn write(path: &Path, flash: &SimFlash) -> std::io::Result<()> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, flash.image())?;
    std::fs::rename(&tmp, path)
}
