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
    /// A new robot's route: `channel` as epoch 1, or none as epoch 0 (which
    /// needs no acknowledgement: the agent starts routed to none).
    pub(super) fn new(channel: Option<String>, now: Instant) -> RouteState {
        RouteState {
            epoch: u32::from(channel.is_some()),
            acked: channel.is_none(),
            channel,
            sent: now,
        }
    }

    pub(super) fn channel(&self) -> Option<&str> {
        self.channel.as_deref()
    }

    pub(super) fn epoch(&self) -> u32 {
        self.epoch
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

    /// Changes the route: a new epoch, to be acknowledged.
    fn change(&mut self, channel: Option<&str>, now: Instant) -> u32 {
        self.channel = channel.map(str::to_string);
        self.epoch = self.epoch.wrapping_add(1);
        self.acked = false;
        self.sent = now;
        self.epoch
    }

    /// The robot registered again and has forgotten its route: it must
    /// confirm the same epoch again.
    pub(super) fn unconfirmed(&mut self, now: Instant) {
        self.acked = false;
        self.sent = now;
    }

    /// An acknowledgement; `true` if it confirms the current route for the
    /// first time.
    fn ack(&mut self, epoch: u32, channel: &Option<String>) -> bool {
        let confirms = epoch == self.epoch && *channel == self.channel && !self.acked;
        if confirms {
            self.acked = true;
        }
        confirms
    }

    /// Whether an unacknowledged route is due to be sent again (noted as
    /// sent when it is).
    fn resend_due(&mut self, now: Instant, retry: Duration) -> bool {
        let due = !self.acked && now.saturating_duration_since(self.sent) >= retry;
        if due {
            self.sent = now;
        }
        due
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
        let epoch = entry.route.change(channel, cx.now);
        let route = entry.route.wire(robot);
        let to = self.target(robot, cx.now);
        info!(
            robot,
            channel = channel.unwrap_or("none"),
            epoch,
            "route changed"
        );
        cx.event(Event::RouteChanged {
            robot: robot.to_string(),
            channel: channel.map(str::to_string),
            epoch,
        });
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
        let Some(entry) = self.robots.get_mut(sender) else {
            return Delivery::Consumed;
        };
        let channel = route_of(&ack.channel);
        if entry.route.ack(ack.epoch, &channel) {
            info!(
                robot = sender,
                channel = channel.as_deref().unwrap_or("none"),
                epoch = ack.epoch,
                "route acknowledged"
            );
            cx.event(Event::RouteAcked {
                robot: sender.to_string(),
                channel,
                epoch: ack.epoch,
            });
        }
        Delivery::Consumed
    }

    /// Resends every unacknowledged route every `route_retry`.
    pub(super) fn retry_routes(&mut self, cx: &mut Ctx<'_>) {
        let (retry, timeout) = (self.config.route_retry, self.config.link_timeout);
        let now = cx.now;
        let mut due = Vec::new();
        for (name, r) in self.robots.iter_mut() {
            if r.route.resend_due(now, retry) {
                let route = r.route.wire(name);
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
