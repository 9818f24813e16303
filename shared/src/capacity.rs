//! The fixed dimensions every tendril crate agrees on, each defined once
//! here (docs/design.md §5): the pose a net reads, the most tendons a robot
//! has, the most hidden units a net may grow, and the net type of that size.
//! The trainer, the host controller and the MCU image all take them from
//! here, so a net the trainer exports always fits the controllers.
//!
//! A net's size is bounded by its *weight store*, not by each dimension at
//! once: the store holds a 7-64-8 net, and a net with more outputs trades
//! hidden units for them ([`max_hidden_for`]: 63 units for nine tendons).
//! Nine tendons thus cost the chip no weight RAM beyond eight.

use crate::net::{weight_capacity, CascadeNet};
use crate::tnet::NetShape;

/// Pose dimension, the net's input count: `px, py, pz` (m), `qw, qx, qy, qz`.
pub const POSE_DIM: usize = 7;

/// The most tendons any tendril robot has (robot files allow 1–9: three
/// segments of three): the width of every tension array on the wire and in
/// the control step.
pub const MAX_TENDONS: usize = 9;

/// The most hidden units a cascade net may have: the trainer's cap and the
/// capacity of both controllers (host and MCU).
pub const MAX_HIDDEN: usize = 64;

/// Packed weight storage of an [`McuNet`]: `weight_capacity(7, 64, 8)` =
/// 3,111 `f32` (12.2 KiB), the store of a 7-64-8 net. A net of any shape
/// whose weights fit is accepted ([`max_hidden_for`]).
pub const MAX_WEIGHTS: usize = weight_capacity(POSE_DIM, MAX_HIDDEN, 8);

/// The most hidden units a net with `outputs` outputs may have: at most
/// [`MAX_HIDDEN`], and no more than its weights fit in [`MAX_WEIGHTS`]
/// (64 up to eight outputs, 63 for nine). The trainer stops growing there.
pub const fn max_hidden_for(outputs: usize) -> usize {
    let mut hidden = MAX_HIDDEN;
    while hidden > 0 && weight_capacity(POSE_DIM, hidden, outputs) > MAX_WEIGHTS {
        hidden -= 1;
    }
    hidden
}

/// Bytes of the largest version-2 `.tnet` file any controller accepts: the
/// longest over every output count of the largest net with that count
/// ([`max_hidden_for`]). The chip's update buffer is this long.
pub const MAX_NET_FILE: usize = {
    let mut longest = 0;
    let mut outputs = 1;
    while outputs <= MAX_TENDONS {
        let len = NetShape {
            inputs: POSE_DIM,
            hidden: max_hidden_for(outputs),
            outputs,
        }
        .encoded_len_v2();
        if len > longest {
            longest = len;
        }
        outputs += 1;
    }
    longest
};

const _: () = assert!(
    max_hidden_for(8) == MAX_HIDDEN,
    "the store holds a 7-64-8 net"
);
const _: () = assert!(
    max_hidden_for(MAX_TENDONS) >= 60,
    "nine tendons keep a useful net"
);

/// The net type every component decodes `.tnet` files into: [`POSE_DIM`]
/// inputs, up to [`MAX_HIDDEN`] hidden units and [`MAX_TENDONS`] outputs.
pub type McuNet = CascadeNet<POSE_DIM, MAX_HIDDEN, MAX_TENDONS, MAX_WEIGHTS>;
