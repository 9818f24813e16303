//! Every figure tendril draws, one function per figure, one file per topic.
//! Figures are PNG (plotters' bitmap backend) with the bundled DejaVu Sans
//! font, so drawing needs no system font library.

pub mod calibration;
pub mod compare;
pub mod learning_curve;
pub mod sim;
pub mod step_response;
pub mod workspace;

use std::path::Path;
use std::sync::Once;

use crate::fsutil::Temporary;

/// What a figure function returns: the PNG was written, or why not.
pub type DrawResult = Result<(), Box<dyn std::error::Error>>;

/// Most decades a log axis spans: beyond that, plotters' tick generation
/// grows without bound, and a figure could not show the spread anyway.
const MAX_DECADES: f64 = 12.0;

/// Log-axis bounds covering the finite positive `values`, whole decades,
/// at most [`MAX_DECADES`] below the largest; `None` when there is no such
/// value (all zero, negative or NaN, or none at all).
pub fn log_bounds(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let (lo, hi) = values
        .filter(|v| v.is_finite() && *v > 0.0)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if !lo.is_finite() {
        return None;
    }
    let top = (hi * 1.8).log10().ceil();
    let bottom = lo.log10().floor().max(top - MAX_DECADES).min(top - 1.0);
    Some((10f64.powf(bottom), 10f64.powf(top)))
}

/// Linear-axis bounds covering the finite `values` with `pad` (a fraction of
/// the span, at least `min_pad`) on each side; `(-min_pad, min_pad)` when
/// there is no finite value.
pub fn linear_bounds(values: impl Iterator<Item = f64>, pad: f64, min_pad: f64) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if !lo.is_finite() {
        return (-min_pad, min_pad);
    }
    let pad = ((hi - lo) * pad).max(min_pad);
    (lo - pad, hi + pad)
}

/// Draw a PNG into a temporary file and put it at `out` by the one output
/// policy ([`crate::fsutil`], docs/design.md §7): renamed over a regular file
/// (a symlink stays a link, its target replaced), copied through a device or
/// FIFO (never replaced), and only when `draw` succeeds, so a failed figure
/// leaves neither a partial PNG nor the temporary file. The temporary's name
/// ends in `.png` because plotters picks the image format from the
/// extension; it is registered for removal on a second Ctrl-C.
pub fn draw_atomically(out: &Path, draw: impl FnOnce(&Path) -> DrawResult) -> DrawResult {
    let tmp = Temporary::for_output_ending(out, ".tmp.png")?;
    draw(tmp.path())?;
    tmp.persist(out)?;
    Ok(())
}

static FONTS: Once = Once::new();

/// Register the bundled font under the family names plotters asks for.
/// Call before drawing; cheap after the first call.
pub fn init_fonts() {
    FONTS.call_once(|| {
        const DEJAVU: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");
        for family in ["sans-serif", "serif", "monospace"] {
            for style in [
                plotters::style::FontStyle::Normal,
                plotters::style::FontStyle::Bold,
                plotters::style::FontStyle::Italic,
                plotters::style::FontStyle::Oblique,
            ] {
                // Registration only fails on a malformed font; the bundled one is fine.
                let _ = plotters::style::register_font(family, style, DEJAVU);
            }
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use plotters::prelude::{BitMapBackend, IntoDrawingArea, WHITE};

    /// A small white PNG, as every figure function draws one.
    fn blank(path: &Path) -> DrawResult {
        let root = BitMapBackend::new(path, (8, 8)).into_drawing_area();
        root.fill(&WHITE)?;
        root.present()?;
        Ok(())
    }

    /// Names in `dir` that are our temporaries.
    fn temporaries(dir: &Path) -> Vec<String> {
        std::fs::read_dir(dir)
            .unwrap()
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with(".tendril-") || n.contains(".tmp"))
            .collect()
    }

    const PNG_MAGIC: &[u8] = b"\x89PNG";

    #[test]
    fn a_figure_replaces_a_regular_file_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("f.png");
        std::fs::write(&out, "old").unwrap();
        draw_atomically(&out, blank).unwrap();
        assert!(std::fs::read(&out).unwrap().starts_with(PNG_MAGIC));
        assert_eq!(temporaries(dir.path()), Vec::<String>::new());
    }

    #[test]
    fn a_failed_figure_keeps_the_old_file_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("f.png");
        std::fs::write(&out, "old").unwrap();
        let err = draw_atomically(&out, |p| {
            blank(p)?;
            Err("failed after drawing".into())
        });
        assert!(err.is_err());
        assert_eq!(std::fs::read_to_string(&out).unwrap(), "old");
        assert_eq!(temporaries(dir.path()), Vec::<String>::new());
    }

    #[cfg(unix)]
    #[test]
    fn a_symlinked_figure_stays_a_link_and_its_target_gets_the_png() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("figures")).unwrap();
        let target = dir.path().join("figures").join("w.png");
        std::fs::write(&target, "old").unwrap();
        let link = dir.path().join("w.png");
        std::os::unix::fs::symlink("figures/w.png", &link).unwrap();
        draw_atomically(&link, blank).unwrap();
        let kind = std::fs::symlink_metadata(&link).unwrap().file_type();
        assert!(kind.is_symlink(), "the link was replaced by a file");
        assert!(std::fs::read(&target).unwrap().starts_with(PNG_MAGIC));
        assert_eq!(temporaries(dir.path()), Vec::<String>::new());
        assert_eq!(
            temporaries(&dir.path().join("figures")),
            Vec::<String>::new()
        );
    }

    #[cfg(unix)]
    #[test]
    fn a_figure_into_a_fifo_is_written_through_and_the_fifo_stays() {
        use std::os::unix::fs::FileTypeExt;
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("w.png");
        let made = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap();
        assert!(made.success());
        let reader = {
            let fifo = fifo.clone();
            std::thread::spawn(move || std::fs::read(fifo).unwrap())
        };
        let drawn = draw_atomically(&fifo, blank);
        // Checked before joining the reader: a FIFO replaced by a file
        // would leave the reader blocked for ever.
        let kind = std::fs::symlink_metadata(&fifo).unwrap().file_type();
        assert!(kind.is_fifo(), "the FIFO was replaced");
        drawn.unwrap();
        assert!(reader.join().unwrap().starts_with(PNG_MAGIC));
        assert_eq!(temporaries(dir.path()), Vec::<String>::new());
    }

    /// A node like /dev/null (1, 3) in `dir`, when this process may make
    /// one that opens (root, no nodev mount): a regression then replaces
    /// only the copy, never the machine's /dev/null.
    #[cfg(target_os = "linux")]
    fn null_device(dir: &Path) -> Option<std::path::PathBuf> {
        let copy = dir.join("null");
        let made = std::process::Command::new("mknod")
            .arg(&copy)
            .args(["c", "1", "3"])
            .stderr(std::process::Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        let opens = made && std::fs::OpenOptions::new().write(true).open(&copy).is_ok();
        opens.then_some(copy)
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_figure_into_a_device_leaves_the_device() {
        use std::os::unix::fs::FileTypeExt;
        let dir = tempfile::tempdir().unwrap();
        let null = null_device(dir.path()).unwrap_or_else(|| "/dev/null".into());
        draw_atomically(&null, blank).unwrap();
        let kind = std::fs::symlink_metadata(&null).unwrap().file_type();
        assert!(kind.is_char_device(), "{} was replaced", null.display());
        assert_eq!(temporaries(dir.path()), Vec::<String>::new());
    }
}
