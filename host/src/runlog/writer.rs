//! [`RunLog`]: the writer thread behind a run's MCAP file and live view.
//!
//! The plant hands each step to [`RunLog::step`] and, at the scene rate, the
//! rod's shape to [`RunLog::scene`]; both only try to queue a record, so the
//! loop never waits on compression, disk or a slow WebSocket client. A full
//! queue drops the record and counts it ([`RunLogStats::dropped`]). The
//! thread encodes, logs through the Foxglove SDK's context to the MCAP sink
//! (chunked, zstd) and, with `live`, to its WebSocket server: the file and
//! the live view carry the same channels.

use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TrySendError};
use std::sync::Arc;
use std::thread::JoinHandle;

use foxglove::messages::{
    line_primitive, log, Color, FrameTransform, FrameTransforms, LinePrimitive, Log, Point3, Pose,
    Quaternion, SceneEntity, SceneUpdate, SpherePrimitive, Timestamp, Vector3,
};
use foxglove::{Channel, ChannelBuilder, Context, PartialMetadata, RawChannel, Schema};
use serde::{Deserialize, Serialize};

use super::channels::{self as ch, StatusMsg, TensionsMsg, TrackingMsg};
use crate::fsutil::StagedFile;

/// Records the queue holds: 4 s of a 1 kHz loop.
const QUEUE: usize = 4096;
/// Chunk size, bytes: a crashed run loses at most this much (compressed,
/// about a quarter of a second of a 1 kHz run with its scene).
const CHUNK_BYTES: u64 = 256 * 1024;
/// Points of the target path the scene draws (the newest setpoints, at
/// least [`PATH_SPACING_M`] apart).
const PATH_POINTS: usize = 400;
/// Spacing of the path's points, m.
const PATH_SPACING_M: f64 = 0.5e-3;
/// The path is its own entity, re-sent every this many scenes (it changes
/// slowly; sending it with every scene would double the file).
const PATH_EVERY_SCENES: u64 = 30;
/// `/status` is written when its bits change and at least this often, ns.
const STATUS_HEARTBEAT_NS: u64 = 100_000_000;

pub use super::config::{parse_addr, RunLogConfig};

/// One plant step.
#[derive(Clone, Debug)]
pub struct StepRecord {
    /// Loop time, ns (the plant's monotonic clock).
    pub t_ns: u64,
    /// The last command applied (0 = none).
    pub command_seq: u64,
    /// Its `command_status` bits.
    pub controller_status: u32,
    /// The plant's status bits.
    pub plant_status: u32,
    /// Commanded (saturated) tensions, N.
    pub commanded: Vec<f64>,
    /// Applied tensions, N.
    pub measured: Vec<f64>,
    /// True tip pose (p, q wxyz).
    pub tip: [f64; 7],
    /// The tracker's newest frame.
    pub frame: Option<[f64; 7]>,
    /// The newest setpoint's pose.
    pub desired: Option<[f64; 7]>,
}

/// The rod at one scene time.
#[derive(Clone, Debug)]
pub struct SceneRecord {
    /// Loop time, ns.
    pub t_ns: u64,
    /// The robot's base pose in the drawing's frame (the tracker's: the
    /// plant robot's `[base]`; the identity pose without one).
    pub base: [f64; 7],
    /// Backbone points, the tracker's frame, m (empty when the plant has no shape).
    pub backbone: Vec<[f64; 3]>,
    /// Each tendon's path, m.
    pub tendons: Vec<Vec<[f64; 3]>>,
    /// True tip pose.
    pub tip: [f64; 7],
    /// The tracker's newest frame.
    pub frame: Option<[f64; 7]>,
    /// The newest setpoint's pose.
    pub desired: Option<[f64; 7]>,
}

enum Record {
    Step(Box<StepRecord>),
    Scene(Box<SceneRecord>),
    Line {
        t_ns: u64,
        level: log::Level,
        text: String,
    },
}

/// Messages written per channel, and what the queue dropped.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RunLogStats {
    /// Messages logged per topic.
    pub messages: BTreeMap<String, u64>,
    /// Records dropped because the writer was behind.
    pub dropped: u64,
    /// The MCAP file, once closed and renamed (`None` when it went
    /// through a device or FIFO).
    pub file: Option<PathBuf>,
    /// Its size, bytes.
    pub bytes: u64,
    /// The live view's port, when one was served.
    pub live_port: Option<u16>,
}

/// What can stop a run log.
#[derive(Debug, thiserror::Error)]
pub enum RunLogError {
    /// The file could not be created, written or renamed.
    #[error("run log {path}: {message}")]
    File {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// The live server could not start.
    #[error("run log: live view on {addr}: {message}")]
    Live {
        /// The address asked for.
        addr: String,
        /// What went wrong.
        message: String,
    },
    /// A configuration value is out of range.
    #[error("{0}")]
    Config(String),
}

/// A run's log: a queue into the writer thread.
pub struct RunLog {
    tx: Option<SyncSender<Record>>,
    dropped: Arc<AtomicU64>,
    thread: Option<JoinHandle<Result<RunLogStats, RunLogError>>>,
    scene_period_ns: u64,
    next_scene_ns: u64,
    backbone_points: usize,
    live_port: Option<u16>,
    lossless: bool,
    discard: Arc<std::sync::atomic::AtomicBool>,
}

impl RunLog {
    /// Open the file and start the live server (if asked), then the writer
    /// thread. Errors (an unwritable directory, a port in use) come back
    /// here, before the loop starts.
    pub fn start(cfg: &RunLogConfig) -> Result<RunLog, RunLogError> {
        cfg.validate().map_err(RunLogError::Config)?;
        let sinks = Sinks::open(cfg)?;
        let live_port = sinks.server.as_ref().map(|s| s.port());
        let (tx, rx) = sync_channel(QUEUE);
        let dropped = Arc::new(AtomicU64::new(0));
        let discard = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let discard_in_thread = Arc::clone(&discard);
        let thread = std::thread::Builder::new()
            .name("tendril-runlog".into())
            .spawn(move || sinks.run(rx, &discard_in_thread))
            .map_err(|e| RunLogError::Config(format!("run log: thread: {e}")))?;
        Ok(RunLog {
            tx: Some(tx),
            dropped,
            thread: Some(thread),
            scene_period_ns: (1e9 / cfg.scene_hz) as u64,
            next_scene_ns: 0,
            backbone_points: cfg.backbone_points,
            live_port,
            lossless: cfg.lossless,
            discard,
        })
    }

    /// The live view's port (useful with port 0).
    pub fn live_port(&self) -> Option<u16> {
        self.live_port
    }

    /// Points the scene wants along the backbone.
    pub fn backbone_points(&self) -> usize {
        self.backbone_points
    }

    /// Whether a scene is due at `t_ns` (then the caller builds the shape
    /// and calls [`RunLog::scene`]).
    pub fn scene_due(&self, t_ns: u64) -> bool {
        t_ns >= self.next_scene_ns
    }

    /// Queue one step (never blocks).
    pub fn step(&self, rec: StepRecord) {
        self.send(Record::Step(Box::new(rec)));
    }

    /// Queue a scene (never blocks) and schedule the next.
    pub fn scene(&mut self, rec: SceneRecord) {
        let t = rec.t_ns;
        self.next_scene_ns =
            if self.next_scene_ns == 0 || t > self.next_scene_ns + self.scene_period_ns {
                t + self.scene_period_ns
            } else {
                self.next_scene_ns + self.scene_period_ns
            };
        self.send(Record::Scene(Box::new(rec)));
    }

    /// Queue a log line (never blocks).
    pub fn line(&self, t_ns: u64, level: log::Level, text: String) {
        self.send(Record::Line { t_ns, level, text });
    }

    fn send(&self, rec: Record) {
        let Some(tx) = &self.tx else { return };
        if self.lossless {
            if tx.send(rec).is_err() {
                self.dropped.fetch_add(1, Ordering::Relaxed);
            }
            return;
        }
        match tx.try_send(rec) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) | Err(TrySendError::Disconnected(_)) => {
                self.dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// Stop without keeping the file (a failed or interrupted run that
    /// publishes nothing): the `.partial` file is removed.
    pub fn discard(self) {
        self.discard.store(true, Ordering::SeqCst);
        drop(self);
    }

    /// Drain the queue, close the file (renamed into place) and stop the
    /// live server.
    pub fn finish(mut self) -> Result<RunLogStats, RunLogError> {
        self.tx = None;
        let mut stats = match self.thread.take().map(JoinHandle::join) {
            Some(Ok(r)) => r?,
            Some(Err(_)) => return Err(RunLogError::Config("run log: writer panicked".into())),
            None => RunLogStats::default(),
        };
        stats.dropped = self.dropped.load(Ordering::Relaxed);
        Ok(stats)
    }
}

impl Drop for RunLog {
    fn drop(&mut self) {
        // An error path: close what was written (a readable file stays
        // under its `.partial` name only if the thread cannot finish).
        self.tx = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

struct Channels {
    scene: Channel<SceneUpdate>,
    tf: Channel<FrameTransforms>,
    log: Channel<Log>,
    tensions: Arc<RawChannel>,
    tracking: Arc<RawChannel>,
    status: Arc<RawChannel>,
}

struct Sinks {
    ctx: Arc<Context>,
    mcap: Option<(
        foxglove::McapWriterHandle<BufWriter<std::fs::File>>,
        StagedFile,
        PathBuf,
    )>,
    server: Option<foxglove::WebSocketServerHandle>,
    channels: Channels,
    path: std::collections::VecDeque<[f64; 3]>,
    last_desired: Option<[f64; 3]>,
    scenes: u64,
    last_status: Option<(u64, (u32, u32))>,
    counts: BTreeMap<String, u64>,
}

fn json_channel(
    ctx: &Arc<Context>,
    topic: &str,
    name: &str,
    schema: &'static str,
) -> Arc<RawChannel> {
    ChannelBuilder::new(topic)
        .context(ctx)
        .message_encoding("json")
        .schema(Schema::new(name, "jsonschema", schema.as_bytes()))
        .build_raw()
        .expect("a topic of a fresh context is free")
}

impl Sinks {
    fn open(cfg: &RunLogConfig) -> Result<Sinks, RunLogError> {
        let ctx = Context::new();
        let mcap = match &cfg.mcap {
            None => None,
            Some(path) => {
                let file_err = |message: String| RunLogError::File {
                    path: path.clone(),
                    message,
                };
                // The output policy (crate::fsutil): a directory, a socket
                // or a FIFO without a reader is refused here, before the
                // run; a device or FIFO is written through at the end.
                let staged = StagedFile::create(path).map_err(|e| file_err(e.to_string()))?;
                let file = staged.writer().map_err(|e| file_err(e.to_string()))?;
                let options = mcap::WriteOptions::new()
                    .compression(Some(mcap::Compression::Zstd))
                    .chunk_size(Some(CHUNK_BYTES))
                    .profile("")
                    .library(concat!("tendril ", env!("CARGO_PKG_VERSION")));
                let handle = ctx
                    .mcap_writer_with_options(options)
                    .create(BufWriter::new(file))
                    .map_err(|e| file_err(e.to_string()))?;
                if !cfg.metadata.is_empty() {
                    handle
                        .write_metadata("run", cfg.metadata.clone())
                        .map_err(|e| file_err(e.to_string()))?;
                }
                Some((handle, staged, path.clone()))
            }
        };
        let server = match &cfg.live {
            None => None,
            Some(addr) => {
                let (host, port) = parse_addr(addr).map_err(RunLogError::Config)?;
                let server = ctx
                    .websocket_server()
                    .name("tendril")
                    .bind(host, port)
                    .start_blocking()
                    .map_err(|e| RunLogError::Live {
                        addr: addr.clone(),
                        message: e.to_string(),
                    })?;
                Some(server)
            }
        };
        let channels = Channels {
            scene: ChannelBuilder::new(ch::SCENE).context(&ctx).build(),
            tf: ChannelBuilder::new(ch::TF).context(&ctx).build(),
            log: ChannelBuilder::new(ch::LOG).context(&ctx).build(),
            tensions: json_channel(&ctx, ch::TENSIONS, "tendril.Tensions", ch::TENSIONS_SCHEMA),
            tracking: json_channel(&ctx, ch::TRACKING, "tendril.Tracking", ch::TRACKING_SCHEMA),
            status: json_channel(&ctx, ch::STATUS, "tendril.Status", ch::STATUS_SCHEMA),
        };
        Ok(Sinks {
            ctx,
            mcap,
            server,
            channels,
            path: std::collections::VecDeque::with_capacity(PATH_POINTS),
            last_desired: None,
            scenes: 0,
            last_status: None,
            counts: BTreeMap::new(),
        })
    }

    fn count(&mut self, topic: &str) {
        *self.counts.entry(topic.to_string()).or_default() += 1;
    }

    fn run(
        mut self,
        rx: Receiver<Record>,
        discard: &std::sync::atomic::AtomicBool,
    ) -> Result<RunLogStats, RunLogError> {
        while let Ok(rec) = rx.recv() {
            match rec {
                Record::Step(s) => self.step(&s),
                Record::Scene(s) => self.scene(&s),
                Record::Line { t_ns, level, text } => self.line(t_ns, level, text),
            }
        }
        let mut stats = RunLogStats {
            messages: std::mem::take(&mut self.counts),
            live_port: self.server.as_ref().map(|s| s.port()),
            ..RunLogStats::default()
        };
        if let Some(server) = self.server.take() {
            server.stop().wait_blocking();
        }
        if let Some((handle, staged, path)) = self.mcap.take() {
            let file_err = |message: String| RunLogError::File {
                path: path.clone(),
                message,
            };
            let writer = handle.close().map_err(|e| file_err(e.to_string()))?;
            if discard.load(Ordering::SeqCst) {
                drop(writer);
                staged.discard();
                return Ok(stats);
            }
            let file = writer
                .into_inner()
                .map_err(|e| file_err(e.error().to_string()))?;
            stats.bytes = file.metadata().map(|m| m.len()).unwrap_or(0);
            drop(file);
            stats.file = staged.commit().map_err(|e| file_err(e.to_string()))?;
        }
        drop(self.ctx);
        Ok(stats)
    }

    fn json<T: Serialize>(&mut self, channel: &str, t_ns: u64, msg: &T) {
        let bytes = serde_json::to_vec(msg).expect("plain data serialises");
        let raw = match channel {
            ch::TENSIONS => &self.channels.tensions,
            ch::TRACKING => &self.channels.tracking,
            _ => &self.channels.status,
        };
        raw.log_with_meta(
            &bytes,
            PartialMetadata {
                log_time: Some(t_ns),
            },
        );
        self.count(channel);
    }

    fn step(&mut self, s: &StepRecord) {
        let p3 = |p: &[f64; 7]| [p[0], p[1], p[2]];
        let dist_mm = |a: [f64; 3], b: [f64; 3]| {
            1e3 * ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
        };
        let desired = s.desired.as_ref().map(p3);
        if let Some(d) = desired {
            let far = self
                .last_desired
                .is_none_or(|l| dist_mm(l, d) >= PATH_SPACING_M * 1e3);
            if far {
                if self.path.len() == PATH_POINTS {
                    self.path.pop_front();
                }
                self.path.push_back(d);
                self.last_desired = Some(d);
            }
        }
        // Rounded far below what is measured (0.1 µm, 10 µN, 10 nm of
        // error): shorter numbers compress to a third of the file.
        let um = |p: [f64; 3]| p.map(|v| round(v, 1e7));
        let actual = p3(&s.tip);
        let measured = s.frame.as_ref().map(p3);
        self.json(
            ch::TENSIONS,
            s.t_ns,
            &TensionsMsg {
                commanded_n: s.commanded.iter().map(|&v| round(v, 1e5)).collect(),
                measured_n: s.measured.iter().map(|&v| round(v, 1e5)).collect(),
            },
        );
        self.json(
            ch::TRACKING,
            s.t_ns,
            &TrackingMsg {
                desired_m: desired.map(um),
                actual_m: um(actual),
                measured_m: measured.map(um),
                error_mm: desired.map(|d| round(dist_mm(d, actual), 1e5)),
                measured_error_mm: desired
                    .zip(measured)
                    .map(|(d, m)| round(dist_mm(d, m), 1e5)),
            },
        );
        // The bits change rarely: a message when they change and at 10 Hz.
        let bits = (s.controller_status, s.plant_status);
        let due = self
            .last_status
            .is_none_or(|(t, b)| b != bits || s.t_ns.saturating_sub(t) >= STATUS_HEARTBEAT_NS);
        if due {
            self.last_status = Some((s.t_ns, bits));
            self.json(
                ch::STATUS,
                s.t_ns,
                &StatusMsg {
                    command_seq: s.command_seq,
                    controller: s.controller_status,
                    controller_flags: ch::controller_flags(s.controller_status),
                    plant: s.plant_status,
                    plant_flags: ch::plant_flags(s.plant_status),
                },
            );
        }
    }

    fn scene(&mut self, s: &SceneRecord) {
        let ts = timestamp(s.t_ns);
        let point = |p: &[f64; 3]| Point3 {
            x: p[0],
            y: p[1],
            z: p[2],
        };
        let strip = |points: &[[f64; 3]], thickness: f64, color: Color| LinePrimitive {
            r#type: line_primitive::Type::LineStrip as i32,
            pose: Some(identity()),
            thickness,
            scale_invariant: false,
            points: points.iter().map(point).collect(),
            color: Some(color),
            colors: vec![],
            indices: vec![],
        };
        let sphere = |p: &[f64; 3], size: f64, color: Color| SpherePrimitive {
            pose: Some(Pose {
                position: Some(Vector3 {
                    x: p[0],
                    y: p[1],
                    z: p[2],
                }),
                orientation: Some(unit()),
            }),
            size: Some(Vector3 {
                x: size,
                y: size,
                z: size,
            }),
            color: Some(color),
        };
        let mut lines = Vec::new();
        if !s.backbone.is_empty() {
            lines.push(strip(&s.backbone, 0.0016, rgba(0.85, 0.85, 0.9, 1.0)));
        }
        for t in &s.tendons {
            lines.push(strip(t, 0.0004, rgba(0.95, 0.6, 0.1, 1.0)));
        }
        let tip = [s.tip[0], s.tip[1], s.tip[2]];
        let mut spheres = vec![sphere(&tip, 0.003, rgba(0.9, 0.2, 0.2, 1.0))];
        if let Some(d) = &s.desired {
            spheres.push(sphere(&[d[0], d[1], d[2]], 0.003, rgba(0.2, 0.8, 0.3, 1.0)));
        }
        if let Some(m) = &s.frame {
            spheres.push(sphere(
                &[m[0], m[1], m[2]],
                0.002,
                rgba(0.2, 0.4, 0.95, 1.0),
            ));
        }
        let entity = SceneEntity {
            timestamp: Some(ts),
            frame_id: ch::TRACKER_FRAME.into(),
            id: "robot".into(),
            lines,
            spheres,
            ..SceneEntity::default()
        };
        let mut entities = vec![entity];
        let path: Vec<[f64; 3]> = self.path.iter().copied().collect();
        if path.len() >= 2 && self.scenes.is_multiple_of(PATH_EVERY_SCENES) {
            entities.push(SceneEntity {
                timestamp: Some(ts),
                frame_id: ch::TRACKER_FRAME.into(),
                id: "target_path".into(),
                lines: vec![strip(&path, 0.0005, rgba(0.2, 0.8, 0.3, 0.8))],
                ..SceneEntity::default()
            });
        }
        self.scenes += 1;
        self.channels.scene.log_with_time(
            &SceneUpdate {
                deletions: vec![],
                entities,
            },
            s.t_ns,
        );
        self.count(ch::SCENE);
        let transform = |child: &str, p: &[f64; 7]| FrameTransform {
            timestamp: Some(ts),
            parent_frame_id: ch::TRACKER_FRAME.into(),
            child_frame_id: child.into(),
            translation: Some(Vector3 {
                x: p[0],
                y: p[1],
                z: p[2],
            }),
            rotation: Some(Quaternion {
                w: p[3],
                x: p[4],
                y: p[5],
                z: p[6],
            }),
        };
        let mut transforms = vec![
            transform(ch::BASE_FRAME, &s.base),
            transform(ch::TIP_FRAME, &s.tip),
        ];
        if let Some(m) = &s.frame {
            transforms.push(transform(ch::MEASURED_TIP_FRAME, m));
        }
        self.channels
            .tf
            .log_with_time(&FrameTransforms { transforms }, s.t_ns);
        self.count(ch::TF);
    }

    fn line(&mut self, t_ns: u64, level: log::Level, text: String) {
        self.channels.log.log_with_time(
            &Log {
                timestamp: Some(timestamp(t_ns)),
                level: level as i32,
                message: text,
                name: "tendril".into(),
                file: String::new(),
                line: 0,
            },
            t_ns,
        );
        self.count(ch::LOG);
    }
}

/// `v` rounded to a multiple of `1/per` (non-finite values as they are).
fn round(v: f64, per: f64) -> f64 {
    (v * per).round() / per
}

fn timestamp(t_ns: u64) -> Timestamp {
    Timestamp::new((t_ns / 1_000_000_000) as u32, (t_ns % 1_000_000_000) as u32)
}

fn rgba(r: f64, g: f64, b: f64, a: f64) -> Color {
    Color { r, g, b, a }
}

fn unit() -> Quaternion {
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 1.0,
    }
}

fn identity() -> Pose {
    Pose {
        position: Some(Vector3 {
            x: 0.0,
            y: 0.0,
            z: 0.0,
        }),
        orientation: Some(unit()),
    }
}
