//! Input traces of the control period and their replay (docs/design.md
//! §5.7): a [`Trace`] is a Setup and a list of periods, each with the
//! link bytes delivered before it and its time. In lock-step mode
//! ([`Down::Step`]) these are every input a period has, so replaying a
//! trace through the host build of the node ([`replay_host`]) and through
//! the chip image under QEMU ([`replay_chip`]) must give the same commands,
//! bit for bit ([`first_difference`]).
//!
//! The file format is postcard ([`Trace::to_bytes`]): the link's own
//! codec, compact, and exact for every `f32` — JSON cannot hold the
//! Setup's ∞ correction window or a NaN.
//!
//! [`synthetic`] makes a trace closed-loop against the host build itself
//! (feedback follows the commands with noise), covering every rule of the
//! period: setpoints along a circle with velocity and tangent, bursts and
//! gaps, a NaN, an outside and a non-unit setpoint, a planner restart and
//! lost setpoints, silence that trips the watchdog and the plant-stale
//! rule, garbage and truncated frames, a corrupted and a valid weight
//! update in chunks, an out-of-order chunk, the same Setup again, and a
//! stuck motor.

use std::collections::VecDeque;
use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use tendril_firmware::board::Board;
use tendril_firmware::node::{Node, MCU_UPDATE_CAPACITY};
use tendril_firmware::{McuNet, McuSlots, DEFAULT_NET, DEFAULT_NET_CRC};
use tendril_shared::link::wire::{
    units, Down, Feedback, LinkCommand, LinkSetpoint, LinkTangent, Setup, Up, WirePose, MAX_CHUNK,
    MAX_UP_PAYLOAD, PROTOCOL_VERSION,
};
use tendril_shared::link::{encode, max_frame_len, FrameDecoder};

use super::bridge::ChipLink;
use super::McuLink;

/// What reaches the node before a period: a message, or raw bytes
/// (garbage, a truncated frame).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Delivery {
    /// A Setup (the running one is kept).
    Setup(Setup),
    /// A setpoint.
    Setpoint(LinkSetpoint),
    /// Plant feedback.
    Feedback(Feedback),
    /// A weight-update chunk.
    Chunk {
        /// Where the bytes go.
        offset: u32,
        /// The update's length.
        total: u32,
        /// The bytes.
        bytes: Vec<u8>,
    },
    /// Bytes as they are on the wire.
    Raw(Vec<u8>),
}

impl Delivery {
    /// The bytes on the wire: a frame, or the raw bytes.
    pub fn wire(&self) -> Result<Vec<u8>> {
        let msg = match self {
            Delivery::Raw(b) => return Ok(b.clone()),
            Delivery::Setup(s) => Down::Setup(*s),
            Delivery::Setpoint(s) => Down::Setpoint(*s),
            Delivery::Feedback(f) => Down::Feedback(f.clone()),
            Delivery::Chunk {
                offset,
                total,
                bytes,
            } => Down::Chunk {
                offset: *offset,
                total: *total,
                bytes,
            },
        };
        frame(&msg)
    }
}

fn frame(msg: &Down<'_>) -> Result<Vec<u8>> {
    let mut buf = [0u8; 512];
    Ok(encode(msg, &mut buf)
        .map_err(|e| anyhow!("link frame: {e}"))?
        .to_vec())
}

/// A Step's bytes: a 0x00 first, so garbage without a delimiter before
/// it cannot swallow it (a lone delimiter costs nothing).
fn step_wire(now_ns: u64) -> Result<Vec<u8>> {
    let mut out = vec![0];
    out.extend(frame(&Down::Step { now_ns })?);
    Ok(out)
}

/// One period of a trace.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TracePeriod {
    /// What arrives before it, in order.
    pub deliveries: Vec<Delivery>,
    /// Its time (the Step's), ns.
    pub now_ns: u64,
}

/// A Setup and the periods after it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Trace {
    /// The controller's configuration, sent first.
    pub setup: Setup,
    /// The first Step's time, ns: it enters lock-step with nothing
    /// delivered before it (until then the chip's timer runs periods,
    /// which would race with any message), and its command is command 0.
    pub start_ns: u64,
    /// The periods, each ended by a Step.
    pub periods: Vec<TracePeriod>,
}

impl Trace {
    /// The file's bytes (postcard).
    pub fn to_bytes(&self) -> Result<Vec<u8>> {
        postcard::to_stdvec(self).context("encoding the trace")
    }

    /// From a file's bytes.
    pub fn from_bytes(bytes: &[u8]) -> Result<Trace> {
        postcard::from_bytes(bytes).context("decoding the trace")
    }

    /// Write to `path` (atomically: the project's one output path).
    pub fn save(&self, path: &Path) -> Result<()> {
        crate::fsutil::write_atomic(path, &self.to_bytes()?)
            .with_context(|| format!("writing {}", path.display()))
    }

    /// Read from `path`.
    pub fn load(path: &Path) -> Result<Trace> {
        Trace::from_bytes(
            &std::fs::read(path).with_context(|| format!("reading {}", path.display()))?,
        )
    }
}

/// A command as compared: every field, tensions as their bits.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CommandBits {
    /// The command's sequence number.
    pub seq: u32,
    /// The setpoint it used.
    pub setpoint_seq: u32,
    /// The status word.
    pub status: u32,
    /// The event bits.
    pub events: u32,
    /// `f32::to_bits` of each tension.
    pub tensions: Vec<u32>,
}

impl From<&LinkCommand> for CommandBits {
    fn from(c: &LinkCommand) -> Self {
        CommandBits {
            seq: c.seq,
            setpoint_seq: c.setpoint_seq,
            status: c.status,
            events: c.events,
            tensions: c.tensions.iter().map(|t| t.to_bits()).collect(),
        }
    }
}

/// Where two replays first differ.
#[derive(Clone, Debug, PartialEq)]
pub struct Difference {
    /// The period (0 = the first Step's).
    pub period: usize,
    /// The one side's command there (None: it has fewer).
    pub a: Option<CommandBits>,
    /// The other's.
    pub b: Option<CommandBits>,
}

/// The first period whose commands differ in any bit, if any.
pub fn first_difference(a: &[LinkCommand], b: &[LinkCommand]) -> Option<Difference> {
    (0..a.len().max(b.len())).find_map(|i| {
        let x = a.get(i).map(CommandBits::from);
        let y = b.get(i).map(CommandBits::from);
        (x != y).then_some(Difference {
            period: i,
            a: x,
            b: y,
        })
    })
}

/// The host's board for the node: bytes in, bytes out, a clock the caller
/// owns. Not a mock of the node: the node is the firmware's own code.
#[derive(Default)]
struct ByteBoard {
    rx: VecDeque<u8>,
    tx: Vec<u8>,
    now_ns: u64,
}

impl Board for ByteBoard {
    fn wait_tick(&mut self) -> u32 {
        self.now_ns += 1_000_000;
        0
    }
    fn now_ns(&self) -> u64 {
        self.now_ns
    }
    fn set_tensions(&mut self, _: &[f32]) {}
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

/// The host build of the chip's node (`tendril_firmware::node::Node`, the
/// chip's update capacity) on a [`ByteBoard`], with the chip's store: the
/// built-in net plus one RAM slot.
pub struct HostNode {
    node: Box<Node<MCU_UPDATE_CAPACITY>>,
    board: ByteBoard,
    ram: Box<McuNet>,
    up: FrameDecoder<{ max_frame_len(MAX_UP_PAYLOAD) }>,
}

impl Default for HostNode {
    fn default() -> Self {
        HostNode::new()
    }
}

impl HostNode {
    /// Unconfigured, on a 1 kHz board clock (the chip's).
    pub fn new() -> HostNode {
        HostNode {
            node: Box::new(Node::new(DEFAULT_NET_CRC, 1_000_000)),
            board: ByteBoard::default(),
            ram: Box::new(McuNet::empty()),
            up: FrameDecoder::new(),
        }
    }

    /// Queue bytes for the node.
    pub fn deliver(&mut self, bytes: &[u8]) {
        self.board.rx.extend(bytes.iter().copied());
    }

    /// One board tick; what the node sent.
    pub fn tick(&mut self) -> Vec<Up> {
        let missed = self.board.wait_tick();
        let mut store = McuSlots::new(&DEFAULT_NET, &mut self.ram);
        self.node.tick(&mut self.board, &mut store, missed);
        let mut out = Vec::new();
        for b in self.board.tx.drain(..) {
            if let Some(Ok(m)) = self.up.push::<Up>(b) {
                out.push(m);
            }
        }
        out
    }

    /// Configure with `setup` (a Hello and the Setup, as the bridge does).
    pub fn open(&mut self, setup: &Setup) -> Result<()> {
        self.deliver(&frame(&Down::Hello {
            protocol: PROTOCOL_VERSION,
        })?);
        self.deliver(&frame(&Down::Setup(*setup))?);
        let ups = self.tick();
        match ups.iter().rev().find_map(|u| match u {
            Up::Hello(h) => Some(*h),
            _ => None,
        }) {
            Some(h) if h.setup_error == 0 && h.setup_hash == setup.hash() => Ok(()),
            h => bail!("the node did not take the Setup: {h:?}"),
        }
    }

    /// `bytes` then one tick: the commands it sent.
    pub fn run(&mut self, bytes: &[u8]) -> Vec<LinkCommand> {
        self.deliver(bytes);
        commands(self.tick())
    }
}

fn commands(ups: Vec<Up>) -> Vec<LinkCommand> {
    ups.into_iter()
        .filter_map(|u| match u {
            Up::Command(c) => Some(c),
            _ => None,
        })
        .collect()
}

/// The first Step's bytes: the Step and a Hello request, whose answer
/// (after the Step's command) marks which command was the Step's.
fn start_wire(trace: &Trace) -> Result<Vec<u8>> {
    let mut w = step_wire(trace.start_ns)?;
    w.extend(frame(&Down::Hello {
        protocol: PROTOCOL_VERSION,
    })?);
    Ok(w)
}

/// Every period's bytes (deliveries, then the Step).
fn period_wire(p: &TracePeriod) -> Result<Vec<u8>> {
    let mut w = Vec::new();
    for d in &p.deliveries {
        w.extend(d.wire()?);
    }
    w.extend(step_wire(p.now_ns)?);
    Ok(w)
}

/// Replay through the host build: one command per Step (the first Step's
/// first), or an error naming the period that sent none.
pub fn replay_host(trace: &Trace) -> Result<Vec<LinkCommand>> {
    let mut node = HostNode::new();
    node.open(&trace.setup)?;
    let mut out = Vec::with_capacity(trace.periods.len() + 1);
    for (i, wire) in std::iter::once(start_wire(trace))
        .chain(trace.periods.iter().map(period_wire))
        .enumerate()
    {
        let c = node.run(&wire?);
        match c.as_slice() {
            [c] => out.push(c.clone()),
            _ => bail!("host: period {i} sent {} commands", c.len()),
        }
    }
    Ok(out)
}

/// Replay through a chip (the image under QEMU) on `link`: each period's
/// bytes, then wait for its command (at most `timeout`).
pub fn replay_chip(trace: &Trace, link: McuLink, timeout: Duration) -> Result<Vec<LinkCommand>> {
    let mut chip = ChipLink::open(link, &trace.setup)?;
    if chip.hello.net_hash != DEFAULT_NET_CRC {
        bail!(
            "the chip's built-in net {:08x} is not the host build's {:08x}",
            chip.hello.net_hash,
            DEFAULT_NET_CRC
        );
    }
    // Timer-driven commands until the first Step: let them drain, then
    // take the last command before the Hello that follows the Step.
    chip.poll(Duration::from_millis(50));
    chip.drain().for_each(drop);
    chip.send_raw(&start_wire(trace)?)?;
    let mut out = Vec::with_capacity(trace.periods.len() + 1);
    let t0 = Instant::now();
    let mut last = None;
    'start: loop {
        if t0.elapsed() > timeout {
            bail!("chip: no answer to the first Step in {timeout:?}");
        }
        chip.poll(Duration::from_millis(5));
        for m in chip.drain().collect::<Vec<_>>() {
            match m {
                Up::Command(c) => last = Some(c),
                Up::Hello(_) => break 'start,
                Up::Telemetry(_) => {}
            }
        }
    }
    out.push(last.ok_or_else(|| anyhow!("chip: no command before the Hello"))?);
    for (i, p) in trace.periods.iter().enumerate() {
        chip.send_raw(&period_wire(p)?)?;
        let t0 = Instant::now();
        let c = loop {
            if let Some(c) = chip.drain().find_map(|m| match m {
                Up::Command(c) => Some(c),
                _ => None,
            }) {
                break c;
            }
            if t0.elapsed() > timeout {
                bail!("chip: no command for period {} in {timeout:?}", i + 1);
            }
            chip.poll(Duration::from_millis(2));
        };
        out.push(c);
    }
    // Nothing more: one command per Step.
    chip.poll(Duration::from_millis(50));
    let extra = chip.drain().filter(|m| matches!(m, Up::Command(_))).count();
    if extra > 0 {
        bail!("chip: {extra} commands after the last Step");
    }
    Ok(out)
}

/// The default net's input box, midpoint and half-width per coordinate.
fn input_box() -> ([f32; 7], [f32; 7]) {
    let (lo, hi) = (DEFAULT_NET.input_lo(), DEFAULT_NET.input_hi());
    let mut mid = [0.0f32; 7];
    let mut half = [0.0f32; 7];
    for i in 0..7 {
        let (l, h) = (
            lo.get(i).copied().unwrap_or(0.0),
            hi.get(i).copied().unwrap_or(0.0),
        );
        mid[i] = 0.5 * (l + h);
        half[i] = 0.5 * (h - l);
    }
    (mid, half)
}

/// A constant-curvature pose of a `length` m backbone whose tip sits
/// `(x, y)` off the axis (the seed robot bends like this to first order).
fn cc_pose(length: f32, x: f32, y: f32) -> [f32; 7] {
    let r = (x * x + y * y).sqrt();
    let phi = y.atan2(x);
    // Lateral offset L(1 − cos θ)/θ ≈ Lθ/2: θ from it by two Newton steps.
    let mut th = 2.0 * r / length;
    for _ in 0..2 {
        if th > 1e-6 {
            let f = length * (1.0 - th.cos()) / th - r;
            let df = length * (th * th.sin() - (1.0 - th.cos())) / (th * th);
            th -= f / df;
        }
    }
    let z = if th > 1e-6 {
        length * th.sin() / th
    } else {
        length
    };
    let (s, c) = (th / 2.0).sin_cos();
    [x, y, z, c, -phi.sin() * s, phi.cos() * s, 0.0]
}

/// A closed-loop trace of `periods` periods (≥ 2000 covers every rule)
/// for `setup` on the default net, `update` being a valid `.tnet` for it;
/// deterministic in `seed`. The plant is the host build's commands,
/// followed with the healthy-motor lag and noise; the scenario is in
/// [`synthetic`]'s module doc.
pub fn synthetic(setup: &Setup, update: &[u8], periods: usize, seed: u64) -> Result<Trace> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = usize::from(setup.n_tendons);
    let dt = u64::from(setup.period_ns);
    let start_ns = 1_000_000_000;
    let mut trace = Trace {
        setup: *setup,
        start_ns,
        periods: Vec::with_capacity(periods),
    };
    let mut node = HostNode::new();
    node.open(setup)?;
    let first = node.run(&start_wire(&trace)?);
    let mut cmd = first
        .first()
        .cloned()
        .ok_or_else(|| anyhow!("no command for the first Step"))?;
    let (mid, half) = input_box();
    // The circle: 15 mm about the axis at the box's middle height, 0.5 Hz.
    let length = mid[2];
    let radius = (0.015f32).min(0.5 * half[0].min(half[1]));
    let pose_at = |t: f32| {
        let a = std::f32::consts::TAU * 0.5 * t;
        cc_pose(length, mid[0] + radius * a.cos(), mid[1] + radius * a.sin())
    };
    let gain = setup.stuck_model_gain;
    let mut plant = [0.0f32; tendril_shared::MAX_TENDONS];
    let (mut sp_seq, mut fb_seq) = (0u32, 0u32);
    // Scenario periods, as fractions of the trace so any length ≥ 2000
    // covers them all.
    let at = |f: f64| (f * periods as f64) as usize;
    let bad_update = {
        let mut b = update.to_vec();
        let i = b.len() / 2;
        if let Some(v) = b.get_mut(i) {
            *v ^= 0x5A;
        }
        b
    };
    let chunks = |blob: &[u8]| -> Vec<Delivery> {
        blob.chunks(MAX_CHUNK)
            .enumerate()
            .map(|(i, c)| Delivery::Chunk {
                offset: (i * MAX_CHUNK) as u32,
                total: blob.len() as u32,
                bytes: c.to_vec(),
            })
            .collect()
    };
    let mut bad_chunks: VecDeque<Delivery> = VecDeque::new();
    let mut good_chunks: VecDeque<Delivery> = VecDeque::new();
    let silence = at(0.20)..at(0.20) + 40;
    let stuck_from = at(0.85);
    for k in 0..periods {
        let now = start_ns + (k as u64 + 1) * dt;
        let t = (k as f64 * dt as f64 * 1e-9) as f32;
        let mut d = Vec::new();
        if k == at(0.30) {
            bad_chunks = chunks(&bad_update).into();
        }
        if k == at(0.50) {
            good_chunks = chunks(update).into();
        }
        if !silence.contains(&k) {
            // Setpoints: usually one, sometimes two (the older superseded)
            // or none (a late planner).
            let special = [0.10, 0.12, 0.14, 0.60, 0.65].map(at).contains(&k);
            let burst = match rng.random_range(0..20) {
                0 if !special => 0,
                1 => 2,
                _ => 1,
            };
            for _ in 0..burst {
                sp_seq += 1;
                if k == at(0.60) {
                    sp_seq = 1; // a planner restart
                }
                if k == at(0.65) {
                    sp_seq += 5; // lost setpoints
                }
                let mut pose = pose_at(t);
                let ahead = pose_at(t + 1e-3);
                let vel: [f32; 7] = std::array::from_fn(|i| (ahead[i] - pose[i]) / 1e-3);
                if k == at(0.10) {
                    pose[0] = f32::NAN;
                }
                if k == at(0.12) {
                    pose[0] = mid[0] + 10.0 * half[0]; // outside the box
                }
                if k == at(0.14) {
                    pose[3] *= 1.5; // not a unit quaternion
                }
                let tangent = (k % 50 == 0).then(|| {
                    let h = 1e-4;
                    let p0 = pose_at(t);
                    let col = |dx: f32, dy: f32| {
                        let p = cc_pose(length, p0[0] + dx, p0[1] + dy);
                        std::array::from_fn(|i| (p[i] - p0[i]) / h)
                    };
                    LinkTangent {
                        dim: 2,
                        columns: [col(h, 0.0), col(0.0, h), [0.0; 7]],
                        axes: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0; 3]],
                    }
                });
                d.push(Delivery::Setpoint(LinkSetpoint {
                    seq: sp_seq,
                    count: 1,
                    superseded_nonfinite: 0,
                    pose: WirePose::from_pose(&pose),
                    velocity: Some(LinkSetpoint::wire_velocity(&vel)),
                    tangent,
                    // Taken 1–9 ms after the planner sent it (the period
                    // leads the pose by that).
                    age_us: 1_000 + (k % 7) as u32 * 1_300,
                }));
            }
            // Feedback: the plant follows the last command with the
            // healthy motor's lag; from `stuck_from` motor 0 is stuck.
            for (i, p) in plant.iter_mut().enumerate().take(n) {
                let target = cmd.tensions.get(i).copied().unwrap_or(0.0);
                if k >= stuck_from && i == 0 {
                    *p = 5.0; // jammed: reads 5 N whatever it is told
                } else {
                    *p += gain * (target - *p);
                }
            }
            // One in ten is lost on its way (the plant counted it).
            fb_seq += 1;
            if rng.random_range(0..10) != 0 {
                let p0 = pose_at(t);
                let noise = |rng: &mut ChaCha8Rng, s: f32| rng.random_range(-s..s);
                let mut tensions = heapless::Vec::new();
                for p in plant.iter().take(n) {
                    let v = units::to_i32(p + noise(&mut rng, 0.005), units::TENSION_N);
                    let _ = tensions.push(v);
                }
                let tip = [0, 1, 2]
                    .map(|i| units::to_i32(p0[i] + noise(&mut rng, 2e-4), units::POSITION_M));
                d.push(Delivery::Feedback(Feedback {
                    seq: fb_seq,
                    count: 1,
                    command_seq: cmd.seq,
                    tensions,
                    tip,
                    // A tracker slower than the loop: a new frame every
                    // fourth period, delivered 2–20 ms late.
                    tip_seq: (k / 4) as u32 + 1,
                    tip_age_us: rng.random_range(2_000..20_000),
                }));
            }
        }
        if let Some(c) = bad_chunks.pop_front() {
            d.push(c);
        } else if let Some(c) = good_chunks.pop_front() {
            d.push(c);
        }
        if k == at(0.45) {
            // Out of order: refused at once.
            d.push(Delivery::Chunk {
                offset: 999,
                total: update.len() as u32,
                bytes: vec![1, 2, 3],
            });
        }
        if k == at(0.25) {
            d.insert(0, Delivery::Raw(vec![0x55, 0x13, 0xFF, 0x02, 0x00]));
        }
        if k == at(0.26) {
            // A truncated frame, ended by a delimiter.
            if let Some(Ok(mut w)) = d.first().map(Delivery::wire) {
                w.truncate(w.len() / 2);
                w.push(0);
                d.insert(0, Delivery::Raw(w));
            }
        }
        if k == at(0.70) {
            d.push(Delivery::Setup(*setup)); // the running one: kept
        }
        let p = TracePeriod {
            deliveries: d,
            now_ns: now,
        };
        let c = node.run(&period_wire(&p)?);
        cmd = match c.as_slice() {
            [c] => c.clone(),
            _ => bail!("synthetic: period {k} sent {} commands", c.len()),
        };
        trace.periods.push(p);
    }
    Ok(trace)
}
