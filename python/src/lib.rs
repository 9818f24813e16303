//! Python bindings of tendril (docs/design.md §8): `tendril._tendril`, re-exported
//! by the pure-Python package `tendril`. The Rust library knows nothing of
//! Python; this crate only converts arrays and errors and releases the GIL.

mod arrays;
mod calibration;
mod classes;
mod detach;
mod errors;
mod generate;
mod net;
mod robot;

use pyo3::prelude::*;

#[pymodule]
fn _tendril(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<classes::Robot>()?;
    m.add_class::<classes::Net>()?;
    m.add_function(wrap_pyfunction!(generate::generate, m)?)?;
    m.add_function(wrap_pyfunction!(calibration::fit_step, m)?)?;
    m.add_function(wrap_pyfunction!(calibration::fit_residual, m)?)?;
    m.add_class::<calibration::Residual>()?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
