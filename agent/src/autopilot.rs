//! Vehicles flown by an autopilot (PX4, ArduPilot) over MAVLink 2.
//!
//! An autopilot-driven vehicle is not a motor mixer: the autopilot closes
//! its own attitude and velocity loops and the agent hands it velocity
//! setpoints. So the robot keeps a [`crate::platform::Platform`] for its
//! limits and command mapping (a quadcopter's outputs are already a
//! normalised body twist; a rover's are wheel speeds), and replaces
//! actuators with an autopilot: the [`vehicle::AutopilotVehicle`] turns the
//! core's outputs back into the body twist they mean and sends it as a
//! SET_POSITION_TARGET_LOCAL_NED velocity setpoint, and feeds the
//! autopilot's position, velocity and battery back into the core.
//!
//! - [`config`]: `[autopilot]` in the robot's config.
//! - [`frames`]: MAVLink local NED <-> MECH (REP 103) ENU.
//! - [`session`]: the MAVLink conversation, without I/O.
//! - [`link`]: the MAVLink connection (UDP, TCP, serial) and its thread.
//! - [`vehicle`]: the [`crate::runtime::Vehicle`] the agent's loop drives.
//!
//! `docs/autopilots.md` is the user's guide.

pub mod config;
pub mod frames;
#[cfg(feature = "mavlink")]
pub mod link;
#[cfg(feature = "mavlink")]
pub mod session;
#[cfg(feature = "mavlink")]
pub mod vehicle;

pub use config::{AutopilotConfig, Flavour};
