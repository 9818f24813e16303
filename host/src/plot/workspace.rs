//! The paper's Figure 1: the reachable tip positions as a point cloud in three
//! orthogonal projections, and a few backbone shapes.

use std::path::Path;

use nalgebra::{DMatrix, Vector3};
use plotters::prelude::*;

/// A labelled backbone shape (base frame, m).
pub struct BackboneCurve {
    /// Legend text, e.g. "t0 = 10 N".
    pub label: String,
    /// Points from base to tip.
    pub points: Vec<Vector3<f64>>,
}

use super::{draw_atomically, linear_bounds, DrawResult};

/// Axis range in mm over the finite values (m), padded by 5 % and at least
/// 1 mm, so a constant column or an empty set still gets a visible axis.
fn range_mm(v: impl Iterator<Item = f64>) -> (f64, f64) {
    linear_bounds(v.map(|x| x * 1e3), 0.05, 1.0)
}

/// Draw the tip cloud of `poses` (n × 7, metres) in three projections and
/// `shapes` in the x–z plane into a PNG at `out` (written atomically).
/// Non-finite points are left out; an empty cloud or shape list gives empty
/// panels. `poses` with fewer than 3 columns is an error.
pub fn draw_workspace(
    poses: &DMatrix<f64>,
    shapes: &[BackboneCurve],
    title: &str,
    out: &Path,
) -> DrawResult {
    super::init_fonts();
    if poses.ncols() < 3 {
        return Err(format!(
            "workspace: poses need px, py, pz columns, got {}",
            poses.ncols()
        )
        .into());
    }
    draw_atomically(out, |tmp| {
        let root = BitMapBackend::new(tmp, (1400, 1200)).into_drawing_area();
        root.fill(&WHITE)?;
        let root = root.titled(title, ("sans-serif", 28))?;
        let panels = root.split_evenly((2, 2));
        let axes = [
            (0, 1, "x [mm]", "y [mm]", "top view"),
            (0, 2, "x [mm]", "z [mm]", "side view (x-z)"),
            (1, 2, "y [mm]", "z [mm]", "front view (y-z)"),
        ];
        for (panel, &(a, b, xl, yl, caption)) in panels.iter().zip(&axes) {
            let xs = poses.column(a);
            let ys = poses.column(b);
            let (x0, x1) = range_mm(xs.iter().copied());
            let (y0, y1) = range_mm(ys.iter().copied());
            let mut chart = ChartBuilder::on(panel)
                .caption(caption, ("sans-serif", 22))
                .margin(12)
                .x_label_area_size(45)
                .y_label_area_size(60)
                .build_cartesian_2d(x0..x1, y0..y1)?;
            chart
                .configure_mesh()
                .x_desc(xl)
                .y_desc(yl)
                .label_style(("sans-serif", 15))
                .draw()?;
            chart.draw_series(
                xs.iter()
                    .zip(ys.iter())
                    .filter(|(x, y)| x.is_finite() && y.is_finite())
                    .map(|(&x, &y)| Circle::new((x * 1e3, y * 1e3), 1, BLUE.mix(0.35).filled())),
            )?;
        }
        // Backbone shapes in the x–z plane.
        let all = shapes
            .iter()
            .flat_map(|s| s.points.iter())
            .filter(|p| p.x.is_finite() && p.z.is_finite());
        let (x0, x1) = range_mm(all.clone().map(|p| p.x));
        let (z0, z1) = range_mm(all.map(|p| p.z));
        let mut chart = ChartBuilder::on(&panels[3])
            .caption("backbone shapes (x-z)", ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .build_cartesian_2d(x0..x1, z0..z1)?;
        chart
            .configure_mesh()
            .x_desc("x [mm]")
            .y_desc("z [mm]")
            .label_style(("sans-serif", 15))
            .draw()?;
        for (k, s) in shapes.iter().enumerate() {
            let color = Palette99::pick(k).to_rgba();
            chart
                .draw_series(LineSeries::new(
                    s.points
                        .iter()
                        .filter(|p| p.x.is_finite() && p.z.is_finite())
                        .map(|p| (p.x * 1e3, p.z * 1e3)),
                    color.stroke_width(2),
                ))?
                .label(s.label.clone())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
                });
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 14))
            .draw()?;
        root.present()?;
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn assert_png(path: &Path) {
        let bytes = std::fs::read(path).unwrap();
        assert_eq!(&bytes[1..4], b"PNG");
        assert!(!path.with_extension("tmp.png").exists());
    }

    #[test]
    fn degenerate_clouds_and_shapes_are_drawn_or_refused() {
        let dir = tempfile::tempdir().unwrap();
        let constant = DMatrix::from_fn(5, 7, |_, j| if j == 3 { 1.0 } else { 0.02 });
        let nan = DMatrix::from_element(4, 7, f64::NAN);
        let mut mixed = constant.clone();
        mixed[(0, 0)] = f64::INFINITY;
        mixed[(1, 2)] = f64::NAN;
        let line = BackboneCurve {
            label: "flat".into(),
            points: vec![Vector3::zeros(); 3],
        };
        let broken = BackboneCurve {
            label: "nan".into(),
            points: vec![Vector3::new(f64::NAN, 0.0, f64::NAN)],
        };
        let cases = [
            ("empty", DMatrix::zeros(0, 7), vec![]),
            ("constant", constant, vec![line]),
            ("nan", nan, vec![broken]),
            ("mixed", mixed, vec![]),
        ];
        for (name, poses, shapes) in cases {
            let out = dir.path().join(format!("{name}.png"));
            draw_workspace(&poses, &shapes, name, &out).unwrap();
            assert_png(&out);
        }
        let out = dir.path().join("narrow.png");
        let err = draw_workspace(&DMatrix::zeros(3, 2), &[], "narrow", &out).unwrap_err();
        assert!(err.to_string().contains("px, py, pz"), "{err}");
        assert!(!out.exists());
    }
}
