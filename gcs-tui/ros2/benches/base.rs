//! What the agent's ROS 2 base platform costs on the robot's computer: a
//! release `mech-agent` with a `[ros2]` section (20 Hz control, 10 Hz
//! telemetry) driving the fake ROS 2 base (`tests/fake_base.py`, Cyclone
//! DDS) that publishes odometry at 50 Hz (or the rates given), routed to a
//! controller that turns it in a circle, with a station (and one simulated
//! robot of its own, parked across the arena) beside it, all in
//! a network namespace of their own (root, iproute2, Python's
//! cyclonedds). Prints the agent's CPU (user + system, over 30 s) and its
//! memory (VmRSS at the end, VmHWM its peak).
//!
//!     cargo build --release --workspace --bins --features mech-agent/ros2
//!     cargo bench -p mech-ros2 --bench base [-- ODOM_HZ...]

#![allow(clippy::unwrap_used)]

#[allow(dead_code)]
#[path = "../tests/support/base_rig.rs"]
mod base_rig;
#[allow(dead_code)]
#[path = "../tests/support/operator.rs"]
mod operator;
#[allow(dead_code)]
#[path = "../tests/support/rig.rs"]
mod rig;

use std::time::{Duration, Instant};

use base_rig::{BaseRig, NAME, Pose2, Setup};
use operator::Pad;

/// How long the agent is measured.
const MEASURE: Duration = Duration::from_secs(30);

/// CPU time (user + system) a process has used.
fn cpu(pid: u32) -> Duration {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    // After the command's closing parenthesis: utime and stime are the
    // 12th and 13th fields, in clock ticks.
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<&str> = rest.split_whitespace().collect();
    let field = |i: usize| f.get(i).and_then(|v| v.parse::<u64>().ok()).unwrap_or(0);
    Duration::from_secs_f64((field(11) + field(12)) as f64 / 100.0)
}

/// A `/proc/PID/status` size, KiB.
fn status_kib(pid: u32, key: &str) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
    status
        .lines()
        .find(|l| l.starts_with(key))
        .and_then(|l| l.split_whitespace().nth(1)?.parse().ok())
        .unwrap_or(0)
}

fn measure(odom_hz: f64) {
    let mut setup = Setup::new(1, Pose2::new(3.2, 0.6, 0.0));
    setup.base_args = vec!["--odom-hz".into(), odom_hz.to_string()];
    let mut rig = BaseRig::start(setup);
    let channel = "pad/bench";
    rig.op.run(&format!("route {NAME} {channel}"));
    rig.eventually("routed to the controller", |r| {
        let route = &r.robot()["route"];
        (route["channel"] == channel && route["acknowledged"] == true).then_some(())
    });
    // 0.1 m/s at 0.3 rad/s: a circle of 0.33 m round (3.2, 0.93), inside
    // the arena and clear of the station's robot (at its centre).
    let _pad = Pad::start(&rig.op, channel, NAME, 0.1, 0.3);
    std::thread::sleep(Duration::from_secs(3));
    let pid = rig.agent_pid();
    let (cpu0, t0) = (cpu(pid), Instant::now());
    std::thread::sleep(MEASURE);
    let used = cpu(pid) - cpu0;
    let wall = t0.elapsed();
    let moving = base_rig::num(&rig.state()["v"]);
    println!(
        "odometry {odom_hz:.0} Hz: agent CPU {:.2} % of a core over {:.0} s, VmRSS {:.1} MiB, VmHWM {:.1} MiB (the base moving at {moving:.2} m/s)",
        100.0 * used.as_secs_f64() / wall.as_secs_f64(),
        wall.as_secs_f64(),
        status_kib(pid, "VmRSS:") as f64 / 1024.0,
        status_kib(pid, "VmHWM:") as f64 / 1024.0,
    );
}

fn main() {
    if let Some(why) = base_rig::unavailable() {
        eprintln!("skipped: {why}");
        return;
    }
    let rates: Vec<f64> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let rates = if rates.is_empty() { vec![50.0] } else { rates };
    for hz in rates {
        measure(hz);
    }
}
