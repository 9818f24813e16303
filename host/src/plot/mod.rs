//! Every figure tendril draws, one function per figure, one file per topic.
//! Figures are PNG (plotters' bitmap backend) with the bundled DejaVu Sans
//! font, so drawing needs no system font library.

pub mod compare;
pub mod learning_curve;
pub mod sim;

use std::sync::Once;

pub mod workspace;

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
