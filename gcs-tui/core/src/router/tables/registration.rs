//! Registration and liveness: the registry of robots, `Hello` (register,
//! or register again after a restart or from a new address), `Bye`, link
//! states from silence, the router's heartbeats, and senders the router
//! does not know told to register again.
//!
//! The registry holds one [`RobotEntry`] per robot, made of each concern's
//! part (its route, links, link meter, traffic) so the hot path finds all
//! of a robot with one lookup; each part's rules are in its concern's file.

use std::collections::{BTreeMap, HashMap};
use std::time::Duration;

use mech_proto::{Body, Bye, Heartbeat, Hello, Level, Notice, NoticeCode, Welcome};
use tokio::time::Instant;
use tracing::{debug, info, warn};

use super::link_quality::LinkMeter;
use super::links::Links;
use super::routes::RouteState;
use super::traffic::Tally;
use super::{Ctx, Delivery, Incoming, Peer, Tables};
use crate::counters::Traffic;
use crate::event::{Event, LinkState};

/// Most unknown senders remembered for rate-limiting the "register again"
/// notice; beyond it the memory is cleared.
const UNKNOWN_SENDERS: usize = 4096;

/// Every registered robot, by name, and what registration remembers about
/// senders it does not know.
#[derive(Debug)]
pub(super) struct Robots {
    by_name: HashMap<String, RobotEntry>,
    /// When each unknown sender was last told to register again.
    unknown_told: HashMap<String, Instant>,
    /// When the router started, for the uptime in its heartbeats.
    started: Instant,
}

/// One registered robot: its id and liveness, and the parts the
/// forwarding path reads (its route, links, link meter and counts).
#[derive(Debug)]
pub(super) struct RobotEntry {
    id: u16,
    liveness: Liveness,
    pub(super) route: RouteState,
    /// Where the robot is heard (UDP, a radio), and so where to send.
    pub(super) links: Links,
    /// Rates each way, loss and round trip (see `super::link_quality`).
    pub(super) meter: LinkMeter,
    pub(super) traffic: Tally,
}

/// How recently a robot was heard, and when the router last beat to it.
#[derive(Debug)]
struct Liveness {
    last_seen: Instant,
    link: LinkState,
    heartbeat_sent: Instant,
}

impl Robots {
    pub(super) fn new(now: Instant) -> Robots {
        Robots {
            by_name: HashMap::new(),
            unknown_told: HashMap::new(),
            started: now,
        }
    }

    pub(super) fn get(&self, name: &str) -> Option<&RobotEntry> {
        self.by_name.get(name)
    }

    pub(super) fn get_mut(&mut self, name: &str) -> Option<&mut RobotEntry> {
        self.by_name.get_mut(name)
    }

    pub(super) fn contains(&self, name: &str) -> bool {
        self.by_name.contains_key(name)
    }

    pub(super) fn iter(&self) -> impl Iterator<Item = (&String, &RobotEntry)> {
        self.by_name.iter()
    }

    pub(super) fn iter_mut(&mut self) -> impl Iterator<Item = (&String, &mut RobotEntry)> {
        self.by_name.iter_mut()
    }

    pub(super) fn names(&self) -> impl Iterator<Item = &String> {
        self.by_name.keys()
    }

    /// Each robot's traffic counters.
    pub(super) fn traffic(&self) -> BTreeMap<String, Traffic> {
        self.by_name
            .iter()
            .map(|(n, r)| (n.clone(), r.traffic.traffic()))
            .collect()
    }

    /// The id a newly registered robot gets: the number its name ends with
    /// (`robot_12` is #12), so the id the operator reads agrees with the
    /// name whatever order robots register in; when the name has no number
    /// in `1..=65535` or another robot holds it, the highest id no robot
    /// holds (65535, 65534...), which stays clear of the small numbers names
    /// carry.
    fn id_for(&self, name: &str) -> u16 {
        // The ids held, gathered once: asking each robot for every id tried
        // made a fleet of names without numbers cost cubic time to register.
        let taken: std::collections::HashSet<u16> = self.by_name.values().map(|r| r.id).collect();
        match crate::names::trailing_number(name) {
            Some(n) if !taken.contains(&n) => n,
            _ => (1..=u16::MAX)
                .rev()
                .find(|id| !taken.contains(id))
                .unwrap_or(0),
        }
    }

    /// Whether `sender`, unknown, is due a "register again" notice (at most
    /// one every `gap`); notes it as told when it is.
    fn tell_unknown(&mut self, sender: &str, now: Instant, gap: Duration) -> bool {
        let recent = self
            .unknown_told
            .get(sender)
            .is_some_and(|t| now.saturating_duration_since(*t) < gap);
        if recent {
            return false;
        }
        if self.unknown_told.len() >= UNKNOWN_SENDERS {
            self.unknown_told.clear();
        }
        self.unknown_told.insert(sender.to_string(), now);
        true
    }
}

impl Liveness {
    fn new(now: Instant) -> Liveness {
        Liveness {
            last_seen: now,
            link: LinkState::Connected,
            heartbeat_sent: now,
        }
    }

    /// The robot was heard at `now`; `true` if that reconnects it.
    fn heard(&mut self, now: Instant) -> bool {
        self.last_seen = now;
        let reconnected = self.link != LinkState::Connected;
        self.link = LinkState::Connected;
        reconnected
    }

    /// The link state silence gives at `now`, if it changed. A robot that
    /// said Bye stays lost until it speaks again.
    fn after_silence(
        &mut self,
        now: Instant,
        stale: Duration,
        lost: Duration,
    ) -> Option<LinkState> {
        let silent = now.saturating_duration_since(self.last_seen);
        let link = if silent >= lost {
            LinkState::Lost
        } else if silent >= stale {
            LinkState::Stale
        } else {
            LinkState::Connected
        };
        if link == self.link || (self.link == LinkState::Lost && link != LinkState::Connected) {
            return None;
        }
        self.link = link;
        Some(link)
    }

    /// Whether a heartbeat is due at `now` (noted as sent when it is).
    fn beat_due(&mut self, now: Instant, period: Duration) -> bool {
        let due = now.saturating_duration_since(self.heartbeat_sent) >= period;
        if due {
            self.heartbeat_sent = now;
        }
        due
    }

    fn silent(&self, now: Instant) -> Duration {
        now.saturating_duration_since(self.last_seen)
    }
}

impl Tables {
    pub(super) fn on_hello(&mut self, m: Incoming<'_>, hello: Hello, cx: &mut Ctx<'_>) -> Delivery {
        if !matches!(cx.from, Peer::Udp(_) | Peer::Serial(_)) {
            return self.bad("Hello must come over UDP or a radio".into(), cx);
        }
        if hello.name != m.header.sender {
            let why = format!("Hello for {} sent by {}", hello.name, m.header.sender);
            return self.bad(why, cx);
        }
        self.register(hello, m.header.seq, cx);
        Delivery::Consumed
    }

    /// Registers a robot (again, after a restart or from a new address: its
    /// id and route are kept, but it must confirm the route), welcomes it
    /// with its id and route on the link the Hello came on, gives it a
    /// latched e-stop, and sends it the station's arena. `seq` is the Hello's sequence number: a robot numbers
    /// its messages afresh when it registers again.
    pub(super) fn register(&mut self, hello: Hello, seq: u32, cx: &mut Ctx<'_>) {
        let known = self.robots.contains(&hello.name);
        if known {
            info!(robot = %hello.name, from = %cx.from, "robot registered again");
        } else {
            self.enrol(&hello, cx);
        }
        let addr = self.link_addr(cx.from);
        let Some(entry) = self.robots.get_mut(&hello.name) else {
            return;
        };
        if known {
            entry.meter.renumbered(seq);
            // An agent that restarted has forgotten its route: it must
            // confirm it.
            entry.route.unconfirmed(cx.now);
        } else {
            entry.meter.received(seq);
        }
        let id = entry.id;
        let route = entry.route.wire(&hello.name);
        let name = hello.name.clone();
        cx.event(Event::Registered {
            hello,
            id,
            addr,
            known,
        });
        let welcome = Body::Welcome(Welcome {
            robot_id: id,
            route,
            router_version: env!("CARGO_PKG_VERSION").into(),
        });
        if let Some(b) = self.make(&name, welcome) {
            cx.send(cx.from, b);
        }
        self.estop_newcomer(&name, cx);
        self.arena_newcomer(&name, cx);
    }

    /// A robot's first registration: its id (see [`Robots::id_for`]), and
    /// the configured default route (none unless configured, so it holds
    /// still).
    fn enrol(&mut self, hello: &Hello, cx: &mut Ctx<'_>) {
        let id = self.robots.id_for(&hello.name);
        let default = self.config.default_route.clone();
        let (route, routed) = RouteState::first(&hello.name, default, cx.now);
        if let Some(e) = routed {
            cx.event(e);
        }
        let entry = RobotEntry {
            id,
            liveness: Liveness::new(cx.now),
            route,
            links: Links::new(cx.from, cx.now),
            meter: LinkMeter::new(cx.now),
            traffic: Tally::first(),
        };
        self.safety.enrol(&hello.name, cx.now);
        self.robots.by_name.insert(hello.name.clone(), entry);
        info!(robot = %hello.name, platform = %hello.platform, from = %cx.from, id, "robot registered");
    }

    pub(super) fn on_bye(&mut self, m: Incoming<'_>, bye: Bye, cx: &mut Ctx<'_>) -> Delivery {
        let sender = m.header.sender.as_str();
        if let Some(entry) = self.robots.get_mut(sender) {
            entry.liveness.link = LinkState::Lost;
            info!(robot = sender, reason = %bye.reason, "robot left");
            cx.event(Event::Bye {
                robot: sender.to_string(),
                reason: bye.reason,
            });
        } else {
            self.subscribers.remove(cx.from);
        }
        Delivery::Consumed
    }

    /// Liveness: any message from a registered robot's name over UDP or
    /// a radio; its sequence number `seq` goes to the link measurement.
    pub(super) fn seen_robot(&mut self, sender: &str, seq: u32, cx: &mut Ctx<'_>) {
        let Some(r) = self.robots.get_mut(sender) else {
            return;
        };
        r.traffic.heard();
        r.meter.received(seq);
        if let Some(old) = r.links.heard(cx.from, cx.now) {
            info!(robot = sender, %old, new = %cx.from, "robot moved to a new address");
        }
        if r.liveness.heard(cx.now) {
            info!(robot = sender, "robot connected");
            cx.event(Event::Link {
                robot: sender.to_string(),
                state: LinkState::Connected,
            });
        }
    }

    /// Link states from silence: stale, then lost.
    pub(super) fn update_links(&mut self, cx: &mut Ctx<'_>) {
        let (stale, lost) = (self.config.stale_after, self.config.lost_after);
        for (name, r) in self.robots.iter_mut() {
            let Some(link) = r.liveness.after_silence(cx.now, stale, lost) else {
                continue;
            };
            if link == LinkState::Lost {
                let silent_ms = r.liveness.silent(cx.now).as_millis() as u64;
                warn!(robot = %name, silent_ms, "robot disconnected");
            } else {
                debug!(robot = %name, link = link.as_str(), "link state");
            }
            cx.event(Event::Link {
                robot: name.clone(),
                state: link,
            });
        }
    }

    /// The router's heartbeat to every robot, every `heartbeat_period`, on
    /// each of its links (a robot with two links hears which are alive),
    /// remembered so the robot's echo of it times the round trip.
    pub(super) fn send_heartbeats(&mut self, cx: &mut Ctx<'_>) {
        let (now, period) = (cx.now, self.config.heartbeat_period);
        let mut due = Vec::new();
        for (name, r) in self.robots.iter_mut() {
            if r.liveness.beat_due(now, period) {
                due.extend(r.links.all().map(|peer| (name.clone(), peer)));
            }
        }
        let uptime_ms = now
            .saturating_duration_since(self.robots.started)
            .as_millis() as u64;
        for (name, peer) in due {
            let body = Body::Heartbeat(Heartbeat::new(uptime_ms));
            if let Some(b) = self.make(&name, body) {
                let seq = self.seq;
                if let Some(r) = self.robots.get_mut(&name) {
                    r.meter.beat_sent(seq, now);
                }
                cx.send(peer, b);
            }
        }
    }

    /// `Bye` to every registered robot: the station is stopping, so each
    /// knows now instead of after its router timeout.
    pub(crate) fn farewell(&mut self, cx: &mut Ctx<'_>) {
        let links: Vec<_> = self
            .robots
            .iter()
            .flat_map(|(n, r)| r.links.all().map(|peer| (n.clone(), peer)))
            .collect();
        for (name, peer) in links {
            let body = Body::Bye(Bye {
                reason: "station stopping".into(),
            });
            if let Some(b) = self.make(&name, body) {
                cx.send(peer, b);
            }
        }
    }

    /// A robot's message from a sender the router does not know (the
    /// station restarted and forgot it): the robot is told to register
    /// again at once, rather than after its router timeout. At most one
    /// notice per sender every `heartbeat_period`.
    pub(super) fn unknown_robot(&mut self, m: Incoming<'_>, cx: &mut Ctx<'_>) {
        if !matches!(cx.from, Peer::Udp(_) | Peer::Serial(_)) {
            return;
        }
        let sender = m.header.sender.as_str();
        let gap = self.config.heartbeat_period;
        if !self.robots.tell_unknown(sender, cx.now, gap) {
            return;
        }
        let notice = Body::Notice(Notice {
            level: Level::Warn,
            code: NoticeCode::UnknownRobot,
            text: "not registered with this router: send Hello".into(),
        });
        if let Some(b) = self.make(sender, notice) {
            cx.send(cx.from, b);
        }
    }
}
