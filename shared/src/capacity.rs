//! The fixed dimensions every tendril crate agrees on, each defined once
//! here (docs/design.md §5): the pose a net reads, the most tendons a robot
//! has, the most hidden units a net may grow, and the net type of that size.
//! The trainer, the host controller and the MCU image all take them from
//! here, so a net the trainer exports always fits the controllers.

use crate::net::{weight_capacity, CascadeNet};

/// Pose dimension, the net's input count: `px, py, pz` (m), `qw, qx, qy, qz`.
pub const POSE_DIM: usize = 7;

/// The most tendons any tendril robot has (robot files allow 1–8): the
/// width of every tension array on the wire and in the control step.
pub const MAX_TENDONS: usize = 8;

/// The most hidden units a cascade net may have: the trainer's cap and the
/// capacity of both controllers (host and MCU).
pub const MAX_HIDDEN: usize = 64;

/// Packed weight storage of an [`McuNet`]: `weight_capacity(7, 64, 8)` =
/// 3,111 `f32` (12.2 KiB).
pub const MAX_WEIGHTS: usize = weight_capacity(POSE_DIM, MAX_HIDDEN, MAX_TENDONS);

/// The net type every component decodes `.tnet` files into: [`POSE_DIM`]
/// inputs, up to [`MAX_HIDDEN`] hidden units and [`MAX_TENDONS`] outputs.
pub type McuNet = CascadeNet<POSE_DIM, MAX_HIDDEN, MAX_TENDONS, MAX_WEIGHTS>;
