//! Atomic file output: write to a temporary file beside the target, then
//! rename, so an interrupted run never leaves a truncated file under the
//! final name. And the check that a command's outputs overwrite none of its
//! inputs nor each other.

use std::io::{self, Write};
use std::path::{Component, Path, PathBuf};

/// Write `bytes` to `path` atomically (temp file in the same directory + rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> io::Result<()> {
    write_atomic_with(path, |w| w.write_all(bytes))
}

/// Stream into `path` atomically: `fill` writes into a temporary file in the
/// same directory, which replaces `path` only if `fill` succeeds.
pub fn write_atomic_with<F>(path: &Path, fill: F) -> io::Result<()>
where
    F: FnOnce(&mut dyn Write) -> io::Result<()>,
{
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    std::fs::create_dir_all(dir)?;
    let mut tmp = tempfile::Builder::new()
        .prefix(".tendril-")
        .suffix(".tmp")
        .tempfile_in(dir)?;
    {
        let mut buf = io::BufWriter::new(tmp.as_file_mut());
        fill(&mut buf)?;
        buf.flush()?;
    }
    tmp.as_file().sync_all()?;
    // tempfile creates 0600; results are meant to be shared like any output.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        tmp.as_file()
            .set_permissions(std::fs::Permissions::from_mode(0o644))?;
    }
    tmp.persist(path).map_err(|e| e.error)?;
    Ok(())
}

/// Two of a command's files resolve to the same path.
#[derive(Debug, thiserror::Error)]
#[error("{output} {} is the same file as {other}: refusing to overwrite it", .path.display())]
pub struct PathCollision {
    /// The output that would overwrite (e.g. `--log`).
    pub output: String,
    /// The input or earlier output it collides with (e.g. `--out`).
    pub other: String,
    /// The path as the user gave it for `output`.
    pub path: PathBuf,
}

/// Refuse, before anything is written, an output path that resolves to one of
/// the `inputs` or to another of the `outputs`. Each entry is (role, path),
/// the role being how the user named it (`--out`, `--data`, …). Paths are
/// compared after resolving: the parent directory canonicalised (symlinks,
/// `..`) plus the file name, or the whole path when the file exists.
pub fn check_distinct(
    inputs: &[(&str, &Path)],
    outputs: &[(&str, &Path)],
) -> Result<(), PathCollision> {
    let resolved_inputs: Vec<(&str, PathBuf)> =
        inputs.iter().map(|(r, p)| (*r, resolve(p))).collect();
    let mut seen_outputs: Vec<(&str, PathBuf)> = Vec::with_capacity(outputs.len());
    for (role, path) in outputs {
        let here = resolve(path);
        let clash = resolved_inputs
            .iter()
            .chain(&seen_outputs)
            .find(|(_, other)| *other == here);
        if let Some((other, _)) = clash {
            return Err(PathCollision {
                output: (*role).to_string(),
                other: (*other).to_string(),
                path: path.to_path_buf(),
            });
        }
        seen_outputs.push((role, here));
    }
    Ok(())
}

/// `path` made absolute with symlinks and `..` resolved as far as the file
/// system allows: a file that does not exist yet is its resolved parent
/// directory plus its name.
fn resolve(path: &Path) -> PathBuf {
    if let Ok(p) = path.canonicalize() {
        return p;
    }
    let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let lexical = normalise_lexically(&absolute);
    match (lexical.parent(), lexical.file_name()) {
        (Some(dir), Some(name)) => dir
            .canonicalize()
            .map(|d| d.join(name))
            .unwrap_or_else(|_| lexical.clone()),
        _ => lexical,
    }
}

/// Drop `.` and fold `dir/..` without touching the file system.
fn normalise_lexically(path: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                out.pop();
            }
            other => out.push(other),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_output_equal_to_an_input_is_refused_whatever_its_spelling() {
        let dir = tempfile::tempdir().unwrap();
        let model = dir.path().join("m.tnet");
        std::fs::write(&model, b"net").unwrap();
        let spelled_otherwise = dir.path().join("sub").join("..").join("./m.tnet");
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        let err = check_distinct(
            &[("--model", &model)],
            &[("--json-out", &spelled_otherwise)],
        )
        .unwrap_err();
        assert_eq!(err.output, "--json-out");
        assert_eq!(err.other, "--model");
        assert!(err.to_string().contains("refusing to overwrite"), "{err}");
    }

    #[test]
    fn two_outputs_naming_one_new_file_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("new.csv");
        let b = dir.path().join(".").join("new.csv");
        let err = check_distinct(&[], &[("--out", &a), ("--log", &b)]).unwrap_err();
        assert_eq!(
            (err.output.as_str(), err.other.as_str()),
            ("--log", "--out")
        );
    }

    #[cfg(unix)]
    #[test]
    fn a_symlink_to_an_input_is_the_input() {
        let dir = tempfile::tempdir().unwrap();
        let data = dir.path().join("data.csv");
        std::fs::write(&data, b"x").unwrap();
        let link = dir.path().join("link.csv");
        std::os::unix::fs::symlink(&data, &link).unwrap();
        assert!(check_distinct(&[("--data", &data)], &[("--out", &link)]).is_err());
    }

    #[test]
    fn distinct_paths_pass() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("a.tnet");
        let b = dir.path().join("a.log.csv");
        let c = dir.path().join("data.csv");
        assert!(check_distinct(&[("--data", &c)], &[("--out", &a), ("--log", &b)]).is_ok());
    }

    #[test]
    fn failed_fill_leaves_previous_file_untouched() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.csv");
        write_atomic(&path, b"old").unwrap();
        let err = write_atomic_with(&path, |w| {
            w.write_all(b"partial")?;
            Err(io::Error::other("interrupted"))
        });
        assert!(err.is_err());
        assert_eq!(std::fs::read(&path).unwrap(), b"old");
        let leftovers: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
            .collect();
        assert!(leftovers.is_empty(), "temporary file left behind");
    }
}
