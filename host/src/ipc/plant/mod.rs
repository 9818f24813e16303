//! The simulated plant: one motor per tendon tracking its commanded tension
//! with first-order dynamics and saturation, optional series tendon
//! compliance, and the robot's tip from the Cosserat statics, warm-started
//! from the previous step (quasi-static: the rod is stiff and light next to
//! the motors, so it settles far faster than they move). A tip "sensor" adds
//! Gaussian noise. Faults: a stuck motor, dropped and delayed commands.
//!
//! The process is event-driven: it sleeps on the `tension_cmd` event and
//! steps when a command arrives (or after a timeout), so the command's
//! one-way latency is the event wake-up, not a polling period.

use std::collections::VecDeque;
use std::path::PathBuf;
use std::time::Duration;

use iceoryx2::port::listener::ListenerWaitError;
use serde::{Deserialize, Serialize};
use tendril_shared::messages::{plant_status, Header, PlantState, TensionCommand, MAX_TENDONS};

use super::clock::now_ns;
use super::stats::{CsvLog, Histogram, Summary};
use super::transport::{self, Services};
use super::{IpcError, StopWatch};
use crate::robot::Robot;
use crate::runlog::{RunLog, RunLogConfig, RunLogStats, SceneRecord, StepRecord};

pub use crate::plant::{
    DelayFault, DropFault, PlantFaults, PlantModel, PlantParams, RobotModel, StuckFault,
};

/// Everything the plant process needs: written by a launcher as JSON
/// (`tendril plant --config FILE`) or built from the flags.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlantConfig {
    /// Robot file.
    pub robot: PathBuf,
    /// Service-name prefix.
    pub prefix: String,
    /// Model parameters.
    pub params: PlantParams,
    /// Busy-poll for commands instead of sleeping on the event.
    pub spin: bool,
    /// Step and publish at least this often without commands, s.
    pub idle_period_s: f64,
    /// Commands older than this mark the state `COMMAND_STALE`, s.
    pub command_timeout_s: f64,
    /// Stop after this many seconds (None: until told).
    pub duration_s: Option<f64>,
    /// Stop with [`IpcError::PeersLost`] after this long without a tension
    /// command, s (None: never).
    pub peer_timeout_s: Option<f64>,
    /// How long the peers may take to appear before the first message, s
    /// (None: [`super::PEER_START_GRACE_S`]; never shorter than the timeout).
    pub peer_start_grace_s: Option<f64>,
    /// Die with the launching process ([`super::die_with_parent`]).
    pub supervised: bool,
    /// Per-step CSV log.
    pub log: Option<PathBuf>,
    /// The run's MCAP file and live view (docs/design.md §12).
    pub runlog: RunLogConfig,
    /// Statistics JSON written at exit.
    pub stats: Option<PathBuf>,
    /// Switch to SCHED_FIFO after set-up.
    pub realtime: bool,
    /// Pin to this CPU.
    pub cpu: Option<usize>,
}

impl Default for PlantConfig {
    fn default() -> Self {
        PlantConfig {
            robot: "robots/seed-4t.toml".into(),
            prefix: super::DEFAULT_PREFIX.into(),
            params: PlantParams::default(),
            spin: false,
            idle_period_s: 0.001,
            command_timeout_s: 0.05,
            duration_s: None,
            peer_timeout_s: Some(2.0),
            peer_start_grace_s: None,
            supervised: false,
            log: None,
            runlog: RunLogConfig::default(),
            stats: None,
            realtime: false,
            cpu: None,
        }
    }
}

/// What the plant reports at exit.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct PlantStats {
    /// Steps taken.
    pub steps: u64,
    /// Commands received.
    pub commands: u64,
    /// Commands with a tension out of range or not finite (saturated before use).
    pub out_of_range_commands: u64,
    /// Commands dropped by fault injection.
    pub dropped: u64,
    /// Commands delayed by fault injection.
    pub delayed: u64,
    /// Gaps in the command sequence numbers (lost messages).
    pub sequence_gaps: u64,
    /// Statics failures.
    pub solve_failures: u64,
    /// One-way command latency: controller's stamp → plant receive (µs).
    pub latency_us: Summary,
    /// Time of one step: motor update + statics (µs).
    pub step_us: Summary,
    /// What the run log wrote (None without one).
    pub runlog: Option<RunLogStats>,
}

/// Column names of the plant log (for `n` tendons).
pub fn log_header(n: usize) -> String {
    let mut cols = vec!["t_ns".to_string(), "cmd_seq".into(), "cmd_status".into()];
    cols.extend((0..n).map(|i| format!("cmd{i}")));
    cols.extend((0..n).map(|i| format!("tau{i}")));
    cols.extend(["px", "py", "pz", "mx", "my", "mz", "status", "step_ns"].map(String::from));
    cols.join(",")
}

/// Run the plant process until stopped.
pub fn run(cfg: &PlantConfig) -> Result<PlantStats, IpcError> {
    super::die_with_parent(cfg.supervised)?;
    let robot = Robot::load(&cfg.robot).map_err(|e| IpcError::Other(e.to_string()))?;
    let mut model = PlantModel::new(&robot, cfg.params.clone())?;
    let n = model.n();
    let node = transport::node("tendril-plant")?;
    let _orphan = transport::ReleaseIfOrphaned(&node);
    let services = Services::open_or_create(&node, &cfg.prefix)?;
    let commands = transport::subscriber(&services.tension_cmd)?;
    let listener = transport::listener(&services.tension_cmd_event)?;
    let state_pub = transport::publisher(&services.plant_state)?;
    let stop = StopWatch::new(&services)?;
    let mut log = CsvLog::create(cfg.log.as_deref(), &log_header(n))?;
    // The run log sees the setpoints too (the desired tip): one more
    // subscriber, drained without waiting, so the planner never notices.
    let mut runlog = match cfg.runlog.enabled() {
        true => Some(Recorder {
            log: RunLog::start(&cfg.runlog).map_err(|e| IpcError::Other(e.to_string()))?,
            setpoints: transport::subscriber(&services.setpoint)?,
            received: Vec::with_capacity(16),
            desired: None,
            controller_status: 0,
            plant_status: 0,
        }),
        false => None,
    };
    if let Some(r) = &runlog {
        r.log.line(
            now_ns(),
            foxglove::messages::log::Level::Info,
            format!(
                "plant: {}, robot {}",
                crate::robot::count(n, "tendon"),
                cfg.robot.display()
            ),
        );
        if let Some(port) = r.log.live_port() {
            // Always said (not a log line a sim's quiet children filter):
            // with port 0 nobody else can know where to connect.
            eprintln!(
                "live view on ws://{} (Foxglove: Open connection)",
                live_host(&cfg.runlog, port)
            );
        }
    }
    super::clock::tighten_timer_slack();
    super::clock::apply_scheduling("plant", cfg.cpu, cfg.realtime, super::clock::PLANT_PRIORITY);

    let start = now_ns();
    let secs = |t: u64| t.saturating_sub(start) as f64 * 1e-9;
    let mut stats = PlantStats::default();
    // Fixed-size histograms, not growing vectors: a plant runs as long as
    // the sim asks (issue 31: memory bounded whatever the duration).
    let mut latencies = Histogram::default();
    let mut step_times = Histogram::default();
    let mut delayed: VecDeque<(u64, TensionCommand)> = VecDeque::new();
    let mut last_cmd: Option<TensionCommand> = None;
    let mut last_cmd_time = start;
    let mut last_step = start;
    let mut seq = 0u64;
    let mut status_sticky = 0u32;
    let mut pending = Vec::with_capacity(16);
    let idle = Duration::from_secs_f64(cfg.idle_period_s.clamp(1e-4, 1.0));
    let mut peers = super::PeerWatch::new(cfg.peer_timeout_s, cfg.peer_start_grace_s, start);
    let faults = cfg.params.faults.clone();
    let mut last_flush = start;

    loop {
        // Wait for a command (event) or the idle period.
        if cfg.spin {
            let until = now_ns() + idle.as_nanos() as u64;
            while now_ns() < until && !commands.has_samples().unwrap_or(false) {
                std::hint::spin_loop();
            }
        } else {
            // A signal cuts the wait short: the loop then sees the stop.
            match listener.timed_wait(|_| {}, idle) {
                Ok(_) | Err(ListenerWaitError::InterruptSignal) => {}
                Err(e) => return Err(IpcError::Receive(format!("tension_cmd event: {e:?}"))),
            }
        }
        pending.clear();
        transport::drain(&commands, &mut pending)?;
        let received = pending.len();
        let now = now_ns();
        let t = secs(now);
        for cmd in pending.drain(..) {
            stats.commands += 1;
            latencies.record(now.saturating_sub(cmd.header.stamp_ns));
            if let Some(prev) = last_cmd {
                if cmd.header.seq > prev.header.seq + 1 {
                    stats.sequence_gaps += cmd.header.seq - prev.header.seq - 1;
                }
            }
            if let Some(DropFault {
                fraction,
                from_s,
                to_s,
            }) = faults.drop
            {
                if t >= from_s && t < to_s && model.uniform() < fraction {
                    stats.dropped += 1;
                    status_sticky |= plant_status::DROPPING;
                    continue;
                }
            }
            match faults.delay {
                Some(d) if t >= d.from_s && t < d.to_s => {
                    stats.delayed += 1;
                    status_sticky |= plant_status::DELAYING;
                    delayed.push_back((now + (d.delay_s * 1e9) as u64, cmd));
                }
                _ => delayed.push_back((now, cmd)),
            }
        }
        while delayed.front().is_some_and(|(due, _)| *due <= now) {
            let Some((_, cmd)) = delayed.pop_front() else {
                break;
            };
            let count = (cmd.count as usize).min(MAX_TENDONS);
            let tau: Vec<f64> = cmd.tensions[..count].iter().map(|&v| v as f64).collect();
            if model.command(&tau) {
                stats.out_of_range_commands += 1;
                status_sticky |= plant_status::COMMAND_OUT_OF_RANGE;
            }
            last_cmd = Some(cmd);
            last_cmd_time = now;
        }
        if let Some(StuckFault { at_s, .. }) = faults.stuck {
            if t >= at_s {
                model.set_stuck();
                status_sticky |= plant_status::MOTOR_STUCK;
            }
        }

        let t0 = now_ns();
        let ok = model.step((t0 - last_step) as f64 * 1e-9);
        let t1 = now_ns();
        last_step = t0;
        step_times.record(t1 - t0);
        stats.steps += 1;

        let mut status = status_sticky;
        if !ok {
            status |= plant_status::SOLVE_FAILED;
        }
        if secs(t1) - secs(last_cmd_time) > cfg.command_timeout_s {
            status |= plant_status::COMMAND_STALE;
        }
        model.sense(t1);
        let frame = model.frame().copied();
        seq += 1;
        let mut msg = PlantState {
            header: Header {
                seq,
                stamp_ns: now_ns(),
            },
            command_seq: last_cmd.map_or(0, |c| c.header.seq),
            count: n as u32,
            status,
            tip_seq: frame.map_or(0, |f| f.seq),
            tip_stamp_ns: frame.map_or(0, |f| f.stamp_ns),
            ..PlantState::default()
        };
        for (dst, src) in msg.tensions.iter_mut().zip(model.tensions()) {
            *dst = *src as f32;
        }
        if let Some(f) = &frame {
            for (dst, src) in msg.tip_pose.iter_mut().zip(f.pose) {
                *dst = src as f32;
            }
        }
        transport::send(&state_pub, msg)?;
        if let Some(r) = runlog.as_mut() {
            r.record(&model, t1, last_cmd.as_ref(), status, frame.as_ref())?;
        }

        let mut row = Vec::with_capacity(3 + 2 * n + 8);
        row.push(t0 as f64);
        row.push(last_cmd.map_or(0.0, |c| c.header.seq as f64));
        row.push(last_cmd.map_or(0.0, |c| c.status as f64));
        row.extend(model.targets().iter().copied());
        row.extend(model.tensions().iter().copied());
        let p = model.pose();
        let m = frame.map_or([f64::NAN; 7], |f| f.pose);
        row.extend([p[0], p[1], p[2], m[0], m[1], m[2]]);
        row.push(status as f64);
        row.push((t1 - t0) as f64);
        log.row(&row)?;
        if t1 - last_flush > 100_000_000 {
            log.flush()?;
            last_flush = t1;
        }

        if stop.requested() || cfg.duration_s.is_some_and(|d| secs(t1) >= d) {
            break;
        }
        if received > 0 {
            peers.heard(t1);
        } else if peers.lost(t1) {
            log.close()?;
            let lost = format!("plant: no tension command for {:.1} s", peers.silence_s(t1));
            // The run log is still published (the run happened); a failure
            // to publish it is part of the error, not lost in a Drop.
            if let Some(r) = runlog.take() {
                if let Err(e) = r.log.finish() {
                    return Err(IpcError::PeersLost(format!("{lost}; and {e}")));
                }
            }
            return Err(IpcError::PeersLost(lost));
        }
    }
    log.close()?;
    if let Some(r) = runlog.take() {
        r.log.line(
            now_ns(),
            foxglove::messages::log::Level::Info,
            format!("plant: stopped after {} steps", stats.steps),
        );
        stats.runlog = Some(r.log.finish().map_err(|e| IpcError::Other(e.to_string()))?);
    }
    stats.solve_failures = model.solve_failures;
    stats.latency_us = latencies.summary();
    stats.step_us = step_times.summary();
    if let Some(path) = &cfg.stats {
        let json = serde_json::to_vec_pretty(&stats).map_err(|e| IpcError::Other(e.to_string()))?;
        super::write_file(path, &json)?;
    }
    Ok(stats)
}

/// The plant's side of the run log: the desired tip from the setpoints,
/// the status bits last seen (a rising bit is a log line).
struct Recorder {
    log: RunLog,
    setpoints: transport::Sub<tendril_shared::messages::Setpoint>,
    received: Vec<tendril_shared::messages::Setpoint>,
    desired: Option<[f64; 7]>,
    controller_status: u32,
    plant_status: u32,
}

impl Recorder {
    fn record(
        &mut self,
        model: &PlantModel,
        t_ns: u64,
        cmd: Option<&TensionCommand>,
        plant_status: u32,
        frame: Option<&crate::plant::reality::Frame>,
    ) -> Result<(), IpcError> {
        use foxglove::messages::log::Level;
        self.received.clear();
        transport::drain(&self.setpoints, &mut self.received)?;
        // A non-finite setpoint (an injected fault) is not a desired tip.
        if let Some(sp) = self
            .received
            .iter()
            .rev()
            .find(|s| s.pose.iter().all(|v| v.is_finite()))
        {
            self.desired = Some(sp.pose.map(f64::from));
        }
        let controller_status = cmd.map_or(0, |c| c.status);
        let rising = controller_status & !self.controller_status;
        for name in crate::runlog::channels::controller_flags(rising) {
            self.log
                .line(t_ns, Level::Warning, format!("controller: {name}"));
        }
        let rising = plant_status & !self.plant_status;
        for name in crate::runlog::channels::plant_flags(rising) {
            self.log.line(t_ns, Level::Error, format!("plant: {name}"));
        }
        self.controller_status = controller_status;
        self.plant_status = plant_status;
        let frame = frame.map(|f| f.pose);
        self.log.step(StepRecord {
            t_ns,
            command_seq: cmd.map_or(0, |c| c.header.seq),
            controller_status,
            plant_status,
            commanded: model.targets().to_vec(),
            measured: model.tensions().to_vec(),
            tip: model.pose(),
            frame,
            desired: self.desired,
        });
        if self.log.scene_due(t_ns) {
            let shape = model.shape(self.log.backbone_points()).unwrap_or_default();
            let xyz = |v: &nalgebra::Vector3<f64>| [v.x, v.y, v.z];
            self.log.scene(SceneRecord {
                t_ns,
                backbone: shape.backbone.iter().map(xyz).collect(),
                tendons: shape
                    .tendons
                    .iter()
                    .map(|t| t.iter().map(xyz).collect())
                    .collect(),
                tip: model.pose(),
                frame,
                desired: self.desired,
            });
        }
        Ok(())
    }
}

/// The address a user types into Foxglove for the live view.
fn live_host(cfg: &RunLogConfig, port: u16) -> String {
    let host = cfg
        .live
        .as_deref()
        .and_then(|a| crate::runlog::writer::parse_addr(a).ok())
        .map_or_else(|| "127.0.0.1".to_string(), |(h, _)| h);
    format!("{host}:{port}")
}
