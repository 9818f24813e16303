//! `tendril`: thin shell over the library — parse the command line, run,
//! turn an error into one line on stderr and a non-zero exit.

fn main() -> std::process::ExitCode {
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("info"))
        .format_timestamp(None)
        .init();
    match tendril::cli::run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("tendril: error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
