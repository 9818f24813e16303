//! A trained `.tnet` net on the host (`docs/design.md` §5, §7): the one
//! place that reads `.tnet` files and runs them. Every consumer — `tendril
//! ik`, `evaluate`, the pipeline, the exact IK's net guess and the Python
//! package — goes through here; the trainer only writes
//! (`learn::cascor::export`, through the shared encoder). The IPC
//! controller alone loads its bytes through the firmware's hot swap
//! (`tendril_firmware::swap`), as the MCU does.
//!
//! - [`read`]: file → the firmware's fixed-capacity [`McuNet`], through the
//!   decoder the MCU uses.
//! - [`mod@infer`]: the firmware's f32 inference, bit-identical to the MCU's.
//! - [`fast`]: [`HostNet`], the same arithmetic laid out for the host CPU
//!   (several queries through each unit at once, no allocation per query),
//!   bit-identical to [`mod@infer`] (8 or, with AVX2, 16 queries per
//!   block); and its relaxed single-query path
//!   ([`HostNet::infer_one_relaxed`], `relaxed`), not bit-identical (a
//!   rational `tanh`, FMA), for answers that claim no parity.
//! - [`robot_check`]: the one check of a net's recorded robot against the
//!   robot a consumer is given (`--allow-robot-mismatch` to override).
//! - [`guarded`]: [`GuardedNet`], a net with its robot's limits that never
//!   hands out an impossible tension (pose guards, command stage), and the
//!   CSV batch of `tendril ik`.
//!
//! [`McuNet`]: tendril_shared::McuNet

pub mod fast;
pub mod guarded;
pub mod infer;
mod ranges;
pub mod read;
mod relaxed;
pub mod robot_check;
#[cfg(test)]
mod test_nets;

pub use fast::HostNet;
pub use guarded::{read_poses, solve_csv, BatchSummary, GuardedNet, IkAnswer, IkError};
pub use infer::{infer, infer_batch, pose_rows, steady_command};
pub use read::{decode, read_tnet, read_tnet_bytes, ReadError, MAX_TNET_BYTES};
pub use robot_check::{
    check_model_robot, decode_with_provenance, load_for_robot, read_model, ModelError, RobotCheck,
    RobotMismatch, CLI_OVERRIDE,
};
