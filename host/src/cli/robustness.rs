//! `tendril robustness`: the robot's closed-loop runs against every reality,
//! net alone and corrected, with one set of default gains (docs/design.md §6.3).

use std::io::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;

use crate::ipc::sim::ModelSource;
use crate::plant::reality::{Reality, BUILTIN};
use crate::robustness::{self, RobustnessConfig};

/// Run the circle, the steps (and the helix on a robot that reaches a
/// volume) against every built-in reality and write a table and a figure.
#[derive(Args, Debug)]
pub struct RobustnessArgs {
    /// Robot description file (the model the planner, IK and net use).
    #[arg(long, default_value = crate::robot::DEFAULT_ROBOT)]
    pub robot: PathBuf,
    /// Trained IK net [default: out/model.tnet if it exists, else the
    /// firmware's built-in net for the default robot].
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Realities, by name or file, comma-separated [default: every built-in].
    #[arg(long, value_delimiter = ',')]
    pub realities: Vec<PathBuf>,
    /// Output directory (robustness.md, robustness.json, robustness.png, one
    /// directory per reality with each run's report).
    #[arg(long, default_value = "out/robustness")]
    pub out: PathBuf,
    /// Cap on each run's seconds of trajectory (a quicker, rougher table).
    #[arg(long)]
    pub quick: Option<f64>,
    /// Only the corrected runs (half the time).
    #[arg(long)]
    pub corrected_only: bool,
    /// The planner's stiffness adaptation (docs/design.md §6.5; on by
    /// default, as in `tendril sim`).
    #[arg(long, value_enum, default_value_t = super::controller::OnOff::On)]
    pub adapt_stiffness: super::controller::OnOff,
    /// Run nothing: redraw the table and figure from these robustness.json
    /// files (a later file's rows replace an earlier one's of the same
    /// reality), e.g. to join a full table with a re-run of some realities.
    #[arg(long, value_delimiter = ',')]
    pub redraw: Vec<PathBuf>,
}

/// Run `tendril robustness`.
pub fn run(args: RobustnessArgs) -> anyhow::Result<()> {
    super::common::refuse_stdout("--out", &args.out, "names a directory")?;
    if let Some(q) = args.quick {
        super::controller::check("--quick", q, q > 0.0, "a number of seconds > 0")?;
    }
    let specs: Vec<PathBuf> = if args.realities.is_empty() {
        BUILTIN
            .iter()
            .map(|(name, _)| PathBuf::from(name))
            .collect()
    } else {
        args.realities.clone()
    };
    let realities = specs
        .iter()
        .map(|p| Reality::load(p))
        .collect::<Result<Vec<_>, _>>()?;
    refuse_shared_names(&specs, &realities)?;
    // Everything goes to a staging directory first and is published when
    // the table is done: an interrupted or failed table leaves exactly the
    // previous one (its runs' directories too).
    let locked = crate::fsutil::staging::LockedOutput::acquire(&args.out)?;
    let staging = locked
        .staging()
        .with_context(|| format!("creating a staging directory in {}", args.out.display()))?;
    let result = table(&args, realities, staging.dir());
    match result {
        Ok((runs, failed)) if !crate::interrupt::stop_requested() => {
            staging.publish().with_context(|| {
                format!("moving the finished table into {}", args.out.display())
            })?;
            let rows_md = args.out.join("robustness.md");
            let _ = writeln!(
                std::io::stdout(),
                "{runs} runs; {failed} corrected runs not clean; table in {}",
                rows_md.display()
            );
            Ok(())
        }
        other => {
            drop(staging);
            locked.abandon();
            match other {
                Err(e) if !crate::interrupt::stop_requested() => Err(e.context(format!(
                    "the table failed; {} was left as it was",
                    args.out.display()
                ))),
                _ => Err(anyhow::anyhow!(
                    "interrupted: {} was left as it was",
                    args.out.display()
                )),
            }
        }
    }
}

/// Each reality's name is a directory of the output: two of one name
/// would write one directory twice.
fn refuse_shared_names(specs: &[PathBuf], realities: &[Reality]) -> anyhow::Result<()> {
    for (i, r) in realities.iter().enumerate() {
        if let Some(j) = realities[..i].iter().position(|x| x.name == r.name) {
            anyhow::bail!(
                "--realities: {} and {} are both named {:?}, and the name is the directory of \
                 each one's runs: rename one",
                specs[j].display(),
                specs[i].display(),
                r.name
            );
        }
    }
    Ok(())
}

/// Run (or redraw) the table into `dir`; returns how many runs it has and
/// how many of the corrected ones were not clean.
fn table(
    args: &RobustnessArgs,
    realities: Vec<Reality>,
    dir: &Path,
) -> anyhow::Result<(usize, usize)> {
    let rows = if args.redraw.is_empty() {
        let cfg = RobustnessConfig {
            exe: std::env::current_exe().context("locating the tendril executable")?,
            robot: args.robot.clone(),
            model: ModelSource::resolve(args.model.clone(), Path::new("out/model.tnet")),
            out: dir.to_path_buf(),
            shown_out: args.out.clone(),
            realities,
            quick_s: args.quick,
            net_alone: !args.corrected_only,
            adapt_stiffness: args.adapt_stiffness == super::controller::OnOff::On,
        };
        robustness::run(&cfg)?
    } else {
        let mut rows: Vec<robustness::Row> = Vec::new();
        for path in &args.redraw {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("reading {}", path.display()))?;
            let more: Vec<robustness::Row> = serde_json::from_str(&text)
                .with_context(|| format!("{}: not a robustness.json", path.display()))?;
            for r in more {
                match rows.iter_mut().find(|x| {
                    x.reality == r.reality && x.run == r.run && x.correction == r.correction
                }) {
                    Some(x) => *x = r,
                    None => rows.push(r),
                }
            }
        }
        rows
    };
    let md = robustness::markdown(&rows, &args.robot);
    crate::fsutil::write_atomic(&dir.join("robustness.md"), md.as_bytes())?;
    let json = serde_json::to_vec_pretty(&rows)?;
    crate::fsutil::write_atomic(&dir.join("robustness.json"), &json)?;
    let title = format!(
        "{}: tracking error against each reality, default gains",
        args.robot.display()
    );
    robustness::figure::draw(&rows, &title, &dir.join("robustness.png"))
        .map_err(|e| anyhow::anyhow!("robustness figure: {e}"))?;
    let failed = rows.iter().filter(|r| r.correction && !r.clean).count();
    Ok((rows.len(), failed))
}
