//! `/<robot>/goal_pose`: a pose in the map frame (rviz2's "2D Goal Pose")
//! becomes a one-waypoint MECH mission. MECH waypoints have no heading, so
//! the orientation is checked (a rotation) but not sent.

use mech_proto::{Mission, Waypoint};

use super::{Refusal, Refused, frame};
use crate::msgs::geometry::PoseStamped;

/// What a goal must satisfy, and how it is sent.
#[derive(Debug, Clone, PartialEq)]
pub struct GoalRules {
    /// The only frame a goal is taken in (`map`).
    pub map_frame: String,
    /// m from the map's origin.
    pub max_distance: f64,
    /// m: the mission's arrival radius.
    pub arrival_radius: f64,
}

/// The waypoint a goal asks for, or why it is refused.
pub fn waypoint(goal: &PoseStamped, rules: &GoalRules) -> Result<Waypoint, Refused> {
    let (p, q) = (goal.pose.position, goal.pose.orientation);
    if let Some(v) = [p.x, p.y, p.z, q.x, q.y, q.z, q.w]
        .iter()
        .find(|v| !v.is_finite())
    {
        return Err(Refused::new(
            Refusal::NotFinite,
            format!("goal_pose has a component {v}"),
        ));
    }
    if frame(&goal.header.frame_id) != frame(&rules.map_frame) {
        return Err(Refused::new(
            Refusal::WrongFrame,
            format!(
                "goal_pose in frame {:?}: goals are taken in {:?} only",
                goal.header.frame_id, rules.map_frame
            ),
        ));
    }
    let distance = (p.x * p.x + p.y * p.y + p.z * p.z).sqrt();
    if distance > rules.max_distance {
        return Err(Refused::new(
            Refusal::OutOfRange,
            format!(
                "goal_pose {distance:.1} m from the origin is beyond max_goal_distance {} m",
                rules.max_distance
            ),
        ));
    }
    if (q.norm() - 1.0).abs() > 0.01 {
        return Err(Refused::new(
            Refusal::OutOfRange,
            format!("goal_pose orientation has length {:.3}, not 1", q.norm()),
        ));
    }
    Ok(Waypoint {
        x: p.x,
        y: p.y,
        z: p.z,
        time: None,
    })
}

/// The one-waypoint mission `id` for `waypoint`.
pub fn mission(id: u32, waypoint: Waypoint, rules: &GoalRules) -> Mission {
    Mission {
        id,
        waypoints: vec![waypoint],
        looped: false,
        arrival_radius: rules.arrival_radius,
        start_index: 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msgs::geometry::{Point, Pose, Quaternion};
    use crate::msgs::std::Header;

    fn rules() -> GoalRules {
        GoalRules {
            map_frame: "map".into(),
            max_distance: 100.0,
            arrival_radius: 0.1,
        }
    }

    fn goal(frame: &str, x: f64, y: f64) -> PoseStamped {
        PoseStamped {
            header: Header {
                frame_id: frame.into(),
                ..Header::default()
            },
            pose: Pose {
                position: Point { x, y, z: 0.0 },
                orientation: Quaternion::from_yaw(0.7),
            },
        }
    }

    #[test]
    fn a_goal_in_the_map_frame_becomes_a_one_waypoint_mission() {
        let w = waypoint(&goal("map", 1.5, -2.0), &rules()).unwrap();
        assert_eq!((w.x, w.y, w.z, w.time), (1.5, -2.0, 0.0, None));
        assert!(waypoint(&goal("/map", 1.5, -2.0), &rules()).is_ok());
        let m = mission(9, w, &rules());
        assert_eq!(
            (m.id, m.waypoints.len(), m.looped, m.arrival_radius),
            (9, 1, false, 0.1)
        );
        assert!(mech_proto::Body::Mission(m).validate().is_ok());
    }

    #[test]
    fn bad_goals_are_refused_with_their_reason() {
        let reason = |g: PoseStamped| waypoint(&g, &rules()).unwrap_err().reason;
        assert_eq!(reason(goal("map", f64::NAN, 0.0)), Refusal::NotFinite);
        assert_eq!(reason(goal("odom", 1.0, 0.0)), Refusal::WrongFrame);
        assert_eq!(reason(goal("", 1.0, 0.0)), Refusal::WrongFrame);
        assert_eq!(reason(goal("map", 100.0, 1.0)), Refusal::OutOfRange);
        let mut zero = goal("map", 1.0, 1.0);
        zero.pose.orientation = Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 0.0,
        };
        assert_eq!(reason(zero), Refusal::OutOfRange);
        let mut nan_q = goal("map", 1.0, 1.0);
        nan_q.pose.orientation.w = f64::NAN;
        assert_eq!(reason(nan_q), Refusal::NotFinite);
    }
}
