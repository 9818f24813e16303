//! Output paths and disk space, checked before a dataset is written: paths
//! compared after resolving their directories, and the free space of a
//! file system.

use std::path::{Path, PathBuf};

/// The directory a file path lives in (`.` for a bare name).
pub fn parent_dir(path: &Path) -> PathBuf {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// `path` with its directory resolved (symlinks, `..`), for comparing paths
/// of files that may not exist yet.
pub fn resolved(path: &Path) -> PathBuf {
    if let Ok(p) = path.canonicalize() {
        return p;
    }
    let dir = parent_dir(path);
    match (dir.canonicalize(), path.file_name()) {
        (Ok(d), Some(name)) => d.join(name),
        _ => path.to_path_buf(),
    }
}

/// Whether `a` and `b` name the same file once their directories are
/// resolved. `-` names no file (stdin as an input, stdout as an output,
/// `docs/design.md` §7), so `--input - --output -` is a pipe, not one file.
pub fn same_file(a: &Path, b: &Path) -> bool {
    let dash = |p: &Path| p.as_os_str() == "-";
    !dash(a) && !dash(b) && resolved(a) == resolved(b)
}

/// Bytes an unprivileged user may still write in the file system holding
/// `dir`, or `None` where that cannot be asked.
pub fn free_bytes(dir: &Path) -> Option<u64> {
    #[cfg(unix)]
    {
        use std::os::unix::ffi::OsStrExt;
        let c_path = std::ffi::CString::new(dir.as_os_str().as_bytes()).ok()?;
        // SAFETY: `c_path` is a NUL-terminated string and `stat` a plain C
        // struct the call fills; both outlive the call.
        let mut stat: libc::statvfs = unsafe { std::mem::zeroed() };
        let rc = unsafe { libc::statvfs(c_path.as_ptr(), &mut stat) };
        if rc != 0 {
            return None;
        }
        #[allow(clippy::unnecessary_cast)] // the field types differ between platforms
        Some((stat.f_bavail as u64).saturating_mul(stat.f_frsize as u64))
    }
    #[cfg(not(unix))]
    {
        let _ = dir;
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_file_sees_through_dot_dot_and_symlinks_of_files_not_yet_written() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        let plain = dir.path().join("new.csv");
        assert!(same_file(&plain, &dir.path().join("sub/../new.csv")));
        assert!(!same_file(&plain, &dir.path().join("sub/new.csv")));
        assert!(
            !same_file(Path::new("-"), Path::new("-")),
            "a pipe is not a file"
        );
        #[cfg(unix)]
        {
            let link = dir.path().join("link");
            std::os::unix::fs::symlink(dir.path().join("sub"), &link).unwrap();
            assert!(same_file(&link.join("x"), &dir.path().join("sub/x")));
        }
    }
}
