//! `tendril-ros2`: thin shell over the library — parse the command line,
//! set up the console and signals, run, turn an error into one line on
//! stderr and a non-zero exit.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context as _;
use clap::{Args, Parser, Subcommand};
use tendril::cli::controller::{ControllerKind, LoopOpts, OnOff};
use tendril::cli::planner::TrajectoryOpts;
use tendril::cli::plant::PlantOpts;
use tendril::ipc::controller::ControllerConfig;
use tendril::ipc::planner::PlannerConfig;
use tendril::plan::LearningChoice;
use tendril::plant::{PlantParams, RobotModel};
use tendril::robot::Robot;
use tendril_ros2::drive::{self, DriveConfig};
use tendril_ros2::node::domain_from_env;
use tendril_ros2::plant::{self, PlantNodeConfig};

/// tendril on ROS 2: the plant as a robot on the graph of ROS_DOMAIN_ID
/// (topics, types, QoS and frames: docs/guide/ros2.md).
#[derive(Parser, Debug)]
#[command(name = "tendril-ros2", version)]
struct Cli {
    /// More output (-v: debug lines).
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    verbose: u8,
    /// Warnings and errors only.
    #[arg(short, long, global = true)]
    quiet: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Be the robot: take tension commands, publish tensions, the tracker's
    /// tip, the backbone, /tf and /diagnostics.
    Plant(PlantArgs),
    /// Drive a robot on ROS 2: tendril's planner and controller send tension
    /// commands and read the robot's joint states and the tracker's tip.
    Drive(Box<DriveArgs>),
}

#[derive(Args, Debug)]
#[command(mut_arg("rate", |a| a.help(format!(
    "Control rate, Hz [default: {DRIVE_RATE_HZ}: a ROS 2 robot's driver rarely takes more]"
))))]
#[command(mut_arg("realtime", |a| a.help(
    "Not for drive: it runs at normal priority beside DDS's threads (given `on`, refused)"
)))]
struct DriveArgs {
    /// Robot description file (the controller's model of the robot).
    #[arg(long, default_value = tendril::robot::DEFAULT_ROBOT)]
    robot: PathBuf,
    /// The IK net (.tnet) for this robot (`tendril train` makes one).
    #[arg(long)]
    model: PathBuf,
    /// Seconds on the path after the settle.
    #[arg(long, default_value_t = 10.0)]
    duration: f64,
    #[command(flatten)]
    path: TrajectoryOpts,
    /// The controller's options, as `tendril controller`'s (--rate: 200 Hz
    /// here, a ROS 2 robot's driver rarely takes more).
    #[command(flatten)]
    control: LoopOpts,
    /// The node's namespace: its relative topics live under it.
    #[arg(long, default_value = "/")]
    namespace: String,
    /// Who runs the control period: the host (in this process), or the
    /// STM32F405 controller image under QEMU behind its serial link, as in
    /// `tendril sim --controller mcu` (--rate then 100 Hz by default).
    #[arg(long, value_enum, default_value_t = ControllerKind::Host)]
    controller: ControllerKind,
    /// With --controller mcu: the image to run (default: built from this checkout).
    #[arg(long)]
    mcu_image: Option<PathBuf>,
    /// Statistics JSON written at exit (tracking error, holds, feedback).
    #[arg(long)]
    stats: Option<PathBuf>,
    /// How long to wait for the robot's first joint state and tip pose
    /// (discovery, then its first answer to the rest tensions), s; a robot
    /// that falls silent on the path is held this long before the drive
    /// gives up (exit status 1).
    #[arg(long, default_value_t = 15.0)]
    wait_for_robot: f64,
    /// Bound on the tracking error, mm: the RMS on a smooth path, the worst
    /// steady state on steps and targets; a run above it, or one whose loop
    /// oscillates or drifts, is not clean (exit status 1, the reasons said
    /// and in --stats' verdicts), as in `tendril sim`.
    #[arg(long, default_value_t = tendril::ipc::sim::DEFAULT_MAX_RMS_MM)]
    max_rms_mm: f64,
    /// Follow targets from the topics target_point (PointStamped) and
    /// target_pose (PoseStamped; its position) in the tracker's frame
    /// instead of --trajectory: each is reached by a shaped move and held;
    /// one out of reach, not finite or in another frame is refused.
    #[arg(long)]
    target_topic: bool,
    /// The run's MCAP file (tensions, the tracker's tip against the
    /// setpoint, status; open it in Foxglove, or `tendril plot`).
    #[arg(long)]
    mcap: Option<PathBuf>,
}

/// `drive`'s control rate without `--rate`, Hz.
const DRIVE_RATE_HZ: f64 = 200.0;

impl DriveArgs {
    fn config(self) -> anyhow::Result<DriveConfig> {
        if self.path.learn == OnOff::On {
            anyhow::bail!(
                "--learn on: learning for repeated paths runs in `tendril sim`'s planner, not yet in drive"
            );
        }
        if self.control.realtime == Some(OnOff::On) {
            anyhow::bail!(
                "--realtime on: drive runs at normal priority (its period shares the CPU with \
                 DDS's threads, which a SCHED_FIFO loop would starve); leave it out"
            );
        }
        let mut controller = ControllerConfig::new(self.robot.clone(), self.model);
        self.control.apply(&mut controller);
        match self.controller {
            ControllerKind::Host => {
                if self.mcu_image.is_some() {
                    anyhow::bail!("--mcu-image needs the chip in the loop: add --controller mcu");
                }
                if self.control.rate.is_none() {
                    controller.rate_hz = DRIVE_RATE_HZ;
                }
            }
            ControllerKind::Mcu => {
                controller.rate_hz = self.control.mcu_rate_hz();
                tendril::mcu::bridge::check_chip_rate(controller.rate_hz)
                    .map_err(anyhow::Error::msg)?;
                controller.mcu = Some(tendril::ipc::controller::McuOptions {
                    socket: None,
                    image: self.mcu_image,
                    garbage_every_ms: None,
                });
            }
        }
        let planner = PlannerConfig {
            shape: self.path.shape()?,
            settle_s: self.path.settle,
            step_shaping: self.path.step_shaping(),
            start_from_rest: true,
            dynamic_offset: self.path.dynamic_offset == OnOff::On,
            learning: LearningChoice::Off,
            // Targets from a topic have no path to fit along.
            adapt_stiffness: self.path.adapt_stiffness == OnOff::On && !self.target_topic,
            // The net's error along the planned path, as `tendril sim` takes it out.
            net_error_offset: !self.target_topic,
            model: Some(controller.model.clone()),
            loop_delay_s: Some(tendril::ipc::controller::loop_delay_s(
                controller.mcu.is_some(),
            )),
            rate_hz: controller.rate_hz,
            ..PlannerConfig::new(self.robot, self.path.shape()?)
        };
        Ok(DriveConfig {
            planner,
            controller,
            duration_s: self.duration,
            domain: domain_from_env()?,
            namespace: self.namespace,
            stats: self.stats,
            wait_for_robot_s: self.wait_for_robot,
            target_topic: self.target_topic,
            max_rms_mm: self.max_rms_mm,
            runlog: tendril::runlog::RunLogConfig {
                mcap: self.mcap,
                ..Default::default()
            },
        })
    }
}

#[derive(Args, Debug)]
struct PlantArgs {
    /// Robot description file.
    #[arg(long, default_value = tendril::robot::DEFAULT_ROBOT)]
    robot: PathBuf,
    /// How the real robot differs from its file and how it is seen: a
    /// reality file or a built-in's name (as `tendril plant --reality`).
    #[arg(long)]
    reality: Option<PathBuf>,
    /// Robot model: quasi-static (statics each step) or dynamic (the rod
    /// with inertia and damping).
    #[arg(long = "model", value_enum, default_value_t = PlantParams::default().model)]
    robot_model: RobotModel,
    /// Motor time constant, ms [default: 20; a --reality with [motors] sets its own].
    #[arg(long)]
    motor_tau_ms: Option<f64>,
    /// Tip tracker noise (standard deviation), mm [default: 0.02; a
    /// --reality with a [tracker] sets its own].
    #[arg(long)]
    noise_mm: Option<f64>,
    /// Seed of the tracker's noise.
    #[arg(long, default_value_t = PlantParams::default().seed)]
    seed: u64,
    /// Plant steps and joint states per second.
    #[arg(long, default_value_t = 200.0)]
    rate: f64,
    /// Backbone and /tf messages per second.
    #[arg(long, default_value_t = 30.0)]
    scene_hz: f64,
    /// Points along the published backbone.
    #[arg(long, default_value_t = 32)]
    backbone_points: usize,
    /// Stop after this many seconds (default: until SIGINT or SIGTERM).
    #[arg(long)]
    duration: Option<f64>,
    /// The node's namespace: its relative topics live under it.
    #[arg(long, default_value = "/")]
    namespace: String,
    /// Statistics JSON written at exit (commands taken and refused, steps).
    #[arg(long)]
    stats: Option<PathBuf>,
}

impl PlantArgs {
    fn config(self) -> anyhow::Result<PlantNodeConfig> {
        let robot = Robot::load(&self.robot)?;
        // The same flags as `tendril plant`, checked by the same code.
        let opts = PlantOpts {
            motor_tau_ms: self.motor_tau_ms,
            compliance_tau_ms: PlantParams::default().compliance_tau_s * 1e3,
            noise_mm: self.noise_mm,
            seed: self.seed,
            statics_steps: PlantParams::default().statics_steps,
            spin: false,
            stuck: None,
            drop: None,
            delay: None,
            reality: self.reality,
        };
        Ok(PlantNodeConfig {
            robot,
            params: PlantParams {
                model: self.robot_model,
                ..opts.params()?
            },
            rate_hz: self.rate,
            scene_hz: self.scene_hz,
            backbone_points: self.backbone_points,
            duration_s: self.duration,
            domain: domain_from_env()?,
            namespace: self.namespace,
            stats: self.stats,
        })
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Drive(args) => {
            let cfg = (*args).config()?;
            log::info!(
                "tendril-ros2 drive: {} at {} Hz on ROS domain {}, namespace {}",
                cfg.controller.robot.display(),
                cfg.controller.rate_hz,
                cfg.domain,
                cfg.namespace
            );
            let s =
                drive::run(&cfg, tendril::interrupt::stop_flag()).context("tendril-ros2 drive")?;
            let rms = s
                .tracking_rms_mm
                .map_or("no tip on the path".to_string(), |r| {
                    format!("{r:.3} mm RMS")
                });
            log::info!(
                "tendril-ros2 drive: {} periods, {} holds, {} overruns; tracking {rms} over {} frames",
                s.periods,
                s.hold_periods,
                s.overruns,
                s.tracked_frames
            );
            if s.tracked_frames == 0 {
                anyhow::bail!(
                    "no tip pose on the path: is a robot publishing joint_states and tip_pose on this domain?"
                );
            }
            let problems = s.verdicts.map(|v| v.problems).unwrap_or_default();
            if !problems.is_empty() {
                anyhow::bail!("the run is not clean: {}", problems.join("; "));
            }
            Ok(())
        }
        Command::Plant(args) => {
            let cfg = args.config()?;
            cfg.validate()?;
            log::info!(
                "tendril-ros2 plant: {} ({} tendons) on ROS domain {}, namespace {}, {} Hz",
                cfg.robot.name,
                cfg.robot.n_tendons(),
                cfg.domain,
                cfg.namespace,
                cfg.rate_hz
            );
            let stats =
                plant::run(&cfg, tendril::interrupt::stop_flag()).context("tendril-ros2 plant")?;
            let refused = stats.refused_length + stats.refused_not_finite + stats.refused_malformed;
            log::info!(
                "tendril-ros2 plant: {} steps, {} commands applied ({} saturated), {} refused, {} overruns",
                stats.steps,
                stats.commands,
                stats.saturated,
                refused,
                stats.overruns
            );
            Ok(())
        }
    }
}

/// The console: RUST_LOG wins; else this crate and tendril at info (-q:
/// warn, -v: debug) and DDS silent (RustDDS logs, at error level, every
/// sample in flight when its participant closes; what matters reaches
/// tendril as an error value).
fn init_console(cli: &Cli) {
    use std::io::Write;
    let level = match (cli.quiet, cli.verbose) {
        (true, _) => log::LevelFilter::Warn,
        (false, 0) => log::LevelFilter::Info,
        (false, _) => log::LevelFilter::Debug,
    };
    let mut b = env_logger::Builder::new();
    match std::env::var("RUST_LOG") {
        Ok(spec) if !spec.is_empty() => {
            b.parse_filters(&spec);
        }
        _ => {
            b.filter_level(log::LevelFilter::Warn)
                .filter_module("rustdds", log::LevelFilter::Off)
                .filter_module("ros2_client", log::LevelFilter::Off)
                .filter_module("tendril", level)
                .filter_module("tendril_ros2", level);
        }
    }
    b.format(|buf, r| match r.level() {
        log::Level::Info => writeln!(buf, "{}", r.args()),
        l => writeln!(buf, "{}: {}", l.as_str().to_lowercase(), r.args()),
    })
    .init();
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    init_console(&cli);
    if let Err(e) = tendril::interrupt::install(Some(tendril::fsutil::exit_hooks())) {
        eprintln!("tendril-ros2: error: signal handling: {e}");
        return ExitCode::FAILURE;
    }
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if tendril::interrupt::stop_requested() => {
            let by = tendril::interrupt::stopped_by().unwrap_or("a stop request");
            eprintln!(
                "tendril-ros2: interrupted by {by}: {}",
                tendril::cli::console::error_line(&e)
            );
            ExitCode::from(tendril::interrupt::EXIT_INTERRUPTED)
        }
        Err(e) => {
            eprintln!(
                "tendril-ros2: error: {}",
                tendril::cli::console::error_line(&e)
            );
            ExitCode::FAILURE
        }
    }
}
