//! `tendril.Robot`: a validated robot description and its forward statics
//! (docs/design.md §2, §8). Batches go through `statics::batch::solve_all`,
//! the path of `tendril fk --input`, so poses are bit-identical to the CLI's.

use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use numpy::ndarray::{Array1, Array2};
use numpy::{AllowTypeChange, IntoPyArray, PyArray1, PyArrayLikeDyn};
use pyo3::prelude::*;
use pyo3::types::PyTuple;
use rayon::prelude::*;
use tendril::inverse::{ExactIk, IkSettings};
use tendril::jobs::ik_batch::answer;
use tendril::robot::{Robot as RobotModel, BUILTIN_DEFAULT_TOML};
use tendril::statics::batch::{solve_all, Load};
use tendril::statics::{SolverSettings, Statics, MAX_STEPS};

use crate::arrays::{check_finite, rows, Rows};
use crate::classes::{Net, Robot};
use crate::detach::detached;
use crate::errors::{invalid, os_error, runtime_error, value_error};

use crate::classes::BUILTIN_ORIGIN;
/// Backbone points `shape` accepts at most (as `tendril fk --shape`).
const MAX_SHAPE_POINTS: usize = 100_000;
const FORCE_COLUMNS: [&str; 3] = ["fx", "fy", "fz"];
const MOMENT_COLUMNS: [&str; 3] = ["mx", "my", "mz"];

fn settings(steps: usize) -> PyResult<SolverSettings> {
    if !(1..=MAX_STEPS).contains(&steps) {
        return Err(value_error(format!(
            "steps: {steps} is outside 1..={MAX_STEPS} (RK4 steps over the backbone length)"
        )));
    }
    Ok(SolverSettings {
        steps,
        ..SolverSettings::default()
    })
}

/// A tip-load argument: `None` (no load), `(3,)` for every row, or `(n, 3)`.
fn wrench(
    arg: Option<&PyArrayLikeDyn<'_, f64, AllowTypeChange>>,
    name: &str,
    columns: &[&str; 3],
    n: usize,
) -> PyResult<Vec<Vector3<f64>>> {
    let Some(arg) = arg else {
        return Ok(vec![Vector3::zeros(); n]);
    };
    let given = rows(arg, name, 3)?;
    check_finite(&given, name, columns)?;
    let vectors: Vec<Vector3<f64>> = given
        .rows
        .iter()
        .map(|r| Vector3::from_row_slice(r))
        .collect();
    match vectors.len() {
        _ if given.single => Ok(vec![vectors[0]; n]),
        m if m == n => Ok(vectors),
        m => Err(value_error(format!(
            "{name}: {m} rows for {n} rows of tensions; give (3,) for all rows or ({n}, 3)"
        ))),
    }
}

impl Robot {
    fn statics(&self, steps: usize) -> PyResult<Statics> {
        Ok(Statics::new(&self.model, settings(steps)?))
    }

    /// Tension rows checked against the robot, with their tip loads.
    fn loads(
        &self,
        tensions: &Rows,
        tip_force: Option<&PyArrayLikeDyn<'_, f64, AllowTypeChange>>,
        tip_moment: Option<&PyArrayLikeDyn<'_, f64, AllowTypeChange>>,
    ) -> PyResult<Vec<Load>> {
        let n = tensions.rows.len();
        let forces = wrench(tip_force, "tip_force", &FORCE_COLUMNS, n)?;
        let moments = wrench(tip_moment, "tip_moment", &MOMENT_COLUMNS, n)?;
        tensions
            .rows
            .iter()
            .zip(forces.into_iter().zip(moments))
            .enumerate()
            .map(|(r, (t, (tip_force, tip_moment)))| {
                self.model
                    .check_tensions(t)
                    .map_err(|e| value_error(format!("tensions: row {r}: {e}")))?;
                Ok(Load {
                    tensions: t.clone(),
                    tip_force,
                    tip_moment,
                })
            })
            .collect()
    }
}

#[pymethods]
impl Robot {
    /// Load and validate a robot file (TOML). Raises ``OSError`` when the
    /// file cannot be read, ``ValueError`` naming the field when it is invalid.
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Robot> {
        match RobotModel::load_with_source(&path) {
            Ok((model, source)) => Ok(Robot {
                model,
                source,
                file: Some(path),
                builtin: false,
            }),
            Err(e) if std::fs::read(&path).is_err() => Err(os_error(&e)),
            Err(e) => Err(invalid(&e)),
        }
    }

    /// Parse and validate robot TOML text. ``ValueError`` names the field.
    #[staticmethod]
    fn from_toml(text: &str) -> PyResult<Robot> {
        let model = RobotModel::from_toml(text, Path::new("<text>")).map_err(|e| invalid(&e))?;
        Ok(Robot {
            model,
            source: text.to_string(),
            file: None,
            builtin: false,
        })
    }

    /// The built-in default robot (robots/seed-4t.toml: the seed paper's
    /// four-tendon robot), the one ``tendril`` uses without ``--robot``.
    #[staticmethod]
    pub fn default() -> PyResult<Robot> {
        let model = RobotModel::from_toml(BUILTIN_DEFAULT_TOML, Path::new(BUILTIN_ORIGIN))
            .map_err(|e| invalid(&e))?;
        Ok(Robot {
            model,
            source: BUILTIN_DEFAULT_TOML.to_string(),
            file: None,
            builtin: true,
        })
    }

    /// Robot name from the file.
    #[getter]
    fn name(&self) -> &str {
        &self.model.name
    }

    /// Number of tendons ``k``.
    #[getter]
    fn n_tendons(&self) -> usize {
        self.model.n_tendons()
    }

    /// Backbone reference length, m.
    #[getter]
    fn length(&self) -> f64 {
        self.model.length
    }

    /// Largest tension of each tendon, N, shape ``(k,)``.
    #[getter]
    fn max_tensions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.model.max_tensions().into_pyarray(py)
    }

    /// Pretension floor of each tendon, N, shape ``(k,)``.
    #[getter]
    fn min_tensions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.model.min_tensions().into_pyarray(py)
    }

    /// The robot file's path, or ``None`` (made from text or built in).
    #[getter]
    fn file(&self) -> Option<PathBuf> {
        self.file.clone()
    }

    /// The TOML text the robot was made from.
    #[getter]
    fn toml(&self) -> &str {
        &self.source
    }

    /// Where the base sits in the tracker's frame (the file's ``[base]``,
    /// docs/design.md §2.4): ``(translation (3,) m, rotation vector (3,)
    /// rad)``; zeros without one. ``fk``, ``shape`` and ``ik`` work in that
    /// frame.
    #[getter]
    fn base<'py>(&self, py: Python<'py>) -> (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>) {
        let b = self.model.base;
        (
            b.translation.to_vec().into_pyarray(py),
            b.rotation.to_vec().into_pyarray(py),
        )
    }

    /// Tension sets to measure for a calibration: the library call of
    /// ``tendril calibrate --plan n`` (greedy D-optimal over the rod's
    /// parameters in ``fit``). tip_mass_g: hang this mass on the tip in
    /// some rows (a known load makes E identifiable; needs gravity in the
    /// robot file).
    ///
    /// Returns ``(tensions (n, k) N, tip_forces (n, 3) N, base frame)``:
    /// measure each row with its force applied (zero: nothing hung).
    /// ``ValueError`` for bad options.
    #[pyo3(signature = (n, fit=tendril::calibrate::DEFAULT_FIT, seed=1, tip_mass_g=None))]
    fn calibration_plan<'py>(
        &self,
        py: Python<'py>,
        n: usize,
        fit: &str,
        seed: u64,
        tip_mass_g: Option<f64>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        use tendril::calibrate::{self as cal, plan};
        let params = cal::parse_fit_list(fit, self.model.n_tendons()).map_err(value_error)?;
        let load = match tip_mass_g {
            None => None,
            Some(g) if g.is_finite() && g > 0.0 => Some(
                plan::hung_mass_force(&self.model, g).ok_or_else(|| {
                    value_error("tip_mass_g: the robot has no gravity, so a hung mass's direction is unknown")
                })?,
            ),
            Some(g) => return Err(value_error(format!("tip_mass_g must be a mass > 0 g, got {g}"))),
        };
        let model = &self.model;
        let fit = plan::plannable(model, &params);
        let rows =
            detached(py, |_| plan::plan(model, &fit, n, seed, load))?.map_err(|e| invalid(&e))?;
        let k = model.n_tendons();
        let tensions = Array2::from_shape_fn((rows.len(), k), |(r, c)| rows[r].tensions[c]);
        let forces = Array2::from_shape_fn((rows.len(), 3), |(r, c)| rows[r].tip_force[c]);
        (tensions.into_pyarray(py), forces.into_pyarray(py)).into_pyobject(py)
    }

    fn __repr__(&self) -> String {
        let origin = match (&self.file, self.builtin) {
            (Some(f), _) => f.display().to_string(),
            (None, true) => BUILTIN_ORIGIN.to_string(),
            (None, false) => "<text>".to_string(),
        };
        format!(
            "Robot({:?}, {} tendons, from {origin})",
            self.model.name,
            self.model.n_tendons()
        )
    }

    /// Fit this robot's parameters to measured tip poses: the library call
    /// of ``tendril calibrate`` (docs/design.md §11).
    ///
    /// data: a measured CSV (t0..t{k-1} [N], px, py, pz [m], optional
    /// qw..qz, fx,fy,fz, mx,my,mz). fit: the parameter list of ``--fit``.
    /// holdout: fraction of rows held out; seed: its split;
    /// positions_only: ignore orientations; mm_per_deg: orientation weight;
    /// tension_noise_n: the load cells' noise, N (its tip scatter may remain).
    ///
    /// Returns ``(robot, report)``: the calibrated ``Robot`` (its ``toml`` is
    /// the file the CLI writes) and the report as a dict (the CLI's
    /// ``.report.json``). ``ValueError`` for bad data or options,
    /// ``OSError`` when the file cannot be read, ``RuntimeError`` when a
    /// statics solve fails. Ctrl-C raises once the fit returns.
    #[pyo3(signature = (data, fit=tendril::calibrate::DEFAULT_FIT, holdout=0.2, seed=1, positions_only=false, mm_per_deg=0.1 * 1e3 * std::f64::consts::PI / 180.0, tension_noise_n=0.0))]
    #[allow(clippy::too_many_arguments)]
    fn calibrate<'py>(
        &self,
        py: Python<'py>,
        data: PathBuf,
        fit: &str,
        holdout: f64,
        seed: u64,
        positions_only: bool,
        mm_per_deg: f64,
        tension_noise_n: f64,
    ) -> PyResult<(Robot, Bound<'py, PyAny>)> {
        use tendril::calibrate::{self as cal, CalibError};
        let params = cal::parse_fit_list(fit, self.model.n_tendons()).map_err(value_error)?;
        if !(mm_per_deg.is_finite() && mm_per_deg > 0.0) {
            return Err(value_error(format!(
                "mm_per_deg must be a positive number, got {mm_per_deg}"
            )));
        }
        if std::fs::metadata(&data).is_err() {
            return Err(os_error(&std::io::Error::new(
                std::io::ErrorKind::NotFound,
                format!("{}: cannot read", data.display()),
            )));
        }
        let measured = cal::read_measurements(&data, &self.model).map_err(|e| invalid(&e))?;
        let mut opts = cal::FitOptions::new(params);
        opts.holdout_fraction = holdout;
        opts.seed = seed;
        opts.use_orientation = !positions_only;
        opts.orientation_m_per_rad = mm_per_deg * 1e-3 * 180.0 / std::f64::consts::PI;
        if !(tension_noise_n.is_finite() && (0.0..=1.0).contains(&tension_noise_n)) {
            return Err(value_error(format!(
                "tension_noise_n must be a tension in [0, 1] N, got {tension_noise_n}"
            )));
        }
        opts.tension_noise_n = tension_noise_n;
        let model = &self.model;
        let result = detached(py, |_| cal::calibrate(model, &measured, &opts))?;
        let c = match result {
            Ok(c) => c,
            Err(e @ CalibError::Solve { .. }) => return Err(runtime_error(&e)),
            Err(e) => return Err(invalid(&e)),
        };
        let text = c.robot_file();
        let robot = Robot::from_toml(&text)?;
        let report = py
            .import("json")?
            .call_method1("loads", (c.report.json(),))?;
        Ok((robot, report))
    }

    /// Forward statics: tip poses for tendon tensions.
    ///
    /// tensions: ``(n, k)`` (or ``(k,)`` for one row), N, each in
    /// ``[0, max_tension]``. tip_force / tip_moment: external tip load in
    /// the base frame, N and N m, ``(3,)`` for every row or ``(n, 3)``.
    /// steps: RK4 steps over the length.
    ///
    /// Returns ``(poses, converged)``: poses ``(n, 7)`` = px, py, pz (m),
    /// qw, qx, qy, qz (unit, w >= 0) in the tracker's frame of the robot
    /// file's ``[base]`` (the base frame without one), NaN where the solve
    /// did not converge;
    /// converged ``(n,)`` bool. For a ``(k,)`` input, ``(7,)`` and a bool.
    /// Rows run in parallel with the GIL released; the results are
    /// bit-identical to ``tendril fk --input`` for the same rows.
    #[pyo3(signature = (tensions, tip_force=None, tip_moment=None, steps=SolverSettings::default().steps))]
    fn fk<'py>(
        &self,
        py: Python<'py>,
        tensions: PyArrayLikeDyn<'py, f64, AllowTypeChange>,
        tip_force: Option<PyArrayLikeDyn<'py, f64, AllowTypeChange>>,
        tip_moment: Option<PyArrayLikeDyn<'py, f64, AllowTypeChange>>,
        steps: usize,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let statics = self.statics(steps)?;
        let given = rows(&tensions, "tensions", self.model.n_tendons())?;
        let loads = self.loads(&given, tip_force.as_ref(), tip_moment.as_ref())?;
        let results = detached(py, |stop| solve_all(&statics, &loads, stop, &|_| {}))?
            .ok_or_else(|| value_error("fk: stopped before the end"))?;
        let mut poses = Array2::from_elem((loads.len(), 7), f64::NAN);
        let mut converged = Array1::from_elem(loads.len(), false);
        let to_tracker = self.model.base.to_tracker();
        for (r, result) in results.iter().enumerate() {
            if let Ok(sol) = result {
                for (c, x) in to_tracker.pose(sol.pose()).into_iter().enumerate() {
                    poses[(r, c)] = x;
                }
                converged[r] = true;
            }
        }
        if given.single {
            let pose = poses.row(0).to_owned().into_pyarray(py);
            return (pose, converged[0]).into_pyobject(py);
        }
        (poses.into_pyarray(py), converged.into_pyarray(py)).into_pyobject(py)
    }

    /// Exact, model-based inverse kinematics (docs/design.md §4.1): the
    /// tensions whose statics put the tip at each target, to a micron.
    ///
    /// targets: ``(n, 7)`` (or ``(7,)``) poses px, py, pz (m), qw, qx, qy,
    /// qz (unit quaternion), in the frame of ``fk`` (as are the reached
    /// poses). position_only: reach the position and ignore the orientation. net: a ``Net`` whose answer starts the search
    /// (faster); without one the search starts from the tension floors.
    /// Among tensions that reach a target the least total tension above the
    /// floors is returned.
    ///
    /// Returns ``(tensions (n, k) N, poses (n, 7) reached, position_error
    /// (n,) m, reachable (n,) bool)``; an unreachable target gives the
    /// closest reachable pose with ``reachable = False``. For a ``(7,)``
    /// input, one row of each. Rows run in parallel with the GIL released.
    /// strict: raise ``ValueError`` for the first unreachable target (its
    /// row, its distance from the closest reachable pose and the limits
    /// that bind) instead of returning it flagged.
    /// Raises ``ValueError`` for a bad target (naming its row) and
    /// ``RuntimeError`` when the search fails.
    #[pyo3(signature = (targets, position_only=false, net=None, strict=false))]
    fn ik<'py>(
        &self,
        py: Python<'py>,
        targets: PyArrayLikeDyn<'py, f64, AllowTypeChange>,
        position_only: bool,
        net: Option<&Net>,
        strict: bool,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let given = rows(&targets, "targets", 7)?;
        if let Some(n) = net {
            if n.ik.tendons() != self.model.n_tendons() {
                return Err(value_error(format!(
                    "net: {} outputs for a robot with {} tendons",
                    n.ik.tendons(),
                    self.model.n_tendons()
                )));
            }
        }
        let solver = ExactIk::new(&self.model, IkSettings::default());
        let guess = net.map(|n| &n.ik);
        let answers = detached(py, |_| {
            given
                .rows
                .par_iter()
                .map(|row| {
                    let mut pose = [0.0; 7];
                    pose.copy_from_slice(row);
                    answer(&solver, guess, &pose, position_only)
                })
                .collect::<Vec<_>>()
        })?;
        let (n, k) = (answers.len(), self.model.n_tendons());
        let mut tensions = Array2::from_elem((n, k), f64::NAN);
        let mut poses = Array2::from_elem((n, 7), f64::NAN);
        let mut error = Array1::from_elem(n, f64::NAN);
        let mut reachable = Array1::from_elem(n, false);
        for (r, a) in answers.into_iter().enumerate() {
            let a = a.map_err(|e| {
                use tendril::inverse::InverseError as E;
                let text = format!("targets: row {r}: {e}");
                match e {
                    E::NotFinite { .. } | E::NotUnit { .. } | E::StartCount { .. } => {
                        value_error(text)
                    }
                    _ => pyo3::exceptions::PyRuntimeError::new_err(text),
                }
            })?;
            for (c, &t) in a.solution.tensions.iter().enumerate() {
                tensions[(r, c)] = t;
            }
            for (c, &x) in a.solution.pose.iter().enumerate() {
                poses[(r, c)] = x;
            }
            if strict && !a.reachable {
                return Err(value_error(format!(
                    "targets: row {r}: unreachable: the closest reachable pose is {:.3e} m away \
                     (tendons at their minimum: {:?}, at their maximum: {:?})",
                    a.solution.position_error, a.solution.at_min, a.solution.at_max
                )));
            }
            error[r] = a.solution.position_error;
            reachable[r] = a.reachable;
        }
        if given.single {
            return (
                tensions.row(0).to_owned().into_pyarray(py),
                poses.row(0).to_owned().into_pyarray(py),
                error[0],
                reachable[0],
            )
                .into_pyobject(py);
        }
        (
            tensions.into_pyarray(py),
            poses.into_pyarray(py),
            error.into_pyarray(py),
            reachable.into_pyarray(py),
        )
            .into_pyobject(py)
    }

    /// Backbone shape for one tension vector: ``points`` (>= 2) positions,
    /// base to tip, evenly spaced in arc length, in the frame of ``fk``, m, shape
    /// ``(points, 3)``. tensions ``(k,)``, N; tip load as in ``fk``.
    /// Raises ``RuntimeError`` when the statics do not converge.
    #[pyo3(signature = (tensions, points=50, tip_force=None, tip_moment=None, steps=SolverSettings::default().steps))]
    fn shape<'py>(
        &self,
        py: Python<'py>,
        tensions: PyArrayLikeDyn<'py, f64, AllowTypeChange>,
        points: usize,
        tip_force: Option<PyArrayLikeDyn<'py, f64, AllowTypeChange>>,
        tip_moment: Option<PyArrayLikeDyn<'py, f64, AllowTypeChange>>,
        steps: usize,
    ) -> PyResult<Bound<'py, numpy::PyArray2<f64>>> {
        if !(2..=MAX_SHAPE_POINTS).contains(&points) {
            return Err(value_error(format!(
                "points: {points} is outside 2..={MAX_SHAPE_POINTS}"
            )));
        }
        let statics = self.statics(steps)?;
        let given = rows(&tensions, "tensions", self.model.n_tendons())?;
        if !given.single {
            return Err(value_error(format!(
                "tensions: shape takes one tension vector ({},), not a batch",
                self.model.n_tendons()
            )));
        }
        let load = self
            .loads(&given, tip_force.as_ref(), tip_moment.as_ref())?
            .remove(0);
        let shape = detached(py, |_| {
            statics
                .equilibrium(&load.tensions, load.tip_force, load.tip_moment, None)
                .map(|sol| statics.shape(&sol, points))
        })?
        .map_err(|e| runtime_error(&e))?;
        let mut out = Array2::zeros((shape.len(), 3));
        let to_tracker = self.model.base.to_tracker();
        for (r, p) in shape.iter().enumerate() {
            for (c, x) in to_tracker.point([p.x, p.y, p.z]).into_iter().enumerate() {
                out[(r, c)] = x;
            }
        }
        Ok(out.into_pyarray(py))
    }
}
