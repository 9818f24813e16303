//! Planner trajectories. A continuum robot with bending tendons has fewer
//! degrees of freedom than a 7-number pose, so an arbitrary pose is not
//! reachable: the planner plans the tip's lateral position (x, y) and lifts
//! each point to the full reachable pose (z and orientation) through the
//! statics, with tensions on the (at most two) tendons facing the bend —
//! the same family of tension vectors the `adjacent` dataset sampler draws.

use std::path::Path;

use nalgebra::{Matrix2, Vector2};

use super::IpcError;
use crate::statics::{Statics, WarmStart};

/// `[∂pose/∂px, ∂pose/∂py]`: how a reachable pose changes when its tip
/// moves laterally (per metre).
pub type Tangent = [[f64; 7]; 2];

/// A desired tip pose and its time derivative at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PosePoint {
    /// px, py, pz (m), qw, qx, qy, qz.
    pub pose: [f64; 7],
    /// d(pose)/dt (per second).
    pub velocity: [f64; 7],
    /// The reachable family's tangent at `pose`, if the trajectory knows it
    /// (lifted paths do; a pose table does not).
    pub tangent: Option<Tangent>,
}

/// Bend vector (N) → tensions: each tendon pulls by the bend's component
/// along its own direction, or not at all.
pub fn bend_tensions(statics: &Statics, bend: &Vector2<f64>) -> Vec<f64> {
    statics
        .robot()
        .tendons
        .iter()
        .map(|t| {
            let dir = Vector2::new(t.angle.cos(), t.angle.sin());
            bend.dot(&dir).max(0.0).min(t.max_tension)
        })
        .collect()
}

/// Lifts lateral tip positions to reachable poses by Newton on the bend
/// vector, warm-started along the path.
pub struct Lifter<'a> {
    statics: &'a Statics,
    bend: Vector2<f64>,
    warm: Option<WarmStart>,
}

impl<'a> Lifter<'a> {
    /// A lifter starting from zero bend.
    pub fn new(statics: &'a Statics) -> Lifter<'a> {
        Lifter {
            statics,
            bend: Vector2::zeros(),
            warm: None,
        }
    }

    fn tip(&mut self, bend: &Vector2<f64>) -> Result<([f64; 7], Vector2<f64>), IpcError> {
        let tau = bend_tensions(self.statics, bend);
        let sol = self
            .statics
            .solve(&tau, self.warm.as_ref())
            .or_else(|_| self.statics.solve(&tau, None))
            .map_err(|e| IpcError::Other(format!("lifting a trajectory point: {e}")))?;
        self.warm = Some(sol.warm.clone());
        let pose = sol.pose();
        Ok((pose, Vector2::new(pose[0], pose[1])))
    }

    /// The reachable pose whose tip is at lateral position `xy` (m).
    pub fn lift(&mut self, xy: [f64; 2]) -> Result<[f64; 7], IpcError> {
        self.lift_with_tangent(xy).map(|(pose, _)| pose)
    }

    /// The reachable pose at lateral position `xy` (m) and its tangent
    /// `[∂pose/∂px, ∂pose/∂py]` along the reachable family: with bend `b`,
    /// `∂pose/∂xy = (∂pose/∂b)(∂xy/∂b)⁻¹`, by forward differences on `b`
    /// at the converged bend (two more warm solves).
    pub fn lift_with_tangent(&mut self, xy: [f64; 2]) -> Result<([f64; 7], Tangent), IpcError> {
        let pose = self.lift_pose(xy)?;
        let h = 1e-3; // N: small against the bends used (≥ 0.1 N per mm)
        let bend = self.bend;
        let warm = self.warm.clone();
        let (px, _) = self.tip(&(bend + Vector2::new(h, 0.0)))?;
        let (py, _) = self.tip(&(bend + Vector2::new(0.0, h)))?;
        self.warm = warm;
        let dx: Vec<f64> = (0..7).map(|k| (px[k] - pose[k]) / h).collect();
        let dy: Vec<f64> = (0..7).map(|k| (py[k] - pose[k]) / h).collect();
        let j = Matrix2::new(dx[0], dy[0], dx[1], dy[1]);
        let Some(ji) = j.try_inverse() else {
            return Err(IpcError::Config(format!(
                "tip position ({:.1}, {:.1}) mm: the robot cannot move laterally there",
                xy[0] * 1e3,
                xy[1] * 1e3
            )));
        };
        let mut tangent = [[0.0; 7]; 2];
        for k in 0..7 {
            let row = nalgebra::RowVector2::new(dx[k], dy[k]) * ji;
            tangent[0][k] = row[0];
            tangent[1][k] = row[1];
        }
        Ok((pose, tangent))
    }

    fn lift_pose(&mut self, xy: [f64; 2]) -> Result<[f64; 7], IpcError> {
        let target = Vector2::new(xy[0], xy[1]);
        let h = 1e-4; // N, finite-difference step on the bend
        let mut bend = self.bend;
        for _ in 0..40 {
            let (pose, p) = self.tip(&bend)?;
            let r = p - target;
            if r.norm() < 1e-8 {
                self.bend = bend;
                return Ok(pose);
            }
            let (_, px) = self.tip(&(bend + Vector2::new(h, 0.0)))?;
            let (_, py) = self.tip(&(bend + Vector2::new(0.0, h)))?;
            let j = Matrix2::from_columns(&[(px - p) / h, (py - p) / h]);
            // A singular Jacobian: the bend saturated every tendon it uses.
            let Some(step) = j.try_inverse().map(|ji| ji * r) else {
                break;
            };
            // Damp big steps: the map is smooth but strongly nonlinear at large bends.
            let scale = (2.0 / step.norm().max(1e-12)).min(1.0);
            bend -= step * scale;
            let max = self
                .statics
                .robot()
                .tendons
                .iter()
                .map(|t| t.max_tension)
                .fold(f64::INFINITY, f64::min);
            if bend.norm() > 2.0 * max {
                break;
            }
        }
        Err(IpcError::Config(format!(
            "tip position ({:.1}, {:.1}) mm is outside the robot's workspace",
            xy[0] * 1e3,
            xy[1] * 1e3
        )))
    }
}

/// What the planner follows.
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// Hold one lateral position.
    Hold([f64; 2]),
    /// Visit lateral positions in turn, `dwell` seconds each.
    Steps {
        /// Targets (m).
        targets: Vec<[f64; 2]>,
        /// Seconds per target.
        dwell: f64,
    },
    /// Circle of `radius` (m) about `center` at `freq` (Hz), starting at +x.
    Circle {
        /// Centre (m).
        center: [f64; 2],
        /// Radius (m).
        radius: f64,
        /// Revolutions per second.
        freq: f64,
    },
    /// Lemniscate of Gerono (figure eight) of half-width `radius` about `center`.
    FigureEight {
        /// Centre (m).
        center: [f64; 2],
        /// Half-width (m).
        radius: f64,
        /// Periods per second.
        freq: f64,
    },
    /// Full poses from a CSV (`t,px,py,pz,qw,qx,qy,qz`, t in s, increasing).
    Table(Vec<(f64, [f64; 7])>),
}

/// A trajectory ready to sample: poses tabulated at a fixed time step
/// (lifted once at start-up), linearly interpolated.
#[derive(Clone, Debug)]
pub struct Trajectory {
    times: Vec<f64>,
    poses: Vec<[f64; 7]>,
    /// One per pose, or empty (a pose table).
    tangents: Vec<Tangent>,
    /// Repeats after its last time (circle, figure eight).
    periodic: bool,
    /// Piecewise-constant targets (steps, hold): no interpolation, zero velocity.
    stepwise: bool,
}

/// Table resolution for lifted continuous paths (s).
const TABLE_DT: f64 = 0.01;

impl Trajectory {
    /// Tabulate `shape` for `statics`' robot.
    pub fn new(shape: &Shape, statics: &Statics) -> Result<Trajectory, IpcError> {
        let mut lifter = Lifter::new(statics);
        match shape {
            Shape::Hold(xy) => {
                let (pose, tangent) = lifter.lift_with_tangent(*xy)?;
                Ok(Trajectory {
                    times: vec![0.0],
                    poses: vec![pose],
                    tangents: vec![tangent],
                    periodic: false,
                    stepwise: true,
                })
            }
            Shape::Steps { targets, dwell } => {
                if targets.is_empty() || *dwell <= 0.0 {
                    return Err(IpcError::Config(
                        "steps need at least one target and a positive dwell".into(),
                    ));
                }
                let mut times = Vec::new();
                let mut poses = Vec::new();
                let mut tangents = Vec::new();
                for (i, xy) in targets.iter().enumerate() {
                    let (pose, tangent) = lifter.lift_with_tangent(*xy)?;
                    times.push(i as f64 * dwell);
                    poses.push(pose);
                    tangents.push(tangent);
                }
                Ok(Trajectory {
                    times,
                    poses,
                    tangents,
                    periodic: false,
                    stepwise: true,
                })
            }
            Shape::Circle {
                center,
                radius,
                freq,
            }
            | Shape::FigureEight {
                center,
                radius,
                freq,
            } => {
                if *freq <= 0.0 || *radius < 0.0 {
                    return Err(IpcError::Config(
                        "a path needs a positive frequency and radius".into(),
                    ));
                }
                let eight = matches!(shape, Shape::FigureEight { .. });
                let period = 1.0 / freq;
                let n = ((period / TABLE_DT).ceil() as usize).max(16);
                let mut times = Vec::with_capacity(n + 1);
                let mut poses = Vec::with_capacity(n + 1);
                let mut tangents = Vec::with_capacity(n + 1);
                for i in 0..=n {
                    let t = period * i as f64 / n as f64;
                    let a = std::f64::consts::TAU * freq * t;
                    let xy = if eight {
                        [
                            center[0] + radius * a.sin(),
                            center[1] + radius * a.sin() * a.cos(),
                        ]
                    } else {
                        [center[0] + radius * a.cos(), center[1] + radius * a.sin()]
                    };
                    let (pose, tangent) = lifter.lift_with_tangent(xy)?;
                    times.push(t);
                    poses.push(pose);
                    tangents.push(tangent);
                }
                Ok(Trajectory {
                    times,
                    poses,
                    tangents,
                    periodic: true,
                    stepwise: false,
                })
            }
            Shape::Table(rows) => {
                if rows.is_empty() || rows.windows(2).any(|w| w[1].0 <= w[0].0) {
                    return Err(IpcError::Config(
                        "pose table needs rows with increasing times".into(),
                    ));
                }
                // The table's poses are the user's; their tangents come from
                // the reachable pose at the same lateral position. If some
                // row's position is out of reach there are none, and the
                // correction falls back to a constant-curvature arc.
                let tangents: Result<Vec<Tangent>, IpcError> = rows
                    .iter()
                    .map(|(_, p)| lifter.lift_with_tangent([p[0], p[1]]).map(|(_, d)| d))
                    .collect();
                let tangents = tangents.unwrap_or_else(|e| {
                    log::warn!("pose table: no tangents for the correction ({e})");
                    Vec::new()
                });
                Ok(Trajectory {
                    times: rows.iter().map(|r| r.0).collect(),
                    poses: rows.iter().map(|r| r.1).collect(),
                    tangents,
                    periodic: false,
                    stepwise: false,
                })
            }
        }
    }

    /// Duration of one pass (s); 0 for a hold.
    pub fn duration(&self) -> f64 {
        *self.times.last().unwrap_or(&0.0)
    }

    /// Pose and velocity at time `t` (s) from the start.
    pub fn sample(&self, t: f64) -> PosePoint {
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
            let i = i.min(n - 1);
            return PosePoint {
                pose: self.poses[i],
                velocity: [0.0; 7],
                tangent: self.tangents.get(i).copied(),
            };
        }
        let (t0, t1) = (self.times[i], self.times[i + 1]);
        let f = ((t - t0) / (t1 - t0)).clamp(0.0, 1.0);
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
                let mut d = [[0.0; 7]; 2];
                for (j, row) in d.iter_mut().enumerate() {
                    for (k, v) in row.iter_mut().enumerate() {
                        *v = a[j][k] + f * (b[j][k] - a[j][k]);
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

/// Read a pose table (`t,px,py,pz,qw,qx,qy,qz`, header line required).
pub fn read_pose_csv(path: &Path) -> Result<Vec<(f64, [f64; 7])>, IpcError> {
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
                rows.push((v[0], [v[1], v[2], v[3], v[4], v[5], v[6], v[7]]));
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

    fn statics() -> Statics {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../robots/seed-4t.toml");
        Statics::new(&Robot::load(&path).unwrap(), SolverSettings::default())
    }

    #[test]
    fn lifted_pose_reproduces_target_through_forward_statics() {
        let s = statics();
        let mut lifter = Lifter::new(&s);
        for xy in [[0.0, 0.0], [0.015, 0.0], [-0.01, 0.012]] {
            let pose = lifter.lift(xy).unwrap();
            assert!((pose[0] - xy[0]).abs() < 1e-7 && (pose[1] - xy[1]).abs() < 1e-7);
            // Independent check: re-solve cold from the tensions of the bend.
            let tau = bend_tensions(&s, &lifter.bend);
            let sol = s.solve(&tau, None).unwrap();
            assert!((sol.position.x - xy[0]).abs() < 1e-7);
            assert!((sol.position.z - pose[2]).abs() < 1e-9);
        }
    }

    #[test]
    fn unreachable_target_is_a_clear_error() {
        let s = statics();
        let err = Lifter::new(&s).lift([0.5, 0.0]).unwrap_err();
        assert!(err.to_string().contains("outside"), "{err}");
    }

    #[test]
    fn circle_samples_lie_on_the_circle_with_tangent_velocity() {
        let s = statics();
        let shape = Shape::Circle {
            center: [0.0, 0.0],
            radius: 0.015,
            freq: 0.2,
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

    /// The tangent predicts the exact lift of a nearby point to second
    /// order: the error of `pose + D c` against `lift(xy + c)` falls about
    /// 4× when `c` halves, and the position part is exact.
    #[test]
    fn tangent_predicts_nearby_lifts_to_second_order() {
        let s = statics();
        for xy in [[0.0, 0.06], [0.03, -0.02], [-0.05, 0.0]] {
            let mut lifter = Lifter::new(&s);
            let (pose, d) = lifter.lift_with_tangent(xy).unwrap();
            let mut errs = Vec::new();
            for scale in [1.0, 0.5, 0.25] {
                let c = [0.002 * scale, -0.0012 * scale];
                let exact = lifter.lift([xy[0] + c[0], xy[1] + c[1]]).unwrap();
                let guess = crate::ipc::correction::family_shift(&pose, &d, c);
                assert!((guess[0] - exact[0]).abs() < 1e-7 && (guess[1] - exact[1]).abs() < 1e-7);
                let err = (2..7)
                    .map(|k| (guess[k] - exact[k]).abs())
                    .fold(0.0, f64::max);
                // A pure shift without the tangent is off by the change itself.
                let moved = (2..7)
                    .map(|k| (pose[k] - exact[k]).abs())
                    .fold(0.0, f64::max);
                assert!(
                    err < 0.05 * moved,
                    "xy {xy:?} c {c:?}: {err:e} vs {moved:e}"
                );
                errs.push(err);
            }
            for w in errs.windows(2) {
                let ratio = w[0] / w[1];
                assert!((2.5..6.0).contains(&ratio), "xy {xy:?}: errors {errs:?}");
            }
        }
    }

    #[test]
    fn pose_tables_get_the_tangent_of_the_reachable_pose_at_each_row() {
        let s = statics();
        let xys = [[0.01, 0.0], [0.0, 0.02], [-0.015, -0.005]];
        let mut lifter = Lifter::new(&s);
        let lifted: Vec<([f64; 7], Tangent)> = xys
            .iter()
            .map(|&xy| lifter.lift_with_tangent(xy).unwrap())
            .collect();
        let rows: Vec<(f64, [f64; 7])> = lifted
            .iter()
            .enumerate()
            .map(|(i, (p, _))| (i as f64, *p))
            .collect();
        let traj = Trajectory::new(&Shape::Table(rows.clone()), &s).unwrap();
        for (i, (_, d)) in lifted.iter().enumerate() {
            let got = traj.sample(i as f64).tangent.expect("a tangent");
            for j in 0..2 {
                for k in 0..7 {
                    assert!(
                        (got[j][k] - d[j][k]).abs() < 1e-4,
                        "row {i}: {got:?} vs {d:?}"
                    );
                }
            }
        }
        // A row out of reach: no tangents (the correction falls back).
        let mut far = rows;
        far[1].1[0] = 0.5;
        let traj = Trajectory::new(&Shape::Table(far), &s).unwrap();
        assert!(traj.sample(0.0).tangent.is_none());
    }
}
