//! `tendril plot`: a run's figure redrawn from its `run.mcap` alone.

use std::path::PathBuf;

use clap::Args;

/// Redraw a run's figure (tip paths, tensions) from its MCAP run log.
#[derive(Args, Debug)]
pub struct PlotArgs {
    /// The run log (`run.mcap` beside a sim's report.json).
    pub mcap: PathBuf,
    /// The figure [default: the log's name with .png].
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Run `tendril plot`.
pub fn run(args: PlotArgs) -> anyhow::Result<()> {
    let out = args.out.unwrap_or_else(|| args.mcap.with_extension("png"));
    let r = crate::runlog::figure::redraw(&args.mcap, &out)?;
    let rms = r.rms_error_mm.map_or_else(
        || "none (the log has no setpoint)".to_string(),
        |e| format!("{e:.3} mm"),
    );
    let line = format!(
        "{}: {} tracking and {} tension messages{}, tip error RMS {rms} (every step, settling included)",
        out.display(),
        r.tracking,
        r.tensions,
        if r.truncated { " (the log was cut short)" } else { "" },
    );
    // With `--out -` the PNG is stdout: the summary goes to stderr.
    if crate::fsutil::is_stdout(&out) {
        eprintln!("{line}");
    } else {
        println!("{line}");
    }
    Ok(())
}
