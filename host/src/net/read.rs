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

/// Read and decode a `.tnet` file; errors name the file and the problem.
pub fn read_tnet(path: &Path) -> Result<Box<McuNet>, ReadError> {
    let bytes = std::fs::read(path).map_err(|cause| ReadError::Io {
        path: path.display().to_string(),
        cause,
    })?;
    decode(&bytes).map_err(|cause| ReadError::Format {
        path: path.display().to_string(),
        cause,
    })
}
