//! Reading a run log back: every message by topic, tolerant of a file cut
//! short by a crash (what was written up to its last whole chunk).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use mcap::read::{LinearReader, Options};
use mcap::records::Record;

use super::channels::{self as ch, StatusMsg, TensionsMsg, TrackingMsg};

/// What can go wrong reading a run log.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Not an MCAP file, or nothing readable in it.
    #[error("{path}: not a readable MCAP file: {message}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What the reader said.
        message: String,
    },
    /// A message on a tendril channel does not decode.
    #[error("{path}: {topic} message {index}: {message}")]
    Message {
        /// The file.
        path: PathBuf,
        /// Its topic.
        topic: String,
        /// Its index on that topic.
        index: usize,
        /// The decoder's message.
        message: String,
    },
}

/// One message as stored.
#[derive(Clone, Debug)]
pub struct Stored {
    /// Log time, ns.
    pub log_time: u64,
    /// Its bytes.
    pub data: Vec<u8>,
}

/// A run log read into memory.
#[derive(Clone, Debug, Default)]
pub struct RunLogFile {
    /// The file.
    pub path: PathBuf,
    /// Messages per topic, in file order.
    pub topics: BTreeMap<String, Vec<Stored>>,
    /// Schema name and encoding per topic.
    pub schemas: BTreeMap<String, (String, String)>,
    /// Metadata records by name.
    pub metadata: BTreeMap<String, BTreeMap<String, String>>,
    /// The file ended before its footer (a crashed writer): what is here
    /// is everything up to the last whole chunk.
    pub truncated: bool,
}

impl RunLogFile {
    /// Read `path`'s messages on `topics` only (and its schemas and
    /// metadata), streaming the file: a long run's log is mostly 3-D scenes,
    /// and a figure needs none of them (a 410 MB log took 980 MB to plot
    /// when read whole). A file cut short ends at its last whole record.
    pub fn open_topics(path: &Path, topics: &[&str]) -> Result<RunLogFile, ReadError> {
        use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};
        use std::io::Read;
        let io = |source: std::io::Error| ReadError::Io {
            path: path.to_path_buf(),
            source,
        };
        let meta = std::fs::metadata(path).map_err(io)?;
        if !meta.is_file() {
            return Err(io(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "not a regular file (a run log is an .mcap file)",
            )));
        }
        let mut file = std::fs::File::open(path).map_err(io)?;
        let options = LinearReaderOptions::default().with_skip_end_magic(true);
        let mut reader = LinearReader::new_with_options(options);
        let mut out = RunLogFile {
            path: path.to_path_buf(),
            ..RunLogFile::default()
        };
        let mut schemas: BTreeMap<u16, (String, String)> = BTreeMap::new();
        let mut channels: BTreeMap<u16, String> = BTreeMap::new();
        let (mut complete, mut any) = (false, false);
        while let Some(event) = reader.next_event() {
            let Ok(event) = event else { break };
            match event {
                LinearReadEvent::ReadRequest(need) => {
                    let n = file.read(reader.insert(need)).map_err(io)?;
                    reader.notify_read(n);
                }
                LinearReadEvent::Record { opcode, data } => {
                    let Ok(record) = mcap::parse_record(opcode, data) else {
                        break;
                    };
                    any = true;
                    match record {
                        Record::Footer(_) => complete = true,
                        Record::Message { ref header, .. } => {
                            let wanted = (channels.get(&header.channel_id))
                                .is_some_and(|t| topics.contains(&t.as_str()));
                            if wanted {
                                out.take(record, &mut schemas, &mut channels);
                            }
                        }
                        other => out.take(other, &mut schemas, &mut channels),
                    }
                }
            }
        }
        if !any {
            return Err(ReadError::Format {
                path: path.to_path_buf(),
                message: "no records".into(),
            });
        }
        out.truncated = !complete;
        Ok(out)
    }

    /// Read `path` whole.
    pub fn open(path: &Path) -> Result<RunLogFile, ReadError> {
        let bytes = std::fs::read(path).map_err(|source| ReadError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_bytes(path, &bytes)
    }

    /// Read an MCAP already in memory (`path` names it in errors).
    pub fn from_bytes(path: &Path, bytes: &[u8]) -> Result<RunLogFile, ReadError> {
        let format = |message: String| ReadError::Format {
            path: path.to_path_buf(),
            message,
        };
        let mut out = RunLogFile {
            path: path.to_path_buf(),
            ..RunLogFile::default()
        };
        let options = enumset::enum_set!(Options::IgnoreEndMagic);
        let reader =
            LinearReader::new_with_options(bytes, options).map_err(|e| format(e.to_string()))?;
        let mut schemas: BTreeMap<u16, (String, String)> = BTreeMap::new();
        let mut channels: BTreeMap<u16, String> = BTreeMap::new();
        let mut complete = false;
        let mut any = false;
        for record in reader {
            let Ok(record) = record else {
                break;
            };
            any = true;
            match record {
                Record::Chunk { header, data } => {
                    let Ok(chunk) = mcap::read::ChunkReader::new(header, &data) else {
                        break;
                    };
                    for inner in chunk {
                        let Ok(inner) = inner else { break };
                        out.take(inner, &mut schemas, &mut channels);
                    }
                }
                Record::Footer(_) => complete = true,
                other => out.take(other, &mut schemas, &mut channels),
            }
        }
        if !any {
            return Err(format("no records".into()));
        }
        out.truncated = !complete;
        Ok(out)
    }

    fn take(
        &mut self,
        record: Record<'_>,
        schemas: &mut BTreeMap<u16, (String, String)>,
        channels: &mut BTreeMap<u16, String>,
    ) {
        match record {
            Record::Schema { header, .. } => {
                schemas.insert(header.id, (header.name, header.encoding));
            }
            Record::Channel(c) => {
                if let Some(s) = schemas.get(&c.schema_id) {
                    self.schemas.insert(c.topic.clone(), s.clone());
                }
                self.topics.entry(c.topic.clone()).or_default();
                channels.insert(c.id, c.topic);
            }
            Record::Message { header, data } => {
                if let Some(topic) = channels.get(&header.channel_id) {
                    self.topics.entry(topic.clone()).or_default().push(Stored {
                        log_time: header.log_time,
                        data: data.into_owned(),
                    });
                }
            }
            Record::Metadata(m) => {
                self.metadata.insert(m.name, m.metadata);
            }
            _ => {}
        }
    }

    /// Messages on `topic` (none when it is absent).
    pub fn messages(&self, topic: &str) -> &[Stored] {
        self.topics.get(topic).map_or(&[], Vec::as_slice)
    }

    fn json<T: serde::de::DeserializeOwned>(
        &self,
        topic: &str,
    ) -> Result<Vec<(u64, T)>, ReadError> {
        self.messages(topic)
            .iter()
            .enumerate()
            .map(|(index, m)| {
                serde_json::from_slice(&m.data)
                    .map(|v| (m.log_time, v))
                    .map_err(|e| ReadError::Message {
                        path: self.path.clone(),
                        topic: topic.into(),
                        index,
                        message: e.to_string(),
                    })
            })
            .collect()
    }

    /// The `/tensions` messages with their times.
    pub fn tensions(&self) -> Result<Vec<(u64, TensionsMsg)>, ReadError> {
        self.json(ch::TENSIONS)
    }

    /// The `/tracking` messages with their times.
    pub fn tracking(&self) -> Result<Vec<(u64, TrackingMsg)>, ReadError> {
        self.json(ch::TRACKING)
    }

    /// The `/status` messages with their times.
    pub fn status(&self) -> Result<Vec<(u64, StatusMsg)>, ReadError> {
        self.json(ch::STATUS)
    }

    /// The `/robot/scene` messages, decoded.
    pub fn scenes(&self) -> Result<Vec<(u64, foxglove::messages::SceneUpdate)>, ReadError> {
        use foxglove::Decode;
        self.messages(ch::SCENE)
            .iter()
            .enumerate()
            .map(|(index, m)| {
                foxglove::messages::SceneUpdate::decode(m.data.as_slice())
                    .map(|v| (m.log_time, v))
                    .map_err(|e| ReadError::Message {
                        path: self.path.clone(),
                        topic: ch::SCENE.into(),
                        index,
                        message: e.to_string(),
                    })
            })
            .collect()
    }
}
