//! The DDS side of a ROS 2 base: a node (`/mech_agent_<robot>`) in the
//! base's domain that publishes its `cmd_vel` and reads its odometry,
//! transforms and battery, and every writer's samples on its `cmd_vel`
//! (to hear another controller). Reads never block: the vehicle drains
//! what came each control period.

use std::collections::VecDeque;

use mech_ros2_dds::msgs::geometry::{Twist, TwistStamped};
use mech_ros2_dds::msgs::nav::{Odometry, TfMessage};
use mech_ros2_dds::msgs::sensor::BatteryState;
use mech_ros2_dds::msgs::std::Header;
use mech_ros2_dds::node::{RosError, err, publisher, reliable_qos, sensor_data_qos, subscription};
use ros2_client::{
    Context, ContextOptions, Gid, Node, NodeName, NodeOptions, Publisher, Subscription,
};

use super::config::{CmdVelType, OdomQos, Ros2Config};
use crate::hal::{ErrorKind, HalError};

/// A sample from the base's topics.
#[derive(Debug, Clone, PartialEq)]
pub enum FromBase {
    Odometry(Box<Odometry>),
    Transforms(TfMessage),
    Battery(BatteryState),
    /// A sample on the base's `cmd_vel` from another writer than the agent.
    ForeignCmdVel {
        writer: String,
    },
    /// A sample that did not decode as its topic's type.
    Unreadable {
        topic: String,
        error: String,
    },
}

/// The base's topics as the vehicle uses them; tests play the base.
pub trait BasePort: Send {
    /// Publishes the velocity command (a `Twist` or `TwistStamped`).
    fn publish(&mut self, twist: &Twist, stamp_micros: u64) -> Result<(), HalError>;
    /// The next sample heard, if any; never blocks.
    fn try_recv(&mut self) -> Option<FromBase>;
}

enum CmdVelWriter {
    Plain(Publisher<Twist>),
    Stamped(Publisher<TwistStamped>, String),
}

enum CmdVelReader {
    Plain(Subscription<Twist>),
    Stamped(Subscription<TwistStamped>),
}

/// The agent's node on the base's DDS domain. The endpoints are declared
/// before the node and the context, so they are dropped first (RustDDS
/// removes an endpoint through its participant).
pub struct DdsBase {
    cmd_vel: CmdVelWriter,
    own_writer: Gid,
    cmd_vel_topic: String,
    watch: CmdVelReader,
    odom: Subscription<Odometry>,
    odom_topic: String,
    tf: Option<(Subscription<TfMessage>, String)>,
    battery: Option<(Subscription<BatteryState>, String)>,
    queue: VecDeque<FromBase>,
    _node: Node,
    _context: Context,
}

impl std::fmt::Debug for DdsBase {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DdsBase")
            .field("cmd_vel", &self.cmd_vel_topic)
            .field("odom", &self.odom_topic)
            .finish_non_exhaustive()
    }
}

/// A node name for the robot: `mech_agent_<robot>`, other characters `_`.
fn node_name(robot: &str) -> String {
    let body: String = robot
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    format!("mech_agent_{body}")
}

impl DdsBase {
    /// Joins `domain` as `/<namespace>/mech_agent_<robot>` with the base's
    /// topics; spawns the node's graph spinner on the current tokio
    /// runtime.
    pub fn open(config: &Ros2Config, robot: &str, domain: u16) -> Result<DdsBase, RosError> {
        let context = Context::with_options(ContextOptions::new().domain_id(domain))
            .map_err(|e| err("cannot join the DDS domain", e))?;
        let namespace = if config.namespace.is_empty() {
            "/"
        } else {
            config.namespace.as_str()
        };
        let name = NodeName::new(namespace, &node_name(robot)).map_err(|e| err("node name", e))?;
        let mut node = context
            .new_node(
                name,
                NodeOptions::new()
                    .enable_rosout(false)
                    .start_parameter_services(false),
            )
            .map_err(|e| err("cannot make the node", e))?;
        let spinner = node.spinner().map_err(|e| err("spinner", e))?;
        tokio::spawn(async move {
            if let Err(e) = spinner.spin().await {
                tracing::warn!("the ROS 2 graph spinner stopped: {e:?}");
            }
        });
        let cmd_vel_topic = config.resolve(&config.cmd_vel);
        // cmd_vel as teleop nodes and Nav2 publish it: reliable.
        let (cmd_vel, own_writer, watch) = match config.cmd_vel_type {
            CmdVelType::Twist => {
                let p = publisher::<Twist>(&mut node, &cmd_vel_topic, reliable_qos(10))?;
                let gid = Gid::from(p.guid());
                let w = subscription::<Twist>(&mut node, &cmd_vel_topic, sensor_data_qos())?;
                (CmdVelWriter::Plain(p), gid, CmdVelReader::Plain(w))
            }
            CmdVelType::TwistStamped => {
                let p = publisher::<TwistStamped>(&mut node, &cmd_vel_topic, reliable_qos(10))?;
                let gid = Gid::from(p.guid());
                let w = subscription::<TwistStamped>(&mut node, &cmd_vel_topic, sensor_data_qos())?;
                let frame = config.cmd_vel_frame.clone();
                (
                    CmdVelWriter::Stamped(p, frame),
                    gid,
                    CmdVelReader::Stamped(w),
                )
            }
        };
        let odom_topic = config.resolve(&config.odom);
        let odom_qos = match config.odom_qos {
            OdomQos::BestEffort => sensor_data_qos(),
            OdomQos::Reliable => reliable_qos(5),
        };
        let odom = subscription::<Odometry>(&mut node, &odom_topic, odom_qos)?;
        let tf = if config.map_frame.is_empty() {
            None
        } else {
            let topic = config.resolve(&config.tf);
            let sub = subscription::<TfMessage>(&mut node, &topic, reliable_qos(100))?;
            Some((sub, topic))
        };
        let battery = if config.battery.is_empty() {
            None
        } else {
            let topic = config.resolve(&config.battery);
            // Best effort reads reliable and best-effort writers alike.
            let sub = subscription::<BatteryState>(&mut node, &topic, sensor_data_qos())?;
            Some((sub, topic))
        };
        Ok(DdsBase {
            cmd_vel,
            own_writer,
            cmd_vel_topic,
            watch,
            odom,
            odom_topic,
            tf,
            battery,
            queue: VecDeque::new(),
            _node: node,
            _context: context,
        })
    }

    /// Everything each subscription has, into the queue.
    fn drain(&mut self) {
        drain(
            &self.odom,
            &self.odom_topic,
            |o| FromBase::Odometry(Box::new(o)),
            &mut self.queue,
        );
        if let Some((sub, topic)) = &self.tf {
            drain(sub, topic, FromBase::Transforms, &mut self.queue);
        }
        if let Some((sub, topic)) = &self.battery {
            drain(sub, topic, FromBase::Battery, &mut self.queue);
        }
        let own = self.own_writer;
        let topic = &self.cmd_vel_topic;
        match &self.watch {
            CmdVelReader::Plain(sub) => drain_writers(sub, own, topic, &mut self.queue),
            CmdVelReader::Stamped(sub) => drain_writers(sub, own, topic, &mut self.queue),
        }
    }
}

/// At most this many samples of one topic are taken per drain, so a flood
/// cannot hold the control loop.
const DRAIN: usize = 256;

fn drain<M>(
    sub: &Subscription<M>,
    topic: &str,
    wrap: fn(M) -> FromBase,
    queue: &mut VecDeque<FromBase>,
) where
    M: serde::de::DeserializeOwned + 'static,
{
    for _ in 0..DRAIN {
        match sub.take() {
            Ok(Some((m, _))) => queue.push_back(wrap(m)),
            Ok(None) => break,
            Err(e) => queue.push_back(FromBase::Unreadable {
                topic: topic.to_string(),
                error: format!("{e:?}"),
            }),
        }
    }
}

fn drain_writers<M>(sub: &Subscription<M>, own: Gid, topic: &str, queue: &mut VecDeque<FromBase>)
where
    M: serde::de::DeserializeOwned + 'static,
{
    for _ in 0..DRAIN {
        match sub.take() {
            Ok(Some((_, info))) if info.publisher_gid() != own => {
                queue.push_back(FromBase::ForeignCmdVel {
                    writer: format!("{:?}", info.publisher_gid()),
                });
            }
            Ok(Some(_)) => {}
            Ok(None) => break,
            Err(e) => queue.push_back(FromBase::Unreadable {
                topic: topic.to_string(),
                error: format!("{e:?}"),
            }),
        }
    }
}

impl BasePort for DdsBase {
    fn publish(&mut self, twist: &Twist, stamp_micros: u64) -> Result<(), HalError> {
        let sent = match &self.cmd_vel {
            CmdVelWriter::Plain(p) => p.publish(*twist).map_err(|e| format!("{e:?}")),
            CmdVelWriter::Stamped(p, frame) => p
                .publish(TwistStamped {
                    header: Header {
                        stamp: mech_ros2_dds::msgs::builtin::Time::from_micros(stamp_micros),
                        frame_id: frame.clone(),
                    },
                    twist: *twist,
                })
                .map_err(|e| format!("{e:?}")),
        };
        sent.map_err(|e| {
            HalError::new(
                ErrorKind::Other,
                format!("cmd_vel on {}: {e}", self.cmd_vel_topic),
            )
        })
    }

    fn try_recv(&mut self) -> Option<FromBase> {
        if self.queue.is_empty() {
            self.drain();
        }
        self.queue.pop_front()
    }
}

#[cfg(test)]
mod tests {
    use super::node_name;

    #[test]
    fn node_names_are_ros_names() {
        assert_eq!(node_name("tb3_1"), "mech_agent_tb3_1");
        assert_eq!(node_name("kiwi-2.b"), "mech_agent_kiwi_2_b");
    }
}
