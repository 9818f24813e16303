//! Stage 5 of the main job: the closed loop — planner, controller and plant
//! as real processes over iceoryx2 — on the runs that suit the robot, each
//! with the IK net alone and with the firmware's integral correction.

use std::fmt::Write as _;
use std::path::Path;

use crate::ipc::sim::{ModelSource, SimConfig, SimError};
use crate::ipc::trajectory::Shape as TrajectoryShape;
use crate::robot::Robot;

/// One closed-loop run of the main job.
#[derive(Clone, Debug)]
pub struct LoopRun {
    /// What the planner follows.
    pub shape: TrajectoryShape,
    /// Sub-directory of the output directory (with `-ik-only` appended for
    /// the run without the correction).
    pub dir: String,
    /// What the report calls it.
    pub label: String,
}

/// The runs for `robot`: the 30 mm circle and 10 mm steps in the lateral
/// plane (docs/design.md §6).
pub fn loop_runs(_robot: &Robot) -> Vec<LoopRun> {
    vec![
        LoopRun {
            shape: TrajectoryShape::Circle {
                center_m: [0.0, 0.0],
                radius_m: 0.015,
                freq_hz: 0.2,
            },
            dir: "sim".into(),
            label: "30 mm circle at 0.2 Hz".into(),
        },
        LoopRun {
            shape: TrajectoryShape::Steps {
                targets_m: vec![[0.01, 0.0], [0.0, 0.01], [-0.01, 0.0], [0.0, -0.01]],
                dwell_s: 2.0,
            },
            dir: "sim-steps".into(),
            label: "10 mm steps".into(),
        },
    ]
}

/// Run every [`loop_runs`] run with the net alone and with the correction,
/// `seconds` of trajectory each, writing under `out`; returns the report
/// section. A failed run is reported and the others go on; an interrupt
/// stops the stage.
pub fn closed_loop_section(
    robot_file: &Path,
    robot: &Robot,
    model: &Path,
    out: &Path,
    seconds: f64,
) -> anyhow::Result<String> {
    let exe = std::env::current_exe()
        .map_err(|e| anyhow::anyhow!("locating the tendril executable: {e}"))?;
    let runs = loop_runs(robot);
    let mut summary = String::from(
        "## 5. Closed loop (planner → controller → plant over iceoryx2)\n\n\
         Tracking error from the plant's true tip against the planner's path; steady state is \
         the mean true error over the last 0.5 s of each ≥ 1 s stretch with one target. \
         The steps' RMS and max include the jumps between targets.\n\n\
         | run | correction | RMS (mm) | max (mm) | steady state, worst target (mm) |\n|---|---|---|---|---|\n",
    );
    let mut sections = Vec::new();
    let letters = "abcdefghijklmnopqrstuvwxyz";
    let mut k = 0;
    for run in &runs {
        for correction in [false, true] {
            let dir = if correction {
                run.dir.clone()
            } else {
                format!("{}-ik-only", run.dir)
            };
            let what = format!(
                "{}, {}",
                run.label,
                if correction {
                    "with the integral correction"
                } else {
                    "IK net alone"
                }
            );
            let mut sim = SimConfig::new(
                exe.clone(),
                robot_file.to_path_buf(),
                ModelSource::File(model.to_path_buf()),
                out.join(&dir),
            );
            sim.duration_s = seconds;
            sim.planner.shape = run.shape.clone();
            sim.set_correction(correction);
            sim.label = what.clone();
            let letter = letters.chars().nth(k).unwrap_or('z');
            k += 1;
            let title = format!("### 5{letter}. {what}");
            let on_off = if correction { "on" } else { "off" };
            match crate::ipc::sim::run(&sim) {
                Ok(r) => {
                    let num = |v: Option<f64>| v.map_or("–".into(), |v| format!("{v:.3}"));
                    let verdict = if r.verdict.clean {
                        String::new()
                    } else {
                        format!(" (failed: {})", r.verdict.problems.join("; "))
                    };
                    let _ = writeln!(
                        summary,
                        "| {} ({dir}) | {on_off} | {} | {} | {}{verdict} |",
                        run.label,
                        num(r.rms_tracking_error_mm),
                        num(r.max_tracking_error_mm),
                        num(r.max_steady_state_error_mm)
                    );
                    sections.push(format!(
                        "{title}\n\n{}\n\n![sim]({dir}/sim.png)\n",
                        r.markdown().trim()
                    ));
                }
                Err(e @ SimError::Interrupted) => return Err(e.into()),
                Err(e) => {
                    log::error!("closed loop {dir}: {e}");
                    let _ = writeln!(summary, "| {} ({dir}) | {on_off} | failed | | |", run.label);
                    sections.push(format!("{title}\n\nThe sim failed: {e}.\n"));
                }
            }
        }
    }
    summary.push('\n');
    summary.push_str(&sections.join("\n"));
    Ok(summary)
}
