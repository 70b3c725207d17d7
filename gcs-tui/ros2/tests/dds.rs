//! The bridge end to end against an independent DDS: Cyclone DDS, through
//! its Python binding, acting as a ROS 2 node (`tests/ros2_node.py`: ROS 2
//! topic and type names, the `.msg` field layout), with `mech-gcs serve
//! --demo` as the station and `mech-ros2` between them, all in a network
//! namespace of their own (DDS discovery is multicast).
//!
//! Shown: odometry and TF for every simulated robot, with the ROS 2
//! layout; cmd_vel drives a robot only while it is routed to its ROS 2
//! channel; goal_pose gets a robot to the goal; NaN, out-of-range,
//! wrong-frame and unknown-robot input refused and counted on
//! `/diagnostics` and in the bridge's last line; an e-stop engaged from
//! ROS 2 stops every robot; attached to the station, each robot's link as
//! the station measures it on `/diagnostics` and the arena on
//! `/mech/markers`.

#![allow(clippy::unwrap_used)]

#[path = "support/rig.rs"]
mod rig;

use rig::{Rig, eventually};
use serde_json::{Value, json};

/// Farther than this between two odometry samples of a robot told
/// nothing is a robot that moved, m. The demo's positions are noisy like
/// UWB (3 cm sigma and outliers, through a median filter): two samples of a
/// robot standing still differ by up to a few centimetres (5 cm was seen
/// exceeded), while a robot obeying any cmd_vel here (0.4 m/s, or 50 m/s
/// clamped to its top speed) is farther than this within the second the
/// checks take; its odometry's speed, zero, is checked too.
const STILL: f64 = 0.15;

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or(f64::NAN)
}

/// A robot's latest odometry (x, y, vx, count), once it has one.
fn odom(s: &Value, robot: &str) -> Option<(f64, f64, f64, u64)> {
    let o = s["odom"].get(robot)?;
    Some((f(&o["x"]), f(&o["y"]), f(&o["vx"]), o["count"].as_u64()?))
}

/// A value of a robot's status on `/diagnostics`.
fn diag<'a>(s: &'a Value, robot: &str, key: &str) -> Option<&'a str> {
    s["diagnostics"][format!("mech: {robot}")]["values"][key].as_str()
}

/// A counter of the bridge's own status on `/diagnostics` (0 until the
/// first arrives).
fn counter(s: &Value, key: &str) -> u64 {
    s["diagnostics"]["mech: ros2 bridge"]["values"][key]
        .as_str()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0)
}

/// Odometry, TF, battery and name markers of every robot, in the ROS 2
/// layout; returns the node's state that showed them.
fn every_robot_in_the_ros2_layout(rig: &mut Rig, robots: [&str; 3]) -> Value {
    // Markers are published once a second, odometry with every sample:
    // wait for both (on a busy machine the first markers come later).
    let s = eventually(
        rig,
        "odometry, TF, diagnostics and markers of every robot",
        |s| {
            (robots.iter().all(|r| {
                odom(s, r).is_some_and(|o| o.3 >= 10)
                    && s["tf"][format!("{r}/base_link")]["count"].as_u64() >= Some(10)
                    && diag(s, r, "route").is_some()
            }) && s["markers"]["mech/names/0"].is_object())
            .then(|| s.clone())
        },
    );
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_secs_f64();
    for r in robots {
        let o = &s["odom"][r];
        assert_eq!(o["frame_id"], "map", "{o}");
        assert_eq!(o["child_frame_id"], format!("{r}/base_link"), "{o}");
        assert_eq!(o["covariance_len"], 36, "{o}");
        assert!(
            (f(&o["q_norm"]) - 1.0).abs() < 1e-9,
            "a unit quaternion: {o}"
        );
        assert!(
            (f(&o["stamp"]) - now).abs() < 30.0,
            "stamped with station time: {o}"
        );
        assert!(f(&o["x"]).is_finite() && f(&o["y"]).is_finite(), "{o}");
        let tf = &s["tf"][format!("{r}/base_link")];
        assert_eq!(tf["parent"], "map", "{tf}");
        assert!(
            (f(&tf["x"]) - f(&o["x"])).abs() < 0.5,
            "TF and odometry agree: {tf} {o}"
        );
        assert_eq!(
            diag(&s, r, "route"),
            Some("none"),
            "a new robot is routed to none"
        );
        let b = &s["battery"][r];
        assert_eq!(b["frame_id"], format!("{r}/base_link"), "{b}");
        assert_eq!(b["voltage_is_nan"], true, "unknown is NaN: {b}");
    }
    assert!(
        s["markers"]["mech/names/0"]["text"] == "robot_1",
        "{}",
        s["markers"]
    );
    s
}

/// robot_2 routed to its ROS 2 channel, sent NaN and too fast a cmd_vel:
/// refused, counted, never forwarded; it does not move. A robot the
/// station does not have: refused and counted.
fn bad_cmd_vel_refused_and_counted(rig: &mut Rig) {
    rig.script("route robot_2 ros2/robot_2\n");
    let s = rig.node.state();
    let (x2, y2, _, _) = odom(&s, "robot_2").unwrap();
    rig.node
        .ask(json!({"op": "drive", "robot": "robot_2", "vx": "nan", "wz": 0.1}));
    eventually(rig, "NaN cmd_vel refused and counted", |s| {
        (counter(s, "refused_not_finite") >= 10).then_some(())
    });
    rig.node
        .ask(json!({"op": "drive", "robot": "robot_2", "vx": 50.0}));
    eventually(rig, "a 50 m/s cmd_vel refused and counted", |s| {
        (counter(s, "refused_out_of_range") >= 10).then_some(())
    });
    rig.node.ask(json!({"op": "halt", "robot": "robot_2"}));
    let s = rig.node.state();
    let (x, y, vx, _) = odom(&s, "robot_2").unwrap();
    assert!(
        (x - x2).hypot(y - y2) < STILL && vx.abs() < 1e-6,
        "robot_2 moved on refused input: ({x2}, {y2}) -> ({x}, {y}), vx {vx}"
    );
    assert_eq!(diag(&s, "robot_2", "cmd_vel_forwarded"), Some("0"), "{s}");

    // A robot the station does not have: refused and counted.
    rig.node
        .ask(json!({"op": "drive", "robot": "robot_9", "vx": 0.2}));
    eventually(rig, "cmd_vel for robot_9 refused as unknown", |s| {
        (counter(s, "refused_unknown_robot") >= 10).then_some(())
    });
    rig.node.ask(json!({"op": "halt", "robot": "robot_9"}));
}

/// Attached to the station (`--attach` its control socket): each robot's
/// link as the station's router measures it on `/diagnostics`, and the
/// demo's arena on `/mech/markers`.
fn the_stations_link_figures_and_arena_through_attaching(rig: &mut Rig, robots: [&str; 3]) {
    let s = eventually(rig, "link quality on /diagnostics and the arena", |s| {
        let linked = robots.iter().all(|r| {
            diag(s, r, "station_link") == Some("connected")
                && diag(s, r, "station_loss").is_some()
                && diag(s, r, "station_rx_hz")
                    .and_then(|v| v.parse::<f64>().ok())
                    .is_some_and(|hz| hz > 1.0)
        });
        let arena = s["markers"]["mech/arena/0"]["type"] == 4;
        (linked && arena).then(|| s.clone())
    });
    assert_eq!(
        s["diagnostics"]["mech: ros2 bridge"]["values"]["station_attached"], "yes",
        "{}",
        s["diagnostics"]
    );
    assert_eq!(s["markers"]["mech/arena/0"]["frame_id"], "map");
}

/// Attached: a mission the station sends (an operator's waypoints) is
/// drawn, its path and next waypoint, while the robot runs it. Last in its
/// test: robot_3 then drives on.
fn the_stations_mission_drawn_through_attaching(rig: &mut Rig) {
    rig.script(
        "waypoint robot_3 2.9,0.6\nwaypoint robot_3 2.9,2.2\nsend robot_3\nroute robot_3 wp/gcs\n",
    );
    eventually(rig, "robot_3's mission from the station drawn", |s| {
        let path = &s["markers"]["mech/missions/2"];
        let next = &s["markers"]["mech/mission_next/2"];
        (path["type"] == 4 && path["action"] == 0 && next["type"] == 2).then_some(())
    });
}

#[test]
fn odometry_and_tf_for_every_robot_and_cmd_vel_obeyed_only_while_routed() {
    if rig::skip_unless_available() {
        return;
    }
    let mut rig = Rig::start(3, &["--attach", "@DIR@/gcs.sock"], false);
    let robots = ["robot_1", "robot_2", "robot_3"];

    let s = every_robot_in_the_ros2_layout(&mut rig, robots);
    the_stations_link_figures_and_arena_through_attaching(&mut rig, robots);

    // cmd_vel for robot_1 while it is routed to none: forwarded by the
    // bridge, dropped by the router; the robot holds still.
    let (x0, y0, _, _) = odom(&s, "robot_1").unwrap();
    rig.node
        .ask(json!({"op": "drive", "robot": "robot_1", "vx": 0.4, "wz": 0.0}));
    let s = eventually(&mut rig, "20 cmd_vel forwarded for robot_1", |s| {
        (diag(s, "robot_1", "cmd_vel_forwarded")?
            .parse::<u64>()
            .ok()?
            >= 20)
            .then(|| s.clone())
    });
    let (x, y, vx, _) = odom(&s, "robot_1").unwrap();
    assert!(
        (x - x0).hypot(y - y0) < STILL && vx.abs() < 1e-6,
        "robot_1 moved before it was routed to ros2/robot_1: ({x0}, {y0}) -> ({x}, {y}), vx {vx}"
    );

    // Routed: it drives.
    rig.script("route robot_1 ros2/robot_1\n");
    eventually(&mut rig, "robot_1 driving on cmd_vel", |s| {
        let (x, y, vx, _) = odom(s, "robot_1")?;
        ((x - x0).hypot(y - y0) > 0.3
            && (vx - 0.4).abs() < 0.05
            && diag(s, "robot_1", "obeys_cmd_vel") == Some("true"))
        .then_some(())
    });

    // Routed elsewhere: it stops although cmd_vel keeps coming.
    rig.script("route robot_1 none\n");
    let before = counter(&rig.node.state(), "cmd_forwarded");
    eventually(&mut rig, "robot_1 stopped once routed to none", |s| {
        let (_, _, vx, _) = odom(s, "robot_1")?;
        (vx.abs() < 1e-6
            && diag(s, "robot_1", "route") == Some("none")
            && counter(s, "cmd_forwarded") > before + 10)
            .then_some(())
    });
    rig.node.ask(json!({"op": "halt", "robot": "robot_1"}));

    bad_cmd_vel_refused_and_counted(&mut rig);
    the_stations_mission_drawn_through_attaching(&mut rig);

    let last = rig.stop_bridge();
    let stats = &last["stats"];
    assert_eq!(last["type"], "ros2", "{last}");
    assert!(stats["refused_not_finite"].as_u64() >= Some(10), "{last}");
    assert!(stats["refused_out_of_range"].as_u64() >= Some(10), "{last}");
    assert!(
        stats["refused_unknown_robot"].as_u64() >= Some(10),
        "{last}"
    );
    assert!(stats["cmd_forwarded"].as_u64() >= Some(20), "{last}");
    assert_eq!(stats["link_rejected"], 0, "{last}");
}

/// A goal in frame odom is refused, and so is a TwistStamped in frame map
/// (cmd_vel is body-frame).
fn wrong_frames_refused(rig: &mut Rig, goal: (f64, f64)) {
    rig.node
        .ask(json!({"op": "goal", "robot": "robot_1", "x": goal.0, "y": goal.1, "frame": "odom"}));
    eventually(rig, "a goal in frame odom refused", |s| {
        (counter(s, "refused_wrong_frame") >= 1).then_some(())
    });
    assert_eq!(counter(&rig.node.state(), "goals_sent"), 0);

    // A TwistStamped in the map frame is refused too (cmd_vel is
    // body-frame).
    rig.node
        .ask(json!({"op": "drive", "robot": "robot_2", "vx": 0.2, "frame": "map"}));
    eventually(rig, "a TwistStamped in frame map refused", |s| {
        (counter(s, "refused_wrong_frame") >= 5).then_some(())
    });
    rig.node.ask(json!({"op": "halt", "robot": "robot_2"}));
}

#[test]
fn goal_pose_gets_a_robot_there_and_an_estop_from_ros_stops_every_robot() {
    if rig::skip_unless_available() {
        return;
    }
    let mut rig = Rig::start(
        2,
        &["--cmd-vel", "stamped", "--estop-service", "cyclone"],
        true,
    );
    let s = eventually(&mut rig, "odometry of both robots", |s| {
        (odom(s, "robot_1").is_some() && odom(s, "robot_2").is_some()).then(|| s.clone())
    });
    let (x0, y0, _, _) = odom(&s, "robot_1").unwrap();
    let goal = (x0 + 1.0, y0 + 0.5);

    wrong_frames_refused(&mut rig, goal);

    // Routed to its goal channel, robot_1 goes to the goal rviz2 would send.
    rig.script("route robot_1 ros2goal/robot_1\n");
    rig.node.ask(json!({"op": "goal", "robot": "robot_1", "x": goal.0, "y": goal.1, "frame": "map", "yaw": 0.5}));
    eventually(&mut rig, "robot_1 at its goal", |s| {
        let (x, y, _, _) = odom(s, "robot_1")?;
        ((x - goal.0).hypot(y - goal.1) < 0.15 && counter(s, "goals_acked") >= 1).then_some(())
    });
    let s = rig.node.state();
    let m = &s["markers"]["mech/goals/0"];
    assert_eq!(
        (m["type"].as_i64(), m["action"].as_i64()),
        (Some(2), Some(0)),
        "{m}"
    );
    assert!((f(&m["x"]) - goal.0).abs() < 1e-9, "the goal's marker: {m}");

    // A stamped cmd_vel in the body frame drives robot_2 once routed.
    rig.script("route robot_2 ros2/robot_2\n");
    let (x2, y2, _, _) = odom(&rig.node.state(), "robot_2").unwrap();
    rig.node
        .ask(json!({"op": "drive", "robot": "robot_2", "vx": 0.3, "frame": "robot_2/base_link"}));
    eventually(&mut rig, "robot_2 driving on TwistStamped", |s| {
        let (x, y, _, _) = odom(s, "robot_2")?;
        ((x - x2).hypot(y - y2) > 0.2).then_some(())
    });

    // E-stop engaged from ROS 2, calling the std_srvs/Trigger service
    // as rmw_cyclonedds does: answered, and every robot reports it.
    let answer = rig.node.ask(json!({"op": "estop_call"}));
    assert_eq!(answer["success"], true, "{answer}");
    assert!(
        answer["message"]
            .as_str()
            .unwrap_or("")
            .contains("only an operator"),
        "{answer}"
    );
    eventually(&mut rig, "every robot e-stopped", |s| {
        (diag(s, "robot_1", "failsafe") == Some("estopped")
            && diag(s, "robot_2", "failsafe") == Some("estopped")
            && counter(s, "estops_sent") >= 1)
            .then_some(())
    });
    eventually(
        &mut rig,
        "robot_2 stopped although cmd_vel keeps coming",
        |s| {
            let (_, _, vx, _) = odom(s, "robot_2")?;
            (vx.abs() < 1e-6).then_some(())
        },
    );
    let last = rig.stop_bridge();
    assert!(
        last["stats"]["refused_wrong_frame"].as_u64() >= Some(5),
        "{last}"
    );
    assert!(last["stats"]["goals_acked"].as_u64() >= Some(1), "{last}");
}

#[test]
fn at_a_station_with_keys_the_bridge_is_a_controller_its_auth_section_limits() {
    if rig::skip_unless_available() {
        return;
    }
    // The bridge's key may publish on ros2/* only: its goals (on
    // ros2goal/*) are refused by the router's gate.
    let station = "[auth]\nmode = \"required\"\n\
        [[auth.keys]]\nrole = \"controller\"\nname = \"ros2\"\nfile = \"ros2.key\"\n\
        channels = [\"ros2/*\"]\n\
        [[auth.keys]]\nrole = \"estop\"\nname = \"ros2-estop\"\nfile = \"ros2-estop.key\"\n";
    let mut rig = Rig::start_with(
        2,
        Some(station),
        &["ros2", "ros2-estop"],
        &[
            "--key",
            "@DIR@/ros2.key",
            "--estop-key",
            "@DIR@/ros2-estop.key",
        ],
        false,
    );
    let s = eventually(
        &mut rig,
        "odometry of both robots, signed all the way",
        |s| (odom(s, "robot_1").is_some() && odom(s, "robot_2").is_some()).then(|| s.clone()),
    );
    let (x0, y0, _, _) = odom(&s, "robot_1").unwrap();
    rig.script("route robot_1 ros2/robot_1\n");
    rig.node
        .ask(json!({"op": "drive", "robot": "robot_1", "vx": 0.3}));
    eventually(&mut rig, "robot_1 driving on signed cmd_vel", |s| {
        let (x, y, _, _) = odom(s, "robot_1")?;
        ((x - x0).hypot(y - y0) > 0.2).then_some(())
    });
    rig.node.ask(json!({"op": "halt", "robot": "robot_1"}));

    rig.script("route robot_2 ros2goal/robot_2\n");
    rig.node
        .ask(json!({"op": "goal", "robot": "robot_2", "x": 0.0, "y": 0.0, "frame": "map"}));
    // Refused by the station's gate, and the bridge is told why at once
    // (the station answers for the robot), not left to give up after 5 s.
    eventually(&mut rig, "the goal refused by the station's gate", |s| {
        (counter(s, "goals_sent") == 1
            && counter(s, "goals_acked") == 1
            && counter(s, "goals_unacked") == 0)
            .then_some(())
    });
    let station_log = std::fs::read_to_string(rig.dir.path().join("station.log")).unwrap();
    assert!(
        station_log
            .lines()
            .any(|l| l.contains("refused") && l.contains("ros2goal/robot_2")),
        "the router says why:\n{station_log}"
    );
    let bridge_log = std::fs::read_to_string(rig.dir.path().join("bridge.log")).unwrap();
    assert!(
        bridge_log.lines().any(|l| l.contains(
            "goal refused: refused by the station: controller ros2 may not publish on \"ros2goal/robot_2\""
        )),
        "the bridge says why:\n{bridge_log}"
    );

    rig.node.ask(json!({"op": "estop"}));
    eventually(
        &mut rig,
        "both robots e-stopped through the e-stop key",
        |s| {
            (diag(s, "robot_1", "failsafe") == Some("estopped")
                && diag(s, "robot_2", "failsafe") == Some("estopped"))
            .then_some(())
        },
    );
    let last = rig.stop_bridge();
    assert_eq!(last["stats"]["link_rejected"], 0, "{last}");
    assert_eq!(last["stats"]["estops_refused"], 0, "{last}");
}
