//! Calibration: fit a robot file's parameters to measurements taken on the
//! real robot (`docs/design.md` §11). [`data`] reads the measured CSV,
//! [`params`] names what may be fitted and writes the robot file back,
//! [`fit`] is the estimator, [`report`] what it tells the user, [`plan`]
//! proposes tension sets that make the fit well conditioned and [`noise`]
//! makes synthetic measurements.

pub mod data;
pub mod fit;
pub mod identify;
pub mod noise;
pub mod params;
pub mod plan;
mod problem;
pub mod report;
pub mod residual;
pub mod rows;
mod sensitivity;
pub mod step;
pub mod verdict;

#[cfg(test)]
mod tests;

pub use data::{parse_measurements, read_measurements, DataError, Measurements};
pub use fit::{calibrate, Calibration, FitOptions, FD_STEP};
pub use params::{parse_fit_list, robot_toml, Param, Values};
pub use report::Report;

use crate::statics::SolveError;

/// Seconds of one statics solve of `robot` on this machine (the median of
/// five cold solves at the lower tension limits): what the cost estimates
/// of a fit and a plan multiply.
pub fn seconds_per_solve(robot: &crate::robot::Robot) -> f64 {
    let s = crate::statics::Statics::new(robot, crate::statics::SolverSettings::default());
    let tau = robot.min_tensions();
    let mut t: Vec<f64> = (0..5)
        .map(|_| {
            let started = std::time::Instant::now();
            let _ = s.solve(&tau, None);
            started.elapsed().as_secs_f64()
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[2]
}

/// The parameters `tendril calibrate` fits when `--fit` is not given.
pub const DEFAULT_FIT: &str = "E,density,length,offsets,angles,base";

/// Why a calibration could not be done.
#[derive(Debug, thiserror::Error)]
pub enum CalibError {
    /// The measured CSV is unusable.
    #[error(transparent)]
    Data(#[from] DataError),
    /// Fewer fit rows than parameters.
    #[error("{rows} fit rows for {params} parameters: a fit needs at least as many rows as parameters (measure more, or fit fewer)")]
    TooFewRows {
        /// Rows left for the fit.
        rows: usize,
        /// Parameters asked for.
        params: usize,
    },
    /// An option is out of range.
    #[error("{0}")]
    Options(String),
    /// A statics solve failed at a row.
    #[error("line {line}: the statics did not solve: {error}")]
    Solve {
        /// Line of the measured CSV.
        line: usize,
        /// The cause.
        error: SolveError,
    },
}

impl Calibration {
    /// The calibrated robot as a robot file: the schema of `docs/design.md`
    /// §2, the fitted tracker frame as its `[base]` table (§2.4), the
    /// tension scales (which the schema does not hold) as a comment.
    pub fn robot_file(&self) -> String {
        let v = &self.values;
        let header = vec![
            format!(
                "Calibrated by tendril calibrate from the robot {:?}.",
                self.report.robot
            ),
            format!(
                "Tension scales (true = scale x recorded): {:?}.",
                v.tension_scale
            ),
        ];
        robot_toml(&self.robot, &header)
    }
}
