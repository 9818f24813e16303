//! Stage 5 of the main job: the closed loop — planner, controller and plant
//! as real processes over iceoryx2 — on the runs that suit the robot, each
//! with the IK net alone and with the firmware's integral correction.

use std::fmt::Write as _;
use std::path::Path;

use crate::ipc::sim::{ModelSource, SimConfig, SimError};
pub use crate::plan::runs::run_dir;
use crate::plan::Family;
use crate::plan::{default_loop_runs, LoopRun};
use crate::statics::Statics;
use crate::units::length_mm_or_dash;

/// Where the runs are written (`dir`, a staging directory) and where the
/// user will find them once it is published: what the reports record.
#[derive(Clone, Copy, Debug)]
pub struct LoopOut<'a> {
    /// The directory the sims write into.
    pub dir: &'a Path,
    /// Where it is published.
    pub published: &'a Path,
}

/// What every loop run of the stage shares.
struct LoopInputs<'a> {
    exe: &'a Path,
    robot_file: &'a Path,
    model: &'a Path,
    out: LoopOut<'a>,
    quick_s: Option<f64>,
}

impl LoopInputs<'_> {
    /// The sim of `run` with or without the correction, written into `dir`
    /// under the stage's directory, its length capped by `--quick`.
    fn sim(&self, run: &LoopRun, dir: &str, correction: bool) -> SimConfig {
        let mut sim = SimConfig::new(
            self.exe.to_path_buf(),
            self.robot_file.to_path_buf(),
            ModelSource::File(self.model.to_path_buf()),
            self.out.dir.join(dir),
        );
        sim.staged_as = Some((self.out.dir.to_path_buf(), self.out.published.to_path_buf()));
        sim.duration_s = self
            .quick_s
            .map_or(run.duration_s, |q| q.min(run.duration_s));
        sim.smoke = self.quick_s.is_some();
        sim.planner.shape = run.shape.clone();
        sim.set_correction(correction);
        sim
    }
}

/// Run every run of [`default_loop_runs`] for the robot (by its reachable
/// family, `docs/design.md` §6.1) with the net alone and with the
/// correction, writing under `out`; `quick_s` caps each run's seconds of
/// trajectory. Returns the report section and how many runs missed their
/// bounds. A failed run is reported and the others go on; an interrupt
/// stops the stage.
pub fn closed_loop_section(
    robot_file: &Path,
    statics: &Statics,
    model: &Path,
    out: LoopOut<'_>,
    quick_s: Option<f64>,
) -> anyhow::Result<(String, LoopTally)> {
    let exe = std::env::current_exe()
        .map_err(|e| anyhow::anyhow!("locating the tendril executable: {e}"))?;
    let inputs = LoopInputs {
        exe: &exe,
        robot_file,
        model,
        out,
        quick_s,
    };
    let runs = default_loop_runs(statics)?;
    let family = Family::of(statics)?;
    let mut summary = String::from(
        "## 5. Closed loop (planner → controller → plant over iceoryx2)\n\n\
         Tracking error from the plant's true tip against the planner's path; steady state is \
         the mean true error over the last 0.5 s of each ≥ 1 s stretch with one target. \
         The steps' RMS and max include the jumps between targets.\n\n",
    );
    let _ = writeln!(
        summary,
        "The robot's tip reaches {}; the runs are the ones that family can follow.\n\n\
         | run | correction | RMS | max | steady state, worst target |\n\
         |---|---|---|---|---|",
        family.describe()
    );
    let mut sections = Vec::new();
    let mut tally = LoopTally::default();
    let letters = "abcdefghijklmnopqrstuvwxyz";
    let mut k = 0;
    // A smoke run (--quick) checks that the loop works: the corrected run
    // of each path is enough, and its net is too weak to compare with.
    let modes: &[bool] = if quick_s.is_some() {
        &[true]
    } else {
        &[false, true]
    };
    for run in &runs {
        for &correction in modes {
            let dir = run_dir(run, correction);
            let what = format!(
                "{}, {}",
                run.label,
                if correction {
                    "with the integral correction"
                } else {
                    "IK net alone"
                }
            );
            let mut sim = inputs.sim(run, &dir, correction);
            sim.label = what.clone();
            let letter = letters.chars().nth(k).unwrap_or('z');
            k += 1;
            let title = format!("### 5{letter}. {what}");
            let on_off = if correction { "on" } else { "off" };
            let (row, section) = row_and_section(
                crate::ipc::sim::run(&sim),
                &format!("{} ({dir})", run.label),
                on_off,
                &dir,
                &title,
                |_| String::new(),
                &mut tally,
            )?;
            summary.push_str(&row);
            sections.push(section);
        }
    }
    if let Some(run) = runs.first() {
        let (row, section) = chip_run(&inputs, run, &mut tally)?;
        summary.push_str(&row);
        sections.push(section);
        let (row, section) = mass_run(&inputs, run, &mut tally)?;
        summary.push_str(&row);
        sections.push(section);
    }
    summary.push('\n');
    summary.push_str(&sections.join("\n"));
    Ok((summary, tally))
}

/// How many loop runs ran, and how many missed their bounds or failed (a
/// chip run that could not start for want of QEMU is neither: its row says
/// what to install).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LoopTally {
    /// Runs that ran (or failed to).
    pub runs: usize,
    /// Of them, the ones that missed a bound or failed.
    pub missed: usize,
}

impl LoopTally {
    /// One run with these problems (none: it passed).
    fn count(&mut self, problems: &[String]) {
        self.runs += 1;
        self.missed += usize::from(!problems.is_empty());
    }
}

/// The built-in reality the main job runs the rod with mass as.
pub const MASS_REALITY: &str = "dynamic-light-damping";

/// The first run once more, corrected, on the rod with mass: the dynamic
/// Cosserat rod with its first mode damped at 5 % ([`MASS_REALITY`]), so a
/// new user sees the realistic number beside the ideal one (`docs/design.md`
/// §6.4: the planner shapes the start and sends the dynamic offset).
fn mass_run(
    inputs: &LoopInputs<'_>,
    run: &LoopRun,
    tally: &mut LoopTally,
) -> anyhow::Result<(String, String)> {
    let dir = format!("{}-mass", run_dir(run, true));
    let what = format!(
        "{}, with the correction, on the rod with mass ({MASS_REALITY})",
        run.label
    );
    let title = format!("### 5y. {what}");
    let mut sim = inputs.sim(run, &dir, true);
    sim.plant.params.reality = crate::plant::reality::Reality::builtin(MASS_REALITY);
    sim.label = what;
    row_and_section(
        crate::ipc::sim::run(&sim),
        &format!("{} ({dir}), the rod with mass", run.label),
        "on",
        &dir,
        &title,
        |_| String::new(),
        tally,
    )
}

/// The first run once more with the chip in the loop: the controller image
/// on an STM32F405 under QEMU, bridged over its serial link, at
/// [`crate::mcu::bridge::MCU_RATE_HZ`] (docs/design.md §5.6). Without QEMU
/// or the Rust target its row says what to install; the other runs stand.
fn chip_run(
    inputs: &LoopInputs<'_>,
    run: &LoopRun,
    tally: &mut LoopTally,
) -> anyhow::Result<(String, String)> {
    let dir = format!("{}-mcu", run_dir(run, true));
    let what = format!("{}, with the correction, the chip in the loop", run.label);
    let title = format!("### 5z. {what}");
    if let Err(e) = crate::mcu::locate_image() {
        let why = format!("{e:#}");
        log::warn!("closed loop {dir}: not run: {why}");
        return Ok((
            format!(
                "| {} ({dir}) | on, chip | not run: {why} | | |\n",
                run.label
            ),
            format!("{title}\n\nNot run: {why}.\n"),
        ));
    }
    let mut sim = inputs.sim(run, &dir, true);
    sim.controller.rate_hz = crate::mcu::bridge::MCU_RATE_HZ;
    sim.planner.rate_hz = crate::mcu::bridge::MCU_RATE_HZ;
    sim.mcu = Some(crate::ipc::sim::SimMcu::default());
    sim.label = what;
    row_and_section(
        crate::ipc::sim::run(&sim),
        &format!(
            "{} ({dir}), chip in the loop at {} Hz",
            run.label,
            crate::mcu::bridge::MCU_RATE_HZ
        ),
        "on",
        &dir,
        &title,
        |r| {
            r.controller
                .as_ref()
                .and_then(|c| c.link.as_ref())
                .map_or(String::new(), |l| {
                    format!(
                        "; setpoint → command p50 {:.2}, p99 {:.2} periods",
                        l.setpoint_to_command_periods.0, l.setpoint_to_command_periods.1
                    )
                })
        },
        tally,
    )
}

/// The table row and the report section of one loop run (its `row`
/// label, the correction `on_off`, `dir`, section `title`), with `more`
/// appended to a row that ran; an interrupt stops the stage, a failure is
/// a row.
fn row_and_section(
    result: Result<crate::ipc::sim::report::SimReport, SimError>,
    row: &str,
    on_off: &str,
    dir: &str,
    title: &str,
    more: impl Fn(&crate::ipc::sim::report::SimReport) -> String,
    tally: &mut LoopTally,
) -> anyhow::Result<(String, String)> {
    Ok(match result {
        Ok(r) => {
            let num = length_mm_or_dash;
            tally.count(&r.verdict.problems);
            let verdict = if r.verdict.clean {
                String::new()
            } else {
                format!(" (failed: {})", r.verdict.problems.join("; "))
            };
            (
                format!(
                    "| {row} | {on_off} | {} | {} | {}{verdict}{} |\n",
                    num(r.rms_tracking_error_mm),
                    num(r.max_tracking_error_mm),
                    num(r.max_steady_state_error_mm),
                    more(&r)
                ),
                format!(
                    "{title}\n\n{}\n\n![sim]({dir}/sim.png)\n",
                    r.markdown().trim()
                ),
            )
        }
        Err(e @ SimError::Interrupted) => return Err(e.into()),
        Err(e) => {
            log::error!("closed loop {dir}: {e}");
            tally.count(&[e.to_string()]);
            (
                format!("| {row} | {on_off} | failed | | |\n"),
                format!("{title}\n\nThe sim failed: {e}.\n"),
            )
        }
    })
}
