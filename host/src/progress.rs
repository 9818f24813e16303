//! The one progress-bar helper (indicatif): every long job draws its bar
//! on stderr the same way, or none when asked for quiet or when info
//! logging is off (`-q`).

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// A bar of `len` units on stderr, in `template` (indicatif's syntax;
/// `{bar:30}` is the bar itself), when `visible` and info logging is on;
/// a hidden bar otherwise (it counts, it draws nothing).
pub fn bar(len: u64, visible: bool, template: &str) -> ProgressBar {
    let target = if visible && log::log_enabled!(log::Level::Info) {
        ProgressDrawTarget::stderr()
    } else {
        ProgressDrawTarget::hidden()
    };
    let bar = ProgressBar::with_draw_target(Some(len), target);
    bar.set_style(
        ProgressStyle::with_template(template)
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar
}
