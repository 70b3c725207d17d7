//! Stations for the bridge's tests: a router on loopback, a simulated
//! fleet, a bridge on Zenoh endpoints of 127.0.0.1 only (no scouting), and
//! the command-language executor with route requests to other stations;
//! and a bare Zenoh session, as a program on the network would have.

#![allow(dead_code)]

use std::time::Duration;

use mech_control::lang::Executor;
use mech_core::fleet::{Fleet, Robot};
use mech_core::{CoreConfig, Gcs, LinkState};
use mech_zenoh::{Bridge, ZenohConfig};

/// A station on the network.
#[derive(Debug)]
pub struct Station {
    pub gcs: Gcs,
    pub bridge: Bridge,
    pub exec: Executor,
    /// Where its bridge listens.
    pub endpoint: String,
}

/// A Zenoh endpoint on loopback with a port nobody holds now.
pub fn free_endpoint() -> String {
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    format!("tcp/127.0.0.1:{}", l.local_addr().unwrap().port())
}

/// A router on loopback ephemeral ports.
pub fn core() -> CoreConfig {
    let mut c = CoreConfig::default();
    c.router.udp = "127.0.0.1:0".parse().unwrap();
    c.router.tcp = None;
    c
}

/// The bridge's settings for a test station: listens on a free loopback
/// port, connects to `connect`.
pub fn zenoh(station: &str, connect: &[String]) -> ZenohConfig {
    ZenohConfig {
        station: station.into(),
        listen: vec![free_endpoint()],
        connect: connect.to_vec(),
        route_requests: mech_zenoh::RouteRequests::Unsigned,
        ..ZenohConfig::default()
    }
}

/// Starts a station with `robots` simulated agents (`robot_1...`).
pub async fn station(core: CoreConfig, zenoh: ZenohConfig, robots: usize) -> Station {
    let gcs = Gcs::start(core).await.unwrap();
    let bridge = Bridge::start(&gcs, &zenoh).await.unwrap();
    let mut exec = Executor::new(gcs.clone())
        .with_spawner(mech_station::sim::simulator())
        .with_remote_routes(bridge.route_requests());
    if robots > 0 {
        exec.execute_line(&format!("spawn {robots}")).await.unwrap();
    }
    Station {
        gcs,
        bridge,
        exec,
        endpoint: zenoh.listen[0].clone(),
    }
}

impl Station {
    pub async fn stop(mut self) {
        self.exec.shutdown().await;
        self.bridge.shutdown().await;
        self.gcs.shutdown().await;
    }

    pub fn robot(&self, name: &str) -> Option<Robot> {
        self.gcs.with_fleet(|f| f.robot(name).cloned())
    }

    /// Waits until `check` holds for the fleet model, failing the test
    /// with `what` and the last reason after `timeout`.
    pub async fn until(
        &self,
        what: &str,
        timeout: Duration,
        check: impl Fn(&Fleet) -> Result<(), String>,
    ) -> Duration {
        eventually(what, timeout, || self.gcs.with_fleet(&check)).await
    }

    pub async fn run(&mut self, line: &str) -> Result<String, String> {
        self.exec
            .execute_line(line)
            .await
            .map(|o| {
                std::iter::once(o.summary)
                    .chain(o.details)
                    .collect::<Vec<_>>()
                    .join("\n")
            })
            .map_err(|e| e.message)
    }
}

/// Polls `check` every 20 ms until it is `Ok`; returns how long that took.
pub async fn eventually(
    what: &str,
    timeout: Duration,
    mut check: impl FnMut() -> Result<(), String>,
) -> Duration {
    let start = tokio::time::Instant::now();
    loop {
        match check() {
            Ok(()) => return start.elapsed(),
            Err(why) if start.elapsed() > timeout => {
                panic!("{what}: not after {timeout:?}: {why}")
            }
            Err(_) => tokio::time::sleep(Duration::from_millis(20)).await,
        }
    }
}

/// Whether `robot` is in the fleet with link `state` (and, for a connected
/// remote robot, its registration and telemetry arrived).
pub fn shown(f: &Fleet, robot: &str, state: LinkState) -> Result<(), String> {
    let r = f.robot(robot).ok_or(format!("{robot} not in the fleet"))?;
    if r.link != state {
        return Err(format!("{robot} is {}", r.link.as_str()));
    }
    if state == LinkState::Connected
        && (r.registration.hello.platform.is_empty() || r.last_telemetry.is_none())
    {
        return Err(format!("{robot} has no registration or telemetry yet"));
    }
    Ok(())
}

/// A Zenoh session of a program that is not a station (a Python script,
/// a ROS 2 node), connected to `endpoint`.
pub async fn program(endpoint: &str) -> zenoh::Session {
    let mut c = zenoh::Config::default();
    for (k, v) in [
        ("mode", "\"peer\"".to_string()),
        ("scouting/multicast/enabled", "false".to_string()),
        ("listen/endpoints", format!("[\"{}\"]", free_endpoint())),
        ("connect/endpoints", format!("[\"{endpoint}\"]")),
    ] {
        c.insert_json5(k, &v).unwrap();
    }
    zenoh::open(c).await.unwrap()
}
