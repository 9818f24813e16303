//! Hot swap of the running net (docs/design.md §5, §5.3). A new blob is
//! validated completely (structure, capacity, CRC, finite values, ranges, and
//! the robot's input/output counts) before a single byte of any net is
//! written, so a rejected blob changes nothing and the next control step runs
//! on the old net.
//!
//! Two ways in: [`NetStore::load`] checks and installs in one call (the
//! host, tests, the vector run), and [`IncrementalSwap`] cuts the same work
//! into one bounded slice per control period (the MCU loop: the check of a
//! 64-unit update alone is longer than a 1 kHz period on a 100 MHz M4).
//!
//! Two stores, one contract ([`NetStore`]):
//! - [`FlashSlot`], the MCU's: the default net is a `static` in flash
//!   (generated at build time, [`crate::DEFAULT_NET`]) and one RAM slot takes
//!   updates; the control step runs whichever is selected. An update that
//!   replaces the RAM net while it is the running one is validated first and
//!   only then written (the loop is single-threaded: the swap runs between
//!   two steps, never inside one).
//! - [`NetSlots`], the host controller's: two RAM buffers, decode into the
//!   spare one, flip an index.

use core::task::Poll;

use tendril_shared::{CascadeNet, CheckJob, Checked, NetHeader, TnetError};

/// Why a blob was not swapped in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum SwapError {
    /// The blob is not a valid `.tnet` for this capacity.
    #[error("weight blob rejected: {0}")]
    Decode(#[from] TnetError),
    /// A newer blob arrived before this one was checked; this one was
    /// dropped unwritten ([`IncrementalSwap::offer`]).
    #[error("weight blob superseded by a newer one before it was checked")]
    Superseded,
    /// Valid, but its shape does not fit the robot.
    #[error("weight blob has {inputs} inputs and {outputs} outputs, the controller needs {want_inputs} and {want_outputs}")]
    ShapeMismatch {
        /// Inputs of the blob's net.
        inputs: usize,
        /// Outputs of the blob's net.
        outputs: usize,
        /// Inputs required.
        want_inputs: usize,
        /// Outputs (tendons) required.
        want_outputs: usize,
    },
}

/// Check a validated header against the required (inputs, outputs).
fn check_want(h: &NetHeader, want: (usize, usize)) -> Result<(), SwapError> {
    let s = h.shape;
    if (s.inputs, s.outputs) == want {
        Ok(())
    } else {
        Err(SwapError::ShapeMismatch {
            inputs: s.inputs,
            outputs: s.outputs,
            want_inputs: want.0,
            want_outputs: want.1,
        })
    }
}

/// A swap is logged at `debug`: it happens inside a control period, where
/// formatting a line and writing it to a serial log costs more than the
/// period can spare (≈ 3,000 instructions under `-icount`; milliseconds of
/// a blocking 115,200-baud UART on a board). The period's events report it
/// to the host, which lists it. A refusal, rare, stays a warning.
fn log_result(result: &Result<(), SwapError>, shape: tendril_shared::NetShape) {
    match result {
        Ok(()) => log::debug!(
            "weights swapped: net {}-{}-{}",
            shape.inputs,
            shape.hidden,
            shape.outputs
        ),
        Err(e) => log::warn!("{e}; keeping the running net"),
    }
}

/// What the control loop needs from a net store: the running net, and a
/// way to replace it that leaves it running if the new one is rejected.
pub trait NetStore<const IN: usize, const H: usize, const OUT: usize, const W: usize> {
    /// The net the control step should run.
    fn active(&self) -> &CascadeNet<IN, H, OUT, W>;

    /// Validate `blob` completely and make it the running net. `want` =
    /// required (inputs, outputs). On any error the running net is
    /// unchanged.
    fn load(&mut self, blob: &[u8], want: (usize, usize)) -> Result<(), SwapError> {
        let result = CascadeNet::<IN, H, OUT, W>::check(blob)
            .map_err(SwapError::from)
            .and_then(|checked| {
                check_want(checked.header(), want)?;
                self.install(&checked)
            });
        log_result(&result, self.active().shape());
        result
    }

    /// Write a completely checked net (whose shape suits the robot) and make
    /// it the running net: the last step of [`NetStore::load`] and of an
    /// [`IncrementalSwap`]. Bounded work (one parse of the blob, no check).
    fn install(&mut self, checked: &Checked<'_>) -> Result<(), SwapError>;

    /// Go back to the built-in net (for [`FlashSlot`], the flash default;
    /// a store without one keeps its running net). Returns whether the
    /// running net changed.
    fn revert(&mut self) -> bool;
}

/// The MCU's store: a default net in flash and one RAM slot for updates
/// (both borrowed, `'static` on the MCU: the RAM net is its own zero-filled
/// `static`, so it lands in `.bss` and costs no flash image).
///
/// Loading a blob: (1) [`CascadeNet::check`] (every check, CRC included)
/// without writing anything, (2) the robot's input/output counts, (3) select
/// the flash net, (4) [`CascadeNet::decode_checked`] into the RAM slot (one
/// more parse; it cannot fail on bytes that just passed), (5) select the RAM
/// slot. A rejection at (1) or
/// (2) leaves everything as it was, even when the RAM slot is the running
/// net; step (3) means that if the control step could ever run during (4)
/// it would run the valid flash net, never a half-written one.
#[derive(Debug)]
pub struct FlashSlot<'a, const IN: usize, const H: usize, const OUT: usize, const W: usize> {
    flash: &'a CascadeNet<IN, H, OUT, W>,
    ram: &'a mut CascadeNet<IN, H, OUT, W>,
    on_ram: bool,
}

impl<'a, const IN: usize, const H: usize, const OUT: usize, const W: usize>
    FlashSlot<'a, IN, H, OUT, W>
{
    /// Run `flash` (the built-in net); `ram` is the slot updates are
    /// decoded into (its contents are ignored until the first update).
    pub const fn new(
        flash: &'a CascadeNet<IN, H, OUT, W>,
        ram: &'a mut CascadeNet<IN, H, OUT, W>,
    ) -> Self {
        FlashSlot {
            flash,
            ram,
            on_ram: false,
        }
    }

    /// `true` while the RAM slot (a loaded update) is the running net.
    pub fn running_ram(&self) -> bool {
        self.on_ram
    }
}

impl<const IN: usize, const H: usize, const OUT: usize, const W: usize> NetStore<IN, H, OUT, W>
    for FlashSlot<'_, IN, H, OUT, W>
{
    fn active(&self) -> &CascadeNet<IN, H, OUT, W> {
        if self.on_ram {
            self.ram
        } else {
            self.flash
        }
    }

    fn install(&mut self, checked: &Checked<'_>) -> Result<(), SwapError> {
        self.on_ram = false;
        self.ram.decode_checked(checked)?;
        self.on_ram = true;
        Ok(())
    }

    fn revert(&mut self) -> bool {
        let changed = self.on_ram;
        self.on_ram = false;
        changed
    }
}

/// Double buffer of nets in RAM (the host controller's store, where RAM is
/// plentiful). Build with the `const` [`NetSlots::new`] so it can live in a
/// `static`.
#[derive(Clone, Debug, PartialEq)]
pub struct NetSlots<const IN: usize, const H: usize, const OUT: usize, const W: usize> {
    slots: [CascadeNet<IN, H, OUT, W>; 2],
    active: usize,
}

impl<const IN: usize, const H: usize, const OUT: usize, const W: usize> Default
    for NetSlots<IN, H, OUT, W>
{
    fn default() -> Self {
        Self::new()
    }
}

impl<const IN: usize, const H: usize, const OUT: usize, const W: usize> NetSlots<IN, H, OUT, W> {
    /// Two empty slots (the active net is empty until the first [`NetSlots::load`]).
    pub const fn new() -> Self {
        NetSlots {
            slots: [CascadeNet::empty(), CascadeNet::empty()],
            active: 0,
        }
    }

    /// The net the control step should run.
    pub fn active(&self) -> &CascadeNet<IN, H, OUT, W> {
        let [a, b] = &self.slots;
        if self.active == 0 {
            a
        } else {
            b
        }
    }

    /// Validate `blob` completely into the spare slot and make it active.
    /// `want` = required (inputs, outputs), checked before decoding; on any
    /// error the active net is unchanged.
    pub fn load(&mut self, blob: &[u8], want: (usize, usize)) -> Result<(), SwapError> {
        NetStore::load(self, blob, want)
    }
}

impl<const IN: usize, const H: usize, const OUT: usize, const W: usize> NetStore<IN, H, OUT, W>
    for NetSlots<IN, H, OUT, W>
{
    fn active(&self) -> &CascadeNet<IN, H, OUT, W> {
        NetSlots::active(self)
    }

    fn install(&mut self, checked: &Checked<'_>) -> Result<(), SwapError> {
        let [a, b] = &mut self.slots;
        let spare = if self.active == 0 { b } else { a };
        spare.decode_checked(checked)?;
        self.active = 1 - self.active.min(1);
        Ok(())
    }

    fn revert(&mut self) -> bool {
        false
    }
}

/// What one [`IncrementalSwap::slice`] did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SwapEvent {
    /// No update in progress; nothing done.
    Idle,
    /// One slice of the check done; the old net keeps running.
    Working,
    /// The update was written and is the running net from the next control
    /// step on.
    Swapped,
    /// The update was refused (the old net keeps running); the job is over.
    Rejected(SwapError),
}

/// An update being checked.
#[derive(Clone, Copy, Debug)]
struct Job<'b, const IN: usize, const H: usize, const OUT: usize, const W: usize> {
    check: CheckJob<'b, IN, H, OUT, W>,
    want: (usize, usize),
    /// The check finished in an earlier slice: this slice installs.
    checked: bool,
}

/// Hot swap without a missed period (docs/design.md §5.3): the check of an
/// offered blob ([`CheckJob`]) runs one bounded slice per control period
/// while the old net keeps running, and the accepted net is written and
/// selected in a slice of its own, between two control steps, so every step
/// runs either the old net or the new one, never a mix. A blob that fails
/// anywhere ends the job and leaves the old net running.
///
/// A second blob offered while one is in progress supersedes it: the first
/// is dropped unwritten ([`SwapError::Superseded`]) and the check starts
/// over on the second (the newest net the sender meant wins; nothing of the
/// first was written, so there is nothing to undo).
///
/// The blob is borrowed for the whole job (`'b`): the bus driver's receive
/// buffer, which must not change until the job ends.
#[derive(Clone, Copy, Debug, Default)]
pub struct IncrementalSwap<'b, const IN: usize, const H: usize, const OUT: usize, const W: usize> {
    job: Option<Job<'b, IN, H, OUT, W>>,
}

impl<'b, const IN: usize, const H: usize, const OUT: usize, const W: usize>
    IncrementalSwap<'b, IN, H, OUT, W>
{
    /// No update in progress.
    pub const fn new() -> Self {
        IncrementalSwap { job: None }
    }

    /// Start swapping in `blob` for a robot that needs `want` = (inputs,
    /// outputs). No work yet (the next [`IncrementalSwap::slice`] does the
    /// first). Returns [`SwapError::Superseded`] if this replaced a job in
    /// progress (its blob is no longer borrowed).
    pub fn offer(&mut self, blob: &'b [u8], want: (usize, usize)) -> Result<(), SwapError> {
        let superseded = self.job.is_some();
        self.job = Some(Job {
            check: CheckJob::new(blob),
            want,
            checked: false,
        });
        if superseded {
            log::warn!("{}; checking the newer blob", SwapError::Superseded);
            Err(SwapError::Superseded)
        } else {
            Ok(())
        }
    }

    /// `true` while a blob is being checked (its buffer is still borrowed).
    pub const fn busy(&self) -> bool {
        self.job.is_some()
    }

    /// One slice of work, between two control steps: up to `budget` bytes
    /// of hashing or value scanning (or the structure, the ranges, or the
    /// final write into `store`, each one bounded by the capacity).
    pub fn slice<S: NetStore<IN, H, OUT, W>>(&mut self, store: &mut S, budget: usize) -> SwapEvent {
        let Some(job) = self.job.as_mut() else {
            return SwapEvent::Idle;
        };
        let result = match job.check.advance(budget) {
            Poll::Pending => return SwapEvent::Working,
            Poll::Ready(Ok(_)) if !job.checked => {
                // Checked in this slice: write in the next one, so no slice
                // does the last check step and the write.
                job.checked = true;
                return SwapEvent::Working;
            }
            Poll::Ready(Ok(checked)) => {
                check_want(checked.header(), job.want).and_then(|()| store.install(&checked))
            }
            Poll::Ready(Err(e)) => Err(SwapError::from(e)),
        };
        self.job = None;
        log_result(&result, store.active().shape());
        match result {
            Ok(()) => SwapEvent::Swapped,
            Err(e) => SwapEvent::Rejected(e),
        }
    }
}

#[cfg(test)]
mod tests;
