//! A robot with a key obeys only what the router signed for it: the agent
//! core driven with raw bytes, as its link delivers them. The forger can
//! send from the router's own address (a host on the same network spoofs it
//! in one line), so only the tag can tell.
#![allow(clippy::unwrap_used)]

use std::time::Duration;

use mech_agent::platform::PlatformSpec;
use mech_agent::{Agent, AgentSettings};
use mech_proto::auth::{FROM_ROUTER, Key};
use mech_proto::{
    Body, Command, EStop, Envelope, FailsafeState, Header, Route, Time, Twist, Welcome,
};

const BOOT_US: u64 = 5_000_000; // the robot's clock: 1970, no network time
const STATION_US: u64 = 1_700_000_000_000_000;

fn ms(v: u64) -> Duration {
    Duration::from_millis(v)
}

/// The router's side: signs with the robot's key, stamps rising.
struct Router {
    key: Key,
    stamp: u64,
}

impl Router {
    fn bytes(&mut self, channel: &str, sender: &str, body: Body) -> Vec<u8> {
        let env = Envelope::new(
            Header {
                sender: sender.into(),
                destination: "robot_1".into(),
                channel: channel.into(),
                ..Header::default()
            },
            body,
        );
        let mut b = mech_proto::encode(&env).unwrap();
        self.stamp += 1_000;
        self.key.seal(&mut b, FROM_ROUTER, self.stamp).unwrap();
        b
    }
}

fn unsigned(channel: &str, body: Body) -> Vec<u8> {
    let env = Envelope::new(
        Header {
            sender: "router".into(),
            destination: "robot_1".into(),
            channel: channel.into(),
            ..Header::default()
        },
        body,
    );
    mech_proto::encode(&env).unwrap()
}

fn twist(vx: f64) -> Body {
    Body::Command(Command::Twist(Twist {
        vx,
        ..Twist::default()
    }))
}

fn route(channel: &str, epoch: u32) -> Route {
    Route {
        robot: "robot_1".into(),
        channel: channel.into(),
        epoch,
    }
}

/// A keyed robot that has asked the time, been answered and welcomed,
/// routed to `joy/0`.
fn welcomed(key: &Key) -> (Agent, Router) {
    let mut agent = Agent::new(
        AgentSettings::new("robot_1"),
        PlatformSpec::diff_drive().build(),
        BOOT_US,
    )
    .with_key(key.clone(), "router");
    let mut router = Router {
        key: key.clone(),
        stamp: STATION_US,
    };
    // Its first message asks the time, not to register.
    let first = agent.tick(ms(0)).outgoing;
    let Body::TimeRequest(ask) = &first[0].body else {
        panic!("a keyed robot asks the time first: {first:?}")
    };
    let answer = router.bytes(
        "",
        "router",
        Body::Time(Time {
            nonce: ask.nonce,
            station_us: STATION_US,
        }),
    );
    agent.handle_bytes(&answer, ms(1));
    let hello = agent.tick(ms(2)).outgoing;
    assert!(
        matches!(hello[0].body, Body::Hello(_)),
        "registers once it knows the time: {hello:?}"
    );
    let welcome = router.bytes(
        "",
        "router",
        Body::Welcome(Welcome {
            robot_id: 1,
            route: route("joy/0", 1),
            router_version: "t".into(),
        }),
    );
    agent.handle_bytes(&welcome, ms(3));
    assert!(agent.registered());
    (agent, router)
}

#[test]
fn forged_routes_commands_and_releases_from_the_routers_address_are_refused() {
    let key = Key::new(&[7; 32]);
    let (mut agent, mut router) = welcomed(&key);
    // Unsigned, or signed with another key, whatever they claim.
    agent.handle_bytes(&unsigned("", Body::Route(route("evil/0", 9))), ms(10));
    let mut other = Router {
        key: Key::new(&[8; 32]),
        stamp: STATION_US + 10_000_000,
    };
    agent.handle_bytes(
        &other.bytes("", "router", Body::Route(route("evil/0", 9))),
        ms(11),
    );
    assert_eq!(agent.route().channel, "joy/0", "forged routes ignored");
    agent.handle_bytes(&unsigned("joy/0", twist(0.5)), ms(12));
    agent.tick(ms(13));
    assert!(
        agent.outputs().iter().all(|u| *u == 0.0),
        "forged command ignored"
    );

    // The router's e-stop is obeyed; a forged release is not.
    let stop = router.bytes(
        "",
        "router",
        Body::EStop(EStop {
            engage: true,
            id: 1,
        }),
    );
    agent.handle_bytes(&stop, ms(20));
    let release = Body::EStop(EStop {
        engage: false,
        id: 2,
    });
    agent.handle_bytes(&unsigned("", release.clone()), ms(21));
    assert_eq!(agent.failsafe_state(ms(22)), FailsafeState::EStopped);
    // Captured and replayed later: refused too.
    let real_release = router.bytes("", "router", release);
    agent.handle_bytes(&real_release, ms(30));
    assert_ne!(agent.failsafe_state(ms(31)), FailsafeState::EStopped);
    let engage = router.bytes(
        "",
        "router",
        Body::EStop(EStop {
            engage: true,
            id: 3,
        }),
    );
    agent.handle_bytes(&engage, ms(40));
    agent.handle_bytes(&real_release, ms(41));
    assert_eq!(
        agent.failsafe_state(ms(42)),
        FailsafeState::EStopped,
        "a replayed release cannot undo a newer e-stop"
    );
    let r = agent.auth_rejections();
    assert_eq!((r.bad_tag, r.replay), (4, 1), "{r:?}");
}

#[test]
fn a_forwarded_command_signed_by_the_router_is_obeyed() {
    let key = Key::new(&[7; 32]);
    let (mut agent, mut router) = welcomed(&key);
    let cmd = router.bytes("joy/0", "gamepad", twist(0.3));
    agent.handle_bytes(&cmd, ms(10));
    agent.tick(ms(11));
    assert!(
        agent.outputs().iter().any(|u| *u > 0.0),
        "obeyed: {:?}",
        agent.outputs()
    );
    assert_eq!(agent.auth_rejections().total(), 0);
}

#[test]
fn the_robots_own_telemetry_sent_back_does_not_keep_a_lost_router_alive() {
    let key = Key::new(&[7; 32]);
    let (mut agent, _router) = welcomed(&key);
    // The robot's signed telemetry, captured and reflected at it every
    // 100 ms after the router went silent.
    let mut reflected = Vec::new();
    for t in (100..3_000).step_by(100) {
        for env in agent.tick(ms(t)).outgoing {
            let mut b = Vec::new();
            agent.encode(&env, &mut b).unwrap();
            reflected.push(b);
        }
        if let Some(b) = reflected.last() {
            agent.handle_bytes(b, ms(t + 1));
        }
    }
    assert_eq!(
        agent.failsafe_state(ms(3_000)),
        FailsafeState::RouterLost,
        "reflections are not the router"
    );
    // Addressed to the router, they are skipped before their tag is even
    // checked (a robot reads only what is addressed to it).
    assert!(agent.counters().not_for_me > 0);
}
