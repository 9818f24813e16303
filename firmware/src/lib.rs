//! The part of tendril that runs on the robot's microcontroller: fixed-size
//! cascade-correlation inference with frozen weights and the deterministic
//! control step with its safety limits. Plain `no_std` Rust, no allocation,
//! testable on the host.
//!
//! - [`infer`]: pose → tensions through a decoded [`tendril_shared::CascadeNet`];
//! - [`control`]: the pure control step and its [`control::Status`] word;
//! - [`swap`]: double-buffered hot swap of the weights;
//! - [`vectors`]: the test-vector format and the runner shared by the MCU
//!   binary and the host parity test.
#![no_std]
#![deny(missing_docs)]

#[cfg(test)]
extern crate std;

#[cfg(test)]
mod tests;

pub mod control;
pub mod infer;
pub mod swap;
pub mod synth;
pub mod vectors;

pub use control::{
    control_step, ControlConfig, ControlState, Feedback, IntegralConfig, SafeHold, Setpoint,
    Status, StepInput, StepOutput, Tensions, POSE_DIM,
};
pub use infer::infer;
pub use swap::{NetSlots, SwapError};

/// Capacity the MCU binary is built with: at most this many hidden units.
/// Two nets of this capacity (the hot-swap double buffer) take
/// 2 × 4 × (16 + 8)(1 + 7 + 16) = 4.6 KiB of RAM.
pub const MCU_MAX_HIDDEN: usize = 16;

/// The MCU binary's net type: 7 pose inputs, [`MCU_MAX_HIDDEN`] hidden
/// units, up to 8 tendons.
pub type McuNet =
    tendril_shared::CascadeNet<POSE_DIM, MCU_MAX_HIDDEN, { tendril_shared::MAX_TENDONS }>;

/// The MCU binary's double buffer.
pub type McuSlots = NetSlots<POSE_DIM, MCU_MAX_HIDDEN, { tendril_shared::MAX_TENDONS }>;
