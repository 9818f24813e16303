//! Run library work with the GIL released, and still honour Ctrl-C.
//!
//! Python handles a signal only when its main thread runs bytecode, which it
//! does not while Rust solves. So the work runs on a scoped thread, and the
//! calling thread waits for it, taking the GIL back briefly every
//! [`POLL`] to let Python check for signals. A pending `KeyboardInterrupt`
//! sets the stop flag the library's batch loops poll; their work is thrown
//! away and nothing is written (docs/design.md §8).

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use pyo3::prelude::*;

/// How often a waiting call looks for a pending signal.
const POLL: Duration = Duration::from_millis(50);

/// Run `work(stop)` with the GIL released. Returns its result, or the
/// signal's exception (`KeyboardInterrupt`) when one arrived meanwhile.
pub fn detached<T, F>(py: Python<'_>, work: F) -> PyResult<T>
where
    T: Send,
    F: FnOnce(&AtomicBool) -> T + Send,
{
    let stop = &AtomicBool::new(false);
    let (result, signal) = py.detach(|| {
        std::thread::scope(|scope| {
            let waiter = std::thread::current();
            let worker = scope.spawn(move || {
                let out = work(stop);
                waiter.unpark();
                out
            });
            let mut signal = None;
            while !worker.is_finished() {
                std::thread::park_timeout(POLL);
                if signal.is_none() && !worker.is_finished() {
                    if let Err(e) = Python::attach(|py| py.check_signals()) {
                        stop.store(true, Ordering::Relaxed);
                        signal = Some(e);
                    }
                }
            }
            let result = match worker.join() {
                Ok(out) => out,
                Err(panic) => std::panic::resume_unwind(panic),
            };
            (result, signal)
        })
    });
    match signal {
        Some(e) => Err(e),
        None => Ok(result),
    }
}
