//! A quickly fitted stand-in IK net for exercising the loop when no trained
//! model is at hand (`tendril sim --quick-model`, HIL tests, benchmarks): an
//! extreme learning machine ([`Elm`], one fixed width, its ridge and weight
//! scale chosen from a few) on given pose → tension samples with jittered copies of each
//! pose, exported as a `.tnet`. Seconds of work; millimetre-class accuracy,
//! which is what the correction loop is there to remove. The real model
//! comes from `tendril train`; where the samples come from is the caller's
//! (`plan::stand_in`).

use nalgebra::DMatrix;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::elm::Elm;
use super::{LearnError, Learner, Split};

/// Jittered copies of each training pose.
pub const JITTER_COPIES: usize = 3;

/// Candidate ridge factors of the fit (relative to the Gram matrix's mean
/// diagonal).
const RIDGES: [f64; 3] = [1e-10, 1e-8, 1e-6];

/// Candidate input-weight scales of the random layer (on inputs normalised
/// to [0, 1]): the small ones keep units near their linear range, which the
/// map from position to tension mostly is.
const SCALES: [f64; 4] = [1.0, 2.0, 4.0, 8.0];

/// Fit a `.tnet` of `hidden` random units mapping `poses` to `tensions`
/// (N, outputs scaled by `max_tensions`), with [`JITTER_COPIES`] jittered
/// copies of each pose (`jitter` scales the jitter). Deterministic for a
/// given seed.
pub fn quick_net(
    poses: &[[f64; 7]],
    tensions: &[Vec<f64>],
    max_tensions: &[f64],
    hidden: usize,
    jitter: f64,
    seed: u64,
) -> Result<Vec<u8>, LearnError> {
    let n = max_tensions.len();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut xs: Vec<[f64; 7]> = Vec::with_capacity(poses.len() * (1 + JITTER_COPIES));
    let mut ys: Vec<&[f64]> = Vec::with_capacity(poses.len() * (1 + JITTER_COPIES));
    for (&pose, tau) in poses.iter().zip(tensions) {
        // The pose has 7 numbers but the robot only k degrees of freedom, so
        // the data lie on a k-dimensional set and a plain fit is free to do
        // anything off it — where the correction loop's shifted setpoints
        // land when the tangent is off. Jittered copies, with the
        // orientation far noisier than the position, make the net vary
        // smoothly off the set and key on the position.
        xs.push(pose);
        ys.push(tau);
        for _ in 0..JITTER_COPIES {
            let mut p = pose;
            for (k, v) in p.iter_mut().enumerate() {
                let sd = jitter * if k < 3 { 2e-4 } else { 1e-2 };
                *v += sd * (rng.random::<f64>() * 2.0 - 1.0) * 3f64.sqrt();
            }
            xs.push(p);
            ys.push(tau);
        }
    }
    let lo: Vec<f64> = (0..7)
        .map(|k| xs.iter().map(|x| x[k]).fold(f64::INFINITY, f64::min))
        .collect();
    let hi: Vec<f64> = (0..7)
        .map(|k| {
            let h = xs.iter().map(|x| x[k]).fold(f64::NEG_INFINITY, f64::max);
            if h - lo[k] < 1e-9 {
                lo[k] + 1.0
            } else {
                h
            }
        })
        .collect();
    // Inputs as the f32 inference will see them.
    let x = DMatrix::from_fn(xs.len(), 7, |i, k| {
        ((xs[i][k] - lo[k]) / (hi[k] - lo[k])) as f32 as f64
    });
    let y = DMatrix::from_fn(xs.len(), n, |i, o| ys[i][o] / max_tensions[o]);
    let split = Split { x: &x, y: &y };
    // One width, a few ridges and scales chosen on the samples themselves:
    // `hidden` units on thousands of rows can hardly over-fit, so the
    // training error is a fair judge.
    let mut elm = Elm::with_grid(vec![hidden], RIDGES.to_vec(), SCALES.to_vec());
    elm.fit(split, split, rng.random())?;
    elm.to_tnet(&lo, &hi, &vec![0.0; n], max_tensions)
}
