//! Registration and liveness: `Hello` (register, or register again after a
//! restart or from a new address), `Bye`, link states from silence, and the
//! router's heartbeats.

use mech_proto::{Body, Bye, Heartbeat, Hello, Route, Welcome};
use tokio::time::Instant;
use tracing::{debug, info, warn};

use super::links::Links;
use super::{Delivery, Incoming, Outbox, Peer, RobotEntry, Tables};
use crate::counters::Traffic;
use crate::event::{Event, LinkState};

impl Tables {
    pub(super) fn on_hello(
        &mut self,
        m: Incoming<'_>,
        hello: Hello,
        out: &mut Outbox,
        events: &mut Vec<Event>,
    ) -> Delivery {
        if !matches!(m.from, Peer::Udp(_) | Peer::Serial(_)) {
            return self.bad(m.from, "Hello must come over UDP or a radio".into(), events);
        }
        if hello.name != m.header.sender {
            let why = format!("Hello for {} sent by {}", hello.name, m.header.sender);
            return self.bad(m.from, why, events);
        }
        self.register(hello, m.from, m.now, out, events);
        Delivery::Consumed
    }

    /// Registers a robot (again, after a restart or from a new address: its
    /// id and route are kept, but it must confirm the route), welcomes it
    /// with its id and route on the link the Hello came on, and gives it a
    /// latched e-stop.
    pub(super) fn register(
        &mut self,
        hello: Hello,
        from: Peer,
        now: Instant,
        out: &mut Outbox,
        events: &mut Vec<Event>,
    ) {
        let known = self.robots.contains_key(&hello.name);
        if known {
            info!(robot = %hello.name, %from, "robot registered again");
        } else {
            self.enrol(&hello, from, now, events);
        }
        let addr = self.link_addr(from);
        let Some(entry) = self.robots.get_mut(&hello.name) else {
            return;
        };
        entry.route_sent = now;
        // An agent that restarted has forgotten its route: it must confirm it.
        if known {
            entry.acked = false;
        }
        let id = entry.id;
        let route = Route {
            robot: hello.name.clone(),
            channel: entry.route.clone().unwrap_or_default(),
            epoch: entry.epoch,
        };
        let name = hello.name.clone();
        events.push(Event::Registered {
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
            out.owned.push((from, b));
        }
        self.estop_newcomer(&name, now, out);
    }

    /// A robot's first registration: a new id, and the configured default
    /// route (none unless configured, so it holds still).
    fn enrol(&mut self, hello: &Hello, from: Peer, now: Instant, events: &mut Vec<Event>) {
        let id = self.next_id;
        self.next_id = self.next_id.wrapping_add(1).max(1);
        let route = self.config.default_route.clone();
        let epoch = u32::from(route.is_some());
        self.robots.insert(
            hello.name.clone(),
            RobotEntry {
                id,
                links: Links::new(from, now),
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
        info!(robot = %hello.name, platform = %hello.platform, %from, id, "robot registered");
        if route.is_some() {
            events.push(Event::RouteChanged {
                robot: hello.name.clone(),
                channel: route,
                epoch,
            });
        }
    }

    pub(super) fn on_bye(
        &mut self,
        m: Incoming<'_>,
        bye: Bye,
        events: &mut Vec<Event>,
    ) -> Delivery {
        let sender = m.header.sender.as_str();
        if let Some(entry) = self.robots.get_mut(sender) {
            entry.link = LinkState::Lost;
            info!(robot = sender, reason = %bye.reason, "robot left");
            events.push(Event::Bye {
                robot: sender.to_string(),
                reason: bye.reason,
            });
        } else {
            self.subscribers.remove(&m.from);
        }
        Delivery::Consumed
    }

    /// Liveness: any message from a registered robot's name over UDP or
    /// a radio.
    pub(super) fn seen_robot(
        &mut self,
        sender: &str,
        from: Peer,
        now: Instant,
        events: &mut Vec<Event>,
    ) {
        if let Some(r) = self.robots.get_mut(sender) {
            r.last_seen = now;
            r.traffic.received += 1;
            if let Some(old) = r.links.heard(from, now) {
                info!(robot = sender, %old, new = %from, "robot moved to a new address");
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

    /// Link states from silence: stale, then lost.
    pub(super) fn update_links(&mut self, now: Instant, events: &mut Vec<Event>) {
        let (stale, lost) = (self.config.stale_after, self.config.lost_after);
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
            if link == r.link || (r.link == LinkState::Lost && link != LinkState::Connected) {
                continue;
            }
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
    }

    /// The router's heartbeat to every robot, every `heartbeat_period`, on
    /// each of its links: a robot with two links hears which are alive.
    pub(super) fn send_heartbeats(&mut self, now: Instant, out: &mut Outbox) {
        let period = self.config.heartbeat_period;
        let mut due = Vec::new();
        for (name, r) in self.robots.iter_mut() {
            if now.saturating_duration_since(r.heartbeat_sent) >= period {
                r.heartbeat_sent = now;
                due.extend(r.links.all().map(|peer| (name.clone(), peer)));
            }
        }
        for (name, peer) in due {
            let body = Body::Heartbeat(Heartbeat { uptime_ms: 0 });
            if let Some(b) = self.make(&name, body) {
                out.owned.push((peer, b));
            }
        }
    }

    /// `Bye` to every registered robot: the station is stopping, so each
    /// knows now instead of after its router timeout.
    pub(crate) fn farewell(&mut self, out: &mut Outbox) {
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
                out.owned.push((peer, b));
            }
        }
    }
}
