//! What one sim run is asked to do ([`SimConfig`]), its defaults and its
//! checks: everything is refused here, before any process starts.

use std::path::{Path, PathBuf};

use serde::Serialize;

use super::{SimError, SimFaults, DEFAULT_KI_PER_S, DEFAULT_MAX_RMS_MM};
use crate::ipc::clock::now_ns;
use crate::ipc::controller::ControllerConfig;
use crate::ipc::planner::PlannerConfig;
use crate::ipc::plant::PlantConfig;
use crate::plan::PathShape;

/// Which net the controller starts with.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub enum ModelSource {
    /// A `.tnet` file.
    File(PathBuf),
    /// The firmware's built-in net ([`BUILT_IN_NET`]), written into the output directory.
    BuiltIn,
    /// A quick random-feature net fitted at start (for tests and demos),
    /// written into the output directory as `quick.tnet`.
    Quick,
}

impl ModelSource {
    /// `explicit` if given, else `fallback` if it exists, else the built-in
    /// net (with one log line saying so).
    pub fn resolve(explicit: Option<PathBuf>, fallback: &Path) -> ModelSource {
        match explicit {
            Some(p) => ModelSource::File(p),
            None if fallback.exists() => ModelSource::File(fallback.to_path_buf()),
            None => {
                log::info!(
                    "no --model and no {}: using the firmware's built-in net \
                     (firmware/vectors/default.tnet)",
                    fallback.display()
                );
                ModelSource::BuiltIn
            }
        }
    }
}

/// Everything one run needs, typed. The child configurations are
/// templates: the launcher fills in robot, model, prefix, log and stats
/// paths, CPU, scheduling and supervision for each process it starts.
#[derive(Clone, Debug, Serialize)]
pub struct SimConfig {
    /// The `tendril` executable to start the children from.
    pub exe: PathBuf,
    /// Robot file: the model the planner, the controller and the net use,
    /// and the plant's robot unless `plant_robot` says otherwise.
    pub robot: PathBuf,
    /// The robot the plant moves (before its reality), when it is not the
    /// model's: e.g. the nominal file under a net trained on a calibrated
    /// one, with the calibrated robot's truth as the reality.
    pub plant_robot: Option<PathBuf>,
    /// The net.
    pub model: ModelSource,
    /// Output directory.
    pub out: PathBuf,
    /// (a staging directory, where a job publishes it later): paths under
    /// the first are recorded in the report as under the second, where the
    /// user will find them.
    pub staged_as: Option<(PathBuf, PathBuf)>,
    /// Service-name prefix (`None`: unique per run).
    pub prefix: Option<String>,
    /// Seconds of trajectory after the settle hold.
    pub duration_s: f64,
    /// Planner: trajectory, rate, settle, injected bad setpoints.
    /// Learn the circle's offset on the model before the run
    /// (`--model-learning on`; `docs/design.md` §6.4).
    pub model_learning: bool,
    pub planner: PlannerConfig,
    /// Controller: loop and correction tuning.
    pub controller: ControllerConfig,
    /// Plant: model and plant-side faults.
    pub plant: PlantConfig,
    /// Process-level faults the launcher injects.
    pub faults: SimFaults,
    /// Run the three processes under SCHED_FIFO.
    pub realtime: bool,
    /// Pin controller and plant to one CPU and the planner to another.
    pub pin: bool,
    /// Free-form description for the report.
    pub label: String,
    /// A run whose RMS tracking error exceeds this (mm) is not clean.
    pub max_rms_mm: f64,
    /// A smoke run (`tendril run --quick`): no accuracy bound, since its
    /// net is weak on purpose; the processes, faults and real time are
    /// still judged.
    pub smoke: bool,
    /// Cap on the run's estimated log size, GB ([`budget`]).
    pub max_log_gb: f64,
    /// The chip in the loop instead of the host controller: the launcher
    /// starts it (so it outlives a bridge killed by a link cut) and the
    /// controller process bridges to it.
    pub mcu: Option<SimMcu>,
}

/// The chip in a sim.
#[derive(Clone, Debug, Default, Serialize)]
pub struct SimMcu {
    /// The controller image (None: built from this checkout).
    pub image: Option<PathBuf>,
    /// Inject garbage on the link every this many ms.
    pub garbage_every_ms: Option<u64>,
}

/// A unique service prefix for one run: parallel sims and tests never share services.
pub fn unique_prefix() -> String {
    format!(
        "tendril-sim-{}-{}",
        std::process::id(),
        now_ns() % 1_000_000_000_000
    )
}

impl SimConfig {
    /// Where the user will find `path` once a staging directory is
    /// published ([`Self::staged_as`]).
    pub fn shown(&self, path: &Path) -> PathBuf {
        match &self.staged_as {
            Some((staging, published)) => match path.strip_prefix(staging) {
                Ok(rel) => published.join(rel),
                Err(_) => path.to_path_buf(),
            },
            None => path.to_path_buf(),
        }
    }

    /// The defaults of `tendril sim`: the 30 mm circle at 0.2 Hz after a
    /// 2 s settle, 10 s, the firmware's integral correction on
    /// ([`DEFAULT_KI_PER_S`]), the controller's other defaults
    /// ([`crate::ipc::controller::defaults`]), the default plant, real-time
    /// and pinned.
    pub fn new(exe: PathBuf, robot: PathBuf, model: ModelSource, out: PathBuf) -> SimConfig {
        let mut controller = ControllerConfig::new(robot.clone(), PathBuf::new());
        controller.ki_per_s = DEFAULT_KI_PER_S;
        SimConfig {
            exe,
            robot: robot.clone(),
            plant_robot: None,
            model,
            out,
            staged_as: None,
            smoke: false,
            prefix: None,
            duration_s: 10.0,
            model_learning: false,
            planner: PlannerConfig {
                prefix: String::new(),
                start_from_rest: true,
                dynamic_offset: true,
                adapt_stiffness: true,
                net_error_offset: true,
                peer_timeout_s: controller.peer_timeout_s,
                supervised: true,
                realtime: true,
                ..PlannerConfig::new(robot.clone(), PathShape::default_circle())
            },
            controller,
            plant: PlantConfig {
                robot,
                ..PlantConfig::default()
            },
            faults: SimFaults::default(),
            realtime: true,
            pin: true,
            label: String::new(),
            max_rms_mm: DEFAULT_MAX_RMS_MM,
            max_log_gb: super::budget::DEFAULT_MAX_LOG_GB,
            mcu: None,
        }
    }

    /// Switch the firmware's integral correction on (default gain) or off (IK alone).
    pub fn set_correction(&mut self, on: bool) {
        self.controller.ki_per_s = if on { DEFAULT_KI_PER_S } else { 0.0 };
        // The net alone is the net without feedback: no stiffness
        // adaptation either (`docs/design.md` §6.5).
        self.planner.adapt_stiffness &= on;
        // Nor the planner's offset for the net's own error: "alone" is the
        // net as it was trained.
        self.planner.net_error_offset &= on;
    }

    /// Reject what cannot be a run, before anything starts.
    pub fn validate(&self) -> Result<(), SimError> {
        if !(self.duration_s.is_finite() && self.duration_s > 0.0) {
            return Err(SimError::Config(format!(
                "--duration {}: must be a finite number of seconds > 0",
                self.duration_s
            )));
        }
        if !(self.max_rms_mm.is_finite() && self.max_rms_mm > 0.0) {
            return Err(SimError::Config(format!(
                "--max-rms-mm {}: must be a finite bound > 0 mm",
                self.max_rms_mm
            )));
        }
        if !(self.max_log_gb.is_finite() && self.max_log_gb > 0.0) {
            return Err(SimError::Config(format!(
                "--max-log-gb {}: must be a finite size > 0 GB",
                self.max_log_gb
            )));
        }
        let settle = self.planner.settle_s;
        if !(settle.is_finite() && settle >= 0.0) {
            return Err(SimError::Config(format!(
                "--settle {settle}: must be a finite number of seconds ≥ 0"
            )));
        }
        let inject = &self.planner.inject;
        if let Some(t) = inject
            .nan_at_s
            .iter()
            .chain(&inject.outside_at_s)
            .find(|t| !(t.is_finite() && **t >= 0.0))
        {
            return Err(SimError::Config(format!(
                "injection time {t}: must be a finite number of seconds ≥ 0"
            )));
        }
        if self.mcu.is_none() && self.faults.cut_link_at.is_some() {
            return Err(SimError::Config(
                "--cut-link-at needs the chip in the loop (--controller mcu)".into(),
            ));
        }
        self.faults.validate()?;
        self.check_schedule_within_the_run()
    }

    /// Refuse a fault or injection scheduled at or after the run's end (the
    /// settle plus `duration_s`): it would never happen, and a run that
    /// reports no fault because none was injected would look clean.
    fn check_schedule_within_the_run(&self) -> Result<(), SimError> {
        let end_s = self.planner.settle_s + self.duration_s;
        let inject = &self.planner.inject;
        let plant = &self.plant.params.faults;
        let mut scheduled = self.faults.scheduled();
        scheduled.extend(inject.nan_at_s.iter().map(|&t| ("inject-nan-at", t)));
        scheduled.extend(
            inject
                .outside_at_s
                .iter()
                .map(|&t| ("inject-outside-at", t)),
        );
        scheduled.extend(plant.stuck.map(|s| ("stuck", s.at_s)));
        scheduled.extend(plant.drop.map(|d| ("drop", d.from_s)));
        scheduled.extend(plant.delay.map(|d| ("delay", d.from_s)));
        match scheduled.iter().find(|(_, t)| *t >= end_s) {
            Some((flag, t)) => Err(SimError::Config(format!(
                "--{flag}: at {} s, at or after the run's end ({} s: {} s settle + {} s \
                 --duration), so it would never happen; schedule it earlier or run longer",
                crate::units::given(*t),
                crate::units::given(end_s),
                crate::units::given(self.planner.settle_s),
                crate::units::given(self.duration_s)
            ))),
            None => Ok(()),
        }
    }
}
