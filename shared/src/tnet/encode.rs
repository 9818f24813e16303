//! The `.tnet` encoder (docs/design.md §5.1): checks a [`TnetView`] as the
//! decoder would and writes it, version 1 without provenance, version 2
//! with it; and [`stamp_provenance`], which turns a version-1 file into
//! version 2.

use serde::Serialize;

use super::{
    check_finite, check_ranges, Field, Provenance, TnetError, TnetView, MAGIC, PROVENANCE_LEN,
    VERSION, VERSION_1,
};
use crate::crc32::Crc32;

/// postcard's view of the file's header, before the provenance block.
#[derive(Serialize)]
struct Head {
    magic: [u8; 4],
    version: u16,
    inputs: u16,
    hidden: u16,
    outputs: u16,
    hidden_activation: u8,
    output_activation: u8,
}

/// postcard's view of the file minus the CRC; the field order *is* the
/// format (the provenance block, raw bytes, sits between head and arrays).
struct Wire<'a> {
    head: Head,
    provenance: Option<[u8; PROVENANCE_LEN]>,
    arrays: Arrays<'a>,
}

/// postcard's view of the arrays.
#[derive(Serialize)]
struct Arrays<'a> {
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

impl<'a> TnetView<'a> {
    /// Check everything the decoder would check: non-empty shape, array
    /// lengths, finite values, non-empty ranges. Returns the postcard view
    /// (version 2 with `provenance`, else version 1).
    fn wire(&self, provenance: Option<&Provenance>) -> Result<Wire<'a>, TnetError> {
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
            head: Head {
                magic: MAGIC,
                version: if provenance.is_some() {
                    VERSION
                } else {
                    VERSION_1
                },
                inputs: dim(s.inputs)?,
                hidden: dim(s.hidden)?,
                outputs: dim(s.outputs)?,
                hidden_activation: self.hidden_activation.code(),
                output_activation: self.output_activation.code(),
            },
            provenance: provenance.map(|p| p.to_bytes()),
            arrays: Arrays {
                input_lo: self.input_lo,
                input_hi: self.input_hi,
                output_lo: self.output_lo,
                output_hi: self.output_hi,
                hidden_weights: self.hidden_weights,
                output_weights: self.output_weights,
            },
        })
    }
}

/// postcard's size of `value`.
fn postcard_len<T: Serialize>(value: &T) -> Result<usize, TnetError> {
    postcard::serialize_with_flavor::<_, postcard::ser_flavors::Size, usize>(
        value,
        postcard::ser_flavors::Size::default(),
    )
    .map_err(|_| TnetError::Malformed)
}

impl Wire<'_> {
    /// Bytes of the body (everything before the CRC).
    fn body_len(&self) -> Result<usize, TnetError> {
        let prov = self.provenance.map_or(0, |p| p.len());
        Ok(postcard_len(&self.head)? + prov + postcard_len(&self.arrays)?)
    }

    /// Write the body into `buf` (at least [`Wire::body_len`] long).
    fn write(&self, buf: &mut [u8], too_small: TnetError) -> Result<usize, TnetError> {
        let head = postcard::to_slice(&self.head, buf)
            .map_err(|_| too_small)?
            .len();
        let mut at = head;
        if let Some(p) = &self.provenance {
            buf.get_mut(at..at + p.len())
                .ok_or(too_small)?
                .copy_from_slice(p);
            at += p.len();
        }
        let rest = buf.get_mut(at..).ok_or(too_small)?;
        let arrays = postcard::to_slice(&self.arrays, rest)
            .map_err(|_| too_small)?
            .len();
        Ok(at + arrays)
    }
}

/// Size in bytes of the encoded version-1 net, CRC included; validates
/// like [`encode`].
pub fn encoded_len(net: &TnetView<'_>) -> Result<usize, TnetError> {
    encoded_len_with(net, None)
}

/// Size in bytes of the net encoded by [`encode_with`] with `provenance`.
pub fn encoded_len_with(
    net: &TnetView<'_>,
    provenance: Option<&Provenance>,
) -> Result<usize, TnetError> {
    Ok(net.wire(provenance)?.body_len()? + 4)
}

/// Encode `net` as version 1 (no provenance) into `buf`, returning the
/// number of bytes written ([`encoded_len`]). Refuses (typed error, nothing
/// promised about `buf`) anything the decoder would reject, so every file
/// this writes decodes.
pub fn encode(net: &TnetView<'_>, buf: &mut [u8]) -> Result<usize, TnetError> {
    encode_with(net, None, buf)
}

/// Encode `net` into `buf`: version 2 with its `provenance` (what the
/// trainer writes), version 1 without. Otherwise as [`encode`].
pub fn encode_with(
    net: &TnetView<'_>,
    provenance: Option<&Provenance>,
    buf: &mut [u8],
) -> Result<usize, TnetError> {
    let wire = net.wire(provenance)?;
    let needed = wire.body_len()? + 4;
    if buf.len() < needed {
        return Err(TnetError::BufferTooSmall {
            needed,
            available: buf.len(),
        });
    }
    let available = buf.len();
    let too_small = TnetError::BufferTooSmall { needed, available };
    let body_len = wire.write(buf, too_small)?;
    let (body, rest) = buf.split_at_mut(body_len);
    let mut crc = Crc32::new();
    crc.update(body);
    let tail = rest.get_mut(..4).ok_or(too_small)?;
    tail.copy_from_slice(&crc.finish().to_le_bytes());
    Ok(body_len + 4)
}

/// Encode `net` into a new vector (host convenience for the trainer's
/// export): version 2 with `provenance`, version 1 without.
#[cfg(feature = "std")]
pub fn encode_to_vec_with(
    net: &TnetView<'_>,
    provenance: Option<&Provenance>,
) -> Result<std::vec::Vec<u8>, TnetError> {
    let mut buf = std::vec![0u8; encoded_len_with(net, provenance)?];
    let n = encode_with(net, provenance, &mut buf)?;
    buf.truncate(n);
    Ok(buf)
}

/// Version 2 of a version-1 byte string: `provenance` inserted after the
/// header, the CRC recomputed (for a net fitted for a known robot by code
/// that writes version 1, like the sim's quick net). The input must decode;
/// a version-2 input is refused ([`TnetError::UnsupportedVersion`]).
#[cfg(feature = "std")]
pub fn stamp_provenance(
    v1: &[u8],
    provenance: &Provenance,
) -> Result<std::vec::Vec<u8>, TnetError> {
    let mut r = super::Reader::new(v1);
    let (_, block) = super::header_and_provenance(&mut r)?;
    if block.is_some() {
        return Err(TnetError::UnsupportedVersion { found: VERSION });
    }
    let header_len = v1.len() - r.remaining().len();
    let body_end = v1.len().checked_sub(4).ok_or(TnetError::Truncated)?;
    let (head, arrays) = v1
        .get(..header_len)
        .zip(v1.get(header_len..body_end))
        .ok_or(TnetError::Truncated)?;
    // A corrupted input must not come out sealed with a fresh CRC.
    let mut crc = Crc32::new();
    crc.update(v1.get(..body_end).unwrap_or(&[]));
    super::crc_matches(
        super::stored_crc(v1.get(body_end..).unwrap_or(&[]))?,
        crc.finish(),
    )?;
    let mut out = std::vec::Vec::with_capacity(v1.len() + PROVENANCE_LEN);
    out.extend_from_slice(head);
    // The version is a one-byte varint right after the magic.
    if let Some(v) = out.get_mut(MAGIC.len()) {
        *v = VERSION as u8;
    }
    out.extend_from_slice(&provenance.to_bytes());
    out.extend_from_slice(arrays);
    let mut crc = Crc32::new();
    crc.update(&out);
    out.extend_from_slice(&crc.finish().to_le_bytes());
    Ok(out)
}

/// [`encode_to_vec_with`] without provenance (version 1).
#[cfg(feature = "std")]
pub fn encode_to_vec(net: &TnetView<'_>) -> Result<std::vec::Vec<u8>, TnetError> {
    encode_to_vec_with(net, None)
}
