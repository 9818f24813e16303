//! A quickly fitted IK net for exercising the loop when no trained model is
//! at hand (HIL tests, benchmarks): random symmetric-sigmoid hidden units
//! (an extreme-learning-machine layer, stored as a cascade net whose hidden
//! units ignore each other) with ridge-fitted linear outputs, trained on
//! statics samples of the poses the planner plans: the two-adjacent-tendon
//! bend family of a one-segment robot ([`quick_net`]), or lifted points of
//! any robot's family around the main job's loop runs ([`quick_net_for`]).
//! Seconds of work; millimetre-class accuracy, which is what the
//! correction loop is there to remove. The real model comes from
//! `tendril train`.

use nalgebra::{DMatrix, Vector2};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tendril_shared::{encode_to_vec, Activation, NetShape, TnetView};

use super::trajectory::Trajectory;
use super::IpcError;
use crate::kinematics::{bend_tensions, Family};
use crate::statics::{Statics, WarmStart};

/// Jittered copies of each training pose (see [`quick_net`]).
const JITTER_COPIES: usize = 3;

/// Largest perturbation of a pulling tendon around the loop runs'
/// tensions ([`quick_net_for`]), as a fraction of its range.
const PERTURBATION: f64 = 0.04;

/// A quick net for any robot, fitted where its loop runs go: a one-segment
/// robot's bend disc up to 6 N ([`quick_net`]); any other robot, `samples`
/// tension sets around the exact IK's tensions along the main job's loop
/// runs ([`super::sim::default_loop_runs`]): a random point of a random
/// run, each tendon that pulls there moved by up to ± [`PERTURBATION`] of
/// its range, the slack ones left slack (so the samples stay on the lift's
/// branch: a two-segment robot reaches a point by several S shapes, and a
/// fit across them averages tensions of different shapes). Deterministic
/// for a given seed.
pub fn quick_net_for(
    statics: &Statics,
    samples: usize,
    hidden: usize,
    seed: u64,
) -> Result<Vec<u8>, IpcError> {
    if Family::of(statics)?.dim() == 2 {
        return quick_net(statics, samples, hidden, 6.0, seed);
    }
    let robot = statics.robot();
    let (lo, hi) = (robot.min_tensions(), robot.max_tensions());
    let paths = super::sim::default_loop_runs(statics)?
        .iter()
        .map(|run| Trajectory::new(&run.shape, statics))
        .collect::<Result<Vec<_>, _>>()?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut set = TrainingSet::with_capacity(samples);
    let mut reference = Vec::new();
    for i in 0..samples {
        let path = &paths[i % paths.len()];
        // Along the path in order (short warm steps), a random offset each.
        let t = path.duration().max(1.0) * (i / paths.len()) as f64
            / (samples / paths.len()).max(1) as f64;
        path.feedforward(t, &mut reference);
        let tau: Vec<f64> = reference
            .iter()
            .enumerate()
            .map(|(k, &r)| {
                let pulls = r > lo[k] + 1e-6;
                let d = PERTURBATION * (hi[k] - lo[k]) * (2.0 * rng.random::<f64>() - 1.0);
                if pulls {
                    (r + d).clamp(lo[k], hi[k])
                } else {
                    r
                }
            })
            .collect();
        set.push(statics, tau)?;
    }
    fit(statics, &set.poses, &set.tensions, hidden, 0.1, &mut rng)
}

/// Fit a `.tnet` with `hidden` random units on `samples` poses whose bends
/// cover a disc of `max_bend` newtons. Deterministic for a given seed.
pub fn quick_net(
    statics: &Statics,
    samples: usize,
    hidden: usize,
    max_bend: f64,
    seed: u64,
) -> Result<Vec<u8>, IpcError> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // Samples on a spiral-ordered grid of bends so each solve warm-starts from a neighbour.
    let mut set = TrainingSet::with_capacity(samples);
    for i in 0..samples {
        let r = max_bend * ((i as f64 + 0.5) / samples as f64).sqrt();
        let a = i as f64 * 2.399_963_229_728_653; // golden angle: even coverage of the disc
        let bend = Vector2::new(r * a.cos(), r * a.sin());
        let tau = bend_tensions(statics, &bend);
        set.push(statics, tau)?;
    }
    fit(statics, &set.poses, &set.tensions, hidden, 1.0, &mut rng)
}

/// Solved training samples, each warm-started from the one before (cold
/// when that fails).
struct TrainingSet {
    poses: Vec<[f64; 7]>,
    tensions: Vec<Vec<f64>>,
    warm: Option<WarmStart>,
}

impl TrainingSet {
    fn with_capacity(n: usize) -> TrainingSet {
        TrainingSet {
            poses: Vec::with_capacity(n),
            tensions: Vec::with_capacity(n),
            warm: None,
        }
    }

    /// Solve the statics of `tau` and keep the pose and tensions.
    fn push(&mut self, statics: &Statics, tau: Vec<f64>) -> Result<(), IpcError> {
        let sol = statics
            .solve(&tau, self.warm.as_ref())
            .or_else(|_| statics.solve(&tau, None))
            .map_err(|e| IpcError::Other(format!("fixture statics: {e}")))?;
        self.warm = Some(sol.warm.clone());
        self.poses.push(sol.pose());
        self.tensions.push(tau);
        Ok(())
    }
}

/// The random-feature fit of `tensions` on `poses` (module docs), with
/// jittered copies of each pose (`jitter` scales the jitter).
fn fit(
    statics: &Statics,
    poses: &[[f64; 7]],
    tensions: &[Vec<f64>],
    hidden: usize,
    jitter: f64,
    rng: &mut ChaCha8Rng,
) -> Result<Vec<u8>, IpcError> {
    let n = statics.robot().n_tendons();
    let mut xs: Vec<[f64; 7]> = Vec::with_capacity(poses.len() * (1 + JITTER_COPIES));
    let mut ys: Vec<Vec<f64>> = Vec::with_capacity(poses.len() * (1 + JITTER_COPIES));
    for (&pose, tau) in poses.iter().zip(tensions) {
        // The pose has 7 numbers but the robot only k degrees of freedom, so
        // the data lie on a k-dimensional set and a plain fit is free to do
        // anything off it — where the correction loop's shifted setpoints
        // land when the tangent is off. Jittered copies, with the
        // orientation far noisier than the position, make the net vary
        // smoothly off the set and key on the position.
        xs.push(pose);
        ys.push(tau.clone());
        for _ in 0..JITTER_COPIES {
            let mut p = pose;
            for (k, v) in p.iter_mut().enumerate() {
                let sd = jitter * if k < 3 { 2e-4 } else { 1e-2 };
                *v += sd * (rng.random::<f64>() * 2.0 - 1.0) * 3f64.sqrt();
            }
            xs.push(p);
            ys.push(tau.clone());
        }
    }
    let samples = xs.len();
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
    let out_hi: Vec<f64> = statics.robot().max_tensions();
    let shape = NetShape {
        inputs: 7,
        hidden,
        outputs: n,
    };
    // Hidden rows: bias + 7 inputs + (k earlier units, zero).
    let mut hidden_w = vec![0.0f32; shape.hidden_weight_count()];
    let mut w_in = DMatrix::<f64>::zeros(hidden, 8);
    for k in 0..hidden {
        for j in 0..8 {
            w_in[(k, j)] = rng.random_range(-4.0..4.0);
        }
        let off = shape.hidden_row_offset(k);
        for j in 0..8 {
            hidden_w[off + j] = w_in[(k, j)] as f32;
        }
    }
    // Features: [1, x̂, h(x̂)] as the f32 inference will see them.
    let cols = 1 + 7 + hidden;
    let mut f = DMatrix::<f64>::zeros(samples, cols);
    for (i, x) in xs.iter().enumerate() {
        let xn: Vec<f64> = (0..7)
            .map(|k| ((x[k] - lo[k]) / (hi[k] - lo[k])) as f32 as f64)
            .collect();
        f[(i, 0)] = 1.0;
        for k in 0..7 {
            f[(i, 1 + k)] = xn[k];
        }
        for k in 0..hidden {
            let s = w_in[(k, 0)] + (0..7).map(|j| w_in[(k, 1 + j)] * xn[j]).sum::<f64>();
            f[(i, 8 + k)] = Activation::SymmetricSigmoid.apply(s as f32) as f64;
        }
    }
    let y = DMatrix::from_fn(samples, n, |i, o| ys[i][o] / out_hi[o]);
    let mut gram = f.transpose() * &f;
    for d in 0..cols {
        gram[(d, d)] += 1e-6 * samples as f64;
    }
    let rhs = f.transpose() * y;
    let w = gram
        .cholesky()
        .ok_or_else(|| IpcError::Other("fixture: singular ridge system".into()))?
        .solve(&rhs);
    let mut output_w = vec![0.0f32; shape.output_weight_count()];
    for o in 0..n {
        for c in 0..cols {
            output_w[o * cols + c] = w[(c, o)] as f32;
        }
    }
    let f32s = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
    let (ilo, ihi, olo, ohi) = (f32s(&lo), f32s(&hi), vec![0.0f32; n], f32s(&out_hi));
    let view = TnetView {
        shape,
        hidden_activation: Activation::SymmetricSigmoid,
        output_activation: Activation::Linear,
        input_lo: &ilo,
        input_hi: &ihi,
        output_lo: &olo,
        output_hi: &ohi,
        hidden_weights: &hidden_w,
        output_weights: &output_w,
    };
    encode_to_vec(&view).map_err(|e| IpcError::Other(format!("fixture: encoding the net: {e:?}")))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::Lifter;
    use crate::robot::Robot;
    use crate::statics::SolverSettings;
    use std::path::Path;

    #[test]
    fn quick_net_inverts_held_out_statics_to_a_few_millimetres() {
        let robot =
            Robot::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../robots/seed-4t.toml"))
                .unwrap();
        let s = Statics::new(&robot, SolverSettings::default());
        let blob = quick_net(&s, 1500, 48, 6.0, 3).unwrap();
        let net = tendril_shared::McuNet::decode(&blob).unwrap();
        // Held-out bends (not on the training spiral): predicted tensions,
        // run forward through the statics, must land near the pose's tip.
        let mut worst: f64 = 0.0;
        for (bx, by) in [(1.3, 0.4), (-2.2, 1.7), (0.3, -3.1), (-1.0, -1.0)] {
            let tau = bend_tensions(&s, &Vector2::new(bx, by));
            let pose = s.solve(&tau, None).unwrap().pose().map(|v| v as f32);
            let pred = tendril_firmware::infer(&net, &pose);
            let pred: Vec<f64> = pred[..4]
                .iter()
                .map(|&v| (v as f64).clamp(0.0, 10.0))
                .collect();
            let tip = s.solve(&pred, None).unwrap().position;
            let err = ((tip.x - pose[0] as f64).powi(2) + (tip.y - pose[1] as f64).powi(2)).sqrt();
            worst = worst.max(err);
        }
        assert!(worst < 3e-3, "worst task-space error {worst} m");
        // A 2 mm sideways shift of the pose alone (z and orientation kept, as
        // the correction loop does) must move the predicted tip by roughly
        // 2 mm in that direction, not anywhere.
        let tau = bend_tensions(&s, &Vector2::new(-1.0, 0.5));
        let pose = s.solve(&tau, None).unwrap().pose().map(|v| v as f32);
        let mut shifted = pose;
        shifted[0] -= 0.002;
        let pred = tendril_firmware::infer(&net, &shifted);
        let pred: Vec<f64> = pred[..4]
            .iter()
            .map(|&v| (v as f64).clamp(0.0, 10.0))
            .collect();
        let tip = s.solve(&pred, None).unwrap().position;
        let dx = tip.x - pose[0] as f64;
        assert!(
            (dx + 0.002).abs() < 1e-3 && (tip.y - pose[1] as f64).abs() < 1e-3,
            "moved by {dx}, {}",
            tip.y - pose[1] as f64
        );
    }

    /// Task-space error of the net at lifted points off its training set:
    /// predicted tensions, run forward through the statics, land within
    /// `bound` m of the point.
    fn check_quick_net_for(file: &str, points: &[Vec<f64>], bound: f64) {
        let robot = Robot::load(
            &Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../robots")
                .join(file),
        )
        .unwrap();
        let s = Statics::new(&robot, SolverSettings::default());
        let n = robot.n_tendons();
        let blob = quick_net_for(&s, 1000, 48, 5).unwrap();
        let net = tendril_shared::McuNet::decode(&blob).unwrap();
        let mut lifter = Lifter::new(&s).unwrap();
        let mut worst: f64 = 0.0;
        for u in points {
            let pose = lifter.lift(u).unwrap().map(|v| v as f32);
            let pred = tendril_firmware::infer(&net, &pose);
            let pred: Vec<f64> = pred[..n]
                .iter()
                .zip(robot.max_tensions())
                .map(|(&v, max)| (v as f64).clamp(0.0, max))
                .collect();
            let tip = s.solve(&pred, None).unwrap().position;
            let err = (0..3)
                .map(|k| (tip[k] - pose[k] as f64).powi(2))
                .sum::<f64>()
                .sqrt();
            worst = worst.max(err);
        }
        assert!(worst < bound, "{file}: worst task-space error {worst} m");
    }

    #[test]
    fn quick_net_for_a_two_segment_robot_inverts_its_volume_to_millimetres() {
        let robot =
            Robot::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../robots/tdcr-2seg.toml"))
                .unwrap();
        let s = Statics::new(&robot, SolverSettings::default());
        let z = Lifter::new(&s)
            .unwrap()
            .mid_height([0.0, 0.0], 0.01)
            .unwrap();
        let points = [
            vec![0.01, 0.0, z],
            vec![-0.006, 0.007, z + 0.002],
            vec![0.0, -0.008, z - 0.002],
        ];
        check_quick_net_for("tdcr-2seg.toml", &points, 2e-3);
    }

    #[test]
    fn quick_net_for_a_one_tendon_robot_inverts_its_curve_to_millimetres() {
        check_quick_net_for("seed-1t.toml", &[vec![0.05], vec![0.07], vec![0.09]], 2e-3);
    }
}
