//! The robustness figure: one bar group per reality — each run's RMS with
//! the correction, the circle's with the net alone, and the steps' steady
//! state — on a log axis (the net alone and the corrected loop differ by
//! orders of magnitude), with the 0.5 mm circle target drawn across.

use std::path::Path;

use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::Row;
use crate::plot::{draw_atomically, init_fonts, log_bounds, DrawResult};

/// One bar series: its label and how to find its value among a reality's rows.
struct Series {
    label: String,
    color: RGBColor,
    run: String,
    correction: bool,
    steady: bool,
}

impl Series {
    fn value(&self, rows: &[Row], reality: &str) -> Option<f64> {
        let r = rows.iter().find(|r| {
            r.reality == reality && r.run == self.run && r.correction == self.correction
        })?;
        if self.steady {
            r.steady_mm
        } else {
            r.rms_mm
        }
    }
}

/// The realities in their table order.
fn realities(rows: &[Row]) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for r in rows {
        if !out.contains(&r.reality) {
            out.push(r.reality.clone());
        }
    }
    out
}

/// Draw the figure of `rows` into a PNG at `out` (atomically).
pub fn draw(rows: &[Row], title: &str, out: &Path) -> DrawResult {
    init_fonts();
    let groups = realities(rows);
    if groups.is_empty() {
        return Err("robustness: no row to plot".into());
    }
    let palette = [
        RGBColor(20, 60, 160),
        RGBColor(120, 160, 220),
        RGBColor(230, 140, 60),
        RGBColor(60, 150, 80),
        RGBColor(170, 60, 20),
    ];
    let mut series = Vec::new();
    let mut runs: Vec<&str> = Vec::new();
    for r in rows {
        if !runs.contains(&r.run.as_str()) {
            runs.push(&r.run);
        }
    }
    for run in &runs {
        let steady = *run == "steps";
        series.push(Series {
            label: format!(
                "{run}, corrected{}",
                if steady { " (steady state)" } else { " (RMS)" }
            ),
            color: palette[series.len() % palette.len()],
            run: run.to_string(),
            correction: true,
            steady,
        });
        if *run == "circle" && rows.iter().any(|r| !r.correction) {
            series.push(Series {
                label: "circle, net alone (RMS)".into(),
                color: palette[series.len() % palette.len()],
                run: run.to_string(),
                correction: false,
                steady: false,
            });
        }
    }
    let values = groups
        .iter()
        .flat_map(|g| series.iter().filter_map(|s| s.value(rows, g)))
        .chain([0.5]);
    let (lo, hi) = log_bounds(values).unwrap_or((0.01, 10.0));
    let shown = |v: f64| v.is_finite() && v > 0.0 && (lo..=hi).contains(&v);
    draw_atomically(out, |tmp| {
        let root = BitMapBackend::new(tmp, (1500, 700)).into_drawing_area();
        root.fill(&WHITE)?;
        let root = root.titled(title, ("sans-serif", 26))?;
        let n = groups.len();
        let mut chart = ChartBuilder::on(&root)
            .margin(14)
            .x_label_area_size(50)
            .y_label_area_size(70)
            .build_cartesian_2d(-0.5..n as f64 - 0.5, (lo..hi).log_scale())?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(0)
            .y_desc("tracking error, mm (log)")
            .label_style(("sans-serif", 15))
            .draw()?;
        let width = 0.8 / series.len() as f64;
        for (si, s) in series.iter().enumerate() {
            let color = s.color;
            let bars: Vec<_> = groups
                .iter()
                .enumerate()
                .filter_map(|(i, g)| s.value(rows, g).filter(|v| shown(*v)).map(|v| (i, v)))
                .map(|(i, v)| {
                    let x0 = i as f64 - 0.4 + si as f64 * width;
                    Rectangle::new([(x0, lo), (x0 + width * 0.92, v)], color.filled())
                })
                .collect();
            chart
                .draw_series(bars)?
                .label(s.label.clone())
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 6), (x + 14, y + 6)], color.filled())
                });
        }
        chart
            .draw_series(LineSeries::new(
                [(-0.5, 0.5), (n as f64 - 0.5, 0.5)],
                BLACK.stroke_width(1),
            ))?
            .label("0.5 mm (the circle's target)")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 14, y)], BLACK));
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 14))
            .draw()?;
        let (bx, by) = root.get_base_pixel();
        let style =
            TextStyle::from(("sans-serif", 15).into_font()).pos(Pos::new(HPos::Center, VPos::Top));
        for (i, g) in groups.iter().enumerate() {
            let (px, py) = chart.backend_coord(&(i as f64, lo));
            root.draw(&Text::new(g.clone(), (px - bx, py - by + 8), style.clone()))?;
        }
        root.present()?;
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(reality: &str, run: &str, correction: bool, rms: f64) -> Row {
        Row {
            reality: reality.into(),
            run: run.into(),
            correction,
            planner: String::new(),
            rms_mm: Some(rms),
            max_mm: Some(2.0 * rms),
            steady_mm: Some(0.5 * rms),
            jitter_mm: 0.02,
            hold_periods: 0,
            faults: 0,
            clean: true,
            problems: Vec::new(),
            dir: String::new(),
        }
    }

    #[test]
    fn figure_is_written_and_an_empty_table_refused() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("r.png");
        let rows = vec![
            row("ideal", "circle", true, 0.02),
            row("ideal", "circle", false, 0.05),
            row("ideal", "steps", true, 0.01),
            row("everything", "circle", true, 0.4),
            row("everything", "circle", false, f64::NAN),
        ];
        draw(&rows, "t", &out).unwrap();
        assert_eq!(&std::fs::read(&out).unwrap()[1..4], b"PNG");
        assert!(draw(&[], "t", &dir.path().join("e.png")).is_err());
    }

    /// The table says, per row, which of the planner's answers to the rod's
    /// mass were on.
    #[test]
    fn the_table_names_what_the_planner_did() {
        let mut r = row("everything", "circle", true, 0.4);
        r.planner = "shaped for 3.62 Hz; offset; learning to 2.6 Hz".into();
        let md = super::super::markdown(&[r], std::path::Path::new("robots/seed-4t.toml"));
        let line = md.lines().find(|l| l.starts_with("| everything")).unwrap();
        assert!(
            line.contains("| shaped for 3.62 Hz; offset; learning to 2.6 Hz |"),
            "{line}"
        );
        assert!(md.contains("| correction | planner | RMS |"), "{md}");
    }
}
