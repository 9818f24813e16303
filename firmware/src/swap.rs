//! Hot swap of the running net (docs/design.md §5). A new blob is validated
//! completely (structure, capacity, CRC, finite values, ranges, and the
//! robot's input/output counts) before a single byte of any net is written,
//! so a rejected blob changes nothing and the next control step runs on the
//! old net.
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

use tendril_shared::{CascadeNet, NetHeader, TnetError};

/// Why a blob was not swapped in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum SwapError {
    /// The blob is not a valid `.tnet` for this capacity.
    #[error("weight blob rejected: {0}")]
    Decode(#[from] TnetError),
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

fn log_result(result: &Result<(), SwapError>, shape: tendril_shared::Shape) {
    match result {
        Ok(()) => log::info!(
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
    fn load(&mut self, blob: &[u8], want: (usize, usize)) -> Result<(), SwapError>;

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

    fn try_load(&mut self, blob: &[u8], want: (usize, usize)) -> Result<(), SwapError> {
        let checked = CascadeNet::<IN, H, OUT, W>::check(blob)?;
        check_want(checked.header(), want)?;
        self.on_ram = false;
        self.ram.decode_checked(&checked)?;
        self.on_ram = true;
        Ok(())
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

    fn load(&mut self, blob: &[u8], want: (usize, usize)) -> Result<(), SwapError> {
        let result = self.try_load(blob, want);
        log_result(&result, self.active().shape());
        result
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
        let result = self.try_load(blob, want);
        log_result(&result, self.active().shape());
        result
    }

    fn try_load(&mut self, blob: &[u8], want: (usize, usize)) -> Result<(), SwapError> {
        let checked = CascadeNet::<IN, H, OUT, W>::check(blob)?;
        check_want(checked.header(), want)?;
        let [a, b] = &mut self.slots;
        let spare = if self.active == 0 { b } else { a };
        spare.decode_checked(&checked)?;
        self.active = 1 - self.active.min(1);
        Ok(())
    }
}

impl<const IN: usize, const H: usize, const OUT: usize, const W: usize> NetStore<IN, H, OUT, W>
    for NetSlots<IN, H, OUT, W>
{
    fn active(&self) -> &CascadeNet<IN, H, OUT, W> {
        NetSlots::active(self)
    }

    fn load(&mut self, blob: &[u8], want: (usize, usize)) -> Result<(), SwapError> {
        NetSlots::load(self, blob, want)
    }

    fn revert(&mut self) -> bool {
        false
    }
}
