//! Unit tests of every rule of the period (they were the host controller's;
//! each is checked here against what a period must do, independent of any
//! transport).

use std::boxed::Box;
use std::vec::Vec;

use tendril_shared::messages::command_status as wire;
use tendril_shared::{TendonLimits, MAX_HIDDEN, MAX_TENDONS, MAX_WEIGHTS, POSE_DIM};

use super::*;
use crate::control::{ControlConfig, IntegralConfig, SafeHold};
use crate::swap::NetSlots;
use crate::synth::{synthetic_blob, INPUT_HI, INPUT_LO};

type Store = NetSlots<POSE_DIM, MAX_HIDDEN, MAX_TENDONS, MAX_WEIGHTS>;
/// A period with its update buffer, as the node and the host hold them.
struct P {
    period: Period,
    update: Box<Update<32768>>,
}

impl P {
    fn new(cfg: PeriodConfig, now_ns: u64) -> P {
        P {
            period: Period::new(cfg, now_ns),
            update: Box::default(),
        }
    }
    fn run<S>(&mut self, store: &mut S, input: &Inputs) -> Outputs
    where
        S: crate::swap::NetStore<POSE_DIM, MAX_HIDDEN, MAX_TENDONS, MAX_WEIGHTS> + ?Sized,
    {
        self.period.run(store, &mut *self.update, input)
    }
    fn update(&mut self) -> &mut Update<32768> {
        &mut self.update
    }
    fn counters(&self) -> &Counters {
        self.period.counters()
    }
    fn last_command(&self) -> &PeriodCommand {
        self.period.last_command()
    }
    fn holding(&self) -> bool {
        self.period.holding()
    }
}

const T: u64 = 1_000_000; // 1 ms

fn blob(seed: u64, hidden: usize) -> Vec<u8> {
    let mut buf = std::vec![0u8; 32768];
    let n = synthetic_blob(seed, hidden, 4, 10.0, &mut buf).unwrap();
    buf.truncate(n);
    buf
}

fn store(seed: u64) -> Box<Store> {
    let mut s: Box<Store> = Box::default();
    s.load(&blob(seed, 8), (POSE_DIM, 4)).unwrap();
    s
}

fn config() -> PeriodConfig {
    let limits = TendonLimits::uniform(4, 10.0, 200.0).unwrap();
    let mut control = ControlConfig::new(limits);
    control.watchdog_ns = 5 * T / 2;
    control.max_dt_ns = 5 * T;
    control.safe_hold = SafeHold::Freeze;
    PeriodConfig {
        control,
        period_ns: T,
        lead_s: 0.0,
        plant_stale_ns: 20 * T,
        stuck: StuckConfig::new(0.02, 0.5, 0.1, T),
        swap_slice_bytes: 4096,
        jump_m: 1e-3,
        settle_after_jump_ns: 100 * T,
        commands_in_flight: 0,
    }
}

/// The middle of the synthetic net's input box (a unit quaternion).
fn pose() -> [f32; 7] {
    let mut p = [0.0; 7];
    for i in 0..3 {
        p[i] = 0.5 * (INPUT_LO[i] + INPUT_HI[i]);
    }
    p[3] = 1.0;
    p
}

fn sp(seq: u64) -> SetpointIn {
    SetpointIn {
        seq,
        pose: pose(),
        velocity: None,
        tangent: None,
        age_ns: 0,
    }
}

fn fb(seq: u64, command_seq: u64, tensions: Tensions) -> FeedbackIn {
    FeedbackIn {
        seq,
        command_seq,
        tensions,
        tip: [0.0, 0.0, 0.35],
        tip_seq: seq as u32,
        tip_age_ns: 0,
    }
}

fn at(k: u64) -> Inputs {
    Inputs {
        now_ns: k * T,
        ..Inputs::default()
    }
}

fn with_sp(k: u64, s: SetpointIn) -> Inputs {
    Inputs {
        setpoint: Some(s),
        setpoints: 1,
        ..at(k)
    }
}

#[test]
fn setpoint_gaps_and_restarts_are_counted() {
    let mut st = store(1);
    let mut p = P::new(config(), 0);
    let o = p.run(&mut *st, &with_sp(1, sp(1)));
    assert_eq!(o.events.bits, 0);
    // Three consecutive arrivals ending at 4: nothing lost.
    let mut i = with_sp(2, sp(4));
    i.setpoints = 3;
    assert!(!p.run(&mut *st, &i).events.has(event::SETPOINTS_LOST));
    // 5..=9 lost.
    let o = p.run(&mut *st, &with_sp(3, sp(10)));
    assert!(o.events.has(event::SETPOINTS_LOST));
    assert_eq!(o.events.setpoints_lost, 5);
    // A new planner starts again at 1.
    let o = p.run(&mut *st, &with_sp(4, sp(1)));
    assert!(o.events.has(event::PLANNER_RESTART));
    assert!(!o.events.has(event::SETPOINTS_LOST));
    let c = p.counters();
    assert_eq!(
        (c.setpoints, c.setpoints_lost, c.planner_restarts),
        (4, 5, 1)
    );
    assert_eq!(o.command.setpoint_seq, 1);
}

#[test]
fn nonfinite_setpoints_are_rejected_and_counted_with_the_superseded_ones() {
    let mut st = store(1);
    let mut p = P::new(config(), 0);
    p.run(&mut *st, &with_sp(1, sp(1)));
    let before = p.last_command().tensions;
    let mut bad = sp(2);
    bad.pose[0] = f32::NAN;
    let mut i = with_sp(2, bad);
    i.superseded_nonfinite = 2;
    i.setpoints = 3;
    let o = p.run(&mut *st, &i);
    assert!(o.events.has(event::NONFINITE_SETPOINT));
    assert_ne!(o.command.status & wire::SETPOINT_REJECTED, 0);
    assert_eq!(p.counters().rejected_nonfinite, 3);
    assert!(o.command.tensions.iter().all(|t| t.is_finite()));
    // The target stayed: the command keeps slewing to the old target, so
    // after enough periods it is where it would have been anyway.
    assert!(o.command.tensions[..4]
        .iter()
        .zip(&before)
        .all(|(a, b)| (a - b).abs() <= 0.2 + 1e-6));
}

#[test]
fn a_quaternion_off_unit_is_rejected() {
    let mut st = store(1);
    let mut p = P::new(config(), 0);
    let mut bad = sp(1);
    bad.pose[3] = 0.5;
    let o = p.run(&mut *st, &with_sp(1, bad));
    assert!(o.events.has(event::BAD_QUATERNION));
    assert_eq!(p.counters().rejected_quaternion, 1);
}

#[test]
fn outside_the_workspace_is_listed_once_per_run_and_counted_every_period() {
    let mut st = store(1);
    let mut p = P::new(config(), 0);
    p.run(&mut *st, &with_sp(1, sp(1)));
    let mut far = sp(2);
    far.pose[0] = 10.0;
    let o = p.run(&mut *st, &with_sp(2, far));
    assert!(o.events.has(event::OUTSIDE_WORKSPACE));
    far.seq = 3;
    let o = p.run(&mut *st, &with_sp(3, far));
    assert!(!o.events.has(event::OUTSIDE_WORKSPACE));
    assert_eq!(p.counters().rejected_workspace, 2);
    // Back inside, then out again: listed again.
    p.run(&mut *st, &with_sp(4, sp(4)));
    far.seq = 5;
    assert!(p
        .run(&mut *st, &with_sp(5, far))
        .events
        .has(event::OUTSIDE_WORKSPACE));
}

#[test]
fn silence_trips_the_watchdog_within_three_periods_and_a_late_planner_resumes() {
    let mut st = store(1);
    let mut p = P::new(config(), 0);
    for k in 1..=50 {
        p.run(&mut *st, &with_sp(k, sp(k)));
    }
    let mut hold_at = None;
    let mut held = None;
    for k in 51..=60 {
        let o = p.run(&mut *st, &at(k));
        if o.events.has(event::WATCHDOG_HOLD) {
            hold_at = Some(k);
            held = Some(o.command.tensions);
            assert!(o.events.hold_silence_ns >= 5 * T / 2);
        }
        if let Some(held) = held {
            assert_ne!(o.command.status & wire::SAFE_HOLD, 0);
            assert_eq!(o.command.tensions, held, "a hold freezes the command");
        }
    }
    let hold_at = hold_at.expect("no watchdog hold after 10 silent periods");
    assert!(
        hold_at - 50 <= 3,
        "hold {} periods after the last setpoint",
        hold_at - 50
    );
    assert!(p.holding());
    // The next setpoint in sequence: a late planner, tracking resumes.
    let o = p.run(&mut *st, &with_sp(61, sp(51)));
    assert!(o.events.has(event::TRACKING_RESUMED));
    let c = p.counters();
    assert_eq!((c.watchdog_trips, c.watchdog_trips_late_planner), (1, 1));
    assert!(c.hold_periods >= 7);
    assert_eq!(c.startup_hold_periods, 0);
}

#[test]
fn no_feedback_for_the_stale_time_marks_the_plant_stale_until_it_returns() {
    let mut st = store(1);
    let mut p = P::new(config(), 0);
    let mut stale_at = None;
    for k in 1..=30 {
        let o = p.run(&mut *st, &with_sp(k, sp(k)));
        if o.events.has(event::PLANT_STALE) {
            stale_at = Some(k);
        }
        if stale_at.is_some() {
            assert_ne!(o.command.status & wire::PLANT_STALE, 0);
        }
    }
    assert_eq!(
        stale_at,
        Some(21),
        "stale after 20 periods without feedback"
    );
    let mut i = with_sp(31, sp(31));
    i.feedback = Some(fb(1, 0, p.last_command().tensions));
    i.feedbacks = 1;
    let o = p.run(&mut *st, &i);
    assert!(o.events.has(event::PLANT_RECOVERED));
    assert_eq!(o.command.status & wire::PLANT_STALE, 0);
    assert_eq!(p.counters().plant_stale_periods, 10);
}

#[test]
fn feedback_gaps_restarts_and_unapplied_commands_are_seen() {
    let mut st = store(1);
    let mut p = P::new(config(), 0);
    let mut k = 0;
    let mut run = |p: &mut P, f: FeedbackIn| {
        k += 1;
        let mut i = with_sp(k, sp(k));
        i.feedback = Some(f);
        i.feedbacks = 1;
        p.run(&mut *st, &i)
    };
    let o = run(&mut p, fb(1, 0, [0.0; MAX_TENDONS]));
    let o = run(&mut p, fb(2, o.command.seq, o.command.tensions));
    assert_eq!(o.events.bits, 0);
    let o = run(&mut p, fb(6, o.command.seq, o.command.tensions));
    assert!(o.events.has(event::PLANT_STATES_LOST));
    assert_eq!(o.events.plant_states_lost, 3);
    // The plant still reports the command before last.
    let o = run(&mut p, fb(7, o.command.seq - 1, o.command.tensions));
    assert!(o.events.has(event::COMMANDS_NOT_APPLIED));
    assert_eq!(o.events.commands_behind, 1);
    let o = run(&mut p, fb(1, o.command.seq, o.command.tensions));
    assert!(o.events.has(event::PLANT_RESTART));
    let c = p.counters();
    assert_eq!(
        (
            c.plant_states_lost,
            c.commands_not_applied,
            c.plant_restarts
        ),
        (3, 1, 1)
    );
}

#[test]
fn a_motor_that_does_not_follow_is_detected_and_the_hold_latches() {
    let mut st = store(1);
    let mut p = P::new(config(), 0);
    let mut last = *p.last_command();
    let mut detected = None;
    for k in 1..=400u64 {
        // Healthy motors follow exactly; motor 2 pulls 3 N more than
        // commanded from k = 100 (jammed, dragging its tendon).
        let mut measured = last.tensions;
        if k >= 100 {
            measured[2] += 3.0;
        }
        let mut i = with_sp(k, sp(k));
        i.feedback = Some(fb(k, last.seq, measured));
        i.feedbacks = 1;
        let o = p.run(&mut *st, &i);
        if o.events.has(event::STUCK_MOTOR) {
            detected = Some((k, o.events.stuck));
            assert_ne!(o.command.status & wire::SAFE_HOLD, 0);
            assert_eq!(o.command.tensions, last.tensions, "held where it was");
        }
        if detected.is_some() {
            assert_eq!(o.command.tensions, p.last_command().tensions);
            assert_ne!(o.command.status & wire::SAFE_HOLD, 0, "latched");
        }
        last = o.command;
    }
    let (k, stuck) = detected.expect("stuck motor not detected");
    assert_eq!(stuck.map(|s| s.0), Some(2));
    assert!((100..=100 + 100 + 5).contains(&k), "detected at period {k}");
    assert_eq!(p.counters().stuck_motor_holds, 1);
}

/// A setpoint with velocity `v`, aged `age_ns`, under a lead of `lead_s`
/// gives, period after period, the commands of an unled, unaged setpoint
/// moved `ahead_s` along `v`.
fn assert_led_as_ahead(lead_s: f32, age_ns: u64, ahead_s: f32) {
    let mut st = store(1);
    let mut cfg = config();
    cfg.lead_s = lead_s;
    let mut led = P::new(cfg, 0);
    let mut plain = P::new(config(), 0);
    let v = [0.5, -0.25, 0.0, 0.0, 0.0, 0.0, 0.0];
    let mut s = sp(1);
    s.velocity = Some(v);
    s.age_ns = age_ns;
    let mut ahead = sp(1);
    for (p, vv) in ahead.pose.iter_mut().zip(&v) {
        *p += vv * ahead_s;
    }
    for k in 1..=40 {
        s.seq = k;
        ahead.seq = k;
        let a = led.run(&mut *st, &with_sp(k, s));
        let b = plain.run(&mut *st, &with_sp(k, ahead));
        assert_eq!(
            a.command.tensions, b.command.tensions,
            "age {age_ns} ns, period {k}"
        );
    }
}

#[test]
fn the_lead_advances_setpoint_and_measured_tip_alike() {
    assert_led_as_ahead(0.02, 0, 0.02);
}

/// A setpoint taken 8 ms after it was sent is led by its age beside the
/// motors' lag: as a setpoint 28 ms ahead on its path with no age; an age
/// beyond [`MAX_SETPOINT_AGE_NS`] counts as that. (The period adds the two
/// in f32, so the setpoint ahead is moved by that sum, checked against the
/// intended time first.)
#[test]
fn a_setpoint_is_led_by_its_age() {
    for (age_ns, ahead_s) in [
        (8_000_000, 0.028),
        (
            10 * MAX_SETPOINT_AGE_NS,
            0.02 + MAX_SETPOINT_AGE_NS as f32 * 1e-9,
        ),
    ] {
        let lead_s = 0.02 + age_ns.min(MAX_SETPOINT_AGE_NS) as f32 * 1e-9;
        assert!((lead_s - ahead_s).abs() < 1e-6);
        assert_led_as_ahead(0.02, age_ns, lead_s);
    }
}

/// Over the link a command may still be on its way when the plant's state
/// leaves: one behind is not a fault there, two are, and the plant that
/// stops applying commands is still seen one period later than on the host.
#[test]
fn commands_in_flight_are_not_unapplied_commands() {
    let mut st = store(1);
    let mut cfg = config();
    cfg.commands_in_flight = 1;
    let mut p = P::new(cfg, 0);
    let mut k = 0;
    let mut run = |p: &mut P, command_seq: u64| {
        k += 1;
        let mut i = with_sp(k, sp(k));
        i.feedback = Some(fb(k, command_seq, p.last_command().tensions));
        i.feedbacks = 1;
        p.run(&mut *st, &i)
    };
    let mut o = run(&mut p, 0);
    // Always one behind: the link's latency, never an event.
    for _ in 0..5 {
        let one_behind = o.command.seq.saturating_sub(1);
        o = run(&mut p, one_behind);
        assert!(!o.events.has(event::COMMANDS_NOT_APPLIED), "{:?}", o.events);
    }
    // The plant stops at the last command it applied.
    let stopped = o.command.seq.saturating_sub(1);
    let o = run(&mut p, stopped);
    assert!(!o.events.has(event::COMMANDS_NOT_APPLIED));
    let o = run(&mut p, stopped);
    assert!(o.events.has(event::COMMANDS_NOT_APPLIED));
    assert_eq!(o.events.commands_behind, 2);
    assert_eq!(p.counters().commands_not_applied, 1);
}

fn swap_config() -> PeriodConfig {
    let mut c = config();
    c.control.integral = IntegralConfig::OFF;
    c
}

#[test]
fn a_whole_update_swaps_in_slices_without_a_missed_period() {
    let mut st = store(1);
    let mut p = P::new(swap_config(), 0);
    let update = blob(2, 64);
    assert!(update.len() > 2 * 4096, "takes several slices");
    assert_eq!(p.update().offer(&update), Ok(false));
    let mut swapped_at = None;
    for k in 1..=20 {
        let o = p.run(&mut *st, &with_sp(k, sp(k)));
        assert_eq!(o.command.seq, k, "one command per period");
        if o.events.has(event::WEIGHTS_SWAPPED) {
            swapped_at = Some(k);
            assert_ne!(o.command.status & wire::WEIGHTS_SWAPPED, 0);
        }
    }
    let k = swapped_at.expect("not swapped in 20 periods");
    assert!(k >= 3, "swapped at period {k}: the check takes slices");
    assert_eq!(st.active().shape().hidden, 64);
    assert_eq!(p.counters().weight_swaps, 1);
}

/// The period that writes the new net does not also run it (the chip's
/// period budget): its command holds the old net's target, and the new
/// net's tensions come from the next period on.
#[test]
fn the_period_that_installs_a_net_holds_the_target_and_the_next_runs_the_new_net() {
    let mut st = store(1);
    let mut cfg = swap_config();
    cfg.control.limits = TendonLimits::uniform(4, 10.0, 1e9).unwrap();
    let mut p = P::new(cfg, 0);
    p.update().offer(&blob(2, 64)).unwrap();
    let mut commands = Vec::new();
    let mut swapped_at = None;
    for k in 1..=20 {
        let o = p.run(&mut *st, &with_sp(k, sp(k)));
        if o.events.has(event::WEIGHTS_SWAPPED) {
            swapped_at = Some(commands.len());
        }
        commands.push(o.command.tensions);
    }
    let i = swapped_at.expect("not swapped in 20 periods");
    assert!(i >= 2 && i + 1 < commands.len());
    // The same setpoint every period, no slew limit: the old net's
    // tensions until the install, held through it, then the new net's.
    assert_eq!(commands[i], commands[i - 1], "the install period held");
    assert_ne!(commands[i + 1], commands[i], "the new net runs after it");
    assert_eq!(commands[i + 2], commands[i + 1]);
}

#[test]
fn a_corrupted_update_is_rejected_and_the_old_net_runs() {
    let mut st = store(1);
    let mut p = P::new(swap_config(), 0);
    let mut update = blob(2, 64);
    let mid = update.len() / 2;
    update[mid] ^= 0x40;
    p.update().offer(&update).unwrap();
    let mut rejected = false;
    for k in 1..=20 {
        let o = p.run(&mut *st, &with_sp(k, sp(k)));
        if o.events.has(event::WEIGHTS_REJECTED) {
            rejected = true;
            assert!(matches!(
                o.events.update_error,
                Some(UpdateError::Rejected(_))
            ));
        }
    }
    assert!(rejected);
    assert_eq!(st.active().shape().hidden, 8, "the old net runs");
    assert_eq!(p.counters().weight_rejections, 1);
}

#[test]
fn chunks_in_order_make_the_blob_and_a_gap_drops_it() {
    let mut p = P::new(swap_config(), 0);
    let update = blob(3, 16);
    let total = update.len();
    for (i, c) in update.chunks(100).enumerate() {
        assert_eq!(p.update().chunk(i * 100, total, c), Ok(false));
    }
    assert!(p.update().checking());
    // A chunk lost in the middle: the rest is refused, nothing is checked.
    let mut q = P::new(swap_config(), 0);
    q.update().chunk(0, total, &update[..100]).unwrap();
    let e = q.update().chunk(200, total, &update[200..300]);
    assert_eq!(
        e,
        Err(UpdateError::OutOfOrder {
            offset: 200,
            received: 100
        })
    );
    assert!(!q.update().busy());
    // Too large for the buffer.
    let mut small: Update<64> = Update::new();
    assert!(matches!(
        small.chunk(0, total, &update[..10]),
        Err(UpdateError::TooLarge { .. })
    ));
    // A new blob (offset 0) supersedes one in progress.
    q.update().chunk(0, total, &update[..100]).unwrap();
    assert_eq!(q.update().chunk(0, total, &update[..100]), Ok(true));
}

#[test]
fn missed_ticks_mark_an_overrun() {
    let mut st = store(1);
    let mut p = P::new(config(), 0);
    let mut i = with_sp(3, sp(1));
    i.missed_ticks = 2;
    let o = p.run(&mut *st, &i);
    assert_ne!(o.command.status & wire::OVERRUN, 0);
    assert_eq!(p.counters().missed_ticks, 2);
}

#[test]
fn the_same_inputs_give_the_same_commands_bit_for_bit() {
    let mut a = store(1);
    let mut b = store(1);
    let mut p = P::new(config(), 0);
    let mut q = P::new(config(), 0);
    for k in 1..200 {
        let mut s = sp(k);
        s.pose[0] += (k as f32 * 0.01).sin() * 0.05;
        let i = with_sp(k, s);
        assert_eq!(p.run(&mut *a, &i), q.run(&mut *b, &i));
    }
}

/// A period with the integral loop on (gain 10 /s, no filter, no window),
/// the slew limit out of the way (a slewing command pauses the loop).
fn integral_config() -> PeriodConfig {
    let mut cfg = config();
    cfg.control.limits = TendonLimits::uniform(4, 10.0, 1e9).unwrap();
    cfg.control.integral = IntegralConfig {
        ki: 10.0,
        limit: 0.01,
        feedback_timeout_ns: 1_000_000_000,
        window: f32::INFINITY,
        filter_tau_s: 0.0,
        map_gain: 0.0,
        map_scale: 1.0,
        map_limit: 0.0,
    };
    cfg
}

#[test]
fn a_tracker_frame_is_integrated_once_over_the_time_since_the_last() {
    // A 40 Hz tracker under a 1 kHz loop: the plant reports every period,
    // a new frame every 25th. The tip sits 1 mm short in x.
    let mut st = store(1);
    let mut p = P::new(integral_config(), 0);
    let mut changes = 0;
    let mut before = p.period.correction().0;
    // From 1 s on, so that the first frame's age does not reach before 0.
    for k in 1001..=1100u64 {
        let frame = (k - 1001) / 25 + 1;
        let mut f = fb(k, k.saturating_sub(1), [0.0; MAX_TENDONS]);
        f.tip = [pose()[0] - 1e-3, pose()[1], pose()[2]];
        f.tip_seq = frame as u32;
        f.tip_age_ns = 20 * T;
        let input = Inputs {
            feedback: Some(f),
            feedbacks: 1,
            ..with_sp(k, sp(k))
        };
        p.run(&mut *st, &input);
        let now = p.period.correction().0;
        if now != before {
            changes += 1;
            assert_eq!(
                (k - 1001) % 25,
                0,
                "the correction moved at period {k}, between frames"
            );
        }
        before = now;
    }
    // Frames 2, 3 and 4 each stand for the 25 ms since the one before
    // (the first for nothing): 10 /s × 1 mm × 75 ms.
    assert_eq!(changes, 3);
    let c = p.period.correction().0[0];
    assert!((c - 0.75e-3).abs() < 1e-7, "correction {c}");
}

/// After a gap in the frames (a lost marker, or frames held back during a
/// shaped move) the first frame counts twice the frame interval, not the
/// gap: the correction grows by the same small step as before it, not by
/// the gap's worth at once (which rang a rod with mass).
#[test]
fn the_first_frame_after_a_gap_counts_twice_the_frame_interval_not_the_gap() {
    // Frames every 10 ms, then none for 300 ms, then every 10 ms again.
    let frames: Vec<u64> = (0..5).chain(35..38).map(|j| 1000 + 10 * j).collect();
    let steps = correction_steps(1000..=1370, |k| {
        let j = frames.iter().rposition(|&t| t <= k).unwrap_or(0);
        (j as u32 + 1, frames[j])
    });
    // 10 /s × 1 mm × 10 ms = 0.1 mm per frame; the first frame after the
    // gap 0.2 mm (twice), not 3 mm (the 300 ms gap).
    assert_eq!(steps.len(), 7, "{steps:?}");
    for (i, s) in steps.iter().enumerate() {
        let want = if i == 4 { 0.2e-3 } else { 0.1e-3 };
        assert!((s - want).abs() < 1e-7, "step {i}: {s} (all {steps:?})");
    }
}

/// A planner's shaped approach from rest holds the frames back from the
/// first on, so the second frame the period sees comes 700 ms after it.
/// It counts a 40 Hz tracker's 25 ms at most, not the wait (the tracker
/// timeout's worth once: a correction that jumped 1.3–1.8 mm at once and
/// rang a rod with mass for 3 s).
#[test]
fn the_second_frame_after_a_held_first_counts_a_slow_trackers_interval_not_the_wait() {
    // Frame 1 at 1000 ms, held to 1700 ms; then a frame every period.
    let steps = correction_steps(1000..=1705, |k| {
        if k < 1700 {
            (1, 1000)
        } else {
            ((k - 1698) as u32, k)
        }
    });
    // 10 /s × 1 mm × 25 ms = 0.25 mm (not 7 mm, nor the 0.01 m bound),
    // then 10 /s × 1 mm × 1 ms a frame.
    assert_eq!(steps.len(), 6, "{steps:?}");
    assert!((steps[0] - 0.25e-3).abs() < 1e-7, "{steps:?}");
    for s in &steps[1..] {
        assert!((s - 0.01e-3).abs() < 1e-8, "{steps:?}");
    }
}

/// The changes of the integral's correction (x, m) over the periods `ks`
/// (ms) of a period with the loop on ([`integral_config`]), the tip 1 mm
/// short in x and the plant reporting every period; `frame(k)`: the
/// tracker's newest frame at period k, (its sequence number, the period it
/// was taken in).
fn correction_steps(
    ks: std::ops::RangeInclusive<u64>,
    frame: impl Fn(u64) -> (u32, u64),
) -> Vec<f32> {
    let mut st = store(1);
    let mut p = P::new(integral_config(), 0);
    let mut steps = Vec::new();
    let mut before = p.period.correction().0[0];
    for k in ks {
        let mut f = fb(k, k.saturating_sub(1), [0.0; MAX_TENDONS]);
        f.tip = [pose()[0] - 1e-3, pose()[1], pose()[2]];
        let (seq, taken) = frame(k);
        f.tip_seq = seq;
        f.tip_age_ns = (k - taken) * T;
        let input = Inputs {
            feedback: Some(f),
            feedbacks: 1,
            ..with_sp(k, sp(k))
        };
        p.run(&mut *st, &input);
        let now = p.period.correction().0[0];
        if now != before {
            steps.push(now - before);
        }
        before = now;
    }
    steps
}

#[test]
fn credited_intervals_follow_a_slower_tracker_within_a_few_frames() {
    use crate::period::credited_interval;
    assert_eq!(credited_interval(25, 0), 25);
    assert_eq!(credited_interval(300, 10), 20);
    // 1 kHz to 40 Hz: 2, 4, 8, 16, then the full 25 ms.
    let mut credit = 1;
    let mut seen = Vec::new();
    for _ in 0..6 {
        credit = credited_interval(25, credit);
        seen.push(credit);
    }
    assert_eq!(seen, [2, 4, 8, 16, 25, 25]);
}

#[test]
fn a_late_frame_is_compared_with_the_path_where_it_was_taken() {
    // The setpoint moves at 10 mm/s; the tracker sees the tip exactly on
    // the path but 30 ms late. Led by its age, the frame shows no error;
    // taken as current, it would show 0.3 mm.
    let mut st = store(1);
    let v = [0.01, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let mut run = |age_known: bool| {
        let mut p = P::new(integral_config(), 0);
        for k in 1..=200u64 {
            let t = k as f32 * 1e-3;
            let mut s = sp(k);
            s.pose[0] += v[0] * t;
            s.velocity = Some(v);
            let mut f = fb(k, k - 1, [0.0; MAX_TENDONS]);
            f.tip = [pose()[0] + v[0] * (t - 0.03), pose()[1], pose()[2]];
            f.tip_seq = k as u32;
            f.tip_age_ns = if age_known { 30 * T } else { 0 };
            let input = Inputs {
                feedback: Some(f),
                feedbacks: 1,
                ..with_sp(k, s)
            };
            p.run(&mut *st, &input);
        }
        p.period.correction().0[0]
    };
    let led = run(true);
    let unled = run(false);
    assert!(led.abs() < 2e-6, "led by its age: {led}");
    // 10 /s × 0.3 mm × 0.2 s ≈ 0.6 mm without.
    assert!(unled > 0.5e-3, "taken as current: {unled}");
}

#[test]
fn the_error_map_learns_an_error_proportional_to_the_bend() {
    // A robot that goes 10 % further than asked along x: the error is
    // −0.1 x. The constant correction alone leaves an error that follows
    // the setpoint around; with the map the error goes (almost) away.
    let mut st = store(1);
    let residual = |map_gain: f32, st: &mut Store| {
        let mut cfg = integral_config();
        cfg.control.integral.ki = 2.0;
        cfg.control.integral.map_gain = map_gain;
        cfg.control.integral.map_scale = 1e-3;
        cfg.control.integral.map_limit = 0.5;
        let mut p = P::new(cfg, 0);
        let mut last = 0.0f32;
        for k in 1..=20_000u64 {
            let t = k as f32 * 1e-3;
            // ±2 mm about the middle at 0.2 Hz: stays inside the small box.
            let x = 2e-3 * (core::f32::consts::TAU * 0.2 * t).sin();
            let mut s = sp(k);
            s.pose[0] += x;
            let (c, m) = p.period.correction();
            // The plant: it reaches the corrected setpoint stretched by 10 %.
            let sent = x + c[0] + m[0][0] * x;
            let mut f = fb(k, k - 1, [0.0; MAX_TENDONS]);
            f.tip = [pose()[0] + 1.1 * sent, pose()[1], pose()[2]];
            f.tip_seq = k as u32;
            let input = Inputs {
                feedback: Some(f),
                feedbacks: 1,
                ..with_sp(k, s)
            };
            p.run(&mut *st, &input);
            if k > 15_000 {
                last = last.max((1.1 * sent - x).abs());
            }
        }
        (last, p.period.correction().1[0][0])
    };
    let (without, _) = residual(0.0, &mut st);
    let (with, m) = residual(2.0, &mut st);
    assert!(
        without > 0.05e-3,
        "a constant correction chases the error: {without}"
    );
    assert!(
        with < 0.2 * without,
        "with the map {with} against {without}"
    );
    // It learned the inverse stretch: 1.1 (1 + m) = 1.
    assert!((m - (1.0 / 1.1 - 1.0)).abs() < 0.01, "map {m}");
}

/// The error map on a circle away from where tracking began, in a loop
/// with the dynamics of the default robot (host defaults: ki 4 /s, 80 ms
/// filter, map 2 /s over 10 mm; motors 20 ms; the first mode 3.6 Hz at
/// 5 %), against a robot 9 % short of its model about its rest pose, the
/// first setpoint, 29.3 mm from the circle's centre. The map learns from x
/// about its running mean ([`crate::control::MAP_MEAN_TAU_S`]); from the
/// fixed origin its update and the constant correction's grew the error
/// pass after pass (in the sim: 0.50 → 1.28 mm over ten passes at 0.4 Hz).
#[test]
fn the_error_map_converges_on_a_fast_circle_away_from_where_tracking_began() {
    let mut st = store(1);
    let mut cfg = integral_config();
    cfg.control.integral = IntegralConfig {
        ki: 4.0,
        limit: 0.02,
        feedback_timeout_ns: 250 * T,
        window: 0.02,
        filter_tau_s: 0.08,
        map_gain: 2.0,
        map_scale: 0.01,
        map_limit: 0.5,
    };
    let mut p = P::new(cfg, 0);
    let dt = 1e-3f64;
    let centre = [f64::from(pose()[0]), f64::from(pose()[1])];
    let rest = [centre[0] + 0.0293, centre[1]];
    let (radius, freq) = (0.015f64, 0.4f64);
    let (wn, zeta, tau_m, short) = (core::f64::consts::TAU * 3.6, 0.05, 0.02, 0.91);
    // Plant state: motor output, tip and its velocity (x, y).
    let (mut um, mut y, mut v) = (rest, rest, [0.0f64; 2]);
    let mut pass_ms2 = std::vec![0.0f64; 12];
    let settle = 1000u64;
    for k in 1..=settle + 12 * 2500 {
        let t = (k.saturating_sub(settle)) as f64 * dt;
        let w = core::f64::consts::TAU * freq * t;
        let r = if k <= settle {
            rest
        } else {
            [centre[0] + radius * w.cos(), centre[1] + radius * w.sin()]
        };
        let mut s = sp(k);
        s.pose[0] = r[0] as f32;
        s.pose[1] = r[1] as f32;
        // What the period sends: the setpoint plus c + M (x − origin).
        let (c, m) = p.period.correction();
        let x = [r[0] - rest[0], r[1] - rest[1]];
        let mut u = r;
        for j in 0..2 {
            u[j] += f64::from(c[j]) + f64::from(m[j][0]) * x[0] + f64::from(m[j][1]) * x[1];
        }
        for j in 0..2 {
            um[j] += dt / tau_m * (u[j] - um[j]);
            let q = rest[j] + short * (um[j] - rest[j]);
            v[j] += (wn * wn * (q - y[j]) - 2.0 * zeta * wn * v[j]) * dt;
            y[j] += v[j] * dt;
        }
        let mut f = fb(k, k - 1, [0.0; MAX_TENDONS]);
        f.tip = [y[0] as f32, y[1] as f32, pose()[2]];
        let input = Inputs {
            feedback: Some(f),
            feedbacks: 1,
            ..with_sp(k, s)
        };
        p.run(&mut *st, &input);
        if k > settle {
            let e2 = (r[0] - y[0]).powi(2) + (r[1] - y[1]).powi(2);
            pass_ms2[((k - settle - 1) / 2500) as usize] += e2 / 2500.0;
        }
    }
    let rms_mm: Vec<f64> = pass_ms2.iter().map(|m| m.sqrt() * 1e3).collect();
    let (second, last) = (rms_mm[1], rms_mm[11]);
    assert!(
        second > 0.2,
        "the model error is there to learn: {rms_mm:?}"
    );
    assert!(last < 0.25 * second, "per pass, mm: {rms_mm:?}");
    for pair in rms_mm[3..].windows(2) {
        assert!(pair[1] < 1.05 * pair[0], "it never grows: {rms_mm:?}");
    }
}

#[test]
fn a_period_configured_again_in_place_runs_as_a_new_one() {
    // Dirty every part of a period: setpoints, feedback, a stuck motor's
    // latched hold, the counters.
    let mut st = store(1);
    let mut p = P::new(config(), 0);
    let mut last = *p.last_command();
    for k in 1..=300u64 {
        let mut measured = last.tensions;
        measured[1] += if k >= 50 { 3.0 } else { 0.0 };
        let mut i = with_sp(k, sp(k));
        i.feedback = Some(fb(k, last.seq, measured));
        i.feedbacks = 1;
        last = p.run(&mut *st, &i).command;
    }
    assert!(p.holding() && p.counters().stuck_motor_holds == 1);
    let t0 = 400 * T;
    // Restarted (the node's first Step) and configured again (a Setup),
    // in place; and configured into an empty slot (the node's first Setup).
    let mut restarted = P::new(config(), 0);
    restarted.period = p.period.clone();
    restarted.period.restart(t0);
    let mut fresh_same = P::new(config(), t0);
    p.period.reconfigure(&integral_config(), t0);
    let mut fresh = P::new(integral_config(), t0);
    let mut slot = None;
    let configured = Period::configure(&mut slot, &integral_config(), t0).clone();
    let mut empty = P::new(config(), 0);
    empty.period = configured;
    for (a, b) in [(&mut restarted, &mut fresh_same), (&mut p, &mut fresh)] {
        assert_eq!(a.counters(), b.counters());
        assert_eq!(a.last_command(), b.last_command());
        assert_eq!(a.period.config(), b.period.config());
        assert!(!a.holding());
    }
    let mut stores = [store(1), store(1), store(1), store(1), store(1)];
    for k in 401..=600u64 {
        let mut s = sp(k);
        s.pose[0] += (k as f32 * 0.01).sin() * 0.01;
        let mut i = with_sp(k, s);
        i.feedback = Some(fb(k, k - 1, fresh.last_command().tensions));
        i.feedbacks = 1;
        let [s0, s1, s2, s3, s4] = &mut stores;
        let want = fresh.run(&mut **s0, &i);
        assert_eq!(p.run(&mut **s1, &i), want, "period {k}");
        assert_eq!(empty.run(&mut **s2, &i), want, "period {k}");
        assert_eq!(restarted.run(&mut **s3, &i), fresh_same.run(&mut **s4, &i));
    }
    assert_eq!(p.counters(), fresh.counters());
    assert_eq!(p.period.correction(), fresh.period.correction());
}
