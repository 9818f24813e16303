//! The paper's learning curve: RMSE (normalised ×100, log scale) of the
//! training and validation splits against the number of installed hidden units.

use std::path::Path;

use plotters::prelude::*;

use crate::learn::cascor::UnitLog;

type DrawResult = Result<(), Box<dyn std::error::Error>>;

/// Draw the learning curve in `history` into a PNG at `out` (written
/// atomically: drawn to a temporary file beside it, then renamed); `best`
/// marks the kept net's hidden-unit count.
pub fn draw_learning_curve(
    history: &[UnitLog],
    best: usize,
    title: &str,
    out: &Path,
) -> DrawResult {
    super::init_fonts();
    if history.is_empty() {
        return Err("learning curve: empty history".into());
    }
    let ys = history
        .iter()
        .flat_map(|r| [r.train_rmse, r.valid_rmse])
        .filter(|v| v.is_finite() && *v > 0.0)
        .map(|v| 100.0 * v);
    let lo = ys.clone().fold(f64::INFINITY, f64::min).max(1e-6) / 1.5;
    let hi = ys.fold(f64::NEG_INFINITY, f64::max).max(lo * 2.0) * 1.5;
    let nmax = history.iter().map(|r| r.hidden).max().unwrap_or(0).max(1) as f64;
    let tmp = out.with_extension("tmp.png");
    {
        let root = BitMapBackend::new(&tmp, (1000, 650)).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 24))
            .margin(15)
            .x_label_area_size(50)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..nmax, (lo..hi).log_scale())?;
        chart
            .configure_mesh()
            .x_desc("hidden units")
            .y_desc("RMSE (normalised ×100)")
            .label_style(("sans-serif", 15))
            .draw()?;
        let series = [("train", BLUE, true), ("validation", RED, false)];
        for (label, color, train) in series {
            let pts: Vec<(f64, f64)> = history
                .iter()
                .map(|r| {
                    (
                        r.hidden as f64,
                        100.0 * if train { r.train_rmse } else { r.valid_rmse },
                    )
                })
                .collect();
            chart
                .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))?
                .label(label)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
                });
            chart.draw_series(pts.into_iter().map(|p| Circle::new(p, 3, color.filled())))?;
        }
        let b = best as f64;
        chart
            .draw_series(LineSeries::new(
                vec![(b, lo), (b, hi)],
                BLACK.mix(0.5).stroke_width(1),
            ))?
            .label(format!("kept: {best} units"))
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], BLACK.mix(0.5)));
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 15))
            .draw()?;
        root.present()?;
    }
    std::fs::rename(&tmp, out)?;
    Ok(())
}
