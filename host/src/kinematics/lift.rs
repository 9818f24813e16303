//! The model-based lift: a continuum robot bending on its tendons has two
//! degrees of freedom, so the planner plans the tip's lateral position
//! (x, y) and lifts it to the full reachable pose (z and orientation)
//! through the statics, with tensions on the (at most two) tendons facing
//! the bend — the family of tension vectors the `adjacent` dataset sampler
//! draws (`docs/design.md` §2, §3). The lift also gives the family's tangent
//! `∂pose/∂(x, y)`, along which the firmware's integral loop moves a
//! setpoint.

use nalgebra::{Matrix2, Vector2};

use super::KinematicsError;
use crate::statics::{Statics, WarmStart};

/// `[∂pose/∂px, ∂pose/∂py]`: how a reachable pose changes when its tip
/// moves laterally (per metre).
pub type Tangent = [[f64; 7]; 2];

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

    fn tip(&mut self, bend: &Vector2<f64>) -> Result<([f64; 7], Vector2<f64>), KinematicsError> {
        let tau = bend_tensions(self.statics, bend);
        let sol = self
            .statics
            .solve(&tau, self.warm.as_ref())
            .or_else(|_| self.statics.solve(&tau, None))
            .map_err(|e| KinematicsError::Statics(e.to_string()))?;
        self.warm = Some(sol.warm.clone());
        let pose = sol.pose();
        Ok((pose, Vector2::new(pose[0], pose[1])))
    }

    /// The reachable pose whose tip is at lateral position `xy` (m).
    pub fn lift(&mut self, xy: [f64; 2]) -> Result<[f64; 7], KinematicsError> {
        self.lift_with_tangent(xy).map(|(pose, _)| pose)
    }

    /// The reachable pose at lateral position `xy` (m) and its tangent
    /// `[∂pose/∂px, ∂pose/∂py]` along the reachable family: with bend `b`,
    /// `∂pose/∂xy = (∂pose/∂b)(∂xy/∂b)⁻¹`, by forward differences on `b`
    /// at the converged bend (two more warm solves).
    pub fn lift_with_tangent(
        &mut self,
        xy: [f64; 2],
    ) -> Result<([f64; 7], Tangent), KinematicsError> {
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
            return Err(KinematicsError::Singular {
                x_mm: xy[0] * 1e3,
                y_mm: xy[1] * 1e3,
            });
        };
        let mut tangent = [[0.0; 7]; 2];
        for k in 0..7 {
            let row = nalgebra::RowVector2::new(dx[k], dy[k]) * ji;
            tangent[0][k] = row[0];
            tangent[1][k] = row[1];
        }
        Ok((pose, tangent))
    }

    fn lift_pose(&mut self, xy: [f64; 2]) -> Result<[f64; 7], KinematicsError> {
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
        Err(KinematicsError::OutsideWorkspace {
            x_mm: xy[0] * 1e3,
            y_mm: xy[1] * 1e3,
        })
    }
}

/// The pose `pose` moved laterally by `c = (cx, cy)` (m) along the robot's
/// own reachable family, to first order: `pose + [∂pose/∂px ∂pose/∂py] c`,
/// quaternion re-normalised with `w ≥ 0`. The tangent comes from the
/// statics ([`Lifter::lift_with_tangent`]), so unlike
/// [`super::arc::arc_shift`] it includes gravity and the real tendon
/// routing. The firmware's integral loop applies the same first-order shift
/// in f32 (`docs/design.md` §5).
pub fn family_shift(pose: &[f64; 7], tangent: &[[f64; 7]; 2], c: [f64; 2]) -> [f64; 7] {
    let mut out = [0.0; 7];
    for (k, v) in out.iter_mut().enumerate() {
        *v = pose[k] + tangent[0][k] * c[0] + tangent[1][k] * c[1];
    }
    let n = out[3..].iter().map(|v| v * v).sum::<f64>().sqrt();
    let sign = if out[3] < 0.0 { -1.0 } else { 1.0 };
    if n > 0.0 && n.is_finite() {
        for v in &mut out[3..] {
            *v *= sign / n;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::Robot;
    use crate::statics::SolverSettings;
    use std::path::Path;

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
                let guess = family_shift(&pose, &d, c);
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
}
