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

/// The share of a helix's rise, on each side of a turn, over which its
/// height turns back smoothly: 0.05 turns it over a tenth of a rise (1 s of
/// a 10 s rise).
pub const HELIX_TURN_BLEND: f64 = 0.05;

/// Height at `t` s of a helix that rises from `heights[0]` to `heights[1]`
/// over `turns` revolutions at `freq` Hz and falls back over as many: at a
/// constant rate, except within [`HELIX_TURN_BLEND`] of a rise of each turn,
/// where a parabola turns it back (the rate changes linearly, so the path
/// has an acceleration everywhere: the dynamic offset needs one, and a
/// corner asked the rod for a kick; `docs/design.md` §6.4). The rate is
/// raised by 1/(1 − blend) so the heights are still reached exactly.
pub fn helix_height(heights: [f64; 2], turns: f64, freq: f64, t: f64) -> f64 {
    let rise = turns / freq;
    let b = HELIX_TURN_BLEND;
    // Up over the first `turns` revolutions (s in [0, 1]), down over the next.
    let s = (t / rise).rem_euclid(2.0);
    let (to_top, to_bottom) = ((s - 1.0).abs(), s.min(2.0 - s));
    let g = if to_top < b {
        1.0 - 0.5 * b - to_top * to_top / (2.0 * b)
    } else if to_bottom < b {
        0.5 * b + to_bottom * to_bottom / (2.0 * b)
    } else {
        1.0 - to_top
    };
    let f = (g - 0.5 * b) / (1.0 - b);
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
        assert!((helix_height([1.0, 2.0], 1.0, 0.5, 2.0) - 2.0).abs() < 1e-12);
        assert!((helix_height([1.0, 2.0], 1.0, 0.5, 4.0) - 1.0).abs() < 1e-12);
        assert!((sweep_coordinate(0.05, 0.09, 0.25, 2.0) - 0.09).abs() < 1e-15);
    }

    /// The helix reaches both heights exactly, rises at Δh/(rise (1 − b))
    /// between its turns, and its rate of climb has no jump anywhere (the
    /// triangle it replaces jumped by twice the rate at each turn): the
    /// largest change of the rate over 1 ms is the parabola's, 2 · rate ·
    /// 1 ms / (2 b · rise), against the triangle's 2 · rate.
    #[test]
    fn the_helix_turns_back_smoothly_and_reaches_both_heights() {
        let (heights, turns, freq) = ([0.39347, 0.39747], 2.0, 0.2);
        let rise = turns / freq;
        let h = |t: f64| helix_height(heights, turns, freq, t);
        let dh = heights[1] - heights[0];
        let rate = dh / (rise * (1.0 - HELIX_TURN_BLEND));
        let (lo, hi) = (0..=20_000)
            .map(|i| h(i as f64 * 1e-3))
            .fold((f64::MAX, f64::MIN), |(a, b), z| (a.min(z), b.max(z)));
        assert!((lo - heights[0]).abs() < 1e-12 && (hi - heights[1]).abs() < 1e-12);
        let dt = 1e-3;
        let climb = |t: f64| (h(t + dt) - h(t)) / dt;
        assert!((climb(0.3 * rise) - rate).abs() < 1e-6 * rate);
        assert!((climb(1.5 * rise) + rate).abs() < 1e-6 * rate);
        let worst = (0..20_000)
            .map(|i| (climb(i as f64 * dt + dt) - climb(i as f64 * dt)).abs())
            .fold(0.0, f64::max);
        let parabola = 2.0 * rate * dt / (2.0 * HELIX_TURN_BLEND * rise);
        assert!(
            worst <= 1.01 * parabola && worst < 0.01 * rate,
            "the climb rate jumps by {worst} m/s in 1 ms (rate {rate})"
        );
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
