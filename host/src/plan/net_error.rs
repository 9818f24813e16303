//! The net's own error along a planned path, taken out before the loop
//! sees it (`docs/design.md` §6.4, "The net's error along the path").
//!
//! A learned net is not the exact inverse: on `tdcr-2seg` its tensions put
//! the tip 0.11 mm off the steps' first target, on `tdcr-3seg` 0.15 mm off
//! on average. The loop's integral removes such an error only once it has
//! seen a target, after the quiet that follows a move, at a gain the rod's
//! mode caps; at a new target the error stands until then. But the planner
//! knows its path ahead and has the robot's exact statics: where the net's
//! tensions put the tip, at every pose of the path, is a forward solve
//! away. The offset that cancels it is sent through the channel the
//! controller already applies beside the period (`Setpoint::
//! dynamic_offset`), so the period's error stays the error against the
//! planner's pose, and the chip in the loop runs the same.

use super::{along_axes, PosePoint, Trajectory};
use crate::statics::Statics;

/// Refinements of the offset: the first cancels the error where the net
/// is asked for the pose, the second where it is asked for the pose plus
/// the first offset (the net's error varies little over 0.1 mm).
const PASSES: usize = 2;

/// Offsets larger than this per axis are not sent, m: a net this far off
/// is not one the loop should be trusting, and the offset is a small
/// correction by design.
pub const MAX_NET_ERROR_OFFSET: f64 = 2e-3;

/// The offset that cancels the net's quasi-static error at every pose of a
/// trajectory, along its tangent axes (m; the position's x, y, z for a
/// pose without a tangent), one row per pose.
#[derive(Clone, Debug)]
pub struct NetErrorOffset {
    rows: Vec<Vec<f64>>,
    /// The largest error found, m (for the planner's report).
    worst_m: f64,
    /// Rows whose statics did not solve: they send no offset.
    unsolved: usize,
}

impl NetErrorOffset {
    /// The offsets for `trajectory` with `tensions_for`, the tensions the
    /// controller commands for a pose in a steady state (the net's output
    /// through the period's command stage), and `statics` the robot's exact
    /// statics: d ← d − axes(FK(net(p + Σ d_j T_j)) − p), twice from d = 0.
    pub fn along(
        trajectory: &Trajectory,
        statics: &Statics,
        mut tensions_for: impl FnMut(&[f64; 7]) -> Vec<f64>,
    ) -> NetErrorOffset {
        let mut rows = Vec::with_capacity(trajectory.poses.len());
        let mut worst_m: f64 = 0.0;
        let mut unsolved = 0;
        let mut warm = None;
        for (i, pose) in trajectory.poses.iter().enumerate() {
            let point = PosePoint {
                pose: *pose,
                velocity: [0.0; 7],
                tangent: trajectory.tangents.get(i).copied(),
            };
            let mut d = [0.0; 3];
            for pass in 0..PASSES {
                let asked = shifted(&point, &d);
                let tensions = tensions_for(&asked);
                // A row whose statics fail sends no offset (the offset is a
                // refinement; the path goes on without it there).
                let Ok(solution) = statics.solve(&tensions, warm.as_ref()) else {
                    d = [f64::NAN; 3];
                    unsolved += 1;
                    warm = None;
                    break;
                };
                let error: [f64; 3] = std::array::from_fn(|k| solution.position[k] - pose[k]);
                if pass == 0 {
                    worst_m = worst_m.max(error.iter().map(|e| e * e).sum::<f64>().sqrt());
                }
                let along = along_axes(&point, error);
                for (dk, ek) in d.iter_mut().zip(along) {
                    *dk -= ek;
                }
                warm = Some(solution.warm);
            }
            let usable = d
                .iter()
                .all(|v| v.is_finite() && v.abs() <= MAX_NET_ERROR_OFFSET);
            rows.push(if usable { d.to_vec() } else { vec![0.0; 3] });
        }
        NetErrorOffset {
            rows,
            worst_m,
            unsolved,
        }
    }

    /// The offset at the trajectory's own time `t_path` (s), interpolated
    /// as the poses are (along a shaped step under way too).
    pub fn at(&self, trajectory: &Trajectory, t_path: f64) -> [f64; 3] {
        let mut out = [0.0; 3];
        trajectory.blend_into(&self.rows, t_path, &mut out);
        out
    }

    /// The first pose's offset as a shift of the whole pose (m and
    /// quaternion units): where the approach from rest should end, so
    /// that the net is asked for the same pose when the hold begins.
    pub fn first_shift(&self, trajectory: &Trajectory) -> [f64; 7] {
        let point = PosePoint {
            pose: trajectory.poses[0],
            velocity: [0.0; 7],
            tangent: trajectory.tangents.first().copied(),
        };
        let d = self.rows.first().map_or([0.0; 3], |r| [r[0], r[1], r[2]]);
        let s = shifted(&point, &d);
        std::array::from_fn(|k| s[k] - point.pose[k])
    }

    /// The largest error of the net along the path, m.
    pub fn worst_m(&self) -> f64 {
        self.worst_m
    }

    /// How many of the path's rows send no offset because their statics
    /// did not solve.
    pub fn unsolved(&self) -> usize {
        self.unsolved
    }
}

/// `point`'s pose moved by the offset `d` as the controller moves it
/// (`ipc::controller::with_dynamic_offset`): Σ_j d_j T_j along the
/// tangent, the position by d without one.
pub(crate) fn shifted(point: &PosePoint, d: &[f64; 3]) -> [f64; 7] {
    let mut pose = point.pose;
    match point.tangent {
        Some(t) => {
            for (column, dj) in t.columns.iter().zip(d).take(t.family.dim()) {
                for (p, c) in pose.iter_mut().zip(column) {
                    *p += c * dj;
                }
            }
        }
        None => {
            for (p, dk) in pose.iter_mut().zip(d) {
                *p += dk;
            }
        }
    }
    pose
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::PathShape;
    use crate::statics::repo_statics;

    /// Against an independent fact, the exact statics: a "net" that is the
    /// trajectory's own exact-IK tensions (what a perfect net commands) with
    /// a known error — every tension 2 % high — puts the tip 0.2–0.6 mm
    /// off the circle; asked for the pose moved by the offset, the same
    /// erring net puts the tip back on the circle to a micron (each of the
    /// two passes leaves the error's change over the previous offset: a
    /// net 5 % high is left 1.8 µm off).
    /// The erring net is the exact IK of the asked pose (solved from the
    /// tensions of the pose before, so it follows one branch) times the
    /// error: a net whose error is a smooth function of the pose.
    #[test]
    fn the_offset_puts_an_erring_nets_tip_back_on_the_path() {
        let statics = repo_statics("seed-4t.toml");
        let traj = Trajectory::new(&PathShape::default_circle(), &statics).unwrap();
        let ik = crate::inverse::ExactIk::new(statics.robot(), Default::default());
        let mut start: Option<Vec<f64>> = None;
        let mut erring = |pose: &[f64; 7]| {
            let target = crate::inverse::Target::from_pose(pose, true).unwrap();
            // A pose moved along the family's tangent is off the reachable
            // surface in its second order (< 1 µm): the closest answer then.
            let answer = match ik.solve(&target, start.as_deref(), None) {
                Ok(a) => a,
                Err(crate::inverse::InverseError::Unreachable { closest, .. }) => *closest,
                Err(e) => panic!("{e}"),
            };
            start = Some(answer.tensions.clone());
            answer
                .tensions
                .iter()
                .map(|t| 1.02 * t)
                .collect::<Vec<f64>>()
        };
        let every = 25;
        let sub = Trajectory {
            times: traj.times.iter().step_by(every).copied().collect(),
            poses: traj.poses.iter().step_by(every).copied().collect(),
            tangents: traj.tangents.iter().step_by(every).copied().collect(),
            feedforward: traj.feedforward.iter().step_by(every).cloned().collect(),
            feedforward_miss: traj
                .feedforward_miss
                .iter()
                .step_by(every)
                .copied()
                .collect(),
            ..traj.clone()
        };
        let offsets = NetErrorOffset::along(&sub, &statics, &mut erring);
        assert_eq!(offsets.unsolved(), 0);
        assert!(
            offsets.worst_m() > 2e-4,
            "the erring net is {} m off",
            offsets.worst_m()
        );
        for (i, pose) in sub.poses.iter().enumerate() {
            let point = PosePoint {
                pose: *pose,
                velocity: [0.0; 7],
                tangent: sub.tangents.get(i).copied(),
            };
            let d = [offsets.rows[i][0], offsets.rows[i][1], offsets.rows[i][2]];
            let asked = shifted(&point, &d);
            let tip = statics.solve(&erring(&asked), None).unwrap().position;
            let miss = (0..3)
                .map(|k| (tip[k] - pose[k]).powi(2))
                .sum::<f64>()
                .sqrt();
            assert!(miss < 1e-6, "pose {i}: the corrected tip is {miss} m off");
        }
    }
}
