//! The bend family of tensions: a lateral "bend vector" b (N) shared out to
//! the tendons facing it, τ_i = clamp(b · (cos φ_i, sin φ_i), 0, τ_max,i) —
//! at most two adjacent tendons pull, the family the `adjacent` dataset
//! sampler draws (`docs/design.md` §3). Fixtures and benchmarks use it to
//! sweep a tip around the workspace.

use nalgebra::Vector2;

use crate::statics::Statics;

/// Bend vector (N) → tensions: each tendon pulls by the bend's component
/// along its own direction, or not at all.
pub fn bend_tensions(statics: &Statics, bend: &Vector2<f64>) -> Vec<f64> {
    statics
        .robot()
        .tendons
        .iter()
        .map(|t| {
            let dir = Vector2::new(t.angle.cos(), t.angle.sin());
            bend.dot(&dir).max(0.0).min(t.max_tension)
        })
        .collect()
}
