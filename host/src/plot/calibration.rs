//! The calibration figure (`tendril calibrate`, `docs/design.md` §11):
//! measured tips against the model's before and after the fit (top view),
//! and a histogram of the tip errors before and after.

use std::path::Path;

use plotters::prelude::*;

use super::{draw_atomically, linear_bounds, DrawResult};
use crate::calibrate::Calibration;

/// Draw `c`'s figure into a PNG at `out` (written atomically).
pub fn draw_calibration(c: &Calibration, out: &Path) -> DrawResult {
    super::init_fonts();
    let err = |tips: &[[f64; 3]]| -> Vec<f64> {
        c.measured
            .iter()
            .zip(tips)
            .map(|(m, t)| (0..3).map(|k| (m[k] - t[k]).powi(2)).sum::<f64>().sqrt() * 1e3)
            .collect()
    };
    let (before, after) = (err(&c.before), err(&c.after));
    draw_atomically(out, |tmp| {
        let root = BitMapBackend::new(tmp, (1500, 650)).into_drawing_area();
        root.fill(&WHITE)?;
        let root = root.titled(
            &format!("calibration of {}", c.report.robot),
            ("sans-serif", 26),
        )?;
        let (left, right) = root.split_horizontally(750);
        let all = c.measured.iter().chain(&c.before).chain(&c.after);
        let (x0, x1) = linear_bounds(all.clone().map(|p| p[0] * 1e3), 0.05, 1.0);
        let (y0, y1) = linear_bounds(all.map(|p| p[1] * 1e3), 0.05, 1.0);
        let mut chart = ChartBuilder::on(&left)
            .caption("tips, top view (x-y)", ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        chart
            .configure_mesh()
            .x_desc("x [mm]")
            .y_desc("y [mm]")
            .label_style(("sans-serif", 15))
            .draw()?;
        for (tips, color, label) in [
            (&c.before, RED, "nominal model"),
            (&c.after, GREEN, "calibrated model"),
            (&c.measured, BLUE, "measured"),
        ] {
            chart
                .draw_series(
                    tips.iter()
                        .map(|p| Circle::new((p[0] * 1e3, p[1] * 1e3), 2, color.mix(0.6).filled())),
                )?
                .label(label)
                .legend(move |(x, y)| Circle::new((x, y), 4, color.filled()));
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
        // Histogram of ‖error‖ in mm, on a log-spaced bin grid so the
        // before (mm) and after (tenths of mm) both show.
        let lo = after
            .iter()
            .chain(&before)
            .copied()
            .filter(|x| *x > 0.0)
            .fold(f64::INFINITY, f64::min)
            .max(1e-4);
        let hi = after
            .iter()
            .chain(&before)
            .copied()
            .fold(lo * 10.0, f64::max);
        let bins = 30;
        let edge = |k: usize| (lo.ln() + (hi.ln() - lo.ln()) * k as f64 / bins as f64).exp();
        let count = |e: &[f64]| -> Vec<usize> {
            let mut h = vec![0; bins];
            for &x in e {
                let k = (((x.max(lo).ln() - lo.ln()) / (hi.ln() - lo.ln())) * bins as f64)
                    .floor()
                    .clamp(0.0, (bins - 1) as f64) as usize;
                h[k] += 1;
            }
            h
        };
        let (hb, ha) = (count(&before), count(&after));
        let top = *hb.iter().chain(&ha).max().unwrap_or(&1) as f64 * 1.1 + 1.0;
        let mut chart = ChartBuilder::on(&right)
            .caption("tip error, every row", ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .build_cartesian_2d((lo..hi).log_scale(), 0.0..top)?;
        chart
            .configure_mesh()
            .x_desc("|measured - model| [mm]")
            .y_desc("rows")
            .label_style(("sans-serif", 15))
            .draw()?;
        for (h, color, label) in [(&hb, RED, "nominal"), (&ha, GREEN, "calibrated")] {
            chart
                .draw_series(h.iter().enumerate().map(|(k, &n)| {
                    Rectangle::new(
                        [(edge(k), 0.0), (edge(k + 1), n as f64)],
                        color.mix(0.5).filled(),
                    )
                }))?
                .label(label)
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 5), (x + 10, y + 5)], color.filled())
                });
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
        root.present()?;
        Ok(())
    })
}
