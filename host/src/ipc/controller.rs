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
use tendril_firmware::control::{
    control_step, ControlConfig, ControlState, Feedback, IntegralConfig, SafeHold,
    Setpoint as FwSetpoint, Status, StepInput,
};
use tendril_firmware::swap::NetSlots;
use tendril_shared::messages::{
    command_status, setpoint_flags, Header, PlantState, Setpoint, TensionCommand, WeightUpdate,
    MAX_TENDONS,
};
use tendril_shared::{TendonLimits, POSE_DIM};

use super::clock::{now_ns, tighten_timer_slack, Tick, Ticker};
use super::stats::{CsvLog, Histogram, Summary};
use super::transport::{self, Services};
use super::{IpcError, StopWatch};
use crate::robot::Robot;

/// Hidden-unit capacity of the controller's net buffers (the one capacity in
/// `tendril_shared`).
pub const NET_CAPACITY: usize = tendril_shared::MAX_HIDDEN;

/// The double-buffered net the controller runs.
pub type Slots = NetSlots<POSE_DIM, NET_CAPACITY, MAX_TENDONS, { tendril_shared::MAX_WEIGHTS }>;

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
    /// Die with the launching process ([`super::die_with_parent`]).
    pub supervised: bool,
    /// Per-period CSV log.
    pub log: Option<PathBuf>,
    /// Statistics JSON written at exit.
    pub stats: Option<PathBuf>,
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
            motor_tau_s: 0.02,
            tension_error_n: 0.5,
            persist_s: 0.1,
        }
    }
}

impl Default for ControllerConfig {
    fn default() -> Self {
        ControllerConfig::new("robots/seed-4t.toml".into(), "out/model.tnet".into())
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
            prefix: super::DEFAULT_PREFIX.into(),
            rate_hz: 1000.0,
            spin_us: 50.0,
            realtime: false,
            cpu: None,
            watchdog_periods: 2.5,
            ki_per_s: 0.0,
            correction_limit_m: 0.003,
            correction_window_m: 0.002,
            lead_s: 0.021,
            slew_n_per_s: 200.0,
            box_margin: 0.05,
            stuck_motor: StuckMotorDetection::default(),
            duration_s: None,
            peer_timeout_s: Some(2.0),
            supervised: false,
            log: None,
            stats: None,
        }
    }
}

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

const FAULT_KINDS: usize = 10;

impl FaultKind {
    fn slot(self) -> usize {
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

/// Messages that arrived since the last period (the newest of each kind).
#[derive(Clone, Copy, Debug, Default)]
pub struct Inbox<'a> {
    /// The newest setpoint.
    pub setpoint: Option<Setpoint>,
    /// How many setpoints arrived (the newest is kept).
    pub setpoints: usize,
    /// The newest plant state.
    pub state: Option<PlantState>,
    /// How many plant states arrived.
    pub states: usize,
    /// A weight update.
    pub weights: Option<&'a WeightUpdate>,
}

/// Stuck-motor detector: a first-order model of each healthy motor driven
/// by the commands sent, compared with the measured tensions.
#[derive(Clone, Copy, Debug)]
struct StuckDetector {
    cfg: StuckMotorDetection,
    /// 1 − exp(−T/τ): the model's step per period.
    gain: f32,
    expected: [f32; MAX_TENDONS],
    over_since: [Option<u64>; MAX_TENDONS],
    synced: bool,
}

impl StuckDetector {
    fn new(cfg: StuckMotorDetection, period_ns: u64) -> StuckDetector {
        let tau = cfg.motor_tau_s.max(1e-6);
        StuckDetector {
            cfg,
            gain: (1.0 - (-(period_ns as f64 * 1e-9) / tau).exp()) as f32,
            expected: [0.0; MAX_TENDONS],
            over_since: [None; MAX_TENDONS],
            synced: false,
        }
    }

    /// Forget the model (a new plant, or one back after a gap): the next
    /// measurement becomes the model's state.
    fn resync(&mut self) {
        self.synced = false;
        self.over_since = [None; MAX_TENDONS];
    }

    /// One fresh measurement at `now_ns` after `sent` was applied for about a
    /// period. Returns a stuck tendon and its tension error, if any.
    fn check(
        &mut self,
        now_ns: u64,
        sent: &[f32; MAX_TENDONS],
        measured: &[f32; MAX_TENDONS],
        n: usize,
    ) -> Option<(usize, f32)> {
        if !self.cfg.enabled {
            return None;
        }
        if !self.synced {
            self.expected = *measured;
            self.synced = true;
            return None;
        }
        let persist_ns = (self.cfg.persist_s.max(0.0) * 1e9) as u64;
        let mut stuck = None;
        for (i, ((e, (&c, &m)), since)) in self
            .expected
            .iter_mut()
            .zip(sent.iter().zip(measured))
            .zip(&mut self.over_since)
            .enumerate()
            .take(n)
        {
            *e += (c - *e) * self.gain;
            let err = m - *e;
            if err.is_finite() && err.abs() as f64 <= self.cfg.tension_error_n {
                *since = None;
                continue;
            }
            let from = *since.get_or_insert(now_ns);
            if now_ns - from >= persist_ns && stuck.is_none() {
                stuck = Some((i, err));
            }
        }
        stuck
    }
}

/// The controller task: configured once ([`Controller::new`]), then one
/// [`Controller::period`] per tick. Nothing in a period allocates: the
/// statistics are fixed histograms and counters, the fault list is
/// preallocated, the log row a fixed array.
pub struct Controller {
    fw: ControlConfig,
    slots: Box<Slots>,
    state: ControlState,
    n: usize,
    lead_s: f32,
    period_ns: u64,
    start_ns: u64,
    watchdog_periods: f64,
    stuck: StuckDetector,
    stats: ControllerStats,
    lateness: Histogram,
    work: Histogram,
    sp_age: Histogram,
    last_listed: [Option<u64>; FAULT_KINDS],
    local_sp_seq: u64,
    local_fb_seq: u64,
    last_sp: Option<Setpoint>,
    last_state: Option<PlantState>,
    last_state_ns: u64,
    stale: bool,
    in_hold: bool,
    outside: bool,
    tracking_started: bool,
    stuck_hold: bool,
    cmd: TensionCommand,
    row: [f64; LOG_FIXED + MAX_TENDONS],
}

impl Controller {
    /// Set up from `cfg`, the robot and the model bytes; the first period's
    /// deadline is `start_ns`.
    pub fn new(
        cfg: &ControllerConfig,
        robot: &Robot,
        model: &[u8],
        start_ns: u64,
    ) -> Result<Controller, IpcError> {
        if !(cfg.rate_hz > 0.0 && cfg.rate_hz <= 20_000.0) {
            return Err(IpcError::Config(format!(
                "controller rate {} Hz: must be in (0, 20000]",
                cfg.rate_hz
            )));
        }
        if !(cfg.ki_per_s >= 0.0
            && cfg.lead_s >= 0.0
            && cfg.slew_n_per_s > 0.0
            && cfg.watchdog_periods > 0.0)
        {
            return Err(IpcError::Config(
                "controller: ki and lead must be ≥ 0, slew rate and watchdog > 0".into(),
            ));
        }
        let n = robot.n_tendons();
        let max: Vec<f32> = robot.max_tensions().iter().map(|&v| v as f32).collect();
        let slew = vec![cfg.slew_n_per_s as f32; n];
        let limits = TendonLimits::new(&max, &slew)
            .map_err(|e| IpcError::Config(format!("tension limits: {e:?}")))?;
        let mut slots: Box<Slots> = Box::default();
        load_net(&mut slots, model, n)
            .map_err(|e| IpcError::Other(format!("{}: {e}", cfg.model.display())))?;

        let period_ns = (1e9 / cfg.rate_hz).round() as u64;
        let mut fw = ControlConfig::new(limits);
        fw.watchdog_ns = (cfg.watchdog_periods * period_ns as f64) as u64;
        fw.max_dt_ns = 5 * period_ns;
        fw.box_margin = cfg.box_margin as f32;
        fw.safe_hold = SafeHold::Freeze;
        if cfg.ki_per_s > 0.0 {
            fw.integral = IntegralConfig {
                ki: cfg.ki_per_s as f32,
                limit: cfg.correction_limit_m as f32,
                feedback_timeout_ns: 20 * period_ns,
                window: cfg.correction_window_m as f32,
            };
        }
        let mut stats = ControllerStats::default();
        stats.faults_detected.reserve_exact(FAULT_CAPACITY);
        Ok(Controller {
            state: ControlState::new(&limits, &[0.0; MAX_TENDONS], start_ns),
            fw,
            slots,
            n,
            lead_s: cfg.lead_s as f32,
            period_ns,
            start_ns,
            watchdog_periods: cfg.watchdog_periods,
            stuck: StuckDetector::new(cfg.stuck_motor, period_ns),
            stats,
            lateness: Histogram::default(),
            work: Histogram::default(),
            sp_age: Histogram::default(),
            last_listed: [None; FAULT_KINDS],
            local_sp_seq: 0,
            local_fb_seq: 0,
            last_sp: None,
            last_state: None,
            last_state_ns: start_ns,
            stale: false,
            in_hold: false,
            outside: false,
            tracking_started: false,
            stuck_hold: false,
            cmd: TensionCommand::default(),
            row: [0.0; LOG_FIXED + MAX_TENDONS],
        })
    }

    /// Period length, ns.
    pub fn period_ns(&self) -> u64 {
        self.period_ns
    }

    /// Number of tendons.
    pub fn n_tendons(&self) -> usize {
        self.n
    }

    /// List a fault (bounded, repeats of a kind thinned to one per
    /// [`FAULT_REPEAT_S`]); `detail` is static so listing never allocates.
    fn detect(
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
        if recent || self.stats.faults_detected.len() >= FAULT_CAPACITY {
            self.stats.faults_not_listed += 1;
            return;
        }
        if let Some(s) = slot {
            *s = Some(now_ns);
        }
        self.stats.faults_detected.push(DetectedFault {
            kind,
            t_s: now_ns.saturating_sub(self.start_ns) as f64 * 1e-9,
            t_ns: now_ns,
            tendon,
            value,
            detail: Cow::Borrowed(detail),
        });
    }

    fn swap_weights(&mut self, w: &WeightUpdate) -> u32 {
        let loaded = match w.payload() {
            Some(bytes) => self.slots.load(bytes, (POSE_DIM, self.n)).is_ok(),
            None => false,
        };
        if loaded {
            self.stats.weight_swaps += 1;
            log::info!(
                "controller: new weights swapped in (update #{})",
                w.header.seq
            );
            command_status::WEIGHTS_SWAPPED
        } else {
            self.stats.weight_rejections += 1;
            log::warn!(
                "controller: weight update #{} rejected (bad length, CRC or shape), old net kept",
                w.header.seq
            );
            command_status::WEIGHTS_REJECTED
        }
    }

    fn take_setpoint(&mut self, s: Setpoint, count: usize, t_wake: u64) -> FwSetpoint {
        self.stats.setpoints += 1;
        self.sp_age.record(t_wake.saturating_sub(s.header.stamp_ns));
        match self.last_sp {
            Some(p) if s.header.seq <= p.header.seq => {
                self.stats.planner_restarts += 1;
                log::info!(
                    "controller: setpoint sequence restarted at #{}: new planner",
                    s.header.seq
                );
            }
            Some(p) => {
                // `count` consecutive setpoints arrived, the newest is `s`.
                let lost = s.header.seq.saturating_sub(p.header.seq + count as u64);
                if lost > 0 {
                    self.stats.setpoints_lost += lost;
                    self.detect(
                        FaultKind::SetpointsLost,
                        t_wake,
                        None,
                        lost as f64,
                        "gap in the setpoint sequence",
                    );
                }
            }
            None => {}
        }
        self.local_sp_seq += 1;
        let mut pose = s.pose;
        if s.flags & setpoint_flags::HAS_VELOCITY != 0 && self.lead_s > 0.0 {
            for (p, v) in pose.iter_mut().zip(&s.velocity) {
                *p += v * self.lead_s;
            }
        }
        self.last_sp = Some(s);
        FwSetpoint {
            seq: self.local_sp_seq,
            pose,
            // The planner's tangent, for the firmware's integral loop.
            tangent: (s.flags & setpoint_flags::HAS_TANGENT != 0).then_some(s.tangent),
        }
    }

    fn take_state(&mut self, f: PlantState, count: usize, t_wake: u64) -> Feedback {
        match self.last_state {
            Some(p) if f.header.seq <= p.header.seq => {
                self.stats.plant_restarts += 1;
                self.stuck.resync();
                log::info!("controller: plant-state sequence restarted: new plant");
            }
            Some(p) => {
                let lost = f.header.seq.saturating_sub(p.header.seq + count as u64);
                if lost > 0 {
                    self.stats.plant_states_lost += lost;
                    self.detect(
                        FaultKind::PlantStatesLost,
                        t_wake,
                        None,
                        lost as f64,
                        "gap in the plant-state sequence",
                    );
                }
            }
            None => {}
        }
        if self.stale {
            self.stale = false;
            self.stats.plant_recoveries += 1;
            self.stuck.resync();
            log::info!("controller: plant state back after a gap");
        }
        // A plant that has applied commands before should have applied the
        // one sent a period ago (it steps within microseconds of the event).
        let behind = self.cmd.header.seq.saturating_sub(f.command_seq);
        if behind > 0 && f.command_seq > 0 {
            self.stats.commands_not_applied += 1;
            self.detect(
                FaultKind::CommandsNotApplied,
                t_wake,
                None,
                behind as f64,
                "the plant had not applied the previous tension command",
            );
        }
        if !self.stuck_hold {
            if let Some((tendon, err)) =
                self.stuck
                    .check(t_wake, &self.cmd.tensions, &f.tensions, self.n)
            {
                self.stuck_hold = true;
                log::error!(
                    "controller: motor {tendon} stuck (tension off by {err:.2} N): safe hold"
                );
                self.detect(
                    FaultKind::StuckMotor,
                    t_wake,
                    Some(tendon),
                    err as f64,
                    "measured tension left the healthy-motor model: safe hold",
                );
            }
        }
        self.local_fb_seq += 1;
        let mut tip = [f.tip_pose[0], f.tip_pose[1], f.tip_pose[2]];
        // Advance the measurement by the same lead as the setpoint.
        if let Some(s) = self
            .last_sp
            .filter(|s| s.flags & setpoint_flags::HAS_VELOCITY != 0)
        {
            for (p, v) in tip.iter_mut().zip(&s.velocity) {
                *p += v * self.lead_s;
            }
        }
        self.last_state = Some(f);
        self.last_state_ns = t_wake;
        Feedback {
            seq: self.local_fb_seq,
            tip_position: tip,
        }
    }

    /// Count what the firmware's status says and list what needs listing.
    fn account(&mut self, status: Status, t_wake: u64) {
        if status.contains(Status::NONFINITE_SETPOINT) {
            self.stats.rejected_nonfinite += 1;
            log::warn!("controller: setpoint with NaN/∞ rejected");
            let n = self.stats.rejected_nonfinite as f64;
            self.detect(
                FaultKind::NonfiniteSetpoint,
                t_wake,
                None,
                n,
                "setpoint with NaN/∞ rejected",
            );
        }
        if status.contains(Status::BAD_QUATERNION) {
            self.stats.rejected_quaternion += 1;
            log::warn!("controller: setpoint with a non-unit quaternion rejected");
            let n = self.stats.rejected_quaternion as f64;
            self.detect(
                FaultKind::BadQuaternion,
                t_wake,
                None,
                n,
                "setpoint with a non-unit quaternion rejected",
            );
        }
        let outside = status.contains(Status::OUT_OF_WORKSPACE);
        if outside {
            self.stats.rejected_workspace += 1;
            if !self.outside {
                log::warn!(
                    "controller: setpoint outside the workspace held ({} so far)",
                    self.stats.rejected_workspace
                );
                let n = self.stats.rejected_workspace as f64;
                self.detect(
                    FaultKind::OutsideWorkspace,
                    t_wake,
                    None,
                    n,
                    "setpoint outside the net's workspace: target held",
                );
            }
        }
        self.outside = outside;
        if status.contains(Status::NEW_SETPOINT) {
            self.tracking_started = true;
        }
        let hold = status.contains(Status::SAFE_HOLD);
        if !self.tracking_started {
            self.stats.startup_hold_cycles += 1;
        } else if hold {
            self.stats.hold_cycles += 1;
            if !self.in_hold {
                self.stats.watchdog_trips += 1;
                log::warn!(
                    "controller: no setpoint for {:.1} periods: safe hold",
                    self.watchdog_periods
                );
                let periods = self
                    .last_sp
                    .map_or(0.0, |s| t_wake.saturating_sub(s.header.stamp_ns) as f64)
                    / self.period_ns as f64;
                self.detect(
                    FaultKind::WatchdogHold,
                    t_wake,
                    None,
                    periods,
                    "no acceptable setpoint within the watchdog time: safe hold",
                );
            }
        } else if self.in_hold {
            log::info!("controller: setpoints back, tracking resumed");
        }
        self.in_hold = hold && self.tracking_started;
        if status.contains(Status::SATURATED) {
            self.stats.saturated_cycles += 1;
        }
        if status.contains(Status::CORRECTION) {
            self.stats.correction_cycles += 1;
        }
    }

    /// One period: take the inbox, run the firmware control step, and return
    /// the tension command to publish. `late` marks the previous period's
    /// overrun. Allocation-free.
    pub fn period(
        &mut self,
        tick: &Tick,
        t_wake: u64,
        late: bool,
        inbox: &Inbox,
    ) -> TensionCommand {
        self.lateness.record(tick.lateness_ns);
        let mut extra = 0u32;
        if late || tick.skipped > 0 {
            extra |= command_status::OVERRUN;
        }
        if let Some(w) = inbox.weights {
            extra |= self.swap_weights(w);
            if extra & command_status::WEIGHTS_REJECTED != 0 {
                self.detect(
                    FaultKind::WeightsRejected,
                    t_wake,
                    None,
                    w.header.seq as f64,
                    "weight update rejected: old net kept",
                );
            }
        }
        let setpoint = inbox
            .setpoint
            .map(|s| self.take_setpoint(s, inbox.setpoints, t_wake));
        let feedback = inbox
            .state
            .map(|f| self.take_state(f, inbox.states, t_wake));
        if feedback.is_none()
            && !self.stale
            && t_wake.saturating_sub(self.last_state_ns) > 20 * self.period_ns
        {
            self.stale = true;
            log::warn!("controller: no plant state for 20 periods");
            self.detect(
                FaultKind::PlantStale,
                t_wake,
                None,
                20.0,
                "no plant state for 20 periods",
            );
        }
        if self.stale {
            self.stats.plant_stale_cycles += 1;
            extra |= command_status::PLANT_STALE;
        }

        let input = StepInput {
            now_ns: tick.deadline_ns,
            setpoint,
            feedback,
        };
        let (next, out) = control_step(&self.fw, self.slots.active(), &self.state, &input);
        self.state = next;
        let mut status = out.status;
        let mut tensions = out.command;
        if self.stuck_hold {
            // A stuck motor: hold every tension where it is (the firmware's
            // own `SafeHold::Freeze`), latched until the controller restarts.
            status |= Status::SAFE_HOLD;
            tensions = self.cmd.tensions;
        }
        self.account(status, t_wake);

        self.cmd = TensionCommand {
            header: Header {
                seq: self.cmd.header.seq + 1,
                stamp_ns: 0,
            },
            setpoint_seq: self.last_sp.map_or(0, |s| s.header.seq),
            count: out.count as u32,
            status: status.bits() | extra,
            tensions,
        };
        self.row[0] = tick.deadline_ns as f64;
        self.row[1] = tick.lateness_ns as f64;
        self.row[3] = self.cmd.status as f64;
        self.row[4] = self.cmd.setpoint_seq as f64;
        self.row[5] = self.last_state.map_or(0.0, |s| s.header.seq as f64);
        for (dst, &t) in self.row[LOG_FIXED..].iter_mut().zip(&tensions) {
            *dst = t as f64;
        }
        self.cmd
    }

    /// Close the period: its work took `work_ns`. Returns the log row
    /// (`log_header` columns).
    pub fn finish(&mut self, work_ns: u64) -> &[f64] {
        self.work.record(work_ns);
        self.row[2] = work_ns as f64;
        let end = (LOG_FIXED + self.n).min(self.row.len());
        &self.row[..end]
    }

    /// The statistics so far, with the ticker's period counts.
    pub fn stats(&self, ticker: &Ticker) -> ControllerStats {
        let mut stats = self.stats.clone();
        stats.cycles = ticker.cycles;
        stats.overruns = ticker.overruns;
        stats.skipped = ticker.skipped;
        stats.overrun_fraction = ticker.overruns as f64 / ticker.cycles.max(1) as f64;
        stats.lateness_us = self.lateness.summary();
        stats.step_us = self.work.summary();
        stats.setpoint_age_us = self.sp_age.summary();
        stats
    }
}

/// Run the controller process until stopped (or its peers are lost).
pub fn run(cfg: &ControllerConfig) -> Result<ControllerStats, IpcError> {
    super::die_with_parent(cfg.supervised)?;
    let robot = Robot::load(&cfg.robot).map_err(|e| IpcError::Other(e.to_string()))?;
    let bytes = std::fs::read(&cfg.model).map_err(|source| IpcError::Io {
        path: cfg.model.clone(),
        source,
    })?;
    // Validate everything before touching shared memory.
    Controller::new(cfg, &robot, &bytes, 0)?;

    let node = transport::node("tendril-controller")?;
    let services = Services::open_or_create(&node, &cfg.prefix)?;
    let setpoints = transport::subscriber(&services.setpoint)?;
    let states = transport::subscriber(&services.plant_state)?;
    let weights = transport::subscriber(&services.weights)?;
    let commands = transport::publisher(&services.tension_cmd)?;
    let notifier = transport::notifier(&services.tension_cmd_event)?;
    let stop = StopWatch::new(&services)?;
    let n = robot.n_tendons();
    let mut log = CsvLog::create(cfg.log.as_deref(), &log_header(n))?;

    tighten_timer_slack();
    super::clock::apply_scheduling(
        "controller",
        cfg.cpu,
        cfg.realtime,
        super::clock::CONTROLLER_PRIORITY,
    );

    let period_ns = (1e9 / cfg.rate_hz).round() as u64;
    let start = now_ns() + period_ns;
    let mut ctl = Controller::new(cfg, &robot, &bytes, start)?;
    let mut ticker = Ticker::new(start, period_ns);
    let spin_ns = (cfg.spin_us * 1e3) as u64;
    let mut overran = false;
    let mut last_flush = start;
    let mut peers = super::PeerWatch::new(cfg.peer_timeout_s, start);
    let outcome = loop {
        let tick = ticker.wait(spin_ns);
        let t_wake = now_ns();
        // Newest messages since the last period.
        let (setpoint, n_sp) = transport::latest(&setpoints)?;
        let (state, n_st) = transport::latest(&states)?;
        let (update, _): (Option<WeightUpdate>, usize) = transport::latest(&weights)?;
        let inbox = Inbox {
            setpoint,
            setpoints: n_sp,
            state,
            states: n_st,
            weights: update.as_ref(),
        };
        let mut cmd = ctl.period(&tick, t_wake, overran, &inbox);
        cmd.header.stamp_ns = now_ns();
        transport::send(&commands, cmd)?;
        notifier
            .notify()
            .map_err(|e| IpcError::Send(format!("tension_cmd event: {e:?}")))?;
        let t_done = now_ns();
        overran = ticker.finish(t_done);
        log.row(ctl.finish(t_done - t_wake))?;
        if t_done - last_flush > 100_000_000 {
            log.flush()?;
            last_flush = t_done;
        }
        if stop.requested()
            || cfg
                .duration_s
                .is_some_and(|d| (t_done - start) as f64 * 1e-9 >= d)
        {
            break Ok(());
        }
        if setpoint.is_some() || state.is_some() {
            peers.heard(t_done);
        } else if peers.lost(t_done) {
            break Err(IpcError::PeersLost(format!(
                "controller: no setpoint and no plant state for {:.1} s",
                peers.silence_s(t_done)
            )));
        }
    };
    log.flush()?;
    let stats = ctl.stats(&ticker);
    if let Some(path) = &cfg.stats {
        let json = serde_json::to_vec_pretty(&stats).map_err(|e| IpcError::Other(e.to_string()))?;
        super::write_file(path, &json)?;
    }
    outcome.map(|()| stats)
}
