//! Where the quick stand-in net's samples come from: statics samples of
//! the poses the planner plans, the two-adjacent-tendon bend family of a
//! one-segment robot ([`quick_net`]) or tensions around the exact IK's along
//! the main job's loop runs of any robot ([`quick_net_for`]); the net is
//! fitted by [`crate::learn::quick`] on the ELM.

use nalgebra::Vector2;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::{bend_tensions, default_loop_runs, Family, PlanError, Trajectory};
use crate::statics::{Statics, WarmStart};

/// Largest perturbation of a pulling tendon around the loop runs'
/// tensions ([`quick_net_for`]), as a fraction of its range.
const PERTURBATION: f64 = 0.04;

/// A quick net for any robot, fitted where its loop runs go: a one-segment
/// robot's bend disc up to 6 N ([`quick_net`]); any other robot, `samples`
/// tension sets around the exact IK's tensions along the main job's loop
/// runs ([`default_loop_runs`]): a random point of a random
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
) -> Result<Vec<u8>, PlanError> {
    if Family::of(statics)?.dim() == 2 {
        return quick_net(statics, samples, hidden, 6.0, seed);
    }
    let robot = statics.robot();
    let (lo, hi) = (robot.min_tensions(), robot.max_tensions());
    let paths = default_loop_runs(statics)?
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
    set.fit(statics, hidden, 0.1, rng.random())
}

/// Fit a `.tnet` with `hidden` random units on `samples` poses whose bends
/// cover a disc of `max_bend` newtons. Deterministic for a given seed.
pub fn quick_net(
    statics: &Statics,
    samples: usize,
    hidden: usize,
    max_bend: f64,
    seed: u64,
) -> Result<Vec<u8>, PlanError> {
    // Samples on a spiral-ordered grid of bends so each solve warm-starts from a neighbour.
    let mut set = TrainingSet::with_capacity(samples);
    for i in 0..samples {
        let r = max_bend * ((i as f64 + 0.5) / samples as f64).sqrt();
        let a = i as f64 * 2.399_963_229_728_653; // golden angle: even coverage of the disc
        let bend = Vector2::new(r * a.cos(), r * a.sin());
        let tau = bend_tensions(statics, &bend);
        set.push(statics, tau)?;
    }
    set.fit(statics, hidden, 1.0, seed)
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
    fn push(&mut self, statics: &Statics, tau: Vec<f64>) -> Result<(), PlanError> {
        let sol = statics
            .solve(&tau, self.warm.as_ref())
            .or_else(|_| statics.solve(&tau, None))
            .map_err(|e| PlanError::Statics(format!("fixture statics: {e}")))?;
        self.warm = Some(sol.warm.clone());
        self.poses.push(sol.pose());
        self.tensions.push(tau);
        Ok(())
    }

    /// The stand-in net on these samples ([`crate::learn::quick::quick_net`]).
    fn fit(
        &self,
        statics: &Statics,
        hidden: usize,
        jitter: f64,
        seed: u64,
    ) -> Result<Vec<u8>, PlanError> {
        let max = statics.robot().max_tensions();
        Ok(crate::learn::quick::quick_net(
            &self.poses,
            &self.tensions,
            &max,
            hidden,
            jitter,
            seed,
        )?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::Lifter;
    use crate::robot::repo_robot;
    use crate::statics::repo_statics;

    #[test]
    fn quick_net_inverts_held_out_statics_to_a_few_millimetres() {
        let s = repo_statics("seed-4t.toml");
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
        let robot = repo_robot(file);
        let s = repo_statics(file);
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
        let s = repo_statics("tdcr-2seg.toml");
        let z = Lifter::new(&s)
            .unwrap()
            .mid_height([0.0, 0.0], 0.01)
            .unwrap();
        let points = [
            vec![0.01, 0.0, z],
            vec![-0.006, 0.007, z + 0.001],
            vec![0.0, -0.008, z - 0.001],
        ];
        check_quick_net_for("tdcr-2seg.toml", &points, 2e-3);
    }

    #[test]
    fn quick_net_for_a_one_tendon_robot_inverts_its_curve_to_millimetres() {
        check_quick_net_for("seed-1t.toml", &[vec![0.05], vec![0.07], vec![0.09]], 2e-3);
    }
}
