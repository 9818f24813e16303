//! Run library work with the GIL released, and still honour Ctrl-C.
//!
//! Python handles a signal only when its main thread runs bytecode, which it
//! does not while Rust solves. So the work runs on a scoped thread, and the
//! calling thread waits for it, taking the GIL back briefly every
//! [`POLL`] to let Python check for signals. A pending `KeyboardInterrupt`
//! sets the stop flag the library's batch loops poll; their work is thrown
//! away and nothing is written (docs/design.md §8).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, RecvTimeoutError};
use std::time::Duration;

use pyo3::prelude::*;

/// How often a waiting call looks for a pending signal.
const POLL: Duration = Duration::from_millis(50);

/// Run `work(stop)` with the GIL released. Returns its result, or the
/// signal's exception (`KeyboardInterrupt`) when one arrived meanwhile.
///
/// The result comes back over a channel, so the caller wakes the moment it
/// is sent. (Waiting on the worker's `is_finished` after an unpark raced
/// with the thread's own exit and slept a whole [`POLL`]: a one-row `fk`
/// took 50 ms instead of a fraction of one.)
pub fn detached<T, F>(py: Python<'_>, work: F) -> PyResult<T>
where
    T: Send,
    F: FnOnce(&AtomicBool) -> T + Send,
{
    let stop = &AtomicBool::new(false);
    let (result, signal) = py.detach(|| {
        std::thread::scope(|scope| {
            let (sender, receiver) = mpsc::sync_channel(1);
            let worker = scope.spawn(move || {
                // The receiver outlives the worker inside this scope.
                let _ = sender.send(work(stop));
            });
            let mut signal = None;
            let result = loop {
                match receiver.recv_timeout(POLL) {
                    Ok(out) => break out,
                    Err(RecvTimeoutError::Timeout) => {
                        if signal.is_none() {
                            if let Err(e) = Python::attach(|py| py.check_signals()) {
                                stop.store(true, Ordering::Relaxed);
                                signal = Some(e);
                            }
                        }
                    }
                    // The worker dropped its sender without sending: it panicked.
                    Err(RecvTimeoutError::Disconnected) => match worker.join() {
                        Err(panic) => std::panic::resume_unwind(panic),
                        Ok(()) => unreachable!("a worker that returns has sent its result"),
                    },
                }
            };
            (result, signal)
        })
    });
    match signal {
        Some(e) => Err(e),
        None => Ok(result),
    }
}
