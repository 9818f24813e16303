//! The complete check of a `.tnet` byte string ([`CascadeNet::check`]) cut
//! into slices of bounded work, so a controller can check a hot-swap update
//! between control steps without missing a period (docs/design.md §5.3).
//!
//! Same checks, same order, same answer as [`CascadeNet::check`] for every
//! byte string and every slice size: the structure (one slice, bounded by
//! the capacity: it reads only the header and the array lengths, never a
//! value), then the CRC of the body (`budget` bytes per slice), then the
//! values for NaN/∞ (`budget` bytes per slice), then the normalisation
//! ranges (one slice). Nothing is written anywhere; the caller writes the
//! accepted net with [`CascadeNet::decode_checked`].

use core::task::Poll;

use super::{fill, prefix, walk, CascadeNet, Checked};
use crate::crc32::Crc32;
use crate::tnet::{
    self, first_non_finite, Activation, Field, NetHeader, NetShape, TnetError, Trailer,
};

/// One `f32` array of the file: the field, the offset of its first value
/// in the file, and its number of values.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Span {
    field: Field,
    start: usize,
    count: usize,
}

/// Where a [`CheckJob`] stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Stage {
    /// The next slice parses the structure.
    Structure,
    /// Hashing the body: `at` bytes done.
    Crc { at: usize },
    /// Scanning `spans[array]` for NaN/∞: `at` bytes of it done.
    Values { array: usize, at: usize },
    /// The next slice checks the normalisation ranges.
    Ranges,
    /// Finished, accepted.
    Accepted,
    /// Finished, rejected.
    Rejected(TnetError),
}

/// The arrays in file order: `input_lo`, `input_hi`, `output_lo`,
/// `output_hi`, `hidden_weights`, `output_weights`.
const ARRAYS: usize = 6;

/// A [`CascadeNet::check`] in progress over a borrowed byte string: call
/// [`CheckJob::advance`] once per control period until it is `Ready`.
/// About 150 bytes; no allocation, no panic.
#[derive(Clone, Copy, Debug)]
pub struct CheckJob<'a, const IN: usize, const H: usize, const OUT: usize, const W: usize> {
    bytes: &'a [u8],
    stage: Stage,
    crc: Crc32,
    stored_crc: u32,
    header: NetHeader,
    spans: [Span; ARRAYS],
}

impl<'a, const IN: usize, const H: usize, const OUT: usize, const W: usize>
    CheckJob<'a, IN, H, OUT, W>
{
    /// Start checking `bytes` (no work yet: the first
    /// [`CheckJob::advance`] parses the structure).
    pub const fn new(bytes: &'a [u8]) -> Self {
        const fn span(field: Field) -> Span {
            Span {
                field,
                start: 0,
                count: 0,
            }
        }
        CheckJob {
            bytes,
            stage: Stage::Structure,
            crc: Crc32::new(),
            stored_crc: 0,
            header: NetHeader {
                shape: NetShape {
                    inputs: 0,
                    hidden: 0,
                    outputs: 0,
                },
                hidden_activation: Activation::Linear,
                output_activation: Activation::Linear,
            },
            spans: [
                span(Field::InputLo),
                span(Field::InputHi),
                span(Field::OutputLo),
                span(Field::OutputHi),
                span(Field::HiddenWeights),
                span(Field::OutputWeights),
            ],
        }
    }

    /// The bytes being checked.
    pub const fn bytes(&self) -> &'a [u8] {
        self.bytes
    }

    /// The same job, continued on `bytes`: the owner of a receive buffer
    /// keeps the job without a borrow between periods (rebinding to `&[]`)
    /// and lends the buffer back for each slice. `bytes` must be the bytes
    /// the job started on, unchanged; the job holds only offsets and a
    /// running CRC, so other bytes give a wrong verdict, never a panic or
    /// an out-of-bounds read.
    pub const fn rebind<'c>(self, bytes: &'c [u8]) -> CheckJob<'c, IN, H, OUT, W> {
        CheckJob {
            bytes,
            stage: self.stage,
            crc: self.crc,
            stored_crc: self.stored_crc,
            header: self.header,
            spans: self.spans,
        }
    }

    /// Do one slice of the check: the structure, or up to `budget` bytes
    /// (at least 4) of hashing or of the value scan, or the ranges.
    /// `Pending` until the last slice; then `Ready` with what
    /// [`CascadeNet::check`] returns for these bytes, and the same again on
    /// every later call.
    pub fn advance(&mut self, budget: usize) -> Poll<Result<Checked<'a>, TnetError>> {
        let budget = (budget & !3).max(4);
        let next = match self.stage {
            Stage::Structure => self.structure(),
            Stage::Crc { at } => self.hash(at, budget),
            Stage::Values { array, at } => self.values(array, at, budget),
            Stage::Ranges => self.ranges(),
            done @ (Stage::Accepted | Stage::Rejected(_)) => Ok(done),
        };
        self.stage = next.unwrap_or_else(Stage::Rejected);
        match self.stage {
            Stage::Accepted => Poll::Ready(Ok(Checked {
                bytes: self.bytes,
                header: self.header,
            })),
            Stage::Rejected(e) => Poll::Ready(Err(e)),
            _ => Poll::Pending,
        }
    }

    /// Header, capacity, every array length and the trailer's length, in one
    /// pass that looks at no value (its work is bounded by the capacity:
    /// a few operations per row).
    fn structure(&mut self) -> Result<Stage, TnetError> {
        let bytes = self.bytes;
        let base = bytes.as_ptr() as usize;
        let spans = &mut self.spans;
        let header = walk::<IN, H, OUT, W>(bytes, Trailer::Length, |field, at, _, run| {
            // The run at index 0 of an array starts it (an empty weight
            // array has no run; its count stays 0 and its start unused).
            if at == 0 {
                if let Some(span) = spans.iter_mut().find(|s| s.field == field) {
                    span.start = (run.as_ptr() as usize).wrapping_sub(base);
                }
            }
        })?;
        let s = header.shape;
        let counts = [
            s.inputs,
            s.inputs,
            s.outputs,
            s.outputs,
            s.hidden_weight_count(),
            s.output_weight_count(),
        ];
        for (span, count) in self.spans.iter_mut().zip(counts) {
            span.count = count;
        }
        let body = bytes.len().saturating_sub(4);
        self.stored_crc = tnet::stored_crc(bytes.get(body..).unwrap_or(&[]))?;
        self.header = header;
        Ok(Stage::Crc { at: 0 })
    }

    /// CRC-32 of the next `budget` bytes of the body; at its end, compare.
    fn hash(&mut self, at: usize, budget: usize) -> Result<Stage, TnetError> {
        let body = self.bytes.len().saturating_sub(4);
        let end = at.saturating_add(budget).min(body);
        self.crc.update(self.bytes.get(at..end).unwrap_or(&[]));
        if end < body {
            return Ok(Stage::Crc { at: end });
        }
        tnet::crc_matches(self.stored_crc, self.crc.finish())?;
        Ok(Stage::Values { array: 0, at: 0 })
    }

    /// Scan the next `budget` bytes of `spans[array]` for NaN/∞.
    fn values(&mut self, array: usize, at: usize, budget: usize) -> Result<Stage, TnetError> {
        let Some(span) = self.spans.get(array) else {
            return Ok(Stage::Ranges);
        };
        let len = span.count.saturating_mul(4);
        let end = at.saturating_add(budget).min(len);
        let run = self
            .bytes
            .get(span.start.saturating_add(at)..span.start.saturating_add(end))
            .ok_or(TnetError::Truncated)?;
        if let Some(i) = first_non_finite(run) {
            return Err(TnetError::NonFinite {
                field: span.field,
                index: at / 4 + i,
            });
        }
        Ok(if end < len {
            Stage::Values { array, at: end }
        } else if array + 1 < ARRAYS {
            Stage::Values {
                array: array + 1,
                at: 0,
            }
        } else {
            Stage::Ranges
        })
    }

    /// Every normalisation range non-empty (`hi > lo`).
    fn ranges(&self) -> Result<Stage, TnetError> {
        let mut lo_in = [0.0f32; IN];
        let mut hi_in = [0.0f32; IN];
        let mut lo_out = [0.0f32; OUT];
        let mut hi_out = [0.0f32; OUT];
        let dests: [&mut [f32]; 4] = [&mut lo_in, &mut hi_in, &mut lo_out, &mut hi_out];
        for (dst, span) in dests.into_iter().zip(&self.spans) {
            let end = span.start.saturating_add(span.count.saturating_mul(4));
            // Finiteness was judged by the value scan.
            let _finite = fill(dst, self.bytes.get(span.start..end).unwrap_or(&[]));
        }
        let (ni, no) = (self.header.shape.inputs, self.header.shape.outputs);
        tnet::check_ranges(Field::InputLo, prefix(&lo_in, ni), prefix(&hi_in, ni))?;
        tnet::check_ranges(Field::OutputLo, prefix(&lo_out, no), prefix(&hi_out, no))?;
        Ok(Stage::Accepted)
    }
}

impl<const IN: usize, const H: usize, const OUT: usize, const W: usize> CascadeNet<IN, H, OUT, W> {
    /// [`CascadeNet::check`] in slices of bounded work ([`CheckJob`]).
    pub const fn check_job(bytes: &[u8]) -> CheckJob<'_, IN, H, OUT, W> {
        CheckJob::new(bytes)
    }
}
