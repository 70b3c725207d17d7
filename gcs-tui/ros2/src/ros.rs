//! The ROS 2 side: one node (`/mech_ros2`) on a DDS domain, through
//! `ros2-client` (RustDDS, no ROS installation). It owns the publishers
//! (per robot `/<robot>/odom` and `/<robot>/battery`; `/tf`,
//! `/diagnostics`, `/mech/markers`) and the subscriptions (per robot
//! `/<robot>/cmd_vel` and `/<robot>/goal_pose`, and `/mech/estop`). Each
//! subscription is read by a task of its own that passes samples on as
//! [`FromRos`]; nothing is checked here (see [`crate::inbound`]).

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;
use std::sync::atomic::Ordering;

use futures::StreamExt;
use ros2_client::qos::History;
use ros2_client::{
    Context, ContextOptions, Name, Node, NodeName, NodeOptions, Publisher, ServiceMapping,
    ServiceTypeName, Subscription,
};
use serde::de::DeserializeOwned;
use tokio::sync::{mpsc, oneshot};
use tracing::{debug, warn};

use crate::config::{CmdVelType, EStopService};
use crate::msgs::diagnostic::DiagnosticArray;
use crate::msgs::geometry::{PoseStamped, Twist, TwistStamped};
use crate::msgs::nav::{Odometry, TfMessage};
use crate::msgs::sensor::BatteryState;
use crate::msgs::std::{Empty, TriggerRequest, TriggerResponse};
use crate::msgs::visualization::MarkerArray;
use crate::stats::{Stats, worth_logging};

/// A sample from ROS 2, as received.
#[derive(Debug)]
pub enum FromRos {
    CmdVel {
        robot: String,
        twist: CmdVel,
    },
    Goal {
        robot: String,
        goal: PoseStamped,
    },
    /// Someone asked for the e-stop on `/mech/estop`: on the topic (no
    /// answer), or calling the service (answered on `reply`).
    EStop {
        reply: Option<oneshot::Sender<TriggerResponse>>,
    },
}

/// A cmd_vel sample of either type.
#[derive(Debug, Clone, PartialEq)]
pub enum CmdVel {
    Plain(Twist),
    Stamped(TwistStamped),
}

pub use mech_ros2_dds::node::{RosError, reliable_qos, sensor_data_qos};
use mech_ros2_dds::node::{err, publisher, subscription};

/// One robot's publishers.
struct RobotTopics {
    odom: Publisher<Odometry>,
    battery: Publisher<BatteryState>,
}

/// The bridge's node and everything it publishes or reads.
pub struct RosNode {
    context: Context,
    node: Node,
    tf: Publisher<TfMessage>,
    diagnostics: Publisher<DiagnosticArray>,
    markers: Publisher<MarkerArray>,
    robots: BTreeMap<String, RobotTopics>,
    /// Names whose cmd_vel and goal_pose are read (robots, and names other
    /// nodes publish for that are not robots, so those are counted).
    watched: BTreeSet<String>,
    cmd_vel: CmdVelType,
    to_bridge: mpsc::Sender<FromRos>,
    stats: Arc<Stats>,
}

impl std::fmt::Debug for RosNode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RosNode")
            .field("domain", &self.context.domain_id())
            .field("robots", &self.robots.len())
            .field("watched", &self.watched)
            .finish_non_exhaustive()
    }
}

impl RosNode {
    /// Joins DDS domain `domain` as node `/mech_ros2` and starts its
    /// spinner (ROS 2 graph discovery), the `/mech/estop` reader (with
    /// `estop`) and the `/mech/estop` service (in `service`'s mapping).
    pub fn start(
        domain: u16,
        cmd_vel: CmdVelType,
        estop: bool,
        service: EStopService,
        to_bridge: mpsc::Sender<FromRos>,
        stats: Arc<Stats>,
    ) -> Result<RosNode, RosError> {
        let context = Context::with_options(ContextOptions::new().domain_id(domain))
            .map_err(|e| err("cannot join the DDS domain", e))?;
        let name = NodeName::new("/", "mech_ros2").map_err(|e| err("node name", e))?;
        let mut node = context
            .new_node(name, NodeOptions::new().enable_rosout(false))
            .map_err(|e| err("cannot make the node", e))?;
        let spinner = node.spinner().map_err(|e| err("spinner", e))?;
        tokio::spawn(async move {
            if let Err(e) = spinner.spin().await {
                warn!("the ROS 2 graph spinner stopped: {e:?}");
            }
        });
        let tf = publisher::<TfMessage>(&mut node, "/tf", reliable_qos(100))?;
        let diagnostics =
            publisher::<DiagnosticArray>(&mut node, "/diagnostics", reliable_qos(10))?;
        let markers = publisher::<MarkerArray>(&mut node, "/mech/markers", reliable_qos(10))?;
        let mut ros = RosNode {
            context,
            node,
            tf,
            diagnostics,
            markers,
            robots: BTreeMap::new(),
            watched: BTreeSet::new(),
            cmd_vel,
            to_bridge,
            stats,
        };
        if estop {
            let sub = subscription::<Empty>(&mut ros.node, "/mech/estop", reliable_qos(10))?;
            let to = ros.to_bridge.clone();
            spawn_reader(
                sub,
                "/mech/estop".into(),
                move |_| Some(FromRos::EStop { reply: None }),
                to,
            );
        }
        let mapping = match service {
            EStopService::Enhanced => Some(ServiceMapping::Enhanced),
            EStopService::Cyclone => Some(ServiceMapping::Cyclone),
            EStopService::Basic => Some(ServiceMapping::Basic),
            EStopService::Off => None,
        };
        if let Some(mapping) = mapping {
            ros.serve_estop(mapping)?;
        }
        Ok(ros)
    }

    /// Answers `/mech/estop` (std_srvs/Trigger) in a task of its own: each
    /// call goes to the bridge, which engages the e-stop and says how.
    fn serve_estop(&mut self, mapping: ServiceMapping) -> Result<(), RosError> {
        let name = Name::parse("/mech/estop").map_err(|e| err("/mech/estop", e))?;
        let server = self
            .node
            .create_server::<TriggerRequest, TriggerResponse>(
                mapping,
                &name,
                &ServiceTypeName::new("std_srvs", "Trigger"),
                reliable_qos(10),
                reliable_qos(10),
            )
            .map_err(|e| err("/mech/estop service", e))?;
        let to = self.to_bridge.clone();
        tokio::spawn(async move {
            loop {
                let (id, _request) = match server.async_receive_request().await {
                    Ok(r) => r,
                    Err(e) => {
                        debug!("unreadable /mech/estop request: {e:?}");
                        continue;
                    }
                };
                let (reply, answer) = oneshot::channel();
                if to
                    .send(FromRos::EStop { reply: Some(reply) })
                    .await
                    .is_err()
                {
                    return;
                }
                let response = answer.await.unwrap_or(TriggerResponse {
                    success: false,
                    message: "the bridge is stopping".into(),
                });
                if let Err(e) = server.async_send_response(id, response).await {
                    warn!("cannot answer a /mech/estop call: {e:?}");
                }
            }
        });
        Ok(())
    }

    /// The DDS domain.
    pub fn domain(&self) -> u16 {
        self.context.domain_id()
    }

    /// Makes robot `robot`'s publishers, and reads its cmd_vel and
    /// goal_pose, if not done yet. `robot` must pass
    /// [`crate::fleet::ros_name_ok`].
    pub fn add_robot(&mut self, robot: &str) -> Result<(), RosError> {
        if !self.robots.contains_key(robot) {
            let odom = publisher::<Odometry>(
                &mut self.node,
                &format!("/{robot}/odom"),
                sensor_data_qos(),
            )?;
            let battery = publisher::<BatteryState>(
                &mut self.node,
                &format!("/{robot}/battery"),
                reliable_qos(5),
            )?;
            self.robots
                .insert(robot.to_string(), RobotTopics { odom, battery });
        }
        self.watch(robot)
    }

    /// Reads `/<name>/cmd_vel` and `/<name>/goal_pose`, if not done yet.
    pub fn watch(&mut self, name: &str) -> Result<(), RosError> {
        if self.watched.contains(name) {
            return Ok(());
        }
        let cmd_topic = format!("/{name}/cmd_vel");
        // Best effort reads from reliable and best-effort writers alike.
        let qos = sensor_data_qos().history(History::KeepLast { depth: 10 });
        let robot = name.to_string();
        match self.cmd_vel {
            CmdVelType::Twist => {
                let sub = subscription::<Twist>(&mut self.node, &cmd_topic, qos)?;
                spawn_reader(
                    sub,
                    cmd_topic,
                    move |t| {
                        Some(FromRos::CmdVel {
                            robot: robot.clone(),
                            twist: CmdVel::Plain(t),
                        })
                    },
                    self.to_bridge.clone(),
                );
            }
            CmdVelType::Stamped => {
                let sub = subscription::<TwistStamped>(&mut self.node, &cmd_topic, qos)?;
                spawn_reader(
                    sub,
                    cmd_topic,
                    move |t| {
                        Some(FromRos::CmdVel {
                            robot: robot.clone(),
                            twist: CmdVel::Stamped(t),
                        })
                    },
                    self.to_bridge.clone(),
                );
            }
        }
        let goal_topic = format!("/{name}/goal_pose");
        let sub = subscription::<PoseStamped>(&mut self.node, &goal_topic, reliable_qos(10))?;
        let robot = name.to_string();
        spawn_reader(
            sub,
            goal_topic,
            move |goal| {
                Some(FromRos::Goal {
                    robot: robot.clone(),
                    goal,
                })
            },
            self.to_bridge.clone(),
        );
        self.watched.insert(name.to_string());
        Ok(())
    }

    /// Names other nodes publish cmd_vel or goal_pose for that the bridge
    /// does not read yet (`rt/<name>/cmd_vel` on DDS).
    pub fn unwatched_publishers(&self) -> Vec<String> {
        let mut names = BTreeSet::new();
        for topic in self.context.discovered_topics() {
            let t = topic.name.as_str();
            let t = t
                .strip_prefix("rt/")
                .or_else(|| t.strip_prefix('/'))
                .unwrap_or(t);
            let name = t
                .strip_suffix("/cmd_vel")
                .or_else(|| t.strip_suffix("/goal_pose"));
            if let Some(name) = name
                && !self.watched.contains(name)
            {
                names.insert(name.to_string());
            }
        }
        names.into_iter().collect()
    }

    /// Publishes a robot's odometry.
    pub fn odometry(&self, robot: &str, o: Odometry) {
        if let Some(r) = self.robots.get(robot) {
            self.count(r.odom.publish(o).map_err(|e| format!("{e:?}")));
        }
    }

    /// Publishes a robot's battery state.
    pub fn battery(&self, robot: &str, b: BatteryState) {
        if let Some(r) = self.robots.get(robot) {
            self.count(r.battery.publish(b).map_err(|e| format!("{e:?}")));
        }
    }

    /// Publishes on `/tf`.
    pub fn tf(&self, tf: TfMessage) {
        self.count(self.tf.publish(tf).map_err(|e| format!("{e:?}")));
    }

    /// Publishes on `/diagnostics`.
    pub fn diagnostics(&self, d: DiagnosticArray) {
        self.count(self.diagnostics.publish(d).map_err(|e| format!("{e:?}")));
    }

    /// Publishes on `/mech/markers`.
    pub fn markers(&self, m: MarkerArray) {
        self.count(self.markers.publish(m).map_err(|e| format!("{e:?}")));
    }

    fn count(&self, r: Result<(), String>) {
        match r {
            Ok(()) => {
                self.stats.published.fetch_add(1, Ordering::Relaxed);
            }
            Err(e) => {
                let n = self.stats.publish_failed.fetch_add(1, Ordering::Relaxed) + 1;
                if worth_logging(n) {
                    warn!(failures = n, "DDS refused a sample: {e}");
                }
            }
        }
    }
}

/// Reads `sub` in a task of its own, passing each sample through `to_event`
/// to the bridge, until the bridge is gone.
fn spawn_reader<M, F>(
    sub: Subscription<M>,
    topic: String,
    mut to_event: F,
    to: mpsc::Sender<FromRos>,
) where
    M: DeserializeOwned + Send + Sync + 'static,
    F: FnMut(M) -> Option<FromRos> + Send + 'static,
{
    tokio::spawn(async move {
        let mut stream = std::pin::pin!(sub.async_stream());
        while let Some(sample) = stream.next().await {
            match sample {
                Ok((m, _info)) => {
                    if let Some(ev) = to_event(m)
                        && to.send(ev).await.is_err()
                    {
                        return;
                    }
                }
                // A sample that does not decode as this type (another
                // layout): nothing to forward.
                Err(e) => debug!(%topic, "unreadable sample: {e:?}"),
            }
        }
    });
}
