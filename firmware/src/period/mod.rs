//! The whole control period (docs/design.md §5.5): configured once, then one
//! [`Period::run`] per tick, on the chip and in the host's controller
//! process alike. Around the control step
//! ([`crate::control::control_step_in_place`]) it holds every rule that
//! decides what the motors get:
//!
//! 1. the period's overrun (ticks missed before it);
//! 2. one bounded slice of a weight update's check or install
//!    ([`update`]: the old net runs until the new one is whole and checked);
//! 3. setpoint acceptance: the sender's sequence (gaps counted, a restart =
//!    a new planner), the *lead* by the motor lag and the setpoint's own
//!    age (`pose + velocity · (lead + age)`: the tip is asked for where the
//!    path is now, not where it was when the planner sent it), then the
//!    step's own NaN/∞, quaternion and workspace rules;
//! 4. plant feedback: its sequence (gaps, restarts), commands the plant had
//!    not applied, the stuck-motor detector ([`stuck`]) and its latched
//!    hold; and the tracker's tip, only when a new frame arrived (a tracker
//!    at 40 Hz gives one frame in 25 periods at 1 kHz: the others must not
//!    integrate it again), led along the path by the motor lag *and its
//!    own age* (so the integral loop integrates `p_desired(t) −
//!    p_measured(t)` for the time the frame was taken), with the time
//!    since the previous frame as its integration interval, at most twice
//!    the previous frame's (25 ms after the first:
//!    [`credited_interval`], a gap is no jump);
//! 5. plant-stale: no feedback for [`PeriodConfig::plant_stale_ns`];
//! 6. the control step (watchdog → safe hold, integral correction,
//!    inference, command stage, slew); in the period that installed a
//!    weight update without inference, the target held
//!    ([`control_step_in_place`]: the install and a net's run do not
//!    both fit the chip's period);
//! 7. the status word, the [`Counters`] and this period's [`Events`].
//!
//! Nothing here allocates, panics or reads a clock: time comes in
//! [`Inputs::now_ns`], so a recorded input trace replays to the same
//! commands bit for bit on any build.

mod configure;
mod stuck;
#[cfg(test)]
mod tests;
pub mod update;

pub use stuck::StuckConfig;
pub use tendril_shared::counters::Counters;
pub use update::{SliceOutcome, Update, UpdateError};

use tendril_shared::messages::command_status as wire;
use tendril_shared::{MAX_HIDDEN, MAX_TENDONS, MAX_WEIGHTS, POSE_DIM};

use crate::control::{
    control_step_in_place, ControlConfig, ControlSetpoint, ControlState, ControlTangent, Feedback,
    Status, StepInput, Tensions,
};
use crate::swap::NetStore;
use stuck::StuckDetector;

/// Everything a period needs besides the net, fixed at configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PeriodConfig {
    /// The control step's configuration (limits, watchdog, integral loop).
    pub control: ControlConfig,
    /// The period, ns.
    pub period_ns: u64,
    /// Motor-lag lead: the setpoint is advanced by `velocity · lead_s`, s.
    pub lead_s: f32,
    /// No plant feedback for this long marks the plant stale, ns.
    pub plant_stale_ns: u64,
    /// Stuck-motor detection.
    pub stuck: StuckConfig,
    /// Bytes of an update's check per period (hashing, value scan).
    pub swap_slice_bytes: usize,
    /// A setpoint whose position moved more than this since the last one is
    /// a *jump* (a step target, not a path), m.
    pub jump_m: f32,
    /// Tracker frames sampled within this long after a jump are not
    /// integrated: the robot is still on its way (motor lag, the rod's
    /// swing), and its error then is the step's, not the model's, ns.
    pub settle_after_jump_ns: u64,
    /// Commands the plant may be behind without it being a fault: those
    /// still on their way when its state was sent. 0 where the state comes
    /// back within the period; over a link whose round trip can exceed
    /// the period, 1 ([`crate::node::LINK_COMMANDS_IN_FLIGHT`]).
    pub commands_in_flight: u8,
}

/// The longest interval the second frame is credited with, ns (the first
/// is credited nothing: there is no interval before it): a 40 Hz
/// tracker's, the slowest the loop's gains are designed for
/// (docs/design.md §6.3), so such a tracker counts its full 25 ms from its
/// second frame on.
pub const FIRST_INTERVAL_BOUND_NS: u64 = 25_000_000;

/// The time a new frame is integrated over (the feedback's `interval_s`):
/// the time since the frame before, but at most twice that frame's own
/// credit (`previous_credit_ns`), and at most [`FIRST_INTERVAL_BOUND_NS`]
/// after a frame credited nothing (the first).
///
/// Why a bound: after a gap in the frames — a tracker that lost the
/// marker, or the frames held back while the robot was on a shaped move —
/// the first frame would otherwise carry the whole gap (up to the tracker
/// timeout, 0.25 s) into the integral and its filter at once: a step in
/// the correction, which rings a rod with mass (measured on a robot 10 %
/// off its file: 1.1 mm of model error corrected in one frame after a
/// 10 mm step, and the rod rang at its mode for 2 s). The integral's rate
/// stays independent of the tracker's (a 40 Hz tracker's frame still
/// counts 25 ms), a dropped frame still counts twice, and a tracker that
/// slows down is followed within a few frames.
///
/// Why the second frame is bounded too: a planner that starts with a
/// shaped approach from rest holds the frames back from the first on, so
/// the second frame the period sees comes after the approach and its
/// quiet, ≈ 0.7 s later. Unbounded, it was credited the tracker timeout:
/// on the default robot 10 % off its file the correction jumped 1.3–1.8 mm
/// at once and the rod rang for 3 s at the first target, in the runs where
/// no second frame slipped through before the approach began.
pub fn credited_interval(since_previous_ns: u64, previous_credit_ns: u64) -> u64 {
    let bound = if previous_credit_ns == 0 {
        FIRST_INTERVAL_BOUND_NS
    } else {
        previous_credit_ns.saturating_mul(2)
    };
    since_previous_ns.min(bound)
}

/// Largest frame age the lead compensates, ns: an older frame is led as if
/// it were this old (a tracker delivering later than this is broken, and
/// extrapolating along the path further would be a guess).
pub const MAX_TIP_AGE_NS: u64 = 200_000_000;

/// Largest setpoint age the lead compensates, ns: an older setpoint is led
/// as if it were this old (a link slower than this is broken; leading along
/// the path further would be a guess).
pub const MAX_SETPOINT_AGE_NS: u64 = 50_000_000;

/// A setpoint as the period takes it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SetpointIn {
    /// The sender's sequence number (1 for its first).
    pub seq: u64,
    /// Desired tip pose `px, py, pz` (m), `qw, qx, qy, qz`.
    pub pose: [f32; POSE_DIM],
    /// Its time derivative (per s), when the planner sent one: the lead.
    pub velocity: Option<[f32; POSE_DIM]>,
    /// The reachable poses about it (for the integral loop), if sent.
    pub tangent: Option<ControlTangent>,
    /// How long before this period the planner sent it, ns (0: not known).
    /// A controller at 100 Hz takes a setpoint up to a period after it was
    /// sent (the chip another half over its link): uncompensated, the tip
    /// trails the path by that much, a lag that changes from run to run
    /// with the phase between planner and controller (2.3–6.8 ms on the
    /// host at 100 Hz, 0.04–0.13 mm on the default circle).
    pub age_ns: u64,
}

/// Plant feedback as the period takes it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FeedbackIn {
    /// The sender's sequence number (1 for its first).
    pub seq: u64,
    /// Sequence number of the last command the plant applied (0 = none).
    pub command_seq: u64,
    /// Measured tensions, N.
    pub tensions: Tensions,
    /// The tracker's newest tip position, m.
    pub tip: [f32; 3],
    /// Its frame number (0 = none yet): a frame is integrated once, in the
    /// first period that sees it.
    pub tip_seq: u32,
    /// How long before this period the tracker sampled `tip`, ns (its
    /// latency plus the transport's): the sample is compared with the
    /// path where the robot was then ([`Period`] docs, step 4).
    pub tip_age_ns: u64,
}

/// What arrived since the last period, and when this period runs.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Inputs {
    /// This period's time (its tick), ns on the controller's clock.
    pub now_ns: u64,
    /// Ticks missed before this one.
    pub missed_ticks: u32,
    /// The newest setpoint.
    pub setpoint: Option<SetpointIn>,
    /// How many setpoints arrived (the newest is taken).
    pub setpoints: u32,
    /// How many of the older ones, superseded before a period saw them,
    /// had a NaN/∞ pose (never applied; counted as rejected).
    pub superseded_nonfinite: u32,
    /// The newest plant feedback.
    pub feedback: Option<FeedbackIn>,
    /// How many feedback messages arrived.
    pub feedbacks: u32,
}

/// Bits of [`Events::bits`]: what happened this period that a report lists.
pub mod event {
    /// Setpoints were lost in a gap of the sequence ([`super::Events::setpoints_lost`]).
    pub const SETPOINTS_LOST: u32 = 1 << 0;
    /// The setpoint sequence restarted: a new planner.
    pub const PLANNER_RESTART: u32 = 1 << 1;
    /// The plant-state sequence restarted: a new plant.
    pub const PLANT_RESTART: u32 = 1 << 2;
    /// Plant states were lost in a gap ([`super::Events::plant_states_lost`]).
    pub const PLANT_STATES_LOST: u32 = 1 << 3;
    /// Feedback is back after the plant was stale.
    pub const PLANT_RECOVERED: u32 = 1 << 4;
    /// The plant had not applied the previous command ([`super::Events::commands_behind`]).
    pub const COMMANDS_NOT_APPLIED: u32 = 1 << 5;
    /// A motor is stuck: hold latched ([`super::Events::stuck`]).
    pub const STUCK_MOTOR: u32 = 1 << 6;
    /// A setpoint with NaN/∞ was rejected.
    pub const NONFINITE_SETPOINT: u32 = 1 << 7;
    /// A setpoint with a non-unit quaternion was rejected.
    pub const BAD_QUATERNION: u32 = 1 << 8;
    /// Setpoints began to lie outside the workspace (first of a run).
    pub const OUTSIDE_WORKSPACE: u32 = 1 << 9;
    /// The watchdog's safe hold began ([`super::Events::hold_silence_ns`]).
    pub const WATCHDOG_HOLD: u32 = 1 << 10;
    /// Tracking resumed after a hold.
    pub const TRACKING_RESUMED: u32 = 1 << 11;
    /// No feedback for the stale time: the correction is frozen.
    pub const PLANT_STALE: u32 = 1 << 12;
    /// A new net runs from this period on.
    pub const WEIGHTS_SWAPPED: u32 = 1 << 13;
    /// A weight update was refused ([`super::Events::update_error`]).
    pub const WEIGHTS_REJECTED: u32 = 1 << 14;
}

/// What happened this period, beyond the status word: [`event`] bits and
/// their values.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Events {
    /// [`event`] bits.
    pub bits: u32,
    /// Setpoints lost in the gap before this one.
    pub setpoints_lost: u64,
    /// Plant states lost in the gap before this one.
    pub plant_states_lost: u64,
    /// Commands the plant was behind.
    pub commands_behind: u64,
    /// The stuck tendon and its tension error, N.
    pub stuck: Option<(u8, f32)>,
    /// Silence since the last acceptable setpoint when the hold began, ns.
    pub hold_silence_ns: u64,
    /// Why an update was refused.
    pub update_error: Option<UpdateError>,
}

impl Events {
    /// Whether any bit of `bits` is set.
    pub const fn has(&self, bits: u32) -> bool {
        self.bits & bits != 0
    }
}

/// The command a period produces.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PeriodCommand {
    /// Command sequence number (1 for the first period).
    pub seq: u64,
    /// The sender's sequence number of the last setpoint taken (0 = none).
    pub setpoint_seq: u64,
    /// Sequence number of the last plant feedback taken (0 = none).
    pub feedback_seq: u64,
    /// Tensions, N (the first `count`).
    pub tensions: Tensions,
    /// Number of tendons.
    pub count: usize,
    /// The status word: the wire bits of
    /// `tendril_shared::messages::command_status` and the step's detail bits.
    pub status: u32,
}

/// One period's result.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Outputs {
    /// What the motors get.
    pub command: PeriodCommand,
    /// What the report lists.
    pub events: Events,
}

/// The controller: configured once ([`Period::new`], or in place:
/// [`Period::configure`]), then [`Period::run`] once per tick. The weight
/// update in progress is the caller's ([`Update`], lent to each run): it is
/// the receive buffer, kilobytes the period's own state (about 1.1 KB)
/// should not carry; on the chip both live in the node's `static`.
#[derive(Clone, Debug)]
pub struct Period {
    cfg: PeriodConfig,
    n: usize,
    state: ControlState,
    stuck: StuckDetector,
    counters: Counters,
    cmd: PeriodCommand,
    /// The last setpoint taken: sender's sequence and velocity.
    last_sp: Option<(u64, Option<[f32; POSE_DIM]>)>,
    last_fb_seq: Option<u64>,
    /// The last tracker frame taken: its number, when it was sampled, and
    /// the interval it was credited with, ns.
    last_tip: Option<(u32, u64, u64)>,
    /// The last setpoint's position, m.
    last_sp_position: Option<[f32; 3]>,
    /// Frames sampled before this are not integrated (after a jump), ns.
    quiet_until_ns: u64,
    local_sp_seq: u64,
    local_fb_seq: u64,
    last_feedback_ns: u64,
    last_setpoint_ns: u64,
    stale: bool,
    in_hold: bool,
    outside: bool,
    tracking_started: bool,
    stuck_hold: bool,
    hold_after_seq: Option<u64>,
    last_sp_gap: u64,
}

impl Period {
    /// The configuration.
    pub const fn config(&self) -> &PeriodConfig {
        &self.cfg
    }

    /// The counts so far.
    pub const fn counters(&self) -> &Counters {
        &self.counters
    }

    /// The last command (the floors before the first period).
    pub const fn last_command(&self) -> &PeriodCommand {
        &self.cmd
    }

    /// The integral correction and its error map so far
    /// ([`crate::control::IntegralConfig`]).
    pub const fn correction(&self) -> ([f32; 3], [[f32; 3]; 3]) {
        (self.state.correction, self.state.error_map)
    }

    /// Whether a hold is on (watchdog or stuck motor).
    pub const fn holding(&self) -> bool {
        self.in_hold || self.stuck_hold
    }

    /// One period on the net in `store`; `update` is the weight update in
    /// progress (fed whole with [`Update::offer`] or in chunks with
    /// [`Update::chunk`]), of which this period checks or installs one slice.
    pub fn run<S, const U: usize>(
        &mut self,
        store: &mut S,
        update: &mut Update<U>,
        input: &Inputs,
    ) -> Outputs
    where
        S: NetStore<POSE_DIM, MAX_HIDDEN, MAX_TENDONS, MAX_WEIGHTS> + ?Sized,
    {
        let now = input.now_ns;
        let mut ev = Events::default();
        let mut extra = 0u32;
        self.counters.periods = self.counters.periods.wrapping_add(1);
        if input.missed_ticks > 0 {
            extra |= wire::OVERRUN;
            self.counters.missed_ticks =
                self.counters.missed_ticks.wrapping_add(input.missed_ticks);
        }

        let mut installed = false;
        match update.slice(store, (POSE_DIM, self.n), self.cfg.swap_slice_bytes) {
            SliceOutcome::Idle | SliceOutcome::Working => {}
            SliceOutcome::Swapped => {
                installed = true;
                self.counters.weight_swaps += 1;
                extra |= wire::WEIGHTS_SWAPPED;
                ev.bits |= event::WEIGHTS_SWAPPED;
            }
            SliceOutcome::Rejected(e) => self.reject_update(&mut ev, &mut extra, e.into()),
        }

        if input.superseded_nonfinite > 0 {
            self.counters.rejected_nonfinite += input.superseded_nonfinite;
            ev.bits |= event::NONFINITE_SETPOINT;
        }
        // Taken by reference, straight into the step's input (the setpoint,
        // with its tangent, written in place): copies would sit in this
        // frame under the control step and the inference, the chip's
        // deepest stack (tests/tests/mcu_budget.rs).
        let mut step = StepInput {
            now_ns: now,
            setpoint: None,
            feedback: None,
        };
        if let Some(s) = &input.setpoint {
            self.take_setpoint(s, input.setpoints, now, &mut ev, &mut step.setpoint);
        }
        step.feedback = input
            .feedback
            .as_ref()
            .and_then(|f| self.take_feedback(f, input.feedbacks, now, &mut ev));
        if input.feedback.is_none()
            && !self.stale
            && now.saturating_sub(self.last_feedback_ns) > self.cfg.plant_stale_ns
        {
            self.stale = true;
            ev.bits |= event::PLANT_STALE;
        }
        if self.stale {
            self.counters.plant_stale_periods += 1;
            extra |= wire::PLANT_STALE;
        }

        // The period that wrote the new net does not also run it (the
        // chip's period budget): the target stays one period.
        let out = control_step_in_place(
            &self.cfg.control,
            store.active(),
            &mut self.state,
            &step,
            !installed,
        );
        let mut status = out.status;
        let mut tensions = out.command;
        if self.stuck_hold {
            // A stuck motor: hold every tension where it is, latched until
            // the controller is configured again.
            status |= Status::SAFE_HOLD;
            tensions = self.cmd.tensions;
        }
        self.account(status, now, &mut ev);
        self.cmd = PeriodCommand {
            seq: self.cmd.seq + 1,
            setpoint_seq: self.last_sp.map_or(0, |(seq, _)| seq),
            feedback_seq: self.last_fb_seq.unwrap_or(0),
            tensions,
            count: out.count,
            status: status.bits() | extra,
        };
        Outputs {
            command: self.cmd,
            events: ev,
        }
    }

    /// Count and report an update that was refused (by the check, or as a
    /// chunk that could not be taken: [`Period::refuse_update`]).
    fn reject_update(&mut self, ev: &mut Events, extra: &mut u32, e: UpdateError) {
        self.counters.weight_rejections += 1;
        *extra |= wire::WEIGHTS_REJECTED;
        ev.bits |= event::WEIGHTS_REJECTED;
        ev.update_error = Some(e);
    }

    /// A weight update (or chunk) the caller could not hand over, counted
    /// as a rejection: returns the events to merge into the next output.
    pub fn refuse_update(&mut self, e: UpdateError) -> Events {
        let mut ev = Events::default();
        let mut extra = 0;
        self.reject_update(&mut ev, &mut extra, e);
        ev
    }

    /// The setpoint `s` for the step, into `out`.
    fn take_setpoint(
        &mut self,
        s: &SetpointIn,
        count: u32,
        now: u64,
        ev: &mut Events,
        out: &mut Option<ControlSetpoint>,
    ) {
        let position = [s.pose[0], s.pose[1], s.pose[2]];
        if let Some(before) = self.last_sp_position {
            let d2 = position
                .iter()
                .zip(&before)
                .fold(0.0f32, |sum, (a, b)| sum + (a - b) * (a - b));
            // NaN positions compare false: not a jump (they are refused).
            if d2 > self.cfg.jump_m * self.cfg.jump_m {
                self.quiet_until_ns = now.saturating_add(self.cfg.settle_after_jump_ns);
            }
        }
        if position.iter().all(|v| v.is_finite()) {
            self.last_sp_position = Some(position);
        }
        self.counters.setpoints += 1;
        self.last_sp_gap = 0;
        match self.last_sp {
            Some((prev, _)) if s.seq <= prev => {
                self.counters.planner_restarts += 1;
                ev.bits |= event::PLANNER_RESTART;
            }
            Some((prev, _)) => {
                // `count` consecutive setpoints arrived, the newest is `s`.
                let lost = s
                    .seq
                    .saturating_sub(prev.saturating_add(u64::from(count.max(1))));
                self.last_sp_gap = lost;
                if lost > 0 {
                    self.counters.setpoints_lost =
                        self.counters.setpoints_lost.wrapping_add(lost as u32);
                    ev.bits |= event::SETPOINTS_LOST;
                    ev.setpoints_lost = lost;
                }
            }
            None => {}
        }
        self.local_sp_seq += 1;
        let mut pose = s.pose;
        if let Some(v) = s.velocity {
            let lead_s = self.cfg.lead_s + s.age_ns.min(MAX_SETPOINT_AGE_NS) as f32 * 1e-9;
            for (p, v) in pose.iter_mut().zip(&v) {
                *p += v * lead_s;
            }
        }
        self.last_sp = Some((s.seq, s.velocity));
        *out = Some(ControlSetpoint {
            seq: self.local_sp_seq,
            pose,
            tangent: s.tangent,
        });
    }

    /// Plant feedback: sequence, staleness, stuck motors; the tip to
    /// integrate when `f` carries a tracker frame not taken before.
    fn take_feedback(
        &mut self,
        f: &FeedbackIn,
        count: u32,
        now: u64,
        ev: &mut Events,
    ) -> Option<Feedback> {
        match self.last_fb_seq {
            Some(prev) if f.seq <= prev => {
                self.counters.plant_restarts += 1;
                self.stuck.resync();
                ev.bits |= event::PLANT_RESTART;
            }
            Some(prev) => {
                let lost = f
                    .seq
                    .saturating_sub(prev.saturating_add(u64::from(count.max(1))));
                if lost > 0 {
                    self.counters.plant_states_lost =
                        self.counters.plant_states_lost.wrapping_add(lost as u32);
                    ev.bits |= event::PLANT_STATES_LOST;
                    ev.plant_states_lost = lost;
                }
            }
            None => {}
        }
        if self.stale {
            self.stale = false;
            self.counters.plant_recoveries += 1;
            self.stuck.resync();
            ev.bits |= event::PLANT_RECOVERED;
        }
        // A plant that has applied commands before should have applied the
        // one sent a period ago, or as many periods ago as commands may be
        // in flight.
        let behind = self.cmd.seq.saturating_sub(f.command_seq);
        if behind > u64::from(self.cfg.commands_in_flight) && f.command_seq > 0 {
            self.counters.commands_not_applied += 1;
            ev.bits |= event::COMMANDS_NOT_APPLIED;
            ev.commands_behind = behind;
        }
        if !self.stuck_hold {
            if let Some((tendon, err)) = self.stuck.check(
                &self.cfg.stuck,
                now,
                &self.cmd.tensions,
                &f.tensions,
                self.n,
            ) {
                self.stuck_hold = true;
                ev.bits |= event::STUCK_MOTOR;
                ev.stuck = Some((tendon as u8, err));
            }
        }
        self.last_fb_seq = Some(f.seq);
        self.last_feedback_ns = now;
        if f.tip_seq == 0 || self.last_tip.is_some_and(|(seq, _, _)| seq == f.tip_seq) {
            return None; // no frame yet, or one already integrated
        }
        // Any other number is a new frame (a restarted tracker counts from 1).
        let sampled = now.saturating_sub(f.tip_age_ns);
        let interval_ns = self.last_tip.map_or(0, |(_, before, credited)| {
            credited_interval(sampled.saturating_sub(before), credited)
        });
        self.last_tip = Some((f.tip_seq, sampled, interval_ns));
        if sampled < self.quiet_until_ns {
            return None; // taken while the robot was still on its way to a jump
        }
        self.local_fb_seq += 1;
        let mut tip = f.tip;
        // Advance the frame along the path by the setpoint's lead and by its
        // own age: it is then compared with the setpoint of its own time.
        let age_s = f.tip_age_ns.min(MAX_TIP_AGE_NS) as f32 * 1e-9;
        if let Some((_, Some(v))) = self.last_sp {
            for (p, v) in tip.iter_mut().zip(&v) {
                *p += v * (self.cfg.lead_s + age_s);
            }
        }
        Some(Feedback {
            seq: self.local_fb_seq,
            tip_position: tip,
            interval_s: interval_ns as f32 * 1e-9,
        })
    }

    /// Count what the step's status says; note what the report lists.
    fn account(&mut self, status: Status, now: u64, ev: &mut Events) {
        let c = &mut self.counters;
        if status.contains(Status::NONFINITE_SETPOINT) {
            c.rejected_nonfinite += 1;
            ev.bits |= event::NONFINITE_SETPOINT;
        }
        if status.contains(Status::BAD_QUATERNION) {
            c.rejected_quaternion += 1;
            ev.bits |= event::BAD_QUATERNION;
        }
        let outside = status.contains(Status::OUT_OF_WORKSPACE);
        if outside {
            c.rejected_workspace += 1;
            if !self.outside {
                ev.bits |= event::OUTSIDE_WORKSPACE;
            }
        }
        self.outside = outside;
        if status.contains(Status::NEW_SETPOINT) {
            self.tracking_started = true;
            self.last_setpoint_ns = now;
        }
        let hold = status.contains(Status::SAFE_HOLD);
        if !self.tracking_started {
            c.startup_hold_periods += 1;
        } else if hold {
            c.hold_periods += 1;
            if !self.in_hold && self.stuck_hold {
                c.stuck_motor_holds += 1;
            } else if !self.in_hold {
                c.watchdog_trips += 1;
                self.hold_after_seq = self.last_sp.map(|(seq, _)| seq);
                ev.bits |= event::WATCHDOG_HOLD;
                ev.hold_silence_ns = now.saturating_sub(self.last_setpoint_ns);
            }
        } else if self.in_hold {
            ev.bits |= event::TRACKING_RESUMED;
            let resumed_in_sequence = self.last_sp_gap == 0
                && self
                    .hold_after_seq
                    .zip(self.last_sp)
                    .is_some_and(|(before, (seq, _))| seq > before);
            if resumed_in_sequence {
                c.watchdog_trips_late_planner += 1;
            }
            self.hold_after_seq = None;
        }
        self.in_hold = hold && self.tracking_started;
        if status.contains(Status::SATURATED) {
            c.saturated_periods += 1;
        }
        if status.contains(Status::CORRECTION) {
            c.correction_periods += 1;
        }
    }
}
