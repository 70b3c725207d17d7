//! The router's shared state and the decision for each message: who is
//! registered where, the routing table, live channels, pending missions and
//! e-stops, external subscribers and counters.
//!
//! Everything here is synchronous and runs under one `std::sync::Mutex` held
//! for a few hash lookups; the socket tasks call [`Tables::handle`] and then
//! send what it put in the [`Outbox`] after releasing the lock. Events are
//! collected and emitted after the lock is released, too.

use std::collections::{HashMap, HashSet};
use std::net::SocketAddr;

use mech_proto::{
    Body, Channels, ChannelsRequest, EStop, Envelope, Header, Heartbeat, Route, Welcome,
};
use tokio::time::Instant;
use tracing::{debug, info, warn};

use super::config::RouterConfig;
use super::rate::RateMeter;
use crate::counters::{ChannelStatus, Counters, DropReason, Drops, Traffic};
use crate::event::{Event, LinkState};

/// Where a message came from, and where a reply goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(crate) enum Peer {
    Udp(SocketAddr),
    /// A TCP connection, by the router's connection number.
    Tcp(u64),
    /// A publisher inside the GCS process.
    Local,
}

impl std::fmt::Display for Peer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Peer::Udp(a) => write!(f, "udp:{a}"),
            Peer::Tcp(n) => write!(f, "tcp#{n}"),
            Peer::Local => f.write_str("gcs"),
        }
    }
}

/// Messages to send once the table lock is released: `raw` targets get the
/// received bytes unchanged (the hot path: no re-encoding), `owned` ones get
/// messages the router made.
#[derive(Debug, Default)]
pub(crate) struct Outbox {
    pub(crate) raw: Vec<Peer>,
    pub(crate) owned: Vec<(Peer, Vec<u8>)>,
}

impl Outbox {
    pub(crate) fn is_empty(&self) -> bool {
        self.raw.is_empty() && self.owned.is_empty()
    }
}

/// What happened to one message, for in-process publishers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Delivery {
    /// Forwarded to this many robots.
    Forwarded(usize),
    /// Not forwarded, for this reason.
    Dropped(DropReason),
    /// A message for the router itself (registration, discovery, acks...).
    Consumed,
}

#[derive(Debug)]
struct RobotEntry {
    id: u16,
    addr: SocketAddr,
    last_seen: Instant,
    link: LinkState,
    route: Option<String>,
    epoch: u32,
    /// The robot acknowledged `epoch`.
    acked: bool,
    route_sent: Instant,
    heartbeat_sent: Instant,
    traffic: Traffic,
}

#[derive(Debug)]
struct ChannelEntry {
    publisher: String,
    last: Instant,
    rate: RateMeter,
    traffic: Traffic,
}

#[derive(Debug)]
struct PendingMission {
    robot: String,
    id: u32,
    bytes: Vec<u8>,
    reply_to: Peer,
    first: Instant,
    last: Instant,
}

#[derive(Debug)]
struct EStopRun {
    engage: bool,
    id: u32,
    pending: HashSet<String>,
    last: Instant,
}

/// The router's state. See the module docs.
#[derive(Debug)]
pub(crate) struct Tables {
    config: RouterConfig,
    robots: HashMap<String, RobotEntry>,
    next_id: u16,
    channels: HashMap<String, ChannelEntry>,
    /// Last address of each controller or tool, by sender name, for replies.
    peers: HashMap<String, Peer>,
    /// External telemetry subscribers and when their subscription lapses.
    subscribers: HashMap<Peer, Instant>,
    missions: Vec<PendingMission>,
    estop: Option<EStopRun>,
    /// E-stop engaged and not released: robots that register get it too.
    estop_latched: Option<u32>,
    next_estop_id: u32,
    next_mission_id: u32,
    seq: u32,
    received: u64,
    forwarded: u64,
    dropped: Drops,
    fanout_dropped: u64,
}

/// A seed for ids that must not repeat across GCS restarts (an agent treats a
/// repeated mission id as the same mission).
fn clock_seed() -> u32 {
    ((mech_proto::unix_micros() / 1_000_000) as u32)
        .max(1)
        .wrapping_mul(16)
}

fn route_of(channel: &str) -> Option<String> {
    (!channel.is_empty()).then(|| channel.to_string())
}

impl Tables {
    pub(crate) fn new(config: RouterConfig) -> Tables {
        let seed = clock_seed();
        Tables {
            config,
            robots: HashMap::new(),
            next_id: 1,
            channels: HashMap::new(),
            peers: HashMap::new(),
            subscribers: HashMap::new(),
            missions: Vec::new(),
            estop: None,
            estop_latched: None,
            next_estop_id: seed,
            next_mission_id: seed,
            seq: 0,
            received: 0,
            forwarded: 0,
            dropped: Default::default(),
            fanout_dropped: 0,
        }
    }

    /// Encodes a message from the router itself.
    fn make(&mut self, destination: &str, body: Body) -> Option<Vec<u8>> {
        self.seq = self.seq.wrapping_add(1);
        let header = Header {
            seq: self.seq,
            stamp_us: mech_proto::unix_micros(),
            sender: self.config.name.clone(),
            destination: destination.to_string(),
            channel: String::new(),
        };
        match mech_proto::encode(&Envelope::new(header, body)) {
            Ok(b) => Some(b),
            Err(e) => {
                warn!(error = %e, destination, "router could not encode its own message");
                None
            }
        }
    }

    fn bad(&mut self, from: Peer, error: String, events: &mut Vec<Event>) -> Delivery {
        self.dropped.count(DropReason::BadPacket);
        let n = self.dropped.bad_packet;
        // Logged at warn for the 1st, 2nd, 4th, 8th... so a flood of garbage
        // cannot flood the log; every one is counted and reported as an event.
        if n.is_power_of_two() {
            warn!(%from, %error, count = n, "bad packet");
        } else {
            debug!(%from, %error, "bad packet");
        }
        events.push(Event::BadPacket {
            from: from.to_string(),
            error,
        });
        Delivery::Dropped(DropReason::BadPacket)
    }

    /// Decides what to do with one received message.
    pub(crate) fn handle(
        &mut self,
        bytes: &[u8],
        from: Peer,
        now: Instant,
        out: &mut Outbox,
        events: &mut Vec<Event>,
    ) -> Delivery {
        self.received += 1;
        let head = match mech_proto::peek(bytes) {
            Ok(h) => h,
            Err(e) => return self.bad(from, e.to_string(), events),
        };
        if head.kind == mech_proto::COMMAND_KIND {
            // The body is checked (a truncated or out-of-range command is
            // never forwarded) but not re-encoded: the received bytes go on.
            // Checked in place: no envelope is built for a forwarded command.
            if let Err(e) = mech_proto::check_command(bytes, &head) {
                return self.bad(from, e.to_string(), events);
            }
            return self.route_command(&head, from, now, out, events);
        }
        let env = match mech_proto::decode(bytes) {
            Ok(env) => env,
            Err(e) => return self.bad(from, e.to_string(), events),
        };
        let sender = env.header.sender.as_str();
        if let Peer::Udp(addr) = from {
            self.seen_robot(sender, addr, now, events);
        }
        match env.body {
            Body::Hello(hello) => {
                let addr = match from {
                    Peer::Udp(a) => a,
                    _ => return self.bad(from, "Hello must come over UDP".into(), events),
                };
                if hello.name != sender {
                    return self.bad(
                        from,
                        format!("Hello for {} sent by {sender}", hello.name),
                        events,
                    );
                }
                self.register(hello, addr, now, out, events);
            }
            Body::Heartbeat(_) => {}
            Body::Telemetry(t) => {
                if self.robots.contains_key(sender) {
                    for (&peer, _) in self.subscribers.iter() {
                        out.raw.push(peer);
                    }
                    events.push(Event::Telemetry {
                        robot: sender.to_string(),
                        telemetry: t,
                    });
                } else {
                    self.dropped.count(DropReason::UnknownRobot);
                    return Delivery::Dropped(DropReason::UnknownRobot);
                }
            }
            Body::FleetCommand(fc) => {
                self.note_publisher(sender, &env.header.channel, from, now, events);
                let channel = env.header.channel.clone();
                let mut delivered = 0;
                for part in fc.parts {
                    let header = Header {
                        seq: env.header.seq,
                        stamp_us: env.header.stamp_us,
                        sender: env.header.sender.clone(),
                        destination: part.robot.clone(),
                        channel: channel.clone(),
                    };
                    let Ok(target) = self.check_route(&part.robot, &channel) else {
                        continue;
                    };
                    match mech_proto::encode(&Envelope::new(header, Body::Command(part.command))) {
                        Ok(b) => {
                            out.owned.push((Peer::Udp(target), b));
                            delivered += 1;
                        }
                        Err(e) => {
                            warn!(error = %e, robot = %part.robot, "cannot re-encode fleet command part")
                        }
                    }
                }
                return Delivery::Forwarded(delivered);
            }
            Body::Mission(m) => {
                let robot = env.header.destination.clone();
                self.note_publisher(sender, &env.header.channel, from, now, events);
                let Some(entry) = self.robots.get_mut(&robot) else {
                    self.dropped.count(DropReason::UnknownRobot);
                    return Delivery::Dropped(DropReason::UnknownRobot);
                };
                let addr = entry.addr;
                entry.traffic.forwarded += 1;
                self.forwarded += 1;
                out.owned.push((Peer::Udp(addr), bytes.to_vec()));
                self.missions
                    .retain(|p| !(p.robot == robot && p.id == m.id));
                self.missions.push(PendingMission {
                    robot: robot.clone(),
                    id: m.id,
                    bytes: bytes.to_vec(),
                    reply_to: from,
                    first: now,
                    last: now,
                });
                info!(%robot, id = m.id, waypoints = m.waypoints.len(), channel = %env.header.channel, "mission sent");
                events.push(Event::MissionSent {
                    robot,
                    channel: env.header.channel.clone(),
                    id: m.id,
                    waypoints: m.waypoints,
                    looped: m.looped,
                });
                return Delivery::Forwarded(1);
            }
            Body::MissionAck(ack) => {
                let before = self.missions.len();
                let mut reply = None;
                self.missions.retain(|p| {
                    let done = p.robot == sender && p.id == ack.id;
                    if done {
                        reply = Some(p.reply_to);
                    }
                    !done
                });
                if let Some(peer) = reply.filter(|p| *p != Peer::Local) {
                    out.raw.push(peer);
                }
                if self.missions.len() != before {
                    info!(
                        robot = sender,
                        id = ack.id,
                        accepted = ack.accepted,
                        "mission acknowledged"
                    );
                    events.push(Event::MissionAcked {
                        robot: sender.to_string(),
                        id: ack.id,
                        accepted: ack.accepted,
                        reason: ack.reason,
                    });
                }
            }
            Body::RouteAck(ack) => {
                if let Some(entry) = self.robots.get_mut(sender) {
                    let channel = route_of(&ack.channel);
                    if ack.epoch == entry.epoch && channel == entry.route && !entry.acked {
                        entry.acked = true;
                        info!(
                            robot = sender,
                            channel = channel.as_deref().unwrap_or("none"),
                            epoch = ack.epoch,
                            "route acknowledged"
                        );
                        events.push(Event::RouteAcked {
                            robot: sender.to_string(),
                            channel,
                            epoch: ack.epoch,
                        });
                    }
                }
            }
            Body::EStop(e) => {
                info!(%from, engage = e.engage, "e-stop requested by {sender}");
                self.start_estop(e.engage, now, out, events);
            }
            Body::EStopAck(ack) => {
                if let Some(run) = self.estop.as_mut() {
                    if run.id == ack.id && run.engage == ack.engage && run.pending.remove(sender) {
                        events.push(Event::EStopAcked {
                            robot: sender.to_string(),
                            engage: ack.engage,
                            id: ack.id,
                        });
                        if run.pending.is_empty() {
                            info!(
                                engage = run.engage,
                                id = run.id,
                                "every robot acknowledged the e-stop"
                            );
                            events.push(Event::EStopComplete {
                                engage: run.engage,
                                id: run.id,
                            });
                            self.estop = None;
                        }
                    }
                }
            }
            Body::ChannelsRequest(ChannelsRequest {}) => {
                let channels = self.channel_status(now);
                let body = Body::Channels(Channels {
                    channels: channels
                        .into_iter()
                        .map(|c| mech_proto::ChannelInfo {
                            name: c.name,
                            publisher: c.publisher,
                            rate_hz: c.rate_hz,
                            robots: c.robots,
                            idle_ms: c.idle.as_millis() as u64,
                        })
                        .collect(),
                });
                if let Some(b) = self.make(sender, body) {
                    out.owned.push((from, b));
                }
            }
            Body::Subscribe(s) => {
                if s.telemetry {
                    self.subscribers
                        .insert(from, now + self.config.subscriber_timeout);
                } else {
                    self.subscribers.remove(&from);
                }
            }
            Body::PositionFix(fix) => match self.robots.get(&fix.robot) {
                Some(r) => out.raw.push(Peer::Udp(r.addr)),
                None => {
                    self.dropped.count(DropReason::UnknownRobot);
                    return Delivery::Dropped(DropReason::UnknownRobot);
                }
            },
            Body::Notice(notice) => {
                events.push(Event::Notice {
                    from: sender.to_string(),
                    notice,
                });
            }
            Body::Cluster(command) => {
                self.note_publisher(sender, &env.header.channel, from, now, events);
                events.push(Event::ClusterCommand {
                    channel: env.header.channel.clone(),
                    command,
                });
            }
            Body::Bye(bye) => {
                if let Some(entry) = self.robots.get_mut(sender) {
                    entry.link = LinkState::Lost;
                    info!(robot = sender, reason = %bye.reason, "robot left");
                    events.push(Event::Bye {
                        robot: sender.to_string(),
                        reason: bye.reason,
                    });
                } else {
                    self.subscribers.remove(&from);
                }
            }
            Body::Command(_) | Body::Welcome(_) | Body::Route(_) | Body::Channels(_) => {
                return self.bad(
                    from,
                    format!("unexpected {} message", env.body.kind()),
                    events,
                );
            }
        }
        Delivery::Consumed
    }

    /// The hot path: forward a command if its robot is routed to its channel.
    fn route_command(
        &mut self,
        head: &mech_proto::Peek<'_>,
        from: Peer,
        now: Instant,
        out: &mut Outbox,
        events: &mut Vec<Event>,
    ) -> Delivery {
        let (sender, destination, channel) = (head.sender, head.destination, head.channel);
        if channel.is_empty() {
            self.dropped.count(DropReason::NotRouted);
            return Delivery::Dropped(DropReason::NotRouted);
        }
        self.note_publisher(sender, channel, from, now, events);
        match self.check_route(destination, channel) {
            Ok(addr) => {
                out.raw.push(Peer::Udp(addr));
                Delivery::Forwarded(1)
            }
            Err(reason) => Delivery::Dropped(reason),
        }
    }

    /// Counts a message published on `channel` and remembers its publisher.
    fn note_publisher(
        &mut self,
        sender: &str,
        channel: &str,
        from: Peer,
        now: Instant,
        events: &mut Vec<Event>,
    ) {
        if channel.is_empty() {
            return;
        }
        if from != Peer::Local && self.peers.get(sender) != Some(&from) {
            self.peers.insert(sender.to_string(), from);
        }
        let changed = match self.channels.get_mut(channel) {
            Some(c) => {
                c.traffic.received += 1;
                c.last = now;
                c.rate.record(now);
                if c.publisher != sender {
                    c.publisher.clear();
                    c.publisher.push_str(sender);
                    true
                } else {
                    false
                }
            }
            None => {
                let mut rate = RateMeter::new(now);
                rate.record(now);
                let traffic = Traffic {
                    received: 1,
                    ..Traffic::default()
                };
                let entry = ChannelEntry {
                    publisher: sender.to_string(),
                    last: now,
                    rate,
                    traffic,
                };
                self.channels.insert(channel.to_string(), entry);
                true
            }
        };
        if changed {
            info!(channel, publisher = sender, %from, "channel publisher");
            events.push(Event::ChannelPublisher {
                channel: channel.to_string(),
                publisher: sender.to_string(),
            });
        }
    }

    /// Whether `robot` obeys `channel` now; counts the outcome for the robot
    /// and the channel (which [`Tables::note_publisher`] created).
    fn check_route(&mut self, robot: &str, channel: &str) -> Result<SocketAddr, DropReason> {
        let outcome = match self.robots.get_mut(robot) {
            None => Err(DropReason::UnknownRobot),
            Some(r) if r.route.as_deref() == Some(channel) => {
                r.traffic.forwarded += 1;
                Ok(r.addr)
            }
            Some(r) => {
                r.traffic.dropped.count(DropReason::NotRouted);
                Err(DropReason::NotRouted)
            }
        };
        let traffic = self.channels.get_mut(channel).map(|c| &mut c.traffic);
        match outcome {
            Ok(_) => {
                self.forwarded += 1;
                if let Some(t) = traffic {
                    t.forwarded += 1;
                }
            }
            Err(reason) => match traffic {
                Some(t) => t.dropped.count(reason),
                None => self.dropped.count(reason),
            },
        }
        outcome
    }

    /// Liveness: any message from a registered robot's name over UDP.
    fn seen_robot(
        &mut self,
        sender: &str,
        addr: SocketAddr,
        now: Instant,
        events: &mut Vec<Event>,
    ) {
        if let Some(r) = self.robots.get_mut(sender) {
            r.last_seen = now;
            r.traffic.received += 1;
            if r.addr != addr {
                info!(robot = sender, old = %r.addr, new = %addr, "robot moved to a new address");
                r.addr = addr;
            }
            if r.link != LinkState::Connected {
                r.link = LinkState::Connected;
                info!(robot = sender, "robot connected");
                events.push(Event::Link {
                    robot: sender.to_string(),
                    state: LinkState::Connected,
                });
            }
        }
    }

    fn register(
        &mut self,
        hello: mech_proto::Hello,
        addr: SocketAddr,
        now: Instant,
        out: &mut Outbox,
        events: &mut Vec<Event>,
    ) {
        let known = self.robots.contains_key(&hello.name);
        if !known {
            let id = self.next_id;
            self.next_id = self.next_id.wrapping_add(1).max(1);
            let route = self.config.default_route.clone();
            let epoch = u32::from(route.is_some());
            self.robots.insert(
                hello.name.clone(),
                RobotEntry {
                    id,
                    addr,
                    last_seen: now,
                    link: LinkState::Connected,
                    route: route.clone(),
                    epoch,
                    acked: route.is_none(),
                    route_sent: now,
                    heartbeat_sent: now,
                    traffic: Traffic {
                        received: 1,
                        ..Traffic::default()
                    },
                },
            );
            info!(robot = %hello.name, platform = %hello.platform, %addr, id, "robot registered");
            if route.is_some() {
                events.push(Event::RouteChanged {
                    robot: hello.name.clone(),
                    channel: route,
                    epoch,
                });
            }
        } else {
            info!(robot = %hello.name, %addr, "robot registered again");
        }
        let Some(entry) = self.robots.get_mut(&hello.name) else {
            return;
        };
        entry.route_sent = now;
        let (id, route) = (
            entry.id,
            Route {
                robot: hello.name.clone(),
                channel: entry.route.clone().unwrap_or_default(),
                epoch: entry.epoch,
            },
        );
        // An agent that restarted has forgotten its route: it must confirm it.
        if known {
            entry.acked = false;
        }
        events.push(Event::Registered {
            robot: hello.name.clone(),
            id,
            addr,
            platform: hello.platform.clone(),
            capabilities: hello.capabilities.clone(),
            motors: hello.motors,
            max_speed: hello.max_speed,
            max_yaw_rate: hello.max_yaw_rate,
            known,
        });
        let welcome = Body::Welcome(Welcome {
            robot_id: id,
            route,
            router_version: env!("CARGO_PKG_VERSION").into(),
        });
        if let Some(b) = self.make(&hello.name, welcome) {
            out.owned.push((Peer::Udp(addr), b));
        }
        if let Some(id) = self.estop_latched {
            let run = self.estop.get_or_insert_with(|| EStopRun {
                engage: true,
                id,
                pending: HashSet::new(),
                last: now,
            });
            if run.engage && run.id == id {
                run.pending.insert(hello.name.clone());
                if let Some(b) = self.make(&hello.name, Body::EStop(EStop { engage: true, id })) {
                    out.owned.push((Peer::Udp(addr), b));
                }
            }
        }
    }

    /// Changes a robot's route; the very next message is judged by the new
    /// entry. Returns the new epoch.
    pub(crate) fn set_route(
        &mut self,
        robot: &str,
        channel: Option<&str>,
        now: Instant,
        out: &mut Outbox,
        events: &mut Vec<Event>,
    ) -> Option<u32> {
        let entry = self.robots.get_mut(robot)?;
        entry.route = channel.map(str::to_string);
        entry.epoch = entry.epoch.wrapping_add(1);
        entry.acked = false;
        entry.route_sent = now;
        let (addr, epoch) = (entry.addr, entry.epoch);
        let route = Route {
            robot: robot.to_string(),
            channel: channel.unwrap_or_default().to_string(),
            epoch,
        };
        info!(
            robot,
            channel = channel.unwrap_or("none"),
            epoch,
            "route changed"
        );
        events.push(Event::RouteChanged {
            robot: robot.to_string(),
            channel: channel.map(str::to_string),
            epoch,
        });
        if let Some(b) = self.make(robot, Body::Route(route)) {
            out.owned.push((Peer::Udp(addr), b));
        }
        Some(epoch)
    }

    /// Engages or releases the e-stop for every robot, repeated until each
    /// acknowledges. Returns its id.
    pub(crate) fn start_estop(
        &mut self,
        engage: bool,
        now: Instant,
        out: &mut Outbox,
        events: &mut Vec<Event>,
    ) -> u32 {
        self.next_estop_id = self.next_estop_id.wrapping_add(1);
        let id = self.next_estop_id;
        self.estop_latched = engage.then_some(id);
        let pending: HashSet<String> = self.robots.keys().cloned().collect();
        if engage {
            warn!(id, robots = pending.len(), "E-STOP engaged");
        } else {
            warn!(id, robots = pending.len(), "e-stop released");
        }
        events.push(Event::EStop { engage, id });
        let targets: Vec<(String, SocketAddr)> = self
            .robots
            .iter()
            .map(|(n, r)| (n.clone(), r.addr))
            .collect();
        for (name, addr) in targets {
            if let Some(b) = self.make(&name, Body::EStop(EStop { engage, id })) {
                out.owned.push((Peer::Udp(addr), b));
            }
        }
        if pending.is_empty() {
            events.push(Event::EStopComplete { engage, id });
            self.estop = None;
        } else {
            self.estop = Some(EStopRun {
                engage,
                id,
                pending,
                last: now,
            });
        }
        id
    }

    /// A fresh mission id (see [`clock_seed`]).
    pub(crate) fn mission_id(&mut self) -> u32 {
        self.next_mission_id = self.next_mission_id.wrapping_add(1);
        self.next_mission_id
    }

    /// Timers: heartbeats, link states, retries, lapsed subscriptions.
    pub(crate) fn tick(&mut self, now: Instant, out: &mut Outbox, events: &mut Vec<Event>) {
        let cfg = &self.config;
        let (stale, lost, hb, route_retry) = (
            cfg.stale_after,
            cfg.lost_after,
            cfg.heartbeat_period,
            cfg.route_retry,
        );
        let mut sends: Vec<(String, SocketAddr, Body)> = Vec::new();
        for (name, r) in self.robots.iter_mut() {
            let silent = now.saturating_duration_since(r.last_seen);
            let link = if silent >= lost {
                LinkState::Lost
            } else if silent >= stale {
                LinkState::Stale
            } else {
                LinkState::Connected
            };
            // A robot that said Bye stays lost until it speaks again.
            if link != r.link && !(r.link == LinkState::Lost && link != LinkState::Connected) {
                if link == LinkState::Lost {
                    warn!(robot = %name, silent_ms = silent.as_millis() as u64, "robot disconnected");
                } else {
                    debug!(robot = %name, link = link.as_str(), "link state");
                }
                r.link = link;
                events.push(Event::Link {
                    robot: name.clone(),
                    state: link,
                });
            }
            if now.saturating_duration_since(r.heartbeat_sent) >= hb {
                r.heartbeat_sent = now;
                sends.push((
                    name.clone(),
                    r.addr,
                    Body::Heartbeat(Heartbeat { uptime_ms: 0 }),
                ));
            }
            if !r.acked && now.saturating_duration_since(r.route_sent) >= route_retry {
                r.route_sent = now;
                let route = Route {
                    robot: name.clone(),
                    channel: r.route.clone().unwrap_or_default(),
                    epoch: r.epoch,
                };
                sends.push((name.clone(), r.addr, Body::Route(route)));
            }
        }
        if let Some(run) = self.estop.as_mut() {
            if now.saturating_duration_since(run.last) >= self.config.estop_retry {
                run.last = now;
                for name in &run.pending {
                    if let Some(r) = self.robots.get(name) {
                        sends.push((
                            name.clone(),
                            r.addr,
                            Body::EStop(EStop {
                                engage: run.engage,
                                id: run.id,
                            }),
                        ));
                    }
                }
            }
        }
        for (name, addr, body) in sends {
            if let Some(b) = self.make(&name, body) {
                out.owned.push((Peer::Udp(addr), b));
            }
        }
        let (retry, give_up) = (self.config.mission_retry, self.config.mission_give_up);
        let robots = &self.robots;
        self.missions.retain_mut(|m| {
            if now.saturating_duration_since(m.first) >= give_up {
                warn!(robot = %m.robot, id = m.id, "mission not acknowledged, giving up");
                events.push(Event::MissionFailed {
                    robot: m.robot.clone(),
                    id: m.id,
                    reason: format!("not acknowledged within {:.1} s", give_up.as_secs_f64()),
                });
                return false;
            }
            if now.saturating_duration_since(m.last) >= retry {
                m.last = now;
                if let Some(r) = robots.get(&m.robot) {
                    out.owned.push((Peer::Udp(r.addr), m.bytes.clone()));
                }
            }
            true
        });
        self.subscribers.retain(|_, until| *until > now);
    }

    /// Live channels (published within `channel_live_for`), by name.
    pub(crate) fn channel_status(&self, now: Instant) -> Vec<ChannelStatus> {
        let mut list: Vec<ChannelStatus> = self
            .channels
            .iter()
            .filter(|(_, c)| now.saturating_duration_since(c.last) < self.config.channel_live_for)
            .map(|(name, c)| {
                let mut robots: Vec<String> = self
                    .robots
                    .iter()
                    .filter(|(_, r)| r.route.as_deref() == Some(name.as_str()))
                    .map(|(n, _)| n.clone())
                    .collect();
                robots.sort();
                ChannelStatus {
                    name: name.clone(),
                    publisher: c.publisher.clone(),
                    rate_hz: c.rate.rate_hz(now),
                    robots,
                    idle: now.saturating_duration_since(c.last),
                }
            })
            .collect();
        list.sort_by(|a, b| a.name.cmp(&b.name));
        list
    }

    pub(crate) fn counters(&self) -> Counters {
        Counters {
            robots: self
                .robots
                .iter()
                .map(|(n, r)| (n.clone(), r.traffic))
                .collect(),
            channels: self
                .channels
                .iter()
                .map(|(n, c)| (n.clone(), c.traffic))
                .collect(),
            received: self.received,
            forwarded: self.forwarded,
            dropped: self.dropped,
            fanout_dropped: self.fanout_dropped,
        }
    }

    pub(crate) fn count_send_failure(&mut self, fanout: bool) {
        if fanout {
            self.fanout_dropped += 1;
        } else {
            self.dropped.count(DropReason::SendFailed);
        }
    }

    /// Counts a bad frame seen outside [`Tables::handle`].
    pub(crate) fn count_bad(&mut self, from: Peer, error: String, events: &mut Vec<Event>) {
        self.bad(from, error, events);
    }

    /// Forgets a peer that went away (its subscription and reply address).
    pub(crate) fn forget_peer(&mut self, peer: Peer) {
        self.subscribers.remove(&peer);
        self.peers.retain(|_, p| *p != peer);
    }

    /// Address of a registered robot.
    pub(crate) fn robot_addr(&self, robot: &str) -> Option<SocketAddr> {
        self.robots.get(robot).map(|r| r.addr)
    }
}
