//! Commands, the hot path: a command is forwarded, bytes unchanged (but
//! signed for the robot when the station authenticates), only to a robot
//! routed to its channel; a fleet command is split so each routed
//! robot gets only its part; a cluster command goes to the controller that
//! serves the channel. Every publisher is noted with its channel's rate.

use mech_proto::{Body, ClusterCommand, Envelope, FleetCommand, Header};
use tokio::time::Instant;
use tracing::{info, warn};

use super::{ChannelEntry, Delivery, Incoming, Outbox, Peer, Tables};
use crate::counters::{DropReason, Traffic};
use crate::event::Event;
use crate::router::rate::RateMeter;

impl Tables {
    /// The hot path: forward a command if its robot is routed to its channel.
    pub(super) fn route_command(
        &mut self,
        head: &mech_proto::Peek<'_>,
        bytes: &[u8],
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
        match self.check_route(destination, channel, now) {
            Ok(to) => {
                self.pass_on(bytes, to, destination, out);
                Delivery::Forwarded(1)
            }
            Err(reason) => Delivery::Dropped(reason),
        }
    }

    pub(super) fn on_fleet_command(
        &mut self,
        m: Incoming<'_>,
        fc: FleetCommand,
        out: &mut Outbox,
        events: &mut Vec<Event>,
    ) -> Delivery {
        let (h, channel) = (m.header, m.header.channel.as_str());
        self.note_publisher(&h.sender, channel, m.from, m.now, events);
        let mut delivered = 0;
        for part in fc.parts {
            let Ok(target) = self.check_route(&part.robot, channel, m.now) else {
                continue;
            };
            let header = Header {
                destination: part.robot.clone(),
                ..h.clone()
            };
            match mech_proto::encode(&Envelope::new(header, Body::Command(part.command))) {
                Ok(mut b) => {
                    b.pop(); // the nil auth element: signed for the robot
                    if let Some(b) = self.seal(&b, &part.robot) {
                        out.owned.push((target, b));
                        delivered += 1;
                    }
                }
                Err(e) => {
                    warn!(error = %e, robot = %part.robot, "cannot re-encode fleet command part")
                }
            }
        }
        Delivery::Forwarded(delivered)
    }

    pub(super) fn on_cluster(
        &mut self,
        m: Incoming<'_>,
        command: ClusterCommand,
        events: &mut Vec<Event>,
    ) -> Delivery {
        let channel = &m.header.channel;
        self.note_publisher(&m.header.sender, channel, m.from, m.now, events);
        events.push(Event::ClusterCommand {
            channel: channel.clone(),
            command,
        });
        Delivery::Consumed
    }

    /// Counts a message published on `channel` and remembers its publisher.
    pub(super) fn note_publisher(
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

    /// Whether `robot` obeys `channel` now, and on which link to send to
    /// it; counts the outcome for the robot and the channel (which
    /// [`Tables::note_publisher`] created).
    pub(super) fn check_route(
        &mut self,
        robot: &str,
        channel: &str,
        now: Instant,
    ) -> Result<Peer, DropReason> {
        let timeout = self.config.link_timeout;
        let outcome = match self.robots.get_mut(robot) {
            None => Err(DropReason::UnknownRobot),
            Some(r) if r.route.as_deref() == Some(channel) => {
                r.traffic.forwarded += 1;
                r.links.target(now, timeout).ok_or(DropReason::UnknownRobot)
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
}
