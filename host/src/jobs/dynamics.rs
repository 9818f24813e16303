//! An offline run: the robot at rest, a step of the tendon tensions, the tip
//! trajectory written as CSV with a figure (`tendril dynamics`,
//! `docs/design.md` §4.2 and §7).

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};

use nalgebra::Vector3;

use crate::dynamics::{Damping, Dynamics, DynamicsError, DynamicsSettings};
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
    /// The time step is not a positive number of seconds.
    #[error("--dt {0} s must be positive and finite")]
    BadDt(f64),
    /// More steps than [`MAX_STEPS`]; the message says what they would cost.
    #[error(
        "--duration {duration_s} s at --dt {dt_s} s is {steps} time steps; at most {MAX_STEPS} \
         are run (a tip CSV of up to {csv_mb:.0} MB and hours of computing): shorten \
         --duration or lengthen --dt"
    )]
    TooManySteps {
        /// Simulated time asked for, s.
        duration_s: f64,
        /// Time step, s.
        dt_s: f64,
        /// Steps that implies.
        steps: f64,
        /// Bound on the CSV those steps would write, MB.
        csv_mb: f64,
    },
    /// The tension step comes at or after the end of the run: it would never act.
    #[error(
        "the tension step at {at_s} s is not before the end of the run (--duration {duration_s} s): \
         it would never happen"
    )]
    StepAfterEnd {
        /// Time of the step, s.
        at_s: f64,
        /// Simulated time, s.
        duration_s: f64,
    },
    /// The output directory's file system has too little room for the CSV.
    #[error(
        "{}: {need_mb:.0} MB may be needed for the tip CSV of {steps} steps but only \
         {free_mb:.0} MB are free",
        .dir.display()
    )]
    NoSpace {
        /// The output directory.
        dir: PathBuf,
        /// Steps of the run.
        steps: u64,
        /// Bound on the CSV, MB.
        need_mb: f64,
        /// Free space, MB.
        free_mb: f64,
    },
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

/// Most time steps of one offline run: 2,000 s at the default 1 ms, a tip
/// CSV of at most ≈ 360 MB ([`CSV_ROW_BYTES`]) and about an hour of
/// computing on one core at the default grid (`docs/design.md` §4.2).
pub const MAX_STEPS: u64 = 2_000_000;

/// Bound on one CSV row: seven numbers of at most 25 characters and their
/// separators (Rust's shortest round-trip `f64` text).
pub const CSV_ROW_BYTES: u64 = 7 * 26;

/// Samples drawn in the figure at most: longer runs are decimated for it
/// (the CSV keeps every step), so memory is bounded whatever the duration.
pub const FIGURE_POINTS: u64 = 20_000;

/// The number of time steps of a run of `duration_s` at `dt_s` with `step`,
/// checked before any work: positive finite times, at most [`MAX_STEPS`],
/// and a step that happens before the end.
pub fn plan_steps(duration_s: f64, dt_s: f64, step: &TensionStep) -> Result<u64, OfflineError> {
    if !(duration_s.is_finite() && duration_s > 0.0) {
        return Err(OfflineError::BadDuration(duration_s));
    }
    if !(dt_s.is_finite() && dt_s > 0.0) {
        return Err(OfflineError::BadDt(dt_s));
    }
    let steps = (duration_s / dt_s).round();
    if steps > MAX_STEPS as f64 {
        return Err(OfflineError::TooManySteps {
            duration_s,
            dt_s,
            steps,
            csv_mb: steps * CSV_ROW_BYTES as f64 / 1e6,
        });
    }
    // The step acts from the first time step at or after `at_s`; the last
    // time step ends at `steps · dt`.
    if step.at_s >= steps * dt_s {
        return Err(OfflineError::StepAfterEnd {
            at_s: step.at_s,
            duration_s,
        });
    }
    Ok(steps as u64)
}

/// Run the step response for `duration_s` (the tensions over each step are
/// those at its end time: the step acts from the first time step at or
/// after `at_s`). Checks `stop` between steps; `on_step` sees each sample,
/// the one at rest (t = 0) first, and may fail (a write): nothing is held,
/// so memory does not grow with the duration.
pub fn step_response(
    robot: &Robot,
    damping: Damping,
    settings: DynamicsSettings,
    step: &TensionStep,
    duration_s: f64,
    stop: &AtomicBool,
    mut on_step: impl FnMut(&Sample, &Dynamics) -> std::io::Result<()>,
) -> Result<(), OfflineError> {
    let steps = plan_steps(duration_s, settings.dt_s, step)?;
    let write_err = |e: std::io::Error| OfflineError::Write {
        path: PathBuf::from("tip.csv"),
        message: e.to_string(),
    };
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
    let first = dynamics.tip();
    on_step(
        &Sample {
            t_s: 0.0,
            position: first.position,
            velocity: first.velocity,
        },
        &dynamics,
    )
    .map_err(write_err)?;
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
        on_step(&sample, &dynamics).map_err(write_err)?;
    }
    Ok(())
}

/// The CSV header of the trajectory (s, m, m/s).
pub const CSV_HEADER: &str = "t,px,py,pz,vx,vy,vz";

/// One CSV row of the trajectory.
fn write_row(w: &mut dyn std::io::Write, s: &Sample) -> std::io::Result<()> {
    let (p, v) = (s.position, s.velocity);
    writeln!(
        w,
        "{},{},{},{},{},{},{}",
        s.t_s, p.x, p.y, p.z, v.x, v.y, v.z
    )
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
    /// Also write `run.mcap` (the rod's shape and tip over time, for
    /// Foxglove; docs/design.md §12).
    pub mcap: bool,
}

/// Run an offline step response with a progress bar and Ctrl-C checks;
/// write `tip.csv` and `tip.png` under `out`. Returns the CSV path.
pub fn run(job: &OfflineRun, stop: &AtomicBool) -> Result<PathBuf, OfflineError> {
    let steps = plan_steps(job.duration_s, job.settings.dt_s, &job.step)?;
    let need = (steps + 2) * CSV_ROW_BYTES;
    std::fs::create_dir_all(&job.out).map_err(|e| OfflineError::Write {
        path: job.out.clone(),
        message: e.to_string(),
    })?;
    match crate::dataset::disk::free_bytes(&job.out) {
        Some(free) if free < need => {
            return Err(OfflineError::NoSpace {
                dir: job.out.clone(),
                steps,
                need_mb: need as f64 / 1e6,
                free_mb: free as f64 / 1e6,
            })
        }
        _ => {}
    }
    let bar = crate::progress::bar(
        steps,
        job.progress,
        "{prefix} [{bar:30}] {pos}/{len} steps, {elapsed} {msg}",
    );
    bar.set_prefix("dynamics");
    let started = std::time::Instant::now();
    // The CSV is streamed into its temporary file as the run goes; the
    // figure gets every `every`-th sample (and the last).
    let csv = job.out.join("tip.csv");
    let every = steps.div_ceil(FIGURE_POINTS).max(1);
    let mut figure = Vec::with_capacity((steps / every + 2) as usize);
    let mut failed = None;
    let mut runlog = match job.mcap {
        false => None,
        true => Some(
            crate::runlog::RunLog::start(&crate::runlog::RunLogConfig {
                mcap: Some(job.out.join("run.mcap")),
                lossless: true,
                ..crate::runlog::RunLogConfig::default()
            })
            .map_err(|e| OfflineError::Write {
                path: job.out.join("run.mcap"),
                message: e.to_string(),
            })?,
        ),
    };
    let written = write_atomic_with(&csv, |w| {
        writeln!(w, "{CSV_HEADER}")?;
        let mut k = 0u64;
        let result = step_response(
            &job.robot,
            job.damping,
            job.settings,
            &job.step,
            job.duration_s,
            stop,
            |s, dynamics| {
                if let Some(log) = runlog.as_mut() {
                    log_step(log, &job.step, s, dynamics);
                }
                if k.is_multiple_of(every) || k == steps {
                    figure.push(*s);
                }
                k += 1;
                bar.inc(1);
                if bar.position().is_multiple_of(100) {
                    bar.set_message(format!("t = {:.2} s", s.t_s));
                }
                write_row(w, s)
            },
        );
        result.map_err(|e| {
            failed = Some(e);
            std::io::Error::other("the run failed")
        })
    });
    bar.finish_and_clear();
    if let Some(log) = runlog.take() {
        if failed.is_some() || written.is_err() {
            log.discard();
        } else {
            log.finish().map_err(|e| OfflineError::Write {
                path: job.out.join("run.mcap"),
                message: e.to_string(),
            })?;
        }
    }
    match (failed, written) {
        (Some(OfflineError::Write { message, .. }), _) => {
            return Err(OfflineError::Write { path: csv, message })
        }
        (Some(e), _) => return Err(e),
        (None, Err(e)) => {
            return Err(OfflineError::Write {
                path: csv,
                message: e.to_string(),
            })
        }
        (None, Ok(())) => {}
    }
    let wall = started.elapsed().as_secs_f64();
    log::info!(
        "dynamics: {} steps of {} ms in {wall:.2} s ({:.2}x real time)",
        steps,
        job.settings.dt_s * 1e3,
        job.duration_s / wall
    );
    let png = job.out.join("tip.png");
    let title = format!(
        "{}: tip after a tension step at {} s",
        job.robot.name, job.step.at_s
    );
    let points: Vec<(f64, [f64; 3])> = figure.iter().map(|s| (s.t_s, s.position.into())).collect();
    crate::plot::step_response::draw_step_response(&points, job.step.at_s, &title, &png).map_err(
        |e| OfflineError::Write {
            path: png.clone(),
            message: e.to_string(),
        },
    )?;
    log::info!("wrote {} and {}", csv.display(), png.display());
    Ok(csv)
}

/// One sample into the run log: the applied tensions, the tip, and at the
/// scene rate the rod's backbone (simulated time as the clock).
fn log_step(log: &mut crate::runlog::RunLog, step: &TensionStep, s: &Sample, dynamics: &Dynamics) {
    let t_ns = (s.t_s * 1e9).round() as u64;
    let tip = dynamics.tip();
    let q =
        crate::statics::pose::quaternion_wxyz(&crate::statics::pose::orthonormalise(&tip.rotation));
    let p = s.position;
    let pose = [p.x, p.y, p.z, q[0], q[1], q[2], q[3]];
    let tensions = step.at(s.t_s - 1e-12).to_vec();
    log.step(crate::runlog::StepRecord {
        t_ns,
        command_seq: 0,
        controller_status: 0,
        plant_status: 0,
        commanded: tensions.clone(),
        measured: tensions,
        tip: pose,
        frame: None,
        desired: None,
    });
    if log.scene_due(t_ns) {
        let backbone =
            crate::numerics::polyline::resample(dynamics.backbone(), log.backbone_points());
        log.scene(crate::runlog::SceneRecord {
            t_ns,
            base: [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
            backbone: backbone.iter().map(|v| [v.x, v.y, v.z]).collect(),
            tendons: vec![],
            tip: pose,
            frame: None,
            desired: None,
        });
    }
}

#[cfg(test)]
mod bounds {
    use super::*;

    fn step(at_s: f64) -> TensionStep {
        TensionStep::parse(&format!("0,0,0,0:2,0,0,0@{at_s}")).unwrap()
    }

    #[test]
    fn a_run_beyond_the_step_cap_is_refused_with_its_cost_before_any_work() {
        for (duration, dt) in [(1e6, 1e-3), (3.0, 1e-9), (2_000.001, 1e-3)] {
            let err = plan_steps(duration, dt, &step(0.1)).unwrap_err();
            let text = err.to_string();
            assert!(matches!(err, OfflineError::TooManySteps { .. }), "{text}");
            assert!(
                text.contains("MB") && text.contains("at most 2000000"),
                "{text}"
            );
        }
        assert_eq!(plan_steps(2_000.0, 1e-3, &step(0.1)).unwrap(), MAX_STEPS);
        assert!(matches!(
            plan_steps(3.0, 0.0, &step(0.1)),
            Err(OfflineError::BadDt(_))
        ));
        assert!(matches!(
            plan_steps(f64::INFINITY, 1e-3, &step(0.1)),
            Err(OfflineError::BadDuration(_))
        ));
    }

    #[test]
    fn a_step_at_or_after_the_end_is_refused() {
        for at in [3.0, 5.0] {
            let err = plan_steps(3.0, 1e-3, &step(at)).unwrap_err();
            assert!(matches!(err, OfflineError::StepAfterEnd { .. }), "{err}");
            assert!(err.to_string().contains("--duration 3 s"), "{err}");
        }
        assert_eq!(plan_steps(3.0, 1e-3, &step(2.999)).unwrap(), 3000);
    }
}
