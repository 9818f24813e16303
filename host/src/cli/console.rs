//! The console: log level from `-v`/`-q` (`RUST_LOG` wins), a plain format
//! for progress lines, and iceoryx2's own logger kept to errors
//! (`IOX2_LOG_LEVEL` wins) so its "No config file was loaded" warning never
//! shows. The sim's children are this same binary, so they get the same setup.

use std::io::Write;

use log::{Level, LevelFilter};

/// How talkative the console is: `-q` → -1, default 0, each `-v` +1.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Verbosity(pub i8);

impl Verbosity {
    /// The level of tendril's own log lines.
    pub fn level(self) -> LevelFilter {
        match self.0 {
            i8::MIN..=-1 => LevelFilter::Warn,
            0 => LevelFilter::Info,
            1 => LevelFilter::Debug,
            _ => LevelFilter::Trace,
        }
    }
}

/// Set up `env_logger` and iceoryx2's log level. Info lines are printed bare
/// (they are the one-line-per-stage console); other levels name themselves.
pub fn init(verbosity: Verbosity) {
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let mut builder = env_logger::Builder::new();
    match std::env::var("RUST_LOG") {
        Ok(spec) if !spec.is_empty() => {
            builder.parse_filters(&spec);
        }
        _ => {
            builder
                .filter_level(LevelFilter::Warn)
                .filter_module("tendril", verbosity.level());
        }
    }
    builder
        .format(|buf, record| match record.level() {
            Level::Info => writeln!(buf, "{}", record.args()),
            Level::Warn => writeln!(buf, "warning: {}", record.args()),
            Level::Error => writeln!(buf, "error: {}", record.args()),
            level => writeln!(buf, "[{level} {}] {}", record.target(), record.args()),
        })
        .init();
}
