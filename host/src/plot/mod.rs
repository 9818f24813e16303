//! Every figure tendril draws, one function per figure, one file per topic.
//! Figures are PNG (plotters' bitmap backend) with the bundled DejaVu Sans
//! font, so drawing needs no system font library.

pub mod compare;
pub mod learning_curve;
pub mod sim;
pub mod workspace;

use std::path::Path;
use std::sync::Once;

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

/// Draw a PNG through a temporary file beside `out`, renamed into place only
/// when `draw` succeeds, so a failed figure leaves neither a partial PNG nor
/// the temporary file.
pub fn draw_atomically(out: &Path, draw: impl FnOnce(&Path) -> DrawResult) -> DrawResult {
    let tmp = out.with_extension("tmp.png");
    let drawn = draw(&tmp).and_then(|()| Ok(std::fs::rename(&tmp, out)?));
    if drawn.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    drawn
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
