//! The decoded, fixed-capacity cascade net: what the firmware runs.
//!
//! This module is the *decoded net*: its storage, the checks and writes of
//! a decode into it, and its accessors. The bytes themselves — layout,
//! header, parser, CRC — are the *wire format*, [`crate::tnet`].
//!
//! # Storage
//! All weights live in one flat `[f32; W]`, packed like the file itself
//! (triangular, not one `1 + IN + MAX_HIDDEN` row per unit): hidden row `k`
//! holds exactly `1 + IN + k` weights `[bias, input 0 … input IN−1,
//! hidden 0 … hidden k−1]` at offset `k (1 + IN) + k (k − 1)/2`, and the
//! output rows of `1 + IN + H` weights (`H` = the net's hidden units) follow
//! the last hidden row. `IN` here is the *capacity*: a net with fewer inputs
//! has zero weights in the missing input columns, so every row lines up with
//! the inference's feature vector `[1, x̂_0 … x̂_{IN−1}, h_0, h_1, …]`.
//! [`weight_capacity`] adds [`ROW_PAD`] zero slots after the largest net so
//! that a dot product rounded up to a multiple of 8 never leaves the array.
//!
//! A 7-input, 64-hidden, 8-output net needs 3,111 `f32` (12.2 KiB) this way
//! instead of 5,184 (20.3 KiB) with rectangular rows.

use crate::tnet::{
    self, Activation, Field, NetHeader, NetShape, Run, TnetError, TnetView, Trailer,
};

mod sliced;
pub use sliced::CheckJob;

/// Zero slots after the last row: the inference rounds every row's dot
/// product up to a multiple of 8 terms, reading up to 7 entries past the row.
pub const ROW_PAD: usize = 7;

/// Offset of hidden row `k` for input capacity `inputs`: rows of
/// `1 + inputs + j` weights for `j < k` before it.
const fn hidden_offset(inputs: usize, k: usize) -> usize {
    k * (1 + inputs) + k * k.saturating_sub(1) / 2
}

/// Storage a net with `hidden` units and `outputs` outputs needs with input
/// capacity `inputs`: its hidden rows, its output rows and [`ROW_PAD`].
const fn weights_needed(inputs: usize, hidden: usize, outputs: usize) -> usize {
    hidden_offset(inputs, hidden) + outputs * (1 + inputs + hidden) + ROW_PAD
}

/// The `W` (weight capacity) that holds every net up to `inputs` inputs,
/// `max_hidden` hidden units and `outputs` outputs, padding included:
/// write `CascadeNet<7, 64, 8, { weight_capacity(7, 64, 8) }>`.
pub const fn weight_capacity(inputs: usize, max_hidden: usize, outputs: usize) -> usize {
    weights_needed(inputs, max_hidden, outputs)
}

/// One unit's incoming weights, borrowed from a net's packed storage.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Row<'a> {
    /// Weight of the constant +1 input.
    pub bias: f32,
    /// Weights of the normalised inputs, `IN` (the capacity) long; entries
    /// past the net's input count are 0.
    pub inputs: &'a [f32],
    /// Weights of the earlier hidden units: `k` long for hidden unit `k`,
    /// `shape().hidden` long for an output.
    pub hidden: &'a [f32],
}

impl<'a> Row<'a> {
    fn split<const IN: usize>(row: &'a [f32]) -> Row<'a> {
        let (bias, rest) = match row.split_first() {
            Some((b, rest)) => (*b, rest),
            None => (0.0, row),
        };
        let (inputs, hidden) = rest.split_at_checked(IN).unwrap_or((rest, &[]));
        Row {
            bias,
            inputs,
            hidden,
        }
    }
}

/// A cascade-correlation net decoded from a `.tnet` file into fixed-capacity
/// storage: up to `IN` inputs, `MAX_HIDDEN` hidden units and `OUT` outputs,
/// weights packed into `W` floats (see the [module docs](self); use
/// [`weight_capacity`] for `W`). No allocation; `size_of` is about
/// `4 (W + 2 IN + 2 OUT)` bytes, so pick capacities with the MCU's RAM in mind.
///
/// Every value in a non-empty net is finite and every range non-empty: the
/// decoder and [`CascadeNet::from_view`] guarantee it, and nothing else can
/// build one.
#[derive(Clone, Debug, PartialEq)]
pub struct CascadeNet<const IN: usize, const MAX_HIDDEN: usize, const OUT: usize, const W: usize> {
    shape: NetShape,
    hidden_activation: Activation,
    output_activation: Activation,
    input_lo: [f32; IN],
    input_hi: [f32; IN],
    output_lo: [f32; OUT],
    output_hi: [f32; OUT],
    weights: [f32; W],
}

impl<const IN: usize, const MAX_HIDDEN: usize, const OUT: usize, const W: usize> Default
    for CascadeNet<IN, MAX_HIDDEN, OUT, W>
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

/// `s[i]` without a panic path, usable in `const fn` (`<[T]>::get` is not).
const fn get(s: &[f32], i: usize) -> Option<f32> {
    match s.split_at_checked(i) {
        Some((_, [v, ..])) => Some(*v),
        _ => None,
    }
}

/// `s[i] = v` without a panic path, usable in `const fn`; whether `i` was
/// in bounds.
const fn set(s: &mut [f32], i: usize, v: f32) -> bool {
    match s.split_at_mut_checked(i) {
        Some((_, [slot, ..])) => {
            *slot = v;
            true
        }
        _ => false,
    }
}

/// Copy the first `n` normalisation ranges `src` into `dst`, refusing an
/// empty one (`hi <= lo`) as [`TnetError::EmptyRange`] of `field`; `const`
/// for [`CascadeNet::from_view`].
const fn copy_ranges(
    field: Field,
    src: (&[f32], &[f32]),
    n: usize,
    dst: (&mut [f32], &mut [f32]),
) -> Result<(), TnetError> {
    let mut i = 0;
    while i < n {
        let (Some(lo), Some(hi)) = (get(src.0, i), get(src.1, i)) else {
            return Err(TnetError::Malformed);
        };
        if hi <= lo {
            return Err(TnetError::EmptyRange { field, index: i });
        }
        if !(set(dst.0, i, lo) && set(dst.1, i, hi)) {
            return Err(TnetError::Malformed);
        }
        i += 1;
    }
    Ok(())
}

/// A `.tnet` byte string that passed [`CascadeNet::check`]: every check
/// the decoder makes, CRC included. Only `check` makes one (private fields),
/// so [`CascadeNet::decode_checked`] can write it without checking again.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Checked<'a> {
    bytes: &'a [u8],
    header: NetHeader,
}

impl Checked<'_> {
    /// What the file holds.
    pub fn header(&self) -> &NetHeader {
        &self.header
    }
}

/// Where a run of consecutive values read from the file goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Dest {
    InputLo,
    InputHi,
    OutputLo,
    OutputHi,
    /// The packed weight storage, from this index on.
    Weights(usize),
}

/// [`tnet::walk`] for a net of capacity `IN`, `H`, `OUT`, `W`: refuses a
/// shape over capacity as soon as the header is read, and hands the
/// visitor each run's place in the packed storage (a row's inputs occupy
/// `IN` columns there; the columns past the file's inputs stay 0).
fn walk<const IN: usize, const H: usize, const OUT: usize, const W: usize>(
    bytes: &[u8],
    trailer: Trailer,
    mut visit: impl FnMut(Field, usize, Dest, &[u8]),
) -> Result<NetHeader, TnetError> {
    let fits = |s: &NetShape| {
        let (ni, nh, no) = (s.inputs, s.hidden, s.outputs);
        if ni > IN || nh > H || no > OUT || weights_needed(IN, nh, no) > W {
            return Err(TnetError::ShapeOverCapacity {
                inputs: ni,
                hidden: nh,
                outputs: no,
                cap_inputs: IN,
                cap_hidden: H,
                cap_outputs: OUT,
            });
        }
        Ok(())
    };
    tnet::walk(bytes, trailer, fits, |field, at, run, values| {
        let dest = match run {
            Run::InputLo => Dest::InputLo,
            Run::InputHi => Dest::InputHi,
            Run::OutputLo => Dest::OutputLo,
            Run::OutputHi => Dest::OutputHi,
            Run::Row {
                unit,
                sees,
                cascade,
            } => {
                let start = match field {
                    Field::OutputWeights => hidden_offset(IN, sees) + unit * (1 + IN + sees),
                    _ => hidden_offset(IN, unit),
                };
                Dest::Weights(if cascade { start + 1 + IN } else { start })
            }
        };
        visit(field, at, dest, values)
    })
}

/// Store the byte run's `f32`s at the start of `dst` (as many as fit: the
/// capacity was checked before; this keeps the code panic-free); returns
/// whether every stored value is finite.
///
/// The finiteness test rides along for two reasons. It keeps the net's
/// invariant even if a borrowed receive buffer changed between the check
/// and the write (the hot swap checks and writes in different control
/// periods, docs/design.md §5.3). And it keeps the loop a loop of unaligned
/// word loads and stores, under 1 M4 instruction per byte whatever the
/// alignment: a plain copy loop becomes a `memcpy` call, whose path for a
/// misaligned source (a run of a `.tnet` starts at any byte offset) costs
/// about 5 per byte.
///
/// The finiteness test alone no longer keeps LLVM from it: after unrelated
/// changes elsewhere in the crate it split the loop into a `memcpy` and a
/// scan (measured: the hot swap's write slice went from 56,600 to 87,680
/// instructions, tests/tests/firmware_qemu.rs). Each stored word is XORed
/// with an opaque zero ([`core::hint::black_box`]), which no copy idiom
/// matches: one more instruction per word.
fn fill(dst: &mut [f32], bytes: &[u8]) -> bool {
    let mut special = 0u32;
    let opaque_zero = core::hint::black_box(0u32);
    for (d, c) in dst.iter_mut().zip(bytes.chunks_exact(4)) {
        let w = tnet::word(c);
        special |= u32::from(w & 0x7f80_0000 == 0x7f80_0000);
        *d = f32::from_bits(w ^ opaque_zero);
    }
    special == 0
}

impl<const IN: usize, const MAX_HIDDEN: usize, const OUT: usize, const W: usize>
    CascadeNet<IN, MAX_HIDDEN, OUT, W>
{
    /// A net with no inputs, no hidden units and no outputs; a placeholder for
    /// static storage (`const`, so it can initialise a `static`).
    pub const fn empty() -> Self {
        CascadeNet {
            shape: NetShape {
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
            weights: [0.0; W],
        }
    }

    /// Check a `.tnet` byte string completely — structure, capacity, CRC,
    /// finite values, non-empty ranges — without writing anything. Exactly
    /// the checks of [`CascadeNet::decode_into`], in the same order, so it
    /// returns the same error.
    pub fn validate(bytes: &[u8]) -> Result<NetHeader, TnetError> {
        Self::check(bytes).map(|c| c.header)
    }

    /// [`CascadeNet::validate`], keeping the bytes for
    /// [`CascadeNet::decode_checked`]: validate first, decide (e.g. whether
    /// the shape suits the robot), then write.
    pub fn check(bytes: &[u8]) -> Result<Checked<'_>, TnetError> {
        let mut lo_in = [0.0f32; IN];
        let mut hi_in = [0.0f32; IN];
        let mut lo_out = [0.0f32; OUT];
        let mut hi_out = [0.0f32; OUT];
        let mut first_bad: Option<TnetError> = None;
        let header =
            walk::<IN, MAX_HIDDEN, OUT, W>(bytes, Trailer::Crc, |field, at, dest, run| {
                if first_bad.is_none() {
                    if let Some(i) = tnet::first_non_finite(run) {
                        first_bad = Some(TnetError::NonFinite {
                            field,
                            index: at + i,
                        });
                    }
                }
                // Finiteness is judged above, in file order.
                let _finite = match dest {
                    Dest::InputLo => fill(&mut lo_in, run),
                    Dest::InputHi => fill(&mut hi_in, run),
                    Dest::OutputLo => fill(&mut lo_out, run),
                    Dest::OutputHi => fill(&mut hi_out, run),
                    Dest::Weights(_) => true,
                };
            })?;
        // Only now that the CRC vouches for the bytes, judge the values.
        if let Some(e) = first_bad {
            return Err(e);
        }
        let (ni, no) = (header.shape.inputs, header.shape.outputs);
        tnet::check_ranges(Field::InputLo, prefix(&lo_in, ni), prefix(&hi_in, ni))?;
        tnet::check_ranges(Field::OutputLo, prefix(&lo_out, no), prefix(&hi_out, no))?;
        Ok(Checked { bytes, header })
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

    /// Decode into `self`. The bytes are [validated](CascadeNet::validate)
    /// completely before the first write: on error `self` is untouched (still
    /// the net it was), on success it holds the new net.
    pub fn decode_into(&mut self, bytes: &[u8]) -> Result<(), TnetError> {
        let checked = Self::check(bytes)?;
        self.decode_checked(&checked)
    }

    /// Write a net that [`CascadeNet::check`] accepted into `self` (one
    /// parse, no second CRC or value check: the bytes are borrowed, so they
    /// are the ones that passed). Fails only if `checked` came from a type
    /// with a larger capacity than `self`'s ([`TnetError::ShapeOverCapacity`],
    /// `self` untouched).
    pub fn decode_checked(&mut self, checked: &Checked<'_>) -> Result<(), TnetError> {
        let (header, bytes) = (checked.header, checked.bytes);
        let s = header.shape;
        if s.inputs > IN || s.hidden > MAX_HIDDEN || s.outputs > OUT {
            return Err(TnetError::ShapeOverCapacity {
                inputs: s.inputs,
                hidden: s.hidden,
                outputs: s.outputs,
                cap_inputs: IN,
                cap_hidden: MAX_HIDDEN,
                cap_outputs: OUT,
            });
        }
        if weights_needed(IN, s.hidden, s.outputs) > W {
            return Err(TnetError::ShapeOverCapacity {
                inputs: s.inputs,
                hidden: s.hidden,
                outputs: s.outputs,
                cap_inputs: IN,
                cap_hidden: MAX_HIDDEN,
                cap_outputs: OUT,
            });
        }
        self.clear_for(s);
        let mut finite = true;
        let written = walk::<IN, MAX_HIDDEN, OUT, W>(bytes, Trailer::Assumed, |_, _, dest, run| {
            finite &= match dest {
                Dest::InputLo => fill(&mut self.input_lo, run),
                Dest::InputHi => fill(&mut self.input_hi, run),
                Dest::OutputLo => fill(&mut self.output_lo, run),
                Dest::OutputHi => fill(&mut self.output_hi, run),
                Dest::Weights(i) => fill(self.weights.get_mut(i..).unwrap_or(&mut []), run),
            }
        });
        // The checked bytes are borrowed, so they cannot have changed; a
        // receive buffer handed over through `unsafe` (the MCU's bus
        // driver) could, between the check and this write, which the hot
        // swap does in different control periods. Never let that break the
        // net's invariant (finite values, non-empty ranges).
        let (ni, no) = (header.shape.inputs, header.shape.outputs);
        let sound = finite
            && tnet::check_ranges(
                Field::InputLo,
                prefix(&self.input_lo, ni),
                prefix(&self.input_hi, ni),
            )
            .is_ok()
            && tnet::check_ranges(
                Field::OutputLo,
                prefix(&self.output_lo, no),
                prefix(&self.output_hi, no),
            )
            .is_ok();
        match written {
            Ok(_) if !sound => {
                self.clear();
                Err(TnetError::Malformed)
            }
            Ok(h) if h == header => {
                self.shape = header.shape;
                self.hidden_activation = header.hidden_activation;
                self.output_activation = header.output_activation;
                Ok(())
            }
            // Unreachable: the same bytes passed the same walk a moment
            // ago. Never leave a half-written net behind, though.
            Ok(_) => {
                self.clear();
                Err(TnetError::Malformed)
            }
            Err(e) => {
                self.clear();
                Err(e)
            }
        }
    }

    /// Make `self` [empty](CascadeNet::empty) in place (`*self = empty()`
    /// would build the whole net on the stack first: 12 KiB on the MCU).
    /// [`CascadeNet::clear`] for a decode of shape `s` that writes every
    /// weight slot of its rows: with all `IN` inputs present the rows are
    /// contiguous and the decode writes each of them, so only the slots
    /// after them (the row padding and the unused capacity) need zeros —
    /// zeroing all 12 KB first cost a hot swap's install slice ~3,800 of
    /// its instructions (tests/tests/mcu_budget.rs). With fewer inputs the
    /// rows have unused columns: everything is cleared.
    fn clear_for(&mut self, s: NetShape) {
        if s.inputs != IN {
            self.clear();
            return;
        }
        let rows_end = weights_needed(IN, s.hidden, s.outputs).saturating_sub(ROW_PAD);
        self.shape = NetShape {
            inputs: 0,
            hidden: 0,
            outputs: 0,
        };
        self.hidden_activation = Activation::Linear;
        self.output_activation = Activation::Linear;
        self.input_lo.fill(0.0);
        self.input_hi.fill(0.0);
        self.output_lo.fill(0.0);
        self.output_hi.fill(0.0);
        if let Some(tail) = self.weights.get_mut(rows_end..) {
            tail.fill(0.0);
        }
    }

    fn clear(&mut self) {
        self.shape = NetShape {
            inputs: 0,
            hidden: 0,
            outputs: 0,
        };
        self.hidden_activation = Activation::Linear;
        self.output_activation = Activation::Linear;
        self.input_lo.fill(0.0);
        self.input_hi.fill(0.0);
        self.output_lo.fill(0.0);
        self.output_hi.fill(0.0);
        self.weights.fill(0.0);
    }

    /// Build a net from a [`TnetView`] (the file's own layout) with the
    /// decoder's checks: non-empty shape, capacity, array lengths, finite
    /// values, non-empty ranges. `const`, so a build script can turn a
    /// `.tnet` into a `static` in flash that is checked at compile time:
    /// `static NET: N = match N::from_view(&VIEW) { Ok(n) => n, Err(_) => panic!("…") };`.
    pub const fn from_view(view: &TnetView<'_>) -> Result<Self, TnetError> {
        let s = view.shape;
        let (ni, nh, no) = (s.inputs, s.hidden, s.outputs);
        if ni == 0 || no == 0 {
            return Err(TnetError::EmptyShape {
                inputs: ni,
                outputs: no,
            });
        }
        if ni > IN || nh > MAX_HIDDEN || no > OUT || weights_needed(IN, nh, no) > W {
            return Err(TnetError::ShapeOverCapacity {
                inputs: ni,
                hidden: nh,
                outputs: no,
                cap_inputs: IN,
                cap_hidden: MAX_HIDDEN,
                cap_outputs: OUT,
            });
        }
        let arrays = [
            (Field::InputLo, view.input_lo, ni),
            (Field::InputHi, view.input_hi, ni),
            (Field::OutputLo, view.output_lo, no),
            (Field::OutputHi, view.output_hi, no),
            (
                Field::HiddenWeights,
                view.hidden_weights,
                s.hidden_weight_count(),
            ),
            (
                Field::OutputWeights,
                view.output_weights,
                s.output_weight_count(),
            ),
        ];
        let mut rest: &[(Field, &[f32], usize)] = &arrays;
        while let [(field, values, expected), tail @ ..] = rest {
            if values.len() != *expected {
                return Err(TnetError::LengthMismatch {
                    field: *field,
                    expected: *expected,
                    found: values.len(),
                });
            }
            let mut i = 0;
            let mut vs: &[f32] = values;
            while let [v, more @ ..] = vs {
                if !v.is_finite() {
                    return Err(TnetError::NonFinite {
                        field: *field,
                        index: i,
                    });
                }
                i += 1;
                vs = more;
            }
            rest = tail;
        }
        let mut net = Self::empty();
        if let Err(e) = copy_ranges(
            Field::InputLo,
            (view.input_lo, view.input_hi),
            ni,
            (&mut net.input_lo, &mut net.input_hi),
        ) {
            return Err(e);
        }
        if let Err(e) = copy_ranges(
            Field::OutputLo,
            (view.output_lo, view.output_hi),
            no,
            (&mut net.output_lo, &mut net.output_hi),
        ) {
            return Err(e);
        }
        // Every index below is in bounds (lengths were checked above and
        // `weights_needed(IN, nh, no) <= W`); `get`/`set` only keep the
        // code free of panic paths.
        let mut k = 0;
        while k < nh + no {
            let (src, file_at, start, hidden) = if k < nh {
                (
                    view.hidden_weights,
                    s.hidden_row_offset(k),
                    hidden_offset(IN, k),
                    k,
                )
            } else {
                let o = k - nh;
                let start = hidden_offset(IN, nh) + o * (1 + IN + nh);
                (view.output_weights, o * s.output_row_len(), start, nh)
            };
            let mut c = 0;
            while c < 1 + ni + hidden {
                let at = if c <= ni {
                    start + c
                } else {
                    start + IN + c - ni
                };
                let Some(w) = get(src, file_at + c) else {
                    return Err(TnetError::Malformed);
                };
                if !set(&mut net.weights, at, w) {
                    return Err(TnetError::Malformed);
                }
                c += 1;
            }
            k += 1;
        }
        net.shape = s;
        net.hidden_activation = view.hidden_activation;
        net.output_activation = view.output_activation;
        Ok(net)
    }

    /// Dimensions of the decoded net (all zero for an empty net).
    pub const fn shape(&self) -> NetShape {
        self.shape
    }

    /// `true` for the placeholder net that [`CascadeNet::empty`] makes.
    pub const fn is_empty(&self) -> bool {
        self.shape.outputs == 0
    }

    /// Activation of the hidden units.
    pub const fn hidden_activation(&self) -> Activation {
        self.hidden_activation
    }

    /// Activation of the outputs.
    pub const fn output_activation(&self) -> Activation {
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

    /// The whole packed weight storage ([module docs](self)): hidden rows,
    /// then output rows, then zeros. What the inference loop walks.
    pub const fn weights(&self) -> &[f32; W] {
        &self.weights
    }

    /// Offset of hidden row `k` in [`CascadeNet::weights`] (`1 + IN + k` long).
    pub const fn hidden_row_offset(k: usize) -> usize {
        hidden_offset(IN, k)
    }

    /// Offset of the first output row in [`CascadeNet::weights`]; output
    /// rows are `1 + IN + shape().hidden` long.
    pub const fn output_rows_offset(&self) -> usize {
        hidden_offset(IN, self.shape.hidden)
    }

    /// Hidden unit `k`'s weights `[bias, IN inputs, k hidden]`, if installed.
    pub fn hidden_row(&self, k: usize) -> Option<&[f32]> {
        if k >= self.shape.hidden {
            return None;
        }
        let start = hidden_offset(IN, k);
        self.weights.get(start..start + 1 + IN + k)
    }

    /// Output `o`'s weights `[bias, IN inputs, every hidden unit]`, if present.
    pub fn output_row(&self, o: usize) -> Option<&[f32]> {
        if o >= self.shape.outputs {
            return None;
        }
        let len = 1 + IN + self.shape.hidden;
        let start = self.output_rows_offset() + o * len;
        self.weights.get(start..start + len)
    }

    /// The installed hidden units in cascade order (`shape().hidden` of them).
    pub fn hidden_units(&self) -> impl ExactSizeIterator<Item = Row<'_>> + '_ {
        (0..self.shape.hidden).map(|k| Row::split::<IN>(self.hidden_row(k).unwrap_or(&[])))
    }

    /// The output units (`shape().outputs` of them).
    pub fn output_units(&self) -> impl ExactSizeIterator<Item = Row<'_>> + '_ {
        (0..self.shape.outputs).map(|o| Row::split::<IN>(self.output_row(o).unwrap_or(&[])))
    }
}
