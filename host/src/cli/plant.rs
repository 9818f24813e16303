//! `tendril plant`: the simulated tendon motors and robot (`docs/design.md` §6).

use std::path::PathBuf;

use anyhow::{bail, Context};
use clap::Args;

use super::controller::{check, peer_timeout};
use crate::ipc::plant::{
    DelayFault, DropFault, PlantConfig, PlantFaults, PlantParams, RobotModel, StuckFault,
};

/// Plant model and fault options (shared with `tendril sim`).
#[derive(Args, Clone, Debug)]
pub struct PlantOpts {
    /// Motor time constant, ms [default: 20; a --reality with [motors] sets
    /// its own, and giving both is refused].
    #[arg(long)]
    pub motor_tau_ms: Option<f64>,
    /// Series tendon compliance as a second lag, ms (0 = rigid).
    #[arg(long, default_value_t = PlantParams::default().compliance_tau_s * 1e3)]
    pub compliance_tau_ms: f64,
    /// Tip position sensor noise (standard deviation), mm [default: 0.02; a
    /// --reality with a [tracker] sets its own, and giving both is refused].
    #[arg(long)]
    pub noise_mm: Option<f64>,
    /// Seed of the sensor noise and message drops.
    #[arg(long, default_value_t = PlantParams::default().seed)]
    pub seed: u64,
    /// RK4 steps of the plant's statics.
    #[arg(long, default_value_t = PlantParams::default().statics_steps)]
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
    /// How the real robot differs from its robot file and how it is seen:
    /// a reality file, or a built-in's name (ideal, em-tracker,
    /// optical-tracker, stiffer-10pct, softer-10pct, geometry, friction,
    /// dynamic-light-damping, everything; docs/design.md §6.2). Only the
    /// plant knows it. Its [motors], [tracker] and [dynamics] take the
    /// place of --motor-tau-ms, --noise-mm and the plant model.
    #[arg(long)]
    pub reality: Option<PathBuf>,
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
    /// The motor time constant asked for, ms (the plant's default when
    /// not given: [`PlantParams`]'s `Default` is its one home).
    pub fn motor_tau_ms(&self) -> f64 {
        self.motor_tau_ms
            .unwrap_or(PlantParams::default().motor_tau_s * 1e3)
    }

    /// The tip sensor's noise asked for, mm (default as above).
    pub fn noise_mm(&self) -> f64 {
        self.noise_mm
            .unwrap_or(PlantParams::default().noise_m * 1e3)
    }

    /// Model parameters in SI units (each refused with its flag's name when
    /// out of range).
    pub fn params(&self) -> anyhow::Result<PlantParams> {
        let (tau, comp, noise) = (self.motor_tau_ms(), self.compliance_tau_ms, self.noise_mm());
        check("--motor-tau-ms", tau, tau > 0.0, "a time constant > 0 ms")?;
        check(
            "--compliance-tau-ms",
            comp,
            comp >= 0.0,
            "≥ 0 ms (0 = rigid)",
        )?;
        check(
            "--noise-mm",
            noise,
            noise >= 0.0,
            "a standard deviation ≥ 0 mm",
        )?;
        if self.statics_steps == 0 {
            bail!("--statics-steps 0: must be at least 1");
        }
        let stuck = match &self.stuck {
            None => None,
            Some(s) => {
                let err = || format!("--stuck {s:?}: expected TENDON@SECONDS");
                let (k, t) = s.split_once('@').with_context(err)?;
                let at_s: f64 = t.trim().parse().with_context(err)?;
                check("--stuck time", at_s, at_s >= 0.0, "a number of seconds ≥ 0")?;
                Some(StuckFault {
                    tendon: k.trim().parse().with_context(err)?,
                    at_s,
                })
            }
        };
        let drop = self
            .drop
            .as_deref()
            .map(|s| {
                window(s, "--drop").map(|(fraction, from_s, to_s)| DropFault {
                    fraction,
                    from_s,
                    to_s,
                })
            })
            .transpose()?;
        if drop.is_some_and(|d| !(0.0..=1.0).contains(&d.fraction)) {
            bail!("--drop: the fraction must be in [0, 1]");
        }
        let delay = self
            .delay
            .as_deref()
            .map(|s| {
                window(s, "--delay").map(|(ms, from_s, to_s)| DelayFault {
                    delay_s: ms * 1e-3,
                    from_s,
                    to_s,
                })
            })
            .transpose()?;
        if let Some(d) = delay {
            check(
                "--delay",
                d.delay_s * 1e3,
                d.delay_s >= 0.0,
                "a delay ≥ 0 ms",
            )?;
        }
        let reality = self
            .reality
            .as_deref()
            .map(crate::plant::reality::Reality::load)
            .transpose()?;
        if let Some(r) = &reality {
            // Either the flag or the reality's section: silently dropping
            // one of them would run another plant than the user asked for.
            for (flag, given, section, has) in [
                (
                    "--motor-tau-ms",
                    self.motor_tau_ms,
                    "[motors]",
                    r.motors.is_some(),
                ),
                (
                    "--noise-mm",
                    self.noise_mm,
                    "[tracker]",
                    r.tracker.is_some(),
                ),
            ] {
                if let (Some(x), true) = (given, has) {
                    bail!(
                        "{flag} {} and reality {}'s {section} both set it: give one (edit the \
                         reality file to change it)",
                        crate::units::given(x),
                        r.name
                    );
                }
            }
        }
        Ok(PlantParams {
            motor_tau_s: tau * 1e-3,
            compliance_tau_s: self.compliance_tau_ms * 1e-3,
            noise_m: noise * 1e-3,
            seed: self.seed,
            statics_steps: self.statics_steps,
            faults: PlantFaults { stuck, drop, delay },
            reality,
            ..PlantParams::default()
        })
    }
}

/// Simulate the tendon motors and the robot, driven by tension commands.
#[derive(Args, Debug)]
pub struct PlantArgs {
    /// The whole configuration as JSON (a `PlantConfig`, as a launcher
    /// writes it); the other options are then ignored.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Robot description file.
    #[arg(long, default_value = crate::robot::DEFAULT_ROBOT)]
    pub robot: PathBuf,
    /// iceoryx2 service-name prefix.
    #[arg(long, default_value = crate::ipc::DEFAULT_PREFIX)]
    pub prefix: String,
    #[command(flatten)]
    pub model: PlantOpts,
    /// Robot model: quasi-static (statics each step) or dynamic (inertia and
    /// damping, docs/design.md §4.2).
    #[arg(long = "model", value_enum, default_value_t = PlantParams::default().model)]
    pub robot_model: RobotModel,
    /// Stop after this many seconds (default: until SIGTERM or a stop message).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Stop (non-zero exit) after this many seconds without a tension
    /// command; 0 = never [default: 2 s, after up to 10 s for a controller
    /// to start; given explicitly, it holds from the start].
    #[arg(long)]
    pub peer_timeout: Option<f64>,
    /// Die with the parent process (as `tendril sim` starts it; also when
    /// the TENDRIL_SUPERVISED environment variable is set).
    #[arg(long)]
    pub supervised: bool,
    /// Per-step CSV log.
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// Statistics JSON written at exit.
    #[arg(long)]
    pub stats: Option<PathBuf>,
    /// The run's MCAP file (Foxglove's 3-D scene, tensions, errors, status;
    /// docs/design.md §12).
    #[arg(long)]
    pub mcap: Option<PathBuf>,
    #[command(flatten)]
    pub runlog: RunLogOpts,
    /// Run under SCHED_FIFO once the model is set up.
    #[arg(long)]
    pub realtime: bool,
    /// Pin to this CPU.
    #[arg(long)]
    pub cpu: Option<usize>,
}

impl PlantArgs {
    /// The configuration: the `--config` file, or the flags.
    pub fn config(self) -> anyhow::Result<PlantConfig> {
        if let Some(path) = &self.config {
            return Ok(crate::ipc::read_config(path)?);
        }
        if let Some(d) = self.duration {
            check("--duration", d, d > 0.0, "a number of seconds > 0")?;
        }
        let (peer_timeout_s, peer_start_grace_s) = peer_timeout(self.peer_timeout)?;
        Ok(PlantConfig {
            robot: self.robot,
            prefix: self.prefix,
            params: PlantParams {
                model: self.robot_model,
                ..self.model.params()?
            },
            spin: self.model.spin,
            duration_s: self.duration,
            peer_timeout_s,
            peer_start_grace_s,
            supervised: self.supervised,
            log: self.log,
            runlog: self.runlog.config(self.mcap)?,
            stats: self.stats,
            realtime: self.realtime,
            cpu: self.cpu,
            ..PlantConfig::default()
        })
    }
}

/// Run-log options shared by `tendril plant` and `tendril sim`.
#[derive(Args, Clone, Debug)]
pub struct RunLogOpts {
    /// Serve the run live to Foxglove (WebSocket) at this address; without
    /// a value 127.0.0.1:8765. Open it in Foxglove with "Open connection".
    #[arg(long, num_args = 0..=1, default_missing_value = DEFAULT_LIVE, value_name = "HOST:PORT")]
    pub live: Option<String>,
    /// 3-D scenes per second in the run log.
    #[arg(long, default_value_t = crate::runlog::RunLogConfig::default().scene_hz)]
    pub scene_hz: f64,
    /// Points along the backbone (and each tendon) in a scene.
    #[arg(long, default_value_t = crate::runlog::RunLogConfig::default().backbone_points)]
    pub backbone_points: usize,
}

/// Where `--live` serves without an address.
pub const DEFAULT_LIVE: &str = "127.0.0.1:8765";

impl RunLogOpts {
    /// The run-log configuration, writing `mcap` if given.
    pub fn config(&self, mcap: Option<PathBuf>) -> anyhow::Result<crate::runlog::RunLogConfig> {
        let cfg = crate::runlog::RunLogConfig {
            mcap,
            live: self.live.clone(),
            scene_hz: self.scene_hz,
            backbone_points: self.backbone_points,
            ..crate::runlog::RunLogConfig::default()
        };
        cfg.validate().map_err(|e| anyhow::anyhow!("{e}"))?;
        Ok(cfg)
    }
}

/// Run `tendril plant`.
pub fn run(args: PlantArgs) -> anyhow::Result<()> {
    let stats = crate::ipc::plant::run(&args.config()?)?;
    log::info!(
        "plant: {} steps, step median {:.1} µs, command latency p50 {:.1} µs",
        stats.steps,
        stats.step_us.p50,
        stats.latency_us.p50
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: PlantArgs,
    }

    /// Every default the command line shows is the configuration's own: a
    /// `tendril plant` without flags runs `PlantConfig::default()`'s plant.
    #[test]
    fn a_plant_without_flags_is_the_configurations_defaults() {
        let given = Cli::parse_from(["plant"]).args.config().unwrap();
        // The command line's own choice, said in its help: the peers'
        // timeout and its start grace.
        let expected = PlantConfig {
            peer_timeout_s: given.peer_timeout_s,
            peer_start_grace_s: given.peer_start_grace_s,
            ..PlantConfig::default()
        };
        assert_eq!(given, expected);
    }
}
