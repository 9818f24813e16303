//! What the controller reports: its statistics and the faults it detected
//! (`controller.json`).

use super::*;
use tendril_shared::link::wire::Telemetry;
use tendril_shared::link::FrameCounters;

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
    /// Times the loop fell behind and skipped periods (see
    /// [`crate::ipc::clock::Ticker::stalls`]).
    pub stalls: u64,
    /// Most periods skipped in one stall.
    pub longest_stall_periods: u64,
    /// Time the loop thread was runnable but had no CPU during the run
    /// (ms; another task, a throttle or wake-up latency had it), from
    /// [`crate::ipc::clock::CpuWait`]; `None` where the kernel does not say.
    pub cpu_wait_ms: Option<f64>,
    /// Of the skipped periods, those the loop spent waiting for a CPU at
    /// least as long: the machine's stall, not the loop's.
    pub skipped_waiting_for_cpu: u64,
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
    /// With the chip in the loop (`--mcu`): the link's statistics and the
    /// chip's own telemetry.
    pub link: Option<LinkStats>,
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

/// The controller's fault list: bounded, repeats of a kind thinned to one
/// per [`FAULT_REPEAT_S`], preallocated so listing never allocates.
#[derive(Clone, Debug)]
pub struct FaultLog {
    start_ns: u64,
    faults: Vec<DetectedFault>,
    not_listed: u64,
    last_listed: [Option<u64>; FAULT_KINDS],
    /// Kinds already logged as a warning (see [`FaultLog::warn_first`]).
    warned: [bool; FAULT_KINDS],
}

impl FaultLog {
    /// An empty list; times are reported from `start_ns`.
    pub fn new(start_ns: u64) -> FaultLog {
        FaultLog {
            start_ns,
            faults: Vec::with_capacity(FAULT_CAPACITY),
            not_listed: 0,
            last_listed: [None; FAULT_KINDS],
            warned: [false; FAULT_KINDS],
        }
    }

    /// Log `message` as a warning the first time `kind` happens, at debug
    /// level after that: a setpoint stream outside the net's box repeats
    /// the event every period it lasts (57 warnings in one `tendril run` of
    /// the three-segment robot), and the run's report counts them all.
    /// Returns whether it warned.
    fn warn_first(&mut self, kind: FaultKind, message: &str) -> bool {
        match self.warned.get_mut(kind.slot()) {
            Some(w) if !*w => {
                *w = true;
                log::warn!("{message} (repeats are counted in the report, not logged)");
                true
            }
            _ => {
                log::debug!("{message}");
                false
            }
        }
    }

    /// List a fault at `now_ns` (shared monotonic clock).
    pub fn detect(
        &mut self,
        kind: FaultKind,
        now_ns: u64,
        tendon: Option<usize>,
        value: f64,
        detail: &'static str,
    ) {
        let repeat_ns = (FAULT_REPEAT_S * 1e9) as u64;
        let slot = self.last_listed.get_mut(kind.slot());
        let recent = slot
            .as_ref()
            .and_then(|s| **s)
            .is_some_and(|t| now_ns.saturating_sub(t) < repeat_ns);
        if recent || self.faults.len() >= FAULT_CAPACITY {
            self.not_listed += 1;
            return;
        }
        if let Some(s) = slot {
            *s = Some(now_ns);
        }
        self.faults.push(DetectedFault {
            kind,
            t_s: now_ns.saturating_sub(self.start_ns) as f64 * 1e-9,
            t_ns: now_ns,
            tendon,
            value,
            detail: Cow::Borrowed(detail),
        });
    }

    /// List and log what one period of the firmware's controller reported
    /// (`events`, with its `counters` after that period) at `now_ns`;
    /// `update_seq` names the weight update in flight.
    pub fn report(
        &mut self,
        ev: &Events,
        counters: &Counters,
        now_ns: u64,
        period_ns: u64,
        update_seq: u64,
    ) {
        if ev.bits == 0 {
            return;
        }
        if ev.has(event::PLANNER_RESTART) {
            log::info!("controller: setpoint sequence restarted: new planner");
        }
        if ev.has(event::SETPOINTS_LOST) {
            let lost = ev.setpoints_lost as f64;
            self.detect(
                FaultKind::SetpointsLost,
                now_ns,
                None,
                lost,
                "gap in the setpoint sequence",
            );
        }
        if ev.has(event::PLANT_RESTART) {
            log::info!("controller: plant-state sequence restarted: new plant");
        }
        if ev.has(event::PLANT_STATES_LOST) {
            let lost = ev.plant_states_lost as f64;
            let detail = "gap in the plant-state sequence";
            self.detect(FaultKind::PlantStatesLost, now_ns, None, lost, detail);
        }
        if ev.has(event::PLANT_RECOVERED) {
            log::info!("controller: plant state back after a gap");
        }
        if ev.has(event::COMMANDS_NOT_APPLIED) {
            self.detect(
                FaultKind::CommandsNotApplied,
                now_ns,
                None,
                ev.commands_behind as f64,
                "the plant had not applied the previous tension command",
            );
        }
        if let (true, Some((tendon, err))) = (ev.has(event::STUCK_MOTOR), ev.stuck) {
            log::error!("controller: motor {tendon} stuck (tension off by {err:.2} N): safe hold");
            self.detect(
                FaultKind::StuckMotor,
                now_ns,
                Some(tendon as usize),
                err as f64,
                "measured tension left the healthy-motor model: safe hold",
            );
        }
        if ev.has(event::NONFINITE_SETPOINT) {
            self.warn_first(
                FaultKind::NonfiniteSetpoint,
                "controller: setpoint with NaN/∞ rejected",
            );
            let n = counters.rejected_nonfinite as f64;
            self.detect(
                FaultKind::NonfiniteSetpoint,
                now_ns,
                None,
                n,
                "setpoint with NaN/∞ rejected",
            );
        }
        if ev.has(event::BAD_QUATERNION) {
            self.warn_first(
                FaultKind::BadQuaternion,
                "controller: setpoint with a non-unit quaternion rejected",
            );
            let n = counters.rejected_quaternion as f64;
            let detail = "setpoint with a non-unit quaternion rejected";
            self.detect(FaultKind::BadQuaternion, now_ns, None, n, detail);
        }
        if ev.has(event::OUTSIDE_WORKSPACE) {
            self.warn_first(
                FaultKind::OutsideWorkspace,
                "controller: setpoint outside the workspace held",
            );
            let n = counters.rejected_workspace as f64;
            let detail = "setpoint outside the net's workspace: target held";
            self.detect(FaultKind::OutsideWorkspace, now_ns, None, n, detail);
        }
        if ev.has(event::WATCHDOG_HOLD) {
            log::debug!("controller: watchdog trip {}", counters.watchdog_trips);
            let periods = ev.hold_silence_ns as f64 / period_ns.max(1) as f64;
            self.detect(
                FaultKind::WatchdogHold,
                now_ns,
                None,
                periods,
                "no acceptable setpoint within the watchdog time: safe hold",
            );
        }
        if ev.has(event::TRACKING_RESUMED) {
            log::info!("controller: setpoints back, tracking resumed");
        }
        if ev.has(event::PLANT_STALE) {
            log::warn!("controller: no plant state for 20 periods");
            self.detect(
                FaultKind::PlantStale,
                now_ns,
                None,
                20.0,
                "no plant state for 20 periods",
            );
        }
        if ev.has(event::WEIGHTS_SWAPPED) {
            log::info!("controller: new weights swapped in (update #{update_seq})");
        }
        if ev.has(event::WEIGHTS_REJECTED) {
            match ev.update_error {
                Some(e) => log::warn!(
                    "controller: weight update #{update_seq} rejected ({e}), old net kept"
                ),
                None => {
                    log::warn!("controller: weight update #{update_seq} rejected, old net kept")
                }
            }
            let detail = "weight update rejected: old net kept";
            self.detect(
                FaultKind::WeightsRejected,
                now_ns,
                None,
                update_seq as f64,
                detail,
            );
        }
    }

    /// Put the list into `stats`.
    pub fn fill(&self, stats: &mut ControllerStats) {
        stats.faults_detected = self.faults.clone();
        stats.faults_not_listed = self.not_listed;
    }
}

impl ControllerStats {
    /// Take the firmware's counts (the period's rules counted them).
    pub fn fill_counters(&mut self, c: &Counters) {
        let u = u64::from;
        self.setpoints = u(c.setpoints);
        self.setpoints_lost = u(c.setpoints_lost);
        self.rejected_nonfinite = u(c.rejected_nonfinite);
        self.rejected_quaternion = u(c.rejected_quaternion);
        self.rejected_workspace = u(c.rejected_workspace);
        self.watchdog_trips = u(c.watchdog_trips);
        self.watchdog_trips_late_planner = u(c.watchdog_trips_late_planner);
        self.stuck_motor_holds = u(c.stuck_motor_holds);
        self.hold_cycles = u(c.hold_periods);
        self.startup_hold_cycles = u(c.startup_hold_periods);
        self.saturated_cycles = u(c.saturated_periods);
        self.correction_cycles = u(c.correction_periods);
        self.weight_swaps = u(c.weight_swaps);
        self.weight_rejections = u(c.weight_rejections);
        self.planner_restarts = u(c.planner_restarts);
        self.plant_restarts = u(c.plant_restarts);
        self.plant_states_lost = u(c.plant_states_lost);
        self.commands_not_applied = u(c.commands_not_applied);
        self.plant_stale_cycles = u(c.plant_stale_periods);
        self.plant_recoveries = u(c.plant_recoveries);
    }
}

/// The link's statistics in the controller's report.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct LinkStats {
    /// Commands the chip sent and the bridge published.
    pub commands: u64,
    /// Gaps in the chip's command sequence (periods whose command was lost
    /// on the link).
    pub commands_lost: u64,
    /// Setpoint forwarded → the first command that used it, µs (host clock,
    /// both ends).
    pub setpoint_to_command_us: Summary,
    /// The same in periods (p50, p99).
    pub setpoint_to_command_periods: (f64, f64),
    /// The bridge's receive-side frame counters.
    pub frames_up: FrameCounters,
    /// The chip's receive-side frame counters (its last telemetry).
    pub frames_down: FrameCounters,
    /// Bytes sent to / received from the chip.
    pub bytes_down: u64,
    /// Bytes received from the chip.
    pub bytes_up: u64,
    /// Garbage bytes injected (fault test).
    pub garbage_bytes_sent: u64,
    /// Weight updates sent / chunks sent.
    pub updates_sent: u64,
    /// Chunks sent.
    pub chunks_sent: u64,
    /// The chip's last telemetry.
    pub chip: Option<Telemetry>,
    /// The chip's telemetry when the bridge connected (a chip that ran
    /// before: its counts before this bridge).
    pub chip_at_connect: Option<Telemetry>,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One warning per kind and process, however often the event repeats;
    /// every occurrence still reaches the fault list's thinning.
    #[test]
    fn a_repeating_event_warns_once_per_kind() {
        let mut log = FaultLog::new(0);
        assert!(log.warn_first(FaultKind::OutsideWorkspace, "outside"));
        assert!(!log.warn_first(FaultKind::OutsideWorkspace, "outside"));
        assert!(log.warn_first(FaultKind::BadQuaternion, "quaternion"));
        assert!(!log.warn_first(FaultKind::BadQuaternion, "quaternion"));
    }
}
