//! `mech-ros2-dds`: what MECH's two ROS 2 parts share. The bridge
//! (`mech-ros2`) shows a station's robots to ROS 2; the agent's ROS 2 base
//! platform (`mech-agent`, feature `ros2`) drives a ROS 2 robot as a MECH
//! robot. Both speak DDS through `ros2-client` (RustDDS, no ROS
//! installation).
//!
//! - [`msgs`]: ROS 2 messages in their `.msg` field layout.
//! - [`node`]: QoS profiles as rclcpp names them, and publishers and
//!   subscriptions made from a topic name and a message type.

pub mod msgs;
pub mod node;
