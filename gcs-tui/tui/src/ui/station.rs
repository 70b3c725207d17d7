//! The interactive station: terminal set-up and the one event loop that
//! multiplexes the render tick, terminal input, gamepads and command-line
//! results, feeds them to [`App::update`], and carries the App's
//! [`Request`]s to the GCS core (router, fleet model, command language).

use std::time::{Duration, Instant};

use crossterm::event::{DisableMouseCapture, EnableMouseCapture, EventStream};
use crossterm::execute;
use futures::StreamExt;
use mech_proto::{ClusterVelocity, Command, Waypoint};
use tokio::sync::mpsc;

use super::app::{Action, App, LogLevel, PromptError, Request, WAYPOINT_CHANNEL};
use super::view::{
    ArenaBounds, ChannelView, ClusterControlView, ClusterOnScreen, FleetSnapshot, RobotView,
    RouteView, Security,
};
use crate::gamepad::PadEvent;
use mech_control::ControlHub;
use mech_control::lang::Executor;
use mech_control::lang::exec::SENDER;
use mech_core::fleet::{Fleet, Robot, Severity};
use mech_core::router::Publishers;
use mech_core::{ChannelStatus, Gcs, RouterHandle};

/// Frames per second of the render tick.
const FPS: u64 = 30;

/// How the station looks and what it listens to.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// Capture the mouse (off with `--no-mouse`).
    pub mouse: bool,
    /// No colours (also when `NO_COLOR` is set).
    pub monochrome: bool,
    /// Arena outline on the map.
    pub arena: Option<ArenaBounds>,
    /// Listen for gamepads.
    pub gamepads: bool,
    /// Command-language lines to run first (e.g. `spawn 4` for the demo).
    pub startup: Vec<String>,
    /// Dead-man, buttons, rate, shaping and limits of the gamepads.
    pub teleop: crate::gamepad::TeleopConfig,
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions {
            mouse: true,
            monochrome: std::env::var_os("NO_COLOR").is_some_and(|v| !v.is_empty()),
            arena: None,
            gamepads: true,
            startup: Vec::new(),
            teleop: crate::gamepad::TeleopConfig::default(),
        }
    }
}

/// The arena the demo's simulated fleet is spread over (the agent
/// simulator's default, the 2017 lab's Pozyx area), for the map outline.
pub fn demo_arena() -> ArenaBounds {
    let a = mech_agent::sim::Arena::default();
    ArenaBounds {
        min_x: a.min_x,
        min_y: a.min_y,
        max_x: a.max_x,
        max_y: a.max_y,
    }
}

/// Converts the core's fleet model into what the screen shows. Read
/// `channels` from the router *before* taking the fleet lock: the router
/// holds its tables while it updates the fleet, so asking it for channels
/// inside [`Gcs::with_fleet`] can deadlock.
pub fn snapshot(fleet: &Fleet, channels: Vec<ChannelStatus>) -> FleetSnapshot {
    let robots = fleet
        .robots
        .values()
        .map(|r| RobotView {
            name: r.name.clone(),
            id: r.id,
            platform: r.platform.clone(),
            pose: r.pose,
            velocity: r.velocity,
            mode: r.mode,
            route: RouteView {
                channel: r.route.requested.clone().unwrap_or_default(),
                acknowledged: !r.route.is_pending(),
            },
            computation: r.computation,
            link: r.link,
            failsafe: r.failsafe,
            health: r.health,
            battery: r.battery,
            mission: r.mission,
            trail: recent_path(r),
            remote: r.remote.clone(),
        })
        .collect();
    FleetSnapshot {
        robots,
        channels: channel_views(channels),
        estop: fleet.estop.engaged,
        security: Security::default(),
        rejected: 0,
        clusters: Some(
            fleet
                .clusters
                .values()
                .map(|c| ClusterOnScreen {
                    name: c.name.clone(),
                    members: c.members.clone(),
                    control: None,
                })
                .collect(),
        ),
    }
}

/// Copies what the cluster controllers report (desired and measured
/// cluster pose, slot targets, tracking errors) into the snapshot's
/// clusters, so the screen stays a function of the App's state. Call it
/// outside [`Gcs::with_fleet`].
pub fn apply_control(snap: &mut FleetSnapshot, control: &mech_control::ControlSnapshot) {
    let Some(clusters) = snap.clusters.as_mut() else {
        return;
    };
    for c in clusters {
        c.control = control
            .clusters
            .iter()
            .find(|v| v.status.cluster == c.name)
            .map(|v| ClusterControlView::from_status(&v.status));
    }
}

/// The part of the robot's recorded path from the last
/// [`super::app::TRAIL_SECONDS`] before its newest telemetry.
fn recent_path(r: &Robot) -> Vec<(f64, f64)> {
    let Some(newest) = r.last_telemetry.or_else(|| r.path.back().map(|p| p.at)) else {
        return Vec::new();
    };
    let from = newest.saturating_sub(Duration::from_secs_f64(super::app::TRAIL_SECONDS));
    r.path
        .iter()
        .filter(|p| p.at >= from)
        .map(|p| (p.x, p.y))
        .collect()
}

/// Runs the station until the operator quits. Restores the terminal on
/// every exit path, including errors and panics.
pub async fn run(gcs: Gcs, executor: Executor, options: RunOptions) -> std::io::Result<()> {
    let mut terminal = ratatui::try_init()?;
    if options.mouse {
        execute!(std::io::stdout(), EnableMouseCapture)?;
    }
    let result = event_loop(&mut terminal, gcs, executor, &options).await;
    if options.mouse {
        let _ = execute!(std::io::stdout(), DisableMouseCapture);
    }
    ratatui::restore();
    result
}

async fn event_loop(
    terminal: &mut ratatui::DefaultTerminal,
    gcs: Gcs,
    executor: Executor,
    options: &RunOptions,
) -> std::io::Result<()> {
    let size = terminal.size()?;
    let mut app = station_app(gcs.router(), options, (size.width, size.height));
    let mut pad_rx = pad_events(options, &mut app);

    // The command language runs in its own task: a line may wait.
    let (line_tx, line_rx) = mpsc::unbounded_channel::<String>();
    let (result_tx, mut result_rx) = mpsc::unbounded_channel();
    // One set of controllers for the command line, the pads and the keys.
    let control = executor.control().clone();
    let exec_task = tokio::spawn(run_lines(executor, line_rx, result_tx));
    for line in &options.startup {
        let _ = line_tx.send(line.clone());
    }

    let mut events = EventStream::new();
    let mut tick = steady_interval(Duration::from_millis(1000 / FPS));
    let mut link = CoreLink::new(gcs.clone(), line_tx.clone(), control);
    // Teleop publishes on its own clock so its rate does not depend on the
    // frame rate.
    let mut teleop_tick = steady_interval(options.teleop.period());
    let mut log_last = 0;

    while app.running {
        tokio::select! {
            _ = tick.tick() => {
                refresh(&mut app, &gcs, link.control(), &mut log_last);
                terminal.draw(|f| f.render_widget(&app, f.area()))?;
            }
            ev = events.next() => match ev {
                Some(Ok(ev)) => {
                    for a in super::keys::on_event(&app, &ev) {
                        app.update(a);
                    }
                }
                Some(Err(e)) => return Err(e),
                None => break,
            },
            _ = teleop_tick.tick() => app.update(Action::Tick(Instant::now())),
            Some(pad) = pad_rx.recv() => app.update(Action::Pad(pad)),
            Some(result) = result_rx.recv() => app.update(Action::CommandResult(result)),
        }
        for req in app.take_requests() {
            link.carry(req, &mut app).await;
        }
    }
    drop(line_tx);
    drop(link);
    let _ = exec_task.await;
    Ok(())
}

/// The App as the station starts it: the run options applied, sized to
/// the terminal (`size`, columns and rows) and the view fitted.
fn station_app(router: &RouterHandle, options: &RunOptions, size: (u16, u16)) -> App {
    let mut app = App::new(router.udp_addr().to_string(), Instant::now());
    app.mouse = options.mouse;
    app.monochrome = options.monochrome;
    app.arena = options.arena;
    app.teleop = crate::gamepad::Teleop::new(options.teleop.clone());
    app.update(Action::Resize(size.0, size.1));
    app.update(Action::FitFleet);
    app
}

/// Gamepad events, from a thread that polls gilrs. Without gamepads (or
/// when the thread cannot start, which is logged on the App) the channel
/// stays empty and closed.
fn pad_events(options: &RunOptions, app: &mut App) -> mpsc::UnboundedReceiver<PadEvent> {
    let (pad_tx, pad_rx) = mpsc::unbounded_channel();
    if options.gamepads {
        if let Err(e) = crate::gamepad::spawn_pump(pad_tx) {
            app.log(LogLevel::Warn, format!("gamepads disabled: {e}"));
        }
    }
    pad_rx
}

/// A timer ticking every `period` that skips the ticks it missed rather
/// than bursting to catch up.
fn steady_interval(period: Duration) -> tokio::time::Interval {
    let mut interval = tokio::time::interval(period);
    interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    interval
}

/// One frame's worth of core state into the App: the fleet log lines since
/// `log_last`, the time, and a fresh snapshot with the router's channels
/// and the controllers' reports (each read outside the fleet lock).
fn refresh(app: &mut App, gcs: &Gcs, control: &ControlHub, log_last: &mut u64) {
    let (mut snap, new_log) = gcs.with_fleet(|f| {
        let lines = new_log_lines(f, log_last);
        (snapshot(f, Vec::new()), lines)
    });
    snap.channels = snapshot_channels(gcs.router());
    snap.security = gcs.router().security();
    snap.rejected = gcs.router().rejections().total();
    apply_control(&mut snap, &control.snapshot());
    for (level, text) in new_log {
        app.update(Action::Log(level, text));
    }
    app.update(Action::Tick(Instant::now()));
    app.update(Action::Fleet(snap));
}

fn snapshot_channels(router: &RouterHandle) -> Vec<ChannelView> {
    channel_views(router.channels())
}

fn channel_views(channels: Vec<ChannelStatus>) -> Vec<ChannelView> {
    channels
        .into_iter()
        .map(|c| ChannelView {
            name: c.name,
            publisher: c.publisher,
            rate_hz: c.rate_hz,
        })
        .collect()
}

/// Core log lines after line `last`, oldest first; `last` moves on to the
/// newest.
fn new_log_lines(f: &Fleet, last: &mut u64) -> Vec<(LogLevel, String)> {
    let mut out = Vec::new();
    for e in f.log_after(*last) {
        *last = e.seq;
        let level = match e.severity {
            Severity::Debug => continue,
            Severity::Info => LogLevel::Info,
            Severity::Warn => LogLevel::Warn,
            Severity::Error => LogLevel::Error,
        };
        out.push((level, e.text.clone()));
    }
    out
}

async fn run_lines(
    mut executor: Executor,
    mut lines: mpsc::UnboundedReceiver<String>,
    results: mpsc::UnboundedSender<Result<String, PromptError>>,
) {
    while let Some(line) = lines.recv().await {
        let r = executor
            .execute_line(&line)
            .await
            .map(|o| {
                let mut text = o.summary;
                for d in o.details {
                    text.push('\n');
                    text.push_str(&d);
                }
                text
            })
            .map_err(|e| PromptError {
                message: e.message,
                column: Some(char_to_byte(&line, e.span.column.saturating_sub(1))),
                line: line.clone(),
            });
        if results.send(r).is_err() {
            break;
        }
    }
    executor.shutdown().await;
}

fn char_to_byte(s: &str, chars: usize) -> usize {
    s.char_indices().nth(chars).map_or(s.len(), |(i, _)| i)
}

/// Carries the App's [`Request`]s to the GCS core: routes, missions,
/// e-stop, teleop publishing, clusters, fleet and offboard control and
/// command-language lines.
#[derive(Debug)]
pub struct CoreLink {
    gcs: Gcs,
    /// One in-process publisher per channel, so sequence numbers and the
    /// router's per-channel rate are those of one steady publisher.
    publishers: Publishers,
    lines: mpsc::UnboundedSender<String>,
    /// The controllers the command line's executor runs too, so a cluster
    /// moved by a pad and by `:cluster-move` is one and the same.
    control: ControlHub,
}

impl CoreLink {
    /// `lines` receives command-language lines for the executor task;
    /// `control` is that executor's [`ControlHub`] ([`Executor::control`]).
    pub fn new(gcs: Gcs, lines: mpsc::UnboundedSender<String>, control: ControlHub) -> CoreLink {
        CoreLink {
            publishers: gcs.router().publishers(SENDER),
            gcs,
            lines,
            control,
        }
    }

    /// The fleet and offboard controllers requests go to.
    pub fn control(&self) -> &ControlHub {
        &self.control
    }

    /// Carries one request; failures are logged on the App.
    pub async fn carry(&mut self, req: Request, app: &mut App) {
        match req {
            Request::Route { robot, channel } => self.route(&robot, &channel, app).await,
            Request::Mission { robots, waypoints } => self.mission(robots, &waypoints, app).await,
            Request::EStop { engage } => {
                self.estop(engage).await;
            }
            Request::Publish {
                channel,
                robots,
                command,
            } => self.publish(&channel, robots, &command, app).await,
            Request::ClusterVelocity { cluster, velocity } => {
                self.drive_cluster(&cluster, velocity, app);
            }
            Request::ToggleNav { robots } => self.toggle_nav(robots),
            Request::DefineCluster { name, members } => {
                self.gcs.update_fleet(|f| f.set_cluster(&name, members));
            }
            Request::Exec(line) => self.exec(line, app).await,
            Request::Quit => {}
        }
    }

    /// Routes `robot` to `channel` (empty: to none).
    async fn route(&self, robot: &str, channel: &str, app: &mut App) {
        let ch = (!channel.is_empty()).then_some(channel);
        if let Err(e) = self.gcs.router().set_route(robot, ch).await {
            app.log(LogLevel::Error, e.to_string());
        }
    }

    /// Sends `waypoints` to each robot as a mission on [`WAYPOINT_CHANNEL`],
    /// keeping them as the robot's draft in the fleet model.
    async fn mission(&self, robots: Vec<String>, waypoints: &[Waypoint], app: &mut App) {
        for robot in robots {
            self.gcs.update_fleet(|f| {
                if let Some(r) = f.robot_mut(&robot) {
                    r.waypoints.draft = waypoints.to_vec();
                }
            });
            let sent = self
                .gcs
                .send_waypoints(SENDER, &robot, WAYPOINT_CHANNEL, waypoints.to_vec(), false)
                .await;
            if let Err(e) = sent {
                app.log(LogLevel::Error, e.to_string());
            }
        }
    }

    /// Engages or releases the fleet e-stop; returns the router's id for it.
    async fn estop(&self, engage: bool) -> u32 {
        let router = self.gcs.router();
        if engage {
            router.estop().await
        } else {
            router.release().await
        }
    }

    /// Publishes a teleop command on `channel` for each of `robots`.
    async fn publish(
        &mut self,
        channel: &str,
        robots: Vec<String>,
        command: &Command,
        app: &mut App,
    ) {
        let p = self.publishers.on(channel);
        for robot in robots {
            if let Err(e) = p.send(&robot, command.clone()).await {
                app.log(LogLevel::Error, e.to_string());
            }
        }
    }

    /// Hands a pad's velocity to the cluster controller. It lapses unless
    /// the pad refreshes it, so a pad that stops publishing leaves the
    /// cluster holding.
    fn drive_cluster(&self, cluster: &str, velocity: ClusterVelocity, app: &mut App) {
        if let Err(e) = self.control.drive_cluster(cluster, velocity) {
            app.log(LogLevel::Error, format!("{cluster}: {e}"));
        }
    }

    /// Switches each robot's waypoint navigation onboard <-> offboard.
    /// Handing navigation back onboard waits for the agent's mission
    /// acknowledgement: it runs beside the event loop and reports in the
    /// fleet log.
    fn toggle_nav(&self, robots: Vec<String>) {
        for robot in robots {
            let hub = self.control.clone();
            tokio::spawn(async move {
                let (severity, text) = match hub.toggle_nav(&robot).await {
                    Ok(text) => (Severity::Info, text),
                    Err(e) => (Severity::Error, format!("nav {robot}: {e}")),
                };
                hub.gcs().update_fleet(|f| f.log(severity, text));
            });
        }
    }

    /// Queues a command-language line for the executor. `estop` and
    /// `release` typed at the prompt act at once: the queue of typed lines
    /// may be busy with a `wait` or a `sleep`.
    async fn exec(&self, line: String, app: &mut App) {
        if let Some(engage) = typed_estop(&line) {
            let id = self.estop(engage).await;
            let what = if engage {
                "E-STOP engaged"
            } else {
                "e-stop released"
            };
            app.log(LogLevel::Warn, format!("{what} (id {id})"));
            return;
        }
        if self.lines.send(line).is_err() {
            app.log(LogLevel::Error, "the command language has stopped");
        }
    }
}

/// `Some(true)` for a line that is `estop`, `Some(false)` for `release`.
fn typed_estop(line: &str) -> Option<bool> {
    let statement = mech_control::lang::parse_line(line).ok().flatten()?;
    match statement.command {
        mech_control::lang::Command::EStop => Some(true),
        mech_control::lang::Command::Release => Some(false),
        _ => None,
    }
}
