//! numpy arrays in: shape checks with messages that name the argument, the
//! shape expected and the shape given.

use numpy::{AllowTypeChange, PyArrayLikeDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::errors::value_error;

/// Rows of a float64 array of `width` columns, given as `(n, width)` or, for
/// one row, `(width,)`. The flag says whether the input was one-dimensional.
pub struct Rows {
    /// Row-major values, `n × width`.
    pub rows: Vec<Vec<f64>>,
    /// Whether the input was a single row `(width,)`.
    pub single: bool,
}

/// Read `array` (anything numpy turns into float64) as rows of `width`.
pub fn rows(
    array: &PyArrayLikeDyn<'_, f64, AllowTypeChange>,
    name: &str,
    width: usize,
) -> PyResult<Rows> {
    let view = array.as_array();
    let shape = array.shape().to_vec();
    let bad = || {
        value_error(format!(
            "{name}: expected shape ({width},) or (n, {width}), got {}",
            shape_text(&shape)
        ))
    };
    match shape.as_slice() {
        [w] if *w == width => Ok(Rows {
            rows: vec![view.iter().copied().collect()],
            single: true,
        }),
        [_, w] if *w == width => Ok(Rows {
            rows: view
                .outer_iter()
                .map(|row| row.iter().copied().collect())
                .collect(),
            single: false,
        }),
        _ => Err(bad()),
    }
}

/// A numpy-style shape: `(4,)`, `(2, 3)`.
fn shape_text(shape: &[usize]) -> String {
    match shape {
        [one] => format!("({one},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(usize::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// Reject a non-finite value of `rows`, naming the argument, row and column.
pub fn check_finite(rows: &Rows, name: &str, columns: &[&str]) -> PyResult<()> {
    for (r, row) in rows.rows.iter().enumerate() {
        if let Some((c, v)) = row.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            let column = columns.get(c).copied().unwrap_or("?");
            return Err(value_error(format!(
                "{name}: row {r}: {column} = {v} is not a finite number"
            )));
        }
    }
    Ok(())
}
