//! `mech-gcs`: the MECH ground-control station's terminal: the TUI and
//! gamepads, attached to a station (`mech-station`) with the attach
//! protocol, whether that station is a `mech-gcs serve` elsewhere or one
//! this process starts for itself.
//!
//! - [`ui`]: robot cards, braille map, waypoints, routing table, events;
//! - [`view`]: the fleet as the screen shows it (what a station sends:
//!   `mech_station::view`);
//! - [`gamepad`]: gamepads and keyboard teleop turned into channel
//!   commands, and the `[gamepad]` section;
//! - [`replay`]: `mech-gcs replay` in the TUI, a recording read back.

#![cfg_attr(test, allow(clippy::unwrap_used, clippy::field_reassign_with_default))]

pub mod gamepad;
pub mod replay;
pub mod ui;

pub use mech_station::view;
