//! The `.tnet` weight format (docs/design.md §5): a trained cascade-correlation net,
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

pub use crate::activation::Activation;
use crate::crc32::Crc32;

/// The four bytes every `.tnet` file starts with.
pub const MAGIC: [u8; 4] = *b"TNET";

/// The format version this crate writes and reads.
pub const VERSION: u16 = 1;

/// The wire codes of the activations (the `hidden_activation` and
/// `output_activation` bytes).
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

    /// Bytes of the `.tnet` file of a net of this shape, CRC included (what
    /// [`encoded_len`] returns for every such net): `const`, so a buffer
    /// can be checked against the largest net at compile time.
    pub const fn encoded_len(&self) -> usize {
        let (i, o) = (self.inputs, self.outputs);
        let arrays = [
            i,
            i,
            o,
            o,
            self.hidden_weight_count(),
            self.output_weight_count(),
        ];
        let mut len = MAGIC.len()
            + varint_len(VERSION as usize)
            + varint_len(i)
            + varint_len(self.hidden)
            + varint_len(o)
            + 2;
        let mut rest: &[usize] = &arrays;
        while let [n, tail @ ..] = rest {
            len += varint_len(*n) + 4 * *n;
            rest = tail;
        }
        len + 4
    }
}

/// Bytes of postcard's varint of `v` (7 bits per byte).
const fn varint_len(mut v: usize) -> usize {
    let mut n = 1;
    while v >= 0x80 {
        v >>= 7;
        n += 1;
    }
    n
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

/// The CRC stored in the trailer after the last field: exactly four bytes
/// must remain ([`TnetError::Truncated`] / [`TnetError::TrailingBytes`]).
pub(crate) fn stored_crc(rest: &[u8]) -> Result<u32, TnetError> {
    match rest {
        [a, b, c, d] => Ok(u32::from_le_bytes([*a, *b, *c, *d])),
        [_, _, _, _, extra @ ..] => Err(TnetError::TrailingBytes { extra: extra.len() }),
        _ => Err(TnetError::Truncated),
    }
}

/// Compare the stored CRC with the one computed over the body.
pub(crate) fn crc_matches(stored: u32, computed: u32) -> Result<(), TnetError> {
    if stored == computed {
        Ok(())
    } else {
        Err(TnetError::CrcMismatch { stored, computed })
    }
}

/// Check the CRC trailer after the last field: exactly four bytes must
/// remain and match the CRC-32 of `all[..all.len() - 4]`.
pub(crate) fn check_trailer(all: &[u8], rest: &[u8]) -> Result<(), TnetError> {
    let stored = stored_crc(rest)?;
    let body = all
        .get(..all.len().saturating_sub(4))
        .ok_or(TnetError::Truncated)?;
    let mut crc = Crc32::new();
    crc.update(body);
    crc_matches(stored, crc.finish())
}
