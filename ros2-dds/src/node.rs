//! QoS profiles as rclcpp names them, and publishers and subscriptions
//! made from a ROS 2 topic name and a [`RosMessage`] type.

use ros2_client::qos::{Durability, History, Liveliness, Reliability, WhenFull};
use ros2_client::{MessageTypeName, Name, Node, Publisher, QosProfile, Subscription};
use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::msgs::RosMessage;

/// Why a node, a topic or an endpoint could not be made.
#[derive(Debug)]
pub struct RosError(pub String);

impl std::fmt::Display for RosError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "ROS 2: {}", self.0)
    }
}

impl std::error::Error for RosError {}

/// A [`RosError`] saying what failed, with the DDS error.
pub fn err(what: &str, e: impl std::fmt::Debug) -> RosError {
    RosError(format!("{what}: {e:?}"))
}

/// Sensor data (rclcpp's `SensorDataQoS`): best effort, the last 5, volatile.
pub fn sensor_data_qos() -> QosProfile {
    QosProfile {
        reliability: Reliability::BestEffort,
        durability: Durability::Volatile,
        history: History::KeepLast { depth: 5 },
        deadline: None,
        lifespan: None,
        liveliness: Liveliness::Automatic,
        liveliness_lease: None,
    }
}

/// rclcpp's default: reliable, the last `depth`, volatile. A writer never
/// waits on a slow reader for long (it keeps the last `depth` only).
pub fn reliable_qos(depth: usize) -> QosProfile {
    sensor_data_qos()
        .reliability(Reliability::Reliable {
            when_full: WhenFull::Wait(std::time::Duration::from_millis(10)),
        })
        .history(History::KeepLast { depth })
}

fn topic<M: RosMessage>(
    node: &mut Node,
    name: &str,
    qos: &QosProfile,
) -> Result<ros2_client::dds::rustdds::Topic, RosError> {
    let n = Name::parse(name).map_err(|e| err(name, e))?;
    node.create_topic(&n, MessageTypeName::new(M::PACKAGE, M::NAME), qos)
        .map_err(|e| err(name, e))
}

/// A publisher of `M` on topic `name` (a ROS 2 name, `/tb3_1/cmd_vel`).
pub fn publisher<M: RosMessage + Serialize>(
    node: &mut Node,
    name: &str,
    qos: QosProfile,
) -> Result<Publisher<M>, RosError> {
    let t = topic::<M>(node, name, &qos)?;
    node.create_publisher(&t, Some(qos))
        .map_err(|e| err(name, e))
}

/// A subscription to `M` on topic `name`.
pub fn subscription<M: RosMessage + DeserializeOwned + 'static>(
    node: &mut Node,
    name: &str,
    qos: QosProfile,
) -> Result<Subscription<M>, RosError> {
    let t = topic::<M>(node, name, &qos)?;
    node.create_subscription(&t, Some(qos))
        .map_err(|e| err(name, e))
}
