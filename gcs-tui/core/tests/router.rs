//! Router integration tests: a real router on 127.0.0.1:0 driven with raw
//! msgpack datagrams (and TCP frames) from test agents and controllers.

#![allow(clippy::unwrap_used)]

#[path = "support/agent.rs"]
mod agent;

use std::time::Duration;

use agent::{Peer, config, envelope, eventually, telemetry, twist};
use mech_core::Gcs;
use mech_core::LinkState;
use mech_core::{Delivery, DropReason, Event};
use mech_proto::framing::{StreamDecoder, write_stream_frame};
use mech_proto::{
    Body, ChannelsRequest, FleetCommand, Mission, MissionAck, Pose, PositionFix, RobotCommand,
    Subscribe, Waypoint,
};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

async fn gcs() -> Gcs {
    Gcs::start(config()).await.unwrap()
}

/// A router whose timing is changed by `f` (the router's UDP workers are
/// threads, so these tests run in real time with short periods; the exact
/// timing rules are unit-tested on the tables with injected time).
async fn gcs_with(f: impl FnOnce(&mut mech_core::RouterConfig)) -> Gcs {
    let mut c = config();
    f(&mut c.router);
    Gcs::start(c).await.unwrap()
}

fn mission(n: usize) -> Mission {
    let waypoints = (0..n)
        .map(|i| Waypoint {
            x: i as f64,
            y: 0.0,
            z: 0.0,
            time: None,
        })
        .collect();
    Mission {
        id: 0,
        waypoints,
        looped: false,
        arrival_radius: 0.1,
        start_index: 0,
    }
}

#[tokio::test]
async fn registration_routes_to_none_and_tracks_the_robot() {
    let gcs = gcs().await;
    let mut robot = Peer::new("robot_1", gcs.router().udp_addr()).await;
    robot.hello().await;
    let env = robot
        .recv_matching(|e| matches!(e.body, Body::Welcome(_)))
        .await;
    let Body::Welcome(w) = env.body else {
        unreachable!()
    };
    assert_eq!(w.route.channel, "", "a new robot is routed to none");
    assert_eq!(w.route.robot, "robot_1");
    let fleet = gcs.snapshot();
    let r = fleet.robot("robot_1").unwrap();
    assert_eq!(r.registration.addr, mech_core::LinkAddr::Udp(robot.addr()));
    assert_eq!(r.link, LinkState::Connected);
    assert_eq!(r.registration.hello.platform, "diff-drive");
    assert_eq!(r.route.requested, None);
    assert!(!r.route.is_pending());

    // A command on any channel is dropped and counted as not routed.
    let mut pad = Peer::new("gamepad", gcs.router().udp_addr()).await;
    pad.command("robot_1", "joy/0", 0.5).await;
    assert!(
        eventually(Duration::from_secs(2), || gcs
            .router()
            .counters()
            .channels
            .get("joy/0")
            .is_some_and(|t| t.dropped.not_routed == 1))
        .await
    );
    assert!(
        robot
            .drain()
            .iter()
            .all(|e| !matches!(e.body, Body::Command(_)))
    );
    gcs.shutdown().await;
}

#[tokio::test]
async fn config_default_route_applies_to_new_robots() {
    let mut cfg = config();
    cfg.router.default_route = Some("joy/0".into());
    let gcs = Gcs::start(cfg).await.unwrap();
    let mut robot = Peer::new("robot_1", gcs.router().udp_addr()).await;
    robot.register().await;
    assert_eq!(robot.route, "joy/0");
    let mut pad = Peer::new("gamepad", gcs.router().udp_addr()).await;
    let seq = pad.command("robot_1", "joy/0", 0.2).await;
    let got = robot
        .recv_matching(|e| matches!(e.body, Body::Command(_)))
        .await;
    assert_eq!(
        (got.header.seq, got.header.sender.as_str()),
        (seq, "gamepad")
    );
    gcs.shutdown().await;
}

#[tokio::test]
async fn re_registering_from_a_new_address_updates_the_robot() {
    let gcs = gcs().await;
    let mut first = Peer::new("robot_1", gcs.router().udp_addr()).await;
    first.register().await;
    // The router has the first agent's route acknowledgement before the
    // second agent speaks: datagrams of different senders are not ordered
    // among themselves, and a late one from the old address would move the
    // robot back there.
    let heard = || {
        gcs.router()
            .counters()
            .robots
            .get("robot_1")
            .map_or(0, |t| t.received)
    };
    assert!(eventually(Duration::from_secs(5), || heard() >= 2).await);
    gcs.router()
        .set_route("robot_1", Some("joy/0"))
        .await
        .unwrap();
    let mut second = Peer::new("robot_1", gcs.router().udp_addr()).await;
    second.hello().await;
    let env = second
        .recv_matching(|e| matches!(e.body, Body::Welcome(_)))
        .await;
    let Body::Welcome(w) = env.body else {
        unreachable!()
    };
    assert_eq!(
        w.route.channel, "joy/0",
        "the restarted agent gets its route back"
    );
    let fleet = gcs.snapshot();
    assert_eq!(fleet.robots.len(), 1, "same robot, not a duplicate");
    assert_eq!(
        fleet.robot("robot_1").unwrap().registration.addr,
        mech_core::LinkAddr::Udp(second.addr())
    );
    let mut pad = Peer::new("gamepad", gcs.router().udp_addr()).await;
    let seq = pad.command("robot_1", "joy/0", 0.3).await;
    let got = second
        .recv_matching(|e| matches!(e.body, Body::Command(_)))
        .await;
    assert_eq!(got.header.seq, seq);
    gcs.shutdown().await;
}

/// Whether `robot_1` soon shows `channel` acknowledged, nothing pending.
async fn acknowledged(gcs: &Gcs, channel: &str) -> bool {
    eventually(Duration::from_secs(2), || {
        let f = gcs.snapshot();
        let r = f.robot("robot_1").unwrap();
        !r.route.is_pending() && r.route.acknowledged.as_deref() == Some(channel)
    })
    .await
}

#[tokio::test]
async fn a_route_switch_drops_the_old_channels_very_next_message() {
    let gcs = gcs().await;
    let mut robot = Peer::new("robot_1", gcs.router().udp_addr()).await;
    robot.register().await;
    let mut pad0 = Peer::new("pad0", gcs.router().udp_addr()).await;
    let mut pad1 = Peer::new("pad1", gcs.router().udp_addr()).await;

    gcs.router()
        .set_route("robot_1", Some("joy/0"))
        .await
        .unwrap();
    assert!(gcs.snapshot().robot("robot_1").unwrap().route.is_pending());
    assert_eq!(robot.follow_route().await, "joy/0");
    assert!(acknowledged(&gcs, "joy/0").await);
    let a = pad0.command("robot_1", "joy/0", 0.1).await;
    let got = robot
        .recv_matching(|e| matches!(e.body, Body::Command(_)))
        .await;
    assert_eq!(
        (
            got.header.sender.as_str(),
            got.header.seq,
            got.header.channel.as_str()
        ),
        ("pad0", a, "joy/0")
    );

    // Switch: the very next joy/0 message is dropped, joy/1 is forwarded.
    // The two pads' datagrams reach the router in either order (datagrams
    // of two senders are not ordered among themselves), so the drop is
    // awaited on its counter rather than assumed done once pad1's command
    // is through.
    gcs.router()
        .set_route("robot_1", Some("joy/1"))
        .await
        .unwrap();
    pad0.command("robot_1", "joy/0", 0.9).await;
    let b = pad1.command("robot_1", "joy/1", 0.2).await;
    let got = robot
        .recv_matching(|e| matches!(e.body, Body::Command(_)))
        .await;
    assert_eq!(
        (got.header.sender.as_str(), got.header.seq),
        ("pad1", b),
        "first command after the switch is the new channel's"
    );
    let joy0_dropped = || gcs.router().counters().channels["joy/0"].dropped.not_routed;
    assert!(eventually(Duration::from_secs(10), || joy0_dropped() >= 1).await);
    let c = gcs.router().counters();
    assert_eq!(c.channels["joy/0"].dropped.not_routed, 1);
    assert_eq!(c.channels["joy/0"].forwarded, 1);
    assert_eq!(c.channels["joy/1"].forwarded, 1);
    assert_eq!(c.robots["robot_1"].dropped.not_routed, 1);

    // The agent is told, and the table shows pending until it acknowledges.
    assert_eq!(robot.follow_route().await, "joy/1");
    assert!(acknowledged(&gcs, "joy/1").await);

    // Routed to none: nothing gets through.
    gcs.router().set_route("robot_1", None).await.unwrap();
    pad1.command("robot_1", "joy/1", 0.2).await;
    assert!(
        eventually(Duration::from_secs(2), || gcs.router().counters().channels
            ["joy/1"]
            .dropped
            .not_routed
            == 1)
        .await
    );
    gcs.shutdown().await;
}

#[tokio::test]
async fn route_changes_are_repeated_until_acknowledged() {
    let gcs = gcs().await;
    let mut robot = Peer::new("robot_1", gcs.router().udp_addr()).await;
    robot.register().await;
    let epoch = gcs
        .router()
        .set_route("robot_1", Some("wp/gcs"))
        .await
        .unwrap();
    for _ in 0..3 {
        let env = robot
            .recv_matching(|e| matches!(e.body, Body::Route(_)))
            .await;
        let Body::Route(r) = env.body else {
            unreachable!()
        };
        assert_eq!((r.channel.as_str(), r.epoch), ("wp/gcs", epoch));
    }
    robot.ack_route("wp/gcs", epoch).await;
    assert!(
        eventually(Duration::from_secs(2), || !gcs
            .snapshot()
            .robot("robot_1")
            .unwrap()
            .route
            .is_pending())
        .await
    );
    tokio::time::sleep(Duration::from_millis(300)).await;
    robot.drain();
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert!(
        robot
            .drain()
            .iter()
            .all(|e| !matches!(e.body, Body::Route(_))),
        "no repeats after the ack"
    );
    gcs.shutdown().await;
}

#[tokio::test]
async fn a_fleet_command_gives_each_robot_only_its_part() {
    let gcs = gcs().await;
    let addr = gcs.router().udp_addr();
    let mut r1 = Peer::new("robot_1", addr).await;
    let mut r2 = Peer::new("robot_2", addr).await;
    let mut r3 = Peer::new("robot_3", addr).await;
    for r in [&mut r1, &mut r2, &mut r3] {
        r.register().await;
    }
    gcs.router()
        .set_route("robot_1", Some("fleet/c1"))
        .await
        .unwrap();
    gcs.router()
        .set_route("robot_2", Some("fleet/c1"))
        .await
        .unwrap();
    let parts = (1..=3)
        .map(|i| RobotCommand {
            robot: format!("robot_{i}"),
            command: twist(i as f64),
        })
        .collect();
    let mut fleet = Peer::new("formation", addr).await;
    fleet
        .send(
            mech_proto::ROUTER,
            "fleet/c1",
            Body::FleetCommand(FleetCommand { parts }),
        )
        .await;
    for (robot, vx) in [(&r1, 1.0), (&r2, 2.0)] {
        let got = robot
            .recv_matching(|e| matches!(e.body, Body::Command(_)))
            .await;
        assert_eq!(got.header.destination, robot.name);
        assert_eq!(got.header.sender, "formation");
        assert_eq!(got.header.channel, "fleet/c1");
        assert_eq!(got.body, Body::Command(twist(vx)));
    }
    tokio::time::sleep(Duration::from_millis(50)).await;
    assert!(
        r3.drain()
            .iter()
            .all(|e| !matches!(e.body, Body::Command(_))),
        "robot_3 is not routed to fleet/c1"
    );
    assert_eq!(
        gcs.router().counters().channels["fleet/c1"]
            .dropped
            .not_routed,
        1
    );
    gcs.shutdown().await;
}

#[tokio::test]
async fn in_process_publishers_take_the_same_routing_path() {
    let gcs = gcs().await;
    let mut robot = Peer::new("robot_1", gcs.router().udp_addr()).await;
    robot.register().await;
    let mut keys = gcs.router().publisher("keyboard", "key/0");
    assert_eq!(
        keys.send("robot_1", twist(0.4)).await.unwrap(),
        Delivery::Dropped(DropReason::NotRouted)
    );
    assert_eq!(
        keys.send("robot_9", twist(0.4)).await.unwrap(),
        Delivery::Dropped(DropReason::UnknownRobot)
    );
    gcs.router()
        .set_route("robot_1", Some("key/0"))
        .await
        .unwrap();
    assert_eq!(
        keys.send("robot_1", twist(0.4)).await.unwrap(),
        Delivery::Forwarded(1)
    );
    let got = robot
        .recv_matching(|e| matches!(e.body, Body::Command(_)))
        .await;
    assert_eq!(
        (got.header.sender.as_str(), got.header.channel.as_str()),
        ("keyboard", "key/0")
    );
    let channels = gcs.router().channels();
    let key = channels.iter().find(|c| c.name == "key/0").unwrap();
    assert_eq!(key.publisher, "keyboard");
    assert_eq!(key.robots, vec!["robot_1".to_string()]);
    gcs.shutdown().await;
}

#[tokio::test]
async fn silence_makes_a_robot_stale_then_lost_and_speech_reconnects_it() {
    let gcs = gcs_with(|r| {
        r.stale_after = Duration::from_millis(200);
        r.lost_after = Duration::from_millis(400);
    })
    .await;
    let mut events = gcs.router().subscribe(64, false);
    let mut robot = Peer::new("robot_1", gcs.router().udp_addr()).await;
    robot.register().await;
    let link = || gcs.snapshot().robot("robot_1").unwrap().link;
    assert_eq!(link(), LinkState::Connected);
    assert!(eventually(Duration::from_secs(2), || link() == LinkState::Stale).await);
    assert!(eventually(Duration::from_secs(2), || link() == LinkState::Lost).await);
    let (mut links, mut heard) = (Vec::new(), None);
    while let Some(ev) = events.try_recv() {
        match ev.event {
            Event::Link { state, .. } => links.push((state, ev.at)),
            Event::Registered { .. } => heard = Some(ev.at),
            _ => {}
        }
    }
    assert_eq!(
        links.iter().map(|l| l.0).collect::<Vec<_>>(),
        vec![LinkState::Stale, LinkState::Lost]
    );
    // Never early (a loaded machine may make either late by a timer tick
    // or more, so their difference is not bounded below).
    let heard = heard.expect("the registration event");
    let (stale_at, lost_at) = (links[0].1, links[1].1);
    assert!(
        stale_at - heard >= Duration::from_millis(200)
            && lost_at - heard >= Duration::from_millis(400),
        "heard at {heard:?}, then {links:?}"
    );
    robot.send_telemetry(telemetry(1.0, 2.0, "", None)).await;
    assert!(
        eventually(Duration::from_secs(1), || gcs
            .snapshot()
            .robot("robot_1")
            .unwrap()
            .link
            == LinkState::Connected)
        .await
    );
    gcs.shutdown().await;
}

#[tokio::test]
async fn heartbeats_go_to_every_robot() {
    let gcs = gcs_with(|r| r.heartbeat_period = Duration::from_millis(50)).await;
    let mut robot = Peer::new("robot_1", gcs.router().udp_addr()).await;
    robot.register().await;
    let t0 = tokio::time::Instant::now();
    let mut beats = 0;
    while beats < 4 {
        if matches!(robot.recv().await.body, Body::Heartbeat(_)) {
            beats += 1;
        }
    }
    // Four periods, give or take a timer tick; never faster.
    let spent = t0.elapsed();
    assert!(spent >= Duration::from_millis(140), "{spent:?}");
    gcs.shutdown().await;
}

#[tokio::test]
async fn a_slow_subscriber_loses_only_its_own_events() {
    let gcs = gcs().await;
    let slow = gcs.router().subscribe(4, true);
    let mut fast = gcs.router().subscribe(10_000, true);
    let mut robot = Peer::new("robot_1", gcs.router().udp_addr()).await;
    robot.register().await;
    gcs.router()
        .set_route("robot_1", Some("joy/0"))
        .await
        .unwrap();
    let mut pad = Peer::new("pad", gcs.router().udp_addr()).await;
    const N: usize = 500;
    // Batches small enough for the kernel's socket buffers; the router
    // drains them between batches.
    for batch in 0..N / 25 {
        for i in 0..25 {
            let x = (batch * 25 + i) as f64;
            robot.send_telemetry(telemetry(x, 0.0, "joy/0", None)).await;
            pad.command("robot_1", "joy/0", 0.1).await;
        }
        let mut commands = 0;
        while commands < 25 {
            if matches!(robot.recv().await.body, Body::Command(_)) {
                commands += 1;
            }
        }
    }
    let mut telemetry_seen = 0;
    assert!(
        eventually(Duration::from_secs(3), || {
            while let Some(ev) = fast.try_recv() {
                if matches!(ev.event, Event::Telemetry { .. }) {
                    telemetry_seen += 1;
                }
            }
            telemetry_seen == N
        })
        .await,
        "fast subscriber saw {telemetry_seen}"
    );
    assert_eq!(fast.dropped(), 0);
    assert!(
        slow.dropped() >= (N - 4) as u64,
        "slow subscriber dropped {}",
        slow.dropped()
    );
    assert_eq!(
        gcs.router().counters().channels["joy/0"].forwarded,
        N as u64
    );
    assert_eq!(
        gcs.snapshot().robot("robot_1").unwrap().telemetry.pose.x,
        (N - 1) as f64,
        "the fleet model never drops"
    );
    gcs.shutdown().await;
}

#[tokio::test]
async fn external_subscribers_receive_telemetry() {
    let gcs = gcs().await;
    let mut robot = Peer::new("robot_1", gcs.router().udp_addr()).await;
    robot.register().await;
    let mut tool = Peer::new("plotter", gcs.router().udp_addr()).await;
    tool.send(
        mech_proto::ROUTER,
        "",
        Body::Subscribe(Subscribe { telemetry: true }),
    )
    .await;
    tokio::time::sleep(Duration::from_millis(20)).await;
    robot.send_telemetry(telemetry(3.0, 4.0, "", None)).await;
    let got = tool
        .recv_matching(|e| matches!(e.body, Body::Telemetry(_)))
        .await;
    assert_eq!(got.header.sender, "robot_1");
    let Body::Telemetry(t) = got.body else {
        unreachable!()
    };
    assert_eq!((t.pose.x, t.pose.y), (3.0, 4.0));
    gcs.shutdown().await;
}

#[tokio::test]
async fn missions_are_retried_until_acknowledged() {
    let gcs = gcs().await;
    let mut events = gcs.router().subscribe(64, false);
    let mut robot = Peer::new("robot_1", gcs.router().udp_addr()).await;
    robot.register().await;
    let id = gcs
        .router()
        .send_mission("gcs", "robot_1", "wp/gcs", mission(3))
        .await
        .unwrap();
    let mut times = Vec::new();
    for _ in 0..3 {
        let env = robot
            .recv_matching(|e| matches!(e.body, Body::Mission(_)))
            .await;
        assert_eq!(env.header.channel, "wp/gcs");
        let Body::Mission(m) = env.body else {
            unreachable!()
        };
        assert_eq!((m.id, m.waypoints.len()), (id, 3));
        times.push(tokio::time::Instant::now());
    }
    for w in times.windows(2) {
        let gap = w[1] - w[0];
        assert!(
            gap >= Duration::from_millis(150),
            "retried too soon: {gap:?}"
        );
    }
    robot
        .send(
            "gcs",
            "",
            Body::MissionAck(MissionAck {
                id,
                accepted: true,
                reason: String::new(),
            }),
        )
        .await;
    tokio::time::sleep(Duration::from_millis(50)).await;
    robot.drain();
    tokio::time::sleep(Duration::from_millis(600)).await;
    assert!(
        robot
            .drain()
            .iter()
            .all(|e| !matches!(e.body, Body::Mission(_))),
        "no repeats after the ack"
    );
    let mut acked = false;
    while let Some(ev) = events.try_recv() {
        if let Event::MissionAcked {
            id: got,
            accepted: true,
            ..
        } = ev.event
        {
            acked = got == id;
        }
    }
    assert!(acked);
    let f = gcs.snapshot();
    assert_eq!(
        f.robot("robot_1")
            .unwrap()
            .waypoints
            .sent
            .as_ref()
            .unwrap()
            .delivery,
        mech_core::fleet::MissionDelivery::Acked
    );
    gcs.shutdown().await;
}

#[tokio::test]
async fn an_unacknowledged_mission_is_reported_failed() {
    let gcs = gcs_with(|r| {
        r.mission_retry = Duration::from_millis(50);
        r.mission_give_up = Duration::from_millis(500);
    })
    .await;
    let mut robot = Peer::new("robot_1", gcs.router().udp_addr()).await;
    robot.register().await;
    let id = gcs
        .router()
        .send_mission("gcs", "robot_1", "wp/gcs", mission(1))
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(700)).await;
    let f = gcs.snapshot();
    let sent = f.robot("robot_1").unwrap().waypoints.sent.clone().unwrap();
    assert_eq!(sent.id, id);
    assert!(
        matches!(sent.delivery, mech_core::fleet::MissionDelivery::Failed(_)),
        "{:?}",
        sent.delivery
    );
    let repeats = robot
        .drain()
        .iter()
        .filter(|e| matches!(e.body, Body::Mission(_)))
        .count();
    assert!(
        (5..=11).contains(&repeats),
        "{repeats} mission sends in 0.5 s, one every 50 ms"
    );
    gcs.shutdown().await;
}

#[tokio::test]
async fn estop_reaches_every_robot_until_each_acknowledges() {
    let gcs = gcs().await;
    let addr = gcs.router().udp_addr();
    let mut r1 = Peer::new("robot_1", addr).await;
    let mut r2 = Peer::new("robot_2", addr).await;
    r1.register().await;
    r2.register().await;
    let id = gcs.router().estop().await;
    assert!(gcs.snapshot().estop.engaged);
    let is_estop = |e: &mech_proto::Envelope| {
        matches!(e.body, Body::EStop(mech_proto::EStop { engage: true, .. }))
    };
    r1.recv_matching(is_estop).await;
    r1.send(
        mech_proto::ROUTER,
        "",
        Body::EStopAck(mech_proto::EStopAck { engage: true, id }),
    )
    .await;
    // robot_2 has not acknowledged: it keeps receiving the e-stop.
    for _ in 0..3 {
        let env = r2.recv_matching(is_estop).await;
        assert_eq!(
            env.body,
            Body::EStop(mech_proto::EStop { engage: true, id })
        );
    }
    assert_eq!(
        gcs.snapshot()
            .estop
            .pending
            .iter()
            .cloned()
            .collect::<Vec<_>>(),
        vec!["robot_2".to_string()]
    );
    r2.send(
        mech_proto::ROUTER,
        "",
        Body::EStopAck(mech_proto::EStopAck { engage: true, id }),
    )
    .await;
    assert!(
        eventually(Duration::from_secs(2), || gcs
            .snapshot()
            .estop
            .pending
            .is_empty())
        .await
    );
    tokio::time::sleep(Duration::from_millis(50)).await;
    r1.drain();
    tokio::time::sleep(Duration::from_millis(250)).await;
    assert!(
        r1.drain().iter().all(|e| !matches!(e.body, Body::EStop(_))),
        "no repeats once everyone acknowledged"
    );
    // A robot registering while the e-stop is engaged gets it too.
    let mut r3 = Peer::new("robot_3", addr).await;
    r3.register().await;
    r3.recv_matching(is_estop).await;
    // Release is explicit.
    let rel = gcs.router().release().await;
    let env = r1.recv_matching(|e| matches!(e.body, Body::EStop(_))).await;
    assert_eq!(
        env.body,
        Body::EStop(mech_proto::EStop {
            engage: false,
            id: rel
        })
    );
    assert!(!gcs.snapshot().estop.engaged);
    gcs.shutdown().await;
}

#[tokio::test]
async fn garbage_is_counted_never_fatal() {
    let gcs = gcs().await;
    let mut robot = Peer::new("robot_1", gcs.router().udp_addr()).await;
    robot.register().await;
    gcs.router()
        .set_route("robot_1", Some("joy/0"))
        .await
        .unwrap();
    let pad = Peer::new("pad", gcs.router().udp_addr()).await;
    let good = mech_proto::encode(&envelope(
        "pad",
        "robot_1",
        "joy/0",
        1,
        Body::Command(twist(0.1)),
    ))
    .unwrap();
    let mut wrong_version = good.clone();
    wrong_version[1] = 9;
    let garbage: Vec<Vec<u8>> = vec![
        b"hello router".to_vec(),
        vec![0xff; 300],
        good[..good.len() / 2].to_vec(),
        wrong_version,
        vec![0x99],
    ];
    for g in &garbage {
        pad.send_raw(g).await;
    }
    pad.send_raw(&good).await;
    let got = robot
        .recv_matching(|e| matches!(e.body, Body::Command(_)))
        .await;
    assert_eq!(got.header.sender, "pad", "routing continues after garbage");
    let c = gcs.router().counters();
    assert_eq!(c.dropped.bad_packet, garbage.len() as u64);
    // Each one reaches the event log: the first on a line of its own, the
    // rest counted in the summary that follows within a second or so.
    let rest = format!("refused {} messages", garbage.len() - 1);
    let summarized = || {
        let log = gcs.snapshot().log;
        let single = log
            .iter()
            .filter(|l| l.text.starts_with("bad packet"))
            .count();
        let summary = log.iter().filter(|l| l.text.starts_with(&rest)).count();
        (single, summary)
    };
    assert!(
        eventually(Duration::from_secs(5), || summarized() == (1, 1)).await,
        "{:?}",
        gcs.snapshot().log
    );
    gcs.shutdown().await;
}

#[tokio::test]
async fn tcp_controllers_publish_and_discover_channels() {
    let gcs = gcs().await;
    let mut robot = Peer::new("robot_1", gcs.router().udp_addr()).await;
    robot.register().await;
    gcs.router()
        .set_route("robot_1", Some("ext/matlab"))
        .await
        .unwrap();
    let mut stream = tokio::net::TcpStream::connect(gcs.router().tcp_addr().unwrap())
        .await
        .unwrap();
    let mut frames = Vec::new();
    write_stream_frame(
        &envelope(
            "matlab",
            "robot_1",
            "ext/matlab",
            1,
            Body::Command(twist(0.7)),
        ),
        &mut frames,
    )
    .unwrap();
    write_stream_frame(
        &envelope(
            "matlab",
            mech_proto::ROUTER,
            "",
            2,
            Body::ChannelsRequest(ChannelsRequest {}),
        ),
        &mut frames,
    )
    .unwrap();
    stream.write_all(&frames).await.unwrap();
    let got = robot
        .recv_matching(|e| matches!(e.body, Body::Command(_)))
        .await;
    assert_eq!(
        (got.header.sender.as_str(), got.body),
        ("matlab", Body::Command(twist(0.7)))
    );
    let mut decoder = StreamDecoder::new();
    let mut buf = [0u8; 4096];
    let reply = loop {
        if let Some(m) = decoder.next_message() {
            break m.unwrap();
        }
        let n = tokio::time::timeout(Duration::from_secs(3), stream.read(&mut buf))
            .await
            .unwrap()
            .unwrap();
        assert!(n > 0, "router closed the stream");
        decoder.push(&buf[..n]);
    };
    let Body::Channels(list) = reply.body else {
        panic!("{reply:?}")
    };
    let ch = list
        .channels
        .iter()
        .find(|c| c.name == "ext/matlab")
        .unwrap();
    assert_eq!(ch.publisher, "matlab");
    assert_eq!(ch.robots, vec!["robot_1".to_string()]);
    gcs.shutdown().await;
}

#[tokio::test]
async fn subscriptions_lapse_unless_renewed() {
    let gcs = gcs_with(|r| r.subscriber_timeout = Duration::from_millis(500)).await;
    let mut robot = Peer::new("robot_1", gcs.router().udp_addr()).await;
    robot.register().await;
    let mut tool = Peer::new("plotter", gcs.router().udp_addr()).await;
    let subscribe = Body::Subscribe(Subscribe { telemetry: true });
    tool.send(mech_proto::ROUTER, "", subscribe.clone()).await;
    // Renewed within the 0.5 s timeout: still subscribed at 0.7 s.
    tokio::time::sleep(Duration::from_millis(350)).await;
    tool.send(mech_proto::ROUTER, "", subscribe).await;
    tokio::time::sleep(Duration::from_millis(350)).await;
    robot.send_telemetry(telemetry(1.0, 2.0, "", None)).await;
    let got = tool.recv_within(Duration::from_secs(1)).await;
    assert!(
        matches!(got.map(|e| e.body), Some(Body::Telemetry(_))),
        "a renewed subscription receives telemetry"
    );
    // Not renewed for longer than the timeout: lapsed.
    tokio::time::sleep(Duration::from_millis(700)).await;
    robot.send_telemetry(telemetry(1.5, 2.0, "", None)).await;
    let got = tool.recv_within(Duration::from_secs(1)).await;
    assert!(
        got.is_none(),
        "a lapsed subscription receives nothing: {got:?}"
    );
    gcs.shutdown().await;
}

#[tokio::test]
async fn position_fixes_reach_their_robot_and_unknown_robots_are_counted() {
    let gcs = gcs().await;
    let mut robot = Peer::new("robot_1", gcs.router().udp_addr()).await;
    robot.register().await;
    let mut tracker = Peer::new("mocap", gcs.router().udp_addr()).await;
    let fix = |robot: &str| {
        Body::PositionFix(PositionFix {
            robot: robot.into(),
            pose: Pose {
                x: 1.25,
                y: -0.5,
                z: 0.0,
                heading: 0.3,
            },
            quality: 0.9,
        })
    };
    tracker.send(mech_proto::ROUTER, "", fix("robot_1")).await;
    let got = robot
        .recv_matching(|e| matches!(e.body, Body::PositionFix(_)))
        .await;
    assert_eq!(got.header.sender, "mocap");
    assert_eq!(got.body, fix("robot_1"));
    tracker.send(mech_proto::ROUTER, "", fix("robot_9")).await;
    assert!(
        eventually(Duration::from_secs(2), || gcs
            .router()
            .counters()
            .dropped
            .unknown_robot
            == 1)
        .await,
        "a fix for an unknown robot is dropped and counted"
    );
    gcs.shutdown().await;
}

#[tokio::test]
async fn after_shutdown_a_connected_tcp_controller_reaches_no_robot() {
    let gcs = gcs().await;
    let mut robot = Peer::new("robot_1", gcs.router().udp_addr()).await;
    robot.register().await;
    gcs.router()
        .set_route("robot_1", Some("ext/matlab"))
        .await
        .unwrap();
    robot.follow_route().await;
    let mut stream = tokio::net::TcpStream::connect(gcs.router().tcp_addr().unwrap())
        .await
        .unwrap();
    let command = |seq, vx| {
        let mut frame = Vec::new();
        let env = envelope(
            "matlab",
            "robot_1",
            "ext/matlab",
            seq,
            Body::Command(twist(vx)),
        );
        write_stream_frame(&env, &mut frame).unwrap();
        frame
    };
    stream.write_all(&command(1, 0.3)).await.unwrap();
    let got = robot
        .recv_matching(|e| matches!(e.body, Body::Command(_)))
        .await;
    assert_eq!(got.body, Body::Command(twist(0.3)), "routed while running");

    // Shutdown returns only once the TCP peer's task has ended: the router
    // closes the connection, and what the controller still writes goes
    // nowhere.
    let mut pad = gcs.router().publisher("pad", "ext/matlab");
    gcs.shutdown().await;
    let mut buf = [0u8; 64];
    let closed = tokio::time::timeout(Duration::from_secs(2), stream.read(&mut buf)).await;
    assert!(
        matches!(closed, Ok(Ok(0)) | Ok(Err(_))),
        "the router closed the TCP connection: {closed:?}"
    );
    let _ = stream.write_all(&command(2, 0.9)).await;
    assert_eq!(
        pad.send("robot_1", twist(0.9)).await.unwrap(),
        Delivery::Dropped(DropReason::Stopped),
        "in-process publishers are refused too"
    );
    tokio::time::sleep(Duration::from_millis(300)).await;
    let late: Vec<_> = robot
        .drain()
        .into_iter()
        .filter(|e| matches!(e.body, Body::Command(_)))
        .collect();
    assert!(
        late.is_empty(),
        "commands after shutdown reached the robot: {late:?}"
    );
}

#[tokio::test]
async fn a_second_station_cannot_share_the_port_of_a_running_one() {
    let first = gcs().await;
    let addr = first.router().udp_addr();
    let mut c = config();
    c.router.udp = addr;
    let second = Gcs::start(c).await;
    let err = second.expect_err("the port is the first station's");
    assert!(err.to_string().contains(&addr.to_string()), "{err}");
    // Once the first one has stopped and gone, the port is free again.
    first.shutdown().await;
    drop(first);
    let mut c = config();
    c.router.udp = addr;
    let third = Gcs::start(c).await.unwrap();
    third.shutdown().await;
}

#[tokio::test]
async fn a_stopping_station_says_bye_to_its_robots() {
    let gcs = gcs().await;
    let mut robot = Peer::new("robot_1", gcs.router().udp_addr()).await;
    robot.register().await;
    gcs.shutdown().await;
    let bye = tokio::time::timeout(
        Duration::from_secs(5),
        robot.recv_matching(|m| matches!(m.body, Body::Bye(_))),
    )
    .await;
    assert!(bye.is_ok(), "the robot was told");
}
