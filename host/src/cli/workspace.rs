//! `tendril workspace`: the reachable-workspace figure (the paper's Figure 1).

use std::path::PathBuf;

use anyhow::Context;

use super::common::RobotArg;
use crate::dataset::Dataset;
use crate::plot::workspace::{draw_workspace, Shape};
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
    let data = Dataset::read_csv(&args.data)?;
    let (robot, _) = args.robot.load()?;
    let statics = Statics::new(&robot, SolverSettings::default());
    let n = robot.n_tendons();
    let mut shapes = Vec::new();
    // Unloaded (gravity sag), then each of the first two tendons' full pull
    // and half pull, and the opposite tendon for contrast.
    let mut cases: Vec<(String, Vec<f64>)> = vec![("no tension".into(), vec![0.0; n])];
    for i in [0usize, n / 2].into_iter().filter(|&i| i < n) {
        let max = robot.tendons[i].max_tension;
        for frac in [0.5, 1.0] {
            let mut t = vec![0.0; n];
            t[i] = frac * max;
            cases.push((format!("t{i} = {:.1} N", t[i]), t));
        }
    }
    cases.dedup_by(|a, b| a.1 == b.1);
    for (label, t) in cases {
        let sol = statics
            .solve(&t, None)
            .with_context(|| format!("shape for {label}"))?;
        shapes.push(Shape {
            label,
            points: statics.shape(&sol, 41),
        });
    }
    let title = format!(
        "{}: reachable tip positions ({} samples)",
        robot.name,
        data.len()
    );
    draw_workspace(&data.poses, &shapes, &title, &args.out)
        .map_err(|e| anyhow::anyhow!("drawing {}: {e}", args.out.display()))?;
    log::info!("wrote {}", args.out.display());
    Ok(())
}
