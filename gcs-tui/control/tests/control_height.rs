//! A flying robot's height through the command language and the real
//! router: a simulated quadcopter hovering at 3.05 m is sent `waypoint
//! quad_1 2.0,3.0 1.0,3.0` (points written without z) and flies them at
//! its height, never down towards z = 0 (for an autopilot, its origin:
//! usually the ground); a point that gives z flies to it.

#![allow(clippy::unwrap_used)]

use std::time::Duration;

use mech_agent::AgentSettings;
use mech_agent::platform::PlatformSpec;
use mech_agent::runtime::{self, Io, Ticker};
use mech_agent::sim::SimAgent;
use mech_control::lang::Executor;
use mech_core::{CoreConfig, Gcs};
use mech_proto::Pose;
use tokio::net::UdpSocket;
use tokio::sync::watch;

async fn run(exec: &mut Executor, line: &str) -> String {
    match exec.execute_line(line).await {
        Ok(o) => o.summary,
        Err(e) => panic!("{line}: {e}"),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn points_without_z_keep_a_quadcopters_height_and_points_with_z_change_it() {
    let mut config = CoreConfig::default();
    config.router.udp = std::net::SocketAddr::from(([127, 0, 0, 1], 0));
    config.router.tcp = None;
    let gcs = Gcs::start(config).await.unwrap();
    let (stop, stopped) = watch::channel(false);
    hovering_quadcopter(&gcs, stopped).await;
    let mut exec = Executor::new(gcs.clone());
    run(&mut exec, "wait connected quad_1 10s").await;
    // The station knows its height before the points are set.
    let deadline = tokio::time::Instant::now() + Duration::from_secs(10);
    while gcs.with_fleet(|f| f.robot("quad_1").unwrap().telemetry.pose.z) < 3.0 {
        assert!(tokio::time::Instant::now() < deadline, "no height heard");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }

    let set = run(&mut exec, "waypoint quad_1 2.0,3.0 1.0,3.0").await;
    assert!(
        set.contains("points without z keep the height of now (quad_1 3.05 m"),
        "{set}"
    );
    let draft = gcs.with_fleet(|f| f.robot("quad_1").unwrap().waypoints.draft.clone());
    assert!(draft.iter().all(|w| (w.z - 3.05).abs() < 0.01), "{draft:?}");
    run(&mut exec, "send quad_1").await;
    run(&mut exec, "route quad_1 wp/gcs").await;
    let lowest = lowest_height_until_the_mission_ends(&gcs).await;
    let end = gcs.with_fleet(|f| f.robot("quad_1").unwrap().telemetry.pose);
    println!("flew the z-less points at {lowest:.3} m at the lowest, ended at {end:?}");
    assert!(lowest > 2.95, "it came down to {lowest:.3} m");
    assert!((end.x - 1.0).hypot(end.y - 3.0) < 0.2, "{end:?}");

    // A point with z flies to that height.
    run(&mut exec, "waypoint quad_1 1.0,2.5,1.5").await;
    run(&mut exec, "send quad_1").await;
    let deadline = tokio::time::Instant::now() + Duration::from_secs(60);
    while (gcs.with_fleet(|f| f.robot("quad_1").unwrap().telemetry.pose.z) - 1.5).abs() > 0.15 {
        assert!(
            tokio::time::Instant::now() < deadline,
            "never went down to 1.5 m"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let _ = stop.send(true);
    gcs.shutdown().await;
}

/// A simulated quadcopter `quad_1` hovering at (1, 1, 3.05), flying until
/// `stopped` turns true.
async fn hovering_quadcopter(gcs: &Gcs, stopped: watch::Receiver<bool>) {
    let hovering = Pose {
        x: 1.0,
        y: 1.0,
        z: 3.05,
        heading: 0.0,
    };
    let sim = SimAgent::new(
        AgentSettings::new("quad_1"),
        &PlatformSpec::quadcopter(),
        hovering,
        None,
        mech_proto::unix_micros(),
    );
    let io = Io::Udp {
        socket: UdpSocket::bind("127.0.0.1:0").await.unwrap(),
        router: gcs.router().udp_addr(),
    };
    let origin = tokio::time::Instant::now();
    tokio::spawn(runtime::drive(
        sim,
        io,
        Ticker::Own(Duration::from_millis(50)),
        origin,
        stopped,
    ));
}

/// quad_1's lowest height until its mission ends.
async fn lowest_height_until_the_mission_ends(gcs: &Gcs) -> f64 {
    let mut lowest = f64::INFINITY;
    let deadline = tokio::time::Instant::now() + Duration::from_secs(60);
    loop {
        let (z, done) = gcs.with_fleet(|f| {
            let r = f.robot("quad_1").unwrap();
            (
                r.telemetry.pose.z,
                r.telemetry.mission.is_some_and(|m| m.next == m.total),
            )
        });
        lowest = lowest.min(z);
        if done {
            break;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "the mission never ended"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    lowest
}
