//! `tendril planner`: stream setpoints along a trajectory (`docs/design.md` §6).

use std::path::PathBuf;

use anyhow::{bail, Context};
use clap::{Args, ValueEnum};

use crate::ipc::planner::{Injections, PlannerConfig};
use crate::ipc::trajectory::{read_pose_csv, Shape};

/// Trajectory kinds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Kind {
    /// Hold the centre.
    Hold,
    /// Step through `--targets-mm`, `--dwell` seconds each.
    Steps,
    /// Circle of `--radius-mm` about `--center-mm` at `--freq`.
    Circle,
    /// Figure eight of half-width `--radius-mm` at `--freq`.
    Figure8,
    /// Full poses from `--poses FILE` (t,px,py,pz,qw,qx,qy,qz).
    Csv,
}

/// What the planner follows (shared with `tendril sim`).
#[derive(Args, Clone, Debug)]
pub struct TrajectoryOpts {
    /// Trajectory kind.
    #[arg(long, value_enum, default_value_t = Kind::Circle)]
    pub trajectory: Kind,
    /// Centre of the path, lateral tip position x,y in mm.
    #[arg(long, default_value = "0,0", allow_hyphen_values = true)]
    pub center_mm: String,
    /// Circle radius / figure-eight half-width, mm (a "30 mm circle" is radius 15).
    #[arg(long, default_value_t = 15.0)]
    pub radius_mm: f64,
    /// Revolutions per second.
    #[arg(long, default_value_t = 0.2)]
    pub freq: f64,
    /// Step targets, "x,y;x,y;…" in mm.
    #[arg(
        long,
        default_value = "10,0;0,10;-10,0;0,-10",
        allow_hyphen_values = true
    )]
    pub targets_mm: String,
    /// Seconds per step target.
    #[arg(long, default_value_t = 2.0)]
    pub dwell: f64,
    /// Pose table for `--trajectory csv`.
    #[arg(long)]
    pub poses: Option<PathBuf>,
    /// Setpoint rate, Hz.
    #[arg(long, default_value_t = 1000.0)]
    pub planner_rate: f64,
    /// Initial hold at the first pose, s.
    #[arg(long, default_value_t = 2.0)]
    pub settle: f64,
}

fn pair(s: &str, what: &str) -> anyhow::Result<[f64; 2]> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("{what} {s:?}: expected two numbers x,y"))?;
    if v.len() != 2 || v.iter().any(|x| !x.is_finite()) {
        bail!("{what} {s:?}: expected two finite numbers x,y");
    }
    Ok([v[0], v[1]])
}

impl TrajectoryOpts {
    /// The trajectory shape in SI units.
    pub fn shape(&self) -> anyhow::Result<Shape> {
        let c = pair(&self.center_mm, "--center-mm")?;
        let center = [c[0] * 1e-3, c[1] * 1e-3];
        let radius = self.radius_mm * 1e-3;
        Ok(match self.trajectory {
            Kind::Hold => Shape::Hold { center_m: center },
            Kind::Steps => Shape::Steps {
                targets_m: self
                    .targets_mm
                    .split(';')
                    .map(|p| pair(p, "--targets-mm").map(|v| [v[0] * 1e-3, v[1] * 1e-3]))
                    .collect::<anyhow::Result<_>>()?,
                dwell_s: self.dwell,
            },
            Kind::Circle => Shape::Circle {
                center_m: center,
                radius_m: radius,
                freq_hz: self.freq,
            },
            Kind::Figure8 => Shape::FigureEight {
                center_m: center,
                radius_m: radius,
                freq_hz: self.freq,
            },
            Kind::Csv => {
                let Some(path) = &self.poses else {
                    bail!("--trajectory csv needs --poses FILE");
                };
                Shape::Table {
                    rows: read_pose_csv(path)?,
                }
            }
        })
    }
}

/// Stream setpoints along a trajectory inside the robot's workspace.
#[derive(Args, Debug)]
pub struct PlannerArgs {
    /// The whole configuration as JSON (a `PlannerConfig`, as a launcher
    /// writes it); the other options are then ignored.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Robot description file.
    #[arg(long, default_value = "robots/seed-4t.toml")]
    pub robot: PathBuf,
    /// iceoryx2 service-name prefix.
    #[arg(long, default_value = crate::ipc::DEFAULT_PREFIX)]
    pub prefix: String,
    #[command(flatten)]
    pub traj: TrajectoryOpts,
    /// Stop after this many seconds (default: until SIGTERM or a stop message).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Send a NaN setpoint at these times (s), comma-separated.
    #[arg(long, value_delimiter = ',')]
    pub inject_nan_at: Vec<f64>,
    /// Send out-of-workspace setpoints from these times (s), comma-separated.
    #[arg(long, value_delimiter = ',')]
    pub inject_outside_at: Vec<f64>,
    /// Length of each out-of-workspace burst, s.
    #[arg(long, default_value_t = 0.05)]
    pub outside_for: f64,
    /// Stop (non-zero exit) after this many seconds without a tension
    /// command from a controller; 0 = never.
    #[arg(long, default_value_t = 2.0)]
    pub peer_timeout: f64,
    /// Die with the parent process (as `tendril sim` starts it; also when
    /// the TENDRIL_SUPERVISED environment variable is set).
    #[arg(long)]
    pub supervised: bool,
    /// Per-setpoint CSV log.
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// Run under SCHED_FIFO once the trajectory is prepared.
    #[arg(long)]
    pub realtime: bool,
    /// Pin to this CPU.
    #[arg(long)]
    pub cpu: Option<usize>,
}

impl PlannerArgs {
    /// The configuration: the `--config` file, or the flags.
    pub fn config(self) -> anyhow::Result<PlannerConfig> {
        if let Some(path) = &self.config {
            return Ok(crate::ipc::read_config(path)?);
        }
        Ok(PlannerConfig {
            robot: self.robot,
            prefix: self.prefix,
            shape: self.traj.shape()?,
            rate_hz: self.traj.planner_rate,
            settle_s: self.traj.settle,
            duration_s: self.duration,
            inject: Injections {
                nan_at_s: self.inject_nan_at,
                outside_at_s: self.inject_outside_at,
                outside_for_s: self.outside_for,
            },
            peer_timeout_s: (self.peer_timeout > 0.0).then_some(self.peer_timeout),
            supervised: self.supervised,
            log: self.log,
            realtime: self.realtime,
            cpu: self.cpu,
        })
    }
}

/// Run `tendril planner`.
pub fn run(args: PlannerArgs) -> anyhow::Result<()> {
    let sent = crate::ipc::planner::run(&args.config()?)?;
    log::info!("planner: sent {sent} setpoints");
    Ok(())
}
