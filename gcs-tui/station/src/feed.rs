//! What every attached TUI is sent: the fleet snapshot, made and
//! serialized once for all of them at the snapshot rate and at once after
//! any event other than telemetry (a route change reaches every screen
//! without waiting for the next period), and the event log, which each
//! session reads from the fleet model after its own cursor ([`LogCursor`])
//! when the feed says it grew. A session forwards the newest snapshot
//! only, so a slow client skips snapshots instead of queueing them.

use std::sync::Arc;
use std::time::Duration;

use mech_control::ControlHub;
use mech_core::ChannelStatus;
use mech_core::Gcs;
use mech_core::fleet::{Fleet, LogEntry, Robot, Severity};
use tokio::sync::watch;

use crate::view::{
    ChannelView, ClusterControlView, ClusterOnScreen, FleetSnapshot, MissionView, RobotView,
    RouteView, SafetyView, Security, TRAIL_SECONDS,
};
use crate::wire::{FromStation, LogLevel, to_line};

/// Recent log lines a client gets when it attaches.
pub(crate) const LOG_HISTORY: usize = 50;

/// Shortest time between two snapshots (an event storm is coalesced).
const MIN_GAP: Duration = Duration::from_millis(3);

/// The shared feed: subscribe to snapshots and log lines.
#[derive(Debug)]
pub(crate) struct Feed {
    snapshots: watch::Sender<Arc<str>>,
    log_seq: watch::Sender<u64>,
    task: tokio::task::JoinHandle<()>,
}

impl Feed {
    /// Starts making snapshots `rate` times a second (while anyone
    /// watches) and after every event.
    pub fn start(gcs: Gcs, control: ControlHub, rate: f64) -> Feed {
        let (snapshots, _) = watch::channel(Arc::<str>::from(""));
        let (log_seq, _) = watch::channel(0);
        let maker = Maker {
            gcs,
            control,
            snapshots: snapshots.clone(),
            log_seq: log_seq.clone(),
            seq: 0,
        };
        let task = tokio::spawn(maker.run(Duration::from_secs_f64(1.0 / rate)));
        Feed {
            snapshots,
            log_seq,
            task,
        }
    }

    /// The newest snapshot line, and every later one.
    pub fn snapshots(&self) -> watch::Receiver<Arc<str>> {
        self.snapshots.subscribe()
    }

    /// The newest event-log line's sequence number, changed when it grows.
    pub fn log_seq(&self) -> watch::Receiver<u64> {
        self.log_seq.subscribe()
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
    log_seq: watch::Sender<u64>,
    seq: u64,
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

    /// Says how far the log has grown, then makes a snapshot if anyone
    /// is watching.
    fn publish(&mut self) {
        let wanted = self.snapshots.receiver_count() > 0;
        // Channels and the controllers' reports lock the router's tables:
        // read them before the fleet (the lock order).
        let channels = wanted.then(|| self.gcs.router().channels());
        let control = wanted.then(|| self.control.snapshot());
        let (snap, newest) = self.gcs.with_fleet(|f| {
            let newest = f.log.back().map_or(0, |e| e.seq);
            (channels.map(|c| snapshot(f, c)), newest)
        });
        self.log_seq.send_if_modified(|seq| {
            let grew = *seq != newest;
            *seq = newest;
            grew
        });
        let Some(mut fleet) = snap else {
            return;
        };
        if let Some(c) = &control {
            apply_control(&mut fleet, c);
        }
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

/// Where a session is in the event log: it sends each line once, in
/// order, and says so when lines it had not sent yet fell out of the log.
#[derive(Debug, Clone, Copy)]
pub(crate) struct LogCursor {
    last: u64,
}

impl LogCursor {
    /// Starting with the newest `n` lines (debug lines left out).
    pub fn recent(f: &Fleet, n: usize) -> LogCursor {
        let shown: Vec<u64> = f
            .log
            .iter()
            .rev()
            .filter(|e| e.severity != Severity::Debug)
            .take(n)
            .map(|e| e.seq)
            .collect();
        let last = shown
            .last()
            .map_or_else(|| f.log.back().map_or(0, |e| e.seq), |s| s - 1);
        LogCursor { last }
    }

    /// The wire lines of the log after the cursor, moving it on.
    pub fn take(&mut self, f: &Fleet) -> Vec<String> {
        self.messages(f).iter().map(to_line).collect()
    }

    /// The log's messages after the cursor, moving it on.
    pub fn messages(&mut self, f: &Fleet) -> Vec<FromStation> {
        let mut out = Vec::new();
        if let Some(first) = f.log.front() {
            if first.seq > self.last + 1 {
                let n = first.seq - self.last - 1;
                out.push(FromStation::Refused {
                    reason: format!("{n} event-log lines were missed: this client read too slowly"),
                });
            }
        }
        for e in f.log_after(self.last) {
            self.last = e.seq;
            out.extend(log_message(e));
        }
        out
    }
}

fn log_message(e: &LogEntry) -> Option<FromStation> {
    let level = match e.severity {
        Severity::Debug => return None,
        Severity::Info => LogLevel::Info,
        Severity::Warn => LogLevel::Warn,
        Severity::Error => LogLevel::Error,
    };
    Some(FromStation::Log {
        seq: e.seq,
        t: mech_control::script::secs(e.at),
        level,
        text: e.text.clone(),
    })
}

/// Converts the core's fleet model into what the screen shows. Read
/// `channels` from the router before taking the fleet lock, so that the
/// fleet is held for the copy alone: the router applies its events to the
/// fleet holding its delivery lock, and waits for whoever holds the fleet
/// (the lock order is [`Gcs::with_fleet`]'s).
pub fn snapshot(fleet: &Fleet, channels: Vec<ChannelStatus>) -> FleetSnapshot {
    let robots = fleet
        .robots
        .values()
        .map(|r| RobotView {
            name: r.name.clone(),
            id: r.registration.id,
            platform: r.registration.hello.platform.clone(),
            telemetry: r.telemetry.clone(),
            route: RouteView {
                channel: r.route.requested.clone().unwrap_or_default(),
                acknowledged: !r.route.is_pending(),
            },
            link: r.link,
            links: r
                .links
                .radio_budget_hz
                .map(|hz| format!("{} {hz}Hz", r.links.label()))
                .unwrap_or_default(),
            fault: r.fault.clone(),
            trail: recent_path(r),
            quality: r.quality,
            remote: r.remote.clone(),
            stale_for: r.stale_for(fleet.now).map(|age| age.as_secs_f64()),
            autopilot: r.autopilot.clone(),
            safety: safety_view(r),
            sent_mission: r.waypoints.sent.as_ref().map(|m| MissionView {
                id: m.id,
                channel: m.channel.clone(),
                waypoints: m.waypoints.clone(),
                looped: m.looped,
            }),
            mission_held: r
                .waypoints
                .sent
                .as_ref()
                .and_then(|m| m.held(&r.name, r.route.requested.as_deref())),
        })
        .collect();
    FleetSnapshot {
        robots,
        channels: channel_views(channels),
        estop: fleet.estop.engaged,
        security: Security::default(),
        rejected: 0,
        replay: None,
        arena: fleet.arena.clone(),
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

/// A robot's safety layer as its card shows it: `None` for a robot that
/// reports none and is not switched off.
fn safety_view(r: &Robot) -> Option<SafetyView> {
    let alarm = r.safety_alarm();
    match r.telemetry.safety {
        Some(s) => Some(SafetyView {
            state: s.state,
            intervention: s.intervention,
            interventions: s.counts.total(),
            alarm,
            footprint: s.radius + s.position_error,
            position_error: s.position_error,
        }),
        None if alarm => Some(SafetyView {
            state: mech_proto::SafetyState::NoArena,
            intervention: mech_proto::Intervention::None,
            interventions: 0,
            alarm,
            footprint: 0.0,
            position_error: 0.0,
        }),
        None => None,
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
