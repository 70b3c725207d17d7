//! Fleet safety in the command language, against a real router and a test
//! agent over loopback: `arena` shows, loads (with located mistakes) and
//! clears the arena; `safety off` sends a robot its arena switched off and
//! makes it an alarm in `status` and in a script's summary; `wait` and
//! `expect safety` read what robots report; the script prints the safety
//! events.

#![allow(clippy::unwrap_used)]

#[path = "../../core/tests/support/agent.rs"]
mod agent;

use std::sync::{Arc, Mutex};

use agent::{Peer, config, telemetry};
use mech_control::lang::Executor;
use mech_control::script::{self, Sink};
use mech_core::Gcs;
use mech_proto::{ArenaAck, Body, Intervention, InterventionCounts, SafetyReport, SafetyState};

async fn setup() -> (Gcs, Executor, Peer) {
    let gcs = Gcs::start(config()).await.unwrap();
    let mut robot = Peer::new("robot_1", gcs.router().udp_addr()).await;
    robot.register().await;
    let exec = Executor::new(gcs.clone());
    (gcs, exec, robot)
}

/// The next arena `robot` is sent, acknowledged.
async fn take_arena(robot: &mut Peer) -> mech_proto::Arena {
    let env = robot
        .recv_matching(|e| matches!(e.body, Body::Arena(_)))
        .await;
    let Body::Arena(a) = env.body else {
        unreachable!()
    };
    let ack = ArenaAck {
        robot: a.robot.clone(),
        id: a.id,
    };
    robot
        .send(mech_proto::ROUTER, "", Body::ArenaAck(ack))
        .await;
    a
}

/// Telemetry saying the robot's layer is `state`, limiting for `why`.
async fn report(robot: &mut Peer, state: SafetyState, why: Intervention, fence: u32) {
    let mut t = telemetry(1.0, 1.0, "", None);
    t.safety = Some(SafetyReport {
        state,
        arena: 1,
        intervention: why,
        counts: InterventionCounts {
            fence,
            ..InterventionCounts::default()
        },
        radius: 0.15,
        position_error: 0.0,
    });
    robot.send_telemetry(t).await;
}

#[tokio::test]
async fn arena_shows_loads_and_clears_the_arena() {
    let (gcs, mut exec, mut robot) = setup().await;
    let none = exec.execute_line("arena").await.unwrap();
    assert!(none.summary.starts_with("no arena"), "{none:?}");
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("lab.toml");
    std::fs::write(
        &file,
        "boundary = [[0, 0], [5, 0], [5, 4], [0, 4]]\nkeep_out = [[[2, 2], [3, 2], [3, 3]]]\n",
    )
    .unwrap();
    let loaded = exec
        .execute_line(&format!("arena load {}", file.display()))
        .await
        .unwrap();
    assert!(
        loaded.summary.contains("4 vertices, 1 keep-out"),
        "{loaded:?}"
    );
    let a = take_arena(&mut robot).await;
    assert_eq!(
        (a.boundary.len(), a.keep_out.len(), a.enabled),
        (4, 1, true)
    );
    let shown = exec.execute_line("arena").await.unwrap();
    assert!(shown.summary.contains("5.00 m x 4.00 m"), "{shown:?}");
    std::fs::write(&file, "boundary = [[0, 0], [5, 0]]\n").unwrap();
    let err = exec
        .execute_line(&format!("arena load {}", file.display()))
        .await
        .unwrap_err();
    assert!(
        err.message.contains("lab.toml:1:12: arena.boundary"),
        "{err}"
    );
    assert_eq!(err.span.column, 12, "at the file name");
    let err = exec.execute_line("arena paint").await.unwrap_err();
    assert!(err.message.contains("load FILE, demo or clear"), "{err}");
    exec.execute_line("arena clear").await.unwrap();
    assert!(take_arena(&mut robot).await.is_empty());
    exec.execute_line("arena demo").await.unwrap();
    assert_eq!(take_arena(&mut robot).await.boundary.len(), 4);
    gcs.shutdown().await;
}

#[tokio::test]
async fn safety_off_is_sent_and_is_an_alarm_in_status_and_the_summary() {
    let (gcs, mut exec, mut robot) = setup().await;
    exec.execute_line("arena demo").await.unwrap();
    take_arena(&mut robot).await;
    report(&mut robot, SafetyState::On, Intervention::Fence, 2).await;
    exec.execute_line("wait safety robot_1 on 3s")
        .await
        .unwrap();
    let status = exec.execute_line("status robot_1").await.unwrap();
    let line = &status.details[0];
    assert!(
        line.contains(" safety on limiting fence interventions fence 2"),
        "{line}"
    );
    assert!(status.summary.contains("; arena 4 vertices"), "{status:?}");
    assert!(!status.summary.contains("SAFETY OFF"), "{status:?}");
    let err = exec.execute_line("safety maybe robot_1").await.unwrap_err();
    assert!(err.message.contains("on or off"), "{err}");
    let out = exec.execute_line("safety off robot_1").await.unwrap();
    assert!(out.summary.starts_with("safety OFF for robot_1"), "{out:?}");
    let a = take_arena(&mut robot).await;
    assert!(!a.enabled, "sent switched off");
    // Requested, not yet reported: already an alarm.
    let status = exec.execute_line("status").await.unwrap();
    assert!(
        status.details[0].contains("safety OFF requested (alarm)"),
        "{status:?}"
    );
    assert!(
        status.summary.contains("; SAFETY OFF robot_1"),
        "{status:?}"
    );
    report(&mut robot, SafetyState::Off, Intervention::None, 2).await;
    exec.execute_line("wait safety robot_1 off 3s")
        .await
        .unwrap();
    exec.execute_line("expect safety robot_1 off")
        .await
        .unwrap();
    let err = exec
        .execute_line("expect safety robot_1 on")
        .await
        .unwrap_err();
    assert!(
        err.message
            .contains("robot_1 reports safety off, expected on"),
        "{err}"
    );
    // A script's summary says so too.
    let buf = Buffer::default();
    let sink: Sink = Arc::new(Mutex::new(Box::new(buf.clone())));
    let outcome = script::run(&gcs, &mut exec, "safety on robot_1\n", sink).await;
    assert_eq!(outcome.exit_code(), 0);
    let lines = buf.lines();
    let summary = lines.last().unwrap();
    assert_eq!(summary["safety"]["arena"], true);
    assert_eq!(summary["safety"]["interventions"]["fence"], 2);
    let switched = lines
        .iter()
        .find(|l| l["event"] == "safety_switched")
        .unwrap();
    assert_eq!(
        (&switched["robot"], &switched["enabled"]),
        (&"robot_1".into(), &true.into())
    );
    // Switched on again but the robot still reports off: still an alarm.
    assert_eq!(summary["safety"]["off"][0], "robot_1");
    gcs.shutdown().await;
}

#[tokio::test]
async fn the_script_prints_what_robots_report_of_their_layer() {
    let (gcs, mut exec, mut robot) = setup().await;
    let buf = Buffer::default();
    let sink: Sink = Arc::new(Mutex::new(Box::new(buf.clone())));
    let run = tokio::spawn({
        let gcs = gcs.clone();
        async move {
            let source = "arena demo\nwait safety robot_1 on 5s\n";
            script::run(&gcs, &mut exec, source, sink).await
        }
    });
    take_arena(&mut robot).await;
    report(&mut robot, SafetyState::On, Intervention::Separation, 0).await;
    assert_eq!(run.await.unwrap().exit_code(), 0);
    let lines = buf.lines();
    let arena = lines.iter().find(|l| l["event"] == "arena").unwrap();
    assert_eq!(
        (&arena["arena"], &arena["vertices"]),
        (&true.into(), &4.into())
    );
    assert_eq!(arena["bounds"], serde_json::json!([0.0, 0.0, 3.9, 2.8]));
    let safety = lines.iter().find(|l| l["event"] == "safety").unwrap();
    assert_eq!(
        (&safety["state"], &safety["intervention"]),
        (&"on".into(), &"separation".into())
    );
    assert!(lines.iter().any(|l| l["event"] == "arena_acked"));
    gcs.shutdown().await;
}

#[derive(Clone, Default)]
struct Buffer(Arc<Mutex<Vec<u8>>>);

impl Buffer {
    fn lines(&self) -> Vec<serde_json::Value> {
        let text = String::from_utf8(self.0.lock().unwrap().clone()).unwrap();
        text.lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect()
    }
}

impl std::io::Write for Buffer {
    fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(b);
        Ok(b.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}
