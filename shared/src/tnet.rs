//! The `.tnet` weight format (DESIGN §5): a trained cascade-correlation net,
//! its normalisation ranges and activation kinds, serialised with postcard and
//! sealed with a CRC-32.
//!
//! # Layout
//! Fields in order, each in postcard's encoding (varints for integers,
//! 4-byte little-endian IEEE-754 for `f32`, a varint length before each
//! sequence):
//!
//! | field | postcard type | meaning |
//! |---|---|---|
//! | magic | `[u8; 4]` | `b"TNET"` |
//! | version | `u16` | [`VERSION`] |
//! | inputs, hidden, outputs | `u16` ×3 | the [`Shape`] |
//! | hidden_activation, output_activation | `u8` ×2 | [`Activation`] codes |
//! | input_lo, input_hi | `[f32]` ×2 | per-input normalisation range, `inputs` long |
//! | output_lo, output_hi | `[f32]` ×2 | per-output range, `outputs` long |
//! | hidden_weights | `[f32]` | hidden unit rows, concatenated |
//! | output_weights | `[f32]` | output unit rows, concatenated |
//! | crc | `[u8; 4]` | CRC-32 (IEEE) of every byte before it, little-endian |
//!
//! # Weight layout
//! The net sees *normalised* inputs `x̂_i = (x_i − lo_i) / (hi_i − lo_i)`.
//! Hidden unit `k` (0-based) has `1 + inputs + k` weights, in the order
//! `[bias, input 0 … input I−1, hidden 0 … hidden k−1]`: it sees the bias
//! (+1), every input and every earlier hidden unit (the cascade). Its value is
//! `h_k = hidden_activation(Σ w·feature)`. Output `o` has `1 + inputs + hidden`
//! weights, `[bias, inputs…, every hidden unit…]`, and its value is
//! `ŷ_o = output_activation(Σ w·feature)`, de-normalised as
//! `y_o = lo_o + ŷ_o (hi_o − lo_o)` (newtons for tendon tensions). Row `k`
//! starts at offset `k (1 + I) + k (k − 1)/2` of `hidden_weights`; row `o` at
//! `o (1 + I + H)` of `output_weights` ([`Shape::hidden_row_offset`]).

use core::fmt;

use serde::Serialize;

use crate::crc32::Crc32;

/// The four bytes every `.tnet` file starts with.
pub const MAGIC: [u8; 4] = *b"TNET";

/// The format version this crate writes and reads.
pub const VERSION: u16 = 1;

/// Activation function of a layer of units.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Activation {
    /// Identity: Fahlman's choice for outputs with continuous targets.
    Linear,
    /// Logistic sigmoid `1/(1+e^−x)`, range (0, 1) like the normalised targets.
    Sigmoid,
    /// Fahlman's symmetric sigmoid `1/(1+e^−x) − 0.5`, range (−0.5, 0.5):
    /// the hidden units of cascade correlation.
    SymmetricSigmoid,
}

impl Activation {
    /// The byte that stands for this activation in the file.
    pub const fn code(self) -> u8 {
        match self {
            Activation::Linear => 0,
            Activation::Sigmoid => 1,
            Activation::SymmetricSigmoid => 2,
        }
    }

    /// The activation a file byte stands for, if any.
    pub const fn from_code(code: u8) -> Option<Activation> {
        match code {
            0 => Some(Activation::Linear),
            1 => Some(Activation::Sigmoid),
            2 => Some(Activation::SymmetricSigmoid),
            _ => None,
        }
    }

    /// Apply the activation in `f32`, the exact code the firmware runs: only
    /// exactly rounded `+ − × ÷`, comparisons and bit moves, so host and MCU
    /// builds give bit-identical results. The sigmoids use `exp_neg`
    /// instead of `libm::expf` (≈ 54 Cortex-M4F instructions with range
    /// checks, a `vdiv` and `scalbnf`; the hidden units' sigmoids were 38 % of
    /// an inference). Absolute error ≤ 1e-6 over every `f32` (measured
    /// 1.0e-7, see the tests); ±∞ saturate to the limits, NaN gives NaN.
    #[inline]
    pub fn apply(self, x: f32) -> f32 {
        match self {
            Activation::Linear => x,
            Activation::Sigmoid => 1.0 / (1.0 + exp_neg(x)),
            Activation::SymmetricSigmoid => 1.0 / (1.0 + exp_neg(x)) - 0.5,
        }
    }
}

/// Inputs are clamped to `±SIGMOID_CLAMP` before [`exp_neg`]: the sigmoid
/// there is within `1/(1+e^24) ≈ 4e-11` of its limit, and `e^±24` keeps the
/// power-of-two scale a normal number (no overflow, no ∞/∞ = NaN).
const SIGMOID_CLAMP: f32 = 24.0;

/// `−log2(e)`: `e^−x = 2^(−x log2 e)`.
const NEG_LOG2_E: f32 = -core::f32::consts::LOG2_E;

/// `1.5·2^23 + 127`: adding it to `|t| < 2^22` rounds `t` to the nearest
/// integer `k` (the sum's ulp is 1) and leaves `k + 127`, the biased
/// exponent of `2^k`, in the low mantissa bits.
const ROUND_BIAS: f32 = 12_583_039.0;

/// Coefficients of `2^f ≈ 1 + f (C1 + f (C2 + f (C3 + f (C4 + f C5))))` on
/// `|f| ≤ 0.5`: minimax in relative error with the constant term fixed at 1
/// (so `σ(0) = 0.5` exactly), each coefficient rounded to `f32` and the rest
/// re-fitted; relative error 1.3e-7.
const EXP2_C: [f32; 5] = [
    f32::from_bits(0x3f31_7215), // 0.693147004
    f32::from_bits(0x3e75_fcd8), // 0.240222335
    f32::from_bits(0x3d63_5bd8), // 0.0555075109
    f32::from_bits(0x3c1e_76e6), // 0.00967190228
    f32::from_bits(0x3aad_d9cb), // 0.00132637599
];

/// `e^−x` for the sigmoids, branch-free and panic-free in ≈ 25 M4F
/// instructions: clamp `x` to `±SIGMOID_CLAMP`, `t = −x log2 e`,
/// `k = round(t)` by the [`ROUND_BIAS`] trick, `f = t − k` (exact,
/// `|f| ≤ 0.5`), a degree-5 polynomial for `2^f`, times `2^k` built from the
/// exponent bits. Relative error ≈ 2e-7, which moves a sigmoid by at most a
/// quarter of that (`dσ = σ(1−σ)·δ`). NaN falls through both comparisons and
/// propagates through `f` and the polynomial, so NaN in gives NaN out.
#[inline(always)]
fn exp_neg(x: f32) -> f32 {
    let x = if x > SIGMOID_CLAMP { SIGMOID_CLAMP } else { x };
    let x = if x < -SIGMOID_CLAMP {
        -SIGMOID_CLAMP
    } else {
        x
    };
    let t = x * NEG_LOG2_E;
    let biased = t + ROUND_BIAS;
    let k = biased - ROUND_BIAS;
    let f = t - k;
    let [c1, c2, c3, c4, c5] = EXP2_C;
    let p = 1.0 + f * (c1 + f * (c2 + f * (c3 + f * (c4 + f * c5))));
    // `k + 127` sits in bits 0..8 of `biased` (92..=162 for |t| ≤ 34.7) and
    // everything above bit 8 shifts out: the bits of 2^k.
    let scale = f32::from_bits(biased.to_bits() << 23);
    p * scale
}

impl fmt::Display for Activation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Activation::Linear => "linear",
            Activation::Sigmoid => "sigmoid",
            Activation::SymmetricSigmoid => "symmetric-sigmoid",
        })
    }
}

/// Dimensions of a cascade net.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Shape {
    /// Number of inputs (7 for a tip pose: px, py, pz, qw, qx, qy, qz).
    pub inputs: usize,
    /// Number of installed hidden units (may be 0).
    pub hidden: usize,
    /// Number of outputs (one tension per tendon).
    pub outputs: usize,
}

impl Shape {
    /// Number of weights of hidden unit `k`: bias, inputs, earlier hidden units.
    pub const fn hidden_row_len(&self, k: usize) -> usize {
        1 + self.inputs + k
    }

    /// Offset of hidden unit `k`'s row in the concatenated hidden weights.
    pub const fn hidden_row_offset(&self, k: usize) -> usize {
        k * (1 + self.inputs) + k * k.saturating_sub(1) / 2
    }

    /// Number of weights of each output: bias, inputs, every hidden unit.
    pub const fn output_row_len(&self) -> usize {
        1 + self.inputs + self.hidden
    }

    /// Total length of `hidden_weights`: Σ_k (1 + I + k).
    pub const fn hidden_weight_count(&self) -> usize {
        self.hidden_row_offset(self.hidden)
    }

    /// Total length of `output_weights`: O (1 + I + H).
    pub const fn output_weight_count(&self) -> usize {
        self.outputs * self.output_row_len()
    }

    /// Multiply-accumulates per inference (one per weight).
    pub const fn macs(&self) -> usize {
        self.hidden_weight_count() + self.output_weight_count()
    }
}

/// Which array of the file a problem was found in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Field {
    /// Lower ends of the input normalisation ranges.
    InputLo,
    /// Upper ends of the input normalisation ranges.
    InputHi,
    /// Lower ends of the output ranges.
    OutputLo,
    /// Upper ends of the output ranges.
    OutputHi,
    /// Concatenated hidden unit weights.
    HiddenWeights,
    /// Concatenated output unit weights.
    OutputWeights,
}

impl fmt::Display for Field {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Field::InputLo => "input_lo",
            Field::InputHi => "input_hi",
            Field::OutputLo => "output_lo",
            Field::OutputHi => "output_hi",
            Field::HiddenWeights => "hidden_weights",
            Field::OutputWeights => "output_weights",
        })
    }
}

/// Everything that can be wrong with a `.tnet` byte string or with a net
/// handed to the encoder. Decoding never panics; it returns one of these.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum TnetError {
    /// The bytes end before the format says they should.
    #[error("weight file truncated: it ends in the middle of the data")]
    Truncated,
    /// Not a `.tnet` file.
    #[error("not a .tnet weight file: magic bytes are {found:02x?}, expected \"TNET\"")]
    BadMagic {
        /// The first four bytes found.
        found: [u8; 4],
    },
    /// A format version this build cannot read.
    #[error("unsupported .tnet version {found} (this build reads version {VERSION})")]
    UnsupportedVersion {
        /// The version in the file.
        found: u16,
    },
    /// Zero inputs or zero outputs.
    #[error("net shape has no inputs or no outputs ({inputs} inputs, {outputs} outputs)")]
    EmptyShape {
        /// Inputs in the file.
        inputs: usize,
        /// Outputs in the file.
        outputs: usize,
    },
    /// The net does not fit the fixed capacity it is decoded into.
    #[error(
        "net shape {inputs}-{hidden}-{outputs} (inputs-hidden-outputs) exceeds this build's capacity {cap_inputs}-{cap_hidden}-{cap_outputs}"
    )]
    ShapeOverCapacity {
        /// Inputs in the file.
        inputs: usize,
        /// Hidden units in the file.
        hidden: usize,
        /// Outputs in the file.
        outputs: usize,
        /// Input capacity.
        cap_inputs: usize,
        /// Hidden unit capacity.
        cap_hidden: usize,
        /// Output capacity.
        cap_outputs: usize,
    },
    /// An activation code outside the known kinds.
    #[error("unknown activation code {code}")]
    UnknownActivation {
        /// The code found.
        code: u8,
    },
    /// An array whose length disagrees with the shape.
    #[error("{field} has {found} entries, the shape needs {expected}")]
    LengthMismatch {
        /// The array.
        field: Field,
        /// Length the shape implies.
        expected: usize,
        /// Length found.
        found: usize,
    },
    /// Bytes that are not valid postcard for the expected field (e.g. an
    /// over-long varint).
    #[error("weight file malformed: invalid encoding")]
    Malformed,
    /// Bytes after the CRC.
    #[error("weight file has {extra} unexpected bytes after the checksum")]
    TrailingBytes {
        /// How many.
        extra: usize,
    },
    /// The checksum does not match: the file is corrupted.
    #[error("weight file corrupted: CRC-32 is {stored:#010x}, data hashes to {computed:#010x}")]
    CrcMismatch {
        /// CRC stored in the file.
        stored: u32,
        /// CRC of the data.
        computed: u32,
    },
    /// A NaN or infinite weight or range bound.
    #[error("{field}[{index}] is not a finite number")]
    NonFinite {
        /// The array.
        field: Field,
        /// Index in it.
        index: usize,
    },
    /// A normalisation range with `hi <= lo` (would divide by zero or flip signs).
    #[error("{field}[{index}]: normalisation range is empty (hi <= lo)")]
    EmptyRange {
        /// `InputLo` or `OutputLo`: which ranges.
        field: Field,
        /// Index of the range.
        index: usize,
    },
    /// A shape dimension too large for the file's `u16` fields.
    #[error("net shape dimension {value} does not fit the format (max 65535)")]
    ShapeTooLarge {
        /// The offending dimension.
        value: usize,
    },
    /// The encoder's output buffer is too small.
    #[error("output buffer holds {available} bytes, the encoded net needs {needed}")]
    BufferTooSmall {
        /// Bytes needed ([`encoded_len`]).
        needed: usize,
        /// Bytes available.
        available: usize,
    },
}

/// A borrowed description of a net to encode: what a trainer hands to
/// [`encode`]. Weight arrays follow the module-level layout.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TnetView<'a> {
    /// Dimensions.
    pub shape: Shape,
    /// Activation of the hidden units (cascade correlation: [`Activation::SymmetricSigmoid`]).
    pub hidden_activation: Activation,
    /// Activation of the outputs ([`Activation::Linear`] or [`Activation::Sigmoid`]).
    pub output_activation: Activation,
    /// Per-input lower bound of the normalisation range (`shape.inputs` long).
    pub input_lo: &'a [f32],
    /// Per-input upper bound (`> input_lo`).
    pub input_hi: &'a [f32],
    /// Per-output lower bound (newtons for tensions; `shape.outputs` long).
    pub output_lo: &'a [f32],
    /// Per-output upper bound (`> output_lo`).
    pub output_hi: &'a [f32],
    /// Hidden unit rows concatenated, [`Shape::hidden_weight_count`] long.
    pub hidden_weights: &'a [f32],
    /// Output rows concatenated, [`Shape::output_weight_count`] long.
    pub output_weights: &'a [f32],
}

/// postcard's view of the file minus the CRC; the field order *is* the format.
#[derive(Serialize)]
struct Wire<'a> {
    magic: [u8; 4],
    version: u16,
    inputs: u16,
    hidden: u16,
    outputs: u16,
    hidden_activation: u8,
    output_activation: u8,
    input_lo: &'a [f32],
    input_hi: &'a [f32],
    output_lo: &'a [f32],
    output_hi: &'a [f32],
    hidden_weights: &'a [f32],
    output_weights: &'a [f32],
}

fn dim(value: usize) -> Result<u16, TnetError> {
    u16::try_from(value).map_err(|_| TnetError::ShapeTooLarge { value })
}

fn check_len(field: Field, slice: &[f32], expected: usize) -> Result<(), TnetError> {
    if slice.len() == expected {
        Ok(())
    } else {
        Err(TnetError::LengthMismatch {
            field,
            expected,
            found: slice.len(),
        })
    }
}

/// First non-finite entry of `values`, as an error naming `field`.
pub(crate) fn check_finite(field: Field, values: &[f32]) -> Result<(), TnetError> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(TnetError::NonFinite { field, index }),
        None => Ok(()),
    }
}

/// First range with `hi <= lo`, as an error naming `field`.
pub(crate) fn check_ranges(field: Field, lo: &[f32], hi: &[f32]) -> Result<(), TnetError> {
    match lo.iter().zip(hi).position(|(l, h)| h <= l) {
        Some(index) => Err(TnetError::EmptyRange { field, index }),
        None => Ok(()),
    }
}

impl<'a> TnetView<'a> {
    /// Check everything the decoder would check: non-empty shape, array
    /// lengths, finite values, non-empty ranges. Returns the postcard view.
    fn wire(&self) -> Result<Wire<'a>, TnetError> {
        let s = self.shape;
        if s.inputs == 0 || s.outputs == 0 {
            return Err(TnetError::EmptyShape {
                inputs: s.inputs,
                outputs: s.outputs,
            });
        }
        let arrays = [
            (Field::InputLo, self.input_lo, s.inputs),
            (Field::InputHi, self.input_hi, s.inputs),
            (Field::OutputLo, self.output_lo, s.outputs),
            (Field::OutputHi, self.output_hi, s.outputs),
            (
                Field::HiddenWeights,
                self.hidden_weights,
                s.hidden_weight_count(),
            ),
            (
                Field::OutputWeights,
                self.output_weights,
                s.output_weight_count(),
            ),
        ];
        for (field, slice, expected) in arrays {
            check_len(field, slice, expected)?;
            check_finite(field, slice)?;
        }
        check_ranges(Field::InputLo, self.input_lo, self.input_hi)?;
        check_ranges(Field::OutputLo, self.output_lo, self.output_hi)?;
        Ok(Wire {
            magic: MAGIC,
            version: VERSION,
            inputs: dim(s.inputs)?,
            hidden: dim(s.hidden)?,
            outputs: dim(s.outputs)?,
            hidden_activation: self.hidden_activation.code(),
            output_activation: self.output_activation.code(),
            input_lo: self.input_lo,
            input_hi: self.input_hi,
            output_lo: self.output_lo,
            output_hi: self.output_hi,
            hidden_weights: self.hidden_weights,
            output_weights: self.output_weights,
        })
    }
}

/// Size in bytes of the encoded net, CRC included; validates like [`encode`].
pub fn encoded_len(net: &TnetView<'_>) -> Result<usize, TnetError> {
    let wire = net.wire()?;
    let size = postcard::serialize_with_flavor::<_, postcard::ser_flavors::Size, usize>(
        &wire,
        postcard::ser_flavors::Size::default(),
    )
    .map_err(|_| TnetError::Malformed)?;
    Ok(size + 4)
}

/// Encode `net` into `buf`, returning the number of bytes written
/// ([`encoded_len`]). Refuses (typed error, nothing promised about `buf`)
/// anything the decoder would reject, so every file this writes decodes.
pub fn encode(net: &TnetView<'_>, buf: &mut [u8]) -> Result<usize, TnetError> {
    let needed = encoded_len(net)?;
    if buf.len() < needed {
        return Err(TnetError::BufferTooSmall {
            needed,
            available: buf.len(),
        });
    }
    let available = buf.len();
    let too_small = TnetError::BufferTooSmall { needed, available };
    let wire = net.wire()?;
    let body_len = postcard::to_slice(&wire, buf).map_err(|_| too_small)?.len();
    let (body, rest) = buf.split_at_mut(body_len);
    let mut crc = Crc32::new();
    crc.update(body);
    let tail = rest.get_mut(..4).ok_or(too_small)?;
    tail.copy_from_slice(&crc.finish().to_le_bytes());
    Ok(body_len + 4)
}

/// Encode `net` into a new vector (host convenience for the trainer's export).
#[cfg(feature = "std")]
pub fn encode_to_vec(net: &TnetView<'_>) -> Result<std::vec::Vec<u8>, TnetError> {
    let mut buf = std::vec![0u8; encoded_len(net)?];
    let n = encode(net, &mut buf)?;
    buf.truncate(n);
    Ok(buf)
}

/// A cursor over the file that maps postcard's errors to [`TnetError`].
pub(crate) struct Reader<'a> {
    rest: &'a [u8],
}

impl<'a> Reader<'a> {
    pub(crate) fn new(bytes: &'a [u8]) -> Self {
        Reader { rest: bytes }
    }

    pub(crate) fn remaining(&self) -> &'a [u8] {
        self.rest
    }

    pub(crate) fn take<T: serde::de::DeserializeOwned>(&mut self) -> Result<T, TnetError> {
        match postcard::take_from_bytes::<T>(self.rest) {
            Ok((v, rest)) => {
                self.rest = rest;
                Ok(v)
            }
            Err(postcard::Error::DeserializeUnexpectedEnd) => Err(TnetError::Truncated),
            Err(_) => Err(TnetError::Malformed),
        }
    }

    /// A sequence length, checked against what the shape needs.
    pub(crate) fn seq_len(&mut self, field: Field, expected: usize) -> Result<(), TnetError> {
        let found: u64 = self.take()?;
        if found == expected as u64 {
            Ok(())
        } else {
            Err(TnetError::LengthMismatch {
                field,
                expected,
                found: usize::try_from(found).unwrap_or(usize::MAX),
            })
        }
    }

    /// The bytes of `n` consecutive `f32`s (postcard writes an `f32` as its
    /// 4 little-endian IEEE-754 bytes, no framing), taken in one step: the
    /// decoder reads thousands of them.
    #[inline]
    pub(crate) fn f32_run(&mut self, n: usize) -> Result<&'a [u8], TnetError> {
        let len = n.checked_mul(4).ok_or(TnetError::Truncated)?;
        match self.rest.split_at_checked(len) {
            Some((run, rest)) => {
                self.rest = rest;
                Ok(run)
            }
            None => Err(TnetError::Truncated),
        }
    }

    pub(crate) fn activation(&mut self) -> Result<Activation, TnetError> {
        let code: u8 = self.take()?;
        Activation::from_code(code).ok_or(TnetError::UnknownActivation { code })
    }
}

/// Parse and check the header (magic, version, shape, activations) of a
/// `.tnet` byte string, without touching the weights: what a loader uses to
/// report a file's shape or pick a capacity.
pub fn read_header(bytes: &[u8]) -> Result<(Shape, Activation, Activation), TnetError> {
    let mut r = Reader::new(bytes);
    header(&mut r)
}

pub(crate) fn header(r: &mut Reader<'_>) -> Result<(Shape, Activation, Activation), TnetError> {
    let found: [u8; 4] = r.take()?;
    if found != MAGIC {
        return Err(TnetError::BadMagic { found });
    }
    let version: u16 = r.take()?;
    if version != VERSION {
        return Err(TnetError::UnsupportedVersion { found: version });
    }
    let inputs = usize::from(r.take::<u16>()?);
    let hidden = usize::from(r.take::<u16>()?);
    let outputs = usize::from(r.take::<u16>()?);
    if inputs == 0 || outputs == 0 {
        return Err(TnetError::EmptyShape { inputs, outputs });
    }
    let hidden_activation = r.activation()?;
    let output_activation = r.activation()?;
    Ok((
        Shape {
            inputs,
            hidden,
            outputs,
        },
        hidden_activation,
        output_activation,
    ))
}

/// Check the CRC trailer after the last field: exactly four bytes must
/// remain and match the CRC-32 of `all[..all.len() - 4]`.
pub(crate) fn check_trailer(all: &[u8], rest: &[u8]) -> Result<(), TnetError> {
    match rest.len() {
        0..=3 => return Err(TnetError::Truncated),
        4 => {}
        n => return Err(TnetError::TrailingBytes { extra: n - 4 }),
    }
    let body = all
        .get(..all.len().saturating_sub(4))
        .ok_or(TnetError::Truncated)?;
    let stored = match rest {
        [a, b, c, d] => u32::from_le_bytes([*a, *b, *c, *d]),
        _ => return Err(TnetError::Truncated),
    };
    let mut crc = Crc32::new();
    crc.update(body);
    let computed = crc.finish();
    if stored == computed {
        Ok(())
    } else {
        Err(TnetError::CrcMismatch { stored, computed })
    }
}

#[cfg(test)]
mod activation_tests {
    //! The sigmoids against `f64` references (`libm::exp`, independent of the
    //! `f32` code under test) over dense sweeps, a stride through every
    //! `f32` bit pattern, and the special values.
    use super::Activation;

    /// Required bound on the absolute error of both sigmoids.
    const BOUND: f64 = 1e-6;

    fn sym_ref(x: f32) -> f64 {
        1.0 / (1.0 + libm::exp(-f64::from(x))) - 0.5
    }

    fn sym_err(x: f32) -> f64 {
        (f64::from(Activation::SymmetricSigmoid.apply(x)) - sym_ref(x)).abs()
    }

    #[test]
    fn symmetric_sigmoid_error_dense_sweep() {
        // 2·10^6 points over [−40, 40]: every range-reduction interval
        // (k = −58 … 58) and the clamp at ±24 many times over.
        let n = 2_000_000;
        let mut worst = (0.0f64, 0.0f32);
        for i in 0..=n {
            let x = -40.0 + 80.0 * (i as f64 / n as f64);
            let x = x as f32;
            let e = sym_err(x);
            if e > worst.0 {
                worst = (e, x);
            }
        }
        assert!(worst.0 <= BOUND, "error {:e} at x = {}", worst.0, worst.1);
        // Measured 9.8e-8; this catches a wrong polynomial coefficient (1 %
        // off in the quartic one alone gives 2.1e-6, in the cubic 2.4e-5).
        assert!(worst.0 < 2e-7, "error {:e} at x = {}", worst.0, worst.1);
    }

    #[test]
    fn symmetric_sigmoid_error_all_f32_stride() {
        // Every 1021st bit pattern (4.2·10^6 values: subnormals, huge
        // magnitudes, both signs, NaNs); the bound on every finite one,
        // NaN in gives NaN out, and nothing leaves [−0.5, 0.5].
        let mut worst = 0.0f64;
        let mut bits = 0u32;
        let mut count = 0u32;
        loop {
            let x = f32::from_bits(bits);
            let y = Activation::SymmetricSigmoid.apply(x);
            if x.is_nan() {
                assert!(y.is_nan(), "NaN {bits:#x} gave {y}");
            } else {
                assert!((-0.5..=0.5).contains(&y), "x = {x}: {y}");
                worst = worst.max(sym_err(x));
            }
            count += 1;
            match bits.checked_add(1021) {
                Some(b) => bits = b,
                None => break,
            }
        }
        assert!(count > 4_000_000);
        assert!(worst <= BOUND, "worst error {worst:e}");
    }

    #[test]
    fn symmetric_sigmoid_special_values() {
        let s = |x: f32| Activation::SymmetricSigmoid.apply(x);
        assert_eq!(s(0.0), 0.0);
        assert_eq!(s(-0.0), 0.0);
        assert_eq!(s(f32::INFINITY), 0.5);
        assert_eq!(s(f32::NEG_INFINITY), -0.5);
        assert_eq!(s(f32::MAX), 0.5);
        assert_eq!(s(f32::MIN), -0.5);
        for x in [f32::MIN_POSITIVE, 1e-40, -1e-40, 1e-30, -1e-30] {
            assert!(s(x).abs() <= 1e-6, "{x}: {}", s(x));
        }
        for x in [24.0f32, 24.000002, 25.0, 1e10, -24.0, -25.0, -1e10] {
            assert!(sym_err(x) <= BOUND, "{x}");
        }
        assert!(s(f32::NAN).is_nan());
        assert!(s(-f32::NAN).is_nan());
        // A NaN with payload bits that would land in the exponent of 2^k.
        assert!(s(f32::from_bits(0x7fc0_01ff)).is_nan());
        assert!(s(f32::from_bits(0xffff_ffff)).is_nan());
    }

    #[test]
    fn plain_sigmoid_error_and_limits() {
        let sig = |x: f32| Activation::Sigmoid.apply(x);
        let n = 1_000_000;
        let mut worst = 0.0f64;
        for i in 0..=n {
            let x = (-40.0 + 80.0 * (i as f64 / n as f64)) as f32;
            let r = 1.0 / (1.0 + libm::exp(-f64::from(x)));
            worst = worst.max((f64::from(sig(x)) - r).abs());
        }
        assert!(worst <= BOUND, "worst error {worst:e}");
        assert_eq!(sig(0.0), 0.5);
        assert_eq!(sig(f32::INFINITY), 1.0);
        assert!(sig(f32::NEG_INFINITY) >= 0.0 && sig(f32::NEG_INFINITY) < 1e-10);
        assert!(sig(f32::NAN).is_nan());
        assert_eq!(Activation::Linear.apply(3.5), 3.5);
    }
}
