//! Synthetic measurements: a noiseless dataset seen through a tracker
//! (`tendril generate --noise-mm`, `docs/design.md` §11): the tracker's
//! frame offset from the robot's base, and Gaussian jitter on the pose.

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::dataset::Dataset;

/// How the tracker sees the tip.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackerNoise {
    /// Standard deviation of each position axis, m.
    pub position_sigma_m: f64,
    /// Standard deviation of each axis of the orientation error's rotation
    /// vector, rad.
    pub angle_sigma_rad: f64,
    /// The base's origin in the tracker frame, m.
    pub frame_offset_m: [f64; 3],
    /// Seed of the noise (independent of the sampler's).
    pub seed: u64,
    /// Fraction of rows, in [0, 1], whose tip position is off by
    /// `outlier_m` in a random direction on top of the jitter: the tracker's
    /// occasional wild reading (a reflection, a swapped marker).
    pub outlier_fraction: f64,
    /// How far an outlier's position is off, m.
    pub outlier_m: f64,
}

/// A standard normal draw (Box–Muller).
fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.random::<f64>().max(f64::MIN_POSITIVE);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

/// Apply `noise` to every pose of `data` in place: p ← p + t + σ_p ε,
/// q ← exp(σ_θ ε) ⊗ q (sign kept w ≥ 0); then a seeded
/// `outlier_fraction` of the rows (rounded, chosen by their own stream so
/// the jitter does not change with it) gets `outlier_m` more in a random
/// direction. Returns the outlier rows.
pub fn add_tracker_noise(data: &mut Dataset, noise: &TrackerNoise) -> Vec<usize> {
    let mut rng = ChaCha8Rng::seed_from_u64(noise.seed);
    for i in 0..data.len() {
        for k in 0..3 {
            data.poses[(i, k)] +=
                noise.frame_offset_m[k] + noise.position_sigma_m * gaussian(&mut rng);
        }
        let e = Vector3::from_fn(|_, _| noise.angle_sigma_rad * gaussian(&mut rng));
        if noise.angle_sigma_rad > 0.0 {
            let p = &data.poses;
            let q = UnitQuaternion::from_quaternion(Quaternion::new(
                p[(i, 3)],
                p[(i, 4)],
                p[(i, 5)],
                p[(i, 6)],
            ));
            let mut q = (UnitQuaternion::from_scaled_axis(e) * q).into_inner();
            if q.w < 0.0 {
                q = -q;
            }
            for (k, x) in [q.w, q.i, q.j, q.k].into_iter().enumerate() {
                data.poses[(i, 3 + k)] = x;
            }
        }
    }
    add_outliers(data, noise)
}

/// The outlier part of [`add_tracker_noise`].
fn add_outliers(data: &mut Dataset, noise: &TrackerNoise) -> Vec<usize> {
    let count = (data.len() as f64 * noise.outlier_fraction.clamp(0.0, 1.0)).round() as usize;
    if count == 0 || noise.outlier_m == 0.0 {
        return Vec::new();
    }
    let mut rng = ChaCha8Rng::seed_from_u64(noise.seed ^ 0x0071_1e55);
    let mut rows = rand::seq::index::sample(&mut rng, data.len(), count).into_vec();
    rows.sort_unstable();
    for &i in &rows {
        let d = Vector3::from_fn(|_, _| gaussian(&mut rng));
        let d = d / d.norm().max(f64::MIN_POSITIVE);
        for k in 0..3 {
            data.poses[(i, k)] += noise.outlier_m * d[k];
        }
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    #[test]
    fn outliers_move_the_asked_fraction_by_the_asked_distance() {
        let clean = Dataset {
            n_tendons: 1,
            tensions: DMatrix::zeros(1000, 1),
            poses: DMatrix::from_fn(1000, 7, |_, j| if j == 3 { 1.0 } else { 0.0 }),
        };
        let mut data = clean.clone();
        let noise = TrackerNoise {
            position_sigma_m: 0.0,
            angle_sigma_rad: 0.0,
            frame_offset_m: [0.0; 3],
            seed: 5,
            outlier_fraction: 0.01,
            outlier_m: 0.005,
        };
        let rows = add_tracker_noise(&mut data, &noise);
        assert_eq!(rows.len(), 10);
        for i in 0..1000 {
            let moved = (0..3)
                .map(|k| data.poses[(i, k)].powi(2))
                .sum::<f64>()
                .sqrt();
            let expect = if rows.contains(&i) { 0.005 } else { 0.0 };
            assert!((moved - expect).abs() < 1e-12, "row {i}: {moved}");
        }
    }
}
