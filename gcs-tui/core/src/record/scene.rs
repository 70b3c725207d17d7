//! The fleet as a `foxglove.SceneUpdate`: each robot an arrow along its
//! heading with its name, coloured by link state; each robot's mission as a
//! line through its waypoints; each cluster's centre. Every update replaces
//! the whole scene (a delete-all first), so robots and clusters that went
//! away disappear.

use std::time::Duration;

use serde_json::{Value, json};

use super::encode::{Time, WORLD, foxglove_pose};
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
    let mut entities = Vec::with_capacity(fleet.robots.len() * 2 + fleet.clusters.len());
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

fn robot(t: Time, r: &Robot) -> Value {
    let color = match r.link {
        LinkState::Connected => rgba(0.2, 0.8, 0.3, 1.0),
        LinkState::Stale => rgba(0.95, 0.7, 0.1, 1.0),
        LinkState::Lost => rgba(0.9, 0.2, 0.2, 1.0),
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
            json!([label(
                p.x,
                p.y,
                p.z + 0.2,
                &r.name,
                rgba(1.0, 1.0, 1.0, 1.0)
            )]),
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
