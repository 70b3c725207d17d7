//! `waypoint ROBOT POINT... [loop]` / `waypoint ROBOT clear`: sets the
//! robots' waypoint drafts, which `send` turns into missions. A point
//! written without a height (`x,y`) keeps the robot's height of now: a
//! flying robot's `z = 0` is its autopilot's origin, usually the ground,
//! so a 2D waypoint list must never bring a drone down (a ground robot
//! ignores `z`).

use mech_proto::Waypoint;

use crate::lang::args::{Args, Target};
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

/// Replace the waypoint draft of every robot of `target` (empty: clear it).
#[derive(Debug, Clone, PartialEq)]
pub struct SetWaypoints {
    pub target: Target,
    pub points: Vec<Waypoint>,
    /// Whether each point gave its height; one that did not takes each
    /// robot's height when the draft is set.
    pub given_z: Vec<bool>,
    pub looped: bool,
}

impl SetWaypoints {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<SetWaypoints, LangError> {
        let target = a.target()?;
        if a.keyword("clear") {
            return Ok(SetWaypoints {
                target,
                points: Vec::new(),
                given_z: Vec::new(),
                looped: false,
            });
        }
        let (mut points, mut given_z) = (Vec::new(), Vec::new());
        let mut looped = false;
        while !a.is_empty() {
            if a.keyword("loop") {
                looped = true;
                break;
            }
            let (point, z, _) = a.point_z()?;
            points.push(point);
            given_z.push(z);
        }
        if points.is_empty() {
            return Err(a.missing("point x,y"));
        }
        if points.len() > mech_proto::MAX_WAYPOINTS {
            return Err(LangError::new(
                target.span,
                format!("at most {} waypoints", mech_proto::MAX_WAYPOINTS),
            ));
        }
        Ok(SetWaypoints {
            target,
            points,
            given_z,
            looped,
        })
    }

    /// The points for a robot at height `z`: those written without a
    /// height are at `z`.
    fn at_height(&self, z: f64) -> Vec<Waypoint> {
        self.points
            .iter()
            .zip(&self.given_z)
            .map(|(p, given)| if *given { *p } else { Waypoint { z, ..*p } })
            .collect()
    }

    pub(super) async fn apply(&self, ctx: &mut Context, _at: Span) -> Result<Outcome, LangError> {
        let robots = ctx.resolve(&self.target)?;
        let heightless = self.given_z.iter().any(|given| !given);
        let kept = ctx.gcs.update_fleet(|f| {
            let mut kept = Vec::new();
            for r in &robots {
                if let Some(robot) = f.robot_mut(r) {
                    let z = robot.telemetry.pose.z;
                    robot.waypoints.draft = self.at_height(z);
                    robot.waypoints.looped = self.looped;
                    if heightless && z.abs() >= AIRBORNE {
                        kept.push(format!("{r} {z:.2} m"));
                    }
                }
            }
            kept
        });
        let l = if self.looped { ", looped" } else { "" };
        let s = if self.points.len() == 1 { "" } else { "s" };
        let kept = if kept.is_empty() {
            String::new()
        } else {
            format!(
                "; points without z keep the height of now ({}; write x,y,z to change it)",
                kept.join(", ")
            )
        };
        Ok(Outcome::new(format!(
            "{} waypoint{s} for {}{l}{kept}",
            self.points.len(),
            robots.join(", ")
        )))
    }
}

/// Height (m) from which the outcome says what height a point without z
/// was given (a ground robot's is of no interest: it ignores z).
const AIRBORNE: f64 = 0.05;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lang::{Command, parse_line};

    fn set(line: &str) -> SetWaypoints {
        match parse_line(line) {
            Ok(Some(s)) => match s.command {
                Command::SetWaypoints(w) => w,
                other => panic!("{other:?}"),
            },
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_point_without_z_takes_the_robots_height_and_one_with_z_keeps_its_own() {
        let w = set("waypoint px4_1 2.0,3.0 1.0,3.0,1.5@10s 0,0");
        assert_eq!(w.given_z, [false, true, false]);
        let at = w.at_height(3.05);
        let z: Vec<f64> = at.iter().map(|p| p.z).collect();
        assert_eq!(z, [3.05, 1.5, 3.05]);
        assert_eq!((at[0].x, at[0].y), (2.0, 3.0));
        assert_eq!(at[1].time, Some(10.0));
    }
}
