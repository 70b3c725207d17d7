//! The MAVLink platform end to end: a real `mech-agent` with an
//! `[autopilot]` section flying a fake PX4 written with pymavlink
//! (`fake_autopilot.py`), registered with a real `mech-gcs --script`.
//! Checks the heartbeat exchange, that nothing is armed or switched
//! before the operator's `autopilot` commands, the setpoints' frame, type
//! mask and signs, the autopilot's position, heading, velocity and battery
//! mapped back into MECH's frame, and the zero-velocity hold when the
//! controller goes quiet and on e-stop.

use std::collections::HashMap;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::thread::JoinHandle;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use mech_proto::Telemetry;
use serde_json::Value;

use crate::station::{Station, free_port, observe_telemetry, root};

fn now() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_secs_f64()
}

/// Drives `drone` forward at 0.5 m/s, climbing 0.1 m/s and turning left
/// 0.2 rad/s, for 3 s (a command every 200 ms keeps its failsafe quiet).
fn drive_for_three_seconds() -> String {
    "drive drone 0.5 0 0.1 0.2\nsleep 200ms\n".repeat(15)
}

/// What one flight left: the station's output, the fake autopilot's
/// events, the telemetry the router forwarded, and when each phase of the
/// script began (wall-clock seconds, as the fake stamps its events).
struct Flight {
    lines: Vec<String>,
    events: Vec<Value>,
    telemetry: HashMap<String, Vec<Telemetry>>,
    /// When the test read the script's `before-arming` line (the script
    /// arms 1.5 s after printing it, so reading it may be that late before
    /// a command counts as early).
    before_arming: f64,
    driving: f64,
    holding: f64,
    /// The station's output and the agent's log, for failure messages.
    context: String,
}

impl Flight {
    /// The fake autopilot's events of `kind`.
    fn of(&self, kind: &str) -> Vec<&Value> {
        self.events.iter().filter(|e| e["event"] == kind).collect()
    }
}

/// A number of an event (NaN when absent).
fn num(v: &Value, k: &str) -> f64 {
    v[k].as_f64().unwrap_or(f64::NAN)
}

/// A `mech-agent` flying the autopilot on `mavlink_port`, registered with
/// the router at `router`.
fn start_agent(dir: &Path, router: &str, mavlink_port: u16) -> Child {
    let config = dir.join("drone.toml");
    std::fs::write(
        &config,
        format!(
            "name = \"drone\"\ncontrol_rate_hz = 20.0\n\
             [platform]\nkind = \"quadcopter\"\nmax_speed = 1.0\nmax_climb = 0.5\nmax_yaw_rate = 1.0\n\
             [autopilot]\nlink = \"udpin:127.0.0.1:{mavlink_port}\"\n\
             [link]\nkind = \"udp\"\nrouter = \"{router}\"\n"
        ),
    )
    .unwrap();
    Command::new(mech_e2e::binary("mech-agent"))
        .arg("--config")
        .arg(&config)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("mech-agent starts")
}

/// The fake PX4 on `mavlink_port`, and a thread collecting the events it
/// prints until it exits; returns once the fake reported its state (it
/// does at once), so that it runs before the agent starts: Python
/// importing pymavlink took seconds on a loaded machine, and the script's
/// time before arming must see the setpoints stream.
fn start_autopilot(mavlink_port: u16) -> (Child, JoinHandle<Vec<Value>>) {
    let mut autopilot = Command::new("python3")
        .arg(root().join("tests/e2e/fake_autopilot.py"))
        .args([&mavlink_port.to_string(), "120"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("python3 runs the fake autopilot (scripts/deps.sh installs pymavlink)");
    let out = autopilot.stdout.take().unwrap();
    let (heard, running) = std::sync::mpsc::channel();
    let events = std::thread::spawn(move || {
        let mut events = Vec::new();
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            if let Ok(event) = serde_json::from_str::<Value>(&line) {
                let _ = heard.send(());
                events.push(event);
            }
        }
        events
    });
    assert!(
        running.recv_timeout(Duration::from_secs(60)).is_ok(),
        "the fake autopilot runs (it reports its state at once)"
    );
    (autopilot, events)
}

/// The operator's script: wait, arm and switch to OFFBOARD, drive, go
/// quiet, e-stop, try to arm again.
fn script() -> String {
    format!(
        "wait connected drone 60s\nsleep 1500ms\nstatus drone\nlog before-arming\nsleep 1500ms\n\
         autopilot drone arm\nautopilot drone offboard\nsleep 1s\n\
         route drone cmd/gcs\nwait route drone cmd/gcs 5s\nmode drone twist\nlog driving\n\
         {}log holding\nsleep 1500ms\nexpect failsafe drone channel-silent\nstatus drone\n\
         estop\nwait estop 5s\nautopilot drone arm\nsleep 1s\nlog done\n",
        drive_for_three_seconds()
    )
}

/// Runs the script against a real agent and the fake PX4; the script must
/// pass.
fn fly() -> Flight {
    let mavlink_port = free_port();
    let mut station = Station::start(&script(), &[]);
    let dir = tempfile::tempdir().unwrap();
    // The agent registers first and finds the autopilot at its next
    // heartbeat (1 Hz), so the station hears that too.
    let (mut autopilot, events) = start_autopilot(mavlink_port);
    let mut agent = start_agent(dir.path(), &station.router(), mavlink_port);
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let observer = {
        let (router, stop) = (station.router(), stop.clone());
        std::thread::spawn(move || observe_telemetry(router, stop))
    };
    station.until("\"summary\":\"before-arming\"");
    let before_arming = now();
    station.until("\"summary\":\"driving\"");
    let driving = now();
    station.until("\"summary\":\"holding\"");
    let holding = now();
    let (lines, ok) = station.finish();
    stop.store(true, std::sync::atomic::Ordering::SeqCst);
    let telemetry = observer.join().unwrap();
    let _ = autopilot.kill();
    let _ = autopilot.wait();
    let events = events.join().unwrap();
    let _ = agent.kill();
    let agent_log = agent
        .wait_with_output()
        .map(|o| String::from_utf8_lossy(&o.stderr).to_string())
        .unwrap_or_default();
    let context = format!("{lines:#?}\nagent: {agent_log}");
    assert!(ok, "the script failed: {context}");
    Flight {
        lines,
        events,
        telemetry,
        before_arming,
        driving,
        holding,
        context,
    }
}

#[test]
fn the_agent_flies_a_fake_px4_over_mavlink() {
    let flight = fly();
    heartbeats_both_ways(&flight);
    nothing_before_the_operator_asked(&flight);
    setpoints_while_driving(&flight);
    zero_velocity_hold(&flight);
    telemetry_in_mechs_frame(&flight);
}

fn heartbeats_both_ways(f: &Flight) {
    let context = &f.context;
    // Heartbeats both ways, MAVLink 2: the agent is an onboard controller
    // (type 18, autopilot "invalid" 8), and it found the PX4.
    let heartbeats = f.of("heartbeat");
    assert!(
        heartbeats.len() >= 5,
        "{} heartbeats: {context}",
        heartbeats.len()
    );
    assert!(heartbeats.iter().all(|h| h["type"] == 18
        && h["autopilot"] == 8
        && h["component"] == 191
        && h["mavlink2"] == true));
    assert!(
        f.lines.iter().any(|l| l.contains("autopilot found: PX4")),
        "{context}"
    );
}

fn nothing_before_the_operator_asked(f: &Flight) {
    let context = &f.context;
    // Nothing armed or switched before the operator asked: setpoints were
    // streaming (zero: the drone was routed to none) but no command came.
    let commands = f.of("command");
    let first_command = commands.first().map_or(f64::INFINITY, |c| num(c, "t"));
    assert!(
        first_command > f.before_arming,
        "a command came before the operator's: {commands:?}"
    );
    let setpoints = f.of("setpoint");
    let early: Vec<&&Value> = setpoints
        .iter()
        .filter(|s| num(s, "t") < first_command)
        .collect();
    assert!(
        early.len() > 20,
        "setpoints stream before arming: {}",
        early.len()
    );
    assert!(
        early
            .iter()
            .all(|s| num(s, "vx") == 0.0 && num(s, "vy") == 0.0 && num(s, "yaw_rate") == 0.0)
    );
    // Then arm (400, param 1) and OFFBOARD (176, custom mode, main mode 6);
    // after the e-stop the second arm was refused by the robot itself.
    let sent: Vec<(i64, Vec<f64>)> = commands
        .iter()
        .map(|c| {
            let p = c["params"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect();
            (c["command"].as_i64().unwrap(), p)
        })
        .collect();
    assert_eq!(sent.len(), 2, "{sent:?}");
    assert_eq!((sent[0].0, sent[0].1[0]), (400, 1.0));
    assert_eq!((sent[1].0, sent[1].1[0], sent[1].1[1]), (176, 1.0, 6.0));
    for accepted in [
        "autopilot accepted arm",
        "autopilot armed",
        "autopilot mode OFFBOARD",
        "e-stopped: arm refused",
    ] {
        assert!(
            f.lines.iter().any(|l| l.contains(accepted)),
            "no {accepted:?}: {context}"
        );
    }
}

fn setpoints_while_driving(f: &Flight) {
    // While driving: LOCAL_NED (1), velocity + yaw rate only (0x05c7), to
    // system 1 component 1. The drone starts facing east, so forward is
    // +east (NED y) at first and swings north as it turns left; climbing is
    // -z; a left turn is a negative NED yaw rate.
    // (A command delayed past the failsafe timeout on a loaded machine
    // would make a zero setpoint here: those are counted, not checked.)
    let window: Vec<&Value> = f
        .of("setpoint")
        .into_iter()
        .filter(|s| (f.driving + 0.3..f.holding).contains(&num(s, "t")))
        .collect();
    let flying: Vec<&Value> = window
        .iter()
        .copied()
        .filter(|s| num(s, "vx").hypot(num(s, "vy")) > 0.01)
        .collect();
    assert!(
        flying.len() > 30 && flying.len() * 10 >= window.len() * 8,
        "{} of {} setpoints while driving moved",
        flying.len(),
        window.len()
    );
    for s in &flying {
        assert_eq!(
            (s["frame"].as_i64(), s["type_mask"].as_i64()),
            (Some(1), Some(0x05c7)),
            "{s}"
        );
        assert_eq!(s["target"], serde_json::json!([1, 1]));
        assert_eq!(s["mavlink2"], true);
        let speed = num(s, "vx").hypot(num(s, "vy"));
        assert!((speed - 0.5).abs() < 0.01, "{s}");
        assert!(
            (num(s, "vz") + 0.1).abs() < 0.01 && (num(s, "yaw_rate") + 0.2).abs() < 0.01,
            "{s}"
        );
        assert!(num(s, "vy") > 0.2, "still mostly east: {s}");
    }
    let (first, last) = (flying[0], flying[flying.len() - 1]);
    assert!(
        num(first, "vx").abs() < 0.1,
        "facing east at first: {first}"
    );
    assert!(
        num(last, "vx") > num(first, "vx") + 0.1,
        "turning left, towards north: {last}"
    );
}

fn zero_velocity_hold(f: &Flight) {
    // The controller went quiet: zero-velocity hold, still streamed.
    let held: Vec<&Value> = f
        .of("setpoint")
        .into_iter()
        .filter(|s| num(s, "t") > f.holding + 0.8)
        .collect();
    assert!(held.len() > 10, "the hold is streamed: {}", held.len());
    assert!(held.iter().all(|s| num(s, "vx") == 0.0
        && num(s, "vy") == 0.0
        && num(s, "vz") == 0.0
        && num(s, "yaw_rate") == 0.0));
}

fn telemetry_in_mechs_frame(f: &Flight) {
    // Telemetry back in MECH's frame: the fake's state at the end (NED)
    // against the last telemetry (ENU), battery 87 %.
    let drone = &f.telemetry["drone"];
    // The first pose the autopilot reported (the agent registers, and
    // sends telemetry without a position, before it hears the autopilot).
    let start = drone
        .iter()
        .find(|t| t.position_quality > 0.0)
        .expect("telemetry with the autopilot's position");
    assert!(
        (start.pose.x - 2.0).abs() < 0.01 && (start.pose.y - 1.0).abs() < 0.01,
        "1 m north, 2 m east is (2, 1): {:?}",
        start.pose
    );
    assert!(
        (start.pose.z - 3.0).abs() < 0.01 && start.pose.heading.abs() < 0.01,
        "{:?}",
        start.pose
    );
    assert_eq!(drone.last().unwrap().battery, Some(0.87));
    let state = f.of("state");
    let end = state.last().unwrap();
    let t = drone.last().unwrap();
    assert!(
        (t.pose.x - num(end, "east")).abs() < 0.05 && (t.pose.y - num(end, "north")).abs() < 0.05,
        "{:?} vs {end}",
        t.pose
    );
    assert!(
        (t.pose.z + num(end, "down")).abs() < 0.05,
        "{:?} vs {end}",
        t.pose
    );
    let heading = mech_proto::wrap_angle(std::f64::consts::FRAC_PI_2 - num(end, "yaw"));
    assert!(mech_proto::wrap_angle(t.pose.heading - heading).abs() < 0.05);
    assert!(
        t.pose.x > 2.5 && t.pose.z > 3.1,
        "it flew east and up: {:?}",
        t.pose
    );
    // While driving, the velocity reported is the autopilot's (ENU), with
    // a counter-clockwise yaw rate.
    let moving = drone
        .iter()
        .find(|t| t.velocity.vx.hypot(t.velocity.vy) > 0.4)
        .expect("moving telemetry");
    assert!(
        (moving.velocity.wz - 0.2).abs() < 0.01 && (moving.velocity.vz - 0.1).abs() < 0.01,
        "{:?}",
        moving.velocity
    );
}
