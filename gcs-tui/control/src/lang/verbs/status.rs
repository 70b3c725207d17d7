//! `status [TARGET]`: one line per robot (link, pose, speed, mode, route,
//! failsafe), for every robot when no target is given.

use mech_core::fleet::Robot;

use super::channel_name;
use crate::lang::args::{Args, Target, failsafe_name};
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

/// Report on the robots of `target`, or on every robot.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Status {
    pub target: Option<Target>,
}

impl Status {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<Status, LangError> {
        Ok(Status {
            target: if a.is_empty() {
                None
            } else {
                Some(a.target()?)
            },
        })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, _at: Span) -> Result<Outcome, LangError> {
        let robots = match &self.target {
            Some(t) => ctx.resolve(t)?,
            None => ctx.gcs.with_fleet(|f| f.robots.keys().cloned().collect()),
        };
        let details = ctx.gcs.with_fleet(|f| {
            robots
                .iter()
                .filter_map(|r| f.robot(r))
                .map(status_line)
                .collect::<Vec<_>>()
        });
        Ok(Outcome {
            summary: format!("{} robots", details.len()),
            details,
        })
    }
}

fn status_line(r: &Robot) -> String {
    format!(
        "{} #{} {} {} at ({:.2}, {:.2}) heading {:.2} speed {:.2} mode {:?} route {}{} failsafe {}",
        r.name,
        r.id,
        r.platform,
        r.link.as_str(),
        r.pose.x,
        r.pose.y,
        r.pose.heading,
        r.speed(),
        r.mode,
        channel_name(&r.route.requested),
        if r.route.is_pending() {
            " (pending)"
        } else {
            ""
        },
        failsafe_name(r.failsafe),
    )
}
