//! Whether a file a tool writes later (a plot at the end of a run, a flash image at SAVE) can
//! be made at its path, checked before the run, so a run is never lost to a path that was
//! wrong from the start.

use std::fs::OpenOptions;
use std::path::Path;

/// Holds that a new file can be made at `path`: its directory exists and takes a new file (a
/// probe made beside it and removed), and `path` is not a directory (`d.svg`, `x.svg/`). The
/// error says which, without the path itself (the caller names it).
pub fn check_new_file(path: &Path) -> Result<(), String> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        return Err(match dir.exists() {
            true => format!("{} is not a directory", dir.display()),
            false => format!("the directory {} does not exist", dir.display()),
        });
    }
    if path.is_dir() || path.as_os_str().to_string_lossy().ends_with('/') {
        return Err("that is a directory".to_string());
    }
    // Something already there must be a file to overwrite: a FIFO would block the writer
    // until a reader came, a device (`/dev/full`) fails in the middle, a link to a place
    // that is not there fails at the end.
    if let Ok(there) = std::fs::symlink_metadata(path) {
        match std::fs::metadata(path) {
            Ok(m) if m.is_file() => {}
            Ok(_) => return Err("that is not a regular file".to_string()),
            Err(_) if there.file_type().is_symlink() => {
                return Err("that is a link to a place that does not exist".to_string())
            }
            Err(e) => return Err(format!("it cannot be read ({e})")),
        }
    }
    let probe = dir.join(format!(".morphlink-write-check-{}", std::process::id()));
    match OpenOptions::new().write(true).create_new(true).open(&probe) {
        Ok(_) => {
            let _ = std::fs::remove_file(&probe);
            Ok(())
        }
        Err(e) => Err(format!("no file can be made in {}: {e}", dir.display())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_directory_a_directory_and_an_unwritable_place_are_refused() {
        let tmp = std::env::temp_dir();
        assert!(check_new_file(&tmp.join("morphlink-out-path-test.svg")).is_ok());
        let e = check_new_file(&tmp.join("no-such-dir-morphlink/x.svg")).unwrap_err();
        assert!(e.contains("does not exist"), "{e}");
        assert_eq!(check_new_file(&tmp).unwrap_err(), "that is a directory");
        // A file where the directory should be.
        let file = tmp.join("morphlink-out-path-file");
        std::fs::write(&file, b"").unwrap();
        let e = check_new_file(&file.join("x.svg")).unwrap_err();
        assert_eq!(e, format!("{} is not a directory", file.display()));
        let _ = std::fs::remove_file(&file);
        // Not a file to overwrite: a device, a FIFO, a dangling link.
        let e = check_new_file(Path::new("/dev/null")).unwrap_err();
        assert_eq!(e, "that is not a regular file");
        #[cfg(unix)]
        {
            let link = tmp.join(format!(
                "morphlink-out-path-dangling-{}",
                std::process::id()
            ));
            let _ = std::fs::remove_file(&link);
            std::os::unix::fs::symlink("/no-such-dir-morphlink/x.svg", &link).unwrap();
            let e = check_new_file(&link).unwrap_err();
            assert_eq!(e, "that is a link to a place that does not exist");
            let _ = std::fs::remove_file(&link);
        }
        let e = check_new_file(Path::new("/proc/x")).unwrap_err();
        assert!(e.starts_with("no file can be made in /proc: "), "{e}");
    }
}
