//! An output written over the length of a run and published at its end
//! ([`StagedFile`]): a run log is the case. It follows the policy of every
//! output ([`super`]): a regular file (or a symlink's target) is written
//! as `NAME.partial` beside it and renamed over it when the run ends, so a
//! reader never sees half a file under the final name and a crashed run
//! leaves its readable part under the `.partial` name; a device, FIFO or
//! descriptor is opened when the run starts (a FIFO without a reader, a
//! directory or an unwritable node is refused before any work) and the
//! finished bytes are copied through it at the end; `-` is stdout.

use std::fs::{File, OpenOptions};
use std::io::{self, Seek, Write};
use std::path::{Path, PathBuf};

use super::{open_through, sink_for, Sink, Temporary};

/// The `.partial` name a file is written under until it is finished.
pub fn partial_path(path: &Path) -> PathBuf {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(".partial");
    path.with_file_name(name)
}

/// Where a [`StagedFile`]'s bytes end up.
enum Dest {
    /// A regular file: written at `partial` beside `target`, renamed over it.
    Replace { target: PathBuf, partial: PathBuf },
    /// A node written through (opened at the start), or stdout (`None`):
    /// the bytes wait in `tmp`.
    Through { node: Option<File>, tmp: Temporary },
}

/// An output file being written during a run (see the module documentation).
pub struct StagedFile {
    dest: Dest,
    file: File,
    committed: bool,
}

impl StagedFile {
    /// Start the output `path`: refuse a directory, a socket or a FIFO
    /// without a reader now, before the run; create the file the bytes go
    /// to first.
    pub fn create(path: &Path) -> io::Result<StagedFile> {
        let (dest, file) = match sink_for(path)? {
            Sink::Replace(target) => {
                if let Some(dir) = target.parent().filter(|d| !d.as_os_str().is_empty()) {
                    std::fs::create_dir_all(dir)?;
                }
                let partial = partial_path(&target);
                let file = OpenOptions::new()
                    .read(true)
                    .write(true)
                    .create(true)
                    .truncate(true)
                    .open(&partial)?;
                (Dest::Replace { target, partial }, file)
            }
            Sink::Through(node) => {
                let node = open_through(&node)?;
                let tmp = Temporary::new_in(&std::env::temp_dir())?;
                let file = tmp.as_file().try_clone()?;
                (
                    Dest::Through {
                        node: Some(node),
                        tmp,
                    },
                    file,
                )
            }
            Sink::Stdout => {
                let tmp = Temporary::new_in(&std::env::temp_dir())?;
                let file = tmp.as_file().try_clone()?;
                (Dest::Through { node: None, tmp }, file)
            }
        };
        Ok(StagedFile {
            dest,
            file,
            committed: false,
        })
    }

    /// A handle to write the bytes into (readable and seekable, as an MCAP
    /// writer needs). Every handle must be flushed before [`Self::commit`].
    pub fn writer(&self) -> io::Result<File> {
        self.file.try_clone()
    }

    /// Where the bytes are now: the `.partial` file, or the temporary of a
    /// node written through.
    pub fn staging_path(&self) -> &Path {
        match &self.dest {
            Dest::Replace { partial, .. } => partial,
            Dest::Through { tmp, .. } => tmp.path(),
        }
    }

    /// Put the finished bytes in place. Returns the regular file's path, or
    /// `None` when they went through a node or to stdout. An error (a full
    /// device, a reader that went away) is returned, naming what failed;
    /// the `.partial` file of a regular output is then left for the caller
    /// to keep or [`Self::discard`] — here it is removed.
    pub fn commit(mut self) -> io::Result<Option<PathBuf>> {
        self.committed = true;
        self.file.sync_all()?;
        match &mut self.dest {
            Dest::Replace { target, partial } => {
                #[cfg(unix)]
                {
                    use std::os::unix::fs::PermissionsExt;
                    self.file
                        .set_permissions(std::fs::Permissions::from_mode(0o644))?;
                }
                if let Err(e) = std::fs::rename(&*partial, &*target) {
                    let _ = std::fs::remove_file(&*partial);
                    return Err(e);
                }
                Ok(Some(target.clone()))
            }
            Dest::Through { node, .. } => {
                self.file.rewind()?;
                let mut w: Box<dyn Write> = match node.take() {
                    Some(f) => Box::new(f),
                    None => Box::new(io::stdout().lock()),
                };
                io::copy(&mut self.file, &mut w)?;
                w.flush()?;
                Ok(None)
            }
        }
    }

    /// Drop the bytes: nothing is published, the `.partial` file (or the
    /// temporary) is removed.
    pub fn discard(self) {
        drop(self);
    }
}

impl Drop for StagedFile {
    fn drop(&mut self) {
        if let (false, Dest::Replace { partial, .. }) = (self.committed, &self.dest) {
            let _ = std::fs::remove_file(partial);
        }
    }
}
