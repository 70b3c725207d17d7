//! ROS 2 mobile bases (TurtleBot 3 and 4, Clearpath Jackal and Husky,
//! Gazebo robots) as MECH robots. The agent runs on the robot's computer
//! beside its ROS 2 stack and speaks DDS itself: it publishes the base's
//! `cmd_vel` and reads its odometry (and transforms, battery). The robot
//! keeps a [`crate::platform::Platform`] for its limits and command mapping,
//! as an autopilot-flown one does, and everything else of a MECH robot
//! (routing, missions, the safety layer, failsafe, e-stop) works as on any.
//!
//! - [`config`]: `[ros2]` in the robot's config.
//! - [`session`]: what the agent knows of the base, without I/O.
//! - [`link`]: the agent's DDS node and the base's topics.
//! - [`vehicle`]: the [`crate::runtime::Vehicle`] the agent's loop drives.
//!
//! `docs/ros2.md`, "A ROS 2 robot as a MECH robot", is the user's guide.

pub mod config;
#[cfg(feature = "ros2")]
pub mod link;
#[cfg(feature = "ros2")]
pub mod session;
#[cfg(feature = "ros2")]
pub mod vehicle;

pub use config::{CmdVelType, OdomQos, Origin, Ros2Config};
