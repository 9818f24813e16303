//! The paper's Figure 3: every learner side by side. Top panel: tension RMSE
//! (normalised ×100) on the train and test splits; bottom panel: the
//! task-space tip error (mean and 95th percentile, mm) on the test split.
//! Both on a log scale, since the learners differ by orders of magnitude.

use std::path::Path;

use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// One learner's bars.
#[derive(Clone, Debug)]
pub struct LearnerBars {
    /// Learner name (x-axis label).
    pub name: String,
    /// Tension RMSE on the train split, normalised ×100.
    pub train_rmse: f64,
    /// Tension RMSE on the test split, normalised ×100.
    pub test_rmse: f64,
    /// Mean tip position error on the test split, mm.
    pub tip_mean_mm: f64,
    /// 95th-percentile tip position error on the test split, mm.
    pub tip_p95_mm: f64,
}

use super::{draw_atomically, log_bounds, DrawResult};

/// One bar series: legend label, colour, and the value it shows.
type Series<'a> = (&'a str, RGBColor, fn(&LearnerBars) -> f64);

fn panel(
    area: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    rows: &[LearnerBars],
    caption: &str,
    y_desc: &str,
    series: &[Series<'_>],
    format: fn(f64) -> String,
) -> DrawResult {
    let n = rows.len();
    let (lo, hi) = log_bounds(
        rows.iter()
            .flat_map(|r| series.iter().map(move |s| (s.2)(r))),
    )
    .unwrap_or((0.01, 1.0));
    // A bar or label outside the axis would be drawn off the chart.
    let shown = |v: f64| v.is_finite() && (lo..=hi).contains(&v);
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 24))
        .margin(14)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(-0.5..n as f64 - 0.5, (lo..hi).log_scale())?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(0)
        .y_desc(y_desc)
        .y_label_formatter(&|v| format(*v))
        .label_style(("sans-serif", 15))
        .draw()?;
    let k = series.len() as f64;
    let width = 0.8 / k;
    for (si, &(label, color, value)) in series.iter().enumerate() {
        let bars: Vec<_> = rows
            .iter()
            .enumerate()
            .filter(|(_, r)| shown(value(r)))
            .map(|(i, r)| {
                let x0 = i as f64 - 0.4 + si as f64 * width;
                Rectangle::new([(x0, lo), (x0 + width * 0.92, value(r))], color.filled())
            })
            .collect();
        chart
            .draw_series(bars)?
            .label(label)
            .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 14, y + 6)], color.filled()));
        chart.draw_series(
            rows.iter()
                .enumerate()
                .filter(|(_, r)| shown(value(r)))
                .map(|(i, r)| {
                    let x = i as f64 - 0.4 + (si as f64 + 0.1) * width;
                    Text::new(format(value(r)), (x, value(r) * 1.12), ("sans-serif", 12))
                }),
        )?;
    }
    // Learner names under their groups (in the x-label area, outside the plot).
    let (bx, by) = area.get_base_pixel();
    let style =
        TextStyle::from(("sans-serif", 16).into_font()).pos(Pos::new(HPos::Center, VPos::Top));
    for (i, r) in rows.iter().enumerate() {
        let (px, py) = chart.backend_coord(&(i as f64, lo));
        area.draw(&Text::new(
            r.name.clone(),
            (px - bx, py - by + 8),
            style.clone(),
        ))?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 15))
        .draw()?;
    Ok(())
}

/// A bar's value in the panel's unit with at least two significant digits:
/// the best learners' tip errors (0.000015 mm) printed as 0.000 at three
/// decimals.
fn bar_label(v: f64) -> String {
    crate::units::number(v, 0)
}

/// Draw the grouped bar chart of `rows` into a PNG at `out` (written via a
/// temporary file and a rename, so a failed draw leaves no partial figure).
/// Values a log axis cannot show (zero, negative, NaN) get no bar; no
/// learner at all is an error.
pub fn draw_comparison(rows: &[LearnerBars], title: &str, out: &Path) -> DrawResult {
    super::init_fonts();
    if rows.is_empty() {
        return Err("comparison: no learner to plot".into());
    }
    draw_atomically(out, |tmp| {
        let root = BitMapBackend::new(tmp, (1500, 1100)).into_drawing_area();
        root.fill(&WHITE)?;
        let root = root.titled(title, ("sans-serif", 28))?;
        let (top, bottom) = root.split_vertically(530);
        panel(
            &top,
            rows,
            "tension RMSE (normalised ×100)",
            "RMSE ×100 (log)",
            &[
                ("train", RGBColor(120, 160, 220), |r| r.train_rmse),
                ("test", RGBColor(20, 60, 160), |r| r.test_rmse),
            ],
            bar_label,
        )?;
        panel(
            &bottom,
            rows,
            "task-space tip position error, test split (Cosserat model)",
            "error (log; nm, µm, mm as the value needs)",
            &[
                ("mean", RGBColor(230, 140, 60), |r| r.tip_mean_mm),
                ("95th percentile", RGBColor(170, 60, 20), |r| r.tip_p95_mm),
            ],
            crate::units::length_mm,
        )?;
        root.present()?;
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chart_is_written_as_a_png() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("c.png");
        let rows: Vec<LearnerBars> = (0..3)
            .map(|i| LearnerBars {
                name: format!("L{i}"),
                train_rmse: 0.1 * (i + 1) as f64,
                test_rmse: 0.2 * (i + 1) as f64,
                tip_mean_mm: 1.0 + i as f64,
                tip_p95_mm: f64::NAN,
            })
            .collect();
        draw_comparison(&rows, "test", &out).unwrap();
        let bytes = std::fs::read(&out).unwrap();
        assert_eq!(&bytes[1..4], b"PNG");
        assert!(!dir.path().join("c.tmp.png").exists());
    }

    #[test]
    fn degenerate_values_are_drawn_or_refused() {
        let dir = tempfile::tempdir().unwrap();
        let bars = |v: f64, w: f64| LearnerBars {
            name: "L".into(),
            train_rmse: v,
            test_rmse: w,
            tip_mean_mm: v,
            tip_p95_mm: w,
        };
        let cases = [
            ("zero", vec![bars(0.0, 0.0)]),
            ("constant", vec![bars(2.0, 2.0), bars(2.0, 2.0)]),
            ("nan", vec![bars(f64::NAN, f64::NAN)]),
            ("mixed", vec![bars(-1.0, f64::INFINITY), bars(1e-300, 5.0)]),
        ];
        for (name, rows) in cases {
            let out = dir.path().join(format!("{name}.png"));
            draw_comparison(&rows, name, &out).unwrap();
            assert_eq!(&std::fs::read(&out).unwrap()[1..4], b"PNG");
        }
        let out = dir.path().join("none.png");
        let err = draw_comparison(&[], "none", &out).unwrap_err();
        assert!(err.to_string().contains("no learner"), "{err}");
        assert!(!out.exists());
    }
}
