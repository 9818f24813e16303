//! Adding what is known only after a run (the report's summary) to its
//! MCAP file as metadata: the file is rewritten beside itself and renamed
//! over the original (the output policy, [`crate::fsutil`]), so a failure
//! leaves the original as it was.

use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::Path;

use mcap::read::Options;

use super::read::ReadError;

/// Write the MCAP at `source` to `path` with a metadata record `name` of
/// `values` added, keeping every message, channel, schema and other
/// metadata record (`source` may be `path` itself, or its `.partial`
/// name). A file cut short by a crash is rewritten whole up to its last
/// chunk.
pub fn add_metadata(
    source: &Path,
    path: &Path,
    name: &str,
    values: BTreeMap<String, String>,
) -> Result<(), ReadError> {
    let io = |source: std::io::Error| ReadError::Io {
        path: path.to_path_buf(),
        source,
    };
    let format = |e: mcap::McapError| ReadError::Format {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    let bytes = std::fs::read(source).map_err(|source_err| ReadError::Io {
        path: source.to_path_buf(),
        source: source_err,
    })?;
    // By the output policy: a temporary beside a regular file, renamed
    // over it; a device or FIFO written through.
    let tmp = crate::fsutil::Temporary::for_output(path).map_err(io)?;
    let file = tmp.as_file().try_clone().map_err(io)?;
    let result = (|| {
        let options = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .profile("")
            .library(concat!("tendril ", env!("CARGO_PKG_VERSION")));
        let mut out = options.create(BufWriter::new(file)).map_err(format)?;
        let lenient = enumset::enum_set!(Options::IgnoreEndMagic);
        let stream = mcap::MessageStream::new_with_options(&bytes, lenient).map_err(format)?;
        for message in stream {
            let Ok(message) = message else { break };
            out.write(&message).map_err(format)?;
        }
        let reader = mcap::read::LinearReader::new_with_options(&bytes, lenient).map_err(format)?;
        for record in reader {
            match record {
                Ok(mcap::records::Record::Metadata(m)) if m.name != name => {
                    out.write_metadata(&m).map_err(format)?;
                }
                Ok(_) => {}
                Err(_) => break,
            }
        }
        out.write_metadata(&mcap::records::Metadata {
            name: name.to_string(),
            metadata: values,
        })
        .map_err(format)?;
        out.finish().map_err(format)?;
        let file = out
            .into_inner()
            .into_inner()
            .map_err(|e| io(e.into_error()))?;
        file.sync_all().map_err(io)?;
        Ok(())
    })();
    result?;
    tmp.persist(path).map_err(io)
}
