//! `tendril workspace`: the reachable-workspace figure (the paper's Figure 1).

use std::path::PathBuf;

use super::common::RobotArg;
use crate::dataset::Dataset;
use crate::pipeline::example_shapes;
use crate::plot::workspace::draw_workspace;
use crate::statics::{SolverSettings, Statics};

/// Plot a dataset's tip positions (three projections) and a few backbone shapes.
#[derive(clap::Args, Debug)]
pub struct WorkspaceArgs {
    /// Dataset CSV (from `tendril generate`).
    #[arg(long, value_name = "CSV")]
    pub data: PathBuf,
    /// Output PNG.
    #[arg(long, value_name = "PNG", default_value = "workspace.png")]
    pub out: PathBuf,
    #[command(flatten)]
    pub robot: RobotArg,
}

/// Run `tendril workspace`.
pub fn run(args: WorkspaceArgs) -> anyhow::Result<()> {
    super::common::refuse_stdout("--out", &args.out, "a PNG is drawn into a file")?;
    let data = Dataset::read_csv(&args.data)?;
    let (robot, _) = args.robot.load()?;
    let statics = Statics::new(&robot, SolverSettings::default());
    let shapes = example_shapes(&statics)?;
    let title = format!(
        "{}: reachable tip positions ({} sample{})",
        robot.name,
        data.len(),
        if data.len() == 1 { "" } else { "s" }
    );
    draw_workspace(&data.poses, &shapes, &title, &args.out)
        .map_err(|e| anyhow::anyhow!("drawing {}: {e}", args.out.display()))?;
    log::info!("wrote {}", args.out.display());
    Ok(())
}
