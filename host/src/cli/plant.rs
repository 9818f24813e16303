//! `tendril plant`: the simulated tendon motors and robot (DESIGN §6).

use std::path::PathBuf;

use anyhow::{bail, Context};
use clap::Args;

use crate::ipc::plant::{PlantConfig, PlantFaults, PlantParams};

/// Plant model and fault options (shared with `tendril sim`).
#[derive(Args, Clone, Debug)]
pub struct PlantOpts {
    /// Motor time constant, ms.
    #[arg(long, default_value_t = 20.0)]
    pub motor_tau_ms: f64,
    /// Series tendon compliance as a second lag, ms (0 = rigid).
    #[arg(long, default_value_t = 0.0)]
    pub compliance_tau_ms: f64,
    /// Tip position sensor noise (standard deviation), mm.
    #[arg(long, default_value_t = 0.02)]
    pub noise_mm: f64,
    /// Seed of the sensor noise and message drops.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// RK4 steps of the plant's statics.
    #[arg(long, default_value_t = 16)]
    pub statics_steps: usize,
    /// Busy-poll for commands instead of sleeping on the event.
    #[arg(long)]
    pub spin: bool,
    /// Fault: motor TENDON sticks at time S: "TENDON@S".
    #[arg(long)]
    pub stuck: Option<String>,
    /// Fault: drop a fraction P of commands between S0 and S1: "P@S0..S1".
    #[arg(long)]
    pub drop: Option<String>,
    /// Fault: delay commands by MS milliseconds between S0 and S1: "MS@S0..S1".
    #[arg(long)]
    pub delay: Option<String>,
}

fn window(spec: &str, what: &str) -> anyhow::Result<(f64, f64, f64)> {
    let err = || format!("{what} {spec:?}: expected VALUE@FROM..TO");
    let (v, w) = spec.split_once('@').with_context(err)?;
    let (a, b) = w.split_once("..").with_context(err)?;
    let v: f64 = v.trim().parse().with_context(err)?;
    let a: f64 = a.trim().parse().with_context(err)?;
    let b: f64 = b.trim().parse().with_context(err)?;
    if !(v.is_finite() && a.is_finite() && b.is_finite() && b >= a) {
        bail!("{}", err());
    }
    Ok((v, a, b))
}

impl PlantOpts {
    /// Model parameters in SI units.
    pub fn params(&self) -> anyhow::Result<PlantParams> {
        let stuck = match &self.stuck {
            None => None,
            Some(s) => {
                let err = || format!("--stuck {s:?}: expected TENDON@SECONDS");
                let (k, t) = s.split_once('@').with_context(err)?;
                Some((
                    k.trim().parse().with_context(err)?,
                    t.trim().parse().with_context(err)?,
                ))
            }
        };
        let drop = self
            .drop
            .as_deref()
            .map(|s| window(s, "--drop"))
            .transpose()?;
        if drop.is_some_and(|d| !(0.0..=1.0).contains(&d.0)) {
            bail!("--drop: the fraction must be in [0, 1]");
        }
        let delay = self
            .delay
            .as_deref()
            .map(|s| window(s, "--delay").map(|(ms, a, b)| (ms * 1e-3, a, b)))
            .transpose()?;
        Ok(PlantParams {
            motor_tau: self.motor_tau_ms * 1e-3,
            compliance_tau: self.compliance_tau_ms * 1e-3,
            noise: self.noise_mm * 1e-3,
            seed: self.seed,
            statics_steps: self.statics_steps,
            faults: PlantFaults { stuck, drop, delay },
            ..PlantParams::default()
        })
    }

    /// Same options as arguments (for spawning a plant).
    pub fn to_args(&self) -> Vec<String> {
        let mut a = vec![
            format!("--motor-tau-ms={}", self.motor_tau_ms),
            format!("--compliance-tau-ms={}", self.compliance_tau_ms),
            format!("--noise-mm={}", self.noise_mm),
            format!("--seed={}", self.seed),
            format!("--statics-steps={}", self.statics_steps),
        ];
        if self.spin {
            a.push("--spin".into());
        }
        for (flag, v) in [
            ("--stuck", &self.stuck),
            ("--drop", &self.drop),
            ("--delay", &self.delay),
        ] {
            if let Some(v) = v {
                a.push(format!("{flag}={v}"));
            }
        }
        a
    }
}

/// Simulate the tendon motors and the robot, driven by tension commands.
#[derive(Args, Debug)]
pub struct PlantArgs {
    /// Robot description file.
    #[arg(long, default_value = "robots/seed-4t.toml")]
    pub robot: PathBuf,
    /// iceoryx2 service-name prefix.
    #[arg(long, default_value = crate::ipc::DEFAULT_PREFIX)]
    pub prefix: String,
    #[command(flatten)]
    pub model: PlantOpts,
    /// Stop after this many seconds (default: until SIGTERM or a stop message).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Per-step CSV log.
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// Statistics JSON written at exit.
    #[arg(long)]
    pub stats: Option<PathBuf>,
    /// Run under SCHED_FIFO once the model is set up.
    #[arg(long)]
    pub realtime: bool,
    /// Pin to this CPU.
    #[arg(long)]
    pub cpu: Option<usize>,
}

/// Run `tendril plant`.
pub fn run(args: PlantArgs) -> anyhow::Result<()> {
    let cfg = PlantConfig {
        robot: args.robot,
        prefix: args.prefix,
        params: args.model.params()?,
        spin: args.model.spin,
        idle_period: 0.001,
        command_timeout: 0.05,
        duration: args.duration,
        log: args.log,
        stats: args.stats,
        realtime: args.realtime,
        cpu: args.cpu,
    };
    let stats = crate::ipc::plant::run(&cfg)?;
    log::info!(
        "plant: {} steps, step median {:.1} µs, command latency p50 {:.1} µs",
        stats.steps,
        stats.step_us.p50,
        stats.latency_us.p50
    );
    Ok(())
}
