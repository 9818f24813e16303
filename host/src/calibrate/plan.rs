//! The experiment planner (`tendril calibrate --plan N`, `docs/design.md`
//! §11): a greedy D-optimal choice of tension sets among random candidates
//! within the limits, each candidate with and without a known tip load when
//! one is planned (the load makes E identifiable: without it, tendons and
//! weight bend the rod by τ·d/(E·I) and ρ·A·g/(E·I), and only the ratios
//! show in tip positions).

use nalgebra::{DMatrix, Matrix3, Vector3};

use super::params::{scale, Param, Values};
use super::CalibError;
use crate::dataset::Sampler;
use crate::robot::Robot;
use crate::statics::{SolverSettings, Statics};

/// Candidates drawn per planned row.
pub const CANDIDATES_PER_ROW: usize = 8;
/// The largest plan: rows someone measures by hand. (The work grows with
/// its square: 5,000 rows are 40,000 candidates, each compared at every
/// one of the 5,000 steps.)
pub const MAX_PLAN_ROWS: usize = 5000;

/// The parameters of `params` a plan can serve: G is left out (with a
/// warning) when it cannot show in tip positions — straight tendons and
/// no tip moment — since the planner judges rows by positions alone.
pub fn plannable(robot: &Robot, params: &[Param]) -> Vec<Param> {
    if super::identify::shear_modulus_unseen(robot, params, false, false).is_some() {
        log::warn!(
            "--plan: G is left out of the plan: with straight tendons and no tip moment it \
             shows only in tip orientations, which the planner does not weigh"
        );
        return params
            .iter()
            .copied()
            .filter(|p| *p != Param::ShearModulus)
            .collect();
    }
    params.to_vec()
}

/// One row to measure: the tensions to set and the known tip force to hang
/// on the tip while measuring (zero: none), N, base frame.
#[derive(Clone, Debug, PartialEq)]
pub struct PlannedRow {
    /// Tensions, N.
    pub tensions: Vec<f64>,
    /// The tip force, N, base frame.
    pub tip_force: [f64; 3],
}

/// The tip force of a hung mass of `grams` on `robot`: its weight along the
/// robot file's gravity (base frame). `None` when the file has no gravity
/// (its direction in the base frame is then unknown: give the force).
pub fn hung_mass_force(robot: &Robot, grams: f64) -> Option<[f64; 3]> {
    (robot.gravity.norm() > 0.0).then(|| (robot.gravity * grams * 1e-3).into())
}

/// `n` rows for `robot` that make a fit of `params` (from tip positions)
/// well conditioned: from `n × 8` (at least 200) tension candidates uniform
/// within [min_tension, max_tension] plus the zero-tension row — each also
/// with the known tip force `load` when one is given — each step adds the
/// candidate whose 3 × p sensitivity block S maximises det(M + SᵀS), M the
/// information so far (det(I + S M⁻¹ Sᵀ), a 3 × 3 determinant); M starts
/// at 1e-9 I. Only the rod's parameters matter: a frame offset is seen
/// equally in every row.
pub fn plan(
    robot: &Robot,
    params: &[Param],
    n: usize,
    seed: u64,
    load: Option<[f64; 3]>,
) -> Result<Vec<PlannedRow>, CalibError> {
    if n == 0 {
        return Err(CalibError::Options("--plan needs at least one row".into()));
    }
    if n > MAX_PLAN_ROWS {
        return Err(CalibError::Options(format!(
            "--plan {n}: at most {MAX_PLAN_ROWS} rows (a plan is measured by hand; for more \
             rows, measure tension sets spread at random: tendril generate --sampler uniform)"
        )));
    }
    let nv = Values::of(robot);
    if let Some(f) = load {
        // A load the rod cannot hold at its floors is no experiment: say so
        // before the candidates are solved.
        Statics::new(robot, SolverSettings::default())
            .solve_loaded(
                &robot.min_tensions(),
                Vector3::from(f),
                Vector3::zeros(),
                None,
            )
            .map_err(|e| {
                CalibError::Options(format!(
                    "the planned tip load {f:?} N is more than the robot holds at its lowest \
                     tensions (the statics: {e}); plan a smaller one"
                ))
            })?;
    }
    let rod: Vec<Param> = params.iter().copied().filter(Param::moves_rod).collect();
    let count = (n * CANDIDATES_PER_ROW).max(200);
    let loads = if load.is_some() { 2 } else { 1 };
    let solves = count * loads * 2 * rod.len();
    let threads = rayon::current_num_threads().max(1);
    log::info!(
        "planning {n} rows from {} candidates: {solves} statics solves, about {:.0} s on \
         {threads} threads",
        count * loads,
        solves as f64 * super::seconds_per_solve(robot) / threads as f64
    );
    let bar = crate::progress::bar(
        (count * loads) as u64 + n as u64,
        true,
        "{spinner} planning [{bar:30}] {pos}/{len} eta {eta}",
    );
    let mut tensions =
        Sampler::Uniform.draw_between(count, &robot.min_tensions(), &robot.max_tensions(), seed);
    tensions.push(robot.min_tensions());
    let forces: Vec<[f64; 3]> = std::iter::once([0.0; 3]).chain(load).collect();
    let candidates: Vec<PlannedRow> = tensions
        .iter()
        .flat_map(|t| {
            forces.iter().map(|&f| PlannedRow {
                tensions: t.clone(),
                tip_force: f,
            })
        })
        .collect();
    // Sensitivity of each candidate's tip to each parameter (scaled).
    let tip = |v: &Values, row: &PlannedRow| -> Result<Vector3<f64>, CalibError> {
        let s = Statics::new(&v.solving_robot(robot), SolverSettings::default());
        let f = Vector3::from(row.tip_force);
        s.solve_loaded(&v.scaled_tensions(&row.tensions), f, Vector3::zeros(), None)
            .map(|sol| sol.position)
            .map_err(|error| CalibError::Solve { line: 0, error })
    };
    use rayon::prelude::*;
    // A candidate whose statics fail (a large load on slack tendons) is no
    // row to measure: it is left out, not the plan.
    let blocks: Vec<Option<DMatrix<f64>>> = candidates
        .par_iter()
        .map(|row| {
            let block = || -> Result<DMatrix<f64>, CalibError> {
                let mut b = DMatrix::zeros(3, rod.len());
                for (j, &p) in rod.iter().enumerate() {
                    let h = super::FD_STEP * scale(p, &nv);
                    let mut plus = nv.clone();
                    plus.set(p, nv.get(p) + h);
                    let mut minus = nv.clone();
                    minus.set(p, nv.get(p) - h);
                    let d = (tip(&plus, row)? - tip(&minus, row)?) / (2.0 * super::FD_STEP);
                    b.set_column(j, &d);
                }
                Ok(b)
            };
            bar.inc(1);
            if crate::interrupt::stop_requested() {
                return Err(CalibError::Options("interrupted".into()));
            }
            Ok(block().ok())
        })
        .collect::<Result<_, CalibError>>()?;
    let usable = blocks.iter().filter(|b| b.is_some()).count();
    if usable < candidates.len() {
        log::warn!(
            "--plan: {} of {} candidates left out: the statics do not solve there",
            candidates.len() - usable,
            candidates.len()
        );
    }
    let mut info = DMatrix::<f64>::identity(rod.len(), rod.len()) * 1e-9;
    let mut taken = vec![false; candidates.len()];
    let mut chosen = Vec::new();
    for _ in 0..n.min(usable) {
        let inv = info
            .clone()
            .try_inverse()
            .ok_or_else(|| CalibError::Options("planner: information matrix singular".into()))?;
        let Some((best, block)) = (0..candidates.len())
            .filter(|&c| !taken[c])
            .filter_map(|c| blocks[c].as_ref().map(|s| (c, s)))
            .map(|(c, s)| {
                let g: DMatrix<f64> = s * &inv * s.transpose();
                let m = Matrix3::from_fn(|i, j| g[(i, j)]) + Matrix3::identity();
                (c, s, m.determinant())
            })
            .max_by(|a, b| a.2.total_cmp(&b.2))
            .map(|(c, s, _)| (c, s))
        else {
            break;
        };
        taken[best] = true;
        bar.inc(1);
        info += block.transpose() * block;
        chosen.push(candidates[best].clone());
    }
    bar.finish_and_clear();
    Ok(chosen)
}
