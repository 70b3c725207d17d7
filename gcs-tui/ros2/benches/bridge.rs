//! The bridge under load, measured: `mech-gcs serve --demo N` (N simulated
//! robots, 20 Hz telemetry each), `mech-ros2`, and a ROS 2 subscriber in
//! this process (ros2-client) reading every robot's `/<robot>/odom`, all
//! in a network namespace of their own (DDS discovery is multicast; run as
//! root). For N = 20 and 100 it prints the odometry rate per robot, the
//! share of samples delivered, the latency from the robot's stamp to this
//! subscriber (station router, bridge and DDS), and the CPU the bridge and
//! the station used. Then cmd_vel to motor: two simulated robots
//! (`mech-agent --sim`), one with a 1 kHz control loop (the bridge's path
//! alone, seen within 1 ms) and one with the default 50 Hz loop (which
//! adds the wait for the robot's next control period), each routed to
//! `ros2/<robot>` while cmd_vel steps between forward and reverse; the
//! latency is from publishing a step to the first telemetry whose motor
//! outputs have turned (the agent reports them every control period).
//!
//!     cargo build --release -p mech-gcs -p mech-agent
//!     cargo bench -p mech-ros2 --bench bridge [-- N...]

use std::collections::HashSet;
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use futures::StreamExt;
use mech_proto::unix_micros;
use mech_ros2::link::{FromStation, StationLink};
use mech_ros2::msgs::RosMessage;
use mech_ros2::msgs::geometry::{Twist, Vector3};
use mech_ros2::msgs::nav::Odometry;
use mech_ros2::ros::{reliable_qos, sensor_data_qos};
use ros2_client::{Context, ContextOptions, MessageTypeName, Name, NodeName, NodeOptions};

const INSIDE: &str = "MECH_ROS2_BENCH_NETNS";
const ROUTER: &str = "127.0.0.1:17400";
const MEASURE: Duration = Duration::from_secs(10);
const STEPS: usize = 40;

fn main() {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| a != "--bench")
        .collect();
    if std::env::var_os(INSIDE).is_none() {
        std::process::exit(outer(&args));
    }
    let fleets: Vec<usize> = args.iter().filter_map(|a| a.parse().ok()).collect();
    let fleets = if fleets.is_empty() {
        vec![20, 100]
    } else {
        fleets
    };
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("runtime");
    for n in fleets {
        runtime.block_on(run(n));
    }
}

/// A network namespace with `lo` up and multicast on, deleted on drop.
struct Netns(String);

impl Drop for Netns {
    fn drop(&mut self) {
        let _ = Command::new("ip").args(["netns", "del", &self.0]).status();
    }
}

/// Runs this program again inside a namespace of its own.
fn outer(args: &[String]) -> i32 {
    let ns = Netns(format!("mechros-bench-{}", std::process::id()));
    for a in [
        vec!["netns", "add", &ns.0],
        vec!["-n", &ns.0, "link", "set", "lo", "up"],
        vec!["-n", &ns.0, "link", "set", "lo", "multicast", "on"],
    ] {
        let ok = Command::new("ip")
            .args(&a)
            .status()
            .is_ok_and(|s| s.success());
        if !ok {
            eprintln!(
                "cannot make a network namespace (ip {}): run as root",
                a.join(" ")
            );
            return 2;
        }
    }
    let exe = std::env::current_exe().expect("own path");
    Command::new("ip")
        .args(["netns", "exec", &ns.0])
        .arg(exe)
        .args(args)
        .env(INSIDE, "1")
        .status()
        .map_or(1, |s| s.code().unwrap_or(1))
}

/// A release binary of the workspace, next to this bench's directory.
fn binary(name: &str) -> PathBuf {
    if name == "mech-ros2" {
        return PathBuf::from(env!("CARGO_BIN_EXE_mech-ros2"));
    }
    let exe = std::env::current_exe().expect("own path");
    let path = exe
        .parent()
        .and_then(Path::parent)
        .expect("target/<profile>/deps")
        .join(name);
    assert!(
        path.exists(),
        "{} is missing: cargo build --release -p mech-gcs -p mech-agent",
        path.display()
    );
    path
}

/// A child process, killed when dropped.
struct Proc(Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// CPU time (user + system) a process has used.
fn cpu(pid: u32) -> Duration {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    // The fields after the command's closing parenthesis, from the state
    // on: utime and stime are the 12th and 13th of them (the line's 14th
    // and 15th), in clock ticks.
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<&str> = rest.split_whitespace().collect();
    let field = |i: usize| f.get(i).and_then(|v| v.parse::<u64>().ok()).unwrap_or(0);
    let ticks = field(11) + field(12);
    Duration::from_secs_f64(ticks as f64 / 100.0)
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

fn summary(mut v: Vec<f64>) -> String {
    v.sort_by(f64::total_cmp);
    format!(
        "p50 {:.2} / p95 {:.2} / p99 {:.2} / max {:.2} ms",
        percentile(&v, 0.5),
        percentile(&v, 0.95),
        percentile(&v, 0.99),
        percentile(&v, 1.0)
    )
}

/// What the ROS 2 subscriber received.
struct Seen {
    /// Samples per robot.
    counts: Vec<u64>,
    /// Robot stamp -> receipt, ms, of the samples in the window.
    latencies: Vec<f64>,
    /// (robot, stamp) of every sample.
    stamps: HashSet<(usize, u64)>,
}

/// The probe robots: name, control and telemetry rate (Hz). The agent
/// computes its outputs and reports them once per control period, so at
/// 1 kHz the latency to the outputs is seen within 1 ms; at 50 Hz (the
/// default) it includes the wait for the next control period.
const PROBES: [(&str, u32); 2] = [("probe_1khz", 1000), ("probe_50hz", 50)];

/// Steps `probe`'s cmd_vel between forward and reverse [`STEPS`] times
/// (publishing at 50 Hz, as a teleop node does) and returns, for each
/// step, the milliseconds from publishing it to the first telemetry whose
/// motor outputs have all turned to its sign. Each step starts at a
/// different phase of the robot's control period.
async fn step_probe(
    node: &mut ros2_client::Node,
    link: &StationLink,
    telemetry: &mut tokio::sync::mpsc::Receiver<FromStation>,
    probe: &str,
) -> Vec<f64> {
    let qos = reliable_qos(10);
    let topic = node
        .create_topic(
            &Name::parse(&format!("/{probe}/cmd_vel")).expect("topic"),
            MessageTypeName::new(Twist::PACKAGE, Twist::NAME),
            &qos,
        )
        .expect("topic");
    let cmd = node
        .create_publisher::<Twist>(&topic, Some(qos))
        .expect("publisher");
    let twist = |vx: f64| Twist {
        linear: Vector3 {
            x: vx,
            y: 0.0,
            z: 0.0,
        },
        angular: Vector3::default(),
    };
    // Let the bridge's reader match this publisher.
    let matched = Instant::now();
    while matched.elapsed() < Duration::from_secs(3) {
        let _ = cmd.publish(twist(0.0));
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let mut steps = Vec::new();
    let mut phase: u64 = 7;
    for k in 0..STEPS {
        // The router drops a subscriber it has not heard from for 5 s.
        link.subscribe(true);
        phase = (phase * 1103515245 + 12345) % 2_147_483_648;
        tokio::time::sleep(Duration::from_micros(phase % 20_000)).await;
        let vx = if k % 2 == 0 { 0.2 } else { -0.2 };
        let sent = unix_micros();
        let deadline = Instant::now() + Duration::from_secs(2);
        let mut next_publish = Instant::now();
        let mut turned = None;
        while Instant::now() < deadline && turned.is_none() {
            if Instant::now() >= next_publish {
                let _ = cmd.publish(twist(vx));
                next_publish += Duration::from_millis(20);
            }
            if let Ok(Some(FromStation::Telemetry {
                robot,
                stamp_us,
                telemetry: t,
            })) = tokio::time::timeout(Duration::from_millis(5), telemetry.recv()).await
                && robot == probe
                && stamp_us > sent
                && !t.actuators.is_empty()
                && t.actuators
                    .iter()
                    .all(|a| a.signum() == vx.signum() && a.abs() > 0.01)
            {
                turned = Some((stamp_us - sent) as f64 / 1000.0);
            }
        }
        match turned {
            Some(ms) => steps.push(ms),
            None => println!("  {probe} step {k}: outputs did not turn within 2 s"),
        }
    }
    steps
}

async fn run(n: usize) {
    let dir = tempfile::tempdir().expect("temp dir");
    let socket = dir.path().join("gcs.sock");
    let mut station = Proc(
        Command::new(binary("mech-gcs"))
            .args(["serve", "--demo", &n.to_string(), "--udp", ROUTER])
            .args(["--tcp", "127.0.0.1:17401", "--socket"])
            .arg(&socket)
            .env("XDG_STATE_HOME", dir.path())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("mech-gcs serve starts"),
    );
    let mut lines = BufReader::new(station.0.stdout.take().expect("stdout")).lines();
    while let Some(Ok(l)) = lines.next() {
        if l.contains("mech-gcs serving") {
            break;
        }
    }
    std::thread::spawn(move || for _ in lines {});
    let bridge = Proc(
        Command::new(binary("mech-ros2"))
            .args(["--router", ROUTER, "--summary-every", "0"])
            .env("RUST_LOG", "warn")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("mech-ros2 starts"),
    );

    // The subscriber: every robot's odometry, with its stamp and arrival.
    let context = Context::with_options(ContextOptions::new()).expect("DDS");
    let mut node = context
        .new_node(
            NodeName::new("/", "mech_bench").expect("name"),
            NodeOptions::new().enable_rosout(false),
        )
        .expect("node");
    let seen = Arc::new(Mutex::new(Seen {
        counts: vec![0; n],
        latencies: Vec::new(),
        stamps: HashSet::new(),
    }));
    let measuring = Arc::new(std::sync::atomic::AtomicBool::new(false));
    for i in 0..n {
        let name = Name::parse(&format!("/robot_{}/odom", i + 1)).expect("topic");
        let qos = sensor_data_qos();
        let topic = node
            .create_topic(
                &name,
                MessageTypeName::new(Odometry::PACKAGE, Odometry::NAME),
                &qos,
            )
            .expect("topic");
        let sub = node
            .create_subscription::<Odometry>(&topic, Some(qos))
            .expect("subscription");
        let (seen, measuring) = (Arc::clone(&seen), Arc::clone(&measuring));
        tokio::spawn(async move {
            let mut stream = std::pin::pin!(sub.async_stream());
            while let Some(Ok((o, _))) = stream.next().await {
                let now = unix_micros();
                let mut s = seen.lock().expect("lock");
                s.counts[i] += 1;
                let Some(stamp) = o.header.stamp.to_micros() else {
                    continue;
                };
                s.stamps.insert((i, stamp));
                if measuring.load(std::sync::atomic::Ordering::Relaxed) {
                    s.latencies.push(now.saturating_sub(stamp) as f64 / 1000.0);
                }
            }
        });
    }
    let started = Instant::now();
    loop {
        let all = seen.lock().expect("lock").counts.iter().all(|c| *c > 0);
        if all {
            break;
        }
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "not every robot's odometry arrived within 60 s"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let discovered = started.elapsed();
    // What the router sends out, straight from it: the samples that should
    // reach ROS 2.
    let stats = Arc::new(mech_ros2::Stats::default());
    let link = Arc::new(
        StationLink::open(ROUTER.parse().expect("addr"), "bench", None, stats)
            .await
            .expect("link"),
    );
    let (tx, mut telemetry) = tokio::sync::mpsc::channel(100_000);
    link.spawn_reader(None, tx);
    link.subscribe(true);
    // Settle for a second, then measure.
    tokio::time::sleep(Duration::from_secs(1)).await;
    while telemetry.try_recv().is_ok() {}
    let (b0, s0) = (cpu(bridge.0.id()), cpu(station.0.id()));
    let counts0 = {
        let mut s = seen.lock().expect("lock");
        s.latencies.clear();
        s.counts.clone()
    };
    measuring.store(true, std::sync::atomic::Ordering::Relaxed);
    let t0 = Instant::now();
    let mut sent = Vec::new();
    let mut renewed = Instant::now();
    while t0.elapsed() < MEASURE {
        if renewed.elapsed() > Duration::from_secs(2) {
            link.subscribe(true);
            renewed = Instant::now();
        }
        if let Ok(Some(FromStation::Telemetry {
            robot, stamp_us, ..
        })) = tokio::time::timeout(Duration::from_millis(50), telemetry.recv()).await
            && let Some(i) = robot
                .strip_prefix("robot_")
                .and_then(|k| k.parse::<usize>().ok())
        {
            sent.push((i - 1, stamp_us));
        }
    }
    measuring.store(false, std::sync::atomic::Ordering::Relaxed);
    let window = t0.elapsed().as_secs_f64();
    let (b1, s1) = (cpu(bridge.0.id()), cpu(station.0.id()));
    let (counts, latencies) = {
        let s = seen.lock().expect("lock");
        (s.counts.clone(), s.latencies.clone())
    };
    // Late samples have a second to arrive.
    tokio::time::sleep(Duration::from_secs(1)).await;
    let missing = {
        let s = seen.lock().expect("lock");
        sent.iter().filter(|k| !s.stamps.contains(k)).count()
    };
    let got: u64 = counts.iter().zip(&counts0).map(|(a, b)| a - b).sum();
    let per_robot = got as f64 / n as f64 / window;
    println!(
        "{n} robots x 20 Hz: odometry {per_robot:.2} Hz per robot ({got} samples in {window:.1} s); \
         of the {} samples the router sent out meanwhile, {missing} did not reach ROS 2; \
         all robots seen {:.1} s after subscribing",
        sent.len(),
        discovered.as_secs_f64()
    );
    println!(
        "  latency robot stamp -> ROS 2 subscriber: {}",
        summary(latencies)
    );
    println!(
        "  CPU: bridge {:.1} % of a core, station (router + {n} simulated robots) {:.1} %",
        100.0 * (b1 - b0).as_secs_f64() / window,
        100.0 * (s1 - s0).as_secs_f64() / window
    );

    // cmd_vel to motor, on probe robots started now (their telemetry,
    // at up to 1 kHz, is not in the figures above).
    let _probes: Vec<Proc> = PROBES
        .iter()
        .map(|(name, hz)| {
            let config = dir.path().join(format!("{name}.toml"));
            std::fs::write(
                &config,
                format!(
                    "name = \"{name}\"\ncontrol_rate_hz = {hz}\ntelemetry_rate_hz = {hz}\n\
                     [platform]\nkind = \"diff-drive\"\ntrack_width = 0.15\nmax_wheel_speed = 0.5\n\
                     [position]\nkind = \"sim\"\n[sim]\nnoise = false\n"
                ),
            )
            .expect("probe config");
            Proc(
                Command::new(binary("mech-agent"))
                    .args(["--sim", "--router", ROUTER, "--config"])
                    .arg(&config)
                    .stdout(Stdio::null())
                    .stderr(Stdio::null())
                    .spawn()
                    .expect("mech-agent starts"),
            )
        })
        .collect();
    let routes: String = PROBES
        .iter()
        .map(|(name, _)| format!("route {name} ros2/{name}\n"))
        .collect();
    let routed = Command::new(binary("mech-gcs"))
        .arg("--attach")
        .arg(&socket)
        .args(["--script", "-"])
        .env("XDG_STATE_HOME", dir.path())
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .and_then(|mut c| {
            if let Some(mut i) = c.stdin.take() {
                i.write_all(format!("wait robots {} 10s\n{routes}", n + PROBES.len()).as_bytes())?;
            }
            c.wait()
        });
    assert!(
        routed.is_ok_and(|s| s.success()),
        "probes routed to ros2/<probe>"
    );
    for (probe, hz) in PROBES {
        let steps = step_probe(&mut node, &link, &mut telemetry, probe).await;
        println!(
            "  cmd_vel -> motor outputs, robot with a {hz} Hz control loop ({} of {STEPS} steps): {}",
            steps.len(),
            summary(steps)
        );
    }
    link.subscribe(false);
    drop(bridge);
    drop(station);
}
