//! Registration and the router's liveness: Hello until a Welcome, the
//! robot's heartbeats (echoing the router's newest, so the router can time
//! the round trip), registering again when the router is lost, says Bye, or
//! says it does not know the robot.

use std::time::Duration;

use mech_proto::{Body, Echo, Heartbeat, Hello};

use super::settings::AgentSettings;
use super::step::Step;
use crate::failsafe::Watchdog;

/// Whether the robot is registered, and whether its router is alive.
#[derive(Debug)]
pub(crate) struct Registration {
    registered: bool,
    /// Anything heard from the router: everything reaches the agent
    /// through it, so any message is proof it is alive.
    router: Watchdog,
    /// Period of `Hello` while unregistered.
    hello_retry: Duration,
    next_hello: Duration,
    /// Period of the robot's heartbeat while registered.
    heartbeat_period: Duration,
    next_heartbeat: Duration,
    /// The newest router heartbeat not yet echoed: its sequence number and
    /// when it arrived, so the next heartbeat tells the router which one it
    /// answers and how long it was held (the router measures the round trip).
    router_beat: Option<(u32, Duration)>,
}

impl Registration {
    pub(crate) fn new(settings: &AgentSettings) -> Registration {
        Registration {
            registered: false,
            router: Watchdog::new(settings.failsafe.router_timeout),
            hello_retry: settings.hello_retry,
            next_hello: Duration::ZERO,
            heartbeat_period: settings.hello_period,
            next_heartbeat: Duration::ZERO,
            router_beat: None,
        }
    }

    pub(crate) fn registered(&self) -> bool {
        self.registered
    }

    /// Nothing heard from the router for its timeout, or it said Bye.
    pub(crate) fn router_lost(&self, now: Duration) -> bool {
        self.router.silent(now)
    }

    /// Nothing heard from the router for longer than `timeout` (shorter
    /// than its router timeout: the silence that stops an onboard mission).
    pub(crate) fn router_silent_for(&self, timeout: Duration, now: Duration) -> bool {
        self.router.silent_for(timeout, now)
    }

    /// A message arrived (from the router, as every message does).
    pub(crate) fn router_heard(&mut self, now: Duration) {
        self.router.heard(now);
    }

    /// The router said it is stopping: it is lost now, not after the
    /// router timeout (the failsafe acts on the next period, and the robot
    /// registers again once a router answers).
    pub(crate) fn router_left(&mut self, robot: &str, reason: &str) {
        tracing::warn!(robot = %robot, reason = %super::wire::truncate(reason), "the router is stopping");
        self.router.forget();
    }

    /// A Welcome: registered (again). Returns whether the robot was not
    /// registered before, so what the router numbered before (e-stops,
    /// commands) is forgotten: a restarted router numbers afresh.
    pub(crate) fn welcomed(&mut self, robot: &str, channel: &str, now: Duration) -> bool {
        let new = !self.registered;
        if new {
            tracing::info!(robot = %robot, route = %channel, "registered with the router");
        }
        self.registered = true;
        self.next_heartbeat = now;
        new
    }

    /// A router heartbeat: echoed by the next heartbeat of the robot.
    pub(crate) fn router_beat(&mut self, seq: u32, now: Duration) {
        self.router_beat = Some((seq, now));
    }

    /// The router restarted and forgot this robot: register now rather than
    /// after the router timeout.
    pub(crate) fn unknown_to_router(&mut self, step: &mut Step) {
        if !self.registered {
            return;
        }
        tracing::info!(robot = %step.robot(), "the router does not know this robot; registering again");
        step.counters.reregistered += 1;
        self.registered = false;
        self.next_hello = step.now;
    }

    /// Station time is known: register now.
    pub(crate) fn synced(&mut self, now: Duration) {
        self.next_hello = now;
    }

    /// One period: after the router is lost, register again (it may have
    /// restarted, or the robot moved); while unregistered, Hello every
    /// `hello_retry` (with a key, ask the station's time first: signed
    /// stamps need it).
    pub(crate) fn tick(&mut self, step: &mut Step, hello: impl FnOnce() -> Hello) {
        let now = step.now;
        if self.registered && self.router.silent(now) {
            self.registered = false;
            self.next_hello = now;
            step.wire.forget_router();
        }
        if !self.registered && now >= self.next_hello {
            self.next_hello = now + self.hello_retry;
            let body = match step.wire.time_request() {
                Some(request) => Body::TimeRequest(request),
                None => Body::Hello(hello()),
            };
            step.send(mech_proto::ROUTER, body);
        }
    }

    /// The periodic heartbeat while registered, when due, echoing the
    /// router's newest heartbeat.
    pub(crate) fn heartbeat_if_due(&mut self, step: &mut Step) {
        let now = step.now;
        if !self.registered || now < self.next_heartbeat {
            return;
        }
        self.next_heartbeat = now + self.heartbeat_period;
        let echo = self.router_beat.take().map(|(seq, at)| Echo {
            seq,
            held_us: now.saturating_sub(at).as_micros() as u64,
        });
        step.send(mech_proto::ROUTER, heartbeat(now, echo));
    }
}

/// A heartbeat at agent time `now`.
pub(crate) fn heartbeat(now: Duration, echo: Option<Echo>) -> Body {
    Body::Heartbeat(Heartbeat {
        uptime_ms: now.as_millis() as u64,
        echo,
    })
}

#[cfg(test)]
mod tests {
    use super::super::testing::*;

    #[test]
    fn says_hello_every_quarter_second_until_welcomed() {
        let mut a = Agent::new(AgentSettings::new("r1"), PlatformSpec::kiwi().build(), 0);
        let hellos = |t: &Tick| {
            t.outgoing
                .iter()
                .filter(|e| matches!(e.body, Body::Hello(_)))
                .count()
        };
        assert_eq!(hellos(&a.tick(ms(0))), 1);
        assert_eq!(hellos(&a.tick(ms(200))), 0);
        let t = a.tick(ms(250));
        assert_eq!(hellos(&t), 1);
        let Body::Hello(h) = &t.outgoing[0].body else {
            panic!()
        };
        assert_eq!((h.platform.as_str(), h.motors), ("kiwi", 3));
        assert!(h.capabilities.contains(&CommandKind::Waypoints));
        a.handle(msg("", route("", 0)), ms(1010));
        assert!(!a.registered(), "only Welcome registers");
        a.handle(
            msg(
                "",
                Body::Welcome(Welcome {
                    robot_id: 1,
                    route: Route {
                        robot: "r1".into(),
                        channel: "".into(),
                        epoch: 0,
                    },
                    router_version: "t".into(),
                }),
            ),
            ms(1020),
        );
        let t = a.tick(ms(2000));
        assert_eq!(hellos(&t), 0);
        assert!(
            t.outgoing
                .iter()
                .any(|e| matches!(e.body, Body::Telemetry(_)))
        );
    }

    #[test]
    fn a_heartbeat_echoes_the_newest_router_heartbeat_once() {
        let mut a = routed("");
        let echoes = |t: &Tick| -> Vec<Option<Echo>> {
            t.outgoing
                .iter()
                .filter_map(|e| match e.body {
                    Body::Heartbeat(h) => Some(h.echo),
                    _ => None,
                })
                .collect()
        };
        // Registration makes a heartbeat due at once: nothing to echo yet.
        assert_eq!(echoes(&a.tick(ms(0))), [None]);
        for (seq, at) in [(40, 300), (41, 550)] {
            let mut beat = msg("", Body::Heartbeat(Heartbeat::new(0)));
            beat.header.seq = seq;
            a.handle(beat, ms(at));
        }
        let held = Duration::from_millis(1000 - 550).as_micros() as u64;
        assert_eq!(
            echoes(&a.tick(ms(1000))),
            [Some(Echo {
                seq: 41,
                held_us: held
            })],
            "the newest, with the time it was held"
        );
        a.handle(msg("", route("", 2)), ms(1500)); // the router is still heard
        assert_eq!(echoes(&a.tick(ms(2000))), [None], "each is echoed once");
    }

    #[test]
    fn a_router_that_does_not_know_the_robot_gets_a_hello_at_once() {
        let mut a = routed("joy/0");
        let t = a.tick(ms(100));
        assert!(!t.outgoing.iter().any(|e| matches!(e.body, Body::Hello(_))));
        let notice = Body::Notice(Notice {
            level: Level::Warn,
            code: NoticeCode::UnknownRobot,
            text: "send Hello".into(),
        });
        a.handle(msg("", notice), ms(110));
        assert!(!a.registered());
        let t = a.tick(ms(120));
        assert!(
            t.outgoing.iter().any(|e| matches!(e.body, Body::Hello(_))),
            "Hello at the next period, not after the router timeout"
        );
        assert_eq!(a.counters().reregistered, 1);
    }

    #[test]
    fn router_loss_stops_and_re_registers() {
        let mut a = routed("joy/0");
        let mut now = ms(0);
        let mut stopped = None;
        while now < ms(3000) {
            now += PERIOD;
            // Everything arrives through the router: after 100 ms it is gone.
            if now <= ms(100) {
                a.handle(msg("joy/0", twist(0.2)), now);
            }
            let t = a.tick(now);
            if stopped.is_none() && !moving(&t.outputs) {
                stopped = Some(now);
            }
            if a.failsafe_state(now) == FailsafeState::RouterLost {
                assert!(
                    t.outgoing.iter().any(|e| matches!(e.body, Body::Hello(_))),
                    "registers again at once"
                );
                break;
            }
        }
        assert_eq!(a.failsafe_state(now), FailsafeState::RouterLost);
        assert!(!a.registered());
        assert!(stopped.unwrap() <= ms(100) + ms(500) + PERIOD);
    }

    #[test]
    fn a_router_bye_stops_at_once_and_registers_again() {
        let mut a = routed("joy/0");
        let now = ms(100);
        a.handle(msg("joy/0", twist(0.2)), now);
        assert!(moving(&a.tick(now).outputs));
        // A Bye from anyone but the router is not the router leaving.
        let bye = |sender: &str| {
            let mut m = msg(
                "",
                Body::Bye(Bye {
                    reason: "stopping".into(),
                }),
            );
            m.header.sender = sender.into();
            m
        };
        a.handle(bye("ctl"), now);
        assert_ne!(a.failsafe_state(now), FailsafeState::RouterLost);
        a.handle(bye(mech_proto::ROUTER), now);
        assert_eq!(a.failsafe_state(now), FailsafeState::RouterLost);
        let t = a.tick(now + PERIOD);
        assert!(!moving(&t.outputs), "stops on the next tick");
        assert!(
            t.outgoing.iter().any(|e| matches!(e.body, Body::Hello(_))),
            "asks to register again at once"
        );
    }
}
