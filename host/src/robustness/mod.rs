//! The robustness table (docs/design.md §6.3): the robot's closed-loop runs
//! (the circle and the steps, and the helix on a robot that reaches a
//! volume) against every reality, with the IK net alone and with the
//! correction, all with the *same default gains*. Each row is one real sim
//! (planner, controller and plant as processes); the plant alone knows the
//! reality. Written as `robustness.md`, `robustness.json` and a figure with
//! one bar group per reality.

pub mod figure;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::ipc::sim::{ModelSource, SimConfig, SimError};
use crate::plan::default_loop_runs;
use crate::plant::reality::Reality;
use crate::statics::{SolverSettings, Statics};

/// What to run.
#[derive(Clone, Debug)]
pub struct RobustnessConfig {
    /// The tendril executable (the sims start its subcommands).
    pub exe: PathBuf,
    /// Robot file (the model the planner, IK and net use).
    pub robot: PathBuf,
    /// The net.
    pub model: ModelSource,
    /// Where the runs are written (a staging directory).
    pub out: PathBuf,
    /// Where the user will find `out` once it is published.
    pub shown_out: PathBuf,
    /// The realities, in table order.
    pub realities: Vec<Reality>,
    /// Cap on each run's seconds of trajectory.
    pub quick_s: Option<f64>,
    /// Also run each with the net alone.
    pub net_alone: bool,
    /// The planner's stiffness adaptation on (`docs/design.md` §6.5).
    pub adapt_stiffness: bool,
}

/// One row: one run against one reality.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Row {
    /// The reality's name.
    pub reality: String,
    /// The run (`circle`, `steps`, `helix`, `sweep`).
    pub run: String,
    /// With the integral correction.
    pub correction: bool,
    /// Which of the planner's answers to the rod's mass and its model's
    /// error were on (the step shaping, the dynamic offset, the learning,
    /// the stiffness adaptation).
    #[serde(default)]
    pub planner: String,
    /// RMS tracking error (true tip), mm.
    pub rms_mm: Option<f64>,
    /// Largest tracking error, mm.
    pub max_mm: Option<f64>,
    /// Worst steady state (steps), mm.
    pub steady_mm: Option<f64>,
    /// The reality's tracker jitter (per axis), mm.
    pub jitter_mm: f64,
    /// Periods the controller held (watchdog, stuck motor).
    pub hold_periods: u64,
    /// Faults the controller detected.
    pub faults: usize,
    /// The run's verdict: clean (no oscillation, within its bounds).
    pub clean: bool,
    /// Why not, if not.
    pub problems: Vec<String>,
    /// Where the run's report is, relative to the table.
    pub dir: String,
}

/// Run every reality × run × {net alone, corrected}; progress on stderr.
/// A failed sim is a row that says so; an interrupt stops the table.
pub fn run(cfg: &RobustnessConfig) -> Result<Vec<Row>, SimError> {
    let robot =
        crate::robot::Robot::load(&cfg.robot).map_err(|e| SimError::Config(e.to_string()))?;
    let statics = Statics::new(&robot, SolverSettings::default());
    let runs = default_loop_runs(&statics).map_err(|e| SimError::Config(e.to_string()))?;
    for r in &cfg.realities {
        r.real_robot(&robot)
            .map_err(|e| SimError::Config(format!("reality {}: {e}", r.name)))?;
    }
    let modes: &[bool] = if cfg.net_alone {
        &[false, true]
    } else {
        &[true]
    };
    let total = cfg.realities.len() * runs.len() * modes.len();
    let mut rows = Vec::with_capacity(total);
    for reality in &cfg.realities {
        for run in &runs {
            for &correction in modes {
                let dir = format!(
                    "{}/{}",
                    reality.name,
                    crate::plan::runs::run_dir(run, correction)
                );
                eprintln!(
                    "robustness {}/{total}: {} · {} · {}",
                    rows.len() + 1,
                    reality.name,
                    run.name,
                    if correction { "corrected" } else { "net alone" }
                );
                let mut sim = SimConfig::new(
                    cfg.exe.clone(),
                    cfg.robot.clone(),
                    cfg.model.clone(),
                    cfg.out.join(&dir),
                );
                sim.staged_as = Some((cfg.out.clone(), cfg.shown_out.clone()));
                sim.duration_s = cfg
                    .quick_s
                    .map_or(run.duration_s, |q| q.min(run.duration_s));
                sim.planner.shape = run.shape.clone();
                sim.planner.adapt_stiffness = cfg.adapt_stiffness;
                sim.set_correction(correction);
                sim.plant.params.reality = Some(reality.clone());
                sim.label = format!(
                    "{} against reality {} ({}), {}",
                    run.label,
                    reality.name,
                    reality.summary(),
                    if correction {
                        "with the correction"
                    } else {
                        "net alone"
                    }
                );
                let jitter_mm = reality.tracker.map_or(0.02, |t| t.position_jitter_mm);
                let mut row = Row {
                    reality: reality.name.clone(),
                    run: run.name.to_string(),
                    correction,
                    planner: String::new(),
                    rms_mm: None,
                    max_mm: None,
                    steady_mm: None,
                    jitter_mm,
                    hold_periods: 0,
                    faults: 0,
                    clean: false,
                    problems: Vec::new(),
                    dir,
                };
                match crate::ipc::sim::run(&sim) {
                    Ok(r) => {
                        row.planner = r.dynamics_summary();
                        row.rms_mm = r.rms_tracking_error_mm;
                        row.max_mm = r.max_tracking_error_mm;
                        row.steady_mm = r.max_steady_state_error_mm;
                        if let Some(c) = &r.controller {
                            row.hold_periods = c.hold_cycles;
                            row.faults = c.faults_detected.len();
                        }
                        row.clean = r.verdict.clean;
                        row.problems = r.verdict.problems;
                    }
                    Err(e @ SimError::Interrupted) => return Err(e),
                    Err(e) => row.problems.push(format!("the sim failed: {e}")),
                }
                rows.push(row);
            }
        }
    }
    Ok(rows)
}

/// The table as markdown.
pub fn markdown(rows: &[Row], robot: &Path) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Robustness: {} against every reality\n\n\
         One default set of gains for every row. Errors are the plant's true tip against the \
         planner's path, mm; steady state is the mean true error over the last 0.5 s of each \
         step target (the worst target); jitter is the reality's tracker jitter per axis; \
         planner says which of the step shaping, the dynamic offset and the learning for \
         repeated paths were on (docs/design.md §6.4).\n\n\
         | reality | run | correction | planner | RMS | max | steady state | jitter | holds | faults | verdict |\n\
         |---|---|---|---|---|---|---|---|---|---|---|",
        robot.display()
    );
    let mm = crate::units::length_mm_or_dash;
    for r in rows {
        let verdict = if r.clean {
            "clean".to_string()
        } else {
            r.problems.join("; ")
        };
        let _ = writeln!(
            s,
            "| {} | [{}]({}/report.md) | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            r.reality,
            r.run,
            r.dir,
            if r.correction { "on" } else { "off" },
            r.planner,
            mm(r.rms_mm),
            mm(r.max_mm),
            mm(r.steady_mm),
            r.jitter_mm,
            r.hold_periods,
            r.faults,
            verdict
        );
    }
    s.push_str("\n![robustness](robustness.png)\n");
    s
}
