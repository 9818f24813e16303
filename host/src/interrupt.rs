//! Ctrl-C, SIGTERM and SIGHUP as a request to stop: the first one sets a
//! flag that long jobs check between work units (training units, dataset
//! chunks), so they stop without writing anything half-done, their
//! temporary files are dropped, and the binary exits 130. A second signal
//! exits at once after removing the temporaries still open; every output is
//! written atomically ([`crate::fsutil`]), so even that leaves no partial
//! file, and the main job's staging directory is removed with the
//! temporaries (`docs/design.md` §7).
//!
//! The `ctrlc` crate (with its `termination` feature) runs one handler for
//! all three signals and does not say which arrived, so the exit status is
//! 130 (128 + SIGINT) for each of them.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Once;

/// Exit status of a command stopped by Ctrl-C, SIGTERM or SIGHUP (128 +
/// SIGINT, as shells report Ctrl-C; the handler cannot tell the signals apart).
pub const EXIT_INTERRUPTED: u8 = 130;

static STOP: AtomicBool = AtomicBool::new(false);
static HANDLER: Once = Once::new();

/// The stop flag, set by the first Ctrl-C, SIGTERM or SIGHUP. Installs the handler on first use;
/// if a handler is already installed (a library user's), theirs is kept and
/// the flag is only ever set by [`request_stop`].
pub fn stop_flag() -> &'static AtomicBool {
    HANDLER.call_once(|| {
        let _ = ctrlc::set_handler(|| {
            // A run moving its finished outputs into place
            // (`fsutil::Publishing`) ends by itself in milliseconds; exiting
            // half-way would mix two runs' files.
            if STOP.swap(true, Ordering::SeqCst) && !crate::fsutil::Publishing::active() {
                crate::fsutil::remove_temporaries();
                std::process::exit(i32::from(EXIT_INTERRUPTED));
            }
            eprintln!("\ninterrupted: stopping; existing outputs are left as they were");
        });
    });
    &STOP
}

/// Ask running jobs to stop, as Ctrl-C does.
pub fn request_stop() {
    STOP.store(true, Ordering::SeqCst);
}

/// Whether a stop was requested (by Ctrl-C or [`request_stop`]).
pub fn stop_requested() -> bool {
    STOP.load(Ordering::SeqCst)
}
