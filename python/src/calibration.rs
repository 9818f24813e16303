//! The calibration's free functions: the first bending mode from a step's
//! tracker trace (`tendril calibrate --step`), and the residual measured
//! rows show against a robot file (`tendril generate --residual-from`).

use std::path::PathBuf;

use pyo3::prelude::*;

use crate::errors::{invalid, value_error};

/// The rod's first bending mode from a tracker trace of the tip after a
/// tension step: the library call of ``tendril calibrate --step``
/// (docs/design.md §11). trace: a CSV (``t_s`` or ``t_ns`` and the tip's
/// ``x_m, y_m, z_m``, or a plant log); skip_s: seconds after the first
/// frame left out (the motors' rise, the higher modes).
///
/// Returns the fit as a dict: ``freq_hz``, ``damping_ratio``, … each with
/// ``value`` and ``interval_95`` (the CLI's ``"fit"`` object).
/// ``ValueError`` for a trace that cannot be read or fitted.
#[pyfunction]
#[pyo3(signature = (trace, skip_s=0.1))]
pub fn fit_step<'py>(py: Python<'py>, trace: PathBuf, skip_s: f64) -> PyResult<Bound<'py, PyAny>> {
    use tendril::calibrate::step;
    if !(skip_s.is_finite() && skip_s >= 0.0) {
        return Err(value_error(format!(
            "skip_s must be a number of seconds >= 0, got {skip_s}"
        )));
    }
    let read = tendril::jobs::step_trace::read_step_trace(&trace).map_err(|e| invalid(&e))?;
    let fit = step::fit_step(&read, skip_s).map_err(|e| invalid(&e))?;
    let text = serde_json::to_string(&fit).map_err(|e| value_error(e.to_string()))?;
    py.import("json")?.call_method1("loads", (text,))
}

/// A fitted residual of measured rows against a robot file's statics
/// (``fit_residual``): what the file does not explain, as a function of the
/// tensions (docs/design.md §11.5).
#[pyclass(frozen, module = "tendril._tendril")]
pub struct Residual {
    inner: tendril::calibrate::residual::Residual,
    n_tendons: usize,
    report: String,
}

#[pymethods]
impl Residual {
    /// The model's poses ``(n, 7)`` (base frame, as ``generate`` returns
    /// them) at ``tensions`` ``(n, k)``, moved by the residual: the rows of
    /// ``tendril generate --residual-from``.
    fn apply<'py>(
        &self,
        py: Python<'py>,
        tensions: numpy::PyArrayLikeDyn<'py, f64, numpy::AllowTypeChange>,
        poses: numpy::PyArrayLikeDyn<'py, f64, numpy::AllowTypeChange>,
    ) -> PyResult<Bound<'py, numpy::PyArray2<f64>>> {
        use numpy::IntoPyArray;
        let mut data = dataset(&tensions, &poses, self.n_tendons)?;
        self.inner.apply_all(&mut data);
        let rows = data.len();
        let flat: Vec<f64> = (0..rows)
            .flat_map(|i| (0..7).map(move |c| (i, c)))
            .map(|(i, c)| data.poses[(i, c)])
            .collect();
        let array = numpy::ndarray::Array2::from_shape_vec((rows, 7), flat)
            .map_err(|e| value_error(e.to_string()))?;
        Ok(array.into_pyarray(py))
    }

    /// The fit: rows, outliers, degree, λ, and the validation RMS of
    /// position (mm) and angle (degrees) without and with the residual, as
    /// in the dataset's sidecar.
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        py.import("json")?
            .call_method1("loads", (self.report.clone(),))
    }
}

/// Rows `(tensions, poses)` as a dataset of `n` tendons.
fn dataset(
    tensions: &numpy::PyArrayLikeDyn<'_, f64, numpy::AllowTypeChange>,
    poses: &numpy::PyArrayLikeDyn<'_, f64, numpy::AllowTypeChange>,
    n: usize,
) -> PyResult<tendril::dataset::Dataset> {
    use crate::arrays::{check_finite, rows};
    let t = rows(tensions, "tensions", n)?;
    let p = rows(poses, "poses", 7)?;
    check_finite(&t, "tensions", &[])?;
    check_finite(&p, "poses", &["px", "py", "pz", "qw", "qx", "qy", "qz"])?;
    if t.rows.len() != p.rows.len() {
        return Err(value_error(format!(
            "tensions has {} rows, poses {}",
            t.rows.len(),
            p.rows.len()
        )));
    }
    let m = t.rows.len();
    Ok(tendril::dataset::Dataset {
        n_tendons: n,
        tensions: nalgebra::DMatrix::from_fn(m, n, |i, j| t.rows[i][j]),
        poses: nalgebra::DMatrix::from_fn(m, 7, |i, j| p.rows[i][j]),
    })
}

/// The residual measured rows show against ``robot``'s statics at their
/// tensions: the library call of ``tendril generate --residual-from``
/// (docs/design.md §11.5). tensions: ``(n, k)`` N, as recorded; poses:
/// ``(n, 7)`` as the tracker saw them (the tracker's frame of the robot's
/// ``[base]``); seed: the validation split's. ``ValueError`` for rows of
/// another robot, too few rows, or a statics solve that fails.
#[pyfunction]
#[pyo3(signature = (robot, tensions, poses, seed=1))]
pub fn fit_residual<'py>(
    py: Python<'py>,
    robot: &crate::classes::Robot,
    tensions: numpy::PyArrayLikeDyn<'py, f64, numpy::AllowTypeChange>,
    poses: numpy::PyArrayLikeDyn<'py, f64, numpy::AllowTypeChange>,
    seed: u64,
) -> PyResult<Residual> {
    let n = robot.model.n_tendons();
    let data = dataset(&tensions, &poses, n)?;
    let statics =
        tendril::statics::Statics::new(&robot.model, tendril::statics::SolverSettings::default());
    let fitted = crate::detach::detached(py, |_| {
        tendril::calibrate::residual::fit(&statics, &data, "rows", seed)
    })?;
    let (inner, report) = fitted.map_err(|e| invalid(&e))?;
    let report = serde_json::to_string(&report).map_err(|e| value_error(e.to_string()))?;
    Ok(Residual {
        inner,
        n_tendons: n,
        report,
    })
}
