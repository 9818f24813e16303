//! `tendril-ros2 plant`: tendril's plant ([`PlantModel`]: motors, the rod
//! quasi-static or dynamic, any reality, the tracker) as a robot on a ROS 2
//! graph. A lab's controller sends tensions as a forward command
//! controller would and reads the tendons' tensions and the tracker's tip
//! back, exactly as from its real robot's driver and tracker.
//!
//! A task in the copper-rs sense: [`PlantNode::new`] sets everything up
//! once, [`PlantNode::step`] is one period — take the commands, move the
//! plant by the time that passed, publish — and [`run`] calls it on an
//! absolute-deadline clock.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant, SystemTime};

use ros2_client::{Publisher, Subscription};
use serde::Serialize;
use tendril::plant::{PlantModel, PlantParams};
use tendril::robot::Robot;

use crate::msg::{
    DiagnosticArray, DiagnosticStatus, Float64MultiArray, Header, JointState, KeyValue, Path, Pose,
    PoseStamped, TfMessage, Time, TransformStamped,
};
use crate::node::RosNode;
use crate::topics::{self, frames};
use crate::Ros2Error;

/// Most commands taken in one period: a flood cannot stall the plant.
const MAX_TAKES_PER_STEP: usize = 64;

/// Everything the plant node needs, set once.
#[derive(Clone, Debug)]
pub struct PlantNodeConfig {
    /// The robot file's robot (the reality in `params` changes the one
    /// that moves).
    pub robot: Robot,
    /// Motors, tracker, model, reality.
    pub params: PlantParams,
    /// Plant steps (and joint states) per second.
    pub rate_hz: f64,
    /// Backbone and `/tf` messages per second.
    pub scene_hz: f64,
    /// Points along the published backbone.
    pub backbone_points: usize,
    /// Stop after this long (None: until a signal).
    pub duration_s: Option<f64>,
    /// ROS domain.
    pub domain: u16,
    /// Node namespace (`/` or `/name`).
    pub namespace: String,
    /// Statistics JSON written at exit.
    pub stats: Option<PathBuf>,
}

impl PlantNodeConfig {
    /// Refuse rates and counts the loop cannot run with, naming the flag.
    pub fn validate(&self) -> Result<(), Ros2Error> {
        let bad = |flag: &str, v: f64, want: &str| {
            Err(Ros2Error::Config(format!("{flag} {v}: expected {want}")))
        };
        if !(self.rate_hz.is_finite() && (1.0..=2000.0).contains(&self.rate_hz)) {
            return bad("--rate", self.rate_hz, "1 to 2000 steps per second");
        }
        if !(self.scene_hz.is_finite() && self.scene_hz > 0.0 && self.scene_hz <= self.rate_hz) {
            return bad("--scene-hz", self.scene_hz, "> 0 and at most --rate");
        }
        if self.backbone_points < 2 {
            return bad(
                "--backbone-points",
                self.backbone_points as f64,
                "at least 2",
            );
        }
        if let Some(d) = self.duration_s {
            if !(d.is_finite() && d > 0.0) {
                return bad("--duration", d, "a number of seconds > 0");
            }
        }
        Ok(())
    }
}

/// What the plant node counted, written as JSON at exit.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct PlantNodeStats {
    /// Plant steps taken.
    pub steps: u64,
    /// Periods that started more than a period late (the clock skipped).
    pub overruns: u64,
    /// Commands applied (saturated ones included).
    pub commands: u64,
    /// Commands applied after saturation to a motor's range.
    pub saturated: u64,
    /// Commands refused: not one value per tendon.
    pub refused_length: u64,
    /// Commands refused: a value not finite.
    pub refused_not_finite: u64,
    /// Samples that could not be read as a `Float64MultiArray`.
    pub refused_malformed: u64,
    /// Seconds from the start to the first command applied (None: none).
    pub first_command_s: Option<f64>,
    /// Tracker frames published on the tip topic.
    pub tip_frames: u64,
    /// Statics or dynamics solves that failed (the last pose kept).
    pub solve_failures: u64,
    /// Seconds the node ran.
    pub duration_s: f64,
}

/// The node's publishers and its one subscription.
struct Endpoints {
    commands: Subscription<Float64MultiArray>,
    joint_states: Publisher<JointState>,
    tip_pose: Publisher<PoseStamped>,
    backbone: Publisher<Path>,
    tf: Publisher<TfMessage>,
    diagnostics: Publisher<DiagnosticArray>,
    /// `tracker` → `base_link`: latched, and sent again with each
    /// diagnostics message (RustDDS keeps no history for a late-joining
    /// transient-local reader; tf2 takes a repeated static transform as is).
    tf_static: Publisher<TfMessage>,
    base: TfMessage,
}

/// The plant on the graph: set up once, stepped each period.
pub struct PlantNode {
    model: PlantModel,
    ends: Endpoints,
    /// Kept alive for the endpoints' lifetime.
    _node: RosNode,
    joint_names: Vec<String>,
    /// Wall-clock time at `start` (message stamps).
    wall_start: SystemTime,
    start: Instant,
    last: Instant,
    next_scene: Instant,
    next_diagnostics: Instant,
    scene_period: Duration,
    backbone_points: usize,
    last_frame_seq: u32,
    stats: PlantNodeStats,
}

impl PlantNode {
    /// Build the plant, join the graph and publish `/tf_static`.
    pub fn new(cfg: &PlantNodeConfig) -> Result<PlantNode, Ros2Error> {
        cfg.validate()?;
        let model = PlantModel::new(&cfg.robot, cfg.params.clone())
            .map_err(|e| Ros2Error::Config(e.to_string()))?;
        let mut node = RosNode::new(cfg.domain, &cfg.namespace, "tendril_plant")?;
        let ends = Endpoints {
            commands: node.subscription(&topics::COMMANDS)?,
            joint_states: node.publisher(&topics::JOINT_STATES)?,
            tip_pose: node.publisher(&topics::TIP_POSE)?,
            backbone: node.publisher(&topics::BACKBONE)?,
            tf: node.publisher(&topics::TF)?,
            diagnostics: node.publisher(&topics::DIAGNOSTICS)?,
            tf_static: node.publisher(&topics::TF_STATIC)?,
            base: TfMessage {
                transforms: vec![TransformStamped {
                    header: Header::now(frames::TRACKER),
                    child_frame_id: frames::BASE.into(),
                    transform: Pose::from_tendril(&model.base_pose()).into(),
                }],
            },
        };
        let now = Instant::now();
        Ok(PlantNode {
            joint_names: (0..model.n()).map(|i| format!("tendon_{i}")).collect(),
            model,
            ends,
            _node: node,
            wall_start: SystemTime::now(),
            start: now,
            last: now,
            next_scene: now,
            next_diagnostics: now,
            scene_period: Duration::from_secs_f64(1.0 / cfg.scene_hz),
            backbone_points: cfg.backbone_points,
            last_frame_seq: 0,
            stats: PlantNodeStats::default(),
        })
    }

    /// What was counted so far.
    pub fn stats(&self) -> &PlantNodeStats {
        &self.stats
    }

    /// One period at `now`: apply the newest valid command, move the plant
    /// by the time since the last step, publish what is due.
    pub fn step(&mut self, now: Instant) {
        self.take_commands(now);
        let dt = now.saturating_duration_since(self.last).as_secs_f64();
        self.last = now;
        if !self.model.step(dt) {
            self.stats.solve_failures += 1;
        }
        let t_ns = now.saturating_duration_since(self.start).as_nanos() as u64;
        self.model.sense(t_ns);
        self.stats.steps += 1;
        self.publish(now);
    }

    fn take_commands(&mut self, now: Instant) {
        for _ in 0..MAX_TAKES_PER_STEP {
            let cmd = match self.ends.commands.take() {
                Ok(Some((cmd, _))) => cmd,
                Ok(None) => break,
                Err(e) => {
                    log::debug!("a command that is not a Float64MultiArray: {e:?}");
                    self.stats.refused_malformed += 1;
                    continue;
                }
            };
            if cmd.data.len() != self.model.n() {
                self.stats.refused_length += 1;
                continue;
            }
            if !cmd.data.iter().all(|t| t.is_finite()) {
                self.stats.refused_not_finite += 1;
                continue;
            }
            if self.model.command(&cmd.data) {
                self.stats.saturated += 1;
            }
            self.stats.commands += 1;
            self.stats
                .first_command_s
                .get_or_insert(now.saturating_duration_since(self.start).as_secs_f64());
        }
    }

    /// The wall-clock stamp of plant time `t_ns`.
    fn stamp(&self, t_ns: u64) -> Time {
        Time::from_system(self.wall_start + Duration::from_nanos(t_ns))
    }

    fn publish(&mut self, now: Instant) {
        let t_ns = now.saturating_duration_since(self.start).as_nanos() as u64;
        let stamp = self.stamp(t_ns);
        let header = |frame: &str| Header {
            stamp,
            frame_id: frame.into(),
        };
        // A best-effort or full reliable queue drops a sample; the next
        // period sends a newer one, so a failed write is not an error here.
        let _ = self.ends.joint_states.publish(JointState {
            header: header(""),
            name: self.joint_names.clone(),
            effort: self.model.tensions().to_vec(),
            ..JointState::default()
        });
        if let Some(frame) = self.model.frame().copied() {
            if frame.seq != self.last_frame_seq {
                self.last_frame_seq = frame.seq;
                let _ = self.ends.tip_pose.publish(PoseStamped {
                    header: Header {
                        stamp: self.stamp(frame.stamp_ns),
                        frame_id: frames::TRACKER.into(),
                    },
                    pose: Pose::from_tendril(&frame.pose),
                });
                self.stats.tip_frames += 1;
            }
        }
        if now >= self.next_scene {
            self.next_scene = now + self.scene_period;
            self.publish_scene(stamp);
        }
        if now >= self.next_diagnostics {
            self.next_diagnostics = now + Duration::from_secs(1);
            let _ = self.ends.diagnostics.publish(self.diagnostics(stamp));
            let _ = self.ends.tf_static.publish(self.ends.base.clone());
        }
    }

    /// The backbone and `base_link` → `tip`.
    fn publish_scene(&mut self, stamp: Time) {
        let header = |frame: &str| Header {
            stamp,
            frame_id: frame.into(),
        };
        if let Some(shape) = self.model.shape(self.backbone_points) {
            let poses = shape
                .backbone
                .iter()
                .map(|p| PoseStamped {
                    header: header(frames::TRACKER),
                    pose: Pose::from_tendril(&[p.x, p.y, p.z, 1.0, 0.0, 0.0, 0.0]),
                })
                .collect();
            let _ = self.ends.backbone.publish(Path {
                header: header(frames::TRACKER),
                poses,
            });
        }
        let tip_in_base = self.model.pose_in_base();
        let _ = self.ends.tf.publish(TfMessage {
            transforms: vec![TransformStamped {
                header: header(frames::BASE),
                child_frame_id: frames::TIP.into(),
                transform: Pose::from_tendril(&tip_in_base).into(),
            }],
        });
    }

    fn diagnostics(&self, stamp: Time) -> DiagnosticArray {
        let s = &self.stats;
        let refused = s.refused_length + s.refused_not_finite + s.refused_malformed;
        let (level, message) = if s.commands == 0 {
            (DiagnosticStatus::WARN, "no tension command yet")
        } else if refused > 0 || s.solve_failures > 0 {
            (DiagnosticStatus::WARN, "commands refused or solves failed")
        } else {
            (DiagnosticStatus::OK, "running")
        };
        let kv = |key: &str, value: u64| KeyValue {
            key: key.into(),
            value: value.to_string(),
        };
        DiagnosticArray {
            header: Header {
                stamp,
                frame_id: String::new(),
            },
            status: vec![DiagnosticStatus {
                level,
                name: "tendril_plant".into(),
                message: message.into(),
                hardware_id: "tendril simulated plant".into(),
                values: vec![
                    kv("steps", s.steps),
                    kv("overruns", s.overruns),
                    kv("commands", s.commands),
                    kv("saturated", s.saturated),
                    kv("refused_length", s.refused_length),
                    kv("refused_not_finite", s.refused_not_finite),
                    kv("refused_malformed", s.refused_malformed),
                    kv("solve_failures", s.solve_failures),
                ],
            }],
        }
    }
}

/// Run the plant node until `stop`, the duration, or an error; writes the
/// statistics if asked.
pub fn run(cfg: &PlantNodeConfig, stop: &AtomicBool) -> Result<PlantNodeStats, Ros2Error> {
    let mut node = PlantNode::new(cfg)?;
    let period = Duration::from_secs_f64(1.0 / cfg.rate_hz);
    let end = cfg
        .duration_s
        .map(|d| node.start + Duration::from_secs_f64(d));
    let mut deadline = node.start;
    while !stop.load(Ordering::Relaxed) && end.is_none_or(|e| Instant::now() < e) {
        node.step(Instant::now());
        deadline += period;
        let now = Instant::now();
        if now > deadline + period {
            node.stats.overruns += 1;
            deadline = now;
        } else if deadline > now {
            std::thread::sleep(deadline - now);
        }
    }
    node.stats.duration_s = node.start.elapsed().as_secs_f64();
    if let Some(path) = &cfg.stats {
        let json = serde_json::to_vec_pretty(&node.stats)
            .map_err(|e| Ros2Error::Config(format!("statistics: {e}")))?;
        tendril::fsutil::write_atomic(path, &json)
            .map_err(|e| Ros2Error::Output(format!("{}: {e}", path.display())))?;
    }
    Ok(node.stats)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config() -> PlantNodeConfig {
        PlantNodeConfig {
            robot: tendril::robot::repo_robot("seed-4t.toml"),
            params: PlantParams::default(),
            rate_hz: 200.0,
            scene_hz: 30.0,
            backbone_points: 32,
            duration_s: None,
            domain: 0,
            namespace: "/".into(),
            stats: None,
        }
    }

    #[test]
    fn rates_the_loop_cannot_keep_are_refused_with_their_flag() {
        assert!(config().validate().is_ok());
        for (cfg, flag) in [
            (
                PlantNodeConfig {
                    rate_hz: 0.0,
                    ..config()
                },
                "--rate",
            ),
            (
                PlantNodeConfig {
                    rate_hz: f64::NAN,
                    ..config()
                },
                "--rate",
            ),
            (
                PlantNodeConfig {
                    scene_hz: 400.0,
                    ..config()
                },
                "--scene-hz",
            ),
            (
                PlantNodeConfig {
                    backbone_points: 1,
                    ..config()
                },
                "--backbone-points",
            ),
            (
                PlantNodeConfig {
                    duration_s: Some(-1.0),
                    ..config()
                },
                "--duration",
            ),
        ] {
            let e = cfg.validate().unwrap_err().to_string();
            assert!(e.contains(flag), "{e}");
        }
    }
}
