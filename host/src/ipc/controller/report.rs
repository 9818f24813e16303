//! What the controller reports: its statistics and the faults it detected
//! (`controller.json`).

use super::*;

/// What the controller reports at exit (`controller.json`). Counts are
/// integers; every count says what it covers.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct ControllerStats {
    /// Periods run.
    pub cycles: u64,
    /// Periods whose work ran past the next deadline.
    pub overruns: u64,
    /// Periods skipped after an overrun (never run late).
    pub skipped: u64,
    /// `overruns / cycles`.
    pub overrun_fraction: f64,
    /// Wake-up time minus deadline (µs).
    pub lateness_us: Summary,
    /// Work per period: receive, control step, publish (µs).
    pub step_us: Summary,
    /// Age of a setpoint when the controller picked it up (µs).
    pub setpoint_age_us: Summary,
    /// Setpoints received.
    pub setpoints: u64,
    /// Setpoints that never arrived: gaps in the planner's sequence numbers.
    pub setpoints_lost: u64,
    /// Setpoints rejected: NaN/∞.
    pub rejected_nonfinite: u64,
    /// Setpoints rejected: quaternion not unit.
    pub rejected_quaternion: u64,
    /// Setpoints held: outside the net's workspace box.
    pub rejected_workspace: u64,
    /// Entries into the watchdog's safe hold after tracking began (a
    /// silent planner); the hold before the first setpoint is not a trip.
    pub watchdog_trips: u64,
    /// Of those, trips after which the same planner's setpoints came back
    /// with no sequence gap: the planner was late (starved of CPU, or its
    /// messages delayed), not silent. A real-time planner on an idle
    /// machine has none; a loaded machine shows them.
    pub watchdog_trips_late_planner: u64,
    /// Entries into the stuck-motor safe hold (not watchdog trips).
    pub stuck_motor_holds: u64,
    /// Periods spent in safe hold after tracking began (watchdog or a
    /// detected fault).
    pub hold_cycles: u64,
    /// Periods before the first setpoint (holding the initial tensions).
    pub startup_hold_cycles: u64,
    /// Periods whose command hit a range or slew limit.
    pub saturated_cycles: u64,
    /// Periods in which the firmware's integral correction moved the pose
    /// handed to the net (the one control law ran).
    pub correction_cycles: u64,
    /// Weight updates swapped in.
    pub weight_swaps: u64,
    /// Weight updates rejected (old net kept).
    pub weight_rejections: u64,
    /// Times the setpoint sequence restarted (a new planner).
    pub planner_restarts: u64,
    /// Times the plant-state sequence restarted (a new plant).
    pub plant_restarts: u64,
    /// Plant states that never arrived: gaps in the plant's sequence numbers.
    pub plant_states_lost: u64,
    /// Periods whose fresh plant state had not yet applied the previous
    /// command (a lost or delayed tension command).
    pub commands_not_applied: u64,
    /// Periods with no fresh plant state for over 20 periods.
    pub plant_stale_cycles: u64,
    /// Gaps to a stale plant state that were recovered from.
    pub plant_recoveries: u64,
    /// Faults the controller detected, in order (at most
    /// [`FAULT_CAPACITY`]; bursts of one kind at most one per
    /// [`FAULT_REPEAT_S`]).
    pub faults_detected: Vec<DetectedFault>,
    /// Detections left out of `faults_detected` (list full or repeats).
    pub faults_not_listed: u64,
}

/// Room for detected faults (preallocated: the loop never allocates).
pub const FAULT_CAPACITY: usize = 256;

/// A fault of one kind is listed at most once per this many seconds.
pub const FAULT_REPEAT_S: f64 = 0.5;

/// What the controller detected.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FaultKind {
    /// A motor's measured tension left what a healthy motor would give
    /// (`tendon`; `value` = measured − expected tension, N): safe hold,
    /// latched until restart.
    StuckMotor,
    /// A setpoint with a NaN/∞ (`value` = rejections so far).
    NonfiniteSetpoint,
    /// A setpoint with a non-unit quaternion (`value` = rejections so far).
    BadQuaternion,
    /// A setpoint outside the net's workspace box: target held.
    OutsideWorkspace,
    /// The setpoint watchdog tripped (`value` = silence, periods).
    WatchdogHold,
    /// Setpoints missing from the sequence (`value` = how many).
    SetpointsLost,
    /// Plant states missing from the sequence (`value` = how many).
    PlantStatesLost,
    /// The plant state had not applied the previous command (`value` =
    /// commands behind).
    CommandsNotApplied,
    /// No plant state for 20 periods (`value` = silence, periods).
    PlantStale,
    /// A weight update was rejected; the old net runs on.
    WeightsRejected,
}

pub(super) const FAULT_KINDS: usize = 10;

impl FaultKind {
    pub(super) fn slot(self) -> usize {
        self as usize
    }
}

/// One detection.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DetectedFault {
    /// What.
    pub kind: FaultKind,
    /// When, s since the controller's first period.
    pub t_s: f64,
    /// When, ns on the monotonic clock all processes share (for latencies
    /// against a launcher's own records).
    pub t_ns: u64,
    /// The tendon concerned, if any.
    pub tendon: Option<usize>,
    /// A number whose meaning the kind gives.
    pub value: f64,
    /// One line for people.
    pub detail: Cow<'static, str>,
}
