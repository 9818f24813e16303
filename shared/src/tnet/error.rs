//! Everything that can be wrong with a `.tnet` byte string or with a net
//! handed to the encoder, and which array of the file it was found in.

use core::fmt;

use super::{VERSION, VERSION_1};

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
    #[error(
        "unsupported .tnet version {found} (this build reads versions {VERSION_1} and {VERSION})"
    )]
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
    /// A version-2 provenance block with unknown flags, a name that is not
    /// UTF-8 or a test fraction outside (0, 1).
    #[error("weight file's provenance block (robot and split) is malformed")]
    BadProvenance,
    /// The encoder's output buffer is too small.
    #[error("output buffer holds {available} bytes, the encoded net needs {needed}")]
    BufferTooSmall {
        /// Bytes needed ([`encoded_len`]).
        needed: usize,
        /// Bytes available.
        available: usize,
    },
}
