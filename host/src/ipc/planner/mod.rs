//! The planner process: streams setpoints (pose + velocity) along a
//! trajectory at a fixed rate with absolute deadlines, after an initial
//! hold at the trajectory's first pose so the robot can settle there.
//! It can also inject bad setpoints (NaN, out of workspace) for the HIL tests.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};
use tendril_shared::messages::{setpoint_flags, Header, PlantState, Setpoint, TensionCommand};

use super::clock::{now_ns, Ticker};
use super::following::Following;
use super::process::{self, Process, Scheduling, Stepped};
use super::stats::CsvLog;
use super::transport::{self, Services};
use super::IpcError;

use crate::plan::learning::PassOutcome;
use crate::plan::{
    along_axes, Desired, Learner, LearningChoice, Motion, PathShape, ShapingChoice,
    StiffnessAdaptation,
};

mod planned;
pub use planned::{check_turning_offset, plan, setpoint_for, Planned, MAX_TURNING_OFFSET_M};

/// Bad setpoints to send instead of the trajectory's, each for one message.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Injections {
    /// Times (s from start) at which to send a pose with a NaN.
    pub nan_at_s: Vec<f64>,
    /// Times (s) at which to send a pose far outside the workspace, for
    /// `outside_for_s` seconds each.
    pub outside_at_s: Vec<f64>,
    /// Duration of each out-of-workspace burst, s.
    pub outside_for_s: f64,
}

impl Default for Injections {
    fn default() -> Self {
        Injections {
            nan_at_s: Vec::new(),
            outside_at_s: Vec::new(),
            outside_for_s: defaults::OUTSIDE_FOR_S,
        }
    }
}

/// The planner's defaults, each written once: [`PlannerConfig::new`] uses
/// them and the command line's flags show them.
pub mod defaults {
    /// Setpoint rate, Hz (the controller's: one setpoint a period).
    pub const RATE_HZ: f64 = crate::ipc::controller::defaults::RATE_HZ;
    /// The hold at the first pose, s.
    pub const SETTLE_S: f64 = 2.0;
    /// Length of an injected out-of-workspace burst, s.
    pub const OUTSIDE_FOR_S: f64 = 0.05;
}

/// Everything the planner process needs: written by a launcher as JSON
/// (`tendril planner --config FILE`) or built from the flags.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlannerConfig {
    /// Robot file (to lift lateral targets to reachable poses).
    pub robot: PathBuf,
    /// Service-name prefix.
    pub prefix: String,
    /// What to follow.
    pub shape: PathShape,
    /// Setpoint rate, Hz.
    pub rate_hz: f64,
    /// Initial hold at the first pose, s.
    pub settle_s: f64,
    /// Stop after this many seconds (None: until told).
    pub duration_s: Option<f64>,
    /// How steps move from target to target (`docs/design.md` §6.4).
    #[serde(default)]
    pub step_shaping: ShapingChoice,
    /// The robot starts at rest (its pose at the lowest tensions): the
    /// settle hold begins with a shaped move from there to the first pose,
    /// so the rod does not ring when the path starts. Off: the first pose
    /// from the first setpoint (a planner restarted on a moving robot).
    #[serde(default)]
    pub start_from_rest: bool,
    /// Send the offset the rod's first mode needs on top of each pose (the
    /// modal inverse of the shaping's mode, `docs/design.md` §6.4); only
    /// with a shaping.
    #[serde(default)]
    pub dynamic_offset: bool,
    /// Learn the offset that puts the tip on a repeated path, pass after
    /// pass, from the tracker's frames (`docs/design.md` §6.4; sent with
    /// the dynamic offset).
    #[serde(default)]
    pub learning: LearningChoice,
    /// Estimate, from the tracker's frames, how much stiffer or softer the
    /// backbone is than its file, and send the pose offset that makes up for
    /// it along the whole path (`docs/design.md` §6.5; sent with the
    /// dynamic offset).
    #[serde(default)]
    pub adapt_stiffness: bool,
    /// Take the controller's net's own quasi-static error along the path
    /// out before the loop sees it: the offset that puts the net's tip on
    /// every pose of the path, from the robot's exact statics
    /// (`docs/design.md` §6.4; sent with the dynamic offset). Needs
    /// `model`.
    #[serde(default)]
    pub net_error_offset: bool,
    /// The net the controller runs (`.tnet`), for `net_error_offset`.
    #[serde(default)]
    pub model: Option<PathBuf>,
    /// The offset learned on the model for a circle, sent on the path
    /// (`docs/design.md` §6.4, "Learning on the model"; `tendril sim
    /// --model-learning on` works it out before the run).
    #[serde(default)]
    pub turning_offset: Option<crate::plan::TurningOffset>,
    /// The controller's integral gains (after its scaling to the mode) that
    /// the stiffness adaptation's loop model assumes (None: the
    /// controller's defaults for the robot; a launcher that knows the
    /// controller's own passes them).
    #[serde(default)]
    pub controller_gains: Option<crate::plan::IntegralGains>,
    /// How long the loop below takes to put a setpoint on the tip, s: what
    /// the stiffness adaptation matches the tracker's frames against (None:
    /// the host controller's, [`super::controller::loop_delay_s`]).
    #[serde(default)]
    pub loop_delay_s: Option<f64>,
    /// Bad setpoints to inject.
    #[serde(default)]
    pub inject: Injections,
    /// Stop with [`IpcError::PeersLost`] after this long without a tension
    /// command from a controller, s (None: never).
    #[serde(default)]
    pub peer_timeout_s: Option<f64>,
    /// How long the peers may take to appear before the first message, s
    /// (None: [`super::PEER_START_GRACE_S`]; never shorter than the timeout).
    #[serde(default)]
    pub peer_start_grace_s: Option<f64>,
    /// Die with the launching process ([`super::die_with_parent`]).
    #[serde(default)]
    pub supervised: bool,
    /// Per-setpoint CSV log.
    #[serde(default)]
    pub log: Option<PathBuf>,
    /// Switch to SCHED_FIFO after the (CPU-heavy) trajectory set-up.
    #[serde(default)]
    pub realtime: bool,
    /// Pin to this CPU.
    #[serde(default)]
    pub cpu: Option<usize>,
}

impl PlannerConfig {
    /// Defaults for following `shape` on `robot`: [`defaults`], steps
    /// shaped for the rod's first mode, no dynamic offset or learning, no
    /// injected faults, peers lost after 2 s of silence.
    pub fn new(robot: PathBuf, shape: PathShape) -> PlannerConfig {
        PlannerConfig {
            robot,
            prefix: super::DEFAULT_PREFIX.into(),
            shape,
            rate_hz: defaults::RATE_HZ,
            settle_s: defaults::SETTLE_S,
            duration_s: None,
            step_shaping: ShapingChoice::default(),
            start_from_rest: false,
            dynamic_offset: false,
            learning: LearningChoice::default(),
            adapt_stiffness: false,
            net_error_offset: false,
            model: None,
            turning_offset: None,
            controller_gains: None,
            loop_delay_s: None,
            inject: Injections::default(),
            peer_timeout_s: Some(2.0),
            peer_start_grace_s: None,
            supervised: false,
            log: None,
            realtime: false,
            cpu: None,
        }
    }
}

/// Flag bit in the planner log (not on the wire): this message was an
/// injected bad setpoint; the logged pose is the trajectory's.
pub const LOG_INJECTED: u32 = 1 << 31;

/// Flag bit in the planner log: learning for repeated paths had stopped on
/// a growing error (the fault event; the best pass's offset is held).
pub const LOG_LEARNING_STOPPED: u32 = 1 << 30;

/// Flag bit in the planner log: a learned offset was sent.
pub const LOG_LEARNED: u32 = 1 << 29;

/// The leading column names of the planner log (then [`log_header`]'s
/// feed-forward columns).
pub const LOG_HEADER: &str = "t_ns,seq,flags,px,py,pz,qw,qx,qy,qz";

/// Column names of the planner log for a robot with `tendons` tendons: the
/// setpoint, then the exact IK's feed-forward tensions `ff0..` (N) for it and
/// `ff_miss_m`, the distance from the setpoint's position to the tip those
/// tensions give (0 on the reachable path; > 0 for a pose-table row out of
/// reach, whose reference is the closest reachable pose; NaN without one),
/// then `stiffness`, the stiffness adaptation's κ̂ applied (NaN when off).
pub fn log_header(tendons: usize) -> String {
    let mut header = LOG_HEADER.to_string();
    for i in 0..tendons {
        header.push_str(&format!(",ff{i}"));
    }
    header.push_str(",ff_miss_m,stiffness");
    header
}

/// Run the planner process until stopped or done; returns how many
/// setpoints it sent.
pub fn run(cfg: &PlannerConfig) -> Result<u64, IpcError> {
    let process = Process {
        name: "planner",
        prefix: &cfg.prefix,
        supervised: cfg.supervised,
        duration_s: cfg.duration_s,
        peer_timeout_s: cfg.peer_timeout_s,
        peer_start_grace_s: cfg.peer_start_grace_s,
        log: cfg.log.as_deref(),
        stats: None,
        scheduling: Some(Scheduling {
            cpu: cfg.cpu,
            realtime: cfg.realtime,
            priority: super::clock::PLANNER_PRIORITY,
        }),
    };
    process::run(
        &process,
        || plan(cfg),
        |planned, services| PlannerTask::open(cfg, planned, services),
    )
}

/// The planner as a [`process::Task`]: each step sleeps to its deadline and
/// sends the setpoint for that time (with the learned offset and any
/// injected fault), and learns from the tracker's newest frame.
struct PlannerTask<'a> {
    inject: &'a Injections,
    rate_hz: f64,
    motion: Motion,
    learner: Option<Learner>,
    publisher: transport::Pub<Setpoint>,
    /// The model's base frame → the tracker's, for what is published and
    /// logged, and back, for the frames the learning reads.
    to_tracker: crate::robot::RigidMap,
    to_base: crate::robot::RigidMap,
    /// The controller's commands say it is alive (the peers-lost rule)
    /// and whether it follows the setpoints (the stiffness adaptation).
    commands: transport::Sub<TensionCommand>,
    /// Whether the loop follows, from the commands heard.
    following: Following,
    /// The stiffness adaptation, when asked for (`docs/design.md` §6.5).
    stiffness: Option<StiffnessAdaptation>,
    /// The tracker's frames, for the learning and the stiffness adaptation.
    states: Option<transport::Sub<PlantState>>,
    last_frame: u32,
    feedforward: Vec<f64>,
    row: Vec<f64>,
    ticker: Ticker,
    start: u64,
    seq: u64,
}

impl<'a> PlannerTask<'a> {
    fn open(
        cfg: &'a PlannerConfig,
        planned: Planned,
        services: &Services,
    ) -> Result<PlannerTask<'a>, IpcError> {
        let tendons = planned.motion.trajectory().tendons();
        let period_ns = (1e9 / cfg.rate_hz).round() as u64;
        let start = now_ns();
        Ok(PlannerTask {
            inject: &cfg.inject,
            rate_hz: cfg.rate_hz,
            states: match planned.learner.is_some() || planned.stiffness.is_some() {
                true => Some(transport::subscriber(&services.plant_state)?),
                false => None,
            },
            stiffness: planned.stiffness,
            motion: planned.motion,
            learner: planned.learner,
            publisher: transport::publisher(&services.setpoint)?,
            to_tracker: planned.base.to_tracker(),
            to_base: planned.base.to_base(),
            commands: transport::subscriber(&services.tension_cmd)?,
            following: Following::default(),
            last_frame: 0,
            feedforward: Vec::with_capacity(tendons),
            row: Vec::with_capacity(10 + tendons + 2),
            ticker: Ticker::new(start, period_ns),
            start,
            seq: 0,
        })
    }

    /// The tracker's newest frame in the model's base frame, once.
    fn new_frame(&mut self) -> Result<Option<PlantState>, IpcError> {
        let Some(states) = self.states.as_ref() else {
            return Ok(None);
        };
        let (state, _): (Option<PlantState>, usize) = transport::latest(states)?;
        Ok(state
            .filter(|s| s.tip_seq != 0 && s.tip_seq != self.last_frame)
            .map(|state| {
                self.last_frame = state.tip_seq;
                super::frame::state(&self.to_base, &state)
            }))
    }

    /// Learn from `frame`, close a pass when the path wraps; returns the
    /// offset learned for `t_path` (s on the path) and the log's learning
    /// flags.
    fn learn(
        &mut self,
        frame: Option<&PlantState>,
        t_path: f64,
        on_path: bool,
    ) -> (Option<[f64; 3]>, u32) {
        let Some(learner) = self.learner.as_mut() else {
            return (None, 0);
        };
        let mut log_flags = 0;
        if let Some(state) = frame {
            learn_from(learner, &self.motion, state, self.start);
        }
        if let Some(outcome) = learner.advance(t_path) {
            say(&outcome);
        }
        if learner.stopped() {
            log_flags |= LOG_LEARNING_STOPPED;
        }
        let learned = on_path.then(|| learner.offset(t_path));
        if learned.is_some() {
            log_flags |= LOG_LEARNED;
        }
        (learned, log_flags)
    }

    /// The stiffness adaptation's tick at `t` with `frame`, the loop below
    /// `following` the setpoints or not: its offset (None when off).
    fn adapt(
        &mut self,
        frame: Option<&PlantState>,
        t: f64,
        desired: &Desired,
        following: bool,
    ) -> Option<[f64; 3]> {
        let adaptation = self.stiffness.as_mut()?;
        if let Some(state) = frame {
            let tip = [0, 1, 2].map(|k| state.tip_pose[k] as f64);
            adaptation.frame(&self.motion, frame_time(state, self.start), tip);
        }
        Some(adaptation.step(self.motion.trajectory(), t, desired, following))
    }
}

impl process::Task for PlannerTask<'_> {
    type Stats = u64;

    fn log_header(&self) -> String {
        log_header(self.motion.trajectory().tendons())
    }

    fn start_ns(&self) -> u64 {
        self.start
    }

    fn step(&mut self, log: &mut CsvLog) -> Result<Stepped, IpcError> {
        let tick = self.ticker.wait(0);
        let t = (tick.deadline_ns - self.start) as f64 * 1e-9;
        let desired = self.motion.at(t);
        let miss = self
            .motion
            .trajectory()
            .feedforward(desired.t_path, &mut self.feedforward);
        let frame = self.new_frame()?;
        let (learned, log_flags) = self.learn(
            frame.as_ref(),
            desired.t_path,
            !desired.holding && !desired.moving,
        );
        let (command, _): (Option<TensionCommand>, usize) = transport::latest(&self.commands)?;
        if let Some(c) = &command {
            self.following.heard(tick.deadline_ns, c.status);
        }
        let following = self.following.follows(tick.deadline_ns);
        let adapted = self.adapt(frame.as_ref(), t, &desired, following);
        let offset = match (learned, adapted) {
            (None, None) => None,
            (a, b) => {
                let (a, b) = (a.unwrap_or_default(), b.unwrap_or_default());
                Some(std::array::from_fn(|k| a[k] + b[k]))
            }
        };
        let mut msg = setpoint_for(&self.motion, t, &desired, offset);
        let clean = msg.pose;
        let mut injected = false;
        if self
            .inject
            .nan_at_s
            .iter()
            .any(|&a| t >= a && t < a + 1.0 / self.rate_hz)
        {
            msg.pose[0] = f32::NAN;
            injected = true;
            log::warn!("planner: injecting a NaN setpoint at {t:.3} s");
        }
        if self
            .inject
            .outside_at_s
            .iter()
            .any(|&a| t >= a && t < a + self.inject.outside_for_s)
        {
            // 1 m sideways: far outside any 0.4 m robot's reach.
            msg.pose[0] += 1.0;
            injected = true;
            msg.velocity = [0.0; 7];
            msg.flags &= !(setpoint_flags::HAS_VELOCITY
                | setpoint_flags::HAS_TANGENT
                | setpoint_flags::HAS_DYNAMIC_OFFSET);
        }
        self.seq += 1;
        let stamp = now_ns();
        msg.header = Header {
            seq: self.seq,
            stamp_ns: stamp,
        };
        transport::send(
            &self.publisher,
            super::frame::setpoint(&self.to_tracker, &msg),
        )?;
        // The log keeps the trajectory's pose (what the robot should do,
        // in the tracker's frame as the plant's log has the tip) and marks
        // injected messages.
        let clean = self.to_tracker.pose(clean.map(f64::from));
        let log_flags = log_flags | msg.flags | if injected { LOG_INJECTED } else { 0 };
        let row = &mut self.row;
        row.clear();
        row.extend([stamp as f64, self.seq as f64, log_flags as f64]);
        row.extend(clean);
        row.extend_from_slice(&self.feedforward);
        row.push(miss);
        row.push(self.stiffness.as_ref().map_or(f64::NAN, |s| s.applied()));
        log.row(row)?;
        Ok(Stepped {
            t_ns: tick.deadline_ns,
            heard: command.is_some(),
        })
    }

    fn silence(&self) -> &'static str {
        "no tension command from a controller"
    }

    fn finish(self, _: &Result<(), IpcError>) -> Result<u64, IpcError> {
        Ok(self.seq)
    }
}

/// One tracker frame to the learner: the error of the tip against the
/// path where the planner was when the frame was taken, along the path's
/// tangent axes. Frames of holds and shaped moves are not the path's.
fn learn_from(learner: &mut Learner, motion: &Motion, state: &PlantState, start_ns: u64) {
    let t = frame_time(state, start_ns);
    let then = motion.at(t);
    if then.holding || then.moving {
        return;
    }
    let p = &then.point.pose;
    let error = [0, 1, 2].map(|k| p[k] - state.tip_pose[k] as f64);
    learner.measure(then.t_path, along_axes(&then.point, error));
}

/// When a tracker frame was measured, s on the planner's clock (which
/// started at `start_ns`): its stamp, so the tracker's latency costs nothing.
fn frame_time(state: &PlantState, start_ns: u64) -> f64 {
    (state.tip_stamp_ns as i128 - start_ns as i128) as f64 * 1e-9
}

/// A pass's outcome on the console: the stop is a fault event.
fn say(outcome: &PassOutcome) {
    match *outcome {
        PassOutcome::Learned { pass, rms_m } => {
            log::debug!("planner: pass {pass} learned, error {:.3} mm RMS", rms_m * 1e3)
        }
        PassOutcome::Held { pass, rms_m } => {
            log::debug!("planner: pass {pass}, offset held, error {:.3} mm RMS", rms_m * 1e3)
        }
        PassOutcome::TooFewFrames { pass } => {
            log::warn!("planner: pass {pass}: too few tracker frames to learn from")
        }
        PassOutcome::Stopped {
            pass,
            best_rms_m,
            rms_m,
        } => log::warn!(
            "planner: learning stopped: the error grew to {:.3} mm RMS in pass {pass} (best {:.3} mm); the best pass's offset is held",
            rms_m * 1e3,
            best_rms_m * 1e3
        ),
    }
}
