//! Flood benchmark (not run by `cargo test`): the release `mech-gcs serve`,
//! with keys required, routes one signed controller's commands to one
//! signed robot at 20 Hz and the robot's telemetry back to the controller
//! at 20 Hz, while 16 sockets send it forged and garbage datagrams (by
//! default 200,000 in 10 s) and an operator attached to the control socket
//! reads the event log. Prints, for the flood's span: commands delivered
//! and their latency (controller's stamp to the robot's receipt, one
//! clock), telemetry delivered, the station's CPU, the event-log lines the
//! operator got, and the load average before and after.
//!
//! ```sh
//! cargo build --release -p mech-gcs
//! cargo bench -p mech-e2e --bench flood -- [SECONDS] [RATE] [SOURCES] [hog]
//! ```
//!
//! `hog` adds a thread spinning on every core for the whole run.
//! `MECH_FLOOD_GCS=PATH` runs another `mech-gcs` binary (to compare two
//! builds under the same load).

use std::collections::{HashMap, HashSet};
use std::io::{BufRead, BufReader, Write};
use std::net::{SocketAddr, UdpSocket};
use std::os::unix::fs::PermissionsExt;
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use mech_e2e::harness::{Killed, poll, unix_us};
use mech_proto::auth::{Key, KeyText, Stamper};
use mech_proto::{
    Body, Command as Cmd, Computation, ControlMode, Envelope, FailsafeState, Header, Health, Hello,
    Pose, RouteAck, Subscribe, Telemetry, Twist, Velocity, VelocitySource,
};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

/// The robot's and the controller's period (20 Hz).
const PERIOD: Duration = Duration::from_millis(50);

/// The channel the controller drives the robot on.
const CHANNEL: &str = "ext/ctl";

fn arg(i: usize) -> Option<String> {
    std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with('-'))
        .nth(i)
}

fn num(i: usize, default: u64) -> u64 {
    arg(i).and_then(|a| a.parse().ok()).unwrap_or(default)
}

/// utime + stime of a process, clock ticks (100 per second on Linux).
fn cpu_ticks(pid: u32) -> u64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    let after = stat.rsplit(')').next().unwrap_or("");
    let f: Vec<&str> = after.split_whitespace().collect();
    let field = |i: usize| f.get(i).and_then(|v| v.parse::<u64>().ok()).unwrap_or(0);
    field(11) + field(12)
}

/// The 1-minute load average.
fn load_average() -> f64 {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse().ok())
        .unwrap_or(f64::NAN)
}

/// A signing peer of the router with its own socket.
struct Signer {
    name: String,
    key: Key,
    stamper: Stamper,
    seq: u32,
}

impl Signer {
    fn new(name: &str, key: Key) -> Signer {
        Signer {
            name: name.into(),
            key,
            stamper: Stamper::default(),
            seq: 0,
        }
    }

    /// A message from this peer, signed, its header stamped now.
    fn message(&mut self, destination: &str, channel: &str, body: Body) -> Vec<u8> {
        self.numbered(destination, channel, body).1
    }

    /// [`Signer::message`] with its sequence number.
    fn numbered(&mut self, destination: &str, channel: &str, body: Body) -> (u32, Vec<u8>) {
        self.seq = self.seq.wrapping_add(1);
        let now = unix_us();
        let header = Header {
            seq: self.seq,
            stamp_us: now,
            sender: self.name.clone(),
            destination: destination.into(),
            channel: channel.into(),
        };
        let mut b = mech_proto::encode(&Envelope::new(header, body)).expect("encodes");
        let stamp = self.stamper.next(now);
        self.key.seal(&mut b, 0, stamp).expect("seals");
        (self.seq, b)
    }
}

fn write_key(dir: &Path, name: &str, secret: [u8; 32]) -> std::path::PathBuf {
    let path = dir.join(format!("{name}.key"));
    std::fs::write(&path, KeyText::render(name, &secret)).expect("key written");
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).expect("key mode");
    path
}

fn telemetry(x: f64) -> Body {
    Body::Telemetry(Telemetry {
        pose: Pose {
            x,
            y: 0.0,
            z: 0.0,
            heading: 0.0,
        },
        velocity: Velocity::default(),
        mode: ControlMode::Twist,
        channel: CHANNEL.into(),
        computation: Computation::Onboard,
        failsafe: FailsafeState::Ok,
        health: Health::Ok,
        battery: Some(0.9),
        position_quality: 1.0,
        actuators: vec![0.0, 0.0],
        mission: None,
        stale: 0,
        velocity_source: VelocitySource::Commanded,
        safety: None,
    })
}

fn twist(vx: f64) -> Body {
    Body::Command(Cmd::Twist(Twist {
        vx,
        vy: 0.0,
        vz: 0.0,
        wz: 0.0,
    }))
}

/// What the run counts. Messages are known by their sequence numbers:
/// those sent while measuring count, wherever they arrive later.
#[derive(Default)]
struct Tally {
    commands_sent: Mutex<Vec<u32>>,
    /// Every command of the controller the robot received: its latency, µs.
    commands_received: Mutex<HashMap<u32, u64>>,
    telemetry_sent: Mutex<Vec<u32>>,
    telemetry_received: Mutex<HashSet<u32>>,
    /// Forged commands that reached the robot (there must be none).
    forged_received: AtomicU64,
    flood_sent: AtomicU64,
    log_lines: AtomicU64,
}

/// Registers the robot (Hello until a Welcome, then acknowledges the route
/// it gives, `default_route`).
fn register(sock: &UdpSocket, router: SocketAddr, robot: &mut Signer) {
    let hello = Body::Hello(Hello {
        name: robot.name.clone(),
        platform: "diff-drive".into(),
        capabilities: vec![mech_proto::CommandKind::Twist],
        motors: 2,
        max_speed: 1.0,
        max_yaw_rate: 2.0,
        agent_version: "flood-bench".into(),
    });
    let mut buf = vec![0u8; 65_536];
    let welcome = poll(Duration::from_secs(10), || {
        let _ = sock.send_to(&robot.message("router", "", hello.clone()), router);
        let (n, _) = sock.recv_from(&mut buf).ok()?;
        match mech_proto::decode(&buf[..n]).ok()?.body {
            Body::Welcome(w) => Some(w),
            _ => None,
        }
    })
    .expect("the robot is welcomed");
    let ack = Body::RouteAck(RouteAck {
        robot: robot.name.clone(),
        channel: welcome.route.channel.clone(),
        epoch: welcome.route.epoch,
    });
    let _ = sock.send_to(&robot.message("router", "", ack), router);
    assert_eq!(welcome.route.channel, CHANNEL, "routed by default_route");
}

/// Datagram `i` of the flood: garbage, a command with a broken tag of the
/// controller's key, one signed with a key the station does not hold, a
/// replayed real command, or an unsigned command.
fn forged(
    i: u64,
    rng: &mut SmallRng,
    ctl: &mut Signer,
    stranger: &mut Signer,
    captured: &[u8],
) -> Vec<u8> {
    match i % 5 {
        0 => {
            let n = rng.random_range(8..200);
            (0..n).map(|_| rng.random()).collect()
        }
        1 => {
            let mut b = ctl.message("robot_1", CHANNEL, twist(9.0));
            let last = b.len() - 1;
            b[last] ^= 0x5a;
            b
        }
        2 => stranger.message("robot_1", CHANNEL, twist(9.0)),
        3 => captured.to_vec(),
        _ => {
            let header = Header {
                seq: 1,
                stamp_us: unix_us(),
                sender: "ctl".into(),
                destination: "robot_1".into(),
                channel: CHANNEL.into(),
            };
            mech_proto::encode(&Envelope::new(header, twist(9.0))).expect("encodes")
        }
    }
}

fn percentile(sorted: &[u64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[i] as f64 / 1000.0
}

fn main() {
    let secs = num(0, 10);
    let rate = num(1, 20_000);
    let sources = num(2, 16).max(1) as usize;
    let hog = std::env::args().any(|a| a == "hog");
    let dir = tempfile::tempdir().expect("temp dir");
    let robot_key = [0x11; 32];
    let ctl_key = [0x22; 32];
    let robot_file = write_key(dir.path(), "robot_1", robot_key);
    let ctl_file = write_key(dir.path(), "ctl", ctl_key);
    let port = mech_e2e::harness::station::free_port();
    let config = dir.path().join("gcs.toml");
    std::fs::write(
        &config,
        format!(
            "[router]\nudp = \"127.0.0.1:{port}\"\ntcp = \"127.0.0.1:0\"\n\
             default_route = \"{CHANNEL}\"\n\
             [station]\nsocket = \"{}\"\n\
             [auth]\nmode = \"required\"\n\
             [[auth.keys]]\nrole = \"robot\"\nname = \"robot_1\"\nfile = {:?}\n\
             [[auth.keys]]\nrole = \"controller\"\nname = \"ctl\"\nfile = {:?}\nchannels = [\"ext/*\"]\n",
            dir.path().join("gcs.sock").display(),
            robot_file.display().to_string(),
            ctl_file.display().to_string(),
        ),
    )
    .expect("config written");
    let stop = Arc::new(AtomicBool::new(false));
    let hogs: Vec<_> = (0..if hog { 2 } else { 0 })
        .map(|_| {
            let stop = stop.clone();
            std::thread::spawn(move || {
                let mut x = 0u64;
                while !stop.load(Ordering::Relaxed) {
                    x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
                }
            })
        })
        .collect();
    let load_before = load_average();
    let program = std::env::var_os("MECH_FLOOD_GCS")
        .map_or_else(|| mech_e2e::binary("mech-gcs"), std::path::PathBuf::from);
    let child = Command::new(program)
        .arg("serve")
        .arg("--config")
        .arg(&config)
        .env("XDG_STATE_HOME", dir.path())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("mech-gcs starts (cargo build --release -p mech-gcs first)");
    let mut station = Killed(Some(child));
    let mut ready = String::new();
    if let Some(out) = station.0.as_mut().and_then(|c| c.stdout.take()) {
        let _ = BufReader::new(out).read_line(&mut ready);
    }
    assert!(
        ready.contains("serving"),
        "the station did not start: {ready:?}"
    );
    let pid = station.pid().expect("station runs");
    let router: SocketAddr = ([127, 0, 0, 1], port).into();
    let tally = Arc::new(Tally::default());

    // The operator reading the event log.
    let socket = dir.path().join("gcs.sock");
    let mut operator = std::os::unix::net::UnixStream::connect(&socket).expect("attaches");
    operator
        .write_all(b"{\"type\":\"hello\",\"protocol\":1,\"stream\":{\"log\":true}}\n")
        .expect("hello");
    let counting = Arc::new(AtomicBool::new(false));
    {
        let (tally, counting) = (tally.clone(), counting.clone());
        let reader = operator.try_clone().expect("socket");
        std::thread::spawn(move || {
            for line in BufReader::new(reader).lines().map_while(Result::ok) {
                if counting.load(Ordering::Relaxed) && line.contains("\"type\":\"log\"") {
                    tally.log_lines.fetch_add(1, Ordering::Relaxed);
                }
            }
        });
    }

    // The robot: registers, reports at 20 Hz, notes every command's latency.
    let robot_sock = Arc::new(UdpSocket::bind("127.0.0.1:0").expect("robot binds"));
    robot_sock
        .set_read_timeout(Some(Duration::from_millis(200)))
        .expect("timeout");
    let mut robot = Signer::new("robot_1", Key::new(&robot_key));
    register(&robot_sock, router, &mut robot);
    let robot = Arc::new(Mutex::new(robot));
    let measuring = Arc::new(AtomicBool::new(false));
    let receiver = {
        let (sock, tally, stop) = (robot_sock.clone(), tally.clone(), stop.clone());
        std::thread::spawn(move || {
            let mut buf = vec![0u8; 65_536];
            while !stop.load(Ordering::Relaxed) {
                let Ok((n, _)) = sock.recv_from(&mut buf) else {
                    continue;
                };
                let now = unix_us();
                let Ok(env) = mech_proto::decode(&buf[..n]) else {
                    continue;
                };
                if let Body::Command(Cmd::Twist(t)) = env.body {
                    if t.vx > 1.0 {
                        tally.forged_received.fetch_add(1, Ordering::Relaxed);
                    } else if env.header.sender == "ctl" {
                        let l = now.saturating_sub(env.header.stamp_us);
                        let mut got = tally.commands_received.lock().expect("lock");
                        got.insert(env.header.seq, l);
                    }
                }
            }
        })
    };
    let reporter = {
        let (sock, robot, tally, stop, measuring) = (
            robot_sock.clone(),
            robot.clone(),
            tally.clone(),
            stop.clone(),
            measuring.clone(),
        );
        std::thread::spawn(move || {
            let mut next = Instant::now();
            let mut x = 0.0;
            while !stop.load(Ordering::Relaxed) {
                x += 0.01;
                let (seq, b) = robot
                    .lock()
                    .expect("lock")
                    .numbered("router", "", telemetry(x));
                if sock.send_to(&b, router).is_ok() && measuring.load(Ordering::Relaxed) {
                    tally.telemetry_sent.lock().expect("lock").push(seq);
                }
                next += PERIOD;
                std::thread::sleep(next.saturating_duration_since(Instant::now()));
            }
        })
    };

    // The controller: subscribes to telemetry, drives at 20 Hz.
    let ctl_sock = Arc::new(UdpSocket::bind("127.0.0.1:0").expect("controller binds"));
    ctl_sock
        .set_read_timeout(Some(Duration::from_millis(200)))
        .expect("timeout");
    let ctl = Arc::new(Mutex::new(Signer::new("ctl", Key::new(&ctl_key))));
    let subscribe = || Body::Subscribe(Subscribe { telemetry: true });
    let sub = ctl.lock().expect("lock").message("router", "", subscribe());
    let _ = ctl_sock.send_to(&sub, router);
    let listener = {
        let (sock, tally, stop) = (ctl_sock.clone(), tally.clone(), stop.clone());
        std::thread::spawn(move || {
            let mut buf = vec![0u8; 65_536];
            while !stop.load(Ordering::Relaxed) {
                let Ok((n, _)) = sock.recv_from(&mut buf) else {
                    continue;
                };
                if let Ok(e) = mech_proto::decode(&buf[..n]) {
                    if matches!(e.body, Body::Telemetry(_)) {
                        tally
                            .telemetry_received
                            .lock()
                            .expect("lock")
                            .insert(e.header.seq);
                    }
                }
            }
        })
    };
    let captured = ctl
        .lock()
        .expect("lock")
        .message("robot_1", CHANNEL, twist(0.2));
    let _ = ctl_sock.send_to(&captured, router);
    let driver = {
        let (sock, ctl, tally, stop, measuring) = (
            ctl_sock.clone(),
            ctl.clone(),
            tally.clone(),
            stop.clone(),
            measuring.clone(),
        );
        std::thread::spawn(move || {
            let mut next = Instant::now();
            let mut n = 0u64;
            while !stop.load(Ordering::Relaxed) {
                n += 1;
                let (seq, b) = ctl
                    .lock()
                    .expect("lock")
                    .numbered("robot_1", CHANNEL, twist(0.3));
                if sock.send_to(&b, router).is_ok() && measuring.load(Ordering::Relaxed) {
                    tally.commands_sent.lock().expect("lock").push(seq);
                }
                if n % 40 == 0 {
                    let s = ctl.lock().expect("lock").message("router", "", subscribe());
                    let _ = sock.send_to(&s, router);
                }
                next += PERIOD;
                std::thread::sleep(next.saturating_duration_since(Instant::now()));
            }
        })
    };

    // Settle, then measure over the flood.
    std::thread::sleep(Duration::from_secs(1));
    let ticks_before = cpu_ticks(pid);
    counting.store(true, Ordering::Relaxed);
    measuring.store(true, Ordering::Relaxed);
    let started = Instant::now();
    let span = Duration::from_secs(secs);
    let flooder = {
        let tally = tally.clone();
        std::thread::spawn(move || {
            let socks: Vec<UdpSocket> = (0..sources)
                .map(|_| UdpSocket::bind("127.0.0.1:0").expect("flooder binds"))
                .collect();
            let mut rng = SmallRng::seed_from_u64(0x0046_4c4f_4f44);
            let mut ctl = Signer::new("ctl", Key::new(&ctl_key));
            let mut stranger = Signer::new("ctl", Key::new(&[0x33; 32]));
            let total = rate * secs;
            let mut i = 0u64;
            // 1 ms steps: the datagrams due by each step, then sleep.
            while i < total {
                let due = ((started.elapsed().as_secs_f64() * rate as f64) as u64).min(total);
                while i < due {
                    let b = forged(i, &mut rng, &mut ctl, &mut stranger, &captured);
                    let _ = socks[i as usize % sources].send_to(&b, router);
                    i += 1;
                }
                std::thread::sleep(Duration::from_millis(1));
            }
            tally.flood_sent.store(i, Ordering::Relaxed);
        })
    };
    let _ = flooder.join();
    let flood_took = started.elapsed();
    std::thread::sleep(span.saturating_sub(flood_took));
    measuring.store(false, Ordering::Relaxed);
    let elapsed = started.elapsed();
    let ticks = cpu_ticks(pid) - ticks_before;
    // Late commands still on their way are counted when they arrive.
    std::thread::sleep(Duration::from_millis(500));
    counting.store(false, Ordering::Relaxed);
    let load_after = load_average();
    stop.store(true, Ordering::Relaxed);
    for t in [receiver, reporter, listener, driver] {
        let _ = t.join();
    }
    for h in hogs {
        let _ = h.join();
    }
    drop(operator);
    station.kill();

    let sent = tally.commands_sent.lock().expect("lock").clone();
    let received = tally.commands_received.lock().expect("lock").clone();
    let mut lat: Vec<u64> = sent
        .iter()
        .filter_map(|s| received.get(s).copied())
        .collect();
    lat.sort_unstable();
    let (sent, got) = (sent.len() as u64, lat.len() as u64);
    let tsent = tally.telemetry_sent.lock().expect("lock").clone();
    let treceived = tally.telemetry_received.lock().expect("lock").clone();
    let tgot = tsent.iter().filter(|s| treceived.contains(s)).count();
    let tsent = tsent.len();
    let cpu = ticks as f64 / elapsed.as_secs_f64();
    println!(
        "flood: {} datagrams from {sources} sources{}; forged commands delivered: {}",
        tally.flood_sent.load(Ordering::Relaxed),
        if hog {
            ", a spinning thread per core"
        } else {
            ""
        },
        tally.forged_received.load(Ordering::Relaxed),
    );
    println!(
        "| flood sent in (s) | commands delivered | latency p50 / p99 / max (ms) | telemetry delivered | station CPU (% of a core) | operator log lines | load average before / after |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- |");
    println!(
        "| {:.1} | {got}/{sent} ({:.1}%) | {:.2} / {:.2} / {:.2} | {tgot}/{tsent} ({:.1}%) | {cpu:.0} | {} | {load_before:.2} / {load_after:.2} |",
        flood_took.as_secs_f64(),
        100.0 * got as f64 / sent.max(1) as f64,
        percentile(&lat, 0.5),
        percentile(&lat, 0.99),
        percentile(&lat, 1.0),
        100.0 * tgot as f64 / tsent.max(1) as f64,
        tally.log_lines.load(Ordering::Relaxed),
    );
}
