//! `tendril sim`: planner, controller and plant as three processes over
//! iceoryx2, with fault injection and a report (docs/design.md §6, §7).

use std::io::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;

use super::controller::{ControllerKind, LoopOpts, OnOff};
use super::planner::TrajectoryOpts;
use super::plant::PlantOpts;
use crate::ipc::planner::Injections;
use crate::ipc::sim::{ModelSource, SimConfig, SimFaults};
use crate::plant::RobotModel;

/// The model `tendril train` writes by default.
const TRAINED_MODEL: &str = "out/model.tnet";

/// Run planner, controller and plant as separate processes and report.
#[derive(Args, Debug)]
pub struct SimArgs {
    /// Robot description file.
    #[arg(long, default_value = crate::robot::DEFAULT_ROBOT)]
    pub robot: PathBuf,
    /// The robot the plant moves, before --reality [default: --robot]. For
    /// a model that is not the robot's file: a net trained on a calibrated
    /// file (--robot) against the robot it was calibrated to (this file and
    /// a reality that makes it the real one).
    #[arg(long)]
    pub plant_robot: Option<PathBuf>,
    /// Trained IK net [default: out/model.tnet if it exists, else the
    /// firmware's built-in net firmware/vectors/default.tnet].
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Fit a quick random-feature IK net (written to OUT/quick.tnet) instead
    /// of loading --model: for tests and demos without a trained model.
    #[arg(long, conflicts_with = "model")]
    pub quick_model: bool,
    /// Run a net trained for another robot than --robot (with a warning) instead of refusing it.
    #[arg(long)]
    pub allow_robot_mismatch: bool,
    /// Output directory for report.json, report.md, sim.png and the logs.
    #[arg(long, default_value = "out/sim")]
    pub out: PathBuf,
    /// Seconds of trajectory after the settle hold.
    #[arg(long, default_value_t = 10.0, allow_hyphen_values = true)]
    pub duration: f64,
    /// Bound on the RMS tracking error, mm: a run above it is not clean
    /// (exit status non-zero, the reason in report.md).
    #[arg(long, default_value_t = crate::ipc::sim::DEFAULT_MAX_RMS_MM)]
    pub max_rms_mm: f64,
    /// Cap on the run's logs, GB: a --duration whose logs would be larger
    /// (≈ 0.7 MB/s with 4 tendons at 1 kHz) is refused before it starts.
    #[arg(long, default_value_t = crate::ipc::sim::budget::DEFAULT_MAX_LOG_GB)]
    pub max_log_gb: f64,
    /// iceoryx2 service-name prefix (default: unique per run).
    #[arg(long)]
    pub prefix: Option<String>,
    /// The planner takes the net's own quasi-static error along the path
    /// out before the loop sees it, from the robot's exact statics (an
    /// offset sent with the dynamic offset; docs/design.md §6.4); off with
    /// --correction off.
    #[arg(long, value_enum, default_value_t = super::controller::OnOff::On)]
    pub net_error_offset: super::controller::OnOff,
    /// Learn the circle's offset on the model before the run: the loop
    /// rehearsed in process against the robot file's plant (its rod, with
    /// --plant dynamic), the offset in the circle's turning frame, then the
    /// path's start (docs/design.md §6.4; four minutes on a three-segment
    /// robot).
    #[arg(long, value_enum, default_value_t = super::controller::OnOff::Off)]
    pub model_learning: super::controller::OnOff,
    /// Send this circle's offset, learned on the model by an earlier run
    /// (its `turning-offset.json`), instead of learning it again.
    #[arg(long, value_name = "FILE", conflicts_with = "model_learning")]
    pub turning_offset: Option<PathBuf>,
    #[command(flatten)]
    pub traj: TrajectoryOpts,
    #[command(flatten)]
    pub tuning: LoopOpts,
    #[command(flatten)]
    pub plant: PlantOpts,
    /// Plant's robot model: quasi-static or dynamic (docs/design.md §4.2).
    #[arg(long = "plant", value_enum, default_value_t = RobotModel::QuasiStatic)]
    pub plant_model: RobotModel,
    /// Pin controller and plant to one CPU (the last this process may use)
    /// and the planner to another: with the plant's real-time priority
    /// above the controller's, the command's event wakes the plant at once
    /// (one-way latency p50 ≈ 7 µs here, against ≈ 25 µs unpinned).
    #[arg(long, value_enum, default_value_t = OnOff::On)]
    pub pin: OnOff,
    /// Fault: SIGKILL the planner at this time (s after the first setpoint).
    #[arg(long, allow_hyphen_values = true)]
    pub kill_planner_at: Option<f64>,
    /// Fault: start a new planner this long after the kill (s).
    #[arg(long, allow_hyphen_values = true)]
    pub restart_planner_after: Option<f64>,
    /// Fault: SIGKILL the plant at this time (s).
    #[arg(long, allow_hyphen_values = true)]
    pub kill_plant_at: Option<f64>,
    /// Fault: start a new plant this long after the kill (s).
    #[arg(long, allow_hyphen_values = true)]
    pub restart_plant_after: Option<f64>,
    /// Fault: publish a weight update with a flipped bit at these times (s).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub corrupt_weights_at: Vec<f64>,
    /// Publish the model again as a valid hot swap at these times (s).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub swap_weights_at: Vec<f64>,
    /// Planner fault: NaN setpoints at these times (s).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub inject_nan_at: Vec<f64>,
    /// Planner fault: out-of-workspace setpoints from these times (s), 50 ms each.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub inject_outside_at: Vec<f64>,
    /// Who runs the control period: the host process, or the STM32F405
    /// controller image under QEMU, bridged over its serial link.
    #[arg(long, value_enum, default_value_t = ControllerKind::Host)]
    pub controller: ControllerKind,
    /// With --controller mcu: the image to run (default: built from this checkout).
    #[arg(long)]
    pub mcu_image: Option<PathBuf>,
    /// With --controller mcu: inject garbage bytes on the link every this many ms.
    #[arg(long)]
    pub link_garbage_every_ms: Option<u64>,
    /// With --controller mcu: kill the bridge at this time (s): the link
    /// goes silent and the chip must hold on its own.
    #[arg(long, allow_hyphen_values = true)]
    pub cut_link_at: Option<f64>,
    /// Start a new bridge this long after the cut (s).
    #[arg(long, allow_hyphen_values = true)]
    pub restore_link_after: Option<f64>,
    /// Do not write `run.mcap` (the Foxglove run log).
    #[arg(long)]
    pub no_mcap: bool,
    #[command(flatten)]
    pub runlog: super::plant::RunLogOpts,
}

impl SimArgs {
    /// The typed configuration these arguments describe.
    fn config(self) -> anyhow::Result<SimConfig> {
        let exe = std::env::current_exe().context("locating the tendril executable")?;
        let model = if self.quick_model {
            ModelSource::Quick
        } else {
            ModelSource::resolve(self.model, Path::new(TRAINED_MODEL))
        };
        let mut cfg = SimConfig::new(exe, self.robot, model, self.out);
        cfg.plant_robot = self.plant_robot;
        cfg.prefix = self.prefix;
        cfg.duration_s = self.duration;
        cfg.max_rms_mm = self.max_rms_mm;
        cfg.max_log_gb = self.max_log_gb;
        cfg.planner.shape = self.traj.shape()?;
        cfg.planner.step_shaping = self.traj.step_shaping();
        cfg.planner.dynamic_offset = self.traj.dynamic_offset == super::controller::OnOff::On;
        cfg.planner.learning = self.traj.learning();
        cfg.model_learning = self.model_learning == super::controller::OnOff::On;
        if let Some(path) = &self.turning_offset {
            cfg.planner.turning_offset =
                Some(crate::plan::TurningOffset::read(path).map_err(anyhow::Error::msg)?);
        }
        // The net alone is the net without feedback: no adaptation either.
        cfg.planner.adapt_stiffness = self.traj.adapt_stiffness == super::controller::OnOff::On
            && self.tuning.correction == super::controller::OnOff::On;
        cfg.planner.net_error_offset = self.net_error_offset == super::controller::OnOff::On
            && self.tuning.correction == super::controller::OnOff::On;
        let rate = match self.controller {
            ControllerKind::Host => self.tuning.rate_hz(),
            ControllerKind::Mcu => {
                let rate = self.tuning.mcu_rate_hz();
                crate::mcu::bridge::check_chip_rate(rate).map_err(anyhow::Error::msg)?;
                rate
            }
        };
        cfg.planner.rate_hz = self.traj.planner_rate.unwrap_or(rate);
        cfg.planner.settle_s = self.traj.settle;
        cfg.planner.inject = Injections {
            nan_at_s: self.inject_nan_at,
            outside_at_s: self.inject_outside_at,
            ..cfg.planner.inject
        };
        self.tuning.check()?;
        self.tuning.apply(&mut cfg.controller);
        cfg.controller.rate_hz = rate;
        cfg.controller.allow_robot_mismatch = self.allow_robot_mismatch;
        // Real-time scheduling is on by default under `sim` (`--realtime
        // off` to disable): it keeps the 1 kHz loop on time on a busy machine.
        cfg.realtime = self.tuning.realtime != Some(OnOff::Off);
        cfg.plant.params = self.plant.params()?;
        cfg.plant.params.model = self.plant_model;
        let plant_robot = cfg.plant_robot.as_ref().unwrap_or(&cfg.robot);
        // Refused here, before any process starts, if it does not fit.
        let robot = crate::robot::Robot::load(plant_robot)?;
        if let Some(reality) = &cfg.plant.params.reality {
            reality
                .real_robot(&robot)
                .map_err(|e| anyhow::anyhow!("--reality {}: {e}", reality.name))?;
        }
        // The robot the controller models (its gains scale to its mode).
        let model = match &cfg.plant_robot {
            Some(_) => crate::robot::Robot::load(&cfg.robot)?,
            None => robot.clone(),
        };
        if model.n_tendons() != robot.n_tendons() {
            anyhow::bail!(
                "--plant-robot has {} but --robot has {}",
                crate::robot::count(robot.n_tendons(), "tendon"),
                model.n_tendons()
            );
        }
        cfg.plant.spin = self.plant.spin;
        // The launcher puts the file in the run's directory (`run.mcap`).
        let mcap = (!self.no_mcap).then(|| PathBuf::from(crate::ipc::sim::RUN_MCAP));
        cfg.plant.runlog = self.runlog.config(mcap)?;
        cfg.pin = self.pin == OnOff::On;
        cfg.faults = SimFaults {
            kill_planner_at: self.kill_planner_at,
            restart_planner_after: self.restart_planner_after,
            kill_plant_at: self.kill_plant_at,
            restart_plant_after: self.restart_plant_after,
            corrupt_weights_at: self.corrupt_weights_at,
            swap_weights_at: self.swap_weights_at,
            cut_link_at: self.cut_link_at,
            restore_link_after: self.restore_link_after,
        };
        let chip_options = self.mcu_image.is_some()
            || self.link_garbage_every_ms.is_some()
            || self.cut_link_at.is_some();
        if self.controller == ControllerKind::Host && chip_options {
            anyhow::bail!(
                "--mcu-image, --link-garbage-every-ms and --cut-link-at need the chip in the loop: add --controller mcu"
            );
        }
        if let Some(ms) = self.link_garbage_every_ms {
            super::controller::check(
                "--link-garbage-every-ms",
                ms as f64,
                ms > 0,
                "a number of ms > 0",
            )?;
        }
        if self.controller == ControllerKind::Mcu {
            cfg.mcu = Some(crate::ipc::sim::SimMcu {
                image: self.mcu_image,
                garbage_every_ms: self.link_garbage_every_ms,
            });
        }
        let reality = cfg.plant.params.reality.as_ref().map_or_else(
            || {
                format!(
                    "motor τ {} ms, noise {} mm",
                    self.plant.motor_tau_ms(),
                    self.plant.noise_mm()
                )
            },
            |r| format!("reality {} ({})", r.name, r.summary()),
        );
        let reality = match &cfg.plant_robot {
            Some(p) => format!("plant robot {}, {reality}", p.display()),
            None => reality,
        };
        // The gain as given, and as the controller applies it.
        let scale = if cfg.controller.scale_gains_to_mode {
            crate::ipc::controller::correction::mode_scale(&model)
        } else {
            1.0
        };
        let ki = if scale < 1.0 && self.tuning.correction == OnOff::On {
            format!(
                "ki {}/s, applied {:.3}/s for the robot's first mode",
                self.tuning.ki,
                self.tuning.ki * scale
            )
        } else {
            format!("ki {}/s", self.tuning.ki)
        };
        cfg.label = format!(
            "controller {:?}, trajectory {:?}, correction {:?} ({ki}), lead {} ms, {reality}, \
             {} s, real-time {}, pinned {:?}",
            self.controller,
            self.traj.trajectory,
            self.tuning.correction,
            self.tuning.lead_ms,
            self.duration,
            if cfg.realtime { "on" } else { "off" },
            self.pin
        );
        Ok(cfg)
    }
}

/// Run `tendril sim`.
pub fn run(args: SimArgs) -> anyhow::Result<()> {
    super::common::refuse_stdout("--out", &args.out, "names a directory")?;
    let out = args.out.clone();
    let r = crate::ipc::sim::run(&args.config()?)?;
    let mm = |v: Option<f64>| v.map_or("–".into(), |v| format!("{v:.3}"));
    let (cycles, overruns) = r
        .controller
        .as_ref()
        .map_or((0, 0), |c| (c.cycles, c.overruns));
    // A closed stdout (`| head`) is not an error of the run.
    let _ = writeln!(
        std::io::stdout(),
        "tracking RMS {} mm, max {} mm (off the path: {} mm RMS) over {} samples; \
         controller {cycles} cycles, {overruns} overruns; IPC latency p50 {} µs",
        mm(r.rms_tracking_error_mm),
        mm(r.max_tracking_error_mm),
        mm(r.rms_path_error_mm),
        r.tracking_samples,
        r.ipc_latency_us
            .map_or("–".into(), |s| format!("{:.1}", s.p50)),
    );
    if !r.verdict.clean {
        anyhow::bail!(
            "the run did not finish cleanly: {} (report in {})",
            r.verdict.problems.join("; "),
            out.display()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cmd {
        #[command(flatten)]
        sim: SimArgs,
    }

    fn three_segment() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../robots/tdcr-3seg.toml")
    }

    fn config(args: &[&str]) -> SimConfig {
        let robot = three_segment();
        let mut all = vec!["sim", "--robot", robot.to_str().unwrap()];
        all.extend_from_slice(args);
        Cmd::try_parse_from(all).unwrap().sim.config().unwrap()
    }

    #[test]
    fn the_report_gives_the_gain_applied_to_a_softer_robot_and_off_turns_the_scaling_off() {
        let robot = crate::robot::Robot::load(&three_segment()).unwrap();
        let scale = crate::ipc::controller::correction::mode_scale(&robot);
        // The three-segment rod's first mode (≈ 1.07 Hz) is below 3.6 Hz.
        assert!(scale > 0.2 && scale < 0.4, "{scale}");
        let scaled = config(&["--ki", "12"]);
        assert!(scaled.controller.scale_gains_to_mode);
        let applied = format!("applied {:.3}/s", 12.0 * scale);
        assert!(scaled.label.contains(&applied), "{}", scaled.label);
        let given = config(&["--ki", "12", "--scale-gains-to-mode", "off"]);
        assert!(!given.controller.scale_gains_to_mode);
        assert!(given.label.contains("(ki 12/s)"), "{}", given.label);
    }

    /// Every default `tendril sim` shows is the library's own: the command
    /// line without flags gives `SimConfig::new`'s run (issue 44: no default
    /// written twice). The only differences are the command line's stated
    /// choices, listed here with why.
    #[test]
    fn a_sim_without_flags_is_the_configurations_defaults() {
        let seed = Path::new(env!("CARGO_MANIFEST_DIR")).join("../robots/seed-4t.toml");
        let cli = Cmd::try_parse_from(["sim", "--robot", seed.to_str().unwrap()])
            .unwrap()
            .sim
            .config()
            .unwrap();
        let lib = SimConfig::new(
            cli.exe.clone(),
            seed.clone(),
            cli.model.clone(),
            cli.out.clone(),
        );
        let (mut a, b) = (
            serde_json::to_value(&cli).unwrap(),
            serde_json::to_value(&lib).unwrap(),
        );
        // The label says what the command line asked for.
        a["label"] = b["label"].clone();
        // A run from the command line writes its run log (`--no-mcap`: none);
        // the library's runs (the main job's, robustness) ask for one.
        assert_eq!(a["plant"]["runlog"]["mcap"], "run.mcap");
        a["plant"]["runlog"]["mcap"] = b["plant"]["runlog"]["mcap"].clone();
        let mut differ = Vec::new();
        diff("", &a, &b, &mut differ);
        assert!(
            differ.is_empty(),
            "the command line's defaults differ from SimConfig::new: {differ:#?}"
        );
    }

    /// The paths where two JSON values differ, with both values.
    fn diff(at: &str, a: &serde_json::Value, b: &serde_json::Value, out: &mut Vec<String>) {
        match (a, b) {
            (serde_json::Value::Object(x), serde_json::Value::Object(y)) => {
                for k in x.keys().chain(y.keys().filter(|k| !x.contains_key(*k))) {
                    let null = serde_json::Value::Null;
                    diff(
                        &format!("{at}.{k}"),
                        x.get(k).unwrap_or(&null),
                        y.get(k).unwrap_or(&null),
                        out,
                    );
                }
            }
            _ if a != b => out.push(format!("{at}: command line {a}, library {b}")),
            _ => {}
        }
    }
}
