//! The messages of the host ↔ MCU link (docs/design.md §5.6): postcard
//! enums, one per direction, carried in the frames of [`super::frame`].
//!
//! A session: the host sends [`Down::Hello`]; the chip answers
//! [`Up::Hello`] with its protocol version, the hash of its built-in net
//! and the hash of its configuration (0 = none). If the configuration hash
//! differs from the robot file's, the host sends [`Down::Setup`] (the
//! controller's whole configuration, nothing on the chip hard-coded) and
//! the chip answers [`Up::Hello`] again with the new hash. From then on the
//! host forwards setpoints, plant feedback and weight-update chunks as they
//! come; the chip runs one period per tick of its own timer and sends a
//! [`Up::Command`] every period and a [`Up::Telemetry`] every
//! [`TELEMETRY_EVERY`] periods. A Setup with the configuration the chip
//! already runs keeps its controller (a host that reconnects does not
//! reset the loop).
//!
//! Sequence numbers are `u32` on the wire (postcard varints: small while
//! small). A sequence that does not advance is taken as a restart of its
//! sender (a new planner or plant) by the period's rules and counted; a gap
//! is counted as lost messages.

use serde::{Deserialize, Serialize};

use crate::counters::Counters;
use crate::link::FrameCounters;
use crate::MAX_TENDONS;

/// Version of this message set; a chip and host of different versions
/// refuse to run together (the host says which to rebuild).
///
/// 2: [`Down::Step`] (lock-step mode). It is appended as the last variant,
/// so every older message keeps its postcard tag, but a version-1 chip
/// would count a Step as a bad message and keep running on its timer: the
/// host must know the chip understands it, hence the bump.
///
/// 4: the quaternion of [`WirePose`] in 1e-6 (`i32`), was 1e-4 (`i16`):
/// 1e-4 moved the default net's command by as much as 0.06 mm RMS of tip
/// (0.11 mm max), the whole gap between the chip and the host controller on
/// the circle. Same bytes on the wire (a unit quaternion's components in
/// 1e-6 are 3-byte varints, as they were in 1e-4).
///
/// 5: [`LinkSetpoint::age_us`], the setpoint's age when the host sent it
/// (the period leads the pose by it; 1–3 bytes on the wire).
pub const PROTOCOL_VERSION: u16 = 5;

/// The chip sends [`Up::Telemetry`] every this many ticks of its timer
/// (100 ms at 1 kHz), and a Hello as often while unconfigured.
pub const TELEMETRY_EVERY: u32 = 100;

/// Largest weight-update chunk, bytes.
pub const MAX_CHUNK: usize = 192;

/// The controller's configuration as the host derives it from the robot
/// file and its options (the chip validates it: limits through
/// [`crate::TendonLimits`]' own checks).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Setup {
    /// Tendons.
    pub n_tendons: u8,
    /// Tension ceilings, N.
    pub max_tension: [f32; MAX_TENDONS],
    /// Tension floors, N.
    pub min_tension: [f32; MAX_TENDONS],
    /// Slew-rate limits, N/s.
    pub slew_rate: [f32; MAX_TENDONS],
    /// Co-contraction set of each tendon (0 = none).
    pub cocontraction_sets: [u8; MAX_TENDONS],
    /// Its weight in its set.
    pub cocontraction_weights: [f32; MAX_TENDONS],
    /// The period, ns.
    pub period_ns: u32,
    /// Setpoint watchdog, ns.
    pub watchdog_ns: u32,
    /// Largest dt the slew limit credits, ns.
    pub max_dt_ns: u32,
    /// Allowed `| |q|² − 1 |`.
    pub quaternion_tolerance: f32,
    /// Fraction of the net's box a setpoint may lie outside.
    pub box_margin: f32,
    /// Integral gain, 1/s (0 = off).
    pub ki: f32,
    /// Bound on each correction component, m.
    pub correction_limit: f32,
    /// Feedback older than this freezes the correction, ns.
    pub feedback_timeout_ns: u32,
    /// Integrate only within this tip error, m.
    pub correction_window: f32,
    /// Time constant of the error's low-pass filter, s (0 = none).
    pub correction_filter_tau_s: f32,
    /// Adaptation gain of the error map, 1/s (0 = off).
    pub correction_map_gain: f32,
    /// The map's normalisation length, m.
    pub correction_map_scale: f32,
    /// Bound on each entry of the map.
    pub correction_map_limit: f32,
    /// A setpoint moving more than this in one message is a jump, m.
    pub jump_m: f32,
    /// Frames sampled this soon after a jump are not integrated, ns.
    pub settle_after_jump_ns: u32,
    /// Motor-lag lead, s.
    pub lead_s: f32,
    /// No feedback for this long: plant stale, ns.
    pub plant_stale_ns: u32,
    /// Stuck-motor detection on.
    pub stuck_enabled: bool,
    /// Healthy-motor model's step per period, `1 − exp(−T/τ)`.
    pub stuck_model_gain: f32,
    /// Tension error that counts, N.
    pub stuck_error_n: f32,
    /// How long it must last, ns.
    pub stuck_persist_ns: u32,
}

impl Setup {
    /// The configuration's hash: CRC-32 of its postcard bytes (never 0,
    /// which means "no configuration").
    pub fn hash(&self) -> u32 {
        let mut buf = [0u8; 256];
        let bytes = postcard::to_slice(self, &mut buf)
            .map(|b| &*b)
            .unwrap_or(&[]);
        crate::crc32::crc32(bytes).max(1)
    }
}

/// The robot's reachable poses about a setpoint (see
/// [`crate::messages::Setpoint::tangent`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LinkTangent {
    /// Valid columns (1..=3).
    pub dim: u8,
    /// `∂pose/∂u_j`.
    pub columns: [[f32; 7]; 3],
    /// The unit axes a_j.
    pub axes: [[f32; 3]; 3],
}

/// Fixed-point units of the link (docs/design.md §5.6): the emulated
/// USART carries 10–70 kB/s (docs/design.md §5.6), so a setpoint and a feedback must fit in well
/// under 130 bytes per 10 ms period. Every quantity is an integer of a unit
/// far below what matters to the loop (a micron, 1e-6 of a quaternion, a
/// millinewton), sent as a postcard varint; the chip turns it back into
/// `f32`. NaN/∞ travel as the type's minimum (the chip must see a bad
/// setpoint to reject it).
pub mod units {
    /// Metres per position unit: 1 µm.
    pub const POSITION_M: f32 = 1e-6;
    /// Quaternion component per unit. Not 1e-4: a trained net turns the
    /// orientation into tensions steeply (on the default robot 1e-4 of a
    /// component moved the tip by 0.06 mm RMS; 1e-6 by 0.0014 mm), since
    /// for a one-segment robot the orientation says where the tip is.
    pub const QUATERNION: f32 = 1e-6;
    /// Pose derivative per unit: 1e-4 m/s (or 1/s for the quaternion).
    pub const VELOCITY: f32 = 1e-4;
    /// Newtons per tension unit: 1 mN.
    pub const TENSION_N: f32 = 1e-3;

    /// `v / unit` rounded, saturated; NaN/∞ → `i32::MIN`.
    pub fn to_i32(v: f32, unit: f32) -> i32 {
        if !v.is_finite() {
            return i32::MIN;
        }
        let q = libm::roundf(v / unit);
        // Saturate one short of MIN, which means NaN.
        if q >= i32::MAX as f32 {
            i32::MAX
        } else if q <= -(i32::MAX as f32) {
            -i32::MAX
        } else {
            q as i32
        }
    }

    /// `to_i32`'s inverse (`i32::MIN` → NaN).
    pub fn from_i32(q: i32, unit: f32) -> f32 {
        if q == i32::MIN {
            f32::NAN
        } else {
            q as f32 * unit
        }
    }

    /// `v / unit` rounded, saturated; NaN/∞ → `i16::MIN`.
    pub fn to_i16(v: f32, unit: f32) -> i16 {
        if !v.is_finite() {
            return i16::MIN;
        }
        libm::roundf(v / unit).clamp(-(i16::MAX as f32), i16::MAX as f32) as i16
    }

    /// `to_i16`'s inverse (`i16::MIN` → NaN).
    pub fn from_i16(q: i16, unit: f32) -> f32 {
        if q == i16::MIN {
            f32::NAN
        } else {
            f32::from(q) * unit
        }
    }
}

/// A pose on the link: position in µm, quaternion in 1e-6.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct WirePose {
    /// `px, py, pz`, µm.
    pub position: [i32; 3],
    /// `qw, qx, qy, qz`, 1e-6.
    pub quaternion: [i32; 4],
}

impl WirePose {
    /// Quantise `px, py, pz, qw, qx, qy, qz` (m).
    pub fn from_pose(p: &[f32; 7]) -> WirePose {
        let [x, y, z, w, qx, qy, qz] = *p;
        WirePose {
            position: [x, y, z].map(|v| units::to_i32(v, units::POSITION_M)),
            quaternion: [w, qx, qy, qz].map(|v| units::to_i32(v, units::QUATERNION)),
        }
    }

    /// Back to `f32` (m).
    pub fn pose(&self) -> [f32; 7] {
        let [x, y, z] = self.position.map(|q| units::from_i32(q, units::POSITION_M));
        let [w, qx, qy, qz] = self
            .quaternion
            .map(|q| units::from_i32(q, units::QUATERNION));
        [x, y, z, w, qx, qy, qz]
    }
}

/// A setpoint, host → chip.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LinkSetpoint {
    /// The planner's sequence number.
    pub seq: u32,
    /// Setpoints the planner sent since the last one forwarded (the host
    /// forwards the newest; 1 normally).
    pub count: u16,
    /// Of the ones not forwarded, how many had a NaN/∞ pose.
    pub superseded_nonfinite: u16,
    /// The pose.
    pub pose: WirePose,
    /// Its time derivative, 1e-4 per s (all 7 coordinates: the period
    /// leads the whole pose).
    pub velocity: Option<[i16; 7]>,
    /// The tangent, when it changed (the chip keeps the last one it got
    /// for the setpoints that come without: it changes slowly along a path
    /// and costs 120 of the link's bytes).
    pub tangent: Option<LinkTangent>,
    /// Its age when the host sent this message (since the planner sent
    /// it), µs (saturating): the period leads the pose by it.
    pub age_us: u32,
}

impl LinkSetpoint {
    /// The velocity in `f32`, per s.
    pub fn velocity(&self) -> Option<[f32; 7]> {
        self.velocity
            .map(|v| v.map(|q| units::from_i16(q, units::VELOCITY)))
    }

    /// Quantise a velocity (per s).
    pub fn wire_velocity(v: &[f32; 7]) -> [i16; 7] {
        v.map(|x| units::to_i16(x, units::VELOCITY))
    }
}

/// Plant feedback, host → chip.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Feedback {
    /// The plant's sequence number.
    pub seq: u32,
    /// Feedback messages since the last one forwarded.
    pub count: u16,
    /// The last command the plant applied.
    pub command_seq: u32,
    /// Measured tensions of the robot's tendons, mN.
    pub tensions: heapless::Vec<i32, MAX_TENDONS>,
    /// The tracker's newest tip position, µm.
    pub tip: [i32; 3],
    /// Its frame number (0 = none yet).
    pub tip_seq: u32,
    /// Its age when the host sent this message, µs (saturating).
    pub tip_age_us: u32,
}

impl Feedback {
    /// The tensions in N, padded with zeros.
    pub fn tensions_n(&self) -> [f32; MAX_TENDONS] {
        let mut out = [0.0f32; MAX_TENDONS];
        for (o, &q) in out.iter_mut().zip(&self.tensions) {
            *o = units::from_i32(q, units::TENSION_N);
        }
        out
    }

    /// The tip in m.
    pub fn tip_m(&self) -> [f32; 3] {
        self.tip.map(|q| units::from_i32(q, units::POSITION_M))
    }
}

/// Host → chip.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Down<'a> {
    /// Ask for the chip's [`Up::Hello`].
    Hello {
        /// The host's [`PROTOCOL_VERSION`].
        protocol: u16,
    },
    /// Configure the controller.
    Setup(Setup),
    /// A setpoint.
    Setpoint(LinkSetpoint),
    /// Plant feedback.
    Feedback(Feedback),
    /// `bytes` of a `total`-byte `.tnet` update at `offset` (offset 0
    /// starts a new update; the chip checks it in slices once whole).
    Chunk {
        /// Where these bytes go.
        offset: u32,
        /// The update's length.
        total: u32,
        /// At most [`MAX_CHUNK`] bytes.
        #[serde(borrow)]
        bytes: &'a [u8],
    },
    /// Lock-step: run one period now, at `now_ns`, on what arrived before
    /// this message, and send its [`Up::Command`]; from the first Step on
    /// the chip's timer no longer runs periods (until a new Setup). The
    /// host then decides every input of every period, messages and times,
    /// so a recorded trace replays bit for bit (docs/design.md §5.7).
    Step {
        /// The period's time, ns (the host's clock, not the chip's).
        now_ns: u64,
    },
}

/// The chip's identity and state, chip → host.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Hello {
    /// The chip's [`PROTOCOL_VERSION`].
    pub protocol: u16,
    /// CRC-32 of the built-in net's `.tnet`.
    pub net_hash: u32,
    /// [`Setup::hash`] of the running configuration (0 = none yet).
    pub setup_hash: u32,
    /// Why the last Setup was refused (0 = it was not).
    pub setup_error: u8,
}

/// The values of a period's events (the firmware's `period::Events`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct EventDetail {
    /// Setpoints lost in the gap before this one.
    pub setpoints_lost: u32,
    /// Plant states lost in the gap before this one.
    pub plant_states_lost: u32,
    /// Commands the plant was behind.
    pub commands_behind: u32,
    /// The stuck tendon and its tension error, N.
    pub stuck: Option<(u8, f32)>,
    /// Silence before a watchdog hold, µs.
    pub hold_silence_us: u32,
}

/// A tension command, chip → host.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LinkCommand {
    /// The period's command sequence number.
    pub seq: u32,
    /// The planner's sequence number of the last setpoint taken.
    pub setpoint_seq: u32,
    /// The status word (wire bits and the step's detail bits).
    pub status: u32,
    /// This period's event bits (the firmware's `period::event`).
    pub events: u32,
    /// The values those events carry (zeros and `None` when none: a byte
    /// each on the wire).
    pub detail: EventDetail,
    /// Tensions of the robot's tendons, N (exact: the chip's own output).
    pub tensions: heapless::Vec<f32, MAX_TENDONS>,
}

/// Counts and health, chip → host, every [`TELEMETRY_EVERY`] ticks.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Telemetry {
    /// The period's counters.
    pub counters: Counters,
    /// The chip's receive-side frame counters.
    pub frames: FrameCounters,
    /// Received bytes dropped because the receive queue was full.
    pub rx_overruns: u32,
    /// Transmit bytes dropped because the transmit queue was full.
    pub tx_dropped: u32,
    /// Ticks of the chip's timer since start.
    pub ticks: u32,
    /// The tick's length, ns.
    pub tick_ns: u32,
    /// Frames whose payload was no valid message (dropped by the chip).
    pub bad_messages: u32,
    /// Weight-update chunks refused (out of order, too large).
    pub chunks_refused: u32,
    /// Longest period so far, µs of the chip's clock.
    pub worst_period_us: u32,
    /// The tick at which the last watchdog hold began (0 = none): a bridge
    /// that connects after a link cut learns from it when the chip held.
    pub last_hold_tick: u32,
    /// Silence before that hold, µs (time since the last acceptable setpoint).
    pub last_hold_silence_us: u32,
}

/// Chip → host.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Up {
    /// Identity and configuration state.
    Hello(Hello),
    /// This period's command.
    Command(LinkCommand),
    /// Counters.
    Telemetry(Telemetry),
}

/// Largest encoded [`Down`] payload, bytes; frame buffers are sized from
/// it. The largest messages are a Setup (243 B with nine tendons), a chunk
/// (205 B) and a setpoint with its tangent (183 B); a test keeps them
/// under it.
pub const MAX_DOWN_PAYLOAD: usize = 256;
/// Largest encoded [`Up`] payload, bytes. The largest messages are a
/// command (84 B with nine tendons) and telemetry (78 B); a test keeps
/// them under it. 128, not 256: the chip's transmit frame buffer is sized
/// from it, and the bytes pay for nine tendons inside its 32 KB RAM.
pub const MAX_UP_PAYLOAD: usize = 128;

#[cfg(test)]
mod tests {
    use super::*;

    fn full_setpoint() -> LinkSetpoint {
        LinkSetpoint {
            seq: u32::MAX,
            count: u16::MAX,
            superseded_nonfinite: u16::MAX,
            pose: WirePose {
                position: [i32::MAX; 3],
                quaternion: [i32::MAX; 4],
            },
            velocity: Some([i16::MAX; 7]),
            tangent: Some(LinkTangent {
                dim: 3,
                columns: [[f32::MAX; 7]; 3],
                axes: [[f32::MAX; 3]; 3],
            }),
            age_us: u32::MAX,
        }
    }

    #[test]
    fn the_largest_messages_fit_their_buffers() {
        let mut buf = [0u8; 1024];
        let sp = postcard::to_slice(&Down::Setpoint(full_setpoint()), &mut buf)
            .unwrap()
            .len();
        assert!(sp <= MAX_DOWN_PAYLOAD, "setpoint {sp} B");
        // The sizes, for the record when the bound is tightened.
        std::println!("setpoint {sp} B");
        let chunk = [0xFFu8; MAX_CHUNK];
        let down = Down::Chunk {
            offset: u32::MAX,
            total: u32::MAX,
            bytes: &chunk,
        };
        let n = postcard::to_slice(&down, &mut buf).unwrap().len();
        assert!(n <= MAX_DOWN_PAYLOAD, "chunk {n} B");
        std::println!("chunk {n} B");
        let setup = Setup {
            n_tendons: MAX_TENDONS as u8,
            max_tension: [f32::MAX; MAX_TENDONS],
            min_tension: [f32::MAX; MAX_TENDONS],
            slew_rate: [f32::MAX; MAX_TENDONS],
            cocontraction_sets: [u8::MAX; MAX_TENDONS],
            cocontraction_weights: [f32::MAX; MAX_TENDONS],
            period_ns: u32::MAX,
            watchdog_ns: u32::MAX,
            max_dt_ns: u32::MAX,
            quaternion_tolerance: 1.0,
            box_margin: 1.0,
            ki: 1.0,
            correction_limit: 1.0,
            feedback_timeout_ns: u32::MAX,
            correction_window: 1.0,
            correction_filter_tau_s: 0.08,
            correction_map_gain: 2.0,
            correction_map_scale: 0.01,
            correction_map_limit: 0.5,
            jump_m: 1e-3,
            settle_after_jump_ns: 300_000_000,
            lead_s: 1.0,
            plant_stale_ns: u32::MAX,
            stuck_enabled: true,
            stuck_model_gain: 1.0,
            stuck_error_n: 1.0,
            stuck_persist_ns: u32::MAX,
        };
        let n = postcard::to_slice(&Down::Setup(setup), &mut buf)
            .unwrap()
            .len();
        assert!(
            n <= 256 && n <= MAX_DOWN_PAYLOAD,
            "setup {n} B: Setup::hash serialises into 256 bytes"
        );
        std::println!("setup {n} B");
        assert_ne!(setup.hash(), 0);
        let mut counters = Counters::default();
        // Every field at its largest varint: set through serde's view.
        let max = postcard::to_slice(&counters, &mut buf).unwrap().len();
        assert_eq!(max, 22, "one byte per zero counter");
        counters.periods = u32::MAX;
        let t = Up::Telemetry(Telemetry {
            counters: Counters { ..counters },
            frames: FrameCounters::default(),
            rx_overruns: u32::MAX,
            tx_dropped: u32::MAX,
            ticks: u32::MAX,
            tick_ns: u32::MAX,
            bad_messages: u32::MAX,
            chunks_refused: u32::MAX,
            worst_period_us: u32::MAX,
            last_hold_tick: u32::MAX,
            last_hold_silence_us: u32::MAX,
        });
        let n = postcard::to_slice(&t, &mut buf).unwrap().len();
        assert!(n <= MAX_UP_PAYLOAD, "telemetry {n} B");
        std::println!("telemetry {n} B");
        let c = Up::Command(LinkCommand {
            seq: u32::MAX,
            setpoint_seq: u32::MAX,
            status: u32::MAX,
            events: u32::MAX,
            detail: EventDetail {
                setpoints_lost: u32::MAX,
                plant_states_lost: u32::MAX,
                commands_behind: u32::MAX,
                stuck: Some((u8::MAX, f32::MAX)),
                hold_silence_us: u32::MAX,
            },
            tensions: heapless::Vec::from_slice(&[f32::MAX; MAX_TENDONS]).unwrap(),
        });
        let n = postcard::to_slice(&c, &mut buf).unwrap().len();
        assert!(n <= MAX_UP_PAYLOAD, "command {n} B");
        std::println!("command {n} B");
    }

    #[test]
    fn a_chunk_round_trips_through_a_frame_borrowing_its_bytes() {
        let bytes = [1u8, 0, 2, 0, 3];
        let msg = Down::Chunk {
            offset: 192,
            total: 12_000,
            bytes: &bytes,
        };
        let mut buf = [0u8; 512];
        let frame = crate::link::encode(&msg, &mut buf).unwrap().to_vec();
        let mut dec = crate::link::FrameDecoder::<512>::new();
        let mut got = None;
        for &b in &frame {
            if let Some(r) = dec.push_raw(b) {
                let payload = r.unwrap().to_vec();
                got = Some(payload);
            }
        }
        let payload = got.unwrap();
        let back: Down<'_> = postcard::from_bytes(&payload).unwrap();
        assert_eq!(back, msg);
    }

    #[test]
    fn a_typical_setpoint_and_feedback_fit_the_emulated_link() {
        // The default robot's circle: 15 mm off the axis, 0.19 m/s tops.
        let sp = Down::Setpoint(LinkSetpoint {
            seq: 123_456,
            count: 1,
            superseded_nonfinite: 0,
            pose: WirePose::from_pose(&[0.015, -0.002, 0.195, 0.99, 0.1, -0.05, 0.0]),
            velocity: Some(LinkSetpoint::wire_velocity(&[
                0.019, 0.004, -0.001, -0.01, 0.03, 0.02, 0.0,
            ])),
            tangent: None,
            age_us: 12_000,
        });
        let fb = Down::Feedback(Feedback {
            seq: 123_400,
            count: 1,
            command_seq: 123_399,
            tensions: heapless::Vec::from_slice(&[4200, 0, 1500, 7800]).unwrap(),
            tip: [15_012, -1_998, 194_950],
            tip_seq: 7,
            tip_age_us: 21_000,
        });
        let mut buf = [0u8; 512];
        let a = crate::link::encode(&sp, &mut buf).unwrap().len();
        let b = crate::link::encode(&fb, &mut buf).unwrap().len();
        // 13 kB/s at 100 Hz is 130 B per period: leave half for bursts,
        // chunks and tangents.
        assert!(a + b <= 80, "setpoint {a} B + feedback {b} B per period");
    }

    #[test]
    fn quantisation_keeps_a_micron_and_nan() {
        let h = core::f32::consts::FRAC_1_SQRT_2;
        let p = [0.0123456, -0.1, 0.3, h, 0.0, h, 0.0];
        let back = WirePose::from_pose(&p).pose();
        for i in 0..3 {
            assert!((back[i] - p[i]).abs() <= 0.5e-6 + 1e-7, "{i}");
        }
        for i in 3..7 {
            assert!((back[i] - p[i]).abs() <= 0.5e-4 + 1e-7, "{i}");
        }
        let mut bad = p;
        bad[1] = f32::NAN;
        bad[4] = f32::INFINITY;
        let back = WirePose::from_pose(&bad).pose();
        assert!(back[1].is_nan() && back[4].is_nan());
        // Far outside the workspace stays far outside (saturated, not wrapped).
        assert!(WirePose::from_pose(&[1e9, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]).pose()[0] > 2000.0);
    }

    #[test]
    fn different_setups_hash_differently() {
        let a = Setup {
            n_tendons: 4,
            max_tension: [10.0; MAX_TENDONS],
            min_tension: [0.0; MAX_TENDONS],
            slew_rate: [200.0; MAX_TENDONS],
            cocontraction_sets: [0; MAX_TENDONS],
            cocontraction_weights: [0.0; MAX_TENDONS],
            period_ns: 1_000_000,
            watchdog_ns: 2_500_000,
            max_dt_ns: 5_000_000,
            quaternion_tolerance: 1e-2,
            box_margin: 0.05,
            ki: 0.0,
            correction_limit: 0.003,
            feedback_timeout_ns: 20_000_000,
            correction_window: 0.002,
            correction_filter_tau_s: 0.08,
            correction_map_gain: 2.0,
            correction_map_scale: 0.01,
            correction_map_limit: 0.5,
            jump_m: 1e-3,
            settle_after_jump_ns: 300_000_000,
            lead_s: 0.021,
            plant_stale_ns: 20_000_000,
            stuck_enabled: true,
            stuck_model_gain: 0.05,
            stuck_error_n: 0.5,
            stuck_persist_ns: 100_000_000,
        };
        let mut b = a;
        b.ki = 2.0;
        assert_ne!(a.hash(), b.hash());
        assert_eq!(a.hash(), { a }.hash());
    }
}
