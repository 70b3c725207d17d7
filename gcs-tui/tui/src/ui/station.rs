//! The interactive station: terminal set-up and the one event loop that
//! multiplexes the render tick, terminal input, gamepads and what the
//! station sends, feeds them to [`App::update`], and carries the App's
//! [`Request`]s to the station over the attach protocol
//! ([`mech_station`]), whether it runs in this process or elsewhere.

use std::time::{Duration, Instant};

use crossterm::event::{DisableMouseCapture, EnableMouseCapture, EventStream};
use crossterm::execute;
use futures::StreamExt;
use std::collections::HashMap;

use mech_proto::Waypoint;
use tokio::sync::mpsc;

use super::app::{Action, App, LogLevel, PromptError, Request, WAYPOINT_CHANNEL};
use super::view::ArenaBounds;
use crate::gamepad::PadEvent;
use mech_control::lang::quote;
use mech_station::client::Attached;
use mech_station::wire::{FromStation, LineResult, LogLevel as WireLevel, ToStation, Welcome};

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
    /// The station attached to (`gcs.sock`, `host:7701`); None when the TUI
    /// runs its own (embedded).
    pub attached: Option<String>,
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
            attached: None,
        }
    }
}

/// Runs the TUI on an attached station until the operator quits. Restores
/// the terminal on every exit path, including errors and panics.
pub async fn run(attached: Attached, options: RunOptions) -> std::io::Result<()> {
    let mut terminal = ratatui::try_init()?;
    if options.mouse {
        execute!(std::io::stdout(), EnableMouseCapture)?;
    }
    let result = event_loop(&mut terminal, attached, &options).await;
    if options.mouse {
        let _ = execute!(std::io::stdout(), DisableMouseCapture);
    }
    ratatui::restore();
    result
}

async fn event_loop(
    terminal: &mut ratatui::DefaultTerminal,
    attached: Attached,
    options: &RunOptions,
) -> std::io::Result<()> {
    let size = terminal.size()?;
    let Attached {
        welcome,
        to,
        mut from,
    } = attached;
    let mut app = station_app(&welcome, options, (size.width, size.height));
    let mut pad_rx = pad_events(options, &mut app);
    let mut link = StationLink::new(to);
    for line in &options.startup {
        link.exec(line.clone());
    }
    let mut events = EventStream::new();
    let mut tick = steady_interval(Duration::from_millis(1000 / FPS));
    // Teleop publishes on its own clock so its rate does not depend on the
    // frame rate.
    let mut teleop_tick = steady_interval(options.teleop.period());
    let mut attached = true;

    while app.running {
        tokio::select! {
            _ = tick.tick() => {
                app.update(Action::Tick(Instant::now()));
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
            m = from.recv(), if attached => match m {
                Some(m) => {
                    // A fresh fleet is drawn at once, not at the next frame.
                    let fresh = matches!(m, FromStation::Snapshot { .. });
                    link.receive(m, &mut app);
                    if fresh {
                        terminal.draw(|f| f.render_widget(&app, f.area()))?;
                    }
                }
                None => {
                    attached = false;
                    app.log(LogLevel::Error, "the station closed the connection: nothing you do reaches the robots now (q quits)");
                }
            },
        }
        for req in app.take_requests() {
            link.carry(req, &mut app);
        }
    }
    Ok(())
}

/// The App as the station starts it: what the station said on attaching
/// and the run options applied, sized to the terminal (`size`, columns and
/// rows) and the view fitted.
fn station_app(welcome: &Welcome, options: &RunOptions, size: (u16, u16)) -> App {
    let mut app = App::new(welcome.router.clone(), Instant::now());
    app.mouse = options.mouse;
    app.monochrome = options.monochrome;
    app.arena = options.arena.or(welcome.arena);
    app.security = welcome.security;
    app.teleop = crate::gamepad::Teleop::new(options.teleop.clone());
    app.teleop.set_channel_prefix(&welcome.pads);
    app.key_channel = welcome.keys.clone();
    app.operator = welcome.operator.clone();
    app.attached = options.attached.clone();
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

fn char_to_byte(s: &str, chars: usize) -> usize {
    s.char_indices().nth(chars).map_or(s.len(), |(i, _)| i)
}

/// Carries the App's [`Request`]s to the station as attach-protocol
/// messages (command-language lines, and teleop at the pads' rate), and
/// what the station sends back to the App.
#[derive(Debug)]
pub struct StationLink {
    to: mpsc::UnboundedSender<ToStation>,
    next_id: u64,
    /// Lines typed at the prompt waiting for their result, by id: their
    /// results go to the prompt; those of lines made from clicks and keys
    /// are logged when they fail.
    typed: HashMap<u64, String>,
}

impl StationLink {
    pub fn new(to: mpsc::UnboundedSender<ToStation>) -> StationLink {
        StationLink {
            to,
            next_id: 0,
            typed: HashMap::new(),
        }
    }

    /// One message from the station into the App.
    pub fn receive(&mut self, m: FromStation, app: &mut App) {
        match m {
            FromStation::Snapshot { fleet, .. } => app.update(Action::Fleet(fleet)),
            FromStation::Log { level, text, .. } => app.update(Action::Log(level.into(), text)),
            FromStation::Result(r) => self.result(r, app),
            FromStation::Refused { reason } => app.log(LogLevel::Warn, reason),
            FromStation::Bye { reason } => {
                app.log(LogLevel::Error, format!("the station said bye: {reason}"));
            }
            FromStation::Welcome(_) | FromStation::Challenge { .. } | FromStation::Event(_) => {}
        }
    }

    fn result(&mut self, r: LineResult, app: &mut App) {
        match self.typed.remove(&r.id) {
            Some(line) => {
                let result = if r.ok {
                    let mut text = r.summary;
                    for d in r.details {
                        text.push('\n');
                        text.push_str(&d);
                    }
                    Ok(text)
                } else {
                    Err(PromptError {
                        message: r.error.unwrap_or_default(),
                        column: r.column.map(|c| char_to_byte(&line, c.saturating_sub(1))),
                        line,
                    })
                };
                app.update(Action::CommandResult(result));
            }
            None if !r.ok => app.log(LogLevel::Error, r.error.unwrap_or_default()),
            None => {}
        }
    }

    /// Carries one request.
    pub fn carry(&mut self, req: Request, app: &mut App) {
        match req {
            Request::Route { robot, channel } => {
                let channel = if channel.is_empty() {
                    "none".into()
                } else {
                    quote(&channel)
                };
                self.line(format!("route {} {channel}", quote(&robot)));
            }
            Request::Mission { robots, waypoints } => self.mission(&robots, &waypoints),
            Request::EStop { engage } => {
                self.line(if engage { "estop" } else { "release" }.into());
            }
            Request::Publish {
                channel,
                robots,
                command,
            } => self.send(ToStation::Publish {
                channel,
                robots,
                command,
            }),
            Request::ClusterVelocity { cluster, velocity } => {
                self.send(ToStation::DriveCluster { cluster, velocity });
            }
            Request::ToggleNav { robots } => {
                for r in robots {
                    self.line(format!("nav {} toggle", quote(&r)));
                }
            }
            Request::DefineCluster { name, members } => {
                let members: Vec<_> = members.iter().map(|m| quote(m)).collect();
                self.line(format!("cluster {} {}", quote(&name), members.join(" ")));
            }
            Request::Exec(line) => self.exec(line),
            Request::Quit => {}
        }
        if self.to.is_closed() {
            app.log(LogLevel::Error, "not attached to a station");
        }
    }

    /// Each robot's waypoint list, then the send, on [`WAYPOINT_CHANNEL`].
    fn mission(&mut self, robots: &[String], waypoints: &[Waypoint]) {
        let points: Vec<String> = waypoints.iter().map(point).collect();
        for robot in robots {
            let r = quote(robot);
            self.line(format!("waypoint {r} {}", points.join(" ")));
            self.line(format!("send {r} {WAYPOINT_CHANNEL}"));
        }
    }

    /// A line typed at the prompt: its result goes back to the prompt.
    pub fn exec(&mut self, line: String) {
        let id = self.line(line.clone());
        self.typed.insert(id, line);
    }

    /// A line made from a click or a key; returns its id.
    fn line(&mut self, text: String) -> u64 {
        self.next_id += 1;
        let id = self.next_id;
        self.send(ToStation::Line { id, text });
        id
    }

    fn send(&self, m: ToStation) {
        // A closed link is reported by `carry`.
        let _ = self.to.send(m);
    }
}

/// A waypoint as the command language writes it: `x,y[,z][@t]`.
fn point(w: &Waypoint) -> String {
    let mut p = format!("{},{}", w.x, w.y);
    if w.z != 0.0 {
        p.push_str(&format!(",{}", w.z));
    }
    if let Some(t) = w.time {
        p.push_str(&format!("@{t}"));
    }
    p
}

impl From<WireLevel> for LogLevel {
    fn from(l: WireLevel) -> LogLevel {
        match l {
            WireLevel::Info => LogLevel::Info,
            WireLevel::Warn => LogLevel::Warn,
            WireLevel::Error => LogLevel::Error,
        }
    }
}
