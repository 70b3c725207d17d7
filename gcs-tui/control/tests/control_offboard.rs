//! Offboard waypoint navigation against simulated agents in stepped time: the
//! GCS-side loop reaches every waypoint in order on both platform kinds, meets
//! arrival times, switches live onboard -> offboard -> onboard without
//! repeating or skipping a waypoint, and stops commanding a robot whose
//! telemetry is lost (its failsafe then stops it).

#![allow(clippy::unwrap_used)]

#[path = "control_support/bench.rs"]
mod bench;

use std::time::Duration;

use bench::{Bench, pose};
use mech_agent::platform::PlatformSpec;
use mech_control::{ControlEvent, NavConfig, OffboardNavigator};
use mech_proto::{Command, FailsafeState, Mission, Waypoint};

const PERIOD: f64 = 0.05;
const OFFBOARD: &str = "offboard/robot_1";
const ONBOARD: &str = "wp/gcs";

fn ticks(seconds: f64) -> usize {
    (seconds / PERIOD).round() as usize
}

fn period() -> Duration {
    Duration::from_secs_f64(PERIOD)
}

fn wp(x: f64, y: f64) -> Waypoint {
    Waypoint {
        x,
        y,
        z: 0.0,
        time: None,
    }
}

fn square_mission(id: u32) -> Mission {
    Mission {
        id,
        waypoints: vec![
            wp(2.0, 0.0),
            wp(2.0, 2.0),
            wp(0.0, 2.0),
            wp(0.0, 0.6),
            wp(1.0, 1.0),
        ],
        looped: false,
        arrival_radius: 0.1,
        start_index: 0,
    }
}

fn one_robot(spec: PlatformSpec, heading: f64, channel: &str) -> Bench {
    Bench::new(&[("robot_1", spec, pose(0.0, 0.0, heading))], channel)
}

/// One offboard control period: step, publish, advance. Returns the events.
fn offboard_tick(world: &mut Bench, nav: &mut OffboardNavigator) -> Vec<ControlEvent> {
    let out = nav.step(world.now_s(), world.state("robot_1").as_ref());
    if let Some(c) = &out.command {
        world.command("robot_1", OFFBOARD, c);
    }
    world.advance(period());
    out.events
}

fn reached(events: &[ControlEvent]) -> impl Iterator<Item = usize> + '_ {
    events.iter().filter_map(|e| match e {
        ControlEvent::WaypointReached { index } => Some(*index),
        _ => None,
    })
}

#[test]
fn offboard_loop_reaches_every_waypoint_in_order_on_both_platforms() {
    for (name, spec) in [
        ("diff-drive", PlatformSpec::diff_drive()),
        ("kiwi", PlatformSpec::kiwi()),
    ] {
        let mut world = one_robot(spec, 2.5, OFFBOARD);
        let mut nav = OffboardNavigator::new("robot_1", square_mission(7), NavConfig::default());
        let mut order = Vec::new();
        let t0 = world.now_s();
        for _ in 0..ticks(120.0) {
            let events = offboard_tick(&mut world, &mut nav);
            order.extend(reached(&events));
            if nav.finished() {
                break;
            }
        }
        let end = world.true_pose("robot_1");
        let final_error = (end.x - 1.0).hypot(end.y - 1.0);
        println!(
            "offboard {name}: reached {order:?} in {:.1} s, final error {final_error:.3} m",
            world.now_s() - t0
        );
        assert_eq!(order, vec![0, 1, 2, 3, 4]);
        assert!(final_error <= 0.12);
        assert_eq!((nav.progress().next, nav.progress().total), (5, 5));
        // Finished: the loop holds the robot with a stop.
        let out = nav.step(world.now_s(), world.state("robot_1").as_ref());
        assert!(matches!(out.command, Some(Command::Stop(_))));
    }
}

#[test]
fn arrival_times_set_the_speed() {
    let mut mission = square_mission(1);
    mission.waypoints.truncate(2);
    mission.waypoints[0].time = Some(16.0);
    mission.waypoints[1].time = Some(32.0);
    let mut world = one_robot(PlatformSpec::kiwi(), 0.0, OFFBOARD);
    let mut nav = OffboardNavigator::new("robot_1", mission, NavConfig::default());
    let t0 = world.now_s();
    let mut order = Vec::new();
    let mut first_at = None;
    for _ in 0..ticks(120.0) {
        let events = offboard_tick(&mut world, &mut nav);
        for i in reached(&events) {
            order.push(i);
            first_at.get_or_insert(world.now_s() - t0);
        }
        if nav.finished() {
            break;
        }
    }
    let took = world.now_s() - t0;
    let first = first_at.unwrap();
    println!(
        "timed mission: waypoints due at 16 s and 32 s, reached at {first:.1} s and {took:.1} s"
    );
    assert_eq!(order, vec![0, 1]);
    assert!(
        (first - 16.0).abs() < 2.0,
        "first waypoint on schedule: {first:.1} s"
    );
    assert!(
        (took - 32.0).abs() < 2.0,
        "second waypoint on schedule: {took:.1} s"
    );
}

/// A platform slower than the navigator's least speed (0.05 m/s) on a
/// timed leg is driven at its own top speed: the speed is clamped to the
/// platform, never the other way round (that panicked the control hub).
#[test]
fn a_platform_slower_than_the_least_speed_meets_no_panic_on_a_timed_leg() {
    let mut mission = square_mission(1);
    mission.waypoints.truncate(1);
    mission.waypoints[0].time = Some(5.0);
    let slow = PlatformSpec::Kiwi {
        radius: 0.1,
        max_wheel_speed: 0.03,
    };
    let mut world = one_robot(slow, 0.0, OFFBOARD);
    let mut nav = OffboardNavigator::new("robot_1", mission, NavConfig::default());
    let mut commanded = 0;
    for _ in 0..ticks(2.0) {
        let out = nav.step(world.now_s(), world.state("robot_1").as_ref());
        if let Some(Command::Twist(t)) = &out.command {
            commanded += 1;
            let speed = t.vx.hypot(t.vy);
            assert!(speed < 0.05, "the platform's top speed: {speed}");
        }
        world.advance(period());
    }
    assert!(commanded > 0, "the robot was driven");
}

/// Index of the waypoint whose arrival circle the true position is in.
fn inside(mission: &Mission, world: &Bench) -> Option<usize> {
    let p = world.true_pose("robot_1");
    mission
        .waypoints
        .iter()
        .position(|w| (w.x - p.x).hypot(w.y - p.y) <= mission.arrival_radius + 0.02)
}

/// What the GCS sees of a mission across switches: waypoint reached
/// events (from onboard progress and from the offboard loop), and the
/// arrival circles the true path entered, in order.
#[derive(Default)]
struct Seen {
    reached: Vec<usize>,
    entered: Vec<usize>,
    /// The onboard progress's `next` last read.
    last_next: u32,
}

impl Seen {
    /// Notes the arrival circle the robot is in, if it just entered it.
    fn track(&mut self, mission: &Mission, world: &Bench) {
        if let Some(i) = inside(mission, world) {
            if self.entered.last() != Some(&i) {
                self.entered.push(i);
            }
        }
    }

    /// Notes the waypoints the onboard progress says were reached since the
    /// last reading.
    fn progress(&mut self, next: u32) {
        self.reached
            .extend((self.last_next..next).map(|i| i as usize));
        self.last_next = next;
    }
}

/// Onboard until waypoint 1 is reached and the robot is mid-leg to 2.
fn onboard_to_mid_leg(world: &mut Bench, mission: &Mission, seen: &mut Seen) {
    for _ in 0..ticks(60.0) {
        world.advance(period());
        seen.track(mission, world);
        let p = world.telemetry("robot_1").unwrap().mission.unwrap();
        seen.progress(p.next);
        if p.next == 2 && inside(mission, world).is_none() {
            break;
        }
    }
}

/// Switched to offboard (routed, then taking over from the reported
/// progress) until waypoint 3 is reached and the robot is mid-leg to 4.
fn offboard_to_mid_leg(world: &mut Bench, mission: &Mission, seen: &mut Seen) -> OffboardNavigator {
    let reported = world.telemetry("robot_1").unwrap().mission;
    world.route("robot_1", OFFBOARD);
    let mut nav =
        OffboardNavigator::take_over("robot_1", mission.clone(), reported, NavConfig::default());
    assert_eq!(nav.progress().next, 2);
    for _ in 0..ticks(60.0) {
        let events = offboard_tick(world, &mut nav);
        seen.track(mission, world);
        seen.reached.extend(reached(&events));
        if nav.progress().next == 4 && inside(mission, world).is_none() {
            break;
        }
    }
    nav
}

/// Back to onboard (a fresh mission id starting at the current next) until
/// the mission finishes; whether it did.
fn onboard_to_the_end(
    world: &mut Bench,
    mission: &Mission,
    nav: &OffboardNavigator,
    seen: &mut Seen,
) -> bool {
    let back = nav.onboard_mission(2);
    world.mission("robot_1", ONBOARD, back);
    world.route("robot_1", ONBOARD);
    seen.last_next = 4;
    for _ in 0..ticks(60.0) {
        world.advance(period());
        seen.track(mission, world);
        if let Some(p) = world
            .telemetry("robot_1")
            .unwrap()
            .mission
            .filter(|p| p.id == 2)
        {
            seen.progress(p.next);
            if p.next == p.total {
                return true;
            }
        }
    }
    false
}

#[test]
fn live_switch_onboard_offboard_onboard_keeps_mission_progress() {
    for (name, spec) in [
        ("diff-drive", PlatformSpec::diff_drive()),
        ("kiwi", PlatformSpec::kiwi()),
    ] {
        let mut world = one_robot(spec, 0.0, ONBOARD);
        let mission = square_mission(1);
        world.mission("robot_1", ONBOARD, mission.clone());
        let mut seen = Seen::default();
        onboard_to_mid_leg(&mut world, &mission, &mut seen);
        assert_eq!(
            seen.last_next, 2,
            "{name}: onboard progress before the switch"
        );
        let nav = offboard_to_mid_leg(&mut world, &mission, &mut seen);
        assert_eq!(
            nav.progress().next,
            4,
            "{name}: offboard progress before switching back"
        );
        assert_eq!(
            world.telemetry("robot_1").unwrap().computation,
            mech_proto::Computation::Offboard
        );
        let finished = onboard_to_the_end(&mut world, &mission, &nav, &mut seen);
        let (reached, entered) = (&seen.reached, &seen.entered);
        println!(
            "live switch {name}: reached {reached:?}, arrival circles entered in order {entered:?}"
        );
        assert!(finished, "{name}: mission finished onboard");
        assert_eq!(
            *reached,
            vec![0, 1, 2, 3, 4],
            "{name}: every waypoint once, in order"
        );
        assert_eq!(
            *entered,
            vec![0, 1, 2, 3, 4],
            "{name}: the robot visited each waypoint once, in order"
        );
    }
}

#[test]
fn lost_telemetry_stops_commanding_and_the_failsafe_stops_the_robot() {
    let mut world = one_robot(PlatformSpec::diff_drive(), 0.0, OFFBOARD);
    let config = NavConfig::default();
    let timeout = config.telemetry_timeout;
    let mut nav = OffboardNavigator::new("robot_1", square_mission(1), config);
    for _ in 0..ticks(3.0) {
        offboard_tick(&mut world, &mut nav);
    }
    assert!(world.speed("robot_1") > 0.1);
    world.silence("robot_1", true);
    let silent_since = world.now_s();
    let mut lost_at = None;
    for _ in 0..ticks(2.0) {
        let now = world.now_s();
        let out = nav.step(now, world.state("robot_1").as_ref());
        if out.events.contains(&ControlEvent::MemberLost {
            robot: "robot_1".into(),
        }) {
            lost_at = Some(now);
        }
        match (&out.command, lost_at) {
            (Some(c), None) => world.command("robot_1", OFFBOARD, c),
            (None, Some(_)) => {}
            (c, l) => panic!("command {c:?} with lost_at {l:?}"),
        }
        world.advance(period());
    }
    let lost_at = lost_at.expect("reported lost");
    assert!(lost_at - silent_since <= timeout + PERIOD + 1e-9);
    assert_eq!(world.failsafe("robot_1"), FailsafeState::ChannelSilent);
    assert!(world.speed("robot_1") < 1e-3, "failsafe stopped it");
    assert!(nav.step(world.now_s(), None).command.is_none());

    // Telemetry back: the loop resumes toward the same waypoint.
    world.silence("robot_1", false);
    world.advance(period());
    let out = nav.step(world.now_s(), world.state("robot_1").as_ref());
    assert!(out.events.contains(&ControlEvent::MemberRecovered {
        robot: "robot_1".into()
    }));
    assert!(matches!(out.command, Some(Command::Twist(_))));
    assert_eq!(out.progress.next, 0);
}
