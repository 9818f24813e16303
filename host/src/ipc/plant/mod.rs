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
use super::process::{self, Process, Scheduling, Stepped};
use super::stats::{CsvLog, Histogram, Summary};
use super::transport::{self, Services};
use super::IpcError;
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
            robot: crate::robot::DEFAULT_ROBOT.into(),
            prefix: super::DEFAULT_PREFIX.into(),
            params: PlantParams::default(),
            spin: false,
            idle_period_s: IDLE_PERIOD_S,
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

/// The plant's state message for `model` after a step: its tensions and
/// its tracker's newest frame (the plant process publishes it; the loop
/// rehearsed in process, `ipc::rehearsal`, hands it to its controller).
pub fn state_message(
    model: &crate::plant::PlantModel,
    header: Header,
    command_seq: u64,
    status: u32,
) -> PlantState {
    let frame = model.frame();
    let mut msg = PlantState {
        header,
        command_seq,
        count: model.n() as u32,
        status,
        tip_seq: frame.map_or(0, |f| f.seq),
        tip_stamp_ns: frame.map_or(0, |f| f.stamp_ns),
        ..PlantState::default()
    };
    for (dst, src) in msg.tensions.iter_mut().zip(model.tensions()) {
        *dst = *src as f32;
    }
    if let Some(f) = frame {
        for (dst, src) in msg.tip_pose.iter_mut().zip(f.pose) {
            *dst = src as f32;
        }
    }
    msg
}

/// The plant's default idle period, s: it steps its model and publishes at
/// least this often without commands (the loop rehearsed in process,
/// `ipc::rehearsal`, steps its plant as often).
pub const IDLE_PERIOD_S: f64 = 1e-3;

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
    let process = Process {
        name: "plant",
        prefix: &cfg.prefix,
        supervised: cfg.supervised,
        duration_s: cfg.duration_s,
        peer_timeout_s: cfg.peer_timeout_s,
        peer_start_grace_s: cfg.peer_start_grace_s,
        log: cfg.log.as_deref(),
        stats: cfg.stats.as_deref(),
        scheduling: Some(Scheduling {
            cpu: cfg.cpu,
            realtime: cfg.realtime,
            priority: super::clock::plant_priority(cfg.params.model_in_effect()),
        }),
    };
    let load = || {
        let robot = Robot::load(&cfg.robot).map_err(|e| IpcError::Other(e.to_string()))?;
        Ok(PlantModel::new(&robot, cfg.params.clone())?)
    };
    process::run(&process, load, |model, services| {
        PlantTask::open(cfg, model, services)
    })
}

/// The plant as a [`process::Task`]: each step waits for a command (its
/// event) or the idle period, applies the commands due (through the fault
/// injection), steps the model and publishes its state.
struct PlantTask {
    model: PlantModel,
    n: usize,
    spin: bool,
    idle: Duration,
    command_timeout_s: f64,
    faults: PlantFaults,
    commands: transport::Sub<TensionCommand>,
    listener: iceoryx2::port::listener::Listener<transport::Svc>,
    state_pub: transport::Pub<PlantState>,
    runlog: Option<Recorder>,
    start: u64,
    stats: PlantStats,
    // Fixed-size histograms, not growing vectors: a plant runs as long as
    // the sim asks (issue 31: memory bounded whatever the duration).
    latencies: Histogram,
    step_times: Histogram,
    delayed: VecDeque<(u64, TensionCommand)>,
    pending: Vec<TensionCommand>,
    last_cmd: Option<TensionCommand>,
    last_cmd_time: u64,
    last_step: u64,
    seq: u64,
    status_sticky: u32,
    row: Vec<f64>,
}

impl PlantTask {
    fn open(
        cfg: &PlantConfig,
        model: PlantModel,
        services: &Services,
    ) -> Result<PlantTask, IpcError> {
        let n = model.n();
        // The run log sees the setpoints too (the desired tip): one more
        // subscriber, drained without waiting, so the planner never notices.
        let runlog = match cfg.runlog.enabled() {
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
        let start = now_ns();
        Ok(PlantTask {
            faults: cfg.params.faults.clone(),
            model,
            n,
            spin: cfg.spin,
            idle: Duration::from_secs_f64(cfg.idle_period_s.clamp(1e-4, 1.0)),
            command_timeout_s: cfg.command_timeout_s,
            commands: transport::subscriber(&services.tension_cmd)?,
            listener: transport::listener(&services.tension_cmd_event)?,
            state_pub: transport::publisher(&services.plant_state)?,
            runlog,
            start,
            stats: PlantStats::default(),
            latencies: Histogram::default(),
            step_times: Histogram::default(),
            delayed: VecDeque::new(),
            pending: Vec::with_capacity(16),
            last_cmd: None,
            last_cmd_time: start,
            last_step: start,
            seq: 0,
            status_sticky: 0,
            row: Vec::with_capacity(3 + 2 * n + 8),
        })
    }

    fn secs(&self, t: u64) -> f64 {
        t.saturating_sub(self.start) as f64 * 1e-9
    }

    /// Wait for a command (its event) or the idle period.
    fn wait(&mut self) -> Result<(), IpcError> {
        if self.spin {
            let until = now_ns() + self.idle.as_nanos() as u64;
            while now_ns() < until && !self.commands.has_samples().unwrap_or(false) {
                std::hint::spin_loop();
            }
            return Ok(());
        }
        // A signal cuts the wait short: the skeleton then sees the stop.
        match self.listener.timed_wait(|_| {}, self.idle) {
            Ok(_) | Err(ListenerWaitError::InterruptSignal) => Ok(()),
            Err(e) => Err(IpcError::Receive(format!("tension_cmd event: {e:?}"))),
        }
    }

    /// Take the commands that arrived (dropped or delayed as the faults
    /// say) and apply those that are due; returns how many arrived.
    fn take_commands(&mut self) -> Result<usize, IpcError> {
        self.pending.clear();
        transport::drain(&self.commands, &mut self.pending)?;
        let received = self.pending.len();
        let now = now_ns();
        let t = self.secs(now);
        for cmd in self.pending.drain(..) {
            self.stats.commands += 1;
            self.latencies
                .record(now.saturating_sub(cmd.header.stamp_ns));
            if let Some(prev) = self.last_cmd {
                if cmd.header.seq > prev.header.seq + 1 {
                    self.stats.sequence_gaps += cmd.header.seq - prev.header.seq - 1;
                }
            }
            if let Some(DropFault {
                fraction,
                from_s,
                to_s,
            }) = self.faults.drop
            {
                if t >= from_s && t < to_s && self.model.uniform() < fraction {
                    self.stats.dropped += 1;
                    self.status_sticky |= plant_status::DROPPING;
                    continue;
                }
            }
            match self.faults.delay {
                Some(d) if t >= d.from_s && t < d.to_s => {
                    self.stats.delayed += 1;
                    self.status_sticky |= plant_status::DELAYING;
                    self.delayed
                        .push_back((now + (d.delay_s * 1e9) as u64, cmd));
                }
                _ => self.delayed.push_back((now, cmd)),
            }
        }
        while self.delayed.front().is_some_and(|(due, _)| *due <= now) {
            let Some((_, cmd)) = self.delayed.pop_front() else {
                break;
            };
            let count = (cmd.count as usize).min(MAX_TENDONS);
            let mut tau = [0.0f64; MAX_TENDONS];
            for (d, &v) in tau.iter_mut().zip(&cmd.tensions[..count]) {
                *d = f64::from(v);
            }
            if self.model.command(&tau[..count]) {
                self.stats.out_of_range_commands += 1;
                self.status_sticky |= plant_status::COMMAND_OUT_OF_RANGE;
            }
            self.last_cmd = Some(cmd);
            self.last_cmd_time = now;
        }
        if let Some(StuckFault { at_s, .. }) = self.faults.stuck {
            if t >= at_s {
                self.model.set_stuck();
                self.status_sticky |= plant_status::MOTOR_STUCK;
            }
        }
        Ok(received)
    }

    /// The state after a step: published, recorded in the run log.
    fn publish(&mut self, t1: u64, status: u32) -> Result<Option<[f64; 7]>, IpcError> {
        let frame = self.model.frame().copied();
        self.seq += 1;
        let last_cmd = self.last_cmd;
        let header = Header {
            seq: self.seq,
            stamp_ns: now_ns(),
        };
        let msg = state_message(
            &self.model,
            header,
            last_cmd.map_or(0, |c| c.header.seq),
            status,
        );
        transport::send(&self.state_pub, msg)?;
        if let Some(r) = self.runlog.as_mut() {
            r.record(&self.model, t1, last_cmd.as_ref(), status, frame.as_ref())?;
        }
        Ok(frame.map(|f| f.pose))
    }
}

impl process::Task for PlantTask {
    type Stats = PlantStats;

    fn log_header(&self) -> String {
        log_header(self.n)
    }

    fn start_ns(&self) -> u64 {
        self.start
    }

    fn step(&mut self, log: &mut CsvLog) -> Result<Stepped, IpcError> {
        self.wait()?;
        let received = self.take_commands()?;

        let t0 = now_ns();
        let ok = self.model.step((t0 - self.last_step) as f64 * 1e-9);
        let t1 = now_ns();
        self.last_step = t0;
        self.step_times.record(t1 - t0);
        self.stats.steps += 1;

        let mut status = self.status_sticky;
        if !ok {
            status |= plant_status::SOLVE_FAILED;
        }
        if self.secs(t1) - self.secs(self.last_cmd_time) > self.command_timeout_s {
            status |= plant_status::COMMAND_STALE;
        }
        self.model.sense(t1);
        let frame = self.publish(t1, status)?;

        let row = &mut self.row;
        row.clear();
        row.push(t0 as f64);
        row.push(self.last_cmd.map_or(0.0, |c| c.header.seq as f64));
        row.push(self.last_cmd.map_or(0.0, |c| c.status as f64));
        row.extend(self.model.targets().iter().copied());
        row.extend(self.model.tensions().iter().copied());
        let p = self.model.pose();
        let m = frame.unwrap_or([f64::NAN; 7]);
        row.extend([p[0], p[1], p[2], m[0], m[1], m[2]]);
        row.push(status as f64);
        row.push((t1 - t0) as f64);
        log.row(row)?;
        Ok(Stepped {
            t_ns: t1,
            heard: received > 0,
        })
    }

    fn silence(&self) -> &'static str {
        "no tension command"
    }

    fn finish(mut self, outcome: &Result<(), IpcError>) -> Result<PlantStats, IpcError> {
        // The run log is published however the run ended (the run
        // happened); a failure to publish it is the skeleton's to report.
        if let Some(r) = self.runlog.take() {
            if outcome.is_ok() {
                r.log.line(
                    now_ns(),
                    foxglove::messages::log::Level::Info,
                    format!("plant: stopped after {} steps", self.stats.steps),
                );
            }
            self.stats.runlog = Some(r.log.finish().map_err(|e| IpcError::Other(e.to_string()))?);
        }
        self.stats.solve_failures = self.model.solve_failures;
        self.stats.latency_us = self.latencies.summary();
        self.stats.step_us = self.step_times.summary();
        Ok(self.stats)
    }
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
                base: model.base_pose(),
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
