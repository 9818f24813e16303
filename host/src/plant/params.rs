//! What a plant is asked to be ([`PlantParams`]): how it moves the robot,
//! its motors, sensor and injected faults (units in the field names).

use serde::{Deserialize, Serialize};

use super::reality::Reality;

/// How the plant moves the robot.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum RobotModel {
    /// Each step jumps to the statics equilibrium of the tendon tensions.
    #[default]
    QuasiStatic,
    /// The Cosserat rod with inertia and damping, stepped in time
    /// (docs/design.md §4.2): the robot swings and rings.
    Dynamic,
}

/// Injected faults.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlantFaults {
    /// A motor that freezes where it is.
    pub stuck: Option<StuckFault>,
    /// Commands dropped at random in a window.
    pub drop: Option<DropFault>,
    /// Commands delayed in a window.
    pub delay: Option<DelayFault>,
}

/// Motor `tendon` freezes at `at_s` seconds after the plant's start.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StuckFault {
    /// Tendon index.
    pub tendon: usize,
    /// When, s.
    pub at_s: f64,
}

/// A fraction of the commands is dropped between `from_s` and `to_s`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DropFault {
    /// Fraction of commands dropped, in [0, 1].
    pub fraction: f64,
    /// Window start, s.
    pub from_s: f64,
    /// Window end, s.
    pub to_s: f64,
}

/// Commands are delayed by `delay_s` between `from_s` and `to_s`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DelayFault {
    /// Extra delay, s.
    pub delay_s: f64,
    /// Window start, s.
    pub from_s: f64,
    /// Window end, s.
    pub to_s: f64,
}

/// Plant model parameters (units in the field names).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlantParams {
    /// Motor time constant, s: tension error decays as exp(−t/τ).
    pub motor_tau_s: f64,
    /// Series tendon compliance as a second lag, s; 0 = rigid tendons.
    pub compliance_tau_s: f64,
    /// Tip position sensor noise, standard deviation, m.
    pub noise_m: f64,
    /// Tip orientation sensor noise, standard deviation per quaternion component.
    pub noise_quat: f64,
    /// Seed of the noise and drop generator.
    pub seed: u64,
    /// RK4 steps of the statics (speed vs accuracy; 16 ≈ 1e-7 m).
    pub statics_steps: usize,
    /// Residual tolerance of the plant's statics, N / N m
    /// ([`crate::statics::SolverSettings::tol`]).
    pub statics_tol: f64,
    /// A warm solve may end on an unverified chord step that moves the tip
    /// by at most this, m ([`crate::statics::SolverSettings::final_step_m`];
    /// 0: every solve verified). The default, [`PLANT_FINAL_STEP_M`] with
    /// [`PLANT_STATICS_TOL`], keeps the plant's tip within 0.1 µm of a
    /// verified solve's (tested), 200 times below the quietest tracker's
    /// noise (20 µm), at one pass a step instead of two or three.
    pub statics_final_step_m: f64,
    /// Faults to inject.
    pub faults: PlantFaults,
    /// Quasi-static or dynamic robot.
    pub model: RobotModel,
    /// Time step of the dynamic robot, s (the plant takes as many as the
    /// elapsed time holds).
    pub dynamics_dt_s: f64,
    /// How the real robot and its tracker differ from the robot file
    /// (None: the robot file, an ideal tracker with `noise_m`).
    pub reality: Option<Reality>,
}

/// The plant's statics tolerance, N / N m: the one-pass warm solve's
/// (`docs/design.md` §2, "Solve").
pub const PLANT_STATICS_TOL: f64 = 1e-7;
/// The plant's bound on an unverified final step, m.
pub const PLANT_FINAL_STEP_M: f64 = 1e-6;

/// The default motors' time constant, s: the plant's, and what the
/// controller's stuck-motor rule and the planner's learning model assume
/// of a robot's motors unless told otherwise.
pub const MOTOR_TAU_S: f64 = 0.02;

impl Default for PlantParams {
    fn default() -> Self {
        PlantParams {
            motor_tau_s: MOTOR_TAU_S,
            compliance_tau_s: 0.0,
            noise_m: 20e-6,
            noise_quat: 1e-5,
            seed: 1,
            statics_steps: 16,
            statics_tol: PLANT_STATICS_TOL,
            statics_final_step_m: PLANT_FINAL_STEP_M,
            faults: PlantFaults::default(),
            model: RobotModel::QuasiStatic,
            dynamics_dt_s: 1e-3,
            reality: None,
        }
    }
}

impl PlantParams {
    /// The robot model the plant runs: the reality's `[dynamics] model`
    /// where it has one, else [`PlantParams::model`].
    pub fn model_in_effect(&self) -> RobotModel {
        self.reality
            .as_ref()
            .and_then(|r| r.dynamics)
            .map_or(self.model, |d| d.model)
    }
}
