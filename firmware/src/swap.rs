//! Hot swap of the running net (DESIGN §5): two net buffers, one active. A
//! new blob is decoded and fully validated into the spare buffer; only then
//! does the active index flip. A rejected blob leaves the active net
//! untouched, so the next control step runs on the old net, and no step ever
//! waits for a decode (the flip is one store).

use tendril_shared::{CascadeNet, TnetError};

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

/// Double buffer of nets. Build with the `const` [`NetSlots::new`] so it can
/// live in a `static` (on the MCU it is the biggest object in RAM).
#[derive(Clone, Debug, PartialEq)]
pub struct NetSlots<const IN: usize, const H: usize, const OUT: usize> {
    slots: [CascadeNet<IN, H, OUT>; 2],
    active: usize,
}

impl<const IN: usize, const H: usize, const OUT: usize> Default for NetSlots<IN, H, OUT> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const IN: usize, const H: usize, const OUT: usize> NetSlots<IN, H, OUT> {
    /// Two empty slots (the active net is empty until the first [`NetSlots::load`]).
    pub const fn new() -> Self {
        NetSlots {
            slots: [CascadeNet::empty(), CascadeNet::empty()],
            active: 0,
        }
    }

    /// The net the control step should run.
    pub fn active(&self) -> &CascadeNet<IN, H, OUT> {
        let [a, b] = &self.slots;
        if self.active == 0 {
            a
        } else {
            b
        }
    }

    /// Validate `blob` completely into the spare slot and make it active.
    /// `want` = required (inputs, outputs), checked after decoding; on any
    /// error the active net is unchanged.
    pub fn load(&mut self, blob: &[u8], want: (usize, usize)) -> Result<(), SwapError> {
        let result = self.try_load(blob, want);
        match &result {
            Ok(()) => {
                let s = self.active().shape();
                log::info!(
                    "weights swapped: net {}-{}-{}",
                    s.inputs,
                    s.hidden,
                    s.outputs
                );
            }
            Err(e) => log::warn!("{e}; keeping the running net"),
        }
        result
    }

    fn try_load(&mut self, blob: &[u8], want: (usize, usize)) -> Result<(), SwapError> {
        let [a, b] = &mut self.slots;
        let spare = if self.active == 0 { b } else { a };
        spare.decode_into(blob)?;
        let s = spare.shape();
        if (s.inputs, s.outputs) != want {
            return Err(SwapError::ShapeMismatch {
                inputs: s.inputs,
                outputs: s.outputs,
                want_inputs: want.0,
                want_outputs: want.1,
            });
        }
        self.active = 1 - self.active.min(1);
        Ok(())
    }
}
