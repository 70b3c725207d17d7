//! Router events and their fan-out: what happened (a robot registered, a
//! route was acknowledged, telemetry arrived...), stamped with router time,
//! delivered to the fleet model first and then to every subscriber through a
//! bounded queue that drops (and counts) rather than block the routing path.

use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use mech_proto::{ClusterCommand, CommandKind, Notice, Telemetry, Waypoint};
use tokio::sync::mpsc;
use tokio::time::Instant;

use crate::fleet::{Fleet, LinkState};

/// Something the router did or saw. Subscribers receive them in order, each
/// wrapped in a [`Stamped`].
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// The router is bound and running.
    Listening {
        udp: SocketAddr,
        tcp: Option<SocketAddr>,
    },
    /// A robot's `Hello` was accepted (first time, or again after a restart
    /// or from a new address: `known` says which).
    Registered {
        robot: String,
        id: u16,
        addr: SocketAddr,
        platform: String,
        capabilities: Vec<CommandKind>,
        motors: u8,
        max_speed: f64,
        max_yaw_rate: f64,
        known: bool,
    },
    /// A robot's link state changed.
    Link { robot: String, state: LinkState },
    /// A robot sent telemetry.
    Telemetry { robot: String, telemetry: Telemetry },
    /// The routing table changed; the robot has not acknowledged yet.
    RouteChanged {
        robot: String,
        channel: Option<String>,
        epoch: u32,
    },
    /// The robot acknowledged the route with this epoch.
    RouteAcked {
        robot: String,
        channel: Option<String>,
        epoch: u32,
    },
    /// A mission is on its way to a robot (retried until acknowledged).
    MissionSent {
        robot: String,
        channel: String,
        id: u32,
        waypoints: Vec<Waypoint>,
        looped: bool,
    },
    /// The robot acknowledged (or refused) the mission.
    MissionAcked {
        robot: String,
        id: u32,
        accepted: bool,
        reason: String,
    },
    /// The mission was not acknowledged in time.
    MissionFailed {
        robot: String,
        id: u32,
        reason: String,
    },
    /// E-stop engaged (`engage`) or released, for every robot.
    EStop { engage: bool, id: u32 },
    /// One robot acknowledged the e-stop or release `id`.
    EStopAcked {
        robot: String,
        engage: bool,
        id: u32,
    },
    /// Every robot known when it was sent acknowledged e-stop/release `id`.
    EStopComplete { engage: bool, id: u32 },
    /// A channel published for the first time, or got a new publisher.
    ChannelPublisher { channel: String, publisher: String },
    /// A cluster command published on a channel, for the fleet controller
    /// that serves it.
    ClusterCommand {
        channel: String,
        command: ClusterCommand,
    },
    /// A robot said goodbye.
    Bye { robot: String, reason: String },
    /// A notice from a robot or controller.
    Notice { from: String, notice: Notice },
    /// A datagram or frame that could not be used.
    BadPacket { from: String, error: String },
}

impl Event {
    /// Short snake_case name, as printed in JSON output.
    pub fn name(&self) -> &'static str {
        match self {
            Event::Listening { .. } => "listening",
            Event::Registered { .. } => "registered",
            Event::Link { .. } => "link",
            Event::Telemetry { .. } => "telemetry",
            Event::RouteChanged { .. } => "route_changed",
            Event::RouteAcked { .. } => "route_acked",
            Event::MissionSent { .. } => "mission_sent",
            Event::MissionAcked { .. } => "mission_acked",
            Event::MissionFailed { .. } => "mission_failed",
            Event::EStop { .. } => "estop",
            Event::EStopAcked { .. } => "estop_acked",
            Event::EStopComplete { .. } => "estop_complete",
            Event::ChannelPublisher { .. } => "channel_publisher",
            Event::ClusterCommand { .. } => "cluster_command",
            Event::Bye { .. } => "bye",
            Event::Notice { .. } => "notice",
            Event::BadPacket { .. } => "bad_packet",
        }
    }
}

/// An event with the router time it happened at (tokio time, so tests with a
/// paused clock see exact times).
#[derive(Debug, Clone, PartialEq)]
pub struct Stamped {
    /// Time since the router started.
    pub at: Duration,
    pub event: Event,
}

/// A subscriber's end: a bounded queue of events. When the subscriber falls
/// behind, new events for it are dropped and counted in [`Subscription::dropped`];
/// the router and other subscribers are not slowed.
#[derive(Debug)]
pub struct Subscription {
    rx: mpsc::Receiver<Arc<Stamped>>,
    dropped: Arc<AtomicU64>,
    telemetry: bool,
}

impl Subscription {
    /// The next event, or `None` once the router has shut down.
    pub async fn recv(&mut self) -> Option<Arc<Stamped>> {
        self.rx.recv().await
    }

    /// The next event if one is queued.
    pub fn try_recv(&mut self) -> Option<Arc<Stamped>> {
        self.rx.try_recv().ok()
    }

    /// Events dropped because this subscriber's queue was full.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }

    /// Whether this subscription receives telemetry events.
    pub fn has_telemetry(&self) -> bool {
        self.telemetry
    }
}

#[derive(Debug)]
struct Subscriber {
    tx: mpsc::Sender<Arc<Stamped>>,
    dropped: Arc<AtomicU64>,
    telemetry: bool,
}

/// Fan-out of router events: the fleet model is updated synchronously (it
/// must never miss a route or link change), then each subscriber's queue is
/// offered the event without waiting.
#[derive(Debug)]
pub(crate) struct EventBus {
    start: Instant,
    fleet: Arc<Mutex<Fleet>>,
    subscribers: Mutex<Vec<Subscriber>>,
}

impl EventBus {
    pub(crate) fn new(start: Instant, fleet: Arc<Mutex<Fleet>>) -> EventBus {
        EventBus {
            start,
            fleet,
            subscribers: Mutex::new(Vec::new()),
        }
    }

    pub(crate) fn subscribe(&self, capacity: usize, telemetry: bool) -> Subscription {
        let (tx, rx) = mpsc::channel(capacity.max(1));
        let dropped = Arc::new(AtomicU64::new(0));
        lock(&self.subscribers).push(Subscriber {
            tx,
            dropped: dropped.clone(),
            telemetry,
        });
        Subscription {
            rx,
            dropped,
            telemetry,
        }
    }

    /// Time since the router started.
    pub(crate) fn elapsed(&self) -> Duration {
        Instant::now().saturating_duration_since(self.start)
    }

    pub(crate) fn emit(&self, event: Event) {
        let stamped = Arc::new(Stamped {
            at: self.elapsed(),
            event,
        });
        lock(&self.fleet).apply(&stamped);
        let is_telemetry = matches!(stamped.event, Event::Telemetry { .. });
        let mut subs = lock(&self.subscribers);
        subs.retain(|s| {
            if is_telemetry && !s.telemetry {
                return true;
            }
            match s.tx.try_send(stamped.clone()) {
                Ok(()) => true,
                Err(mpsc::error::TrySendError::Full(_)) => {
                    s.dropped.fetch_add(1, Ordering::Relaxed);
                    true
                }
                Err(mpsc::error::TrySendError::Closed(_)) => false,
            }
        });
    }

    /// Closes every subscription (after shutdown, `recv` returns `None`).
    pub(crate) fn close(&self) {
        lock(&self.subscribers).clear();
    }
}

/// Locks a mutex, recovering the data if a panicking thread poisoned it: the
/// router's tables stay usable (every update is a single assignment or
/// counter increment, so no half-written state survives a panic).
pub(crate) fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}
