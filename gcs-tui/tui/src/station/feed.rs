//! What every attached TUI is sent, made once for all of them: the fleet
//! snapshot, serialized at the snapshot rate and at once after any event
//! other than telemetry (a route change reaches every screen without
//! waiting for the next period), and the event log's new lines. A session
//! forwards the newest snapshot only, so a slow client skips snapshots
//! instead of queueing them.

use std::sync::Arc;
use std::time::Duration;

use mech_control::ControlHub;
use mech_core::ChannelStatus;
use mech_core::Gcs;
use mech_core::fleet::{Fleet, LogEntry, Robot, Severity};
use tokio::sync::{broadcast, watch};

use super::wire::{FromStation, LogLevel, to_line};
use crate::view::{
    ChannelView, ClusterControlView, ClusterOnScreen, FleetSnapshot, RobotView, RouteView,
    Security, TRAIL_SECONDS,
};

/// Log lines kept for a session that falls behind before it is told it
/// missed some.
const LOG_QUEUE: usize = 1024;

/// Recent log lines a client gets when it attaches.
pub(super) const LOG_HISTORY: usize = 50;

/// Shortest time between two snapshots (an event storm is coalesced).
const MIN_GAP: Duration = Duration::from_millis(10);

/// A log line ready to send: its sequence number and its wire line.
#[derive(Debug, Clone)]
pub(super) struct LogItem {
    pub seq: u64,
    pub line: Arc<str>,
}

/// The shared feed: subscribe to snapshots and log lines.
#[derive(Debug)]
pub(super) struct Feed {
    snapshots: watch::Sender<Arc<str>>,
    log: broadcast::Sender<LogItem>,
    task: tokio::task::JoinHandle<()>,
}

impl Feed {
    /// Starts making snapshots `rate` times a second (while anyone
    /// watches) and after every event.
    pub fn start(gcs: Gcs, control: ControlHub, rate: f64) -> Feed {
        let (snapshots, _) = watch::channel(Arc::<str>::from(""));
        let (log, _) = broadcast::channel(LOG_QUEUE);
        let maker = Maker {
            gcs,
            control,
            snapshots: snapshots.clone(),
            log: log.clone(),
            seq: 0,
            log_last: 0,
        };
        let task = tokio::spawn(maker.run(Duration::from_secs_f64(1.0 / rate)));
        Feed {
            snapshots,
            log,
            task,
        }
    }

    /// The newest snapshot line, and every later one.
    pub fn snapshots(&self) -> watch::Receiver<Arc<str>> {
        self.snapshots.subscribe()
    }

    /// Log lines from now on.
    pub fn log(&self) -> broadcast::Receiver<LogItem> {
        self.log.subscribe()
    }

    pub fn stop(&self) {
        self.task.abort();
    }
}

/// The feed's task state.
struct Maker {
    gcs: Gcs,
    control: ControlHub,
    snapshots: watch::Sender<Arc<str>>,
    log: broadcast::Sender<LogItem>,
    seq: u64,
    log_last: u64,
}

impl Maker {
    async fn run(mut self, period: Duration) {
        let mut events = self.gcs.router().subscribe_default(false);
        let mut tick = tokio::time::interval(period);
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
        loop {
            tokio::select! {
                _ = tick.tick() => {}
                ev = events.recv() => {
                    if ev.is_none() {
                        // The router stopped.
                        self.publish();
                        return;
                    }
                    // Let the rest of a burst arrive, then show it all.
                    tokio::time::sleep(MIN_GAP).await;
                    while events.try_recv().is_some() {}
                }
            }
            self.publish();
        }
    }

    /// New log lines, then a snapshot if anyone is watching.
    fn publish(&mut self) {
        let wanted = self.snapshots.receiver_count() > 0;
        let (snap, lines) = {
            // Channels and the controllers' reports lock the router's
            // tables: read them before the fleet (the lock order).
            let channels = wanted.then(|| self.gcs.router().channels());
            let control = wanted.then(|| self.control.snapshot());
            let (fleet, lines) = self.gcs.with_fleet(|f| {
                let lines = log_after(f, &mut self.log_last);
                (channels.map(|c| snapshot(f, c)), lines)
            });
            (
                fleet.map(|mut s| {
                    if let Some(c) = &control {
                        apply_control(&mut s, c);
                    }
                    s
                }),
                lines,
            )
        };
        for item in lines {
            // Nobody listening is fine: new clients read the history.
            let _ = self.log.send(item);
        }
        if let Some(mut fleet) = snap {
            let router = self.gcs.router();
            fleet.security = router.security();
            fleet.rejected = router.rejections().total();
            self.seq += 1;
            let line = to_line(&FromStation::Snapshot {
                seq: self.seq,
                fleet,
            });
            self.snapshots.send_replace(line.into());
        }
    }
}

/// The fleet log's lines after `last` (moving `last` on), as wire lines.
fn log_after(f: &Fleet, last: &mut u64) -> Vec<LogItem> {
    let mut out = Vec::new();
    for e in f.log_after(*last) {
        *last = e.seq;
        if let Some(item) = log_item(e) {
            out.push(item);
        }
    }
    out
}

/// The newest `n` log lines (debug lines left out), oldest first.
pub(super) fn log_history(f: &Fleet, n: usize) -> Vec<LogItem> {
    let mut items: Vec<LogItem> = f.log.iter().rev().filter_map(log_item).take(n).collect();
    items.reverse();
    items
}

fn log_item(e: &LogEntry) -> Option<LogItem> {
    let level = match e.severity {
        Severity::Debug => return None,
        Severity::Info => LogLevel::Info,
        Severity::Warn => LogLevel::Warn,
        Severity::Error => LogLevel::Error,
    };
    let line = to_line(&FromStation::Log {
        seq: e.seq,
        t: mech_control::script::secs(e.at),
        level,
        text: e.text.clone(),
    });
    Some(LogItem {
        seq: e.seq,
        line: line.into(),
    })
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
/// [`TRAIL_SECONDS`] before its newest telemetry.
fn recent_path(r: &Robot) -> Vec<(f64, f64)> {
    let Some(newest) = r.last_telemetry.or_else(|| r.path.back().map(|p| p.at)) else {
        return Vec::new();
    };
    let from = newest.saturating_sub(Duration::from_secs_f64(TRAIL_SECONDS));
    r.path
        .iter()
        .filter(|p| p.at >= from)
        .map(|p| (p.x, p.y))
        .collect()
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
