//! `tendril modes`: the rod's first two bending modes (frequency, damping)
//! at rest and with each segment bent, at given tensions, or along a run
//! (`docs/design.md` §6.4).

use anyhow::Context;

use super::common::{parse_list, RobotArg};
use crate::dynamics::modes::ModeSearch;
use crate::jobs::modes::{poses, poses_along, table, ModesTable};
use crate::plant::reality::Reality;

/// Identify the rod's vibration modes from its dynamic model.
#[derive(clap::Args, Debug)]
pub struct ModesArgs {
    #[command(flatten)]
    robot: RobotArg,
    /// Tensions (N), one per tendon: the modes at this pose only (default:
    /// at rest and with each segment bent by half its first tendon's range).
    #[arg(long, value_name = "T0,T1,...", conflicts_with = "along")]
    at: Option<String>,
    /// The modes along a run: evenly spaced rows of a CSV of tensions, a
    /// run's plant log (`OUT/plant-0.csv`, columns tau0..) or fk's batch
    /// input (t0..). A path can move the modes where the table at rest and
    /// bent does not show it.
    #[arg(long, value_name = "CSV")]
    along: Option<std::path::PathBuf>,
    /// How many rows of --along.
    #[arg(long, value_name = "N", default_value_t = 16, requires = "along",
          value_parser = clap::value_parser!(u32).range(1..=1000))]
    rows: u32,
    /// The modes of the robot a reality makes (its stiffness, density,
    /// length and damping ratio), as the plant runs it; default: the robot
    /// file's, which is all a controller knows.
    #[arg(long, value_name = "FILE|NAME")]
    reality: Option<std::path::PathBuf>,
    /// Print the table as JSON instead.
    #[arg(long)]
    json: bool,
}

/// Run `tendril modes`.
pub fn run(args: ModesArgs) -> anyhow::Result<()> {
    let (nominal, _) = args.robot.load()?;
    let at = match &args.at {
        Some(text) => {
            let at = parse_list(text, "--at")?;
            nominal
                .check_tensions(&at)
                .with_context(|| format!("--at {text}"))?;
            Some(at)
        }
        None => None,
    };
    let (robot, damping) = match &args.reality {
        Some(spec) => {
            let reality = Reality::load(spec)?;
            let real = reality
                .real_robot(&nominal)
                .map_err(|e| anyhow::anyhow!("reality {}: {e}", reality.name))?;
            let damping = reality.damping(&real);
            (real, damping)
        }
        None => {
            let damping = crate::dynamics::Damping::of_robot(&nominal);
            (nominal, damping)
        }
    };
    let poses = match &args.along {
        Some(path) => {
            let rows = poses_along(path, robot.n_tendons(), args.rows as usize)?;
            // The robot's own tension rule, as for --at (its maxima too).
            for (line, t) in &rows {
                robot
                    .check_tensions(t)
                    .with_context(|| format!("--along {}, {line}", path.display()))?;
            }
            rows
        }
        None => poses(&robot, at.as_deref()),
    };
    let t = table(&robot, damping, &poses, &ModeSearch::default())?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&t)?);
    } else {
        print!("{}", render(&t));
    }
    Ok(())
}

/// The table as text: one line per pose.
fn render(t: &ModesTable) -> String {
    let mut s = format!(
        "{:<36} {:>9} {:>7} {:>9} {:>7}\n",
        "pose", "f1 (Hz)", "zeta1", "f2 (Hz)", "zeta2"
    );
    for row in &t.rows {
        let cell = |k: usize| match row.modes.get(k) {
            Some(m) => format!("{:>9.3} {:>7.3}", m.freq_hz, m.damping_ratio),
            None => format!("{:>9} {:>7}", "—", "overdamped"),
        };
        s.push_str(&format!("{:<36} {} {}\n", row.pose, cell(0), cell(1)));
    }
    if let Some((lo, hi)) = t.first_mode_range_hz() {
        s.push_str(&format!(
            "first mode {lo:.3}–{hi:.3} Hz over these poses ({:.1} % about the middle); \
             Euler–Bernoulli beam {:.3} Hz\n",
            100.0 * (hi - lo) / (hi + lo),
            t.beam_first_mode_hz
        ));
    }
    s
}
