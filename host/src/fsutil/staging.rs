//! Where a job with many outputs (the main job, `tendril robustness`)
//! writes until it has finished (`docs/design.md` §7):
//! a staging directory inside the (locked) output directory, published only
//! when every stage is done. An interrupt — Ctrl-C, SIGTERM, SIGHUP, even a
//! second one — or a failure therefore leaves exactly the previous run's
//! outputs: the staging directory is removed and nothing in the output
//! directory was touched.
//!
//! Publishing moves each file the run wrote at the top level over its
//! namesake (a symlink stays a link and its target is replaced, as every
//! output is, [`crate::fsutil::move_into_place`]), and swaps each
//! sub-directory the run wrote (`compare/`, `sim*/`) as a whole, so no stale
//! file of the previous run survives in it. Other entries of the output
//! directory (the user's files, other robots' `out/<stem>/`) are left alone.
//! Signals are deferred while publishing ([`crate::fsutil::Publishing`]):
//! it takes milliseconds and an interrupted publish would mix two runs.

use std::io;
use std::path::{Path, PathBuf};

use super::{move_into_place, register_temporary_dir, unregister_temporary_dir, DirLock};

/// The staging directory's name inside the output directory.
pub const STAGING: &str = ".tendril-staging";

/// A run's staging directory; removed when dropped unless published.
#[derive(Debug)]
pub struct Staging {
    out: PathBuf,
    dir: PathBuf,
}

impl Staging {
    /// Make a fresh staging directory in `out`, which the caller holds
    /// locked (`_lock`): a leftover one can only be a killed run's.
    pub fn create(out: &Path, _lock: &DirLock) -> io::Result<Staging> {
        let dir = out.join(STAGING);
        if std::fs::symlink_metadata(&dir).is_ok() {
            std::fs::remove_dir_all(&dir)?;
        }
        std::fs::create_dir(&dir)?;
        register_temporary_dir(&dir);
        Ok(Staging {
            out: out.to_path_buf(),
            dir,
        })
    }

    /// The staging directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Where `name` is written now.
    pub fn path(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }

    /// Where a staged `path` will be once published (for the report: it
    /// names the final files). Paths outside the staging directory are
    /// returned unchanged.
    pub fn shown(&self, path: &Path) -> PathBuf {
        match path.strip_prefix(&self.dir) {
            Ok(rel) => self.out.join(rel),
            Err(_) => path.to_path_buf(),
        }
    }

    /// Move everything staged into the output directory (see the module
    /// documentation) with signals deferred, then remove the staging directory.
    pub fn publish(self) -> io::Result<()> {
        let _deferred = crate::fsutil::Publishing::start();
        let old = self.dir.join(".previous");
        let mut entries: Vec<_> = std::fs::read_dir(&self.dir)?
            .map(|e| e.map(|e| e.path()))
            .collect::<io::Result<_>>()?;
        entries.sort();
        for from in entries {
            let Some(name) = from.file_name() else {
                continue;
            };
            if name == DirLock::FILE || from == old {
                continue;
            }
            let to = self.out.join(name);
            if std::fs::symlink_metadata(&from)?.is_dir() {
                swap_dir(&from, &to, &old)?;
            } else {
                move_into_place(&from, &to)?;
            }
        }
        std::fs::remove_dir_all(&self.dir)?;
        unregister_temporary_dir(&self.dir);
        std::mem::forget(self);
        Ok(())
    }
}

/// A job's output directory, locked for the job: created if missing, and
/// removed again by [`LockedOutput::abandon`] when the job publishes
/// nothing into a directory it created (no empty `out/` holding a lock).
#[derive(Debug)]
pub struct LockedOutput {
    out: PathBuf,
    existed: bool,
    lock: DirLock,
}

impl LockedOutput {
    /// Create `out` if needed and lock it (see [`DirLock`]). A path that
    /// is there but is not a directory is refused, naming it.
    pub fn acquire(out: &Path) -> Result<LockedOutput, super::LockError> {
        let existed = match std::fs::metadata(out) {
            Ok(m) if m.is_dir() => true,
            Ok(_) => {
                return Err(super::LockError::Io {
                    path: out.to_path_buf(),
                    source: io::Error::new(
                        io::ErrorKind::NotADirectory,
                        "is not a directory (this output is a directory)",
                    ),
                })
            }
            Err(_) => false,
        };
        let lock = DirLock::acquire(out)?;
        Ok(LockedOutput {
            out: out.to_path_buf(),
            existed,
            lock,
        })
    }

    /// A staging directory in it (see [`Staging`]).
    pub fn staging(&self) -> io::Result<Staging> {
        Staging::create(&self.out, &self.lock)
    }

    /// Release the lock; if this job created the directory and nothing
    /// but the lock is in it, remove it.
    pub fn abandon(self) {
        let LockedOutput { out, existed, lock } = self;
        drop(lock);
        if !existed {
            let _ = std::fs::remove_file(out.join(DirLock::FILE));
            let _ = std::fs::remove_dir(&out);
        }
    }
}

/// Put directory `from` at `to` (a symlink's target when `to` is a link to
/// a directory), moving what was there to `old` first and removing it after.
fn swap_dir(from: &Path, to: &Path, old: &Path) -> io::Result<()> {
    let to = match std::fs::symlink_metadata(to) {
        Ok(m) if m.file_type().is_symlink() => to.canonicalize()?,
        _ => to.to_path_buf(),
    };
    if std::fs::symlink_metadata(&to).is_ok() {
        if std::fs::symlink_metadata(old).is_ok() {
            std::fs::remove_dir_all(old)?;
        }
        std::fs::rename(&to, old)?;
    }
    std::fs::rename(from, &to)?;
    if std::fs::symlink_metadata(old).is_ok() {
        std::fs::remove_dir_all(old)?;
    }
    Ok(())
}

impl Drop for Staging {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
        unregister_temporary_dir(&self.dir);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lock(out: &Path) -> DirLock {
        DirLock::acquire(out).unwrap()
    }

    #[test]
    fn dropping_unpublished_staging_leaves_the_previous_outputs() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path();
        std::fs::write(out.join("report.md"), "complete").unwrap();
        let l = lock(out);
        let s = Staging::create(out, &l).unwrap();
        std::fs::write(s.path("report.md"), "partial").unwrap();
        std::fs::create_dir(s.path("sim")).unwrap();
        drop(s);
        assert_eq!(
            std::fs::read_to_string(out.join("report.md")).unwrap(),
            "complete"
        );
        assert!(!out.join(STAGING).exists());
        assert!(!out.join("sim").exists());
    }

    #[test]
    fn publish_replaces_files_and_whole_subdirectories_and_keeps_the_rest() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path();
        std::fs::write(out.join("report.md"), "old").unwrap();
        std::fs::write(out.join("notes.txt"), "the user's").unwrap();
        std::fs::create_dir(out.join("sim")).unwrap();
        std::fs::write(out.join("sim/plant-1.csv"), "stale").unwrap();
        std::fs::create_dir(out.join("other-robot")).unwrap();
        let l = lock(out);
        let lock_before = std::fs::read(out.join(DirLock::FILE)).unwrap();
        let s = Staging::create(out, &l).unwrap();
        std::fs::write(s.path("report.md"), "new").unwrap();
        std::fs::create_dir(s.path("sim")).unwrap();
        std::fs::write(s.path("sim/plant-0.csv"), "fresh").unwrap();
        std::fs::write(s.path("sim").join(DirLock::FILE), "").unwrap();
        assert_eq!(s.shown(&s.path("sim")), out.join("sim"));
        s.publish().unwrap();
        assert_eq!(
            std::fs::read_to_string(out.join("report.md")).unwrap(),
            "new"
        );
        assert_eq!(
            std::fs::read_to_string(out.join("notes.txt")).unwrap(),
            "the user's"
        );
        assert!(out.join("other-robot").is_dir());
        assert!(!out.join("sim/plant-1.csv").exists(), "stale file survived");
        assert_eq!(
            std::fs::read_to_string(out.join("sim/plant-0.csv")).unwrap(),
            "fresh"
        );
        assert!(!out.join(STAGING).exists());
        assert_eq!(std::fs::read(out.join(DirLock::FILE)).unwrap(), lock_before);
    }

    #[cfg(unix)]
    #[test]
    fn a_symlinked_output_stays_a_link_when_published() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("out");
        std::fs::create_dir(&out).unwrap();
        std::fs::write(tmp.path().join("kept.md"), "old").unwrap();
        std::os::unix::fs::symlink("../kept.md", out.join("report.md")).unwrap();
        let l = lock(&out);
        let s = Staging::create(&out, &l).unwrap();
        std::fs::write(s.path("report.md"), "new").unwrap();
        s.publish().unwrap();
        assert!(std::fs::symlink_metadata(out.join("report.md"))
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(
            std::fs::read_to_string(tmp.path().join("kept.md")).unwrap(),
            "new"
        );
    }

    #[test]
    fn a_killed_runs_staging_is_cleared_by_the_next() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path();
        std::fs::create_dir(out.join(STAGING)).unwrap();
        std::fs::write(out.join(STAGING).join("report.md"), "killed").unwrap();
        let l = lock(out);
        let s = Staging::create(out, &l).unwrap();
        assert!(!s.path("report.md").exists());
    }
}
