//! `tendril calibrate`: fit a robot file to measurements, or plan the
//! measurements (`docs/design.md` §11).

use std::path::PathBuf;

use anyhow::Context;

use super::common::RobotArg;
use crate::calibrate::{self, FitOptions};

use crate::calibrate::DEFAULT_FIT;

/// Fit a robot file's parameters to measured tip poses; or, with --plan N,
/// propose N tension sets to measure.
#[derive(clap::Args, Debug, Clone)]
pub struct CalibrateArgs {
    /// The nominal robot file the fit starts from.
    #[command(flatten)]
    pub robot: RobotArg,
    /// Measured CSV: t0..t{n-1} [N], px,py,pz [m], optional qw..qz, fx,fy,fz, mx,my,mz.
    #[arg(
        long,
        value_name = "CSV",
        required_unless_present_any = ["plan", "step"],
        conflicts_with = "plan"
    )]
    pub data: Option<PathBuf>,
    /// A tracker's trace of the tip after a tension step (CSV: `t_s` or
    /// `t_ns`; `x_m,y_m,z_m`, or a plant log's `mx,my,mz`, or `px,py,pz`;
    /// or a run log, `*.mcap`, its `/tracking` frames): fit the rod's first
    /// bending mode, its damping and the dynamic rod's retardation time
    /// with 95 % intervals, instead of the statics. The fit goes to --out
    /// as JSON (`-`: stdout).
    #[arg(long, value_name = "TRACE", conflicts_with_all = ["data", "plan"])]
    pub step: Option<PathBuf>,
    /// With --step: seconds after the trace's first frame (the step) before
    /// the fit starts: the motors' rise and the higher modes.
    #[arg(long, default_value_t = 0.1)]
    pub skip_s: f64,
    /// Parameters to fit: E, G, density, length, offsets, angles, tension_scale, base
    /// (base_t, base_r; offset2 etc. for one tendon).
    #[arg(long, value_name = "LIST", default_value = DEFAULT_FIT)]
    pub fit: String,
    /// Output: the calibrated robot file; with --plan, the tension CSV. The
    /// report goes beside it as <stem>.report.json, .report.md and .png.
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Propose N tension sets (greedy D-optimal) instead of fitting; at most
    /// 5,000 (rows someone measures by hand). `--out -` prints them.
    #[arg(long, value_name = "N")]
    pub plan: Option<usize>,
    /// With --plan: a known mass hung on the tip for some rows, grams; its
    /// weight along the robot file's gravity is each row's fx,fy,fz. Rows
    /// with a known load make E identifiable (docs/design.md §11).
    #[arg(
        long,
        value_name = "GRAMS",
        requires = "plan",
        conflicts_with = "plan_tip_load"
    )]
    pub plan_tip_mass_g: Option<f64>,
    /// With --plan: a known tip force for some rows, N, base frame
    /// ("fx,fy,fz"; e.g. a weight over a pulley).
    #[arg(
        long,
        value_name = "FX,FY,FZ",
        requires = "plan",
        allow_hyphen_values = true
    )]
    pub plan_tip_load: Option<String>,
    /// Fraction of rows held out of the fit to judge it, in [0, 0.5].
    #[arg(long, default_value_t = 0.2)]
    pub holdout: f64,
    /// Seed of the held-out split (and of the planner's candidates).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Ignore the orientation columns even when present.
    #[arg(long)]
    pub positions_only: bool,
    /// Weight of an orientation error against a position error, mm per
    /// degree, in [0.001, 1000].
    #[arg(long, default_value_t = 0.1 * 1e3 * std::f64::consts::PI / 180.0)]
    pub mm_per_deg: f64,
    /// Standard deviation of the recorded tensions' noise (the load cells),
    /// N, in [0, 1]: the tip scatter it makes through the robot's
    /// compliance is reported and may remain in the fit's residual.
    #[arg(long, default_value_t = 0.0, value_name = "N")]
    pub tension_noise_n: f64,
}

/// The known tip load `--plan-tip-mass-g` or `--plan-tip-load` asks for.
fn planned_load(
    robot: &crate::robot::Robot,
    args: &CalibrateArgs,
) -> anyhow::Result<Option<[f64; 3]>> {
    if let Some(g) = args.plan_tip_mass_g {
        if !(g.is_finite() && g > 0.0) {
            anyhow::bail!(
                "--plan-tip-mass-g must be a mass > 0 g, got {}",
                crate::units::given(g)
            );
        }
        return calibrate::plan::hung_mass_force(robot, g)
            .map(Some)
            .ok_or_else(|| {
                anyhow::anyhow!(
                    "--plan-tip-mass-g: {} has no gravity, so a hung mass's direction in its base \
                 frame is unknown: give the force with --plan-tip-load fx,fy,fz",
                    args.robot.robot.display()
                )
            });
    }
    let Some(text) = &args.plan_tip_load else {
        return Ok(None);
    };
    let v = super::common::parse_list(text, "--plan-tip-load")?;
    match v[..] {
        [x, y, z]
            if [x, y, z].iter().all(|c| c.is_finite()) && (x != 0.0 || y != 0.0 || z != 0.0) =>
        {
            Ok(Some([x, y, z]))
        }
        _ => anyhow::bail!(
            "--plan-tip-load {text:?}: expected three finite numbers fx,fy,fz (N, base frame), \
             not all zero"
        ),
    }
}

/// The weights of an orientation error `--mm-per-deg` accepts: beyond
/// them one kind of error silences the other.
const MM_PER_DEG: std::ops::RangeInclusive<f64> = 1e-3..=1e3;

/// Run `tendril calibrate`.
pub fn run(args: CalibrateArgs) -> anyhow::Result<()> {
    let (robot, _) = args.robot.load()?;
    if let Some(trace) = &args.step {
        return step(&robot, trace, &args);
    }
    if args.plan.is_none() && (args.plan_tip_mass_g.is_some() || args.plan_tip_load.is_some()) {
        // clap's `requires` gives way to the data/plan/step choice.
        anyhow::bail!(
            "--plan-tip-mass-g and --plan-tip-load plan rows: they need --plan N (a fit takes \
             each row's known load from its fx,fy,fz columns)"
        );
    }
    let fit =
        calibrate::parse_fit_list(&args.fit, robot.n_tendons()).map_err(anyhow::Error::msg)?;
    if let Some(n) = args.plan {
        crate::fsutil::check_distinct(&[("--robot", &args.robot.robot)], &[("--out", &args.out)])?;
        let fit = calibrate::plan::plannable(&robot, &fit);
        let load = planned_load(&robot, &args)?;
        let rows = calibrate::plan::plan(&robot, &fit, n, args.seed, load)?;
        let mut header: Vec<String> = (0..robot.n_tendons()).map(|i| format!("t{i}")).collect();
        if load.is_some() {
            header.extend(["fx", "fy", "fz"].map(String::from));
        }
        let mut text = header.join(",") + "\n";
        for r in &rows {
            let forces = load.map(|_| r.tip_force);
            let cells: Vec<String> = r
                .tensions
                .iter()
                .chain(forces.iter().flatten())
                .map(|x| format!("{x}"))
                .collect();
            text += &(cells.join(",") + "\n");
        }
        if let Some(f) = load {
            let loaded = rows.iter().filter(|r| r.tip_force == f).count();
            log::info!(
                "{loaded} of {} rows carry the known tip load {f:?} N: measure them with it hung",
                rows.len()
            );
        }
        crate::fsutil::write_atomic(&args.out, text.as_bytes())
            .with_context(|| format!("{}", args.out.display()))?;
        log::info!(
            "wrote {} tension sets to {}",
            rows.len(),
            args.out.display()
        );
        return Ok(());
    }
    let data_path = args
        .data
        .clone()
        .expect("clap requires --data without --plan");
    super::common::refuse_stdout(
        "--out",
        &args.out,
        "the calibrated robot file has its report and figure beside it",
    )?;
    if !MM_PER_DEG.contains(&args.mm_per_deg) {
        anyhow::bail!(
            "--mm-per-deg must be in [{}, {}] mm per degree, got {}",
            MM_PER_DEG.start(),
            MM_PER_DEG.end(),
            crate::units::given(args.mm_per_deg)
        );
    }
    let stem = args.out.with_extension("");
    let side = |ext: &str| PathBuf::from(format!("{}.{ext}", stem.display()));
    let (json, md, png) = (side("report.json"), side("report.md"), side("png"));
    crate::fsutil::check_distinct(
        &[("--robot", &args.robot.robot), ("--data", &data_path)],
        &[
            ("--out", &args.out),
            ("report", &json),
            ("report", &md),
            ("figure", &png),
        ],
    )?;
    let data = calibrate::read_measurements(&data_path, &robot)?;
    let mut opts = FitOptions::new(fit);
    opts.holdout_fraction = args.holdout;
    opts.seed = args.seed;
    opts.use_orientation = !args.positions_only;
    opts.orientation_m_per_rad = args.mm_per_deg * 1e-3 * 180.0 / std::f64::consts::PI;
    if !(args.tension_noise_n.is_finite() && (0.0..=1.0).contains(&args.tension_noise_n)) {
        anyhow::bail!(
            "--tension-noise-n must be a tension in [0, 1] N, got {}",
            crate::units::given(args.tension_noise_n)
        );
    }
    opts.tension_noise_n = args.tension_noise_n;
    log::info!("{}", calibrate::fit::cost_estimate(&robot, &data, &opts));
    let c = calibrate::calibrate(&robot, &data, &opts)?;
    let calibrated = c.report.verdict.calibrated;
    if calibrated {
        // The robot file must read back as a valid robot before it is written.
        let text = c.robot_file();
        crate::robot::Robot::from_toml(&text, &args.out)
            .context("the calibrated robot does not pass the robot-file checks")?;
        crate::fsutil::write_atomic(&args.out, text.as_bytes())
            .with_context(|| format!("{}", args.out.display()))?;
    }
    crate::fsutil::write_atomic(&json, c.report.json().as_bytes())
        .with_context(|| format!("{}", json.display()))?;
    crate::fsutil::write_atomic(&md, c.report.markdown().as_bytes())
        .with_context(|| format!("{}", md.display()))?;
    crate::plot::calibration::draw_calibration(&c, &png)
        .map_err(|e| anyhow::anyhow!("{}: {e}", png.display()))?;
    let r = &c.report;
    if !calibrated {
        anyhow::bail!(
            "the fit is not a calibration, so no robot file was written ({} left as it was); \
             the report says why ({}): {}",
            args.out.display(),
            md.display(),
            r.verdict.problems.join("; ")
        );
    }
    let held = if r.rows_held_out == 0 {
        "no rows held out".to_string()
    } else {
        format!(
            "held-out tip error rms {:.3} mm -> {:.3} mm",
            r.held_out_before.rms_m * 1e3,
            r.held_out_after.rms_m * 1e3
        )
    };
    log::info!(
        "calibrated {} in {:.2} s: {held} (fit rows {:.3} -> {:.3} mm); {} fixed as unidentifiable; {} rows down-weighted; wrote {}",
        r.robot,
        r.seconds,
        r.fit_before.rms_m * 1e3,
        r.fit_after.rms_m * 1e3,
        r.unidentifiable.len(),
        r.downweighted.len(),
        args.out.display()
    );
    Ok(())
}

/// `tendril calibrate --step TRACE`: the first mode from a measured step,
/// beside the robot file's own (identified from its dynamic model at rest).
fn step(
    robot: &crate::robot::Robot,
    trace: &std::path::Path,
    args: &CalibrateArgs,
) -> anyhow::Result<()> {
    if !(args.skip_s.is_finite() && args.skip_s >= 0.0) {
        anyhow::bail!(
            "--skip-s must be a number of seconds ≥ 0, got {}",
            crate::units::given(args.skip_s)
        );
    }
    crate::fsutil::check_distinct(&[("--step", trace)], &[("--out", &args.out)])?;
    let fit = calibrate::step::fit_step(
        &crate::jobs::step_trace::read_step_trace(trace)?,
        args.skip_s,
    )?;
    let zeros = vec![0.0; robot.n_tendons()];
    let file_mode = crate::dynamics::modes::identify(
        robot,
        crate::dynamics::Damping::of_robot(robot),
        &zeros,
        &crate::dynamics::modes::ModeSearch::default(),
    )
    .ok()
    .and_then(|m| m.first().copied());
    let json = serde_json::json!({
        "trace": trace.display().to_string(),
        "fit": fit,
        "robot_file_mode": file_mode,
    });
    let text = serde_json::to_string_pretty(&json)? + "\n";
    if args.out.as_os_str() == "-" {
        print!("{text}");
    } else {
        crate::fsutil::write_atomic(&args.out, text.as_bytes())
            .with_context(|| format!("{}", args.out.display()))?;
    }
    let e = |x: &calibrate::step::Estimate, scale: f64, digits: usize| {
        format!(
            "{:.*} [{:.*}, {:.*}]",
            digits,
            x.value * scale,
            digits,
            x.interval_95[0] * scale,
            digits,
            x.interval_95[1] * scale
        )
    };
    let file = file_mode.map_or(String::new(), |m| {
        format!(
            "; the robot file's model: {:.3} Hz, ζ {:.3}",
            m.freq_hz, m.damping_ratio
        )
    });
    log::info!(
        "first bending mode {} Hz, ζ {}, retardation time {} ms (95 % intervals; {} frames, residual {:.3} mm){file}",
        e(&fit.freq_hz, 1.0, 3),
        e(&fit.damping_ratio, 1.0, 4),
        e(&fit.retardation_s, 1e3, 2),
        fit.frames,
        fit.residual_mm
    );
    Ok(())
}
