//! Live onboard <-> offboard switching through the real router, seen from a
//! robot: a bare UDP agent registers, holds a mission, and records what
//! reaches it. Measures the time from the `nav robot_1 offboard` request to
//! the first offboard command arriving at the robot, and checks that the
//! handover keeps the mission's progress in both directions.

#![allow(clippy::unwrap_used)]

use std::net::SocketAddr;
use std::time::Duration;

use mech_control::lang::Executor;
use mech_core::{CoreConfig, Gcs};
use mech_proto::{
    Body, CommandKind, Computation, ControlMode, Envelope, FailsafeState, Header, Health, Hello,
    MissionAck, MissionProgress, Pose, RouteAck, Telemetry, Velocity,
};
use tokio::net::UdpSocket;
use tokio::sync::mpsc;
use tokio::time::Instant;

fn envelope(body: Body, seq: u32) -> Envelope {
    Envelope::new(
        Header {
            seq,
            stamp_us: 0,
            sender: "robot_1".into(),
            destination: mech_proto::ROUTER.into(),
            channel: String::new(),
        },
        body,
    )
}

/// A minimal robot: registers, acknowledges routes and missions, reports
/// telemetry at 20 Hz with the progress of the mission it holds (standing
/// still, `next` = the mission's start index, or 2 for the first mission),
/// and forwards everything it receives, time-stamped, to the test.
async fn bare_agent(router: SocketAddr, seen: mpsc::UnboundedSender<(Instant, Envelope)>) {
    let socket = UdpSocket::bind("127.0.0.1:0").await.unwrap();
    let mut seq = 0u32;
    let mut send = |body: Body| {
        seq += 1;
        mech_proto::encode(&envelope(body, seq)).unwrap()
    };
    let hello = Hello {
        name: "robot_1".into(),
        platform: "kiwi".into(),
        capabilities: vec![
            CommandKind::Twist,
            CommandKind::Waypoints,
            CommandKind::Stop,
        ],
        motors: 3,
        max_speed: 0.5,
        max_yaw_rate: 2.0,
        agent_version: "bare".into(),
    };
    socket
        .send_to(&send(Body::Hello(hello)), router)
        .await
        .unwrap();
    let mut channel = String::new();
    let mut mission: Option<MissionProgress> = None;
    let mut telemetry = tokio::time::interval(Duration::from_millis(50));
    let mut buf = vec![0u8; 65536];
    loop {
        tokio::select! {
            _ = telemetry.tick() => {
                let t = Telemetry {
                    pose: Pose::default(),
                    velocity: Velocity::default(),
                    mode: ControlMode::Idle,
                    channel: channel.clone(),
                    computation: if channel.starts_with("offboard/") { Computation::Offboard } else { Computation::Onboard },
                    failsafe: FailsafeState::Ok,
                    health: Health::Ok,
                    battery: None,
                    position_quality: 1.0,
                    actuators: vec![0.0; 3],
                    mission: mission.filter(|_| channel == "wp/gcs"),
                    stale: 0,
                    velocity_source: mech_proto::VelocitySource::Commanded,
                    safety: None,
                };
                let _ = socket.send_to(&send(Body::Telemetry(t)), router).await;
            }
            r = socket.recv_from(&mut buf) => {
                let Ok((n, _)) = r else { return };
                let at = Instant::now();
                let Ok(env) = mech_proto::decode(&buf[..n]) else { continue };
                let reply = match &env.body {
                    Body::Welcome(w) => {
                        channel = w.route.channel.clone();
                        Some(Body::RouteAck(RouteAck { robot: "robot_1".into(), channel: channel.clone(), epoch: w.route.epoch }))
                    }
                    Body::Route(r) => {
                        channel = r.channel.clone();
                        Some(Body::RouteAck(RouteAck { robot: "robot_1".into(), channel: channel.clone(), epoch: r.epoch }))
                    }
                    Body::Mission(m) => {
                        let next = if mission.is_none() { 2 } else { m.start_index };
                        mission = Some(MissionProgress { id: m.id, next, total: m.waypoints.len() as u32 });
                        Some(Body::MissionAck(MissionAck { id: m.id, accepted: true, reason: String::new() }))
                    }
                    _ => None,
                };
                if let Some(body) = reply {
                    let _ = socket.send_to(&send(body), router).await;
                }
                if seen.send((at, env)).is_err() {
                    return;
                }
            }
        }
    }
}

async fn next_matching(
    rx: &mut mpsc::UnboundedReceiver<(Instant, Envelope)>,
    what: &str,
    pred: impl Fn(&Envelope) -> bool,
) -> (Instant, Envelope) {
    tokio::time::timeout(Duration::from_secs(5), async {
        loop {
            let (at, env) = rx.recv().await.expect("agent running");
            if pred(&env) {
                return (at, env);
            }
        }
    })
    .await
    .unwrap_or_else(|_| panic!("no {what} reached the robot"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn nav_switch_keeps_progress_and_reaches_the_robot_in_one_hop() {
    let mut config = CoreConfig::default();
    config.router.udp = "127.0.0.1:0".parse().unwrap();
    config.router.tcp = None;
    let gcs = Gcs::start(config).await.unwrap();
    let mut exec = Executor::new(gcs.clone());
    let (tx, mut rx) = mpsc::unbounded_channel();
    let agent = tokio::spawn(bare_agent(gcs.router().udp_addr(), tx));

    exec.execute_line("wait connected robot_1 5s")
        .await
        .unwrap();
    exec.execute_line("waypoint robot_1 1,0 2,0 3,0 4,0 5,0")
        .await
        .unwrap();
    exec.execute_line("send robot_1").await.unwrap();
    exec.execute_line("route robot_1 wp/gcs").await.unwrap();
    exec.execute_line("wait route robot_1 wp/gcs 5s")
        .await
        .unwrap();
    // Wait until the progress (next = 2) has reached the fleet model.
    let deadline = Instant::now() + Duration::from_secs(10);
    while gcs
        .snapshot()
        .robot("robot_1")
        .and_then(|r| r.telemetry.mission)
        .is_none_or(|m| m.next != 2)
    {
        assert!(
            Instant::now() < deadline,
            "the agent's progress never arrived"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    while rx.try_recv().is_ok() {}

    let mut latencies = Vec::new();
    let mut router_latencies = Vec::new();
    for round in 0..20 {
        let (to_robot, at_router) = offboard_and_back(&mut exec, &mut rx, round).await;
        latencies.push(to_robot);
        router_latencies.push(at_router);
    }
    latencies.sort();
    router_latencies.sort();
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    println!(
        "nav offboard switch, request -> first offboard command at the robot over {} runs: \
         median {:.3} ms, max {:.3} ms (request -> forwarded by the router: median {:.3} ms)",
        latencies.len(),
        ms(latencies[latencies.len() / 2]),
        ms(latencies[latencies.len() - 1]),
        ms(router_latencies[router_latencies.len() / 2]),
    );
    agent.abort();
    gcs.shutdown().await;
}

/// One round of the switch: offboard (the route reaches the robot before
/// the first command, which resumes from the reported progress), then back
/// onboard (the mission is stored before the route back). Returns how long
/// the offboard switch took to the robot's first offboard command, and to
/// the router forwarding it.
async fn offboard_and_back(
    exec: &mut Executor,
    rx: &mut mpsc::UnboundedReceiver<(Instant, Envelope)>,
    round: usize,
) -> (Duration, Duration) {
    let requested = Instant::now();
    let out = exec.execute_line("nav robot_1 offboard").await.unwrap();
    let (route_at, _) = next_matching(
        rx,
        "route to offboard/robot_1",
        |e| matches!(&e.body, Body::Route(r) if r.channel == "offboard/robot_1"),
    )
    .await;
    let (cmd_at, _) = next_matching(rx, "offboard command", |e| {
        matches!(e.body, Body::Command(_)) && e.header.channel == "offboard/robot_1"
    })
    .await;
    assert!(
        route_at <= cmd_at,
        "the route change reaches the robot before the first command"
    );
    assert!(
        out.summary.contains("from waypoint 2 of 5"),
        "round {round}: {}",
        out.summary
    );
    let to_robot = cmd_at.duration_since(requested);
    let view = exec.control().nav_view("robot_1").unwrap();
    let at_router = view.switch_latency.unwrap();

    let back = exec.execute_line("nav robot_1 onboard").await.unwrap();
    assert!(
        back.summary.contains("resumes at waypoint 2 of 5"),
        "{}",
        back.summary
    );
    let (mission_at, mission) =
        next_matching(rx, "mission", |e| matches!(e.body, Body::Mission(_))).await;
    let Body::Mission(m) = mission.body else {
        unreachable!()
    };
    assert_eq!(m.start_index, 2, "handed back at the same next waypoint");
    let (route_back_at, _) = next_matching(
        rx,
        "route to wp/gcs",
        |e| matches!(&e.body, Body::Route(r) if r.channel == "wp/gcs"),
    )
    .await;
    assert!(
        mission_at < route_back_at,
        "the mission is stored before the robot is routed to run it"
    );
    assert!(
        exec.control().nav_view("robot_1").is_none(),
        "the GCS loop stopped"
    );
    // Telemetry with the new mission's progress before the next round.
    tokio::time::sleep(Duration::from_millis(120)).await;
    while rx.try_recv().is_ok() {}
    (to_robot, at_router)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn offboard_resumes_from_progress_reported_before_the_robot_was_routed_elsewhere() {
    let mut config = CoreConfig::default();
    config.router.udp = "127.0.0.1:0".parse().unwrap();
    config.router.tcp = None;
    let gcs = Gcs::start(config).await.unwrap();
    let mut exec = Executor::new(gcs.clone());
    let (tx, mut rx) = mpsc::unbounded_channel();
    let agent = tokio::spawn(bare_agent(gcs.router().udp_addr(), tx));
    exec.execute_line("wait connected robot_1 5s")
        .await
        .unwrap();
    exec.execute_line("waypoint robot_1 1,0 2,0 3,0")
        .await
        .unwrap();
    exec.execute_line("send robot_1").await.unwrap();
    exec.execute_line("route robot_1 wp/gcs").await.unwrap();
    // The progress (next = 2) is reported before the robot moves to a
    // gamepad channel, where it reports no mission progress.
    tokio::time::sleep(Duration::from_millis(300)).await;
    exec.execute_line("route robot_1 joy/0").await.unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert_eq!(
        gcs.with_fleet(|f| f.robot("robot_1").unwrap().telemetry.mission),
        None
    );

    let text = exec.control().toggle_nav("robot_1").await.unwrap();
    assert_eq!(text, "robot_1 offboard from waypoint 2 of 3");
    next_matching(&mut rx, "offboard command", |e| {
        e.header.channel == "offboard/robot_1"
    })
    .await;
    let text = exec.control().toggle_nav("robot_1").await.unwrap();
    assert_eq!(text, "robot_1 onboard from waypoint 2 of 3");
    agent.abort();
    gcs.shutdown().await;
}
