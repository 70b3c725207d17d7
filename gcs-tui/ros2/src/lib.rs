//! `mech-ros2`: MECH robots on ROS 2. A bridge that joins a running
//! station's router as an external controller (the MECH protocol over UDP,
//! signed with its keys: the router's gate, keys and routing table apply to
//! it as to any controller) and speaks DDS natively on the other side, as
//! ROS 2 node `/mech_ros2` (`ros2-client`, RustDDS; no ROS installation).
//!
//! Out, per robot (REP 103, 105): `/<robot>/odom`, `/tf` (`map` ->
//! `<robot>/base_link`), `/<robot>/battery`, `/diagnostics`, and
//! `/mech/markers` for rviz2. In: `/<robot>/cmd_vel` as Twist commands on
//! `ros2/<robot>`, `/<robot>/goal_pose` as one-waypoint missions on
//! `ros2goal/<robot>`, `/mech/estop` as an e-stop engage. See
//! `docs/ros2.md`.
//!
//! [`bridge`] runs it; [`inbound`] and [`outbound`] are the pure
//! conversions, [`link`] the station side, [`ros`] the DDS side, and
//! [`station`] the optional attach to the station for what the protocol
//! does not carry (each robot's link quality, the arena).

pub mod bridge;
pub mod config;
pub mod fleet;
pub mod inbound;
pub mod link;
pub use mech_ros2_dds::msgs;
pub mod outbound;
pub mod ros;
pub mod station;
pub mod stats;

pub use bridge::Bridge;
pub use config::Ros2Config;
pub use stats::{Stats, StatsSnapshot};
