//! The UI state machine: [`App`] holds everything the screen shows, every
//! user intent is an [`Action`], and [`App::update`] is the only place state
//! changes. What must reach the robots is queued as [`Request`]s that the
//! event loop hands to the GCS core; the App itself does no I/O.
//!
//! This file has the state, the actions and requests, and the dispatch;
//! the larger families of changes have a file each: `prompt` (command
//! line, waypoint entry and the table's filter), `mouse` (clicks, drags,
//! the wheel and hovering resolved against the layout), `manual`
//! (keyboard teleop and gamepads) and `table` (the fleet table: its rows,
//! sorting, cursor and detail).

use std::collections::{BTreeSet, VecDeque};
use std::time::Instant;

use mech_proto::{ClusterVelocity, Command, Waypoint};
use ratatui::layout::Rect;

use super::columns::Column;
use super::layout::{Areas, CARD_HEIGHT, SidePanel};
use super::view::{
    ArenaBounds, ChannelView, ClusterOnScreen, FleetSnapshot, ReplayClock, RobotView, Security,
};
use super::viewport::Viewport;
use crate::gamepad::{DriveKey, KEY_CHANNEL, KeyTeleop, PadEvent, PadState, Teleop, TeleopConfig};
use mech_core::names::natural_cmp;

mod manual;
mod mouse;
mod prompt;
mod table;

pub use prompt::parse_waypoint;

/// Channel the UI publishes waypoint missions on.
pub const WAYPOINT_CHANNEL: &str = "wp/gcs";

pub use crate::view::TRAIL_SECONDS;
const LOG_LINES: usize = 200;
const HISTORY_LINES: usize = 100;

/// Which panel receives navigation keys.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Focus {
    #[default]
    Map,
    Cards,
    Waypoints,
    Routes,
}

impl Focus {
    fn next(self) -> Focus {
        match self {
            Focus::Map => Focus::Cards,
            Focus::Cards => Focus::Waypoints,
            Focus::Waypoints => Focus::Routes,
            Focus::Routes => Focus::Map,
        }
    }

    fn prev(self) -> Focus {
        match self {
            Focus::Map => Focus::Routes,
            Focus::Cards => Focus::Map,
            Focus::Waypoints => Focus::Cards,
            Focus::Routes => Focus::Waypoints,
        }
    }
}

/// A one-line text entry in progress.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Prompt {
    /// `:` command line, run by the shared command language.
    Command(String),
    /// `x,y[,t]` waypoint entry.
    Waypoint(String),
    /// `/` the fleet table's filter, applied as it is typed.
    Filter(String),
}

/// How the robots are shown: cards beside the map, or the fleet table in
/// place of both (the side column stays).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum RobotsView {
    #[default]
    Cards,
    Table,
}

/// The fleet table: its order, filter, rows, cursor and whether the
/// cursor's robot is shown in detail.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct TableState {
    pub sort: Column,
    pub descending: bool,
    /// Text the rows must contain (name, route or state), any case.
    pub filter: String,
    /// Indices into [`App::robots`], filtered and sorted: kept up to date
    /// by `update`, so drawing only reads them.
    pub rows: Vec<usize>,
    /// The robot the keys act on, by name, so it stays put when rows
    /// re-sort (a speed column re-sorts every frame).
    pub cursor: Option<String>,
    /// First row shown.
    pub scroll: usize,
    /// The cursor's robot in detail (card, events, counters) in place of
    /// the table.
    pub detail: bool,
}

/// The last command-line error, with the column it points at.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PromptError {
    pub line: String,
    pub message: String,
    /// Byte offset in `line` of the mistake, if known.
    pub column: Option<usize>,
}

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

/// Severity of a log line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LogLevel {
    Info,
    Warn,
    Error,
}

/// One line of the events pane.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogLine {
    pub level: LogLevel,
    pub text: String,
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

/// The whole UI state. Rendering is a pure function of it.
#[derive(Debug)]
pub struct App {
    pub router_addr: String,
    pub robots: Vec<RobotView>,
    pub channels: Vec<ChannelView>,
    pub clusters: Vec<ClusterOnScreen>,
    pub selection: BTreeSet<String>,
    pub arena: Option<ArenaBounds>,
    pub viewport: Viewport,
    /// Terminal size, for click resolution.
    pub size: (u16, u16),
    pub focus: Focus,
    pub side: SidePanel,
    pub show_help: bool,
    /// First help entry shown.
    pub help_scroll: usize,
    pub waypoint_mode: bool,
    /// Waypoints being edited, in mission order.
    pub waypoints: Vec<Waypoint>,
    pub prompt: Option<Prompt>,
    pub prompt_error: Option<PromptError>,
    pub robots_view: RobotsView,
    pub table: TableState,
    /// The robot under the mouse pointer on the map: always labelled.
    pub hover: Option<String>,
    pub history: Vec<String>,
    history_pos: Option<usize>,
    /// Fleet-wide e-stop engaged (requested here or reported by the core).
    pub estop: bool,
    /// Whether the station checks signatures (shown in the status bar).
    pub security: Security,
    /// Messages the station refused, as last reported.
    pub rejected: u64,
    /// A replay's clock, when the TUI shows a recording.
    pub replay: Option<ReplayClock>,
    pub log: VecDeque<LogLine>,
    /// Routing-table cursor: robot row, channel column.
    pub route_cursor: (usize, usize),
    pub cards_scroll: usize,
    pub key_teleop_on: bool,
    pub key_teleop: KeyTeleop,
    /// The channel keyboard teleop publishes on (the station names it).
    pub key_channel: String,
    /// Who the station logs this TUI's commands under.
    pub operator: String,
    /// The station this TUI is attached to (`gcs.sock`, `host:7701`); None
    /// when it runs its own station (embedded).
    pub attached: Option<String>,
    pub teleop: Teleop,
    /// Cluster a pad in cluster mode drives (the last one made or selected).
    pub active_cluster: Option<String>,
    pub now: Instant,
    /// Draw with modifiers only, no colours.
    pub monochrome: bool,
    pub mouse: bool,
    pub running: bool,
    drag_from: Option<(u16, u16)>,
    fitted_once: bool,
    outbox: Vec<Request>,
}

impl App {
    pub fn new(router_addr: impl Into<String>, now: Instant) -> App {
        App {
            router_addr: router_addr.into(),
            robots: Vec::new(),
            channels: Vec::new(),
            clusters: Vec::new(),
            selection: BTreeSet::new(),
            arena: None,
            viewport: Viewport::default(),
            size: (80, 24),
            focus: Focus::Map,
            side: SidePanel::Cards,
            show_help: false,
            help_scroll: 0,
            waypoint_mode: false,
            waypoints: Vec::new(),
            prompt: None,
            prompt_error: None,
            robots_view: RobotsView::Cards,
            table: TableState::default(),
            hover: None,
            history: Vec::new(),
            history_pos: None,
            estop: false,
            security: Security::default(),
            rejected: 0,
            replay: None,
            log: VecDeque::new(),
            route_cursor: (0, 0),
            cards_scroll: 0,
            key_teleop_on: false,
            key_teleop: KeyTeleop::default(),
            key_channel: KEY_CHANNEL.to_string(),
            operator: String::new(),
            attached: None,
            teleop: Teleop::new(TeleopConfig::default()),
            active_cluster: None,
            now,
            monochrome: false,
            mouse: true,
            running: true,
            drag_from: None,
            fitted_once: false,
            outbox: Vec::new(),
        }
    }

    /// Requests queued since the last call, oldest first.
    pub fn take_requests(&mut self) -> Vec<Request> {
        std::mem::take(&mut self.outbox)
    }

    /// The current layout.
    pub fn areas(&self) -> Areas {
        let table = self.robots_view == RobotsView::Table;
        Areas::compute(Rect::new(0, 0, self.size.0, self.size.1), self.side, table)
    }

    pub fn robot(&self, name: &str) -> Option<&RobotView> {
        self.robots.iter().find(|r| r.name == name)
    }

    /// Channel columns of the routing table: none, every live channel, the
    /// waypoint and keyboard channels, and any channel a robot is routed to.
    pub fn route_columns(&self) -> Vec<String> {
        let mut cols: Vec<String> = vec![String::new()];
        let mut push = |c: &str| {
            if !cols.iter().any(|x| x == c) {
                cols.push(c.to_string());
            }
        };
        push(WAYPOINT_CHANNEL);
        push(&self.key_channel);
        for p in self.teleop.pads() {
            push(&p.channel());
        }
        for c in &self.channels {
            push(&c.name);
        }
        for r in &self.robots {
            if !r.route.channel.is_empty() {
                push(&r.route.channel);
            }
        }
        cols
    }

    /// Connected pads, for display.
    pub fn pads(&self) -> Vec<&PadState> {
        self.teleop.pads().collect()
    }

    pub fn log(&mut self, level: LogLevel, text: impl Into<String>) {
        self.log.push_back(LogLine {
            level,
            text: text.into(),
        });
        while self.log.len() > LOG_LINES {
            self.log.pop_front();
        }
    }

    /// Applies one action: a flat dispatch, one method per kind of change.
    pub fn update(&mut self, action: Action) {
        match action {
            Action::Tick(now) => self.tick(now),
            Action::Resize(w, h) => self.size = (w, h),
            Action::Quit => self.quit(),
            Action::ToggleHelp => self.toggle_help(),
            Action::HelpScroll(d) => self.scroll_help(d),
            Action::Fleet(snapshot) => self.apply_snapshot(snapshot),
            Action::ToggleRecording => self.outbox.push(Request::Exec("record toggle".into())),
            Action::Select(s) => self.select(s),
            Action::Click { col, row, add } => self.click(col, row, add),
            Action::Drag { col, row } => self.drag(col, row),
            Action::MouseUp => self.drag_from = None,
            Action::Hover { col, row } => self.hover(col, row),
            Action::Scroll { col, row, steps } => self.scroll(col, row, steps),
            Action::Zoom(f) => self.viewport.zoom(f),
            Action::Pan(dx, dy) => self.viewport.pan_cells(dx, dy),
            Action::FitFleet => self.fit_fleet(),
            Action::FocusNext => self.step_focus(Focus::next),
            Action::FocusPrev => self.step_focus(Focus::prev),
            Action::MakeCluster => self.make_cluster(),
            Action::WaypointMode(on) => self.set_waypoint_mode(on),
            Action::AddWaypoint(w) => self.add_waypoint(w),
            Action::RemoveLastWaypoint => {
                self.waypoints.pop();
            }
            Action::ClearWaypoints => self.waypoints.clear(),
            Action::SendWaypoints => self.send_waypoints(),
            Action::OpenCommandLine => self.open_command_line(),
            Action::OpenWaypointEntry => self.prompt = Some(Prompt::Waypoint(String::new())),
            Action::PromptChar(c) => self.edit_prompt(|s| s.push(c)),
            Action::PromptBackspace => self.edit_prompt(|s| {
                s.pop();
            }),
            Action::PromptSubmit => self.submit_prompt(),
            Action::PromptCancel => self.cancel_prompt(),
            Action::HistoryPrev => self.history_step(-1),
            Action::HistoryNext => self.history_step(1),
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

    fn toggle_help(&mut self) {
        self.show_help = !self.show_help;
        self.help_scroll = 0;
    }

    /// Scrolls the help by `d` entries, keeping the last page full.
    fn scroll_help(&mut self, d: i32) {
        let rows = super::help::visible_entries(self.size.1);
        let max = super::help::KEYS.len().saturating_sub(rows);
        self.help_scroll = (self.help_scroll as i64 + i64::from(d)).clamp(0, max as i64) as usize;
    }

    /// Engages (or releases) the fleet e-stop at once on screen and asks the
    /// core to do the same.
    fn set_estop(&mut self, engage: bool) {
        self.estop = engage;
        self.outbox.push(Request::EStop { engage });
        if engage {
            self.log(LogLevel::Warn, "E-STOP engaged");
        } else {
            self.log(LogLevel::Warn, "e-stop released");
        }
    }

    /// Takes the core's state as it is: the e-stop, robots (in natural
    /// name order: robot_2 before robot_10), channels and (when the source
    /// keeps them) clusters; fits the map to the first robots seen.
    fn apply_snapshot(&mut self, s: FleetSnapshot) {
        self.estop = s.estop;
        self.security = s.security;
        self.rejected = s.rejected;
        self.replay = s.replay;
        // Fit the map once, to the first robots that reported where they
        // are (a robot that registered has no position until its first
        // telemetry, and reads as the origin).
        let first = s.robots.iter().any(|r| r.pose.x != 0.0 || r.pose.y != 0.0);
        self.robots = s.robots;
        // Already in order from the station: a stable sort then costs one
        // comparison per robot.
        self.robots.sort_by(|a, b| natural_cmp(&a.name, &b.name));
        self.channels = s.channels;
        if let Some(c) = s.clusters {
            self.clusters = c;
        }
        self.selection
            .retain(|n| self.robots.iter().any(|r| &r.name == n));
        self.refresh_rows();
        if first && !self.fitted_once {
            self.fitted_once = true;
            self.fit_fleet();
        }
    }

    /// Fits the map to the fleet (as the map view lays it out, also while
    /// the table hides the map).
    fn fit_fleet(&mut self) {
        let area = Rect::new(0, 0, self.size.0, self.size.1);
        let inner = Areas::compute(area, self.side, false).map_inner();
        let mut pts: Vec<(f64, f64)> = self.robots.iter().map(|r| (r.pose.x, r.pose.y)).collect();
        if let Some(a) = self.arena {
            pts.push((a.min_x, a.min_y));
            pts.push((a.max_x, a.max_y));
        }
        pts.extend(self.waypoints.iter().map(|w| (w.x, w.y)));
        self.viewport.fit(pts, inner.width, inner.height, 1.0);
    }

    /// The next (or previous) panel; the map is skipped while the table
    /// hides it.
    fn step_focus(&mut self, step: fn(Focus) -> Focus) {
        let mut f = step(self.focus);
        if f == Focus::Map && self.robots_view == RobotsView::Table {
            f = step(f);
        }
        self.set_focus(f);
    }

    fn set_focus(&mut self, f: Focus) {
        self.focus = f;
        self.side = match f {
            Focus::Cards => SidePanel::Cards,
            Focus::Waypoints => SidePanel::Waypoints,
            Focus::Routes => SidePanel::Routes,
            Focus::Map => self.side,
        };
    }

    /// Robots in the order the robots panel shows them: the table's rows
    /// (sorted and filtered) in the table view, else the fleet in name
    /// order. Next and previous follow it.
    fn display_order(&self) -> Vec<String> {
        match self.robots_view {
            RobotsView::Table => self
                .table
                .rows
                .iter()
                .map(|&i| self.robots[i].name.clone())
                .collect(),
            RobotsView::Cards => self.robots.iter().map(|r| r.name.clone()).collect(),
        }
    }

    fn select(&mut self, s: Select) {
        let names = self.display_order();
        let idx_of = |n: &str| names.iter().position(|x| x == n);
        let known = |n: &str| self.robots.iter().any(|r| r.name == n);
        let mut acted_on = None;
        match s {
            Select::Only(n) => {
                self.selection.clear();
                if known(&n) {
                    self.selection.insert(n.clone());
                    acted_on = Some(n);
                }
            }
            Select::Toggle(n) => {
                if !self.selection.remove(&n) && known(&n) {
                    self.selection.insert(n.clone());
                }
                acted_on = Some(n);
            }
            Select::Next | Select::Prev | Select::AddNext | Select::AddPrev => {
                if names.is_empty() {
                    return;
                }
                let picked = self.selection.iter().filter_map(|n| idx_of(n));
                let (first, last) = (picked.clone().min(), picked.max());
                let n = names.len();
                let i = match (&s, first, last) {
                    (Select::Prev | Select::AddPrev, Some(i), _) => (i + n - 1) % n,
                    (Select::Prev | Select::AddPrev, None, _) => n - 1,
                    (_, _, Some(i)) => (i + 1) % n,
                    (_, _, None) => 0,
                };
                if !matches!(s, Select::AddNext | Select::AddPrev) {
                    self.selection.clear();
                }
                self.selection.insert(names[i].clone());
                acted_on = Some(names[i].clone());
            }
            Select::All => self.selection = names.iter().cloned().collect(),
            Select::Clear => self.selection.clear(),
            Select::Cluster(c) => {
                if let Some(cl) = self.clusters.iter().find(|x| x.name == c) {
                    self.selection = cl.members.iter().cloned().collect();
                    self.active_cluster = Some(c);
                }
            }
        }
        if let Some(name) = acted_on {
            if let Some(i) = self.robots.iter().position(|r| r.name == name) {
                self.route_cursor.0 = i;
            }
            self.table.cursor = Some(name);
        }
        self.keep_selection_visible();
    }

    /// Lines one robot card takes.
    pub fn card_height(&self) -> usize {
        CARD_HEIGHT
    }

    fn keep_selection_visible(&mut self) {
        if self.robots_view == RobotsView::Table {
            self.keep_cursor_visible();
            return;
        }
        let Some(area) = self.areas().cards else {
            return;
        };
        let per = self.card_height();
        let visible = (usize::from(area.height.saturating_sub(2)) / per).max(1);
        let Some(i) = self
            .robots
            .iter()
            .position(|r| self.selection.contains(&r.name))
        else {
            return;
        };
        if i < self.cards_scroll {
            self.cards_scroll = i;
        } else if i >= self.cards_scroll + visible {
            self.cards_scroll = i + 1 - visible;
        }
    }

    fn make_cluster(&mut self) {
        let members = self.selected_robots();
        if members.len() < 2 {
            self.log(
                LogLevel::Warn,
                "select at least two robots to make a cluster",
            );
            return;
        }
        let mut n = self.clusters.len() + 1;
        while self.clusters.iter().any(|c| c.name == format!("c{n}")) {
            n += 1;
        }
        let name = format!("c{n}");
        self.log(
            LogLevel::Info,
            format!("cluster {name}: {}", members.join(" ")),
        );
        self.outbox.push(Request::DefineCluster {
            name: name.clone(),
            members: members.clone(),
        });
        self.clusters.push(ClusterOnScreen {
            name: name.clone(),
            members,
            control: None,
        });
        self.active_cluster = Some(name);
    }

    fn toggle_nav(&mut self) {
        let robots = self.selected_robots();
        if robots.is_empty() {
            self.log(
                LogLevel::Warn,
                "select a robot to switch onboard/offboard navigation",
            );
            return;
        }
        self.log(
            LogLevel::Info,
            format!("navigation onboard/offboard switch: {}", robots.join(" ")),
        );
        self.outbox.push(Request::ToggleNav { robots });
    }

    /// Selected robots, in card order.
    fn selected_robots(&self) -> Vec<String> {
        self.robots
            .iter()
            .filter(|r| self.selection.contains(&r.name))
            .map(|r| r.name.clone())
            .collect()
    }

    /// Waypoint mode places waypoints with clicks on the map, so it brings
    /// the map back from the table.
    fn set_waypoint_mode(&mut self, on: bool) {
        self.waypoint_mode = on;
        if on {
            self.robots_view = RobotsView::Cards;
            self.set_focus(Focus::Waypoints);
        }
    }

    fn add_waypoint(&mut self, w: Waypoint) {
        if self.waypoints.len() < mech_proto::MAX_WAYPOINTS {
            self.waypoints.push(w);
        } else {
            self.log(
                LogLevel::Warn,
                format!(
                    "a mission holds at most {} waypoints: ({:.2}, {:.2}) not added",
                    mech_proto::MAX_WAYPOINTS,
                    w.x,
                    w.y
                ),
            );
        }
    }

    fn send_waypoints(&mut self) {
        if self.waypoints.is_empty() {
            self.log(LogLevel::Warn, "no waypoints to send");
            return;
        }
        let robots = self.selected_robots();
        if robots.is_empty() {
            self.log(
                LogLevel::Warn,
                "select a robot or a cluster to send waypoints to",
            );
            return;
        }
        self.log(
            LogLevel::Info,
            format!(
                "mission of {} waypoint(s) -> {} on {WAYPOINT_CHANNEL}",
                self.waypoints.len(),
                robots.join(" ")
            ),
        );
        self.outbox.push(Request::Mission {
            robots,
            waypoints: self.waypoints.clone(),
        });
    }

    /// Moves the routing-table cursor, wrapping around at the edges.
    fn move_route_cursor(&mut self, dr: i32, dc: i32) {
        let rows = self.robots.len().max(1) as i64;
        let cols = self.route_columns().len().max(1) as i64;
        let r = (self.route_cursor.0 as i64 + i64::from(dr)).rem_euclid(rows);
        let c = (self.route_cursor.1 as i64 + i64::from(dc)).rem_euclid(cols);
        self.route_cursor = (r as usize, c as usize);
    }

    fn apply_route_cursor(&mut self) {
        let cols = self.route_columns();
        if let (Some(r), Some(c)) = (
            self.robots.get(self.route_cursor.0),
            cols.get(self.route_cursor.1),
        ) {
            let (robot, channel) = (r.name.clone(), c.clone());
            self.route(robot, channel);
        }
    }

    fn route(&mut self, robot: String, channel: String) {
        if self.robot(&robot).is_none() {
            self.log(LogLevel::Error, format!("no robot named {robot}"));
            return;
        }
        let shown = if channel.is_empty() { "none" } else { &channel };
        self.log(LogLevel::Info, format!("route {robot} -> {shown}"));
        if let Some(r) = self.robots.iter_mut().find(|r| r.name == robot) {
            r.route.channel = channel.clone();
            r.route.acknowledged = false;
        }
        self.outbox.push(Request::Route { robot, channel });
    }
}
