//! The host's end of the chip's link: the chip's configuration from the
//! controller's ([`setup_for`], [`setup_of`]), the messages a setpoint and
//! a plant state become ([`link_setpoint`], [`link_feedback`]), and the
//! open link itself with its framing ([`ChipLink`]).

use std::time::Duration;

use anyhow::{anyhow, bail, Result};
pub use tendril_firmware::node::setup_of;
use tendril_shared::link::wire::{
    units, Down, Feedback, Hello, LinkSetpoint, LinkTangent, Setup, Up, WirePose, MAX_UP_PAYLOAD,
    PROTOCOL_VERSION,
};
use tendril_shared::link::{encode, max_frame_len, FrameCounters, FrameDecoder};
use tendril_shared::messages::{setpoint_flags, PlantState, Setpoint};

use super::McuLink;
use crate::ipc::controller::{period_config, ControllerConfig};
use crate::ipc::IpcError;
use crate::robot::Robot;

/// The chip's configuration for `cfg` and the robot: the host controller's
/// own period configuration, flattened for the link.
pub fn setup_for(cfg: &ControllerConfig, robot: &Robot) -> Result<Setup, IpcError> {
    let p = period_config(cfg, robot)?;
    Ok(setup_of(&p))
}

/// The planner's setpoint as a link message sent at `now_ns` (its age is
/// measured to it); the tangent only when it differs from `last` (the chip
/// keeps the last one).
pub fn link_setpoint(
    s: &Setpoint,
    count: usize,
    superseded_nonfinite: usize,
    last: &mut Option<LinkTangent>,
    now_ns: u64,
) -> LinkSetpoint {
    let tangent = (s.flags & setpoint_flags::HAS_TANGENT != 0).then_some(LinkTangent {
        dim: s.tangent_dim.min(3) as u8,
        columns: s.tangent,
        axes: s.tangent_axes,
    });
    let send_tangent = match (tangent, *last) {
        (Some(t), Some(l)) => !close(&t, &l),
        (Some(_), None) => true,
        _ => false,
    };
    if send_tangent {
        *last = tangent;
    }
    LinkSetpoint {
        seq: s.header.seq as u32,
        count: count.min(u16::MAX as usize) as u16,
        superseded_nonfinite: superseded_nonfinite.min(u16::MAX as usize) as u16,
        pose: WirePose::from_pose(&s.pose),
        velocity: (s.flags & setpoint_flags::HAS_VELOCITY != 0)
            .then(|| LinkSetpoint::wire_velocity(&s.velocity)),
        tangent: if send_tangent { tangent } else { None },
        age_us: age_us(now_ns, s.header.stamp_ns),
    }
}

/// Whether two tangents agree to 1 % (the tangent is a first-order model
/// of the reachable poses: a 1 % change moves a correction of at most 3 mm
/// by at most 30 µm, and sending it on every setpoint would take 120 of the
/// ~130 bytes the emulated link carries per period).
fn close(a: &LinkTangent, b: &LinkTangent) -> bool {
    a.dim == b.dim
        && a.columns
            .iter()
            .flatten()
            .chain(a.axes.iter().flatten())
            .zip(b.columns.iter().flatten().chain(b.axes.iter().flatten()))
            .all(|(x, y)| (x - y).abs() <= 1e-2 * (1.0 + x.abs().max(y.abs())))
}

/// The plant's state as a link message, sent at `now_ns` (the tracker
/// frame's age is measured to it: the chip's clock is not the host's).
pub fn link_feedback(f: &PlantState, count: usize, n: usize, now_ns: u64) -> Feedback {
    let mut tensions = heapless::Vec::new();
    for &t in f.tensions.iter().take(n) {
        let _ = tensions.push(units::to_i32(t, units::TENSION_N));
    }
    Feedback {
        seq: f.header.seq as u32,
        count: count.min(u16::MAX as usize) as u16,
        command_seq: f.command_seq as u32,
        tensions,
        tip: [0, 1, 2].map(|i| units::to_i32(f.tip_pose[i], units::POSITION_M)),
        tip_seq: f.tip_seq,
        tip_age_us: age_us(now_ns, f.tip_stamp_ns),
    }
}

/// The link to a configured chip: frames out, messages in.
pub struct ChipLink {
    link: McuLink,
    rx: FrameDecoder<{ max_frame_len(MAX_UP_PAYLOAD) }>,
    inbox: Vec<Up>,
    buf: Vec<u8>,
    /// The chip's Hello after configuration.
    pub hello: Hello,
}

impl ChipLink {
    /// Connect, check the protocol, and configure the chip with `setup`
    /// (kept if it already runs it). Then send `model` if it is not the
    /// chip's built-in net.
    pub fn open(link: McuLink, setup: &Setup) -> Result<ChipLink> {
        let mut me = ChipLink {
            link,
            rx: FrameDecoder::new(),
            inbox: Vec::new(),
            buf: vec![0; 1024],
            hello: Hello {
                protocol: 0,
                net_hash: 0,
                setup_hash: 0,
                setup_error: 0,
            },
        };
        // A 0x00 first: whatever the chip's decoder holds from an earlier
        // host is dropped, not merged with the first frame.
        me.link.send(&[0])?;
        me.send(&Down::Hello {
            protocol: PROTOCOL_VERSION,
        })?;
        let hello = me.wait_hello(Duration::from_secs(10), |_| true)?;
        if hello.protocol != PROTOCOL_VERSION {
            bail!(
                "the chip speaks link protocol {}, this tendril {}: rebuild the image (it is built by `tendril controller --mcu` from this checkout)",
                hello.protocol,
                PROTOCOL_VERSION
            );
        }
        let want = setup.hash();
        if hello.setup_hash != want {
            me.send(&Down::Setup(*setup))?;
            let h = me.wait_hello(Duration::from_secs(5), |h| {
                h.setup_hash == want || h.setup_error != 0
            })?;
            if h.setup_error != 0 {
                bail!(
                    "the chip refused the controller's configuration (error {})",
                    h.setup_error
                );
            }
            me.hello = h;
        } else {
            me.hello = hello;
        }
        Ok(me)
    }

    fn wait_hello(&mut self, timeout: Duration, ok: impl Fn(&Hello) -> bool) -> Result<Hello> {
        let t0 = std::time::Instant::now();
        while t0.elapsed() < timeout {
            self.poll(Duration::from_millis(20));
            let found = self.inbox.iter().rev().find_map(|m| match m {
                Up::Hello(h) if ok(h) => Some(*h),
                _ => None,
            });
            self.inbox.clear();
            if let Some(h) = found {
                return Ok(h);
            }
        }
        Err(anyhow!("no answer from the chip in {timeout:?}"))
    }

    /// Send one message.
    pub fn send(&mut self, msg: &Down<'_>) -> Result<()> {
        let frame = encode(msg, &mut self.buf).map_err(|e| anyhow!("link frame: {e}"))?;
        self.link.send(frame)
    }

    /// Send raw bytes (garbage injection).
    pub fn send_raw(&mut self, bytes: &[u8]) -> Result<()> {
        self.link.send(bytes)
    }

    /// Decode what arrived within `timeout` into the inbox.
    pub fn poll(&mut self, timeout: Duration) {
        let mut first = self.link.recv(timeout);
        while let Some(bytes) = first.take().or_else(|| self.link.try_recv()) {
            for b in bytes {
                if let Some(Ok(msg)) = self.rx.push::<Up>(b) {
                    self.inbox.push(msg);
                }
            }
        }
    }

    /// Messages decoded so far (drained).
    pub fn drain(&mut self) -> std::vec::Drain<'_, Up> {
        self.inbox.drain(..)
    }

    /// The bridge's frame counters.
    pub fn counters(&self) -> FrameCounters {
        self.rx.counters()
    }

    /// Bytes sent but not yet read by the chip.
    pub fn backlog(&self) -> usize {
        self.link.backlog()
    }

    /// Bytes sent and received.
    pub fn bytes(&self) -> (u64, u64) {
        (self.link.bytes_sent(), self.link.bytes_received())
    }
}

/// How long before `now_ns` something stamped `stamp_ns` was sent or
/// measured, µs (saturating): the ages the link carries.
fn age_us(now_ns: u64, stamp_ns: u64) -> u32 {
    (now_ns.saturating_sub(stamp_ns) / 1000).min(u64::from(u32::MAX)) as u32
}
