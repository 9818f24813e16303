//! Ctrl-C, SIGTERM and SIGHUP as a request to stop — the one signal
//! mechanism of every tendril process (`docs/design.md` §7). The binary
//! calls [`install`] once, first thing; the library only reads the flag
//! ([`stop_requested`], [`stop_flag`]), so a library user (the Python
//! package) keeps its own handling.
//!
//! The first signal sets the flag, which long jobs check between work units
//! (training units, dataset chunks) and every process loop checks each
//! period: they stop without writing anything half-done, their temporary
//! files are dropped, and the binary exits [`EXIT_INTERRUPTED`] naming the
//! signal. A second signal exits at once after removing the temporaries
//! still open — unless a finished run is being moved into place
//! ([`crate::fsutil::Publishing`]), which takes milliseconds and would mix
//! two runs if cut (both through [`ExitHooks`]). Every output is written atomically ([`crate::fsutil`]),
//! so even that leaves no partial file.
//!
//! signal-hook delivers the signals to an ordinary thread (its self-pipe
//! iterator), so what happens on a signal — printing, removing files — is
//! plain code, not a signal handler's async-signal-safe subset. iceoryx2's
//! own handler is switched off on every node
//! ([`crate::ipc::transport::node`]): two handlers for one signal would
//! each see only some of them.

use std::sync::atomic::{AtomicBool, AtomicI32, Ordering};
use std::sync::Once;

use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};

/// Exit status of a command stopped by Ctrl-C, SIGTERM or SIGHUP: 128 +
/// SIGINT, as shells report Ctrl-C, for each of them (scripts test one
/// number); the message names the signal that came.
pub const EXIT_INTERRUPTED: u8 = 130;

static STOP: AtomicBool = AtomicBool::new(false);
/// The first signal that asked to stop (0: none, or [`request_stop`]).
static SIGNAL: AtomicI32 = AtomicI32::new(0);
static INSTALLED: Once = Once::new();

/// What a second signal does before the forced exit, given by the caller
/// (the output policy's, [`crate::fsutil::exit_hooks`]): this module sits
/// below every other and uses none.
#[derive(Clone, Copy, Debug)]
pub struct ExitHooks {
    /// Remove the temporary files still open.
    pub cleanup: fn(),
    /// Whether a finished run is being moved into place right now: then
    /// the second signal waits for it.
    pub deferring: fn() -> bool,
}

/// Route SIGINT, SIGTERM and SIGHUP to the stop flag (idempotent). With
/// `hooks` (a command someone runs), the first signal prints one line
/// saying the command is stopping and a second forces the exit; without
/// (a process a sim supervises), every signal only asks to stop: its
/// launcher speaks for it, and a forced exit would skip the clean-up of
/// its shared memory (a launcher's death can signal a child more than
/// once: the kernel sends the parent-death signal once per thread that
/// carries it).
pub fn install(hooks: Option<ExitHooks>) -> std::io::Result<()> {
    let mut result = Ok(());
    INSTALLED.call_once(|| {
        result = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP]).and_then(
            |mut signals| {
                std::thread::Builder::new()
                    .name("tendril-signals".into())
                    .spawn(move || {
                        for signal in signals.forever() {
                            on_signal(signal, hooks);
                        }
                    })
                    .map(drop)
            },
        );
    });
    result
}

fn on_signal(signal: i32, hooks: Option<ExitHooks>) {
    let _ = SIGNAL.compare_exchange(0, signal, Ordering::SeqCst, Ordering::SeqCst);
    let again = STOP.swap(true, Ordering::SeqCst);
    let Some(hooks) = hooks else { return };
    if again {
        if !(hooks.deferring)() {
            (hooks.cleanup)();
            std::process::exit(i32::from(EXIT_INTERRUPTED));
        }
        return;
    }
    {
        eprintln!(
            "\n{}: stopping; existing outputs are left as they were",
            signal_name(signal)
        );
    }
}

/// `SIGINT (Ctrl-C)`, `SIGTERM`, `SIGHUP` — how messages name a signal.
pub fn signal_name(signal: i32) -> &'static str {
    match signal {
        SIGINT => "SIGINT (Ctrl-C)",
        SIGTERM => "SIGTERM",
        SIGHUP => "SIGHUP",
        _ => "a signal",
    }
}

/// The signal that stopped this process, named; `None` when none came
/// (also when [`request_stop`] asked).
pub fn stopped_by() -> Option<&'static str> {
    match SIGNAL.load(Ordering::SeqCst) {
        0 => None,
        s => Some(signal_name(s)),
    }
}

/// The stop flag, for jobs that poll it between work units. Set by the
/// first signal once [`install`]ed, or by [`request_stop`].
pub fn stop_flag() -> &'static AtomicBool {
    &STOP
}

/// Ask running jobs to stop, as Ctrl-C does.
pub fn request_stop() {
    STOP.store(true, Ordering::SeqCst);
}

/// Whether a stop was requested (by a signal or [`request_stop`]).
pub fn stop_requested() -> bool {
    STOP.load(Ordering::SeqCst)
}
