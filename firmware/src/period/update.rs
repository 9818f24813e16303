//! A weight update on its way in: received whole (the host) or in chunks
//! (the link), then checked and installed one bounded slice per period
//! (docs/design.md §5.3) while the running net keeps running.
//!
//! The buffer and the check job live together here, so the job needs no
//! borrow between periods ([`CheckJob::rebind`]): the buffer is lent to it
//! for each slice and is never written while a check runs (a new blob
//! supersedes the job first).

use tendril_shared::{CheckJob, MAX_HIDDEN, MAX_TENDONS, MAX_WEIGHTS, POSE_DIM};

use crate::swap::{NetStore, SwapError};

/// The check job over the controller's net capacity.
type Job = CheckJob<'static, POSE_DIM, MAX_HIDDEN, MAX_TENDONS, MAX_WEIGHTS>;

/// Why an update (or a chunk of one) was not taken.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum UpdateError {
    /// The blob is longer than the update buffer.
    #[error("weight update of {len} bytes exceeds the {capacity}-byte buffer")]
    TooLarge {
        /// The blob's length.
        len: usize,
        /// The buffer's capacity.
        capacity: usize,
    },
    /// A chunk did not continue the blob being received (lost or reordered
    /// chunk, or a chunk of another length): the partial blob is dropped.
    #[error("weight chunk at byte {offset} does not continue the {received} bytes received")]
    OutOfOrder {
        /// The chunk's offset.
        offset: usize,
        /// Bytes of the blob received before it.
        received: usize,
    },
    /// The check or the install refused the blob; the old net runs.
    #[error(transparent)]
    Rejected(#[from] SwapError),
}

// One `State` per update buffer and no heap to box into: the ~150-byte
// variant costs nothing worth saving.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug)]
enum State {
    Idle,
    /// Chunks arriving: `total` bytes expected, `len` of them here.
    Receiving {
        total: usize,
    },
    /// Complete and being checked; `checked` once the check accepted it
    /// (the install takes a slice of its own).
    Checking {
        job: Job,
        checked: bool,
    },
}

/// `dst ← src` for slices of one length (a zip: `copy_from_slice` links a
/// length-mismatch panic the controller image must not carry).
fn copy(dst: &mut [u8], src: &[u8]) {
    for (d, s) in dst.iter_mut().zip(src) {
        *d = *s;
    }
}

/// Incoming-update buffer of `U` bytes and its check.
#[derive(Clone, Debug)]
pub struct Update<const U: usize> {
    buf: [u8; U],
    len: usize,
    state: State,
}

/// What [`Update::slice`] did this period.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SliceOutcome {
    /// Nothing to check, or still receiving.
    Idle,
    /// One slice of the check; the old net keeps running.
    Working,
    /// The new net runs from this period on.
    Swapped,
    /// Refused; the old net keeps running.
    Rejected(SwapError),
}

impl<const U: usize> Default for Update<U> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const U: usize> Update<U> {
    /// Empty, nothing in progress.
    pub const fn new() -> Self {
        Update {
            buf: [0; U],
            len: 0,
            state: State::Idle,
        }
    }

    /// Drop whatever is in progress (a new configuration: the update was
    /// for the old one). In place: the buffer is never moved.
    pub fn reset(&mut self) {
        self.state = State::Idle;
        self.len = 0;
    }

    /// The [`tendril_shared::tnet::net_hash`] of the blob in the buffer:
    /// its trailing CRC field, which the check compared with the CRC of the
    /// bytes before it. Meaningful in the period that reports
    /// [`SliceOutcome::Swapped`] (the installed net's); `None` when the
    /// buffer is shorter than a CRC.
    pub fn blob_hash(&self) -> Option<u32> {
        let blob = self.buf.get(..self.len)?;
        let crc = blob.get(blob.len().checked_sub(4)?..)?;
        Some(u32::from_le_bytes(crc.try_into().ok()?))
    }

    /// Whether a blob is being received or checked.
    pub const fn busy(&self) -> bool {
        !matches!(self.state, State::Idle)
    }

    /// Whether a check is running (the buffer is lent to it).
    pub const fn checking(&self) -> bool {
        matches!(self.state, State::Checking { .. })
    }

    /// Take a whole blob: copied, and checked from the next slice on.
    /// Supersedes anything in progress (returns whether it did, with the
    /// result).
    pub fn offer(&mut self, blob: &[u8]) -> Result<bool, UpdateError> {
        let superseded = self.busy();
        self.state = State::Idle;
        let dst = self
            .buf
            .get_mut(..blob.len())
            .ok_or(UpdateError::TooLarge {
                len: blob.len(),
                capacity: U,
            })?;
        copy(dst, blob);
        self.len = blob.len();
        self.start_check();
        Ok(superseded)
    }

    /// Take one chunk of a `total`-byte blob at `offset`. Offset 0 starts a
    /// new blob (superseding anything in progress); the others must follow
    /// the bytes received, else the partial blob is dropped. The last chunk
    /// starts the check. Returns whether an update in progress was
    /// superseded.
    pub fn chunk(
        &mut self,
        offset: usize,
        total: usize,
        bytes: &[u8],
    ) -> Result<bool, UpdateError> {
        let mut superseded = false;
        if offset == 0 {
            superseded = self.busy();
            if total > U {
                self.state = State::Idle;
                return Err(UpdateError::TooLarge {
                    len: total,
                    capacity: U,
                });
            }
            self.state = State::Receiving { total };
            self.len = 0;
        }
        let State::Receiving { total: want } = self.state else {
            return Err(UpdateError::OutOfOrder {
                offset,
                received: 0,
            });
        };
        let end = offset.saturating_add(bytes.len());
        let fits = offset == self.len && want == total && end <= total;
        let dst = if fits {
            self.buf.get_mut(offset..end)
        } else {
            None
        };
        let Some(dst) = dst else {
            let received = self.len;
            self.state = State::Idle;
            return Err(UpdateError::OutOfOrder { offset, received });
        };
        copy(dst, bytes);
        self.len = end;
        if end == total {
            self.start_check();
        }
        Ok(superseded)
    }

    fn start_check(&mut self) {
        self.state = State::Checking {
            job: CheckJob::new(&[]),
            checked: false,
        };
    }

    /// One bounded slice: up to `budget` bytes of the check, or the
    /// install into `store` (a slice of its own). `want` = the robot's
    /// (inputs, outputs).
    pub fn slice<S>(&mut self, store: &mut S, want: (usize, usize), budget: usize) -> SliceOutcome
    where
        S: NetStore<POSE_DIM, MAX_HIDDEN, MAX_TENDONS, MAX_WEIGHTS> + ?Sized,
    {
        let State::Checking { job, checked } = self.state else {
            return SliceOutcome::Idle;
        };
        let blob = self.buf.get(..self.len).unwrap_or(&[]);
        let mut running = job.rebind(blob);
        let result = match running.advance(budget) {
            core::task::Poll::Pending => {
                self.state = State::Checking {
                    job: running.rebind(&[]),
                    checked,
                };
                return SliceOutcome::Working;
            }
            core::task::Poll::Ready(Ok(_)) if !checked => {
                // Checked in this slice: install in the next, so no slice
                // does both the last check step and the write.
                self.state = State::Checking {
                    job: running.rebind(&[]),
                    checked: true,
                };
                return SliceOutcome::Working;
            }
            core::task::Poll::Ready(Ok(accepted)) => {
                let shape = accepted.header().shape;
                if (shape.inputs, shape.outputs) == want {
                    store.install(&accepted)
                } else {
                    Err(SwapError::ShapeMismatch {
                        inputs: shape.inputs,
                        outputs: shape.outputs,
                        want_inputs: want.0,
                        want_outputs: want.1,
                    })
                }
            }
            core::task::Poll::Ready(Err(e)) => Err(SwapError::from(e)),
        };
        self.state = State::Idle;
        match result {
            Ok(()) => SliceOutcome::Swapped,
            Err(e) => SliceOutcome::Rejected(e),
        }
    }
}
