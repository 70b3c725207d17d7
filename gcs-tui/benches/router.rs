//! Router benchmarks on loopback with real sockets (`cargo bench -p mech-gcs
//! --bench router`). Prints numbers; asserts nothing about time.
//!
//! (a) latency the router adds (controller -> router -> agent) against a
//!     direct controller -> agent baseline in the same run, p50/p99/p99.9;
//! (b) sustained forwarded messages per second with zero loss (a bounded
//!     number of messages in flight, so kernel buffers never overflow);
//! (c) switch latency: route change to the first forwarded message of the
//!     new channel;
//! (d) telemetry fan-out: 1,000 robots at 50 Hz into the router, fleet model
//!     plus one in-process subscriber, counting every drop.

#![allow(clippy::unwrap_used)]

use std::net::{SocketAddr, UdpSocket};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use mech_gcs::router::Event;
use mech_gcs::{Gcs, GcsConfig};
use mech_proto::{
    Body, Command, CommandKind, Computation, ControlMode, Envelope, FailsafeState, Header, Health,
    Hello, Pose, RouteAck, Telemetry, Twist, Velocity,
};

fn env(sender: &str, dest: &str, channel: &str, seq: u32, body: Body) -> Vec<u8> {
    let header = Header {
        seq,
        stamp_us: 0,
        sender: sender.into(),
        destination: dest.into(),
        channel: channel.into(),
    };
    mech_proto::encode(&Envelope::new(header, body)).unwrap()
}

fn command(sender: &str, robot: &str, channel: &str, seq: u32) -> Vec<u8> {
    env(
        sender,
        robot,
        channel,
        seq,
        Body::Command(Command::Twist(Twist {
            vx: 0.5,
            vy: 0.0,
            vz: 0.0,
            wz: 0.1,
        })),
    )
}

fn hello(name: &str) -> Vec<u8> {
    let h = Hello {
        name: name.into(),
        platform: "diff-drive".into(),
        capabilities: vec![CommandKind::Twist],
        motors: 2,
        max_speed: 1.0,
        max_yaw_rate: 2.0,
        agent_version: "bench".into(),
    };
    env(name, "router", "", 0, Body::Hello(h))
}

fn telemetry(name: &str, x: f64) -> Vec<u8> {
    let t = Telemetry {
        pose: Pose {
            x,
            y: 1.0,
            z: 0.0,
            heading: 0.3,
        },
        velocity: Velocity {
            vx: 0.2,
            vy: 0.0,
            vz: 0.0,
            wz: 0.0,
        },
        mode: ControlMode::Twist,
        channel: "joy/0".into(),
        computation: Computation::Onboard,
        failsafe: FailsafeState::Ok,
        health: Health::Ok,
        battery: Some(0.8),
        position_quality: 1.0,
        actuators: vec![0.1, 0.1],
        mission: None,
    };
    env(name, "router", "", 0, Body::Telemetry(t))
}

/// Receives until a Command arrives; returns its sequence number.
fn recv_command(sock: &UdpSocket, buf: &mut [u8]) -> Option<(u32, String)> {
    let deadline = Instant::now() + Duration::from_secs(2);
    while Instant::now() < deadline {
        let n = sock.recv(buf).ok()?;
        if let Ok(p) = mech_proto::peek(&buf[..n]) {
            if p.kind == 5 {
                return Some((p.seq, p.channel.to_string()));
            }
        }
    }
    None
}

/// A blocking agent: registers, acknowledges the Welcome route.
fn agent(name: &str, router: SocketAddr) -> UdpSocket {
    // Not connected: the latency baseline sends to it directly. A large
    // receive buffer, so the throughput run's window fits in it.
    let sock = socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::DGRAM, None).unwrap();
    sock.set_recv_buffer_size(4 << 20).unwrap();
    sock.bind(&SocketAddr::from(([127, 0, 0, 1], 0)).into())
        .unwrap();
    let sock: UdpSocket = sock.into();
    sock.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
    sock.send_to(&hello(name), router).unwrap();
    let mut buf = [0u8; 2048];
    loop {
        let n = sock.recv(&mut buf).unwrap();
        if let Ok(Envelope {
            body: Body::Welcome(w),
            ..
        }) = mech_proto::decode(&buf[..n])
        {
            let ack = RouteAck {
                robot: name.into(),
                channel: w.route.channel,
                epoch: w.route.epoch,
            };
            sock.send_to(&env(name, "router", "", 0, Body::RouteAck(ack)), router)
                .unwrap();
            return sock;
        }
    }
}

fn acknowledge_routes(sock: &UdpSocket, name: &str, router: SocketAddr) {
    let mut buf = [0u8; 2048];
    let _ = sock.set_read_timeout(Some(Duration::from_millis(50)));
    while let Ok(n) = sock.recv(&mut buf) {
        if let Ok(Envelope {
            body: Body::Route(r),
            ..
        }) = mech_proto::decode(&buf[..n])
        {
            let ack = RouteAck {
                robot: name.into(),
                channel: r.channel,
                epoch: r.epoch,
            };
            sock.send_to(&env(name, "router", "", 0, Body::RouteAck(ack)), router)
                .unwrap();
        }
    }
    let _ = sock.set_read_timeout(Some(Duration::from_secs(2)));
}

/// CPU time (user + system) of the calling thread, seconds, from
/// /proc/thread-self/stat (clock ticks of 10 ms: use over long runs).
fn thread_cpu() -> f64 {
    let stat = std::fs::read_to_string("/proc/thread-self/stat").unwrap_or_default();
    let fields: Vec<&str> = stat
        .rsplit(')')
        .next()
        .unwrap_or("")
        .split_whitespace()
        .collect();
    let ticks = |i: usize| {
        fields
            .get(i)
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap_or(0.0)
    };
    // After the command name: state is field 0, utime 11, stime 12.
    (ticks(11) + ticks(12)) / 100.0
}

fn percentiles(label: &str, mut v: Vec<Duration>) -> [Duration; 3] {
    v.sort();
    let at = |q: f64| v[((v.len() as f64 * q) as usize).min(v.len() - 1)];
    let p = [at(0.50), at(0.99), at(0.999)];
    println!(
        "  {label:<28} n={:<6} p50 {:>7.1} us  p99 {:>7.1} us  p99.9 {:>7.1} us",
        v.len(),
        p[0].as_secs_f64() * 1e6,
        p[1].as_secs_f64() * 1e6,
        p[2].as_secs_f64() * 1e6
    );
    p
}

fn config() -> GcsConfig {
    let mut c = GcsConfig::default();
    c.router.udp = "127.0.0.1:0".parse().unwrap();
    c.router.tcp = None;
    c.log.dir = None;
    c.router.subscriber_queue = 65_536;
    if let Some(n) = std::env::var("MECH_BENCH_WORKERS")
        .ok()
        .and_then(|v| v.parse().ok())
    {
        c.router.udp_workers = n;
    }
    c
}

fn main() {
    // `cargo bench` passes `--bench`; accept and ignore arguments.
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let gcs = rt.block_on(Gcs::start(config())).unwrap();
    let router = gcs.router().clone();
    let addr = router.udp_addr();
    println!(
        "mech-gcs router benchmark, loopback UDP, router on 2 tokio worker threads, {} UDP receive tasks, {} CPUs",
        config().router.udp_workers,
        std::thread::available_parallelism().map_or(0, |n| n.get())
    );

    // (a) latency
    let robot = agent("robot_1", addr);
    rt.block_on(router.set_route("robot_1", Some("joy/0")))
        .unwrap();
    acknowledge_routes(&robot, "robot_1", addr);
    let controller = UdpSocket::bind("127.0.0.1:0").unwrap();
    let robot_addr = robot.local_addr().unwrap();
    let mut buf = vec![0u8; 65_536];
    const SAMPLES: u32 = 20_000;
    let warm = 1000;
    let (mut direct, mut routed) = (Vec::new(), Vec::new());
    for i in 0..SAMPLES + warm {
        let msg = command("pad", "robot_1", "joy/0", i);
        let t = Instant::now();
        controller.send_to(&msg, robot_addr).unwrap();
        recv_command(&robot, &mut buf).unwrap();
        let d = t.elapsed();
        let t = Instant::now();
        controller.send_to(&msg, addr).unwrap();
        let (seq, _) = recv_command(&robot, &mut buf).unwrap();
        let r = t.elapsed();
        assert_eq!(seq, i);
        if i >= warm {
            direct.push(d);
            routed.push(r);
        }
    }
    println!("(a) one-way latency, controller -> agent:");
    let d = percentiles("direct (baseline)", direct);
    let r = percentiles("through the router", routed);
    println!(
        "  router adds                  p50 {:>7.1} us  p99 {:>7.1} us  p99.9 {:>7.1} us  (target p99 <= 200 us)",
        (r[0].as_secs_f64() - d[0].as_secs_f64()) * 1e6,
        (r[1].as_secs_f64() - d[1].as_secs_f64()) * 1e6,
        (r[2].as_secs_f64() - d[2].as_secs_f64()) * 1e6
    );

    // (b) throughput with a bounded window
    let received = Arc::new(AtomicU64::new(0));
    let stop = Arc::new(AtomicBool::new(false));
    let rx = {
        let robot = robot.try_clone().unwrap();
        let (received, stop) = (received.clone(), stop.clone());
        std::thread::spawn(move || {
            robot
                .set_read_timeout(Some(Duration::from_millis(200)))
                .unwrap();
            let mut buf = vec![0u8; 2048];
            while !stop.load(Ordering::Relaxed) {
                if let Ok(n) = robot.recv(&mut buf) {
                    if buf[..n].get(2) == Some(&5) {
                        received.fetch_add(1, Ordering::Relaxed);
                    }
                }
            }
        })
    };
    let msg = command("pad", "robot_1", "joy/0", 1);
    const WINDOW: u64 = 1024;
    let run = Duration::from_secs(3);
    let before = router.counters();
    let t = Instant::now();
    let mut sent = 0u64;
    while t.elapsed() < run {
        if sent - received.load(Ordering::Relaxed) < WINDOW {
            controller.send_to(&msg, addr).unwrap();
            sent += 1;
        } else {
            std::thread::yield_now();
        }
    }
    let drain = Instant::now();
    while received.load(Ordering::Relaxed) < sent && drain.elapsed() < Duration::from_secs(1) {
        std::thread::sleep(Duration::from_millis(1));
    }
    let elapsed = t.elapsed().as_secs_f64();
    stop.store(true, Ordering::Relaxed);
    rx.join().unwrap();
    let got = received.load(Ordering::Relaxed);
    let after = router.counters();
    println!("(b) sustained forwarding, {WINDOW} messages in flight:");
    println!(
        "  {:.0} msg/s forwarded ({} sent, {} received, {} lost; router forwarded {})  (target >= 300k msg/s)",
        got as f64 / elapsed,
        sent,
        got,
        sent - got,
        after.forwarded - before.forwarded
    );

    // (b') the router's own cost per command: an in-process publisher
    // (same decision code and the same socket send as UDP input) with no
    // receive syscall, single task.
    {
        let mut publisher = router.publisher("bench", "joy/0");
        const N: u32 = 200_000;
        let cpu0 = thread_cpu();
        let t = Instant::now();
        let forwarded = rt.block_on(async {
            let mut ok = 0u32;
            for _ in 0..N {
                let cmd = Command::Twist(Twist {
                    vx: 0.5,
                    vy: 0.0,
                    vz: 0.0,
                    wz: 0.1,
                });
                if publisher.send("robot_1", cmd).await.unwrap()
                    == mech_gcs::router::Delivery::Forwarded(1)
                {
                    ok += 1;
                }
            }
            ok
        });
        let per = t.elapsed().as_secs_f64() / f64::from(N);
        let cpu = (thread_cpu() - cpu0) / f64::from(N);
        println!(
            "  in-process publisher: {:.0} commands/s wall ({:.2} us each), {:.2} us CPU each = {:.0} commands/s per core; {forwarded} forwarded (includes encoding each command)",
            1.0 / per,
            per * 1e6,
            cpu * 1e6,
            1.0 / cpu
        );
        let mut b = vec![0u8; 2048];
        let _ = robot.set_read_timeout(Some(Duration::from_millis(100)));
        while robot.recv(&mut b).is_ok() {}
    }

    // (c) switch latency
    robot
        .set_read_timeout(Some(Duration::from_secs(2)))
        .unwrap();
    let mut switch = Vec::new();
    let mut late_old = 0;
    // Sequence numbers of this phase start high, so stragglers of earlier
    // phases are told apart from this phase's old-channel messages.
    const BASE: u32 = 1 << 30;
    for i in 0..2000u32 {
        let (new, old) = if i % 2 == 0 {
            ("joy/1", "joy/0")
        } else {
            ("joy/0", "joy/1")
        };
        let t = Instant::now();
        rt.block_on(router.set_route("robot_1", Some(new))).unwrap();
        controller
            .send_to(&command("pad", "robot_1", old, BASE + i), addr)
            .unwrap();
        controller
            .send_to(&command("pad", "robot_1", new, BASE + i), addr)
            .unwrap();
        loop {
            let (seq, ch) = recv_command(&robot, &mut buf).unwrap();
            if ch == new && seq == BASE + i {
                break;
            }
            if seq >= BASE && ch == old {
                late_old += 1;
            }
        }
        switch.push(t.elapsed());
    }
    println!("(c) switch: route change -> first forwarded message of the new channel:");
    percentiles("switch latency", switch);
    println!("  old-channel messages forwarded after a switch: {late_old} (must be 0)");

    // (d) telemetry fan-out
    const ROBOTS: usize = 1000;
    const RATE_HZ: u64 = 50;
    let mut sub = router.subscribe(65_536, true);
    let counted = Arc::new(AtomicU64::new(0));
    let reader = {
        let counted = counted.clone();
        rt.spawn(async move {
            while let Some(ev) = sub.recv().await {
                if matches!(ev.event, Event::Telemetry { .. }) {
                    counted.fetch_add(1, Ordering::Relaxed);
                }
            }
            sub.dropped()
        })
    };
    const THREADS: usize = 4;
    let robots: Vec<(String, UdpSocket)> = (0..ROBOTS)
        .map(|i| {
            let name = format!("sim_{i}");
            let s = UdpSocket::bind("127.0.0.1:0").unwrap();
            s.connect(addr).unwrap();
            s.send(&hello(&name)).unwrap();
            if i % 100 == 99 {
                std::thread::sleep(Duration::from_millis(5));
            }
            (name, s)
        })
        .collect();
    std::thread::sleep(Duration::from_millis(300));
    let registered = gcs.with_fleet(|f| f.robots.len());
    let before = router.counters();
    let run = Duration::from_secs(5);
    let sent = Arc::new(AtomicU64::new(0));
    let mut groups: Vec<Vec<(String, UdpSocket)>> = (0..THREADS).map(|_| Vec::new()).collect();
    for (i, r) in robots.into_iter().enumerate() {
        groups[i % THREADS].push(r);
    }
    let start = Instant::now();
    let handles: Vec<_> = groups
        .into_iter()
        .enumerate()
        .map(|(g, group)| {
            let sent = sent.clone();
            std::thread::spawn(move || {
                let msgs: Vec<Vec<u8>> = group.iter().map(|(n, _)| telemetry(n, 1.0)).collect();
                let period = Duration::from_nanos(1_000_000_000 / RATE_HZ);
                // Each thread's robots send spread over the period, in slices.
                let slices = 10usize;
                let per_slice = group.len().div_ceil(slices);
                let offset = period / THREADS as u32 * g as u32 / slices as u32;
                let mut next = start + offset;
                let mut k = 0usize;
                while start.elapsed() < run {
                    let now = Instant::now();
                    if now < next {
                        std::thread::sleep(next - now);
                    }
                    let lo = (k % slices) * per_slice;
                    for i in lo..(lo + per_slice).min(group.len()) {
                        if group[i].1.send(&msgs[i]).is_ok() {
                            sent.fetch_add(1, Ordering::Relaxed);
                        }
                    }
                    k += 1;
                    next += period / slices as u32;
                }
            })
        })
        .collect();
    for h in handles {
        h.join().unwrap();
    }
    std::thread::sleep(Duration::from_millis(300));
    let elapsed = start.elapsed().as_secs_f64() - 0.3;
    let after = router.counters();
    let sent = sent.load(Ordering::Relaxed);
    let routed_in = after.received - before.received;
    let seen = counted.load(Ordering::Relaxed);
    let fleet_robots = gcs.with_fleet(|f| {
        f.robots
            .values()
            .filter(|r| r.last_telemetry.is_some())
            .count()
    });
    rt.block_on(gcs.shutdown());
    let dropped = rt.block_on(reader).unwrap();
    println!(
        "(d) telemetry fan-out, {ROBOTS} robots at {RATE_HZ} Hz for {:.1} s ({registered} registered):",
        elapsed
    );
    println!(
        "  sent {sent} ({:.0}/s), router received {routed_in} (lost in kernel {}), subscriber got {seen} (dropped {dropped}), fleet model has telemetry for {fleet_robots} robots  (target: zero drops)",
        sent as f64 / elapsed,
        sent.saturating_sub(routed_in)
    );
}
