//! The fleet as a `foxglove.SceneUpdate`: the arena (its boundary, keep-outs
//! and slow zones as closed lines on the ground, its obstacle discs as
//! flat cylinders); each robot an arrow along its heading with its name,
//! coloured by link state (orange while its safety layer limits it, the
//! reason in its label); each robot's mission as a line through its
//! waypoints; each cluster's centre. Every update replaces the whole scene
//! (a delete-all first), so robots and clusters that went away disappear.

use std::time::Duration;

use mech_proto::{Intervention, Point};
use serde_json::{Value, json};

use super::encode::{Time, WORLD, foxglove_pose};
use crate::arena::ArenaShape;
use crate::event::LinkState;
use crate::fleet::{Cluster, Fleet, Robot};

/// Shortest time between two scenes of `robots` robots at most `scene_hz`
/// a second: longer for a big fleet (half a millisecond per robot), whose
/// scene takes longer to make and to draw.
pub fn period(scene_hz: f64, robots: usize) -> Duration {
    Duration::from_secs_f64((1.0 / scene_hz).max(robots as f64 * 0.0005))
}

/// The scene of `fleet` at `unix_ns` (JSON).
pub fn scene(unix_ns: u64, fleet: &Fleet) -> Vec<u8> {
    let t = Time::from_unix_ns(unix_ns);
    let mut entities = Vec::with_capacity(fleet.robots.len() * 2 + fleet.clusters.len() + 4);
    if let Some(a) = &fleet.arena {
        arena(t, a, &mut entities);
    }
    for r in fleet.robots.values() {
        entities.push(robot(t, r));
        if let Some(m) = mission(t, r) {
            entities.push(m);
        }
    }
    for c in fleet.clusters.values() {
        if let Some(e) = cluster(t, c, fleet) {
            entities.push(e);
        }
    }
    let update = json!({
        "deletions": [{"timestamp": t, "type": 1, "id": ""}],
        "entities": entities,
    });
    serde_json::to_vec(&update).unwrap_or_default()
}

/// An entity with every primitive list present (Foxglove's JSON decoding
/// expects them all) and `fill` setting the ones used.
fn entity(t: Time, id: String, fill: impl FnOnce(&mut serde_json::Map<String, Value>)) -> Value {
    let mut e = json!({
        "timestamp": t, "frame_id": WORLD, "id": id,
        "lifetime": {"sec": 0, "nsec": 0}, "frame_locked": false, "metadata": [],
        "arrows": [], "cubes": [], "spheres": [], "cylinders": [], "lines": [],
        "triangles": [], "texts": [], "models": [],
    });
    if let Value::Object(m) = &mut e {
        fill(m);
    }
    e
}

fn rgba(r: f64, g: f64, b: f64, a: f64) -> Value {
    json!({"r": r, "g": g, "b": b, "a": a})
}

fn label(x: f64, y: f64, z: f64, text: &str, color: Value) -> Value {
    json!({
        "pose": foxglove_pose(x, y, z, 0.0), "billboard": true, "font_size": 14.0,
        "scale_invariant": true, "color": color, "text": text,
    })
}

/// A closed line through `points` on the ground.
fn outline(points: &[Point], color: Value, thickness: f64) -> Value {
    let points: Vec<Value> = points
        .iter()
        .map(|p| json!({"x": p.x, "y": p.y, "z": 0.0}))
        .collect();
    json!({
        "type": 1, "pose": foxglove_pose(0.0, 0.0, 0.0, 0.0), "thickness": thickness,
        "scale_invariant": false, "points": points, "color": color, "colors": [], "indices": [],
    })
}

/// The arena: `arena/boundary` (grey), `arena/keep_out` (red),
/// `arena/slow_zones` (amber) and `arena/obstacles` (red discs).
fn arena(t: Time, a: &ArenaShape, out: &mut Vec<Value>) {
    if !a.boundary.is_empty() {
        let line = outline(&a.boundary, rgba(0.75, 0.75, 0.75, 1.0), 0.03);
        out.push(entity(t, "arena/boundary".into(), |m| {
            m.insert("lines".into(), json!([line]));
        }));
    }
    if !a.keep_out.is_empty() {
        let lines: Vec<Value> = a
            .keep_out
            .iter()
            .map(|k| outline(k, rgba(0.9, 0.2, 0.2, 1.0), 0.03))
            .collect();
        out.push(entity(t, "arena/keep_out".into(), |m| {
            m.insert("lines".into(), Value::Array(lines));
        }));
    }
    if !a.slow_zones.is_empty() {
        let lines: Vec<Value> = a
            .slow_zones
            .iter()
            .map(|z| outline(&z.polygon, rgba(0.95, 0.7, 0.1, 1.0), 0.02))
            .collect();
        out.push(entity(t, "arena/slow_zones".into(), |m| {
            m.insert("lines".into(), Value::Array(lines));
        }));
    }
    if !a.obstacles.is_empty() {
        let discs: Vec<Value> = a
            .obstacles
            .iter()
            .map(|d| {
                let size = 2.0 * d.radius;
                json!({"pose": foxglove_pose(d.x, d.y, 0.05, 0.0),
                       "size": {"x": size, "y": size, "z": 0.1},
                       "bottom_scale": 1.0, "top_scale": 1.0,
                       "color": rgba(0.9, 0.2, 0.2, 0.6)})
            })
            .collect();
        out.push(entity(t, "arena/obstacles".into(), |m| {
            m.insert("cylinders".into(), Value::Array(discs));
        }));
    }
}

fn robot(t: Time, r: &Robot) -> Value {
    let limited = r
        .telemetry
        .safety
        .map(|s| s.intervention)
        .filter(|i| *i != Intervention::None);
    let color = match (r.link, limited) {
        (LinkState::Connected, Some(_)) => rgba(1.0, 0.55, 0.0, 1.0),
        (LinkState::Connected, None) => rgba(0.2, 0.8, 0.3, 1.0),
        (LinkState::Stale, _) => rgba(0.95, 0.7, 0.1, 1.0),
        (LinkState::Lost, _) => rgba(0.9, 0.2, 0.2, 1.0),
    };
    let name = match (limited, r.safety_alarm()) {
        (_, true) => format!("{} [SAFETY OFF]", r.name),
        (Some(i), false) => format!("{} [{}]", r.name, i.as_str()),
        (None, false) => r.name.clone(),
    };
    let p = r.telemetry.pose;
    entity(t, format!("robot/{}", r.name), |m| {
        m.insert(
            "arrows".into(),
            json!([{
                "pose": foxglove_pose(p.x, p.y, p.z, p.heading), "shaft_length": 0.2,
                "shaft_diameter": 0.04, "head_length": 0.1, "head_diameter": 0.1,
                "color": color,
            }]),
        );
        m.insert(
            "texts".into(),
            json!([label(p.x, p.y, p.z + 0.2, &name, rgba(1.0, 1.0, 1.0, 1.0))]),
        );
    })
}

fn mission(t: Time, r: &Robot) -> Option<Value> {
    let sent = r.waypoints.sent.as_ref()?;
    let points: Vec<Value> = sent
        .waypoints
        .iter()
        .map(|w| json!({"x": w.x, "y": w.y, "z": w.z}))
        .collect();
    let color = rgba(0.3, 0.6, 1.0, 0.9);
    let spheres: Vec<Value> = sent
        .waypoints
        .iter()
        .map(|w| {
            json!({"pose": foxglove_pose(w.x, w.y, w.z, 0.0),
                   "size": {"x": 0.08, "y": 0.08, "z": 0.08}, "color": color})
        })
        .collect();
    let line = json!({
        "type": if sent.looped { 1 } else { 0 }, "pose": foxglove_pose(0.0, 0.0, 0.0, 0.0),
        "thickness": 0.02, "scale_invariant": false, "points": points, "color": color,
        "colors": [], "indices": [],
    });
    Some(entity(t, format!("mission/{}", r.name), |m| {
        m.insert("lines".into(), json!([line]));
        m.insert("spheres".into(), Value::Array(spheres));
    }))
}

/// A cluster's centre: the mean position of its members the fleet knows.
fn cluster(t: Time, c: &Cluster, fleet: &Fleet) -> Option<Value> {
    let poses: Vec<_> = c
        .members
        .iter()
        .filter_map(|m| fleet.robot(m))
        .map(|r| r.telemetry.pose)
        .collect();
    if poses.is_empty() {
        return None;
    }
    let n = poses.len() as f64;
    let x = poses.iter().map(|p| p.x).sum::<f64>() / n;
    let y = poses.iter().map(|p| p.y).sum::<f64>() / n;
    let color = rgba(0.9, 0.4, 0.9, 0.8);
    Some(entity(t, format!("cluster/{}", c.name), |m| {
        m.insert(
            "spheres".into(),
            json!([{"pose": foxglove_pose(x, y, 0.0, 0.0),
                    "size": {"x": 0.12, "y": 0.12, "z": 0.12}, "color": color}]),
        );
        m.insert("texts".into(), json!([label(x, y, 0.25, &c.name, color)]));
    }))
}

#[cfg(test)]
mod tests {
    use mech_proto::{Hello, InterventionCounts, SafetyReport, SafetyState};

    use super::*;
    use crate::arena::ArenaConfig;
    use crate::event::{Event, LinkAddr, Stamped};
    use crate::fleet::FleetConfig;

    fn ids(scene: &Value) -> Vec<String> {
        scene["entities"]
            .as_array()
            .unwrap()
            .iter()
            .map(|e| e["id"].as_str().unwrap().to_string())
            .collect()
    }

    #[test]
    fn the_scene_draws_the_arena_and_a_limited_robots_reason() {
        let mut fleet = Fleet::new(FleetConfig::default());
        let mut arena = ArenaConfig::demo().shape();
        arena.keep_out.push(vec![
            Point { x: 1.0, y: 1.0 },
            Point { x: 1.5, y: 1.0 },
            Point { x: 1.5, y: 1.5 },
        ]);
        fleet.apply(&Stamped {
            at: Duration::ZERO,
            event: Event::Arena { arena: Some(arena) },
        });
        fleet.apply(&Stamped {
            at: Duration::ZERO,
            event: Event::Registered {
                hello: Hello {
                    name: "robot_1".into(),
                    platform: "kiwi".into(),
                    capabilities: vec![],
                    motors: 3,
                    max_speed: 1.0,
                    max_yaw_rate: 2.0,
                    agent_version: "t".into(),
                },
                id: 1,
                addr: LinkAddr::Udp("127.0.0.1:9000".parse().unwrap()),
                known: false,
            },
        });
        fleet.robots.get_mut("robot_1").unwrap().telemetry.safety = Some(SafetyReport {
            state: SafetyState::On,
            arena: 1,
            intervention: Intervention::Fence,
            counts: InterventionCounts::default(),
            radius: 0.15,
            position_error: 0.0,
        });
        let scene: Value = serde_json::from_slice(&scene(1, &fleet)).unwrap();
        assert_eq!(
            ids(&scene),
            ["arena/boundary", "arena/keep_out", "robot/robot_1"]
        );
        let boundary = &scene["entities"][0]["lines"][0];
        assert_eq!(boundary["type"], 1, "a closed loop");
        assert_eq!(boundary["points"].as_array().unwrap().len(), 4);
        let label = &scene["entities"][2]["texts"][0]["text"];
        assert_eq!(label, "robot_1 [fence]");
    }
}
