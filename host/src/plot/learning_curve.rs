//! The paper's learning curve: RMSE (normalised ×100, log scale) of the
//! training and validation splits against the number of installed hidden units.

use std::path::Path;

use plotters::prelude::*;

use super::{draw_atomically, log_bounds, DrawResult};

/// One point of a learning curve: the RMSE of both splits (normalised, as a
/// fraction) after `hidden` hidden units were installed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurvePoint {
    /// Installed hidden units.
    pub hidden: usize,
    /// Normalised RMSE on the training split.
    pub train_rmse: f64,
    /// Normalised RMSE on the validation split.
    pub valid_rmse: f64,
}

/// Draw the learning curve in `history` into a PNG at `out` (written
/// atomically: drawn to a temporary file beside it, then renamed); `best`
/// marks the kept net's hidden-unit count. RMSE values that a log axis cannot
/// show (zero, NaN) are left out; when none is left the axes are drawn with a
/// note saying so. An empty history is an error.
pub fn draw_learning_curve(
    history: &[CurvePoint],
    best: usize,
    title: &str,
    out: &Path,
) -> DrawResult {
    super::init_fonts();
    if history.is_empty() {
        return Err("learning curve: empty history, nothing to plot".into());
    }
    let percent = |v: f64| 100.0 * v;
    let bounds = log_bounds(
        history
            .iter()
            .flat_map(|r| [r.train_rmse, r.valid_rmse])
            .map(percent),
    );
    let (lo, hi) = bounds.unwrap_or((0.01, 1.0));
    let shown = |v: f64| v.is_finite() && (lo..=hi).contains(&v);
    let nmax = history
        .iter()
        .map(|r| r.hidden)
        .chain([best])
        .max()
        .unwrap_or(0)
        .max(1) as f64;
    draw_atomically(out, |tmp| {
        let root = BitMapBackend::new(tmp, (1000, 650)).into_drawing_area();
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
        if bounds.is_none() {
            chart.draw_series([Text::new(
                "every RMSE is zero or not finite: nothing to show on a log axis",
                (nmax * 0.05, (lo * hi).sqrt()),
                ("sans-serif", 18),
            )])?;
        }
        let series = [("train", BLUE, true), ("validation", RED, false)];
        for (label, color, train) in series {
            let pts: Vec<(f64, f64)> = history
                .iter()
                .map(|r| {
                    let v = if train { r.train_rmse } else { r.valid_rmse };
                    (r.hidden as f64, percent(v))
                })
                .filter(|&(_, y)| shown(y))
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
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn history(rmse: &[(f64, f64)]) -> Vec<CurvePoint> {
        rmse.iter()
            .enumerate()
            .map(|(hidden, &(train_rmse, valid_rmse))| CurvePoint {
                hidden,
                train_rmse,
                valid_rmse,
            })
            .collect()
    }

    fn assert_png(path: &Path) {
        let bytes = std::fs::read(path).unwrap();
        assert_eq!(&bytes[1..4], b"PNG");
        assert!(!path.with_extension("tmp.png").exists());
    }

    #[test]
    fn degenerate_curves_are_drawn_or_refused() {
        let dir = tempfile::tempdir().unwrap();
        let cases: [(&str, Vec<(f64, f64)>); 6] = [
            ("zero", vec![(0.0, 0.0); 4]),
            ("constant", vec![(0.25, 0.25); 4]),
            ("nan", vec![(f64::NAN, f64::NAN); 3]),
            ("single", vec![(0.1, 0.2)]),
            (
                "mixed",
                vec![(0.0, f64::INFINITY), (1e-300, 0.3), (5.0, -1.0)],
            ),
            ("tiny", vec![(f64::MIN_POSITIVE, 1e-200)]),
        ];
        for (name, rmse) in cases {
            let out = dir.path().join(format!("{name}.png"));
            draw_learning_curve(&history(&rmse), 0, name, &out).unwrap();
            assert_png(&out);
        }
        let out = dir.path().join("empty.png");
        let err = draw_learning_curve(&[], 0, "empty", &out).unwrap_err();
        assert!(err.to_string().contains("empty history"), "{err}");
        assert!(!out.exists());
    }
}
