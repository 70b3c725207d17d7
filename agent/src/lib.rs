//! `mech-agent`: the robot side of MECH.
//!
//! A thin agent any Linux robot can run: it registers with the GCS router,
//! obeys the one channel it is routed to, runs onboard control through its
//! platform's kinematics, reports telemetry, and zeroes its actuators when
//! its controller, the router or an e-stop says so.
//!
//! - [`hal`]: hardware traits (motor, digital and PWM pins, position source,
//!   wheel encoder, datagram link); [`drivers`]: L298, UDP and serial
//!   links, Pozyx, NMEA GPS, external positions, encoder edge counting.
//! - [`platform`]: differential drive, kiwi, quadcopter.
//! - [`autopilot`]: vehicles flown by PX4 or ArduPilot over MAVLink 2.
//! - [`ros2_base`]: ROS 2 mobile bases driven through their `cmd_vel`.
//! - [`control`], [`failsafe`]: onboard control and the failsafe;
//!   [`median`]: the moving median of position fixes.
//! - [`safety`]: fleet safety, the geofence and separation filter every
//!   obeyed command passes through.
//! - [`wheels`], [`fusion`]: wheel encoders (measured speed, closed-loop
//!   wheel speed, stall detection) and odometry fused with position fixes.
//! - [`machine`]: the agent core ([`Agent`]), socket-free, one state
//!   machine per concern (registration, command intake, the e-stop,
//!   missions, sensors and faults, the autopilot queue, actuation, fleet
//!   safety, telemetry); [`runtime`]: the tokio loop around it.
//! - [`sim`]: simulated robots and fleets; [`config`]: the robot's TOML;
//!   [`launch`]: bringing a robot up from its config; [`preflight`]:
//!   `--check`'s opening of the devices the config names.

// Tests may unwrap: a panic there is a failed test, not a crashed robot.
#![cfg_attr(test, allow(clippy::unwrap_used))]

pub mod auth;
pub mod autopilot;
pub mod clock;
pub mod config;
pub mod control;
pub mod drivers;
pub mod failsafe;
pub mod fusion;
pub mod hal;
pub mod launch;
pub mod links;
pub mod machine;
pub mod median;
pub mod order;
pub mod platform;
pub mod preflight;
pub mod ros2_base;
pub mod runtime;
pub mod safety;
pub mod sim;
pub mod wheels;

pub use clock::{Clock, ManualClock, MonotonicClock};
pub use machine::{Agent, AgentSettings, Counters, Tick};
pub use platform::{Platform, PlatformSpec};
