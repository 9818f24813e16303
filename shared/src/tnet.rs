//! The `.tnet` weight format (docs/design.md §5): a trained cascade-correlation net,
//! its normalisation ranges and activation kinds, serialised with postcard and
//! sealed with a CRC-32.
//!
//! This module is the *wire format*: magic, version, header, the encoder,
//! the parser every decode runs (`walk`: header, array lengths, trailer) and
//! the CRC check; its errors are in `tnet/error.rs`. The *decoded* net, the
//! fixed-capacity storage the firmware runs, is [`crate::net`].
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
//! | inputs, hidden, outputs | `u16` ×3 | the [`NetShape`] |
//! | hidden_activation, output_activation | `u8` ×2 | [`Activation`] codes |
//! | provenance (version 2 only) | 81 raw bytes | [`Provenance`]: robot fingerprint `[u8; 32]`, robot name `[u8; 32]` (UTF-8, zero-padded), flags `u8` (bit 0: split recorded), split seed `u64` LE, test fraction `f64` LE |
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
//! `o (1 + I + H)` of `output_weights` ([`NetShape::hidden_row_offset`]).

pub use crate::activation::Activation;
use crate::crc32::Crc32;

mod encode;
mod error;
mod provenance;
pub use encode::{encode, encode_with, encoded_len, encoded_len_with};
#[cfg(feature = "std")]
pub use encode::{encode_to_vec, encode_to_vec_with, stamp_provenance};
pub use error::{Field, TnetError};
pub use provenance::{Provenance, SplitRecord, NAME_LEN, PROVENANCE_LEN};

/// The four bytes every `.tnet` file starts with.
pub const MAGIC: [u8; 4] = *b"TNET";

/// The newest format version: this crate writes it for a net with a
/// [`Provenance`] ([`encode_with`]) and reads it and [`VERSION_1`].
pub const VERSION: u16 = 2;

/// The first format version, without the provenance block: still read,
/// and written for a net without provenance ([`encode`]: test vectors,
/// synthetic nets, the firmware's built-in net).
pub const VERSION_1: u16 = 1;

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
pub struct NetShape {
    /// Number of inputs (7 for a tip pose: px, py, pz, qw, qx, qy, qz).
    pub inputs: usize,
    /// Number of installed hidden units (may be 0).
    pub hidden: usize,
    /// Number of outputs (one tension per tendon).
    pub outputs: usize,
}

impl NetShape {
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

    /// Bytes of the version-2 `.tnet` file (with its [`Provenance`]) of a
    /// net of this shape, CRC included: the largest file of this shape.
    pub const fn encoded_len_v2(&self) -> usize {
        // Both version numbers are one-byte varints.
        self.encoded_len() + PROVENANCE_LEN
    }

    /// Bytes of the version-1 `.tnet` file of a net of this shape, CRC
    /// included (what [`encoded_len`] returns for every such net): `const`,
    /// so a buffer can be checked against the largest net at compile time.
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
            + varint_len(VERSION_1 as usize)
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

/// A borrowed description of a net to encode: what a trainer hands to
/// [`encode`]. Weight arrays follow the module-level layout.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TnetView<'a> {
    /// Dimensions.
    pub shape: NetShape,
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
    /// Hidden unit rows concatenated, [`NetShape::hidden_weight_count`] long.
    pub hidden_weights: &'a [f32],
    /// Output rows concatenated, [`NetShape::output_weight_count`] long.
    pub output_weights: &'a [f32],
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

    /// `n` raw bytes.
    pub(crate) fn raw(&mut self, n: usize) -> Result<&'a [u8], TnetError> {
        match self.rest.split_at_checked(n) {
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

/// How a controller names a `.tnet` file to a host (the link's Hello,
/// docs/design.md §5.6): the CRC-32 of its bytes before the trailing CRC,
/// i.e. the file's own CRC field. Not the CRC-32 of the whole file: with
/// the file's CRC appended, that is the CRC's residue, 0x2144DF1C, for
/// every valid file, and would name no net at all.
pub fn net_hash(bytes: &[u8]) -> u32 {
    crate::crc32::crc32(bytes.get(..bytes.len().saturating_sub(4)).unwrap_or(bytes))
}

/// Parse and check the header (magic, version, shape, activations) of a
/// `.tnet` byte string, without touching the weights: what a loader uses to
/// report a file's shape or pick a capacity.
pub fn read_header(bytes: &[u8]) -> Result<(NetShape, Activation, Activation), TnetError> {
    let mut r = Reader::new(bytes);
    header(&mut r)
}

/// The [`Provenance`] of a `.tnet` byte string: `None` for version 1.
/// Parses the header and the block only; the caller decodes (and so
/// CRC-checks) the bytes first, as the host's `read_tnet` does.
pub fn read_provenance(bytes: &[u8]) -> Result<Option<Provenance>, TnetError> {
    let mut r = Reader::new(bytes);
    let (_, block) = header_and_provenance(&mut r)?;
    block.map(Provenance::parse).transpose()
}

pub(crate) fn header(r: &mut Reader<'_>) -> Result<(NetShape, Activation, Activation), TnetError> {
    header_and_provenance(r).map(|(h, _)| h)
}

/// The header and, for version 2, the raw provenance block (skipped, not
/// judged: the firmware runs a net whatever robot it names).
#[allow(clippy::type_complexity)]
pub(crate) fn header_and_provenance<'a>(
    r: &mut Reader<'a>,
) -> Result<((NetShape, Activation, Activation), Option<&'a [u8]>), TnetError> {
    let found: [u8; 4] = r.take()?;
    if found != MAGIC {
        return Err(TnetError::BadMagic { found });
    }
    let version: u16 = r.take()?;
    if version != VERSION && version != VERSION_1 {
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
    let block = if version == VERSION {
        Some(r.raw(PROVENANCE_LEN)?)
    } else {
        None
    };
    let shape = NetShape {
        inputs,
        hidden,
        outputs,
    };
    Ok(((shape, hidden_activation, output_activation), block))
}

/// What the decoder learnt from a `.tnet` it has fully validated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NetHeader {
    /// Dimensions.
    pub shape: NetShape,
    /// Activation of the hidden units.
    pub hidden_activation: Activation,
    /// Activation of the outputs.
    pub output_activation: Activation,
}

/// The little-endian word in a 4-byte chunk (`chunks_exact(4)` gives only
/// those; the pattern keeps the code free of panicking indexing).
#[inline]
pub(crate) fn word(c: &[u8]) -> u32 {
    match c {
        [a, b, c, d] => u32::from_le_bytes([*a, *b, *c, *d]),
        _ => 0,
    }
}

/// Index of the first NaN or ±∞ in a byte run of `f32`s: exponent bits all
/// ones (a bit test instead of a float compare; same answer as `is_finite`).
pub(crate) fn first_non_finite(bytes: &[u8]) -> Option<usize> {
    bytes
        .chunks_exact(4)
        .position(|c| word(c) & 0x7f80_0000 == 0x7f80_0000)
}

/// What [`walk`] checks after the last array.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Trailer {
    /// Four bytes that match the CRC-32 of everything before them.
    Crc,
    /// Exactly four bytes, their value not judged yet (the incremental
    /// check, [`crate::CheckJob`], hashes the body in later slices).
    Length,
    /// Exactly four bytes or [`TnetError::Malformed`] (the write after a
    /// complete check).
    Assumed,
}

/// Which values of the file a run of consecutive `f32`s holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Run {
    /// The whole `input_lo` array.
    InputLo,
    /// The whole `input_hi` array.
    InputHi,
    /// The whole `output_lo` array.
    OutputLo,
    /// The whole `output_hi` array.
    OutputHi,
    /// Part of row `unit` (hidden unit or output, as the field says), a
    /// row that sees `sees` hidden units: its bias and inputs
    /// (`cascade: false`) or its `sees` hidden-unit weights (`cascade: true`).
    Row {
        unit: usize,
        sees: usize,
        cascade: bool,
    },
}

/// Parse the whole file — header, every array, and the trailer — calling
/// `fits(header)` once the header is read (the decoded net's capacity
/// check), then `visit(field, index_in_field, run, bytes)` for each run of
/// consecutive `f32`s, in file order: each range array whole, and each
/// weight row as two runs (bias and inputs; earlier hidden units), because
/// the decoded net stores the inputs in a fixed number of columns. Checks
/// structure, not values (the visitor does).
pub(crate) fn walk(
    bytes: &[u8],
    trailer: Trailer,
    fits: impl FnOnce(&NetShape) -> Result<(), TnetError>,
    mut visit: impl FnMut(Field, usize, Run, &[u8]),
) -> Result<NetHeader, TnetError> {
    let mut r = Reader::new(bytes);
    let (shape, hidden_activation, output_activation) = header(&mut r)?;
    fits(&shape)?;
    let (ni, nh, no) = (shape.inputs, shape.hidden, shape.outputs);
    let ranges = [
        (Field::InputLo, ni, Run::InputLo),
        (Field::InputHi, ni, Run::InputHi),
        (Field::OutputLo, no, Run::OutputLo),
        (Field::OutputHi, no, Run::OutputHi),
    ];
    for (field, n, run) in ranges {
        r.seq_len(field, n)?;
        visit(field, 0, run, r.f32_run(n)?);
    }
    let mut row = |r: &mut Reader<'_>, field: Field, file_at: usize, unit: usize, sees: usize| {
        let head = Run::Row {
            unit,
            sees,
            cascade: false,
        };
        visit(field, file_at, head, r.f32_run(1 + ni)?);
        let tail = Run::Row {
            unit,
            sees,
            cascade: true,
        };
        visit(field, file_at + 1 + ni, tail, r.f32_run(sees)?);
        Ok::<(), TnetError>(())
    };
    r.seq_len(Field::HiddenWeights, shape.hidden_weight_count())?;
    for k in 0..nh {
        row(
            &mut r,
            Field::HiddenWeights,
            shape.hidden_row_offset(k),
            k,
            k,
        )?;
    }
    r.seq_len(Field::OutputWeights, shape.output_weight_count())?;
    for o in 0..no {
        let file_at = o * shape.output_row_len();
        row(&mut r, Field::OutputWeights, file_at, o, nh)?;
    }
    match trailer {
        Trailer::Crc => check_trailer(bytes, r.remaining())?,
        Trailer::Length => {
            stored_crc(r.remaining())?;
        }
        Trailer::Assumed if r.remaining().len() != 4 => return Err(TnetError::Malformed),
        Trailer::Assumed => {}
    }
    Ok(NetHeader {
        shape,
        hidden_activation,
        output_activation,
    })
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

#[cfg(test)]
mod tests;
