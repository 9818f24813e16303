//! The decoded, fixed-capacity cascade net: what the firmware runs.

use crate::tnet::{self, Activation, Field, Reader, Shape, TnetError};

/// One unit's incoming weights, zero-padded to the capacity: the bias, one
/// weight per input, one per (earlier) hidden unit. `#[repr(C)]` keeps the
/// row contiguous in memory for the inference loop.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct Unit<const IN: usize, const MAX_HIDDEN: usize> {
    /// Weight of the constant +1 input.
    pub bias: f32,
    /// Weights of the normalised inputs (entries past the net's input count are 0).
    pub inputs: [f32; IN],
    /// Weights of the hidden units (for hidden unit `k`, entries `k..` are 0).
    pub hidden: [f32; MAX_HIDDEN],
}

impl<const IN: usize, const MAX_HIDDEN: usize> Unit<IN, MAX_HIDDEN> {
    /// All weights zero.
    pub const ZERO: Self = Unit {
        bias: 0.0,
        inputs: [0.0; IN],
        hidden: [0.0; MAX_HIDDEN],
    };

    /// The whole row as one slice, `[bias, inputs…, hidden…]`
    /// (`1 + IN + MAX_HIDDEN` long): the inference loop runs one dot product
    /// per unit over it.
    pub fn as_slice(&self) -> &[f32] {
        const {
            assert!(core::mem::size_of::<Self>() == 4 * (1 + IN + MAX_HIDDEN));
            assert!(core::mem::align_of::<Self>() == core::mem::align_of::<f32>());
        }
        // SAFETY: `Unit` is `#[repr(C)]` and made only of `f32`s (a scalar and
        // two arrays), so it is `1 + IN + MAX_HIDDEN` contiguous, aligned,
        // initialised `f32`s without padding (checked at compile time
        // above); the pointer comes from the whole struct, so its provenance
        // covers every element, and the borrow of `self` keeps it alive.
        unsafe {
            core::slice::from_raw_parts((self as *const Self).cast::<f32>(), 1 + IN + MAX_HIDDEN)
        }
    }
}

/// A cascade-correlation net decoded from a `.tnet` file into fixed-capacity
/// storage: up to `IN` inputs, `MAX_HIDDEN` hidden units and `OUT` outputs.
/// No allocation; `size_of` is `4 (MAX_HIDDEN + OUT)(1 + IN + MAX_HIDDEN)`
/// bytes plus the ranges, so pick capacities with the MCU's RAM in mind.
///
/// Every value in a decoded net is finite and every range non-empty: the
/// decoder guarantees it, and nothing else can build a non-empty net.
#[derive(Clone, Debug, PartialEq)]
pub struct CascadeNet<const IN: usize, const MAX_HIDDEN: usize, const OUT: usize> {
    shape: Shape,
    hidden_activation: Activation,
    output_activation: Activation,
    input_lo: [f32; IN],
    input_hi: [f32; IN],
    output_lo: [f32; OUT],
    output_hi: [f32; OUT],
    hidden: [Unit<IN, MAX_HIDDEN>; MAX_HIDDEN],
    outputs: [Unit<IN, MAX_HIDDEN>; OUT],
}

impl<const IN: usize, const MAX_HIDDEN: usize, const OUT: usize> Default
    for CascadeNet<IN, MAX_HIDDEN, OUT>
{
    fn default() -> Self {
        Self::empty()
    }
}

/// The first `n` entries of `a` (all of it if `n` exceeds the length: callers
/// check capacities first, this only keeps the code panic-free).
fn prefix<T>(a: &[T], n: usize) -> &[T] {
    a.get(..n).unwrap_or(a)
}

fn prefix_mut<T>(a: &mut [T], n: usize) -> &mut [T] {
    let len = a.len();
    match a.get_mut(..n.min(len)) {
        Some(p) => p,
        None => &mut [],
    }
}

impl<const IN: usize, const MAX_HIDDEN: usize, const OUT: usize> CascadeNet<IN, MAX_HIDDEN, OUT> {
    /// A net with no inputs, no hidden units and no outputs; a placeholder for
    /// static storage (`const`, so it can initialise a `static`).
    pub const fn empty() -> Self {
        CascadeNet {
            shape: Shape {
                inputs: 0,
                hidden: 0,
                outputs: 0,
            },
            // All-zero bit pattern (Linear is code 0), so a `static` of empty
            // nets lands in .bss and costs no flash.
            hidden_activation: Activation::Linear,
            output_activation: Activation::Linear,
            input_lo: [0.0; IN],
            input_hi: [0.0; IN],
            output_lo: [0.0; OUT],
            output_hi: [0.0; OUT],
            hidden: [Unit::ZERO; MAX_HIDDEN],
            outputs: [Unit::ZERO; OUT],
        }
    }

    /// Decode a `.tnet` byte string. Never panics: any byte string either
    /// decodes into a fully checked net or gives a [`TnetError`].
    ///
    /// The net is returned by value; on a small stack prefer
    /// [`CascadeNet::decode_into`] on static storage.
    pub fn decode(bytes: &[u8]) -> Result<Self, TnetError> {
        let mut net = Self::empty();
        net.decode_into(bytes)?;
        Ok(net)
    }

    /// Decode into `self`. On success `self` holds the new net; on error it is
    /// left [empty](CascadeNet::empty) (never half-written), so a caller that
    /// must keep running decodes into a spare buffer (the firmware's
    /// double-buffered hot swap does).
    pub fn decode_into(&mut self, bytes: &[u8]) -> Result<(), TnetError> {
        let result = self.try_decode(bytes);
        if result.is_err() {
            self.clear();
        }
        result
    }

    fn clear(&mut self) {
        *self = Self::empty();
    }

    fn try_decode(&mut self, bytes: &[u8]) -> Result<(), TnetError> {
        let mut r = Reader::new(bytes);
        let (shape, hidden_activation, output_activation) = tnet::header(&mut r)?;
        if shape.inputs > IN || shape.hidden > MAX_HIDDEN || shape.outputs > OUT {
            return Err(TnetError::ShapeOverCapacity {
                inputs: shape.inputs,
                hidden: shape.hidden,
                outputs: shape.outputs,
                cap_inputs: IN,
                cap_hidden: MAX_HIDDEN,
                cap_outputs: OUT,
            });
        }
        self.clear();
        let (ni, nh, no) = (shape.inputs, shape.hidden, shape.outputs);
        r.float_seq(Field::InputLo, prefix_mut(&mut self.input_lo, ni))?;
        r.float_seq(Field::InputHi, prefix_mut(&mut self.input_hi, ni))?;
        r.float_seq(Field::OutputLo, prefix_mut(&mut self.output_lo, no))?;
        r.float_seq(Field::OutputHi, prefix_mut(&mut self.output_hi, no))?;

        r.seq_len(Field::HiddenWeights, shape.hidden_weight_count())?;
        for (k, unit) in prefix_mut(&mut self.hidden, nh).iter_mut().enumerate() {
            unit.bias = r.take()?;
            r.floats(prefix_mut(&mut unit.inputs, ni))?;
            r.floats(prefix_mut(&mut unit.hidden, k))?;
        }
        r.seq_len(Field::OutputWeights, shape.output_weight_count())?;
        for unit in prefix_mut(&mut self.outputs, no).iter_mut() {
            unit.bias = r.take()?;
            r.floats(prefix_mut(&mut unit.inputs, ni))?;
            r.floats(prefix_mut(&mut unit.hidden, nh))?;
        }
        tnet::check_trailer(bytes, r.remaining())?;

        // Only now that the CRC vouches for the bytes, judge the values.
        self.shape = shape;
        self.hidden_activation = hidden_activation;
        self.output_activation = output_activation;
        tnet::check_finite(Field::InputLo, self.input_lo())?;
        tnet::check_finite(Field::InputHi, self.input_hi())?;
        tnet::check_finite(Field::OutputLo, self.output_lo())?;
        tnet::check_finite(Field::OutputHi, self.output_hi())?;
        let mut offset = 0;
        for (k, unit) in self.hidden_units().iter().enumerate() {
            check_row(Field::HiddenWeights, offset, unit, ni, k)?;
            offset += shape.hidden_row_len(k);
        }
        offset = 0;
        for unit in self.output_units() {
            check_row(Field::OutputWeights, offset, unit, ni, nh)?;
            offset += shape.output_row_len();
        }
        tnet::check_ranges(Field::InputLo, self.input_lo(), self.input_hi())?;
        tnet::check_ranges(Field::OutputLo, self.output_lo(), self.output_hi())?;
        Ok(())
    }

    /// Dimensions of the decoded net (all zero for an empty net).
    pub fn shape(&self) -> Shape {
        self.shape
    }

    /// `true` for the placeholder net that [`CascadeNet::empty`] makes.
    pub fn is_empty(&self) -> bool {
        self.shape.outputs == 0
    }

    /// Activation of the hidden units.
    pub fn hidden_activation(&self) -> Activation {
        self.hidden_activation
    }

    /// Activation of the outputs.
    pub fn output_activation(&self) -> Activation {
        self.output_activation
    }

    /// Lower ends of the input normalisation ranges (`shape().inputs` long).
    pub fn input_lo(&self) -> &[f32] {
        prefix(&self.input_lo, self.shape.inputs)
    }

    /// Upper ends of the input normalisation ranges.
    pub fn input_hi(&self) -> &[f32] {
        prefix(&self.input_hi, self.shape.inputs)
    }

    /// Lower ends of the output ranges (`shape().outputs` long).
    pub fn output_lo(&self) -> &[f32] {
        prefix(&self.output_lo, self.shape.outputs)
    }

    /// Upper ends of the output ranges.
    pub fn output_hi(&self) -> &[f32] {
        prefix(&self.output_hi, self.shape.outputs)
    }

    /// The installed hidden units in cascade order (`shape().hidden` long).
    pub fn hidden_units(&self) -> &[Unit<IN, MAX_HIDDEN>] {
        prefix(&self.hidden, self.shape.hidden)
    }

    /// The output units (`shape().outputs` long).
    pub fn output_units(&self) -> &[Unit<IN, MAX_HIDDEN>] {
        prefix(&self.outputs, self.shape.outputs)
    }
}

/// Check one unit's used weights are finite; `offset` is the row's start in
/// the flat file array so the error points at the file's index.
fn check_row<const IN: usize, const H: usize>(
    field: Field,
    offset: usize,
    unit: &Unit<IN, H>,
    inputs: usize,
    hidden: usize,
) -> Result<(), TnetError> {
    let at = |i: usize| TnetError::NonFinite {
        field,
        index: offset + i,
    };
    if !unit.bias.is_finite() {
        return Err(at(0));
    }
    if let Some(i) = prefix(&unit.inputs, inputs)
        .iter()
        .position(|v| !v.is_finite())
    {
        return Err(at(1 + i));
    }
    if let Some(i) = prefix(&unit.hidden, hidden)
        .iter()
        .position(|v| !v.is_finite())
    {
        return Err(at(1 + inputs + i));
    }
    Ok(())
}
