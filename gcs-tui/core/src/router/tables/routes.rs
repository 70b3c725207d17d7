//! Route changes: the very next message is judged by the new entry; the
//! agent is told (repeated until it acknowledges the epoch).
//!
//! A robot's [`RouteState`]: the channel it obeys (`None`: none), the
//! epoch that numbers each change, and whether the robot confirmed it.
//! Every change takes a new epoch and needs a new acknowledgement; only an
//! acknowledgement of the current epoch and channel counts.

use std::time::Duration;

use mech_proto::{Body, Route, RouteAck};
use tokio::time::Instant;
use tracing::info;

use super::{Ctx, Delivery, Incoming, Tables};
use crate::event::Event;

/// `None` for the wire's empty channel ("none").
fn route_of(channel: &str) -> Option<String> {
    (!channel.is_empty()).then(|| channel.to_string())
}

/// One robot's route.
#[derive(Debug)]
pub(super) struct RouteState {
    channel: Option<String>,
    epoch: u32,
    /// The robot acknowledged `epoch`.
    acked: bool,
    /// When the route was last sent to the robot.
    sent: Instant,
}

impl RouteState {
    /// A new robot's route: `channel` (the configured default) as epoch 1,
    /// or none as epoch 0 (which needs no acknowledgement: the agent starts
    /// routed to none); with the event that says so when it has a channel.
    pub(super) fn first(
        robot: &str,
        channel: Option<String>,
        now: Instant,
    ) -> (RouteState, Option<Event>) {
        let event = channel.as_ref().map(|c| Event::RouteChanged {
            robot: robot.to_string(),
            channel: Some(c.clone()),
            epoch: 1,
        });
        let route = RouteState {
            epoch: u32::from(channel.is_some()),
            acked: channel.is_none(),
            channel,
            sent: now,
        };
        (route, event)
    }

    /// Whether the robot obeys `channel` now.
    pub(super) fn is(&self, channel: &str) -> bool {
        self.channel.as_deref() == Some(channel)
    }

    /// The route as sent to the robot named `robot`.
    pub(super) fn wire(&self, robot: &str) -> Route {
        Route {
            robot: robot.to_string(),
            channel: self.channel.clone().unwrap_or_default(),
            epoch: self.epoch,
        }
    }

    /// Changes `robot`'s route: a new epoch, to be acknowledged. Returns
    /// the event that says so and the route to send the robot.
    fn change(&mut self, robot: &str, channel: Option<&str>, now: Instant) -> (Event, Route) {
        self.channel = channel.map(str::to_string);
        self.epoch = self.epoch.wrapping_add(1);
        self.acked = false;
        self.sent = now;
        let epoch = self.epoch;
        info!(
            robot,
            channel = channel.unwrap_or("none"),
            epoch,
            "route changed"
        );
        let event = Event::RouteChanged {
            robot: robot.to_string(),
            channel: self.channel.clone(),
            epoch,
        };
        (event, self.wire(robot))
    }

    /// The robot registered again and has forgotten its route: it must
    /// confirm the same epoch again.
    pub(super) fn unconfirmed(&mut self, now: Instant) {
        self.acked = false;
        self.sent = now;
    }

    /// `robot`'s acknowledgement: the event, when it confirms the current
    /// epoch and channel for the first time.
    fn acked(&mut self, robot: &str, ack: RouteAck) -> Option<Event> {
        let channel = route_of(&ack.channel);
        if ack.epoch != self.epoch || channel != self.channel || self.acked {
            return None;
        }
        self.acked = true;
        info!(
            robot,
            channel = channel.as_deref().unwrap_or("none"),
            epoch = ack.epoch,
            "route acknowledged"
        );
        Some(Event::RouteAcked {
            robot: robot.to_string(),
            channel,
            epoch: ack.epoch,
        })
    }

    /// The route to send `robot` again at `now`, while it is not
    /// acknowledged, every `retry` (noted as sent).
    fn resend(&mut self, robot: &str, now: Instant, retry: Duration) -> Option<Route> {
        if self.acked || now.saturating_duration_since(self.sent) < retry {
            return None;
        }
        self.sent = now;
        Some(self.wire(robot))
    }
}

impl Tables {
    /// Changes a robot's route; the very next message is judged by the new
    /// entry. Returns the new epoch.
    pub(crate) fn set_route(
        &mut self,
        robot: &str,
        channel: Option<&str>,
        cx: &mut Ctx<'_>,
    ) -> Option<u32> {
        let entry = self.robots.get_mut(robot)?;
        let (event, route) = entry.route.change(robot, channel, cx.now);
        let to = entry.links.target(cx.now, self.config.link_timeout);
        let epoch = route.epoch;
        cx.event(event);
        if let (Some(b), Some(to)) = (self.make(robot, Body::Route(route)), to) {
            cx.send(to, b);
        }
        Some(epoch)
    }

    pub(super) fn on_route_ack(
        &mut self,
        m: Incoming<'_>,
        ack: RouteAck,
        cx: &mut Ctx<'_>,
    ) -> Delivery {
        let sender = m.header.sender.as_str();
        let acked = self
            .robots
            .get_mut(sender)
            .and_then(|r| r.route.acked(sender, ack));
        if let Some(e) = acked {
            cx.event(e);
        }
        Delivery::Consumed
    }

    /// Resends every unacknowledged route every `route_retry`.
    pub(super) fn retry_routes(&mut self, cx: &mut Ctx<'_>) {
        let (retry, timeout) = (self.config.route_retry, self.config.link_timeout);
        let now = cx.now;
        let mut due = Vec::new();
        for (name, r) in self.robots.iter_mut() {
            if let Some(route) = r.route.resend(name, now, retry) {
                due.extend(r.links.target(now, timeout).map(|to| (to, route)));
            }
        }
        for (to, route) in due {
            let robot = route.robot.clone();
            if let Some(b) = self.make(&robot, Body::Route(route)) {
                cx.send(to, b);
            }
        }
    }
}
