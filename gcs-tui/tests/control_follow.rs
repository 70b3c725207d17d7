//! Follow-the-leader in stepped-time simulation: followers hold their offsets
//! while the leader is driven by another controller (here a scripted twist, as
//! a gamepad would send), and stop when the leader's telemetry is lost.

#![allow(clippy::unwrap_used)]

#[path = "control_support/sim.rs"]
mod sim;

use mech_gcs::control::{ControlEvent, FollowConfig, FollowTheLeader, Follower};
use mech_proto::{Command, Offset, Twist};
use sim::{SimBot, World};

const PERIOD: f64 = 0.05;
const SUBSTEPS: usize = 5;

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

fn convoy() -> (World, FollowTheLeader) {
    let world = World::new(vec![
        SimBot::new("robot_1", "diff-drive", 0.0, 0.0, 0.0),
        SimBot::new("robot_2", "kiwi", -1.2, 0.9, 1.0),
        SimBot::new("robot_3", "diff-drive", -1.5, -0.2, -0.5),
    ]);
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
        let now = world.now;
        world.deliver("robot_1", &leader_twist(now));
        let out = follow.step(now, &world.states());
        assert!(
            out.commands.iter().all(|c| c.robot != "robot_1"),
            "the leader is not ours to drive"
        );
        for c in &out.commands {
            world.deliver(&c.robot, &c.command);
        }
        if i >= ticks(10.0) {
            errors.extend(out.targets.iter().map(|t| (t.robot.clone(), t.error)));
        }
        world.advance(PERIOD, SUBSTEPS);
    }
    let leader = world.robot("robot_1").pose;
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
        let now = world.now;
        world.deliver("robot_1", &leader_twist(now));
        let out = follow.step(now, &world.states());
        for c in &out.commands {
            world.deliver(&c.robot, &c.command);
        }
        world.advance(PERIOD, SUBSTEPS);
    }
    world.robot("robot_1").reporting = false;
    world.robot("robot_3").reporting = false;
    let mut saw_leader_lost = false;
    for _ in 0..ticks(2.0) {
        let now = world.now;
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
        for c in &out.commands {
            world.deliver(&c.robot, &c.command);
        }
        world.advance(PERIOD, SUBSTEPS);
    }
    assert!(saw_leader_lost);
    assert!(world.robot("robot_2").speed() < 1e-3);
    assert!(
        world.robot("robot_3").speed() < 1e-3,
        "failsafe stopped the silent follower"
    );
}
