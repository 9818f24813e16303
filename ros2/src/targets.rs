//! Targets from a ROS topic (`tendril-ros2 drive --target-topic`): a lab's
//! planner, a teleoperation node or an RViz click sends tip positions
//! (`geometry_msgs/PointStamped` on `target_point`, or the position of a
//! `geometry_msgs/PoseStamped` on `target_pose`), in place of tendril's
//! built-in path.
//!
//! Each accepted target is reached as the planner reaches its steps
//! (`docs/design.md` §6.4): a minimum-jerk move through the robot's
//! first-mode ZVD shaper, along a straight line in the coordinates of the
//! robot's family of reachable positions, each point lifted to the
//! reachable pose by the exact IK (its tangent sent for the correction),
//! then held. A target is refused and counted when it is not finite, is
//! in another frame than the tracker's, or is out of reach (its lifted
//! tip more than [`REACH_TOLERANCE_M`] from it).

use tendril::plan::{Family, Lifter, StepShaping};
use tendril::robot::{RigidMap, Robot};
use tendril::statics::{SolverSettings, Statics};
use tendril_shared::messages::{setpoint_flags, Header as MsgHeader, Setpoint};

use crate::msg::Point;
use crate::topics::frames;
use crate::Ros2Error;

/// A target whose nearest reachable tip is farther than this is refused, m.
pub const REACH_TOLERANCE_M: f64 = 1e-4;

/// Why a target was refused (the drive counts each).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refusal {
    /// A coordinate is NaN or infinite.
    NotFinite,
    /// The header names a frame other than the tracker's (or none).
    Frame,
    /// No reachable pose puts the tip there.
    OutOfReach,
}

/// A move from `from` to `to` (family coordinates, m; the poses there)
/// that began at `t0` s.
#[derive(Clone, Copy, Debug)]
struct Move {
    from: [f64; 3],
    to: [f64; 3],
    from_pose: [f64; 7],
    to_pose: [f64; 7],
    t0: f64,
}

/// Follows the newest accepted target.
pub struct TargetFollower {
    lifter: Lifter,
    family: Family,
    shaping: Option<StepShaping>,
    to_base: RigidMap,
    mv: Move,
    /// The setpoint last lifted (reused while holding).
    held: Setpoint,
    /// Whether `held` is the end of the current move.
    settled: bool,
}

impl TargetFollower {
    /// Start at the robot's rest (its pose at the floors), holding there.
    pub fn new(robot: &Robot, to_base: RigidMap) -> Result<TargetFollower, Ros2Error> {
        let statics = Statics::new(robot, SolverSettings::default());
        let cfg = |e: String| Ros2Error::Config(format!("targets from a topic: {e}"));
        let lifter = Lifter::new(&statics).map_err(|e| cfg(e.to_string()))?;
        let family = lifter.family();
        let rest = statics
            .solve(&robot.min_tensions(), None)
            .map_err(|e| cfg(format!("the robot at rest: {e}")))?
            .pose();
        let u = family.coordinates(&[rest[0], rest[1], rest[2]]);
        let shaping = StepShaping::for_robot(robot).ok();
        // The rest pose as it is (at the floors the exact IK has no
        // tangent there: tendons at their floors cannot move the tip
        // every way), held until the first target.
        Ok(TargetFollower {
            lifter,
            family,
            shaping,
            to_base,
            mv: Move {
                from: u,
                to: u,
                from_pose: rest,
                to_pose: rest,
                t0: 0.0,
            },
            held: plain_setpoint(&rest, setpoint_flags::HOLD),
            settled: true,
        })
    }

    /// Take a target at `t` s (the drive's path clock), in `frame`.
    pub fn offer(&mut self, p: &Point, frame: &str, t: f64) -> Result<(), Refusal> {
        let p = [p.x, p.y, p.z];
        if !p.iter().all(|v| v.is_finite()) {
            return Err(Refusal::NotFinite);
        }
        if frame != frames::TRACKER {
            return Err(Refusal::Frame);
        }
        let in_base = self.to_base.point(p);
        let u = self.family.coordinates(&in_base);
        let lifted = self
            .lifter
            .lifted(&u[..self.family.dim()])
            .map_err(|_| Refusal::OutOfReach)?;
        let reached = self
            .family
            .coordinates(&[lifted.pose[0], lifted.pose[1], lifted.pose[2]]);
        let miss = (0..self.family.dim())
            .map(|k| (reached[k] - u[k]).powi(2))
            .sum::<f64>();
        if miss.sqrt() > REACH_TOLERANCE_M {
            return Err(Refusal::OutOfReach);
        }
        // From where the move in progress is now: a new target mid-move
        // turns without a jump.
        let (now, _) = self.at(t);
        self.mv = Move {
            from: now,
            to: u,
            from_pose: self.held.pose.map(f64::from),
            to_pose: lifted.pose,
            t0: t,
        };
        self.settled = false;
        Ok(())
    }

    /// Coordinates at `t` and whether the move is over.
    fn at(&self, t: f64) -> ([f64; 3], bool) {
        let (s, done) = self.progress(t);
        let u = std::array::from_fn(|k| self.mv.from[k] + (self.mv.to[k] - self.mv.from[k]) * s);
        (u, done)
    }

    /// The move's fraction made at `t` and whether it is over.
    fn progress(&self, t: f64) -> (f64, bool) {
        match &self.shaping {
            Some(sh) => {
                let dt = t - self.mv.t0;
                (sh.progress(dt).0, dt >= sh.length_s())
            }
            None => (1.0, true),
        }
    }

    fn lift(&mut self, u: &[f64; 3], flags: u32) -> Result<Setpoint, Ros2Error> {
        let lifted = self
            .lifter
            .lifted(&u[..self.family.dim()])
            .map_err(|e| Ros2Error::Config(e.to_string()))?;
        let d = lifted.tangent;
        Ok(Setpoint {
            header: MsgHeader::default(),
            pose: lifted.pose.map(|v| v as f32),
            velocity: [0.0; 7],
            tangent: d.columns.map(|c| c.map(|v| v as f32)),
            tangent_axes: d.family.axes_padded().map(|a| a.map(|v| v as f32)),
            tangent_dim: d.family.dim() as u32,
            flags: flags | setpoint_flags::HAS_TANGENT,
            dynamic_offset: [0.0; 3],
            reserved: 0,
        })
    }

    /// The setpoint at `t` (model base frame, header empty): on the move,
    /// or the target held once it is over.
    pub fn setpoint(&mut self, t: f64) -> Setpoint {
        if self.settled {
            return self.held;
        }
        let (u, done) = self.at(t);
        let flags = if done {
            setpoint_flags::HOLD
        } else {
            setpoint_flags::MOVING
        };
        // Where the exact IK has no tangent (near the rest pose, where
        // tendons sit at their floors) the pose between the move's ends.
        self.held = match self.lift(&u, flags) {
            Ok(s) => s,
            Err(_) => {
                let (s, _) = self.progress(t);
                plain_setpoint(&between(&self.mv.from_pose, &self.mv.to_pose, s), flags)
            }
        };
        self.settled = done;
        self.held
    }

    /// The target's pose while it is held (for the tracking figures).
    pub fn holding(&self) -> Option<[f64; 7]> {
        self.settled.then(|| self.held.pose.map(f64::from))
    }
}

/// A setpoint at `pose` with no tangent (the correction then works on the
/// position alone).
fn plain_setpoint(pose: &[f64; 7], flags: u32) -> Setpoint {
    Setpoint {
        pose: pose.map(|v| v as f32),
        flags,
        ..Setpoint::default()
    }
}

/// The pose a fraction `s` from `a` to `b`: positions on the line, the
/// quaternion normalised along the shorter arc.
fn between(a: &[f64; 7], b: &[f64; 7], s: f64) -> [f64; 7] {
    let dot: f64 = (3..7).map(|k| a[k] * b[k]).sum();
    let sign = if dot < 0.0 { -1.0 } else { 1.0 };
    let mut p: [f64; 7] = std::array::from_fn(|k| {
        let bk = if k >= 3 { sign * b[k] } else { b[k] };
        a[k] + (bk - a[k]) * s
    });
    let n = (3..7).map(|k| p[k] * p[k]).sum::<f64>().sqrt();
    if n > 0.0 {
        (3..7).for_each(|k| p[k] /= n);
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn between_two_poses_is_on_the_line_with_a_unit_quaternion() {
        let a = [0.0, 0.0, 0.4, 1.0, 0.0, 0.0, 0.0];
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let b = [0.02, 0.0, 0.39, h, 0.0, h, 0.0];
        assert_eq!(between(&a, &b, 0.0), a);
        let m = between(&a, &b, 0.5);
        assert!((m[0] - 0.01).abs() < 1e-15 && (m[2] - 0.395).abs() < 1e-15);
        let n: f64 = (3..7).map(|k| m[k] * m[k]).sum();
        assert!((n - 1.0).abs() < 1e-12);
        // q and −q are one rotation: the shorter arc is taken.
        let neg = [0.02, 0.0, 0.39, -h, 0.0, -h, 0.0];
        assert!((between(&a, &neg, 0.5)[3] - m[3]).abs() < 1e-12);
    }

    #[test]
    fn targets_that_are_not_finite_elsewhere_or_out_of_reach_are_refused() {
        let robot = tendril::robot::repo_robot("seed-4t.toml");
        let mut f = TargetFollower::new(&robot, robot.base.to_base()).unwrap();
        let p = |x: f64, y: f64| Point { x, y, z: 0.0 };
        assert_eq!(
            f.offer(&p(f64::NAN, 0.0), frames::TRACKER, 0.0),
            Err(Refusal::NotFinite)
        );
        assert_eq!(f.offer(&p(0.01, 0.0), "map", 0.0), Err(Refusal::Frame));
        assert_eq!(
            f.offer(&p(0.5, 0.0), frames::TRACKER, 0.0),
            Err(Refusal::OutOfReach)
        );
        assert!(f.holding().is_some(), "a refused target leaves the hold");
        assert_eq!(f.offer(&p(0.01, 0.005), frames::TRACKER, 1.0), Ok(()));
        // The shaped move ends on the lifted target and holds it.
        let end = f.setpoint(10.0);
        assert_ne!(end.flags & setpoint_flags::HOLD, 0);
        assert!(
            (f64::from(end.pose[0]) - 0.01).abs() < 1e-6,
            "{:?}",
            end.pose
        );
        assert!(
            (f64::from(end.pose[1]) - 0.005).abs() < 1e-6,
            "{:?}",
            end.pose
        );
        assert!(f.holding().is_some());
    }
}
