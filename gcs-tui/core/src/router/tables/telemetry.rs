//! Telemetry and the other traffic for the station itself: telemetry fans
//! out to external subscribers and becomes an event; subscriptions lapse
//! unless renewed; position fixes go to their robot; channel discovery and
//! notices.

use mech_proto::{Body, Channels, Notice, PositionFix, Subscribe, Telemetry};
use tokio::time::Instant;

use super::{Delivery, Incoming, Outbox, Peer, Tables};
use crate::counters::{ChannelStatus, DropReason};
use crate::event::Event;

impl Tables {
    pub(super) fn on_telemetry(
        &mut self,
        m: Incoming<'_>,
        t: Telemetry,
        out: &mut Outbox,
        events: &mut Vec<Event>,
    ) -> Delivery {
        let sender = m.header.sender.as_str();
        let Some(robot) = self.robots.get_mut(sender) else {
            self.dropped.count(DropReason::UnknownRobot);
            self.unknown_robot(m, out);
            return Delivery::Dropped(DropReason::UnknownRobot);
        };
        if let Peer::Serial(_) = m.from {
            robot.links.radio_telemetry(m.bytes.len());
        }
        let subscribers: Vec<(Peer, String)> = self
            .subscribers
            .iter()
            .map(|(peer, (_, name))| (*peer, name.clone()))
            .collect();
        for (peer, name) in subscribers {
            self.pass_on(m.bytes, peer, &name, out);
        }
        events.push(Event::Telemetry {
            robot: sender.to_string(),
            telemetry: t,
        });
        Delivery::Consumed
    }

    pub(super) fn on_subscribe(&mut self, m: Incoming<'_>, s: Subscribe) -> Delivery {
        if s.telemetry {
            let until = m.now + self.config.subscriber_timeout;
            self.subscribers
                .insert(m.from, (until, m.header.sender.clone()));
        } else {
            self.subscribers.remove(&m.from);
        }
        Delivery::Consumed
    }

    pub(super) fn on_position_fix(
        &mut self,
        m: Incoming<'_>,
        fix: PositionFix,
        out: &mut Outbox,
    ) -> Delivery {
        match self.target(&fix.robot, m.now) {
            Some(to) => {
                self.pass_on(m.bytes, to, &fix.robot, out);
                Delivery::Consumed
            }
            None => {
                self.dropped.count(DropReason::UnknownRobot);
                Delivery::Dropped(DropReason::UnknownRobot)
            }
        }
    }

    pub(super) fn on_channels_request(&mut self, m: Incoming<'_>, out: &mut Outbox) -> Delivery {
        let channels = self
            .channel_status(m.now)
            .into_iter()
            .map(|c| mech_proto::ChannelInfo {
                name: c.name,
                publisher: c.publisher,
                rate_hz: c.rate_hz,
                robots: c.robots,
                idle_ms: c.idle.as_millis() as u64,
            })
            .collect();
        let body = Body::Channels(Channels { channels });
        if let Some(b) = self.make(&m.header.sender, body) {
            out.owned.push((m.from, b));
        }
        Delivery::Consumed
    }

    pub(super) fn on_notice(
        &mut self,
        m: Incoming<'_>,
        notice: Notice,
        events: &mut Vec<Event>,
    ) -> Delivery {
        events.push(Event::Notice {
            from: m.header.sender.clone(),
            notice,
        });
        Delivery::Consumed
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
}
