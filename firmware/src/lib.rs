//! The part of tendril that runs on the robot's microcontroller: fixed-size
//! cascade-correlation inference with frozen weights and the deterministic
//! control step with its safety limits. Plain `no_std` Rust, no allocation,
//! testable on the host.
#![no_std]
#![deny(missing_docs)]
