//! The replay player (the station a TUI attaches to for `mech-gcs replay`)
//! on a real recording: a router on loopback
//! recorded while a test robot reported moving along x, then played back.

#![allow(clippy::unwrap_used)]

#[path = "../../core/tests/support/agent.rs"]
mod agent;

use std::path::Path;
use std::time::Duration;

use agent::{Peer, config, telemetry};
use mech_core::replay::Replay;
use mech_core::{Gcs, RecordTarget};
use mech_proto::{Command, Stop};
use mech_station::replay::player::{self, Player};
use mech_station::wire::{FromStation, ToStation};

/// Records robot_1 reporting x = 0, 1, ... 9, 50 ms apart.
async fn recording(file: &Path) {
    let gcs = Gcs::start(config()).await.unwrap();
    gcs.start_recording(RecordTarget::File(file.to_path_buf()))
        .unwrap();
    let mut robot = Peer::new("robot_1", gcs.router().udp_addr()).await;
    robot.register().await;
    for i in 0..10 {
        robot
            .send_telemetry(telemetry(f64::from(i), 1.0, "", None))
            .await;
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let counted = gcs.router().counters().received;
    agent::eventually(Duration::from_secs(5), || {
        gcs.recording().unwrap().messages >= counted
    })
    .await;
    gcs.stop_recording().await.unwrap();
    gcs.shutdown().await;
}

fn x_of(p: &Player<'_>) -> Option<f64> {
    let s = p.snapshot();
    s.robots
        .iter()
        .find(|r| r.name == "robot_1")
        .map(|r| r.telemetry.pose.x)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_player_plays_pauses_seeks_and_changes_speed() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("run.mcap");
    recording(&file).await;
    let replay = Replay::open(&file).unwrap();
    let mut p = Player::new(&replay);
    let span = p.clock().end;
    assert!(span > 0.4, "{span}");
    assert_eq!(p.clock().at, 0.0);
    assert!(!p.clock().paused);

    // Played past the end: stops there, paused, where the robot ended.
    p.advance(Duration::from_secs(60));
    assert!(p.clock().paused && p.clock().at == span, "{:?}", p.clock());
    assert_eq!(x_of(&p), Some(9.0));
    assert_eq!(p.snapshot().replay, Some(p.clock()));

    // Back to the middle: a position the robot reported on the way.
    p.command("seek 0").unwrap();
    assert_eq!(p.clock().at, 0.0);
    p.command(&format!("seek {}", span / 2.0)).unwrap();
    let middle = x_of(&p).unwrap();
    assert!(middle > 0.0 && middle < 9.0, "{middle}");

    // Relative seeks, clamped to the recording.
    p.command("seek -1000").unwrap();
    assert_eq!(p.clock().at, 0.0);
    p.command("seek +1000s").unwrap();
    assert_eq!(p.clock().at, span);

    // Paused, time does not move; at 2x it moves twice as far.
    p.command("seek 0").unwrap();
    p.command("pause").unwrap();
    p.advance(Duration::from_millis(100));
    assert_eq!(p.clock().at, 0.0);
    assert!(p.command("speed 2x").unwrap().contains("x2"));
    p.command("play").unwrap();
    p.advance(Duration::from_millis(100));
    assert!((p.clock().at - 0.2).abs() < 1e-9, "{:?}", p.clock());
    assert!(!p.clock().paused);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_player_refuses_what_would_reach_a_robot_and_bad_numbers() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("run.mcap");
    recording(&file).await;
    let replay = Replay::open(&file).unwrap();
    let mut p = Player::new(&replay);
    for line in [
        "route robot_1 joy/0",
        "estop",
        "drive robot_1 0.2 0 0",
        "",
        "pause now",
    ] {
        let err = p.command(line).unwrap_err();
        assert!(err.contains("sends nothing to robots"), "{line}: {err}");
    }
    for (line, why) in [
        ("speed 20", "outside"),
        ("speed 0.01", "outside"),
        ("speed fast", "a number"),
        ("seek soon", "seconds"),
        ("seek NaN", "seconds"),
    ] {
        let err = p.command(line).unwrap_err();
        assert!(err.contains(why), "{line}: {err}");
    }
    assert_eq!(p.clock().speed, 1.0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn attached_to_a_replay_lines_get_results_and_teleop_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("run.mcap");
    recording(&file).await;
    let mut attached = player::attach(Replay::open(&file).unwrap());
    assert_eq!(attached.welcome.operator, "replay");
    attached
        .to
        .send(ToStation::Line {
            id: 7,
            text: "pause".into(),
        })
        .unwrap();
    attached
        .to
        .send(ToStation::Publish {
            channel: "joy/0".into(),
            robots: vec!["robot_1".into()],
            command: Command::Stop(Stop {}),
        })
        .unwrap();
    let (mut result, mut refused, mut paused) = (None, None, false);
    while result.is_none() || refused.is_none() || !paused {
        let m = tokio::time::timeout(Duration::from_secs(10), attached.from.recv())
            .await
            .expect("the replay answers")
            .expect("still playing");
        match m {
            FromStation::Result(r) => result = Some(r),
            FromStation::Refused { reason } => refused = Some(reason),
            FromStation::Snapshot { fleet, .. } => {
                paused |= fleet.replay.is_some_and(|c| c.paused);
            }
            _ => {}
        }
    }
    let result = result.unwrap();
    assert!(result.ok && result.id == 7, "{result:?}");
    assert!(refused.unwrap().contains("sends nothing to robots"));
    attached.to.send(ToStation::Bye).unwrap();
}
