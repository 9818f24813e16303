//! `tendril controller`: the firmware control step in a 1 kHz
//! absolute-deadline loop (`docs/design.md` §5, §6).

use std::path::PathBuf;

use anyhow::bail;
use clap::{Args, ValueEnum};

use crate::ipc::controller::{correction, ControllerConfig};

/// On/off switch.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum OnOff {
    /// Enabled.
    On,
    /// Disabled.
    Off,
}

use crate::ipc::controller::defaults;

/// The control rate without `--rate`, Hz.
pub const DEFAULT_RATE_HZ: f64 = defaults::RATE_HZ;

/// Who runs the control period (`tendril sim`, `tendril-ros2 drive`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ControllerKind {
    /// The host runs the period (its own process in `tendril sim`, the
    /// drive's process in `tendril-ros2 drive`).
    Host,
    /// The chip (QEMU netduinoplus2), bridged over its serial link.
    Mcu,
}

/// Loop and tuning options (shared with `tendril sim`).
#[derive(Args, Clone, Debug)]
pub struct LoopOpts {
    /// Control rate, Hz [default: 1000; 100 with the chip in the loop, whose
    /// emulated serial link carries ~10 kB/s in a loaded loop: docs/design.md §5.6].
    #[arg(long)]
    pub rate: Option<f64>,
    /// Spin this long before each deadline instead of sleeping, µs (0 = pure sleep).
    #[arg(long, default_value_t = defaults::SPIN_US)]
    pub spin_us: f64,
    /// Run under SCHED_FIFO (needs privileges; falls back with a warning).
    /// Default: off for `controller`, on for `sim` (all three processes).
    #[arg(long, value_enum)]
    pub realtime: Option<OnOff>,
    /// Setpoint silence, in periods, that trips the safe hold.
    #[arg(long, default_value_t = defaults::WATCHDOG_PERIODS)]
    pub watchdog_periods: f64,
    /// Integral correction of the measured tip error: the firmware control
    /// step's own integral loop (along the planner's statics tangent when the
    /// setpoint carries one, so the net sees poses like its training data;
    /// position only otherwise). `off` = IK alone.
    #[arg(long, value_enum, default_value_t = OnOff::On)]
    pub correction: OnOff,
    /// Integral gain of the correction, 1/s (docs/design.md §6.3: stable
    /// with the dynamic rod's first mode, the motors and a 40 Hz tracker).
    /// Given for the default robot: scaled down for a robot with a lower
    /// first mode unless `--scale-gains-to-mode off` (the report gives the
    /// gain applied).
    #[arg(long, default_value_t = correction::KI_PER_S)]
    pub ki: f64,
    /// Scale the correction's bandwidth (`--ki`, `--correction-map-gain`,
    /// the corner of `--correction-filter-ms`) by the robot's first
    /// bending mode over the default robot's 3.6 Hz, when lower, so the loop
    /// keeps its margins on a softer robot (docs/design.md §6.3). `off`:
    /// the gains apply as given.
    #[arg(long, value_enum, default_value_t = OnOff::On)]
    pub scale_gains_to_mode: OnOff,
    /// Bound on the correction per axis, mm (above the model errors of a
    /// real robot: ±10 % stiffness moves the default robot's tip ≈ 3 mm;
    /// the shift along the reachable poses is first order, accurate to
    /// ~2 µm at 1 mm, and the loop removes the rest).
    #[arg(long, default_value_t = correction::LIMIT_M * 1e3)]
    pub correction_limit_mm: f64,
    /// Integrate only while the lateral tip error is at most this, mm
    /// (integral separation: larger errors are transients, not IK error).
    #[arg(long, default_value_t = correction::WINDOW_M * 1e3)]
    pub correction_window_mm: f64,
    /// Time constant of the low-pass filter on the tip error before it is
    /// integrated, ms (0 = none); lengthened with `--scale-gains-to-mode`.
    #[arg(long, default_value_t = correction::FILTER_TAU_S * 1e3)]
    pub correction_filter_ms: f64,
    /// Adaptation gain of the correction's error map, 1/s (0 = a constant
    /// correction only); scaled with `--scale-gains-to-mode`.
    #[arg(long, default_value_t = correction::MAP_GAIN_PER_S)]
    pub correction_map_gain: f64,
    /// No tracker frame for this long freezes the correction, ms.
    #[arg(long, default_value_t = correction::TRACKER_TIMEOUT_S * 1e3)]
    pub tracker_timeout_ms: f64,
    /// Motor-lag lead: setpoints are advanced by velocity × lead, ms
    /// (≈ motor time constant + half a period; 0 = off).
    #[arg(long, default_value_t = defaults::LEAD_S * 1e3)]
    pub lead_ms: f64,
    /// Tension slew-rate limit, N/s.
    #[arg(long, default_value_t = defaults::SLEW_N_PER_S)]
    pub slew: f64,
}

/// Refuse a numeric option that is not finite or fails `ok`, naming the
/// flag and what it must be. Every numeric option of `sim`, `controller`,
/// `plant` and `planner` passes here before anything starts (issue 31: a
/// NaN used to reach a child's JSON configuration as `null` and fail there
/// as a parse error of an internal file).
pub(crate) fn check(flag: &str, value: f64, ok: bool, want: &str) -> anyhow::Result<()> {
    if value.is_finite() && ok {
        Ok(())
    } else {
        bail!("{flag} {value}: must be {want}")
    }
}

/// The largest loop rate the processes accept, Hz (as the controller's own check).
pub(crate) const MAX_RATE_HZ: f64 = 20_000.0;

/// `--peer-timeout`: (the timeout, the start grace). Given explicitly, the
/// timeout holds from the start; by default the peers get
/// [`crate::ipc::PEER_START_GRACE_S`] to appear, then 2 s of silence.
pub(crate) fn peer_timeout(flag: Option<f64>) -> anyhow::Result<(Option<f64>, Option<f64>)> {
    match flag {
        None => Ok((Some(2.0), None)),
        Some(t) => {
            check(
                "--peer-timeout",
                t,
                t >= 0.0,
                "a number of seconds ≥ 0 (0 = never)",
            )?;
            Ok(((t > 0.0).then_some(t), Some(t)))
        }
    }
}

impl LoopOpts {
    /// Refuse values no loop can run with, naming the flag.
    pub fn check(&self) -> anyhow::Result<()> {
        let r = self.rate_hz();
        check("--rate", r, r > 0.0 && r <= MAX_RATE_HZ, "in (0, 20000] Hz")?;
        let period_us = 1e6 / r;
        check(
            "--spin-us",
            self.spin_us,
            self.spin_us >= 0.0 && self.spin_us <= period_us,
            &format!("in [0, {period_us}] µs (one period)"),
        )?;
        let w = self.watchdog_periods;
        check("--watchdog-periods", w, w > 0.0, "a number of periods > 0")?;
        check("--ki", self.ki, self.ki >= 0.0, "a gain ≥ 0 (1/s)")?;
        let (l, win) = (self.correction_limit_mm, self.correction_window_mm);
        check("--correction-limit-mm", l, l >= 0.0, "≥ 0 mm")?;
        check("--correction-window-mm", win, win >= 0.0, "≥ 0 mm")?;
        let f = self.correction_filter_ms;
        check(
            "--correction-filter-ms",
            f,
            (0.0..=10_000.0).contains(&f),
            "in [0, 10000] ms",
        )?;
        let g = self.correction_map_gain;
        check(
            "--correction-map-gain",
            g,
            (0.0..=100.0).contains(&g),
            "in [0, 100] /s",
        )?;
        let t = self.tracker_timeout_ms;
        check(
            "--tracker-timeout-ms",
            t,
            t > 0.0 && t <= 60_000.0,
            "in (0, 60000] ms",
        )?;
        let lead = self.lead_ms;
        check(
            "--lead-ms",
            lead,
            (0.0..=1000.0).contains(&lead),
            "in [0, 1000] ms",
        )?;
        check("--slew", self.slew, self.slew > 0.0, "a rate > 0 N/s")
    }

    /// The control rate: `--rate`, else 1000 Hz.
    pub fn rate_hz(&self) -> f64 {
        self.rate.unwrap_or(DEFAULT_RATE_HZ)
    }

    /// The rate with the chip in the loop: `--rate`, else
    /// [`crate::mcu::bridge::MCU_RATE_HZ`].
    pub fn mcu_rate_hz(&self) -> f64 {
        self.rate.unwrap_or(crate::mcu::bridge::MCU_RATE_HZ)
    }

    /// Fill the loop fields of a controller config.
    pub fn apply(&self, cfg: &mut ControllerConfig) {
        cfg.rate_hz = self.rate_hz();
        cfg.spin_us = self.spin_us;
        cfg.realtime = self.realtime == Some(OnOff::On);
        cfg.watchdog_periods = self.watchdog_periods;
        cfg.ki_per_s = if self.correction == OnOff::On {
            self.ki
        } else {
            0.0
        };
        cfg.correction_limit_m = self.correction_limit_mm * 1e-3;
        cfg.correction_window_m = self.correction_window_mm * 1e-3;
        cfg.correction_filter_tau_s = self.correction_filter_ms * 1e-3;
        cfg.tracker_timeout_s = self.tracker_timeout_ms * 1e-3;
        cfg.correction_map_gain_per_s = self.correction_map_gain;
        cfg.scale_gains_to_mode = self.scale_gains_to_mode == OnOff::On;
        cfg.lead_s = self.lead_ms * 1e-3;
        cfg.slew_n_per_s = self.slew;
    }
}

/// Run the firmware control step at a fixed rate between planner and plant.
#[derive(Args, Debug)]
pub struct ControllerArgs {
    /// The whole configuration as JSON (a `ControllerConfig`, as a launcher
    /// writes it); the other options are then ignored.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Robot description file (tension limits).
    #[arg(long, default_value = crate::robot::DEFAULT_ROBOT)]
    pub robot: PathBuf,
    /// Trained IK net (`tendril train` output) [default: out/model.tnet if it
    /// exists, else the firmware's built-in net for the default robot, as
    /// `tendril sim` does].
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Run a net trained for another robot than --robot (with a warning) instead of refusing it.
    #[arg(long)]
    pub allow_robot_mismatch: bool,
    /// iceoryx2 service-name prefix.
    #[arg(long, default_value = crate::ipc::DEFAULT_PREFIX)]
    pub prefix: String,
    #[command(flatten)]
    pub tuning: LoopOpts,
    /// Stop after this many seconds (default: until SIGTERM or a stop message).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Stop (non-zero exit) after this many seconds with neither a setpoint
    /// nor a plant state; 0 = never [default: 2 s, after up to 10 s for the
    /// peers to start; given explicitly, it holds from the start].
    #[arg(long)]
    pub peer_timeout: Option<f64>,
    /// Die with the parent process (as `tendril sim` starts it; also when
    /// the TENDRIL_SUPERVISED environment variable is set).
    #[arg(long)]
    pub supervised: bool,
    /// Per-period CSV log.
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// Statistics JSON written at exit.
    #[arg(long)]
    pub stats: Option<PathBuf>,
    /// Pin to this CPU.
    #[arg(long)]
    pub cpu: Option<usize>,
    /// Put the chip in the loop: start the STM32F405 controller image
    /// under QEMU (netduinoplus2) and bridge the services to its serial
    /// link; the chip runs every rule of the period on its own timer.
    #[arg(long)]
    pub mcu: bool,
    /// With --mcu: a chip already running behind this link socket (QEMU's
    /// `-serial unix:SOCKET,server=on`) instead of starting one.
    #[arg(long, requires = "mcu")]
    pub mcu_socket: Option<PathBuf>,
    /// With --mcu: the controller image to start (default: built from
    /// this checkout).
    #[arg(long, requires = "mcu")]
    pub mcu_image: Option<PathBuf>,
    /// With --mcu: inject a burst of garbage bytes on the link every this
    /// many ms (the link's fault test).
    #[arg(long, requires = "mcu")]
    pub link_garbage_every_ms: Option<u64>,
}

impl ControllerArgs {
    /// The configuration: the `--config` file, or the flags.
    pub fn config(self) -> anyhow::Result<ControllerConfig> {
        if let Some(path) = &self.config {
            return Ok(crate::ipc::read_config(path)?);
        }
        self.tuning.check()?;
        if let Some(d) = self.duration {
            check("--duration", d, d > 0.0, "a number of seconds > 0")?;
        }
        let model = match crate::ipc::sim::ModelSource::resolve(
            self.model,
            std::path::Path::new("out/model.tnet"),
        ) {
            crate::ipc::sim::ModelSource::File(path) => path,
            _ => built_in_net_file()?,
        };
        let mut cfg = ControllerConfig::new(self.robot, model);
        cfg.allow_robot_mismatch = self.allow_robot_mismatch;
        cfg.prefix = self.prefix;
        self.tuning.apply(&mut cfg);
        cfg.duration_s = self.duration;
        (cfg.peer_timeout_s, cfg.peer_start_grace_s) = peer_timeout(self.peer_timeout)?;
        cfg.supervised = self.supervised;
        cfg.log = self.log;
        cfg.stats = self.stats;
        cfg.cpu = self.cpu;
        if self.mcu {
            cfg.rate_hz = self.tuning.mcu_rate_hz();
            crate::mcu::bridge::check_chip_rate(cfg.rate_hz).map_err(anyhow::Error::msg)?;
            if let Some(ms) = self.link_garbage_every_ms {
                check(
                    "--link-garbage-every-ms",
                    ms as f64,
                    ms > 0,
                    "a number of ms > 0",
                )?;
            }
            cfg.mcu = Some(crate::ipc::controller::McuOptions {
                socket: self.mcu_socket,
                image: self.mcu_image,
                garbage_every_ms: self.link_garbage_every_ms,
            });
        }
        Ok(cfg)
    }
}

/// The firmware's built-in net, in a temporary file while the process
/// runs (the controller reads its net from a file; the file is removed at
/// the end, and by the signal handler's clean-up on a forced exit).
fn built_in_net_file() -> anyhow::Result<PathBuf> {
    let tmp = crate::fsutil::Temporary::new_in(&std::env::temp_dir())?;
    std::io::Write::write_all(&mut tmp.as_file(), crate::ipc::sim::BUILT_IN_NET)?;
    let path = tmp.path().to_path_buf();
    BUILT_IN_FILE
        .lock()
        .map_err(|_| anyhow::anyhow!("the built-in net's file"))?
        .replace(tmp);
    Ok(path)
}

/// The file [`built_in_net_file`] wrote, held (and removed) by [`run`].
static BUILT_IN_FILE: std::sync::Mutex<Option<crate::fsutil::Temporary>> =
    std::sync::Mutex::new(None);

/// Run `tendril controller`.
pub fn run(args: ControllerArgs) -> anyhow::Result<()> {
    let result = args.config().and_then(|cfg| {
        // The backend: the period on the host, or the chip over its link.
        Ok(match cfg.mcu {
            Some(_) => crate::mcu::bridge::run(&cfg)?,
            None => crate::ipc::controller::run(&cfg)?,
        })
    });
    // The built-in net's temporary file, if one was written, goes now.
    if let Ok(mut file) = BUILT_IN_FILE.lock() {
        file.take();
    }
    let stats = result?;
    log::info!(
        "controller: {} cycles, {} overruns, lateness p50 {:.1} µs p99 {:.1} µs",
        stats.cycles,
        stats.overruns,
        stats.lateness_us.p50,
        stats.lateness_us.p99
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
        args: ControllerArgs,
    }

    /// Every default the command line shows is the configuration's own: a
    /// `tendril controller` without flags runs `ControllerConfig::new`'s
    /// loop (issue 44: the lead was 20.5 ms here and 21 ms there).
    #[test]
    fn a_command_line_without_flags_is_the_configurations_defaults() {
        let given = Cli::parse_from(["controller", "--model", "m.tnet"])
            .args
            .config()
            .unwrap();
        let mut expected = ControllerConfig::new("robots/seed-4t.toml".into(), "m.tnet".into());
        // The command line's own choices, said in its help: the correction
        // on at its gain (the library's config starts with it off).
        expected.ki_per_s = crate::ipc::controller::correction::KI_PER_S;
        expected.peer_timeout_s = given.peer_timeout_s;
        expected.peer_start_grace_s = given.peer_start_grace_s;
        assert_eq!(given, expected);
    }
}
