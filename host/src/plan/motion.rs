//! What the planner asks for at each instant of its clock
//! (`docs/design.md` §6.4): the settle hold (or the shaped approach from
//! rest to the first pose), then the trajectory on its eased clock, and the
//! offset the rod's dynamics need on top of it (the modal inverse).

use super::net_error::NetErrorOffset;
use super::shaping::{ModalInverse, StepShaping};
use super::turning_offset::TurningOffset;
use super::{PosePoint, Trajectory};

/// The desired point at one instant of the planner's clock.
#[derive(Clone, Copy, Debug)]
pub struct Desired {
    /// Pose, velocity (on the planner's clock) and tangent.
    pub point: PosePoint,
    /// The trajectory's own time (for its feed-forward tensions), s.
    pub t_path: f64,
    /// In the settle hold (or the approach): not part of the path.
    pub holding: bool,
    /// On a shaped move between targets (a step, the approach).
    pub moving: bool,
    /// `point.velocity` is the motion's (false in a plain hold).
    pub has_velocity: bool,
}

/// The largest dynamic offset sent, per axis (m): a path with corners (a pose table) has accelerations the
/// modal inverse would turn into kicks; an offset this size is a
/// 0.5 s⁻² · 4 m/s² path, far beyond the loop runs (tens of µm).
pub const MAX_DYNAMIC_OFFSET: f64 = 2e-3;

/// Time step of the offset's central differences, s: short against the
/// shaped moves (≥ 70 ms), long against the trajectory table's 10 ms rows.
const DIFFERENCE_S: f64 = 0.01;

/// The planner's motion: the trajectory with its settle hold, the optional
/// approach from rest and the optional modal inverse.
#[derive(Clone, Debug)]
pub struct Motion {
    trajectory: Trajectory,
    settle_s: f64,
    approach: Option<(StepShaping, [f64; 7])>,
    /// Where the approach ends, relative to the first pose: the offset the
    /// hold then sends (`plan::net_error`), so that the net is asked for
    /// the same pose on either side of the approach's end.
    approach_end_shift: [f64; 7],
    inverse: Option<ModalInverse>,
    /// The offset that takes the net's own error out (`plan::net_error`).
    net_error: Option<NetErrorOffset>,
    /// The offset learned on the model for a circle (`plan::turning_offset`).
    turning: Option<TurningOffset>,
    /// Where the approach ends for the turning offset, beside
    /// `approach_end_shift`: the hold sends the offset at the path's start.
    turning_shift: [f64; 7],
}

impl Motion {
    /// `trajectory` after a settle hold of `settle_s`; approached from the
    /// pose `rest` by the trajectory's shaping when both are given; with
    /// the dynamic offset of `inverse` when given.
    pub fn new(
        trajectory: Trajectory,
        settle_s: f64,
        rest: Option<[f64; 7]>,
        inverse: Option<ModalInverse>,
    ) -> Motion {
        let approach = trajectory.shaping().zip(rest);
        Motion {
            trajectory,
            settle_s,
            approach,
            approach_end_shift: [0.0; 7],
            inverse,
            net_error: None,
            turning: None,
            turning_shift: [0.0; 7],
        }
    }

    /// With the offset learned on the model for the path: sent in the hold
    /// (its value at the path's start) and on the path, not on shaped
    /// moves; the approach from rest ends where it puts the first pose, so
    /// that it does not step in when the path starts (a step rings the
    /// rod's mode, which on the three-segment robot decays over seconds).
    pub fn with_turning_offset(self, turning: TurningOffset) -> Motion {
        let point = self.trajectory.sample(0.0);
        let p = point.pose;
        let d = along_axes(&point, turning.at(0.0, [p[0], p[1], p[2]]));
        let shifted = super::net_error::shifted(&point, &d);
        Motion {
            turning: Some(turning),
            turning_shift: std::array::from_fn(|k| shifted[k] - p[k]),
            ..self
        }
    }

    /// The learned turning offset for `now`, m along the point's tangent
    /// axes (none without one and on shaped moves; in the hold, its value
    /// at the path's start).
    pub fn turning_offset(&self, now: &Desired) -> Option<[f64; 3]> {
        let turning = self.turning.as_ref()?;
        if now.moving {
            return None;
        }
        let p = &now.point.pose;
        Some(along_axes(
            &now.point,
            turning.at(now.t_path, [p[0], p[1], p[2]]),
        ))
    }

    /// The error the loop had on the model at `t` with the learned
    /// turning offset, base frame, m: on the path the table's
    /// ([`TurningOffset::expected_error`]); in the hold after the approach,
    /// the offset's value at the path's start, which the hold sends and
    /// the tip then holds; zero without a table and on a move.
    pub fn expected_error(&self, t: f64, now: &Desired) -> [f64; 3] {
        let Some(turning) = &self.turning else {
            return [0.0; 3];
        };
        let p = now.point.pose;
        let p = [p[0], p[1], p[2]];
        match (now.holding, now.moving) {
            (false, _) => turning.expected_error(t - self.settle_s, now.t_path, p),
            (true, false) => turning.at(0.0, p).map(|v| -v),
            (true, true) => [0.0; 3],
        }
    }

    /// With the offset that takes the net's own error out along the path:
    /// sent in the hold and on the path; the approach from rest, which
    /// sends none, ends where it puts the first pose.
    pub fn with_net_error(self, net_error: NetErrorOffset) -> Motion {
        let shift = net_error.first_shift(&self.trajectory);
        Motion {
            net_error: Some(net_error),
            ..self.with_approach_end_shift(shift)
        }
    }

    /// The approach from rest ends at the first pose moved by `shift`
    /// (position m, quaternion components) instead of at the first pose.
    fn with_approach_end_shift(mut self, shift: [f64; 7]) -> Motion {
        self.approach_end_shift = shift;
        self
    }

    /// The net's error offset for `now` (none without one, and none on the
    /// approach from rest: its setpoints have no tangent to carry it, and
    /// it ends where the offset puts the pose instead), m along the point's
    /// tangent axes.
    pub fn net_error_offset(&self, now: &Desired) -> Option<[f64; 3]> {
        let net_error = self.net_error.as_ref()?;
        (!(now.holding && now.moving)).then(|| net_error.at(&self.trajectory, now.t_path))
    }

    /// The trajectory followed.
    pub fn trajectory(&self) -> &Trajectory {
        &self.trajectory
    }

    /// What is asked for `t` s after the planner started.
    pub fn at(&self, t: f64) -> Desired {
        if t < self.settle_s {
            let mut point = self.trajectory.sample(0.0);
            point.velocity = [0.0; 7];
            let moving = match &self.approach {
                // The approach ends where the hold's offset puts the pose;
                // the hold itself sends the first pose and the offset.
                Some((shaping, rest)) if t.max(0.0) < shaping.length_s() => {
                    for ((p, d), e) in (point.pose.iter_mut())
                        .zip(&self.approach_end_shift)
                        .zip(&self.turning_shift)
                    {
                        *p += d + e;
                    }
                    approach(shaping, rest, t.max(0.0), &mut point)
                }
                _ => false,
            };
            return Desired {
                point,
                t_path: 0.0,
                holding: true,
                moving,
                has_velocity: moving,
            };
        }
        let (t_path, pace) = self.trajectory.path_clock(t - self.settle_s);
        let mut point = self.trajectory.sample(t_path);
        for v in &mut point.velocity {
            *v *= pace;
        }
        Desired {
            point,
            t_path,
            holding: false,
            moving: self.trajectory.moving(t_path),
            has_velocity: true,
        }
    }

    /// The offset the rod's dynamics need at `t` (none without an
    /// inverse), m along the point's tangent axes (the position's x, y, z
    /// without a tangent), as the controller's correction moves a pose: the
    /// modal inverse of the motion's velocity and acceleration by central
    /// differences over ±10 ms, projected on the axes and clamped to
    /// ±[`MAX_DYNAMIC_OFFSET`]. The tangent carries it to the orientation
    /// and the rest of the pose as the robot's own statics do. Zero on a shaped move (a step,
    /// the approach) and in a hold: the shaper already leaves the mode
    /// alone there, and its moves, half a mode's period long, would ask for
    /// offsets of millimetres (a 10 mm step: 3 mm), past the clamp — a
    /// clamped inverse rang 1.3 mm where the shaped step alone left 0.03.
    /// `now` is [`Motion::at`]`(t)`, which the caller has.
    pub fn dynamic_offset(&self, t: f64, now: &Desired) -> Option<[f64; 3]> {
        let inverse = self.inverse?;
        if now.moving || now.holding {
            return Some([0.0; 3]);
        }
        let h = DIFFERENCE_S;
        let (a, b, c) = (
            self.at(t - h).point.pose,
            now.point.pose,
            self.at(t + h).point.pose,
        );
        let velocity: [f64; 7] = std::array::from_fn(|k| (c[k] - a[k]) / (2.0 * h));
        let acceleration: [f64; 7] = std::array::from_fn(|k| (c[k] - 2.0 * b[k] + a[k]) / (h * h));
        let full = inverse.offset(&velocity, &acceleration);
        let along = along_axes(&now.point, [full[0], full[1], full[2]]);
        Some(along.map(|v| v.clamp(-MAX_DYNAMIC_OFFSET, MAX_DYNAMIC_OFFSET)))
    }
}

/// A position change (m) as coordinates along `point`'s tangent axes (the
/// position's x, y, z without a tangent): how the planner sends offsets
/// and how the controller turns them back into a pose
/// (`ipc::controller::with_dynamic_offset`).
pub fn along_axes(point: &PosePoint, position: [f64; 3]) -> [f64; 3] {
    match point.tangent {
        Some(tangent) => {
            let k = tangent.family.dim();
            let axes = tangent.family.axes_padded();
            std::array::from_fn(|j| {
                if j < k {
                    (0..3).map(|i| axes[j][i] * position[i]).sum()
                } else {
                    0.0
                }
            })
        }
        None => position,
    }
}

/// Move `point` (the first pose) back towards `rest` by what the shaped
/// move has not yet made at `t` s, with the move's velocity and no
/// tangent; whether the move is still under way.
fn approach(shaping: &StepShaping, rest: &[f64; 7], t: f64, point: &mut PosePoint) -> bool {
    if t >= shaping.length_s() {
        return false;
    }
    let (done, rate) = shaping.progress(t);
    for ((p, v), r) in point
        .pose
        .iter_mut()
        .zip(point.velocity.iter_mut())
        .zip(rest)
    {
        let span = *p - r;
        *p -= (1.0 - done) * span;
        *v = rate * span;
    }
    super::trajectory::normalise_quaternion(&mut point.pose);
    point.tangent = None;
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::PathShape;
    use crate::statics::repo_statics;

    fn circle_motion(inverse: Option<ModalInverse>) -> Motion {
        let s = repo_statics("seed-4t.toml");
        let shape = PathShape::default_circle();
        let shaping = StepShaping::for_mode(3.6, 0.05).unwrap();
        let traj = Trajectory::new(&shape, &s)
            .unwrap()
            .with_shaping(Some(shaping));
        let rest = s.solve(&[0.0; 4], None).unwrap().pose();
        Motion::new(traj, 2.0, Some(rest), inverse)
    }

    /// The approach starts at rest and arrives at the first pose within the
    /// shaping's length, flagged as a move; the path then eases in from
    /// rest (its speed rises from 0 to the circle's 2π · 0.2 · 15 mm/s).
    #[test]
    fn the_approach_and_the_eased_start_go_from_rest_to_the_circle() {
        let m = circle_motion(None);
        let first = m.at(0.0);
        assert!(first.holding && first.moving);
        // At rest the seed robot sags under gravity: 29 mm along x.
        let rest = repo_statics("seed-4t.toml")
            .solve(&[0.0; 4], None)
            .unwrap()
            .pose();
        for (a, b) in first.point.pose.iter().zip(&rest) {
            assert!(
                (a - b).abs() < 1e-9,
                "starts at rest: {:?}",
                first.point.pose
            );
        }
        let arrived = m.at(1.9);
        assert!(arrived.holding && !arrived.moving);
        assert!((arrived.point.pose[0] - 0.015).abs() < 1e-6);
        let speed = |d: &Desired| d.point.velocity[0].hypot(d.point.velocity[1]);
        assert!(speed(&m.at(2.0)) < 1e-9);
        let cruise = speed(&m.at(4.0));
        let want = std::f64::consts::TAU * 0.2 * 0.015;
        assert!(
            (cruise - want).abs() < 1e-3 * want,
            "speed {cruise} vs {want}"
        );
        assert!(!m.at(4.0).moving && !m.at(4.0).holding);
        assert!(m.dynamic_offset(3.0, &m.at(3.0)).is_none());
    }

    /// With the net's error offset the approach ends at the first pose
    /// moved by the offset's shift, and the hold then sends the first pose
    /// itself (the offset goes beside it): the net is asked for the same
    /// pose on either side of the approach's end. The start is still the
    /// robot at rest.
    #[test]
    fn the_approach_ends_where_the_holds_offset_puts_the_pose() {
        let shift = [1e-4, -2e-4, 5e-5, 1e-5, 0.0, -1e-5, 0.0];
        let shifted = circle_motion(None).with_approach_end_shift(shift);
        let plain = circle_motion(None);
        let length = StepShaping::for_mode(3.6, 0.05).unwrap().length_s();
        for (a, b) in shifted
            .at(0.0)
            .point
            .pose
            .iter()
            .zip(&plain.at(0.0).point.pose)
        {
            assert!((a - b).abs() < 1e-12, "starts at rest");
        }
        let (end, hold) = (shifted.at(length - 1e-9), shifted.at(length + 1e-9));
        assert!(end.moving && hold.holding && !hold.moving);
        let plain_hold = plain.at(length + 1e-9).point.pose;
        for (k, d) in shift.iter().enumerate().take(3) {
            let want = plain_hold[k] + d;
            assert!(
                (end.point.pose[k] - want).abs() < 1e-9,
                "axis {k}: {}",
                end.point.pose[k]
            );
            assert_eq!(hold.point.pose[k], plain_hold[k]);
        }
    }

    /// A turning offset is sent in the hold at its value for the path's
    /// start, and the approach ends where that puts the first pose: the
    /// pose the net is asked for does not step at the approach's end or at
    /// the path's start. Shaped moves send none.
    #[test]
    fn a_turning_offset_is_in_place_before_the_path_starts() {
        let mut turning = TurningOffset::zero([0.0, 0.0], 5.0, 2);
        turning.harmonics[0] = [[1e-4, 0.0], [-5e-5, 0.0], [2e-5, 0.0]];
        turning.harmonics[1] = [[3e-5, 1e-5], [0.0, 4e-5], [0.0, 0.0]];
        let m = circle_motion(None).with_turning_offset(turning.clone());
        let length = StepShaping::for_mode(3.6, 0.05).unwrap().length_s();
        // What the controller asks the net for: the pose moved by the offset.
        let asked = |t: f64| {
            let d = m.at(t);
            let o = m.turning_offset(&d).unwrap_or([0.0; 3]);
            super::super::net_error::shifted(&d.point, &o)
        };
        assert!(
            m.turning_offset(&m.at(0.1)).is_none(),
            "none on the approach"
        );
        let (end, hold) = (asked(length - 1e-9), asked(length + 1e-9));
        let start = asked(2.0 + 1e-9);
        for k in 0..3 {
            assert!(
                (end[k] - hold[k]).abs() < 1e-9,
                "axis {k}: {end:?} {hold:?}"
            );
            assert!(
                (start[k] - hold[k]).abs() < 1e-8,
                "axis {k}: {start:?} {hold:?}"
            );
        }
        // The first pose at +x: radial is x, tangential y.
        let p = m.at(1.9).point.pose;
        let want = turning.at(0.0, [p[0], p[1], p[2]]);
        assert!((want[0] - 1.3e-4).abs() < 1e-12 && (want[1] - -5e-5).abs() < 1e-12);
        assert!((hold[0] - p[0] - want[0]).abs() < 1e-9, "{hold:?}");
        // The error the table expects of the hold is the offset the hold
        // sends, held by the tip (none on the approach; the path's is the
        // table's own, here none).
        let expected = m.expected_error(1.9, &m.at(1.9));
        assert!(
            (0..3).all(|k| (expected[k] + want[k]).abs() < 1e-15),
            "{expected:?}"
        );
        assert_eq!(m.expected_error(0.1, &m.at(0.1)), [0.0; 3]);
        assert_eq!(m.expected_error(2.5, &m.at(2.5)), [0.0; 3]);
    }

    /// On the circle at cruise the modal inverse's offset is the closed
    /// form: a = −Ω² r radially, so the offset is −(Ω/ω)² r plus the
    /// damping's lead 2ζ/ω · v.
    #[test]
    fn the_dynamic_offset_on_a_circle_is_the_modal_inverse() {
        let inverse = ModalInverse {
            mode_hz: 3.6,
            damping_ratio: 0.05,
        };
        let m = circle_motion(Some(inverse));
        let t = 5.0;
        let d = m.at(t);
        let offset = m.dynamic_offset(t, &d).unwrap();
        let (w, big_w) = (std::f64::consts::TAU * 3.6, std::f64::consts::TAU * 0.2);
        for (k, (&got, (&p, &v))) in offset
            .iter()
            .zip(d.point.pose.iter().zip(&d.point.velocity))
            .take(2)
            .enumerate()
        {
            let want = -(big_w / w).powi(2) * p + 2.0 * 0.05 / w * v;
            // The offsets are ~50–80 µm; the table's 10 ms rows and the
            // differences: within 2 µm.
            assert!((got - want).abs() < 2e-6, "axis {k}: {got} vs {want}");
        }
    }
}
