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

use std::sync::atomic::{AtomicBool, Ordering};

use ros2_client::{Publisher, Subscription};
use tendril::ipc::clock::{now_ns, Ticker};
use tendril::ipc::controller::{Controller, ControllerConfig, Inbox};
use tendril::ipc::following::Following;
use tendril::ipc::planner::{plan, setpoint_for, Planned};
use tendril::ipc::sim::analysis::Sample;
use tendril::robot::RigidMap;
use tendril::runlog::{RunLog, RunLogStats, StepRecord};
use tendril_shared::messages::{command_status, Header as MsgHeader, Setpoint, TensionCommand};

use crate::chip::ChipController;
use crate::msg::{
    DiagnosticArray, Float64MultiArray, Header, JointState, PointStamped, PoseStamped,
};
use crate::node::RosNode;
use crate::targets::{Refusal, TargetFollower};
use crate::topics;
use crate::verdicts::{Bound, Verdicts};
use crate::Ros2Error;

mod config;
mod diagnostics;
mod feedback;

use feedback::Feedback;

pub use config::{DriveConfig, DriveStats};

struct Endpoints {
    commands: Publisher<Float64MultiArray>,
    commanded: Publisher<JointState>,
    diagnostics: Publisher<DiagnosticArray>,
    joint_states: Subscription<JointState>,
    tip_pose: Subscription<PoseStamped>,
    target_point: Subscription<PointStamped>,
    target_pose: Subscription<PoseStamped>,
}

/// The drive: set up once, one [`Drive::period`] per tick.
pub struct Drive {
    planned: Planned,
    /// Targets from the topics, when they replace the planner's path.
    targets: Option<TargetFollower>,
    runlog: Option<RunLog>,
    /// The host period (with the chip in the loop: the settings' check).
    ctl: Controller,
    /// The chip as the controller (`--controller mcu`).
    chip: Option<ChipController>,
    /// The setpoint last sent to the chip (its commands are logged
    /// against it).
    last_setpoint: Setpoint,
    /// The next period's deadline (monotonic ns).
    next_deadline_ns: u64,
    /// Setpoints sent before the path (to the starting chip).
    seq_base: u64,
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
    /// When the tracker's last tip pose came (monotonic ns).
    last_tip_ns: u64,
    /// The tracker is silent after this long (the period's tracker
    /// timeout, `--tracker-timeout`), ns.
    tracker_silent_after_ns: u64,
    /// A silence this long ends the run, ns.
    give_up_after_ns: u64,
    /// How long the path's clock has been held, ns.
    held_ns: u64,
    /// Who is silent now ("robot", "tracker"), the path held for it.
    silent: Option<&'static str>,
    /// Why the run ended early, when it did.
    gave_up: Option<Ros2Error>,
    /// The last command sent (with the chip in the loop, a period may
    /// bring none).
    last_status: u32,
    /// Whether the loop follows the path, from the commands sent: the
    /// stiffness adaptation fits nothing while it does not.
    following: Following,
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
        // The stiffness adaptation models this controller's own integral.
        let mut planner = cfg.planner.clone();
        (planner.controller_gains).get_or_insert(cfg.controller.integral_gains(&robot));
        let planned = plan(&planner).map_err(err)?;
        // The chip's image, built (a checkout's first run: a minute) before
        // the drive joins the graph: a robot found before would get no
        // command meanwhile.
        let mut controller = cfg.controller.clone();
        if let Some(m) = controller.mcu.as_mut().filter(|m| m.image.is_none()) {
            m.image =
                Some(tendril::mcu::locate_image().map_err(|e| Ros2Error::Chip(e.to_string()))?);
        }
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
            chip: None,
            last_setpoint: Setpoint::default(),
            next_deadline_ns: 0,
            seq_base: 0,
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
            last_tip_ns: 0,
            tracker_silent_after_ns: (cfg.controller.tracker_timeout_s.max(0.0) * 1e9) as u64,
            held_ns: 0,
            silent: None,
            gave_up: None,
            last_status: 0,
            following: Following::default(),
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
        if controller.mcu.is_some() {
            drive.start_chip(&controller, period_ns, stop)?;
        }
        // The path's clock starts now, with the robot (and the chip) heard from.
        let start = now_ns() + period_ns;
        drive.ctl = Controller::new(&cfg.controller, &robot, &bytes, start).map_err(err)?;
        drive.ticker = Ticker::new(start, period_ns);
        drive.last_heard_ns = start;
        drive.last_tip_ns = start;
        Ok(drive)
    }

    /// Start the chip behind its bridge and wait for its first command,
    /// sending it the path's first setpoint and the robot's state (the rest
    /// tensions stay on the robot meanwhile).
    fn start_chip(
        &mut self,
        controller: &ControllerConfig,
        period_ns: u64,
        stop: &AtomicBool,
    ) -> Result<(), Ros2Error> {
        let mut chip = ChipController::start(controller)?;
        let first = match self.targets.as_mut() {
            Some(f) => f.setpoint(0.0),
            None => setpoint_for(
                &self.planned.motion,
                0.0,
                &self.planned.motion.at(0.0),
                None,
            ),
        };
        let setpoint = tendril::ipc::frame::setpoint(&self.to_tracker, &first);
        let state = self
            .feedback_state(now_ns())
            .ok_or_else(|| Ros2Error::Config("no feedback to start the chip with".into()))?;
        let (waited, seq) = chip.wait_ready(&setpoint, &state, period_ns, stop)?;
        self.stats.chip_start_s = Some(waited);
        // The path's messages go on from the wait's: a restart would read
        // as a new planner and a new plant.
        self.seq_base = seq;
        self.feedback.seq = seq;
        self.chip = Some(chip);
        Ok(())
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

    /// One period; returns whether the run goes on.
    pub fn period(&mut self) -> bool {
        if let Err(e) = self.forward_chip_commands() {
            self.gave_up = Some(e);
            return false;
        }
        let tick = self.ticker.wait(self.spin_ns);
        self.next_deadline_ns = tick.deadline_ns + self.ticker.period_ns();
        let t_wake = now_ns();
        let state = self.take_feedback(t_wake);
        if state.is_some() {
            self.last_heard_ns = t_wake;
        }
        // A silent robot or tracker: the path's clock stops, so the
        // setpoint — and with the correction frozen by the period's stale
        // and tracker rules, the command — holds where it was until both
        // are heard again.
        let robot = t_wake.saturating_sub(self.last_heard_ns);
        let tracker = t_wake.saturating_sub(self.last_tip_ns);
        let silent = if robot > self.silent_after_ns {
            Some(("robot", "no joint state or tip pose", robot))
        } else if tracker > self.tracker_silent_after_ns {
            Some(("tracker", "no tip pose", tracker))
        } else {
            None
        };
        self.silent = silent.map(|(who, _, _)| who);
        if let Some((who, what, silence)) = silent {
            // The periods the ticker skipped (late by a whole period) are
            // held time too: the setpoint must not move a period on.
            self.held_ns += (1 + tick.skipped) * self.ticker.period_ns();
            self.stats.path_held_periods += 1;
            if silence > self.give_up_after_ns {
                self.gave_up = Some(Ros2Error::RobotSilent(format!(
                    "the {who} fell silent for {:.1} s ({what}; --wait-for-robot {} s): the \
                     last command held",
                    silence as f64 * 1e-9,
                    self.give_up_after_ns as f64 * 1e-9
                )));
                return false;
            }
        }
        let t = self.since_start(tick.deadline_ns);
        let mut setpoint = match self.targets.is_some() {
            true => self.target_setpoint(t),
            false => {
                let desired = self.planned.motion.at(t);
                // A silent robot, a held controller: nothing to fit.
                let following = self.silent.is_none() && self.following.follows(t_wake);
                let Planned {
                    motion, stiffness, ..
                } = &mut self.planned;
                let adapted = stiffness
                    .as_mut()
                    .map(|s| s.step(motion.trajectory(), t, &desired, following));
                setpoint_for(motion, t, &desired, adapted)
            }
        };
        setpoint.header = MsgHeader {
            seq: self.seq_base + tick.index + 1,
            stamp_ns: t_wake,
        };
        let cmd = match self.chip.as_mut() {
            None => {
                let state = state.map(|s| tendril::ipc::frame::state(&self.to_base, &s));
                let inbox = Inbox {
                    setpoint: Some(setpoint),
                    setpoints: 1,
                    superseded_nonfinite: 0,
                    state,
                    states: usize::from(state.is_some()),
                    weights: None,
                };
                self.ctl.period(&tick, t_wake, self.overran, &inbox)
            }
            // The chip's period runs on its own timer: its commands go to
            // the robot as they come, between this period and the next.
            Some(chip) => {
                let sp = tendril::ipc::frame::setpoint(&self.to_tracker, &setpoint);
                let offered = match state {
                    Some(s) => chip.offer(&sp).and_then(|()| chip.offer_state(&s)),
                    None => chip.offer(&sp),
                };
                if let Err(e) = offered {
                    self.gave_up = Some(e);
                    return false;
                }
                self.last_setpoint = setpoint;
                return self.end_period(t_wake, t);
            }
        };
        self.send(&cmd, tick.deadline_ns, &setpoint);
        self.end_period(t_wake, t)
    }

    /// With the chip in the loop, until the next period is due: send each
    /// command it makes to the robot as soon as it comes (polling every
    /// [`CHIP_POLL_NS`]), not at the next period, which would add up to a
    /// period to its age. The robot's answers go to the chip once a period,
    /// with the setpoint: forwarded as they came, the circle tracked 0.09–0.15
    /// mm RMS against 0.05–0.10 mm (four runs each; BENCHMARKS.md).
    fn forward_chip_commands(&mut self) -> Result<(), Ros2Error> {
        let Some(mut chip) = self.chip.take() else {
            return Ok(());
        };
        let result = loop {
            let now = now_ns();
            match chip.take_command() {
                Ok(Some(cmd)) => {
                    let setpoint = self.last_setpoint;
                    self.send(&cmd, now, &setpoint)
                }
                Ok(None) if now_ns() + CHIP_POLL_NS < self.next_deadline_ns => {
                    std::thread::sleep(std::time::Duration::from_nanos(CHIP_POLL_NS))
                }
                Ok(None) => break Ok(()),
                Err(e) => break Err(e),
            }
        };
        self.chip = Some(chip);
        result
    }

    /// Send `cmd` to the robot (and as `commanded`), count it, log it at
    /// `t_ns` (monotonic) against `setpoint`.
    fn send(&mut self, cmd: &TensionCommand, t_ns: u64, setpoint: &Setpoint) {
        self.last_status = cmd.status;
        self.following.heard(t_ns, cmd.status);
        if cmd.status & command_status::SAFE_HOLD != 0 {
            self.stats.hold_periods += 1;
        }
        let tensions: Vec<f64> = cmd.tensions[..self.n].iter().map(|&v| v as f64).collect();
        if let Some(log) = &self.runlog {
            // The tracker's tip as it came (its frame); the setpoint is in
            // the model's base frame.
            let tip = self.feedback.tip.map(|(p, _)| p.map(f64::from));
            log.step(StepRecord {
                t_ns: t_ns.saturating_sub(self.ticker.start_ns()),
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
        self.stats.commands += 1;
    }

    /// The period's end: `/diagnostics` once a second, the clock's and the
    /// host period's books; whether the run goes on after path time `t`.
    fn end_period(&mut self, t_wake: u64, t: f64) -> bool {
        if self.stats.periods.is_multiple_of(self.diagnostics_every) {
            let _ = (self.ends.diagnostics).publish(self.diagnostics(self.last_status));
        }
        let t_done = now_ns();
        self.overran = self.ticker.finish(t_done);
        if self.chip.is_none() {
            self.ctl.finish(t_done - t_wake);
        }
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

    /// The statistics so far.
    pub fn stats(&self) -> DriveStats {
        let mut s = self.stats.clone();
        let c = self.ctl.stats(&self.ticker);
        s.overruns = c.overruns;
        s.stale_periods = c.plant_stale_cycles;
        s.stiffness_applied = self.planned.stiffness.as_ref().map(|a| a.applied());
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

/// How often the drive looks for the chip's commands between its periods, ns.
const CHIP_POLL_NS: u64 = 200_000;

/// Periods without a joint state or tip pose after which the robot is
/// silent and the path holds: the period's plant-stale time, so the path
/// and the correction stop together.
const SILENT_AFTER_PERIODS: u64 = 20;

/// Run the drive until the path ends or `stop`; writes the statistics and
/// closes the run log.
pub fn run(cfg: &DriveConfig, stop: &AtomicBool) -> Result<DriveStats, Ros2Error> {
    let mut drive = Drive::new(cfg, stop)?;
    while !stop.load(Ordering::Relaxed) && drive.period() {}
    let mut stats = drive.stats();
    if let Some(chip) = drive.chip.take() {
        // The chip's own counts (its telemetry), not the unused host period's.
        match chip.finish() {
            Ok(c) => {
                stats.overruns = c.skipped;
                stats.stale_periods = c.plant_stale_cycles;
                stats.chip_periods = Some(c.cycles);
            }
            Err(e) => log::warn!("drive: {e}: the chip's counts are missing"),
        }
    }
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
    if let Some(e) = drive.gave_up {
        log::warn!(
            "drive: after {} periods; the statistics and the run log cover them",
            stats.periods
        );
        return Err(e);
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
    use tendril::ipc::planner::PlannerConfig;
    use tendril::runlog::RunLogConfig;

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
