//! Fixed-size, `#[repr(C)]` messages of the planner → controller → plant loop
//! (docs/design.md §6). They travel through iceoryx2 shared memory as plain bytes, so
//! every field is a number or an array of numbers (no pointers, no `bool`, no
//! enums with invalid bit patterns) and the layout is pinned by tests below.
//! The host wraps them for iceoryx2 (`ZeroCopySend`); this crate stays
//! dependency-free and `no_std` so the MCU build can use the same layouts.
//!
//! Every message starts with a [`Header`]: a sequence number (per publisher,
//! starting at 1, so 0 means "never received") and a timestamp in nanoseconds
//! of the sender's monotonic clock (`CLOCK_MONOTONIC` on Linux, shared by all
//! processes on one machine, so receive time minus stamp is the one-way
//! latency).

pub use crate::capacity::MAX_TENDONS;

/// Bytes a [`WeightUpdate`] can carry: more than twice the largest net a
/// controller accepts (12.5 KiB; checked at compile time).
pub const WEIGHT_UPDATE_CAPACITY: usize = 32 * 1024;

const _: () = assert!(
    crate::capacity::MAX_NET_FILE <= WEIGHT_UPDATE_CAPACITY,
    "the largest net must fit a WeightUpdate"
);

/// Sequence number and send time, first field of every message.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Header {
    /// Per-publisher counter, 1 for the first message (0 = none yet).
    pub seq: u64,
    /// Sender's monotonic clock at publication, nanoseconds.
    pub stamp_ns: u64,
}

/// Bits of [`Setpoint::flags`].
pub mod setpoint_flags {
    /// The planner's settle hold before the path (it holds the first pose,
    /// or approaches it from rest): not part of the path.
    pub const HOLD: u32 = 1 << 0;
    /// `velocity` is valid and may be used for feed-forward.
    pub const HAS_VELOCITY: u32 = 1 << 1;
    /// Last setpoint of the trajectory; the planner stops after it.
    pub const FINAL: u32 = 1 << 2;
    /// `tangent` is valid: the controller may move the setpoint along the
    /// robot's reachable poses instead of guessing how they bend.
    pub const HAS_TANGENT: u32 = 1 << 3;
    /// The setpoint is part of a shaped move between targets (a step, the
    /// approach to a path's first pose): the tip is still on its way. The
    /// sim's analysis treats such setpoints as a step's transient; the
    /// period does not read the bit yet (`docs/design.md` §6.4: the chip's
    /// worst period has no room for it).
    pub const MOVING: u32 = 1 << 4;
    /// `dynamic_offset` is valid: the controller asks the net for the pose
    /// moved by it.
    pub const HAS_DYNAMIC_OFFSET: u32 = 1 << 5;
}

/// Desired tip pose, planner → controller.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Setpoint {
    /// Sequence number and send time.
    pub header: Header,
    /// Desired tip pose `px, py, pz` (m), `qw, qx, qy, qz` (Hamilton, w ≥ 0).
    pub pose: [f32; 7],
    /// Time derivative of `pose` (per second): lets the controller lead the
    /// motors by their lag instead of trailing the trajectory.
    pub velocity: [f32; 7],
    /// `∂pose/∂u_j` along the robot's reachable poses at this setpoint (per
    /// metre), u_j = `tangent_axes[j]` · p the tip's coordinate along axis
    /// j; the first `tangent_dim` columns are valid, the rest zero. A
    /// continuum robot reaches a k-dimensional family of poses (k = 3 for a
    /// volume, 2 for a surface over the lateral plane, 1 for a curve), so a
    /// correction of the tip's position must also change the rest of the
    /// pose the way the robot's own statics do; the planner, which has the
    /// statics, says how (first order).
    pub tangent: [[f32; 7]; 3],
    /// The unit axes a_j (base frame) of the columns of `tangent`; the
    /// first `tangent_dim` are valid, the rest zero.
    pub tangent_axes: [[f32; 3]; 3],
    /// k, the number of valid tangent columns and axes (1..=3; 0 = none).
    pub tangent_dim: u32,
    /// [`setpoint_flags`] bits.
    pub flags: u32,
    /// What the rod's dynamics ask of the command on top of the pose, m
    /// along the tangent's axes (`tangent_axes`; the position's x, y, z
    /// without a tangent), as the correction moves it: the net is asked for
    /// `pose + Σ_j d_j tangent_j`, so that the rod, which lags an
    /// accelerating command by its first mode, ends up at `pose` — the
    /// modal model's inverse along the path (`docs/design.md` §6.4). `pose`
    /// stays the reference the tip is measured against. Valid with
    /// `HAS_DYNAMIC_OFFSET`.
    pub dynamic_offset: [f32; 3],
    /// Explicit padding to the header's 8-byte alignment; zero.
    pub reserved: u32,
}

/// Bits of [`TensionCommand::status`]: what the controller did this period.
///
/// These are the one definition of the wire bits: the firmware's
/// `control::Status` takes its summary bits from here and keeps its detail
/// bits above [`command_status::WIRE_MASK`] (checked at compile time there).
pub mod command_status {
    /// The bits this module defines (the low 16); a controller may send
    /// more detailed bits above them.
    pub const WIRE_MASK: u32 = 0xFFFF;
    /// The setpoint watchdog fired: tensions are a safe hold, not tracking.
    pub const SAFE_HOLD: u32 = 1 << 0;
    /// The latest setpoint was rejected (NaN/∞, bad quaternion, out of workspace).
    pub const SETPOINT_REJECTED: u32 = 1 << 1;
    /// At least one tension hit its range or slew limit.
    pub const SATURATED: u32 = 1 << 2;
    /// No fresh plant state: the correction loop is frozen.
    pub const PLANT_STALE: u32 = 1 << 3;
    /// The integral correction loop is active.
    pub const CORRECTION: u32 = 1 << 4;
    /// Weights were swapped at the start of this period.
    pub const WEIGHTS_SWAPPED: u32 = 1 << 5;
    /// A weight update was rejected (bad CRC, shape, NaN) this period.
    pub const WEIGHTS_REJECTED: u32 = 1 << 6;
    /// The previous period overran its deadline (one or more periods skipped).
    pub const OVERRUN: u32 = 1 << 7;
    /// No setpoint has been received yet: holding the initial tensions.
    pub const NO_SETPOINT: u32 = 1 << 8;

    const ALL: u32 = SAFE_HOLD
        | SETPOINT_REJECTED
        | SATURATED
        | PLANT_STALE
        | CORRECTION
        | WEIGHTS_SWAPPED
        | WEIGHTS_REJECTED
        | OVERRUN
        | NO_SETPOINT;
    const _: () = assert!(ALL & !WIRE_MASK == 0, "wire bits stay in WIRE_MASK");
}

/// Bytes after a `[f32; MAX_TENDONS]` that bring the next field to an
/// 8-byte boundary: 4 with an odd [`MAX_TENDONS`], else 0. The messages
/// carry them as an explicit zero field, so no byte in shared memory is
/// compiler padding with an undefined value.
pub const TENSION_PAD: usize = (8 - MAX_TENDONS * 4 % 8) % 8;

/// Tendon tensions to apply, controller → plant.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TensionCommand {
    /// Sequence number and send time.
    pub header: Header,
    /// Sequence number of the setpoint this command tracks (0 = none).
    pub setpoint_seq: u64,
    /// Desired tendon tensions (N); entries past `count` are zero.
    pub tensions: [f32; MAX_TENDONS],
    /// Zero: the explicit padding after `tensions` ([`TENSION_PAD`]).
    pub pad: [u8; TENSION_PAD],
    /// Number of valid entries in `tensions`.
    pub count: u32,
    /// [`command_status`] bits.
    pub status: u32,
}

/// Bits of [`PlantState::status`]: faults and conditions of the plant.
pub mod plant_status {
    /// A motor is stuck (fault injection).
    pub const MOTOR_STUCK: u32 = 1 << 0;
    /// A command arrived with a tension outside `[0, max_tension]` or non-finite.
    pub const COMMAND_OUT_OF_RANGE: u32 = 1 << 1;
    /// The statics solve failed; `tip_pose` is the last good one.
    pub const SOLVE_FAILED: u32 = 1 << 2;
    /// No command for longer than the plant's timeout: motors hold.
    pub const COMMAND_STALE: u32 = 1 << 3;
    /// Commands are being dropped (fault injection).
    pub const DROPPING: u32 = 1 << 4;
    /// Commands are being delayed (fault injection).
    pub const DELAYING: u32 = 1 << 5;
}

/// Measured plant state, plant → controller and planner.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlantState {
    /// Sequence number and send time.
    pub header: Header,
    /// Sequence number of the last command applied (0 = none).
    pub command_seq: u64,
    /// Measured tendon tensions (N); entries past `count` are zero.
    pub tensions: [f32; MAX_TENDONS],
    /// Zero: the explicit padding after `tensions` ([`TENSION_PAD`]).
    pub pad: [u8; TENSION_PAD],
    /// The tracker's newest tip pose: `px, py, pz` (m), `qw..qz`, with its
    /// noise, sampled at `tip_stamp_ns` (docs/design.md §6.2: a tracker
    /// samples at its own rate and delivers late; this is its last delivered
    /// sample, repeated until the next arrives).
    pub tip_pose: [f32; 7],
    /// Number of valid entries in `tensions`.
    pub count: u32,
    /// [`plant_status`] bits.
    pub status: u32,
    /// The tracker's frame number of `tip_pose` (1 for its first; 0 = no
    /// sample yet): a controller integrates each frame once.
    pub tip_seq: u32,
    /// When the tracker sampled `tip_pose`, ns on the sender's clock (the
    /// monotonic clock the processes share).
    pub tip_stamp_ns: u64,
}

/// A new `.tnet` for the running controller (hot swap, docs/design.md §5): the
/// controller validates the bytes fully before the swap and keeps the old
/// net on any error.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WeightUpdate {
    /// Sequence number and send time.
    pub header: Header,
    /// Number of valid bytes in `bytes`.
    pub len: u32,
    /// Explicit padding; zero.
    pub reserved: u32,
    /// The `.tnet` file contents; bytes past `len` are ignored.
    pub bytes: [u8; WEIGHT_UPDATE_CAPACITY],
}

impl Default for WeightUpdate {
    fn default() -> Self {
        WeightUpdate {
            header: Header::default(),
            len: 0,
            reserved: 0,
            bytes: [0; WEIGHT_UPDATE_CAPACITY],
        }
    }
}

impl WeightUpdate {
    /// The valid part of the payload, or `None` when `len` exceeds the
    /// capacity (a corrupted message: never index past the array).
    pub fn payload(&self) -> Option<&[u8]> {
        self.bytes.get(..self.len as usize)
    }

    /// Fill from a `.tnet` file's bytes; `None` if it does not fit.
    pub fn from_bytes(header: Header, bytes: &[u8]) -> Option<WeightUpdate> {
        if bytes.len() > WEIGHT_UPDATE_CAPACITY {
            return None;
        }
        let mut msg = WeightUpdate {
            header,
            len: bytes.len() as u32,
            ..WeightUpdate::default()
        };
        msg.bytes.get_mut(..bytes.len())?.copy_from_slice(bytes);
        Some(msg)
    }
}

/// Bits of [`Control::command`]: lifecycle requests from the launcher.
pub mod control_command {
    /// Stop cleanly: finish the period, write statistics, exit 0.
    pub const STOP: u32 = 1;
}

/// Lifecycle request from the launcher (`tendril sim`) to every process.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Control {
    /// Sequence number and send time.
    pub header: Header,
    /// A [`control_command`] value.
    pub command: u32,
    /// Explicit padding; zero.
    pub reserved: u32,
}

/// Whether every component of a pose is finite and its quaternion has unit
/// norm within `tol`: the first check a receiver makes on a setpoint.
pub fn pose_is_sane(pose: &[f32; 7], tol: f32) -> bool {
    if pose.iter().any(|v| !v.is_finite()) {
        return false;
    }
    let n2 = pose[3] * pose[3] + pose[4] * pose[4] + pose[5] * pose[5] + pose[6] * pose[6];
    (n2 - 1.0).abs() <= tol
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::mem::{align_of, offset_of, size_of};

    #[test]
    fn layouts_have_no_implicit_padding() {
        // Size = sum of field sizes: no compiler-inserted holes whose bytes
        // would be undefined in shared memory.
        assert_eq!(size_of::<Header>(), 16);
        assert_eq!(
            size_of::<Setpoint>(),
            16 + 7 * 4 * 2 + 7 * 4 * 3 + 3 * 4 * 3 + 4 + 4 + 3 * 4 + 4
        );
        assert_eq!(
            size_of::<TensionCommand>(),
            16 + 8 + MAX_TENDONS * 4 + TENSION_PAD + 4 + 4
        );
        assert_eq!(
            size_of::<PlantState>(),
            16 + 8 + MAX_TENDONS * 4 + TENSION_PAD + 7 * 4 + 4 * 3 + 8
        );
        assert_eq!(
            offset_of!(PlantState, tip_stamp_ns),
            24 + MAX_TENDONS * 4 + TENSION_PAD + 7 * 4 + 12
        );
        assert_eq!(size_of::<WeightUpdate>(), 16 + 8 + WEIGHT_UPDATE_CAPACITY);
        assert_eq!(size_of::<Control>(), 16 + 8);
        assert_eq!(offset_of!(Setpoint, pose), 16);
        assert_eq!(offset_of!(Setpoint, tangent), 16 + 7 * 4 * 2);
        assert_eq!(offset_of!(Setpoint, tangent_axes), 16 + 7 * 4 * 5);
        assert_eq!(offset_of!(Setpoint, tangent_dim), 16 + 7 * 4 * 5 + 36);
        assert_eq!(offset_of!(Setpoint, flags), 16 + 7 * 4 * 5 + 40);
        assert_eq!(offset_of!(Setpoint, dynamic_offset), 16 + 7 * 4 * 5 + 44);
        assert_eq!(offset_of!(TensionCommand, tensions), 24);
        assert_eq!(
            offset_of!(PlantState, tip_pose),
            24 + MAX_TENDONS * 4 + TENSION_PAD
        );
        assert_eq!(align_of::<Setpoint>(), 8);
    }

    #[test]
    fn weight_update_round_trips_and_rejects_oversize() {
        let data = [7u8, 1, 2, 3];
        let msg = WeightUpdate::from_bytes(Header::default(), &data).unwrap();
        assert_eq!(msg.payload(), Some(&data[..]));
        let big = [0u8; WEIGHT_UPDATE_CAPACITY + 1];
        assert!(WeightUpdate::from_bytes(Header::default(), &big).is_none());
        let mut corrupt = msg;
        corrupt.len = u32::MAX;
        assert_eq!(corrupt.payload(), None);
    }

    #[test]
    fn pose_sanity_rejects_nan_and_non_unit_quaternions() {
        let ok = [0.0, 0.0, 0.4, 1.0, 0.0, 0.0, 0.0];
        assert!(pose_is_sane(&ok, 1e-3));
        let mut nan = ok;
        nan[1] = f32::NAN;
        assert!(!pose_is_sane(&nan, 1e-3));
        let mut inf = ok;
        inf[0] = f32::INFINITY;
        assert!(!pose_is_sane(&inf, 1e-3));
        let mut long = ok;
        long[3] = 1.1;
        assert!(!pose_is_sane(&long, 1e-3));
    }
}
