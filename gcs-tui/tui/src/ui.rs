//! Terminal user interface: robot cards, braille map, waypoints, routing
//! table, events, command line and help, drawn from what a station sends.
//!
//! [`app::App`] is the state and [`app::Action`] the only way to change it;
//! rendering (`impl Widget for &App`) is a pure function of that state, with
//! each panel a small widget of its own.
//!
//! - state: [`app`] (App, actions, requests, and one state per panel),
//!   [`view`] (what the station reports, as the screen shows it; shared
//!   with the station, which sends it), [`layout`] (where each panel goes), [`viewport`] (map geometry),
//!   [`labels`] (where the map's text goes so nothing overlaps),
//!   [`columns`] (the fleet table's columns, sorting and filter),
//!   [`series`] (what the plots and trends draw);
//! - drawing: [`render`] (the whole screen) over one widget per panel:
//!   [`status`], [`cards`], [`table`] (the fleet table, with a trend of
//!   its sort column), [`detail`] (one robot, with [`plots`] of its last
//!   minute), [`map`], [`waypoints`], [`routes`], [`events`] and [`help`],
//!   styled by [`theme`];
//! - input and I/O: [`keys`] (terminal events into actions), [`terminal`]
//!   (the terminal and its event loop) and [`link`] (requests carried to
//!   the station, what it sends into the App);
//! - [`fixture`]: fixed fleets for snapshots, benchmarks and tests.

pub mod app;
pub mod cards;
pub mod columns;
pub mod detail;
pub mod events;
pub mod fixture;
pub mod help;
pub mod keys;
pub mod labels;
pub mod layout;
pub mod link;
pub mod map;
pub mod plots;
pub mod render;
pub mod routes;
pub mod series;
pub mod status;
pub mod table;
pub mod terminal;
pub mod theme;
pub mod viewport;
pub mod waypoints;

pub use crate::view;
pub use app::{
    Action, App, CardsState, EventLog, FleetState, Focus, Help, History, LogLevel, LogLine,
    ManualControl, MapState, Prompt, PromptError, PromptLine, Request, RobotsView, RoutesState,
    Screen, Select, Session, TableState, WaypointsState,
};
pub use columns::Column;
pub use link::StationLink;
pub use series::Series;
pub use terminal::{RunOptions, run};
pub use view::{
    ArenaBounds, ArenaShape, ChannelView, ClusterControlView, ClusterOnScreen, FleetSnapshot,
    LinkQuality, LinkState, RobotView, RouteView, SafetyView, SlotView,
};
