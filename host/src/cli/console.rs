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

/// An error and its causes as one line, `outer: cause: …`, each cause
/// left out when the message before it already says it: many errors
/// carry their source in their own message (`{path}: {source}`), and
/// `{:#}` would print it twice.
pub fn error_line(e: &anyhow::Error) -> String {
    let mut line = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if text.is_empty() || line.contains(&text) {
            continue;
        }
        if !line.is_empty() {
            line.push_str(": ");
        }
        line.push_str(&text);
    }
    line
}

#[cfg(test)]
mod tests {
    use super::error_line;

    #[derive(Debug, thiserror::Error)]
    #[error("out/run.mcap: {source}")]
    struct WithSource {
        source: std::io::Error,
    }

    #[test]
    fn a_cause_already_in_the_message_is_said_once() {
        let io = std::io::Error::other("No space left on device");
        let e = anyhow::Error::new(WithSource { source: io }).context("publishing the run");
        assert_eq!(
            error_line(&e),
            "publishing the run: out/run.mcap: No space left on device"
        );
    }

    #[test]
    fn a_cause_not_in_the_message_is_added() {
        let e = anyhow::anyhow!("disk full").context("writing data.csv");
        assert_eq!(error_line(&e), "writing data.csv: disk full");
    }
}
