//! Planner trajectories. A continuum robot has fewer degrees of freedom than
//! a 7-number pose, so an arbitrary pose is not reachable: the planner plans
//! the tip's k coordinates on the robot's family ([`super::Family`]: x, y, z for a
//! robot that reaches a volume, x, y for one that bends over a surface, the
//! coordinate along its axis for one that moves on a curve) and lifts each
//! point to the full reachable pose with the exact IK
//! ([`Lifter`], `docs/design.md` §4.1, §6), tabulated
//! once at start-up with the tensions as a feed-forward reference. A pose
//! table's rows get theirs from the exact IK on the full pose
//! ([`super::table`]). Building one from a shape is [`super::build`]'s job;
//! this module samples it.

use super::{FamilyTangent, StepShaping};

/// A desired tip pose and its time derivative at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PosePoint {
    /// px, py, pz (m), qw, qx, qy, qz.
    pub pose: [f64; 7],
    /// d(pose)/dt (per second).
    pub velocity: [f64; 7],
    /// The reachable family's tangent at `pose`, if the trajectory knows it
    /// (lifted paths do; a pose table does when every row is in reach).
    pub tangent: Option<FamilyTangent>,
}

/// A trajectory ready to sample: poses tabulated at a fixed time step
/// (lifted once at start-up), linearly interpolated.
#[derive(Clone, Debug)]
pub struct Trajectory {
    pub(super) times: Vec<f64>,
    pub(super) poses: Vec<[f64; 7]>,
    /// One per pose, or empty (a pose table with a row out of reach).
    pub(super) tangents: Vec<FamilyTangent>,
    /// Feed-forward tensions (N), one set per pose: the exact IK's answer
    /// (`docs/design.md` §4.1); NaN where it gave none.
    pub(super) feedforward: Vec<Vec<f64>>,
    /// Distance (m) from each pose's position to where its feed-forward
    /// tensions put the tip: 0 when reached, the closest reachable
    /// distance for a pose out of reach, NaN without an answer.
    pub(super) feedforward_miss: Vec<f64>,
    /// Repeats after its last time (circle, figure eight).
    pub(super) periodic: bool,
    /// Piecewise-constant targets (steps, hold): no interpolation, zero velocity.
    pub(super) stepwise: bool,
    /// How a stepwise trajectory moves from one target to the next (None:
    /// it jumps).
    pub(super) shaping: Option<StepShaping>,
}

impl Trajectory {
    /// Shape this trajectory's motion as `shaping` says ([`StepShaping`]):
    /// a stepwise trajectory moves between its targets by a minimum-jerk
    /// move through a ZVD shaper instead of jumping; a path starts from
    /// rest on an eased clock ([`Trajectory::path_clock`]) and is then
    /// followed as it is (shaping the path itself would delay it and shrink
    /// it at its own frequency). A hold has nothing to shape.
    pub fn with_shaping(mut self, shaping: Option<StepShaping>) -> Trajectory {
        self.shaping = shaping.filter(|_| self.poses.len() > 1);
        self
    }

    /// The shaping in force.
    pub fn shaping(&self) -> Option<StepShaping> {
        self.shaping
    }

    /// Whether a shaped step is under way at path time `t` (s): the tip is
    /// on its way to a target, not following a path.
    pub fn moving(&self, t: f64) -> bool {
        self.steps_under_way(self.local_time(t)).next().is_some()
    }

    /// How far the newest shaped step under way at path time `t` (s) has
    /// got, 0 to 1 along its shaped profile (None: no step under way, or
    /// not a stepwise trajectory).
    pub fn step_progress(&self, t: f64) -> Option<f64> {
        self.steps_under_way(self.local_time(t))
            .last()
            .map(|(_, left, _)| 1.0 - left)
    }

    /// The path time to sample at `t` s after the motion starts, and how
    /// fast it runs (the factor on [`PosePoint::velocity`]): a shaped path
    /// eases in ([`StepShaping::eased_time`]); otherwise (t, 1).
    pub fn path_clock(&self, t: f64) -> (f64, f64) {
        match self.shaping {
            Some(s) if !self.stepwise => (s.eased_time(t), s.progress(t).0),
            _ => (t, 1.0),
        }
    }

    /// The steps still under way at `t` (s): (index i of the target, the
    /// fraction of the step from target i−1 still to make, its rate) for
    /// each target asked for less than the shaping's length before.
    fn steps_under_way(&self, t: f64) -> impl Iterator<Item = (usize, f64, f64)> + '_ {
        let shaping = self.shaping.filter(|_| self.stepwise);
        (1..self.times.len()).filter_map(move |i| {
            let s = shaping?;
            let since = t - self.times[i];
            if since < 0.0 || since >= s.length_s() {
                return None;
            }
            let (done, rate) = s.progress(since);
            Some((i, 1.0 - done, rate))
        })
    }

    pub fn tendons(&self) -> usize {
        self.feedforward.first().map_or(0, Vec::len)
    }

    /// The segment at time `t` (s from the start): index of the pose in
    /// force and the fraction of the way to the next one (0 when stepwise or
    /// past the end).
    fn segment(&self, t: f64) -> (usize, f64) {
        let n = self.poses.len();
        let t = self.local_time(t);
        let i = self
            .times
            .iter()
            .rposition(|&ti| ti <= t)
            .unwrap_or_default();
        if self.stepwise || i + 1 >= n {
            return (i.min(n - 1), 0.0);
        }
        let (t0, t1) = (self.times[i], self.times[i + 1]);
        (i, ((t - t0) / (t1 - t0)).clamp(0.0, 1.0))
    }

    /// Feed-forward tensions (N) at time `t` (s), interpolated like the
    /// poses, into `out` (resized to the tendons); returns the tip's
    /// distance from the path there (m, see [`Trajectory::tendons`]).
    pub fn feedforward(&self, t: f64, out: &mut Vec<f64>) -> f64 {
        self.blend(&self.feedforward, t, out);
        let (i, f) = self.segment(t);
        if f == 0.0 {
            let mut miss = self.feedforward_miss[i];
            for (j, _, _) in self.steps_under_way(self.local_time(t)) {
                miss = miss.max(self.feedforward_miss[j - 1]);
            }
            return miss;
        }
        self.feedforward_miss[i].max(self.feedforward_miss[i + 1])
    }

    /// A table with one row per pose (the feed-forward tensions, or any
    /// column set tabulated beside them) at time `t` (s), interpolated as
    /// the poses are: linearly between a path's rows, and along each
    /// shaped step under way between a stepwise trajectory's targets.
    pub fn blend(&self, rows: &[Vec<f64>], t: f64, out: &mut Vec<f64>) {
        out.clear();
        out.resize(rows.first().map_or(0, Vec::len), 0.0);
        self.blend_into(rows, t, out);
    }

    /// [`Trajectory::blend`] into `out`, as many columns as it holds (no
    /// allocation: the planner's step calls it every period).
    pub fn blend_into(&self, rows: &[Vec<f64>], t: f64, out: &mut [f64]) {
        let (i, f) = self.segment(t);
        let a = &rows[i];
        if f == 0.0 {
            for (o, a) in out.iter_mut().zip(a) {
                *o = *a;
            }
            for (j, left, _) in self.steps_under_way(self.local_time(t)) {
                let (to, from) = (&rows[j], &rows[j - 1]);
                for (o, (b, a)) in out.iter_mut().zip(to.iter().zip(from)) {
                    *o -= left * (b - a);
                }
            }
            return;
        }
        let b = &rows[i + 1];
        for (o, (a, b)) in out.iter_mut().zip(a.iter().zip(b)) {
            *o = a + f * (b - a);
        }
    }

    /// The feed-forward tensions, one set per pose (N; NaN where the
    /// exact IK gave none).
    pub fn feedforward_rows(&self) -> &[Vec<f64>] {
        &self.feedforward
    }

    /// `t` within one pass of a periodic trajectory.
    fn local_time(&self, t: f64) -> f64 {
        if self.periodic && self.duration() > 0.0 {
            t.rem_euclid(self.duration())
        } else {
            t
        }
    }

    /// Duration of one pass (s); 0 for a hold.
    pub fn duration(&self) -> f64 {
        *self.times.last().unwrap_or(&0.0)
    }

    /// Pose and velocity at time `t` (s) from the start.
    pub fn sample(&self, t: f64) -> PosePoint {
        let (i, f) = self.segment(t);
        if self.stepwise || i + 1 >= self.poses.len() {
            return self.shaped_point(i, t);
        }
        let (t0, t1) = (self.times[i], self.times[i + 1]);
        let mut pose = [0.0; 7];
        let mut velocity = [0.0; 7];
        for k in 0..7 {
            let (a, b) = (self.poses[i][k], self.poses[i + 1][k]);
            pose[k] = a + f * (b - a);
            velocity[k] = (b - a) / (t1 - t0);
        }
        normalise_quaternion(&mut pose);
        let tangent = match (self.tangents.get(i), self.tangents.get(i + 1)) {
            (Some(a), Some(b)) => {
                let mut d = *a;
                for (column, (ca, cb)) in d.columns.iter_mut().zip(a.columns.iter().zip(&b.columns))
                {
                    for (v, (x, y)) in column.iter_mut().zip(ca.iter().zip(cb)) {
                        *v = x + f * (y - x);
                    }
                }
                Some(d)
            }
            _ => None,
        };
        PosePoint {
            pose,
            velocity,
            tangent,
        }
    }
}

/// Scale a pose's quaternion (its last four numbers) back to unit length
/// after poses were blended.
pub(super) fn normalise_quaternion(pose: &mut [f64; 7]) {
    let n = pose[3..].iter().map(|v| v * v).sum::<f64>().sqrt();
    for v in &mut pose[3..] {
        *v /= n;
    }
}

impl Trajectory {
    /// Target `i`'s point at `t`, less what the steps still under way have
    /// not yet made ([`Trajectory::steps_under_way`]; none without a
    /// shaping): pose(t) = pose_i − Σ_j (1 − g(t − t_j)) (pose_j − pose_{j−1}),
    /// velocity Σ_j g'(t − t_j) (pose_j − pose_{j−1}), the tangent likewise.
    fn shaped_point(&self, i: usize, t: f64) -> PosePoint {
        let mut pose = self.poses[i];
        let mut velocity = [0.0; 7];
        let mut tangent = self.tangents.get(i).copied();
        let mut moving = false;
        for (j, left, rate) in self.steps_under_way(self.local_time(t)) {
            moving = true;
            let (to, from) = (&self.poses[j], &self.poses[j - 1]);
            for k in 0..7 {
                pose[k] -= left * (to[k] - from[k]);
                velocity[k] += rate * (to[k] - from[k]);
            }
            if let (Some(d), Some(b), Some(a)) = (
                tangent.as_mut(),
                self.tangents.get(j),
                self.tangents.get(j - 1),
            ) {
                for (column, (cb, ca)) in d.columns.iter_mut().zip(b.columns.iter().zip(&a.columns))
                {
                    for (v, (y, x)) in column.iter_mut().zip(cb.iter().zip(ca)) {
                        *v -= left * (y - x);
                    }
                }
            }
        }
        if moving {
            normalise_quaternion(&mut pose);
        }
        PosePoint {
            pose,
            velocity,
            tangent,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::{Lifter, PathShape};
    use crate::statics::repo_statics as statics_of;
    use crate::statics::Statics;

    fn statics() -> Statics {
        statics_of("seed-4t.toml")
    }

    #[test]
    fn circle_samples_lie_on_the_circle_with_tangent_velocity() {
        let s = statics();
        let shape = PathShape::default_circle();
        let traj = Trajectory::new(&shape, &s).unwrap();
        for t in [0.0, 0.37, 1.3, 4.99, 6.1] {
            let p = traj.sample(t);
            let r = (p.pose[0].powi(2) + p.pose[1].powi(2)).sqrt();
            assert!((r - 0.015).abs() < 2e-6, "r = {r}");
            // Speed of a 15 mm circle at 0.2 Hz is 2π·0.2·15 mm/s.
            let v = (p.velocity[0].powi(2) + p.velocity[1].powi(2)).sqrt();
            assert!(
                (v - std::f64::consts::TAU * 0.2 * 0.015).abs() < 1e-4,
                "v = {v}"
            );
            // Tangent: velocity ⟂ radius.
            assert!((p.pose[0] * p.velocity[0] + p.pose[1] * p.velocity[1]).abs() < 1e-5);
        }
    }

    /// A helix on the two-segment robot: every sample's tip is on the
    /// circle, and its height rises and falls linearly between the two
    /// heights away from its turns (at 1/(1 − b) the triangle's rate, b =
    /// [`crate::plan::path::HELIX_TURN_BLEND`]) and is each height at its
    /// turn (the lifted poses put the tip there, so the planner's poses are
    /// the shape's points).
    #[test]
    fn helix_rises_and_falls_linearly_on_its_circle() {
        let s = statics_of("tdcr-2seg.toml");
        let z = Lifter::new(&s)
            .unwrap()
            .mid_height([0.0, 0.0], 0.01)
            .unwrap();
        // ± 1 mm: 2 mm above the mid height is 0.2 mm under the top of the
        // reachable band, where the family folds.
        let (z0, z1) = (z - 0.001, z + 0.001);
        let shape = PathShape::Helix {
            center_m: [0.0, 0.0],
            radius_m: 0.01,
            freq_hz: 0.5,
            heights_m: [z0, z1],
            turns: 1.0,
        };
        let traj = Trajectory::new(&shape, &s).unwrap();
        assert!((traj.duration() - 4.0).abs() < 1e-12);
        for t in [0.0, 0.5, 1.0, 2.0, 3.0, 3.9] {
            let p = traj.sample(t);
            let r = p.pose[0].hypot(p.pose[1]);
            assert!((r - 0.01).abs() < 2e-6, "t {t}: r = {r}");
            let b = crate::plan::path::HELIX_TURN_BLEND;
            let triangle: f64 = if t <= 2.0 { t / 2.0 } else { 2.0 - t / 2.0 };
            let rise = if t == 0.0 || t == 2.0 {
                triangle
            } else {
                (triangle - b / 2.0) / (1.0 - b)
            };
            let want = z0 + rise * (z1 - z0);
            assert!(
                (p.pose[2] - want).abs() < 1e-6,
                "t {t}: z {} vs {want}",
                p.pose[2]
            );
            assert_eq!(p.tangent.unwrap().family.dim(), 3);
        }
    }

    /// 3-D steps on the two-segment robot hold each target exactly.
    #[test]
    fn volume_steps_hold_their_3d_targets() {
        let s = statics_of("tdcr-2seg.toml");
        let z = 0.395;
        let targets = vec![vec![0.008, 0.0, z], vec![0.0, 0.008, z + 0.002]];
        let shape = PathShape::Steps {
            targets_m: targets.clone(),
            dwell_s: 1.0,
            height_m: None,
        };
        let traj = Trajectory::new(&shape, &s).unwrap();
        for (i, target) in targets.iter().enumerate() {
            let p = traj.sample(i as f64 + 0.5);
            for (a, b) in p.pose.iter().zip(target) {
                assert!((a - b).abs() < 1e-6, "target {i}: {:?}", p.pose);
            }
        }
    }

    /// Shaped steps on the default robot: the pose moves from one target to
    /// the next along the shaping's progress (its velocity the derivative
    /// of its position), reaches the target when the shaping ends, and a
    /// hold stays a hold.
    #[test]
    fn shaped_steps_move_smoothly_and_arrive() {
        let s = statics();
        let shape = PathShape::Steps {
            targets_m: vec![vec![0.0, 0.0], vec![0.01, 0.0]],
            dwell_s: 2.0,
            height_m: None,
        };
        let shaping = StepShaping::for_mode(3.6, 0.05).unwrap();
        let traj = Trajectory::new(&shape, &s)
            .unwrap()
            .with_shaping(Some(shaping));
        assert_eq!(traj.shaping(), Some(shaping));
        let end = 2.0 + shaping.length_s();
        let (a, b) = (traj.sample(1.9).pose, traj.sample(end + 0.01).pose);
        assert!(
            a[0].abs() < 1e-6 && (b[0] - 0.01).abs() < 1e-6,
            "{a:?} {b:?}"
        );
        let dt = 1e-5;
        let mut last_x = a[0];
        for k in 0..=100 {
            let t = 2.0 + shaping.length_s() * k as f64 / 100.0;
            let p = traj.sample(t);
            let (before, after) = (traj.sample(t - dt).pose, traj.sample(t + dt).pose);
            for i in 0..3 {
                let rate = (after[i] - before[i]) / (2.0 * dt);
                assert!(
                    (p.velocity[i] - rate).abs() < 1e-4 * 0.05 + 1e-6,
                    "t {t}: velocity {} vs {rate}",
                    p.velocity[i]
                );
            }
            let (progress, _) = shaping.progress(t - 2.0);
            assert!(
                (p.pose[0] - 0.01 * progress).abs() < 1e-4,
                "t {t}: x {}",
                p.pose[0]
            );
            assert!(p.pose[0] >= last_x - 1e-12, "t {t}: went back");
            last_x = p.pose[0];
            let q: f64 = p.pose[3..].iter().map(|v| v * v).sum();
            assert!((q - 1.0).abs() < 1e-12);
        }
        let mut ff = Vec::new();
        traj.feedforward(2.0 + shaping.length_s() / 2.0, &mut ff);
        let (mut first, mut second) = (Vec::new(), Vec::new());
        traj.feedforward(1.0, &mut first);
        traj.feedforward(end + 1.0, &mut second);
        let (progress, _) = shaping.progress(shaping.length_s() / 2.0);
        for ((m, a), b) in ff.iter().zip(&first).zip(&second) {
            assert!((m - (a + progress * (b - a))).abs() < 1e-12);
        }
        let hold = PathShape::Hold {
            center_m: vec![0.005, 0.0],
            height_m: None,
        };
        let held = Trajectory::new(&hold, &s)
            .unwrap()
            .with_shaping(Some(shaping));
        assert_eq!(held.shaping(), None);
    }

    /// A sweep on the one-tendon robot: the tip's coordinate along the
    /// axis follows the raised cosine between the two coordinates.
    #[test]
    fn sweep_follows_its_raised_cosine_along_the_axis() {
        let s = statics_of("seed-1t.toml");
        let family = crate::plan::Family::of(&s).unwrap();
        let (from, to) = (0.05, 0.09);
        let shape = PathShape::Sweep {
            from_m: from,
            to_m: to,
            freq_hz: 0.25,
        };
        let traj = Trajectory::new(&shape, &s).unwrap();
        for t in [0.0, 0.7, 2.0, 3.3] {
            let p = traj.sample(t);
            let u = family.coordinates(&[p.pose[0], p.pose[1], p.pose[2]])[0];
            let want = from + (to - from) * 0.5 * (1.0 - (std::f64::consts::TAU * 0.25 * t).cos());
            // Linear interpolation of a 10 ms table: within 1e-6 m.
            assert!((u - want).abs() < 1e-6, "t {t}: {u} vs {want}");
        }
    }

    /// Shapes a robot's family cannot follow are one clear error naming
    /// the shape and the family.
    #[test]
    fn shapes_the_family_cannot_follow_are_clear_errors() {
        let circle = PathShape::Circle {
            center_m: [0.0, 0.0],
            radius_m: 0.01,
            freq_hz: 0.2,
            height_m: None,
        };
        let err = Trajectory::new(&circle, &statics_of("seed-1t.toml")).unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains("circle") && text.contains("curve (k = 1"),
            "{text}"
        );
        let four = statics();
        let sweep = PathShape::Sweep {
            from_m: 0.0,
            to_m: 0.01,
            freq_hz: 0.2,
        };
        let text = Trajectory::new(&sweep, &four).unwrap_err().to_string();
        assert!(text.contains("sweep") && text.contains("surface"), "{text}");
        let high = PathShape::Circle {
            center_m: [0.0, 0.0],
            radius_m: 0.01,
            freq_hz: 0.2,
            height_m: Some(0.39),
        };
        let text = Trajectory::new(&high, &four).unwrap_err().to_string();
        assert!(
            text.contains("height") && text.contains("surface"),
            "{text}"
        );
        let steps = PathShape::Steps {
            targets_m: vec![vec![0.01, 0.0, 0.39]],
            dwell_s: 1.0,
            height_m: None,
        };
        let text = Trajectory::new(&steps, &four).unwrap_err().to_string();
        assert!(text.contains("3 coordinates"), "{text}");
    }
}
