//! `waypoint ROBOT POINT... [loop]` / `waypoint ROBOT clear`: sets the
//! robots' waypoint drafts, which `send` turns into missions.

use mech_proto::Waypoint;

use crate::lang::args::{Args, Target};
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

/// Replace the waypoint draft of every robot of `target` (empty: clear it).
#[derive(Debug, Clone, PartialEq)]
pub struct SetWaypoints {
    pub target: Target,
    pub points: Vec<Waypoint>,
    pub looped: bool,
}

impl SetWaypoints {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<SetWaypoints, LangError> {
        let target = a.target()?;
        if a.keyword("clear") {
            return Ok(SetWaypoints {
                target,
                points: Vec::new(),
                looped: false,
            });
        }
        let mut points = Vec::new();
        let mut looped = false;
        while !a.is_empty() {
            if a.keyword("loop") {
                looped = true;
                break;
            }
            points.push(a.point()?.0);
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
            looped,
        })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, _at: Span) -> Result<Outcome, LangError> {
        let robots = ctx.resolve(&self.target)?;
        ctx.gcs.update_fleet(|f| {
            for r in &robots {
                if let Some(robot) = f.robot_mut(r) {
                    robot.waypoints.draft.clone_from(&self.points);
                    robot.waypoints.looped = self.looped;
                }
            }
        });
        let l = if self.looped { ", looped" } else { "" };
        let s = if self.points.len() == 1 { "" } else { "s" };
        Ok(Outcome::new(format!(
            "{} waypoint{s} for {}{l}",
            self.points.len(),
            robots.join(", ")
        )))
    }
}
