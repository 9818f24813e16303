//! The robot the loop drives, as physics (`docs/design.md` §6): tendon
//! motors with saturation, dead band and backlash, optional tendon
//! compliance, the tip from warm-started Cosserat statics or the dynamic
//! rod, a tip tracker, the injectable motor and message faults, and the
//! realities that make it differ from its robot file. No transport: the
//! plant process ([`crate::ipc::plant`]) wraps it.

mod model;
mod params;
pub mod reality;

pub use model::PlantModel;
pub use params::{
    DelayFault, DropFault, PlantFaults, PlantParams, RobotModel, StuckFault, MOTOR_TAU_S,
};

/// Why a plant could not be made or stepped.
#[derive(Debug, thiserror::Error)]
pub enum PlantError {
    /// A parameter, the reality or its tracker does not fit the robot.
    #[error("{0}")]
    Config(String),
    /// The robot's statics or dynamics failed.
    #[error("{0}")]
    Solve(String),
}

#[cfg(test)]
mod tests;
