//! `tendril.Net`: a trained `.tnet` net answering tip poses with tensions
//! through the firmware's f32 inference and the checks of `tendril ik`
//! (docs/design.md §5, §7).

use std::path::PathBuf;

use numpy::ndarray::Array2;
use numpy::{AllowTypeChange, IntoPyArray, PyArrayLikeDyn};
use pyo3::prelude::*;
use pyo3::types::PyTuple;
use tendril::net::{check_model_robot, read_model, GuardedNet, ReadError};

use crate::arrays::rows;
use crate::classes::{Net, Robot, BUILTIN_ORIGIN};
use crate::detach::detached;
use crate::errors::{invalid, os_error, value_error};

#[pymethods]
impl Net {
    /// Load a ``.tnet`` file written by ``tendril train``. robot: the robot
    /// it drives (default: ``Robot.default()``); the firmware's command stage
    /// for it turns the net's output into tensions in its limits.
    /// allow_extrapolation: answer poses outside the net's training
    /// ranges instead of refusing them. A net that records another robot
    /// than ``robot`` raises ``ValueError`` naming both, unless
    /// allow_robot_mismatch (then a warning is logged).
    #[staticmethod]
    #[pyo3(signature = (path, robot=None, allow_extrapolation=false, allow_robot_mismatch=false))]
    fn load(
        path: PathBuf,
        robot: Option<&Robot>,
        allow_extrapolation: bool,
        allow_robot_mismatch: bool,
    ) -> PyResult<Net> {
        let fallback;
        let model = match robot {
            Some(r) => &r.model,
            None => {
                fallback = tendril::robot::Robot::from_toml(
                    tendril::robot::BUILTIN_DEFAULT_TOML,
                    std::path::Path::new(BUILTIN_ORIGIN),
                )
                .map_err(|e| invalid(&e))?;
                &fallback
            }
        };
        let (net, provenance) = read_model(&path).map_err(|e| match &e {
            ReadError::Io { .. } => os_error(&e),
            _ => invalid(&e),
        })?;
        check_model_robot(
            &path,
            provenance.as_ref(),
            model,
            allow_robot_mismatch,
            "allow_robot_mismatch=True",
        )
        .map_err(|e| invalid(&e))?;
        let ik = GuardedNet::new(net, model, allow_extrapolation).map_err(|e| invalid(&e))?;
        Ok(Net {
            ik,
            to_base: model.base.to_base(),
        })
    }

    /// Number of tendons (outputs) ``k``.
    #[getter]
    fn n_tendons(&self) -> usize {
        self.ik.tendons()
    }

    /// Tensions for tip poses.
    ///
    /// poses: ``(n, 7)`` (or ``(7,)``) = px, py, pz (m), qw, qx, qy, qz (a
    /// unit quaternion; its sign is normalised to w >= 0), in the tracker's
    /// frame of the robot's ``[base]`` as ``tendril ik`` takes them (the
    /// base frame without one).
    ///
    /// Returns ``(tensions, raw)``, each ``(n, k)`` in N (``(k,)`` for one
    /// pose): what the firmware's command stage commands for the net's
    /// output (each co-contraction set shifted into range, then clipped to
    /// ``[min_tension, max_tension]``), and the output as the net gave it
    /// (tensions up to co-contraction) — the ``t*`` and ``raw_t*`` columns
    /// of ``tendril ik``.
    /// A non-finite value, a non-unit quaternion or (unless extrapolation is
    /// allowed) a pose outside the training ranges raises ``ValueError``
    /// naming the row.
    fn predict<'py>(
        &self,
        py: Python<'py>,
        poses: PyArrayLikeDyn<'py, f64, AllowTypeChange>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let given = rows(&poses, "poses", 7)?;
        let answers = detached(py, |_| {
            given
                .rows
                .iter()
                .enumerate()
                .map(|(r, pose)| {
                    let pose: [f64; 7] = pose.as_slice().try_into().unwrap_or([f64::NAN; 7]);
                    self.ik
                        .solve(&self.to_base.pose(pose))
                        .map_err(|e| value_error(format!("poses: row {r}: {e}")))
                })
                .collect::<PyResult<Vec<_>>>()
        })??;
        let k = self.ik.tendons();
        let mut tensions = Array2::zeros((answers.len(), k));
        let mut raw = Array2::zeros((answers.len(), k));
        for (r, a) in answers.iter().enumerate() {
            for c in 0..k {
                tensions[(r, c)] = a.tensions[c];
                raw[(r, c)] = a.raw[c];
            }
        }
        if given.single {
            let one = |m: Array2<f64>| m.row(0).to_owned().into_pyarray(py);
            return (one(tensions), one(raw)).into_pyobject(py);
        }
        (tensions.into_pyarray(py), raw.into_pyarray(py)).into_pyobject(py)
    }
}
