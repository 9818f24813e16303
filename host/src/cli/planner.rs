//! `tendril planner`: stream setpoints along a trajectory (`docs/design.md` §6).

use std::path::PathBuf;

use anyhow::{bail, Context};
use clap::{Args, ValueEnum};

use super::controller::{check, peer_timeout};
use crate::ipc::planner::{Injections, PlannerConfig};
use crate::plan::{read_pose_csv, PathShape};

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
    /// Circle whose height moves between `--heights-mm` over `--turns`
    /// revolutions and back (a robot that reaches a volume).
    Helix,
    /// Sinusoid along the axis between the two coordinates of `--sweep-mm`
    /// at `--freq` (a robot whose tip moves on a curve).
    Sweep,
    /// Full poses from `--poses FILE` (t,px,py,pz,qw,qx,qy,qz).
    Csv,
}

/// What the planner follows (shared with `tendril sim`). Points are the
/// tip's coordinates on the robot's family (`docs/design.md` §6): x,y for
/// a one-segment robot, x,y,z (or x,y and `--height-mm`) for one that
/// reaches a volume, the coordinate along the axis for a one-tendon robot.
#[derive(Args, Clone, Debug)]
pub struct TrajectoryOpts {
    /// Trajectory kind.
    #[arg(long, value_enum, default_value_t = Kind::Circle)]
    pub trajectory: Kind,
    /// Centre of the path (lateral x,y) or the held point, mm.
    #[arg(long, default_value = "0,0", allow_hyphen_values = true)]
    pub center_mm: String,
    /// Circle radius / figure-eight half-width, mm (a "30 mm circle" is radius 15).
    #[arg(long, default_value_t = 15.0)]
    pub radius_mm: f64,
    /// Height of a circle, figure eight, hold or lateral steps on a robot
    /// that reaches a volume, mm (default: its mid height).
    #[arg(long, allow_hyphen_values = true)]
    pub height_mm: Option<f64>,
    /// Revolutions (sweeps) per second.
    #[arg(long, default_value_t = 0.2)]
    pub freq: f64,
    /// Step targets, "x,y;x,y;…" (or x,y,z / one coordinate each) in mm.
    #[arg(
        long,
        default_value = "10,0;0,10;-10,0;0,-10",
        allow_hyphen_values = true
    )]
    pub targets_mm: String,
    /// Seconds per step target.
    #[arg(long, default_value_t = 2.0)]
    pub dwell: f64,
    /// Helix start and top heights "from,to", mm.
    #[arg(long, allow_hyphen_values = true)]
    pub heights_mm: Option<String>,
    /// Helix revolutions from one height to the other (a multiple of ½).
    #[arg(long, default_value_t = 1.0)]
    pub turns: f64,
    /// Sweep coordinates "from,to" along the robot's axis, mm.
    #[arg(long, allow_hyphen_values = true)]
    pub sweep_mm: Option<String>,
    /// Pose table for `--trajectory csv`.
    #[arg(long)]
    pub poses: Option<PathBuf>,
    /// Setpoint rate, Hz [default: 1000 (the planner's default); under
    /// `sim`, the controller's rate].
    #[arg(long)]
    pub planner_rate: Option<f64>,
    /// Initial hold at the first pose, s.
    #[arg(long, default_value_t = crate::ipc::planner::defaults::SETTLE_S)]
    pub settle: f64,
    /// Move between step targets by a minimum-jerk move through a ZVD input
    /// shaper on the robot file's first bending mode (`tendril modes`), so
    /// the rod does not ring; off: steps jump.
    #[arg(long, value_enum, default_value_t = super::controller::OnOff::On)]
    pub shape_steps: super::controller::OnOff,
    /// Send the offset the rod's first mode needs on top of each pose (the
    /// modal inverse: what the planner's acceleration asks of a rod with
    /// mass), with --shape-steps on.
    #[arg(long, value_enum, default_value_t = super::controller::OnOff::On)]
    pub dynamic_offset: super::controller::OnOff,
    /// Learn, pass after pass of a repeated path (circle, figure-eight,
    /// helix, sweep), the offset that puts the tip on it from the tracker's
    /// frames (iterative learning control on the path's harmonics below
    /// the rod's mode, checked to converge before it starts), with
    /// --shape-steps on.
    #[arg(long, value_enum, default_value_t = super::controller::OnOff::Off)]
    pub learn: super::controller::OnOff,
    /// Estimate from the tracker's frames how much stiffer or softer the
    /// backbone is than the robot file says, and offset every pose by what
    /// that moves the tip (one number for the whole path and every step
    /// target; docs/design.md §6.5).
    #[arg(long, value_enum, default_value_t = super::controller::OnOff::On)]
    pub adapt_stiffness: super::controller::OnOff,
}

impl TrajectoryOpts {
    /// The planner's learning these options ask for.
    pub fn learning(&self) -> crate::plan::LearningChoice {
        match self.learn {
            super::controller::OnOff::On => crate::plan::LearningChoice::Auto,
            super::controller::OnOff::Off => crate::plan::LearningChoice::Off,
        }
    }

    /// The planner's step shaping these options ask for.
    pub fn step_shaping(&self) -> crate::plan::ShapingChoice {
        match self.shape_steps {
            super::controller::OnOff::On => crate::plan::ShapingChoice::Auto,
            super::controller::OnOff::Off => crate::plan::ShapingChoice::Off,
        }
    }
}

/// Comma-separated finite numbers in mm, as metres.
fn metres(s: &str, what: &str) -> anyhow::Result<Vec<f64>> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("{what} {s:?}: expected comma-separated numbers"))?;
    if v.iter().any(|x| !x.is_finite()) {
        bail!("{what} {s:?}: expected finite numbers");
    }
    Ok(v.into_iter().map(|x| x * 1e-3).collect())
}

fn pair(s: &str, what: &str) -> anyhow::Result<[f64; 2]> {
    match metres(s, what)?[..] {
        [a, b] => Ok([a, b]),
        _ => bail!("{what} {s:?}: expected two numbers"),
    }
}

impl TrajectoryOpts {
    /// Refuse rates, times and sizes no trajectory can have, naming the flag.
    pub fn check(&self) -> anyhow::Result<()> {
        let r = self
            .planner_rate
            .unwrap_or(crate::ipc::planner::defaults::RATE_HZ);
        check(
            "--planner-rate",
            r,
            r > 0.0 && r <= super::controller::MAX_RATE_HZ,
            "in (0, 20000] Hz",
        )?;
        check(
            "--settle",
            self.settle,
            self.settle >= 0.0,
            "a number of seconds ≥ 0",
        )?;
        check(
            "--radius-mm",
            self.radius_mm,
            self.radius_mm >= 0.0,
            "≥ 0 mm",
        )?;
        check("--freq", self.freq, self.freq > 0.0, "a frequency > 0 Hz")?;
        check(
            "--dwell",
            self.dwell,
            self.dwell > 0.0,
            "a number of seconds > 0",
        )?;
        check(
            "--turns",
            self.turns,
            self.turns > 0.0,
            "a number of revolutions > 0",
        )?;
        if let Some(h) = self.height_mm {
            check("--height-mm", h, true, "a finite height in mm")?;
        }
        Ok(())
    }

    /// The trajectory shape in SI units.
    pub fn shape(&self) -> anyhow::Result<PathShape> {
        self.check()?;
        let radius = self.radius_mm * 1e-3;
        let height = self.height_mm.map(|h| h * 1e-3);
        let lateral = || pair(&self.center_mm, "--center-mm");
        Ok(match self.trajectory {
            Kind::Hold => PathShape::Hold {
                center_m: metres(&self.center_mm, "--center-mm")?,
                height_m: height,
            },
            Kind::Steps => PathShape::Steps {
                targets_m: self
                    .targets_mm
                    .split(';')
                    .map(|p| metres(p, "--targets-mm"))
                    .collect::<anyhow::Result<_>>()?,
                dwell_s: self.dwell,
                height_m: height,
            },
            Kind::Circle => PathShape::Circle {
                center_m: lateral()?,
                radius_m: radius,
                freq_hz: self.freq,
                height_m: height,
            },
            Kind::Figure8 => PathShape::FigureEight {
                center_m: lateral()?,
                radius_m: radius,
                freq_hz: self.freq,
                height_m: height,
            },
            Kind::Helix => {
                let Some(h) = &self.heights_mm else {
                    bail!("--trajectory helix needs --heights-mm FROM,TO");
                };
                PathShape::Helix {
                    center_m: lateral()?,
                    radius_m: radius,
                    freq_hz: self.freq,
                    heights_m: pair(h, "--heights-mm")?,
                    turns: self.turns,
                }
            }
            Kind::Sweep => {
                let Some(range) = &self.sweep_mm else {
                    bail!("--trajectory sweep needs --sweep-mm FROM,TO");
                };
                let [from_m, to_m] = pair(range, "--sweep-mm")?;
                PathShape::Sweep {
                    from_m,
                    to_m,
                    freq_hz: self.freq,
                }
            }
            Kind::Csv => {
                let Some(path) = &self.poses else {
                    bail!("--trajectory csv needs --poses FILE");
                };
                PathShape::Table {
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
    #[arg(long, default_value = crate::robot::DEFAULT_ROBOT)]
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
    #[arg(long, default_value_t = crate::ipc::planner::defaults::OUTSIDE_FOR_S)]
    pub outside_for: f64,
    /// Stop (non-zero exit) after this many seconds without a tension
    /// command from a controller; 0 = never [default: 2 s, after up to 10 s
    /// for a controller to start; given explicitly, it holds from the start].
    #[arg(long)]
    pub peer_timeout: Option<f64>,
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
    /// The robot is at rest when the planner starts: approach the first
    /// pose by a shaped move during the settle hold (with --shape-steps on).
    #[arg(long)]
    pub from_rest: bool,
    /// How long the loop below takes to put a setpoint on the tip, ms (the
    /// stiffness adaptation matches frames against it; docs/design.md
    /// §6.5): 0 for the host controller (the default), 1.4 for the chip
    /// over its link.
    #[arg(long)]
    pub loop_delay_ms: Option<f64>,
}

impl PlannerArgs {
    /// The configuration: the `--config` file, or the flags.
    pub fn config(self) -> anyhow::Result<PlannerConfig> {
        if let Some(path) = &self.config {
            return Ok(crate::ipc::read_config(path)?);
        }
        if let Some(d) = self.duration {
            check("--duration", d, d > 0.0, "a number of seconds > 0")?;
        }
        let of = self.outside_for;
        check("--outside-for", of, of > 0.0, "a number of seconds > 0")?;
        let (peer_timeout_s, peer_start_grace_s) = peer_timeout(self.peer_timeout)?;
        if let Some(d) = self.loop_delay_ms {
            check(
                "--loop-delay-ms",
                d,
                (0.0..=1000.0).contains(&d),
                "a number of ms in 0–1000",
            )?;
        }
        Ok(PlannerConfig {
            prefix: self.prefix,
            step_shaping: self.traj.step_shaping(),
            start_from_rest: self.from_rest,
            dynamic_offset: self.traj.dynamic_offset == super::controller::OnOff::On,
            learning: self.traj.learning(),
            adapt_stiffness: self.traj.adapt_stiffness == super::controller::OnOff::On,
            loop_delay_s: self.loop_delay_ms.map(|ms| ms * 1e-3),
            rate_hz: self
                .traj
                .planner_rate
                .unwrap_or(crate::ipc::planner::defaults::RATE_HZ),
            settle_s: self.traj.settle,
            duration_s: self.duration,
            inject: Injections {
                nan_at_s: self.inject_nan_at,
                outside_at_s: self.inject_outside_at,
                outside_for_s: self.outside_for,
            },
            peer_timeout_s,
            peer_start_grace_s,
            supervised: self.supervised,
            log: self.log,
            realtime: self.realtime,
            cpu: self.cpu,
            ..PlannerConfig::new(self.robot, self.traj.shape()?)
        })
    }
}

/// Run `tendril planner`.
pub fn run(args: PlannerArgs) -> anyhow::Result<()> {
    let sent = crate::ipc::planner::run(&args.config()?)?;
    log::info!("planner: sent {sent} setpoints");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: PlannerArgs,
    }

    /// Every default the command line shows is the configuration's own: a
    /// `tendril planner` without flags follows `PlannerConfig::new`'s path
    /// on the default robot, with the command line's own choices said in
    /// its help (the dynamic offset and the stiffness adaptation on, the
    /// peers' timeout).
    #[test]
    fn a_planner_without_flags_is_the_configurations_defaults() {
        let given = Cli::parse_from(["planner"]).args.config().unwrap();
        let mut expected =
            PlannerConfig::new(crate::robot::DEFAULT_ROBOT.into(), given.shape.clone());
        expected.dynamic_offset = true;
        expected.adapt_stiffness = true;
        expected.peer_timeout_s = given.peer_timeout_s;
        expected.peer_start_grace_s = given.peer_start_grace_s;
        assert_eq!(given, expected);
        assert_eq!(given.shape, PathShape::default_circle());
    }
}
