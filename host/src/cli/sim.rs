//! `tendril sim`: planner, controller and plant as three processes over
//! iceoryx2, with fault injection and a report (DESIGN §6, §7).

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;

use super::controller::LoopOpts;
use super::planner::TrajectoryOpts;
use super::plant::PlantOpts;
use crate::ipc::sim::{unique_prefix, SimConfig, SimFaults};

/// Run planner, controller and plant as separate processes and report.
#[derive(Args, Debug)]
pub struct SimArgs {
    /// Robot description file.
    #[arg(long, default_value = "robots/seed-4t.toml")]
    pub robot: PathBuf,
    /// Trained IK net (`tendril train` output).
    #[arg(long, default_value = "out/model.tnet")]
    pub model: PathBuf,
    /// Fit a quick random-feature IK net (written to OUT/quick.tnet) instead
    /// of loading --model: for tests and demos without a trained model.
    #[arg(long)]
    pub quick_model: bool,
    /// Output directory for report.json, report.md, sim.png and the logs.
    #[arg(long, default_value = "out/sim")]
    pub out: PathBuf,
    /// Seconds of trajectory after the settle hold.
    #[arg(long, default_value_t = 10.0)]
    pub duration: f64,
    /// iceoryx2 service-name prefix (default: unique per run).
    #[arg(long)]
    pub prefix: Option<String>,
    #[command(flatten)]
    pub traj: TrajectoryOpts,
    #[command(flatten)]
    pub tuning: LoopOpts,
    #[command(flatten)]
    pub plant: PlantOpts,
    /// Pin controller and plant to one CPU (the last this process may use)
    /// and the planner to another: with the plant's real-time priority
    /// above the controller's, the command's event wakes the plant at once
    /// (one-way latency p50 ≈ 7 µs here, against ≈ 25 µs unpinned).
    #[arg(long, value_enum, default_value_t = super::controller::OnOff::On)]
    pub pin: super::controller::OnOff,
    /// Fault: SIGKILL the planner at this time (s after the first setpoint).
    #[arg(long)]
    pub kill_planner_at: Option<f64>,
    /// Fault: start a new planner this long after the kill (s).
    #[arg(long)]
    pub restart_planner_after: Option<f64>,
    /// Fault: SIGKILL the plant at this time (s).
    #[arg(long)]
    pub kill_plant_at: Option<f64>,
    /// Fault: start a new plant this long after the kill (s).
    #[arg(long)]
    pub restart_plant_after: Option<f64>,
    /// Fault: publish a weight update with a flipped bit at these times (s).
    #[arg(long, value_delimiter = ',')]
    pub corrupt_weights_at: Vec<f64>,
    /// Publish the model again as a valid hot swap at these times (s).
    #[arg(long, value_delimiter = ',')]
    pub swap_weights_at: Vec<f64>,
    /// Planner fault: NaN setpoints at these times (s).
    #[arg(long, value_delimiter = ',')]
    pub inject_nan_at: Vec<f64>,
    /// Planner fault: out-of-workspace setpoints from these times (s), 50 ms each.
    #[arg(long, value_delimiter = ',')]
    pub inject_outside_at: Vec<f64>,
}

/// Run `tendril sim`.
pub fn run(args: SimArgs) -> anyhow::Result<()> {
    args.traj.shape()?; // fail early on a bad trajectory
    args.plant.params()?;
    if args.duration.is_nan() || args.duration <= 0.0 {
        anyhow::bail!("--duration must be positive");
    }
    let model = if args.quick_model {
        let robot = crate::robot::Robot::load(&args.robot)?;
        let statics =
            crate::statics::Statics::new(&robot, crate::statics::SolverSettings::default());
        let blob = crate::ipc::fixture::quick_net(&statics, 2000, 48, 6.0, 7)?;
        std::fs::create_dir_all(&args.out)
            .with_context(|| format!("creating {}", args.out.display()))?;
        let path = args.out.join("quick.tnet");
        crate::fsutil::write_atomic(&path, &blob)
            .with_context(|| format!("writing {}", path.display()))?;
        path
    } else {
        args.model.clone()
    };
    if !model.exists() {
        anyhow::bail!(
            "model {} not found: train one with `tendril train` or pass --model",
            args.model.display()
        );
    }
    let exe = std::env::current_exe().context("locating the tendril executable")?;
    // Real-time scheduling is on by default under `sim` (`--realtime off`
    // to disable): it keeps the 1 kHz loop on time on a busy machine.
    let mut tuning = args.tuning.clone();
    let realtime =
        tuning.realtime.unwrap_or(super::controller::OnOff::On) == super::controller::OnOff::On;
    tuning.realtime = Some(if realtime {
        super::controller::OnOff::On
    } else {
        super::controller::OnOff::Off
    });
    let mut planner_args = args.traj.to_args();
    let mut plant_args = args.plant.to_args();
    if realtime {
        planner_args.push("--realtime".into());
        plant_args.push("--realtime".into());
    }
    let mut controller_args = tuning.to_args();
    if args.pin == super::controller::OnOff::On {
        let cpus = crate::ipc::clock::allowed_cpus();
        if let (Some(&first), Some(&last)) = (cpus.first(), cpus.last()) {
            controller_args.push(format!("--cpu={last}"));
            plant_args.push(format!("--cpu={last}"));
            if first != last {
                planner_args.push(format!("--cpu={first}"));
            }
        }
    }
    let join = |v: &[f64]| {
        v.iter()
            .map(|x| x.to_string())
            .collect::<Vec<_>>()
            .join(",")
    };
    if !args.inject_nan_at.is_empty() {
        planner_args.push(format!("--inject-nan-at={}", join(&args.inject_nan_at)));
    }
    if !args.inject_outside_at.is_empty() {
        planner_args.push(format!(
            "--inject-outside-at={}",
            join(&args.inject_outside_at)
        ));
    }
    let label = format!(
        "trajectory {:?}, correction {:?} (ki {}/s), lead {} ms, motor τ {} ms, noise {} mm, \
         {} s, real-time {}, pinned {:?}",
        args.traj.trajectory,
        args.tuning.correction,
        args.tuning.ki,
        args.tuning.lead_ms,
        args.plant.motor_tau_ms,
        args.plant.noise_mm,
        args.duration,
        if realtime { "on" } else { "off" },
        args.pin
    );
    let cfg = SimConfig {
        exe,
        robot: args.robot,
        model,
        out: args.out.clone(),
        prefix: args.prefix.unwrap_or_else(unique_prefix),
        duration: args.duration,
        settle: args.traj.settle,
        rate: args.tuning.rate,
        planner_args,
        controller_args,
        plant_args,
        faults: SimFaults {
            kill_planner_at: args.kill_planner_at,
            restart_planner_after: args.restart_planner_after,
            kill_plant_at: args.kill_plant_at,
            restart_plant_after: args.restart_plant_after,
            corrupt_weights_at: args.corrupt_weights_at,
            swap_weights_at: args.swap_weights_at,
        },
        label,
    };
    let r = crate::ipc::sim::run(&cfg)?;
    println!(
        "tracking RMS {:.3} mm, max {:.3} mm; controller {} cycles, {} overruns, lateness p50 {:.1} µs p99 {:.1} µs; IPC p50 {:.1} µs p99 {:.1} µs; report in {}",
        r["rms_tracking_error_mm"].as_f64().unwrap_or(f64::NAN),
        r["max_tracking_error_mm"].as_f64().unwrap_or(f64::NAN),
        r["controller"]["cycles"],
        r["controller"]["overruns"],
        r["controller"]["lateness_us"]["p50"].as_f64().unwrap_or(f64::NAN),
        r["controller"]["lateness_us"]["p99"].as_f64().unwrap_or(f64::NAN),
        r["ipc_latency_us"]["p50"].as_f64().unwrap_or(f64::NAN),
        r["ipc_latency_us"]["p99"].as_f64().unwrap_or(f64::NAN),
        args.out.display()
    );
    Ok(())
}
