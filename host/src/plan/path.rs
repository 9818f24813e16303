//! Pure path geometry: where a shape's point is on the robot's family at a
//! time, and the times a closed path is tabulated at. No statics here; the
//! lift onto reachable poses is [`super::lift`].

use std::f64::consts::TAU;

/// Table resolution for lifted continuous paths (s).
pub const TABLE_DT: f64 = 0.01;

/// Times of one period of a closed path at `freq` Hz lasting `cycles`
/// periods of the base frequency, tabulated at [`TABLE_DT`] (at least 16
/// intervals).
pub fn periodic_times(freq: f64, cycles: f64) -> Vec<f64> {
    let period = cycles / freq;
    let n = ((period / TABLE_DT).ceil() as usize).max(16);
    (0..=n).map(|i| period * i as f64 / n as f64).collect()
}

/// Lateral point at `t` s of a circle of `radius` about `center`, `freq`
/// revolutions per second, starting at +x.
pub fn circle_point(center: [f64; 2], radius: f64, freq: f64, t: f64) -> [f64; 2] {
    let a = TAU * freq * t;
    [center[0] + radius * a.cos(), center[1] + radius * a.sin()]
}

/// Lateral point at `t` s of a lemniscate of Gerono (figure eight) of
/// half-width `radius` about `center`, `freq` periods per second.
pub fn figure_eight_point(center: [f64; 2], radius: f64, freq: f64, t: f64) -> [f64; 2] {
    let a = TAU * freq * t;
    [
        center[0] + radius * a.sin(),
        center[1] + radius * a.sin() * a.cos(),
    ]
}

/// Height at `t` s of a helix that rises linearly from `heights[0]` to
/// `heights[1]` over `turns` revolutions at `freq` Hz and falls back over
/// as many.
pub fn helix_height(heights: [f64; 2], turns: f64, freq: f64, t: f64) -> f64 {
    let rise = turns / freq;
    // Up over the first `turns` revolutions, down over the next.
    let f = if t <= rise { t / rise } else { 2.0 - t / rise };
    heights[0] + f * (heights[1] - heights[0])
}

/// Coordinate along the axis at `t` s of a sweep,
/// `from + (to − from) (1 − cos 2π f t) / 2`.
pub fn sweep_coordinate(from: f64, to: f64, freq: f64, t: f64) -> f64 {
    let a = TAU * freq * t;
    from + (to - from) * 0.5 * (1.0 - a.cos())
}

/// Centroid and radius of the lateral (x, y) parts of `targets`: the circle
/// about their centroid that holds them all (a missing y counts as 0).
pub fn lateral_circle(targets: &[Vec<f64>]) -> ([f64; 2], f64) {
    let lateral = |t: &Vec<f64>| [t[0], *t.get(1).unwrap_or(&0.0)];
    let n = targets.len() as f64;
    let centroid = targets
        .iter()
        .map(lateral)
        .fold([0.0; 2], |c, t| [c[0] + t[0] / n, c[1] + t[1] / n]);
    let radius = targets
        .iter()
        .map(|t| {
            let t = lateral(t);
            (t[0] - centroid[0]).hypot(t[1] - centroid[1])
        })
        .fold(0.0, f64::max);
    (centroid, radius)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn periodic_times_cover_one_period_at_the_table_step() {
        let t = periodic_times(0.2, 1.0);
        assert_eq!(t.len(), 501);
        assert_eq!(t[0], 0.0);
        assert!((t[500] - 5.0).abs() < 1e-12);
        assert_eq!(periodic_times(100.0, 1.0).len(), 17);
    }

    #[test]
    fn closed_paths_return_to_their_start() {
        let (c, r, f) = ([0.01, -0.02], 0.015, 0.2);
        let (a, b) = (circle_point(c, r, f, 0.0), circle_point(c, r, f, 5.0));
        assert!((a[0] - 0.025).abs() < 1e-15 && (a[0] - b[0]).abs() < 1e-12);
        let e = figure_eight_point(c, r, f, 1.25);
        assert!((e[0] - 0.025).abs() < 1e-12 && (e[1] - c[1]).abs() < 1e-12);
        assert_eq!(helix_height([1.0, 2.0], 1.0, 0.5, 2.0), 2.0);
        assert_eq!(helix_height([1.0, 2.0], 1.0, 0.5, 4.0), 1.0);
        assert!((sweep_coordinate(0.05, 0.09, 0.25, 2.0) - 0.09).abs() < 1e-15);
    }

    #[test]
    fn lateral_circle_holds_every_target() {
        let targets = [vec![0.01, 0.0], vec![-0.01, 0.0], vec![0.0, 0.01, 0.3]];
        let (c, r) = lateral_circle(&targets);
        assert!((c[0]).abs() < 1e-15 && (c[1] - 0.01 / 3.0).abs() < 1e-15);
        assert!(
            (r - (0.01f64.powi(2) + (0.01 / 3.0f64).powi(2))
                .sqrt()
                .max(0.02 / 3.0))
            .abs()
                < 1e-15
        );
    }
}
