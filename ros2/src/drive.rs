//! `tendril-ros2 drive`: tendril's planner and controller against a robot
//! that lives on ROS 2 — tension commands out, the robot's measured
//! tensions and the tracker's tip in (`docs/design.md` §13).
//!
//! One process, one period: the planner's setpoint for the period's
//! deadline ([`tendril::ipc::planner::setpoint_for`], the planner process's
//! own code), the newest joint state and tip pose from DDS as the plant
//! state, then the host controller's period ([`Controller::period`]: the
//! firmware's period, every safety rule of the iceoryx2 loop — a silent
//! tracker is a hold, a bad command never leaves it) and the command out.
//! A robot that falls silent (no joint state or tip pose for the period's
//! stale time) holds the path where it was, so the command holds; it goes
//! on when the robot answers again, and the run ends with an error when
//! the silence outlasts `--wait-for-robot`.
//! Configured once, allocation-free in the period apart from DDS's own
//! serialisation.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::SystemTime;

use ros2_client::{Publisher, Subscription};
use serde::Serialize;
use tendril::ipc::clock::{now_ns, Ticker};
use tendril::ipc::controller::{Controller, ControllerConfig, Inbox};
use tendril::ipc::planner::{plan, setpoint_for, Planned, PlannerConfig};
use tendril::ipc::sim::analysis::Sample;
use tendril::robot::RigidMap;
use tendril::runlog::{RunLog, RunLogConfig, RunLogStats, StepRecord};
use tendril_shared::messages::{command_status, Header as MsgHeader, PlantState, MAX_TENDONS};

use crate::msg::{
    DiagnosticArray, DiagnosticStatus, Float64MultiArray, Header, JointState, KeyValue,
    PointStamped, PoseStamped, Time,
};
use crate::node::RosNode;
use crate::targets::{Refusal, TargetFollower};
use crate::topics;
use crate::verdicts::{Bound, Verdicts};
use crate::Ros2Error;

/// Everything `drive` needs, set once.
#[derive(Clone, Debug)]
pub struct DriveConfig {
    /// The path (its `robot` is the controller's).
    pub planner: PlannerConfig,
    /// The controller: robot, net, rate, gains, watchdogs.
    pub controller: ControllerConfig,
    /// Seconds on the path after the planner's settle.
    pub duration_s: f64,
    /// ROS domain.
    pub domain: u16,
    /// Node namespace.
    pub namespace: String,
    /// Statistics JSON written at exit.
    pub stats: Option<PathBuf>,
    /// How long to wait for the robot's first joint state and tip pose
    /// before the path starts, s; also how long a silent robot is held
    /// before the run gives up.
    pub wait_for_robot_s: f64,
    /// Follow targets from `target_point` / `target_pose` instead of the
    /// planner's path ([`crate::targets`]).
    pub target_topic: bool,
    /// Bound on the tracking error, mm (`tendril sim`'s `--max-rms-mm`):
    /// the RMS on a smooth path, the worst steady state on steps and
    /// targets.
    pub max_rms_mm: f64,
    /// The run's MCAP file and live view (`docs/design.md` §12): the
    /// commanded and measured tensions, the tracker's tip against the
    /// setpoint, the status — what the plant logs in `tendril sim`, less
    /// the rod's true shape, which only the robot knows.
    pub runlog: RunLogConfig,
}

/// What the drive measured and counted, written as JSON at exit.
#[derive(Clone, Debug, Default, Serialize)]
pub struct DriveStats {
    /// Control periods run.
    pub periods: u64,
    /// Periods that ended after the next deadline.
    pub overruns: u64,
    /// Periods whose command was a safe hold.
    pub hold_periods: u64,
    /// Periods with the robot stale: no joint state or tip pose for the
    /// period's stale time (20 periods), the correction frozen — the
    /// iceoryx2 loop's rule for a silent plant (the period's counter, not
    /// the status bit, which the correction also sets while it waits for
    /// a tracker frame).
    pub stale_periods: u64,
    /// Periods the path was held because the robot was silent (its clock
    /// stopped, so the setpoint and the command held).
    pub path_held_periods: u64,
    /// Joint states taken / refused (not one finite value per tendon).
    pub joint_states: u64,
    /// Joint states refused.
    pub joint_states_refused: u64,
    /// Tip poses taken / refused (not finite).
    pub tip_poses: u64,
    /// Tip poses refused.
    pub tip_poses_refused: u64,
    /// Seconds from joining the graph to the robot's first joint state and
    /// tip pose (discovery and the first answer), the rest tensions sent
    /// meanwhile; the path starts then.
    pub first_feedback_s: f64,
    /// Tracking error on the path (after the settle): the tracker's tip
    /// against the path where the planner was when the tip was sampled.
    pub tracking_rms_mm: Option<f64>,
    /// Its largest value.
    pub tracking_max_mm: Option<f64>,
    /// Tip poses in the tracking figures.
    pub tracked_frames: u64,
    /// Targets taken from the topics (`--target-topic`).
    pub targets: u64,
    /// Targets refused: a coordinate not finite.
    pub targets_refused_not_finite: u64,
    /// Targets refused: not in the tracker's frame.
    pub targets_refused_frame: u64,
    /// Targets refused: out of the robot's reach.
    pub targets_refused_out_of_reach: u64,
    /// The sim report's verdicts on the tracker's tips against the path:
    /// is the loop oscillating (a sustained tone above the path's own
    /// frequencies), does its error grow, where did steps settle.
    pub verdicts: Option<Verdicts>,
}

struct Endpoints {
    commands: Publisher<Float64MultiArray>,
    commanded: Publisher<JointState>,
    diagnostics: Publisher<DiagnosticArray>,
    joint_states: Subscription<JointState>,
    tip_pose: Subscription<PoseStamped>,
    target_point: Subscription<PointStamped>,
    target_pose: Subscription<PoseStamped>,
}

/// The newest feedback from the robot, as the controller's plant state.
struct Feedback {
    tensions: Option<[f32; MAX_TENDONS]>,
    tip: Option<([f32; 7], u64)>,
    tip_seq: u32,
    seq: u64,
}

/// The drive: set up once, one [`Drive::period`] per tick.
pub struct Drive {
    planned: Planned,
    /// Targets from the topics, when they replace the planner's path.
    targets: Option<TargetFollower>,
    runlog: Option<RunLog>,
    ctl: Controller,
    ticker: Ticker,
    ends: Endpoints,
    _node: RosNode,
    n: usize,
    to_base: RigidMap,
    to_tracker: RigidMap,
    settle_s: f64,
    end_s: f64,
    feedback: Feedback,
    /// When the robot was last heard from (monotonic ns).
    last_heard_ns: u64,
    /// The robot is silent after this long (the period's plant-stale
    /// time), ns.
    silent_after_ns: u64,
    /// A silence this long ends the run, ns.
    give_up_after_ns: u64,
    /// How long the path's clock has been held, ns.
    held_ns: u64,
    /// Why the run ended early, when it did.
    gave_up: Option<String>,
    overran: bool,
    /// Periods between `/diagnostics` messages (one a second).
    diagnostics_every: u64,
    /// Spin this long before each deadline instead of sleeping, ns
    /// (`--spin-us`).
    spin_ns: u64,
    names: Vec<String>,
    sum_sq: f64,
    /// The tips against the path, for the verdicts (capacity for one a
    /// period: no allocation in the period).
    samples: Vec<Sample>,
    /// The path's fundamental frequency, Hz (the tone test's band starts
    /// above its harmonics).
    path_hz: f64,
    /// What the tracking error is held to.
    bound: Bound,
    stats: DriveStats,
}

impl Drive {
    /// Plan the path, load the net, join the graph, wait for the robot
    /// (until `stop`).
    pub fn new(cfg: &DriveConfig, stop: &AtomicBool) -> Result<Drive, Ros2Error> {
        if !(cfg.duration_s.is_finite() && cfg.duration_s > 0.0) {
            return Err(Ros2Error::Config(format!(
                "--duration {}: expected a number of seconds > 0",
                cfg.duration_s
            )));
        }
        if !(cfg.max_rms_mm.is_finite() && cfg.max_rms_mm > 0.0) {
            return Err(Ros2Error::Config(format!(
                "--max-rms-mm {}: expected a bound in mm > 0",
                cfg.max_rms_mm
            )));
        }
        let err = |e: tendril::ipc::IpcError| Ros2Error::Config(e.to_string());
        let (robot, bytes) = tendril::ipc::controller::load(&cfg.controller).map_err(err)?;
        let planned = plan(&cfg.planner).map_err(err)?;
        let mut node = RosNode::new(cfg.domain, &cfg.namespace, "tendril_drive")?;
        let ends = Endpoints {
            commands: node.publisher(&topics::COMMANDS)?,
            commanded: node.publisher(&topics::COMMANDED)?,
            diagnostics: node.publisher(&topics::DIAGNOSTICS)?,
            joint_states: node.subscription(&topics::JOINT_STATES)?,
            tip_pose: node.subscription(&topics::TIP_POSE)?,
            target_point: node.subscription(&topics::TARGET_POINT)?,
            target_pose: node.subscription(&topics::TARGET_POSE)?,
        };
        let targets = match cfg.target_topic {
            true => Some(TargetFollower::new(&robot, robot.base.to_base())?),
            false => None,
        };
        let period_ns = (1e9 / cfg.controller.rate_hz).round() as u64;
        let start = now_ns() + period_ns;
        // This controller checks the settings before the wait (a bad one is
        // refused at once); the path's own is made when the robot answers.
        let mut drive = Drive {
            ctl: Controller::new(&cfg.controller, &robot, &bytes, start).map_err(err)?,
            ticker: Ticker::new(start, period_ns),
            ends,
            _node: node,
            n: robot.n_tendons(),
            to_base: robot.base.to_base(),
            to_tracker: planned.base.to_tracker(),
            planned,
            targets,
            runlog: match cfg.runlog.enabled() {
                true => {
                    Some(RunLog::start(&cfg.runlog).map_err(|e| Ros2Error::Output(e.to_string()))?)
                }
                false => None,
            },
            settle_s: cfg.planner.settle_s,
            end_s: cfg.planner.settle_s + cfg.duration_s,
            feedback: Feedback {
                tensions: None,
                tip: None,
                tip_seq: 0,
                seq: 0,
            },
            last_heard_ns: 0,
            silent_after_ns: SILENT_AFTER_PERIODS * period_ns,
            give_up_after_ns: (cfg.wait_for_robot_s.max(0.0) * 1e9) as u64,
            held_ns: 0,
            gave_up: None,
            overran: false,
            diagnostics_every: cfg.controller.rate_hz.round().max(1.0) as u64,
            spin_ns: (cfg.controller.spin_us.max(0.0) * 1e3) as u64,
            names: (0..robot.n_tendons())
                .map(|i| format!("tendon_{i}"))
                .collect(),
            sum_sq: 0.0,
            samples: Vec::with_capacity(
                ((cfg.planner.settle_s + cfg.duration_s) * cfg.controller.rate_hz).ceil() as usize
                    + 1,
            ),
            path_hz: match cfg.target_topic {
                true => 0.0,
                false => tendril::ipc::sim::assess::trajectory_hz(&cfg.planner.shape),
            },
            bound: Bound::of(&cfg.planner.shape, cfg.target_topic, cfg.max_rms_mm),
            stats: DriveStats::default(),
        };
        drive.stats.first_feedback_s = drive.wait_for_robot(&robot.min_tensions(), cfg, stop)?;
        // The path's clock starts now, with the robot heard from.
        let start = now_ns() + period_ns;
        drive.ctl = Controller::new(&cfg.controller, &robot, &bytes, start).map_err(err)?;
        drive.ticker = Ticker::new(start, period_ns);
        drive.last_heard_ns = start;
        Ok(drive)
    }

    /// Send the robot's rest tensions (its floors: where the planner's
    /// approach starts) until it has answered with a joint state and a tip
    /// pose, as a robot's driver and tracker do once they have discovered
    /// this node; returns the seconds that took. What they sent is the
    /// first period's feedback.
    fn wait_for_robot(
        &mut self,
        rest: &[f64],
        cfg: &DriveConfig,
        stop: &AtomicBool,
    ) -> Result<f64, Ros2Error> {
        let start = std::time::Instant::now();
        while self.feedback.tensions.is_none() || self.feedback.tip.is_none() {
            if stop.load(Ordering::Relaxed) {
                return Err(Ros2Error::Interrupted("while waiting for the robot".into()));
            }
            if start.elapsed().as_secs_f64() > cfg.wait_for_robot_s {
                let heard = match (self.feedback.tensions, self.feedback.tip) {
                    (None, None) => "neither a joint state nor a tip pose",
                    (Some(_), None) => "joint states but no tip pose",
                    _ => "tip poses but no joint state",
                };
                return Err(Ros2Error::Config(format!(
                    "no robot answered on ROS domain {} within {} s: {heard} (a driver \
                     publishing {} and a tracker publishing {}, both taking {})",
                    cfg.domain,
                    cfg.wait_for_robot_s,
                    topics::JOINT_STATES.name,
                    topics::TIP_POSE.name,
                    topics::COMMANDS.name
                )));
            }
            let _ = self.ends.commands.publish(Float64MultiArray {
                data: rest.to_vec(),
                ..Float64MultiArray::default()
            });
            std::thread::sleep(std::time::Duration::from_millis(10));
            self.take_feedback(now_ns());
        }
        // The wait's tips were timed on no path: not tracking figures.
        self.feedback.seq = 0;
        self.sum_sq = 0.0;
        self.stats.tracked_frames = 0;
        self.stats.tracking_max_mm = None;
        self.samples.clear();
        Ok(start.elapsed().as_secs_f64())
    }

    /// The path's time at monotonic `t_ns`: seconds since the first
    /// period's deadline, less the time the path was held for a silent
    /// robot.
    fn since_start(&self, t_ns: u64) -> f64 {
        (t_ns as i128 - self.ticker.start_ns() as i128 - self.held_ns as i128) as f64 * 1e-9
    }

    /// Take the newest joint state and tip pose; returns the plant state
    /// when anything new arrived and both kinds have been seen.
    fn take_feedback(&mut self, t_wake: u64) -> Option<PlantState> {
        // The first period takes what the wait for the robot took.
        let mut fresh = self.stats.periods == 0;
        while let Ok(Some((js, _))) = self.ends.joint_states.take() {
            if js.effort.len() == self.n && js.effort.iter().all(|t| t.is_finite()) {
                let mut t = [0.0f32; MAX_TENDONS];
                for (dst, &v) in t.iter_mut().zip(&js.effort) {
                    *dst = v as f32;
                }
                self.feedback.tensions = Some(t);
                self.stats.joint_states += 1;
                fresh = true;
            } else {
                self.stats.joint_states_refused += 1;
            }
        }
        while let Ok(Some((tip, _))) = self.ends.tip_pose.take() {
            let p = &tip.pose;
            let pose = [
                p.position.x,
                p.position.y,
                p.position.z,
                p.orientation.w,
                p.orientation.x,
                p.orientation.y,
                p.orientation.z,
            ];
            if pose.iter().all(|v| v.is_finite()) {
                let age_ns = wall_age_ns(&tip.header.stamp);
                self.feedback.tip = Some((pose.map(|v| v as f32), t_wake.saturating_sub(age_ns)));
                self.feedback.tip_seq += 1;
                self.stats.tip_poses += 1;
                fresh = true;
                self.track(pose, t_wake.saturating_sub(age_ns));
            } else {
                self.stats.tip_poses_refused += 1;
            }
        }
        let (tensions, (tip_pose, tip_stamp_ns)) = (self.feedback.tensions?, self.feedback.tip?);
        if !fresh {
            return None;
        }
        self.feedback.seq += 1;
        let state = PlantState {
            header: MsgHeader {
                seq: self.feedback.seq,
                stamp_ns: t_wake,
            },
            command_seq: 0,
            tensions,
            pad: Default::default(),
            tip_pose,
            count: self.n as u32,
            status: 0,
            tip_seq: self.feedback.tip_seq,
            tip_stamp_ns,
        };
        Some(tendril::ipc::frame::state(&self.to_base, &state))
    }

    /// The tip (tracker's frame) against the path where the planner was
    /// when it was sampled, once on the path.
    fn track(&mut self, tip: [f64; 7], stamp_ns: u64) {
        let t = self.since_start(stamp_ns);
        if t < self.settle_s || t > self.end_s {
            return;
        }
        let (want, hold, moving) = match &self.targets {
            Some(f) => match f.holding() {
                Some(pose) => (self.to_tracker.pose(pose), false, false),
                None => return,
            },
            None => {
                let desired = self.planned.motion.at(t);
                let want = self.to_tracker.pose(desired.point.pose);
                (want, desired.holding, desired.moving)
            }
        };
        if self.samples.len() < self.samples.capacity() {
            self.samples.push(Sample {
                t,
                desired: [want[0], want[1], want[2]],
                actual: [tip[0], tip[1], tip[2]],
                hold,
                moving,
            });
        }
        if hold || moving {
            return;
        }
        let e = (0..3)
            .map(|k| (tip[k] - want[k]).powi(2))
            .sum::<f64>()
            .sqrt()
            * 1e3;
        self.sum_sq += e * e;
        self.stats.tracked_frames += 1;
        let max = self.stats.tracking_max_mm.get_or_insert(0.0);
        *max = max.max(e);
    }

    /// One period; returns whether the run goes on.
    pub fn period(&mut self) -> bool {
        let tick = self.ticker.wait(self.spin_ns);
        let t_wake = now_ns();
        let state = self.take_feedback(t_wake);
        if state.is_some() {
            self.last_heard_ns = t_wake;
        }
        // A silent robot: the path's clock stops, so the setpoint — and
        // with the correction frozen by the period's stale rule, the
        // command — holds where it was until the robot answers.
        let silence = t_wake.saturating_sub(self.last_heard_ns);
        if silence > self.silent_after_ns {
            self.held_ns += self.ticker.period_ns();
            self.stats.path_held_periods += 1;
            if silence > self.give_up_after_ns {
                self.gave_up = Some(format!(
                    "the robot fell silent for {:.1} s (no joint state or tip pose; \
                     --wait-for-robot {} s): the last command held",
                    silence as f64 * 1e-9,
                    self.give_up_after_ns as f64 * 1e-9
                ));
                return false;
            }
        }
        let t = self.since_start(tick.deadline_ns);
        let mut setpoint = match self.targets.is_some() {
            true => self.target_setpoint(t),
            false => {
                let desired = self.planned.motion.at(t);
                setpoint_for(&self.planned.motion, t, &desired, None)
            }
        };
        setpoint.header = MsgHeader {
            seq: tick.index + 1,
            stamp_ns: t_wake,
        };
        let inbox = Inbox {
            setpoint: Some(setpoint),
            setpoints: 1,
            superseded_nonfinite: 0,
            state,
            states: usize::from(state.is_some()),
            weights: None,
        };
        let cmd = self.ctl.period(&tick, t_wake, self.overran, &inbox);
        if cmd.status & command_status::SAFE_HOLD != 0 {
            self.stats.hold_periods += 1;
        }
        let tensions: Vec<f64> = cmd.tensions[..self.n].iter().map(|&v| v as f64).collect();
        if let Some(log) = &self.runlog {
            // The tracker's tip as it came (its frame); the setpoint is in
            // the model's base frame.
            let tip = self.feedback.tip.map(|(p, _)| p.map(f64::from));
            log.step(StepRecord {
                t_ns: tick.deadline_ns.saturating_sub(self.ticker.start_ns()),
                command_seq: cmd.header.seq,
                controller_status: cmd.status,
                plant_status: 0,
                commanded: tensions.clone(),
                measured: self.feedback.tensions.map_or_else(Vec::new, |t| {
                    t[..self.n].iter().map(|&v| f64::from(v)).collect()
                }),
                // The robot's true tip is the robot's own: the tracker's
                // frame stands for it.
                tip: tip.unwrap_or([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]),
                frame: tip,
                desired: Some(self.to_tracker.pose(setpoint.pose.map(f64::from))),
            });
        }
        // A full reliable queue (a peer gone) loses this command; the next
        // period sends a newer one, and the robot's driver holds the last.
        let _ = self.ends.commanded.publish(JointState {
            header: Header::now(""),
            name: self.names.clone(),
            effort: tensions.clone(),
            ..JointState::default()
        });
        let _ = self.ends.commands.publish(Float64MultiArray {
            data: tensions,
            ..Float64MultiArray::default()
        });
        if tick.index.is_multiple_of(self.diagnostics_every) {
            let _ = self.ends.diagnostics.publish(self.diagnostics(cmd.status));
        }
        let t_done = now_ns();
        self.overran = self.ticker.finish(t_done);
        self.ctl.finish(t_done - t_wake);
        self.stats.periods += 1;
        t < self.end_s
    }

    /// Take the targets that arrived (each, in order: a refused one leaves
    /// the last accepted in force) and return the setpoint at `t`.
    fn target_setpoint(&mut self, t: f64) -> tendril_shared::messages::Setpoint {
        let Some(follower) = self.targets.as_mut() else {
            return Default::default();
        };
        let mut offered: Vec<(crate::msg::Point, String)> = Vec::new();
        while let Ok(Some((p, _))) = self.ends.target_point.take() {
            offered.push((p.point, p.header.frame_id));
        }
        while let Ok(Some((p, _))) = self.ends.target_pose.take() {
            offered.push((p.pose.position, p.header.frame_id));
        }
        for (point, frame) in offered {
            match follower.offer(&point, &frame, t) {
                Ok(()) => self.stats.targets += 1,
                Err(Refusal::NotFinite) => self.stats.targets_refused_not_finite += 1,
                Err(Refusal::Frame) => self.stats.targets_refused_frame += 1,
                Err(Refusal::OutOfReach) => self.stats.targets_refused_out_of_reach += 1,
            }
        }
        follower.setpoint(t)
    }

    /// The period's status and counters for `/diagnostics` (once a second:
    /// the controller's statistics are gathered here, not in every period).
    fn diagnostics(&self, status: u32) -> DiagnosticArray {
        let s = self.stats();
        let c = self.ctl.stats(&self.ticker);
        let (level, message) = if status & command_status::SAFE_HOLD != 0 {
            (DiagnosticStatus::ERROR, "safe hold")
        } else if status & command_status::PLANT_STALE != 0 && c.plant_stale_cycles > 0 {
            (
                DiagnosticStatus::WARN,
                "the robot is silent: path held, correction frozen",
            )
        } else if s.joint_states_refused + s.tip_poses_refused > 0 {
            (DiagnosticStatus::WARN, "feedback refused")
        } else {
            (DiagnosticStatus::OK, "tracking")
        };
        let kv = |key: &str, value: String| KeyValue {
            key: key.into(),
            value,
        };
        let rms = s.tracking_rms_mm.map_or("—".into(), |r| format!("{r:.4}"));
        DiagnosticArray {
            header: Header::now(""),
            status: vec![DiagnosticStatus {
                level,
                name: "tendril_drive".into(),
                message: message.into(),
                hardware_id: "tendril controller (host period)".into(),
                values: vec![
                    kv("status_bits", format!("{status:#x}")),
                    kv("periods", s.periods.to_string()),
                    kv("overruns", s.overruns.to_string()),
                    kv("hold_periods", c.hold_cycles.to_string()),
                    kv("stale_periods", c.plant_stale_cycles.to_string()),
                    kv("path_held_periods", s.path_held_periods.to_string()),
                    kv("saturated_periods", c.saturated_cycles.to_string()),
                    kv("joint_states", s.joint_states.to_string()),
                    kv("joint_states_refused", s.joint_states_refused.to_string()),
                    kv("tip_poses", s.tip_poses.to_string()),
                    kv("tip_poses_refused", s.tip_poses_refused.to_string()),
                    kv("tracking_rms_mm", rms),
                ],
            }],
        }
    }

    /// The statistics so far.
    pub fn stats(&self) -> DriveStats {
        let mut s = self.stats.clone();
        let c = self.ctl.stats(&self.ticker);
        s.overruns = c.overruns;
        s.stale_periods = c.plant_stale_cycles;
        if s.tracked_frames > 0 {
            s.tracking_rms_mm = Some((self.sum_sq / s.tracked_frames as f64).sqrt());
        }
        s
    }

    /// The verdicts on the run so far (at its end: they read every tip),
    /// by `tendril sim`'s rules.
    pub fn verdicts(&self, tracking_rms_mm: Option<f64>) -> Verdicts {
        crate::verdicts::judge(&self.samples, self.path_hz, self.bound, tracking_rms_mm)
    }
}

/// Periods without a joint state or tip pose after which the robot is
/// silent and the path holds: the period's plant-stale time, so the path
/// and the correction stop together.
const SILENT_AFTER_PERIODS: u64 = 20;

/// How long ago (ns) the wall-clock `stamp` was; 0 for a stamp from the
/// future (another machine's clock ahead of this one's).
fn wall_age_ns(stamp: &Time) -> u64 {
    let now = SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .unwrap_or_default();
    let then = std::time::Duration::new(stamp.sec.max(0) as u64, stamp.nanosec.min(999_999_999));
    now.saturating_sub(then).as_nanos() as u64
}

/// Run the drive until the path ends or `stop`; writes the statistics and
/// closes the run log.
pub fn run(cfg: &DriveConfig, stop: &AtomicBool) -> Result<DriveStats, Ros2Error> {
    let mut drive = Drive::new(cfg, stop)?;
    while !stop.load(Ordering::Relaxed) && drive.period() {}
    let mut stats = drive.stats();
    stats.verdicts = Some(drive.verdicts(stats.tracking_rms_mm));
    let logged: Option<RunLogStats> = drive
        .runlog
        .take()
        .map(RunLog::finish)
        .transpose()
        .map_err(|e| Ros2Error::Output(e.to_string()))?;
    if let Some(l) = logged.filter(|l| l.dropped > 0) {
        log::warn!(
            "drive: the run log dropped {} records (its writer fell behind)",
            l.dropped
        );
    }
    if let Some(path) = &cfg.stats {
        let json = serde_json::to_vec_pretty(&stats)
            .map_err(|e| Ros2Error::Config(format!("statistics: {e}")))?;
        tendril::fsutil::write_atomic(path, &json)
            .map_err(|e| Ros2Error::Output(format!("{}: {e}", path.display())))?;
    }
    if let Some(why) = drive.gave_up {
        return Err(Ros2Error::RobotSilent(format!(
            "{why}; after {} periods, the statistics and the run log cover them",
            stats.periods
        )));
    }
    if stop.load(Ordering::Relaxed) {
        // Whole files, of a run cut short: said, and the exit status says it.
        return Err(Ros2Error::Interrupted(format!(
            "after {} periods; the statistics and the run log cover them",
            stats.periods
        )));
    }
    Ok(stats)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stamp_from_the_future_is_no_age_and_one_from_the_past_its_age() {
        let now = SystemTime::now()
            .duration_since(SystemTime::UNIX_EPOCH)
            .unwrap();
        let past = Time {
            sec: (now.as_secs() - 2) as i32,
            nanosec: now.subsec_nanos(),
        };
        let age = wall_age_ns(&past) as f64 * 1e-9;
        assert!((2.0..2.5).contains(&age), "{age}");
        let future = Time {
            sec: (now.as_secs() + 60) as i32,
            nanosec: 0,
        };
        assert_eq!(wall_age_ns(&future), 0);
    }

    #[test]
    fn a_drive_needs_a_positive_duration() {
        let cfg = DriveConfig {
            planner: PlannerConfig::new(
                "robots/seed-4t.toml".into(),
                tendril::plan::PathShape::Hold {
                    center_m: vec![0.0, 0.0],
                    height_m: None,
                },
            ),
            controller: ControllerConfig::default(),
            duration_s: 0.0,
            domain: 0,
            namespace: "/".into(),
            stats: None,
            wait_for_robot_s: 1.0,
            target_topic: false,
            max_rms_mm: 2.0,
            runlog: RunLogConfig::default(),
        };
        let e = Drive::new(&cfg, &AtomicBool::new(false))
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("--duration"), "{e}");
    }
}
