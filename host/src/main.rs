//! `tendril`: thin shell over the library — parse the command line, set up
//! the console, run, turn an error into one line on stderr and a non-zero exit.

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    quiet_broken_pipe();
    let cli = tendril::cli::Cli::parse();
    // A line of its own on a signal and a forced exit on a second, unless
    // a sim supervises this process (its launcher speaks and stops it).
    let supervised = std::env::var_os(tendril::ipc::SUPERVISED_ENV).is_some();
    let hooks = (!supervised).then(tendril::fsutil::exit_hooks);
    if let Err(e) = tendril::interrupt::install(hooks) {
        eprintln!("tendril: error: signal handling: {e}");
        return ExitCode::FAILURE;
    }
    tendril::cli::console::init(cli.verbosity());
    match tendril::cli::run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if tendril::interrupt::stop_requested() => {
            let by = tendril::interrupt::stopped_by().unwrap_or("a stop request");
            let line = tendril::cli::console::error_line(&e);
            // What the command says it left, with the signal named.
            let left = line
                .strip_prefix("interrupted")
                .unwrap_or(&line)
                .trim_start_matches([':', ';', ' ']);
            if left.is_empty() {
                eprintln!("tendril: interrupted by {by}; no output was written or changed");
            } else {
                eprintln!("tendril: interrupted by {by}: {left}");
            }
            ExitCode::from(tendril::interrupt::EXIT_INTERRUPTED)
        }
        Err(e) => {
            eprintln!("tendril: error: {}", tendril::cli::console::error_line(&e));
            ExitCode::FAILURE
        }
    }
}

/// Let a closed stdout (`tendril ik … | head -1`) end the process quietly, as
/// it ends `cat` or `grep`: the Rust runtime ignores SIGPIPE, so a write to
/// the closed pipe would fail and `print!` panic (exit 101). With SIGPIPE's
/// default disposition restored, the kernel ends the process instead. Every
/// file the process writes is written atomically, so nothing is left half-done.
fn quiet_broken_pipe() {
    #[cfg(unix)]
    // SAFETY: called first thing in `main`, before any other thread exists;
    // SIG_DFL is a valid disposition for SIGPIPE.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}
