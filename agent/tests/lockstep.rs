//! How a fleet controller is simulated in lock-step with `SimRobot`: four
//! robots (two diff-drive, two kiwi) read their telemetry, a controller
//! computes one vehicle-level command each per step, the robots step. No
//! sockets, no clock: the same platform maths and onboard controllers the
//! agent uses.
#![allow(clippy::unwrap_used)]

use mech_agent::PlatformSpec;
use mech_agent::sim::SimRobot;
use mech_proto::{Command, Pose, Twist, VelocityHeading};

/// A toy formation controller: each robot drives to its slot on a line.
fn controller(slot: (f64, f64), pose: &Pose, holonomic: bool) -> Command {
    let (dx, dy) = (slot.0 - pose.x, slot.1 - pose.y);
    let dist = dx.hypot(dy);
    if dist < 0.01 {
        return Command::Twist(Twist::default());
    }
    let speed = (0.8 * dist).min(0.3);
    if holonomic {
        // World velocity rotated into the body frame.
        let (s, c) = pose.heading.sin_cos();
        let (vx, vy) = (dx / dist * speed, dy / dist * speed);
        Command::Twist(Twist {
            vx: c * vx + s * vy,
            vy: -s * vx + c * vy,
            vz: 0.0,
            wz: 0.0,
        })
    } else {
        Command::VelocityHeading(VelocityHeading {
            speed,
            heading: dy.atan2(dx),
        })
    }
}

#[test]
fn four_robots_reach_a_line_formation_in_lockstep() {
    let specs = [
        PlatformSpec::diff_drive(),
        PlatformSpec::kiwi(),
        PlatformSpec::diff_drive(),
        PlatformSpec::kiwi(),
    ];
    let mut robots: Vec<SimRobot> = specs
        .iter()
        .enumerate()
        .map(|(i, s)| {
            SimRobot::new(
                s,
                Pose {
                    x: 0.5 * i as f64,
                    y: 2.0 - 0.3 * i as f64,
                    z: 0.0,
                    heading: i as f64,
                },
            )
        })
        .collect();
    let slots: Vec<(f64, f64)> = (0..4).map(|i| (1.0 + 0.4 * i as f64, 0.5)).collect();
    let dt = 0.02;
    for _ in 0..2000 {
        let telemetry: Vec<_> = robots.iter().map(SimRobot::telemetry).collect();
        for (i, robot) in robots.iter_mut().enumerate() {
            let cmd = controller(slots[i], &telemetry[i].pose, robot.platform().holonomic());
            robot.apply(&cmd).unwrap();
        }
        for robot in &mut robots {
            robot.step(dt);
        }
    }
    for (robot, slot) in robots.iter().zip(&slots) {
        let p = robot.pose();
        assert!(
            (p.x - slot.0).hypot(p.y - slot.1) < 0.03,
            "{} at {p:?}, slot {slot:?}",
            robot.platform().name()
        );
    }
}
