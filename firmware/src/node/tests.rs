//! Unit tests of the controller node ([`crate::node`]) on an in-process
//! board: lock-step mode, Setup handling, garbage between messages, and a
//! weight update sent in chunks. The board is a byte queue each way and a
//! clock the test advances, so every input is the test's.

use std::boxed::Box;
use std::collections::VecDeque;
use std::vec::Vec;

use tendril_shared::link::wire::{
    Down, Feedback, Hello, LinkCommand, LinkSetpoint, Setup, Telemetry, Up, WirePose, MAX_CHUNK,
    MAX_UP_PAYLOAD, PROTOCOL_VERSION, TELEMETRY_EVERY,
};
use tendril_shared::link::{encode, encode_raw, max_frame_len, FrameDecoder};
use tendril_shared::MAX_TENDONS;

use crate::board::Board;
use crate::node::{setup_error, Node, MCU_UPDATE_CAPACITY};
use crate::period::event;
use crate::{McuNet, McuSlots, DEFAULT_NET, DEFAULT_NET_CRC};

const TICK: u32 = 1_000_000;

#[derive(Default)]
struct TestBoard {
    rx: VecDeque<u8>,
    tx: Vec<u8>,
    now: u64,
    tensions: Vec<f32>,
}

impl Board for TestBoard {
    fn wait_tick(&mut self) -> u32 {
        self.now += u64::from(TICK);
        0
    }
    fn now_ns(&self) -> u64 {
        self.now
    }
    fn set_tensions(&mut self, tensions: &[f32]) {
        self.tensions = tensions.to_vec();
    }
    fn link_read(&mut self, buf: &mut [u8]) -> usize {
        let n = buf.len().min(self.rx.len());
        for (d, s) in buf.iter_mut().zip(self.rx.drain(..n)) {
            *d = s;
        }
        n
    }
    fn link_write(&mut self, bytes: &[u8]) -> usize {
        self.tx.extend_from_slice(bytes);
        bytes.len()
    }
}

struct Rig {
    node: Box<Node<MCU_UPDATE_CAPACITY>>,
    board: TestBoard,
    ram: Box<McuNet>,
    up: FrameDecoder<{ max_frame_len(MAX_UP_PAYLOAD) }>,
}

impl Rig {
    fn new() -> Rig {
        Rig {
            node: Box::new(Node::new(DEFAULT_NET_CRC, TICK)),
            board: TestBoard::default(),
            ram: Box::new(McuNet::empty()),
            up: FrameDecoder::new(),
        }
    }

    fn send(&mut self, msg: &Down<'_>) {
        let mut buf = [0u8; 512];
        let f = encode(msg, &mut buf).unwrap();
        self.board.rx.extend(f.iter().copied());
    }

    /// One tick; what the node sent.
    fn tick(&mut self) -> Vec<Up> {
        let missed = self.board.wait_tick();
        let mut store = McuSlots::new(&DEFAULT_NET, &mut self.ram);
        self.node.tick(&mut self.board, &mut store, missed);
        let mut out = Vec::new();
        for b in self.board.tx.drain(..) {
            if let Some(r) = self.up.push::<Up>(b) {
                out.push(r.unwrap());
            }
        }
        out
    }

    fn step(&mut self, now_ns: u64) -> Vec<Up> {
        self.send(&Down::Step { now_ns });
        self.tick()
    }
}

fn commands(ups: &[Up]) -> Vec<LinkCommand> {
    ups.iter()
        .filter_map(|u| match u {
            Up::Command(c) => Some(c.clone()),
            _ => None,
        })
        .collect()
}

fn hello(ups: &[Up]) -> Option<Hello> {
    ups.iter().rev().find_map(|u| match u {
        Up::Hello(h) => Some(*h),
        _ => None,
    })
}

fn telemetry(ups: &[Up]) -> Option<Telemetry> {
    ups.iter().find_map(|u| match u {
        Up::Telemetry(t) => Some(*t),
        _ => None,
    })
}

/// A 1 kHz configuration of the default net's four tendons.
fn setup() -> Setup {
    Setup {
        n_tendons: 4,
        max_tension: [10.0; MAX_TENDONS],
        min_tension: [0.0; MAX_TENDONS],
        slew_rate: [200.0; MAX_TENDONS],
        cocontraction_sets: [0; MAX_TENDONS],
        cocontraction_weights: [0.0; MAX_TENDONS],
        period_ns: TICK,
        watchdog_ns: 5 * TICK / 2 * 10,
        max_dt_ns: 5 * TICK,
        quaternion_tolerance: 1e-2,
        box_margin: 0.05,
        ki: 0.0,
        correction_limit: 0.003,
        feedback_timeout_ns: 20 * TICK,
        correction_window: 0.002,
        correction_filter_tau_s: 0.0,
        correction_map_gain: 0.0,
        correction_map_scale: 0.01,
        correction_map_limit: 0.0,
        jump_m: 1e-3,
        settle_after_jump_ns: 100 * TICK,
        lead_s: 0.0,
        plant_stale_ns: 20 * TICK,
        stuck_enabled: false,
        stuck_model_gain: 0.05,
        stuck_error_n: 0.5,
        stuck_persist_ns: 100 * TICK,
    }
}

/// The middle of the default net's input box, its quaternion normalised.
fn pose() -> [f32; 7] {
    let lo = DEFAULT_NET.input_lo();
    let hi = DEFAULT_NET.input_hi();
    let mut p = [0.0f32; 7];
    for (i, v) in p.iter_mut().enumerate() {
        *v = 0.5 * (lo[i] + hi[i]);
    }
    let n = p[3..].iter().map(|v| v * v).sum::<f32>().sqrt();
    for v in &mut p[3..] {
        *v /= n;
    }
    p
}

fn setpoint(seq: u32) -> Down<'static> {
    Down::Setpoint(LinkSetpoint {
        seq,
        count: 1,
        superseded_nonfinite: 0,
        pose: WirePose::from_pose(&pose()),
        velocity: None,
        tangent: None,
        age_us: 0,
    })
}

fn feedback(seq: u32, command_seq: u32) -> Down<'static> {
    Down::Feedback(Feedback {
        seq,
        count: 1,
        command_seq,
        tensions: heapless::Vec::from_slice(&[1000, 1000, 1000, 1000]).unwrap(),
        tip: [0, 0, 390_000],
        tip_seq: seq,
        tip_age_us: 0,
    })
}

/// Configured (the Setup answered with a Hello), not yet stepped.
fn configured() -> Rig {
    let mut r = Rig::new();
    r.send(&Down::Hello {
        protocol: PROTOCOL_VERSION,
    });
    r.send(&Down::Setup(setup()));
    let h = hello(&r.tick()).unwrap();
    assert_eq!(h.setup_hash, setup().hash());
    assert_eq!(h.setup_error, 0);
    assert_eq!(h.net_hash, DEFAULT_NET_CRC);
    r
}

#[test]
fn a_step_runs_one_period_at_its_time_and_stops_the_timer() {
    let mut r = configured();
    // On the timer: a command every tick (1 ms period, 1 ms tick).
    let timer: Vec<LinkCommand> = (0..5).flat_map(|_| commands(&r.tick())).collect();
    assert_eq!(timer.len(), 5);
    assert!(!r.node.lockstep());
    // The first Step starts the period afresh: its command is the first.
    r.send(&setpoint(1));
    let c = commands(&r.step(1_000_000_000));
    assert_eq!(c.len(), 1, "one command per Step");
    assert_eq!((c[0].seq, c[0].setpoint_seq), (1, 1));
    assert!(r.node.lockstep());
    assert_eq!(r.node.period().unwrap().counters().periods, 1);
    // The timer runs nothing any more, however long.
    for _ in 0..50 {
        assert!(commands(&r.tick()).is_empty());
    }
    // The period's time is the Step's: 50 ticks of silence on the board's
    // clock are no silence for the watchdog (25 ms), the Step's 1 ms is.
    r.send(&setpoint(2));
    let c = commands(&r.step(1_001_000_000));
    assert_eq!((c[0].seq, c[0].setpoint_seq), (2, 2));
    assert_eq!(c[0].events & event::WATCHDOG_HOLD, 0);
    // Silence in the Steps' time trips it.
    let c = commands(&r.step(1_100_000_000));
    assert_ne!(c[0].events & event::WATCHDOG_HOLD, 0, "{c:?}");
    // Two Steps in one read: two periods, the messages between them going
    // to the second.
    r.send(&Down::Step {
        now_ns: 1_101_000_000,
    });
    r.send(&setpoint(3));
    r.send(&Down::Step {
        now_ns: 1_102_000_000,
    });
    let c = commands(&r.tick());
    assert_eq!(c.len(), 2);
    assert_eq!((c[0].seq, c[0].setpoint_seq), (4, 2));
    assert_eq!((c[1].seq, c[1].setpoint_seq), (5, 3));
}

#[test]
fn the_same_inputs_in_lock_step_give_the_same_commands_whatever_the_board_clock() {
    let run = |idle_ticks: usize| {
        let mut r = configured();
        for _ in 0..idle_ticks {
            r.tick();
        }
        let mut out = Vec::new();
        for k in 0..300u32 {
            if k % 3 == 0 {
                r.send(&setpoint(k + 1));
            }
            r.send(&feedback(k + 1, k));
            out.extend(commands(&r.step(5_000_000 + u64::from(k) * 1_000_000)));
            // The board's clock runs on at its own pace.
            for _ in 0..(k as usize % 4) {
                r.tick();
            }
        }
        out
    };
    let a = run(0);
    let b = run(37);
    assert_eq!(a.len(), 300);
    assert_eq!(a, b);
}

/// How a period's inputs reach the chip: `waits` ticks before the next
/// period (9: the tick after the period before; 0: in the period's own
/// tick), with the age `age_us` the host gave it when it sent it.
#[derive(Clone, Copy)]
struct Arrival {
    waits: u32,
    age_us: u32,
}

/// A 100 Hz loop on the 1 kHz board with the integral loop on, a setpoint
/// that says it moves at 50 mm/s along x, and the tip seen where the
/// setpoint is, the tracker frame arriving as `frame` says, the setpoint as
/// `setpoint` says. The commands.
fn frames_waiting(frame: Arrival, setpoint: Arrival) -> Vec<LinkCommand> {
    let mut r = Rig::new();
    let mut s = setup();
    s.period_ns = 10 * TICK;
    s.watchdog_ns = 25 * s.period_ns;
    s.max_dt_ns = 5 * s.period_ns;
    s.feedback_timeout_ns = 20 * s.period_ns;
    s.plant_stale_ns = 20 * s.period_ns;
    s.ki = 10.0;
    s.slew_rate = [1e6; MAX_TENDONS];
    r.send(&Down::Setup(s));
    let mut out: Vec<LinkCommand> = Vec::new();
    let mut since_period = None;
    for k in 0..600u32 {
        if since_period == Some(9 - setpoint.waits) {
            let seq = out.len() as u32;
            let Down::Setpoint(mut sp) = self::setpoint(seq + 1) else {
                unreachable!()
            };
            sp.velocity = Some(LinkSetpoint::wire_velocity(&[
                0.05, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
            ]));
            sp.age_us = setpoint.age_us;
            r.send(&Down::Setpoint(sp));
        }
        if since_period == Some(9 - frame.waits) {
            let seq = out.len() as u32;
            let Down::Feedback(mut f) = feedback(seq, out.last().map_or(0, |c| c.seq)) else {
                unreachable!()
            };
            let p = pose();
            f.tip = [0, 1, 2].map(|i| (p[i] * 1e6).round() as i32);
            f.tip_age_us = frame.age_us;
            r.send(&Down::Feedback(f));
        }
        let c = commands(&r.tick());
        since_period = if c.is_empty() {
            since_period.map(|n| n + 1)
        } else {
            Some(0)
        };
        out.extend(c);
        assert!(k < 30 || since_period.is_some(), "no period in 30 ticks");
    }
    out
}

/// Arrived at once, or `waits` ms old just before the period.
fn at_once(waits: u32) -> Arrival {
    Arrival { waits, age_us: 0 }
}

fn on_host(waits: u32) -> Arrival {
    Arrival {
        waits: 0,
        age_us: waits * 1000,
    }
}

#[test]
fn a_frame_that_waits_for_the_period_ages_meanwhile() {
    // Sampled one tick after a period, the frame is compared with the path
    // where the robot was then, whether it waited nine ticks here (sent at
    // once) or on the host (sent nine ticks old, just before the period).
    // The setpoint is as new as the period.
    let waited_here = frames_waiting(at_once(9), at_once(0));
    let waited_on_host = frames_waiting(on_host(9), at_once(0));
    let first_difference =
        |a: &[LinkCommand], b: &[LinkCommand]| a.iter().zip(b).position(|(x, y)| x != y);
    assert_eq!(waited_here.len(), 60);
    assert_eq!(first_difference(&waited_here, &waited_on_host), None);
    // The age matters: a frame as new as the period is another sample.
    let fresh = frames_waiting(at_once(0), at_once(0));
    assert!(first_difference(&waited_on_host, &fresh).is_some());
    let corrected = |cs: &[LinkCommand]| {
        cs.iter()
            .filter(|c| c.status & tendril_shared::messages::command_status::CORRECTION != 0)
            .count()
    };
    assert!(corrected(&waited_on_host) > 30, "the loop integrated");
    assert_eq!(corrected(&fresh), 0, "a frame of the setpoint's own time");
}

#[test]
fn a_setpoint_that_waits_for_the_period_ages_meanwhile() {
    // The setpoint sent the tick after a period: led along its path by its
    // age whether it waited nine ticks here or on the host. A frame taken
    // with it then shows the tip where the path was: no error to integrate;
    // a setpoint as new as the period is led less, and the loop integrates.
    let waited_here = frames_waiting(at_once(9), at_once(9));
    let waited_on_host = frames_waiting(at_once(9), on_host(9));
    assert_eq!(waited_here.len(), 60);
    assert_eq!(waited_here, waited_on_host);
    let corrected = |cs: &[LinkCommand]| {
        cs.iter()
            .filter(|c| c.status & tendril_shared::messages::command_status::CORRECTION != 0)
            .count()
    };
    assert_eq!(
        corrected(&waited_here),
        0,
        "the setpoint was led by its age"
    );
    assert!(corrected(&frames_waiting(at_once(9), at_once(0))) > 30);
}

#[test]
fn setups_refused_kept_and_replaced() {
    let mut r = configured();
    for k in 0..10 {
        r.send(&setpoint(k + 1));
        r.step(u64::from(k) * 1_000_000);
    }
    // Refused: the Hello says why, the running period goes on.
    let mut bad = setup();
    bad.n_tendons = 0;
    r.send(&Down::Setup(bad));
    let h = hello(&r.tick()).unwrap();
    assert_eq!(h.setup_error, setup_error::TENDONS);
    assert_eq!(h.setup_hash, setup().hash());
    let mut bad = setup();
    bad.max_tension[1] = f32::NAN;
    r.send(&Down::Setup(bad));
    assert_eq!(hello(&r.tick()).unwrap().setup_error, setup_error::LIMITS);
    let mut bad = setup();
    bad.period_ns = 0;
    r.send(&Down::Setup(bad));
    assert_eq!(hello(&r.tick()).unwrap().setup_error, setup_error::TIMING);
    let c = commands(&r.step(10_000_000));
    assert_eq!(c[0].seq, 11, "a refused Setup keeps the running period");
    // The same Setup: kept, still in lock-step, counters keep counting.
    r.send(&Down::Setup(setup()));
    let h = hello(&r.tick()).unwrap();
    assert_eq!((h.setup_hash, h.setup_error), (setup().hash(), 0));
    assert!(r.node.lockstep());
    let c = commands(&r.step(11_000_000));
    assert_eq!(c[0].seq, 12);
    assert_eq!(r.node.period().unwrap().counters().periods, 12);
    // A different one: a new period, back on the timer until a Step.
    let mut other = setup();
    other.slew_rate = [150.0; MAX_TENDONS];
    r.send(&Down::Setup(other));
    let ups = r.tick();
    assert_eq!(hello(&ups).unwrap().setup_hash, other.hash());
    assert!(!r.node.lockstep());
    let c = commands(&r.tick());
    assert_eq!(c.len(), 1, "timer-driven again");
    let c = commands(&r.step(50_000_000));
    assert_eq!(c[0].seq, 1, "the first Step after a Setup starts afresh");
}

#[test]
fn a_setup_that_replaces_the_running_one_configures_as_a_fresh_node() {
    // The node configures its period in place (no `Period` on the stack):
    // a running node, with counters, a latched stuck-motor hold and the
    // integral loop's state, then another Setup, must command exactly as a
    // node configured with that Setup alone.
    let mut other = setup();
    other.ki = 4.0;
    other.correction_window = f32::INFINITY;
    other.slew_rate = [150.0; MAX_TENDONS];
    let mut running = configured();
    let mut stuck = setup();
    stuck.stuck_enabled = true;
    running.send(&Down::Setup(stuck));
    running.tick();
    for k in 0..200u32 {
        running.send(&setpoint(k + 1));
        running.send(&feedback(k + 1, k));
        running.step(u64::from(k) * 1_000_000);
    }
    assert!(running.node.period().unwrap().holding(), "a latched hold");
    running.send(&Down::Setup(other));
    running.tick();
    let mut fresh = Rig::new();
    fresh.send(&Down::Setup(other));
    fresh.tick();
    assert!(!running.node.period().unwrap().holding());
    for k in 0..100u32 {
        let now = 1_000_000_000 + u64::from(k) * 1_000_000;
        for r in [&mut running, &mut fresh] {
            r.send(&setpoint(1000 + k));
            r.send(&feedback(1000 + k, k));
        }
        let (a, b) = (commands(&running.step(now)), commands(&fresh.step(now)));
        assert_eq!(a.len(), 1);
        assert_eq!(a, b, "period {k}");
    }
    let counters = |r: &Rig| *r.node.period().unwrap().counters();
    assert_eq!(counters(&running), counters(&fresh));
    assert!(
        counters(&fresh).correction_periods > 0,
        "the loop integrated"
    );
}

#[test]
fn garbage_and_truncated_frames_between_messages_are_counted_and_cost_no_period() {
    let mut r = configured();
    let (mut bad_messages, mut frame_errors, mut seen) = (0, 0, 0);
    // Telemetry comes every TELEMETRY_EVERY ticks: run until two came.
    for k in 0..3 * TELEMETRY_EVERY {
        r.send(&setpoint(k + 1));
        match k % 4 {
            // Garbage ended by a delimiter.
            0 => {
                r.board.rx.extend([0x55, 0x13, 0xFF, 0x02, 0x00]);
                frame_errors += 1;
            }
            // A truncated frame: the next frame's delimiter ends it.
            1 => {
                let mut buf = [0u8; 512];
                let f = encode(&feedback(k, k), &mut buf).unwrap();
                let cut = f.len() / 2;
                r.board.rx.extend(f[..cut].iter().copied());
                r.board.rx.push_back(0);
                frame_errors += 1;
            }
            // A good frame whose payload is no message (variant 200).
            2 => {
                let mut buf = [0u8; 512];
                let f = encode_raw(&[200, 1, 2], &mut buf).unwrap();
                r.board.rx.extend(f.iter().copied());
                bad_messages += 1;
            }
            _ => {}
        }
        let ups = r.step(u64::from(k) * 1_000_000);
        let c = commands(&ups);
        assert_eq!(c.len(), 1, "period {k}");
        assert_eq!(
            c[0].setpoint_seq,
            k + 1,
            "the setpoint before the Step is taken"
        );
        if let Some(t) = telemetry(&ups) {
            seen += 1;
            assert_eq!(
                t.frames.cobs_errors + t.frames.crc_errors,
                frame_errors,
                "{t:?}"
            );
            assert_eq!(t.bad_messages, bad_messages, "{t:?}");
            assert_eq!(t.counters.periods, k + 1, "one period per Step");
        }
    }
    assert!(seen >= 2, "{seen} telemetry messages");
}

fn send_update(r: &mut Rig, blob: &[u8], first_period: u64) -> Vec<LinkCommand> {
    let mut out = Vec::new();
    let total = u32::try_from(blob.len()).unwrap();
    for (i, chunk) in blob.chunks(MAX_CHUNK).enumerate() {
        r.send(&Down::Chunk {
            offset: u32::try_from(i * MAX_CHUNK).unwrap(),
            total,
            bytes: chunk,
        });
        out.extend(commands(&r.step((first_period + i as u64) * 1_000_000)));
    }
    for k in 0..20 {
        let at = first_period + (blob.len() / MAX_CHUNK) as u64 + 1 + k;
        out.extend(commands(&r.step(at * 1_000_000)));
    }
    out
}

#[test]
fn a_chunked_update_is_swapped_in_and_a_corrupted_one_rejected() {
    let blob: &[u8] = include_bytes!("../../vectors/default.tnet");
    let mut r = configured();
    r.step(0);
    // Corrupted in the middle (weights): the check refuses it.
    let mut bad = blob.to_vec();
    let mid = bad.len() / 2;
    bad[mid] ^= 0x5A;
    let c = send_update(&mut r, &bad, 1);
    let ev = c.iter().fold(0, |a, c| a | c.events);
    assert_ne!(ev & event::WEIGHTS_REJECTED, 0);
    assert_eq!(ev & event::WEIGHTS_SWAPPED, 0);
    // An out-of-order chunk is refused at once, in the next command.
    r.send(&Down::Chunk {
        offset: 999,
        total: u32::try_from(blob.len()).unwrap(),
        bytes: &blob[..10],
    });
    let c = commands(&r.step(500_000_000));
    assert_ne!(c[0].events & event::WEIGHTS_REJECTED, 0);
    // The valid one swaps in.
    let c = send_update(&mut r, blob, 501);
    let swaps = c
        .iter()
        .filter(|c| c.events & event::WEIGHTS_SWAPPED != 0)
        .count();
    assert_eq!(
        swaps,
        1,
        "{:?}",
        c.iter().map(|c| c.events).collect::<Vec<_>>()
    );
    assert_eq!(r.node.period().unwrap().counters().weight_swaps, 1);
}

/// The Hello names the net that runs: the built-in one until an update is
/// swapped in (a refused one changes nothing), then the update's, so that a
/// bridge that reconnects sends its net only when the chip lacks it.
#[test]
fn the_hello_names_the_net_that_runs() {
    let builtin: &[u8] = include_bytes!("../../vectors/default.tnet");
    // Another valid net: one weight's lowest mantissa bit flipped, the CRC
    // field made right again.
    let mut other = builtin.to_vec();
    let body = other.len() - 4;
    other[(body / 2) & !3] ^= 1;
    let crc = tendril_shared::crc32::crc32(&other[..body]);
    other[body..].copy_from_slice(&crc.to_le_bytes());
    let other_hash = tendril_shared::tnet::net_hash(&other);
    assert_ne!(other_hash, DEFAULT_NET_CRC);
    let mut r = configured();
    r.step(0);
    let ask = |r: &mut Rig| {
        r.send(&Down::Hello {
            protocol: tendril_shared::link::wire::PROTOCOL_VERSION,
        });
        hello(&r.tick()).unwrap().net_hash
    };
    assert_eq!(ask(&mut r), DEFAULT_NET_CRC);
    let mut corrupt = other.clone();
    corrupt[body / 3] ^= 0x5A;
    let c = send_update(&mut r, &corrupt, 1);
    assert_ne!(
        c.iter().fold(0, |a, c| a | c.events) & event::WEIGHTS_REJECTED,
        0
    );
    assert_eq!(
        ask(&mut r),
        DEFAULT_NET_CRC,
        "a refused update changes nothing"
    );
    let c = send_update(&mut r, &other, 501);
    assert_ne!(
        c.iter().fold(0, |a, c| a | c.events) & event::WEIGHTS_SWAPPED,
        0
    );
    assert_eq!(ask(&mut r), other_hash, "the swapped-in net's hash");
}

/// A valid `Setup` for `n` tendons: limits, antagonistic pairs or none,
/// times and gains from the strategy's draws.
fn setup_from(n: usize, paired: bool, f: &[f32; 16], t: &[u32; 7]) -> Setup {
    let mut s = Setup {
        n_tendons: n as u8,
        max_tension: [0.0; MAX_TENDONS],
        min_tension: [0.0; MAX_TENDONS],
        slew_rate: [0.0; MAX_TENDONS],
        cocontraction_sets: [0; MAX_TENDONS],
        cocontraction_weights: [0.0; MAX_TENDONS],
        period_ns: t[0],
        watchdog_ns: t[1],
        max_dt_ns: t[2],
        quaternion_tolerance: f[0],
        box_margin: f[1],
        ki: f[2],
        correction_limit: f[3],
        feedback_timeout_ns: t[3],
        correction_window: f[4],
        correction_filter_tau_s: f[5],
        correction_map_gain: f[6],
        correction_map_scale: f[7],
        correction_map_limit: f[8],
        jump_m: f[9],
        settle_after_jump_ns: t[4],
        lead_s: f[10],
        plant_stale_ns: t[5],
        stuck_enabled: true,
        stuck_model_gain: f[11],
        stuck_error_n: f[12],
        stuck_persist_ns: t[6],
    };
    for i in 0..n {
        s.max_tension[i] = 1.0 + f[13] * (i + 1) as f32;
        s.min_tension[i] = s.max_tension[i] * 0.001 * f[14];
        s.slew_rate[i] = 1.0 + f[15];
        if paired {
            s.cocontraction_sets[i] = (i / 2) as u8;
            s.cocontraction_weights[i] = 1.0;
        } else {
            s.cocontraction_sets[i] = tendril_shared::CoContraction::NONE;
        }
    }
    s
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(256))]

    /// `setup_of` inverts `period_config`: any valid link `Setup` becomes a
    /// period configuration and comes back bit for bit, so the host's
    /// bridge, the chip and the budget image speak one mapping.
    #[test]
    fn setup_round_trips_through_the_period_configuration(
        half in 1usize..=MAX_TENDONS / 2,
        odd in proptest::bool::ANY,
        paired in proptest::bool::ANY,
        f in proptest::array::uniform16(0.001f32..100.0),
        t in proptest::array::uniform7(1u32..=u32::MAX),
    ) {
        // Pairs need an even count.
        let n = if odd && !paired { 2 * half - 1 } else { 2 * half };
        let s = setup_from(n, paired, &f, &t);
        let p = crate::node::period_config(&s).expect("a valid setup");
        proptest::prop_assert_eq!(crate::node::setup_of(&p), s);
    }
}
