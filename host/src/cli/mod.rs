//! Command-line interface: one file per subcommand, each an argument struct
//! plus a call into the library. The contract is `docs/design.md` §7.

use clap::{Parser, Subcommand};

mod calibrate;
pub mod common;
mod compare;
pub mod console;
pub mod controller;
mod dynamics;
pub mod evaluate;
mod fk;
pub mod generate;
pub mod ik;
mod modes;
pub mod planner;
pub mod plant;
mod plot;
mod robustness;
mod run;
mod sim;
pub mod train;
mod workspace;

/// Learn and run inverse kinematics of tendon-driven continuum robots.
///
/// With no subcommand, runs the whole pipeline on the default robot and
/// writes a report and figures under `out/`.
#[derive(Parser, Debug)]
#[command(name = "tendril", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    /// More detail on stderr (-v: per-unit training detail, -vv: trace); RUST_LOG wins.
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    verbose: u8,
    /// Only warnings and errors on stderr (and no training progress bar); RUST_LOG wins.
    #[arg(short = 'q', global = true, conflicts_with = "verbose")]
    quiet_console: bool,
}

impl Cli {
    /// The console verbosity `-v`/`-q` ask for.
    pub fn verbosity(&self) -> console::Verbosity {
        if self.quiet_console {
            console::Verbosity(-1)
        } else {
            console::Verbosity(self.verbose.min(i8::MAX as u8) as i8)
        }
    }
}

// Parsed once per process: the size of the largest variant does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand, Debug)]
enum Command {
    /// The whole pipeline on a robot file: dataset, net, comparison, firmware, closed loop.
    Run(run::RunArgs),
    /// Forward statics: tip pose for tendon tensions (one, or a CSV batch).
    Fk(fk::FkArgs),
    /// Fit a robot file to measured tip poses (or plan the measurements).
    Calibrate(calibrate::CalibrateArgs),
    /// Generate the tension <-> pose dataset (CSV + JSON sidecar).
    Generate(generate::GenerateArgs),
    /// Train every learner on one split and compare them (Table II, Figure 3).
    Compare(compare::CompareArgs),
    /// Plot a dataset's reachable workspace and a few backbone shapes.
    Workspace(workspace::WorkspaceArgs),
    /// Stream setpoints along a trajectory (iceoryx2 process).
    Planner(planner::PlannerArgs),
    /// Run the firmware control step at 1 kHz (iceoryx2 process).
    Controller(controller::ControllerArgs),
    /// Simulate tendon motors and the robot (iceoryx2 process).
    Plant(plant::PlantArgs),
    /// Launch planner, controller and plant; inject faults; write a report.
    Sim(sim::SimArgs),
    /// Train a cascade-correlation IK net and export it as .tnet.
    Train(train::TrainArgs),
    /// Tendon tensions for tip poses through a trained .tnet net (one or a CSV batch).
    Ik(ik::IkArgs),
    /// Tension RMSE, task-space tip error and inference time of a .tnet net.
    Evaluate(evaluate::EvaluateArgs),
    /// Dynamic step response: tip trajectory (CSV) and figure after a tension step.
    Dynamics(dynamics::DynamicsArgs),
    /// The rod's first two bending modes (frequency, damping ratio) over its workspace.
    Modes(modes::ModesArgs),
    /// The closed loop against every reality (a plant unlike its model): table and figure.
    Robustness(robustness::RobustnessArgs),
    /// Redraw a run's figure from its run.mcap (the Foxglove run log) alone.
    Plot(plot::PlotArgs),
}

/// Run the subcommand `cli` names (the whole pipeline without one).
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        None => crate::pipeline::run_default(),
        Some(Command::Run(a)) => run::run(a),
        Some(Command::Fk(a)) => fk::run(a),
        Some(Command::Calibrate(a)) => calibrate::run(a),
        Some(Command::Generate(a)) => generate::run(a),
        Some(Command::Compare(a)) => compare::run(a),
        Some(Command::Workspace(a)) => workspace::run(a),
        Some(Command::Planner(a)) => planner::run(a),
        Some(Command::Controller(a)) => controller::run(a),
        Some(Command::Plant(a)) => plant::run(a),
        Some(Command::Sim(a)) => sim::run(a),
        Some(Command::Train(a)) => train::run(a),
        Some(Command::Ik(a)) => ik::run(a),
        Some(Command::Evaluate(a)) => evaluate::run(a),
        Some(Command::Dynamics(a)) => dynamics::run(a),
        Some(Command::Modes(a)) => modes::run(a),
        Some(Command::Robustness(a)) => robustness::run(a),
        Some(Command::Plot(a)) => plot::run(a),
    }
}
