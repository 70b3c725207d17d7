//! The agent's ROS 2 base end to end: a real `mech-agent` with a `[ros2]`
//! section drives a fake ROS 2 mobile base over DDS (`tests/fake_base.py`:
//! Cyclone DDS, a diff-drive on its last cmd_vel, odometry and battery
//! under ROS 2's names) and registers with a real station (`mech-gcs
//! serve --demo N`), all in a network namespace of their own. The fake's
//! true pose is what is measured; the agent knows only the odometry.
//!
//! Shown: the robot registers, obeys nobody until routed (zero cmd_vel
//! meanwhile), reports the origin composed with its odometry and the
//! base's battery, and drives a mission to within the arrival radius
//! (also localised on a map: `map` -> `odom` from `/tf` composed in);
//! an e-stop and the station's loss bring the cmd_vel the base gets to
//! zero; driven at the fence it stays inside; among simulated robots
//! crossing its path every disc keeps its distance; NaN odometry,
//! odometry gone silent and a second writer on its cmd_vel each get the
//! station told and the base held at zero.
//!
//! Each test prints its figures as `figure: ...` lines (`--nocapture`).

#![allow(clippy::unwrap_used)]

#[path = "support/base_rig.rs"]
mod base_rig;
#[path = "support/operator.rs"]
mod operator;
// The DDS tests' rig: these use its namespace, station and nodes, not its
// bridge.
#[allow(dead_code)]
#[path = "support/rig.rs"]
mod rig;

use std::f64::consts::FRAC_PI_2;
use std::time::Duration;

use base_rig::{BaseRig, MAX_SPEED, NAME, Pose2, RADIUS, Setup, at, num, reported};
use operator::{Pad, now};
use serde_json::json;

/// The station's arrival radius for its missions (`[fleet]
/// arrival_radius`'s default), m.
const ARRIVAL_RADIUS: f64 = 0.1;

/// The demo arena (`ArenaConfig::demo`): 3.9 m x 2.8 m from the origin,
/// margin 0.1 m.
const ARENA: (f64, f64) = (3.9, 2.8);
const MARGIN: f64 = 0.1;

/// A channel a test's controller publishes on.
const PAD: &str = "pad/test";

/// The e-stop state in telemetry (`FailsafeState` 3).
const ESTOPPED: u64 = 3;

fn is_zero(c: &(f64, f64, f64, u64)) -> bool {
    c.1 == 0.0 && c.2 == 0.0
}

/// The agent's samples: writer 0, the first the base heard (the agent
/// streams from its start; a test's intruder comes later).
fn agents(cmds: &[(f64, f64, f64, u64)]) -> Vec<(f64, f64, f64, u64)> {
    cmds.iter().copied().filter(|c| c.3 == 0).collect()
}

/// When the agent's cmd_vel went to zero for good after `since`: the first
/// of its samples from which every later one is zero, if there are later
/// ones at all.
fn zero_from(cmds: &[(f64, f64, f64, u64)], since: f64) -> Option<f64> {
    let mine: Vec<_> = agents(cmds).into_iter().filter(|c| c.0 > since).collect();
    let last_moving = mine.iter().rposition(|c| !is_zero(c));
    let first_zero = last_moving.map_or(0, |i| i + 1);
    // A few zeros after it: the stream goes on at zero.
    (mine.len() >= first_zero + 3).then(|| mine[first_zero].0)
}

/// Waits until the base moves at more than half its top speed.
fn until_driving(rig: &mut BaseRig, what: &str) {
    rig.eventually(what, |r| {
        let s = r.state();
        (num(&s["v"]) > MAX_SPEED / 2.0).then_some(())
    });
}

/// Waits until the base's true speed and turn are zero and the agent's
/// cmd_vel has been zero since; returns when its zero stream began.
fn until_held(rig: &mut BaseRig, since: f64, what: &str) -> f64 {
    rig.eventually(what, |r| {
        let s = r.state();
        let stopped = num(&s["v"]) == 0.0 && num(&s["w"]) == 0.0;
        let zero = zero_from(&r.cmds(since), since)?;
        stopped.then_some(zero)
    })
}

/// The robot routed to `channel`, acknowledged.
fn route(rig: &mut BaseRig, channel: &str) {
    rig.op.run(&format!("route {NAME} {channel}"));
    let want = if channel == "none" { "" } else { channel };
    rig.eventually(&format!("{NAME} routed to {channel}"), |r| {
        let route = &r.robot()["route"];
        (route["channel"] == want && route["acknowledged"] == true).then_some(())
    });
}

/// Its reported pose against origin ∘ the base's true odometry pose, once
/// the base stands still (so the two are of the same moment).
fn reported_pose_is_origin_composed_with_odometry(rig: &mut BaseRig) {
    rig.eventually("the base standing still", |r| {
        let s = r.state();
        (num(&s["v"]) == 0.0 && num(&s["w"]) == 0.0).then_some(())
    });
    // Its odometry (30 Hz) and the robot's telemetry (10 Hz) then carry
    // the pose it stopped at.
    std::thread::sleep(Duration::from_millis(500));
    let (truth, pose) = rig.eventually("the reported pose matches the odometry", |r| {
        let truth = r.truth();
        let pose = reported(&r.robot());
        let ok = pose.distance(truth.x, truth.y) < 0.002
            && base_rig::wrap(pose.heading - truth.heading).abs() < 0.002;
        ok.then_some((truth, pose))
    });
    eprintln!(
        "figure: ros2 base reported pose off the truth by {:.4} m, {:.4} rad (odometry frame at {:?} in the arena)",
        pose.distance(truth.x, truth.y),
        base_rig::wrap(pose.heading - truth.heading).abs(),
        rig.setup.odom_frame()
    );
}

#[test]
fn registers_obeys_nobody_until_routed_and_drives_a_mission_to_arrival() {
    if base_rig::skip_unless_available() {
        return;
    }
    // The odometry frame turned a quarter turn in the arena: the base's
    // forward (+x in odom) is the arena's +y.
    let mut setup = Setup::new(1, Pose2::new(0.8, 0.6, FRAC_PI_2));
    setup.origin = Pose2::new(0.6, 0.5, FRAC_PI_2);
    let mut rig = BaseRig::start(setup);
    let t0 = now();

    let robot = rig.robot();
    assert_eq!(
        robot["route"]["channel"], "",
        "routed to none at first: {robot}"
    );
    reported_pose_is_origin_composed_with_odometry(&mut rig);
    rig.eventually("the base's battery (80 %) in telemetry", |r| {
        let b = num(&r.robot()["battery"]);
        ((b - 0.8).abs() < 0.01).then_some(())
    });

    // Unrouted, a controller's twist is not obeyed: zero cmd_vel streams.
    let start = rig.truth();
    {
        let _pad = Pad::start(&rig.op, PAD, NAME, MAX_SPEED, 0.0);
        std::thread::sleep(Duration::from_secs(2));
    }
    let cmds = rig.cmds(t0);
    let mine = agents(&cmds);
    // 20 a second; fewer on a loaded machine.
    assert!(
        mine.len() >= 10,
        "the agent streams cmd_vel while held: {} samples in {:.1} s\n{}",
        mine.len(),
        now() - t0,
        rig.logs()
    );
    assert!(
        mine.iter().all(is_zero),
        "cmd_vel while routed to none: {:?}",
        mine.iter().find(|c| !is_zero(c))
    );
    let here = rig.truth();
    assert!(
        here.distance(start.x, start.y) < 1e-6,
        "the base moved while routed to none: {start:?} -> {here:?}"
    );
    eprintln!(
        "figure: ros2 base cmd_vel while held: {} samples in {:.1} s, all zero",
        mine.len(),
        mine.last().unwrap().0 - mine[0].0
    );

    // A mission, onboard: round the corner, away from robot_1 (1.95, 1.4).
    let goal = (1.4, 2.1);
    rig.op
        .run(&format!("waypoint {NAME} 0.8,1.5 {},{}", goal.0, goal.1));
    rig.op.run(&format!("send {NAME}"));
    route(&mut rig, "wp/gcs");
    let arrived = rig.eventually_within(WAIT_MISSION, "the mission finished", |r| {
        let m = &r.robot()["mission"];
        (m["total"].as_u64() == Some(2) && m["next"] == m["total"]).then(now)
    });
    // Standing still, then measured on the truth.
    until_held(&mut rig, arrived, "the base stopped at the goal");
    let truth = rig.truth();
    let error = truth.distance(goal.0, goal.1);
    eprintln!("figure: ros2 base arrival error {error:.3} m (arrival radius {ARRIVAL_RADIUS} m)");
    assert!(
        error <= ARRIVAL_RADIUS + 0.02,
        "arrived {error:.3} m from the goal, truth {truth:?}\n{}",
        rig.logs()
    );
    reported_pose_is_origin_composed_with_odometry(&mut rig);
}

#[test]
fn localised_on_a_map_its_pose_is_map_to_odom_composed_with_odometry() {
    if base_rig::skip_unless_available() {
        return;
    }
    // A localiser's map -> odom on /tf (the odometry's frame shifted and
    // turned 0.4 rad in the map), the map placed in the arena by the
    // origin: the agent composes the three.
    let mut setup = Setup::new(1, Pose2::new(0.7, 0.6, 0.3));
    setup.origin = Pose2::new(0.1, 0.2, 0.0);
    setup.map = Some(Pose2::new(0.4, -0.1, 0.4));
    let mut rig = BaseRig::start(setup);
    reported_pose_is_origin_composed_with_odometry(&mut rig);
    let goal = (1.2, 1.0);
    rig.op
        .run(&format!("waypoint {NAME} {},{}", goal.0, goal.1));
    rig.op.run(&format!("send {NAME}"));
    route(&mut rig, "wp/gcs");
    rig.eventually_within(WAIT_MISSION, "the mission finished", |r| {
        let m = &r.robot()["mission"];
        (m["total"].as_u64() == Some(1) && m["next"] == m["total"]).then_some(())
    });
    let truth = rig.truth();
    let error = truth.distance(goal.0, goal.1);
    eprintln!("figure: ros2 base on a map: arrival error {error:.3} m");
    assert!(
        error <= ARRIVAL_RADIUS + 0.02,
        "arrived {error:.3} m from the goal, truth {truth:?}\n{}",
        rig.logs()
    );
    reported_pose_is_origin_composed_with_odometry(&mut rig);
}

/// Long enough for a 2.5 m mission at 0.22 m/s on a loaded machine.
const WAIT_MISSION: Duration = Duration::from_secs(90);

#[test]
fn an_estop_and_the_stations_loss_bring_its_cmd_vel_to_zero() {
    if base_rig::skip_unless_available() {
        return;
    }
    // Up the left of the arena, robot_1 at its centre well away.
    let mut rig = BaseRig::start(Setup::new(1, Pose2::new(0.6, 0.5, FRAC_PI_2)));
    rig.op.run(&format!("waypoint {NAME} 0.6,2.4"));
    rig.op.run(&format!("send {NAME}"));
    route(&mut rig, "wp/gcs");
    until_driving(&mut rig, "the base driving its mission");

    let t = now();
    rig.op.run("estop");
    let zero = until_held(&mut rig, t, "the base stopped by the e-stop");
    eprintln!(
        "figure: ros2 base e-stop -> zero cmd_vel at the base {:.3} s",
        zero - t
    );
    rig.eventually("the robot reports the e-stop", |r| {
        (r.robot()["failsafe"].as_u64() == Some(ESTOPPED)).then_some(())
    });

    // Released and sent again, it drives; the station killed, it stops.
    rig.op.run("release");
    rig.op.run(&format!("send {NAME}"));
    until_driving(&mut rig, "the base driving again after the release");
    let t = now();
    rig.kill_station();
    let zero = until_held(&mut rig, t, "the base stopped after the station's loss");
    eprintln!(
        "figure: ros2 base station killed -> zero cmd_vel at the base {:.3} s (on an onboard mission the router's silence counts from channel_timeout, 0.5 s)",
        zero - t
    );
    // Held: zeros keep coming while the station is gone.
    let count = rig.state()["cmd_count"].as_u64().unwrap();
    std::thread::sleep(Duration::from_secs(1));
    let later = now() - 1.0;
    let cmds = agents(&rig.cmds(later));
    assert!(
        cmds.len() >= 5 && cmds.iter().all(is_zero),
        "zero cmd_vel streams with the station gone ({count} before): {cmds:?}"
    );
    assert!(rig.agent_running(), "the agent outlives the station");
}

#[test]
fn driven_at_the_fence_it_stays_inside_the_arena() {
    if base_rig::skip_unless_available() {
        return;
    }
    // Facing the top edge (y = 2.8) from 0.9 m below it.
    let mut rig = BaseRig::start(Setup::new(1, Pose2::new(0.7, 1.9, FRAC_PI_2)));
    route(&mut rig, PAD);
    let t0 = now();
    let pad = Pad::start(&rig.op, PAD, NAME, MAX_SPEED, 0.0);
    until_driving(&mut rig, "the base driving at the fence");
    // It drives until the fence stops it, the controller still pressing.
    rig.eventually("the base stopped at the fence", |r| {
        let s = r.state();
        (num(&s["v"]) == 0.0 && now() - t0 > 3.0).then_some(())
    });
    std::thread::sleep(Duration::from_secs(2));
    let track = rig.track(t0);
    drop(pad);
    let clearance = track
        .iter()
        .map(|(_, p)| {
            let edge = p.x.min(p.y).min(ARENA.0 - p.x).min(ARENA.1 - p.y);
            edge - RADIUS
        })
        .fold(f64::INFINITY, f64::min);
    let last = track.last().unwrap().1;
    eprintln!(
        "figure: ros2 base at the fence: min clearance of its disc to the edge {clearance:.3} m (margin {MARGIN} m), stopped at y = {:.3}",
        last.y
    );
    // Inside, and by the margin: the base stops at once on the agent's
    // zero, within the braking the layer allows for.
    assert!(
        clearance > MARGIN - 0.02,
        "the base's disc came within {clearance:.3} m of the edge (margin {MARGIN})\n{}",
        rig.logs()
    );
    assert!(
        ARENA.1 - last.y - RADIUS < MARGIN + 0.15,
        "the fence, not something else, stopped it: at {last:?}"
    );
    assert!(
        rig.op.heard(t0, &[NAME, "fence"]).is_some(),
        "the station heard of the fence:\n{}",
        rig.op.tail(30)
    );
}

/// The closest the base's true centre came to each simulated robot's
/// reported one (`base_dist`) and their discs (`base_gap`), and the two
/// simulated robots to each other.
struct Closest {
    base_dist: [f64; 2],
    base_gap: [f64; 2],
    demo_dist: f64,
    demo_gap: f64,
}

/// Every snapshot: the base's true centre at its arrival against each
/// simulated robot's reported one, and the simulated robots' between
/// them; each robot's own disc from its telemetry.
fn closest(track: &[(f64, Pose2)], snaps: &[(f64, serde_json::Value)]) -> Closest {
    let radius = |r: &serde_json::Value| {
        num(&r["safety"]["footprint"]) - num(&r["safety"]["position_error"])
    };
    let mut c = Closest {
        base_dist: [f64::INFINITY; 2],
        base_gap: [f64::INFINITY; 2],
        demo_dist: f64::INFINITY,
        demo_gap: f64::INFINITY,
    };
    for (t, fleet) in snaps {
        let Some(truth) = at(track, *t) else {
            continue;
        };
        let robots = fleet["robots"].as_array().unwrap();
        let demo: Vec<_> = robots
            .iter()
            .filter(|r| r["name"] == "robot_1" || r["name"] == "robot_2")
            .collect();
        for (i, r) in demo.iter().enumerate() {
            let p = reported(r);
            let d = truth.distance(p.x, p.y);
            c.base_dist[i] = c.base_dist[i].min(d);
            c.base_gap[i] = c.base_gap[i].min(d - RADIUS - radius(r));
        }
        if let [a, b] = demo[..] {
            let (pa, pb) = (reported(a), reported(b));
            let d = pa.distance(pb.x, pb.y);
            c.demo_dist = c.demo_dist.min(d);
            c.demo_gap = c.demo_gap.min(d - radius(a) - radius(b));
        }
    }
    c
}

#[test]
fn among_simulated_robots_crossing_its_path_every_disc_keeps_its_distance() {
    if base_rig::skip_unless_available() {
        return;
    }
    // robot_1 (diff-drive) at (1.17, 1.4) and robot_2 (kiwi) at (2.73,
    // 1.4) swap places while the base crosses their path from the bottom
    // edge to the top, all through the centre.
    // They start once the base is 0.4 m from the centre, so that the
    // three meet there (the simulated robots are faster).
    let mut rig = BaseRig::start(Setup::new(2, Pose2::new(1.95, 0.45, FRAC_PI_2)));
    let t0 = now();
    rig.op.run("waypoint robot_1 2.73,1.4");
    rig.op.run("waypoint robot_2 1.17,1.4");
    rig.op.run(&format!("waypoint {NAME} 1.95,2.35"));
    rig.op.run("cluster pair robot_1 robot_2");
    rig.op.run("send pair");
    rig.op.run(&format!("send {NAME}"));
    route(&mut rig, "wp/gcs");
    rig.eventually("the base near the centre", |r| {
        (r.truth().y > 1.0).then_some(())
    });
    rig.op.run("route pair wp/gcs");
    let finished = |r: &serde_json::Value| {
        let m = &r["mission"];
        m["total"].as_u64() == Some(1) && m["next"] == m["total"]
    };
    let arrived = rig::poll(WAIT_MISSION, || {
        let snaps = rig.op.snapshots_since(now() - 1.0);
        let (_, fleet) = snaps.last()?;
        let robots = fleet["robots"].as_array()?;
        (robots.len() == 3 && robots.iter().all(finished)).then_some(())
    })
    .is_some();
    let track = rig.track(t0);
    let snaps = rig.op.snapshots_since(t0);

    let Closest {
        base_dist,
        base_gap,
        demo_dist,
        demo_gap,
    } = closest(&track, &snaps);
    let end = rig.truth();
    eprintln!(
        "figure: ros2 base among 2 simulated robots: min centre distance to robot_1 {:.3} m, \
         robot_2 {:.3} m, robot_1-robot_2 {:.3} m; min gap between discs {:.3} m, {:.3} m, {:.3} m \
         (margin {MARGIN} m) over {} snapshots; all arrived: {arrived}, base ends at ({:.2}, {:.2})",
        base_dist[0],
        base_dist[1],
        demo_dist,
        base_gap[0],
        base_gap[1],
        demo_gap,
        snaps.len(),
        end.x,
        end.y
    );
    assert!(snaps.len() > 100, "{} snapshots", snaps.len());
    // The paths crossed: the base went through the centre line.
    assert!(
        end.y > 1.9,
        "the base crossed the simulated robots' path: ends at {end:?}\n{}",
        rig.logs()
    );
    // A reported centre is the robot's estimate, off its truth by up to
    // its position error (a few cm on the demo's noise): the gap kept on
    // those is the margin, less what the estimates are off.
    for (what, gap) in [
        ("ros2 base - robot_1", base_gap[0]),
        ("ros2 base - robot_2", base_gap[1]),
        ("robot_1 - robot_2", demo_gap),
    ] {
        assert!(
            gap > MARGIN - 0.05,
            "{what}: discs {gap:.3} m apart (margin {MARGIN})\n{}",
            rig.logs()
        );
    }
}

/// A controller drives the base on a small circle (0.2 m radius) at
/// (0.8, 0.8), well away from robot_1 at the arena's centre.
fn circling(setup: Setup) -> (BaseRig, Pad) {
    let mut rig = BaseRig::start(setup);
    route(&mut rig, PAD);
    let pad = Pad::start(&rig.op, PAD, NAME, 0.12, 0.6);
    until_circling(&mut rig, "the base circling");
    (rig, pad)
}

fn until_circling(rig: &mut BaseRig, what: &str) {
    rig.eventually(what, |r| {
        let s = r.state();
        (num(&s["v"]) > 0.1 && num(&s["w"]) > 0.5).then_some(())
    });
}

/// Waits until the robot reports its outputs held for a fault.
fn until_fault(rig: &mut BaseRig, what: &str) {
    rig.eventually(what, |r| {
        (r.robot()["failsafe"].as_u64() == Some(FAULT)).then_some(())
    });
}

/// The failsafe state of a robot whose outputs are held because its
/// vehicle cannot be driven (`FailsafeState` 4).
const FAULT: u64 = 4;

/// The count a refusal notice gives (`... (N refused)`).
fn refused_count(notice: &serde_json::Value) -> Option<u64> {
    let text = notice["text"].as_str()?;
    let open = text.rfind('(')?;
    text[open + 1..].strip_suffix(" refused)")?.parse().ok()
}

#[test]
fn nan_odometry_is_refused_counted_told_and_never_the_pose() {
    if base_rig::skip_unless_available() {
        return;
    }
    let (mut rig, pad) = circling(Setup::new(1, Pose2::new(0.8, 0.6, 0.0)));
    let t = now();
    rig.base.ask(json!({"op": "nan", "on": true, "field": "x"}));
    let (first, notice) = rig.eventually("the station told of NaN odometry", |r| {
        r.op.heard(t, &[NAME, "odometry", "/tb3_1/odom", "refused"])
    });
    // With no usable odometry the base is held at zero, as a fault.
    let zero = until_held(&mut rig, t, "the base held on NaN odometry");
    until_fault(&mut rig, "the robot reports the hold as a fault");
    // Refusals are told again (at most every 5 s), counted.
    let (_, again) = rig.eventually_within(WAIT_MISSION, "the refusals told again, counted", |r| {
        r.op.heard_all(first, &[NAME, "odometry", "/tb3_1/odom", "refused"])
            .into_iter()
            .find(|(_, m)| refused_count(m) > Some(1))
    });
    eprintln!(
        "figure: ros2 base NaN odometry -> zero cmd_vel {:.3} s; notices: {} | {}",
        zero - t,
        notice["text"],
        again["text"]
    );
    let snaps = rig.op.snapshots_since(t);
    let nan_pose = snaps.iter().find_map(|(_, f)| {
        let r = f["robots"].as_array()?.iter().find(|r| r["name"] == NAME)?;
        let p = reported(r);
        (!(p.x.is_finite() && p.y.is_finite() && p.heading.is_finite())).then(|| r.clone())
    });
    assert!(nan_pose.is_none(), "a NaN became the pose: {nan_pose:?}");
    // A NaN orientation and a NaN speed are refused alike.
    for field in ["yaw", "vx"] {
        rig.base
            .ask(json!({"op": "nan", "on": true, "field": field}));
        std::thread::sleep(Duration::from_secs(1));
        let s = rig.state();
        assert_eq!(num(&s["v"]), 0.0, "NaN {field}: the base moves: {s}");
    }

    // Good odometry again: it is obeyed again, and the pose follows it
    // (compared once the controller is gone and the base stands).
    rig.base.ask(json!({"op": "nan", "on": false}));
    until_circling(&mut rig, "the base circling again on good odometry");
    drop(pad);
    reported_pose_is_origin_composed_with_odometry(&mut rig);
}

#[test]
fn odometry_gone_silent_holds_the_base_and_its_mission_goes_on_after() {
    if base_rig::skip_unless_available() {
        return;
    }
    let mut rig = BaseRig::start(Setup::new(1, Pose2::new(0.6, 0.5, FRAC_PI_2)));
    let goal = (0.6, 1.9);
    rig.op
        .run(&format!("waypoint {NAME} {},{}", goal.0, goal.1));
    rig.op.run(&format!("send {NAME}"));
    route(&mut rig, "wp/gcs");
    until_driving(&mut rig, "the base driving its mission");

    let t = now();
    rig.base.ask(json!({"op": "silence", "on": true}));
    let zero = until_held(&mut rig, t, "the base held without odometry");
    let (heard, notice) = rig.eventually("the station told of no odometry", |r| {
        r.op.heard(t, &[NAME, "no odometry", "/tb3_1/odom", "ROS_DOMAIN_ID"])
    });
    until_fault(&mut rig, "the robot reports the hold as a fault");
    eprintln!(
        "figure: ros2 base odometry silent -> zero cmd_vel {:.3} s, notice after {:.3} s (odom_timeout 2 s): {}",
        zero - t,
        heard - t,
        notice["text"]
    );
    assert!(
        zero - t > 1.0,
        "held before the odometry timed out ({:.3} s)",
        zero - t
    );
    let held_at = rig.truth();

    // Odometry back: the mission goes on from where the base stood.
    let t = now();
    rig.base.ask(json!({"op": "silence", "on": false}));
    rig.eventually("the station told the odometry is back", |r| {
        r.op.heard(t, &[NAME, "odometry", "/tb3_1/odom", "again"])
    });
    rig.eventually_within(WAIT_MISSION, "the mission finished after the hold", |r| {
        let m = &r.robot()["mission"];
        (m["total"].as_u64() == Some(1) && m["next"] == m["total"]).then_some(())
    });
    let end = rig.truth();
    let error = end.distance(goal.0, goal.1);
    eprintln!(
        "figure: ros2 base mission after an odometry hold at y = {:.3}: arrival error {error:.3} m",
        held_at.y
    );
    assert!(
        error <= ARRIVAL_RADIUS + 0.02 && held_at.distance(goal.0, goal.1) > 0.3,
        "held at {held_at:?}, ended at {end:?}"
    );
}

#[test]
fn a_second_writer_on_its_cmd_vel_holds_the_base_and_tells_the_station() {
    if base_rig::skip_unless_available() {
        return;
    }
    let (mut rig, _pad) = circling(Setup::new(1, Pose2::new(0.8, 0.6, 0.0)));
    let t = now();
    rig.base.ask(json!({"op": "intruder", "vx": 0.1}));
    let (heard, notice) = rig.eventually("the station told of a second cmd_vel writer", |r| {
        r.op.heard(t, &[NAME, "/tb3_1/cmd_vel", "another"])
    });
    let zero = rig.eventually(
        "the agent's cmd_vel at zero while the other is heard",
        |r| zero_from(&r.cmds(t), t),
    );
    until_fault(&mut rig, "the robot reports the hold as a fault");
    eprintln!(
        "figure: ros2 base second cmd_vel writer -> notice {:.3} s, agent's cmd_vel zero {:.3} s: {}",
        heard - t,
        zero - t,
        notice["text"]
    );
    let s = rig.state();
    assert!(s["cmd_writers"].as_u64() >= Some(2), "{s}");
    // Still zero a second later, the other writer still at it.
    std::thread::sleep(Duration::from_secs(1));
    let mine = agents(&rig.cmds(now() - 1.0));
    assert!(
        mine.len() >= 5 && mine.iter().all(is_zero),
        "the agent's cmd_vel while another writes: {mine:?}"
    );
    let t = now();
    rig.base.ask(json!({"op": "intruder_stop"}));
    rig.eventually("the station told the other writer left", |r| {
        r.op.heard(t, &[NAME, "no other writer", "/tb3_1/cmd_vel"])
    });
    rig.eventually("the base circling again once the other writer left", |r| {
        let mine = agents(&r.cmds(now() - 0.5));
        mine.iter().any(|c| !is_zero(c)).then_some(())
    });
    until_circling(&mut rig, "the base circling again");
}

#[test]
fn twist_stamped_and_best_effort_odometry_drive_it_too() {
    if base_rig::skip_unless_available() {
        return;
    }
    // A TurtleBot 4 on Jazzy: TwistStamped, odometry best effort.
    let mut setup = Setup::new(1, Pose2::new(0.8, 0.6, 0.0));
    setup.ros2 = "cmd_vel_type = \"twist-stamped\"\nodom_qos = \"best-effort\"".into();
    setup.base_args = ["--stamped", "--odom-qos", "best-effort"]
        .map(String::from)
        .to_vec();
    let (mut rig, pad) = circling(setup);
    let s = rig.state();
    assert_eq!(s["cmd"]["frame"], "base_link", "{s}");
    drop(pad);
    reported_pose_is_origin_composed_with_odometry(&mut rig);
}
