//! The ROS 2 messages tendril speaks, as in common_interfaces (the same
//! fields in the same order in every distribution since Humble): serde
//! structs that ros2-client writes as CDR. Field order is the wire format,
//! so it follows the `.msg` files exactly; names are the `.msg` names.
//!
//! Written here rather than generated: the dozen types below are all
//! tendril needs, and a generator would need the ROS interface files at
//! build time (a ROS install), which this crate exists to avoid.

use ros2_client::Message;
use serde::{Deserialize, Serialize};

/// `builtin_interfaces/Time`: seconds and nanoseconds since the epoch.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Time {
    /// Whole seconds.
    pub sec: i32,
    /// Nanoseconds, 0..1e9.
    pub nanosec: u32,
}

impl Time {
    /// The wall-clock time `t` (seconds since the epoch; 0 before it).
    pub fn from_system(t: std::time::SystemTime) -> Time {
        let d = t.duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
        Time {
            sec: i32::try_from(d.as_secs()).unwrap_or(i32::MAX),
            nanosec: d.subsec_nanos(),
        }
    }

    /// The wall clock now (ROS 2's system time).
    pub fn now() -> Time {
        Time::from_system(std::time::SystemTime::now())
    }
}

/// `std_msgs/Header`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// When the data was taken.
    pub stamp: Time,
    /// The frame the data is in (REP 105 names: `docs/guide/ros2.md`).
    pub frame_id: String,
}

impl Header {
    /// A header stamped now, in `frame`.
    pub fn now(frame: &str) -> Header {
        Header {
            stamp: Time::now(),
            frame_id: frame.into(),
        }
    }
}

/// `sensor_msgs/JointState`: tendril's tendons as joints, their measured
/// tension in `effort` (N).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct JointState {
    /// Stamp and frame (the frame is not used by joint states).
    pub header: Header,
    /// Joint names, one per tendon.
    pub name: Vec<String>,
    /// Positions (tendril sends none: its drives are tension-controlled).
    pub position: Vec<f64>,
    /// Velocities (none).
    pub velocity: Vec<f64>,
    /// Efforts: tendon tensions, N.
    pub effort: Vec<f64>,
}

/// `std_msgs/MultiArrayDimension`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MultiArrayDimension {
    /// The dimension's label.
    pub label: String,
    /// Its size.
    pub size: u32,
    /// Its stride.
    pub stride: u32,
}

/// `std_msgs/MultiArrayLayout`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MultiArrayLayout {
    /// Dimensions (empty for a plain vector, as ros2_control sends).
    pub dim: Vec<MultiArrayDimension>,
    /// Padding before the data.
    pub data_offset: u32,
}

/// `std_msgs/Float64MultiArray`: a forward command controller's command,
/// one tension per tendon (N) in the robot file's order.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Float64MultiArray {
    /// Layout (ignored on input: `data` is read as one vector).
    pub layout: MultiArrayLayout,
    /// The values.
    pub data: Vec<f64>,
}

/// `geometry_msgs/Point`, m.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Point {
    /// x, m.
    pub x: f64,
    /// y, m.
    pub y: f64,
    /// z, m.
    pub z: f64,
}

/// `geometry_msgs/Quaternion` (ROS order: x, y, z, w).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }
    }
}

/// `geometry_msgs/Pose`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Position, m.
    pub position: Point,
    /// Orientation.
    pub orientation: Quaternion,
}

impl Pose {
    /// From tendril's pose `[px, py, pz, qw, qx, qy, qz]` (m; the
    /// quaternion scalar first, as in the statics).
    pub fn from_tendril(p: &[f64; 7]) -> Pose {
        Pose {
            position: Point {
                x: p[0],
                y: p[1],
                z: p[2],
            },
            orientation: Quaternion {
                x: p[4],
                y: p[5],
                z: p[6],
                w: p[3],
            },
        }
    }
}

/// `geometry_msgs/PoseStamped`: the tracker's tip pose.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseStamped {
    /// Stamp (when the tip was sampled) and frame.
    pub header: Header,
    /// The pose.
    pub pose: Pose,
}

/// `geometry_msgs/PointStamped`: a target for the tip.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PointStamped {
    /// Stamp and frame.
    pub header: Header,
    /// The point, m.
    pub point: Point,
}

/// `geometry_msgs/Vector3`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// `geometry_msgs/Transform`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    /// Translation, m.
    pub translation: Vector3,
    /// Rotation.
    pub rotation: Quaternion,
}

impl From<Pose> for Transform {
    fn from(p: Pose) -> Transform {
        Transform {
            translation: Vector3 {
                x: p.position.x,
                y: p.position.y,
                z: p.position.z,
            },
            rotation: p.orientation,
        }
    }
}

/// `geometry_msgs/TransformStamped`: `child_frame_id` in `header.frame_id`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TransformStamped {
    /// Stamp and parent frame.
    pub header: Header,
    /// The child frame.
    pub child_frame_id: String,
    /// The child's pose in the parent.
    pub transform: Transform,
}

/// `tf2_msgs/TFMessage`: what `/tf` and `/tf_static` carry.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TfMessage {
    /// The transforms.
    pub transforms: Vec<TransformStamped>,
}

/// `nav_msgs/Path`: the backbone as a line of poses, which RViz draws.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Path {
    /// Stamp and frame of the whole line.
    pub header: Header,
    /// The points, base to tip.
    pub poses: Vec<PoseStamped>,
}

/// `diagnostic_msgs/KeyValue`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct KeyValue {
    /// Key.
    pub key: String,
    /// Value, as text.
    pub value: String,
}

/// `diagnostic_msgs/DiagnosticStatus`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DiagnosticStatus {
    /// [`DiagnosticStatus::OK`], `WARN`, `ERROR` or `STALE`.
    pub level: u8,
    /// The component's name.
    pub name: String,
    /// A sentence.
    pub message: String,
    /// The hardware's id.
    pub hardware_id: String,
    /// Counters and values.
    pub values: Vec<KeyValue>,
}

impl DiagnosticStatus {
    /// Level: all is well.
    pub const OK: u8 = 0;
    /// Level: something to look at.
    pub const WARN: u8 = 1;
    /// Level: broken.
    pub const ERROR: u8 = 2;
}

/// `diagnostic_msgs/DiagnosticArray`: what `/diagnostics` carries.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DiagnosticArray {
    /// Stamp.
    pub header: Header,
    /// One status per component.
    pub status: Vec<DiagnosticStatus>,
}

impl Message for JointState {}
impl Message for Float64MultiArray {}
impl Message for PoseStamped {}
impl Message for PointStamped {}
impl Message for TfMessage {}
impl Message for Path {}
impl Message for DiagnosticArray {}
