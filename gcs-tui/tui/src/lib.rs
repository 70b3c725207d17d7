//! `mech-gcs`: the MECH ground-control station program: the terminal UI,
//! gamepads, the simulator for `--demo`, logging and the configuration file,
//! over the station core (`mech-core`) and its controllers and command
//! language (`mech-control`).
//!
//! - [`ui`]: robot cards, braille map, waypoints, routing table, events;
//! - [`view`]: the fleet as the screen shows it (what a station sends);
//! - [`gamepad`]: gamepads and keyboard teleop turned into channel commands;
//! - [`config`]: `gcs.toml`, assembled from each layer's section;
//! - [`foxglove`]: the Foxglove live view (`--foxglove`, cargo feature
//!   `foxglove`);
//! - [`logging`]: rolling log files;
//! - [`replay`]: `mech-gcs replay`, a recording read back;
//! - [`sim`]: simulated agents for `spawn` and `--demo`;
//! - [`station`]: `mech-gcs serve`, the attach protocol, attaching.

#![cfg_attr(test, allow(clippy::unwrap_used, clippy::field_reassign_with_default))]

pub mod config;
pub mod foxglove;
pub mod gamepad;
pub mod logging;
pub mod replay;
pub mod sim;
pub mod station;
pub mod ui;
pub mod view;

pub use config::GcsConfig;
