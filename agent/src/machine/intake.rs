//! Command intake: the route in force (which one channel this robot obeys)
//! and the checks every command passes before the controller takes it: not
//! while e-stopped, only on the routed channel (a rejected controller is
//! told why, at most once a second), never older than one already obeyed
//! from its sender (see [`crate::order`]). The silence of the routed
//! channel, which the failsafe judges, is kept here too.

use std::time::Duration;

use mech_proto::{Body, Command, Header, Level, NoticeCode, Route, RouteAck};

use super::missions::Missions;
use super::settings::AgentSettings;
use super::step::Step;
use crate::control::Controller;
use crate::failsafe::Watchdog;
use crate::order::{CommandOrder, is_older};

/// The route in force and what has been obeyed on it.
#[derive(Debug)]
pub(crate) struct Intake {
    /// The channel this robot obeys ("" = none) and its epoch.
    route: Route,
    /// Whether a route has been applied at all (epoch 0 is a valid epoch).
    routed_once: bool,
    /// Newest command obeyed from each sender on each channel.
    order: CommandOrder,
    /// Commands accepted on the routed channel (and route changes, which
    /// restart the silence timer).
    channel: Watchdog,
    /// Answer a rejected command with `Notice{NotRouted}`.
    notify_not_routed: bool,
    last_not_routed_notice: Option<Duration>,
    /// When a command was last refused with a notice (at most one a
    /// second: a controller repeating a command the robot cannot take
    /// must not flood the station's log).
    last_refusal_notice: Option<Duration>,
}

impl Intake {
    pub(crate) fn new(settings: &AgentSettings) -> Intake {
        Intake {
            route: Route {
                robot: settings.name.clone(),
                channel: String::new(),
                epoch: 0,
            },
            routed_once: false,
            order: CommandOrder::default(),
            channel: Watchdog::new(settings.failsafe.channel_timeout),
            notify_not_routed: settings.notify_not_routed,
            last_not_routed_notice: None,
            last_refusal_notice: None,
        }
    }

    pub(crate) fn route(&self) -> &Route {
        &self.route
    }

    /// The routed channel ("" = none).
    pub(crate) fn channel(&self) -> &str {
        &self.route.channel
    }

    /// Whether the robot is routed to a channel.
    pub(crate) fn routed(&self) -> bool {
        !self.route.channel.is_empty()
    }

    /// Nothing accepted on the routed channel for the channel timeout.
    pub(crate) fn channel_silent(&self, now: Duration) -> bool {
        self.channel.silent(now)
    }

    /// The routed channel's controller is at work (a command was obeyed, or
    /// a mission on it started): the silence timer restarts.
    pub(crate) fn channel_heard(&mut self, now: Duration) {
        self.channel.heard(now);
    }

    /// Forgets every sender's order (the robot registered: a restarted
    /// router's controllers number afresh).
    pub(crate) fn forget_senders(&mut self) {
        self.order.clear();
    }

    /// Whether a `Route` should be applied: it is for this robot and not a
    /// delayed resend of one already replaced (an older epoch).
    pub(crate) fn fresh_route(&self, r: &Route, step: &mut Step) -> bool {
        if r.robot != step.robot() {
            step.counters.not_for_me += 1;
            false
        } else if self.routed_once && is_older(r.epoch, self.route.epoch) {
            step.counters.stale_routes += 1;
            false
        } else {
            true
        }
    }

    /// Puts `route` in force. Returns whether it changed anything (a first
    /// route, another channel or epoch): the senders' order is forgotten and
    /// the channel's silence timer restarts.
    pub(crate) fn apply(&mut self, route: Route, now: Duration) -> bool {
        let changed = !self.routed_once
            || route.channel != self.route.channel
            || route.epoch != self.route.epoch;
        if changed {
            tracing::info!(robot = %self.route.robot, channel = %route.channel, epoch = route.epoch, "route");
            self.routed_once = true;
            self.order.clear();
            self.channel.heard(now);
            self.route.channel = route.channel;
            self.route.epoch = route.epoch;
        }
        changed
    }

    /// The acknowledgement of the route in force.
    pub(crate) fn ack(&self) -> Body {
        Body::RouteAck(RouteAck {
            robot: self.route.robot.clone(),
            channel: self.route.channel.clone(),
            epoch: self.route.epoch,
        })
    }

    /// A command, obeyed if it passes every check: the robot is not
    /// `estopped`, the command comes on the routed channel, and it is not
    /// older than one already obeyed from its sender (by the `header`'s
    /// sequence number and stamp). A stop pauses its channel's mission; a
    /// command the controller cannot take is refused with a notice to its
    /// sender. Refusals are counted.
    pub(crate) fn command(
        &mut self,
        header: &Header,
        cmd: &Command,
        estopped: bool,
        controller: &mut Controller,
        missions: &mut Missions,
        step: &mut Step,
    ) {
        if !self.admit(header, estopped, step) {
            return;
        }
        if matches!(cmd, Command::Stop(_)) {
            missions.pause(&header.channel);
        }
        match controller.command(cmd) {
            Ok(()) => {
                step.counters.commands += 1;
                self.channel.heard(step.now);
            }
            Err(e) => {
                step.counters.refused += 1;
                if once_a_second(&mut self.last_refusal_notice, step.now) {
                    let text = e.to_string();
                    step.notice(&header.sender, Level::Warn, NoticeCode::Unsupported, &text);
                }
            }
        }
    }

    /// Whether a command may go to the controller (see [`Intake::command`]).
    fn admit(&mut self, header: &Header, estopped: bool, step: &mut Step) -> bool {
        let (channel, sender) = (header.channel.as_str(), header.sender.as_str());
        if estopped {
            step.counters.ignored_estopped += 1;
            return false;
        }
        if !self.routed() || channel != self.route.channel {
            step.counters.not_routed += 1;
            self.tell_not_routed(channel, sender, step);
            return false;
        }
        let restart_after = self.channel.timeout();
        if !self.order.admit(
            sender,
            channel,
            header.seq,
            header.stamp_us,
            step.now,
            restart_after,
        ) {
            step.counters.stale_commands += 1;
            return false;
        }
        true
    }

    /// Tells a controller its command was rejected, at most once a second.
    fn tell_not_routed(&mut self, channel: &str, sender: &str, step: &mut Step) {
        if !self.notify_not_routed || !once_a_second(&mut self.last_not_routed_notice, step.now) {
            return;
        }
        let text = format!(
            "{} obeys channel {:?}; command on {channel:?} rejected",
            step.robot(),
            self.route.channel
        );
        step.notice(sender, Level::Warn, NoticeCode::NotRouted, &text);
    }
}

/// Whether a notice last sent at `last` may be sent again at `now` (a
/// second later or more); notes it sent when it may.
fn once_a_second(last: &mut Option<Duration>, now: Duration) -> bool {
    if last.is_some_and(|t| now.saturating_sub(t) < Duration::from_secs(1)) {
        return false;
    }
    *last = Some(now);
    true
}

#[cfg(test)]
mod tests {
    use super::super::testing::*;

    /// A controller repeating a command the robot cannot take (50 Hz for
    /// 2.5 s) has each one refused and counted, but is told so once a
    /// second: the notices go to the station's log.
    #[test]
    fn refusals_are_counted_each_and_told_once_a_second() {
        let mut a = routed("joy/0");
        let mut notices = 0;
        for k in 0..125u32 {
            let mut m = msg(
                "joy/0",
                Body::Command(mech_proto::Command::Actuators(mech_proto::Actuators {
                    outputs: vec![0.5],
                })),
            );
            m.header.seq = k + 1;
            let out = a.handle(m, ms(10 + u64::from(k) * 20));
            notices += out
                .iter()
                .filter(|e| matches!(&e.body, Body::Notice(n) if n.code == NoticeCode::Unsupported))
                .count();
        }
        assert_eq!(a.counters().refused, 125);
        assert_eq!(notices, 3, "at 0 s, 1 s and 2 s");
    }

    #[test]
    fn obeys_the_routed_channel_and_rejects_others() {
        let mut a = routed("joy/0");
        a.handle(msg("joy/0", twist(0.2)), ms(10));
        assert!(moving(&a.tick(ms(20)).outputs));
        let out = a.handle(msg("key/0", twist(-0.3)), ms(30));
        assert!(matches!(&out[0].body, Body::Notice(n) if n.code == NoticeCode::NotRouted));
        assert_eq!(out[0].header.destination, "ctl");
        let t = a.tick(ms(40));
        assert!(
            t.outputs.iter().all(|u| *u > 0.0),
            "still the joy/0 command: {:?}",
            t.outputs
        );
        assert_eq!(a.counters().not_routed, 1);
        // A second rejection within a second is counted but not answered.
        assert!(a.handle(msg("key/0", twist(-0.3)), ms(50)).is_empty());
        assert_eq!(a.counters().not_routed, 2);
    }

    #[test]
    fn unrouted_robot_holds_still() {
        let mut a = routed("");
        a.handle(msg("joy/0", twist(0.2)), ms(10));
        assert!(!moving(&a.tick(ms(20)).outputs));
        assert_eq!(a.counters().not_routed, 1);
    }

    #[test]
    fn route_change_zeroes_acks_and_switches_channel() {
        let mut a = routed("joy/0");
        a.handle(msg("joy/0", twist(0.2)), ms(10));
        assert!(moving(&a.tick(ms(20)).outputs));
        let out = a.handle(msg("", route("wp/gcs", 2)), ms(30));
        assert!(matches!(&out[0].body, Body::RouteAck(r) if r.channel == "wp/gcs" && r.epoch == 2));
        assert!(!moving(&a.tick(ms(40)).outputs), "zeroed on switch");
        a.handle(msg("joy/0", twist(0.2)), ms(50));
        assert!(!moving(&a.tick(ms(60)).outputs), "old channel now rejected");
        a.handle(msg("wp/gcs", twist(0.1)), ms(70));
        assert!(moving(&a.tick(ms(80)).outputs));
        // A repeated Route (router retry) is acked again but changes nothing.
        let out = a.handle(msg("", route("wp/gcs", 2)), ms(90));
        assert!(matches!(&out[0].body, Body::RouteAck(_)));
        assert!(moving(&a.tick(ms(100)).outputs));
        let t = a.telemetry(ms(100));
        assert_eq!(t.channel, "wp/gcs");
        assert_eq!(t.computation, Computation::Onboard);
        a.handle(msg("", route("offboard/r1", 3)), ms(110));
        assert_eq!(a.telemetry(ms(110)).computation, Computation::Offboard);
    }
}

#[cfg(test)]
mod route_tests {
    use super::super::testing::*;
    use super::*;

    fn route_to(robot: &str, channel: &str, epoch: u32) -> Route {
        Route {
            robot: robot.into(),
            channel: channel.into(),
            epoch,
        }
    }

    #[test]
    fn the_first_route_is_taken_whatever_its_epoch_and_then_none_older() {
        let mut bench = Bench::new();
        let mut intake = Intake::new(&AgentSettings::new("r1"));
        let first = route_to("r1", "joy/0", u32::MAX);
        assert!(intake.fresh_route(&first, &mut bench.step(ms(0))));
        assert!(intake.apply(first.clone(), ms(0)), "a first route changes");
        assert!(!intake.apply(first, ms(5)), "a resend changes nothing");
        let older = route_to("r1", "wp/gcs", u32::MAX - 1);
        assert!(!intake.fresh_route(&older, &mut bench.step(ms(10))));
        assert_eq!(bench.counters.stale_routes, 1);
        let past_the_wrap = route_to("r1", "wp/gcs", 0);
        assert!(intake.fresh_route(&past_the_wrap, &mut bench.step(ms(20))));
        assert!(!intake.fresh_route(&route_to("r2", "wp/gcs", 1), &mut bench.step(ms(30))));
        assert_eq!(bench.counters.not_for_me, 1);
        assert!(
            matches!(intake.ack(), Body::RouteAck(a) if a.channel == "joy/0" && a.epoch == u32::MAX)
        );
    }
}
