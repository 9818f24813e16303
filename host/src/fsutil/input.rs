//! The input side of the file policy: inputs read with a cap (a robot
//! file, a sidecar) or streamed line by line with a cap on a line (a CSV),
//! `-` as stdin, and names read from files that become paths.

use std::fs::File;
use std::io::{self, Read};
use std::path::Path;

use super::is_stdout;

/// Open a line-oriented input (a CSV) for reading: `-` is stdin (what a
/// pipe gives: `… | tendril fk --input - --output -`), anything else the
/// file at `path`.
pub fn open_input(path: &Path) -> io::Result<Box<dyn Read + Send>> {
    if is_stdout(path) {
        return Ok(Box::new(io::stdin()));
    }
    Ok(Box::new(File::open(path)?))
}

/// Read a small input file whole, refusing what cannot be one: a path that
/// is not a regular file (after symlinks: `/dev/zero`, a FIFO, a directory)
/// and a file of more than `max` bytes, checked before reading and again
/// while reading (a file that grows). The error says which, with the size.
pub fn read_capped(path: &Path, max: u64) -> io::Result<Vec<u8>> {
    let meta = std::fs::metadata(path)?;
    if !meta.is_file() {
        let kind = if meta.is_dir() {
            "a directory"
        } else {
            "a device, FIFO or socket"
        };
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("not a regular file ({kind})"),
        ));
    }
    let too_big = |len: u64| {
        io::Error::new(
            io::ErrorKind::InvalidData,
            format!(
                "{} is larger than the {} this input may be",
                mib(len),
                mib(max)
            ),
        )
    };
    if meta.len() > max {
        return Err(too_big(meta.len()));
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    File::open(path)?.take(max + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > max {
        return Err(too_big(bytes.len() as u64));
    }
    Ok(bytes)
}

/// A reader of line-oriented text (CSV) that fails on a line longer than
/// [`LineCapped::MAX_LINE`]: an endless input without newlines (`/dev/zero`,
/// a binary file) is an error at once instead of one record that grows
/// until memory runs out.
pub struct LineCapped<R> {
    inner: R,
    since_newline: usize,
}

impl<R> LineCapped<R> {
    /// Longest line accepted, bytes.
    pub const MAX_LINE: usize = 1 << 20;

    /// Wrap `inner`.
    pub fn new(inner: R) -> LineCapped<R> {
        LineCapped {
            inner,
            since_newline: 0,
        }
    }
}

impl<R: Read> Read for LineCapped<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let n = self.inner.read(buf)?;
        let chunk = &buf[..n];
        self.since_newline = match chunk.iter().rposition(|&b| b == b'\n') {
            Some(i) => n - i - 1,
            None => self.since_newline + n,
        };
        if self.since_newline > Self::MAX_LINE {
            return Err(io::Error::new(
                io::ErrorKind::InvalidData,
                format!(
                    "a line longer than {}: not line-oriented text",
                    mib(Self::MAX_LINE as u64)
                ),
            ));
        }
        Ok(n)
    }
}

/// `n` bytes in MiB for a message (`64.0 MiB`, `1 MiB`).
fn mib(n: u64) -> String {
    let m = n as f64 / (1u64 << 20) as f64;
    if m.fract() == 0.0 {
        format!("{m:.0} MiB")
    } else {
        format!("{m:.1} MiB")
    }
}

/// Longest name [`check_plain_name`] accepts, bytes.
pub const MAX_PLAIN_NAME: usize = 64;

/// Check that `name`, read from a file, can become one file or directory
/// name inside an output directory: letters, digits, `-`, `_` and `.`,
/// not starting with `.` (no `..`, no hidden file), at most
/// [`MAX_PLAIN_NAME`] bytes. The error says what is wrong.
pub fn check_plain_name(name: &str) -> Result<(), String> {
    if name.is_empty() {
        return Err("must not be empty".into());
    }
    if name.len() > MAX_PLAIN_NAME {
        return Err(format!(
            "{name:?} is longer than {MAX_PLAIN_NAME} characters"
        ));
    }
    if let Some(c) = name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.')))
    {
        return Err(format!(
            "{name:?} has {c:?}: it names a directory of the output, so only letters, digits, \
             '-', '_' and '.' are allowed"
        ));
    }
    if name.starts_with('.') {
        return Err(format!(
            "{name:?} starts with '.': it names a directory of the output"
        ));
    }
    Ok(())
}
