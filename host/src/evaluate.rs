//! Metrics of `docs/design.md` §4, shared by every learner: tension RMSE (normalised
//! ×100 and in newtons) and the **task-space error** — predicted tensions,
//! through the firmware's command stage (what the MCU would command; also
//! what the tension RMSE is taken on), go through the Cosserat statics and the
//! resulting tip is compared with the pose that was asked for. Tension RMSE
//! alone hides what a robot user cares about: where the tip lands.

use nalgebra::{DMatrix, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::numerics::percentile;
use crate::statics::Statics;

/// Summary of a list of non-negative errors.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ErrorStats {
    /// Arithmetic mean.
    pub mean: f64,
    /// Root mean square.
    pub rms: f64,
    /// 95th percentile (nearest rank).
    pub p95: f64,
    /// Largest value.
    pub max: f64,
}

impl ErrorStats {
    /// Statistics of the finite values in `values` (all zero when there is none).
    pub fn of(values: &[f64]) -> ErrorStats {
        let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return ErrorStats::default();
        }
        v.sort_by(|a, b| a.total_cmp(b));
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let rms = (v.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
        ErrorStats {
            mean,
            rms,
            p95: percentile::of_sorted(&v, 95.0).unwrap_or(0.0),
            max: v[v.len() - 1],
        }
    }
}

/// Per-sample task-space errors of predicted tensions.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TaskErrors {
    /// Tip position error |p − p_true| per sample, in millimetres (NaN where the solve failed).
    pub position_mm: Vec<f64>,
    /// Tip orientation error (rotation angle between the two orientations) per sample, in degrees
    /// (NaN where the solve failed).
    pub orientation_deg: Vec<f64>,
    /// Number of samples whose statics solve did not converge, even after a warm-started retry.
    pub failed: usize,
}

impl TaskErrors {
    /// Statistics of the position errors (mm) over the converged samples.
    pub fn position_stats(&self) -> ErrorStats {
        ErrorStats::of(&self.position_mm)
    }

    /// Statistics of the orientation errors (degrees) over the converged samples.
    pub fn orientation_stats(&self) -> ErrorStats {
        ErrorStats::of(&self.orientation_deg)
    }
}

/// Why a metric could not be computed.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// Two matrices that must describe the same samples disagree in shape.
    #[error("shape mismatch: {0}")]
    Shape(String),
}

/// Root-mean-square difference over every entry of two equally shaped matrices
/// (the units are those of the inputs: newtons for raw tensions).
pub fn tension_rmse(predicted: &DMatrix<f64>, truth: &DMatrix<f64>) -> Result<f64, EvalError> {
    same_shape(predicted, truth)?;
    if predicted.is_empty() {
        return Ok(0.0);
    }
    Ok(((predicted - truth).norm_squared() / predicted.len() as f64).sqrt())
}

/// Tension RMSE on the paper's scale: both matrices in newtons, each column
/// divided by its range `hi − lo` (from the training split), RMSE over every
/// entry, ×100. `lo`/`hi` are per-tendon ranges, e.g. `MinMax::lo`/`hi`.
pub fn tension_rmse_normalised(
    predicted: &DMatrix<f64>,
    truth: &DMatrix<f64>,
    lo: &[f64],
    hi: &[f64],
) -> Result<f64, EvalError> {
    same_shape(predicted, truth)?;
    if lo.len() != predicted.ncols() || hi.len() != predicted.ncols() {
        return Err(EvalError::Shape(format!(
            "{} tension columns but {} / {} range entries",
            predicted.ncols(),
            lo.len(),
            hi.len()
        )));
    }
    if predicted.is_empty() {
        return Ok(0.0);
    }
    let mut sum = 0.0;
    for c in 0..predicted.ncols() {
        let span = hi[c] - lo[c];
        let span = if span > 0.0 { span } else { 1.0 };
        for r in 0..predicted.nrows() {
            let d = (predicted[(r, c)] - truth[(r, c)]) / span;
            sum += d * d;
        }
    }
    Ok(100.0 * (sum / predicted.len() as f64).sqrt())
}

/// Task-space error of predicted tensions (`n × T`, newtons) against the
/// poses they should reach (`n × 7`: px, py, pz in m, qw, qx, qy, qz).
///
/// Each row goes through the firmware's command stage for `statics.robot()`
/// (co-contraction shift, then the clip to [min_tension, max_tension]: what
/// the MCU would command, [`crate::command_stage`]), is solved cold in
/// parallel (rayon), and the tip compared with the true pose. Rows whose cold solve fails are retried warm
/// from the converged row nearest in tension space; rows that still fail are
/// counted in `failed` and carry NaN errors. Cold first because a warm start
/// from an unrelated pose can converge to a wrong branch without complaint
/// (`docs/design.md` §3).
pub fn task_space_errors(
    statics: &Statics,
    predicted_tensions: &DMatrix<f64>,
    true_poses: &DMatrix<f64>,
) -> Result<TaskErrors, EvalError> {
    let n = predicted_tensions.nrows();
    let t = statics.robot().n_tendons();
    if predicted_tensions.ncols() != t {
        return Err(EvalError::Shape(format!(
            "{} tension columns for a robot with {} tendons",
            predicted_tensions.ncols(),
            t
        )));
    }
    if true_poses.nrows() != n || true_poses.ncols() != 7 {
        return Err(EvalError::Shape(format!(
            "poses are {}×{}, expected {}×7",
            true_poses.nrows(),
            true_poses.ncols(),
            n
        )));
    }
    let staged = staged_tensions(statics, predicted_tensions)?;
    let commanded: Vec<Vec<f64>> = (0..n)
        .map(|r| staged.row(r).iter().copied().collect())
        .collect();
    Ok(errors_of_commands(statics, &commanded, true_poses))
}

/// Predicted tensions (`n × T`, N) through the firmware's command stage for
/// `statics.robot()`: what the MCU would command, and what tension errors
/// are measured on (a net trained on centred targets, `docs/design.md` §4,
/// gives tensions only up to co-contraction; the stage makes them a command).
pub fn staged_tensions(
    statics: &Statics,
    predicted_tensions: &DMatrix<f64>,
) -> Result<DMatrix<f64>, EvalError> {
    let limits = crate::command_stage::limits_for(statics.robot(), 1.0)
        .map_err(|e| EvalError::Shape(format!("tension limits: {e}")))?;
    Ok(crate::command_stage::command_rows(
        &limits,
        predicted_tensions,
    ))
}

/// [`task_space_errors`] through the plain per-tendon clip to
/// [min_tension, max_tension] instead of the command stage: what the stage
/// is compared against.
pub fn task_space_errors_plain_clip(
    statics: &Statics,
    predicted_tensions: &DMatrix<f64>,
    true_poses: &DMatrix<f64>,
) -> Result<TaskErrors, EvalError> {
    let n = predicted_tensions.nrows();
    if predicted_tensions.ncols() != statics.robot().n_tendons()
        || true_poses.nrows() != n
        || true_poses.ncols() != 7
    {
        return Err(EvalError::Shape(format!(
            "{}×{} tensions and {}×{} poses for a robot with {} tendons",
            n,
            predicted_tensions.ncols(),
            true_poses.nrows(),
            true_poses.ncols(),
            statics.robot().n_tendons()
        )));
    }
    let clamped = clamp_tensions(statics, predicted_tensions);
    Ok(errors_of_commands(statics, &clamped, true_poses))
}

/// Solve each commanded row (cold, then warm from the nearest converged row
/// for the failures) and compare its tip with the true pose.
fn errors_of_commands(
    statics: &Statics,
    clamped: &[Vec<f64>],
    true_poses: &DMatrix<f64>,
) -> TaskErrors {
    let n = clamped.len();
    let first: Vec<_> = (0..n)
        .into_par_iter()
        .map(|r| statics.solve(&clamped[r], None).ok())
        .collect();

    // Retry failures warm from the nearest converged row (tension space).
    let solved: Vec<usize> = (0..n).filter(|&r| first[r].is_some()).collect();
    let retry: Vec<_> = (0..n)
        .into_par_iter()
        .map(|r| {
            if first[r].is_some() {
                return None;
            }
            let near = solved.iter().copied().min_by(|&a, &b| {
                dist2(&clamped[a], &clamped[r]).total_cmp(&dist2(&clamped[b], &clamped[r]))
            })?;
            let warm = &first[near].as_ref()?.warm;
            statics.solve(&clamped[r], Some(warm)).ok()
        })
        .collect();

    let mut out = TaskErrors {
        position_mm: vec![f64::NAN; n],
        orientation_deg: vec![f64::NAN; n],
        failed: 0,
    };
    for r in 0..n {
        let sol = match (&first[r], &retry[r]) {
            (Some(s), _) | (None, Some(s)) => s,
            (None, None) => {
                out.failed += 1;
                continue;
            }
        };
        let p_true = Vector3::new(true_poses[(r, 0)], true_poses[(r, 1)], true_poses[(r, 2)]);
        out.position_mm[r] = 1000.0 * (sol.position - p_true).norm();
        let q_true = [
            true_poses[(r, 3)],
            true_poses[(r, 4)],
            true_poses[(r, 5)],
            true_poses[(r, 6)],
        ];
        out.orientation_deg[r] = quaternion_angle_deg(&sol.quaternion, &q_true);
    }
    out
}

/// Rows of `tensions` clamped to [min_tension, max_tension] per tendon
/// (NaN → the floor).
pub fn clamp_tensions(statics: &Statics, tensions: &DMatrix<f64>) -> Vec<Vec<f64>> {
    let max = statics.robot().max_tensions();
    let min = statics.robot().min_tensions();
    (0..tensions.nrows())
        .map(|r| {
            (0..tensions.ncols())
                .map(|c| {
                    let v = tensions[(r, c)];
                    if v.is_nan() {
                        min[c]
                    } else {
                        v.clamp(min[c], max[c])
                    }
                })
                .collect()
        })
        .collect()
}

/// Rotation angle (degrees) between two unit quaternions (w, x, y, z); sign-agnostic.
pub fn quaternion_angle_deg(a: &[f64; 4], b: &[f64; 4]) -> f64 {
    let na = a.iter().map(|x| x * x).sum::<f64>().sqrt();
    let nb = b.iter().map(|x| x * x).sum::<f64>().sqrt();
    let dot: f64 = a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>() / (na * nb);
    (2.0 * dot.abs().min(1.0).acos()).to_degrees()
}

fn dist2(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

fn same_shape(a: &DMatrix<f64>, b: &DMatrix<f64>) -> Result<(), EvalError> {
    if a.shape() != b.shape() {
        return Err(EvalError::Shape(format!(
            "predicted is {}×{}, truth is {}×{}",
            a.nrows(),
            a.ncols(),
            b.nrows(),
            b.ncols()
        )));
    }
    Ok(())
}

/// Everything `tendril evaluate` reports for one split of one learner.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SplitMetrics {
    /// Number of samples evaluated.
    pub samples: usize,
    /// Tension RMSE of the staged predictions against the dataset's tensions,
    /// normalised by the tension ranges, ×100 (the paper's scale).
    pub tension_rmse_norm100: f64,
    /// Tension RMSE of the staged predictions in newtons.
    pub tension_rmse_newton: f64,
    /// Task-space tip position error, mm.
    pub position_mm: ErrorStats,
    /// Task-space tip orientation error, degrees.
    pub orientation_deg: ErrorStats,
    /// Statics solves that did not converge (excluded from the statistics).
    pub failed_solves: usize,
    /// Mean wall time of one inference, nanoseconds (batch timing, one thread).
    pub inference_ns_per_query: f64,
    /// Task-space tip position error through the plain per-tendon clip
    /// instead of the command stage, mm; `None` when the stage changed no
    /// row (the two are then identical).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position_mm_plain_clip: Option<ErrorStats>,
}

/// [`task_space_errors_plain_clip`]'s position statistics when the command
/// stage changes at least one row of `predicted_tensions` (by > 1 µN);
/// `None` when it changes none.
pub fn plain_clip_position_if_different(
    statics: &Statics,
    predicted_tensions: &DMatrix<f64>,
    true_poses: &DMatrix<f64>,
) -> Result<Option<ErrorStats>, EvalError> {
    let limits = crate::command_stage::limits_for(statics.robot(), 1.0)
        .map_err(|e| EvalError::Shape(format!("tension limits: {e}")))?;
    let clipped = clamp_tensions(statics, predicted_tensions);
    let differs = clipped.iter().enumerate().any(|(r, clip)| {
        let row: Vec<f64> = (0..clip.len())
            .map(|c| predicted_tensions[(r, c)])
            .map(|v| if v.is_nan() { 0.0 } else { v })
            .collect();
        let staged = crate::command_stage::command_for(&limits, &row);
        staged.iter().zip(clip).any(|(a, b)| (a - b).abs() > 1e-6)
    });
    if !differs {
        return Ok(None);
    }
    Ok(Some(
        task_space_errors_plain_clip(statics, predicted_tensions, true_poses)?.position_stats(),
    ))
}

impl SplitMetrics {
    /// Assemble metrics from a learner's predictions (newtons) and the
    /// truth: tension errors and tip errors of the staged predictions
    /// ([`staged_tensions`]); `lo`/`hi` are the dataset's tension ranges.
    pub fn compute(
        statics: &Statics,
        predicted_tensions: &DMatrix<f64>,
        true_tensions: &DMatrix<f64>,
        true_poses: &DMatrix<f64>,
        lo: &[f64],
        hi: &[f64],
        inference_ns_per_query: f64,
    ) -> Result<SplitMetrics, EvalError> {
        let task = task_space_errors(statics, predicted_tensions, true_poses)?;
        let staged = staged_tensions(statics, predicted_tensions)?;
        Ok(SplitMetrics {
            samples: predicted_tensions.nrows(),
            tension_rmse_norm100: tension_rmse_normalised(&staged, true_tensions, lo, hi)?,
            tension_rmse_newton: tension_rmse(&staged, true_tensions)?,
            position_mm: task.position_stats(),
            orientation_deg: task.orientation_stats(),
            failed_solves: task.failed,
            inference_ns_per_query,
            position_mm_plain_clip: plain_clip_position_if_different(
                statics,
                predicted_tensions,
                true_poses,
            )?,
        })
    }

    /// A small table (one metric per line) for stdout; the tip errors are
    /// through the command stage, each in the unit that fits its size
    /// ([`crate::units`]). The plain clip's errors stay in the JSON only:
    /// for a net trained on centred targets (every net the trainer makes
    /// now, docs/design.md §4) they are meaningless, and on the console they
    /// read like a failure.
    pub fn table(&self, title: &str) -> String {
        use crate::units::{degrees, length_mm, number};
        let p = &self.position_mm;
        let o = &self.orientation_deg;
        format!(
            "{title} ({} samples)\n\
             \x20 tension RMSE          {:>10} (normalised ×100)   {:>10} N\n\
             \x20 tip position error     mean {:>9}  rms {:>9}  p95 {:>9}  max {:>9}\n\
             \x20 tip orientation error  mean {:>9}  rms {:>9}  p95 {:>9}  max {:>9}\n\
             \x20 failed solves          {}\n\
             \x20 inference              {} ns/query\n",
            self.samples,
            number(self.tension_rmse_norm100, 4),
            number(self.tension_rmse_newton, 6),
            length_mm(p.mean),
            length_mm(p.rms),
            length_mm(p.p95),
            length_mm(p.max),
            degrees(o.mean),
            degrees(o.rms),
            degrees(o.p95),
            degrees(o.max),
            self.failed_solves,
            number(self.inference_ns_per_query, 1)
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stats_of_one_to_hundred() {
        let v: Vec<f64> = (1..=100).map(|i| i as f64).collect();
        let s = ErrorStats::of(&v);
        assert_eq!(s.mean, 50.5);
        assert_eq!(s.p95, 95.0);
        assert_eq!(s.max, 100.0);
        let rms = ((1..=100).map(|i| (i * i) as f64).sum::<f64>() / 100.0).sqrt();
        assert!((s.rms - rms).abs() < 1e-12);
    }

    #[test]
    fn stats_skip_nan() {
        let s = ErrorStats::of(&[1.0, f64::NAN, 3.0]);
        assert_eq!(s.mean, 2.0);
        assert_eq!(s.max, 3.0);
    }

    #[test]
    fn normalised_rmse_divides_by_range_and_scales_by_100() {
        let truth = DMatrix::from_row_slice(2, 2, &[0.0, 0.0, 10.0, 5.0]);
        let pred = DMatrix::from_row_slice(2, 2, &[1.0, 0.5, 10.0, 5.0]);
        // errors /range: 0.1, 0.1, 0, 0 → rms = sqrt(0.02/4)
        let r = tension_rmse_normalised(&pred, &truth, &[0.0, 0.0], &[10.0, 5.0]).unwrap();
        assert!((r - 100.0 * (0.02f64 / 4.0).sqrt()).abs() < 1e-12);
        let n = tension_rmse(&pred, &truth).unwrap();
        assert!((n - (1.25f64 / 4.0).sqrt()).abs() < 1e-12);
        assert!(tension_rmse(&pred, &DMatrix::zeros(3, 2)).is_err());
    }

    #[test]
    fn quaternion_angle_of_known_rotation() {
        let h = (0.5f64).to_radians(); // 1 degree about y, half angle
        let a = [1.0, 0.0, 0.0, 0.0];
        let b = [h.cos(), 0.0, h.sin(), 0.0];
        assert!((quaternion_angle_deg(&a, &b) - 1.0).abs() < 1e-9);
        let nb = [-b[0], -b[1], -b[2], -b[3]];
        assert!((quaternion_angle_deg(&a, &nb) - 1.0).abs() < 1e-9);
    }
}
