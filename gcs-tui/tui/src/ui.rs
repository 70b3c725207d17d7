//! Terminal user interface: robot cards, braille map, waypoints, routing
//! table, events, command line and help, over the GCS core.
//!
//! [`app::App`] is the state and [`app::Action`] the only way to change it;
//! rendering (`impl Widget for &App`) is a pure function of that state, with
//! each panel a small widget of its own.

pub mod app;
pub mod layout;
pub mod view;
pub mod viewport;

pub use app::{Action, App, Focus, LogLevel, Prompt, PromptError, Request, Select};
pub use view::{
    ArenaBounds, ChannelView, ClusterControlView, ClusterOnScreen, FleetSnapshot, LinkState,
    RobotView, RouteView, SlotView,
};
pub mod cards;
pub mod events;
pub mod fixture;
pub mod help;
pub mod keys;
pub mod map;
pub mod render;
pub mod routes;
pub mod station;
pub mod status;
pub mod theme;
pub mod waypoints;

pub use station::{CoreLink, RunOptions, apply_control, demo_arena, run, snapshot};
