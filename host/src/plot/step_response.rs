//! The step-response figure: tip coordinates against time, in the house
//! style of `crate::plot` (PNG, bundled font, written atomically).

use std::path::Path;

use plotters::prelude::*;

use super::{draw_atomically, init_fonts, linear_bounds, DrawResult};

/// Draw the tip's x, y, z (mm, each relative to its value at t = 0) against
/// time, with the step time marked, into a PNG at `out`.
/// `samples` are (time s, tip position m) pairs.
pub fn draw_step_response(
    samples: &[(f64, [f64; 3])],
    step_s: f64,
    title: &str,
    out: &Path,
) -> DrawResult {
    init_fonts();
    let Some(first) = samples.first() else {
        return Err("step response: no samples to plot".into());
    };
    let t_end = samples.last().map_or(1.0, |s| s.0).max(1e-6);
    let mm = |s: &(f64, [f64; 3]), axis: usize| (s.1[axis] - first.1[axis]) * 1e3;
    let (lo, hi) = linear_bounds(
        samples.iter().flat_map(|s| [mm(s, 0), mm(s, 1), mm(s, 2)]),
        0.05,
        1e-3,
    );
    draw_atomically(out, |tmp| {
        let root = BitMapBackend::new(tmp, (1000, 650)).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 24))
            .margin(15)
            .x_label_area_size(50)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..t_end, lo..hi)?;
        chart
            .configure_mesh()
            .x_desc("time (s)")
            .y_desc("tip displacement from rest (mm)")
            .label_style(("sans-serif", 15))
            .draw()?;
        chart.draw_series(LineSeries::new(
            [(step_s, lo), (step_s, hi)],
            BLACK.mix(0.3).stroke_width(1),
        ))?;
        for (axis, label, color) in [(0, "x", BLUE), (1, "y", GREEN), (2, "z", RED)] {
            chart
                .draw_series(LineSeries::new(
                    samples.iter().map(|s| (s.0, mm(s, axis))),
                    color.stroke_width(2),
                ))?
                .label(label)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
                });
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font(("sans-serif", 16))
            .draw()?;
        root.present()?;
        Ok(())
    })
}
