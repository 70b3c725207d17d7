//! Router benchmarks on loopback with real sockets (`cargo bench -p mech-core
//! --bench router`). Prints numbers; asserts nothing about time.
//!
//! (a) latency the router adds (controller -> router -> agent) against a
//!     direct controller -> agent baseline and a bare UDP relay (a thread
//!     in `recv_from`/`send_to`, as peerbench's `udp-relay`) in the same
//!     run, p50/p99/p99.9;
//! (b) sustained forwarded messages per second with zero loss (a bounded
//!     number of messages in flight, so kernel buffers never overflow);
//!     (a) and (b) run twice: unauthenticated, then with every message
//!     signed (the controller signs each command, the router checks it and
//!     signs it again for the robot);
//! (c) switch latency: route change to the first forwarded message of the
//!     new channel;
//! (d) telemetry fan-out: 1,000 robots at 50 Hz into the router, fleet model
//!     plus one in-process subscriber, counting every drop;
//! (r) recording: the router threads' CPU time per message with and
//!     without a recording (1,000 robots at 50 Hz; 100 at 20 Hz), the
//!     recorder thread's, and the file size per robot-hour;
//! (m) what polling costs: the router threads' CPU at 2k, 8k, 32k and 64k
//!     commands per second, paced evenly as a controller (or peerbench)
//!     sends them, with polling on (`router.udp_poll`) and off.

#![allow(clippy::unwrap_used)]

use std::net::{SocketAddr, UdpSocket};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use mech_core::Event;
use mech_core::auth::{AuthMode, KeyEntry, KeyFile, Role};
use mech_core::{CoreConfig, Gcs};
use mech_proto::auth::{Key, Stamper};
use mech_proto::{
    Body, Command, CommandKind, Computation, ControlMode, Envelope, FailsafeState, Header, Health,
    Hello, Pose, RouteAck, Telemetry, Twist, Velocity,
};

/// Signs what a bench peer sends, when the run authenticates.
struct Signer {
    key: Key,
    stamper: Stamper,
}

/// `bytes` as sent: signed with a fresh stamp by `signer`, if any.
fn sealed(signer: &mut Option<Signer>, mut bytes: Vec<u8>) -> Vec<u8> {
    if let Some(s) = signer {
        let stamp = s.stamper.next(mech_proto::unix_micros());
        s.key.seal(&mut bytes, 0, stamp).unwrap();
    }
    bytes
}

/// A controller's command stream: the same Twist, signed afresh each time
/// when the run authenticates (a replayed tag is refused).
struct Commands {
    signer: Option<Signer>,
    unsigned: Vec<u8>,
}

impl Commands {
    fn next(&mut self) -> std::borrow::Cow<'_, [u8]> {
        match self.signer {
            None => std::borrow::Cow::Borrowed(&self.unsigned),
            Some(_) => std::borrow::Cow::Owned(sealed(&mut self.signer, self.unsigned.clone())),
        }
    }
}

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
        stale: 0,
        velocity_source: mech_proto::VelocitySource::Commanded,
        safety: None,
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
fn agent(name: &str, router: SocketAddr, signer: &mut Option<Signer>) -> UdpSocket {
    // Not connected: the latency baseline sends to it directly. A large
    // receive buffer, so the throughput run's window fits in it.
    let sock = socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::DGRAM, None).unwrap();
    sock.set_recv_buffer_size(4 << 20).unwrap();
    sock.bind(&SocketAddr::from(([127, 0, 0, 1], 0)).into())
        .unwrap();
    let sock: UdpSocket = sock.into();
    sock.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
    sock.send_to(&sealed(signer, hello(name)), router).unwrap();
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
            let ack = sealed(signer, env(name, "router", "", 0, Body::RouteAck(ack)));
            sock.send_to(&ack, router).unwrap();
            return sock;
        }
    }
}

fn acknowledge_routes(
    sock: &UdpSocket,
    name: &str,
    router: SocketAddr,
    signer: &mut Option<Signer>,
) {
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
            let ack = sealed(signer, env(name, "router", "", 0, Body::RouteAck(ack)));
            sock.send_to(&ack, router).unwrap();
        }
    }
    let _ = sock.set_read_timeout(Some(Duration::from_secs(2)));
}

/// CPU time (user + system, seconds) in a `/proc/.../stat` line (clock
/// ticks of 10 ms: use over long runs).
fn stat_cpu(stat: &str) -> f64 {
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

/// CPU time of the calling thread, seconds.
fn thread_cpu() -> f64 {
    stat_cpu(&std::fs::read_to_string("/proc/thread-self/stat").unwrap_or_default())
}

/// Name of the router runtime's threads, so their CPU time can be told
/// apart from the benchmark's own senders and receivers.
const ROUTER_THREAD: &str = "mech-router";

/// CPU time of every router thread together (its tokio threads and its
/// UDP worker threads), seconds.
fn router_cpu() -> f64 {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return 0.0;
    };
    tasks
        .flatten()
        .filter(|t| {
            std::fs::read_to_string(t.path().join("comm"))
                .is_ok_and(|c| c.trim_end() == ROUTER_THREAD || c.starts_with("mech-udp-"))
        })
        .map(|t| stat_cpu(&std::fs::read_to_string(t.path().join("stat")).unwrap_or_default()))
        .sum()
}

/// Jiffies of the whole machine from /proc/stat: (stolen by the
/// hypervisor, total). A virtual machine whose host is busy loses time the
/// guest cannot see in its own clocks; printed so noisy numbers are
/// recognised as such.
fn steal_jiffies() -> (u64, u64) {
    let stat = std::fs::read_to_string("/proc/stat").unwrap_or_default();
    let cpu: Vec<u64> = stat
        .lines()
        .next()
        .unwrap_or("")
        .split_whitespace()
        .skip(1)
        .filter_map(|v| v.parse().ok())
        .collect();
    (cpu.get(7).copied().unwrap_or(0), cpu.iter().take(8).sum())
}

/// Percent of CPU time stolen by the hypervisor since `from`.
fn stolen_since(from: (u64, u64)) -> f64 {
    let now = steal_jiffies();
    let total = now.1.saturating_sub(from.1).max(1);
    now.0.saturating_sub(from.0) as f64 * 100.0 / total as f64
}

fn report_steal(from: (u64, u64)) {
    println!(
        "  CPU time stolen by the hypervisor during this phase: {:.0}%",
        stolen_since(from)
    );
}

/// Datagrams the kernel dropped at the UDP socket bound to `addr` because
/// its receive buffer was full (the `drops` column of /proc/net/udp).
fn socket_drops(addr: SocketAddr) -> u64 {
    let port = format!(":{:04X} ", addr.port());
    std::fs::read_to_string("/proc/net/udp")
        .unwrap_or_default()
        .lines()
        .filter(|l| {
            l.split_whitespace()
                .nth(1)
                .is_some_and(|a| a.ends_with(port.trim_end()))
        })
        .filter_map(|l| l.split_whitespace().last()?.parse::<u64>().ok())
        .sum()
}

/// Which phases to run: `MECH_BENCH_PHASES=ab` runs (a) and (b) only.
fn phase(p: char) -> bool {
    std::env::var("MECH_BENCH_PHASES").map_or(true, |v| v.contains(p))
}

/// Counts forwarded commands arriving at `robot` on a thread of its own.
struct CommandCounter {
    received: Arc<AtomicU64>,
    stop: Arc<AtomicBool>,
    thread: std::thread::JoinHandle<()>,
}

impl CommandCounter {
    fn start(robot: &UdpSocket) -> CommandCounter {
        let received = Arc::new(AtomicU64::new(0));
        let stop = Arc::new(AtomicBool::new(false));
        let robot = robot.try_clone().unwrap();
        let thread = {
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
        CommandCounter {
            received,
            stop,
            thread,
        }
    }

    fn get(&self) -> u64 {
        self.received.load(Ordering::Relaxed)
    }

    /// Waits until `sent` arrived or nothing more arrives for 200 ms.
    fn settle(&self, sent: u64) -> u64 {
        let mut last = (self.get(), Instant::now());
        while self.get() < sent && last.1.elapsed() < Duration::from_millis(200) {
            std::thread::sleep(Duration::from_millis(1));
            let now = self.get();
            if now != last.0 {
                last = (now, Instant::now());
            }
        }
        self.get()
    }

    fn stop(self) {
        self.stop.store(true, Ordering::Relaxed);
        self.thread.join().unwrap();
    }
}

/// Offers `rate` commands per second for `run`, in bursts every ~200 us;
/// returns (sent, received, seconds the sending took, router CPU seconds,
/// where losses happened).
#[allow(clippy::too_many_arguments)]
fn offer(
    handle: &mech_core::router::RouterHandle,
    controller: &UdpSocket,
    router: SocketAddr,
    robot: SocketAddr,
    counter: &CommandCounter,
    commands: &mut Commands,
    rate: f64,
    run: Duration,
) -> (u64, u64, f64, f64, Lost) {
    let base = counter.get();
    let drops0 = (socket_drops(router), socket_drops(robot));
    let forwarded0 = handle.counters().forwarded;
    let cpu0 = router_cpu();
    let t = Instant::now();
    let mut sent = 0u64;
    while t.elapsed() < run {
        let due = (t.elapsed().as_secs_f64() * rate) as u64;
        while sent < due {
            if controller.send_to(&commands.next(), router).is_ok() {
                sent += 1;
            }
        }
        // Sleeping, not spinning: the router needs the cores.
        std::thread::sleep(Duration::from_micros(200));
    }
    let took = t.elapsed().as_secs_f64();
    let got = counter.settle(base + sent) - base;
    let cpu = router_cpu() - cpu0;
    let lost = Lost {
        at_router: socket_drops(router) - drops0.0,
        forwarded: handle.counters().forwarded - forwarded0,
        at_robot: socket_drops(robot) - drops0.1,
    };
    (sent, got, took, cpu, lost)
}

/// Where offered commands went missing.
struct Lost {
    /// Dropped by the kernel at the router's socket (the router fell behind).
    at_router: u64,
    /// Forwarded by the router.
    forwarded: u64,
    /// Dropped by the kernel at the robot's socket (the receiver fell behind).
    at_robot: u64,
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

fn config() -> CoreConfig {
    let mut c = CoreConfig::default();
    c.router.udp = "127.0.0.1:0".parse().unwrap();
    c.router.tcp = None;
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
        .thread_name(ROUTER_THREAD)
        .enable_all()
        .build()
        .unwrap();
    println!(
        "mech-core router benchmark, loopback UDP, router with {} UDP worker threads and 2 tokio threads, {} CPUs",
        config().router.udp_workers,
        std::thread::available_parallelism().map_or(0, |n| n.get())
    );
    // `MECH_BENCH_AUTH=off` or `on` runs (a) and (b) one way only.
    let auth = std::env::var("MECH_BENCH_AUTH").unwrap_or_default();
    for authenticated in [false, true] {
        if !phase('a') && !phase('b') {
            break;
        }
        if (auth == "off" && authenticated) || (auth == "on" && !authenticated) {
            continue;
        }
        println!(
            "== {}",
            if authenticated {
                "authenticated: every message signed (HMAC-SHA-256), checked and signed again"
            } else {
                "unauthenticated"
            }
        );
        forwarding(&rt, authenticated);
    }
    let gcs = rt.block_on(Gcs::start(config())).unwrap();
    let router = gcs.router().clone();
    let addr = router.udp_addr();
    let robot = agent("robot_1", addr, &mut None);
    rt.block_on(router.set_route("robot_1", Some("joy/0")))
        .unwrap();
    acknowledge_routes(&robot, "robot_1", addr, &mut None);
    let controller = UdpSocket::bind("127.0.0.1:0").unwrap();
    let mut buf = vec![0u8; 65_536];
    if phase('p') {
        let stolen = steal_jiffies();
        in_process(&rt, &router, &robot);
        report_steal(stolen);
    }
    if phase('c') {
        let stolen = steal_jiffies();
        switching(&rt, &router, &controller, &robot, addr, &mut buf);
        report_steal(stolen);
    }
    if phase('d') {
        let stolen = steal_jiffies();
        fanout(&rt, gcs, addr);
        report_steal(stolen);
    } else {
        rt.block_on(gcs.shutdown());
    }
    if phase('r') {
        let stolen = steal_jiffies();
        recording_cost(&rt);
        report_steal(stolen);
    }
    if phase('m') {
        let stolen = steal_jiffies();
        polling_cost(&rt);
        report_steal(stolen);
    }
}

/// Sends `rate` commands per second for `run`, each at its due time
/// (start + i / rate): sleeping until shortly before it, then spinning, so
/// the stream is even, as a paced controller's is. Returns how many were
/// sent.
fn paced(
    controller: &UdpSocket,
    router: SocketAddr,
    commands: &mut Commands,
    rate: f64,
    run: Duration,
) -> u64 {
    let start = Instant::now();
    let mut sent = 0u64;
    let total = (rate * run.as_secs_f64()) as u64;
    while sent < total {
        let due = start + Duration::from_secs_f64(sent as f64 / rate);
        let now = Instant::now();
        if due > now + Duration::from_micros(100) {
            std::thread::sleep(due - now - Duration::from_micros(80));
        }
        while Instant::now() < due {
            std::hint::spin_loop();
        }
        if controller.send_to(&commands.next(), router).is_ok() {
            sent += 1;
        }
    }
    sent
}

/// (m) the router threads' CPU at medium rates, polling on and off.
fn polling_cost(rt: &tokio::runtime::Runtime) {
    println!(
        "(m) router CPU at medium rates, commands paced evenly (load average {})",
        load_average()
    );
    let budget = config().router.udp_poll;
    for poll in [budget, Duration::ZERO] {
        let mut cfg = config();
        cfg.router.udp_poll = poll;
        let gcs = rt.block_on(Gcs::start(cfg)).unwrap();
        let router = gcs.router().clone();
        let addr = router.udp_addr();
        let robot = agent("robot_1", addr, &mut None);
        rt.block_on(router.set_route("robot_1", Some("joy/0")))
            .unwrap();
        acknowledge_routes(&robot, "robot_1", addr, &mut None);
        let controller = UdpSocket::bind("127.0.0.1:0").unwrap();
        let counter = CommandCounter::start(&robot);
        let mut commands = Commands {
            signer: None,
            unsigned: command("pad", "robot_1", "joy/0", 1),
        };
        let label = if poll.is_zero() {
            "polling off".to_string()
        } else {
            format!("polling {} us", poll.as_micros())
        };
        for rate in [2e3, 8e3, 32e3, 64e3] {
            let run = Duration::from_secs(4);
            let base = counter.get();
            let cpu0 = router_cpu();
            let t = Instant::now();
            let sent = paced(&controller, addr, &mut commands, rate, run);
            let took = t.elapsed().as_secs_f64();
            let cpu = router_cpu() - cpu0;
            let got = counter.settle(base + sent) - base;
            println!(
                "  {label:<16} {:>3.0}k msg/s: router CPU {:>5.1}% of a core, {:>5.2} us/msg; {sent} sent, {} lost",
                rate / 1e3,
                cpu / took * 100.0,
                cpu / got.max(1) as f64 * 1e6,
                sent.saturating_sub(got)
            );
        }
        counter.stop();
        rt.block_on(gcs.shutdown());
    }
}

/// The machine's load average over the last minute, as /proc/loadavg says.
fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|l| l.split_whitespace().next().map(str::to_string))
        .unwrap_or_else(|| "unknown".into())
}

/// (a) and (b) on a router of their own, with or without authentication.
fn forwarding(rt: &tokio::runtime::Runtime, authenticated: bool) {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = config();
    let (mut robot_signer, controller_signer) = if authenticated {
        let mut keys = Vec::new();
        for (role, name) in [(Role::Robot, "robot_1"), (Role::Controller, "pad")] {
            let file = dir.path().join(format!("{name}.key"));
            let k = KeyFile::generate(name, &file).unwrap();
            cfg.auth.keys.push(KeyEntry {
                role,
                name: name.into(),
                file,
                channels: if role == Role::Controller {
                    vec!["*".into()]
                } else {
                    vec![]
                },
            });
            keys.push(Signer {
                key: k.key,
                stamper: Stamper::default(),
            });
        }
        cfg.auth.mode = Some(AuthMode::Required);
        let controller = keys.pop();
        (keys.pop(), controller)
    } else {
        (None, None)
    };
    let gcs = rt.block_on(Gcs::start(cfg)).unwrap();
    let router = gcs.router().clone();
    let addr = router.udp_addr();
    let robot = agent("robot_1", addr, &mut robot_signer);
    rt.block_on(router.set_route("robot_1", Some("joy/0")))
        .unwrap();
    acknowledge_routes(&robot, "robot_1", addr, &mut robot_signer);
    let controller = UdpSocket::bind("127.0.0.1:0").unwrap();
    let robot_addr = robot.local_addr().unwrap();
    let mut buf = vec![0u8; 65_536];
    let mut commands = Commands {
        signer: controller_signer,
        unsigned: command("pad", "robot_1", "joy/0", 1),
    };
    if phase('a') {
        let stolen = steal_jiffies();
        latency(
            &controller,
            &robot,
            robot_addr,
            addr,
            &mut buf,
            &mut commands.signer,
        );
        report_steal(stolen);
    }
    if phase('b') {
        let stolen = steal_jiffies();
        throughput(&router, &controller, &robot, addr, &mut commands);
        report_steal(stolen);
    }
    let rejected = router.rejections().total();
    if authenticated {
        println!("  messages the router refused: {rejected} (must be 0)");
    }
    rt.block_on(gcs.shutdown());
}

/// A bare UDP relay, as peerbench's `udp-relay` target is: a thread
/// blocking in `recv_from` and passing each datagram to `to` with
/// `send_to`, until `stop` is set (it wakes at least every 100 ms to look).
struct Relay {
    addr: SocketAddr,
    stop: Arc<AtomicBool>,
    thread: std::thread::JoinHandle<()>,
}

impl Relay {
    fn start(to: SocketAddr) -> Relay {
        let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
        sock.set_read_timeout(Some(Duration::from_millis(100)))
            .unwrap();
        let addr = sock.local_addr().unwrap();
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let thread = std::thread::spawn(move || {
            let mut buf = [0u8; 2048];
            while !flag.load(Ordering::Relaxed) {
                if let Ok((n, _)) = sock.recv_from(&mut buf) {
                    let _ = sock.send_to(&buf[..n], to);
                }
            }
        });
        Relay { addr, stop, thread }
    }

    fn stop(self) {
        self.stop.store(true, Ordering::Relaxed);
        self.thread.join().unwrap();
    }
}

/// (a) one-way latency directly, through a bare relay and through the
/// router, interleaved so the three see the same machine.
fn latency(
    controller: &UdpSocket,
    robot: &UdpSocket,
    robot_addr: SocketAddr,
    addr: SocketAddr,
    buf: &mut [u8],
    signer: &mut Option<Signer>,
) {
    const SAMPLES: u32 = 20_000;
    let warm = 1000;
    let relay = Relay::start(robot_addr);
    let (mut direct, mut relayed, mut routed) = (Vec::new(), Vec::new(), Vec::new());
    let mut one_way = |to: SocketAddr, i: u32| {
        let msg = sealed(signer, command("pad", "robot_1", "joy/0", i));
        let t = Instant::now();
        controller.send_to(&msg, to).unwrap();
        let (seq, _) = recv_command(robot, buf).unwrap();
        assert_eq!(seq, i);
        t.elapsed()
    };
    for i in 0..SAMPLES + warm {
        let d = one_way(robot_addr, i);
        let b = one_way(relay.addr, i);
        let r = one_way(addr, i);
        if i >= warm {
            direct.push(d);
            relayed.push(b);
            routed.push(r);
        }
    }
    relay.stop();
    println!("(a) one-way latency, controller -> agent:");
    let d = percentiles("direct (baseline)", direct);
    let b = percentiles("through a bare UDP relay", relayed);
    let r = percentiles("through the router", routed);
    let us = |x: Duration, y: Duration| (x.as_secs_f64() - y.as_secs_f64()) * 1e6;
    println!(
        "  router adds                  p50 {:>7.1} us  p99 {:>7.1} us  p99.9 {:>7.1} us  (target p99 <= 200 us)",
        us(r[0], d[0]),
        us(r[1], d[1]),
        us(r[2], d[2])
    );
    println!(
        "  router over the bare relay   p50 {:>7.1} us  p99 {:>7.1} us  p99.9 {:>7.1} us  (p50 {:.2}x the relay's)",
        us(r[0], b[0]),
        us(r[1], b[1]),
        us(r[2], b[2]),
        r[0].as_secs_f64() / b[0].as_secs_f64()
    );
}

/// (b) sustained forwarding: a bounded window, then stepped offered rates,
/// with the router threads' CPU time per forwarded command.
fn throughput(
    router: &mech_core::router::RouterHandle,
    controller: &UdpSocket,
    robot: &UdpSocket,
    addr: SocketAddr,
    commands: &mut Commands,
) {
    let counter = CommandCounter::start(robot);
    bounded_window(router, controller, addr, &counter, commands);
    match stepped_rates(router, controller, robot, addr, &counter, commands) {
        Some(r) => println!("  sustained zero-loss rate: {:.0} msg/s", r),
        None => println!("  sustained zero-loss rate: below the first step"),
    }
    counter.stop();
}

/// (b), first part: at most a window of commands in flight for 3 s; the
/// rate forwarded and the router's CPU per command.
fn bounded_window(
    router: &mech_core::router::RouterHandle,
    controller: &UdpSocket,
    addr: SocketAddr,
    counter: &CommandCounter,
    commands: &mut Commands,
) {
    const WINDOW: u64 = 1024;
    let run = Duration::from_secs(3);
    let before = router.counters();
    let cpu0 = router_cpu();
    let t = Instant::now();
    let mut sent = 0u64;
    while t.elapsed() < run {
        if sent - counter.get() < WINDOW {
            controller.send_to(&commands.next(), addr).unwrap();
            sent += 1;
        } else {
            std::thread::yield_now();
        }
    }
    let got = counter.settle(sent);
    let elapsed = t.elapsed().as_secs_f64();
    let cpu = router_cpu() - cpu0;
    let after = router.counters();
    let forwarded = after.forwarded - before.forwarded;
    println!(
        "(b) sustained forwarding; sender, router (2 threads) and receiver share {} CPUs:",
        std::thread::available_parallelism().map_or(0, |n| n.get())
    );
    println!(
        "  window of {WINDOW}: {:.0} msg/s forwarded ({sent} sent, {got} received, {} lost; router forwarded {forwarded})",
        got as f64 / elapsed,
        sent - got,
    );
    let per = cpu / forwarded.max(1) as f64;
    println!(
        "  router CPU {:.2} us per forwarded command = {:.0} msg/s per core, {:.0} msg/s on 2 cores  (target >= 300k msg/s on 2 cores)",
        per * 1e6,
        1.0 / per,
        2.0 / per
    );
}

/// (b), second part: stepped offered rates until one loses a message or
/// the sender cannot offer it; the highest rate delivered in full.
fn stepped_rates(
    router: &mech_core::router::RouterHandle,
    controller: &UdpSocket,
    robot: &UdpSocket,
    addr: SocketAddr,
    counter: &CommandCounter,
    commands: &mut Commands,
) -> Option<f64> {
    let mut best = None;
    for rate in [
        25e3, 50e3, 75e3, 100e3, 125e3, 150e3, 175e3, 200e3, 250e3, 300e3, 350e3, 400e3,
    ] {
        let (sent, got, took, cpu, lost) = offer(
            router,
            controller,
            addr,
            robot.local_addr().unwrap(),
            counter,
            commands,
            rate,
            Duration::from_secs(2),
        );
        let achieved = sent as f64 / took;
        println!(
            "  offered {:>4.0}k msg/s: sent {:>4.0}k msg/s, {sent} sent, {got} received, {} lost ({} at the router's socket, {} forwarded, {} at the robot's socket), router CPU {:.2} us/msg ({:.0}% of a core)",
            rate / 1e3,
            achieved / 1e3,
            sent.saturating_sub(got),
            lost.at_router,
            lost.forwarded,
            lost.at_robot,
            cpu / got.max(1) as f64 * 1e6,
            cpu / took * 100.0
        );
        if got < sent {
            break;
        }
        if achieved < 0.95 * rate {
            println!("  (the sender cannot offer more on these cores)");
            return Some(achieved);
        }
        best = Some(achieved);
    }
    best
}

/// The router's own cost per command with no receive syscall.
fn in_process(
    rt: &tokio::runtime::Runtime,
    router: &mech_core::router::RouterHandle,
    robot: &UdpSocket,
) {
    // The router's own cost per command: an in-process publisher
    // (same decision code and the same socket send as UDP input) with no
    // receive syscall, single task.
    {
        let mut publisher = router.publisher("bench", "joy/0");
        let n: u32 = std::env::var("MECH_BENCH_N")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(200_000);
        let cpu0 = thread_cpu();
        let t = Instant::now();
        let forwarded = rt.block_on(async {
            let mut ok = 0u32;
            for _ in 0..n {
                let cmd = Command::Twist(Twist {
                    vx: 0.5,
                    vy: 0.0,
                    vz: 0.0,
                    wz: 0.1,
                });
                if publisher.send("robot_1", cmd).await.unwrap()
                    == mech_core::router::Delivery::Forwarded(1)
                {
                    ok += 1;
                }
            }
            ok
        });
        let per = t.elapsed().as_secs_f64() / f64::from(n);
        let cpu = (thread_cpu() - cpu0) / f64::from(n);
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
}

/// (c) switch latency.
fn switching(
    rt: &tokio::runtime::Runtime,
    router: &mech_core::router::RouterHandle,
    controller: &UdpSocket,
    robot: &UdpSocket,
    addr: SocketAddr,
    buf: &mut [u8],
) {
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
            let (seq, ch) = recv_command(robot, buf).unwrap();
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
}

/// Threads sending telemetry in [`send_telemetry`].
const THREADS: usize = 4;

/// `n` robots `sim_0`.. registered with the router at `addr`, each with its
/// own socket.
fn register_robots(addr: SocketAddr, n: usize) -> Vec<(String, UdpSocket)> {
    (0..n)
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
        .collect()
}

/// Every robot sends telemetry at `rate_hz` for `run`, spread over the
/// period by [`THREADS`] threads; returns how many were sent.
fn send_telemetry(robots: Vec<(String, UdpSocket)>, rate_hz: u64, run: Duration) -> u64 {
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
                let period = Duration::from_nanos(1_000_000_000 / rate_hz);
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
    sent.load(Ordering::Relaxed)
}

/// CPU time of the threads named `name`, seconds.
fn threads_cpu(name: &str) -> f64 {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return 0.0;
    };
    tasks
        .flatten()
        .filter(|t| {
            std::fs::read_to_string(t.path().join("comm")).is_ok_and(|c| c.trim_end() == name)
        })
        .map(|t| stat_cpu(&std::fs::read_to_string(t.path().join("stat")).unwrap_or_default()))
        .sum()
}

/// One telemetry load on a fresh router, recording to `file` or not.
struct LoadRun {
    sent: u64,
    received: u64,
    secs: f64,
    router_cpu: f64,
    recorder_cpu: f64,
    status: Option<mech_core::RecordingStatus>,
}

fn telemetry_load(
    rt: &tokio::runtime::Runtime,
    robots: usize,
    rate_hz: u64,
    record: Option<&std::path::Path>,
) -> LoadRun {
    let gcs = rt.block_on(Gcs::start(config())).unwrap();
    let addr = gcs.router().udp_addr();
    if let Some(f) = record {
        gcs.start_recording(mech_core::RecordTarget::File(f.to_owned()))
            .unwrap();
    }
    let socks = register_robots(addr, robots);
    std::thread::sleep(Duration::from_millis(500));
    let before = gcs.router().counters().received;
    let (cpu0, rec0) = (router_cpu(), threads_cpu("mech-record"));
    let start = Instant::now();
    let sent = send_telemetry(socks, rate_hz, Duration::from_secs(6));
    std::thread::sleep(Duration::from_millis(300));
    let secs = start.elapsed().as_secs_f64();
    let router_cpu = router_cpu() - cpu0;
    let recorder_cpu = threads_cpu("mech-record") - rec0;
    let received = gcs.router().counters().received - before;
    let status = rt.block_on(gcs.stop_recording());
    rt.block_on(gcs.shutdown());
    LoadRun {
        sent,
        received,
        secs,
        router_cpu,
        recorder_cpu,
        status,
    }
}

/// (r) what recording costs: the same telemetry load without and with a
/// recording, the router threads' CPU time, the recorder thread's, and
/// the file's size per robot-hour.
fn recording_cost(rt: &tokio::runtime::Runtime) {
    let dir = tempfile::tempdir().unwrap();
    println!("(r) recording cost: telemetry into a fresh router, without and with recording");
    for (robots, hz) in [(1000usize, 50u64), (100, 20)] {
        let plain = telemetry_load(rt, robots, hz, None);
        let file = dir.path().join(format!("bench-{robots}.mcap"));
        let rec = telemetry_load(rt, robots, hz, Some(&file));
        let status = rec.status.clone().unwrap_or_default();
        let size = std::fs::metadata(&file).map_or(0, |m| m.len());
        let per_msg = |r: &LoadRun| r.router_cpu / r.received.max(1) as f64 * 1e6;
        println!(
            "  {robots} robots at {hz} Hz: router CPU {:.2} us/msg ({:.0}% of a core) without, {:.2} us/msg ({:.0}%) recording: {:+.1}%",
            per_msg(&plain),
            plain.router_cpu / plain.secs * 100.0,
            per_msg(&rec),
            rec.router_cpu / rec.secs * 100.0,
            (per_msg(&rec) / per_msg(&plain) - 1.0) * 100.0
        );
        println!(
            "    recorder thread {:.0}% of a core ({:.2} us/msg); sent {} / {}, router received {} / {}; recorded {} messages, dropped {}",
            rec.recorder_cpu / rec.secs * 100.0,
            rec.recorder_cpu / rec.received.max(1) as f64 * 1e6,
            plain.sent,
            rec.sent,
            plain.received,
            rec.received,
            status.messages,
            status.dropped
        );
        let robot_hours = robots as f64 * rec.secs / 3600.0;
        println!(
            "    file {:.1} MB for {:.1} s: {:.1} MB per robot-hour at {hz} Hz (zstd chunks)",
            size as f64 / 1e6,
            rec.secs,
            size as f64 / 1e6 / robot_hours
        );
    }
}

/// (d) telemetry fan-out.
fn fanout(rt: &tokio::runtime::Runtime, gcs: Gcs, addr: SocketAddr) {
    let router = gcs.router().clone();
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
    let robots = register_robots(addr, ROBOTS);
    std::thread::sleep(Duration::from_millis(300));
    let registered = gcs.with_fleet(|f| f.robots.len());
    let before = router.counters();
    let run = Duration::from_secs(5);
    let start = Instant::now();
    let sent = send_telemetry(robots, RATE_HZ, run);
    std::thread::sleep(Duration::from_millis(300));
    let elapsed = start.elapsed().as_secs_f64() - 0.3;
    let after = router.counters();
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
