//! Markers for rviz2 on `/mech/markers` (visualization_msgs/MarkerArray):
//! each robot's name over it, and each goal the bridge sent, with a line
//! from the robot to it while it is being approached; with the bridge
//! attached to the station, the arena (boundary, keep-outs, slow zones,
//! obstacles: [`arena_markers`]) and the missions the station sent
//! ([`mission_markers`]).
//!
//! Waypoints of missions other external controllers sent go from their
//! sender to the robot and are in nothing the bridge receives, so they are
//! not drawn.

use mech_core::arena::ArenaShape;
use mech_proto::Telemetry;
use mech_station::view::MissionView;

use crate::fleet::Goal;
use crate::msgs::builtin::{Duration, Time};
use crate::msgs::geometry::{Point, Pose, Vector3};
use crate::msgs::std::{ColorRgba, Header};
use crate::msgs::visualization::{
    ADD, CYLINDER, DELETE, LINE_STRIP, Marker, SPHERE, TEXT_VIEW_FACING,
};

/// Marker namespaces: rviz2 lists and toggles them.
pub const NS_NAMES: &str = "mech/names";
pub const NS_GOALS: &str = "mech/goals";
pub const NS_GOAL_LINES: &str = "mech/goal_lines";
pub const NS_ARENA: &str = "mech/arena";
pub const NS_KEEP_OUT: &str = "mech/keep_out";
pub const NS_SLOW_ZONES: &str = "mech/slow_zones";
pub const NS_OBSTACLES: &str = "mech/obstacles";
pub const NS_MISSIONS: &str = "mech/missions";
pub const NS_MISSION_NEXT: &str = "mech/mission_next";

/// Markers live this long without an update (they are sent every second),
/// so a bridge that stops leaves nothing behind.
const LIFETIME: Duration = Duration { sec: 3, nanosec: 0 };

const WHITE: ColorRgba = ColorRgba {
    r: 1.0,
    g: 1.0,
    b: 1.0,
    a: 1.0,
};
const ORANGE: ColorRgba = ColorRgba {
    r: 1.0,
    g: 0.6,
    b: 0.1,
    a: 0.9,
};
const GREEN: ColorRgba = ColorRgba {
    r: 0.2,
    g: 0.9,
    b: 0.3,
    a: 0.9,
};
const RED: ColorRgba = ColorRgba {
    r: 0.95,
    g: 0.2,
    b: 0.15,
    a: 0.9,
};
const YELLOW: ColorRgba = ColorRgba {
    r: 0.95,
    g: 0.85,
    b: 0.1,
    a: 0.8,
};
const BLUE: ColorRgba = ColorRgba {
    r: 0.2,
    g: 0.5,
    b: 1.0,
    a: 0.9,
};
const GREY: ColorRgba = ColorRgba {
    r: 0.6,
    g: 0.6,
    b: 0.6,
    a: 0.7,
};

fn marker(ns: &str, id: i32, kind: i32, map: &str, stamp: Time) -> Marker {
    Marker {
        header: Header {
            stamp,
            frame_id: map.to_string(),
        },
        ns: ns.to_string(),
        id,
        r#type: kind,
        action: ADD,
        pose: Pose::default(),
        lifetime: LIFETIME,
        ..Marker::default()
    }
}

/// Where a goal stands, from the robot's telemetry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GoalState {
    /// Sent, not yet acknowledged, or held but not being run (the robot
    /// is routed elsewhere).
    Waiting,
    /// The robot is running it.
    Active,
    /// The robot reports it finished.
    Reached,
    /// Refused by the robot or never acknowledged.
    Failed,
}

/// The state of `goal` given the robot's latest telemetry.
pub fn goal_state(goal: &Goal, t: &Telemetry) -> GoalState {
    if goal.unacked || goal.ack.as_ref().is_some_and(|(ok, _)| !ok) {
        return GoalState::Failed;
    }
    match t.mission {
        Some(m) if m.id == goal.mission.id && m.next >= m.total => GoalState::Reached,
        Some(m) if m.id == goal.mission.id && t.channel == goal.channel => GoalState::Active,
        _ => GoalState::Waiting,
    }
}

/// The markers of robot number `index` (its marker ids), named `name`.
pub fn robot_markers(
    index: i32,
    name: &str,
    t: &Telemetry,
    goal: Option<&Goal>,
    map: &str,
    stamp: Time,
) -> Vec<Marker> {
    let p = &t.pose;
    let mut label = marker(NS_NAMES, index, TEXT_VIEW_FACING, map, stamp);
    label.pose.position = Point {
        x: p.x,
        y: p.y,
        z: p.z + 0.4,
    };
    label.scale.z = 0.2;
    label.color = WHITE;
    label.text = name.to_string();
    let mut out = vec![label];
    let Some(goal) = goal else {
        out.push(deleted(NS_GOALS, index, map, stamp));
        out.push(deleted(NS_GOAL_LINES, index, map, stamp));
        return out;
    };
    let Some(w) = goal.waypoint() else {
        return out;
    };
    let state = goal_state(goal, t);
    let mut sphere = marker(NS_GOALS, index, SPHERE, map, stamp);
    sphere.pose.position = Point {
        x: w.x,
        y: w.y,
        z: w.z,
    };
    let d = 2.0 * goal.mission.arrival_radius.max(0.05);
    sphere.scale = Vector3 { x: d, y: d, z: d };
    sphere.color = match state {
        GoalState::Reached => GREEN,
        GoalState::Failed => GREY,
        GoalState::Waiting | GoalState::Active => ORANGE,
    };
    out.push(sphere);
    if state == GoalState::Active {
        let mut line = marker(NS_GOAL_LINES, index, LINE_STRIP, map, stamp);
        line.scale.x = 0.03;
        line.color = ORANGE;
        line.points = vec![
            Point {
                x: p.x,
                y: p.y,
                z: p.z,
            },
            Point {
                x: w.x,
                y: w.y,
                z: w.z,
            },
        ];
        out.push(line);
    } else {
        out.push(deleted(NS_GOAL_LINES, index, map, stamp));
    }
    out
}

/// The arena: its boundary (white), keep-outs (red), slow zones (yellow)
/// as closed lines on the floor, static obstacles as red cylinders.
pub fn arena_markers(arena: &ArenaShape, map: &str, stamp: Time) -> Vec<Marker> {
    let outline = |ns: &str, id: usize, polygon: &[mech_proto::Point], color: ColorRgba| {
        let mut m = marker(ns, id as i32, LINE_STRIP, map, stamp);
        m.scale.x = 0.02;
        m.color = color;
        m.points = polygon
            .iter()
            .chain(polygon.first())
            .map(|p| Point {
                x: p.x,
                y: p.y,
                z: 0.0,
            })
            .collect();
        m
    };
    let mut out = vec![outline(NS_ARENA, 0, &arena.boundary, WHITE)];
    for (i, k) in arena.keep_out.iter().enumerate() {
        out.push(outline(NS_KEEP_OUT, i, k, RED));
    }
    for (i, z) in arena.slow_zones.iter().enumerate() {
        out.push(outline(NS_SLOW_ZONES, i, &z.polygon, YELLOW));
    }
    for (i, d) in arena.obstacles.iter().enumerate() {
        let mut m = marker(NS_OBSTACLES, i as i32, CYLINDER, map, stamp);
        m.pose.position = Point {
            x: d.x,
            y: d.y,
            z: 0.1,
        };
        m.scale = Vector3 {
            x: 2.0 * d.radius,
            y: 2.0 * d.radius,
            z: 0.2,
        };
        m.color = RED;
        out.push(m);
    }
    out
}

/// The mission the station sent robot number `index`, while the robot
/// runs it (its telemetry reports that mission, not finished): its path
/// through every waypoint (closed when looped) and a sphere on the next.
/// Otherwise both markers are deleted.
pub fn mission_markers(
    index: i32,
    mission: &MissionView,
    t: &Telemetry,
    map: &str,
    stamp: Time,
) -> Vec<Marker> {
    let next = match t.mission {
        Some(m) if m.id == mission.id && m.next < m.total => m.next as usize,
        _ => {
            return vec![
                deleted(NS_MISSIONS, index, map, stamp),
                deleted(NS_MISSION_NEXT, index, map, stamp),
            ];
        }
    };
    let at = |w: &mech_proto::Waypoint| Point {
        x: w.x,
        y: w.y,
        z: w.z,
    };
    let mut path = marker(NS_MISSIONS, index, LINE_STRIP, map, stamp);
    path.scale.x = 0.02;
    path.color = BLUE;
    path.points = mission.waypoints.iter().map(at).collect();
    if mission.looped {
        path.points.extend(mission.waypoints.first().map(at));
    }
    let mut out = vec![path];
    match mission.waypoints.get(next) {
        Some(w) => {
            let mut sphere = marker(NS_MISSION_NEXT, index, SPHERE, map, stamp);
            sphere.pose.position = at(w);
            sphere.scale = Vector3 {
                x: 0.1,
                y: 0.1,
                z: 0.1,
            };
            sphere.color = BLUE;
            out.push(sphere);
        }
        None => out.push(deleted(NS_MISSION_NEXT, index, map, stamp)),
    }
    out
}

fn deleted(ns: &str, id: i32, map: &str, stamp: Time) -> Marker {
    Marker {
        action: DELETE,
        ..marker(ns, id, SPHERE, map, stamp)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fleet::tests::telemetry;
    use mech_proto::{Mission, MissionProgress, Waypoint};
    use std::time::Instant;

    fn goal() -> Goal {
        let now = Instant::now();
        Goal {
            mission: Mission {
                id: 7,
                waypoints: vec![Waypoint {
                    x: 2.0,
                    y: 1.0,
                    z: 0.0,
                    time: None,
                }],
                looped: false,
                arrival_radius: 0.1,
                start_index: 0,
            },
            channel: "ros2goal/robot_1".into(),
            first_sent: now,
            last_sent: now,
            ack: Some((true, String::new())),
            unacked: false,
        }
    }

    #[test]
    fn a_goal_is_a_sphere_with_a_line_while_the_robot_runs_it() {
        let mut t = telemetry(0.5, 0.0);
        t.channel = "ros2goal/robot_1".into();
        t.mission = Some(MissionProgress {
            id: 7,
            next: 0,
            total: 1,
        });
        let g = goal();
        assert_eq!(goal_state(&g, &t), GoalState::Active);
        let m = robot_markers(3, "robot_1", &t, Some(&g), "map", Time::default());
        assert_eq!(m.len(), 3);
        assert_eq!(
            (m[0].ns.as_str(), m[0].text.as_str(), m[0].id),
            (NS_NAMES, "robot_1", 3)
        );
        assert_eq!((m[1].r#type, m[1].pose.position.x), (SPHERE, 2.0));
        assert_eq!((m[2].r#type, m[2].points.len()), (LINE_STRIP, 2));
        assert!(m.iter().all(|m| m.header.frame_id == "map"));

        t.mission = Some(MissionProgress {
            id: 7,
            next: 1,
            total: 1,
        });
        assert_eq!(goal_state(&g, &t), GoalState::Reached);
        let m = robot_markers(3, "robot_1", &t, Some(&g), "map", Time::default());
        assert_eq!((m[1].color, m[2].action), (GREEN, DELETE));

        t.channel = "joy/0".into();
        t.mission = None;
        assert_eq!(goal_state(&g, &t), GoalState::Waiting, "routed elsewhere");
    }

    #[test]
    fn the_arena_is_drawn_closed_with_its_keep_outs_zones_and_obstacles() {
        let mut arena = mech_core::ArenaConfig::demo().shape();
        let square = |x: f64| {
            [(x, 1.0), (x + 0.5, 1.0), (x + 0.5, 1.5), (x, 1.5)]
                .map(|(x, y)| mech_proto::Point { x, y })
                .to_vec()
        };
        arena.keep_out = vec![square(1.0)];
        arena.slow_zones = vec![mech_proto::SlowZone {
            polygon: square(2.0),
            max_speed: 0.1,
        }];
        arena.obstacles = vec![mech_proto::Disc {
            x: 3.0,
            y: 2.0,
            radius: 0.2,
        }];
        let m = arena_markers(&arena, "map", Time::default());
        let kinds: Vec<(&str, i32, usize)> = m
            .iter()
            .map(|m| (m.ns.as_str(), m.r#type, m.points.len()))
            .collect();
        assert_eq!(
            kinds,
            [
                (NS_ARENA, LINE_STRIP, arena.boundary.len() + 1),
                (NS_KEEP_OUT, LINE_STRIP, 5),
                (NS_SLOW_ZONES, LINE_STRIP, 5),
                (NS_OBSTACLES, CYLINDER, 0),
            ]
        );
        assert_eq!(m[0].points.first(), m[0].points.last(), "closed");
        assert_eq!((m[3].pose.position.x, m[3].scale.x), (3.0, 0.4));
        assert!(
            m.iter()
                .all(|m| m.header.frame_id == "map" && m.action == ADD)
        );
    }

    #[test]
    fn a_mission_the_station_sent_is_drawn_while_the_robot_runs_it() {
        let w = |x: f64| Waypoint {
            x,
            y: 1.0,
            z: 0.0,
            time: None,
        };
        let mission = MissionView {
            id: 9,
            channel: "wp/gcs".into(),
            waypoints: vec![w(1.0), w(2.0), w(3.0)],
            looped: true,
        };
        let mut t = telemetry(0.5, 0.0);
        t.mission = Some(MissionProgress {
            id: 9,
            next: 1,
            total: 3,
        });
        let m = mission_markers(2, &mission, &t, "map", Time::default());
        assert_eq!(
            (m[0].ns.as_str(), m[0].r#type, m[0].id),
            (NS_MISSIONS, LINE_STRIP, 2)
        );
        assert_eq!(
            m[0].points.len(),
            4,
            "closed: the loop goes back to the first"
        );
        assert_eq!(
            (m[1].ns.as_str(), m[1].pose.position.x),
            (NS_MISSION_NEXT, 2.0)
        );
        // Finished, or another mission: deleted.
        t.mission = Some(MissionProgress {
            id: 9,
            next: 3,
            total: 3,
        });
        let m = mission_markers(2, &mission, &t, "map", Time::default());
        assert!(m.iter().all(|m| m.action == DELETE));
        t.mission = None;
        let m = mission_markers(2, &mission, &t, "map", Time::default());
        assert!(m.iter().all(|m| m.action == DELETE));
    }

    #[test]
    fn a_robot_without_a_goal_has_its_label_only() {
        let m = robot_markers(
            0,
            "robot_2",
            &telemetry(0.0, 0.0),
            None,
            "map",
            Time::default(),
        );
        assert_eq!(m[0].action, ADD);
        assert!(m[1..].iter().all(|m| m.action == DELETE));
    }
}
