//! Two (or three) stations in one process, each with its own simulated
//! fleet, bridged through Zenoh over loopback: each shows the other's
//! robots read-only; a command published on Zenoh reaches a robot only
//! while it is routed to the command's channel; a remote robot is routed
//! only where its station's `[auth]` lists the asking operator's key; a
//! station or robot that leaves shows lost; bad names and payloads are
//! refused and counted; a `get` on a whole station reads its state without
//! reaching the route-request queryable's refusals.

#![allow(clippy::unwrap_used)]

#[path = "support/stations.rs"]
mod support;

use std::time::Duration;

use mech_core::LinkState;
use mech_core::auth::{AuthMode, KeyEntry, KeyFile, Role};
use mech_proto::ControlMode;
use support::{Station, core, eventually, program, shown, station, zenoh};

/// Generous: a loaded 2-core machine runs these.
const WAIT: Duration = Duration::from_secs(20);

/// Publishes a twist on `key` every 50 ms until aborted, as a program on
/// the Zenoh network would.
fn publish_twists(session: zenoh::Session, key: String) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        let p = session.declare_publisher(key).await.unwrap();
        loop {
            p.put(r#"{"twist": {"vx": 0.2, "wz": 0.1}}"#).await.unwrap();
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    })
}

async fn two_stations(robots: usize) -> (Station, Station) {
    let a = station(core(), zenoh("site-a", &[]), robots).await;
    let b = station(
        core(),
        zenoh("site-b", std::slice::from_ref(&a.endpoint)),
        robots,
    )
    .await;
    for (st, other) in [(&a, "site-b"), (&b, "site-a")] {
        for i in 1..=robots {
            let name = format!("robot_{i}@{other}");
            st.until(&name, WAIT, |f| shown(f, &name, LinkState::Connected))
                .await;
        }
    }
    (a, b)
}

/// Station b shows site-a's robots as remote and read-only, and its
/// `route all` touches only its own.
async fn site_a_is_read_only_at_b(b: &mut Station) {
    let remote = b.robot("robot_1@site-a").unwrap();
    assert_eq!(remote.remote.as_deref(), Some("site-a"));
    assert!(!remote.registration.hello.platform.is_empty());
    let status = b.run("status").await.unwrap();
    assert!(
        status.contains("stations site-a connected (2 robots)"),
        "{status}"
    );
    assert!(
        status.contains("robot_2@site-a") && status.contains("remote site-a (read-only)"),
        "{status}"
    );
    let e = b.run("drive robot_1@site-a 0.2 0.1").await.unwrap_err();
    assert!(e.contains("read-only"), "{e}");
    assert!(
        b.run("route all none")
            .await
            .unwrap()
            .contains("robot_1, robot_2 routed")
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn each_station_sees_the_others_robots_and_zenoh_commands_obey_routes() {
    let (mut a, mut b) = two_stations(2).await;
    site_a_is_read_only_at_b(&mut b).await;

    // A program on the network drives robot_1 of site-a on ext/zenoh.
    let tool = program(&a.endpoint).await;
    let driving = publish_twists(tool.clone(), "mech/site-a/robot_1/cmd/ext/zenoh".into());
    let unrouted = || a.bridge.stats();
    eventually("commands reach the router, unrouted", WAIT, || {
        let s = unrouted();
        (s.commands_dropped >= 10)
            .then_some(())
            .ok_or(format!("{s:?}"))
    })
    .await;
    assert_eq!(a.bridge.stats().commands_forwarded, 0);
    assert_eq!(
        a.robot("robot_1").unwrap().telemetry.mode,
        ControlMode::Idle
    );

    a.run("route robot_1 ext/zenoh").await.unwrap();
    a.until("robot_1 obeys Zenoh", WAIT, |f| {
        let r = f.robot("robot_1").unwrap();
        (r.telemetry.mode == ControlMode::Twist && r.reported_channel() == Some("ext/zenoh"))
            .then_some(())
            .ok_or(format!(
                "mode {:?} on {:?}",
                r.telemetry.mode,
                r.reported_channel()
            ))
    })
    .await;
    assert!(a.bridge.stats().commands_forwarded > 0);
    assert_eq!(
        a.robot("robot_2").unwrap().telemetry.mode,
        ControlMode::Idle
    );
    b.until("site-b sees robot_1 of site-a driven", WAIT, |f| {
        let r = f.robot("robot_1@site-a").unwrap();
        (r.telemetry.mode == ControlMode::Twist
            && r.route.requested.as_deref() == Some("ext/zenoh"))
        .then_some(())
        .ok_or(format!("{:?} {:?}", r.telemetry.mode, r.route))
    })
    .await;

    // Routed away, the same commands stop reaching it.
    a.run("route robot_1 none").await.unwrap();
    a.until("robot_1 stops obeying", WAIT, |f| {
        let r = f.robot("robot_1").unwrap();
        (r.route.acknowledged.is_none() && !r.route.is_pending())
            .then_some(())
            .ok_or(format!("{:?}", r.route))
    })
    .await;
    let forwarded = a.bridge.stats().commands_forwarded;
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert_eq!(a.bridge.stats().commands_forwarded, forwarded);
    driving.abort();
    tool.close().await.unwrap();
    a.stop().await;
    b.stop().await;
}

/// A station that authenticates, listing `op-b` as an operator.
async fn authenticated_station(dir: &std::path::Path) -> Station {
    let op_b = dir.join("op-b.key");
    KeyFile::generate("op-b", &op_b).unwrap();
    let mut c = core();
    c.auth.mode = Some(AuthMode::Required);
    c.auth.keys = vec![KeyEntry {
        role: Role::Operator,
        name: "op-b".into(),
        file: op_b,
        channels: vec![],
    }];
    let mut z = zenoh("site-a", &[]);
    z.commands = false;
    z.route_requests = mech_zenoh::RouteRequests::Signed;
    station(c, z, 2).await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_remote_robot_is_routed_only_with_an_operator_key_its_station_lists() {
    let dir = tempfile::tempdir().unwrap();
    let a = authenticated_station(dir.path()).await;
    let mut with_key = zenoh("site-b", std::slice::from_ref(&a.endpoint));
    with_key.operator_key = Some(dir.path().join("op-b.key"));
    let mut b = station(core(), with_key, 0).await;
    let c_key = dir.path().join("op-c.key");
    KeyFile::generate("op-c", &c_key).unwrap();
    let mut unlisted = zenoh("site-c", std::slice::from_ref(&a.endpoint));
    unlisted.operator_key = Some(c_key);
    let mut c = station(core(), unlisted, 0).await;
    let mut unsigned = station(
        core(),
        zenoh("site-d", std::slice::from_ref(&a.endpoint)),
        0,
    )
    .await;
    // Both robots: their samples come in no promised order.
    for s in [&b, &c, &unsigned] {
        s.until("robots of site-a", WAIT, |f| {
            shown(f, "robot_1@site-a", LinkState::Connected)
                .and_then(|()| shown(f, "robot_2@site-a", LinkState::Connected))
        })
        .await;
    }

    let done = b.run("route robot_1@site-a ext/b").await.unwrap();
    assert!(done.contains("for operator op-b"), "{done}");
    a.until("site-a routed robot_1", WAIT, |f| {
        let r = f.robot("robot_1").unwrap();
        (r.route.acknowledged.as_deref() == Some("ext/b"))
            .then_some(())
            .ok_or(format!("{:?}", r.route))
    })
    .await;
    b.until("site-b sees the new route", WAIT, |f| {
        let r = f.robot("robot_1@site-a").unwrap();
        (r.route.acknowledged.as_deref() == Some("ext/b"))
            .then_some(())
            .ok_or(format!("{:?}", r.route))
    })
    .await;

    let refused = c.run("route robot_2@site-a ext/c").await.unwrap_err();
    assert!(
        refused.contains("did not route") && refused.contains("not listed"),
        "{refused}"
    );
    let refused = unsigned
        .run("route robot_2@site-a ext/d")
        .await
        .unwrap_err();
    assert!(refused.contains("unsigned route request"), "{refused}");
    assert_eq!(a.robot("robot_2").unwrap().route.requested, None);
    assert!(a.gcs.router().rejections().total() >= 1);
    assert_eq!(a.bridge.stats().route_requests_refused, 2);
    assert_eq!(a.bridge.stats().route_requests_done, 1);
    let again = b.run("route robot_1@site-a none").await.unwrap();
    assert!(again.contains("routed to none"), "{again}");
    for s in [a, b, c, unsigned] {
        s.stop().await;
    }
}

/// The bound the tests assert on "shows lost within 1 s": generous, for a
/// loaded 2-core machine; the measured time is printed.
const LOST_BOUND: Duration = Duration::from_secs(5);

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_station_or_robot_that_leaves_shows_lost() {
    let (mut a, b) = two_stations(1).await;
    // robot_1 of site-a stops (its agent says goodbye, or goes silent and
    // site-a's router loses it after lost_after): site-a withdraws its
    // token and site-b shows it lost.
    let left = std::time::Instant::now();
    a.exec.shutdown().await;
    b.until("robot_1@site-a lost", WAIT, |f| {
        shown(f, "robot_1@site-a", LinkState::Lost)
    })
    .await;
    let took = left.elapsed();
    println!("robot left -> lost at the other station after {took:?}");
    assert!(took < LOST_BOUND, "{took:?}");
    assert_eq!(
        b.gcs.with_fleet(|f| f.stations["site-a"]),
        LinkState::Connected
    );

    let left = std::time::Instant::now();
    b.bridge.shutdown().await;
    a.until("site-b and its robot lost", WAIT, |f| {
        if f.stations.get("site-b") != Some(&LinkState::Lost) {
            return Err("site-b not lost".into());
        }
        shown(f, "robot_1@site-b", LinkState::Lost)
    })
    .await;
    let took = left.elapsed();
    println!("station left -> it and its robot lost at the other station after {took:?}");
    assert!(took < LOST_BOUND, "{took:?}");
    let mut b_exec = b.exec;
    b_exec.shutdown().await;
    b.gcs.shutdown().await;
    a.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_names_and_payloads_are_refused_and_counted() {
    let a = station(core(), zenoh("site-a", &[]), 1).await;
    // A robot whose name cannot be a key chunk registers at site-a.
    let sock = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let hello = mech_proto::Envelope::new(
        mech_proto::Header {
            seq: 1,
            stamp_us: mech_proto::unix_micros(),
            sender: "bad*bot".into(),
            destination: mech_proto::ROUTER.into(),
            channel: String::new(),
        },
        mech_proto::Body::Hello(mech_proto::Hello {
            name: "bad*bot".into(),
            platform: "diff-drive".into(),
            capabilities: vec![],
            motors: 2,
            max_speed: 1.0,
            max_yaw_rate: 1.0,
            agent_version: "test".into(),
        }),
    );
    let bytes = mech_proto::encode(&hello).unwrap();
    sock.send_to(&bytes, a.gcs.router().udp_addr()).unwrap();
    eventually("the bad name is refused", WAIT, || {
        let s = a.bridge.stats();
        (s.names_rejected > 0).then_some(()).ok_or(format!("{s:?}"))
    })
    .await;
    // The count comes first; the log line reaches the fleet model after
    // it, through the router's events.
    eventually("the operator is told which name and why", WAIT, || {
        a.gcs
            .with_fleet(|f| {
                f.log
                    .iter()
                    .any(|l| l.text.contains("\"bad*bot\" cannot be a Zenoh key chunk"))
            })
            .then_some(())
            .ok_or("not in the log yet".to_string())
    })
    .await;

    let tool = program(&a.endpoint).await;
    for (key, payload) in [
        ("mech/site-a/robot_1/cmd/ext/x", r#"{"twist": {"vX": 1}}"#),
        ("mech/site-a/robot_1/cmd/ext/x", "not json"),
        (
            "mech/site-a/robot_1/cmd/ext/x",
            r#"{"actuators": {"outputs": [9]}}"#,
        ),
    ] {
        tool.put(key, payload).await.unwrap();
    }
    tool.put("mech/site-a/nobody/cmd/ext/x", r#"{"stop": {}}"#)
        .await
        .unwrap();
    eventually(
        "bad commands counted, the unknown robot's dropped",
        WAIT,
        || {
            let s = a.bridge.stats();
            (s.bad_input >= 3 && s.commands_dropped >= 1)
                .then_some(())
                .ok_or(format!("{s:?}"))
        },
    )
    .await;
    assert_eq!(a.bridge.stats().commands_forwarded, 0);
    tool.close().await.unwrap();
    a.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_get_on_the_whole_station_reads_state_and_asks_for_no_route() {
    let a = station(core(), zenoh("site-a", &[]), 1).await;
    a.until("robot_1 reporting", WAIT, |f| {
        shown(f, "robot_1", LinkState::Connected)
    })
    .await;
    let tool = program(&a.endpoint).await;
    // The docs' own selector: every state of every robot of site-a. It
    // intersects the route-request queryable's key too.
    let mut keys = Vec::new();
    let mut errors = Vec::new();
    for _ in 0..3 {
        let replies = tool
            .get("mech/site-a/**")
            .timeout(Duration::from_secs(5))
            .await
            .unwrap();
        while let Ok(reply) = replies.recv_async().await {
            match reply.result() {
                Ok(sample) => keys.push(sample.key_expr().to_string()),
                Err(e) => errors.push(e.payload().try_to_string().unwrap_or_default().to_string()),
            }
        }
        if keys.iter().any(|k| k == "mech/site-a/robot_1/telemetry") {
            break;
        }
    }
    assert!(
        keys.iter().any(|k| k == "mech/site-a/robot_1/telemetry"),
        "the state is answered: {keys:?}"
    );
    assert!(errors.is_empty(), "{errors:?}");
    assert!(
        keys.iter()
            .all(|k| !k.ends_with("/route/request") && !k.contains('*')),
        "nothing answered as a route request: {keys:?}"
    );
    let stats = a.bridge.stats();
    assert_eq!(stats.route_requests_refused, 0, "{stats:?}");
    assert_eq!(stats.route_requests_done, 0, "{stats:?}");
    let logged = a
        .gcs
        .with_fleet(|f| f.log.iter().any(|l| l.text.contains("not a route request")));
    assert!(!logged, "no refusal in the event log");
    tool.close().await.unwrap();
    a.stop().await;
}
