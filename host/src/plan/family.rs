//! The robot's family of reachable tip positions (`docs/design.md` §6): its
//! dimension k and k unit axes in the base frame, the coordinates the
//! planner plans in and the firmware's correction integrates along.
//!
//! - k = 3 (axes x, y, z): two or more anchor groups that can each bend
//!   sideways in two directions (a two-segment robot) place the tip in a
//!   volume;
//! - k = 2 (axes x, y): one such group bends the tip over a surface, whose
//!   height and orientation follow from the lateral position;
//! - k = 1: every tendon pulls along one line (one tendon, or tendons at
//!   equal or opposite angles), so the tip moves on a curve; the axis is
//!   the lateral direction in which it moves as tension grows (from the
//!   statics, gravity included: tip at full pull minus tip at the floors).

use nalgebra::Vector3;

use super::PlanError;
use crate::robot::anchor_groups;
use crate::statics::Statics;

/// Tendon directions whose cross product is below this span one line.
const PARALLEL: f64 = 1e-6;

/// Dimension and axes of the robot's reachable tip positions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Family {
    dim: usize,
    axes: [[f64; 3]; 3],
}

impl Family {
    /// The lateral family (k = 2, axes x and y): a one-segment robot.
    pub const LATERAL: Family = Family {
        dim: 2,
        axes: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]],
    };

    /// The volume family (k = 3, axes x, y, z).
    pub const VOLUME: Family = Family {
        dim: 3,
        axes: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
    };

    /// A curve along the unit lateral `axis` (k = 1); `None` unless it is a
    /// finite non-zero vector.
    pub fn curve(axis: [f64; 3]) -> Option<Family> {
        let a = Vector3::from(axis);
        let n = a.norm();
        (n.is_finite() && n > 0.0).then(|| Family {
            dim: 1,
            axes: [(a / n).into(), [0.0; 3], [0.0; 3]],
        })
    }

    /// The family of `statics`' robot (module docs). Errors when no tension
    /// moves the tip sideways.
    pub fn of(statics: &Statics) -> Result<Family, PlanError> {
        let robot = statics.robot();
        let direction = |i: usize| {
            let t = &robot.tendons[i];
            [t.angle.cos(), t.angle.sin()]
        };
        let spans_plane = |tendons: &[usize]| {
            tendons.iter().any(|&i| {
                tendons.iter().any(|&j| {
                    let (a, b) = (direction(i), direction(j));
                    (a[0] * b[1] - a[1] * b[0]).abs() > PARALLEL
                })
            })
        };
        let bending: Vec<usize> = (0..robot.n_tendons())
            .filter(|&i| robot.tendons[i].offset > 0.0)
            .collect();
        let groups = anchor_groups(robot);
        let planar_groups = groups.iter().filter(|g| spans_plane(g)).count();
        if planar_groups >= 2 {
            return Ok(Family::VOLUME);
        }
        if spans_plane(&bending) {
            return Ok(Family::LATERAL);
        }
        // One line: pull every tendon on the first one's side.
        let Some(&first) = bending.first() else {
            return Err(PlanError::Immobile);
        };
        let d0 = direction(first);
        let floors = robot.min_tensions();
        let pulled: Vec<f64> = (0..robot.n_tendons())
            .map(|i| {
                let d = direction(i);
                if bending.contains(&i) && d[0] * d0[0] + d[1] * d0[1] > 0.0 {
                    robot.tendons[i].max_tension
                } else {
                    floors[i]
                }
            })
            .collect();
        let rest = statics
            .solve(&floors, None)
            .map_err(|e| PlanError::Inverse(e.into()))?;
        let full = statics
            .solve(&pulled, None)
            .map_err(|e| PlanError::Inverse(e.into()))?;
        let d = full.position - rest.position;
        Family::curve([d.x, d.y, 0.0]).ok_or(PlanError::Immobile)
    }

    /// k: 1, 2 or 3.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// The k unit axes, base frame.
    pub fn axes(&self) -> &[[f64; 3]] {
        &self.axes[..self.dim]
    }

    /// All three axis slots (those past k are zero), as the setpoint carries them.
    pub fn axes_padded(&self) -> [[f64; 3]; 3] {
        self.axes
    }

    /// The tip's coordinates along the axes, `a_j · p` (first k entries).
    pub fn coordinates(&self, p: &[f64; 3]) -> [f64; 3] {
        let mut u = [0.0; 3];
        for (uj, a) in u.iter_mut().zip(self.axes()) {
            *uj = a[0] * p[0] + a[1] * p[1] + a[2] * p[2];
        }
        u
    }

    /// What the family is, for messages: "a volume (k = 3)" and so on.
    pub fn describe(&self) -> String {
        match self.dim {
            3 => "a volume (k = 3: x, y, z)".into(),
            2 => "a surface over the lateral plane (k = 2: x, y)".into(),
            _ => {
                let a = self.axes[0];
                format!(
                    "a curve (k = 1: along ({:.3}, {:.3}, {:.3}))",
                    a[0], a[1], a[2]
                )
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn family(file: &str) -> Family {
        Family::of(&crate::statics::repo_statics(file)).unwrap()
    }

    /// The dimension follows the anchor groups: two bending segments reach a
    /// volume, one a surface; the one-tendon robot's axis is +x, the side
    /// its tendon (at angle 0) pulls toward (gravity along x bends it that
    /// way too, so the difference is along x).
    #[test]
    fn dimension_and_axes_follow_the_tendon_layout() {
        assert_eq!(family("seed-4t.toml"), Family::LATERAL);
        assert_eq!(family("tdcr-2seg.toml"), Family::VOLUME);
        let one = family("seed-1t.toml");
        assert_eq!(one.dim(), 1);
        let a = one.axes()[0];
        assert!(
            (a[0] - 1.0).abs() < 1e-9 && a[1].abs() < 1e-9 && a[2] == 0.0,
            "{a:?}"
        );
    }

    #[test]
    fn coordinates_project_on_the_axes() {
        let f = Family::curve([3.0, 4.0, 0.0]).unwrap();
        let u = f.coordinates(&[1.0, 2.0, 7.0]);
        assert!((u[0] - (0.6 + 1.6)).abs() < 1e-12 && u[1] == 0.0);
        assert!(Family::curve([0.0; 3]).is_none());
    }
}
