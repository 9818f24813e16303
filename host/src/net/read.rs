//! Reading a `.tnet` weight file (`docs/design.md` §5.1) into the
//! firmware's fixed-capacity net, through the `tendril-shared` decoder the
//! MCU uses: every check of the format (magic, version, capacity, CRC,
//! finite values, non-empty ranges) is the MCU's own.

use std::path::Path;

use tendril_shared::{McuNet, TnetError};

/// Why a `.tnet` file could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The format rejected the bytes.
    // The cause is part of the message and deliberately not a `source`:
    // error chains printed with `{:#}` would repeat it.
    #[error("{path}: {cause}")]
    Format {
        /// The file concerned.
        path: String,
        /// What the format says.
        cause: TnetError,
    },
    /// Reading the file failed.
    #[error("{path}: {cause}")]
    Io {
        /// The file concerned.
        path: String,
        /// The I/O error.
        cause: std::io::Error,
    },
}

/// Decode `.tnet` bytes into the firmware's fixed-capacity net (boxed: ~12 KiB).
pub fn decode(bytes: &[u8]) -> Result<Box<McuNet>, TnetError> {
    let mut net = Box::<McuNet>::default();
    net.decode_into(bytes)?;
    Ok(net)
}

/// Largest `.tnet` file read, bytes: the largest net the capacity holds is
/// 12.6 KiB; anything near this is not a net (and `/dev/zero` is refused as
/// not a regular file, never read until memory runs out).
pub const MAX_TNET_BYTES: u64 = 1 << 20;

/// A `.tnet` file's bytes, refusing what cannot be one ([`MAX_TNET_BYTES`],
/// not a regular file).
pub fn read_tnet_bytes(path: &Path) -> Result<Vec<u8>, ReadError> {
    crate::fsutil::read_capped(path, MAX_TNET_BYTES).map_err(|cause| ReadError::Io {
        path: path.display().to_string(),
        cause,
    })
}

/// Read and decode a `.tnet` file; errors name the file and the problem.
pub fn read_tnet(path: &Path) -> Result<Box<McuNet>, ReadError> {
    let bytes = read_tnet_bytes(path)?;
    decode(&bytes).map_err(|cause| ReadError::Format {
        path: path.display().to_string(),
        cause,
    })
}
