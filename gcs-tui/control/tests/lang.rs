//! Command-language executor and script runner against a real router and
//! test agents over loopback.

#![allow(clippy::unwrap_used)]

#[path = "../../core/tests/support/agent.rs"]
mod agent;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use agent::{Peer, config};
use mech_control::lang::{Executor, Span};
use mech_control::script::{self, ScriptOutcome, Sink};
use mech_core::Gcs;
use mech_proto::{Body, Command, Stop};

async fn setup() -> (Gcs, Executor, Peer) {
    let gcs = Gcs::start(config()).await.unwrap();
    let mut robot = Peer::new("robot_1", gcs.router().udp_addr()).await;
    robot.register().await;
    let exec = Executor::new(gcs.clone());
    (gcs, exec, robot)
}

#[tokio::test]
async fn route_then_wait_for_the_acknowledgement() {
    let (gcs, mut exec, mut robot) = setup().await;
    exec.execute_line("route robot_1 joy/0").await.unwrap();
    let err = exec
        .execute_line("expect route robot_1 joy/0")
        .await
        .unwrap_err();
    assert!(err.message.contains("requested joy/0"), "{err}");
    assert_eq!(
        err.span,
        Span {
            line: 1,
            column: 14
        }
    );
    assert_eq!(robot.follow_route().await, "joy/0");
    exec.execute_line("wait route robot_1 joy/0 2s")
        .await
        .unwrap();
    exec.execute_line("expect route robot_1 joy/0")
        .await
        .unwrap();
    gcs.shutdown().await;
}

#[tokio::test]
async fn wait_times_out_with_the_reason() {
    let (gcs, mut exec, _robot) = setup().await;
    let err = exec
        .execute_line("  wait connected robot_9 200ms")
        .await
        .unwrap_err();
    assert_eq!(err.span, Span { line: 1, column: 3 });
    assert!(
        err.message
            .contains("timed out after 0.2 s: robot_9 is not registered"),
        "{err}"
    );
    gcs.shutdown().await;
}

#[tokio::test]
async fn drive_goes_through_routing_and_stop_uses_the_robots_channel() {
    let (gcs, mut exec, mut robot) = setup().await;
    exec.execute_line("mode robot_1 twist").await.unwrap();
    let out = exec.execute_line("drive robot_1 0.3 0 0.1").await.unwrap();
    assert!(
        out.summary.contains("dropped (not-routed"),
        "{}",
        out.summary
    );
    exec.execute_line("expect dropped cmd/gcs 1").await.unwrap();
    exec.execute_line("route robot_1 cmd/gcs").await.unwrap();
    robot.follow_route().await;
    let out = exec.execute_line("drive robot_1 0.3 0 0.1").await.unwrap();
    assert!(out.summary.contains("forwarded"), "{}", out.summary);
    let got = robot
        .recv_matching(|e| matches!(e.body, Body::Command(_)))
        .await;
    assert_eq!(
        (got.header.sender.as_str(), got.header.channel.as_str()),
        ("gcs", "cmd/gcs")
    );
    exec.execute_line("stop all").await.unwrap();
    let got = robot
        .recv_matching(|e| matches!(e.body, Body::Command(_)))
        .await;
    assert_eq!(got.body, Body::Command(Command::Stop(Stop {})));
    gcs.shutdown().await;
}

#[tokio::test]
async fn commands_refuse_what_cannot_work_and_point_at_the_argument() {
    let (gcs, mut exec, _robot) = setup().await;
    let e = exec
        .execute_line("mode robot_1 steering-throttle")
        .await
        .unwrap_err();
    assert!(e.message.contains("cannot obey steering-throttle"), "{e}");
    let e = exec.execute_line("drive robot_1 1").await.unwrap_err();
    assert!(e.message.contains("no drive mode"), "{e}");
    let e = exec.execute_line("send robot_1").await.unwrap_err();
    assert!(e.message.contains("no waypoints"), "{e}");
    let e = exec
        .execute_line("cluster c1 robot_1 robot_9")
        .await
        .unwrap_err();
    assert_eq!(e.span.column, 20);
    let e = exec.execute_line("route ghost joy/0").await.unwrap_err();
    assert_eq!(e.span.column, 7);
    let e = exec.execute_line("spawn 2").await.unwrap_err();
    assert!(e.message.contains("not available"), "{e}");
    exec.execute_line("cluster c1 robot_1").await.unwrap();
    let out = exec.execute_line("status c1").await.unwrap();
    assert_eq!(out.details.len(), 1);
    assert!(out.details[0].starts_with("robot_1 "));
    gcs.shutdown().await;
}

/// Robots in natural order (robot_2 before robot_10), each with the link
/// the router measured from the gaps in its sequence numbers.
#[tokio::test]
async fn status_lists_robots_naturally_with_their_link_quality() {
    let (gcs, mut exec, mut robot_1) = setup().await;
    let mut robots = Vec::new();
    for name in ["robot_10", "robot_2"] {
        let mut r = Peer::new(name, gcs.router().udp_addr()).await;
        r.register().await;
        robots.push(r);
    }
    let robot_10 = &mut robots[0];
    for k in 0..5 {
        let hb = Body::Heartbeat(mech_proto::Heartbeat::new(k));
        let bytes = robot_10.encode("router", "", 10 + 2 * k as u32, hb);
        robot_10.send_raw(&bytes).await;
    }
    robot_1
        .send("router", "", Body::Heartbeat(mech_proto::Heartbeat::new(1)))
        .await;
    tokio::time::sleep(Duration::from_millis(1300)).await;
    let out = exec.execute_line("status").await.unwrap();
    let names: Vec<&str> = out
        .details
        .iter()
        .map(|l| l.split(' ').next().unwrap())
        .collect();
    assert_eq!(names, ["robot_1", "robot_2", "robot_10"]);
    assert!(out.details[0].contains(" link rx "), "{:?}", out.details);
    assert!(out.details[0].contains("loss 0.0%"), "{:?}", out.details);
    // robot_10 sent its Hello (1) and route acknowledgement (2), then
    // heartbeats 10, 12, ... 18: 7 of 18 arrived.
    assert!(out.details[2].contains("loss 61.1%"), "{:?}", out.details);
    gcs.shutdown().await;
}

#[tokio::test]
async fn send_delivers_the_waypoint_list_as_a_mission() {
    let (gcs, mut exec, robot) = setup().await;
    exec.execute_line("waypoint robot_1 1,2 3,2@15s loop")
        .await
        .unwrap();
    let sent = exec.execute_line("send robot_1").await.unwrap();
    // Routed to none: told it runs the mission only once routed, and how.
    assert_eq!(
        sent.details,
        [
            "robot_1 is routed to none: it runs the mission once routed to wp/gcs \
          (route robot_1 wp/gcs)"
        ],
        "{sent:?}"
    );
    exec.execute_line("route robot_1 wp/gcs").await.unwrap();
    let again = exec.execute_line("send robot_1").await.unwrap();
    assert!(again.details.is_empty(), "routed: no hint {again:?}");
    let env = robot
        .recv_matching(|e| matches!(e.body, Body::Mission(_)))
        .await;
    assert_eq!(env.header.channel, "wp/gcs");
    let Body::Mission(m) = env.body else {
        unreachable!()
    };
    assert!(m.looped);
    assert_eq!(m.waypoints.len(), 2);
    assert_eq!(
        (m.waypoints[1].x, m.waypoints[1].y, m.waypoints[1].time),
        (3.0, 2.0, Some(15.0))
    );
    gcs.shutdown().await;
}

#[derive(Clone, Default)]
struct Buffer(Arc<Mutex<Vec<u8>>>);

impl std::io::Write for Buffer {
    fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(b);
        Ok(b.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

#[tokio::test]
async fn the_script_runner_prints_json_and_stops_at_the_first_failure() {
    let (gcs, mut exec, _robot) = setup().await;
    let buf = Buffer::default();
    let sink: Sink = Arc::new(Mutex::new(Box::new(buf.clone())));
    let source = "log \"start\"\nroute robot_1 joy/0\nexpect link robot_1 lost\nlog \"never\"\n";
    let outcome = script::run(&gcs, &mut exec, source, sink).await;
    assert_eq!(outcome.exit_code(), 1);
    let ScriptOutcome::Failed { error, commands } = outcome else {
        panic!()
    };
    assert_eq!((error.span.line, commands), (3, 3));
    let text = String::from_utf8(buf.0.lock().unwrap().clone()).unwrap();
    let lines: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let results: Vec<_> = lines.iter().filter(|l| l["type"] == "result").collect();
    assert_eq!(results.len(), 3);
    assert_eq!(results[1]["ok"], true);
    assert_eq!(results[2]["ok"], false);
    assert!(
        results[2]["error"]
            .as_str()
            .unwrap()
            .contains("robot_1 is connected, expected lost")
    );
    let route_event = lines
        .iter()
        .position(|l| l["event"] == "route_changed")
        .unwrap();
    let route_result = lines.iter().position(|l| l["line"] == 2).unwrap();
    assert!(
        route_event < route_result,
        "a command's events print before its result"
    );
    let last = lines.last().unwrap();
    assert_eq!(
        (last["type"].as_str(), last["ok"].as_bool()),
        (Some("summary"), Some(false))
    );
    gcs.shutdown().await;
}

#[tokio::test]
async fn an_invalid_script_runs_nothing() {
    let (gcs, mut exec, _robot) = setup().await;
    let sink: Sink = Arc::new(Mutex::new(Box::new(std::io::sink())));
    let outcome = script::run(
        &gcs,
        &mut exec,
        "route robot_1 joy/0\nwait bogus robot_1\n",
        sink,
    )
    .await;
    let ScriptOutcome::Invalid(e) = &outcome else {
        panic!("{outcome:?}")
    };
    assert_eq!(e.span, Span { line: 2, column: 6 });
    assert_eq!(outcome.exit_code(), 2);
    tokio::time::sleep(Duration::from_millis(20)).await;
    assert_eq!(
        gcs.snapshot().robot("robot_1").unwrap().route.requested,
        None,
        "nothing ran"
    );
    gcs.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn record_starts_reports_and_stops_a_recording_with_the_commands_in_it() {
    let (gcs, exec, _robot) = setup().await;
    let dir = tempfile::tempdir().unwrap();
    let mut exec = exec.with_source("script");
    let status = exec.execute_line("record").await.unwrap();
    assert_eq!(status.summary, "not recording");
    let err = exec.execute_line("record start").await.unwrap_err();
    assert!(err.message.contains("record start FILE"), "{err}");
    let err = exec.execute_line("record pause").await.unwrap_err();
    assert!(
        err.message.contains("start, stop, toggle or nothing"),
        "{err}"
    );
    let file = dir.path().join("a.mcap");
    let started = exec
        .execute_line(&format!("record start {}", file.display()))
        .await
        .unwrap();
    assert!(started.summary.starts_with("recording to"), "{started:?}");
    let again = exec.execute_line("record start other.mcap").await;
    assert!(again.unwrap_err().message.contains("already recording"));
    exec.execute_line("route robot_1 joy/0").await.unwrap();
    let status = exec.execute_line("status").await.unwrap();
    assert!(status.summary.contains("; recording "), "{status:?}");
    let stopped = exec.execute_line("record stop").await.unwrap();
    assert!(stopped.summary.contains("0 dropped"), "{stopped:?}");
    assert!(exec.execute_line("record stop").await.is_err());
    gcs.shutdown().await;
    let replay = mech_core::replay::Replay::open(&file).unwrap();
    let commands: Vec<String> = replay
        .entries()
        .filter_map(|e| match e {
            mech_core::replay::Entry::Operator(o) => Some(format!("{} {}", o.source, o.text)),
            _ => None,
        })
        .collect();
    // The start is in it (recorded once it ran), and the refused second
    // start; the stop is not (the file was finished by then).
    let start = format!("script record start {}", file.display());
    assert_eq!(
        commands,
        [
            start.as_str(),
            "script record start other.mcap",
            "script route robot_1 joy/0",
            "script status"
        ]
    );
}

/// With a recording directory, `record start` writes rotating files there.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn record_start_without_a_file_uses_the_recording_directory() {
    let (gcs, exec, _robot) = setup().await;
    let dir = tempfile::tempdir().unwrap();
    let mut exec = exec.with_record_dir(dir.path().to_owned());
    let started = exec.execute_line("record start").await.unwrap();
    assert!(started.summary.contains("mech-"), "{started:?}");
    exec.execute_line("record stop").await.unwrap();
    gcs.shutdown().await;
    let files: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert_eq!(files.len(), 1);
}

/// `record toggle` (the TUI's record key) starts when not recording and
/// stops when recording.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn record_toggle_starts_then_stops() {
    let (gcs, exec, _robot) = setup().await;
    let dir = tempfile::tempdir().unwrap();
    let mut exec = exec.with_record_dir(dir.path().to_owned());
    let started = exec.execute_line("record toggle").await.unwrap();
    assert!(started.summary.starts_with("recording to "), "{started:?}");
    assert!(gcs.recording().is_some_and(|s| s.active));
    let stopped = exec.execute_line("record toggle").await.unwrap();
    assert!(stopped.summary.starts_with("stopped: "), "{stopped:?}");
    assert!(!gcs.recording().is_some_and(|s| s.active));
    let err = exec.execute_line("record pause").await.unwrap_err();
    assert!(err.message.contains("start, stop, toggle"), "{err}");
    gcs.shutdown().await;
}

/// `wait moved` measures from where each robot was as the wait began, so a
/// script can wait for a controller to drive a robot however late the
/// controller starts; it times out saying how far the robot got.
#[tokio::test]
async fn wait_moved_holds_once_the_robot_is_farther_than_the_distance() {
    let (gcs, mut exec, mut robot) = setup().await;
    robot
        .send_telemetry(agent::telemetry(1.0, 2.0, "", None))
        .await;
    let at = |x: f64| {
        move |f: &mech_core::fleet::Fleet| {
            f.robot("robot_1").is_some_and(|r| r.telemetry.pose.x == x)
        }
    };
    assert!(agent::eventually(Duration::from_secs(10), || gcs.with_fleet(at(1.0))).await);
    let err = exec
        .execute_line("wait moved robot_1 0.5 200ms")
        .await
        .unwrap_err();
    assert!(
        err.message.contains("robot_1 moved 0.000 m of 0.5 m"),
        "{err}"
    );

    // The robot creeps on in 0.1 m steps until the wait is over: wherever
    // it was as the wait began, it is more than 0.5 m on five steps later.
    let done = std::sync::atomic::AtomicBool::new(false);
    let (waited, moved_to) = tokio::join!(
        async {
            let out = exec.execute_line("wait moved robot_1 0.5 30s").await;
            done.store(true, std::sync::atomic::Ordering::SeqCst);
            out
        },
        async {
            let mut x = 1.0;
            while !done.load(std::sync::atomic::Ordering::SeqCst) && x < 20.0 {
                x += 0.1;
                robot
                    .send_telemetry(agent::telemetry(x, 2.0, "", None))
                    .await;
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
            x
        }
    );
    let out = waited.unwrap();
    assert!(out.summary.starts_with("after "), "{}", out.summary);
    assert!(moved_to > 1.45, "the wait held at x = {moved_to:.2}");
    gcs.shutdown().await;
}
