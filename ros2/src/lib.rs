//! tendril on ROS 2 (`docs/guide/ros2.md`): tendril's plant as a robot on a
//! lab's ROS 2 graph, in pure Rust — ros2-client on RustDDS, so no ROS
//! installation or sourced workspace is needed, and any ROS 2 node (or any
//! DDS peer speaking ROS 2's conventions, such as Cyclone DDS) talks to it.
//!
//! - [`msg`]: the common_interfaces messages used, as serde structs;
//! - [`topics`]: the one table of topic names, types and QoS, and the frames;
//! - [`node`]: joining the domain of `ROS_DOMAIN_ID`;
//! - [`plant`]: `tendril-ros2 plant`, the plant node;
//! - [`drive`]: `tendril-ros2 drive`, the planner and controller against a robot on ROS 2;
//! - [`chip`]: `drive --controller mcu`, the STM32F405 image under QEMU as its controller;
//! - [`targets`]: `drive`'s targets from a topic;
//! - [`verdicts`]: `tendril sim`'s verdicts on a drive's run.

pub mod chip;
pub mod drive;
pub mod msg;
pub mod node;
pub mod plant;
pub mod targets;
pub mod topics;
pub mod verdicts;

/// What can go wrong on the ROS 2 side.
#[derive(Debug, thiserror::Error)]
pub enum Ros2Error {
    /// A setting or input that cannot work, with its name.
    #[error("{0}")]
    Config(String),
    /// DDS refused to create an entity or to write.
    #[error("DDS: {0}")]
    Dds(String),
    /// An output could not be written.
    #[error("{0}")]
    Output(String),
    /// The robot (or its tracker) stopped answering for longer than the
    /// drive waits.
    #[error("{0}")]
    RobotSilent(String),
    /// The chip as the controller: its bridge or QEMU failed.
    #[error("the chip: {0}")]
    Chip(String),
    /// A signal asked to stop before the work began; nothing was written.
    #[error("interrupted {0}")]
    Interrupted(String),
}
