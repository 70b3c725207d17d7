//! What the core's tests share: messages as a router and a controller
//! send them, and an agent registered and routed.

pub(super) use std::time::Duration;

pub(super) use mech_proto::{
    Body, Bye, Command, CommandKind, Computation, EStop, Echo, Envelope, FailsafeState, Header,
    Health, Heartbeat, Level, Mission, Notice, NoticeCode, Pose, Route, Twist, VelocitySource,
    Waypoint, Welcome,
};

pub(super) use super::{Agent, AgentSettings, Tick};
pub(super) use crate::control::Mode;
pub(super) use crate::hal::{EdgeCount, PositionSample};
pub(super) use crate::platform::PlatformSpec;
pub(super) use crate::wheels::WheelSettings;

pub(super) const PERIOD: Duration = Duration::from_millis(20);
pub(super) fn ms(v: u64) -> Duration {
    Duration::from_millis(v)
}
pub(super) fn msg(channel: &str, body: Body) -> Envelope {
    Envelope::new(
        Header {
            sender: "ctl".into(),
            destination: "r1".into(),
            channel: channel.into(),
            ..Header::default()
        },
        body,
    )
}
pub(super) fn twist(vx: f64) -> Body {
    Body::Command(Command::Twist(Twist {
        vx,
        ..Twist::default()
    }))
}
pub(super) fn route(channel: &str, epoch: u32) -> Body {
    Body::Route(Route {
        robot: "r1".into(),
        channel: channel.into(),
        epoch,
    })
}
/// A registered agent with a position, routed to `channel`.
pub(super) fn routed(channel: &str) -> Agent {
    let mut a = Agent::new(
        AgentSettings::new("r1"),
        PlatformSpec::diff_drive().build(),
        0,
    );
    a.observe_position(PositionSample {
        pose: Pose::default(),
        stamp: ms(0),
        quality: 1.0,
        has_heading: true,
    });
    let w = Body::Welcome(Welcome {
        robot_id: 1,
        route: Route {
            robot: "r1".into(),
            channel: channel.into(),
            epoch: 1,
        },
        router_version: "t".into(),
    });
    let out = a.handle(msg("", w), ms(0));
    assert!(matches!(&out[0].body, Body::RouteAck(r) if r.channel == channel && r.epoch == 1));
    a
}
pub(super) fn moving(outputs: &[f64]) -> bool {
    outputs.iter().any(|u| *u != 0.0)
}
pub(super) fn router_heartbeat(a: &mut Agent, now: Duration) {
    a.handle(msg("", Body::Heartbeat(Heartbeat::new(0))), now);
}
pub(super) fn estop(engage: bool, id: u32) -> Body {
    Body::EStop(EStop { engage, id })
}
/// A mission of one waypoint at (`x`, 0), 5 cm arrival radius.
pub(super) fn mission_to(id: u32, x: f64) -> Mission {
    Mission {
        id,
        waypoints: vec![Waypoint {
            x,
            y: 0.0,
            z: 0.0,
            time: None,
        }],
        looped: false,
        arrival_radius: 0.05,
        start_index: 0,
    }
}
pub(super) fn one_waypoint(id: u32) -> Body {
    Body::Mission(mission_to(id, 2.0))
}

/// What a part is handed, for testing it on its own: robot `r1`'s wire,
/// counters and replies.
#[derive(Debug)]
pub(super) struct Bench {
    pub(super) wire: super::wire::Wire,
    pub(super) counters: super::counters::Counters,
    pub(super) out: Vec<Envelope>,
}

impl Bench {
    pub(super) fn new() -> Bench {
        Bench {
            wire: super::wire::Wire::new("r1", 0),
            counters: super::counters::Counters::default(),
            out: Vec::new(),
        }
    }

    /// A step at `now`, its replies collected in `out`.
    pub(super) fn step(&mut self, now: Duration) -> super::step::Step<'_> {
        super::step::Step::new(now, &mut self.wire, &mut self.counters, &mut self.out)
    }
}
