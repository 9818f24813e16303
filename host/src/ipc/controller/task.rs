//! The controller task: configured once, one allocation-free step per
//! period around the firmware's whole control period
//! ([`tendril_firmware::period::Period`]: every rule that decides what the
//! motors get is there, shared with the chip). The host keeps its clock,
//! its transport and its statistics.

use tendril_firmware::control::ControlTangent;
use tendril_firmware::period::{FeedbackIn, Inputs, Period, SetpointIn, Update, UpdateError};

use super::*;

/// A watchdog hold this long (periods) is reported on the console; shorter
/// ones, a planner late by a few periods, only in the report.
const LONG_HOLD_PERIODS: u64 = 20;

/// The host controller's period (the firmware's, unchanged).
pub type HostPeriod = Period;

/// The host's weight-update buffer: as large as the iceoryx2 message.
pub type HostUpdate = Update<WEIGHT_UPDATE_CAPACITY>;

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

/// The firmware's setpoint from the planner's message, for a period at
/// `now_ns` (its age is measured to it).
pub fn setpoint_in(s: &Setpoint, now_ns: u64) -> SetpointIn {
    SetpointIn {
        seq: s.header.seq,
        age_ns: now_ns.saturating_sub(s.header.stamp_ns),
        pose: s.pose,
        velocity: (s.flags & setpoint_flags::HAS_VELOCITY != 0).then_some(s.velocity),
        // The planner's tangent, for the firmware's integral loop (which
        // checks its dimension and values).
        tangent: (s.flags & setpoint_flags::HAS_TANGENT != 0).then_some(ControlTangent {
            dim: s.tangent_dim as usize,
            columns: s.tangent,
            axes: s.tangent_axes,
        }),
    }
}

/// The planner's setpoint with its dynamic offset applied, and the shift
/// every measured tip gets until the next setpoint (`docs/design.md` §6.4).
/// The pose moves by Σ_j d_j T_j along its tangent (its position by d
/// without one), as the period's correction moves a pose, so the net is
/// asked for the pose plus the offset; the tip moves by the same position
/// shift, so the period's error — setpoint less tip — is still the error
/// against the planner's pose. Done here, outside the period, for the host
/// controller and the chip's bridge alike: the chip's RAM and its worst
/// period had no room for it (BENCHMARKS.md). A non-finite offset makes a
/// non-finite pose, which the period refuses.
pub fn with_dynamic_offset(s: &Setpoint) -> (Setpoint, [f32; 3]) {
    if s.flags & setpoint_flags::HAS_DYNAMIC_OFFSET == 0 {
        return (*s, [0.0; 3]);
    }
    let d = s.dynamic_offset;
    let mut shift = [0.0f32; 7];
    let k = s.tangent_dim.min(3) as usize;
    if s.flags & setpoint_flags::HAS_TANGENT != 0 && k > 0 {
        for (column, dj) in s.tangent.iter().zip(d).take(k) {
            for (v, c) in shift.iter_mut().zip(column) {
                *v += c * dj;
            }
        }
    } else {
        shift[..3].copy_from_slice(&d);
    }
    let mut out = *s;
    for (p, v) in out.pose.iter_mut().zip(shift) {
        *p += v;
    }
    (out, [shift[0], shift[1], shift[2]])
}

/// Tracker frames held back while the robot is on a shaped move
/// (`docs/design.md` §6.4): the planner flags a shaped move's setpoints
/// `MOVING`, and until the quiet time after the last of them every plant
/// state goes to the period with the last frame from before the move, so
/// the period integrates no frame of the move's transient — what its jump
/// rule does for a jump, which a shaped move never makes. Done here, beside
/// the period, for the host controller and the chip's bridge alike: in the
/// period the rule cost the chip 960 instructions a period it did not have
/// (BENCHMARKS.md). The period credits the first frame after with at most
/// twice the interval of the one before it, not the gap
/// (`tendril_firmware::period::credited_interval`).
#[derive(Clone, Copy, Debug, Default)]
pub struct MoveQuiet {
    settle_ns: u64,
    until_ns: u64,
    held: Option<([f32; 7], u32, u64)>,
}

impl MoveQuiet {
    /// Quiet for `settle_s` after a move's last setpoint.
    pub fn new(settle_s: f64) -> MoveQuiet {
        MoveQuiet {
            settle_ns: (settle_s * 1e9) as u64,
            ..MoveQuiet::default()
        }
    }

    /// A setpoint arrived at `now_ns`.
    pub fn setpoint(&mut self, s: &Setpoint, now_ns: u64) {
        if s.flags & setpoint_flags::MOVING != 0 {
            self.until_ns = now_ns.saturating_add(self.settle_ns);
        }
    }

    /// The plant state as the period is to see it at `now_ns`.
    pub fn state(&mut self, f: &PlantState, now_ns: u64) -> PlantState {
        let mut out = *f;
        match self.held {
            Some((tip, seq, stamp)) if now_ns < self.until_ns => {
                out.tip_pose = tip;
                out.tip_seq = seq;
                out.tip_stamp_ns = stamp;
            }
            _ => self.held = Some((f.tip_pose, f.tip_seq, f.tip_stamp_ns)),
        }
        out
    }
}

/// The plant's state with its tip moved by `shift` (m): see
/// [`with_dynamic_offset`].
pub fn tip_shifted(f: &PlantState, shift: [f32; 3]) -> PlantState {
    let mut out = *f;
    for (p, s) in out.tip_pose.iter_mut().zip(shift) {
        *p += s;
    }
    out
}

/// The firmware's feedback from the plant's message, for a period at
/// `now_ns` (the tracker frame's age is measured to it).
pub fn feedback_in(f: &PlantState, now_ns: u64) -> FeedbackIn {
    FeedbackIn {
        seq: f.header.seq,
        command_seq: f.command_seq,
        tensions: f.tensions,
        tip: [f.tip_pose[0], f.tip_pose[1], f.tip_pose[2]],
        tip_seq: f.tip_seq,
        tip_age_ns: now_ns.saturating_sub(f.tip_stamp_ns),
    }
}

/// The firmware period's configuration from the controller's.
pub fn period_config(
    cfg: &ControllerConfig,
    robot: &Robot,
) -> Result<tendril_firmware::period::PeriodConfig, IpcError> {
    if !(cfg.rate_hz > 0.0 && cfg.rate_hz <= 20_000.0) {
        return Err(IpcError::Config(format!(
            "controller rate {} Hz: must be in (0, 20000]",
            cfg.rate_hz
        )));
    }
    if !(cfg.ki_per_s >= 0.0
        && cfg.correction_filter_tau_s >= 0.0
        && cfg.correction_map_gain_per_s >= 0.0
        && cfg.tracker_timeout_s > 0.0
        && cfg.lead_s >= 0.0
        && cfg.slew_n_per_s > 0.0
        && cfg.watchdog_periods > 0.0)
    {
        return Err(IpcError::Config(
            "controller: ki, the correction's filter and lead must be ≥ 0, slew rate, \
             watchdog and tracker timeout > 0"
                .into(),
        ));
    }
    let limits = crate::command_stage::limits_for(robot, cfg.slew_n_per_s)
        .map_err(|e| IpcError::Config(format!("tension limits: {e}")))?;
    let period_ns = (1e9 / cfg.rate_hz).round() as u64;
    let mut fw = ControlConfig::new(limits);
    fw.watchdog_ns = (cfg.watchdog_periods * period_ns as f64) as u64;
    fw.max_dt_ns = 5 * period_ns;
    fw.box_margin = cfg.box_margin as f32;
    fw.safe_hold = SafeHold::Freeze;
    if cfg.ki_per_s > 0.0 {
        let scale = if cfg.scale_gains_to_mode {
            correction::mode_scale(robot)
        } else {
            1.0
        };
        fw.integral = IntegralConfig {
            ki: (cfg.ki_per_s * scale) as f32,
            limit: cfg.correction_limit_m as f32,
            feedback_timeout_ns: ((cfg.tracker_timeout_s * 1e9) as u64).max(2 * period_ns),
            window: cfg.correction_window_m as f32,
            filter_tau_s: (cfg.correction_filter_tau_s / scale) as f32,
            map_gain: (cfg.correction_map_gain_per_s * scale) as f32,
            map_scale: correction::MAP_SCALE_M as f32,
            map_limit: correction::MAP_LIMIT as f32,
        };
    }
    let s = cfg.stuck_motor;
    let stuck = if s.enabled {
        StuckConfig::new(
            s.motor_tau_s as f32,
            s.tension_error_n as f32,
            s.persist_s as f32,
            period_ns,
        )
    } else {
        StuckConfig::OFF
    };
    Ok(tendril_firmware::period::PeriodConfig {
        control: fw,
        period_ns,
        lead_s: cfg.lead_s as f32,
        plant_stale_ns: 20 * period_ns,
        stuck,
        swap_slice_bytes: tendril_firmware::SWAP_SLICE_BYTES,
        jump_m: correction::JUMP_M as f32,
        settle_after_jump_ns: (correction::SETTLE_AFTER_JUMP_S * 1e9) as u64,
        // The plant's state comes back within the period over IPC.
        commands_in_flight: 0,
    })
}

/// The controller task: configured once ([`Controller::new`]), then one
/// [`Controller::period`] per tick. Nothing in a period allocates: the
/// statistics are fixed histograms and counters, the fault list is
/// preallocated, the log row a fixed array.
pub struct Controller {
    period: Box<HostPeriod>,
    update: Box<HostUpdate>,
    slots: Box<Slots>,
    n: usize,
    period_ns: u64,
    faults: FaultLog,
    lateness: Histogram,
    work: Histogram,
    sp_age: Histogram,
    /// When the current watchdog hold began (monotonic ns), if one is on.
    hold_started_ns: Option<u64>,
    /// A lasting hold was reported on the console (once per run).
    hold_warned: bool,
    /// Sequence number of the newest weight update offered.
    update_seq: u64,
    last_state_seq: u64,
    /// The newest setpoint's dynamic offset, m: every measured tip moves
    /// by it ([`with_dynamic_offset`]).
    tip_shift: [f32; 3],
    /// Frames held back over shaped moves.
    quiet: MoveQuiet,
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
        let pcfg = period_config(cfg, robot)?;
        let n = robot.n_tendons();
        let mut slots: Box<Slots> = Box::default();
        load_net(&mut slots, model, n)
            .map_err(|e| IpcError::Other(format!("{}: {e}", cfg.model.display())))?;
        let period = Box::new(HostPeriod::new(pcfg, start_ns));
        Ok(Controller {
            period,
            update: Box::default(),
            slots,
            n,
            period_ns: pcfg.period_ns,
            faults: FaultLog::new(start_ns),
            lateness: Histogram::default(),
            work: Histogram::default(),
            sp_age: Histogram::default(),
            hold_started_ns: None,
            hold_warned: false,
            update_seq: 0,
            last_state_seq: 0,
            tip_shift: [0.0; 3],
            quiet: MoveQuiet::new(correction::QUIET_AFTER_MOVE_S),
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

    /// One period: take the inbox, run the firmware's period, and return
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
        let mut refused = None;
        if let Some(w) = inbox.weights {
            self.update_seq = w.header.seq;
            let taken = match w.payload() {
                Some(bytes) => self.update.offer(bytes),
                None => Err(UpdateError::TooLarge {
                    len: w.len as usize,
                    capacity: WEIGHT_UPDATE_CAPACITY,
                }),
            };
            match taken {
                Ok(true) => log::warn!(
                    "controller: weight update #{} supersedes the one being checked",
                    w.header.seq
                ),
                Ok(false) => {}
                Err(e) => refused = Some(self.period.refuse_update(e)),
            }
        }
        if let Some(s) = &inbox.setpoint {
            self.sp_age.record(t_wake.saturating_sub(s.header.stamp_ns));
        }
        let shifted = inbox.setpoint.as_ref().map(|s| {
            self.quiet.setpoint(s, tick.deadline_ns);
            let (s, shift) = with_dynamic_offset(s);
            self.tip_shift = shift;
            s
        });
        let state = inbox
            .state
            .as_ref()
            .map(|f| tip_shifted(&self.quiet.state(f, tick.deadline_ns), self.tip_shift));
        let input = Inputs {
            now_ns: tick.deadline_ns,
            missed_ticks: if late || tick.skipped > 0 {
                (tick.skipped as u32).max(1)
            } else {
                0
            },
            setpoint: shifted.as_ref().map(|s| setpoint_in(s, tick.deadline_ns)),
            setpoints: inbox.setpoints as u32,
            superseded_nonfinite: inbox.superseded_nonfinite as u32,
            feedback: state.as_ref().map(|f| feedback_in(f, tick.deadline_ns)),
            feedbacks: inbox.states as u32,
        };
        if let Some(f) = &inbox.state {
            self.last_state_seq = f.header.seq;
        }
        let out = self.period.run(&mut *self.slots, &mut *self.update, &input);
        let counters = *self.period.counters();
        if let Some(ev) = refused {
            self.faults
                .report(&ev, &counters, t_wake, self.period_ns, self.update_seq);
        }
        self.faults.report(
            &out.events,
            &counters,
            t_wake,
            self.period_ns,
            self.update_seq,
        );
        self.watch_hold(t_wake);

        let c = out.command;
        let mut status = c.status;
        if let Some(ev) = refused {
            if ev.has(event::WEIGHTS_REJECTED) {
                status |= command_status::WEIGHTS_REJECTED;
            }
        }
        self.cmd = TensionCommand {
            header: Header {
                seq: c.seq,
                stamp_ns: 0,
            },
            setpoint_seq: c.setpoint_seq,
            count: c.count as u32,
            status,
            tensions: c.tensions,
            pad: Default::default(),
        };
        self.row[0] = tick.deadline_ns as f64;
        self.row[1] = tick.lateness_ns as f64;
        self.row[3] = self.cmd.status as f64;
        self.row[4] = self.cmd.setpoint_seq as f64;
        self.row[5] = self.last_state_seq as f64;
        for (dst, &t) in self.row[LOG_FIXED..].iter_mut().zip(&c.tensions) {
            *dst = t as f64;
        }
        self.cmd
    }

    /// A watchdog hold that lasts is worth one console line per run (a
    /// planner a few periods late, on a loaded machine, only in the report).
    fn watch_hold(&mut self, t_wake: u64) {
        let holding = self.cmd.status & command_status::SAFE_HOLD != 0 || self.period.holding();
        if !self.period.holding() || !holding {
            self.hold_started_ns = None;
            return;
        }
        let since = *self.hold_started_ns.get_or_insert(t_wake);
        let held = t_wake.saturating_sub(since) / self.period_ns.max(1);
        if held >= LONG_HOLD_PERIODS
            && !self.hold_warned
            && self.period.counters().stuck_motor_holds == 0
        {
            self.hold_warned = true;
            log::warn!(
                "controller: no setpoint for {held} periods: safe hold (later holds \
                 are counted in the report, not logged)"
            );
        }
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
        let mut stats = ControllerStats::default();
        stats.fill_counters(self.period.counters());
        self.faults.fill(&mut stats);
        stats.cycles = ticker.cycles;
        stats.overruns = ticker.overruns;
        stats.skipped = ticker.skipped;
        stats.stalls = ticker.stalls;
        stats.longest_stall_periods = ticker.longest_stall;
        stats.overrun_fraction = ticker.overruns as f64 / ticker.cycles.max(1) as f64;
        stats.lateness_us = self.lateness.summary();
        stats.step_us = self.work.summary();
        stats.setpoint_age_us = self.sp_age.summary();
        stats
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn setpoint(flags: u32, offset: [f32; 3]) -> Setpoint {
        Setpoint {
            pose: [0.01, 0.0, 0.39, 1.0, 0.0, 0.0, 0.0],
            // A tangent of two columns: x moves qy, y moves qx.
            tangent: [
                [1.0, 0.0, -0.1, 0.0, 0.0, 2.0, 0.0],
                [0.0, 1.0, 0.0, 0.0, -2.0, 0.0, 0.0],
                [0.0; 7],
            ],
            tangent_axes: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0; 3]],
            tangent_dim: 2,
            flags,
            dynamic_offset: offset,
            ..Setpoint::default()
        }
    }

    /// The offset moves the pose along the tangent (orientation included)
    /// and the tip by the same position shift, so setpoint less tip is the
    /// error against the planner's pose; without the flag nothing moves; a
    /// NaN offset makes a NaN pose, which the period refuses.
    #[test]
    fn the_dynamic_offset_moves_the_pose_along_the_tangent_and_the_tip_alike() {
        let flags = setpoint_flags::HAS_TANGENT | setpoint_flags::HAS_DYNAMIC_OFFSET;
        let s = setpoint(flags, [2e-4, -1e-4, 5.0]);
        let (moved, shift) = with_dynamic_offset(&s);
        let want = [0.01 + 2e-4, -1e-4, 0.39 - 2e-5, 1.0, 2e-4, 4e-4, 0.0];
        for (k, (a, b)) in moved.pose.iter().zip(want).enumerate() {
            assert!((a - b).abs() < 1e-7, "pose[{k}] {a} vs {b}");
        }
        for k in 0..3 {
            assert!(
                (shift[k] - (moved.pose[k] - s.pose[k])).abs() < 1e-7,
                "shift {shift:?}"
            );
        }
        let tip = PlantState {
            tip_pose: [0.0101, 0.0002, 0.3899, 1.0, 0.0, 0.0, 0.0],
            ..PlantState::default()
        };
        let shifted = tip_shifted(&tip, shift);
        for k in 0..3 {
            let before = s.pose[k] - tip.tip_pose[k];
            let after = moved.pose[k] - shifted.tip_pose[k];
            assert!(
                (before - after).abs() < 1e-7,
                "axis {k}: {before} vs {after}"
            );
        }
        let (plain, none) = with_dynamic_offset(&setpoint(setpoint_flags::HAS_TANGENT, [1.0; 3]));
        assert_eq!((plain.pose, none), (s.pose, [0.0; 3]));
        let (no_tangent, shift) = with_dynamic_offset(&setpoint(
            setpoint_flags::HAS_DYNAMIC_OFFSET,
            [1e-4, 0.0, 2e-4],
        ));
        assert_eq!(shift, [1e-4, 0.0, 2e-4]);
        assert_eq!(no_tangent.pose[3..], s.pose[3..]);
        let (nan, _) = with_dynamic_offset(&setpoint(flags, [f32::NAN, 0.0, 0.0]));
        assert!(nan.pose.iter().any(|v| v.is_nan()));
    }

    /// Frames pass until a shaped move's setpoint; from then until the
    /// settle time after its last one the period gets the frame from
    /// before the move (no new frame to integrate); then frames pass again.
    #[test]
    fn frames_are_held_over_a_shaped_move_and_its_settle() {
        let ms = 1_000_000u64;
        let mut quiet = MoveQuiet::new(0.3);
        let frame = |seq: u32| PlantState {
            tip_pose: [seq as f32 * 1e-3, 0.0, 0.4, 1.0, 0.0, 0.0, 0.0],
            tip_seq: seq,
            tip_stamp_ns: u64::from(seq) * ms,
            ..PlantState::default()
        };
        assert_eq!(quiet.state(&frame(1), ms).tip_seq, 1);
        let moving = Setpoint {
            flags: setpoint_flags::MOVING,
            ..Setpoint::default()
        };
        for k in 2..=100u32 {
            let now = u64::from(k) * ms;
            if k <= 50 {
                quiet.setpoint(&moving, now);
            } else {
                quiet.setpoint(&Setpoint::default(), now);
            }
            let seen = quiet.state(&frame(k), now);
            assert_eq!(seen.tip_seq, 1, "period {k}");
            assert_eq!(seen.tip_pose, frame(1).tip_pose);
        }
        // 50 ms + 300 ms: held until 350 ms, passed from then.
        assert_eq!(quiet.state(&frame(349), 349 * ms).tip_seq, 1);
        assert_eq!(quiet.state(&frame(350), 350 * ms).tip_seq, 350);
        assert_eq!(quiet.state(&frame(351), 351 * ms).tip_seq, 351);
    }
}
