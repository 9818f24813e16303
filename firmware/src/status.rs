//! What a control step did, as bits ([`Status`]): the summary bits the
//! wire carries and the detail bits that say why.

use core::fmt;

use tendril_shared::messages::command_status as wire;

/// What the control step did this period, as bits. The summary bits are
/// `tendril_shared::messages::command_status`'s (defined there, taken from
/// there) so `bits()` can be sent as `TensionCommand::status`; the detail
/// bits, 16 and up, say why and stay clear of the wire bits (a compile-time
/// check below).
#[derive(Clone, Copy, Default, PartialEq, Eq, Hash)]
pub struct Status(u32);

impl Status {
    /// Watchdog fired (or the net is unusable): tensions are a safe hold.
    pub const SAFE_HOLD: Status = Status(wire::SAFE_HOLD);
    /// The setpoint of this step was rejected (NaN/∞, quaternion, workspace).
    pub const SETPOINT_REJECTED: Status = Status(wire::SETPOINT_REJECTED);
    /// A tension hit its range or slew limit.
    pub const SATURATED: Status = Status(wire::SATURATED);
    /// Integral loop enabled but no fresh feedback: correction frozen.
    pub const PLANT_STALE: Status = Status(wire::PLANT_STALE);
    /// The integral correction changed the pose sent to the net.
    pub const CORRECTION: Status = Status(wire::CORRECTION);
    /// A new weight blob replaced the net before this step.
    pub const WEIGHTS_SWAPPED: Status = Status(wire::WEIGHTS_SWAPPED);
    /// A weight blob was rejected before this step; the old net ran.
    pub const WEIGHTS_REJECTED: Status = Status(wire::WEIGHTS_REJECTED);
    /// No acceptable setpoint yet: holding the initial command.
    pub const NO_SETPOINT: Status = Status(wire::NO_SETPOINT);
    /// A new setpoint was accepted this step.
    pub const NEW_SETPOINT: Status = Status(1 << 16);
    /// The setpoint's sequence number was not newer than the last: ignored.
    pub const STALE_SETPOINT: Status = Status(1 << 17);
    /// Setpoint rejected: a NaN or infinite component.
    pub const NONFINITE_SETPOINT: Status = Status(1 << 18);
    /// Setpoint rejected: quaternion norm off by more than the tolerance.
    pub const BAD_QUATERNION: Status = Status(1 << 19);
    /// Setpoint outside the net's normalisation box: previous target held.
    pub const OUT_OF_WORKSPACE: Status = Status(1 << 20);
    /// The net produced a NaN/∞ tension: previous target held.
    pub const NONFINITE_OUTPUT: Status = Status(1 << 21);
    /// A target tension was clamped into `[min_tension, max_tension]`.
    pub const RANGE_CLAMPED: Status = Status(1 << 22);
    /// A tension change was cut to the slew limit.
    pub const SLEW_LIMITED: Status = Status(1 << 23);
    /// Time went backwards: `dt` taken as 0.
    pub const CLOCK_FAULT: Status = Status(1 << 24);
    /// The net's shape does not fit the robot (inputs ≠ 7 or outputs ≠ tendons).
    pub const NET_MISMATCH: Status = Status(1 << 25);
    /// Feedback was NaN/∞ and was ignored.
    pub const BAD_FEEDBACK: Status = Status(1 << 26);
    /// The corrected pose left the box: integral frozen, uncorrected pose used.
    pub const CORRECTION_LIMITED: Status = Status(1 << 27);
    /// The target left `[min, max]` and a co-contraction set was shifted
    /// to bring it back (the bend kept; [`crate::command`]).
    pub const CO_CONTRACTED: Status = Status(1 << 28);

    /// Every detail bit (none of them a wire bit).
    const DETAIL: u32 = Status::NEW_SETPOINT.0
        | Status::STALE_SETPOINT.0
        | Status::NONFINITE_SETPOINT.0
        | Status::BAD_QUATERNION.0
        | Status::OUT_OF_WORKSPACE.0
        | Status::NONFINITE_OUTPUT.0
        | Status::RANGE_CLAMPED.0
        | Status::SLEW_LIMITED.0
        | Status::CLOCK_FAULT.0
        | Status::NET_MISMATCH.0
        | Status::BAD_FEEDBACK.0
        | Status::CORRECTION_LIMITED.0
        | Status::CO_CONTRACTED.0;

    /// No bits set.
    pub const fn empty() -> Status {
        Status(0)
    }

    /// The raw bits.
    pub const fn bits(self) -> u32 {
        self.0
    }

    /// From raw bits (unknown bits kept).
    pub const fn from_bits(bits: u32) -> Status {
        Status(bits)
    }

    /// Whether every bit of `other` is set.
    pub const fn contains(self, other: Status) -> bool {
        self.0 & other.0 == other.0
    }

    /// Whether any bit of `other` is set.
    pub const fn intersects(self, other: Status) -> bool {
        self.0 & other.0 != 0
    }

    /// Set the bits of `other`.
    pub fn insert(&mut self, other: Status) {
        self.0 |= other.0;
    }
}

// The detail bits must not change the meaning of a status word on the wire.
const _: () = assert!(Status::DETAIL & wire::WIRE_MASK == 0);

impl core::ops::BitOr for Status {
    type Output = Status;
    fn bitor(self, rhs: Status) -> Status {
        Status(self.0 | rhs.0)
    }
}

impl core::ops::BitOrAssign for Status {
    fn bitor_assign(&mut self, rhs: Status) {
        self.0 |= rhs.0;
    }
}

impl fmt::Debug for Status {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Status({:#010x})", self.0)
    }
}
