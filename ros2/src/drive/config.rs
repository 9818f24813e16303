//! What `drive` is told and what it reports.

use std::path::PathBuf;

use serde::Serialize;
use tendril::ipc::controller::ControllerConfig;
use tendril::ipc::planner::PlannerConfig;
use tendril::runlog::RunLogConfig;

use crate::verdicts::Verdicts;

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
    /// Commands sent to the robot (one a period with the host's period;
    /// with the chip's, the commands it sent).
    pub commands: u64,
    /// With the chip in the loop: the seconds from starting QEMU to its
    /// first command (the run's net installed), and the periods it ran.
    pub chip_start_s: Option<f64>,
    /// See [`DriveStats::chip_start_s`].
    pub chip_periods: Option<u64>,
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
    /// The stiffness adaptation's estimate at the end, κ̂ (the backbone
    /// 1/(1 − κ̂) times as stiff as its file; `docs/design.md` §6.5); None
    /// when it is off (`--adapt-stiffness off`, `--target-topic`).
    pub stiffness_applied: Option<f64>,
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
