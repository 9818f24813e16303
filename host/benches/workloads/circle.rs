//! The dynamic plant's workload, shared by `benches/dynamics.rs` and
//! `examples/dynamics_steps.rs` so both time the same steps: the seed
//! robot's tensions along the 30 mm circle at 0.2 Hz, one per 1 ms step.

use nalgebra::Vector2;
use tendril::plan::bend_tensions;
use tendril::statics::Statics;

/// `n` tension vectors of the circle (bend (−3 + 1.5 cos a, 1.5 sin a),
/// a = 2π · 0.2 Hz · t), one per millisecond from t = 0.
pub fn circle_tensions(statics: &Statics, n: usize) -> Vec<Vec<f64>> {
    (0..n)
        .map(|k| {
            let a = std::f64::consts::TAU * 0.2 * k as f64 * 1e-3;
            bend_tensions(statics, &Vector2::new(-3.0 + 1.5 * a.cos(), 1.5 * a.sin()))
        })
        .collect()
}
