//! Telemetry from one station to another through Zenoh, measured: 100
//! robots at 20 Hz register with station A over UDP; A's bridge publishes
//! their telemetry, B's bridge puts it into B's fleet model. Prints the
//! latency (A's router received it -> it is in B's model: p50, p95, p99,
//! max), how much arrived, and the CPU the two bridges used (their own
//! runtime and Zenoh's threads), against the same load without bridges.
//!
//! `cargo bench -p mech-zenoh --bench telemetry` (release build). Both
//! stations, the robots and the bridges share this machine's cores.

use std::net::{SocketAddr, UdpSocket};
use std::time::{Duration, Instant};

use mech_core::{CoreConfig, Gcs, LinkState};
use mech_proto::{
    Body, Computation, ControlMode, Envelope, FailsafeState, Header, Health, Hello, Pose,
    Telemetry, Velocity,
};
use mech_zenoh::{Bridge, ZenohConfig};

const ROBOTS: usize = 100;
const RATE_HZ: u32 = 20;
const RUN: Duration = Duration::from_secs(10);

fn message(sender: &str, seq: u32, body: Body) -> Vec<u8> {
    let header = Header {
        seq,
        stamp_us: mech_proto::unix_micros(),
        sender: sender.into(),
        destination: mech_proto::ROUTER.into(),
        channel: String::new(),
    };
    mech_proto::encode(&Envelope::new(header, body)).unwrap()
}

fn telemetry(x: f64) -> Body {
    Body::Telemetry(Telemetry {
        pose: Pose {
            x,
            y: 1.0,
            z: 0.0,
            heading: 0.5,
        },
        velocity: Velocity::default(),
        velocity_source: Default::default(),
        safety: None,
        mode: ControlMode::Twist,
        channel: "joy/0".into(),
        computation: Computation::Onboard,
        failsafe: FailsafeState::Ok,
        health: Health::Ok,
        battery: Some(0.8),
        position_quality: 1.0,
        actuators: vec![0.1, 0.1],
        mission: None,
        stale: 0,
    })
}

/// The robots: each registers, then sends telemetry at `RATE_HZ` for
/// `run`, spread evenly over each period, from one thread.
fn robots(router: SocketAddr, run: Duration) -> std::thread::JoinHandle<u64> {
    std::thread::Builder::new()
        .name("robots".into())
        .spawn(move || {
            let socks: Vec<(String, UdpSocket)> = (0..ROBOTS)
                .map(|i| {
                    let s = UdpSocket::bind("127.0.0.1:0").unwrap();
                    s.connect(router).unwrap();
                    (format!("bot_{i}"), s)
                })
                .collect();
            for (name, s) in &socks {
                let hello = Body::Hello(Hello {
                    name: name.clone(),
                    platform: "diff-drive".into(),
                    capabilities: vec![],
                    motors: 2,
                    max_speed: 1.0,
                    max_yaw_rate: 1.0,
                    agent_version: "bench".into(),
                });
                s.send(&message(name, 0, hello)).unwrap();
            }
            let gap = Duration::from_secs(1) / RATE_HZ / ROBOTS as u32;
            let (start, mut sent, mut next) = (Instant::now(), 0u64, Instant::now());
            while start.elapsed() < run {
                let (name, s) = &socks[sent as usize % ROBOTS];
                let x = start.elapsed().as_secs_f64();
                if s.send(&message(name, sent as u32 + 1, telemetry(x)))
                    .is_ok()
                {
                    sent += 1;
                }
                next += gap;
                if let Some(wait) = next.checked_duration_since(Instant::now()) {
                    std::thread::sleep(wait);
                }
            }
            sent
        })
        .unwrap()
}

/// CPU seconds of this process's threads whose names `pick` accepts.
fn cpu(pick: impl Fn(&str) -> bool) -> f64 {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return 0.0;
    };
    tasks
        .flatten()
        .filter(|t| {
            std::fs::read_to_string(t.path().join("comm")).is_ok_and(|c| pick(c.trim_end()))
        })
        .map(|t| {
            let stat = std::fs::read_to_string(t.path().join("stat")).unwrap_or_default();
            let f: Vec<f64> = stat
                .rsplit(')')
                .next()
                .unwrap_or("")
                .split_whitespace()
                .map(|v| v.parse().unwrap_or(0.0))
                .collect();
            // After the name: utime is field 11, stime 12, in 10 ms ticks.
            (f.get(11).unwrap_or(&0.0) + f.get(12).unwrap_or(&0.0)) / 100.0
        })
        .sum()
}

/// The bridges' threads: their runtime and Zenoh's (app, acc, tx, rx, net).
fn bridge_thread(name: &str) -> bool {
    name.starts_with("mech-bridge")
        || ["app-", "acc-", "tx-", "rx-", "net-"]
            .iter()
            .any(|p| name.starts_with(p))
}

fn station_thread(name: &str) -> bool {
    name.starts_with("mech-station") || name.starts_with("mech-udp-")
}

fn core() -> CoreConfig {
    let mut c = CoreConfig::default();
    c.router.udp = "127.0.0.1:0".parse().unwrap();
    c.router.tcp = None;
    c
}

fn endpoint() -> String {
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    format!("tcp/127.0.0.1:{}", l.local_addr().unwrap().port())
}

fn runtime(name: &'static str) -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .thread_name(name)
        .enable_all()
        .build()
        .unwrap()
}

/// Robots at A without any bridge: what the station costs alone.
fn baseline(stations: &tokio::runtime::Runtime) -> f64 {
    let a = stations.block_on(Gcs::start(core())).unwrap();
    robots(a.router().udp_addr(), Duration::from_secs(1))
        .join()
        .unwrap();
    let before = cpu(station_thread);
    let sent = robots(a.router().udp_addr(), RUN).join().unwrap();
    let used = cpu(station_thread) - before;
    stations.block_on(a.shutdown());
    println!(
        "without bridges: {sent} telemetry in {:.0} s; station threads {:.1} % of a core",
        RUN.as_secs_f64(),
        used / RUN.as_secs_f64() * 100.0
    );
    used
}

/// Two stations, A with the robots' router, B connected to A, each with
/// a bridge started on the bridges' runtime.
fn bridged(
    stations: &tokio::runtime::Runtime,
    bridges: &tokio::runtime::Runtime,
) -> (Gcs, Gcs, Bridge, Bridge) {
    let (a, b) = stations.block_on(async { (Gcs::start(core()).await, Gcs::start(core()).await) });
    let (a, b) = (a.unwrap(), b.unwrap());
    let (ea, eb) = (endpoint(), endpoint());
    let za = ZenohConfig {
        station: "site-a".into(),
        listen: vec![ea.clone()],
        ..ZenohConfig::default()
    };
    let zb = ZenohConfig {
        station: "site-b".into(),
        listen: vec![eb],
        connect: vec![ea],
        ..ZenohConfig::default()
    };
    let (ba, bb) = bridges.block_on(async {
        let ba = Bridge::start(&a, &za).await.unwrap();
        (ba, Bridge::start(&b, &zb).await.unwrap())
    });
    (a, b, ba, bb)
}

fn main() {
    if std::env::args().any(|a| a == "--list") {
        return;
    }
    let stations = runtime("mech-station");
    let bridges = runtime("mech-bridge");
    let alone = baseline(&stations);
    let (a, b, ba, bb) = bridged(&stations, &bridges);
    // Warm up: every robot registered at A and shown connected at B.
    robots(a.router().udp_addr(), Duration::from_secs(2))
        .join()
        .unwrap();
    let shown = b.with_fleet(|f| {
        f.robots_of("site-a")
            .filter(|r| r.link == LinkState::Connected && r.last_telemetry.is_some())
            .count()
    });
    bb.clear_ages();
    let heard_before = bb.stats().remote_telemetry;
    let out_before = ba.stats();
    let (bridge_cpu, station_cpu) = (cpu(bridge_thread), cpu(station_thread));
    let sent = robots(a.router().udp_addr(), RUN).join().unwrap();
    std::thread::sleep(Duration::from_millis(300));
    let bridge_used = cpu(bridge_thread) - bridge_cpu;
    let station_used = cpu(station_thread) - station_cpu;
    let s = bb.stats();
    let heard = s.remote_telemetry - heard_before;
    let secs = RUN.as_secs_f64();
    println!(
        "{ROBOTS} robots x {RATE_HZ} Hz for {secs:.0} s ({shown} shown at B before the run): \
         sent {sent}, B received {heard} ({:.2} % lost)",
        100.0 * (sent.saturating_sub(heard)) as f64 / sent as f64
    );
    // Where samples went missing: A's bridge missing router events, A's
    // bridge not publishing, or Zenoh dropping them between the bridges
    // (telemetry is published with congestion control Drop: newest wins).
    let out = ba.stats();
    println!(
        "  A's bridge: published {} (telemetry and state), publish failed {}, router events missed {}; \
         B's bridge: bad input {}",
        out.published - out_before.published,
        out.publish_failed - out_before.publish_failed,
        out.events_missed - out_before.events_missed,
        s.bad_input
    );
    if let Some([p50, p95, p99, max]) = s.remote_age_us {
        println!(
            "latency A's router -> B's fleet model: p50 {p50} us, p95 {p95} us, p99 {p99} us, max {max} us"
        );
    }
    println!(
        "CPU: both bridges {:.1} % of a core ({:.1} us per sample, published at A and received \
         at B); both stations {:.1} % (alone, without bridges: {:.1} %)",
        bridge_used / secs * 100.0,
        bridge_used / heard.max(1) as f64 * 1e6,
        station_used / secs * 100.0,
        alone / secs * 100.0
    );
    bridges.block_on(async {
        ba.shutdown().await;
        bb.shutdown().await;
    });
    stations.block_on(async {
        a.shutdown().await;
        b.shutdown().await;
    });
}
