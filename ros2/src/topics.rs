//! The one table of tendril's ROS 2 topics: name, type and QoS
//! (`docs/guide/ros2.md` prints it). Names are relative to the node's
//! namespace; QoS follows ROS 2's own profiles — sensor data best effort
//! (`rmw_qos_profile_sensor_data`: keep last 5, volatile), commands and
//! diagnostics reliable (the default profile: keep last 10), `/tf_static`
//! reliable and transient-local (tf2's latched static transforms).

use rustdds::policy::{Durability, History, Reliability};
use rustdds::{QosPolicies, QosPolicyBuilder};

/// How a topic's samples are delivered.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Qos {
    /// Best effort, keep last 5, volatile: a late sample is worth less
    /// than the next one.
    SensorData,
    /// Reliable, keep last 10, volatile: every command counts.
    Reliable,
    /// Reliable, keep last 1, transient local: a late joiner gets the last.
    Latched,
}

impl Qos {
    /// The RustDDS policies.
    pub fn policies(self) -> QosPolicies {
        let reliable = Reliability::Reliable {
            max_blocking_time: rustdds::Duration::from_millis(100),
        };
        let (reliability, depth, durability) = match self {
            Qos::SensorData => (Reliability::BestEffort, 5, Durability::Volatile),
            Qos::Reliable => (reliable, 10, Durability::Volatile),
            Qos::Latched => (reliable, 1, Durability::TransientLocal),
        };
        QosPolicyBuilder::new()
            .reliability(reliability)
            .history(History::KeepLast { depth })
            .durability(durability)
            .build()
    }
}

/// One topic: its name (relative to the namespace), ROS type and QoS.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TopicSpec {
    /// Name, without the leading namespace.
    pub name: &'static str,
    /// ROS package of the type.
    pub package: &'static str,
    /// Type name in the package.
    pub type_name: &'static str,
    /// Delivery.
    pub qos: Qos,
    /// What it carries, for the guide.
    pub what: &'static str,
}

/// Tension commands: `std_msgs/Float64MultiArray`, N, one per tendon in the
/// robot file's order (ros2_control's forward command controller's topic).
pub const COMMANDS: TopicSpec = TopicSpec {
    name: "tendon_controller/commands",
    package: "std_msgs",
    type_name: "Float64MultiArray",
    qos: Qos::Reliable,
    what: "tendon tension commands, N, robot file's order",
};

/// What the drive commanded, as `sensor_msgs/JointState` efforts (N),
/// stamped as sent: for logging and for the command's latency.
pub const COMMANDED: TopicSpec = TopicSpec {
    name: "tendon_controller/commanded",
    package: "sensor_msgs",
    type_name: "JointState",
    qos: Qos::Reliable,
    what: "the commanded tensions (effort, N), stamped when sent (`drive` only)",
};

/// Measured tendon tensions as `sensor_msgs/JointState` efforts, N.
pub const JOINT_STATES: TopicSpec = TopicSpec {
    name: "joint_states",
    package: "sensor_msgs",
    type_name: "JointState",
    qos: Qos::SensorData,
    what: "measured tendon tensions (effort, N); joints named tendon_0, tendon_1, …",
};

/// The tracker's tip pose, in the tracker's frame.
pub const TIP_POSE: TopicSpec = TopicSpec {
    name: "tip_pose",
    package: "geometry_msgs",
    type_name: "PoseStamped",
    qos: Qos::SensorData,
    what: "the tracker's tip pose (its noise, rate and latency), frame `tracker`",
};

/// The backbone for RViz, in the tracker's frame.
pub const BACKBONE: TopicSpec = TopicSpec {
    name: "backbone",
    package: "nav_msgs",
    type_name: "Path",
    qos: Qos::SensorData,
    what: "the rod's backbone, base to tip (the true shape), frame `tracker`",
};

/// The moving transforms (`base_link` → `tip`).
pub const TF: TopicSpec = TopicSpec {
    name: "/tf",
    package: "tf2_msgs",
    type_name: "TFMessage",
    qos: Qos::Reliable,
    what: "base_link → tip (the true tip)",
};

/// The fixed transforms (`tracker` → `base_link`).
pub const TF_STATIC: TopicSpec = TopicSpec {
    name: "/tf_static",
    package: "tf2_msgs",
    type_name: "TFMessage",
    qos: Qos::Latched,
    what: "tracker → base_link (the robot file's [base])",
};

/// The node's status and counters, once a second.
pub const DIAGNOSTICS: TopicSpec = TopicSpec {
    name: "/diagnostics",
    package: "diagnostic_msgs",
    type_name: "DiagnosticArray",
    qos: Qos::Reliable,
    what: "the node's status and counters (plant: steps, commands taken and refused; drive: the period's holds, stale periods, feedback refused, tracking)",
};

/// Every topic `tendril-ros2 plant` uses, commands first.
pub const PLANT_TOPICS: [TopicSpec; 7] = [
    COMMANDS,
    JOINT_STATES,
    TIP_POSE,
    BACKBONE,
    TF,
    TF_STATIC,
    DIAGNOSTICS,
];

/// Targets for the tip (`drive --target-topic`), in the tracker's frame.
pub const TARGET_POINT: TopicSpec = TopicSpec {
    name: "target_point",
    package: "geometry_msgs",
    type_name: "PointStamped",
    qos: Qos::Reliable,
    what: "a target for the tip, frame `tracker` (`drive --target-topic`)",
};

/// Targets as poses: the position is used (`drive --target-topic`).
pub const TARGET_POSE: TopicSpec = TopicSpec {
    name: "target_pose",
    package: "geometry_msgs",
    type_name: "PoseStamped",
    qos: Qos::Reliable,
    what: "a target for the tip as a pose (its position; the orientation follows from the robot), frame `tracker`",
};

/// Every topic `tendril-ros2 drive` uses.
pub const DRIVE_TOPICS: [TopicSpec; 7] = [
    COMMANDS,
    COMMANDED,
    JOINT_STATES,
    TIP_POSE,
    TARGET_POINT,
    TARGET_POSE,
    DIAGNOSTICS,
];

/// Frame ids (REP 103 units, REP 105 names).
pub mod frames {
    /// The tracker's fixed frame: every pose tendril reports is in it.
    pub const TRACKER: &str = "tracker";
    /// The robot's base (REP 105's `base_link`).
    pub const BASE: &str = "base_link";
    /// The rod's tip.
    pub const TIP: &str = "tip";
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The table's names are valid ROS names, each used once, and its QoS
    /// are the profiles the module's documentation names.
    #[test]
    fn each_topic_has_one_valid_name_and_its_profile() {
        let mut names: Vec<&str> = PLANT_TOPICS.iter().map(|t| t.name).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), PLANT_TOPICS.len());
        for t in PLANT_TOPICS.iter().chain(&DRIVE_TOPICS) {
            assert!(ros2_client::Name::parse(t.name).is_ok(), "{}", t.name);
        }
        let sensor = JOINT_STATES.qos.policies();
        assert_eq!(sensor.reliability(), Some(Reliability::BestEffort));
        assert_eq!(sensor.history(), Some(History::KeepLast { depth: 5 }));
        let latched = TF_STATIC.qos.policies();
        assert_eq!(latched.durability(), Some(Durability::TransientLocal));
        assert!(matches!(
            COMMANDS.qos.policies().reliability(),
            Some(Reliability::Reliable { .. })
        ));
    }
}
