//! Writing a file so that it is either whole or absent: the bytes go to a hidden temporary
//! name beside the target, are flushed to disk, and the temporary is renamed onto the target.
//! An error (or a panic) on the way removes the temporary; a reader never sees half a file at
//! the target's name. The Python package's `lgi.io.atomic` keeps the same promise for the
//! files it writes.

use crate::error::{LgiError, Result};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// A temporary name beside `target`: `.NAME.PID.N.tmp` in the same folder (a rename within a
/// folder is atomic; one across file systems is not).
fn temporary_beside(target: &Path) -> PathBuf {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let name = target
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    target.with_file_name(format!(".{name}.{}.{n}.tmp", std::process::id()))
}

/// Removes the temporary unless disarmed (on success, after the rename).
struct Cleanup(Option<PathBuf>);

impl Drop for Cleanup {
    fn drop(&mut self) {
        if let Some(p) = self.0.take() {
            let _ = std::fs::remove_file(p);
        }
    }
}

/// Writes `target` through `fill`, which gets a buffered writer on the temporary file; the
/// target is replaced only once `fill` succeeded and the data is on disk.
pub fn write_with(
    target: &Path,
    fill: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<()> {
    // A device or a pipe (`/dev/full`, `/dev/stdout`) is written in place: renaming a file
    // over it would replace the device. A link is followed, so the file it names is replaced
    // and the link stays.
    let resolved;
    let target = match std::fs::metadata(target) {
        Ok(m) if !m.is_file() && !m.is_dir() => return write_in_place(target, fill),
        Ok(_) if target.is_symlink() => {
            resolved = std::fs::canonicalize(target).map_err(|e| LgiError::write(target, &e))?;
            resolved.as_path()
        }
        _ => target,
    };
    let tmp = temporary_beside(target);
    let file = std::fs::File::create(&tmp).map_err(|e| LgiError::write(target, &e))?;
    let mut cleanup = Cleanup(Some(tmp.clone()));
    let mut w = std::io::BufWriter::new(file);
    fill(&mut w)
        .and_then(|()| w.flush())
        .map_err(|e| LgiError::write(target, &e))?;
    let file = w
        .into_inner()
        .map_err(|e| LgiError::write(target, e.error()))?;
    file.sync_all().map_err(|e| LgiError::write(target, &e))?;
    drop(file);
    std::fs::rename(&tmp, target).map_err(|e| LgiError::write(target, &e))?;
    cleanup.0 = None;
    Ok(())
}

fn write_in_place(
    target: &Path,
    fill: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<()> {
    let file = std::fs::OpenOptions::new()
        .write(true)
        .open(target)
        .map_err(|e| LgiError::write(target, &e))?;
    let mut w = std::io::BufWriter::new(file);
    fill(&mut w)
        .and_then(|()| w.flush())
        .map_err(|e| LgiError::write(target, &e))
}

/// Writes `bytes` to `target` whole or not at all ([`write_with`]).
pub fn write_bytes(target: &Path, bytes: &[u8]) -> Result<()> {
    write_with(target, |w| w.write_all(bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fresh, empty folder for one test (removed first if an earlier run left it).
    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("lgi-atomic-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    fn leftovers(dir: &Path) -> Vec<String> {
        std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".tmp"))
            .collect()
    }

    #[test]
    fn a_complete_write_replaces_the_target_and_leaves_no_temporary() {
        let dir = scratch("replace");
        let target = dir.as_path().join("model.lgi");
        std::fs::write(&target, b"old").unwrap();
        write_bytes(&target, b"new bytes").unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"new bytes");
        assert!(leftovers(dir.as_path()).is_empty());
    }

    #[test]
    fn a_failed_write_keeps_the_old_target_and_removes_the_temporary() {
        let dir = scratch("failed");
        let target = dir.as_path().join("model.lgi");
        std::fs::write(&target, b"old").unwrap();
        let err = write_with(&target, |w| {
            w.write_all(b"half of it")?;
            Err(std::io::Error::other("disk full"))
        })
        .unwrap_err();
        assert!(err.to_string().contains("disk full"), "{err}");
        assert_eq!(std::fs::read(&target).unwrap(), b"old");
        assert!(leftovers(dir.as_path()).is_empty());
    }

    #[cfg(unix)]
    #[test]
    fn a_device_is_written_in_place_never_replaced() {
        let full = Path::new("/dev/full");
        if !full.exists() {
            return;
        }
        let err = write_bytes(full, &[0u8; 65536]).unwrap_err();
        assert!(err.to_string().contains("/dev/full"), "{err}");
        let kind = std::fs::metadata(full).unwrap().file_type();
        assert!(!kind.is_file(), "/dev/full is still a device");
    }

    #[cfg(unix)]
    #[test]
    fn a_link_keeps_pointing_at_the_replaced_file() {
        let dir = scratch("link");
        let real = dir.join("real.lgi");
        let link = dir.join("link.lgi");
        std::fs::write(&real, b"old").unwrap();
        std::os::unix::fs::symlink(&real, &link).unwrap();
        write_bytes(&link, b"new").unwrap();
        assert!(link.is_symlink());
        assert_eq!(std::fs::read(&real).unwrap(), b"new");
    }

    #[test]
    fn a_panic_mid_write_leaves_nothing_at_a_new_target() {
        let dir = scratch("panic");
        let target = dir.as_path().join("new.lgi");
        let r = std::panic::catch_unwind(|| {
            let _ = write_with(&target, |w| {
                w.write_all(b"half")?;
                panic!("interrupted");
            });
        });
        assert!(r.is_err());
        assert!(!target.exists());
        assert!(leftovers(dir.as_path()).is_empty());
    }
}
