//! A stale message is never obeyed: a command overtaken by a newer one
//! from the same sender, a route epoch already replaced, a mission already
//! superseded on its channel. Each is counted and reported in telemetry.
#![allow(clippy::unwrap_used)]

use std::time::Duration;

use mech_agent::platform::PlatformSpec;
use mech_agent::{Agent, AgentSettings};
use mech_proto::{Body, Command, Envelope, Header, Mission, Route, Stop, Twist, Waypoint, Welcome};

fn ms(v: u64) -> Duration {
    Duration::from_millis(v)
}

fn msg(sender: &str, channel: &str, seq: u32, stamp_us: u64, body: Body) -> Envelope {
    Envelope::new(
        Header {
            seq,
            stamp_us,
            sender: sender.into(),
            destination: "r1".into(),
            channel: channel.into(),
        },
        body,
    )
}

fn twist(vx: f64) -> Body {
    Body::Command(Command::Twist(Twist {
        vx,
        ..Twist::default()
    }))
}

fn route(channel: &str, epoch: u32) -> Route {
    Route {
        robot: "r1".into(),
        channel: channel.into(),
        epoch,
    }
}

fn routed() -> Agent {
    let mut a = Agent::new(AgentSettings::new("r1"), PlatformSpec::kiwi().build(), 0);
    let welcome = Body::Welcome(Welcome {
        robot_id: 1,
        route: route("joy/0", 1),
        router_version: "t".into(),
    });
    a.handle(msg("router", "", 1, 0, welcome), ms(0));
    a
}

fn moving(a: &mut Agent, now: Duration) -> bool {
    a.tick(now).outputs.iter().any(|u| *u != 0.0)
}

#[test]
fn a_drive_overtaken_by_a_stop_is_not_obeyed_and_a_restarted_sender_is() {
    let mut a = routed();
    // The controller sent drive (seq 41) then stop (seq 42); the network
    // delivers the stop first.
    a.handle(msg("pad", "joy/0", 40, 1_000_000, twist(0.2)), ms(10));
    assert!(moving(&mut a, ms(20)));
    let stop = Body::Command(Command::Stop(Stop {}));
    a.handle(msg("pad", "joy/0", 42, 1_002_000, stop), ms(30));
    assert!(!moving(&mut a, ms(40)));
    a.handle(msg("pad", "joy/0", 41, 1_001_000, twist(0.5)), ms(50));
    assert!(!moving(&mut a, ms(60)), "the older drive is ignored");
    assert_eq!(a.counters().stale_commands, 1);
    assert_eq!(a.telemetry(ms(60)).stale, 1, "reported in telemetry");
    // Another sender on the same channel has its own numbering.
    a.handle(msg("matlab", "joy/0", 3, 1_003_000, twist(0.1)), ms(70));
    assert!(moving(&mut a, ms(80)));
    // The pad restarts: its numbers start again near zero, its clock has
    // moved on, and it is obeyed.
    a.handle(msg("pad", "joy/0", 1, 9_000_000, twist(0.3)), ms(90));
    assert!(moving(&mut a, ms(100)));
    a.handle(msg("pad", "joy/0", 2, 9_001_000, twist(0.0)), ms(110));
    assert_eq!(a.counters().stale_commands, 1, "the restart was not stale");
}

#[test]
fn a_route_change_starts_every_senders_numbering_afresh() {
    let mut a = routed();
    a.handle(msg("pad", "joy/0", 500, 0, twist(0.2)), ms(10));
    a.handle(
        msg("router", "", 2, 0, Body::Route(route("joy/1", 2))),
        ms(20),
    );
    a.handle(
        msg("router", "", 3, 0, Body::Route(route("joy/0", 3))),
        ms(30),
    );
    a.handle(msg("pad", "joy/0", 7, 0, twist(0.2)), ms(40));
    assert!(moving(&mut a, ms(50)), "obeyed after the route changed");
    assert_eq!(a.counters().stale_commands, 0);
}

#[test]
fn a_delayed_older_route_does_not_switch_the_robot_back() {
    let mut a = routed();
    a.handle(
        msg("router", "", 2, 0, Body::Route(route("joy/1", 5))),
        ms(10),
    );
    assert_eq!(a.route().channel, "joy/1");
    a.handle(
        msg("router", "", 3, 0, Body::Route(route("joy/0", 4))),
        ms(20),
    );
    assert_eq!(a.route().channel, "joy/1", "epoch 4 is older than 5");
    assert_eq!(a.counters().stale_routes, 1);
}

#[test]
fn a_delayed_older_mission_does_not_replace_a_newer_one() {
    let mut a = routed();
    let mission = |id: u32, x: f64| {
        Body::Mission(Mission {
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
        })
    };
    let acks = a.handle(msg("gcs", "wp/gcs", 1, 0, mission(101, 2.0)), ms(10));
    assert_eq!(acks.len(), 1);
    let late = a.handle(msg("gcs", "wp/gcs", 2, 0, mission(100, -2.0)), ms(20));
    assert!(late.is_empty(), "not acknowledged: {late:?}");
    assert_eq!(a.mission("wp/gcs").unwrap().mission.id, 101);
    assert_eq!(a.counters().stale_missions, 1);
}
