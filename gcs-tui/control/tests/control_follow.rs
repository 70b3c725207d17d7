//! Follow-the-leader in stepped-time simulation: followers hold their offsets
//! while the leader is driven by another controller (here a scripted twist, as
//! a gamepad would send), and stop when the leader's telemetry is lost.

#![allow(clippy::unwrap_used)]

#[path = "control_support/bench.rs"]
mod bench;

use bench::{Bench, pose};
use mech_agent::platform::PlatformSpec;
use mech_control::{ControlEvent, FollowConfig, FollowTheLeader, Follower};
use mech_proto::{Command, Offset, Twist};
use std::time::Duration;

const PERIOD: f64 = 0.05;
const CHANNEL: &str = "follow/robot_1";
const JOY: &str = "joy/0";

fn ticks(seconds: f64) -> usize {
    (seconds / PERIOD).round() as usize
}

fn leader_twist(t: f64) -> Command {
    Command::Twist(Twist {
        vx: 0.25,
        vy: 0.0,
        vz: 0.0,
        wz: 0.2 * (0.2 * t).sin(),
    })
}

fn convoy() -> (Bench, FollowTheLeader) {
    let mut world = Bench::new(
        &[
            ("robot_1", PlatformSpec::diff_drive(), pose(0.0, 0.0, 0.0)),
            ("robot_2", PlatformSpec::kiwi(), pose(-1.2, 0.9, 1.0)),
            (
                "robot_3",
                PlatformSpec::diff_drive(),
                pose(-1.5, -0.2, -0.5),
            ),
        ],
        CHANNEL,
    );
    // The leader is driven by someone else: a gamepad on joy/0.
    world.route("robot_1", JOY);
    let follow = FollowTheLeader::new(
        "robot_1",
        vec![
            Follower {
                robot: "robot_2".into(),
                offset: Offset { x: -0.7, y: 0.6 },
            },
            Follower {
                robot: "robot_3".into(),
                offset: Offset { x: -0.8, y: -0.6 },
            },
        ],
        FollowConfig::default(),
    );
    (world, follow)
}

#[test]
fn followers_hold_their_offsets_while_the_leader_is_driven() {
    let (mut world, mut follow) = convoy();
    let mut errors: Vec<(String, f64)> = Vec::new();
    for i in 0..ticks(60.0) {
        let now = world.now_s();
        world.command("robot_1", JOY, &leader_twist(now));
        let out = follow.step(now, &world.states());
        assert!(
            out.commands.iter().all(|c| c.robot != "robot_1"),
            "the leader is not ours to drive"
        );
        world.fleet(CHANNEL, &out.commands);
        if i >= ticks(10.0) {
            errors.extend(out.targets.iter().map(|t| (t.robot.clone(), t.error)));
        }
        world.advance(Duration::from_secs_f64(PERIOD));
    }
    let leader = world.true_pose("robot_1");
    assert!(leader.x.hypot(leader.y) > 5.0, "the leader really moved");
    for robot in ["robot_2", "robot_3"] {
        let e: Vec<f64> = errors
            .iter()
            .filter(|(r, _)| r == robot)
            .map(|(_, e)| *e)
            .collect();
        let max = e.iter().copied().fold(0.0, f64::max);
        let rms = (e.iter().map(|x| x * x).sum::<f64>() / e.len() as f64).sqrt();
        println!("follow {robot}: offset error max {max:.3} m, RMS {rms:.3} m over 50 s");
        assert!(max < 0.05, "{robot} max offset error {max:.3} m");
        assert!(rms < 0.03, "{robot} RMS offset error {rms:.3} m");
    }
}

#[test]
fn followers_stop_when_the_leader_is_lost_and_lost_followers_get_nothing() {
    let (mut world, mut follow) = convoy();
    for _ in 0..ticks(5.0) {
        let now = world.now_s();
        world.command("robot_1", JOY, &leader_twist(now));
        let out = follow.step(now, &world.states());
        world.fleet(CHANNEL, &out.commands);
        world.advance(Duration::from_secs_f64(PERIOD));
    }
    world.silence("robot_1", true);
    world.silence("robot_3", true);
    let mut saw_leader_lost = false;
    for _ in 0..ticks(2.0) {
        let now = world.now_s();
        let out = follow.step(now, &world.states());
        saw_leader_lost |= out.events.contains(&ControlEvent::MemberLost {
            robot: "robot_1".into(),
        });
        if saw_leader_lost {
            assert!(out.lost.contains(&"robot_1".to_string()));
            assert!(
                out.commands.iter().all(|c| c.robot != "robot_3"),
                "lost follower not commanded"
            );
            let to_2 = out
                .commands
                .iter()
                .find(|c| c.robot == "robot_2")
                .expect("robot_2 commanded");
            assert!(
                matches!(to_2.command, Command::Stop(_)),
                "no leader: hold still"
            );
        }
        world.fleet(CHANNEL, &out.commands);
        world.advance(Duration::from_secs_f64(PERIOD));
    }
    assert!(saw_leader_lost);
    assert!(world.speed("robot_2") < 1e-3);
    assert!(
        world.speed("robot_3") < 1e-3,
        "failsafe stopped the silent follower"
    );
}

#[test]
fn formation_frame_turns_no_faster_than_followers_can_drive() {
    let (mut world, mut follow) = convoy();
    // Gather behind a still leader.
    for _ in 0..ticks(15.0) {
        let out = follow.step(world.now_s(), &world.states());
        world.fleet(CHANNEL, &out.commands);
        world.advance(Duration::from_secs_f64(PERIOD));
    }
    // The leader spins in place by half a turn as fast as it can.
    let spin = Command::Twist(Twist {
        vx: 0.0,
        vy: 0.0,
        vz: 0.0,
        wz: 2.0,
    });
    let hold = Command::Twist(Twist::default());
    let mut worst = 0.0f64;
    let mut target_speed = 0.0f64;
    let mut last: Option<(f64, f64)> = None;
    for i in 0..ticks(12.0) {
        let now = world.now_s();
        let heading = world.true_pose("robot_1").heading;
        if i < ticks(4.0) {
            let turning = heading.abs() < 3.0;
            world.command("robot_1", JOY, if turning { &spin } else { &hold });
        }
        let out = follow.step(now, &world.states());
        world.fleet(CHANNEL, &out.commands);
        let t = out.targets.iter().find(|t| t.robot == "robot_2").unwrap();
        if let Some((x, y)) = last {
            target_speed = target_speed.max((t.x - x).hypot(t.y - y) / PERIOD);
        }
        last = Some((t.x, t.y));
        worst = worst.max(out.targets.iter().map(|t| t.error).fold(0.0, f64::max));
        world.advance(Duration::from_secs_f64(PERIOD));
    }
    let heading = world.true_pose("robot_1").heading;
    let end = follow.step(world.now_s(), &world.states());
    println!(
        "leader spun to {heading:.2} rad: fastest target {target_speed:.2} m/s, \
         worst follower error {worst:.3} m, final {:.3} m",
        end.targets.iter().map(|t| t.error).fold(0.0, f64::max)
    );
    assert!(heading.cos() < -0.95, "the leader turned round");
    assert!(
        target_speed <= 0.6 * 0.5 + 0.05,
        "targets move within the followers' reach"
    );
    assert!(worst < 0.15, "followers kept up: {worst:.3} m");
    assert!(
        end.targets.iter().all(|t| t.error < 0.05),
        "settled behind the turned leader"
    );
}
