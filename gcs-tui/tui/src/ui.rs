//! Terminal user interface: robot cards, braille map, waypoints, routing
//! table, events, command line and help, drawn from what a station sends.
//!
//! [`app::App`] is the state and [`app::Action`] the only way to change it;
//! rendering (`impl Widget for &App`) is a pure function of that state, with
//! each panel a small widget of its own.
//!
//! - state: [`app`] (App, actions, requests), [`view`] (what the station
//!   reports, as the screen shows it; shared with the station, which sends
//!   it), [`layout`] (where each panel goes) and [`viewport`] (map
//!   geometry);
//! - drawing: [`render`] (the whole screen) over one widget per panel:
//!   [`status`], [`cards`], [`map`], [`waypoints`], [`routes`], [`events`]
//!   and [`help`], styled by [`theme`];
//! - input and I/O: [`keys`] (terminal events into actions) and [`station`]
//!   (the event loop, and requests carried to the station);
//! - [`fixture`]: fixed fleets for snapshots, benchmarks and tests.

pub mod app;
pub mod cards;
pub mod events;
pub mod fixture;
pub mod help;
pub mod keys;
pub mod layout;
pub mod map;
pub mod render;
pub mod routes;
pub mod station;
pub mod status;
pub mod theme;
pub mod viewport;
pub mod waypoints;

pub use crate::view;
pub use app::{Action, App, Focus, LogLevel, Prompt, PromptError, Request, Select};
pub use station::{RunOptions, StationLink, run};
pub use view::{
    ArenaBounds, ChannelView, ClusterControlView, ClusterOnScreen, FleetSnapshot, LinkState,
    RobotView, RouteView, SlotView,
};
