//! The controller task: configured once, one allocation-free step per
//! period around the firmware's control step.

use super::*;

/// A watchdog hold this long (periods) is reported on the console; shorter
/// ones, a planner late by a few periods, only in the report.
const LONG_HOLD_PERIODS: u64 = 20;

/// Messages that arrived since the last period (the newest of each kind).
#[derive(Clone, Copy, Debug, Default)]
pub struct Inbox<'a> {
    /// The newest setpoint.
    pub setpoint: Option<Setpoint>,
    /// How many setpoints arrived (the newest is kept).
    pub setpoints: usize,
    /// How many of the older ones (replaced by the newest before the
    /// firmware saw them) had a NaN/∞ pose: never applied, but counted
    /// and reported like the ones the firmware rejects.
    pub superseded_nonfinite: usize,
    /// The newest plant state.
    pub state: Option<PlantState>,
    /// How many plant states arrived.
    pub states: usize,
    /// A weight update.
    pub weights: Option<&'a WeightUpdate>,
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
    /// When the current watchdog hold began (monotonic ns).
    hold_started_ns: u64,
    /// A lasting hold was reported on the console (once per run).
    hold_warned: bool,
    outside: bool,
    tracking_started: bool,
    stuck_hold: bool,
    /// Sequence number of the last setpoint before the current watchdog hold.
    hold_after_seq: Option<u64>,
    /// Setpoints lost (sequence gap) before the newest one taken.
    last_sp_gap: u64,
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
        let limits = crate::command_stage::limits_for(robot, cfg.slew_n_per_s)
            .map_err(|e| IpcError::Config(format!("tension limits: {e}")))?;
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
            hold_started_ns: 0,
            hold_warned: false,
            outside: false,
            tracking_started: false,
            stuck_hold: false,
            hold_after_seq: None,
            last_sp_gap: 0,
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
        self.last_sp_gap = 0;
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
                self.last_sp_gap = lost;
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
            // The planner's tangent, for the firmware's integral loop (which
            // checks its dimension and values).
            tangent: (s.flags & setpoint_flags::HAS_TANGENT != 0).then_some(FwTangent {
                dim: s.tangent_dim as usize,
                columns: s.tangent,
                axes: s.tangent_axes,
            }),
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
            if !self.in_hold && self.stuck_hold {
                // The stuck-motor hold, listed as `stuck_motor` already.
                self.stats.stuck_motor_holds += 1;
            } else if !self.in_hold {
                self.stats.watchdog_trips += 1;
                self.hold_after_seq = self.last_sp.map(|s| s.header.seq);
                self.hold_started_ns = t_wake;
                log::debug!("controller: watchdog trip {}", self.stats.watchdog_trips);
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
            } else if !self.stuck_hold && !self.hold_warned {
                // A planner a few periods late (a loaded machine) trips the
                // watchdog for a period or two: counted in the report, not
                // worth a console line. A hold that lasts is, once per run.
                let held = t_wake.saturating_sub(self.hold_started_ns) / self.period_ns.max(1);
                if held >= LONG_HOLD_PERIODS {
                    self.hold_warned = true;
                    log::warn!(
                        "controller: no setpoint for {held} periods: safe hold (later holds \
                         are counted in the report, not logged)"
                    );
                }
            }
        } else if self.in_hold {
            log::info!("controller: setpoints back, tracking resumed");
            let resumed_in_sequence = self.last_sp_gap == 0
                && self
                    .hold_after_seq
                    .zip(self.last_sp)
                    .is_some_and(|(before, s)| s.header.seq > before);
            if resumed_in_sequence {
                self.stats.watchdog_trips_late_planner += 1;
            }
            self.hold_after_seq = None;
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
        if inbox.superseded_nonfinite > 0 {
            self.stats.rejected_nonfinite += inbox.superseded_nonfinite as u64;
            log::warn!(
                "controller: {} setpoint(s) with NaN/∞ rejected (superseded in the same period)",
                inbox.superseded_nonfinite
            );
            let n = self.stats.rejected_nonfinite as f64;
            self.detect(
                FaultKind::NonfiniteSetpoint,
                t_wake,
                None,
                n,
                "setpoint with NaN/∞ rejected",
            );
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
