//! An offline run: the robot at rest, a step of the tendon tensions, the tip
//! trajectory written as CSV with a figure (`tendril dynamics`,
//! `docs/design.md` §4.2 and §7).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use indicatif::{ProgressBar, ProgressStyle};
use nalgebra::Vector3;

use super::{Damping, Dynamics, DynamicsError, DynamicsSettings};
use crate::fsutil::write_atomic_with;
use crate::robot::Robot;

/// Why an offline run failed.
#[derive(Debug, thiserror::Error)]
pub enum OfflineError {
    /// The tension step could not be read.
    #[error("--tensions-step {text:?}: {problem}")]
    BadStep {
        /// What the user gave.
        text: String,
        /// What is wrong with it.
        problem: String,
    },
    /// The duration is not a positive number of seconds.
    #[error("duration {0} s must be positive and finite")]
    BadDuration(f64),
    /// The dynamics failed.
    #[error(transparent)]
    Dynamics(#[from] DynamicsError),
    /// Ctrl-C: nothing was written.
    #[error("interrupted: no output was written")]
    Interrupted,
    /// Writing an output failed.
    #[error("writing {}: {message}", .path.display())]
    Write {
        /// The output.
        path: PathBuf,
        /// The cause.
        message: String,
    },
}

/// Tensions `before` until `at_s`, `after` from then on (N, s).
#[derive(Clone, Debug, PartialEq)]
pub struct TensionStep {
    /// Tensions at rest, N.
    pub before: Vec<f64>,
    /// Tensions after the step, N.
    pub after: Vec<f64>,
    /// Time of the step, s.
    pub at_s: f64,
}

impl TensionStep {
    /// Parse `T0,T1,..:T0,T1,..@SECONDS` (e.g. `0,0,0,0:2,0,0,0@0.1`).
    pub fn parse(text: &str) -> Result<TensionStep, OfflineError> {
        let bad = |problem: &str| OfflineError::BadStep {
            text: text.to_string(),
            problem: problem.to_string(),
        };
        let (tensions, at) = text
            .split_once('@')
            .ok_or_else(|| bad("expected BEFORE:AFTER@SECONDS"))?;
        let (before, after) = tensions
            .split_once(':')
            .ok_or_else(|| bad("expected BEFORE:AFTER@SECONDS"))?;
        let list = |s: &str| -> Result<Vec<f64>, OfflineError> {
            s.split(',')
                .map(|x| {
                    x.trim()
                        .parse::<f64>()
                        .map_err(|_| bad(&format!("{x:?} is not a number")))
                })
                .collect()
        };
        let at_s: f64 = at
            .trim()
            .parse()
            .map_err(|_| bad(&format!("step time {at:?} is not a number")))?;
        if !(at_s.is_finite() && at_s >= 0.0) {
            return Err(bad("the step time must be finite and not negative"));
        }
        let (before, after) = (list(before)?, list(after)?);
        if before.len() != after.len() {
            return Err(bad("before and after need the same number of tensions"));
        }
        Ok(TensionStep {
            before,
            after,
            at_s,
        })
    }

    /// The tensions at time `t_s`.
    pub fn at(&self, t_s: f64) -> &[f64] {
        if t_s < self.at_s {
            &self.before
        } else {
            &self.after
        }
    }
}

/// One row of the trajectory.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Time, s.
    pub t_s: f64,
    /// Tip position, base frame, m.
    pub position: Vector3<f64>,
    /// Tip velocity, base frame, m/s.
    pub velocity: Vector3<f64>,
}

/// Run the step response for `duration_s` (the tensions over each step are
/// those at its end time: the step acts from the first time step at or
/// after `at_s`). Checks `stop` between steps; `on_step` sees each sample.
pub fn step_response(
    robot: &Robot,
    damping: Damping,
    settings: DynamicsSettings,
    step: &TensionStep,
    duration_s: f64,
    stop: &AtomicBool,
    mut on_step: impl FnMut(&Sample),
) -> Result<Vec<Sample>, OfflineError> {
    if !(duration_s.is_finite() && duration_s > 0.0) {
        return Err(OfflineError::BadDuration(duration_s));
    }
    robot
        .check_tensions(&step.after)
        .map_err(DynamicsError::from)?;
    let mut dynamics = Dynamics::at_rest(
        robot,
        damping,
        settings,
        &step.before,
        Vector3::zeros(),
        Vector3::zeros(),
    )?;
    let steps = (duration_s / settings.dt_s).round() as usize;
    let mut out = Vec::with_capacity(steps + 1);
    let first = dynamics.tip();
    out.push(Sample {
        t_s: 0.0,
        position: first.position,
        velocity: first.velocity,
    });
    for k in 1..=steps {
        if stop.load(Ordering::SeqCst) {
            return Err(OfflineError::Interrupted);
        }
        let t_s = k as f64 * settings.dt_s;
        let tip = dynamics.step(step.at(t_s - 1e-9 * settings.dt_s))?;
        let sample = Sample {
            t_s,
            position: tip.position,
            velocity: tip.velocity,
        };
        on_step(&sample);
        out.push(sample);
    }
    Ok(out)
}

/// Write the trajectory as CSV (`t,px,py,pz,vx,vy,vz`; s, m, m/s), atomically.
pub fn write_csv(path: &Path, samples: &[Sample]) -> Result<(), OfflineError> {
    write_atomic_with(path, |w| {
        writeln!(w, "t,px,py,pz,vx,vy,vz")?;
        for s in samples {
            let (p, v) = (s.position, s.velocity);
            writeln!(
                w,
                "{},{},{},{},{},{},{}",
                s.t_s, p.x, p.y, p.z, v.x, v.y, v.z
            )?;
        }
        Ok(())
    })
    .map_err(|e| OfflineError::Write {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

/// What `tendril dynamics` asks for.
#[derive(Clone, Debug)]
pub struct OfflineRun {
    /// The robot.
    pub robot: Robot,
    /// The tension step.
    pub step: TensionStep,
    /// Simulated time, s.
    pub duration_s: f64,
    /// Time scheme and grid.
    pub settings: DynamicsSettings,
    /// Material damping.
    pub damping: Damping,
    /// Output directory (`tip.csv`, `tip.png`).
    pub out: PathBuf,
    /// Show a progress bar on stderr.
    pub progress: bool,
}

/// Run an offline step response with a progress bar and Ctrl-C checks;
/// write `tip.csv` and `tip.png` under `out`. Returns the CSV path.
pub fn run(job: &OfflineRun, stop: &AtomicBool) -> Result<PathBuf, OfflineError> {
    let steps = (job.duration_s / job.settings.dt_s).round().max(0.0) as u64;
    let bar = if job.progress {
        ProgressBar::new(steps)
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template("{prefix} [{bar:30}] {pos}/{len} steps, {elapsed} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar.set_prefix("dynamics");
    let started = std::time::Instant::now();
    let samples = step_response(
        &job.robot,
        job.damping,
        job.settings,
        &job.step,
        job.duration_s,
        stop,
        |s| {
            bar.inc(1);
            if bar.position().is_multiple_of(100) {
                bar.set_message(format!("t = {:.2} s", s.t_s));
            }
        },
    );
    bar.finish_and_clear();
    let samples = samples?;
    let wall = started.elapsed().as_secs_f64();
    log::info!(
        "dynamics: {} steps of {} ms in {wall:.2} s ({:.2}x real time)",
        steps,
        job.settings.dt_s * 1e3,
        job.duration_s / wall
    );
    let csv = job.out.join("tip.csv");
    write_csv(&csv, &samples)?;
    let png = job.out.join("tip.png");
    let title = format!(
        "{}: tip after a tension step at {} s",
        job.robot.name, job.step.at_s
    );
    super::figure::draw_step_response(&samples, job.step.at_s, &title, &png).map_err(|e| {
        OfflineError::Write {
            path: png.clone(),
            message: e.to_string(),
        }
    })?;
    log::info!("wrote {} and {}", csv.display(), png.display());
    Ok(csv)
}
