//! The one process skeleton (`docs/design.md` §6, in the shape of a
//! `copper-rs` task): a tendril process is configured once, then runs one
//! step after another until it is told to stop, its time is up or its
//! peers fall silent. What every process does around its steps is written
//! here, once: tie the process to its launcher, open its iceoryx2 node and
//! the loop's services, watch for a stop, keep the CSV log flowing, apply
//! the stop / duration / peers-lost rules, close the log and write the
//! statistics JSON. The controller (host period), the bridge (the chip's
//! period over the link), the plant and the planner are [`Task`]s on it;
//! each owns only its ports and its step.

use std::path::Path;

use serde::Serialize;

use super::stats::CsvLog;
use super::transport::{self, Services};
use super::{IpcError, PeerWatch, StopWatch};

/// How often the skeleton hands the log's rows to its writer thread, ns.
const LOG_FLUSH_NS: u64 = 100_000_000;

/// What the skeleton needs to know of a process: its configuration's
/// common part, borrowed from the task's own configuration.
#[derive(Clone, Copy, Debug)]
pub struct Process<'a> {
    /// Who it is: its node is `tendril-{name}` and its messages begin
    /// `{name}:`.
    pub name: &'static str,
    /// Service-name prefix of the loop it joins.
    pub prefix: &'a str,
    /// Die with the launching process ([`super::die_with_parent`]).
    pub supervised: bool,
    /// Stop after this many seconds of its own time (None: until told).
    pub duration_s: Option<f64>,
    /// Stop with [`IpcError::PeersLost`] after this long without hearing a
    /// peer, s (None: never).
    pub peer_timeout_s: Option<f64>,
    /// How long the peers may take to appear, s ([`PeerWatch::new`]).
    pub peer_start_grace_s: Option<f64>,
    /// Its CSV log (None: none).
    pub log: Option<&'a Path>,
    /// Where its statistics JSON goes at exit (None: nowhere).
    pub stats: Option<&'a Path>,
    /// Scheduling applied once set up (None: the task runs none of its
    /// own hot loop on this CPU — the bridge, whose period is the chip's).
    pub scheduling: Option<Scheduling>,
}

/// A process's CPU and priority ([`super::clock::apply_scheduling`]).
#[derive(Clone, Copy, Debug)]
pub struct Scheduling {
    /// Pin to this CPU.
    pub cpu: Option<usize>,
    /// Try `SCHED_FIFO` at `priority`.
    pub realtime: bool,
    /// Its `SCHED_FIFO` priority.
    pub priority: i32,
}

/// What one step tells the skeleton.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Stepped {
    /// The step's time on the monotonic clock, ns: the duration and the
    /// peers' silence count from it.
    pub t_ns: u64,
    /// Whether a peer was heard in this step.
    pub heard: bool,
}

/// A process's own work: opened by [`run`]'s `open`, then stepped.
pub trait Task: Sized {
    /// What it reports at exit (the statistics JSON).
    type Stats: Serialize;
    /// The column names of its CSV log.
    fn log_header(&self) -> String;
    /// Its time zero on the monotonic clock, ns (its first deadline).
    fn start_ns(&self) -> u64;
    /// Wait for the next step, run it and log its row.
    fn step(&mut self, log: &mut CsvLog) -> Result<Stepped, IpcError>;
    /// What its peers' silence means, for the peers-lost error ("no
    /// tension command").
    fn silence(&self) -> &'static str;
    /// The run is over (its log closed): release what it holds and say
    /// what it did. `outcome` is how the loop ended.
    fn finish(self, outcome: &Result<(), IpcError>) -> Result<Self::Stats, IpcError>;
}

/// Run a process: tie it to its launcher, `load` what it checks before it
/// touches shared memory, open the node and the loop's services, `open`
/// the task on them, then step it until a stop, the duration or lost peers.
/// The log is closed, the task finished and its statistics written however
/// the loop ended; the first error is returned (a second one is added to
/// its message, not lost).
pub fn run<L, T: Task>(
    process: &Process<'_>,
    load: impl FnOnce() -> Result<L, IpcError>,
    open: impl FnOnce(L, &Services) -> Result<T, IpcError>,
) -> Result<T::Stats, IpcError> {
    super::die_with_parent(process.supervised)?;
    let loaded = load()?;
    let node = transport::node(&format!("tendril-{}", process.name))?;
    let _orphan = transport::ReleaseIfOrphaned(&node);
    let services = Services::open_or_create(&node, process.prefix)?;
    let stop = StopWatch::new(&services)?;
    let mut task = open(loaded, &services)?;
    let mut log = CsvLog::create(process.log, &task.log_header())?;
    if let Some(s) = process.scheduling {
        super::clock::tighten_timer_slack();
        super::clock::apply_scheduling(process.name, s.cpu, s.realtime, s.priority);
    }
    let start = task.start_ns();
    let mut peers = PeerWatch::new(process.peer_timeout_s, process.peer_start_grace_s, start);
    let mut last_flush = start;
    let outcome = loop {
        let step = match task.step(&mut log) {
            Ok(step) => step,
            Err(e) => break Err(e),
        };
        let t = step.t_ns;
        if t.saturating_sub(last_flush) > LOG_FLUSH_NS {
            if let Err(e) = log.flush() {
                break Err(e);
            }
            last_flush = t;
        }
        let elapsed_s = t.saturating_sub(start) as f64 * 1e-9;
        if stop.requested() || process.duration_s.is_some_and(|d| elapsed_s >= d) {
            break Ok(());
        }
        if step.heard {
            peers.heard(t);
        } else if peers.lost(t) {
            break Err(IpcError::PeersLost(format!(
                "{}: {} for {:.1} s",
                process.name,
                task.silence(),
                peers.silence_s(t)
            )));
        }
    };
    let outcome = outcome.and(log.close());
    let finished = task.finish(&outcome);
    let written = match (&finished, process.stats) {
        (Ok(stats), Some(path)) => serde_json::to_vec_pretty(stats)
            .map_err(|e| IpcError::Other(e.to_string()))
            .and_then(|json| super::write_file(path, &json)),
        _ => Ok(()),
    };
    match (outcome, finished, written) {
        (Ok(()), Ok(stats), Ok(())) => Ok(stats),
        (Err(first), Ok(_), Ok(())) => Err(first),
        (Err(first), Err(second), _) | (Err(first), _, Err(second)) => Err(also(first, &second)),
        (Ok(()), Err(e), _) | (Ok(()), Ok(_), Err(e)) => Err(e),
    }
}

/// `first` with `second` added to its message, of `first`'s kind (a lost
/// peer stays a lost peer: the launcher tells the two apart).
fn also(first: IpcError, second: &IpcError) -> IpcError {
    match first {
        IpcError::PeersLost(why) => IpcError::PeersLost(format!("{why}; and {second}")),
        first => IpcError::Other(format!("{first}; and {second}")),
    }
}

#[cfg(test)]
mod tests;
