//! File output, one policy for every command (`docs/design.md` §7): a
//! regular file (new or existing, or the target of a symlink) is written to
//! a temporary file beside it and renamed into place, so an interrupted run
//! never leaves a truncated file under the final name; a path that names
//! something else — a device (`/dev/null`, `/dev/full`), a FIFO, a socket, a
//! process substitution (`/dev/fd/N`), `/dev/stdout` — is opened and written
//! *through*, never replaced; `-` is stdout. Also the lock that keeps two
//! runs out of one output directory, and the check that a command's outputs
//! overwrite none of its inputs nor each other.

use std::fs::{File, OpenOptions};
use std::io::{self, Read, Seek, Write};
use std::path::{Component, Path, PathBuf};
use std::sync::Mutex;

mod input;
mod staged;
pub mod staging;

pub use input::{check_plain_name, open_input, read_capped, LineCapped, MAX_PLAIN_NAME};
pub use staged::{partial_path, StagedFile};

/// Whether `path` is `-`, which every single-file output reads as stdout.
pub fn is_stdout(path: &Path) -> bool {
    path.as_os_str() == "-"
}

/// Where the bytes for an output path go.
#[derive(Debug, PartialEq, Eq)]
enum Sink {
    /// `-`.
    Stdout,
    /// Open this path and write into it (devices, FIFOs, sockets, descriptors).
    Through(PathBuf),
    /// A regular file (existing or not) at this path, with symlinks
    /// resolved: written beside it and renamed over it.
    Replace(PathBuf),
}

/// Whether output to `path` lands in a regular file (new or existing, or a
/// symlink's target) rather than being written through a device, FIFO,
/// socket or descriptor, or to stdout (`-`). For outputs that need a
/// companion file beside them (a dataset's sidecar): beside a device there
/// is no place for one.
pub fn is_regular_output(path: &Path) -> io::Result<bool> {
    Ok(matches!(sink_for(path)?, Sink::Replace(_)))
}

/// Paths that name an open descriptor of this process: whatever is behind
/// them (even a regular file a shell redirected to) is written through, as a
/// shell's `>` would, so the caller's descriptor sees the bytes.
fn names_a_descriptor(path: &Path) -> bool {
    ["/dev/stdout", "/dev/stderr", "/dev/fd/", "/proc/"]
        .iter()
        .any(|p| path.to_string_lossy().starts_with(p))
}

/// Decide how `path` is written (see the module documentation).
fn sink_for(path: &Path) -> io::Result<Sink> {
    if is_stdout(path) {
        return Ok(Sink::Stdout);
    }
    match std::fs::metadata(path) {
        Ok(m) if m.is_dir() => Err(io::Error::new(
            io::ErrorKind::IsADirectory,
            "is a directory, not a file",
        )),
        Ok(m) if !m.is_file() || names_a_descriptor(path) => Ok(Sink::Through(path.to_path_buf())),
        Ok(_) => Ok(Sink::Replace(path.canonicalize()?)),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(Sink::Replace(follow_links(path)?)),
        Err(e) => Err(e),
    }
}

/// `path` with its chain of symlinks followed to the (missing) file at the
/// end, so a dangling link gets its target created and stays a link.
fn follow_links(path: &Path) -> io::Result<PathBuf> {
    let mut p = path.to_path_buf();
    // As the kernel does (MAXSYMLINKS): a loop is an error, not a hang.
    for _ in 0..40 {
        match std::fs::symlink_metadata(&p) {
            Ok(m) if m.file_type().is_symlink() => {
                let target = std::fs::read_link(&p)?;
                p = match p.parent() {
                    Some(dir) if target.is_relative() => dir.join(target),
                    _ => target,
                };
            }
            _ => return Ok(p),
        }
    }
    Err(io::Error::other("too many levels of symbolic links"))
}

/// Temporary files being written now, removed by [`remove_temporaries`]
/// when a second signal ends the process before their owners can.
static TEMPORARIES: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// Temporary directories (the main job's staging directory), removed with
/// everything in them by [`remove_temporaries`].
static TEMPORARY_DIRS: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// Remove every temporary output file and directory still registered.
/// Called from the signal handler before a forced exit; never blocks (a
/// held lock is skipped).
pub fn remove_temporaries() {
    remove_temporaries_where(|_| true);
}

/// Register a directory for [`remove_temporaries`] (its owner removes it
/// in the ordinary course and then calls [`unregister_temporary_dir`]).
pub fn register_temporary_dir(dir: &Path) {
    if let Ok(mut list) = TEMPORARY_DIRS.lock() {
        list.push(dir.to_path_buf());
    }
}

/// Undo [`register_temporary_dir`].
pub fn unregister_temporary_dir(dir: &Path) {
    if let Ok(mut list) = TEMPORARY_DIRS.lock() {
        list.retain(|d| d != dir);
    }
}

/// What a second signal does before its forced exit
/// ([`crate::interrupt::install`]): remove the temporaries, unless a run
/// is being published.
pub fn exit_hooks() -> crate::interrupt::ExitHooks {
    crate::interrupt::ExitHooks {
        cleanup: remove_temporaries,
        deferring: Publishing::active,
    }
}

/// Whether a [`Publishing`] guard is alive.
static PUBLISHING: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// While alive, a second signal does not end the process at once
/// ([`crate::interrupt`]): moving a finished run's files into place takes
/// milliseconds, and stopping half-way would leave two runs' files mixed.
#[derive(Debug)]
pub struct Publishing(());

impl Publishing {
    /// Defer forced exits until the guard is dropped.
    pub fn start() -> Publishing {
        PUBLISHING.store(true, std::sync::atomic::Ordering::SeqCst);
        Publishing(())
    }

    /// Whether a guard is alive.
    pub fn active() -> bool {
        PUBLISHING.load(std::sync::atomic::Ordering::SeqCst)
    }
}

impl Drop for Publishing {
    fn drop(&mut self) {
        PUBLISHING.store(false, std::sync::atomic::Ordering::SeqCst);
    }
}

/// Move the finished file `from` to output path `to` by the output policy:
/// renamed over a regular file or a symlink's target (the link stays a
/// link), copied through into a device, FIFO or descriptor (then removed).
/// `from` must be on the same file system as `to`'s target (beside it).
pub fn move_into_place(from: &Path, to: &Path) -> io::Result<()> {
    match sink_for(to)? {
        Sink::Replace(target) => std::fs::rename(from, target),
        sink => {
            let mut src = File::open(from)?;
            write_to(&sink, |w| io::copy(&mut src, w).map(drop))?;
            std::fs::remove_file(from)
        }
    }
}

/// [`remove_temporaries`] for those `which` picks: the unit test removes
/// only its own, not the live temporaries of the tests running beside it.
fn remove_temporaries_where(which: impl Fn(&Path) -> bool) {
    if let Ok(list) = TEMPORARIES.try_lock() {
        for p in list.iter().filter(|p| which(p)) {
            let _ = std::fs::remove_file(p);
        }
    }
    if let Ok(list) = TEMPORARY_DIRS.try_lock() {
        for d in list.iter().filter(|d| which(d)) {
            let _ = std::fs::remove_dir_all(d);
        }
    }
}

/// A temporary output file beside its target (`.tendril-*.tmp`), registered
/// for [`remove_temporaries`] while it lives and removed when dropped unless
/// persisted.
pub struct Temporary {
    // Always Some until `persist` takes it (Drop forbids moving it out otherwise).
    file: Option<tempfile::NamedTempFile>,
}

impl Temporary {
    /// Create one in `dir`.
    pub fn new_in(dir: &Path) -> io::Result<Temporary> {
        Temporary::named_in(dir, ".tmp")
    }

    /// Create one in `dir` whose name ends in `suffix`.
    fn named_in(dir: &Path, suffix: &str) -> io::Result<Temporary> {
        let file = tempfile::Builder::new()
            .prefix(".tendril-")
            .suffix(suffix)
            .tempfile_in(dir)?;
        if let Ok(mut list) = TEMPORARIES.lock() {
            list.push(file.path().to_path_buf());
        }
        Ok(Temporary { file: Some(file) })
    }

    /// One for building the contents of output `path` before
    /// [`Temporary::persist`]: beside the file it will replace (so the
    /// rename is atomic), or in the system's temporary directory when
    /// `path` is written through or is `-` (`/dev/fd/63`'s directory takes
    /// no new files).
    pub fn for_output(path: &Path) -> io::Result<Temporary> {
        Temporary::for_output_ending(path, ".tmp")
    }

    /// As [`Temporary::for_output`], with a name ending in `suffix`
    /// (`.tmp.png`): for writers that pick the file's format from its
    /// extension, as plotters' bitmap backend does.
    pub fn for_output_ending(path: &Path, suffix: &str) -> io::Result<Temporary> {
        match sink_for(path)? {
            Sink::Replace(target) => {
                let dir = match target.parent() {
                    Some(d) if !d.as_os_str().is_empty() => d,
                    _ => Path::new("."),
                };
                std::fs::create_dir_all(dir)?;
                Temporary::named_in(dir, suffix)
            }
            _ => Temporary::named_in(&std::env::temp_dir(), suffix),
        }
    }

    /// Its path.
    pub fn path(&self) -> &Path {
        self.named().path()
    }

    fn named(&self) -> &tempfile::NamedTempFile {
        self.file
            .as_ref()
            .expect("a Temporary holds its file until persisted")
    }

    /// The open file.
    pub fn as_file(&self) -> &File {
        self.named().as_file()
    }

    /// Put the finished contents at `path` by the output policy: renamed
    /// over a regular file (or a symlink's target), copied through into a
    /// device, FIFO or descriptor, or to stdout for `-`.
    pub fn persist(mut self, path: &Path) -> io::Result<()> {
        match sink_for(path)? {
            Sink::Replace(target) => {
                self.as_file().sync_all()?;
                // tempfile creates 0600; results are meant to be shared like any output.
                #[cfg(unix)]
                {
                    use std::os::unix::fs::PermissionsExt;
                    self.as_file()
                        .set_permissions(std::fs::Permissions::from_mode(0o644))?;
                }
                let from = self.path().to_path_buf();
                let named = self.file.take().expect("held until persisted");
                unregister(&from);
                named.persist(&target).map_err(|e| e.error)?;
                Ok(())
            }
            sink => {
                let mut src = self.as_file();
                src.rewind()?;
                write_to(&sink, |w| io::copy(&mut src, w).map(drop))
            }
        }
    }
}

impl Drop for Temporary {
    fn drop(&mut self) {
        if let Some(named) = &self.file {
            unregister(named.path());
        }
    }
}

fn unregister(path: &Path) {
    if let Ok(mut list) = TEMPORARIES.lock() {
        list.retain(|p| p != path);
    }
}

/// Stream `fill` into a sink that is written directly (stdout or through).
fn write_to<F>(sink: &Sink, fill: F) -> io::Result<()>
where
    F: FnOnce(&mut dyn Write) -> io::Result<()>,
{
    let mut w: Box<dyn Write> = match sink {
        Sink::Stdout => Box::new(io::stdout().lock()),
        Sink::Through(p) => Box::new(open_through(p)?),
        Sink::Replace(_) => unreachable!("a regular file is written through a temporary"),
    };
    let mut buf = io::BufWriter::new(&mut w);
    fill(&mut buf)?;
    buf.flush()?;
    drop(buf);
    w.flush()
}

/// How long [`open_through`] waits for a FIFO's reader to appear.
pub const FIFO_READER_WAIT: std::time::Duration = std::time::Duration::from_secs(5);

/// Open a node that is written through (a device, FIFO, socket or
/// descriptor) for writing: no truncate, no create (it exists and is not a
/// regular file). A FIFO is opened without blocking: with no reader the
/// open is retried for [`FIFO_READER_WAIT`] (a reader started beside the
/// command may come a moment later), or until a stop is requested, and
/// then refused with an error that says so — a blocking open would hang
/// the command, deaf to SIGTERM, until somebody reads.
pub fn open_through(path: &Path) -> io::Result<File> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        use std::os::unix::fs::OpenOptionsExt;
        use std::os::unix::io::AsRawFd;
        if std::fs::metadata(path)?.file_type().is_socket() {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                "a socket, which cannot be opened as a file",
            ));
        }
        let deadline = std::time::Instant::now() + FIFO_READER_WAIT;
        loop {
            match OpenOptions::new()
                .write(true)
                .custom_flags(libc::O_NONBLOCK)
                .open(path)
            {
                Ok(file) => {
                    // Writes block again (a slow reader is waited for, not
                    // an error); only the open had to not wait.
                    // SAFETY: fcntl on a descriptor this File owns.
                    let fd = file.as_raw_fd();
                    let flags = unsafe { libc::fcntl(fd, libc::F_GETFL) };
                    if flags < 0
                        || unsafe { libc::fcntl(fd, libc::F_SETFL, flags & !libc::O_NONBLOCK) } < 0
                    {
                        return Err(io::Error::last_os_error());
                    }
                    return Ok(file);
                }
                Err(e) if e.raw_os_error() == Some(libc::ENXIO) => {
                    if std::time::Instant::now() >= deadline || crate::interrupt::stop_requested() {
                        return Err(io::Error::new(
                            io::ErrorKind::BrokenPipe,
                            format!(
                                "a FIFO with no reader (waited {} s): start its reader first",
                                FIFO_READER_WAIT.as_secs()
                            ),
                        ));
                    }
                    std::thread::sleep(std::time::Duration::from_millis(20));
                }
                Err(e) => return Err(e),
            }
        }
    }
    #[cfg(not(unix))]
    {
        OpenOptions::new().write(true).open(path)
    }
}

/// Write `bytes` to `path` by the output policy (see the module documentation).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> io::Result<()> {
    write_atomic_with(path, |w| w.write_all(bytes))
}

/// Stream into `path` by the output policy: for a regular file, `fill`
/// writes into a temporary file in the same directory, which replaces the
/// file only if `fill` succeeds; a device, FIFO or descriptor is written
/// through (an error such as ENOSPC is returned); `-` is stdout.
pub fn write_atomic_with<F>(path: &Path, fill: F) -> io::Result<()>
where
    F: FnOnce(&mut dyn Write) -> io::Result<()>,
{
    let target = match sink_for(path)? {
        Sink::Replace(target) => target,
        sink => return write_to(&sink, fill),
    };
    let tmp = Temporary::for_output(&target)?;
    {
        let mut buf = io::BufWriter::new(tmp.as_file());
        fill(&mut buf)?;
        buf.flush()?;
    }
    tmp.persist(&target)
}

/// A run's exclusive hold on its output directory: the standard library's
/// advisory lock ([`File::try_lock`]: `flock` on Unix, `LockFileEx` on
/// Windows) on [`DirLock::FILE`] in it, released when dropped and by the
/// kernel when the process dies (even by SIGKILL), so no stale lock
/// outlives a run.
#[derive(Debug)]
pub struct DirLock {
    _file: File,
}

/// The output directory could not be locked.
#[derive(Debug, thiserror::Error)]
pub enum LockError {
    /// Another live process holds the lock.
    #[error("{} is in use by another tendril run (pid {pid})", .dir.display())]
    InUse {
        /// The directory.
        dir: PathBuf,
        /// The holder's pid as it recorded it (`unknown` if it had not yet).
        pid: String,
    },
    /// Creating or locking the lock file failed.
    #[error("{}: {source}", .path.display())]
    Io {
        /// The directory or lock file.
        path: PathBuf,
        /// The OS error.
        source: io::Error,
    },
}

impl DirLock {
    /// Name of the lock file inside the directory.
    pub const FILE: &'static str = ".tendril.lock";

    /// Create `dir` if needed and lock it, failing at once (no wait) when
    /// another run holds it; nothing else in `dir` is touched either way.
    pub fn acquire(dir: &Path) -> Result<DirLock, LockError> {
        let io_err = |path: &Path| {
            let path = path.to_path_buf();
            move |source| LockError::Io { path, source }
        };
        if std::fs::metadata(dir).is_ok_and(|m| !m.is_dir()) {
            // Not "File exists (os error 17)": say what is wrong.
            return Err(LockError::Io {
                path: dir.to_path_buf(),
                source: io::Error::new(
                    io::ErrorKind::NotADirectory,
                    "is a file, not a directory (this output is a directory)",
                ),
            });
        }
        std::fs::create_dir_all(dir).map_err(io_err(dir))?;
        let path = dir.join(Self::FILE);
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(io_err(&path))?;
        match file.try_lock() {
            Ok(()) => {}
            Err(std::fs::TryLockError::WouldBlock) => {
                // Windows locks the bytes too, so the holder's pid may be
                // unreadable there: the message then says `unknown`.
                let mut pid = String::new();
                let _ = file.read_to_string(&mut pid);
                let pid = match pid.trim() {
                    "" => "unknown".to_string(),
                    p => p.to_string(),
                };
                return Err(LockError::InUse {
                    dir: dir.to_path_buf(),
                    pid,
                });
            }
            // A target whose std has no file lock: run unlocked, with a
            // warning, rather than refuse every run there; the lock guards
            // against a user's slip (two runs into one directory), not a
            // hazard to the robot.
            Err(std::fs::TryLockError::Error(e)) if e.kind() == io::ErrorKind::Unsupported => {
                log::warn!(
                    "{}: not locked (no file lock on this platform: {e}); \
                     keep other runs out of {} yourself",
                    path.display(),
                    dir.display()
                );
            }
            Err(std::fs::TryLockError::Error(e)) => {
                return Err(LockError::Io { path, source: e });
            }
        }
        // Only the holder writes: the pid is for the message above.
        file.set_len(0).map_err(io_err(&path))?;
        write!(file, "{}", std::process::id()).map_err(io_err(&path))?;
        Ok(DirLock { _file: file })
    }
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
mod tests;
