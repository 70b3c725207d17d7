//! Manual control: gamepads (gilrs) and keyboard teleop turned into commands
//! on controller channels (`joy/N`, `key/0`).
//!
//! The pipeline is input events ([`input`]) -> shaping ([`shaping`]) ->
//! per-mode mapping ([`mapping`]) -> publish logic with dead-man, hot-plug and
//! steady rate ([`teleop`]); [`keyboard`] is the keyboard equivalent. The
//! outputs are plain values; the UI hands them to the router, which delivers
//! a channel's commands only to the robots routed to it, so re-routing a
//! robot away from a pad leaves nothing driving it.

mod config;
pub mod input;
pub mod keyboard;
pub mod mapping;
pub mod shaping;
pub mod teleop;

pub use config::{GamepadConfig, teleop_config};
pub use input::{
    GamepadError, GilrsSource, InputSource, PadAxis, PadButton, PadEvent, PadEventKind, PadId,
    ScriptedSource, spawn_pump,
};
pub use keyboard::{DriveKey, KEY_CHANNEL, KeyTeleop};
pub use mapping::{Limits, Mapped, Sticks, TeleopMode};
pub use shaping::Shaping;
pub use teleop::{PadState, Teleop, TeleopAction, TeleopConfig, TeleopOutput};
