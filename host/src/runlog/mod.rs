//! Run logs for the robotics tools people already use (docs/design.md §12).
//!
//! A closed-loop run leaves `run.mcap` beside its `report.json`: the rod's
//! shape as a Foxglove 3-D scene, the tip frames, the commanded and
//! measured tensions, the tracking error, the status bits and the faults,
//! on the loop's clock, with the report's summary as metadata. The same
//! channels can be served live over the Foxglove WebSocket protocol. The
//! plant writes it ([`RunLog`], a thread behind a queue): it has the rod's
//! true shape, and the controller never waits on it.
//!
//! Built on the Foxglove SDK (`foxglove`: the well-known schemas, the MCAP
//! sink, the WebSocket server) and read back with the `mcap` crate
//! ([`read`]), which is also what `tendril plot run.mcap` uses.

pub mod channels;
mod config;
pub mod figure;
pub mod finalize;
pub mod read;
pub mod writer;

pub use read::RunLogFile;
pub use writer::{RunLog, RunLogConfig, RunLogStats, SceneRecord, StepRecord};
