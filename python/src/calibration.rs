//! The calibration's functions that need no robot: the first bending mode
//! from a step's tracker trace (`tendril calibrate --step`).

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
    let read = step::read_trace(&trace).map_err(|e| invalid(&e))?;
    let fit = step::fit_step(&read, skip_s).map_err(|e| invalid(&e))?;
    let text = serde_json::to_string(&fit).map_err(|e| value_error(e.to_string()))?;
    py.import("json")?.call_method1("loads", (text,))
}
