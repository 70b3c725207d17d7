//! Offboard waypoint navigation in stepped-time simulation: the GCS-side loop
//! reaches every waypoint in order on both platform kinds, meets arrival times,
//! hands progress over in both directions, and stops commanding a robot whose
//! telemetry is lost.

#![allow(clippy::unwrap_used)]

#[path = "control_support/sim.rs"]
mod sim;

use mech_gcs::control::{ControlEvent, NavConfig, OffboardNavigator};
use mech_proto::{Command, Mission, Waypoint};
use sim::{SimBot, World};

const PERIOD: f64 = 0.05;
const SUBSTEPS: usize = 5;

fn ticks(seconds: f64) -> usize {
    (seconds / PERIOD).round() as usize
}

fn square_mission(id: u32) -> Mission {
    let wp = |x, y| Waypoint {
        x,
        y,
        z: 0.0,
        time: None,
    };
    Mission {
        id,
        waypoints: vec![
            wp(2.0, 0.0),
            wp(2.0, 2.0),
            wp(0.0, 2.0),
            wp(0.0, 0.0),
            wp(1.0, 1.0),
        ],
        looped: false,
        arrival_radius: 0.1,
        start_index: 0,
    }
}

/// Runs the navigator until it finishes; returns the reached indices, the
/// time taken and the final distance to the last waypoint.
fn fly(world: &mut World, nav: &mut OffboardNavigator, limit: f64) -> (Vec<usize>, f64, f64) {
    let robot = nav.robot().to_string();
    let t0 = world.now;
    let mut reached = Vec::new();
    for _ in 0..ticks(limit) {
        let now = world.now;
        let state = world.states().into_iter().find(|s| s.robot == robot);
        let out = nav.step(now, state.as_ref());
        for e in &out.events {
            if let ControlEvent::WaypointReached { index } = e {
                reached.push(*index);
            }
        }
        if let Some(c) = &out.command {
            world.deliver(&robot, c);
        }
        if nav.finished() {
            break;
        }
        world.advance(PERIOD, SUBSTEPS);
    }
    let last = nav.mission().waypoints.last().copied().unwrap();
    let pose = world.robot(&robot).pose;
    (
        reached,
        world.now - t0,
        (pose.x - last.x).hypot(pose.y - last.y),
    )
}

#[test]
fn offboard_loop_reaches_every_waypoint_in_order_on_both_platforms() {
    for platform in ["diff-drive", "kiwi"] {
        let mut world = World::new(vec![SimBot::new("robot_1", platform, 0.0, 0.0, 2.5)]);
        let mut nav = OffboardNavigator::new("robot_1", square_mission(7), NavConfig::default());
        let (reached, took, final_error) = fly(&mut world, &mut nav, 120.0);
        println!(
            "offboard {platform}: reached {reached:?} in {took:.1} s, final error {final_error:.3} m"
        );
        assert_eq!(reached, vec![0, 1, 2, 3, 4]);
        assert!(final_error <= 0.1);
        assert_eq!(nav.progress().next, 5);
        assert_eq!(nav.progress().total, 5);
    }
}

#[test]
fn arrival_times_set_the_speed() {
    let mut mission = square_mission(1);
    mission.waypoints.truncate(2);
    mission.waypoints[0].time = Some(16.0);
    mission.waypoints[1].time = Some(32.0);
    let mut world = World::new(vec![SimBot::new("robot_1", "kiwi", 0.0, 0.0, 0.0)]);
    let mut nav = OffboardNavigator::new("robot_1", mission, NavConfig::default());
    let (reached, took, _) = fly(&mut world, &mut nav, 120.0);
    println!("timed mission: 2 waypoints due at 16 s and 32 s, finished after {took:.1} s");
    assert_eq!(reached, vec![0, 1]);
    assert!(
        (took - 32.0).abs() < 2.0,
        "arrived on schedule, took {took:.1} s"
    );
}

#[test]
fn progress_is_handed_over_in_both_directions() {
    let mut nav = OffboardNavigator::new("robot_1", square_mission(3), NavConfig::default());
    nav.resume_at(2);
    assert_eq!(nav.progress().next, 2);
    let mut world = World::new(vec![SimBot::new("robot_1", "kiwi", 2.0, 2.0, 0.0)]);
    let mut reached = Vec::new();
    for _ in 0..ticks(30.0) {
        let state = world.states().pop();
        let out = nav.step(world.now, state.as_ref());
        for e in &out.events {
            if let ControlEvent::WaypointReached { index } = e {
                reached.push(*index);
            }
        }
        if let Some(c) = &out.command {
            world.deliver("robot_1", c);
        }
        if reached.len() == 1 {
            break;
        }
        world.advance(PERIOD, SUBSTEPS);
    }
    assert_eq!(
        reached,
        vec![2],
        "resumed at the reported next waypoint, not the first"
    );
    let back = nav.onboard_mission(4);
    assert_eq!(back.start_index, 3);
    assert_eq!(back.id, 4);
    assert_eq!(back.waypoints, square_mission(3).waypoints);
}

#[test]
fn lost_telemetry_stops_commanding_and_the_failsafe_stops_the_robot() {
    let mut world = World::new(vec![SimBot::new("robot_1", "diff-drive", 0.0, 0.0, 0.0)]);
    let config = NavConfig::default();
    let timeout = config.telemetry_timeout;
    let mut nav = OffboardNavigator::new("robot_1", square_mission(1), config);
    for _ in 0..ticks(3.0) {
        let out = nav.step(world.now, world.states().first());
        world.deliver("robot_1", out.command.as_ref().unwrap());
        world.advance(PERIOD, SUBSTEPS);
    }
    assert!(world.robot("robot_1").speed() > 0.1);
    world.robot("robot_1").reporting = false;
    let silent_since = world.now;
    let mut lost_at = None;
    for _ in 0..ticks(2.0) {
        let now = world.now;
        let out = nav.step(now, world.states().first());
        if out.events.contains(&ControlEvent::MemberLost {
            robot: "robot_1".into(),
        }) {
            lost_at = Some(now);
        }
        match (&out.command, lost_at) {
            (Some(c), None) => world.deliver("robot_1", c),
            (None, Some(_)) => {}
            (c, l) => panic!("command {c:?} with lost_at {l:?}"),
        }
        world.advance(PERIOD, SUBSTEPS);
    }
    let lost_at = lost_at.expect("reported lost");
    assert!(lost_at - silent_since <= timeout + PERIOD + 1e-9);
    assert!(world.robot("robot_1").speed() < 1e-3, "failsafe stopped it");
    assert!(nav.step(world.now, None).command.is_none());
    // Telemetry back: the loop resumes from the same waypoint.
    world.robot("robot_1").reporting = true;
    world.advance(PERIOD, SUBSTEPS);
    let out = nav.step(world.now, world.states().first());
    assert!(out.events.contains(&ControlEvent::MemberRecovered {
        robot: "robot_1".into()
    }));
    assert!(matches!(out.command, Some(Command::Twist(_))));
    assert_eq!(out.progress.next, 0);
}
