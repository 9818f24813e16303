//! Joining a ROS 2 graph: the domain from `ROS_DOMAIN_ID` (as every ROS 2
//! node reads it), one node, and its publishers and subscriptions made from
//! the topic table ([`crate::topics`]).

use ros2_client::{
    Context, ContextOptions, MessageTypeName, Name, Node, NodeName, NodeOptions, Publisher,
    Subscription,
};
use serde::de::DeserializeOwned;
use serde::Serialize;

use crate::topics::TopicSpec;
use crate::Ros2Error;

/// The environment variable ROS 2 reads its domain from.
pub const DOMAIN_ENV: &str = "ROS_DOMAIN_ID";

/// Highest domain id ROS 2 allows on Linux (the RTPS port arithmetic's
/// limit with the default port parameters).
pub const MAX_DOMAIN_ID: u16 = 232;

/// The domain: `ROS_DOMAIN_ID` if set (0..=232), else 0.
pub fn domain_from_env() -> Result<u16, Ros2Error> {
    match std::env::var(DOMAIN_ENV) {
        Err(std::env::VarError::NotPresent) => Ok(0),
        Ok(s) if s.trim().is_empty() => Ok(0),
        Ok(s) => parse_domain(&s),
        Err(std::env::VarError::NotUnicode(_)) => Err(Ros2Error::Config(format!(
            "{DOMAIN_ENV} is not text: expected a domain id 0..={MAX_DOMAIN_ID}"
        ))),
    }
}

/// A domain id from text, 0..=[`MAX_DOMAIN_ID`].
pub fn parse_domain(s: &str) -> Result<u16, Ros2Error> {
    match s.trim().parse::<u16>() {
        Ok(d) if d <= MAX_DOMAIN_ID => Ok(d),
        _ => Err(Ros2Error::Config(format!(
            "{DOMAIN_ENV}={s:?}: expected a domain id 0..={MAX_DOMAIN_ID}"
        ))),
    }
}

/// One node on the graph, with what it needs to make its endpoints.
pub struct RosNode {
    /// Kept alive for the node's lifetime (it owns the DDS participant).
    _context: Context,
    node: Node,
    namespace: String,
}

impl RosNode {
    /// Join `domain` as `namespace`/`name` (no rosout, no parameter
    /// services: a plant or controller needs neither, and they add
    /// discovery traffic).
    pub fn new(domain: u16, namespace: &str, name: &str) -> Result<RosNode, Ros2Error> {
        let node_name = NodeName::new(namespace, name).map_err(|e| {
            Ros2Error::Config(format!(
                "node name {namespace:?} / {name:?}: {e:?} (a namespace starts with '/')"
            ))
        })?;
        let context = Context::with_options(ContextOptions::new().domain_id(domain))
            .map_err(|e| Ros2Error::Dds(format!("joining domain {domain}: {e:?}")))?;
        let node = context
            .new_node(node_name, NodeOptions::new().enable_rosout(false))
            .map_err(|e| Ros2Error::Dds(format!("creating the node: {e:?}")))?;
        Ok(RosNode {
            _context: context,
            node,
            namespace: namespace.into(),
        })
    }

    fn topic(&self, spec: &TopicSpec) -> Result<rustdds::Topic, Ros2Error> {
        let full = resolve(&self.namespace, spec.name);
        let name =
            Name::parse(&full).map_err(|e| Ros2Error::Config(format!("topic {full}: {e:?}")))?;
        self.node
            .create_topic(
                &name,
                MessageTypeName::new(spec.package, spec.type_name),
                &ros2_client::QosProfile::from(&spec.qos.policies()),
            )
            .map_err(|e| Ros2Error::Dds(format!("topic {}: {e:?}", spec.name)))
    }

    /// A publisher on `spec`'s topic with its QoS.
    pub fn publisher<M: Serialize>(&mut self, spec: &TopicSpec) -> Result<Publisher<M>, Ros2Error> {
        let topic = self.topic(spec)?;
        self.node
            .create_publisher(&topic, None)
            .map_err(|e| Ros2Error::Dds(format!("publisher on {}: {e:?}", spec.name)))
    }

    /// A subscription to `spec`'s topic with its QoS.
    pub fn subscription<M: DeserializeOwned + 'static>(
        &mut self,
        spec: &TopicSpec,
    ) -> Result<Subscription<M>, Ros2Error> {
        let topic = self.topic(spec)?;
        self.node
            .create_subscription(&topic, None)
            .map_err(|e| Ros2Error::Dds(format!("subscription to {}: {e:?}", spec.name)))
    }
}

/// A topic name made absolute in `namespace` (ROS 2's rule: a name with a
/// leading `/` is absolute, any other lives in the node's namespace).
/// Resolved here because ros2-client (0.8 to 0.12) joins the root namespace `/` and a
/// relative name with a second slash (`rt//joint_states`), a topic no other
/// ROS 2 node would match.
pub fn resolve(namespace: &str, name: &str) -> String {
    if name.starts_with('/') {
        name.into()
    } else {
        format!("{}/{name}", namespace.trim_end_matches('/'))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_names_live_in_the_namespace_and_absolute_ones_do_not() {
        assert_eq!(resolve("/", "joint_states"), "/joint_states");
        assert_eq!(
            resolve("/arm", "tendon_controller/commands"),
            "/arm/tendon_controller/commands"
        );
        assert_eq!(resolve("/arm", "/tf"), "/tf");
    }

    #[test]
    fn domain_ids_outside_ros_2s_range_are_refused_with_the_range_named() {
        assert_eq!(parse_domain("0").unwrap(), 0);
        assert_eq!(parse_domain(" 232 ").unwrap(), 232);
        for bad in ["233", "-1", "seven", "", "1.5"] {
            let e = parse_domain(bad).unwrap_err().to_string();
            assert!(
                e.contains("0..=232") && e.contains(DOMAIN_ENV),
                "{bad}: {e}"
            );
        }
    }
}
