//! The `tendril sim` figure: desired vs actual tip path (top view) and the
//! commanded and actual tendon tensions over time.

use std::path::Path;

use plotters::prelude::*;

/// What the sim figure shows, in plain numbers.
#[derive(Debug, Clone, PartialEq)]
pub struct SimFigure<'a> {
    /// Desired tip path, top view (x, y), mm.
    pub desired_mm: Vec<(f64, f64)>,
    /// Actual tip path, top view (x, y), mm.
    pub actual_mm: Vec<(f64, f64)>,
    /// Tension samples in time order.
    pub tensions: Vec<TensionSample<'a>>,
    /// Tendons to draw a pair of lines for.
    pub tendons: usize,
}

/// The tensions at one instant, N, tendon 0 first; a missing entry is not drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TensionSample<'a> {
    /// Time, s.
    pub t_s: f64,
    /// Tensions the controller commanded, N.
    pub commanded: &'a [f64],
    /// Tensions the plant reported, N.
    pub actual: &'a [f64],
}

/// Draw `figure` into a PNG at `path`, by the output policy
/// ([`super::draw_atomically`]).
pub fn draw(path: &Path, figure: &SimFigure<'_>) -> Result<(), Box<dyn std::error::Error>> {
    super::draw_atomically(path, |tmp| draw_into(tmp, figure))
}

fn draw_into(path: &Path, figure: &SimFigure<'_>) -> Result<(), Box<dyn std::error::Error>> {
    super::init_fonts();
    let tensions = &figure.tensions;

    let root = BitMapBackend::new(path, (1400, 600)).into_drawing_area();
    root.fill(&WHITE)?;
    let (left, right) = root.split_horizontally(600);

    // Top view of the tip path.
    let (des, act) = (&figure.desired_mm, &figure.actual_mm);
    let pts = des
        .iter()
        .chain(act)
        .filter(|p| p.0.is_finite() && p.1.is_finite());
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for p in pts {
        x0 = x0.min(p.0);
        x1 = x1.max(p.0);
        y0 = y0.min(p.1);
        y1 = y1.max(p.1);
    }
    if x0 > x1 {
        (x0, x1, y0, y1) = (-1.0, 1.0, -1.0, 1.0);
    }
    // Equal axes around the data.
    let half = ((x1 - x0).max(y1 - y0) / 2.0 + 2.0).max(1.0);
    let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
    let mut chart = ChartBuilder::on(&left)
        .caption("tip path, top view", ("sans-serif", 22))
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(55)
        .build_cartesian_2d(cx - half..cx + half, cy - half..cy + half)?;
    chart
        .configure_mesh()
        .x_desc("x (mm)")
        .y_desc("y (mm)")
        .draw()?;
    chart
        .draw_series(LineSeries::new(des.iter().copied(), BLUE.stroke_width(2)))?
        .label("desired")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE.stroke_width(2)));
    chart
        .draw_series(LineSeries::new(act.iter().copied(), RED.stroke_width(1)))?
        .label("actual")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED));
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;

    // Tensions over time: commanded (thin) and actual (thick) per tendon.
    let n = figure.tendons;
    let t_max = tensions
        .last()
        .map(|r| r.t_s)
        .filter(|t| t.is_finite())
        .unwrap_or(1.0);
    let t_min = tensions
        .first()
        .map(|r| r.t_s)
        .filter(|t| t.is_finite())
        .unwrap_or(0.0);
    let mut f_max: f64 = 1.0;
    for r in tensions {
        for v in r.commanded.iter().chain(r.actual) {
            if v.is_finite() {
                f_max = f_max.max(*v);
            }
        }
    }
    let at = |v: &[f64], k: usize| v.get(k).copied().unwrap_or(f64::NAN);
    let mut chart = ChartBuilder::on(&right)
        .caption(
            "tendon tensions (thin: commanded, thick: actual)",
            ("sans-serif", 22),
        )
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(55)
        .build_cartesian_2d(t_min..t_max.max(t_min + 1e-3), 0.0..f_max * 1.05)?;
    chart
        .configure_mesh()
        .x_desc("time (s)")
        .y_desc("tension (N)")
        .draw()?;
    for k in 0..n {
        let color = Palette99::pick(k).to_rgba();
        chart.draw_series(LineSeries::new(
            tensions.iter().map(|r| (r.t_s, at(r.commanded, k))),
            color.stroke_width(1),
        ))?;
        chart
            .draw_series(LineSeries::new(
                tensions.iter().map(|r| (r.t_s, at(r.actual, k))),
                color.stroke_width(3),
            ))?
            .label(format!("tendon {k}"))
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(3))
            });
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}
