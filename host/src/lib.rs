//! tendril host library: everything that needs `std`.
//!
//! Data flows one way: robot file → statics → dataset → learner → `.tnet` →
//! firmware core → control loop ↔ plant. The `tendril` binary (`main.rs`) is a
//! thin shell over this library.

pub mod calibrate;
pub mod cli;
pub mod command_stage;
pub mod compare;
pub mod dataset;
pub mod dynamics;
pub mod evaluate;
pub mod firmware_parity;
pub mod fsutil;
pub mod interrupt;
pub mod inverse;
pub mod ipc;
pub mod jobs;
pub mod learn;
pub mod mcu;
pub mod net;
pub mod numerics;
pub mod pipeline;
pub mod plan;
pub mod plant;
pub mod plot;
pub mod progress;
pub mod robot;
pub mod robustness;
pub mod runlog;
pub mod statics;
pub mod units;
