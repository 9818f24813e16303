//! `tendril.generate`: the dataset generation job of `tendril generate`
//! (docs/design.md §3), returning the rows as numpy arrays.
//!
//! Every call runs the library's job, so the rows are the ones the CLI
//! writes for the same robot, sampler, seed and count. Without a path, the
//! job writes into a temporary directory that is removed afterwards.

use std::path::{Path, PathBuf};

use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray2};
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use tendril::dataset::{Dataset, Sampler};
use tendril::jobs::dataset::{self as job, GenerateError, GenerateRequest};
use tendril::robot::DEFAULT_ROBOT;

use crate::classes::Robot;
use crate::detach::detached;
use crate::errors::{invalid, one_line, os_error, value_error};

/// `(tensions, poses)` as numpy arrays.
type Rows<'py> = (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<f64>>);

const SAMPLERS: [Sampler; 2] = [Sampler::Adjacent, Sampler::Uniform];

fn sampler(name: Option<&str>) -> PyResult<Option<Sampler>> {
    let Some(name) = name else {
        return Ok(None);
    };
    SAMPLERS
        .into_iter()
        .find(|s| s.name() == name)
        .map(Some)
        .ok_or_else(|| {
            value_error(format!(
                "sampler: {name:?} is not one of \"adjacent\", \"uniform\""
            ))
        })
}

/// The robot file the job reads for `robot` when the dataset goes to a
/// path: the sidecar records that file and its SHA-256, so it must exist
/// and hold the robot's exact text.
fn robot_file_for_sidecar(robot: &Robot) -> PyResult<PathBuf> {
    let same_text = |path: &Path| std::fs::read_to_string(path).is_ok_and(|t| t == robot.source);
    if let Some(file) = &robot.file {
        if !same_text(file) {
            return Err(value_error(format!(
                "{}: the robot file changed since Robot.load read it; load it again",
                file.display()
            )));
        }
        return Ok(file.clone());
    }
    // With no such file in the working directory, the library reads its
    // built-in copy, as `tendril generate` without --robot does.
    let default = PathBuf::from(DEFAULT_ROBOT);
    if robot.builtin && (!default.exists() || same_text(&default)) {
        return Ok(default);
    }
    Err(value_error(
        "generate(path=...): the sidecar records the robot file, and this robot was made \
         from text (or ./robots/seed-4t.toml differs from the built-in robot): save the \
         TOML to a file and pass Robot.load(file)",
    ))
}

fn raise(e: GenerateError) -> PyErr {
    match &e {
        GenerateError::Io { .. } | GenerateError::NoSpace { .. } | GenerateError::Dataset(_) => {
            os_error(&e)
        }
        GenerateError::EverySolveFailed { .. } | GenerateError::TooManyFailures { .. } => {
            PyRuntimeError::new_err(one_line(&e))
        }
        _ => invalid(&e),
    }
}

/// Sample tensions, solve the statics of each, and return the rows.
///
/// robot: a ``Robot``. samples: rows to draw (1 to 20,000,000). seed: the
/// sampler's seed. sampler: ``"adjacent"`` (two neighbouring tendons pull;
/// the default for more than two tendons) or ``"uniform"``. path: when
/// given, the CSV is written there with its JSON sidecar beside it, as
/// ``tendril generate --out path`` does (atomically). steps: RK4 steps.
///
/// Returns ``(tensions, poses)``: ``(n, k)`` in N and ``(n, 7)`` = px, py,
/// pz (m), qw, qx, qy, qz, one row per sample that solved (failed samples
/// are dropped and counted in the sidecar). Raises ``RuntimeError`` when
/// more than ``max_failure_fraction`` of the solves failed.
#[pyfunction]
#[pyo3(signature = (robot, samples, seed=1, sampler=None, path=None, *, steps=16,
                    max_failure_fraction=job::DEFAULT_MAX_FAILURE_FRACTION,
                    test_fraction=tendril::dataset::split::TEST_FRACTION, progress=false))]
#[allow(clippy::too_many_arguments)] // Python keyword arguments, each optional
pub fn generate<'py>(
    py: Python<'py>,
    robot: &Robot,
    samples: usize,
    seed: u64,
    sampler: Option<&str>,
    path: Option<PathBuf>,
    steps: usize,
    max_failure_fraction: f64,
    test_fraction: f64,
    progress: bool,
) -> PyResult<Rows<'py>> {
    let sampler = self::sampler(sampler)?;
    let scratch = tempfile::tempdir().map_err(|e| os_error(&e))?;
    let (robot_path, out) = match path {
        Some(out) => (robot_file_for_sidecar(robot)?, out),
        None => {
            let robot_path = scratch.path().join("robot.toml");
            std::fs::write(&robot_path, &robot.source).map_err(|e| os_error(&e))?;
            (robot_path, scratch.path().join("data.csv"))
        }
    };
    let request = GenerateRequest {
        robot_path,
        samples,
        seed,
        sampler,
        // The robot's default: resolved rows on three segments (design §3).
        resolve: None,
        out: out.clone(),
        max_failure_fraction,
        test_fraction,
        steps,
    };
    let data = detached(py, |stop| {
        job::generate(&request, progress, stop).map_err(raise)?;
        Dataset::read_csv(&out).map_err(|e| os_error(&e))
    })??;
    Ok((
        matrix(&data.tensions).into_pyarray(py),
        matrix(&data.poses).into_pyarray(py),
    ))
}

fn matrix(m: &nalgebra::DMatrix<f64>) -> Array2<f64> {
    Array2::from_shape_fn((m.nrows(), m.ncols()), |(r, c)| m[(r, c)])
}
