//! Footprint of a simulated fleet in one process: spawns N agents
//! (`SimFleet`, as `mech-gcs --demo` does) against an in-process router that
//! welcomes them and counts telemetry, then prints the process's RSS and CPU.
//!
//! `cargo run --release -p mech-agent --example sim_fleet [robots] [seconds]`

use std::time::{Duration, Instant};

use mech_agent::sim::{Arena, SimFleet, SimFleetOptions};
use mech_proto::{Body, Envelope, Header, Heartbeat, Route, Welcome};
use tokio::net::UdpSocket;

fn proc_field(file: &str, key: &str) -> Option<u64> {
    let text = std::fs::read_to_string(file).ok()?;
    let line = text.lines().find(|l| l.starts_with(key))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// utime + stime of this process, in clock ticks.
fn cpu_ticks() -> u64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let after = stat.rsplit(')').next().unwrap_or("");
    let f: Vec<&str> = after.split_whitespace().collect();
    f.get(11).and_then(|u| u.parse::<u64>().ok()).unwrap_or(0)
        + f.get(12).and_then(|s| s.parse::<u64>().ok()).unwrap_or(0)
}

/// A message from the router to `robot`, encoded.
fn from_router(robot: &str, body: Body) -> Option<Vec<u8>> {
    let header = Header {
        sender: "router".into(),
        destination: robot.to_string(),
        ..Header::default()
    };
    mech_proto::encode(&Envelope::new(header, body)).ok()
}

/// The router's answer to a robot's registration: routed to none.
fn welcome(robot: &str) -> Body {
    Body::Welcome(Welcome {
        robot_id: 0,
        route: Route {
            robot: robot.to_string(),
            channel: String::new(),
            epoch: 0,
        },
        router_version: "bench".into(),
    })
}

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() -> std::io::Result<()> {
    let n: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(200);
    let secs: u64 = std::env::args()
        .nth(2)
        .and_then(|a| a.parse().ok())
        .unwrap_or(10);
    let router = UdpSocket::bind("127.0.0.1:0").await?;
    let fleet = SimFleet::spawn(
        n,
        router.local_addr()?,
        Arena::default(),
        SimFleetOptions::default(),
    )
    .await?;
    let mut addrs = std::collections::HashMap::new();
    let mut buf = vec![0u8; 65536];
    let (mut telemetry, mut welcomed) = (0u64, 0usize);
    let start = Instant::now();
    let mut measure_from = None;
    let mut next_heartbeat = Instant::now();
    while start.elapsed() < Duration::from_secs(secs + 2) {
        if let Ok(Ok((len, from))) =
            tokio::time::timeout(Duration::from_millis(20), router.recv_from(&mut buf)).await
        {
            match mech_proto::decode(&buf[..len]).map(|e| e.body) {
                Ok(Body::Hello(h)) => {
                    if let Some(bytes) = from_router(&h.name, welcome(&h.name)) {
                        router.send_to(&bytes, from).await?;
                    }
                    if addrs.insert(h.name, from).is_none() {
                        welcomed += 1;
                    }
                }
                Ok(Body::Telemetry(_)) if measure_from.is_some() => telemetry += 1,
                _ => {}
            }
        }
        if Instant::now() >= next_heartbeat {
            next_heartbeat = Instant::now() + Duration::from_millis(250);
            for (name, to) in &addrs {
                if let Some(bytes) = from_router(name, Body::Heartbeat(Heartbeat::new(0))) {
                    router.send_to(&bytes, *to).await?;
                }
            }
        }
        if measure_from.is_none() && start.elapsed() >= Duration::from_secs(2) {
            measure_from = Some((Instant::now(), cpu_ticks()));
        }
    }
    let (t0, c0) = measure_from.unwrap_or((start, 0));
    let elapsed = t0.elapsed().as_secs_f64();
    let tick_hz = 100.0; // CLK_TCK on Linux
    let cpu = (cpu_ticks() - c0) as f64 / tick_hz / elapsed * 100.0;
    println!(
        "{n} simulated agents ({welcomed} registered): RSS {} kB (peak {} kB), CPU {cpu:.1}% of one core (agents + this router), {:.0} telemetry/s",
        proc_field("/proc/self/status", "VmRSS:").unwrap_or(0),
        proc_field("/proc/self/status", "VmHWM:").unwrap_or(0),
        telemetry as f64 / elapsed
    );
    fleet.shutdown().await;
    Ok(())
}
