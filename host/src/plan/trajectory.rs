//! Planner trajectories. A continuum robot has fewer degrees of freedom than
//! a 7-number pose, so an arbitrary pose is not reachable: the planner plans
//! the tip's k coordinates on the robot's family ([`Family`]: x, y, z for a
//! robot that reaches a volume, x, y for one that bends over a surface, the
//! coordinate along its axis for one that moves on a curve) and lifts each
//! point to the full reachable pose with the exact IK
//! ([`crate::kinematics::Lifter`], `docs/design.md` §4.1, §6), tabulated
//! once at start-up with the tensions as a feed-forward reference. A pose
//! table's rows get theirs from the exact IK on the full pose.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::IpcError;
use crate::inverse::{ExactIk, InverseError, Target};
use crate::kinematics::{Family, Lifter, Tangent};
use crate::statics::{Statics, WarmStart};

/// A desired tip pose and its time derivative at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PosePoint {
    /// px, py, pz (m), qw, qx, qy, qz.
    pub pose: [f64; 7],
    /// d(pose)/dt (per second).
    pub velocity: [f64; 7],
    /// The reachable family's tangent at `pose`, if the trajectory knows it
    /// (lifted paths do; a pose table does when every row is in reach).
    pub tangent: Option<Tangent>,
}

/// What the planner follows (serialised with a `kind` tag, units in the
/// field names). Points are the tip's coordinates on the robot's family
/// (module docs): x, y (m) for a robot that bends over a surface; x, y, z,
/// or x, y and a `height_m`, for one that reaches a volume (no height: the
/// robot's mid height, [`Lifter::mid_height`]); the one coordinate along
/// the axis for one that moves on a curve.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Shape {
    /// Hold one point.
    Hold {
        /// The point, m.
        center_m: Vec<f64>,
        /// Height for a lateral `center_m` on a robot that reaches a volume, m.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        height_m: Option<f64>,
    },
    /// Visit points in turn, `dwell_s` seconds each.
    Steps {
        /// Targets, m.
        targets_m: Vec<Vec<f64>>,
        /// Seconds per target.
        dwell_s: f64,
        /// Height for lateral targets on a robot that reaches a volume, m.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        height_m: Option<f64>,
    },
    /// Circle of `radius_m` about lateral `center_m` at `freq_hz`, starting at +x.
    Circle {
        /// Lateral centre, m.
        center_m: [f64; 2],
        /// Radius, m.
        radius_m: f64,
        /// Revolutions per second.
        freq_hz: f64,
        /// Height on a robot that reaches a volume, m (default: its mid height).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        height_m: Option<f64>,
    },
    /// Lemniscate of Gerono (figure eight) of half-width `radius_m` about `center_m`.
    FigureEight {
        /// Lateral centre, m.
        center_m: [f64; 2],
        /// Half-width, m.
        radius_m: f64,
        /// Periods per second.
        freq_hz: f64,
        /// Height on a robot that reaches a volume, m (default: its mid height).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        height_m: Option<f64>,
    },
    /// A circle whose height moves linearly from `heights_m[0]` to
    /// `heights_m[1]` over `turns` revolutions and back over as many
    /// (periodic; a robot that reaches a volume).
    Helix {
        /// Lateral centre, m.
        center_m: [f64; 2],
        /// Radius, m.
        radius_m: f64,
        /// Revolutions per second.
        freq_hz: f64,
        /// Start and top heights, m.
        heights_m: [f64; 2],
        /// Revolutions from one height to the other (a multiple of ½, so
        /// the path closes).
        turns: f64,
    },
    /// The tip's coordinate along the axis of a robot that moves on a
    /// curve, `from_m + (to_m − from_m) (1 − cos 2π f t) / 2`.
    Sweep {
        /// Start (and end) coordinate, m.
        from_m: f64,
        /// Farthest coordinate, m.
        to_m: f64,
        /// Periods per second.
        freq_hz: f64,
    },
    /// Full poses from a table (times increasing).
    Table {
        /// The rows.
        rows: Vec<PoseRow>,
    },
}

impl Shape {
    /// The shape's name as in its `kind` tag.
    pub fn name(&self) -> &'static str {
        match self {
            Shape::Hold { .. } => "hold",
            Shape::Steps { .. } => "steps",
            Shape::Circle { .. } => "circle",
            Shape::FigureEight { .. } => "figure_eight",
            Shape::Helix { .. } => "helix",
            Shape::Sweep { .. } => "sweep",
            Shape::Table { .. } => "table",
        }
    }

    /// Whether a robot of `family` can follow the shape (its kind and the
    /// number of coordinates of its points), before anything is lifted:
    /// an [`IpcError::Config`] naming the shape and the family if not.
    pub fn check(&self, family: &Family) -> Result<(), IpcError> {
        let k = family.dim();
        let points = |points: &[&Vec<f64>], height: &Option<f64>| {
            for p in points {
                let fits = p.len() == k || (k == 3 && p.len() == 2);
                if !fits {
                    let why = format!(
                        "a point has {} coordinates, the robot's family {k}",
                        p.len()
                    );
                    return Err(unfit(self, family, &why));
                }
                if height.is_some() && !(k == 3 && p.len() == 2) {
                    return Err(unfit(
                        self,
                        family,
                        "a height needs lateral (x, y) points on a robot that reaches a volume",
                    ));
                }
            }
            Ok(())
        };
        match self {
            Shape::Hold { center_m, height_m } => points(&[center_m], height_m),
            Shape::Steps {
                targets_m,
                height_m,
                ..
            } => points(&targets_m.iter().collect::<Vec<_>>(), height_m),
            Shape::Circle { height_m, .. } | Shape::FigureEight { height_m, .. } => {
                if k < 2 {
                    Err(unfit(self, family, "a lateral path needs two coordinates"))
                } else if height_m.is_some() && k != 3 {
                    Err(unfit(
                        self,
                        family,
                        "a height needs a robot that reaches a volume",
                    ))
                } else {
                    Ok(())
                }
            }
            Shape::Helix { .. } if k != 3 => Err(unfit(
                self,
                family,
                "a helix needs a robot that reaches a volume",
            )),
            Shape::Sweep { .. } if k != 1 => Err(unfit(
                self,
                family,
                "a sweep is for a robot whose tip moves on a curve (plan a circle or steps)",
            )),
            Shape::Helix { .. } | Shape::Sweep { .. } | Shape::Table { .. } => Ok(()),
        }
    }
}

/// One row of a pose table.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseRow {
    /// Time from the start, s.
    pub t_s: f64,
    /// px, py, pz (m), qw, qx, qy, qz.
    pub pose: [f64; 7],
}

/// A trajectory ready to sample: poses tabulated at a fixed time step
/// (lifted once at start-up), linearly interpolated.
#[derive(Clone, Debug)]
pub struct Trajectory {
    times: Vec<f64>,
    poses: Vec<[f64; 7]>,
    /// One per pose, or empty (a pose table with a row out of reach).
    tangents: Vec<Tangent>,
    /// Feed-forward tensions (N), one set per pose: the exact IK's answer
    /// (`docs/design.md` §4.1); NaN where it gave none.
    feedforward: Vec<Vec<f64>>,
    /// Distance (m) from each pose's position to where its feed-forward
    /// tensions put the tip: 0 when reached, the closest reachable
    /// distance for a pose out of reach, NaN without an answer.
    feedforward_miss: Vec<f64>,
    /// Repeats after its last time (circle, figure eight).
    periodic: bool,
    /// Piecewise-constant targets (steps, hold): no interpolation, zero velocity.
    stepwise: bool,
}

/// Table resolution for lifted continuous paths (s).
const TABLE_DT: f64 = 0.01;

/// Lifted points as trajectory columns.
#[derive(Default)]
struct LiftedPath {
    poses: Vec<[f64; 7]>,
    tangents: Vec<Tangent>,
    tensions: Vec<Vec<f64>>,
}

impl LiftedPath {
    fn push(&mut self, lifter: &mut Lifter, u: &[f64]) -> Result<(), IpcError> {
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

/// The shape cannot be followed by a robot of this family.
fn unfit(shape: &Shape, family: &Family, why: &str) -> IpcError {
    IpcError::Config(format!(
        "trajectory {}: {why}; this robot's tip reaches {}",
        shape.name(),
        family.describe()
    ))
}

/// A point of `shape` on the family: `given` coordinates (k of them, or
/// lateral x, y plus `height` / the mid height on a robot that reaches a
/// volume).
fn on_family(
    shape: &Shape,
    lifter: &Lifter,
    given: &[f64],
    height: Option<f64>,
    default_height: &mut dyn FnMut(&Lifter) -> Result<f64, IpcError>,
) -> Result<Vec<f64>, IpcError> {
    let family = lifter.family();
    let k = family.dim();
    if given.iter().chain(&height).any(|v| !v.is_finite()) {
        return Err(IpcError::Config(format!(
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
fn mid_height_once(center: [f64; 2], radius: f64) -> impl FnMut(&Lifter) -> Result<f64, IpcError> {
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

/// Times of one period of a closed path at `freq` Hz lasting `cycles`
/// periods of the base frequency, tabulated at [`TABLE_DT`].
fn periodic_times(freq: f64, cycles: f64) -> Vec<f64> {
    let period = cycles / freq;
    let n = ((period / TABLE_DT).ceil() as usize).max(16);
    (0..=n).map(|i| period * i as f64 / n as f64).collect()
}

impl Trajectory {
    /// Tabulate `shape` for `statics`' robot: points on the robot's family
    /// lifted to reachable poses by the exact IK, each point warm-started
    /// from the previous one ([`Lifter`]). A shape the family cannot follow
    /// (a circle for a robot whose tip moves on a curve, a sweep for one that
    /// reaches a surface) is an [`IpcError::Config`] naming both.
    pub fn new(shape: &Shape, statics: &Statics) -> Result<Trajectory, IpcError> {
        let mut lifter = Lifter::new(statics)?;
        let family = lifter.family();
        let k = family.dim();
        shape.check(&family)?;
        match shape {
            Shape::Hold { center_m, height_m } => {
                let mut z = mid_height_once([center_m[0], *center_m.get(1).unwrap_or(&0.0)], 0.0);
                let u = on_family(shape, &lifter, center_m, *height_m, &mut z)?;
                let mut path = LiftedPath::default();
                path.push(&mut lifter, &u)?;
                Ok(path.into_trajectory(vec![0.0], false, true))
            }
            Shape::Steps {
                targets_m: targets,
                dwell_s: dwell,
                height_m,
            } => {
                if targets.is_empty() || dwell.is_nan() || *dwell <= 0.0 {
                    return Err(IpcError::Config(
                        "steps need at least one target and a positive dwell".into(),
                    ));
                }
                // Lateral targets on a robot that reaches a volume: the mid
                // height of the smallest circle about their centroid holding them.
                let lateral = |t: &Vec<f64>| [t[0], *t.get(1).unwrap_or(&0.0)];
                let n = targets.len() as f64;
                let centroid = targets
                    .iter()
                    .map(lateral)
                    .fold([0.0; 2], |c, t| [c[0] + t[0] / n, c[1] + t[1] / n]);
                let radius = targets
                    .iter()
                    .map(|t| {
                        let t = lateral(t);
                        (t[0] - centroid[0]).hypot(t[1] - centroid[1])
                    })
                    .fold(0.0, f64::max);
                let mut z = mid_height_once(centroid, radius);
                let points = targets
                    .iter()
                    .map(|t| {
                        if t.is_empty() {
                            return Err(unfit(shape, &family, "an empty target"));
                        }
                        on_family(shape, &lifter, t, *height_m, &mut z)
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                let mut path = LiftedPath::default();
                for u in &points {
                    path.push(&mut lifter, u)?;
                }
                let times = (0..targets.len()).map(|i| i as f64 * dwell).collect();
                Ok(path.into_trajectory(times, false, true))
            }
            Shape::Circle {
                center_m: center,
                radius_m: radius,
                freq_hz: freq,
                height_m,
            }
            | Shape::FigureEight {
                center_m: center,
                radius_m: radius,
                freq_hz: freq,
                height_m,
            } => {
                if !(*freq > 0.0 && *radius >= 0.0) {
                    return Err(IpcError::Config(
                        "a path needs a positive frequency and radius".into(),
                    ));
                }
                if k < 2 {
                    return Err(unfit(
                        shape,
                        &family,
                        "a lateral path needs two coordinates",
                    ));
                }
                let height = match (k, height_m) {
                    (3, Some(z)) => Some(*z),
                    (3, None) => Some(mid_height_once(*center, *radius)(&lifter)?),
                    (_, None) => None,
                    (_, Some(_)) => {
                        return Err(unfit(
                            shape,
                            &family,
                            "a height needs a robot that reaches a volume",
                        ))
                    }
                };
                let eight = matches!(shape, Shape::FigureEight { .. });
                let times = periodic_times(*freq, 1.0);
                let mut path = LiftedPath::default();
                for &t in &times {
                    let a = std::f64::consts::TAU * freq * t;
                    let mut u = if eight {
                        vec![
                            center[0] + radius * a.sin(),
                            center[1] + radius * a.sin() * a.cos(),
                        ]
                    } else {
                        vec![center[0] + radius * a.cos(), center[1] + radius * a.sin()]
                    };
                    u.extend(height);
                    path.push(&mut lifter, &u)?;
                }
                Ok(path.into_trajectory(times, true, false))
            }
            Shape::Helix {
                center_m: center,
                radius_m: radius,
                freq_hz: freq,
                heights_m: heights,
                turns,
            } => {
                if k != 3 {
                    return Err(unfit(
                        shape,
                        &family,
                        "a helix needs a robot that reaches a volume",
                    ));
                }
                let halves = 2.0 * turns;
                let valid = *freq > 0.0
                    && *radius >= 0.0
                    && halves >= 1.0
                    && halves.fract() == 0.0
                    && heights.iter().all(|z| z.is_finite());
                if !valid {
                    return Err(IpcError::Config(
                        "a helix needs a positive frequency and radius, finite heights and a \
                         whole number of half turns (≥ ½)"
                            .into(),
                    ));
                }
                let times = periodic_times(*freq, 2.0 * turns);
                let rise = turns / freq;
                let mut path = LiftedPath::default();
                for &t in &times {
                    let a = std::f64::consts::TAU * freq * t;
                    // Up over the first `turns` revolutions, down over the next.
                    let f = if t <= rise { t / rise } else { 2.0 - t / rise };
                    let z = heights[0] + f * (heights[1] - heights[0]);
                    let u = [
                        center[0] + radius * a.cos(),
                        center[1] + radius * a.sin(),
                        z,
                    ];
                    path.push(&mut lifter, &u)?;
                }
                Ok(path.into_trajectory(times, true, false))
            }
            Shape::Sweep {
                from_m,
                to_m,
                freq_hz: freq,
            } => {
                if k != 1 {
                    return Err(unfit(
                        shape,
                        &family,
                        "a sweep is for a robot whose tip moves on a curve (plan a circle or steps)",
                    ));
                }
                if !(*freq > 0.0 && from_m.is_finite() && to_m.is_finite()) {
                    return Err(IpcError::Config(
                        "a sweep needs finite coordinates and a positive frequency".into(),
                    ));
                }
                let times = periodic_times(*freq, 1.0);
                let mut path = LiftedPath::default();
                for &t in &times {
                    let a = std::f64::consts::TAU * freq * t;
                    let u = from_m + (to_m - from_m) * 0.5 * (1.0 - a.cos());
                    path.push(&mut lifter, &[u])?;
                }
                Ok(path.into_trajectory(times, true, false))
            }
            Shape::Table { rows } => {
                if rows.is_empty() || rows.windows(2).any(|w| w[1].t_s <= w[0].t_s) {
                    return Err(IpcError::Config(
                        "pose table needs rows with increasing times".into(),
                    ));
                }
                // The table's poses are the user's; their tangents come from
                // the reachable pose at the same coordinates on the family.
                // If some row is out of reach there are none, and the
                // firmware's correction moves the position alone.
                let tangents: Result<Vec<Tangent>, _> = rows
                    .iter()
                    .map(|r| {
                        let u = family.coordinates(&[r.pose[0], r.pose[1], r.pose[2]]);
                        lifter.lift_with_tangent(&u[..k]).map(|(_, d)| d)
                    })
                    .collect();
                let tangents = tangents.unwrap_or_else(|e| {
                    log::warn!("pose table: no tangents for the correction ({e})");
                    Vec::new()
                });
                let (feedforward, feedforward_miss) = table_feedforward(lifter.ik(), rows);
                Ok(Trajectory {
                    times: rows.iter().map(|r| r.t_s).collect(),
                    poses: rows.iter().map(|r| r.pose).collect(),
                    tangents,
                    feedforward,
                    feedforward_miss,
                    periodic: false,
                    stepwise: false,
                })
            }
        }
    }

    /// Tendons of the feed-forward tensions.
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

/// Exact tensions for each row of a pose table (full-pose targets with the
/// IK's default orientation weight, the backbone length in m/rad,
/// `docs/design.md` §4.1), each row warm-started from the previous one, and
/// each row's miss: 0 when reached, the distance to the closest reachable
/// pose when out of reach (the row is named in the log, its reference is
/// that closest pose's tensions), NaN when the IK gave no answer.
fn table_feedforward(ik: &ExactIk, rows: &[PoseRow]) -> (Vec<Vec<f64>>, Vec<f64>) {
    let n = ik.robot().tendons.len();
    let mut tensions = Vec::with_capacity(rows.len());
    let mut misses = Vec::with_capacity(rows.len());
    let mut previous: Option<(Vec<f64>, WarmStart)> = None;
    let mut out_of_reach = 0;
    for (i, row) in rows.iter().enumerate() {
        let answer = Target::from_pose(&row.pose, false).and_then(|target| {
            let start = previous.as_ref().map(|(t, w)| (t.as_slice(), w));
            ik.solve(&target, start.map(|s| s.0), start.map(|s| s.1))
        });
        let (tau, miss) = match answer {
            Ok(s) => {
                previous = Some((s.tensions.clone(), s.warm));
                (s.tensions, 0.0)
            }
            Err(InverseError::Unreachable { closest }) => {
                out_of_reach += 1;
                log::warn!(
                    "pose table row {} (t = {} s) is out of reach: feed-forward from the closest reachable pose, {:.3} mm and {:.4} rad away ({})",
                    i + 1,
                    row.t_s,
                    closest.position_error * 1e3,
                    closest.orientation_error.unwrap_or(f64::NAN),
                    closest.active_limits()
                );
                previous = Some((closest.tensions.clone(), closest.warm));
                (closest.tensions, closest.position_error)
            }
            Err(e) => {
                log::warn!(
                    "pose table row {} (t = {} s): no feed-forward tensions ({e})",
                    i + 1,
                    row.t_s
                );
                (vec![f64::NAN; n], f64::NAN)
            }
        };
        tensions.push(tau);
        misses.push(miss);
    }
    if out_of_reach > 0 {
        log::warn!(
            "pose table: {out_of_reach} of {} rows out of reach (their feed-forward is the closest reachable pose's)",
            rows.len()
        );
    }
    (tensions, misses)
}

/// Read a pose table (`t,px,py,pz,qw,qx,qy,qz`, header line required).
pub fn read_pose_csv(path: &Path) -> Result<Vec<PoseRow>, IpcError> {
    let text = std::fs::read_to_string(path).map_err(|source| IpcError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let mut rows = Vec::new();
    for (n, line) in text.lines().enumerate().skip(1) {
        if line.trim().is_empty() {
            continue;
        }
        let v: Result<Vec<f64>, _> = line.split(',').map(|s| s.trim().parse::<f64>()).collect();
        match v {
            Ok(v) if v.len() == 8 && v.iter().all(|x| x.is_finite()) => {
                rows.push(PoseRow {
                    t_s: v[0],
                    pose: [v[1], v[2], v[3], v[4], v[5], v[6], v[7]],
                });
            }
            _ => {
                return Err(IpcError::Config(format!(
                    "{} line {}: expected 8 finite numbers t,px,py,pz,qw,qx,qy,qz",
                    path.display(),
                    n + 1
                )))
            }
        }
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::Robot;
    use crate::statics::SolverSettings;
    use nalgebra::Vector3;

    fn statics() -> Statics {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../robots/seed-4t.toml");
        Statics::new(&Robot::load(&path).unwrap(), SolverSettings::default())
    }

    #[test]
    fn circle_samples_lie_on_the_circle_with_tangent_velocity() {
        let s = statics();
        let shape = Shape::Circle {
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

    #[test]
    fn pose_tables_get_the_tangent_of_the_reachable_pose_at_each_row() {
        let s = statics();
        let xys = [[0.01, 0.0], [0.0, 0.02], [-0.015, -0.005]];
        let mut lifter = Lifter::new(&s).unwrap();
        let lifted: Vec<([f64; 7], Tangent)> = xys
            .iter()
            .map(|&xy| lifter.lift_with_tangent(xy).unwrap())
            .collect();
        let rows: Vec<PoseRow> = lifted
            .iter()
            .enumerate()
            .map(|(i, (p, _))| PoseRow {
                t_s: i as f64,
                pose: *p,
            })
            .collect();
        let traj = Trajectory::new(&Shape::Table { rows: rows.clone() }, &s).unwrap();
        for (i, (_, d)) in lifted.iter().enumerate() {
            let got = traj.sample(i as f64).tangent.expect("a tangent");
            for j in 0..2 {
                for k in 0..7 {
                    assert!(
                        (got.columns[j][k] - d.columns[j][k]).abs() < 1e-4,
                        "row {i}: {got:?} vs {d:?}"
                    );
                }
            }
        }
        // A row out of reach: no tangents (the correction falls back).
        let mut far = rows;
        far[1].pose[0] = 0.5;
        let traj = Trajectory::new(&Shape::Table { rows: far }, &s).unwrap();
        assert!(traj.sample(0.0).tangent.is_none());
    }

    /// Feed-forward tensions of a pose table: reachable rows (poses of
    /// known tensions) get tensions whose fresh forward solve gives the
    /// row's pose; a row out of reach is no failure, its miss is the
    /// distance to where its (closest-pose) tensions put the tip.
    #[test]
    fn pose_table_rows_get_exact_feedforward_tensions() {
        let s = statics();
        let truth = [
            [3.0, 1.0, 0.0, 0.0],
            [0.0, 2.0, 1.5, 0.0],
            [0.5, 0.0, 0.0, 4.0],
        ];
        let mut rows: Vec<PoseRow> = truth
            .iter()
            .enumerate()
            .map(|(i, tau)| PoseRow {
                t_s: i as f64,
                pose: s.solve(tau, None).unwrap().pose(),
            })
            .collect();
        let traj = Trajectory::new(&Shape::Table { rows: rows.clone() }, &s).unwrap();
        assert_eq!(traj.tendons(), 4);
        let mut ff = Vec::new();
        for row in &rows {
            assert_eq!(traj.feedforward(row.t_s, &mut ff), 0.0);
            let reached = statics().solve(&ff, None).unwrap();
            let p = reached.position;
            let miss = (p - Vector3::new(row.pose[0], row.pose[1], row.pose[2])).norm();
            assert!(miss <= 1e-6, "row at {} s: {miss:e} m", row.t_s);
            assert!(ff.iter().all(|&t| (0.0..=10.0).contains(&t)), "{ff:?}");
        }
        rows[1].pose[0] += 0.3;
        let traj = Trajectory::new(&Shape::Table { rows: rows.clone() }, &s).unwrap();
        let miss = traj.feedforward(1.0, &mut ff);
        let p = statics().solve(&ff, None).unwrap().position;
        let expected = (p - Vector3::new(rows[1].pose[0], rows[1].pose[1], rows[1].pose[2])).norm();
        assert!(
            miss > 0.1 && (miss - expected).abs() < 1e-9,
            "{miss} vs {expected}"
        );
        assert_eq!(traj.feedforward(2.0, &mut ff), 0.0);
    }

    use crate::statics::repo_statics as statics_of;

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
        let shape = Shape::Helix {
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
        let shape = Shape::Steps {
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
        let family = Family::of(&s).unwrap();
        let (from, to) = (0.05, 0.09);
        let shape = Shape::Sweep {
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
        let circle = Shape::Circle {
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
        let sweep = Shape::Sweep {
            from_m: 0.0,
            to_m: 0.01,
            freq_hz: 0.2,
        };
        let text = Trajectory::new(&sweep, &four).unwrap_err().to_string();
        assert!(text.contains("sweep") && text.contains("surface"), "{text}");
        let high = Shape::Circle {
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
        let steps = Shape::Steps {
            targets_m: vec![vec![0.01, 0.0, 0.39]],
            dwell_s: 1.0,
            height_m: None,
        };
        let text = Trajectory::new(&steps, &four).unwrap_err().to_string();
        assert!(text.contains("3 coordinates"), "{text}");
    }

    /// Configurations written before heights existed still read.
    #[test]
    fn shapes_without_a_height_still_deserialise() {
        let text = r#"{"kind":"circle","center_m":[0.0,0.0],"radius_m":0.015,"freq_hz":0.2}"#;
        let shape: Shape = serde_json::from_str(text).unwrap();
        assert_eq!(
            shape,
            Shape::Circle {
                center_m: [0.0, 0.0],
                radius_m: 0.015,
                freq_hz: 0.2,
                height_m: None
            }
        );
        let text = r#"{"kind":"steps","targets_m":[[0.01,0.0]],"dwell_s":2.0}"#;
        assert!(serde_json::from_str::<Shape>(text).is_ok());
    }
}
