//! Route changes: the very next message is judged by the new entry; the
//! agent is told (repeated until it acknowledges the epoch).

use mech_proto::{Body, Route, RouteAck};
use tokio::time::Instant;
use tracing::info;

use super::{Delivery, Incoming, Outbox, Tables};
use crate::event::Event;

/// `None` for the wire's empty channel ("none").
fn route_of(channel: &str) -> Option<String> {
    (!channel.is_empty()).then(|| channel.to_string())
}

impl Tables {
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
        let epoch = entry.epoch;
        let to = self.target(robot, now);
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
        if let (Some(b), Some(to)) = (self.make(robot, Body::Route(route)), to) {
            out.owned.push((to, b));
        }
        Some(epoch)
    }

    pub(super) fn on_route_ack(
        &mut self,
        m: Incoming<'_>,
        ack: RouteAck,
        events: &mut Vec<Event>,
    ) -> Delivery {
        let sender = m.header.sender.as_str();
        let Some(entry) = self.robots.get_mut(sender) else {
            return Delivery::Consumed;
        };
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
        Delivery::Consumed
    }

    /// Resends every unacknowledged route every `route_retry`.
    pub(super) fn retry_routes(&mut self, now: Instant, out: &mut Outbox) {
        let (retry, timeout) = (self.config.route_retry, self.config.link_timeout);
        let mut due = Vec::new();
        for (name, r) in self.robots.iter_mut() {
            if !r.acked && now.saturating_duration_since(r.route_sent) >= retry {
                r.route_sent = now;
                let route = Route {
                    robot: name.clone(),
                    channel: r.route.clone().unwrap_or_default(),
                    epoch: r.epoch,
                };
                due.extend(r.links.target(now, timeout).map(|to| (to, route)));
            }
        }
        for (to, route) in due {
            let robot = route.robot.clone();
            if let Some(b) = self.make(&robot, Body::Route(route)) {
                out.owned.push((to, b));
            }
        }
    }
}
