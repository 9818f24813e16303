//! `tendril sim --model-learning on`: the circle's offset learned on the
//! model before the run (`ipc::rehearsal`, `docs/design.md` §6.4), then
//! sent by the planner on the path.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::{SimConfig, SimError};
use crate::ipc::rehearsal::{self, Settings, StartSettings, VirtualLoop};
use crate::plan::{PathShape, TurningOffset};
use crate::plant::PlantParams;

/// What the learning on the model did (`report.json`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ModelLearningReport {
    /// The rehearsed loop's measured pass without the offset, RMS mm.
    pub unaided_pass_rms_mm: f64,
    /// The same pass after each iteration, RMS mm.
    pub iteration_pass_rms_mm: Vec<f64>,
    /// With the offset sent (the best iteration's), RMS mm.
    pub learned_pass_rms_mm: f64,
    /// The offset's largest coefficient, mm.
    pub largest_offset_mm: f64,
    /// Why the iterations stopped early, if they did.
    #[serde(default)]
    pub stopped: Option<String>,
    /// Rehearsals of the loop run.
    pub rehearsals: usize,
    /// Wall time, s.
    pub seconds: f64,
    /// The path's first seconds (the window the start is learned on) with
    /// the periodic offset alone → with the learned start, RMS mm.
    #[serde(default)]
    pub start_window_rms_mm: Option<[f64; 2]>,
    /// The window after each of the start's iterations, RMS mm.
    #[serde(default)]
    pub start_iteration_rms_mm: Vec<f64>,
}

/// The offset for `cfg`'s circle, learned on the loop rehearsed against
/// the robot file's plant model with the controller's net (`model_path`,
/// `model_bytes`); `None` when not asked for.
pub fn before_run(
    cfg: &SimConfig,
    model_path: &Path,
    model_bytes: &[u8],
) -> Result<Option<(TurningOffset, ModelLearningReport)>, SimError> {
    if !cfg.model_learning {
        return Ok(None);
    }
    let PathShape::Circle { center_m, .. } = cfg.planner.shape else {
        return Err(SimError::Config(format!(
            "--model-learning on learns a circle's offset; this path is a {}",
            cfg.planner.shape.name()
        )));
    };
    let period_s =
        cfg.planner.shape.period_s().ok_or_else(|| {
            SimError::Config("--model-learning on: the circle has no period".into())
        })?;
    if cfg.controller.ki_per_s == 0.0 {
        return Err(SimError::Config(
            "--model-learning on needs the correction (it learns on the loop with it)".into(),
        ));
    }
    let robot =
        crate::robot::Robot::load(&cfg.robot).map_err(|e| SimError::Config(e.to_string()))?;
    // The planner as it will run, less what the rehearsal cannot be: the
    // learning and the stiffness adaptation read the tracker's frames.
    let mut planner = cfg.planner.clone();
    planner.model = Some(model_path.to_path_buf());
    planner.turning_offset = None;
    planner.learning = crate::plan::LearningChoice::Off;
    planner.adapt_stiffness = false;
    let planned = crate::ipc::planner::plan(&planner)?;
    let mut controller = cfg.controller.clone();
    controller.model = model_path.to_path_buf();
    // The model: the robot file's plant (its rod, static or dynamic, with
    // its own damping), an ideal tracker; never a reality, which the
    // controller does not know.
    let plant = PlantParams {
        model: cfg.plant.params.model_in_effect(),
        ..PlantParams::default()
    };
    let rehearsed = VirtualLoop {
        robot: &robot,
        net: model_bytes,
        controller: &controller,
        plant: &plant,
        motion: &planned.motion,
        period_s,
        settle_s: planner.settle_s,
    };
    // The measured pass waits for the ring of the path's start to decay
    // (the step shaping's mode: the rod's first, as designed for).
    // The path's start is learned after it, on the same mode.
    let settings = match cfg.planner.step_shaping {
        crate::plan::ShapingChoice::Designed(s) => Settings {
            start: StartSettings::for_mode(s.mode_hz, s.damping_ratio, s.length_s()),
            ..Settings::default().passes_to_settle(period_s, s.mode_hz, s.damping_ratio)
        },
        _ => Settings::default(),
    };
    let total = settings.most_rehearsals();
    log::info!(
        "sim: learning the circle's offset on the model: up to {total} rehearsals of {:.0} s of loop",
        planner.settle_s + period_s * settings.passes as f64
    );
    let bar = crate::progress::bar(
        total as u64,
        true,
        "learning on the model {bar:30} {pos}/{len} rehearsals {elapsed}",
    );
    let started = std::time::Instant::now();
    let learned = rehearsal::learn(&rehearsed, center_m, &settings, &|| bar.inc(1));
    bar.finish_and_clear();
    if crate::interrupt::stop_requested() {
        return Err(SimError::Interrupted);
    }
    let learned = learned?;
    let report = ModelLearningReport {
        unaided_pass_rms_mm: learned.unaided_rms_m * 1e3,
        iteration_pass_rms_mm: learned.iteration_rms_m.iter().map(|v| v * 1e3).collect(),
        learned_pass_rms_mm: learned.learned_rms_m() * 1e3,
        largest_offset_mm: learned.offset.largest_m() * 1e3,
        stopped: learned.stopped.clone(),
        rehearsals: learned.rehearsals,
        seconds: started.elapsed().as_secs_f64(),
        start_window_rms_mm: learned
            .start
            .as_ref()
            .map(|s| [s.unaided_rms_m * 1e3, s.learned_rms_m() * 1e3]),
        start_iteration_rms_mm: learned.start.as_ref().map_or(vec![], |s| {
            s.iteration_rms_m.iter().map(|v| v * 1e3).collect()
        }),
    };
    if let Some(why) = &learned.stopped {
        log::warn!("sim: learning on the model stopped early: {why}");
    }
    if let Some(why) = learned.start.as_ref().and_then(|s| s.stopped.as_ref()) {
        log::warn!("sim: learning the path's start on the model stopped early: {why}");
    }
    if let (Some([before, after]), Some(s)) = (report.start_window_rms_mm, &settings.start) {
        log::info!(
            "sim: on the model, the path's first {:.1} s {before:.3} → {after:.3} mm RMS",
            s.window.length_s()
        );
    }
    log::info!(
        "sim: on the model, the circle's pass {:.3} → {:.3} mm RMS ({} rehearsals, {:.0} s)",
        report.unaided_pass_rms_mm,
        report.learned_pass_rms_mm,
        report.rehearsals,
        report.seconds
    );
    let mut offset = learned.offset;
    offset.learned_for = Some(crate::plan::LearnedFor {
        robot: robot.fingerprint(),
        shape: cfg.planner.shape.clone(),
    });
    Ok(Some((offset, report)))
}

#[cfg(test)]
mod tests {
    use std::path::{Path, PathBuf};

    use super::*;
    use crate::ipc::sim::ModelSource;

    fn config(shape: PathShape) -> SimConfig {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let mut cfg = SimConfig::new(
            PathBuf::from("tendril"),
            root.join("robots/seed-4t.toml"),
            ModelSource::BuiltIn,
            PathBuf::from("out"),
        );
        cfg.planner.shape = shape;
        cfg.model_learning = true;
        cfg
    }

    /// What cannot be learned this way is refused with one line that names
    /// it, before any rehearsal runs; not asking for it costs nothing.
    #[test]
    fn a_path_other_than_a_circle_or_no_correction_is_refused_by_name() {
        let net = crate::ipc::sim::BUILT_IN_NET;
        let steps = PathShape::Steps {
            targets_m: vec![vec![0.01, 0.0], vec![0.0, 0.01]],
            dwell_s: 2.0,
            height_m: None,
        };
        let err = before_run(&config(steps), Path::new("m.tnet"), net).unwrap_err();
        assert!(
            err.to_string().contains("circle") && err.to_string().contains("steps"),
            "{err}"
        );
        let mut cfg = config(PathShape::default_circle());
        cfg.set_correction(false);
        let err = before_run(&cfg, Path::new("m.tnet"), net).unwrap_err();
        assert!(err.to_string().contains("correction"), "{err}");
        cfg.model_learning = false;
        assert!(before_run(&cfg, Path::new("m.tnet"), net)
            .unwrap()
            .is_none());
    }
}
