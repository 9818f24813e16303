//! Planner trajectories. A continuum robot has fewer degrees of freedom than
//! a 7-number pose, so an arbitrary pose is not reachable: the planner plans
//! the tip's k coordinates on the robot's family ([`super::Family`]: x, y, z for a
//! robot that reaches a volume, x, y for one that bends over a surface, the
//! coordinate along its axis for one that moves on a curve) and lifts each
//! point to the full reachable pose with the exact IK
//! ([`Lifter`], `docs/design.md` §4.1, §6), tabulated
//! once at start-up with the tensions as a feed-forward reference. A pose
//! table's rows get theirs from the exact IK on the full pose
//! ([`super::table`]).

use super::path::{
    circle_point, figure_eight_point, helix_height, lateral_circle, periodic_times,
    sweep_coordinate,
};
use super::shape::unfit;
use super::{FamilyTangent, Lifter, PathShape, PlanError};
use crate::statics::Statics;

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
}

/// Lifted points as trajectory columns.
#[derive(Default)]
struct LiftedPath {
    poses: Vec<[f64; 7]>,
    tangents: Vec<FamilyTangent>,
    tensions: Vec<Vec<f64>>,
}

impl LiftedPath {
    fn push(&mut self, lifter: &mut Lifter, u: &[f64]) -> Result<(), PlanError> {
        let lifted = lifter.lifted(u)?;
        self.poses.push(lifted.pose);
        self.tangents.push(lifted.tangent);
        self.tensions.push(lifted.tensions);
        Ok(())
    }

    fn into_trajectory(self, times: Vec<f64>, periodic: bool, stepwise: bool) -> Trajectory {
        Trajectory {
            times,
            feedforward_miss: vec![0.0; self.poses.len()],
            poses: self.poses,
            tangents: self.tangents,
            feedforward: self.tensions,
            periodic,
            stepwise,
        }
    }
}

/// A point of `shape` on the family: `given` coordinates (k of them, or
/// lateral x, y plus `height` / the mid height on a robot that reaches a
/// volume).
fn on_family(
    shape: &PathShape,
    lifter: &Lifter,
    given: &[f64],
    height: Option<f64>,
    default_height: &mut dyn FnMut(&Lifter) -> Result<f64, PlanError>,
) -> Result<Vec<f64>, PlanError> {
    let family = lifter.family();
    let k = family.dim();
    if given.iter().chain(&height).any(|v| !v.is_finite()) {
        return Err(PlanError::Shape(format!(
            "trajectory {}: coordinates must be finite numbers",
            shape.name()
        )));
    }
    match (k, given.len(), height) {
        (3, 2, h) => {
            let z = match h {
                Some(z) => z,
                None => default_height(lifter)?,
            };
            Ok(vec![given[0], given[1], z])
        }
        (_, n, None) if n == k => Ok(given.to_vec()),
        (_, n, Some(_)) if n == k || k != 3 => Err(unfit(
            shape,
            &family,
            "a height needs lateral (x, y) points on a robot that reaches a volume",
        )),
        (_, n, _) => Err(unfit(
            shape,
            &family,
            &format!("a point has {n} coordinates, the robot's family {k}"),
        )),
    }
}

/// The mid height for a lateral path of `radius` about `center`, computed once.
fn mid_height_once(center: [f64; 2], radius: f64) -> impl FnMut(&Lifter) -> Result<f64, PlanError> {
    let mut cached = None;
    move |lifter: &Lifter| {
        if let Some(z) = cached {
            return Ok(z);
        }
        let z = lifter.mid_height(center, radius)?;
        log::info!(
            "trajectory: mid height {:.2} mm for radius {:.1} mm about ({:.1}, {:.1}) mm",
            z * 1e3,
            radius * 1e3,
            center[0] * 1e3,
            center[1] * 1e3
        );
        cached = Some(z);
        Ok(z)
    }
}

impl Trajectory {
    /// Tabulate `shape` for `statics`' robot: points on the robot's family
    /// lifted to reachable poses by the exact IK, each point warm-started
    /// from the previous one ([`Lifter`]). A shape the family cannot follow
    /// (a circle for a robot whose tip moves on a curve, a sweep for one that
    /// reaches a surface) is a [`PlanError::Shape`] naming both.
    pub fn new(shape: &PathShape, statics: &Statics) -> Result<Trajectory, PlanError> {
        let mut lifter = Lifter::new(statics)?;
        shape.check(&lifter.family())?;
        let lifter = &mut lifter;
        match shape {
            PathShape::Hold { center_m, height_m } => hold(shape, lifter, center_m, *height_m),
            PathShape::Steps {
                targets_m,
                dwell_s,
                height_m,
            } => steps(shape, lifter, targets_m, *dwell_s, *height_m),
            PathShape::Circle {
                center_m,
                radius_m,
                freq_hz,
                height_m,
            }
            | PathShape::FigureEight {
                center_m,
                radius_m,
                freq_hz,
                height_m,
            } => lateral_path(shape, lifter, *center_m, *radius_m, *freq_hz, *height_m),
            PathShape::Helix {
                center_m,
                radius_m,
                freq_hz,
                heights_m,
                turns,
            } => helix(
                shape, lifter, *center_m, *radius_m, *freq_hz, *heights_m, *turns,
            ),
            PathShape::Sweep {
                from_m,
                to_m,
                freq_hz,
            } => sweep(shape, lifter, *from_m, *to_m, *freq_hz),
            PathShape::Table { rows } => super::table::table(lifter, rows),
        }
    }

    pub fn tendons(&self) -> usize {
        self.feedforward.first().map_or(0, Vec::len)
    }

    /// The segment at time `t` (s from the start): index of the pose in
    /// force and the fraction of the way to the next one (0 when stepwise or
    /// past the end).
    fn segment(&self, t: f64) -> (usize, f64) {
        let n = self.poses.len();
        let t = if self.periodic && self.duration() > 0.0 {
            t.rem_euclid(self.duration())
        } else {
            t
        };
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
        let (i, f) = self.segment(t);
        let a = &self.feedforward[i];
        out.clear();
        if f == 0.0 {
            out.extend_from_slice(a);
            return self.feedforward_miss[i];
        }
        let b = &self.feedforward[i + 1];
        out.extend(a.iter().zip(b).map(|(a, b)| a + f * (b - a)));
        self.feedforward_miss[i].max(self.feedforward_miss[i + 1])
    }

    /// Duration of one pass (s); 0 for a hold.
    pub fn duration(&self) -> f64 {
        *self.times.last().unwrap_or(&0.0)
    }

    /// Pose and velocity at time `t` (s) from the start.
    pub fn sample(&self, t: f64) -> PosePoint {
        let (i, f) = self.segment(t);
        if self.stepwise || i + 1 >= self.poses.len() {
            return PosePoint {
                pose: self.poses[i],
                velocity: [0.0; 7],
                tangent: self.tangents.get(i).copied(),
            };
        }
        let (t0, t1) = (self.times[i], self.times[i + 1]);
        let mut pose = [0.0; 7];
        let mut velocity = [0.0; 7];
        for k in 0..7 {
            let (a, b) = (self.poses[i][k], self.poses[i + 1][k]);
            pose[k] = a + f * (b - a);
            velocity[k] = (b - a) / (t1 - t0);
        }
        let qn = (pose[3..].iter().map(|v| v * v).sum::<f64>()).sqrt();
        for v in &mut pose[3..] {
            *v /= qn;
        }
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

/// Hold one point (at the mid height of the robot there when lateral on a
/// robot that reaches a volume).
fn hold(
    shape: &PathShape,
    lifter: &mut Lifter,
    center: &[f64],
    height: Option<f64>,
) -> Result<Trajectory, PlanError> {
    let mut z = mid_height_once([center[0], *center.get(1).unwrap_or(&0.0)], 0.0);
    let u = on_family(shape, lifter, center, height, &mut z)?;
    let mut path = LiftedPath::default();
    path.push(lifter, &u)?;
    Ok(path.into_trajectory(vec![0.0], false, true))
}

/// Visit `targets` in turn, `dwell` s each.
fn steps(
    shape: &PathShape,
    lifter: &mut Lifter,
    targets: &[Vec<f64>],
    dwell: f64,
    height: Option<f64>,
) -> Result<Trajectory, PlanError> {
    if targets.is_empty() || dwell.is_nan() || dwell <= 0.0 {
        return Err(PlanError::Shape(
            "steps need at least one target and a positive dwell".into(),
        ));
    }
    // Lateral targets on a robot that reaches a volume: the mid
    // height of the smallest circle about their centroid holding them.
    let (centroid, radius) = lateral_circle(targets);
    let mut z = mid_height_once(centroid, radius);
    let family = lifter.family();
    let points = targets
        .iter()
        .map(|t| {
            if t.is_empty() {
                return Err(unfit(shape, &family, "an empty target"));
            }
            on_family(shape, lifter, t, height, &mut z)
        })
        .collect::<Result<Vec<_>, _>>()?;
    let mut path = LiftedPath::default();
    for u in &points {
        path.push(lifter, u)?;
    }
    let times = (0..targets.len()).map(|i| i as f64 * dwell).collect();
    Ok(path.into_trajectory(times, false, true))
}

/// A circle or figure eight of `radius` about lateral `center` at `freq`
/// Hz (at `height`, or the mid height, on a robot that reaches a volume).
fn lateral_path(
    shape: &PathShape,
    lifter: &mut Lifter,
    center: [f64; 2],
    radius: f64,
    freq: f64,
    height: Option<f64>,
) -> Result<Trajectory, PlanError> {
    if !(freq > 0.0 && radius >= 0.0) {
        return Err(PlanError::Shape(
            "a path needs a positive frequency and radius".into(),
        ));
    }
    let family = lifter.family();
    let k = family.dim();
    if k < 2 {
        return Err(unfit(
            shape,
            &family,
            "a lateral path needs two coordinates",
        ));
    }
    let height = match (k, height) {
        (3, Some(z)) => Some(z),
        (3, None) => Some(mid_height_once(center, radius)(lifter)?),
        (_, None) => None,
        (_, Some(_)) => {
            return Err(unfit(
                shape,
                &family,
                "a height needs a robot that reaches a volume",
            ))
        }
    };
    let eight = matches!(shape, PathShape::FigureEight { .. });
    lift_closed(lifter, periodic_times(freq, 1.0), |t| {
        let xy = if eight {
            figure_eight_point(center, radius, freq, t)
        } else {
            circle_point(center, radius, freq, t)
        };
        let mut u = xy.to_vec();
        u.extend(height);
        u
    })
}

/// A circle whose height rises from `heights[0]` to `heights[1]` over
/// `turns` revolutions and falls back over as many.
fn helix(
    shape: &PathShape,
    lifter: &mut Lifter,
    center: [f64; 2],
    radius: f64,
    freq: f64,
    heights: [f64; 2],
    turns: f64,
) -> Result<Trajectory, PlanError> {
    let family = lifter.family();
    if family.dim() != 3 {
        return Err(unfit(
            shape,
            &family,
            "a helix needs a robot that reaches a volume",
        ));
    }
    let halves = 2.0 * turns;
    let valid = freq > 0.0
        && radius >= 0.0
        && halves >= 1.0
        && halves.fract() == 0.0
        && heights.iter().all(|z| z.is_finite());
    if !valid {
        return Err(PlanError::Shape(
            "a helix needs a positive frequency and radius, finite heights and a \
             whole number of half turns (≥ ½)"
                .into(),
        ));
    }
    lift_closed(lifter, periodic_times(freq, 2.0 * turns), |t| {
        let [x, y] = circle_point(center, radius, freq, t);
        vec![x, y, helix_height(heights, turns, freq, t)]
    })
}

/// The tip's coordinate along the axis of a robot that moves on a curve,
/// swept between `from` and `to` at `freq` Hz.
fn sweep(
    shape: &PathShape,
    lifter: &mut Lifter,
    from: f64,
    to: f64,
    freq: f64,
) -> Result<Trajectory, PlanError> {
    let family = lifter.family();
    if family.dim() != 1 {
        return Err(unfit(
            shape,
            &family,
            "a sweep is for a robot whose tip moves on a curve (plan a circle or steps)",
        ));
    }
    if !(freq > 0.0 && from.is_finite() && to.is_finite()) {
        return Err(PlanError::Shape(
            "a sweep needs finite coordinates and a positive frequency".into(),
        ));
    }
    lift_closed(lifter, periodic_times(freq, 1.0), |t| {
        vec![sweep_coordinate(from, to, freq, t)]
    })
}

/// Lift `point(t)` at each of `times` (one period of a closed path) into a
/// periodic trajectory.
fn lift_closed(
    lifter: &mut Lifter,
    times: Vec<f64>,
    point: impl Fn(f64) -> Vec<f64>,
) -> Result<Trajectory, PlanError> {
    let mut path = LiftedPath::default();
    for &t in &times {
        path.push(lifter, &point(t))?;
    }
    Ok(path.into_trajectory(times, true, false))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::statics::repo_statics as statics_of;

    fn statics() -> Statics {
        statics_of("seed-4t.toml")
    }

    #[test]
    fn circle_samples_lie_on_the_circle_with_tangent_velocity() {
        let s = statics();
        let shape = PathShape::Circle {
            center_m: [0.0, 0.0],
            radius_m: 0.015,
            freq_hz: 0.2,
            height_m: None,
        };
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
    /// circle, and its height is the linear rise and fall between the two
    /// heights (the lifted poses put the tip there, so the planner's poses
    /// are the shape's points).
    #[test]
    fn helix_rises_and_falls_linearly_on_its_circle() {
        let s = statics_of("tdcr-2seg.toml");
        let z = Lifter::new(&s)
            .unwrap()
            .mid_height([0.0, 0.0], 0.01)
            .unwrap();
        let (z0, z1) = (z - 0.002, z + 0.002);
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
            let rise = if t <= 2.0 { t / 2.0 } else { 2.0 - t / 2.0 };
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
