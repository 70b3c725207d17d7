//! The TUI in a terminal: terminal set-up and restore, and the one event
//! loop that multiplexes the render tick, terminal input, gamepads and
//! what the station sends, feeds them to [`App::update`], and hands the
//! App's [`Request`](super::app::Request)s to the [`StationLink`], which carries them to the
//! station over the attach protocol ([`mech_station`]), whether it runs
//! in this process or elsewhere.

use std::time::{Duration, Instant};

use crossterm::event::{DisableMouseCapture, EnableMouseCapture, EventStream};
use crossterm::execute;
use futures::StreamExt;
use tokio::sync::mpsc;

use super::app::{Action, App, LogLevel};
use super::link::StationLink;
use super::view::ArenaBounds;
use crate::gamepad::PadEvent;
use mech_station::client::Attached;
use mech_station::wire::{FromStation, Welcome};

/// Frames per second of the render tick.
const FPS: u64 = 30;

/// How the TUI looks and what it listens to.
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
    app.session.mouse = options.mouse;
    app.session.monochrome = options.monochrome;
    app.map.arena = options.arena.or(welcome.arena);
    app.fleet.security = welcome.security;
    app.manual.pads = crate::gamepad::Teleop::new(options.teleop.clone());
    app.manual.pads.set_channel_prefix(&welcome.pads);
    app.manual.key_channel = welcome.keys.clone();
    app.session.operator = welcome.operator.clone();
    app.session.attached = options.attached.clone();
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
