//! `tendril generate`: the tension ↔ pose dataset (docs/design.md §3).

use std::path::PathBuf;

use super::common::{stop_flag, RobotArg};
use crate::dataset::split::TEST_FRACTION;
use crate::dataset::{Resolve, Sampler};
use crate::jobs::dataset::{
    self as job, GenerateRequest, DEFAULT_MAX_FAILURE_FRACTION, DEFAULT_SAMPLES,
};
use crate::statics::SolverSettings;

/// Sample tensions, solve the statics for each, write CSV + JSON sidecar.
#[derive(clap::Args, Debug, Clone)]
pub struct GenerateArgs {
    #[command(flatten)]
    pub robot: RobotArg,
    /// Number of samples (1 to 20,000,000).
    #[arg(long, default_value_t = DEFAULT_SAMPLES)]
    pub samples: usize,
    /// Random seed of the sampler.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Tension sampler [default: adjacent for robots with more than two tendons, else uniform].
    #[arg(long, value_enum)]
    pub sampler: Option<Sampler>,
    /// Which tensions each row keeps: the drawn ones, or the least bending effort that reaches
    /// the drawn tip position [default: least-bending for robots with more than four bending
    /// degrees of freedom (three segments), else drawn] (docs/design.md §3).
    #[arg(long, value_enum)]
    pub resolve: Option<Resolve>,
    /// Output CSV, a regular file (not a device or FIFO); the sidecar goes beside it as <name>.json.
    #[arg(long, value_name = "CSV", default_value = "data.csv")]
    pub out: PathBuf,
    /// Fail (exit non-zero, after writing) if more than this fraction of solves fails.
    #[arg(long, default_value_t = DEFAULT_MAX_FAILURE_FRACTION)]
    pub max_failure_fraction: f64,
    /// Held-out test fraction recorded for the learners (split seed 1).
    #[arg(long, default_value_t = TEST_FRACTION)]
    pub test_fraction: f64,
    /// RK4 steps over the length (1 to 100,000).
    #[arg(long, default_value_t = SolverSettings::default().steps)]
    pub steps: usize,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Add to every row's pose the residual that measured rows (a CSV of
    /// tensions and tracker poses, no sidecar) show against this robot
    /// file's statics: give the calibrated file and the rows it was
    /// calibrated on, and the dataset carries what no parameter of the file
    /// explains (a smooth function of the tensions, fitted by ridge
    /// regression; docs/design.md §11.5). The fit is in the sidecar.
    #[arg(long, value_name = "CSV")]
    pub residual_from: Option<PathBuf>,
    /// Synthetic measurements: Gaussian tracker jitter on each position axis, mm.
    #[arg(long, value_name = "SIGMA", default_value_t = 0.0)]
    pub noise_mm: f64,
    /// Synthetic measurements: Gaussian jitter on each axis of the orientation, degrees.
    #[arg(long, value_name = "D", default_value_t = 0.0)]
    pub noise_deg: f64,
    /// Synthetic measurements: the robot's base in the tracker frame, mm (x,y,z).
    #[arg(long, value_name = "X,Y,Z")]
    pub frame_offset_mm: Option<String>,
    /// Seed of the measurement noise.
    #[arg(long, default_value_t = 2)]
    pub noise_seed: u64,
    /// Synthetic measurements: fraction of rows, in [0, 1], whose tip position is an outlier
    /// (off by --outlier-mm in a random direction, on top of the jitter).
    #[arg(long, value_name = "F", default_value_t = 0.0)]
    pub outlier_fraction: f64,
    /// Synthetic measurements: how far an outlier's tip position is off, mm.
    #[arg(long, value_name = "MM", default_value_t = 5.0)]
    pub outlier_mm: f64,
}

impl GenerateArgs {
    /// The library request these arguments ask for.
    pub fn request(&self) -> GenerateRequest {
        GenerateRequest {
            robot_path: self.robot.robot.clone(),
            samples: self.samples,
            seed: self.seed,
            sampler: self.sampler,
            resolve: self.resolve,
            out: self.out.clone(),
            max_failure_fraction: self.max_failure_fraction,
            test_fraction: self.test_fraction,
            steps: self.steps,
        }
    }
}

/// Run `tendril generate`.
pub fn run(args: GenerateArgs) -> anyhow::Result<()> {
    super::common::refuse_stdout(
        "--out",
        &args.out,
        "a dataset is a CSV with its sidecar (.json) beside it",
    )?;
    let noise = tracker_noise(&args)?;
    // The residual is fitted before anything is generated: rows it cannot
    // use leave no dataset behind.
    let residual = match &args.residual_from {
        Some(path) => Some(fit_residual(&args, path)?),
        None => None,
    };
    let mut sidecar = job::generate(&args.request(), !args.quiet, stop_flag())?;
    if let Some((residual, record)) = residual {
        log::info!(
            "added the residual of {} ({} rows, {} outliers left out; degree {}, λ {:.0e}): the \
             model's position error on its validation rows {:.3} → {:.3} mm RMS, orientation \
             {:.3}° → {:.3}°",
            record.file,
            record.rows,
            record.outliers,
            record.degree,
            record.lambda,
            record.valid_position_rms_mm.0,
            record.valid_position_rms_mm.1,
            record.valid_angle_rms_deg.0,
            record.valid_angle_rms_deg.1
        );
        crate::calibrate::residual::add_to_dataset(&args.out, &mut sidecar, &residual, record)?;
    }
    if let Some(noise) = noise {
        // The rows as a tracker would record them (docs/design.md §11); the
        // sidecar keeps describing the noiseless solves.
        let mut data = crate::dataset::Dataset::read_csv(&args.out)?;
        let outliers = crate::calibrate::noise::add_tracker_noise(&mut data, &noise);
        data.write_csv(&args.out)?;
        log::info!(
            "added tracker noise: {} mm per axis, {}° per axis, base at {:?} mm, {} outlier \
             rows off by {} mm",
            args.noise_mm,
            args.noise_deg,
            noise.frame_offset_m.map(|x| x * 1e3),
            outliers.len(),
            args.outlier_mm
        );
    }
    log::info!(
        "wrote {} to {} in {:.2} s ({} re-solved cold, {} dropped)",
        rows(sidecar.count),
        args.out.display(),
        sidecar.seconds,
        sidecar.resolved_cold,
        sidecar.dropped
    );
    Ok(())
}

/// The residual of the measured rows at `path` against the robot's statics.
fn fit_residual(
    args: &GenerateArgs,
    path: &std::path::Path,
) -> anyhow::Result<(
    crate::calibrate::residual::Residual,
    crate::dataset::ResidualRecord,
)> {
    let (robot, _) = args.robot.load()?;
    let statics = crate::statics::Statics::new(
        &robot,
        SolverSettings {
            steps: args.steps,
            ..SolverSettings::default()
        },
    );
    let rows = crate::dataset::Dataset::read_csv(path)
        .map_err(|e| anyhow::anyhow!("--residual-from: {e}"))?;
    let shown = path.display().to_string();
    // The validation fifth is drawn with seed 1, whatever the sampler's
    // seed: one measured file gives one residual (Python's `fit_residual`
    // draws the same).
    crate::calibrate::residual::fit(&statics, &rows, &shown, 1)
        .map_err(|e| anyhow::anyhow!("--residual-from {shown}: {e}"))
}

fn rows(n: usize) -> String {
    if n == 1 {
        "1 row".into()
    } else {
        format!("{n} rows")
    }
}

/// The tracker noise the flags ask for, or `None` for a noiseless dataset.
fn tracker_noise(
    args: &GenerateArgs,
) -> anyhow::Result<Option<crate::calibrate::noise::TrackerNoise>> {
    use crate::units::given;
    // Synthetic trackers within what a lab meets (a tracker 10 m from the
    // base, a metre of jitter are already absurd): beyond, the numbers
    // only overflow.
    for (flag, x, max) in [
        ("--noise-mm", args.noise_mm, 1000.0),
        ("--noise-deg", args.noise_deg, 180.0),
        ("--outlier-mm", args.outlier_mm, 10_000.0),
    ] {
        if !(x.is_finite() && (0.0..=max).contains(&x)) {
            anyhow::bail!("{flag} must be in [0, {max}], got {}", given(x));
        }
    }
    let offset = match &args.frame_offset_mm {
        None => [0.0; 3],
        Some(text) => {
            let v = super::common::parse_list(text, "--frame-offset-mm")?;
            if v.len() != 3 || v.iter().any(|x| !(x.is_finite() && x.abs() <= 10_000.0)) {
                anyhow::bail!(
                    "--frame-offset-mm takes three numbers x,y,z within ±10000 mm, got {text:?}"
                );
            }
            [v[0] * 1e-3, v[1] * 1e-3, v[2] * 1e-3]
        }
    };
    if !(0.0..=1.0).contains(&args.outlier_fraction) {
        anyhow::bail!(
            "--outlier-fraction must be in [0, 1], got {}",
            given(args.outlier_fraction)
        );
    }
    let outliers = args.outlier_fraction > 0.0 && args.outlier_mm > 0.0;
    if args.noise_mm == 0.0 && args.noise_deg == 0.0 && offset == [0.0; 3] && !outliers {
        return Ok(None);
    }
    Ok(Some(crate::calibrate::noise::TrackerNoise {
        position_sigma_m: args.noise_mm * 1e-3,
        angle_sigma_rad: args.noise_deg.to_radians(),
        frame_offset_m: offset,
        seed: args.noise_seed,
        outlier_fraction: args.outlier_fraction,
        outlier_m: args.outlier_mm * 1e-3,
    }))
}
