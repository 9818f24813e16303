//! The fit's view of the data (`docs/design.md` §11): what is observed per
//! row and how, the model tips the residuals compare with the measurements,
//! and the residuals themselves. The estimator (`fit.rs`) and the
//! sensitivities (`sensitivity.rs`) both work on a [`Problem`].

use nalgebra::{DVector, Matrix3, UnitQuaternion, Vector3};
use rayon::prelude::*;

use super::data::Measurements;
use super::params::Values;
use super::CalibError;
use crate::robot::Robot;
use crate::statics::pose::{orthonormalise, quaternion_wxyz};
use crate::statics::{Solution, SolverSettings, Statics, TipVector};

/// Relative central-difference step: the parameter moves by ±1e-4 of its
/// scale ([`super::params::scale`]). The truncation error is O(h²) ≈ 1e-8
/// of the sensitivity; the solve's own error (residual ≤ 5e-10 N) divided
/// by h stays far below the tracker's noise.
pub const FD_STEP: f64 = 1e-4;

/// A model tip the residuals compare with a measurement: a solution's, or
/// one moved to first order by a parameter's sensitivity.
#[derive(Clone, Copy, Debug)]
pub(super) struct ModelTip {
    pub(super) position: Vector3<f64>,
    pub(super) quaternion: [f64; 4],
}

impl ModelTip {
    pub(super) fn of(sol: &Solution) -> ModelTip {
        ModelTip {
            position: sol.position,
            quaternion: sol.quaternion,
        }
    }

    /// `sol`'s tip moved by `sign` × `d` (position, then R column by
    /// column), R made a rotation again.
    pub(super) fn moved(sol: &Solution, d: &TipVector, sign: f64) -> ModelTip {
        let dr = Matrix3::from_column_slice(&d.as_slice()[3..12]);
        ModelTip {
            position: sol.position + sign * d.fixed_rows::<3>(0),
            quaternion: quaternion_wxyz(&orthonormalise(&(sol.rotation + sign * dr))),
        }
    }
}

pub(super) fn tips(sols: &[Solution]) -> Vec<ModelTip> {
    sols.iter().map(ModelTip::of).collect()
}

/// The fit's view of the data: what is observed per row and how.
pub(super) struct Problem<'a> {
    pub(super) nominal: &'a Robot,
    pub(super) nominal_values: Values,
    pub(super) data: &'a Measurements,
    pub(super) use_orientation: bool,
    pub(super) orientation_m_per_rad: f64,
    pub(super) settings: SolverSettings,
}

impl Problem<'_> {
    /// Residual entries per row: 3 position, plus 3 orientation.
    pub(super) fn dims(&self) -> usize {
        if self.use_orientation {
            6
        } else {
            3
        }
    }

    /// Statics of every row at `v`, warm-started from `warm` when given.
    pub(super) fn solve(
        &self,
        v: &Values,
        rows: &[usize],
        warm: Option<&[Solution]>,
    ) -> Result<Vec<Solution>, CalibError> {
        let statics = Statics::new(&v.solving_robot(self.nominal), self.settings);
        rows.par_iter()
            .enumerate()
            .map(|(k, &i)| {
                let tau = v.scaled_tensions(&self.data.tensions[i]);
                let f = Vector3::from(self.data.tip_forces[i]);
                let m = Vector3::from(self.data.tip_moments[i]);
                let w = warm.map(|s| &s[k].warm);
                statics
                    .solve_loaded(&tau, f, m, w)
                    .map_err(|error| CalibError::Solve {
                        line: self.data.lines[i],
                        error,
                    })
            })
            .collect()
    }

    /// Residuals (measured − model) of `rows`, row-major.
    pub(super) fn residuals(&self, v: &Values, rows: &[usize], sols: &[ModelTip]) -> DVector<f64> {
        let d = self.dims();
        let mut r = DVector::zeros(rows.len() * d);
        // The model's tips in the tracker's frame: p_tracker = R_b p + t_b.
        let to_tracker = v.base().to_tracker();
        let qb = UnitQuaternion::from_scaled_axis(Vector3::from(v.base_rotation));
        for (k, &i) in rows.iter().enumerate() {
            let p = Vector3::from(to_tracker.point(sols[k].position.into()));
            let e = Vector3::from(self.data.positions[i]) - p;
            r.fixed_rows_mut::<3>(k * d).copy_from(&e);
            if let (true, Some(q)) = (self.use_orientation, &self.data.quaternions) {
                let [w, x, y, z] = q[i];
                let measured =
                    UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
                let [w, x, y, z] = sols[k].quaternion;
                let tip = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
                let model = qb * tip;
                // The rotation taking the model's tip frame to the measured
                // one, as a rotation vector (rad), weighed as a length.
                let err = (measured * model.inverse()).scaled_axis();
                r.fixed_rows_mut::<3>(k * d + 3)
                    .copy_from(&(err * self.orientation_m_per_rad));
            }
        }
        r
    }
}
