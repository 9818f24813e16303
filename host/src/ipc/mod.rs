//! The closed loop as separate OS processes over iceoryx2 shared memory
//! (`DESIGN.md` §6): planner → `setpoint` → controller → `tension_cmd` →
//! plant → `plant_state` → controller and planner, plus `weights` (hot swap)
//! and `control` (stop). `sim` launches the three and writes a report.
//!
//! Each process is a library function taking a config struct, so the CLI
//! files stay thin and tests can reason about the same code.

pub mod clock;
pub mod controller;
pub mod correction;
pub mod fixture;
pub mod planner;
pub mod plant;
pub mod sim;
pub mod stats;
pub mod trajectory;
pub mod transport;

use iceoryx2_bb_posix::signal::SignalHandler;
use tendril_shared::messages::{control_command, Control};

pub use transport::DEFAULT_PREFIX;

/// What can go wrong in the IPC processes.
#[derive(Debug, thiserror::Error)]
pub enum IpcError {
    /// A service or node name is not acceptable to iceoryx2.
    #[error("bad name: {0}")]
    BadName(String),
    /// A service could not be created or opened.
    #[error("iceoryx2 service: {0}")]
    Service(String),
    /// A port (publisher, subscriber, notifier, listener) could not be created.
    #[error("iceoryx2 port: {0}")]
    Port(String),
    /// Publishing failed.
    #[error("iceoryx2 send: {0}")]
    Send(String),
    /// Receiving failed.
    #[error("iceoryx2 receive: {0}")]
    Receive(String),
    /// Bad configuration (argument values).
    #[error("{0}")]
    Config(String),
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Anything from the layers below (robot file, statics, model file).
    #[error("{0}")]
    Other(String),
}

/// Why a process should stop: a `STOP` on the control service (the
/// launcher's clean shutdown) or SIGTERM/SIGINT.
pub struct StopWatch {
    control: transport::Sub<Control>,
}

impl StopWatch {
    /// Watch the control service of `services`.
    pub fn new(services: &transport::Services) -> Result<StopWatch, IpcError> {
        Ok(StopWatch {
            control: transport::subscriber(&services.control)?,
        })
    }

    /// Whether a stop was requested since the last call (cheap: one
    /// shared-memory poll and an atomic read).
    pub fn requested(&self) -> bool {
        if SignalHandler::termination_requested() {
            return true;
        }
        let mut stop = false;
        while let Ok(Some(sample)) = self.control.receive() {
            if sample.payload().0.command == control_command::STOP {
                stop = true;
            }
        }
        stop
    }
}

/// Write `bytes` to `path` atomically, mapping the error.
pub(crate) fn write_file(path: &std::path::Path, bytes: &[u8]) -> Result<(), IpcError> {
    crate::fsutil::write_atomic(path, bytes)
        .map_err(|e| IpcError::Other(format!("{}: {e}", path.display())))
}
