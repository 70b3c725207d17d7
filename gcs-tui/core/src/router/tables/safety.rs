//! Fleet safety at the router: the station's arena and each robot's safety
//! switch, delivered reliably; the neighbour lists the station's
//! broadcaster hands over, signed and sent; and what each robot's
//! telemetry says of its safety layer (`docs/safety.md`).
//!
//! [`SiteSafety`] holds the arena (`None`: the station has none) and
//! numbers every arena message: each change of the arena or of a robot's
//! switch takes a new id, which goes to the robot every `arena_retry`
//! until the robot acknowledges that id (as a route does). It also holds
//! each registered robot's part, `RobotSafety`: its switch, the id it owes
//! an acknowledgement for, and what it last reported.
//!
//! Without an arena nothing is sent at registration (the robot's layer
//! says "no arena"); clearing the arena sends every robot that had one an
//! empty arena, so each drops its fence. Nothing here is on the path of
//! forwarded commands.

use std::collections::HashMap;
use std::time::Duration;

use mech_proto::{Arena, ArenaAck, Body, Intervention, Neighbours, SafetyReport, SafetyState};
use tokio::time::Instant;
use tracing::{info, warn};

use super::{Ctx, Delivery, Incoming, Tables};
use crate::arena::ArenaShape;
use crate::event::Event;

/// The station's arena, each robot's switch and arena delivery, and the
/// ids of the arena messages.
#[derive(Debug)]
pub(super) struct SiteSafety {
    arena: Option<ArenaShape>,
    next_id: u32,
    /// Every registered robot's part, by name (off the forwarding path,
    /// so kept here rather than in the robot's registry entry).
    robots: HashMap<String, RobotSafety>,
}

/// One robot's safety switch and the delivery of its arena.
#[derive(Debug)]
struct RobotSafety {
    /// Whether its layer is on (only an operator switches it off).
    enabled: bool,
    /// The arena id it was last sent; 0: never sent one.
    id: u32,
    /// It acknowledged `id`.
    acked: bool,
    /// When `id` was last sent.
    sent: Instant,
    /// What its telemetry last said of its layer.
    reported: Option<(SafetyState, Intervention)>,
}

impl SiteSafety {
    /// Ids start from `seed` (see `super::clock_seed`), so a restarted
    /// station's are newer than its predecessor's.
    pub(super) fn new(seed: u32) -> SiteSafety {
        SiteSafety {
            arena: None,
            next_id: seed,
            robots: HashMap::new(),
        }
    }

    fn next_id(&mut self) -> u32 {
        self.next_id = self.next_id.wrapping_add(1).max(1);
        self.next_id
    }

    /// The station's arena, if it has one.
    pub(super) fn arena(&self) -> Option<&ArenaShape> {
        self.arena.as_ref()
    }

    /// A robot registered for the first time: its layer on, no arena
    /// sent yet.
    pub(super) fn enrol(&mut self, robot: &str, now: Instant) {
        let part = RobotSafety {
            enabled: true,
            id: 0,
            acked: true,
            sent: now,
            reported: None,
        };
        self.robots.insert(robot.to_string(), part);
    }

    /// Sets (or clears) the arena; returns the robots to send it to, each
    /// with a new id: every robot, or when clearing, those sent one before.
    fn set_arena(&mut self, arena: Option<ArenaShape>, now: Instant) -> Vec<String> {
        let clearing = arena.is_none();
        self.arena = arena;
        let names: Vec<String> = self
            .robots
            .iter()
            .filter(|(_, r)| !clearing || r.id != 0)
            .map(|(n, _)| n.clone())
            .collect();
        for name in &names {
            let id = self.next_id();
            if let Some(r) = self.robots.get_mut(name) {
                r.renumber(id, now);
            }
        }
        names
    }

    /// Switches `robot`'s layer; returns the arena id to send it with a new
    /// id when the station has an arena or had one to send it, else 0 (the
    /// switch waits for the next arena); `None` for an unknown robot.
    fn switch(&mut self, robot: &str, enabled: bool, now: Instant) -> Option<u32> {
        let has_arena = self.arena.is_some();
        let held = self.robots.get(robot)?.id;
        let id = if has_arena || held != 0 {
            self.next_id()
        } else {
            0
        };
        let r = self.robots.get_mut(robot)?;
        r.enabled = enabled;
        if id != 0 {
            r.renumber(id, now);
        }
        Some(id)
    }

    /// A robot registering (for the first time or again), when the station
    /// has an arena: a new robot gets a new id, a known one the id it holds,
    /// to be confirmed again (its agent may have restarted without it).
    /// `true` if it is to be sent the arena.
    fn newcomer(&mut self, robot: &str, now: Instant) -> bool {
        if self.arena.is_none() {
            return false;
        }
        let Some(held) = self.robots.get(robot).map(|r| r.id) else {
            return false;
        };
        let id = if held == 0 { self.next_id() } else { held };
        if let Some(r) = self.robots.get_mut(robot) {
            r.renumber(id, now);
        }
        true
    }

    /// `robot` acknowledged arena `id`: the event, when that confirms the
    /// id it owes for the first time.
    fn acked(&mut self, robot: &str, id: u32) -> Option<Event> {
        let s = self.robots.get_mut(robot)?;
        if id != s.id || s.acked {
            return None;
        }
        s.acked = true;
        info!(robot, id, enabled = s.enabled, "arena acknowledged");
        Some(Event::ArenaAcked {
            robot: robot.to_string(),
            id,
            enabled: s.enabled,
        })
    }

    /// The robots whose unacknowledged arena is due again at `now` (noted
    /// as sent).
    fn due(&mut self, now: Instant, retry: Duration) -> Vec<String> {
        self.robots
            .iter_mut()
            .filter_map(|(name, r)| r.resend_due(now, retry).then(|| name.clone()))
            .collect()
    }

    /// The arena message `robot` owes an acknowledgement for (empty when
    /// the station has none).
    fn arena_for(&self, robot: &str) -> Option<Arena> {
        let s = self.robots.get(robot)?;
        Some(match &self.arena {
            Some(a) => a.to_arena(robot, s.id, s.enabled),
            None => ArenaShape::none_for(robot, s.id, s.enabled),
        })
    }

    /// Whether `robot` is registered with its layer on.
    fn enabled(&self, robot: &str) -> bool {
        self.robots.get(robot).is_some_and(|r| r.enabled)
    }

    /// What a robot's telemetry says of its safety layer: an event when its
    /// state or intervention changed since the last telemetry.
    pub(super) fn reported(&mut self, robot: &str, report: Option<SafetyReport>) -> Option<Event> {
        let report = report?;
        let r = self.robots.get_mut(robot)?;
        let now = (report.state, report.intervention);
        // A robot starts without an arena, limiting nothing: nothing to say.
        let was = r
            .reported
            .unwrap_or((SafetyState::NoArena, Intervention::None));
        if was == now {
            return None;
        }
        r.reported = Some(now);
        Some(Event::Safety {
            robot: robot.to_string(),
            state: report.state,
            intervention: report.intervention,
        })
    }
}

impl RobotSafety {
    /// A new arena id to deliver.
    fn renumber(&mut self, id: u32, now: Instant) {
        self.id = id;
        self.acked = false;
        self.sent = now;
    }

    /// Whether an unacknowledged arena is due to be sent again (noted as
    /// sent when it is).
    fn resend_due(&mut self, now: Instant, retry: Duration) -> bool {
        let due = !self.acked && self.id != 0 && now.saturating_duration_since(self.sent) >= retry;
        if due {
            self.sent = now;
        }
        due
    }
}

impl Tables {
    /// The station's arena, if it has one.
    pub(crate) fn arena(&self) -> Option<&ArenaShape> {
        self.safety.arena()
    }

    /// Sets (or clears) the station's arena and sends it to every robot,
    /// each with a new id, repeated until acknowledged.
    pub(crate) fn set_arena(&mut self, arena: Option<ArenaShape>, cx: &mut Ctx<'_>) {
        match &arena {
            Some(a) => info!(arena = %a.summary(), "arena set"),
            None => info!("arena cleared"),
        }
        let names = self.safety.set_arena(arena.clone(), cx.now);
        cx.event(Event::Arena { arena });
        for name in names {
            self.send_arena(&name, cx);
        }
    }

    /// Switches `robot`'s safety layer on or off. The robot is sent its
    /// arena with the switch (a new id) when the station has one, or had
    /// one to send it; without, the switch waits for the next arena.
    /// Returns the arena id sent (0: none yet), `None` for an unknown
    /// robot.
    pub(crate) fn set_safety(
        &mut self,
        robot: &str,
        enabled: bool,
        cx: &mut Ctx<'_>,
    ) -> Option<u32> {
        let id = self.safety.switch(robot, enabled, cx.now)?;
        if enabled {
            info!(robot, id, "safety switched on");
        } else {
            warn!(robot, id, "safety switched OFF by an operator");
        }
        cx.event(Event::SafetySwitched {
            robot: robot.to_string(),
            enabled,
            id,
        });
        if id != 0 {
            self.send_arena(robot, cx);
        }
        Some(id)
    }

    /// A robot registering (for the first time or again) is sent the
    /// station's arena (see [`SiteSafety::newcomer`]).
    pub(super) fn arena_newcomer(&mut self, robot: &str, cx: &mut Ctx<'_>) {
        if self.safety.newcomer(robot, cx.now) {
            self.send_arena(robot, cx);
        }
    }

    pub(super) fn on_arena_ack(
        &mut self,
        m: Incoming<'_>,
        ack: ArenaAck,
        cx: &mut Ctx<'_>,
    ) -> Delivery {
        let sender = m.header.sender.as_str();
        if ack.robot != sender {
            return self.bad(format!("arena ack for {} sent by {sender}", ack.robot), cx);
        }
        if let Some(e) = self.safety.acked(sender, ack.id) {
            cx.event(e);
        }
        Delivery::Consumed
    }

    /// Resends every unacknowledged arena every `arena_retry`.
    pub(super) fn retry_arenas(&mut self, cx: &mut Ctx<'_>) {
        for name in self.safety.due(cx.now, self.config.arena_retry) {
            self.send_arena(&name, cx);
        }
    }

    /// Sends `robot` the arena it owes an acknowledgement for, on the link
    /// it is reached on.
    fn send_arena(&mut self, robot: &str, cx: &mut Ctx<'_>) {
        let Some(arena) = self.safety.arena_for(robot) else {
            return;
        };
        let to = self.target(robot, cx.now);
        if let (Some(b), Some(to)) = (self.make(robot, Body::Arena(arena)), to) {
            cx.send(to, b);
        }
    }

    /// Signs the neighbour list `n` for its robot and sends it on the
    /// robot's link; `false` if the robot is not registered or cannot be
    /// reached, or its layer is switched off (it would not use them).
    pub(crate) fn send_neighbours(&mut self, n: Neighbours, cx: &mut Ctx<'_>) -> bool {
        let robot = n.robot.clone();
        if !self.safety.enabled(&robot) {
            return false;
        }
        let Some(to) = self.target(&robot, cx.now) else {
            return false;
        };
        match self.make(&robot, Body::Neighbours(n)) {
            Some(b) => {
                cx.send(to, b);
                true
            }
            None => false,
        }
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use mech_proto::{
        Envelope, Header, Hello, Intervention, InterventionCounts, Point, SafetyReport,
        SafetyState, Telemetry,
    };

    use super::super::{Effects, Peer};
    use super::*;
    use crate::router::RouterConfig;

    /// One decision at `now` from `from`: what was sent and what happened.
    fn decide<R>(
        t: &mut Tables,
        now: Instant,
        from: Peer,
        f: impl FnOnce(&mut Tables, &mut Ctx<'_>) -> R,
    ) -> (R, Vec<(Peer, Envelope)>, Vec<Event>) {
        let mut fx = Effects::default();
        let r = f(t, &mut Ctx::new(now, from, &mut fx));
        let sent = fx
            .out
            .owned
            .iter()
            .map(|(p, b)| (*p, mech_proto::decode(b).unwrap()))
            .collect();
        (r, sent, fx.events)
    }

    fn message(sender: &str, body: Body) -> Vec<u8> {
        let header = Header {
            sender: sender.into(),
            destination: "router".into(),
            ..Header::default()
        };
        mech_proto::encode(&Envelope::new(header, body)).unwrap()
    }

    fn hello(name: &str) -> Vec<u8> {
        message(
            name,
            Body::Hello(Hello {
                name: name.into(),
                platform: "kiwi".into(),
                capabilities: vec![],
                motors: 3,
                max_speed: 1.0,
                max_yaw_rate: 2.0,
                agent_version: "t".into(),
            }),
        )
    }

    fn peer(n: u16) -> Peer {
        Peer::Udp(format!("127.0.0.1:{}", 9000 + n).parse().unwrap())
    }

    /// The arenas among `sent`, as (to, robot, id, enabled, empty).
    fn arenas(sent: &[(Peer, Envelope)]) -> Vec<(Peer, String, u32, bool, bool)> {
        sent.iter()
            .filter_map(|(p, e)| match &e.body {
                Body::Arena(a) => Some((*p, a.robot.clone(), a.id, a.enabled, a.is_empty())),
                _ => None,
            })
            .collect()
    }

    fn square() -> ArenaShape {
        let p = |x, y| Point { x, y };
        ArenaShape {
            boundary: vec![p(0.0, 0.0), p(4.0, 0.0), p(4.0, 3.0), p(0.0, 3.0)],
            keep_out: vec![],
            slow_zones: vec![],
            obstacles: vec![],
            margin: 0.1,
        }
    }

    fn ack(t: &mut Tables, robot: &str, id: u32, at: Instant) -> Vec<Event> {
        let bytes = message(
            robot,
            Body::ArenaAck(ArenaAck {
                robot: robot.into(),
                id,
            }),
        );
        decide(t, at, peer(1), |t, cx| t.handle(&bytes, cx)).2
    }

    #[test]
    fn an_arena_reaches_every_robot_at_registration_and_on_change_until_acknowledged() {
        let t0 = Instant::now();
        let ms = |v| t0 + Duration::from_millis(v);
        let mut t = Tables::new(RouterConfig::default(), None);
        let (_, sent, _) = decide(&mut t, t0, peer(1), |t, cx| t.handle(&hello("robot_1"), cx));
        assert!(
            arenas(&sent).is_empty(),
            "no arena at the station: none sent"
        );
        let (_, sent, events) = decide(&mut t, ms(10), Peer::Local, |t, cx| {
            t.set_arena(Some(square()), cx)
        });
        assert!(matches!(&events[..], [Event::Arena { arena: Some(_) }]));
        let first = arenas(&sent);
        assert_eq!(first.len(), 1);
        let (to, robot, id, enabled, empty) = first[0].clone();
        assert_eq!(
            (to, robot.as_str(), enabled, empty),
            (peer(1), "robot_1", true, false)
        );
        // Repeated every 100 ms until acknowledged.
        let (_, sent, _) = decide(&mut t, ms(109), Peer::Local, |t, cx| t.tick(cx));
        assert!(arenas(&sent).is_empty());
        let (_, sent, _) = decide(&mut t, ms(110), Peer::Local, |t, cx| t.tick(cx));
        assert_eq!(
            arenas(&sent),
            [(peer(1), "robot_1".into(), id, true, false)]
        );
        assert!(
            ack(&mut t, "robot_1", id.wrapping_sub(1), ms(120)).is_empty(),
            "an older id"
        );
        let events = ack(&mut t, "robot_1", id, ms(130));
        assert_eq!(
            events,
            [Event::ArenaAcked {
                robot: "robot_1".into(),
                id,
                enabled: true
            }]
        );
        assert!(
            ack(&mut t, "robot_1", id, ms(140)).is_empty(),
            "counted once"
        );
        let (_, sent, _) = decide(&mut t, ms(400), Peer::Local, |t, cx| t.tick(cx));
        assert!(arenas(&sent).is_empty(), "acknowledged: no more");
        // A newcomer gets it with an id of its own, after its Welcome.
        let (_, sent, _) = decide(&mut t, ms(500), peer(2), |t, cx| {
            t.handle(&hello("robot_2"), cx)
        });
        assert!(matches!(sent[0].1.body, Body::Welcome(_)));
        let second = arenas(&sent);
        assert_eq!(second.len(), 1);
        assert_ne!(second[0].2, id);
        // Registering again (a restarted agent), robot_1 must confirm again.
        let (_, sent, _) = decide(&mut t, ms(600), peer(1), |t, cx| {
            t.handle(&hello("robot_1"), cx)
        });
        assert_eq!(
            arenas(&sent),
            [(peer(1), "robot_1".into(), id, true, false)]
        );
        let (_, sent, _) = decide(&mut t, ms(700), Peer::Local, |t, cx| t.tick(cx));
        assert!(arenas(&sent).iter().any(|a| a.1 == "robot_1"));
    }

    #[test]
    fn an_operator_switches_a_robots_layer_and_clearing_the_arena_empties_it() {
        let t0 = Instant::now();
        let ms = |v| t0 + Duration::from_millis(v);
        let mut t = Tables::new(RouterConfig::default(), None);
        decide(&mut t, t0, peer(1), |t, cx| t.handle(&hello("robot_1"), cx));
        decide(&mut t, t0, peer(2), |t, cx| t.handle(&hello("robot_2"), cx));
        // Without an arena the switch is kept for the next one.
        let (id, sent, events) = decide(&mut t, ms(10), Peer::Local, |t, cx| {
            t.set_safety("robot_2", false, cx)
        });
        assert_eq!(id, Some(0));
        assert!(arenas(&sent).is_empty());
        assert!(matches!(
            &events[..],
            [Event::SafetySwitched {
                enabled: false,
                id: 0,
                ..
            }]
        ));
        let (_, sent, _) = decide(&mut t, ms(20), Peer::Local, |t, cx| {
            t.set_arena(Some(square()), cx)
        });
        let mut got: Vec<(String, bool)> = arenas(&sent).into_iter().map(|a| (a.1, a.3)).collect();
        got.sort();
        assert_eq!(got, [("robot_1".into(), true), ("robot_2".into(), false)]);
        let (id, sent, _) = decide(&mut t, ms(30), Peer::Local, |t, cx| {
            t.set_safety("robot_1", false, cx)
        });
        let id = id.unwrap();
        assert_eq!(
            arenas(&sent),
            [(peer(1), "robot_1".into(), id, false, false)]
        );
        assert_eq!(
            decide(&mut t, ms(30), Peer::Local, |t, cx| t
                .set_safety("nobody", false, cx))
            .0,
            None
        );
        // No neighbours for a robot whose layer is off.
        let list = |robot: &str| Neighbours {
            robot: robot.into(),
            stamp_us: 1,
            robots: vec![],
            obstacles: vec![],
        };
        let (off, _, _) = decide(&mut t, ms(40), Peer::Local, |t, cx| {
            t.send_neighbours(list("robot_1"), cx)
        });
        assert!(!off);
        decide(&mut t, ms(50), Peer::Local, |t, cx| {
            t.set_safety("robot_1", true, cx)
        });
        let (on, sent, _) = decide(&mut t, ms(60), Peer::Local, |t, cx| {
            t.send_neighbours(list("robot_1"), cx)
        });
        assert!(on);
        assert!(matches!(&sent[..], [(p, e)] if *p == peer(1)
            && e.header.destination == "robot_1" && matches!(e.body, Body::Neighbours(_))));
        // Cleared: every robot is sent an empty arena.
        let (_, sent, events) = decide(&mut t, ms(70), Peer::Local, |t, cx| t.set_arena(None, cx));
        assert!(matches!(&events[..], [Event::Arena { arena: None }]));
        assert!(arenas(&sent).iter().all(|a| a.4), "{sent:?}");
        assert_eq!(arenas(&sent).len(), 2);
    }

    #[test]
    fn a_robots_report_of_its_layer_is_an_event_when_it_changes() {
        let t0 = Instant::now();
        let mut t = Tables::new(RouterConfig::default(), None);
        decide(&mut t, t0, peer(1), |t, cx| t.handle(&hello("robot_1"), cx));
        let telemetry = |state, intervention| {
            message(
                "robot_1",
                Body::Telemetry(Telemetry {
                    pose: Default::default(),
                    velocity: Default::default(),
                    mode: Default::default(),
                    channel: String::new(),
                    computation: Default::default(),
                    failsafe: Default::default(),
                    health: Default::default(),
                    battery: None,
                    position_quality: 1.0,
                    actuators: vec![],
                    mission: None,
                    stale: 0,
                    velocity_source: Default::default(),
                    safety: Some(SafetyReport {
                        state,
                        arena: 1,
                        intervention,
                        counts: InterventionCounts::default(),
                        radius: 0.15,
                        position_error: 0.0,
                    }),
                }),
            )
        };
        let safety_events = |t: &mut Tables, bytes: &[u8]| {
            decide(t, t0, peer(1), |t, cx| t.handle(bytes, cx))
                .2
                .into_iter()
                .filter(|e| matches!(e, Event::Safety { .. }))
                .collect::<Vec<_>>()
        };
        let quiet = telemetry(SafetyState::NoArena, Intervention::None);
        assert!(safety_events(&mut t, &quiet).is_empty(), "nothing to say");
        let fence = telemetry(SafetyState::On, Intervention::Fence);
        assert_eq!(
            safety_events(&mut t, &fence),
            [Event::Safety {
                robot: "robot_1".into(),
                state: SafetyState::On,
                intervention: Intervention::Fence
            }]
        );
        assert!(safety_events(&mut t, &fence).is_empty(), "once per change");
        let off = telemetry(SafetyState::Off, Intervention::None);
        assert_eq!(safety_events(&mut t, &off).len(), 1);
    }
}
