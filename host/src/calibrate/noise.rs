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
}

/// A standard normal draw (Box–Muller).
fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.random::<f64>().max(f64::MIN_POSITIVE);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

/// Apply `noise` to every pose of `data` in place: p ← p + t + σ_p ε,
/// q ← exp(σ_θ ε) ⊗ q (sign kept w ≥ 0).
pub fn add_tracker_noise(data: &mut Dataset, noise: &TrackerNoise) {
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
}
