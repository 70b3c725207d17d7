//! Fleet safety at the station, over real loopback sockets: the configured
//! arena reaches each robot when it registers and again until it is
//! acknowledged; an operator's switch goes out the same way; the neighbour
//! broadcaster, beside the router, sends each robot the robots near it
//! (another station's too) at 10 Hz or more, and nothing to a robot whose
//! layer is off.

#![allow(clippy::unwrap_used)]

#[path = "support/agent.rs"]
mod agent;

use agent::{Peer, config, telemetry};
use mech_core::{ArenaConfig, Event, Gcs};
use mech_proto::{ArenaAck, Body, Envelope, InterventionCounts, SafetyReport, SafetyState};

/// A station with the demo arena.
async fn station() -> Gcs {
    let mut c = config();
    c.arena = Some(ArenaConfig::demo());
    Gcs::start(c).await.unwrap()
}

/// `peer` registered, its arena received and acknowledged; the arena.
async fn registered_with_arena(peer: &mut Peer) -> mech_proto::Arena {
    peer.register().await;
    let env = peer
        .recv_matching(|e| matches!(e.body, Body::Arena(_)))
        .await;
    let Body::Arena(arena) = env.body else {
        unreachable!()
    };
    let ack = ArenaAck {
        robot: peer.name.clone(),
        id: arena.id,
    };
    peer.send(mech_proto::ROUTER, "", Body::ArenaAck(ack)).await;
    arena
}

/// Telemetry at (`x`, `y`) with the layer on, radius 0.2 m.
async fn report(peer: &mut Peer, x: f64, y: f64) {
    let mut t = telemetry(x, y, "", None);
    t.safety = Some(SafetyReport {
        state: SafetyState::On,
        arena: 1,
        intervention: Default::default(),
        counts: InterventionCounts::default(),
        radius: 0.2,
        position_error: 0.0,
    });
    peer.send_telemetry(t).await;
}

fn neighbours(env: &Envelope) -> Option<&mech_proto::Neighbours> {
    match &env.body {
        Body::Neighbours(n) => Some(n),
        _ => None,
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn each_robot_gets_its_arena_and_its_neighbours_at_ten_hertz_or_more() {
    let gcs = station().await;
    let router = gcs.router().udp_addr();
    let mut events = gcs.router().subscribe(1024, false);
    let mut r1 = Peer::new("robot_1", router).await;
    let mut r2 = Peer::new("robot_2", router).await;
    let arena = registered_with_arena(&mut r1).await;
    assert_eq!(arena.robot, "robot_1");
    assert!(arena.enabled && arena.boundary.len() == 4, "{arena:?}");
    assert_eq!(arena.margin, 0.1);
    registered_with_arena(&mut r2).await;
    loop {
        let e = events.recv().await.unwrap();
        if matches!(&e.event, Event::ArenaAcked { robot, .. } if robot == "robot_1") {
            break;
        }
    }
    // Until the station knows where a robot is, it sends it no list.
    assert!(r1.drain().iter().all(|e| neighbours(e).is_none()));
    report(&mut r1, 1.0, 1.0).await;
    report(&mut r2, 2.0, 1.0).await;
    // Another station's robot, shown here through a bridge.
    let remote = mech_proto::Hello {
        name: "robot_9".into(),
        platform: "kiwi".into(),
        capabilities: vec![],
        motors: 3,
        max_speed: 1.0,
        max_yaw_rate: 2.0,
        agent_version: String::new(),
    };
    let elapsed = gcs.router().elapsed();
    gcs.update_fleet(|f| {
        f.remote_info("site-b", "robot_9", 7, &remote);
        f.remote_telemetry("site-b", "robot_9", &telemetry(1.5, 2.0, "", None), elapsed);
    });
    // Twenty lists in a row to robot_1, each naming both others (robot_2
    // cooperating, the remote robot not), at 20 Hz by default: at least
    // 10 Hz on a loaded machine. Each telemetry keeps the states fresh.
    let mut stamps = Vec::new();
    while stamps.len() < 20 {
        let env = r1.recv_matching(|e| neighbours(e).is_some()).await;
        let n = neighbours(&env).unwrap();
        assert_eq!(n.robot, "robot_1");
        assert_eq!(env.header.destination, "robot_1");
        let mut ids: Vec<(u16, bool)> = n.robots.iter().map(|r| (r.id, r.cooperative)).collect();
        ids.sort_unstable();
        if ids.len() == 2 {
            assert_eq!(ids, [(2, true), (7, false)]);
            stamps.push(n.stamp_us);
        }
        report(&mut r1, 1.0, 1.0).await;
        report(&mut r2, 2.0, 1.0).await;
    }
    let span = (stamps[19] - stamps[0]) as f64 / 1e6;
    assert!(
        span <= 19.0 / 10.0,
        "20 lists over {span:.2} s: under 10 Hz"
    );
    // Switched off: robot_2 is sent its arena disabled, and lists no more.
    let id = gcs.router().set_safety("robot_2", false).await.unwrap();
    let env = r2
        .recv_matching(|e| matches!(&e.body, Body::Arena(a) if a.id == id))
        .await;
    assert!(matches!(&env.body, Body::Arena(a) if !a.enabled));
    r2.drain();
    // robot_1's next lists still name robot_2; robot_2 gets none meanwhile.
    for _ in 0..3 {
        let env = r1.recv_matching(|e| neighbours(e).is_some()).await;
        assert!(neighbours(&env).unwrap().robots.iter().any(|r| r.id == 2));
    }
    let to_r2 = r2.drain();
    assert!(to_r2.iter().all(|e| neighbours(e).is_none()), "{to_r2:?}");
    gcs.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_station_without_an_arena_sends_no_arena_and_no_neighbours_until_one_is_set() {
    let gcs = Gcs::start(config()).await.unwrap();
    let router = gcs.router().udp_addr();
    let mut r1 = Peer::new("robot_1", router).await;
    r1.register().await;
    report(&mut r1, 1.0, 1.0).await;
    // Two router heartbeats (a quarter second apart): by then any arena or
    // list would have come, five broadcasts over.
    let mut seen = Vec::new();
    let mut beats = 0;
    while beats < 2 {
        let env = r1.recv().await;
        beats += usize::from(matches!(env.body, Body::Heartbeat(_)));
        seen.push(env);
    }
    assert!(
        seen.iter()
            .all(|e| !matches!(e.body, Body::Arena(_) | Body::Neighbours(_))),
        "{seen:?}"
    );
    gcs.router()
        .set_arena(Some(ArenaConfig::demo().shape()))
        .await;
    assert!(gcs.with_fleet(|f| f.arena.is_some()));
    let env = r1.recv_matching(|e| matches!(e.body, Body::Arena(_))).await;
    assert!(matches!(&env.body, Body::Arena(a) if a.enabled && !a.is_empty()));
    r1.recv_matching(|e| neighbours(e).is_some()).await;
    // Cleared: an empty arena, then no more lists.
    gcs.router().set_arena(None).await;
    let env = r1.recv_matching(|e| matches!(e.body, Body::Arena(_))).await;
    assert!(matches!(&env.body, Body::Arena(a) if a.is_empty()));
    gcs.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_recording_carries_the_arena_the_switches_and_what_robots_report() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("safety.mcap");
    let gcs = station().await;
    let router = gcs.router().udp_addr();
    let mut r1 = Peer::new("robot_1", router).await;
    registered_with_arena(&mut r1).await;
    gcs.router().set_safety("robot_1", false).await.unwrap();
    // Begun after both: the file's start holds them.
    gcs.start_recording(mech_core::RecordTarget::File(file.clone()))
        .unwrap();
    let mut t = telemetry(3.6, 1.0, "", None);
    t.safety = Some(SafetyReport {
        state: SafetyState::On,
        arena: 1,
        intervention: mech_proto::Intervention::Fence,
        counts: InterventionCounts::default(),
        radius: 0.15,
        position_error: 0.0,
    });
    let mut events = gcs.router().subscribe(256, false);
    r1.send_telemetry(t).await;
    while !matches!(events.recv().await.unwrap().event, Event::Safety { .. }) {}
    gcs.shutdown().await;
    let replay = mech_core::replay::Replay::open(&file).unwrap();
    let start = replay.fleet_at(replay.start());
    assert_eq!(
        start.arena.as_ref().map(|a| a.boundary.len()),
        Some(4),
        "the arena at the file's start"
    );
    assert!(!start.robot("robot_1").unwrap().safety_enabled);
    let reported: Vec<(String, String)> = replay
        .events()
        .filter_map(|s| match s.event {
            Event::Safety {
                robot,
                intervention,
                ..
            } => Some((robot, intervention.as_str().to_string())),
            _ => None,
        })
        .collect();
    assert_eq!(reported, [("robot_1".to_string(), "fence".to_string())]);
}
