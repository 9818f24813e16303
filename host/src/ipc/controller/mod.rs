//! The controller process: the firmware's `no_std` control step (the very
//! function the MCU runs, integral correction included: one control law,
//! `docs/design.md` §5) inside an absolute-deadline loop at 1 kHz.
//!
//! Each period: sleep until `t0 + k·T`, take the newest setpoint, plant state
//! and weight update, run [`tendril_firmware::control::control_step`],
//! publish the tension command and raise the plant's event. The host side
//! adds only what the MCU gets from its hardware and board code: the clock,
//! the transport, and the *motor-lag lead*: the plant's motors trail their
//! command by a time constant, so the setpoint handed to the step is the
//! planner's pose advanced by `velocity · lead`; the measured tip handed to
//! the step's integral loop is advanced by the same amount, so the loop still
//! integrates `p_desired(t) − p_measured(t)` and does not fight the lead.

use std::borrow::Cow;
use std::path::PathBuf;

use serde::{Deserialize, Serialize};
use tendril_firmware::control::{ControlConfig, IntegralConfig, SafeHold};
use tendril_firmware::period::{event, Counters, Events, StuckConfig};
use tendril_firmware::swap::NetSlots;
use tendril_shared::messages::{
    command_status, setpoint_flags, Header, PlantState, Setpoint, TensionCommand, WeightUpdate,
    MAX_TENDONS, WEIGHT_UPDATE_CAPACITY,
};
use tendril_shared::{MAX_HIDDEN, MAX_WEIGHTS, POSE_DIM};

use super::clock::{now_ns, Tick, Ticker};
use super::process::{self, Process, Scheduling, Stepped};
use super::stats::{CsvLog, Histogram, Summary};
use super::transport::{self, Services};
use super::IpcError;
use crate::robot::Robot;

mod report;
mod task;

/// The integral correction's defaults: one set for every robot file, plant
/// and reality (docs/design.md §6.3 derives them from the loop: the first
/// bending mode, the motor lag and the tracker's delay).
pub mod correction {
    /// Integral gain, 1/s.
    pub const KI_PER_S: f64 = 4.0;
    /// Time constant of the error's low-pass filter, s (corner 2 Hz).
    pub const FILTER_TAU_S: f64 = 0.08;
    /// Bound on the correction per axis, m: above the model errors a real
    /// robot has (±10 % stiffness moves the default robot's sag by ≈ 3 mm).
    pub const LIMIT_M: f64 = 0.02;
    /// Integrate only while the tip error is at most this, m: a guard
    /// against a robot far off (the jumps of step targets are left out by
    /// [`SETTLE_AFTER_JUMP_S`]), above the largest model error a reality
    /// makes (≈ 9 mm on the two-segment robot with its tendons ±3° off).
    pub const WINDOW_M: f64 = 0.02;
    /// A setpoint that moves more than this in one period is a jump, m
    /// (a path at 0.2 Hz on a 15 mm radius moves 0.02 mm per ms).
    pub const JUMP_M: f64 = 1e-3;
    /// Tracker frames sampled within this after a jump are not integrated,
    /// s: the motors (20 ms) and the rod's swing settle first.
    pub const SETTLE_AFTER_JUMP_S: f64 = 0.3;
    /// Tracker frames are held back this long after a shaped move's last
    /// setpoint, s (`MoveQuiet`, `docs/design.md` §6.4). A shaped move
    /// leaves the rod still at its end (the shaper cancels the mode) and
    /// nothing of a jump's transient to wait out: what is left is the
    /// motors' lag (20 ms; the lead covers the move's velocity) and a
    /// tracker frame's latency (20 ms on the EM tracker), so five motor
    /// time constants. Until 2026-12-07 a move waited the jump's 0.3 s,
    /// and the model error at a new target stood uncorrected for 0.2 s
    /// longer (default robot 10 % off its file: each target settled
    /// 0.17–0.21 s later; BENCHMARKS.md, "The approach from rest, the
    /// first target, and the quiet after a shaped move").
    pub const QUIET_AFTER_MOVE_S: f64 = 0.1;
    /// No tracker frame for this long freezes the correction, s.
    pub const TRACKER_TIMEOUT_S: f64 = 0.25;
    /// Adaptation gain of the error map, 1/s.
    pub const MAP_GAIN_PER_S: f64 = 2.0;
    /// The map's normalisation length, m (a setpoint this far from where
    /// tracking began adapts the map at half the gain).
    pub const MAP_SCALE_M: f64 = 0.01;
    /// Bound on each entry of the map: the robot moves up to 50 % more or
    /// less than its model says.
    pub const MAP_LIMIT: f64 = 0.5;
    /// The first bending mode the gains are set for, Hz (the default
    /// robot's, from its robot file: [`crate::robot::first_bending_mode_rad_s`]).
    pub const REFERENCE_MODE_HZ: f64 = 3.6;

    /// The factor on the loop's bandwidth for `robot`: its first bending
    /// mode over [`REFERENCE_MODE_HZ`], at most 1 (a stiffer robot keeps the
    /// default gains: above the mode, the motor lag and the tracker's delay
    /// bound the loop, and they do not scale).
    pub fn mode_scale(robot: &crate::robot::Robot) -> f64 {
        let f1 = crate::robot::first_bending_mode_rad_s(robot) / std::f64::consts::TAU;
        (f1 / REFERENCE_MODE_HZ).min(1.0)
    }

    /// The integral's gain, error filter and error map as
    /// `task::period_config` scales them on `robot` ([`mode_scale`] when
    /// `scale_to_mode`): what the planner's learning and stiffness
    /// adaptation model, for the sim's launcher and a planner alone alike.
    pub fn applied(
        robot: &crate::robot::Robot,
        ki_per_s: f64,
        filter_tau_s: f64,
        map_gain_per_s: f64,
        scale_to_mode: bool,
    ) -> crate::plan::IntegralGains {
        let scale = if scale_to_mode {
            mode_scale(robot)
        } else {
            1.0
        };
        crate::plan::IntegralGains {
            ki_per_s: ki_per_s * scale,
            filter_tau_s: filter_tau_s / scale,
            // The map learns only where the integral does (ki > 0).
            map_gain_per_s: if ki_per_s > 0.0 {
                map_gain_per_s * scale
            } else {
                0.0
            },
            map_scale_m: MAP_SCALE_M,
        }
    }
}

pub use report::{
    ControllerStats, DetectedFault, FaultKind, FaultLog, LinkStats, FAULT_CAPACITY, FAULT_REPEAT_S,
};
pub use task::{
    feedback_in, period_config, setpoint_in, tip_shifted, with_dynamic_offset, Controller,
    HostPeriod, Inbox, MoveQuiet,
};

/// The double-buffered net the controller runs, of the one capacity in
/// `tendril_shared` (the trainer's cap, so every exported net fits).
pub type Slots = NetSlots<POSE_DIM, MAX_HIDDEN, MAX_TENDONS, MAX_WEIGHTS>;

/// Where the chip is: started by the bridge (an image) or already running
/// (a socket some launcher owns).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct McuOptions {
    /// A running chip's link socket; None: start QEMU with `image`.
    pub socket: Option<PathBuf>,
    /// The controller image (None: built by [`crate::mcu::locate_image`]).
    pub image: Option<PathBuf>,
    /// Inject a garbage burst on the link every this many ms (fault test).
    pub garbage_every_ms: Option<u64>,
}

/// Everything the controller process needs: written by a launcher as JSON
/// (`tendril controller --config FILE`) or built from the flags. Units are
/// in the field names.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ControllerConfig {
    /// Robot file (tension limits, tendon count).
    pub robot: PathBuf,
    /// The `.tnet` to start with.
    pub model: PathBuf,
    /// Run a net that records another robot than `robot` (with a warning)
    /// instead of refusing to start ([`crate::net::check_model_robot`]).
    pub allow_robot_mismatch: bool,
    /// Service-name prefix.
    pub prefix: String,
    /// Loop rate, Hz.
    pub rate_hz: f64,
    /// Spin this long before each deadline instead of sleeping, µs.
    pub spin_us: f64,
    /// Try `SCHED_FIFO`.
    pub realtime: bool,
    /// Pin to this CPU (see [`super::clock::PLANT_PRIORITY`] for why `sim`
    /// puts controller and plant on one CPU).
    pub cpu: Option<usize>,
    /// Setpoint silence, in periods, that trips the watchdog.
    pub watchdog_periods: f64,
    /// Integral gain of the firmware's correction loop, 1/s; 0 = IK alone.
    pub ki_per_s: f64,
    /// Bound on the integral correction per axis, m.
    pub correction_limit_m: f64,
    /// The correction integrates only while the lateral tip error is at
    /// most this, m (integral separation; see
    /// [`tendril_firmware::control::IntegralConfig`]).
    pub correction_window_m: f64,
    /// Time constant of the low-pass filter on the tip error before it is
    /// integrated, s (docs/design.md §6.3).
    pub correction_filter_tau_s: f64,
    /// Adaptation gain of the correction's error map, 1/s (0 = a constant
    /// correction only; docs/design.md §6.3).
    pub correction_map_gain_per_s: f64,
    /// Scale the correction's bandwidth (ki, the map's gain, the filter's
    /// corner) down for a robot whose first bending mode, from its robot
    /// file, is below the default robot's ([`correction::REFERENCE_MODE_HZ`]):
    /// the gains are the default robot's, the loop keeps its margins.
    pub scale_gains_to_mode: bool,
    /// No tracker frame for this long freezes the correction, s (longer
    /// than the slowest tracker's frame interval plus a dropout or two).
    pub tracker_timeout_s: f64,
    /// Motor-lag lead: advance the setpoint by velocity · lead, s.
    pub lead_s: f64,
    /// Slew-rate limit per tendon, N/s.
    pub slew_n_per_s: f64,
    /// Fraction of the net's input box a setpoint may lie outside.
    pub box_margin: f64,
    /// Stuck-motor detection.
    pub stuck_motor: StuckMotorDetection,
    /// Stop after this many seconds (None: until told).
    pub duration_s: Option<f64>,
    /// Stop with [`IpcError::PeersLost`] after this long with neither a
    /// setpoint nor a plant state, s (None: never).
    pub peer_timeout_s: Option<f64>,
    /// How long the peers may take to appear before the first message, s
    /// (None: [`super::PEER_START_GRACE_S`]; never shorter than the timeout).
    pub peer_start_grace_s: Option<f64>,
    /// Die with the launching process ([`super::die_with_parent`]).
    pub supervised: bool,
    /// Per-period CSV log.
    pub log: Option<PathBuf>,
    /// Statistics JSON written at exit.
    pub stats: Option<PathBuf>,
    /// The chip in the loop: the bridge runs instead of the host period
    /// ([`crate::mcu::bridge`]).
    pub mcu: Option<McuOptions>,
}

/// When a motor counts as stuck: its measured tension leaves the tension a
/// healthy motor would have (the command through a first-order lag of the
/// motor's time constant) by more than `tension_error_n` for `persist_s`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StuckMotorDetection {
    /// Detect at all.
    pub enabled: bool,
    /// Time constant of a healthy motor, s.
    pub motor_tau_s: f64,
    /// Measured − expected tension that counts as a fault, N.
    pub tension_error_n: f64,
    /// How long the error must last, s.
    pub persist_s: f64,
}

impl Default for StuckMotorDetection {
    fn default() -> Self {
        StuckMotorDetection {
            enabled: true,
            motor_tau_s: crate::plant::MOTOR_TAU_S,
            tension_error_n: 0.5,
            persist_s: 0.1,
        }
    }
}

impl Default for ControllerConfig {
    fn default() -> Self {
        ControllerConfig::new(crate::robot::DEFAULT_ROBOT.into(), "out/model.tnet".into())
    }
}

impl ControllerConfig {
    /// Defaults for `robot` and `model`: 1 kHz, watchdog 2.5 periods, IK
    /// alone (no correction), 21 ms lead for the default 20 ms motors,
    /// peers lost after 2 s of silence.
    pub fn new(robot: PathBuf, model: PathBuf) -> ControllerConfig {
        ControllerConfig {
            robot,
            model,
            allow_robot_mismatch: false,
            prefix: super::DEFAULT_PREFIX.into(),
            rate_hz: defaults::RATE_HZ,
            spin_us: defaults::SPIN_US,
            realtime: false,
            cpu: None,
            watchdog_periods: defaults::WATCHDOG_PERIODS,
            ki_per_s: 0.0,
            correction_limit_m: correction::LIMIT_M,
            correction_window_m: correction::WINDOW_M,
            correction_filter_tau_s: correction::FILTER_TAU_S,
            correction_map_gain_per_s: correction::MAP_GAIN_PER_S,
            scale_gains_to_mode: true,
            tracker_timeout_s: correction::TRACKER_TIMEOUT_S,
            lead_s: defaults::LEAD_S,
            slew_n_per_s: defaults::SLEW_N_PER_S,
            box_margin: 0.05,
            stuck_motor: StuckMotorDetection::default(),
            duration_s: None,
            peer_timeout_s: Some(2.0),
            peer_start_grace_s: None,
            supervised: false,
            log: None,
            stats: None,
            mcu: None,
        }
    }

    /// This controller's integral correction as the planner's learning and
    /// stiffness adaptation model it: its gain and error filter after the
    /// scaling to `robot`'s mode.
    pub fn integral_gains(&self, robot: &Robot) -> crate::plan::IntegralGains {
        correction::applied(
            robot,
            self.ki_per_s,
            self.correction_filter_tau_s,
            self.correction_map_gain_per_s,
            self.scale_gains_to_mode,
        )
    }
}

/// How long the loop below takes to put the planner's setpoint on the tip,
/// s, beyond what the controller's period makes up for: the period leads
/// each setpoint by its age (`tendril_firmware::period::SetpointIn::age_ns`),
/// so the host controller puts it on the tip in time at any rate (the tip
/// against the planner's path shifted in time, ideal plant, the default
/// circle: −0.2 ms at 1 kHz and at 100 Hz); the chip's command still
/// crosses the link back after its period (1.3–1.8 ms at 100 Hz, six runs). On a
/// circle an uncounted delay reads as stiffness: 1 ms is κ̂ ≈ 0.01.
pub fn loop_delay_s(chip: bool) -> f64 {
    match chip {
        true => CHIP_COMMAND_RETURN_S,
        false => 0.0,
    }
}

/// The chip's command's way back over the link, s (measured, above).
const CHIP_COMMAND_RETURN_S: f64 = 0.0014;

/// The controller's defaults, each written once: [`ControllerConfig::new`]
/// uses them and the command line's flags show them (a test checks that a
/// command line without flags gives `new`'s configuration).
pub mod defaults {
    /// Control rate, Hz.
    pub const RATE_HZ: f64 = 1000.0;
    /// Spin before each deadline, µs.
    pub const SPIN_US: f64 = 50.0;
    /// Setpoint silence that trips the safe hold, periods.
    pub const WATCHDOG_PERIODS: f64 = 2.5;
    /// Motor-lag lead, s: the plant's motor time constant (20 ms) plus half
    /// a 1 kHz period. (Was 21 ms here and 20.5 ms in the command line and
    /// the sim: the 20.5 ms every measurement used is kept.)
    pub const LEAD_S: f64 = 0.0205;
    /// Tension slew-rate limit, N/s.
    pub const SLEW_N_PER_S: f64 = 200.0;
}

/// Column names of the controller log.
pub fn log_header(n: usize) -> String {
    let mut cols = vec![
        "t_ns".to_string(),
        "lateness_ns".into(),
        "work_ns".into(),
        "status".into(),
        "sp_seq".into(),
        "state_seq".into(),
    ];
    cols.extend((0..n).map(|i| format!("cmd{i}")));
    cols.join(",")
}

/// Columns of the controller log before the tensions.
const LOG_FIXED: usize = 6;

/// Load a `.tnet` file into the controller's net buffers.
pub fn load_net(slots: &mut Slots, bytes: &[u8], tendons: usize) -> Result<(), IpcError> {
    slots
        .load(bytes, (POSE_DIM, tendons))
        .map_err(|e| IpcError::Other(e.to_string()))
}

/// Everything a controller process checks before it touches shared
/// memory, whichever backend runs the period (the host here, the chip
/// through [`crate::mcu::bridge`]): its launcher's death, the robot, the
/// net (read capped, decoded, made for this robot) and the whole
/// configuration. Returns the robot and the net's bytes.
pub fn load(cfg: &ControllerConfig) -> Result<(Robot, Vec<u8>), IpcError> {
    super::die_with_parent(cfg.supervised)?;
    let robot = Robot::load(&cfg.robot).map_err(|e| IpcError::Other(e.to_string()))?;
    let bytes =
        crate::fsutil::read_capped(&cfg.model, crate::net::MAX_TNET_BYTES).map_err(|source| {
            IpcError::Io {
                path: cfg.model.clone(),
                source,
            }
        })?;
    let (_, provenance) = crate::net::decode_with_provenance(&bytes)
        .map_err(|e| IpcError::Other(format!("{}: {e}", cfg.model.display())))?;
    crate::net::check_model_robot(
        &cfg.model,
        provenance.as_ref(),
        &robot,
        cfg.allow_robot_mismatch,
        crate::net::CLI_OVERRIDE,
    )
    .map_err(|e| IpcError::Other(e.to_string()))?;
    Controller::new(cfg, &robot, &bytes, 0)?;
    Ok((robot, bytes))
}

/// The skeleton's view of a controller's configuration (host period or
/// bridge: the same process, the same rules).
pub fn process(cfg: &ControllerConfig, scheduling: bool) -> Process<'_> {
    Process {
        name: "controller",
        prefix: &cfg.prefix,
        supervised: cfg.supervised,
        duration_s: cfg.duration_s,
        peer_timeout_s: cfg.peer_timeout_s,
        peer_start_grace_s: cfg.peer_start_grace_s,
        log: cfg.log.as_deref(),
        stats: cfg.stats.as_deref(),
        scheduling: scheduling.then_some(Scheduling {
            cpu: cfg.cpu,
            realtime: cfg.realtime,
            priority: super::clock::CONTROLLER_PRIORITY,
        }),
    }
}

/// What a controller's peers' silence is.
pub const SILENT_PEERS: &str = "no setpoint and no plant state";

/// Run the controller process with the period on the host until stopped
/// (or its peers are lost). With the chip in the loop the command line runs
/// [`crate::mcu::bridge::run`] instead: the controller knows no backend but
/// its own.
pub fn run(cfg: &ControllerConfig) -> Result<ControllerStats, IpcError> {
    if cfg.mcu.is_some() {
        return Err(IpcError::Config(
            "the chip's controller is the bridge (tendril controller --mcu), not the host period"
                .into(),
        ));
    }
    process::run(
        &process(cfg, true),
        || load(cfg),
        |(robot, bytes), services| HostTask::open(cfg, &robot, &bytes, services),
    )
}

/// The host period as a [`process::Task`]: each step sleeps to its
/// deadline, takes the newest messages, runs the control step, publishes
/// the command and raises the plant's event.
struct HostTask {
    ctl: Controller,
    ticker: Ticker,
    spin_ns: u64,
    overran: bool,
    cpu_wait: super::clock::CpuWait,
    n_tendons: usize,
    /// Setpoints and tracker frames come in the tracker's frame, the
    /// period works in the model's base frame (`docs/design.md` §2.4).
    to_base: crate::robot::RigidMap,
    setpoints: transport::Sub<Setpoint>,
    states: transport::Sub<PlantState>,
    weights: transport::Sub<WeightUpdate>,
    commands: transport::Pub<TensionCommand>,
    notifier: iceoryx2::port::notifier::Notifier<transport::Svc>,
}

impl HostTask {
    fn open(
        cfg: &ControllerConfig,
        robot: &Robot,
        bytes: &[u8],
        services: &Services,
    ) -> Result<HostTask, IpcError> {
        let period_ns = (1e9 / cfg.rate_hz).round() as u64;
        let start = now_ns() + period_ns;
        Ok(HostTask {
            ctl: Controller::new(cfg, robot, bytes, start)?,
            ticker: Ticker::new(start, period_ns),
            spin_ns: (cfg.spin_us * 1e3) as u64,
            overran: false,
            cpu_wait: super::clock::CpuWait::for_this_thread(),
            n_tendons: robot.n_tendons(),
            to_base: robot.base.to_base(),
            setpoints: transport::subscriber(&services.setpoint)?,
            states: transport::subscriber(&services.plant_state)?,
            weights: transport::subscriber(&services.weights)?,
            commands: transport::publisher(&services.tension_cmd)?,
            notifier: transport::notifier(&services.tension_cmd_event)?,
        })
    }
}

impl process::Task for HostTask {
    type Stats = ControllerStats;

    fn log_header(&self) -> String {
        log_header(self.n_tendons)
    }

    fn start_ns(&self) -> u64 {
        self.ticker.start_ns()
    }

    fn step(&mut self, log: &mut CsvLog) -> Result<Stepped, IpcError> {
        let period_ns = self.ctl.period_ns();
        let tick = self.ticker.wait(self.spin_ns);
        self.cpu_wait.after_wake(tick.skipped, period_ns);
        let t_wake = now_ns();
        // Newest messages since the last period.
        let mut superseded_nonfinite = 0;
        let (setpoint, n_sp) = transport::latest_inspecting(&self.setpoints, |s: &Setpoint| {
            if s.pose.iter().any(|v| !v.is_finite()) {
                superseded_nonfinite += 1;
            }
        })?;
        let (state, n_st) = transport::latest(&self.states)?;
        let setpoint = setpoint.map(|s| super::frame::setpoint(&self.to_base, &s));
        let state = state.map(|f| super::frame::state(&self.to_base, &f));
        let (update, _): (Option<WeightUpdate>, usize) = transport::latest(&self.weights)?;
        let inbox = Inbox {
            setpoint,
            setpoints: n_sp,
            superseded_nonfinite,
            state,
            states: n_st,
            weights: update.as_ref(),
        };
        let mut cmd = self.ctl.period(&tick, t_wake, self.overran, &inbox);
        cmd.header.stamp_ns = now_ns();
        transport::send(&self.commands, cmd)?;
        self.notifier
            .notify()
            .map_err(|e| IpcError::Send(format!("tension_cmd event: {e:?}")))?;
        let t_done = now_ns();
        self.overran = self.ticker.finish(t_done);
        log.row(self.ctl.finish(t_done - t_wake))?;
        Ok(Stepped {
            t_ns: t_done,
            heard: setpoint.is_some() || state.is_some(),
        })
    }

    fn silence(&self) -> &'static str {
        SILENT_PEERS
    }

    fn finish(self, _: &Result<(), IpcError>) -> Result<ControllerStats, IpcError> {
        let mut stats = self.ctl.stats(&self.ticker);
        stats.cpu_wait_ms = self.cpu_wait.total_ns().map(|ns| ns as f64 * 1e-6);
        stats.skipped_waiting_for_cpu = self.cpu_wait.skipped_waiting;
        Ok(stats)
    }
}
