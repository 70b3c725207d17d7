//! The Python client package end to end: its own tests, its encoder and
//! decoder against mech-proto byte for byte, and its two examples driving
//! simulated robots through a real `mech-gcs --script`: go-to-goal against
//! a station that requires keys (signing, station time, router-signed
//! telemetry), leader-follower unsigned, as against `mech-gcs --demo`.

use mech_proto::{
    Actuators, Body, ChannelInfo as Channel, Channels, Command as Cmd, Computation, ControlMode,
    Envelope, FailsafeState, FleetCommand, Health, Mission, MissionAck, MissionProgress, Notice,
    NoticeCode, Pose, RobotCommand, Stop, Subscribe, Telemetry, Time, TimeRequest, Twist, Velocity,
    VelocityHeading, VelocitySource, Waypoint,
};

use std::time::{Duration, Instant};

use crate::station::{Station, header, observe_timed, pose_in, python, root, run_ok};

#[test]
fn the_python_package_passes_its_own_tests() {
    let mut c = python();
    c.args(["-m", "unittest", "discover", "-s"])
        .arg(root().join("clients/python/tests"));
    run_ok(c, "python3 -m unittest");
}

/// Python builds these messages with `mech_client`; mech-proto builds the
/// same envelopes here; the bytes must agree exactly.
const PYTHON_ENCODES: &str = r#"
from mech_client import protocol as p
def env(kind, body, sender="py", destination="robot_1", channel="ext/python"):
    return p.encode(p.envelope(kind, body, seq=9, stamp_us=1_700_000_000_000_000,
                               sender=sender, destination=destination, channel=channel)).hex()
print(env(p.Kind.COMMAND, p.command_body(p.twist(0.3, -0.1, 0.05, 1.25))))
print(env(p.Kind.COMMAND, p.command_body(p.velocity_heading(-0.2, 3.0))))
print(env(p.Kind.COMMAND, p.command_body(p.actuators([0.5, -1, 0]))))
print(env(p.Kind.COMMAND, p.command_body(p.stop())))
print(env(p.Kind.FLEET_COMMAND, [[["robot_1", p.command_body(p.twist(0.1))],
                                  ["robot_2", p.command_body(p.stop())]]], destination="router"))
print(env(p.Kind.MISSION, p.mission_body(4_000_000_000, [p.Waypoint(1.0, 2.0), p.Waypoint(0.5, -1.5, 0.25, 12.5)],
                                         looped=True, arrival_radius=0.15, start_index=1), channel="wp/python"))
print(env(p.Kind.SUBSCRIBE, [True], destination="router", channel=""))
print(env(p.Kind.CHANNELS_REQUEST, [], destination="router", channel=""))
print(env(p.Kind.TIME_REQUEST, [2**64 - 1], destination="router", channel=""))
"#;

/// What [`PYTHON_ENCODES`] writes, built with mech-proto, in its order.
fn encoded_by_python() -> Vec<Envelope> {
    let twist = |vx| {
        Cmd::Twist(Twist {
            vx,
            ..Twist::default()
        })
    };
    let ext = |body| Envelope::new(header("py", "robot_1", "ext/python"), body);
    let to_router = |channel: &str, body| Envelope::new(header("py", "router", channel), body);
    vec![
        ext(Body::Command(Cmd::Twist(Twist {
            vx: 0.3,
            vy: -0.1,
            vz: 0.05,
            wz: 1.25,
        }))),
        ext(Body::Command(Cmd::VelocityHeading(VelocityHeading {
            speed: -0.2,
            heading: 3.0,
        }))),
        ext(Body::Command(Cmd::Actuators(Actuators {
            outputs: vec![0.5, -1.0, 0.0],
        }))),
        ext(Body::Command(Cmd::Stop(Stop {}))),
        to_router(
            "ext/python",
            Body::FleetCommand(FleetCommand {
                parts: vec![
                    RobotCommand {
                        robot: "robot_1".into(),
                        command: twist(0.1),
                    },
                    RobotCommand {
                        robot: "robot_2".into(),
                        command: Cmd::Stop(Stop {}),
                    },
                ],
            }),
        ),
        Envelope::new(
            header("py", "robot_1", "wp/python"),
            Body::Mission(Mission {
                id: 4_000_000_000,
                waypoints: vec![
                    Waypoint {
                        x: 1.0,
                        y: 2.0,
                        z: 0.0,
                        time: None,
                    },
                    Waypoint {
                        x: 0.5,
                        y: -1.5,
                        z: 0.25,
                        time: Some(12.5),
                    },
                ],
                looped: true,
                arrival_radius: 0.15,
                start_index: 1,
            }),
        ),
        to_router("", Body::Subscribe(Subscribe { telemetry: true })),
        to_router("", Body::ChannelsRequest(mech_proto::ChannelsRequest {})),
        to_router("", Body::TimeRequest(TimeRequest { nonce: u64::MAX })),
    ]
}

#[test]
fn the_python_encoder_agrees_with_mech_proto_byte_for_byte() {
    let expected = encoded_by_python();
    let mut c = python();
    c.args(["-c", PYTHON_ENCODES]);
    let out = run_ok(c, "python3 with mech_client");
    let text = String::from_utf8(out.stdout).unwrap();
    let got: Vec<&str> = text.lines().collect();
    assert_eq!(got.len(), expected.len(), "{text}");
    for (i, (py, env)) in got.iter().zip(&expected).enumerate() {
        let rust: String = mech_proto::encode(env)
            .unwrap()
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
        assert_eq!(*py, rust, "message {i}: {:?}", env.body);
    }
}

/// One message of each kind the Python decoder reads from a station.
fn decoded_by_python() -> [Body; 5] {
    let telemetry = Telemetry {
        pose: Pose {
            x: 1.5,
            y: -0.25,
            z: 2.0,
            heading: 0.75,
        },
        velocity: Velocity {
            vx: 0.1,
            vy: 0.2,
            vz: -0.3,
            wz: 0.4,
        },
        mode: ControlMode::Waypoints,
        channel: "wp/gcs".into(),
        computation: Computation::Offboard,
        failsafe: FailsafeState::ChannelSilent,
        health: Health::Degraded,
        battery: Some(0.5),
        position_quality: 0.9,
        actuators: vec![0.25, -0.5],
        mission: Some(MissionProgress {
            id: 7,
            next: 2,
            total: 3,
        }),
        stale: 4,
        velocity_source: VelocitySource::Measured,
        safety: None,
    };
    [
        Body::Telemetry(telemetry),
        Body::Channels(Channels {
            channels: vec![Channel {
                name: "ext/python".into(),
                publisher: "py".into(),
                rate_hz: 19.5,
                robots: vec!["robot_1".into()],
                idle_ms: 12,
            }],
        }),
        Body::MissionAck(MissionAck {
            id: 4_000_000_000,
            accepted: false,
            reason: "no position".into(),
        }),
        Body::Time(Time {
            nonce: u64::MAX,
            station_us: 1_700_000_000_000_001,
        }),
        Body::Notice(Notice {
            level: mech_proto::Level::Warn,
            code: NoticeCode::NotRouted,
            text: "robot_1 obeys \"\"".into(),
        }),
    ]
}

#[test]
fn the_python_decoder_reads_what_mech_proto_writes() {
    let hex: Vec<String> = decoded_by_python()
        .into_iter()
        .map(|b| {
            mech_proto::encode(&Envelope::new(header("robot_1", "py", ""), b))
                .unwrap()
                .iter()
                .map(|b| format!("{b:02x}"))
                .collect()
        })
        .collect();
    let script = format!(
        "import sys\nfrom mech_client import protocol as p\n\
         for h in {hex:?}:\n    print(repr(p.decode(bytes.fromhex(h)).body))\n"
    );
    let mut c = python();
    c.args(["-c", &script]);
    let out = run_ok(c, "python3 with mech_client");
    let text = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 5, "{text}");
    for (line, wanted) in lines.iter().zip([
        &[
            "x=1.5, y=-0.25, z=2.0, heading=0.75",
            "vx=0.1, vy=0.2, vz=-0.3, wz=0.4",
            "mode=<ControlMode.WAYPOINTS: 5>",
            "channel='wp/gcs', offboard=True",
            "failsafe=<FailsafeState.CHANNEL_SILENT: 1>, health=<Health.DEGRADED: 1>",
            "battery=0.5, position_quality=0.9, actuators=[0.25, -0.5]",
            "mission=MissionProgress(id=7, next=2, total=3), stale=4, measured=True",
        ][..],
        &["name='ext/python', publisher='py', rate_hz=19.5, robots=['robot_1'], idle_ms=12"],
        &["MissionAck(id=4000000000, accepted=False, reason='no position')"],
        &["Time(nonce=18446744073709551615, station_us=1700000000000001)"],
        &["level=<Level.WARN: 2>, code=3, text='robot_1 obeys \"\"'"],
    ]) {
        for w in wanted {
            assert!(line.contains(w), "{line}\nlacks {w}");
        }
    }
}

#[test]
fn go_to_goal_signs_and_drives_a_simulated_robot_to_its_goal() {
    let goal = (1.0, 2.2);
    let script = format!(
        "spawn 1\nwait connected robot_1 10s\nroute robot_1 ext/python\n\
         wait route robot_1 ext/python 5s\nstatus robot_1\nlog go\n\
         wait near robot_1 {},{} 0.15 60s\nsleep 500ms\nstatus robot_1\n",
        goal.0, goal.1
    );
    let mut station = Station::start(
        &script,
        &[(
            "python",
            "role = \"controller\"\nchannels = [\"ext/python\"]",
        )],
    );
    station.until("\"summary\":\"go\"");
    let mut c = python();
    c.arg(root().join("clients/python/examples/go_to_goal.py"))
        .args(["robot_1", &goal.0.to_string(), &goal.1.to_string()])
        .args(["--router", &station.router(), "--timeout", "45", "--key"])
        .arg(station.key("python"));
    let out = run_ok(c, "go_to_goal.py");
    let report = String::from_utf8_lossy(&out.stdout);
    assert!(report.contains("\"arrived\": true"), "{report}");
    let (lines, ok) = station.finish();
    assert!(ok, "the station's script failed: {lines:#?}");
    let start = pose_in(&lines, "robot_1", 0);
    let end = pose_in(&lines, "robot_1", 1);
    let error = (end.0 - goal.0).hypot(end.1 - goal.1);
    assert!(
        (start.0 - goal.0).hypot(start.1 - goal.1) > 1.0,
        "the robot started at the goal: {start:?}"
    );
    assert!(
        error < 0.15,
        "robot_1 ended {error:.2} m from the goal: {end:?}"
    );
    let summary = lines.last().unwrap();
    assert!(summary.contains("\"authenticated\":true"), "{summary}");
}

#[test]
fn leader_follower_keeps_the_follower_behind_the_leader() {
    let offset = 0.6;
    let script = "spawn 2\nwait connected robot_1 10s\nwait connected robot_2 10s\n\
                  route robot_1 ext/python\nroute robot_2 ext/python\n\
                  wait route robot_1 ext/python 5s\nwait route robot_2 ext/python 5s\n\
                  log go\nsleep 120s\n";
    let mut station = Station::start(script, &[]);
    station.until("\"summary\":\"go\"");
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let observer = {
        let (router, stop) = (station.router(), stop.clone());
        std::thread::spawn(move || observe_timed(router, stop))
    };
    let mut c = python();
    c.arg(root().join("clients/python/examples/leader_follower.py"))
        .args(["robot_1", "robot_2", "--seconds", "25"])
        .args([
            "--offset",
            &offset.to_string(),
            "--router",
            &station.router(),
        ]);
    let out = run_ok(c, "leader_follower.py");
    let ended = Instant::now();
    stop.store(true, std::sync::atomic::Ordering::SeqCst);
    let track = observer.join().unwrap();
    station.child.kill().ok();
    station.child.wait().ok();
    let report = String::from_utf8_lossy(&out.stdout).to_string();
    let pose = |t: &mech_proto::Telemetry| (t.pose.x, t.pose.y, t.pose.heading);
    let (leader, follower) = (&track["robot_1"], &track["robot_2"]);
    // The leader went round its circle: a path of metres, ending near where
    // it started a lap earlier or later, and never far from its centre.
    let path: f64 = leader
        .windows(2)
        .map(|w| {
            let (a, b) = (pose(&w[0].1), pose(&w[1].1));
            (b.0 - a.0).hypot(b.1 - a.1)
        })
        .sum();
    assert!(path > 2.0, "the leader drove only {path:.2} m: {report}");
    // Over the program's last 5 s of driving, the follower kept its slot,
    // `offset` behind the leader.
    let window = (
        ended - Duration::from_secs(6),
        ended - Duration::from_secs(1),
    );
    let pairs = paired(leader, follower, window);
    assert!(
        pairs.len() > 50,
        "{} pairs of samples in the last 5 s ({} leader, {} follower samples in all): {report}",
        pairs.len(),
        leader.len(),
        follower.len()
    );
    let (mean, behind) = tracking(&pairs, offset);
    // The slot circles 0.78 m from the centre of the leader's circle, so a
    // follower that did not follow is 0.78 m from it on average or more;
    // one following is within 0.2 m on a quiet machine, 0.31 m seen on a
    // busy one (the program's loop is late).
    assert!(
        mean < 0.45,
        "the follower was {mean:.2} m from its slot on average over {} samples: {report}",
        pairs.len()
    );
    assert!(
        behind * 10 > pairs.len() * 9,
        "the follower was behind the leader {behind} of {} times: {report}",
        pairs.len()
    );
    assert!(report.contains("\"mean_error\""), "{report}");
}

type Pose2 = (f64, f64, f64);

/// Each follower sample that arrived within `window` with the leader
/// sample that arrived nearest to it, if within 60 ms (by the observer's
/// clock: the two robots' counts differ when it was late or a datagram was
/// lost, so the n-th samples of each are not of one moment).
fn paired(
    leader: &[(Instant, Telemetry)],
    follower: &[(Instant, Telemetry)],
    window: (Instant, Instant),
) -> Vec<(Pose2, Pose2)> {
    let pose = |t: &Telemetry| (t.pose.x, t.pose.y, t.pose.heading);
    let apart = |a: &Instant, b: &Instant| a.max(b).duration_since(*a.min(b));
    follower
        .iter()
        .filter(|(at, _)| *at >= window.0 && *at <= window.1)
        .filter_map(|(at, f)| {
            let (when, l) = leader.iter().min_by_key(|(t, _)| apart(t, at))?;
            (apart(when, at) < Duration::from_millis(60)).then(|| (pose(l), pose(f)))
        })
        .collect()
}

/// The follower's mean distance from its slot, `offset` behind the
/// leader, and how many times it was behind the leader.
fn tracking(pairs: &[(Pose2, Pose2)], offset: f64) -> (f64, usize) {
    let error = |(l, f): &(Pose2, Pose2)| {
        let slot = (l.0 - offset * l.2.cos(), l.1 - offset * l.2.sin());
        (f.0 - slot.0).hypot(f.1 - slot.1)
    };
    let mean = pairs.iter().map(error).sum::<f64>() / pairs.len().max(1) as f64;
    let behind = pairs
        .iter()
        .filter(|(l, f)| (f.0 - l.0) * l.2.cos() + (f.1 - l.1) * l.2.sin() < 0.0)
        .count();
    (mean, behind)
}

/// A mission and channel discovery through the package's own calls.
const MISSION_AND_CHANNELS: &str = r#"
import json, sys
from mech_client import Client, Waypoint
with Client("py_planner", sys.argv[1]) as mech:
    ack = mech.send_mission("robot_1", "wp/python", [Waypoint(2.6, 0.8), Waypoint(1.0, 2.0)],
                            arrival_radius=0.1)
    channels = {c.name: c.robots for c in mech.channels()}
    t = mech.wait_telemetry("robot_1")
    print(json.dumps({"accepted": ack.accepted, "channels": channels, "mode": t.mode.name}))
"#;

#[test]
fn a_python_client_sends_a_mission_and_discovers_the_channel() {
    let script = "spawn 1\nwait connected robot_1 10s\nroute robot_1 wp/python\n\
                  wait route robot_1 wp/python 5s\nlog go\n\
                  wait near robot_1 1.0,2.0 0.15 60s\nstatus robot_1\n";
    let mut station = Station::start(script, &[]);
    station.until("\"summary\":\"go\"");
    let mut c = python();
    c.args(["-c", MISSION_AND_CHANNELS, &station.router()]);
    let out = run_ok(c, "python3 with mech_client");
    let report = String::from_utf8_lossy(&out.stdout);
    assert!(report.contains("\"accepted\": true"), "{report}");
    assert!(
        report.contains("\"wp/python\": [\"robot_1\"]"),
        "the channel lists its robot: {report}"
    );
    assert!(report.contains("\"mode\": \"WAYPOINTS\""), "{report}");
    let (lines, ok) = station.finish();
    assert!(ok, "robot_1 did not reach the last waypoint: {lines:#?}");
}

/// A mission on a channel the key does not list, then one on its own.
const REFUSED_MISSION: &str = r#"
import json, sys
from mech_client import Client, Waypoint
with Client.from_key_file(sys.argv[1], sys.argv[2]) as mech:
    for channel in ("wp/gcs", "wp/python"):
        ack = mech.send_mission("robot_1", channel, [Waypoint(1.0, 1.0)], timeout=3.0)
        print(json.dumps({"channel": channel, "accepted": ack.accepted, "reason": ack.reason}))
"#;

/// A signed controller whose mission the station's permissions refuse
/// learns why at once, in the robot's answer (`docs/external-controllers.md`),
/// where it used to wait out its timeout for an answer that never came.
#[test]
fn a_mission_its_key_may_not_send_comes_back_refused_with_why() {
    let script = "spawn 1\nwait connected robot_1 10s\nlog go\nsleep 30s\n";
    let mut station = Station::start(
        script,
        &[(
            "python",
            "role = \"controller\"\nchannels = [\"wp/python\"]",
        )],
    );
    station.until("\"summary\":\"go\"");
    let mut c = python();
    c.args(["-c", REFUSED_MISSION])
        .arg(station.key("python"))
        .arg(station.router());
    let out = run_ok(c, "python3 with mech_client");
    station.child.kill().ok();
    station.child.wait().ok();
    let report = String::from_utf8_lossy(&out.stdout);
    let lines: Vec<&str> = report.lines().collect();
    assert_eq!(lines.len(), 2, "{report}");
    assert_eq!(
        lines[0],
        r#"{"channel": "wp/gcs", "accepted": false, "reason": "refused by the station: controller python may not publish on \"wp/gcs\""}"#
    );
    assert!(
        lines[1].starts_with(r#"{"channel": "wp/python", "accepted": true"#),
        "{report}"
    );
}

/// A `mech-gcs serve --demo N` for the headless recipe, stopped on drop.
struct Served {
    child: std::process::Child,
    socket: std::path::PathBuf,
    router: String,
    dir: tempfile::TempDir,
}

impl Served {
    fn start(robots: usize) -> Served {
        use std::io::BufRead;
        let dir = tempfile::tempdir().unwrap();
        let socket = dir.path().join("gcs.sock");
        let mut child = std::process::Command::new(mech_e2e::binary("mech-gcs"))
            .args(["serve", "--demo", &robots.to_string()])
            .args(["--udp", "127.0.0.1:0", "--tcp", "127.0.0.1:0", "--socket"])
            .arg(&socket)
            .env("XDG_STATE_HOME", dir.path())
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::null())
            .spawn()
            .expect("mech-gcs serve starts");
        let out = child.stdout.take().expect("stdout piped");
        let mut lines = std::io::BufReader::new(out).lines();
        let ready = lines
            .next()
            .and_then(Result::ok)
            .expect("mech-gcs serve prints a ready line");
        std::thread::spawn(move || for _ in lines {});
        let router = ready
            .split("router on ")
            .nth(1)
            .and_then(|rest| rest.split_whitespace().next())
            .unwrap_or_else(|| panic!("no router address in {ready:?}"))
            .to_string();
        Served {
            child,
            socket,
            router,
            dir,
        }
    }

    /// `mech-gcs --attach SOCKET --script -` with `script`: its output.
    fn attach_script(&self, script: &str) -> std::process::Output {
        use std::io::Write;
        let mut child = std::process::Command::new(mech_e2e::binary("mech-gcs"))
            .arg("--attach")
            .arg(&self.socket)
            .args(["--script", "-"])
            .env("XDG_STATE_HOME", self.dir.path())
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .expect("mech-gcs --attach --script starts");
        child
            .stdin
            .take()
            .expect("stdin")
            .write_all(script.as_bytes())
            .expect("script written");
        child.wait_with_output().expect("the script ends")
    }
}

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Telemetry of `robot` from `router` (unauthenticated) until it is more
/// than `metres` from where it was first heard; panics after `timeout`.
/// The subscription is renewed every second: it lapses after 5 s unheard
/// (`router.subscriber_timeout`), and a client slow to start on a loaded
/// machine may take longer than that to move the robot.
fn wait_until_moving(router: &str, robot: &str, metres: f64, timeout: std::time::Duration) {
    let socket = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    socket
        .set_read_timeout(Some(std::time::Duration::from_millis(100)))
        .unwrap();
    let subscribe = mech_proto::encode(&Envelope::new(
        header("watcher", "router", ""),
        Body::Subscribe(Subscribe { telemetry: true }),
    ))
    .unwrap();
    let start = std::time::Instant::now();
    let mut renewed: Option<std::time::Instant> = None;
    let mut first: Option<(f64, f64)> = None;
    let (mut heard, mut farthest) = (0, 0.0f64);
    let mut buf = vec![0; 65_536];
    while start.elapsed() < timeout {
        if renewed.is_none_or(|t| t.elapsed() >= std::time::Duration::from_secs(1)) {
            socket.send_to(&subscribe, router).unwrap();
            renewed = Some(std::time::Instant::now());
        }
        let Ok(n) = socket.recv(&mut buf) else {
            continue;
        };
        if let Ok(Envelope {
            header,
            body: Body::Telemetry(t),
            ..
        }) = mech_proto::decode(&buf[..n])
        {
            if header.sender != robot {
                continue;
            }
            let (x0, y0) = *first.get_or_insert((t.pose.x, t.pose.y));
            let d = (t.pose.x - x0).hypot(t.pose.y - y0);
            if d > metres {
                return;
            }
            heard += 1;
            farthest = farthest.max(d);
        }
    }
    panic!(
        "{robot} did not move {metres} m within {timeout:?} \
         ({heard} telemetry samples heard, farthest {farthest:.3} m)"
    );
}

/// The headless recipe of `docs/external-controllers.md`: `mech-gcs serve
/// --demo 1` stays up, a script attached to it routes robot_1 to the
/// client's channel and leaves (the route stays), go_to_goal.py drives it
/// there. Then, while go_to_goal.py drives it again, the station is killed
/// under it: the client stops with the reason (exit 3) instead of driving
/// blind until its timeout (exit 1).
#[test]
fn headless_serve_attach_route_and_drive_and_a_station_gone_is_not_driven_blind() {
    let mut served = Served::start(1);
    let router = served.router.clone();
    let routed = served.attach_script(
        "wait connected robot_1 10s\nroute robot_1 ext/python\nwait route robot_1 ext/python 5s\n",
    );
    assert!(
        routed.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&routed.stdout),
        String::from_utf8_lossy(&routed.stderr)
    );
    let go = |x: f64, y: f64| {
        let mut c = python();
        c.arg(root().join("clients/python/examples/go_to_goal.py"))
            .args(["robot_1", &x.to_string(), &y.to_string()])
            .args(["--router", &router, "--timeout", "45"]);
        c
    };
    let out = run_ok(go(2.0, 2.2), "go_to_goal.py after the attached script left");
    let report = String::from_utf8_lossy(&out.stdout);
    assert!(report.contains("\"arrived\": true"), "{report}");

    let driving = go(0.4, 0.3)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("go_to_goal.py starts");
    wait_until_moving(
        &served.router,
        "robot_1",
        0.1,
        std::time::Duration::from_secs(30),
    );
    served.child.kill().expect("the station killed");
    served.child.wait().ok();
    let out = driving.wait_with_output().expect("go_to_goal.py ends");
    let report = String::from_utf8_lossy(&out.stdout);
    assert_eq!(
        out.status.code(),
        Some(3),
        "{report}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        report.contains("\"arrived\": false")
            && (report.contains("port unreachable") || report.contains("s old")),
        "{report}"
    );
}
