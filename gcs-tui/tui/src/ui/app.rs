//! The UI state machine: [`App`] holds everything the screen shows, every
//! user intent is an [`Action`], and [`App::update`] is the only place state
//! changes. What must reach the robots is queued as [`Request`]s that the
//! event loop hands to the station; the App itself does no I/O.
//!
//! The App is a handful of per-panel states, each a struct in a file of its
//! own with the changes that concern it and its tests, and the actions that
//! reach across panels as `impl App` beside it:
//! - `fleet` ([`FleetState`]): the robots, channels and clusters as the
//!   station reports them, the e-stop, security and refusals; clusters made
//!   here and the navigation switch;
//! - `session` ([`Session`]): the station this TUI speaks to, as whom, and
//!   how it draws;
//! - `screen` ([`Screen`]): terminal size, focus, the side column, cards or
//!   table, the help;
//! - `map` ([`MapState`]): the viewport, the arena, the robot under the
//!   pointer, a drag;
//! - `cards` ([`CardsState`]): the selection and the cards' scroll;
//! - `table` ([`TableState`]): the fleet table's order, filter, rows,
//!   cursor and detail;
//! - `waypoints` ([`WaypointsState`]): the list being edited and placing
//!   mode;
//! - `routes` ([`RoutesState`]): the routing table's cursor and re-routing;
//! - `events` ([`EventLog`]): the events pane's lines;
//! - `prompt` ([`PromptLine`]): the command line, waypoint entry and the
//!   table's filter as typed, the history, the last error;
//! - `manual` ([`ManualControl`]): keyboard teleop and gamepads on the App's
//!   own clock;
//! - `history` ([`History`]): each robot's last minute, sampled from the
//!   snapshots, for the plots and the table's trends;
//! - `mouse`: clicks, drags, the wheel and hovering resolved against the
//!   layout (no state of its own).

use std::time::Instant;

use mech_proto::{ClusterVelocity, Command, Waypoint};

use super::columns::Column;
use super::layout::Areas;
use super::view::{FleetSnapshot, RobotView};
use crate::gamepad::{DriveKey, PadEvent};

mod cards;
mod events;
mod fleet;
mod history;
mod manual;
mod map;
mod mouse;
mod prompt;
mod routes;
mod screen;
mod session;
mod table;
mod waypoints;

pub use cards::CardsState;
pub use events::{EventLog, LogLevel, LogLine};
pub use fleet::FleetState;
pub use history::{HISTORY_SECONDS, History, RobotHistory, SAMPLE_PERIOD, Sample};
pub use manual::ManualControl;
pub use map::MapState;
pub use prompt::{Prompt, PromptError, PromptLine, parse_waypoint};
pub use routes::RoutesState;
pub use screen::{Focus, Help, RobotsView, Screen};
pub use session::Session;
pub use table::TableState;
pub use waypoints::WaypointsState;

/// Channel the UI publishes waypoint missions on.
pub const WAYPOINT_CHANNEL: &str = "wp/gcs";

pub use crate::view::TRAIL_SECONDS;

/// Selection changes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Select {
    /// Only this robot.
    Only(String),
    /// Add or remove this robot.
    Toggle(String),
    Next,
    Prev,
    /// Add the robot after the last selected one.
    AddNext,
    /// Add the robot before the first selected one.
    AddPrev,
    All,
    Clear,
    /// Every member of a cluster.
    Cluster(String),
}

/// Everything that can happen to the UI.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// Render tick: time moves on (teleop rates, trails).
    Tick(Instant),
    Resize(u16, u16),
    Quit,
    ToggleHelp,
    /// Scroll the help by entries (down positive).
    HelpScroll(i32),
    /// Fresh state from the core.
    Fleet(FleetSnapshot),
    Select(Select),
    /// Left click at an absolute terminal cell; `add` when shift/ctrl held.
    Click {
        col: u16,
        row: u16,
        add: bool,
    },
    /// Mouse drag to a cell (pans the map).
    Drag {
        col: u16,
        row: u16,
    },
    /// Mouse button released.
    MouseUp,
    /// The pointer moved over a cell (the robot under it is labelled).
    Hover {
        col: u16,
        row: u16,
    },
    /// Mouse wheel over a cell: zoom about it (`steps` > 0 zooms in).
    Scroll {
        col: u16,
        row: u16,
        steps: i32,
    },
    Zoom(f64),
    /// Pan by cells (right / up positive).
    Pan(f64, f64),
    FitFleet,
    FocusNext,
    FocusPrev,
    MakeCluster,
    /// Enter or leave waypoint mode.
    WaypointMode(bool),
    AddWaypoint(Waypoint),
    RemoveLastWaypoint,
    ClearWaypoints,
    /// Send the waypoint list to the selected robots.
    SendWaypoints,
    OpenCommandLine,
    OpenWaypointEntry,
    PromptChar(char),
    PromptBackspace,
    PromptSubmit,
    PromptCancel,
    HistoryPrev,
    HistoryNext,
    /// Outcome of a command line the core ran.
    CommandResult(Result<String, PromptError>),
    /// Move the routing-table cursor (robot rows, channel columns).
    RouteCursor(i32, i32),
    /// Route the robot under the cursor to the channel under the cursor.
    ApplyRouteCursor,
    Route {
        robot: String,
        channel: String,
    },
    EStop,
    Release,
    ToggleKeyTeleop,
    /// Move the selected robots' waypoint navigation to the other side
    /// (onboard <-> offboard).
    ToggleNav,
    /// Start recording into the recording directory, or stop.
    ToggleRecording,
    Drive(DriveKey),
    DriveStop,
    Pad(PadEvent),
    Log(LogLevel, String),
    /// The fleet table in place of the cards and the map, or back.
    ToggleTable,
    /// Sort the table by a column; the column it is sorted by already:
    /// reverse.
    SortBy(Column),
    /// Sort by the column `n` places after the current one.
    SortStep(i32),
    SortReverse,
    /// Open the table (if need be) and its `/` filter.
    OpenFilter,
    ClearFilter,
    /// Move the table's cursor by rows (selecting only that robot).
    TableMove(i32),
    /// The cursor's robot in detail, or back to the table.
    ToggleDetail,
    CloseDetail,
}

/// What the core must do on the UI's behalf.
#[derive(Debug, Clone, PartialEq)]
pub enum Request {
    Route {
        robot: String,
        channel: String,
    },
    /// Upload a waypoint mission on [`WAYPOINT_CHANNEL`] to each robot.
    Mission {
        robots: Vec<String>,
        waypoints: Vec<Waypoint>,
    },
    EStop {
        engage: bool,
    },
    /// A teleop command on `channel` for the robots routed to it.
    Publish {
        channel: String,
        robots: Vec<String>,
        command: Command,
    },
    /// A cluster velocity from a pad in cluster mode, for the active
    /// cluster; it goes to the cluster controller on `fleet/<cluster>`,
    /// which knows the members.
    ClusterVelocity {
        cluster: String,
        velocity: ClusterVelocity,
    },
    DefineCluster {
        name: String,
        members: Vec<String>,
    },
    /// Switch each robot's waypoint navigation between the agent and the
    /// GCS loop (`offboard/<robot>`), keeping the mission's progress.
    ToggleNav {
        robots: Vec<String>,
    },
    /// A command-language line for the core's executor.
    Exec(String),
    Quit,
}

/// The whole UI state: one state per panel. Rendering is a pure function
/// of it.
#[derive(Debug)]
pub struct App {
    pub fleet: FleetState,
    pub session: Session,
    pub screen: Screen,
    pub map: MapState,
    pub cards: CardsState,
    pub table: TableState,
    pub waypoints: WaypointsState,
    pub routes: RoutesState,
    pub events: EventLog,
    pub prompt: PromptLine,
    pub manual: ManualControl,
    pub history: History,
    /// False once the operator quit: the event loop ends.
    pub running: bool,
    outbox: Vec<Request>,
}

impl App {
    pub fn new(router_addr: impl Into<String>, now: Instant) -> App {
        App {
            fleet: FleetState::default(),
            session: Session::new(router_addr),
            screen: Screen::default(),
            map: MapState::default(),
            cards: CardsState::default(),
            table: TableState::default(),
            waypoints: WaypointsState::default(),
            routes: RoutesState::default(),
            events: EventLog::default(),
            prompt: PromptLine::default(),
            manual: ManualControl::new(now),
            history: History::new(now),
            running: true,
            outbox: Vec::new(),
        }
    }

    /// Requests queued since the last call, oldest first.
    pub fn take_requests(&mut self) -> Vec<Request> {
        std::mem::take(&mut self.outbox)
    }

    /// The current layout.
    pub fn areas(&self) -> Areas {
        self.screen.areas()
    }

    pub fn robot(&self, name: &str) -> Option<&RobotView> {
        self.fleet.robot(name)
    }

    /// Adds a line to the events pane.
    pub fn log(&mut self, level: LogLevel, text: impl Into<String>) {
        self.events.push(level, text);
    }

    /// Applies one action: a flat dispatch, to the panel's state or to the
    /// App where an action reaches across panels.
    pub fn update(&mut self, action: Action) {
        match action {
            Action::Tick(now) => self.tick(now),
            Action::Resize(w, h) => self.screen.size = (w, h),
            Action::Quit => self.quit(),
            Action::ToggleHelp => self.screen.help.toggle(),
            Action::HelpScroll(d) => self.screen.scroll_help(d),
            Action::Fleet(snapshot) => self.apply_snapshot(snapshot),
            Action::ToggleRecording => self.outbox.push(Request::Exec("record toggle".into())),
            Action::Select(s) => self.select(s),
            Action::Click { col, row, add } => self.click(col, row, add),
            Action::Drag { col, row } => self.map.drag_to(col, row),
            Action::MouseUp => self.map.end_drag(),
            Action::Hover { col, row } => self.hover(col, row),
            Action::Scroll { col, row, steps } => self.scroll(col, row, steps),
            Action::Zoom(f) => self.map.viewport.zoom(f),
            Action::Pan(dx, dy) => self.map.viewport.pan_cells(dx, dy),
            Action::FitFleet => self.fit_fleet(),
            Action::FocusNext => self.screen.step_focus(Focus::next),
            Action::FocusPrev => self.screen.step_focus(Focus::prev),
            Action::MakeCluster => self.make_cluster(),
            Action::WaypointMode(on) => self.set_waypoint_mode(on),
            Action::AddWaypoint(w) => self.add_waypoint(w),
            Action::RemoveLastWaypoint => self.waypoints.remove_last(),
            Action::ClearWaypoints => self.waypoints.list.clear(),
            Action::SendWaypoints => self.send_waypoints(),
            Action::OpenCommandLine => self.prompt.open_command_line(),
            Action::OpenWaypointEntry => self.prompt.open = Some(Prompt::Waypoint(String::new())),
            Action::PromptChar(c) => self.edit_prompt(|s| s.push(c)),
            Action::PromptBackspace => self.edit_prompt(|s| {
                s.pop();
            }),
            Action::PromptSubmit => self.submit_prompt(),
            Action::PromptCancel => self.cancel_prompt(),
            Action::HistoryPrev => self.prompt.history_step(-1),
            Action::HistoryNext => self.prompt.history_step(1),
            Action::CommandResult(r) => self.command_result(r),
            Action::RouteCursor(dr, dc) => self.move_route_cursor(dr, dc),
            Action::ApplyRouteCursor => self.apply_route_cursor(),
            Action::Route { robot, channel } => self.route(robot, channel),
            Action::EStop => self.set_estop(true),
            Action::Release => self.set_estop(false),
            Action::ToggleKeyTeleop => self.toggle_key_teleop(),
            Action::ToggleNav => self.toggle_nav(),
            Action::Drive(k) => self.drive(k),
            Action::DriveStop => self.drive_stop(),
            Action::Pad(ev) => self.pad(&ev),
            Action::Log(level, text) => self.log(level, text),
            Action::ToggleTable => self.toggle_table(),
            Action::SortBy(c) => self.sort_by(c),
            Action::SortStep(n) => self.sort_by(self.table.sort.step(n)),
            Action::SortReverse => self.sort_by(self.table.sort),
            Action::OpenFilter => self.open_filter(),
            Action::ClearFilter => self.set_filter(String::new()),
            Action::TableMove(n) => self.table_move(n),
            Action::ToggleDetail => self.table.detail = !self.table.detail,
            Action::CloseDetail => self.table.detail = false,
        }
    }

    fn quit(&mut self) {
        self.running = false;
        self.outbox.push(Request::Quit);
    }

    /// Engages (or releases) the fleet e-stop at once on screen and asks the
    /// core to do the same.
    fn set_estop(&mut self, engage: bool) {
        self.fleet.estop = engage;
        self.outbox.push(Request::EStop { engage });
        if engage {
            self.log(LogLevel::Warn, "E-STOP engaged");
        } else {
            self.log(LogLevel::Warn, "e-stop released");
        }
    }
}
